//! Full (re)build: binned SAH, `Middle` or `EqualCounts` top-down splits over a flat array of
//! boxes partitioned in place, with an explicit work stack and buffers reused across builds.

use super::node::{Node, PrimBox};
use super::{Bvh, BvhConfig, NONE, SplitMethod};
use crate::{Aabb, ProxyKey};
use glam::Vec3A;
use slotmap::Key;

/// The most SAH buckets a node may use (`BvhConfig::sah_buckets`).
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

impl PrimBox {
    /// Twice the centroid, `min + max`: the build bins and splits on doubled centroids, which
    /// orders and buckets them exactly as the centroids would be.
    #[inline]
    fn c2(&self) -> Vec3A {
        self.min + self.max
    }
}

/// The union of a set of boxes and the bounds of their doubled centroids. 64 bytes.
#[derive(Clone, Copy, Debug)]
struct Bounds {
    min: Vec3A,
    max: Vec3A,
    cmin: Vec3A,
    cmax: Vec3A,
}

impl Bounds {
    const EMPTY: Bounds = Bounds {
        min: Vec3A::INFINITY,
        max: Vec3A::NEG_INFINITY,
        cmin: Vec3A::INFINITY,
        cmax: Vec3A::NEG_INFINITY,
    };

    #[inline]
    fn add(&mut self, r: &PrimBox) {
        let c = r.c2();
        self.min = self.min.min(r.min);
        self.max = self.max.max(r.max);
        self.cmin = self.cmin.min(c);
        self.cmax = self.cmax.max(c);
    }

    #[inline]
    fn union(&self, o: &Bounds) -> Bounds {
        Bounds {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
            cmin: self.cmin.min(o.cmin),
            cmax: self.cmax.max(o.cmax),
        }
    }

    /// Surface area of the box union; 0 when empty (as [`Aabb::surface_area`]).
    #[inline]
    fn area(&self) -> f32 {
        area(self.min, self.max)
    }

    fn aabb(&self) -> Aabb {
        Aabb::new(self.min.into(), self.max.into())
    }

    fn of(refs: &[PrimBox]) -> Bounds {
        let mut b = Bounds::EMPTY;
        refs.iter().for_each(|r| b.add(r));
        b
    }
}

/// Surface area of the box `min..max`; 0 when empty (as [`Aabb::surface_area`]).
#[inline]
fn area(min: Vec3A, max: Vec3A) -> f32 {
    let d = (max - min).max(Vec3A::ZERO);
    2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
}

/// A node still to be made: the primitive range `start..end`, the parent to link it to, and
/// the bounds of its boxes and centroids (computed by whoever split the parent).
#[derive(Clone, Copy, Debug)]
struct Task {
    start: u32,
    end: u32,
    parent: u32,
    /// True for a second child: its index must be written into the parent's `first`.
    second: bool,
    bounds: Bounds,
}

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

/// Buffers every build reuses, so a rebuild allocates only when the tree grew.
#[derive(Clone, Debug, Default)]
pub(crate) struct BuildScratch {
    /// `ids[i]`: the primitive index (before the build) of the box now at `boxes[i]`.
    ids: Vec<u32>,
    tasks: Vec<Task>,
    keys: Vec<ProxyKey>,
    /// By primitive index before the build: its index after (`NONE` for a tombstone).
    new_pos: Vec<u32>,
    work: Work,
}

/// Per-node scratch of [`split`]: SAH buckets and the gather buffers of the sorting splits.
#[derive(Clone, Debug, Default)]
struct Work {
    /// [`BIN_SETS`] copies of the SAH buckets (`sah_buckets` of each in use).
    buckets: Vec<[Bucket; MAX_BUCKETS]>,
    /// Nodes of at least this many primitives use all the copies: [`BIN_SETS_MIN`] (tests
    /// change it to compare both ways).
    bin_sets_min: usize,
    order: Vec<(f32, u32)>,
    /// `bins[k]`: the SAH bucket of the node's `k`-th primitive, from the binning pass.
    bins: Vec<u8>,
    tmp_refs: Vec<PrimBox>,
    tmp_ids: Vec<u32>,
    /// [`partition_bins`]' lists of the misplaced positions left and right of the split.
    wrong: [Vec<u32>; 2],
}

/// A chosen split: `refs[..mid]` go left; the bounds of both halves.
struct Split {
    mid: usize,
    left: Bounds,
    right: Bounds,
}

