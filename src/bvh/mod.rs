//! The refittable bounding-volume hierarchy over rigid bodies, given by their world AABBs.
//!
//! A [`Bvh`] is a flat depth-first array of 32-byte nodes (pbrt's `LinearBVHNode`) built with
//! binned SAH (or [`SplitMethod::Middle`] / [`SplitMethod::EqualCounts`]), refitted bottom-up
//! in one reverse sweep per step, and rebuilt when its quality degrades.
//!
//! # Life cycle and exactness
//! Queries and pairs are **always exact for the current boxes**, whatever was called since
//! the last [`Bvh::refit`]:
//! - [`Bvh::update`] writes the box; if it left its leaf's box, the leaf and its ancestors are
//!   grown (walking up only while an ancestor does not contain it), so the tree stays
//!   conservative. [`Bvh::refit`] later tightens every node.
//!   Inside the crate, `update_box_deferred` grows only the leaf and notes it, for a caller
//!   that refits before its next pass anyway or enlarges the noted leaves' ancestors once
//!   (`enlarge_deferred`); no query or pair pass may run in between.
//! - [`Bvh::insert`] appends the box to a *pending* list that queries and pairs test
//!   linearly (pending × tree by tree queries, pending × pending by sort-and-sweep on x) until
//!   the next rebuild.
//! - [`Bvh::remove`] turns a primitive of the tree into a *tombstone* (an empty box that
//!   overlaps nothing); a pending one is dropped at once. The next rebuild compacts.
//!
//! # Rebuild policy
//! [`Bvh::refit`] rebuilds instead of refitting when the pending inserts plus tombstones exceed
//! [`BvhConfig::rebuild_after_changes`] × the primitive count at the last build (any change
//! when that count was 0), and rebuilds after refitting when [`Bvh::sah_cost`] exceeds
//! [`BvhConfig::rebuild_threshold`] × the cost at the last build.
//!
//! # Keys
//! [`Bvh::insert`] mints keys from a slotmap owned by the tree; `BroadPhase` mints its own keys
//! and hands them in. Use one way or the other on one tree, never both.
//!
//! # Conventions
//! The same for [`Bvh`] and [`Octree`](crate::Octree):
//! - **Constructors refuse, never correct.** [`Bvh::new`] and [`Bvh::from_aabbs`] return `Err`
//!   naming the first bad field or box ([`Error::InvalidConfig`], [`Error::NonFinite`],
//!   [`Error::InvertedAabb`]) and build nothing; no value is clamped or replaced.
//! - **`check` returns.** [`BvhConfig::check`] tells a caller whether a configuration is
//!   valid, as a `Result`.
//! - **Pairs two ways.** [`Bvh::for_each_pair`] calls a closure per overlapping pair;
//!   [`Bvh::pairs_into`] appends them to a `Vec<Pair>`, canonical and unsorted.
//! - **Stats are cheap.** [`Bvh::stats`] walks the node array once (for the SAH cost and the
//!   depth) and allocates nothing.

mod build;
mod lanes;
mod node;
mod pairs;
#[cfg(feature = "parallel")]
mod pairs_split;
mod query;
mod ray;
mod refit;
mod split;
mod validate;

use crate::error::Error;
use crate::geom::{Aabb, SimdBox, check_aabb};
use crate::pair::ProxyKey;
use lanes::Lanes;
use node::Node;
use slotmap::{Key, SecondaryMap, SlotMap};

pub(crate) use build::BuildScratch;
use pairs::PairScratch;
#[cfg(feature = "parallel")]
pub(crate) use pairs_split::SplitScratch;

/// "No index" in the `u32` side arrays.
const NONE: u32 = u32::MAX;

/// How [`Bvh::rebuild`] chooses the split of a node's primitives.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum SplitMethod {
    /// Binned surface-area heuristic (pbrt): best of `sah_buckets − 1` planes along the
    /// centroid bounds' longest axis; a node becomes a leaf when no split is cheaper.
    #[default]
    Sah,
    /// Split at the midpoint of the centroid bounds' longest axis (equal counts if one side
    /// would be empty). Fast to build, poorer trees for clustered input.
    Middle,
    /// Split at the median centroid along the longest axis: a balanced tree.
    EqualCounts,
}

