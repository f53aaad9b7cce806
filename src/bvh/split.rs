//! How a node's primitives are split: binned SAH (with an exact sweep for nodes of at most
//! `sah_buckets` primitives), `Middle` or `EqualCounts`, each partitioning the node's boxes in
//! place and returning the bounds of both halves.

use super::{BvhConfig, SplitMethod};
use crate::geom::{SimdBox, ordered_bits};
use glam::Vec3A;

/// The most SAH buckets a node may use (`BvhConfig::sah_buckets`): past a few dozen, more
/// planes barely lower the tree's cost while the bucket sweeps grow, and a bucket index stays
/// a byte.
pub(crate) const MAX_BUCKETS: usize = 64;

/// Interleaved copies of the SAH buckets that a large node bins into: primitive `i` goes to
/// copy `i % BIN_SETS`. Neighbours in the array often share a bucket (a rebuild starts from the
/// last tree order), and one copy makes each update wait for the previous one's store.
const BIN_SETS: usize = 4;

// `sah_split` masks bucket indices with `MAX_BUCKETS − 1`.
const _: () = assert!(MAX_BUCKETS.is_power_of_two());

/// Nodes of at least this many primitives bin into [`BIN_SETS`] copies; smaller ones into one,
/// where clearing and merging the copies would cost more than the stalls.
const BIN_SETS_MIN: usize = 1024;

/// The union of a set of boxes and the bounds of their doubled centroids
/// ([`SimdBox::center2`]: the build bins and splits on doubled centroids, which order and bucket
/// exactly as the centroids would). 64 bytes.
#[derive(Clone, Copy, Debug)]
pub(super) struct Bounds {
    pub(super) boxes: SimdBox,
    pub(super) centroids: SimdBox,
}

impl Bounds {
    pub(super) const EMPTY: Bounds = Bounds {
        boxes: SimdBox::EMPTY,
        centroids: SimdBox::EMPTY,
    };

    #[inline]
    fn add(&mut self, r: &SimdBox) {
        self.boxes = self.boxes.union(r);
        self.centroids = self.centroids.union_point(r.center2());
    }

    #[inline]
    fn union(&self, o: &Bounds) -> Bounds {
        Bounds {
            boxes: self.boxes.union(&o.boxes),
            centroids: self.centroids.union(&o.centroids),
        }
    }

    pub(super) fn of(refs: &[SimdBox]) -> Bounds {
        let mut b = Bounds::EMPTY;
        refs.iter().for_each(|r| b.add(r));
        b
    }
}

/// An SAH bucket: how many primitives binned into it, and their bounds.
#[derive(Clone, Copy, Debug)]
struct Bucket {
    count: u32,
    bounds: Bounds,
}

impl Bucket {
    const EMPTY: Bucket = Bucket {
        count: 0,
        bounds: Bounds::EMPTY,
    };
}

/// Per-node scratch of [`split`]: SAH buckets and the gather buffers of the sorting splits.
#[derive(Clone, Debug, Default)]
pub(super) struct Work {
    /// [`BIN_SETS`] copies of the SAH buckets (`sah_buckets` of each in use).
    buckets: Vec<[Bucket; MAX_BUCKETS]>,
    /// Nodes of at least this many primitives use all the copies: [`BIN_SETS_MIN`] (tests
    /// change it to compare both ways).
    bin_sets_min: usize,
    order: Vec<(f32, u32)>,
    /// `bins[k]`: the SAH bucket of the node's `k`-th primitive, from the binning pass.
    bins: Vec<u8>,
    tmp_refs: Vec<SimdBox>,
    tmp_ids: Vec<u32>,
    /// [`partition_bins`]' lists of the misplaced positions left and right of the split.
    wrong: [Vec<u32>; 2],
}

impl Work {
    /// Heap bytes held (capacities).
    pub(super) fn heap_bytes(&self) -> usize {
        use core::mem::size_of;
        self.buckets.capacity() * size_of::<[Bucket; MAX_BUCKETS]>()
            + self.order.capacity() * 8
            + self.bins.capacity()
            + self.tmp_refs.capacity() * 32
            + (self.tmp_ids.capacity() + self.wrong[0].capacity() + self.wrong[1].capacity()) * 4
    }

