//! The top-down preallocated octree for moving spheres (Ericson, *Real-Time Collision
//! Detection* 7.3).
//!
//! Two placements ([`Placement`]), both computed in O(1) from integer cell coordinates; a move
//! that keeps the node only stores the new sphere.
//!
//! - [`Placement::Strict`] (RTCD 7.3; the default of a standalone [`Octree`], see
//!   [`Octree::new`]): every sphere lives in the deepest node
//!   whose split planes its AABB does not straddle. Spheres on the root's planes stay near the
//!   root, so a sphere is tested against the filtered straddlers of all its ancestors. Pairs
//!   come from a pass that radix-sorts the spheres into depth-first node order and streams over
//!   the node runs with a filtered ancestor stack (module `strict`).
//! - [`Placement::Loose`] (RTCD 7.3.6, looseness 2): a node's *loose bounds* are its cell grown
//!   by half the cell size on every side, and a sphere lives at the deepest level whose cells
//!   are at least its diameter, in the cell holding its centre; its box is then inside the
//!   node's loose bounds wherever the centre is, so a sphere's level depends only on its radius
//!   and nothing stays near the root for straddling a plane. Pairs are found between a node and
//!   its 26 same-level neighbours, and across levels by descending the neighbours' occupied
//!   subtrees (module `loose`). The default of
//!   [`BroadPhase`](crate::BroadPhase) ([`Config::octree_placement`](crate::Config)), whose
//!   octree holds spheres of every size.
//!
//! The region is fixed ([`Octree::new`]) or follows the spheres ([`Octree::growing`], module
//! `region`: when a growing tree re-roots, over which cube, and why no pass between two
//! re-roots is quadratic).
//!
//! Queries and rays follow the per-node lists through occupied subtrees, testing nodes by
//! their cells (strict) or loose bounds (loose) (module `query`); module `validate` checks
//! every invariant, for the tests.
//!
//! The modules, each standing only on those before it: `cell` (implicit node indexing and
//! Morton codes), `nodes` (paged per-node arrays and the one subtree walk), `placement` (both
//! placement rules, the walk keys and the region a node's spheres reach: apart from
//! [`Octree::for_each_pair`] choosing the pass, the only code that tells the placements
//! apart), `lists` (the per-node sphere lists and the relinks a move defers to the next
//! pass), `region` (the growing region), `batch` (the batched update split over tasks,
//! feature `parallel`), `walk` (the walk order, the test counter and the short and swept pair
//! loops both passes use), then `strict` and `loose` (one pair pass each; `loose_node`
//! holds the loose pass's work per node), `query` and
//! `validate`. This file holds the type and its API.
//!
//! Memory: the tree is "preallocated" in the sense of implicit indexing (level `L` starts at
//! node `(8^L − 1)/7`, a node's index within its level is its Morton code), but the per-node
//! arrays are paged: a page of 4096 list heads is allocated the first time a sphere is linked
//! into one of its nodes, a page of 4096 child masks the first time a sphere is linked below
//! one of them. A depth-10 tree (1.2 G implicit nodes) therefore costs a 2.4 MB page table
//! plus the pages its spheres touch; the levels between the root and the spheres' own keep
//! masks only, and the deepest level heads only.
//!
//! # Conventions
//! The same for [`Octree`] and [`Bvh`](crate::Bvh):
//! - **Constructors refuse, never correct.** [`Octree::new`] and [`Octree::with_placement`]
//!   return `Err` naming the first bad argument ([`Error::DepthOutOfRange`],
//!   [`Error::InvalidBounds`]) and build nothing; no argument is clamped or replaced.
//! - **`check` returns.** A `check` method (such as
//!   [`BvhConfig::check`](crate::BvhConfig::check)) tells a caller whether values it gives are
//!   valid, as a `Result`.
//! - **Pairs two ways.** [`Octree::for_each_pair`] calls a closure per overlapping pair;
//!   [`Octree::pairs_into`] appends them to a `Vec<Pair>`, canonical and unsorted.
//! - **Stats are cheap.** [`Octree::stats`] copies counters: no allocation, O(1).