/// Tunables of a [`Bvh`]; [`Bvh::new`] refuses values outside the documented ranges.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BvhConfig {
    /// The split method of every (re)build. Default [`SplitMethod::Sah`].
    pub split: SplitMethod,
    /// The most primitives a leaf may hold, `1..=255`; default 8. SAH may stop earlier.
    pub max_leaf_size: u32,
    /// SAH buckets per node, `2..=64`; default 12 (pbrt).
    pub sah_buckets: u32,
    /// The SAH cost of visiting a node, in units of one box-vs-box primitive test; `0..=64`,
    /// default 4. Larger values make fewer, fuller leaves (up to `max_leaf_size`); a node of at
    /// most this many primitives is always a leaf. The default is above 1 because a box test
    /// is a few vector instructions while a node visit (the stack, two child tests, the
    /// branches) costs several of them.
    pub traversal_cost: f32,
    /// [`Bvh::refit`] rebuilds when `sah_cost() / cost at build` exceeds this ratio; finite
    /// and `>= 1`, default 1.5.
    pub rebuild_threshold: f32,
    /// [`Bvh::refit`] rebuilds when pending inserts plus removed primitives since the last
    /// build exceed this fraction of the primitive count at that build; `>= 0` (0: any change,
    /// `+∞`: never), default 0.1.
    pub rebuild_after_changes: f32,
}

impl Default for BvhConfig {
    fn default() -> Self {
        Self {
            split: SplitMethod::Sah,
            max_leaf_size: 8,
            sah_buckets: 12,
            traversal_cost: 4.0,
            rebuild_threshold: 1.5,
            rebuild_after_changes: 0.1,
        }
    }
}

impl BvhConfig {
    /// `Ok` if every field is in its documented range, else the first offending field.
    pub fn check(&self) -> Result<(), Error> {
        let bad = |what, value: f32| Err(Error::InvalidConfig { what, value });
        if !(1..=255).contains(&self.max_leaf_size) {
            return bad("max_leaf_size", self.max_leaf_size as f32);
        }
        if !(2..=split::MAX_BUCKETS as u32).contains(&self.sah_buckets) {
            return bad("sah_buckets", self.sah_buckets as f32);
        }
        if !(0.0..=64.0).contains(&self.traversal_cost) {
            return bad("traversal_cost", self.traversal_cost);
        }
        if !(self.rebuild_threshold.is_finite() && self.rebuild_threshold >= 1.0) {
            return bad("rebuild_threshold", self.rebuild_threshold);
        }
        if self.rebuild_after_changes.is_nan() || self.rebuild_after_changes < 0.0 {
            return bad("rebuild_after_changes", self.rebuild_after_changes);
        }
        Ok(())
    }
}

/// A snapshot of a tree's shape and history, from [`Bvh::stats`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BvhStats {
    /// Nodes in the array (interior and leaves).
    pub nodes: usize,
    /// Leaf nodes.
    pub leaves: usize,
    /// Levels from the root to the deepest leaf (1 for a lone leaf, 0 for no tree).
    pub depth: usize,
    /// Live primitives ([`Bvh::len`]).
    pub primitives: usize,
    /// Primitives inserted since the last build, tested linearly until the next.
    pub pending: usize,
    /// Removed primitives still occupying a leaf slot until the next build.
    pub tombstones: usize,
    /// [`Bvh::sah_cost`] now.
    pub cost: f32,
    /// [`Bvh::sah_cost`] right after the last build.
    pub cost_at_build: f32,
    /// `cost / cost_at_build`, or 1 when the cost at build was 0.
    pub cost_ratio: f32,
    /// Full builds so far (explicit and triggered by [`Bvh::refit`]).
    pub rebuilds: u64,
    /// Refit sweeps so far (a refit that rebuilds instead does not count).
    pub refits: u64,
}