    /// Readies the buffers for a build: the bucket copies exist and large nodes use them all.
    pub(super) fn prepare(&mut self) {
        self.buckets.resize(BIN_SETS, [Bucket::EMPTY; MAX_BUCKETS]);
        self.bin_sets_min = BIN_SETS_MIN;
    }
}

/// A chosen split: `refs[..mid]` go left; the bounds of both halves.
pub(super) struct Split {
    pub(super) mid: usize,
    pub(super) left: Bounds,
    pub(super) right: Bounds,
}

/// How to split a node's primitives (`refs`, with `ids` alongside), or `None` for a leaf.
/// Every `Some` has both halves non-empty, so the build always terminates.
#[inline]
pub(super) fn split(
    config: &BvhConfig,
    work: &mut Work,
    refs: &mut [SimdBox],
    ids: &mut [u32],
    bounds: &Bounds,
) -> Option<Split> {
    let n = refs.len();
    if n == 1 {
        return None;
    }
    let small = n <= config.max_leaf_size as usize;
    // SAH: a split costs at least the traversal step, so a node of at most that many
    // primitives is a leaf without looking for a plane.
    if small && config.split == SplitMethod::Sah && n as f32 <= config.traversal_cost {
        return None;
    }
    let extent = bounds.centroids.extent();
    let axis = extent.max_position();
    let nb = config.sah_buckets as usize;
    if !(extent[axis] > 0.0 && (nb as f32 / extent[axis]).is_finite()) {
        // All centroids (practically) coincide: no plane separates them.
        return if small {
            None
        } else {
            Some(halves(refs, n / 2))
        };
    }
    match config.split {
        SplitMethod::Sah if n <= nb => sweep_split(config, work, refs, ids, bounds, axis),
        // One copy per axis, so the hot loops read the coordinate straight from memory.
        SplitMethod::Sah => match axis {
            0 => sah_split::<0>(config, work, refs, ids, bounds),
            1 => sah_split::<1>(config, work, refs, ids, bounds),
            _ => sah_split::<2>(config, work, refs, ids, bounds),
        },
        _ if small => None,
        SplitMethod::Middle => {
            let mid_point = 0.5 * (bounds.centroids.min[axis] + bounds.centroids.max[axis]);
            let mid = partition(refs, ids, |r| r.center2()[axis] < mid_point);
            if mid == 0 || mid == n {
                Some(median_split(work, refs, ids, axis))
            } else {
                Some(halves(refs, mid))
            }
        }
        SplitMethod::EqualCounts => Some(median_split(work, refs, ids, axis)),
    }
}

// Binned SAH (pbrt 4.3.2), with the traversal cost as a parameter. Splitting a node of area S
// into children A and B costs one traversal step C_t (in units of one box-vs-box test) plus,
// for a query that reaches the node, the expected tests of the children it also reaches:
// P(reach A | reach node) = S_A / S for convex boxes, so
//     cost(split) = C_t + (N_A·S_A + N_B·S_B) / S,      cost(leaf) = N.
// A leaf is made when it is no dearer than the best split (and holds at most
// `max_leaf_size`). Only planes between `nb` equal-width buckets of the centroid bounds'
// longest axis are tried: one pass bins every primitive (count, box union and centroid
// bounds per bucket), a suffix pass and a prefix pass give the children's areas for all
// nb − 1 planes in O(nb). The costs are compared multiplied by S, which keeps zero-area nodes
// finite. Both end buckets hold a centroid (the extremes of the centroid bounds), so every
// candidate has two non-empty sides. The bucket unions are the children's exact bounds, so
// the children need no pass of their own before they are split in turn: each tree level costs
// one binning pass over its boxes, and one partition pass that reads a byte per primitive (its
// bucket, noted while binning) and moves only the boxes on the wrong side.
#[inline]
fn sah_split<const AXIS: usize>(
    config: &BvhConfig,
    work: &mut Work,
    refs: &mut [SimdBox],
    ids: &mut [u32],
    bounds: &Bounds,
) -> Option<Split> {
    let n = refs.len();
    let nb = config.sah_buckets as usize;
    let binner = Binner::<AXIS>::new(bounds, nb);
    let buckets = bin_all(&binner, work, refs);
    let (best_cost, best_plane) = best_plane(buckets);
    if leaf_is_cheaper(config, n, bounds, best_cost) {
        return None;
    }
    let union = |b: &[Bucket]| b.iter().fold(Bucket::EMPTY, |acc, b| merge(&acc, b));
    let (best_left, best_right) = (
        union(&buckets[..=best_plane]),
        union(&buckets[best_plane + 1..]),
    );
    // Left: the primitives binned at or below the plane, so the halves are exactly the ones
    // counted and bounded by the sweep (the pass reads one byte per primitive, and touches the
    // boxes only to swap them).
    let mid = best_left.count as usize;
    if mid == 0 || mid == n {
        // Reached when doubled centroids `min + max` overflow to ±∞ (boxes near `f32::MAX`):
        // every primitive bins alike and no plane separates them. Split in halves instead.
        return Some(halves(refs, n / 2));
    }
    partition_bins(
        refs,
        ids,
        &work.bins[..n],
        best_plane as u8,
        mid,
        &mut work.wrong,
    );
    Some(Split {
        mid,
        left: best_left.bounds,
        right: best_right.bounds,
    })
}

