//! `BroadPhase`: spheres and rigid bodies behind one set of keys, one sorted pair list per step,
//! and the pairs that started and stopped overlapping since the last step.
//!
//! Every proxy has a dense slot ([`store`]); the key is checked once, at the API boundary.
//! Its box lives in exactly one structure, under its key: a sphere in the [`Octree`], a dynamic
//! body in the dynamic [`Bvh`], a static body in the static one. An update stores the new
//! shape and marks the slot; the step applies it ([`apply`]), then runs one of two passes,
//! defined once on [`BroadPhase`] ("The passes and the incremental regime"), chosen by
//! [`cost`] and run by [`step`].
//!
//! The files: this one holds the type and its public API; [`shape`] what a proxy is and whom
//! it pairs with; [`config`] the settings; [`fat`] the fat-box layer (motion, fat boxes, the
//! marks a step reads); [`slack`] what the incremental pass need not re-test; [`gapped`] the
//! lists it patches; [`patch`] the regime's lookup hints and patch buffers; [`packed`] the
//! packed pair the passes share; [`cost`] the cost model;
//! [`step`] the passes; [`regime`] the incremental regime's state as a type, its entry and
//! its exit; [`query`], [`snapshot`] (serde) and [`validate`] (the invariants).

mod apply;
mod config;
mod cost;
mod fat;
mod gapped;
mod packed;
mod patch;
mod query;
mod regime;
mod shape;
mod slack;
#[cfg(feature = "serde")]
mod snapshot;
mod step;
mod store;
mod validate;

pub use config::{Config, Passes};
pub use query::{QueryFilter, QueryPredicate};
pub use shape::{BodyKind, CollisionGroups, Shape};

use crate::bvh::Bvh;
use crate::geom::{self, check_aabb, check_sphere};
use crate::octree::Octree;
use crate::pair::{Pair, ProxyKey};
use crate::{Aabb, BatchError, Error, Vec3};
use shape::write_sphere;
use store::{Kind, Store, flag, mark_stale_in};

/// Which pass a step ran.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Pass {
    /// Nothing was inserted, updated or removed: the lists were left as they were.
    #[default]
    Unchanged,
    /// The full pass over exact boxes: the structures' pair passes.
    Full,
    /// The full pass over fat boxes, which (re)starts the candidate list.
    FullFat,
    /// Only the candidates of what moved were re-tested, and the proxies that left their fat
    /// box queried the structures.
    Incremental,
}

/// What the last [`BroadPhase::step`] did: how the adaptive choice went, and the state of the
/// structures after it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepStats {
    /// The pass that ran.
    pub pass: Pass,
    /// Proxies updated, inserted or removed since the previous step.
    pub updated: usize,
    /// Proxies that escaped: given a new fat box (they left the old one, or are new); each
    /// one is one query of the structures in an incremental step.
    pub escaped: usize,
    /// Candidate pairs whose exact boxes were tested.
    pub candidates_tested: usize,
    /// Candidate pairs held after the step (0 outside the incremental regime).
    pub candidates: usize,
    /// Pairs reported.
    pub pairs: usize,
    /// The tasks each phase of the step's full pass was split into over rayon's pool (feature
    /// `parallel`), 0 if no full pass ran split. For the tests that check the split ran.
    #[doc(hidden)]
    pub split_tasks: usize,
    /// Spheres per octree level (`[0]` is the root, with the spheres outside its region).
    pub octree_per_level: [u32; crate::octree::MAX_DEPTH as usize + 1],
    /// The dynamic BVH's SAH cost over its cost at its last build (1 when just built).
    pub dynamic_cost_ratio: f32,
    /// Rebuilds of the dynamic BVH so far.
    pub dynamic_rebuilds: u64,
    /// Rebuilds of the static BVH so far.
    pub static_rebuilds: u64,
}