/// A refittable BVH over axis-aligned boxes; see the [module docs](self) for the life cycle.
#[derive(Clone, Debug)]
pub struct Bvh {
    config: BvhConfig,
    /// Mints keys for [`Bvh::insert`].
    slots: SlotMap<ProxyKey, ()>,
    /// Key → primitive index.
    ids: SecondaryMap<ProxyKey, u32>,
    /// Primitive index → key; null for a tombstone. Indices `< tree_len` are in tree order
    /// (a leaf's range indexes them directly), the rest are pending.
    keys: Vec<ProxyKey>,
    /// Primitive index → current box; [`Aabb::EMPTY`] for a tombstone.
    boxes: Vec<SimdBox>,
    /// The tree primitives' boxes (`boxes[..tree_len]`) again, face by face, for the leaf
    /// kernels of the pair passes.
    lanes: Lanes,
    /// Primitives covered by the node array (live or tombstones).
    tree_len: usize,
    /// Tombstones among the first `tree_len` primitives.
    tombstones: usize,
    /// Depth-first node array: node `n`'s first child is `n + 1`.
    nodes: Vec<Node>,
    /// Node → parent node (`NONE` for the root).
    parent: Vec<u32>,
    /// Primitive index (`< tree_len`) → its leaf node.
    leaf_of: Vec<u32>,
    cost_at_build: f32,
    /// The SAH cost at the last build or refit.
    cost_last: f32,
    rebuilds: u64,
    refits: u64,
    /// Scratch reused by every build and traversal.
    scratch: BuildScratch,
    /// Scratch of the `&mut self` pair traversals.
    pair_scratch: PairScratch,
    /// Leaves grown by [`Bvh::update_box_deferred`] whose ancestors are not grown yet
    /// (a leaf may appear more than once); empty whenever the tree is exact.
    deferred: Vec<u32>,
}

impl Bvh {
    /// An empty tree, or `Err(InvalidConfig)` naming the first out-of-range field.
    pub fn new(config: BvhConfig) -> Result<Bvh, Error> {
        config.check()?;
        Ok(Bvh {
            config,
            slots: SlotMap::with_key(),
            ids: SecondaryMap::new(),
            keys: Vec::new(),
            boxes: Vec::new(),
            lanes: Lanes::default(),
            tree_len: 0,
            tombstones: 0,
            nodes: Vec::new(),
            parent: Vec::new(),
            leaf_of: Vec::new(),
            cost_at_build: 0.0,
            cost_last: 0.0,
            rebuilds: 0,
            refits: 0,
            scratch: BuildScratch::default(),
            pair_scratch: PairScratch::default(),
            deferred: Vec::new(),
        })
    }

    /// A tree built in one pass over `aabbs`, with the key of each box in input order; `Err`
    /// (nothing built) if any box is not finite or inverted.
    pub fn from_aabbs(config: BvhConfig, aabbs: &[Aabb]) -> Result<(Bvh, Vec<ProxyKey>), Error> {
        let mut bvh = Bvh::new(config)?;
        aabbs.iter().try_for_each(check_aabb)?;
        // Sized once: growing by doubling would copy every array a few times over, and fault
        // in fresh pages for each copy.
        let n = aabbs.len();
        bvh.slots = SlotMap::with_capacity_and_key(n);
        bvh.ids = SecondaryMap::with_capacity(n);
        bvh.keys.reserve_exact(n);
        bvh.boxes.reserve_exact(n);
        let keys = aabbs
            .iter()
            .map(|aabb| bvh.insert(*aabb))
            .collect::<Result<Vec<_>, _>>()?;
        bvh.rebuild();
        Ok((bvh, keys))
    }

    /// The configuration the tree was made with.
    #[must_use]
    pub fn config(&self) -> &BvhConfig {
        &self.config
    }

    /// Adds a box and returns its new key. It is pending (tested linearly) until the next
    /// rebuild. `Err` for a non-finite or inverted box, or `Full`; the tree is then unchanged.
    pub fn insert(&mut self, aabb: Aabb) -> Result<ProxyKey, Error> {
        check_aabb(&aabb)?;
        self.check_room()?;
        let key = self.slots.insert(());
        self.push_pending(key, aabb);
        Ok(key)
    }

    /// [`Bvh::insert`] under a key minted by the caller (`BroadPhase`). A key already live in
    /// this tree is refused with `UnknownProxy` (it names no new proxy).
    #[cfg(test)]
    pub(crate) fn insert_keyed(&mut self, key: ProxyKey, aabb: Aabb) -> Result<(), Error> {
        check_aabb(&aabb)?;
        self.check_room()?;
        if key.is_null() || self.ids.contains_key(key) {
            return Err(Error::UnknownProxy);
        }
        self.push_pending(key, aabb);
        Ok(())
    }