#[cfg(feature = "parallel")]
mod batch;
mod cell;
mod lists;
mod loose;
mod loose_node;
mod nodes;
mod placement;
mod query;
mod ray;
mod region;
mod strict;
mod validate;
mod walk;

#[cfg(feature = "parallel")]
pub(crate) use batch::Moves;
pub(crate) use cell::curve_order;
pub use placement::{depth_for, depth_for_loose};

use crate::error::Error;
use crate::geom::{self, Aabb};
use crate::pair::{Pair, ProxyKey};
use cell::level_of;
use glam::Vec3;
use lists::Deferred;
#[cfg(feature = "parallel")]
use lists::relink_all;
use nodes::Nodes;
use placement::Lattice;
use region::Regrow;
use slotmap::{Key as _, SlotMap};

/// The deepest octree accepted by `Octree::new`: levels `0..=MAX_DEPTH`. At depth 10 a cell's
/// Morton code (10 bits per axis) still fits a `u32`, and so does the index of every node
/// (1 227 133 513 of them).
pub const MAX_DEPTH: u32 = 10;

/// "No object" / "no node" in the flat arrays.
const NONE: u32 = u32::MAX;

/// Which node a sphere lives in; see the [module docs](self). Fixed when the tree is made.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Placement {
    /// The deepest node whose split planes the sphere's box does not straddle (RTCD 7.3).
    /// Spheres on a plane stay in the node that owns the plane, however small they are.
    #[default]
    Strict,
    /// Loose octree with looseness 2 (RTCD 7.3.6): the deepest level whose cells are at least
    /// the sphere's diameter on every axis, in the cell holding its centre. Spheres whose centre
    /// is outside the bounds, or whose diameter exceeds the bounds' shortest side, stay in the
    /// root.
    Loose,
}

/// Per-sphere data, indexed by id: the slot index of the sphere's key, so a caller that
/// updates its spheres in key order streams through it, and a removal leaves a hole (`node ==
/// NONE`) instead of moving another sphere. The pair pass reads the sphere (its box is
/// [`Obj::aabb`], recomputed rather than stored) and `walk_key`; queries follow the node lists
/// ([`Link`]). The cell range placement computes is not kept: the strict pass quantises the
/// box again, the loose pass only the union of a node's boxes. 24 bytes.
#[derive(Clone, Copy, Debug)]
#[repr(C)]
pub(crate) struct Obj {
    /// The sphere exactly as given. 16 bytes.
    center: Vec3,
    radius: f32,
    /// The node the sphere is linked in. 4 bytes.
    node: u32,
    /// The node's walk key (`Lattice::walk_key`), set on every link, in 32 bits: the whole key
    /// while it fits (`walk_key_bits(depth) <= 32`, every depth below [`MAX_DEPTH`]); a
    /// deeper tree's pass sorts by `Lattice::walk_key` of `node` instead. 4 bytes.
    walk_key: u32,
}
const _: () = assert!(core::mem::size_of::<Obj>() == 24);

impl Obj {
    /// An id no sphere holds.
    const HOLE: Obj = Obj {
        center: Vec3::ZERO,
        radius: 0.0,
        node: NONE,
        walk_key: 0,
    };

    /// The box every pair test uses, `center ± radius`: the box `Lattice::locate` quantised,
    /// bit for bit.
    #[inline]
    fn aabb(&self) -> Aabb {
        Aabb::from_center_radius(self.center, self.radius)
    }

    /// Places the record in `node` of `lattice`, its walk key with it (truncated past 32 bits,
    /// where it is not read, see [`Obj::walk_key`]).
    #[inline]
    fn set_node(&mut self, lattice: &Lattice, node: u32) {
        self.walk_key = lattice.walk_key(node) as u32;
        self.node = node;
    }