/// The broadphase of a physics step: insert spheres and bodies, move them, and call
/// [`BroadPhase::step`] once per frame for the overlapping pairs and the pair events.
///
/// # The passes and the incremental regime
/// The **full pass** runs the structures' own pair passes over the boxes they hold: the
/// octree's for sphere × sphere, the dynamic BVH's self traversal and its traversal against the
/// static BVH for body × body, and sphere × body by queries from the smaller side into the
/// other's structure. Its cost follows the number of proxies. The **incremental pass** needs
/// the structures to hold *fat* boxes (each exact box grown by a *skin* that follows how far
/// that proxy moves per step, or swept along its motion once it left one) and the sorted list of *candidates*, the pairs of overlapping fat
/// boxes. Since an exact box lies in its fat box, every overlapping pair is a candidate. A step
/// then
/// 1. drops the candidates of proxies that were removed or left their fat box ("escaped"),
/// 2. queries the octree and both BVHs with each escaped proxy's new fat box for its new
///    candidates (a pair of two escaped proxies is found from both sides and kept once),
/// 3. scans old and new candidates in one pass, re-testing the exact boxes of those that name
///    a proxy that moved by half the least slack of its candidates (the least distance by
///    which any of its candidates' overlap outcomes could change) and keeping the others' last outcome, and patches the lists in place with what changed.
///
/// A proxy that moved less than that and stayed in its fat box changes nothing of this: its
/// update call applies it at once (a *nudge*, see `apply`), and the step never visits it.
///
/// Its cost follows what moved. While the structures hold fat boxes and the candidates are
/// kept, the broadphase is in the *incremental regime*; a full pass over fat boxes enters it
/// and a full pass over exact boxes leaves it. The regime is one value that exists only while
/// the broadphase is in it (the candidates, their reverse index, the fat boxes, the anchors
/// and slacks, and every proxy's exact box; outside it a sphere's exact box is the one its
/// octree record holds). Each step estimates both costs from what it is
/// about to do (movers, escapes, candidates) and runs the cheaper pass ([`Passes`]), so the
/// cost never jumps when a world wakes up or settles; [`StepStats::pass`] says which ran.
/// Outside the regime the estimate reads the motion just applied, not how many proxies were
/// sent: a proxy moving more than its smallest skin a step would escape every few
/// steps, a slower one would re-test in proportion to its motion over its size, and one sent
/// where it already was would cost nothing; so a settling pile sent whole every frame enters
/// the regime while its balls still move millimetres a step. Collision groups are tested where a pair is first found (in the
/// structures' passes and the escaped proxies' queries), so a filtered pair is never a
/// candidate, never sorted and never diffed.
#[derive(Clone, Debug)]
pub struct BroadPhase {
    config: Config,
    store: Store,
    /// The spheres, under their keys, each at its exact box (in the incremental regime, its
    /// fat box [`Incremental::held`](regime::Incremental::held)).
    octree: Octree,
    /// The dynamic and the static bodies, under their keys, each at its exact box (in the
    /// incremental regime, its fat box).
    dynamic: Bvh,
    statics: Bvh,
    /// A body's held box changed (or one was inserted or removed) since the tree's last refit.
    dynamic_changed: bool,
    statics_changed: bool,
    /// Dynamic bodies given a new fat box since the dynamic tree's last refit.
    dynamic_escapes: usize,
    /// The incremental regime's state, while the broadphase is in it (see
    /// [`regime::Incremental`]).
    regime: Option<regime::Incremental>,
    /// The buffers of the regime last left, kept for the next entry.
    spare: regime::Incremental,
    /// True once any proxy was given groups other than the default: until then the pair
    /// passes skip the groups test.
    any_groups: bool,
    /// Slots updated (or inserted) since the last step, each once (`flag::MOVED`).
    movers: Vec<u32>,
    /// Live slots updated since the last step and not yet applied (`flag::STALE`), all
    /// listed in `movers`.
    stale: usize,
    /// The radix sort's scratch for `movers` (see [`apply`]).
    movers_tmp: Vec<u32>,
    movers_counts: Vec<u32>,
    /// Slots given a new fat box since the last step, each once (`flag::ESCAPED`).
    escaped: Vec<u32>,
    /// Slots re-anchored this step, each once (`flag::LOUD`).
    loud: Vec<u32>,
    /// Slots to re-anchor at the next incremental step, each once (`flag::PENDING`).
    pending: Vec<u32>,
    /// Proxies removed since the last step.
    removals: usize,
    /// Proxies updated since the last step whose updates applied themselves, each once (see
    /// [`apply::Nudges`]): they are in no list, and count in the step's `updated`.
    nudged: usize,
    /// The lowest slot the next update may nudge: one past the last updated slot while the
    /// updates since the last step came in ascending slot order, `u32::MAX` once one did not
    /// (see `apply::in_order`).
    nudge_from: u32,
    /// The motion of the proxies applied this step, for the pass estimate.
    motion: fat::Motion,
    /// Scratch of the passes: new candidates or pairs (a full pass's sorted pairs until they
    /// replace the key pairs), sort buffer, events.
    fresh: Vec<u64>,
    sort_buf: Vec<u64>,
    added_packed: Vec<u64>,
    removed_packed: Vec<u64>,
    /// The lists handed out by `step` (the pair list behind a gap, see [`gapped::Gapped`]).
    pairs: gapped::Gapped<Pair>,
    added: Vec<Pair>,
    removed: Vec<Pair>,
    /// Steps taken: the clock of the per-proxy speed estimates.
    now: u32,
    /// The running work estimate of the incremental regime (see [`step`]).
    costs: cost::Costs,
    stats: StepStats,
    /// The parallel full pass's buffers.
    #[cfg(feature = "parallel")]
    par: step::Parallel,
}

