//! Full (re)build: binned SAH, `Middle` or `EqualCounts` top-down splits over an index array
//! partitioned in place, with an explicit work stack.

use super::node::Node;
use super::{Bvh, BvhConfig, NONE, SplitMethod};
use crate::{Aabb, ProxyKey};
use slotmap::Key;

/// The most SAH buckets a node may use (`BvhConfig::sah_buckets`).
pub(crate) const MAX_BUCKETS: usize = 64;

/// A primitive as the build sees it: its box and its index before the build. 28 bytes, so
/// the partition passes stream contiguous memory instead of chasing indices.
#[derive(Clone, Copy, Debug)]
pub(crate) struct BuildRef {
    aabb: Aabb, // 24 bytes
    id: u32,    // 4 bytes
}

/// A node still to be made: the primitive range `start..end`, the parent to link it to, and
/// the bounds of its boxes and of their centroids (computed by whoever split the parent).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Task {
    start: u32,
    end: u32,
    parent: u32,
    /// True for a second child: its index must be written into the parent's `first`.
    second: bool,
    bounds: Aabb,
    centroids: Aabb,
}

/// Buffers every build reuses, so a rebuild allocates only when the tree grew.
#[derive(Clone, Debug, Default)]
pub(crate) struct BuildScratch {
    refs: Vec<BuildRef>,
    tasks: Vec<Task>,
    keys: Vec<ProxyKey>,
    bins: Bins,
}

/// SAH bins, sized to `sah_buckets` once per build and reset per node (only the used ones:
/// resetting a fixed 64-entry array per node dominated small nodes).
#[derive(Clone, Debug, Default)]
struct Bins {
    buckets: Vec<Bucket>,
    /// The union of the buckets right of each plane.
    right: Vec<Bucket>,
}

/// A chosen split: `refs[..mid]` go left; the bounds and centroid bounds of both halves.
struct Split {
    mid: usize,
    left: (Aabb, Aabb),
    right: (Aabb, Aabb),
}

#[derive(Clone, Copy, Debug)]
struct Bucket {
    count: u32,
    bounds: Aabb,
    centroids: Aabb,
}

impl Bucket {
    const EMPTY: Bucket = Bucket {
        count: 0,
        bounds: Aabb::EMPTY,
        centroids: Aabb::EMPTY,
    };

    fn merge(&self, other: &Bucket) -> Bucket {
        Bucket {
            count: self.count + other.count,
            bounds: self.bounds.union(&other.bounds),
            centroids: self.centroids.union(&other.centroids),
        }
    }
}

impl Bvh {
    /// Rebuilds the whole tree from the current boxes with [`BvhConfig::split`]: pending
    /// inserts join the tree, tombstones are dropped, and the SAH cost is remembered as the
    /// reference for [`Bvh::refit`]'s quality check. Keys stay valid. O(n log n).
    pub fn rebuild(&mut self) {
        let mut s = core::mem::take(&mut self.scratch);
        s.refs.clear();
        s.refs.extend(
            self.boxes
                .iter()
                .zip(&self.keys)
                .enumerate()
                .filter(|(_, (_, key))| !key.is_null())
                .map(|(i, (aabb, _))| BuildRef {
                    aabb: *aabb,
                    id: i as u32,
                }),
        );
        let n = s.refs.len();
        self.nodes.clear();
        self.parent.clear();
        self.leaf_of.clear();
        self.leaf_of.resize(n, NONE);
        self.nodes.reserve(2 * n);
        self.parent.reserve(2 * n);
        build_nodes(
            &self.config,
            &mut s.refs,
            &mut s.tasks,
            &mut s.bins,
            &mut self.nodes,
            &mut self.parent,
            &mut self.leaf_of,
        );
        // Renumber: primitive index = position in tree order, so a leaf's range indexes
        // `boxes` and `keys` directly and traversals read contiguous memory.
        s.keys.clear();
        self.boxes.clear();
        for r in &s.refs {
            self.boxes.push(r.aabb);
            s.keys.push(self.keys[r.id as usize]);
        }
        core::mem::swap(&mut self.keys, &mut s.keys);
        for (i, &key) in self.keys.iter().enumerate() {
            self.ids[key] = i as u32;
        }
        self.tree_len = n;
        self.tombstones = 0;
        self.cost_at_build = self.sah_cost();
        self.rebuilds += 1;
        self.scratch = s;
    }
}