    /// [`Obj::aabb`] as the passes' SIMD box.
    #[inline]
    pub(crate) fn simd_box(&self) -> crate::geom::SimdBox {
        crate::geom::SimdBox::from_center_radius(self.center, self.radius)
    }
}

/// A sphere's neighbours in its node's list, `NONE` at the ends; read by queries and written
/// only when the sphere changes node. 8 bytes.
#[derive(Clone, Copy, Debug)]
struct Link {
    next: u32,
    prev: u32,
}

impl Link {
    const NONE: Link = Link {
        next: NONE,
        prev: NONE,
    };
}

/// Per-depth occupancy and the cost of the last pair pass, from [`Octree::stats`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct OctreeStats {
    /// Spheres placed at each level (`per_level[0]` is the root and includes the overflow
    /// spheres); levels deeper than the tree's depth are 0.
    pub per_level: [u32; MAX_DEPTH as usize + 1],
    /// Spheres kept in the root because they do not fit it: strict, the AABB leaves the
    /// bounds; loose, the centre is outside the bounds or the diameter exceeds the shortest side.
    pub overflow: u32,
    /// AABB overlap tests done by the last pair pass (0 before the first).
    pub aabb_tests: u64,
    /// Times a growing tree ([`Octree::growing`]) re-rooted so far (0 for a fixed region).
    pub reroots: u32,
    /// Nodes visited by the last pair pass (0 before the first).
    pub nodes_visited: u32,
}

/// The cost of one pair pass.
#[derive(Clone, Copy, Debug, Default)]
struct PassCost {
    /// AABB overlap tests.
    tests: u64,
    /// Nodes visited.
    nodes_visited: u32,
}

/// Buffers of the pair passes, reused by every pass; they never shrink.
#[derive(Clone, Debug, Default)]
struct PassScratch {
    walk: walk::Scratch,
    strict: strict::Scratch,
    loose: loose::Scratch,
}

impl PassScratch {
    fn heap_bytes(&self) -> usize {
        self.walk.heap_bytes() + self.strict.heap_bytes() + self.loose.heap_bytes()
    }
}

/// A top-down octree over spheres with implicit node indexing; see the [module docs](self).
///
/// The region is fixed ([`Octree::new`]) or follows the spheres ([`Octree::growing`]); spheres
/// outside [`Octree::bounds`] are kept in the root and paired correctly. Every `Err`
/// leaves the tree exactly as it was.
#[derive(Clone, Debug)]
pub struct Octree {
    /// Bounds, depth, placement and the integer lattice.
    lattice: Lattice,
    /// The last sphere radius placed on `lattice` and its level ([`Lattice::locate_memo`]).
    memo: placement::LevelMemo,
    /// Hot data by id (see [`Obj`]).
    objs: Vec<Obj>,
    /// List links by id.
    links: Vec<Link>,
    /// Id → the version of its key (the key is `version << 32 | id` as slotmap's FFI form,
    /// see [`key_at`]), 0 for a hole: a key is live iff its version is `versions[its slot
    /// index]`.
    versions: Vec<u32>,
    /// Live spheres.
    live: usize,
    /// Mints keys for [`Octree::insert`].
    minted: SlotMap<ProxyKey, ()>,
    nodes: Nodes,
    per_level: [u32; MAX_DEPTH as usize + 1],
    overflow: u32,
    passes: PassScratch,
    /// The cost of the last pair pass.
    last_pass: PassCost,
    /// The region follows the spheres ([`Octree::growing`]); else it is fixed.
    growing: bool,
    /// A growing tree's region hint: covered by every region that still gives the typical
    /// sphere its cells.
    hint: Option<Aabb>,
    /// A growing tree's re-root policy state (module `region`).
    regrow: Regrow,
    /// Overflow spheres right after the last re-root: the next re-root waits for twice as
    /// many (or the limit, whichever is more), so re-roots stay amortised even when no region
    /// covers the world.
    overflow_after: u32,
    reroots: u32,
    /// Spheres moved to another node by [`Octree::update_live_deferred`] whose lists have not
    /// caught up yet, each id at most once, in the order they moved (the broadphase's slot
    /// order). The next pass relinks them while it sorts (see [`Octree::prepare_pass`]); any
    /// other change to the tree relinks them first ([`Octree::flush_relinks`]).
    deferred: Vec<Deferred>,
}