/// The bucket of a doubled centroid along `AXIS`, for the `nb` buckets over a node's centroid
/// bounds.
///
/// `x = (c − lo)·scale ∈ [0, nb]` for a doubled centroid `c` (lane `AXIS` of `center2`, the
/// sums the centroid bounds were taken over, so `x >= 0` exactly). Adding [`Binner::MAGIC`],
/// 1.5·2²³, whose float spacing is 1, rounds `x` to the nearest integer; clamped to `nb − 1` (a
/// NaN from overflowed sums too: `min` returns its argument then) and read back from the bits,
/// that is the bucket: monotone in `x`, 0 for the smallest centroid and `nb − 1` for the
/// largest, as the SAH sweep needs, in a few instructions where a saturating `as` cast takes a
/// dozen. (The end buckets are half and one and a half buckets wide.) The float clamp keeps the
/// index in `0..nb` whatever the input, which the mask shows the compiler (no bounds check);
/// the lanes are computed together from the sum the centroid bounds take anyway.
struct Binner<const AXIS: usize> {
    /// Buckets in use, `2..=MAX_BUCKETS`.
    nb: usize,
    lo: Vec3A,
    scale: Vec3A,
    first: Vec3A,
    last: Vec3A,
}

impl<const AXIS: usize> Binner<AXIS> {
    /// 1.5·2²³: floats in `[2²³, 2²⁴)` are the integers, so adding this rounds to one.
    const MAGIC: f32 = 12_582_912.0;

    #[inline]
    fn new(bounds: &Bounds, nb: usize) -> Self {
        Binner {
            nb,
            lo: Vec3A::splat(bounds.centroids.min[AXIS]),
            scale: Vec3A::splat(nb as f32 / bounds.centroids.extent()[AXIS]),
            first: Vec3A::splat(Self::MAGIC),
            last: Vec3A::splat(Self::MAGIC + (nb - 1) as f32),
        }
    }

    /// Counts and bounds `r` in its bucket of `set`, and notes the bucket in `bin` for the
    /// partition.
    #[inline]
    fn bin(&self, set: &mut [Bucket; MAX_BUCKETS], r: &SimdBox, bin: &mut u8) {
        let c = r.center2();
        let rounded = ((c - self.lo) * self.scale + self.first)
            .min(self.last)
            .max(self.first);
        let k = rounded[AXIS].to_bits().wrapping_sub(Self::MAGIC.to_bits()) as usize;
        debug_assert!(k < self.nb);
        *bin = k as u8;
        let b = &mut set[k & (MAX_BUCKETS - 1)];
        b.count += 1;
        b.bounds.add(r);
    }
}