    /// Appends a box its caller has checked under a key the caller minted and that is not
    /// live in this tree (`BroadPhase`); pending until the next rebuild.
    pub(crate) fn insert_checked(&mut self, key: ProxyKey, aabb: &Aabb) {
        debug_assert!(check_aabb(aabb).is_ok());
        debug_assert!(!key.is_null() && !self.ids.contains_key(key));
        self.push_pending(key, *aabb);
    }

    /// Heap bytes held (capacities, not lengths), build and traversal scratch included.
    #[must_use]
    pub fn heap_bytes(&self) -> usize {
        self.ids.capacity() * 12
            + self.keys.capacity() * 8
            + self.boxes.capacity() * 32
            + self.lanes.heap_bytes()
            + self.nodes.capacity() * 32
            + (self.parent.capacity() + self.leaf_of.capacity()) * 4
            + self.pair_scratch.heap_bytes()
            + self.scratch.heap_bytes()
            + self.deferred.capacity() * 4
    }

    fn check_room(&self) -> Result<(), Error> {
        if self.boxes.len() >= NONE as usize - 1 {
            return Err(Error::Full);
        }
        Ok(())
    }

    fn push_pending(&mut self, key: ProxyKey, aabb: Aabb) {
        self.ids.insert(key, self.boxes.len() as u32);
        self.keys.push(key);
        self.boxes.push(SimdBox::new(&aabb));
    }

    /// Replaces the box of `key`. Queries and pairs see the new box at once; node boxes are
    /// only grown here and tightened by [`Bvh::refit`]. `Err` (tree unchanged) for a bad
    /// box or a stale key.
    pub fn update(&mut self, key: ProxyKey, aabb: Aabb) -> Result<(), Error> {
        check_aabb(&aabb)?;
        self.update_checked(key, &aabb)
    }

    /// [`Bvh::update`] of a box the caller has already checked (finite, `min <= max`).
    #[inline]
    pub(crate) fn update_checked(&mut self, key: ProxyKey, aabb: &Aabb) -> Result<(), Error> {
        debug_assert!(check_aabb(aabb).is_ok());
        self.update_box(key, &SimdBox::new(aabb))
    }

    /// [`Bvh::update_checked`] of a box already in the hot form: a caller holding a `SimdBox`
    /// passes it as is (making an `Aabb` of it and back goes through memory and stalls).
    #[inline]
    pub(crate) fn update_box(&mut self, key: ProxyKey, b: &SimdBox) -> Result<(), Error> {
        if let Some(leaf) = self.write_box(key, b)? {
            self.enlarge_ancestors(leaf, b);
        }
        Ok(())
    }

    /// Writes `key`'s box (and its lane); the leaf that holds it, if it is in the tree yet.
    #[inline]
    fn write_box(&mut self, key: ProxyKey, b: &SimdBox) -> Result<Option<u32>, Error> {
        let id = *self.ids.get(key).ok_or(Error::UnknownProxy)? as usize;
        self.boxes[id] = *b;
        if id < self.tree_len {
            self.lanes.set(id, b);
            Ok(Some(self.leaf_of[id]))
        } else {
            Ok(None)
        }
    }

    /// [`Bvh::update_box`] that leaves the ancestors alone: the box is written and its leaf's
    /// box grown to hold it, and the leaf is noted if it grew. Until the next
    /// [`Bvh::enlarge_deferred`], [`Bvh::refit`] or [`Bvh::rebuild`], interior boxes may miss
    /// the box, so no query or pair pass may run (the pair passes check it in debug builds).
    /// A caller that refits before its next pass (a full pass) pays no walk up at all, and one
    /// that does not enlarges each grown leaf's ancestors once, however many of its boxes moved.
    #[inline]
    pub(crate) fn update_box_deferred(&mut self, key: ProxyKey, b: &SimdBox) -> Result<(), Error> {
        if let Some(leaf_index) = self.write_box(key, b)? {
            let leaf = &mut self.nodes[leaf_index as usize];
            let old = leaf.bounds();
            if !old.contains(b) {
                leaf.set_box(&old.union(b));
                self.deferred.push(leaf_index);
            }
        }
        Ok(())
    }

    /// True if [`Bvh::update_box_deferred`] grew leaves whose ancestors are not grown yet.
    #[must_use]
    pub(crate) fn has_deferred(&self) -> bool {
        !self.deferred.is_empty()
    }