/// Builds the depth-first array over `refs`, reordering `refs` into tree order.
///
/// Depth-first order with an explicit stack: a task's node gets the next free index when it
/// is popped; a split pushes the second child, then the first, so the first child is popped
/// next and lands at `parent + 1`. The second child is popped once the whole first subtree is
/// placed, and writes its index into the parent's `first`.
fn build_nodes(
    config: &BvhConfig,
    refs: &mut [BuildRef],
    tasks: &mut Vec<Task>,
    bins: &mut Bins,
    nodes: &mut Vec<Node>,
    parent: &mut Vec<u32>,
    leaf_of: &mut [u32],
) {
    if refs.is_empty() {
        return;
    }
    let (bounds, centroids) = bounds_of(refs);
    let nb = config.sah_buckets as usize;
    bins.buckets.resize(nb, Bucket::EMPTY);
    bins.right.resize(nb, Bucket::EMPTY);
    tasks.clear();
    tasks.push(Task {
        start: 0,
        end: refs.len() as u32,
        parent: NONE,
        second: false,
        bounds,
        centroids,
    });
    while let Some(t) = tasks.pop() {
        let index = nodes.len() as u32;
        if t.second {
            nodes[t.parent as usize].first = index;
        }
        parent.push(t.parent);
        let range = t.start as usize..t.end as usize;
        match split(
            config,
            bins,
            &mut refs[range.clone()],
            &t.bounds,
            &t.centroids,
        ) {
            None => {
                nodes.push(Node::leaf(&t.bounds, t.start, t.end - t.start));
                leaf_of[range].fill(index);
            }
            Some(s) => {
                nodes.push(Node::interior(&t.bounds));
                let mid = t.start + s.mid as u32;
                tasks.push(Task {
                    start: mid,
                    end: t.end,
                    parent: index,
                    second: true,
                    bounds: s.right.0,
                    centroids: s.right.1,
                });
                tasks.push(Task {
                    start: t.start,
                    end: mid,
                    parent: index,
                    second: false,
                    bounds: s.left.0,
                    centroids: s.left.1,
                });
            }
        }
    }
}

/// How to split `refs` (a node's primitives), or `None` for a leaf. Every `Some` has both
/// halves non-empty, so the build always terminates.
fn split(
    config: &BvhConfig,
    bins: &mut Bins,
    refs: &mut [BuildRef],
    bounds: &Aabb,
    centroids: &Aabb,
) -> Option<Split> {
    let n = refs.len();
    let small = n <= config.max_leaf_size as usize;
    if n == 1 {
        return None;
    }
    let extent = centroids.extent();
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
        SplitMethod::Sah => sah_split(config, bins, refs, bounds, centroids, axis),
        _ if small => None,
        SplitMethod::Middle => {
            let mid_point = centroids.center()[axis];
            let mid = partition(refs, |r| r.aabb.center()[axis] < mid_point);
            if mid == 0 || mid == n {
                Some(median_split(refs, axis))
            } else {
                Some(halves(refs, mid))
            }
        }
        SplitMethod::EqualCounts => Some(median_split(refs, axis)),
    }
}