/// Bins every primitive of `refs` (noting each one's bucket in `work.bins`), into the
/// [`BIN_SETS`] interleaved bucket copies for a large node, and returns the node's buckets.
#[inline]
fn bin_all<'w, const AXIS: usize>(
    binner: &Binner<AXIS>,
    work: &'w mut Work,
    refs: &[SimdBox],
) -> &'w [Bucket] {
    let n = refs.len();
    let nb = binner.nb;
    let Work {
        buckets: sets,
        bin_sets_min,
        bins,
        ..
    } = work;
    if bins.len() < n {
        bins.resize(n, 0);
    }
    let bins = &mut bins[..n];
    let [s0, s1, s2, s3] = &mut sets[..] else {
        unreachable!("Work::prepare makes BIN_SETS bucket sets")
    };
    if n < *bin_sets_min {
        s0[..nb].fill(Bucket::EMPTY);
        for (r, k) in refs.iter().zip(bins.iter_mut()) {
            binner.bin(s0, r, k);
        }
        return &s0[..nb];
    }
    for set in [&mut *s0, &mut *s1, &mut *s2, &mut *s3] {
        set[..nb].fill(Bucket::EMPTY);
    }
    let mut chunks = refs.chunks_exact(BIN_SETS);
    let mut bin_chunks = bins.chunks_exact_mut(BIN_SETS);
    for (r, k) in (&mut chunks).zip(&mut bin_chunks) {
        binner.bin(s0, &r[0], &mut k[0]);
        binner.bin(s1, &r[1], &mut k[1]);
        binner.bin(s2, &r[2], &mut k[2]);
        binner.bin(s3, &r[3], &mut k[3]);
    }
    for (r, k) in chunks.remainder().iter().zip(bin_chunks.into_remainder()) {
        binner.bin(s0, r, k);
    }
    for i in 0..nb {
        s0[i] = merge(&merge(&s0[i], &s1[i]), &merge(&s2[i], &s3[i]));
    }
    &s0[..nb]
}

/// The cheapest plane between `buckets` (plane `i` right after bucket `i`), with its cost
/// `N_A·S_A + N_B·S_B`. The sweeps track counts and box areas only: `right_cost[i]` is `N·S`
/// of the buckets right of plane `i`.
#[inline(always)]
fn best_plane(buckets: &[Bucket]) -> (f32, usize) {
    let nb = buckets.len();
    let mut right_cost = [0.0f32; MAX_BUCKETS];
    let (mut count, mut union) = (0, SimdBox::EMPTY);
    for i in (1..nb).rev() {
        let b = &buckets[i];
        (count, union) = (count + b.count, union.union(&b.bounds.boxes));
        right_cost[i - 1] = count as f32 * union.surface_area();
    }
    let (mut best_cost, mut best_plane) = (f32::INFINITY, 0);
    let (mut count, mut union) = (0, SimdBox::EMPTY);
    for i in 0..nb - 1 {
        let b = &buckets[i];
        (count, union) = (count + b.count, union.union(&b.bounds.boxes));
        let cost = count as f32 * union.surface_area() + right_cost[i];
        // `i == 0`: areas overflow to ∞ for huge boxes, and the best must still be a plane.
        if i == 0 || cost < best_cost {
            (best_cost, best_plane) = (cost, i);
        }
    }
    (best_cost, best_plane)
}

/// True if a leaf of `n` primitives costs no more than the best split (of cost `best` × S)
/// and may hold them.
fn leaf_is_cheaper(config: &BvhConfig, n: usize, bounds: &Bounds, best: f32) -> bool {
    let area = bounds.boxes.surface_area();
    n <= config.max_leaf_size as usize && n as f32 * area <= config.traversal_cost * area + best
}

fn merge(a: &Bucket, b: &Bucket) -> Bucket {
    Bucket {
        count: a.count + b.count,
        bounds: a.bounds.union(&b.bounds),
    }
}

/// SAH for a node with no more primitives than buckets: sort them by centroid along `axis`
/// and evaluate the cost of all n − 1 splits between neighbours exactly (same cost and leaf
/// rule as the binned version, which would spend more time on its buckets than on the node).
#[inline]
fn sweep_split(
    config: &BvhConfig,
    work: &mut Work,
    refs: &mut [SimdBox],
    ids: &mut [u32],
    bounds: &Bounds,
    axis: usize,
) -> Option<Split> {
    let n = refs.len();
    debug_assert!(n <= MAX_BUCKETS);
    sort_by_axis(refs, ids, axis, &mut work.tmp_refs, &mut work.tmp_ids);
    // The sweeps track the boxes only (the centroid bounds matter for the chosen halves
    // alone, computed once at the end): `right_area[i]` is the area right of split `i`.
    let mut right_area = [0.0f32; MAX_BUCKETS];
    let mut union = SimdBox::EMPTY;
    for i in (1..n).rev() {
        union = union.union(&refs[i]);
        right_area[i - 1] = union.surface_area();
    }
    let (mut best_cost, mut best_mid) = (f32::INFINITY, 1);
    let mut union = SimdBox::EMPTY;
    for i in 0..n - 1 {
        union = union.union(&refs[i]);
        let cost = (i + 1) as f32 * union.surface_area() + (n - i - 1) as f32 * right_area[i];
        if i == 0 || cost < best_cost {
            (best_cost, best_mid) = (cost, i + 1);
        }
    }
    if leaf_is_cheaper(config, n, bounds, best_cost) {
        return None;
    }
    Some(halves(refs, best_mid))
}