    /// Removes `key`'s box; its key is never valid again. `Err(UnknownProxy)` for a stale or
    /// unknown key.
    pub fn remove(&mut self, key: ProxyKey) -> Result<(), Error> {
        let id = self.ids.remove(key).ok_or(Error::UnknownProxy)? as usize;
        self.slots.remove(key);
        if id < self.tree_len {
            self.keys[id] = ProxyKey::null();
            self.boxes[id] = SimdBox::EMPTY;
            self.lanes.set(id, &SimdBox::EMPTY);
            self.tombstones += 1;
        } else {
            // Pending: keep the pending region dense by moving the last one into the hole.
            self.keys.swap_remove(id);
            self.boxes.swap_remove(id);
            if let Some(&moved) = self.keys.get(id) {
                self.ids[moved] = id as u32;
            }
        }
        Ok(())
    }

    /// The SAH cost at the last refit or build over the cost at the last build (1 when that
    /// was 0), and the builds so far: [`Bvh::stats`]'s `cost_ratio` and `rebuilds` as of the
    /// last refit, in O(1).
    #[must_use]
    pub(crate) fn refit_stats(&self) -> (f32, u64) {
        let ratio = if self.cost_at_build > 0.0 {
            self.cost_last / self.cost_at_build
        } else {
            1.0
        };
        (ratio, self.rebuilds)
    }

    /// Live primitives.
    #[must_use]
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// True if the tree holds no live primitive.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// True if `key` names a live primitive of this tree.
    #[must_use]
    pub fn contains(&self, key: ProxyKey) -> bool {
        self.ids.contains_key(key)
    }

    /// The current box of `key` (as last given), or `None` for a stale or unknown key.
    #[must_use]
    pub fn aabb(&self, key: ProxyKey) -> Option<Aabb> {
        self.ids.get(key).map(|&id| self.boxes[id as usize].aabb())
    }

    /// Primitives inserted since the last build.
    fn pending(&self) -> usize {
        self.boxes.len() - self.tree_len
    }

    /// Calls `f` with every live primitive's key and current box, in primitive order.
    pub fn for_each(&self, mut f: impl FnMut(ProxyKey, Aabb)) {
        for (key, aabb) in self.keys.iter().zip(&self.boxes) {
            if !key.is_null() {
                f(*key, aabb.aabb());
            }
        }
    }

    /// Shape and history of the tree. O(nodes), no allocation.
    #[must_use]
    pub fn stats(&self) -> BvhStats {
        let (leaves, max_depth) = self.shape();
        let cost = self.sah_cost();
        BvhStats {
            nodes: self.nodes.len(),
            leaves,
            depth: max_depth,
            primitives: self.len(),
            pending: self.pending(),
            tombstones: self.tombstones,
            cost,
            cost_at_build: self.cost_at_build,
            cost_ratio: if self.cost_at_build > 0.0 {
                cost / self.cost_at_build
            } else {
                1.0
            },
            rebuilds: self.rebuilds,
            refits: self.refits,
        }
    }
}