impl BroadPhase {
    /// A broadphase with `config`. Fields out of range are replaced by their nearest valid
    /// value (a bad region hint by none, a bad margin or skin by 0, a bad threshold by 1.5);
    /// use [`BroadPhase::try_new`] to be told instead.
    #[must_use]
    pub fn new(config: Config) -> Self {
        let d = Config::default();
        let nonneg = |x: f32| if x.is_finite() && x >= 0.0 { x } else { 0.0 };
        Self::build(Config {
            bounds: config
                .bounds
                .filter(|hint| geom::check_bounds(hint).is_ok()),
            octree_placement: config.octree_placement,
            margin: nonneg(config.margin),
            rebuild_threshold: if config.rebuild_threshold.is_finite()
                && config.rebuild_threshold >= 1.0
            {
                config.rebuild_threshold
            } else {
                d.rebuild_threshold
            },
            skin: nonneg(config.skin),
            passes: config.passes,
        })
    }

    /// A broadphase with `config`, or the first field out of range.
    pub fn try_new(config: Config) -> Result<Self, Error> {
        config.validate()?;
        Ok(Self::build(config))
    }

    /// Builds from a validated config: every structure's constructor accepts it.
    fn build(config: Config) -> Self {
        let octree = match config.bounds {
            Some(hint) => Octree::growing_with_hint(config.octree_placement, hint),
            None => Ok(Octree::growing(config.octree_placement)),
        };
        let bvh = config.bvh_config();
        let (Ok(octree), Ok(dynamic), Ok(statics)) = (octree, Bvh::new(bvh), Bvh::new(bvh)) else {
            unreachable!("Config::validate checks every field the structures check");
        };
        Self {
            config,
            store: Store::default(),
            octree,
            dynamic,
            statics,
            dynamic_changed: false,
            statics_changed: false,
            dynamic_escapes: 0,
            regime: None,
            spare: regime::Incremental::default(),
            any_groups: false,
            movers: Vec::new(),
            stale: 0,
            movers_tmp: Vec::new(),
            movers_counts: Vec::new(),
            escaped: Vec::new(),
            loud: Vec::new(),
            pending: Vec::new(),
            removals: 0,
            nudged: 0,
            nudge_from: 0,
            motion: fat::Motion::default(),
            fresh: Vec::new(),
            sort_buf: Vec::new(),
            added_packed: Vec::new(),
            removed_packed: Vec::new(),
            pairs: gapped::Gapped::default(),
            added: Vec::new(),
            removed: Vec::new(),
            now: 0,
            costs: cost::Costs::default(),
            stats: StepStats::default(),
            #[cfg(feature = "parallel")]
            par: step::Parallel::default(),
        }
    }

    /// The configuration in force (after [`BroadPhase::new`]'s corrections).
    #[must_use]
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// What the last [`BroadPhase::step`] did.
    #[must_use]
    pub fn stats(&self) -> StepStats {
        self.stats
    }

    /// The octree holding the spheres, under the broadphase's keys, for debug views and
    /// stats, as the last [`BroadPhase::step`] left it (updates since then are applied by the
    /// next one). Each sphere is held as `center ± (radius + margin)`, or a larger box around it
    /// while the incremental pass runs; its level is where that box lives.
    #[must_use]
    pub fn octree(&self) -> &Octree {
        &self.octree
    }

    /// The BVH holding the dynamic or the static bodies, under the broadphase's keys, as the
    /// last [`BroadPhase::step`] left it. Each
    /// body is held as its box grown by the margin, or a larger box around it while the
    /// incremental pass runs.
    #[must_use]
    pub fn bvh(&self, kind: BodyKind) -> &Bvh {
        match kind {
            BodyKind::Dynamic => &self.dynamic,
            BodyKind::Static => &self.statics,
        }
    }

    /// Heap bytes held by the broadphase (every buffer's capacity), for memory budgets.
    #[must_use]
    pub fn heap_bytes(&self) -> usize {
        let v = |n: usize, one: usize| n * one;
        self.store.heap_bytes()
            + self.octree.heap_bytes()
            + self.dynamic.heap_bytes()
            + self.statics.heap_bytes()
            + v(
                self.movers.capacity()
                    + self.movers_tmp.capacity()
                    + self.movers_counts.capacity()
                    + self.escaped.capacity()
                    + self.loud.capacity()
                    + self.pending.capacity(),
                4,
            )
            + self
                .regime
                .as_ref()
                .map_or(0, regime::Incremental::heap_bytes)
            + self.spare.heap_bytes()
            + v(
                self.fresh.capacity()
                    + self.sort_buf.capacity()
                    + self.added_packed.capacity()
                    + self.removed_packed.capacity(),
                8,
            )
            + v(
                self.pairs.capacity() + self.added.capacity() + self.removed.capacity(),
                core::mem::size_of::<Pair>(),
            )
            + self.par_heap_bytes()
    }