// Binned SAH (pbrt 4.3.2). Splitting a node of area S into children A and B costs one
// traversal step plus, for a ray that hits the node, the expected primitive tests of the
// children it also hits: P(hit A | hit node) = S_A / S for convex boxes, so
//     cost(split) = 1 + (N_A·S_A + N_B·S_B) / S,      cost(leaf) = N.
// Only planes between `nb` equal-width buckets of the centroid bounds' longest axis are
// tried: one pass bins every primitive (count and box union per bucket), a suffix pass and a
// prefix pass give the children's areas for all nb − 1 planes in O(nb). The costs are
// compared multiplied by S, which keeps zero-area nodes finite. Both end buckets hold a
// centroid (the extremes of the centroid bounds), so every candidate has two non-empty sides.
fn sah_split(
    config: &BvhConfig,
    bins: &mut Bins,
    refs: &mut [BuildRef],
    bounds: &Aabb,
    centroids: &Aabb,
    axis: usize,
) -> Option<Split> {
    let n = refs.len();
    let nb = config.sah_buckets as usize;
    if n <= nb {
        return sweep_split(config, bins, refs, bounds, axis);
    }
    let lo = centroids.min[axis];
    let scale = nb as f32 / (centroids.max[axis] - lo);
    let bucket_of = |r: &BuildRef| (((r.aabb.center()[axis] - lo) * scale) as usize).min(nb - 1);

    let Bins { buckets, right } = bins;
    buckets.fill(Bucket::EMPTY);
    for r in refs.iter() {
        let b = &mut buckets[bucket_of(r)];
        let c = r.aabb.center();
        b.count += 1;
        b.bounds = b.bounds.union(&r.aabb);
        b.centroids = Aabb::new(b.centroids.min.min(c), b.centroids.max.max(c));
    }
    // right[i]: the union of buckets i+1.. (the right side of plane i).
    let mut acc = Bucket::EMPTY;
    for i in (1..nb).rev() {
        acc = acc.merge(&buckets[i]);
        right[i - 1] = acc;
    }
    let (mut best_cost, mut best_plane, mut best_left) = (f32::INFINITY, 0, Bucket::EMPTY);
    let mut acc = Bucket::EMPTY;
    for i in 0..nb - 1 {
        acc = acc.merge(&buckets[i]);
        let cost = acc.count as f32 * acc.bounds.surface_area()
            + right[i].count as f32 * right[i].bounds.surface_area();
        // `i == 0`: areas overflow to ∞ for huge boxes, and the best must still be a plane.
        if i == 0 || cost < best_cost {
            (best_cost, best_plane, best_left) = (cost, i, acc);
        }
    }
    let area = bounds.surface_area();
    if n <= config.max_leaf_size as usize && n as f32 * area <= area + best_cost {
        return None;
    }
    let mid = partition(refs, |r| bucket_of(r) <= best_plane);
    if mid == 0 || mid == n {
        debug_assert!(false, "SAH split left a side empty");
        return Some(halves(refs, n / 2));
    }
    let best_right = right[best_plane];
    Some(Split {
        mid,
        left: (best_left.bounds, best_left.centroids),
        right: (best_right.bounds, best_right.centroids),
    })
}

/// SAH for a node with no more primitives than buckets: sort them by centroid along `axis`
/// and evaluate the cost of all n − 1 splits between neighbours exactly (same cost and leaf
/// rule as the binned version, which would spend more time on its buckets than on the node).
fn sweep_split(
    config: &BvhConfig,
    bins: &mut Bins,
    refs: &mut [BuildRef],
    bounds: &Aabb,
    axis: usize,
) -> Option<Split> {
    let n = refs.len();
    refs.sort_unstable_by(|a, b| a.aabb.center()[axis].total_cmp(&b.aabb.center()[axis]));
    let right = &mut bins.right;
    let mut acc = Aabb::EMPTY;
    for i in (1..n).rev() {
        acc = acc.union(&refs[i].aabb);
        right[i - 1].bounds = acc;
    }
    let (mut best_cost, mut best_mid) = (f32::INFINITY, 1);
    let mut acc = Aabb::EMPTY;
    for i in 0..n - 1 {
        acc = acc.union(&refs[i].aabb);
        let cost = (i + 1) as f32 * acc.surface_area()
            + (n - i - 1) as f32 * right[i].bounds.surface_area();
        if cost < best_cost {
            (best_cost, best_mid) = (cost, i + 1);
        }
    }
    let area = bounds.surface_area();
    if n <= config.max_leaf_size as usize && n as f32 * area <= area + best_cost {
        return None;
    }
    Some(halves(refs, best_mid))
}