/// Sorts `refs` (and `ids` alongside) by centroid along `axis`, stably, by rank: the rank of
/// entry `i` is the number of entries that precede it in the sorted order (smaller keys, and
/// equal keys of smaller index), counted by comparisons without branches, and each entry is
/// then stored once at its rank. The few entries of a node that `sweep_split` takes (at most
/// `sah_buckets`) lie in random order in a first build, where an insertion sort mispredicts
/// at every step; when they already lie in order, as in a rebuild of a tree whose boxes barely
/// moved, one pass over the keys finds so and nothing moves. The keys are the centroid sums'
/// bits mapped to integers in the order of `f32::total_cmp` ([`ordered_bits`]), so the ranks
/// are a permutation whatever the floats are.
#[inline]
fn sort_by_axis(
    refs: &mut [SimdBox],
    ids: &mut [u32],
    axis: usize,
    tmp_refs: &mut Vec<SimdBox>,
    tmp_ids: &mut Vec<u32>,
) {
    let n = refs.len();
    debug_assert!(n <= MAX_BUCKETS);
    let mut keys = [0u32; MAX_BUCKETS];
    for (key, r) in keys.iter_mut().zip(refs.iter()) {
        *key = ordered_bits(r.center2()[axis]);
    }
    let keys = &keys[..n];
    if keys.windows(2).all(|w| w[0] <= w[1]) {
        return;
    }
    let mut rank = [0u8; MAX_BUCKETS];
    for (i, &key) in keys.iter().enumerate() {
        let before = keys[..i].iter().map(|&k| u32::from(k <= key)).sum::<u32>()
            + keys[i + 1..]
                .iter()
                .map(|&k| u32::from(k < key))
                .sum::<u32>();
        rank[i] = before as u8;
    }
    tmp_refs.clear();
    tmp_refs.extend_from_slice(refs);
    tmp_ids.clear();
    tmp_ids.extend_from_slice(ids);
    for ((r, &id), &k) in tmp_refs.iter().zip(tmp_ids.iter()).zip(&rank) {
        refs[k as usize] = *r;
        ids[k as usize] = id;
    }
}

/// Reorders `refs` and `ids` so that position `k` holds what was at `order[k].1`.
fn gather(
    order: &[(f32, u32)],
    tmp_refs: &mut Vec<SimdBox>,
    tmp_ids: &mut Vec<u32>,
    refs: &mut [SimdBox],
    ids: &mut [u32],
) {
    tmp_refs.clear();
    tmp_ids.clear();
    tmp_refs.extend(order.iter().map(|&(_, i)| refs[i as usize]));
    tmp_ids.extend(order.iter().map(|&(_, i)| ids[i as usize]));
    refs.copy_from_slice(tmp_refs);
    ids.copy_from_slice(tmp_ids);
}

/// Splits at the median centroid along `axis` (`select_nth_unstable_by`, O(n)).
fn median_split(work: &mut Work, refs: &mut [SimdBox], ids: &mut [u32], axis: usize) -> Split {
    let mid = refs.len() / 2;
    let Work {
        order,
        tmp_refs,
        tmp_ids,
        ..
    } = work;
    order.clear();
    order.extend(
        refs.iter()
            .enumerate()
            .map(|(i, r)| (r.center2()[axis], i as u32)),
    );
    order.select_nth_unstable_by(mid, |a, b| a.0.total_cmp(&b.0));
    gather(order, tmp_refs, tmp_ids, refs, ids);
    halves(refs, mid)
}