    #[cfg(feature = "parallel")]
    fn par_heap_bytes(&self) -> usize {
        self.par.heap_bytes()
    }

    #[cfg(not(feature = "parallel"))]
    fn par_heap_bytes(&self) -> usize {
        0
    }

    /// Reserves room for `spheres` more spheres and `bodies` more bodies, exactly: a world
    /// that knows its size ahead keeps no growth slack in its per-proxy arrays (which
    /// otherwise grow by doubling). The octree's arrays are indexed by slot, so with spheres
    /// to come they are reserved for every new slot.
    /// A hint: room the allocator cannot give is not reserved (no error, no panic).
    pub fn reserve(&mut self, spheres: usize, bodies: usize) {
        let additional = spheres.saturating_add(bodies).min(MAX_PROXIES);
        let slots = self.store.reserve(additional);
        if let Some(r) = &mut self.regime {
            r.reserve(slots);
        }
        // Every insert is listed as moved and escaped until the next step.
        for list in [&mut self.movers, &mut self.escaped] {
            crate::radix::try_grow_to(list, list.len() + additional);
        }
        if spheres > 0 {
            self.octree.reserve_ids(self.store.slots() + additional);
        }
    }

    /// Adds a sphere; it pairs from the next [`BroadPhase::step`] on. `Err` on a non-finite
    /// centre or radius or a negative radius. Any finite position is accepted: the octree's region follows the spheres.
    pub fn insert_sphere(&mut self, center: Vec3, radius: f32) -> Result<ProxyKey, Error> {
        self.insert_sphere_with(center, radius, CollisionGroups::ALL)
    }

    /// Adds a body by its world AABB. `Err` on a non-finite or inverted box.
    pub fn insert_body(&mut self, aabb: Aabb, kind: BodyKind) -> Result<ProxyKey, Error> {
        self.insert_body_with(aabb, kind, CollisionGroups::ALL)
    }

    /// Adds many spheres at once, `(center, radius)` per entry, and returns their keys in the
    /// batch's order. Checked whole first: on the first bad entry (what
    /// [`BroadPhase::insert_sphere`] refuses, or `Error::Full` at the first entry that does
    /// not fit) nothing is added and the error names the entry.
    ///
    /// The batch's spheres are numbered by place. The broadphase keeps a proxy's records at
    /// its key's slot, and a batch hands its slots to its spheres along a space-filling curve
    /// through their centres, so spheres near each other get records near each other in
    /// memory. A step that visits a sphere's neighbours (the re-tests and the queries of a
    /// world that partly moves) then reads fewer cache lines than after inserts one at a time
    /// in an order that has nothing to do with place: load a world in one batch.
    pub fn insert_spheres(&mut self, spheres: &[(Vec3, f32)]) -> Result<Vec<ProxyKey>, BatchError> {
        for (index, &(center, radius)) in spheres.iter().enumerate() {
            check_sphere(center, radius).map_err(|error| BatchError { index, error })?;
        }
        let room = MAX_PROXIES
            .saturating_sub(self.store.len())
            .min(self.store.available());
        if spheres.len() > room {
            return Err(BatchError {
                index: room,
                error: Error::Full,
            });
        }
        self.reserve(spheres.len(), 0);
        let mut keys = vec![ProxyKey::default(); spheres.len()];
        for i in crate::octree::curve_order(spheres.iter().map(|s| s.0)) {
            let (center, radius) = spheres[i as usize];
            let inserted = self.insert(Shape::Sphere { center, radius }, CollisionGroups::ALL);
            debug_assert!(inserted.is_ok(), "the batch's room was checked");
            if let Ok(key) = inserted {
                keys[i as usize] = key;
            }
        }
        Ok(keys)
    }

    /// [`BroadPhase::insert_sphere`] with collision `groups`: the same checks and errors (on
    /// `Err` nothing changes), and the same as inserting then calling
    /// [`BroadPhase::set_groups`], in one call.
    pub fn insert_sphere_with(
        &mut self,
        center: Vec3,
        radius: f32,
        groups: CollisionGroups,
    ) -> Result<ProxyKey, Error> {
        check_sphere(center, radius)?;
        self.insert(Shape::Sphere { center, radius }, groups)
    }

    /// [`BroadPhase::insert_body`] with collision `groups`: the same checks and errors (on
    /// `Err` nothing changes), and the same as inserting then calling
    /// [`BroadPhase::set_groups`], in one call.
    pub fn insert_body_with(
        &mut self,
        aabb: Aabb,
        kind: BodyKind,
        groups: CollisionGroups,
    ) -> Result<ProxyKey, Error> {
        check_aabb(&aabb)?;
        self.insert(Shape::Body { aabb, kind }, groups)
    }