impl Bvh {
    /// Rebuilds the whole tree from the current boxes with [`BvhConfig::split`]: pending
    /// inserts join the tree, tombstones are dropped, and the SAH cost is remembered as the
    /// reference for [`Bvh::refit`]'s quality check. Keys stay valid. O(n log n); allocates
    /// only when the tree grew past its largest size so far.
    pub fn rebuild(&mut self) {
        let mut s = core::mem::take(&mut self.scratch);
        // The build partitions `boxes` itself: drop the tombstones, remembering where each
        // live box came from.
        s.ids.clear();
        if self.tombstones == 0 {
            s.ids.extend(0..self.boxes.len() as u32);
        } else {
            let mut n = 0;
            for i in 0..self.boxes.len() {
                if !self.keys[i].is_null() {
                    self.boxes[n] = self.boxes[i];
                    s.ids.push(i as u32);
                    n += 1;
                }
            }
            self.boxes.truncate(n);
        }
        let n = self.boxes.len();
        self.nodes.clear();
        self.parent.clear();
        self.leaf_of.clear();
        self.leaf_of.resize(n, NONE);
        build_nodes(
            &self.config,
            &mut s,
            &mut self.boxes,
            &mut self.nodes,
            &mut self.parent,
            &mut self.leaf_of,
        );
        // Renumber: primitive index = position in tree order, so a leaf's range indexes
        // `boxes` and `keys` directly and traversals read contiguous memory.
        // - The new position of each old primitive is noted first, then the old keys are read
        //   in their own order and stored at their new places: stores to scattered places
        //   cost about half what loads from them do (a first build's keys lie in insertion
        //   order, so its map updates go in order too).
        // - A rebuild of a tree whose boxes barely moved leaves most primitives in place, and
        //   their entries in `ids` need no update.
        // - Both buffers are overwritten whole (with no tombstones every old index gets a new
        //   one; the live keys fill `0..n`), so they are only resized, which writes nothing
        //   when the length stays: a fill of ~12 MB was a tenth of an in-order 1M rebuild.
        if self.tombstones != 0 {
            s.new_pos.clear();
        }
        s.new_pos.resize(self.keys.len(), NONE);
        for (i, &old) in s.ids.iter().enumerate() {
            s.new_pos[old as usize] = i as u32;
        }
        s.keys.resize(n, ProxyKey::null());
        for (old, (&key, &i)) in self.keys.iter().zip(&s.new_pos).enumerate() {
            // Tombstones (null keys) got no new position.
            if i != NONE {
                s.keys[i as usize] = key;
                if i != old as u32 {
                    self.ids[key] = i;
                }
            }
        }
        core::mem::swap(&mut self.keys, &mut s.keys);
        self.tree_len = n;
        self.tombstones = 0;
        self.cost_at_build = self.sah_cost();
        self.rebuilds += 1;
        self.scratch = s;
    }
}

/// Builds the depth-first array over `refs`, reordering `refs` and `s.ids` into tree order.
///
/// Depth-first order with an explicit stack: a task's node gets the next free index when it
/// is popped; a split pushes the second child, then the first, so the first child is popped
/// next and lands at `parent + 1`. The second child is popped once the whole first subtree is
/// placed, and writes its index into the parent's `first`.
fn build_nodes(
    config: &BvhConfig,
    s: &mut BuildScratch,
    refs: &mut [PrimBox],
    nodes: &mut Vec<Node>,
    parent: &mut Vec<u32>,
    leaf_of: &mut [u32],
) {
    let BuildScratch {
        ids, tasks, work, ..
    } = s;
    if refs.is_empty() {
        return;
    }
    work.buckets.resize(BIN_SETS, [Bucket::EMPTY; MAX_BUCKETS]);
    work.bin_sets_min = BIN_SETS_MIN;
    tasks.clear();
    tasks.push(Task {
        start: 0,
        end: refs.len() as u32,
        parent: NONE,
        second: false,
        bounds: Bounds::of(refs),
    });
    while let Some(t) = tasks.pop() {
        let index = nodes.len() as u32;
        if t.second {
            nodes[t.parent as usize].first = index;
        }
        parent.push(t.parent);
        let range = t.start as usize..t.end as usize;
        let aabb = t.bounds.aabb();
        match split(
            config,
            work,
            &mut refs[range.clone()],
            &mut ids[range.clone()],
            &t.bounds,
        ) {
            None => {
                nodes.push(Node::leaf(&aabb, t.start, t.end - t.start));
                leaf_of[range].fill(index);
            }
            Some(sp) => {
                nodes.push(Node::interior(&aabb));
                let mid = t.start + sp.mid as u32;
                tasks.push(Task {
                    start: mid,
                    end: t.end,
                    parent: index,
                    second: true,
                    bounds: sp.right,
                });
                tasks.push(Task {
                    start: t.start,
                    end: mid,
                    parent: index,
                    second: false,
                    bounds: sp.left,
                });
            }
        }
    }
}