/// The split `refs[..mid]` / `refs[mid..]` as they lie, with bounds computed by one pass.
fn halves(refs: &[SimdBox], mid: usize) -> Split {
    Split {
        mid,
        left: Bounds::of(&refs[..mid]),
        right: Bounds::of(&refs[mid..]),
    }
}

/// Moves the `mid` primitives whose bucket `bins[k]` is at most `plane` (and their ids) to the
/// front. The misplaced ones are listed first, on each side of `mid`, by a pass over the bucket
/// bytes that stores every position and advances the list's end by the comparison (no branch
/// to mispredict when the buckets lie at random, as in a first build); the counts guarantee
/// the two lists are equally long, and their entries are swapped pairwise in increasing order.
/// Runs of 32 already in place, which a rebuild of a tree whose boxes barely moved is made of,
/// are skipped by one vectorised maximum (left) or minimum (right) over their bytes.
fn partition_bins(
    refs: &mut [SimdBox],
    ids: &mut [u32],
    bins: &[u8],
    plane: u8,
    mid: usize,
    wrong: &mut [Vec<u32>; 2],
) {
    /// Bytes checked per skip test: one or two vector registers.
    const RUN: usize = 32;
    let n = bins.len();
    let [wrong_left, wrong_right] = wrong;
    if wrong_left.len() < mid {
        wrong_left.resize(mid, 0);
    }
    if wrong_right.len() < n - mid {
        wrong_right.resize(n - mid, 0);
    }
    let mut left = 0;
    for start in (0..mid).step_by(RUN) {
        let run = &bins[start..(start + RUN).min(mid)];
        if run.iter().fold(0, |m, &b| m.max(b)) <= plane {
            continue;
        }
        for (k, &b) in run.iter().enumerate() {
            // `left <= start + k < mid`: in bounds.
            wrong_left[left] = (start + k) as u32;
            left += usize::from(b > plane);
        }
    }
    let mut right = 0;
    for start in (mid..n).step_by(RUN) {
        let run = &bins[start..(start + RUN).min(n)];
        if run.iter().fold(u8::MAX, |m, &b| m.min(b)) > plane {
            continue;
        }
        for (k, &b) in run.iter().enumerate() {
            // `right <= start + k − mid < n − mid`: in bounds.
            wrong_right[right] = (start + k) as u32;
            right += usize::from(b <= plane);
        }
    }
    debug_assert_eq!(left, right);
    for (&i, &j) in wrong_left[..left].iter().zip(&wrong_right[..right]) {
        refs.swap(i as usize, j as usize);
        ids.swap(i as usize, j as usize);
    }
}