impl Octree {
    /// An empty strict octree over the fixed region `bounds` with levels `0..=depth` (spheres
    /// outside it are paired from the root: exact, but slower the more there are; see
    /// [`Octree::growing`] for a region that follows them). `Err(DepthOutOfRange)` if
    /// `depth > MAX_DEPTH`, `Err(InvalidBounds)` if the bounds are not finite or have no
    /// volume. Cheap at any depth: node storage is paged in as spheres arrive.
    pub fn new(bounds: Aabb, depth: u32) -> Result<Octree, Error> {
        Octree::with_placement(bounds, depth, Placement::Strict)
    }

    /// An empty octree with the given placement; same errors as [`Octree::new`].
    pub fn with_placement(bounds: Aabb, depth: u32, placement: Placement) -> Result<Octree, Error> {
        if depth > MAX_DEPTH {
            return Err(Error::DepthOutOfRange {
                depth,
                max: MAX_DEPTH,
            });
        }
        geom::check_bounds(&bounds)?;
        Ok(Octree::build(Lattice::new(bounds, depth, placement), false))
    }

    /// An empty octree whose region follows its spheres: a cube re-rooted (every sphere placed
    /// again) by [`Octree::maintain`] when spheres leave it, when the tree has doubled since
    /// its last re-root (the first spheres included), or when the spheres' sizes call for
    /// other cells; its depth follows the spheres' radii, and their spacing in a sparse world. No world is outside it: a world far
    /// from the origin, kilometres wide or spread by a teleport is paired at the speed of a
    /// well-placed one. See [`Octree::maintain`] for when it runs.
    #[must_use]
    pub fn growing(placement: Placement) -> Octree {
        let start = Aabb::new(Vec3::splat(-1.0), Vec3::ONE);
        Octree::build(Lattice::new(start, 0, placement), true)
    }

    /// [`Octree::growing`] with a hint of the region the spheres will occupy: each region the
    /// tree picks also covers `hint` as long as that keeps the typical sphere's cells (a hint
    /// far too wide or far away is ignored). `Err(InvalidBounds)` if the hint is not finite
    /// or has no volume.
    pub fn growing_with_hint(placement: Placement, hint: Aabb) -> Result<Octree, Error> {
        geom::check_bounds(&hint)?;
        let mut t = Octree::growing(placement);
        t.hint = Some(hint);
        Ok(t)
    }

    fn build(lattice: Lattice, growing: bool) -> Octree {
        let depth = lattice.depth;
        Octree {
            lattice,
            memo: placement::LevelMemo::EMPTY,
            objs: Vec::new(),
            links: Vec::new(),
            versions: Vec::new(),
            live: 0,
            minted: SlotMap::with_key(),
            nodes: Nodes::new(cell::node_count(depth)),
            per_level: [0; MAX_DEPTH as usize + 1],
            overflow: 0,
            passes: PassScratch::default(),
            last_pass: PassCost::default(),
            growing,
            hint: None,
            regrow: Regrow::default(),
            overflow_after: 0,
            reroots: 0,
            deferred: Vec::new(),
        }
    }

    /// True if the region follows the spheres ([`Octree::growing`]).
    #[must_use]
    pub fn is_growing(&self) -> bool {
        self.growing
    }

    /// Inserts a sphere and returns its new key. `Err` on a non-finite centre or radius or a
    /// negative radius (tree unchanged); a sphere outside the bounds is accepted.
    pub fn insert(&mut self, center: Vec3, radius: f32) -> Result<ProxyKey, Error> {
        geom::check_sphere(center, radius)?;
        if self.live >= (u32::MAX - 1) as usize {
            return Err(Error::Full);
        }
        let key = self.minted.insert(());
        self.push(key, center, radius);
        Ok(key)
    }