    /// True if `key` names a live proxy here: false for a stale key (its proxy removed) or a
    /// null one.
    #[must_use]
    pub fn contains(&self, key: ProxyKey) -> bool {
        self.store.resolve(key).is_some()
    }

    fn insert(&mut self, shape: Shape, groups: CollisionGroups) -> Result<ProxyKey, Error> {
        if self.octree.len() + self.dynamic.len() + self.statics.len() >= MAX_PROXIES {
            return Err(Error::Full);
        }
        let slot = self.store.alloc(shape, self.now).ok_or(Error::Full)?;
        if groups != CollisionGroups::ALL {
            self.store.set_group(slot as usize, groups);
            self.any_groups = true;
        }
        self.place(slot);
        Ok(self.store.key(slot))
    }

    /// Puts the new live proxy in `slot` (its shape stored) into its structure under its key,
    /// holding its exact box, or a fat one in the incremental regime, keeps its exact box
    /// where [`regime::Incremental`] says, and marks it for the next step to find its pairs.
    /// [`BroadPhase::insert`] and a snapshot's restore both place proxies here.
    fn place(&mut self, slot: u32) {
        let key = self.store.key(slot);
        self.keep_exact(slot, self.exact_box(&self.store.shape[slot as usize]));
        let held = self.held_shape(slot, glam::Vec3A::ZERO);
        if let Some(r) = &mut self.regime {
            r.held[slot as usize] = held.aabb;
        }
        match self.store.shape[slot as usize] {
            Shape::Sphere { center, .. } => self.octree.insert_checked(key, center, held.radius),
            Shape::Body { kind, .. } => {
                let tree = self.tree_mut(kind);
                tree.insert_checked(key, &held.aabb.aabb());
            }
        }
        self.mark(slot, flag::MOVED | flag::ESCAPED);
    }

    /// The tree of bodies of `kind`, marked changed.
    fn tree_mut(&mut self, kind: BodyKind) -> &mut Bvh {
        match kind {
            BodyKind::Dynamic => {
                self.dynamic_changed = true;
                &mut self.dynamic
            }
            BodyKind::Static => {
                self.statics_changed = true;
                &mut self.statics
            }
        }
    }

    /// Moves or resizes a sphere. `Err(UnknownProxy)` for a stale key, `Err(WrongKind)` for a
    /// body's key, or a geometry error; on `Err` nothing changes. Only the shape is stored
    /// here: the next [`BroadPhase::step`] moves it in the octree, and queries see it at once
    /// (see the crate docs' "Queries", which also say which updates apply themselves).
    #[inline]
    pub fn update_sphere(&mut self, key: ProxyKey, center: Vec3, radius: f32) -> Result<(), Error> {
        self.check_sphere_update(key, center, radius)?;
        self.store_spheres(core::iter::once((key, center, Some(radius))));
        Ok(())
    }

    /// Sets a body's world AABB (its kind stays). `Err(UnknownProxy)` for a stale key,
    /// `Err(WrongKind)` for a sphere's key, or a geometry error; on `Err` nothing changes.
    /// Stored like [`BroadPhase::update_sphere`]'s.
    pub fn update_body(&mut self, key: ProxyKey, aabb: Aabb) -> Result<(), Error> {
        let slot = self.check_body_update(key, &aabb)?;
        self.set_body(slot, &aabb);
        Ok(())
    }

    /// Moves or resizes many spheres at once: `(key, center, radius)` per entry. The whole batch
    /// is checked first; on the first bad entry (non-finite, negative radius, stale key, a
    /// body's key) nothing is applied and the error names the entry. A key given twice is
    /// fine: the last entry wins.
    pub fn update_spheres(&mut self, updates: &[(ProxyKey, Vec3, f32)]) -> Result<(), BatchError> {
        self.first_refused(updates.len(), |bp, i| {
            let (key, center, radius) = updates[i];
            bp.check_sphere_update(key, center, radius)
        })?;
        self.store_spheres(updates.iter().map(|&(k, c, r)| (k, c, Some(r))));
        Ok(())
    }