/// How to split a node's primitives (`refs`, with `ids` alongside), or `None` for a leaf.
/// Every `Some` has both halves non-empty, so the build always terminates.
fn split(
    config: &BvhConfig,
    work: &mut Work,
    refs: &mut [PrimBox],
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
    let extent = bounds.cmax - bounds.cmin;
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
            let mid_point = 0.5 * (bounds.cmin[axis] + bounds.cmax[axis]);
            let mid = partition(refs, ids, |r| r.c2()[axis] < mid_point);
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
fn sah_split<const AXIS: usize>(
    config: &BvhConfig,
    work: &mut Work,
    refs: &mut [PrimBox],
    ids: &mut [u32],
    bounds: &Bounds,
) -> Option<Split> {
    let n = refs.len();
    let nb = config.sah_buckets as usize;
    // `x = (c − lo)·scale ∈ [0, nb]` for a doubled centroid `c` (lane `AXIS` of `PrimBox::c2`,
    // the sums the centroid bounds were taken over, so `x >= 0` exactly). Adding 1.5·2²³,
    // whose float spacing is 1, rounds `x` to the nearest integer; clamped to `nb − 1` (a NaN
    // from overflowed sums too: `min` returns its argument then) and read back from the bits,
    // that is the bucket: monotone in `x`, 0 for the smallest centroid and `nb − 1` for the
    // largest, as the SAH sweep needs, in a few instructions where a saturating `as` cast
    // takes a dozen. (The end buckets are half and one and a half buckets wide.) The float
    // clamp keeps the index in `0..nb` whatever the input, which the mask shows the compiler
    // (no bounds check); the lanes are computed together from the sum the centroid bounds
    // take anyway.
    const MAGIC: f32 = 12_582_912.0;
    let lo = Vec3A::splat(bounds.cmin[AXIS]);
    let scale = Vec3A::splat(nb as f32 / (bounds.cmax[AXIS] - bounds.cmin[AXIS]));
    let (first, last) = (Vec3A::splat(MAGIC), Vec3A::splat(MAGIC + (nb - 1) as f32));
    // Count and bound a primitive in its bucket of `set`, and note the bucket for the partition.
    let bin = |set: &mut [Bucket; MAX_BUCKETS], r: &PrimBox, bin: &mut u8| {
        let c = r.c2();
        let rounded = ((c - lo) * scale + first).min(last).max(first);
        let k = rounded[AXIS].to_bits().wrapping_sub(MAGIC.to_bits()) as usize;
        debug_assert!(k < nb);
        *bin = k as u8;
        let b = &mut set[k & (MAX_BUCKETS - 1)];
        b.count += 1;
        b.bounds.min = b.bounds.min.min(r.min);
        b.bounds.max = b.bounds.max.max(r.max);
        b.bounds.cmin = b.bounds.cmin.min(c);
        b.bounds.cmax = b.bounds.cmax.max(c);
    };

    let Work {
        buckets: sets,
        bin_sets_min,
        bins,
        wrong,
        ..
    } = work;
    if bins.len() < n {
        bins.resize(n, 0);
    }
    let bins = &mut bins[..n];
    let [s0, s1, s2, s3] = &mut sets[..] else {
        unreachable!("build_nodes makes BIN_SETS bucket sets")
    };
    if n >= *bin_sets_min {
        for set in [&mut *s0, &mut *s1, &mut *s2, &mut *s3] {
            set[..nb].fill(Bucket::EMPTY);
        }
        let mut chunks = refs.chunks_exact(BIN_SETS);
        let mut bin_chunks = bins.chunks_exact_mut(BIN_SETS);
        for (r, k) in (&mut chunks).zip(&mut bin_chunks) {
            bin(s0, &r[0], &mut k[0]);
            bin(s1, &r[1], &mut k[1]);
            bin(s2, &r[2], &mut k[2]);
            bin(s3, &r[3], &mut k[3]);
        }
        for (r, k) in chunks.remainder().iter().zip(bin_chunks.into_remainder()) {
            bin(s0, r, k);
        }
        for i in 0..nb {
            s0[i] = merge(&merge(&s0[i], &s1[i]), &merge(&s2[i], &s3[i]));
        }
    } else {
        s0[..nb].fill(Bucket::EMPTY);
        for (r, k) in refs.iter().zip(bins.iter_mut()) {
            bin(s0, r, k);
        }
    }
    let buckets = &s0[..nb];
    // The sweeps track counts and box areas only: `right_cost[i]` is `N·S` of the buckets
    // right of plane `i`. The chosen plane's full bounds (centroids too) are merged at the end.
    let mut right_cost = [0.0f32; MAX_BUCKETS];
    let (mut count, mut lo, mut hi) = (0, Vec3A::INFINITY, Vec3A::NEG_INFINITY);
    for i in (1..nb).rev() {
        let b = &buckets[i];
        (count, lo, hi) = (count + b.count, lo.min(b.bounds.min), hi.max(b.bounds.max));
        right_cost[i - 1] = count as f32 * area(lo, hi);
    }
    let (mut best_cost, mut best_plane) = (f32::INFINITY, 0);
    let (mut count, mut lo, mut hi) = (0, Vec3A::INFINITY, Vec3A::NEG_INFINITY);
    for i in 0..nb - 1 {
        let b = &buckets[i];
        (count, lo, hi) = (count + b.count, lo.min(b.bounds.min), hi.max(b.bounds.max));
        let cost = count as f32 * area(lo, hi) + right_cost[i];
        // `i == 0`: areas overflow to ∞ for huge boxes, and the best must still be a plane.
        if i == 0 || cost < best_cost {
            (best_cost, best_plane) = (cost, i);
        }
    }
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
    partition_bins(refs, ids, bins, best_plane as u8, mid, wrong);
    Some(Split {
        mid,
        left: best_left.bounds,
        right: best_right.bounds,
    })
}

/// True if a leaf of `n` primitives costs no more than the best split (of cost `best` × S)
/// and may hold them.
fn leaf_is_cheaper(config: &BvhConfig, n: usize, bounds: &Bounds, best: f32) -> bool {
    let area = bounds.area();
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
fn sweep_split(
    config: &BvhConfig,
    work: &mut Work,
    refs: &mut [PrimBox],
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
    let (mut lo, mut hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
    for i in (1..n).rev() {
        (lo, hi) = (lo.min(refs[i].min), hi.max(refs[i].max));
        right_area[i - 1] = area(lo, hi);
    }
    let (mut best_cost, mut best_mid) = (f32::INFINITY, 1);
    let (mut lo, mut hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
    for i in 0..n - 1 {
        (lo, hi) = (lo.min(refs[i].min), hi.max(refs[i].max));
        let cost = (i + 1) as f32 * area(lo, hi) + (n - i - 1) as f32 * right_area[i];
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
/// bits mapped to integers in the order of `f32::total_cmp`, so the ranks are a permutation
/// whatever the floats are.
fn sort_by_axis(
    refs: &mut [PrimBox],
    ids: &mut [u32],
    axis: usize,
    tmp_refs: &mut Vec<PrimBox>,
    tmp_ids: &mut Vec<u32>,
) {
    let n = refs.len();
    debug_assert!(n <= MAX_BUCKETS);
    let mut keys = [0u32; MAX_BUCKETS];
    for (key, r) in keys.iter_mut().zip(refs.iter()) {
        let bits = r.c2()[axis].to_bits();
        // Negative floats reversed below the positive ones: `total_cmp`'s order, unsigned.
        *key = bits ^ (((bits as i32 >> 31) as u32) | 0x8000_0000);
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
    tmp_refs: &mut Vec<PrimBox>,
    tmp_ids: &mut Vec<u32>,
    refs: &mut [PrimBox],
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
fn median_split(work: &mut Work, refs: &mut [PrimBox], ids: &mut [u32], axis: usize) -> Split {
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
            .map(|(i, r)| (r.c2()[axis], i as u32)),
    );
    order.select_nth_unstable_by(mid, |a, b| a.0.total_cmp(&b.0));
    gather(order, tmp_refs, tmp_ids, refs, ids);
    halves(refs, mid)
}

/// The split `refs[..mid]` / `refs[mid..]` as they lie, with bounds computed by one pass.
fn halves(refs: &[PrimBox], mid: usize) -> Split {
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
    refs: &mut [PrimBox],
    ids: &mut [u32],
    bins: &[u8],
    plane: u8,
    mid: usize,
    wrong: &mut [Vec<u32>; 2],
) {
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
fn partition(refs: &mut [PrimBox], ids: &mut [u32], left: impl Fn(&PrimBox) -> bool) -> usize {
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
    use crate::Vec3;
    use crate::rng::Rng;

    /// Unit boxes with their min corner at `(x, 0, 0)`, and their ids `0..`.
    fn refs(xs: &[f32]) -> (Vec<PrimBox>, Vec<u32>) {
        let refs = xs
            .iter()
            .map(|&x| PrimBox {
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
        a.min == b.min && a.max == b.max && a.cmin == b.cmin && a.cmax == b.cmax
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
            let refs: Vec<PrimBox> = xs
                .iter()
                .map(|&x| PrimBox {
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
        let boxes: Vec<PrimBox> = (0..n)
            .map(|_| {
                let c = rng.vec3_in(Vec3::splat(-50.0), Vec3::new(80.0, 20.0, 20.0));
                let h = Vec3::splat(rng.range(0.1, 2.0));
                PrimBox::new(&Aabb::new(c - h, c + h))
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