    /// Inserts a sphere its caller has checked (`check_sphere`) under a key the caller minted
    /// (the `BroadPhase` owns the key space) and that is not live in this tree. A tree fed
    /// through this function must not also mint keys with `insert`.
    pub(crate) fn insert_checked(&mut self, key: ProxyKey, center: Vec3, radius: f32) {
        debug_assert!(geom::check_sphere(center, radius).is_ok());
        debug_assert!(self.id_of(key).is_none());
        self.push(key, center, radius);
    }

    /// Test support: [`Octree::insert_checked`] with the checks, updating a live key instead.
    #[cfg(test)]
    pub(crate) fn insert_keyed(
        &mut self,
        key: ProxyKey,
        center: Vec3,
        radius: f32,
    ) -> Result<(), Error> {
        geom::check_sphere(center, radius)?;
        if self.id_of(key).is_some() {
            return self.update_checked(key, center, radius);
        }
        if key.is_null() || crate::pair::slot(key) >= u32::MAX - 1 {
            return Err(Error::UnknownProxy);
        }
        self.push(key, center, radius);
        Ok(())
    }

    /// Reserves the per-id arrays, exactly, for ids below `ids` (the broadphase's slots); a
    /// hint, as [`crate::radix::try_grow_to`].
    pub(crate) fn reserve_ids(&mut self, ids: usize) {
        crate::radix::try_grow_to(&mut self.objs, ids);
        crate::radix::try_grow_to(&mut self.links, ids);
        crate::radix::try_grow_to(&mut self.versions, ids);
    }

    /// Heap bytes held (capacities, not lengths), pair-pass scratch included.
    #[must_use]
    pub fn heap_bytes(&self) -> usize {
        self.objs.capacity() * core::mem::size_of::<Obj>()
            + self.links.capacity() * 8
            + self.versions.capacity() * 4
            + self.nodes.heap_bytes()
            + self.passes.heap_bytes()
            + self.deferred.capacity() * core::mem::size_of::<Deferred>()
    }

    /// Moves and/or resizes a sphere. `Err(UnknownProxy)` for a stale or foreign key, `Err`
    /// on bad geometry; either way the tree is unchanged. A move that stays in the same node
    /// only stores the new sphere.
    pub fn update(&mut self, key: ProxyKey, center: Vec3, radius: f32) -> Result<(), Error> {
        geom::check_sphere(center, radius)?;
        self.update_checked(key, center, radius)
    }

    /// [`Octree::update`] for a sphere its caller has already checked (`check_sphere`).
    /// Always inlined: the centre then stays in registers (passed to a call it goes through
    /// memory, and storing it again right after reading it back stalls).
    #[inline(always)]
    pub(crate) fn update_checked(
        &mut self,
        key: ProxyKey,
        center: Vec3,
        radius: f32,
    ) -> Result<(), Error> {
        let id = self.id_of(key).ok_or(Error::UnknownProxy)?;
        self.update_id(id, center, radius);
        Ok(())
    }

    /// Readies the next pair pass ([`Octree::for_each_pair`], or with `parts` above 1
    /// [`Octree::for_each_pair_chunked`], whose sort is then split in up to `parts` parts):
    /// maintains the region, then sorts the spheres into walk order with `tmp` as the sort's
    /// second buffer, which the caller lends while it holds nothing (the broadphase's pair list,
    /// before the pass fills it); `tmp` is left empty. The relinks deferred by
    /// [`Octree::update_live_deferred`] are done here too: beside the sort, as a task of their
    /// own, when the sort is split. The pass must come next, with no change to the tree
    /// between.
    pub(crate) fn prepare_pass(&mut self, tmp: &mut Vec<u64>, parts: usize) {
        self.maintain();
        let mut p = core::mem::take(&mut self.passes);
        // The deferred relinks write only the lists (links and node arrays), which the sort
        // does not read: with the sort split over the pool, they run beside it.
        #[cfg(feature = "parallel")]
        if parts > 1 && !self.deferred.is_empty() {
            let mut links = core::mem::take(&mut self.links);
            let mut nodes = core::mem::replace(&mut self.nodes, Nodes::new(0));
            let deferred = core::mem::take(&mut self.deferred);
            let tree = &*self;
            rayon::join(
                || tree.prepare_walk(&mut p.walk, tmp, parts),
                || relink_all(&tree.objs, &mut links, &mut nodes, &deferred),
            );
            (self.links, self.nodes, self.deferred) = (links, nodes, deferred);
            self.relinked();
            self.passes = p;
            return;
        }
        self.flush_relinks();
        self.prepare_walk(&mut p.walk, tmp, parts);
        self.passes = p;
    }