    /// The stores of a checked batch of live spheres, with the arrays borrowed once: each
    /// entry's centre, and its radius where it gives one (else the sphere keeps its own). In
    /// the incremental regime an update that needs nothing of the step is applied here (see
    /// [`apply::Nudges`]); every other one marks its slot stale.
    #[inline]
    fn store_spheres(
        &mut self,
        entries: impl Iterator<Item = (ProxyKey, Vec3, Option<f32>)> + Clone,
    ) {
        let (st, movers, margin, now) = (
            &mut self.store,
            &mut self.movers,
            self.config.margin,
            self.now,
        );
        let n = st.slots();
        let slots = entries.clone().map(|(k, ..)| crate::pair::slot(k));
        let order = (&mut self.nudge_from, self.nudged);
        let mut nudges = apply::Nudges::plan(&mut self.regime, order, slots, n, now);
        let (shape, flags, stamp) = (&mut st.shape[..n], &mut st.flags[..n], &mut st.stamp[..n]);
        let (mut newly_stale, mut nudged) = (0, self.nudged);
        for (key, center, radius) in entries {
            let slot = crate::pair::slot(key);
            let s = slot as usize;
            let radius = match (radius, shape[s]) {
                (Some(r), _) => r,
                (None, Shape::Sphere { radius, .. }) => radius,
                (None, Shape::Body { .. }) => {
                    debug_assert!(false, "a checked sphere batch names a body");
                    continue;
                }
            };
            write_sphere(&mut shape[s], center, radius);
            let new = || fat::grown_sphere(center, radius, margin).aabb;
            if nudges.take((flags, stamp), s, new, &mut nudged) {
                continue;
            }
            newly_stale += usize::from(mark_stale_in(flags, movers, slot));
        }
        self.stale += newly_stale;
        self.nudged = nudged;
    }

    /// Moves many spheres at once, keeping their radii: `centers[i]` is the new centre of
    /// `keys[i]`, as an engine keeps them in two arrays. Checked whole first like
    /// [`BroadPhase::update_spheres`]: slices of different lengths (`Error::LengthMismatch`,
    /// at the first index only one slice has), a non-finite centre, a stale key or a body's
    /// key refuse the batch, nothing is applied and the error names the entry. A key given
    /// twice is fine: the last entry wins.
    pub fn update_centers(
        &mut self,
        keys: &[ProxyKey],
        centers: &[Vec3],
    ) -> Result<(), BatchError> {
        if keys.len() != centers.len() {
            return Err(BatchError {
                index: keys.len().min(centers.len()),
                error: Error::LengthMismatch {
                    keys: keys.len(),
                    values: centers.len(),
                },
            });
        }
        // A radius of 0 always passes: only the centre is checked.
        self.first_refused(keys.len(), |bp, i| {
            bp.check_sphere_update(keys[i], centers[i], 0.0)
        })?;
        self.store_spheres(keys.iter().zip(centers).map(|(&k, &c)| (k, c, None)));
        Ok(())
    }

    /// Sets many bodies' boxes at once: `(key, aabb)` per entry. The whole batch is checked
    /// first; on the first bad entry (non-finite or inverted box, stale key, a sphere's key)
    /// nothing is applied and the error names the entry. A key given twice is fine: the last
    /// entry wins.
    pub fn update_bodies(&mut self, updates: &[(ProxyKey, Aabb)]) -> Result<(), BatchError> {
        self.first_refused(updates.len(), |bp, i| {
            let (key, aabb) = &updates[i];
            bp.check_body_update(*key, aabb)
        })?;
        for (key, aabb) in updates {
            self.set_body(crate::pair::slot(*key), aabb);
        }
        Ok(())
    }

    /// The first of a batch's `len` entries that `check` refuses, as the batch's error. A
    /// large batch is checked in parts over rayon's current pool (feature `parallel`, more
    /// than one thread), which finds the same entry: the parts are read-only, and the earlier
    /// part's error wins. A worker asleep since the last step also wakes here, where the
    /// caller checks whatever it has not taken, rather than in the step.
    fn first_refused<T>(
        &self,
        len: usize,
        check: impl Fn(&Self, usize) -> Result<T, Error> + Sync,
    ) -> Result<(), BatchError> {
        #[cfg(feature = "parallel")]
        if len >= PARALLEL_MIN_BATCH && rayon::current_num_threads() >= 2 {
            return self.first_refused_par(0..len, &check);
        }
        self.first_refused_in(0..len, &check)
    }

    /// [`BroadPhase::first_refused`] over the entries `range`, in order.
    fn first_refused_in<T>(
        &self,
        range: core::ops::Range<usize>,
        check: &impl Fn(&Self, usize) -> Result<T, Error>,
    ) -> Result<(), BatchError> {
        for index in range {
            check(self, index).map_err(|error| BatchError { index, error })?;
        }
        Ok(())
    }

    /// [`BroadPhase::first_refused_in`] split in halves by `rayon::join` down to parts of at
    /// most [`BATCH_PART`] entries.
    #[cfg(feature = "parallel")]
    fn first_refused_par<T>(
        &self,
        range: core::ops::Range<usize>,
        check: &(impl Fn(&Self, usize) -> Result<T, Error> + Sync),
    ) -> Result<(), BatchError> {
        if range.len() <= BATCH_PART {
            return self.first_refused_in(range, check);
        }
        let mid = range.start + range.len() / 2;
        let (low, high) = rayon::join(
            || self.first_refused_par(range.start..mid, check),
            || self.first_refused_par(mid..range.end, check),
        );
        low.and(high)
    }