impl Bvh {
    /// Leaves and levels of the node array, in one pass without a stack: in depth-first
    /// order node `n` is its parent's first child when the parent is `n − 1` (one level
    /// deeper), else the second child of an ancestor of `n − 1`, whose level is found by
    /// climbing the parent links from `n − 1`; each link is climbed once over the pass.
    fn shape(&self) -> (usize, usize) {
        let (mut leaves, mut depth, mut max_depth) = (0, 0, 0);
        for (n, node) in self.nodes.iter().enumerate() {
            let p = self.parent[n];
            if p == NONE {
                depth = 1;
            } else {
                let mut a = n as u32 - 1;
                while a != p {
                    a = self.parent[a as usize];
                    depth -= 1;
                }
                depth += 1;
            }
            max_depth = max_depth.max(depth);
            leaves += usize::from(node.is_leaf());
        }
        (leaves, max_depth)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;
    use glam::Vec3;

    #[test]
    fn insert_keyed_takes_the_callers_keys() {
        let mut outer = SlotMap::<ProxyKey, ()>::with_key();
        let mut bvh = Bvh::new(BvhConfig::default()).unwrap();
        let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        let k = outer.insert(());
        bvh.insert_keyed(k, b).unwrap();
        assert_eq!(bvh.insert_keyed(k, b), Err(Error::UnknownProxy));
        assert_eq!(
            bvh.insert_keyed(ProxyKey::null(), b),
            Err(Error::UnknownProxy)
        );
        let bad = Aabb::new(Vec3::ONE, Vec3::ZERO);
        assert!(bvh.insert_keyed(outer.insert(()), bad).is_err());
        assert_eq!(bvh.len(), 1);
        bvh.refit();
        assert_eq!(bvh.aabb(k), Some(b));
        bvh.remove(k).unwrap();
        outer.remove(k);
        let k2 = outer.insert(());
        assert!(!bvh.contains(k) && !bvh.contains(k2));
        bvh.validate();
    }

    /// `shape` walks without a stack; the reference keeps every node's level in a vector.
    #[test]
    fn shape_counts_leaves_and_levels() {
        let mut rng = Rng::new(9);
        for (split, n, spread) in [
            (SplitMethod::Sah, 1, 1.0),
            (SplitMethod::Sah, 3000, 40.0),
            (SplitMethod::EqualCounts, 777, 5.0),
            (SplitMethod::Middle, 300, 0.0),
        ] {
            // `spread` 0: boxes at 2^i, which the midpoint split peels off one by one.
            let boxes: Vec<Aabb> = (0..n)
                .map(|i| {
                    let c = if spread == 0.0 {
                        Vec3::splat(2f32.powi(i % 100))
                    } else {
                        rng.vec3_in(Vec3::splat(-spread), Vec3::splat(spread))
                    };
                    Aabb::from_center_radius(c, 0.5)
                })
                .collect();
            let config = BvhConfig {
                split,
                max_leaf_size: 2,
                ..BvhConfig::default()
            };
            let (bvh, _) = Bvh::from_aabbs(config, &boxes).unwrap();
            let mut depth = vec![0usize; bvh.nodes.len()];
            for n in 0..bvh.nodes.len() {
                let p = bvh.parent[n];
                depth[n] = if p == NONE { 1 } else { depth[p as usize] + 1 };
            }
            let leaves = bvh.nodes.iter().filter(|n| n.is_leaf()).count();
            let max = depth.iter().copied().max().unwrap_or(0);
            assert_eq!(bvh.shape(), (leaves, max), "{split:?} {n}");
        }
        assert_eq!(Bvh::new(BvhConfig::default()).unwrap().shape(), (0, 0));
    }

    /// Stands in for a counting allocator (which needs `unsafe impl GlobalAlloc`): after a
    /// warm-up, a step of update-all + refit + pairs must not grow or move any buffer.
    #[test]
    fn steady_state_steps_reuse_every_buffer() {
        let mut rng = Rng::new(4);
        let mut boxes: Vec<Aabb> = (0..2000)
            .map(|_| {
                Aabb::from_center_radius(rng.vec3_in(Vec3::splat(-20.0), Vec3::splat(20.0)), 0.6)
            })
            .collect();
        let config = BvhConfig {
            rebuild_threshold: 1e6,
            ..BvhConfig::default()
        };
        let (mut bvh, keys) = Bvh::from_aabbs(config, &boxes).unwrap();
        let fingerprint = |b: &Bvh| {
            [
                (b.nodes.as_ptr() as usize, b.nodes.capacity()),
                (b.boxes.as_ptr() as usize, b.boxes.capacity()),
                b.pair_scratch.fingerprint()[0],
                b.pair_scratch.fingerprint()[1],
            ]
        };
        let mut pairs = Vec::with_capacity(100_000);
        let mut step = |bvh: &mut Bvh, boxes: &mut [Aabb], rng: &mut Rng| {
            for (b, k) in boxes.iter_mut().zip(&keys) {
                let d = rng.vec3_in(Vec3::splat(-0.05), Vec3::splat(0.05));
                *b = Aabb::new(b.min + d, b.max + d);
                bvh.update(*k, *b).unwrap();
            }
            bvh.refit();
            pairs.clear();
            bvh.for_each_pair(|a, b| pairs.push((a, b)));
        };
        for _ in 0..5 {
            step(&mut bvh, &mut boxes, &mut rng);
        }
        let before = fingerprint(&bvh);
        for _ in 0..20 {
            step(&mut bvh, &mut boxes, &mut rng);
            assert_eq!(fingerprint(&bvh), before);
        }
        assert_eq!(bvh.stats().rebuilds, 1);
    }
}