    /// The capacity of the walk-order sort's own second buffer, which a pass prepared with a
    /// lent one ([`Octree::prepare_pass`]) never grows.
    #[cfg(test)]
    pub(crate) fn own_sort_buffer(&self) -> usize {
        self.passes.walk.tmp.capacity()
    }

    /// A buffer of the pair passes that sits idle between them (the walk-order sort's items,
    /// room for every sphere), lent as scratch: its contents are garbage to both sides. The
    /// broadphase sorts its pair list with it, so the two sorts share one second buffer.
    pub(crate) fn idle_buffer(&mut self) -> &mut Vec<u64> {
        self.passes.walk.idle_items()
    }

    /// The box the live sphere of id `id` is held at (`center ± radius` as last stored).
    #[inline]
    pub(crate) fn held_box_of(&self, id: u32) -> crate::geom::SimdBox {
        debug_assert!(
            self.objs.get(id as usize).is_some_and(|o| o.node != NONE),
            "held_box_of an id not live here"
        );
        self.objs[id as usize].simd_box()
    }

    #[inline(always)]
    fn update_id(&mut self, id: u32, center: Vec3, radius: f32) {
        self.flush_relinks();
        let at = self.lattice.locate_memo(center, radius, &mut self.memo);
        self.store_located(id, center, radius, &at);
    }

    /// Stores sphere `id` at `center`, `radius`, placed at `at` (from this tree's lattice),
    /// relinking it if its node changed.
    #[inline(always)]
    fn store_located(&mut self, id: u32, center: Vec3, radius: f32, at: &placement::Located) {
        let old = self.store_sphere(id, center, radius, at);
        if old != at.node() {
            self.relink(id, old, at.node());
        }
    }

    /// Stores sphere `id`'s new `center` and `radius`, placed at `at`, and keeps the count of
    /// spheres outside the region; returns the node it was in (its record still names it).
    #[inline(always)]
    fn store_sphere(&mut self, id: u32, center: Vec3, radius: f32, at: &placement::Located) -> u32 {
        let i = id as usize;
        let old = self.objs[i].node;
        if old == 0 || at.outside() {
            let was_outside = self.is_outside(id);
            self.overflow = self.overflow - u32::from(was_outside) + u32::from(at.outside());
        }
        let o = &mut self.objs[i];
        (o.center, o.radius) = (center, radius);
        old
    }

    /// Moves one sphere's count from the level of node `from` to that of node `to`.
    #[inline]
    fn count_move(&mut self, from: u32, to: u32) {
        self.per_level[level_of(from) as usize] -= 1;
        self.per_level[level_of(to) as usize] += 1;
    }

    /// Removes a sphere; its key is never valid again. `Err(UnknownProxy)` for a stale or
    /// foreign key (tree unchanged).
    pub fn remove(&mut self, key: ProxyKey) -> Result<(), Error> {
        let id = self.id_of(key).ok_or(Error::UnknownProxy)?;
        self.flush_relinks();
        self.unlink(id);
        let i = id as usize;
        self.per_level[level_of(self.objs[i].node) as usize] -= 1;
        self.overflow -= u32::from(self.is_outside(id));
        self.minted.remove(key);
        self.objs[i] = Obj::HOLE;
        self.versions[i] = 0;
        self.live -= 1;
        while self.objs.last().is_some_and(|o| o.node == NONE) {
            self.objs.pop();
            self.links.pop();
            self.versions.pop();
        }
        Ok(())
    }