    /// The slot of a live sphere, or what [`BroadPhase::update_sphere`] refuses.
    #[inline]
    fn check_sphere_update(&self, key: ProxyKey, center: Vec3, radius: f32) -> Result<u32, Error> {
        check_sphere(center, radius)?;
        let slot = self.store.resolve(key).ok_or(Error::UnknownProxy)?;
        match self.store.kind[slot as usize] {
            Kind::Sphere => Ok(slot),
            _ => Err(Error::WrongKind),
        }
    }

    /// The slot of a live body, or what [`BroadPhase::update_body`] refuses.
    #[inline]
    fn check_body_update(&self, key: ProxyKey, aabb: &Aabb) -> Result<u32, Error> {
        check_aabb(aabb)?;
        let slot = self.store.resolve(key).ok_or(Error::UnknownProxy)?;
        match self.store.kind[slot as usize] {
            Kind::Dynamic | Kind::Static => Ok(slot),
            _ => Err(Error::WrongKind),
        }
    }

    /// Stores a checked body update: its new box (its kind stays), applied at once where that
    /// is all the step would do ([`apply::Nudges`]), else marked stale.
    #[inline]
    fn set_body(&mut self, slot: u32, aabb: &Aabb) {
        let s = slot as usize;
        let shape = &mut self.store.shape[s];
        if let Shape::Body { aabb: a, .. } = shape {
            *a = *aabb;
        }
        let (shape, st, margin) = (*shape, &mut self.store, self.config.margin);
        let order = (&mut self.nudge_from, self.nudged);
        let once = core::iter::once(slot);
        let mut nudges = apply::Nudges::plan(&mut self.regime, order, once, st.slots(), self.now);
        let new = || fat::grown(shape, margin).aabb;
        if nudges.take((&mut st.flags, &mut st.stamp), s, new, &mut self.nudged) {
            return;
        }
        self.mark_stale(slot);
    }

    /// Marks `slot` updated and not yet applied, listing it in `movers` once.
    #[inline]
    fn mark_stale(&mut self, slot: u32) {
        self.stale += usize::from(mark_stale_in(&mut self.store.flags, &mut self.movers, slot));
    }

    /// Removes a proxy; its pairs are reported in `removed` at the next step.
    /// `Err(UnknownProxy)` for a stale key.
    pub fn remove(&mut self, key: ProxyKey) -> Result<(), Error> {
        let slot = self.store.resolve(key).ok_or(Error::UnknownProxy)?;
        let removed = match self.store.shape[slot as usize] {
            Shape::Sphere { .. } => self.octree.remove(key),
            Shape::Body { kind, .. } => self.tree_mut(kind).remove(key),
        };
        debug_assert!(removed.is_ok(), "a live proxy missing from its structure");
        let (f, stamp) = (
            self.store.flags[slot as usize],
            self.store.stamp[slot as usize],
        );
        if f & flag::STALE != 0 {
            self.stale -= 1;
        }
        if self.regime.is_some() && apply::was_nudged(f, stamp, self.now) {
            // Counted once in the step's `updated`, as removed.
            self.nudged -= 1;
        }
        self.store.free(slot);
        self.removals += 1;
        Ok(())
    }

    /// Sets the collision groups of a proxy; the change shows in the next step's lists.
    /// `Err(UnknownProxy)` for a stale key (nothing changes).
    pub fn set_groups(&mut self, key: ProxyKey, groups: CollisionGroups) -> Result<(), Error> {
        let slot = self.store.resolve(key).ok_or(Error::UnknownProxy)?;
        let s = slot as usize;
        if self.store.group(s) == groups {
            return Ok(());
        }
        self.store.set_group(s, groups);
        self.any_groups |= groups != CollisionGroups::ALL;
        // Its candidates were filtered by the old groups: it finds them again, like a proxy
        // that left its fat box.
        self.mark(slot, flag::MOVED | flag::ESCAPED);
        Ok(())
    }

    /// The collision groups of a proxy, or `None` for a stale key.
    #[must_use]
    pub fn groups(&self, key: ProxyKey) -> Option<CollisionGroups> {
        let slot = self.store.resolve(key)?;
        Some(self.store.group(slot as usize))
    }

    /// Number of live proxies.
    #[must_use]
    pub fn len(&self) -> usize {
        self.store.len()
    }