/// Splits at the median centroid along `axis` (`select_nth_unstable_by`, O(n)).
fn median_split(refs: &mut [BuildRef], axis: usize) -> Split {
    let mid = refs.len() / 2;
    refs.select_nth_unstable_by(mid, |a, b| {
        a.aabb.center()[axis].total_cmp(&b.aabb.center()[axis])
    });
    halves(refs, mid)
}

/// The split `refs[..mid]` / `refs[mid..]` as they lie, with bounds computed by one pass.
fn halves(refs: &[BuildRef], mid: usize) -> Split {
    Split {
        mid,
        left: bounds_of(&refs[..mid]),
        right: bounds_of(&refs[mid..]),
    }
}

/// The union of the boxes, and the bounds of their centroids.
fn bounds_of(refs: &[BuildRef]) -> (Aabb, Aabb) {
    refs.iter()
        .fold((Aabb::EMPTY, Aabb::EMPTY), |(bounds, centroids), r| {
            let c = r.aabb.center();
            (
                bounds.union(&r.aabb),
                Aabb::new(centroids.min.min(c), centroids.max.max(c)),
            )
        })
}

/// Moves the refs satisfying `left` to the front (Hoare's scheme: each misplaced pair is
/// swapped once) and returns how many there are.
fn partition(refs: &mut [BuildRef], left: impl Fn(&BuildRef) -> bool) -> usize {
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
        i += 1;
        j -= 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Vec3;

    fn refs(xs: &[f32]) -> Vec<BuildRef> {
        xs.iter()
            .enumerate()
            .map(|(i, &x)| BuildRef {
                aabb: Aabb::new(Vec3::new(x, 0.0, 0.0), Vec3::new(x + 1.0, 1.0, 1.0)),
                id: i as u32,
            })
            .collect()
    }

    fn bins() -> Bins {
        let nb = BvhConfig::default().sah_buckets as usize;
        Bins {
            buckets: vec![Bucket::EMPTY; nb],
            right: vec![Bucket::EMPTY; nb],
        }
    }

    #[test]
    fn partition_moves_the_left_ones_first() {
        let mut r = refs(&[5.0, 1.0, 7.0, 2.0, 9.0, 0.0]);
        let mid = partition(&mut r, |r| r.aabb.min.x < 4.0);
        assert_eq!(mid, 3);
        assert!(r[..3].iter().all(|r| r.aabb.min.x < 4.0));
        assert!(r[3..].iter().all(|r| r.aabb.min.x >= 4.0));
    }

    #[test]
    fn sah_separates_two_clusters() {
        let mut r = refs(&[0.0, 0.5, 1.0, 100.0, 100.5, 101.0, 0.2, 100.2, 0.7]);
        let (b, c) = bounds_of(&r);
        let config = BvhConfig::default();
        let s = split(&config, &mut bins(), &mut r, &b, &c).expect("a split");
        assert_eq!(s.mid, 5);
        assert!(r[..5].iter().all(|r| r.aabb.min.x < 50.0));
        assert_eq!(s.left.0, bounds_of(&r[..5]).0);
        assert_eq!(s.right.0, bounds_of(&r[5..]).0);
        assert_eq!(s.right.1, bounds_of(&r[5..]).1);
    }

    #[test]
    fn coincident_centroids_end_in_leaf_or_halves() {
        let config = BvhConfig::default();
        let mut r = refs(&[3.0; 4]);
        let (b, c) = bounds_of(&r);
        assert!(split(&config, &mut bins(), &mut r, &b, &c).is_none());
        let mut r = refs(&[3.0; 9]);
        assert_eq!(
            split(&config, &mut bins(), &mut r, &b, &c).map(|s| s.mid),
            Some(4)
        );
    }
}