/// Moves the refs satisfying `left` (and their ids) to the front (Hoare's scheme: each
/// misplaced pair is swapped once) and returns how many there are.
fn partition(refs: &mut [SimdBox], ids: &mut [u32], left: impl Fn(&SimdBox) -> bool) -> usize {
    let (mut i, mut j) = (0, refs.len());
    loop {
        while i < j && left(&refs[i]) {
            i += 1;
        }
        while i < j && !left(&refs[j - 1]) {
            j -= 1;
        }
        if i >= j {
            return i;
        }
        refs.swap(i, j - 1);
        ids.swap(i, j - 1);
        i += 1;
        j -= 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::Aabb;
    use crate::rng::Rng;
    use glam::Vec3;

    /// Unit boxes with their min corner at `(x, 0, 0)`, and their ids `0..`.
    fn refs(xs: &[f32]) -> (Vec<SimdBox>, Vec<u32>) {
        let refs = xs
            .iter()
            .map(|&x| SimdBox {
                min: Vec3A::new(x, 0.0, 0.0),
                max: Vec3A::new(x + 1.0, 1.0, 1.0),
            })
            .collect();
        (refs, (0..xs.len() as u32).collect())
    }

    fn work() -> Work {
        Work {
            buckets: vec![[Bucket::EMPTY; MAX_BUCKETS]; BIN_SETS],
            bin_sets_min: BIN_SETS_MIN,
            ..Work::default()
        }
    }

    fn same(a: &Bounds, b: &Bounds) -> bool {
        a.boxes == b.boxes && a.centroids == b.centroids
    }

    #[test]
    fn partition_moves_the_left_ones_first_with_their_ids() {
        let (mut r, mut ids) = refs(&[5.0, 1.0, 7.0, 2.0, 9.0, 0.0]);
        let mid = partition(&mut r, &mut ids, |r| r.min.x < 4.0);
        assert_eq!(mid, 3);
        assert!(r[..3].iter().all(|r| r.min.x < 4.0));
        assert!(r[3..].iter().all(|r| r.min.x >= 4.0));
        let xs = [5.0, 1.0, 7.0, 2.0, 9.0, 0.0];
        assert!(r.iter().zip(&ids).all(|(r, &i)| r.min.x == xs[i as usize]));
    }

    #[test]
    fn partition_bins_moves_the_low_buckets_first_with_their_ids() {
        // The bucket of each box is its x. Runs in place (skipped by the run check), runs with
        // a few misplaced ones and shuffled stretches, around a left side of odd length.
        let mut rng = Rng::new(11);
        let mut xs: Vec<f32> = (0..300).map(|i| if i < 150 { 2.0 } else { 9.0 }).collect();
        for i in (40..60).chain(90..250) {
            xs[i] = rng.below(12) as f32;
        }
        xs[5] = 7.0;
        xs[290] = 1.0;
        let plane = 4;
        let bins: Vec<u8> = xs.iter().map(|&x| x as u8).collect();
        let mid = bins.iter().filter(|&&b| b <= plane).count();
        let (mut r, mut ids) = refs(&xs);
        partition_bins(&mut r, &mut ids, &bins, plane, mid, &mut Default::default());
        assert!(r[..mid].iter().all(|r| r.min.x <= 4.0));
        assert!(r[mid..].iter().all(|r| r.min.x > 4.0));
        assert!(r.iter().zip(&ids).all(|(r, &i)| r.min.x == xs[i as usize]));
    }

    #[test]
    fn sort_by_axis_is_stable_and_keeps_ids() {
        let xs = [3.0, 1.0, 3.0, 0.0, 1.0, 3.0, -2.0];
        let (mut r, mut ids) = refs(&xs);
        sort_by_axis(&mut r, &mut ids, 0, &mut Vec::new(), &mut Vec::new());
        assert_eq!(ids, [6, 3, 1, 4, 0, 2, 5]);
        assert!(r.iter().zip(&ids).all(|(r, &i)| r.min.x == xs[i as usize]));
        // Already sorted: nothing moves.
        let before = ids.clone();
        sort_by_axis(&mut r, &mut ids, 0, &mut Vec::new(), &mut Vec::new());
        assert_eq!(ids, before);
    }

    #[test]
    fn sort_by_axis_equals_a_stable_sort() {
        // Random sizes up to the most buckets, keys with many ties, signs mixed, zeros of
        // both signs and infinities (overflowed sums): the same order as a stable sort.
        let mut rng = Rng::new(3);
        let pool = [
            -f32::INFINITY,
            -2.5,
            -1.0,
            -0.0,
            0.0,
            0.5,
            1.0,
            7.0,
            f32::INFINITY,
        ];
        for _ in 0..2000 {
            let n = 1 + rng.below(MAX_BUCKETS as u32) as usize;
            let xs: Vec<f32> = (0..n).map(|_| pool[rng.below(9) as usize]).collect();
            let refs: Vec<SimdBox> = xs
                .iter()
                .map(|&x| SimdBox {
                    min: Vec3A::new(0.0, x, 0.0),
                    max: Vec3A::new(1.0, x, 1.0),
                })
                .collect();
            let (mut r, mut ids) = (refs.clone(), (0..n as u32).collect::<Vec<_>>());
            sort_by_axis(&mut r, &mut ids, 1, &mut Vec::new(), &mut Vec::new());
            let mut want: Vec<u32> = (0..n as u32).collect();
            want.sort_by(|&a, &b| (2.0 * xs[a as usize]).total_cmp(&(2.0 * xs[b as usize])));
            assert_eq!(ids, want, "{xs:?}");
            assert!(r.iter().zip(&ids).all(|(r, &i)| *r == refs[i as usize]));
        }
    }

    /// Large nodes bin into `BIN_SETS` interleaved bucket copies, small ones into one: both
    /// must give the same split, with exact child bounds (merging the copies loses nothing).
    #[test]
    fn interleaved_bucket_sets_bin_like_one() {
        let mut rng = Rng::new(5);
        let n = BIN_SETS_MIN + 3;
        let boxes: Vec<SimdBox> = (0..n)
            .map(|_| {
                let c = rng.vec3_in(Vec3::splat(-50.0), Vec3::new(80.0, 20.0, 20.0));
                let h = Vec3::splat(rng.range(0.1, 2.0));
                SimdBox::new(&Aabb::new(c - h, c + h))
            })
            .collect();
        let config = BvhConfig::default();
        let b = Bounds::of(&boxes);
        let run = |bin_sets_min| {
            let mut w = Work {
                bin_sets_min,
                ..work()
            };
            let (mut r, mut ids) = (boxes.clone(), (0..n as u32).collect::<Vec<_>>());
            let s = split(&config, &mut w, &mut r, &mut ids, &b).expect("a split");
            assert!(same(&s.left, &Bounds::of(&r[..s.mid])));
            assert!(same(&s.right, &Bounds::of(&r[s.mid..])));
            assert!(r.iter().zip(&ids).all(|(r, &i)| *r == boxes[i as usize]));
            (s.mid, ids)
        };
        let (sets, one) = (run(BIN_SETS_MIN), run(usize::MAX));
        assert_eq!(sets, one);
        assert!(sets.0 > 0 && sets.0 < n);
    }

    #[test]
    fn sah_separates_two_clusters() {
        for (nb, traversal_cost) in [(12, 1.0), (4, 1.0), (12, 0.0)] {
            let config = BvhConfig {
                sah_buckets: nb,
                traversal_cost,
                ..BvhConfig::default()
            };
            let (mut r, mut ids) = refs(&[0.0, 0.5, 1.0, 100.0, 100.5, 101.0, 0.2, 100.2, 0.7]);
            let b = Bounds::of(&r);
            let s = split(&config, &mut work(), &mut r, &mut ids, &b).expect("a split");
            assert_eq!(s.mid, 5, "{nb} buckets");
            assert!(r[..5].iter().all(|r| r.min.x < 50.0));
            assert!(same(&s.left, &Bounds::of(&r[..5])));
            assert!(same(&s.right, &Bounds::of(&r[5..])));
        }
    }

    #[test]
    fn traversal_cost_bounds_the_leaves() {
        // Eight far-apart unit boxes: a split is cheap, so only the traversal cost keeps them
        // together: with C_t = 8 no split can beat the leaf.
        let xs: Vec<f32> = (0..8).map(|i| 10.0 * i as f32).collect();
        for (traversal_cost, leaf) in [(1.0, false), (8.0, true)] {
            let config = BvhConfig {
                traversal_cost,
                max_leaf_size: 8,
                ..BvhConfig::default()
            };
            let (mut r, mut ids) = refs(&xs);
            let b = Bounds::of(&r);
            let s = split(&config, &mut work(), &mut r, &mut ids, &b);
            assert_eq!(s.is_none(), leaf, "C_t = {traversal_cost}");
        }
    }

    #[test]
    fn coincident_centroids_end_in_leaf_or_halves() {
        let config = BvhConfig {
            max_leaf_size: 4,
            ..BvhConfig::default()
        };
        let (mut r, mut ids) = refs(&[3.0; 4]);
        let b = Bounds::of(&r);
        assert!(split(&config, &mut work(), &mut r, &mut ids, &b).is_none());
        let (mut r, mut ids) = refs(&[3.0; 9]);
        let b = Bounds::of(&r);
        assert_eq!(
            split(&config, &mut work(), &mut r, &mut ids, &b).map(|s| s.mid),
            Some(4)
        );
    }

    #[test]
    fn median_split_keeps_ids_with_their_boxes() {
        let xs = [9.0, 3.0, 7.0, 1.0, 5.0, 8.0, 2.0];
        let (mut r, mut ids) = refs(&xs);
        let s = median_split(&mut work(), &mut r, &mut ids, 0);
        assert_eq!(s.mid, 3);
        assert!(
            r[..3]
                .iter()
                .all(|a| r[3..].iter().all(|b| a.min.x <= b.min.x))
        );
        assert!(r.iter().zip(&ids).all(|(r, &i)| r.min.x == xs[i as usize]));
    }
}