    /// True if there are no proxies.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.store.len() == 0
    }

    /// The proxy's box as given by the user (without the margin), or `None` for a stale key.
    #[must_use]
    pub fn aabb(&self, key: ProxyKey) -> Option<Aabb> {
        self.shape(key).map(|s| s.aabb())
    }

    /// What the proxy is, or `None` for a stale key.
    #[must_use]
    pub fn shape(&self, key: ProxyKey) -> Option<Shape> {
        let slot = self.store.resolve(key)?;
        Some(self.store.shape[slot as usize])
    }

    /// Every live proxy with its shape as the user gave it, in slot order.
    pub fn iter(&self) -> impl Iterator<Item = (ProxyKey, Shape)> + '_ {
        (0..self.store.slots() as u32)
            .filter(|&s| self.store.kind[s as usize] != Kind::Free)
            .map(|s| (self.store.key(s), self.store.shape[s as usize]))
    }

    /// Computes this step's pairs and their difference with the previous step's, then
    /// returns: read them through [`BroadPhase::pairs`], [`BroadPhase::added`] and
    /// [`BroadPhase::removed`], which borrow the broadphase only for reading, so the loop over
    /// them may look proxies up ([`BroadPhase::shape`], [`BroadPhase::groups`]). Steady state
    /// allocates nothing: every list is kept and reused.
    pub fn step(&mut self) {
        // A step that will split its work over rayon's pool runs on the pool as one job: a
        // caller outside the pool then hands it over once (each hand-over wakes a worker and,
        // at its end, the caller), and the split phases inside it (the apply's, the pass's)
        // start on a worker that is already awake.
        #[cfg(feature = "parallel")]
        if self.tasks() >= 2 && self.regime.is_none() {
            rayon::scope(|_| self.step_in());
            return;
        }
        self.step_in();
    }

    /// [`BroadPhase::step`] on the thread it is called on.
    #[inline(always)]
    fn step_in(&mut self) {
        // The updates since the last step reach the structures first, in slot order.
        self.apply_updates();
        // The octree's region follows the spheres: re-rooted here, before any pass or query.
        self.octree.maintain();
        let plan = self.plan();
        self.run(plan);
        // The apply leaves the octree's lists behind for the pass to relink (beside its sort);
        // a step that sorted none relinks them here, so queries see them whole.
        self.octree.flush_relinks();
        self.trim_events();
        self.now = self.now.wrapping_add(1);
    }

    /// Gives back the room of the event lists that a burst left far above their use (the
    /// first step adds every pair at once): each is cut to half again what this step used,
    /// or the room the step keeps ahead for them, once it holds more than twice that. A
    /// list in steady state never comes near that bound, so steps keep allocating nothing.
    fn trim_events(&mut self) {
        let floor = self.store.len() / 8;
        trim(&mut self.added, floor);
        trim(&mut self.removed, floor);
        trim(&mut self.added_packed, floor);
        trim(&mut self.removed_packed, floor);
        #[cfg(feature = "parallel")]
        self.par.trim(trim);
    }

    /// Every pair whose (margin-grown) boxes overlapped at the last [`BroadPhase::step`],
    /// sorted by `(a, b)`; empty before the first step. Operations since that step show only
    /// in the next one.
    #[must_use]
    pub fn pairs(&self) -> &[Pair] {
        &self.pairs
    }

    /// The pairs of the last step's [`BroadPhase::pairs`] that were not in the step's before
    /// it, sorted by `(a, b)`.
    #[must_use]
    pub fn added(&self) -> &[Pair] {
        &self.added
    }

    /// The pairs of the step before the last that are not in the last step's
    /// [`BroadPhase::pairs`] (including every pair of a proxy removed in between), sorted by
    /// `(a, b)`. A removed proxy's key in this list is already stale: [`BroadPhase::shape`]
    /// gives `None` for it.
    #[must_use]
    pub fn removed(&self) -> &[Pair] {
        &self.removed
    }
}

/// Cuts `v`'s room to half again its length (at least `floor`) once it holds more than twice
/// that ([`BroadPhase::trim_events`]).
fn trim<T>(v: &mut Vec<T>, floor: usize) {
    let keep = (v.len() + v.len() / 2).max(floor).max(TRIM_FLOOR);
    if v.capacity() > 2 * keep {
        v.shrink_to(keep);
    }
}

/// The least room [`trim`] leaves a list, in entries: below it a list whose length swings
/// between a few and a few hundred would be cut and grown again.
const TRIM_FLOOR: usize = 256;

/// The most live proxies: the structures index their entries with `u32`.
const MAX_PROXIES: usize = (u32::MAX - 2) as usize;

/// Update batches of at least this many entries are checked in parts over rayon's pool.
#[cfg(feature = "parallel")]
const PARALLEL_MIN_BATCH: usize = 16_384;
/// The most entries of a part of a batch checked over the pool: a smaller part costs about
/// as much to hand out as to check.
#[cfg(feature = "parallel")]
const BATCH_PART: usize = 4096;