    /// Number of spheres.
    #[must_use]
    pub fn len(&self) -> usize {
        self.live
    }

    /// True if the tree holds no sphere.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.live == 0
    }

    /// True if `key` names a live sphere of this tree.
    #[must_use]
    pub fn contains(&self, key: ProxyKey) -> bool {
        self.id_of(key).is_some()
    }

    /// The sphere's AABB `center ± radius`, or `None` for a stale or foreign key.
    #[must_use]
    pub fn aabb(&self, key: ProxyKey) -> Option<Aabb> {
        self.id_of(key).map(|id| self.objs[id as usize].aabb())
    }

    /// The sphere's centre and radius exactly as last given, or `None` for a stale key.
    #[must_use]
    pub fn sphere(&self, key: ProxyKey) -> Option<(Vec3, f32)> {
        self.id_of(key).map(|id| {
            let o = &self.objs[id as usize];
            (o.center, o.radius)
        })
    }

    /// The level (0 = root) of the node holding the sphere, or `None` for a stale key.
    /// Spheres outside the region ([`Octree::bounds`]) are at level 0.
    #[must_use]
    pub fn level_of(&self, key: ProxyKey) -> Option<u32> {
        self.id_of(key)
            .map(|id| level_of(self.objs[id as usize].node))
    }

    /// The region the levels subdivide: the bounds given to [`Octree::new`], or a growing
    /// tree's current region (a cube; before its first re-root, `±1` m).
    #[must_use]
    pub fn bounds(&self) -> Aabb {
        self.lattice.bounds
    }

    /// The deepest level: the tree has levels `0..=depth` (a growing tree's current depth).
    #[must_use]
    pub fn depth(&self) -> u32 {
        self.lattice.depth
    }

    /// The placement given to [`Octree::with_placement`] ([`Placement::Strict`] for
    /// [`Octree::new`]).
    #[must_use]
    pub fn placement(&self) -> Placement {
        self.lattice.placement
    }

    /// Calls `f(a, b)` once for every pair of spheres whose AABBs overlap (closed: touching
    /// boxes overlap), in no particular order and with no particular key order inside a pair.
    /// A growing tree first [maintains](Octree::maintain) its region.
    pub fn for_each_pair(&mut self, f: impl FnMut(ProxyKey, ProxyKey)) {
        if !self.passes.walk.ready {
            self.flush_relinks();
            self.maintain();
        }
        let mut p = core::mem::take(&mut self.passes);
        self.last_pass = match self.lattice.placement {
            Placement::Strict => self.strict_pairs(&mut p.walk, &mut p.strict, f),
            Placement::Loose => self.loose_pairs(&mut p.walk, &mut p.loose, f),
        };
        self.passes = p;
    }

    /// The pairs of [`Octree::for_each_pair`], found in chunks over rayon's current pool:
    /// chunk `c` calls `emit(&mut out[c], a, b)` for each pair it finds (each pair is found by
    /// one chunk, once; which one is unspecified). `alongside` runs concurrently, with shared
    /// access to the tree (for queries). A strict tree's pass runs as one task, into `out[0]`.
    #[cfg(feature = "parallel")]
    pub(crate) fn for_each_pair_chunked<S, E, A>(&mut self, out: &mut [S], emit: &E, alongside: A)
    where
        S: Send,
        E: Fn(&mut S, ProxyKey, ProxyKey) + Sync,
        A: FnOnce(&Octree) + Send,
    {
        if !self.passes.walk.ready {
            self.flush_relinks();
            self.maintain();
        }
        let mut p = core::mem::take(&mut self.passes);
        let tree = &*self;
        let pass = || match tree.lattice.placement {
            Placement::Strict => match out.first_mut() {
                Some(o) => tree.strict_pairs(&mut p.walk, &mut p.strict, |a, b| emit(o, a, b)),
                None => PassCost::default(),
            },
            Placement::Loose => tree.loose_pairs_chunked(&mut p.walk, &mut p.loose, out, emit),
        };
        let (cost, ()) = rayon::join(pass, || alongside(tree));
        self.last_pass = cost;
        self.passes = p;
    }

    /// Appends every overlapping pair, canonical (`a < b`) but **unsorted**, to `out`
    /// (which is not cleared); sort with [`crate::pair::sort_dedup`] if order matters.
    pub fn pairs_into(&mut self, out: &mut Vec<Pair>) {
        self.for_each_pair(|a, b| out.push(Pair::new(a, b)));
    }

    /// Calls `f` with every sphere's key and box (`center ± radius`), in key slot order.
    pub fn for_each(&self, mut f: impl FnMut(ProxyKey, Aabb)) {
        for (id, obj) in self.objs.iter().enumerate() {
            if obj.node != NONE {
                f(self.key_of(id as u32), obj.aabb());
            }
        }
    }

    /// Occupancy per level, the overflow count, and the cost of the last pair pass.
    #[must_use]
    pub fn stats(&self) -> OctreeStats {
        OctreeStats {
            per_level: self.per_level,
            overflow: self.overflow,
            reroots: self.reroots,
            aabb_tests: self.last_pass.tests,
            nodes_visited: self.last_pass.nodes_visited,
        }
    }

    /// The id of the live sphere `key` names, if any.
    #[inline]
    fn id_of(&self, key: ProxyKey) -> Option<u32> {
        let ffi = key.data().as_ffi();
        let (id, version) = (ffi as u32, (ffi >> 32) as u32);
        (version != 0 && self.versions.get(id as usize) == Some(&version) && !key.is_null())
            .then_some(id)
    }

    /// The key of the live sphere `id`.
    #[inline]
    fn key_of(&self, id: u32) -> ProxyKey {
        key_at(&self.versions, id)
    }

    /// Adds a sphere that passed the checks under `key` (not live here) at its id.
    fn push(&mut self, key: ProxyKey, center: Vec3, radius: f32) {
        self.flush_relinks();
        let at = self.lattice.locate(center, radius);
        let id = crate::pair::slot(key);
        let i = id as usize;
        if self.objs.len() <= i {
            crate::radix::grow_slots(&mut self.objs, i + 1);
            crate::radix::grow_slots(&mut self.links, i + 1);
            crate::radix::grow_slots(&mut self.versions, i + 1);
            self.objs.resize(i + 1, Obj::HOLE);
            self.links.resize(i + 1, Link::NONE);
            self.versions.resize(i + 1, 0);
        }
        self.objs[i] = Obj {
            center,
            radius,
            ..Obj::HOLE
        };
        self.versions[i] = (key.data().as_ffi() >> 32) as u32;
        self.live += 1;
        self.per_level[level_of(at.node()) as usize] += 1;
        self.overflow += u32::from(at.outside());
        self.link(id, at.node());
    }

    /// True if the sphere with id `id` is counted in `overflow` (only root spheres can
    /// be).
    fn is_outside(&self, id: u32) -> bool {
        let o = &self.objs[id as usize];
        o.node == 0 && {
            let (c, r) = (o.center, o.radius);
            self.lattice.is_outside(&o.aabb(), c, r)
        }
    }
}

/// The key of id `id` whose version is `versions[id]`: slotmap's FFI form, `version << 32 |
/// index`, which both the broadphase's keys and the ones [`Octree::insert`] mints take.
#[inline]
fn key_at(versions: &[u32], id: u32) -> ProxyKey {
    let ffi = (u64::from(versions[id as usize]) << 32) | u64::from(id);
    ProxyKey::from(slotmap::KeyData::from_ffi(ffi))
}

#[cfg(test)]
mod tests;
