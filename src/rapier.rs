//! rapier3d interop (feature `rapier`): mirror a rapier world into a [`BroadPhase`] and check
//! its pairs against rapier's broad phase and against brute force.
//!
//! # When rapier computes its pairs
//!
//! `PhysicsPipeline::step` (rapier3d 0.36) runs, in this order: the user-change pass (a
//! collider whose parent was moved with `set_position`/`set_translation` gets the parent's pose
//! × its `position_wrt_parent`); **collision detection** (`BroadPhaseBvh::update`, then the
//! narrow phase registers the added/removed pairs); the solver and integration; then the
//! colliders are moved to their new poses and their BVH leaves refitted (`set_aabb`), but the
//! pairs those new poses create or break are only found by the *next* step's `update`. A
//! position-based kinematic body reaches its `set_next_kinematic_*` target during the step,
//! after detection. So when `step` returns, `NarrowPhase::contact_pairs()` describe the poses
//! the bodies had **when `step` was called**, not the poses they have now.
//!
//! Hence the loop: **call [`Mirror::sync`] immediately before `PhysicsPipeline::step`**, then
//! [`Mirror::compare`] (or [`Mirror::step`]) after it and before the next `sync`. Syncing
//! after the step instead compares rapier's pairs of the previous poses with ours of the new
//! ones, and fast objects then show up as pairs rapier "lacks" (see `tests/rapier_parity.rs`).
//!
//! # Why rapier's set contains the exact set
//!
//! rapier's broad-phase box is the shape's AABB loosened by the collider's contact skin plus
//! half the prediction distance (`IntegrationParameters::prediction_distance()`, 0.02 m by
//! default; soft-CCD grows it further towards the predicted pose). The BVH leaf is that box
//! fattened by `0.04 · length_unit` whenever the box leaves the previous leaf, and a pair is
//! dropped only once the two leaves stop overlapping. Every pair of overlapping tight boxes
//! is therefore in rapier's set; rapier's set also holds near misses, so with margin 0 the
//! contract is `exact ⊆ ours ⊆ rapier` with `ours == exact`.
//!
//! rapier filters pairs broadleaf knows nothing about: colliders sharing a parent body,
//! collision groups, and `ActiveCollisionTypes` (fixed×fixed and kinematic×kinematic are off by
//! default). `ours ⊆ rapier` holds for worlds with one collider per body, default groups and
//! `ActiveCollisionTypes::all()` on every collider.

use crate::pair::{self, Pair, ProxyKey};
use crate::scene::{DT, Feed, Frame, GAS_RADIUS, Object, Recorded, Rng, Spawn};
use crate::{Aabb, BodyKind, BroadPhase, Config, Shape, StepPairs, Vec3, brute};
use core::fmt;
use core::time::Duration;
use rapier3d::dynamics::{
    CCDSolver, ImpulseJointSet, IntegrationParameters, IslandManager, MultibodyJointSet,
    RigidBodyBuilder, RigidBodyHandle, RigidBodySet, SoftBodySet,
};
use rapier3d::geometry::{
    ActiveCollisionTypes, Collider, ColliderBuilder, ColliderHandle, ColliderSet,
    DefaultBroadPhase, NarrowPhase,
};
use rapier3d::math::{Pose, Vector};
use rapier3d::pipeline::PhysicsPipeline;
use slotmap::SecondaryMap;

/// What a collider became in the mirror; a change of class re-inserts it under a new key.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Class {
    Sphere,
    Body(BodyKind),
}

impl Class {
    fn of(shape: &Shape) -> Self {
        match *shape {
            Shape::Sphere { .. } => Class::Sphere,
            Shape::Body { kind, .. } => Class::Body(kind),
        }
    }
}

/// One mirrored collider, stored at the collider's arena index.
#[derive(Clone, Copy, Debug)]
struct Entry {
    handle: ColliderHandle,
    key: ProxyKey,
    class: Class,
    /// The `sync` call that last saw the collider.
    stamp: u64,
}

/// Counts of what one [`Mirror::sync`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SyncReport {
    /// Colliders inserted (new, or re-inserted after a change of class or collider slot).
    pub inserted: usize,
    /// Colliders whose sphere or box changed and was pushed.
    pub updated: usize,
    /// Colliders removed (gone from the set, disabled, or replaced in their slot).
    pub removed: usize,
    /// Colliders whose pose or shape gave a non-finite sphere or box: not inserted, or left at
    /// their previous box, as rapier's broad phase does with them.
    pub skipped: usize,
}

/// A [`BroadPhase`] that follows a rapier `ColliderSet`: ball colliders are spheres (world
/// centre, radius), every other collider a body by its world AABB; those bodies are
/// [`BodyKind::Static`] on a fixed parent or without a parent, else [`BodyKind::Dynamic`]
/// (spheres have no kind: a ball on a fixed body is a sphere like any other).
#[derive(Clone, Debug)]
pub struct Mirror {
    broadphase: BroadPhase,
    /// Indexed by the collider handle's arena index.
    slots: Vec<Option<Entry>>,
    handles: SecondaryMap<ProxyKey, ColliderHandle>,
    stamp: u64,
    /// Reused buffer of rapier's mapped pairs.
    rapier: Vec<Pair>,
}

impl Mirror {
    /// An empty mirror whose broadphase uses `config` (corrected as by [`BroadPhase::new`]).
    /// Use margin 0 for the cross-check.
    #[must_use]
    pub fn new(config: Config) -> Self {
        Self {
            broadphase: BroadPhase::new(config),
            slots: Vec::new(),
            handles: SecondaryMap::new(),
            stamp: 0,
            rapier: Vec::new(),
        }
    }

    /// Brings the broadphase up to date with `colliders`: inserts new enabled colliders,
    /// pushes changed spheres and boxes, removes vanished or disabled ones. Each collider's
    /// pose is its parent's current pose × `position_wrt_parent` (its own pose without a
    /// parent): the pose the next `PhysicsPipeline::step` detects collisions at. Call it right
    /// before that step (see the module docs).
    pub fn sync(&mut self, bodies: &RigidBodySet, colliders: &ColliderSet) -> SyncReport {
        self.stamp += 1;
        let mut report = SyncReport::default();
        for (handle, co) in colliders.iter() {
            if !co.is_enabled() {
                continue;
            }
            let shape = world_shape(co, bodies);
            let i = handle.into_raw_parts().0 as usize;
            if self.slots.len() <= i {
                self.slots.resize(i + 1, None);
            }
            if let Some(e) = self.slots[i] {
                if e.handle != handle || e.class != Class::of(&shape) {
                    self.drop_slot(i);
                    report.removed += 1;
                }
            }
            match &mut self.slots[i] {
                Some(e) => {
                    e.stamp = self.stamp;
                    if self.broadphase.shape(e.key) != Some(shape) {
                        let pushed = match shape {
                            Shape::Sphere { center, radius } => {
                                self.broadphase.update_sphere(e.key, center, radius)
                            }
                            Shape::Body { aabb, .. } => self.broadphase.update_body(e.key, aabb),
                        };
                        match pushed {
                            Ok(()) => report.updated += 1,
                            Err(_) => report.skipped += 1,
                        }
                    }
                }
                slot @ None => {
                    let inserted = match shape {
                        Shape::Sphere { center, radius } => {
                            self.broadphase.insert_sphere(center, radius)
                        }
                        Shape::Body { aabb, kind } => self.broadphase.insert_body(aabb, kind),
                    };
                    match inserted {
                        Ok(key) => {
                            *slot = Some(Entry {
                                handle,
                                key,
                                class: Class::of(&shape),
                                stamp: self.stamp,
                            });
                            self.handles.insert(key, handle);
                            report.inserted += 1;
                        }
                        Err(_) => report.skipped += 1,
                    }
                }
            }
        }
        // In index order, so the broadphase's key reuse (and so its pair order) is
        // deterministic.
        for i in 0..self.slots.len() {
            if self.slots[i].is_some_and(|e| e.stamp != self.stamp) {
                self.drop_slot(i);
                report.removed += 1;
            }
        }
        report
    }

    fn drop_slot(&mut self, i: usize) {
        if let Some(e) = self.slots[i].take() {
            self.handles.remove(e.key);
            let removed = self.broadphase.remove(e.key);
            debug_assert!(removed.is_ok(), "a mirrored key is live");
        }
    }

    /// The mirrored broadphase.
    #[must_use]
    pub fn broadphase(&self) -> &BroadPhase {
        &self.broadphase
    }

    /// The broadphase's [`BroadPhase::step`]: this step's pairs and events.
    pub fn step(&mut self) -> StepPairs<'_> {
        self.broadphase.step()
    }

    /// Number of mirrored colliders.
    #[must_use]
    pub fn len(&self) -> usize {
        self.handles.len()
    }

    /// True if no collider is mirrored.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.handles.is_empty()
    }

    /// The key of a mirrored collider; `None` if the collider was not (or no longer) mirrored
    /// at the last `sync`.
    #[must_use]
    pub fn key(&self, handle: ColliderHandle) -> Option<ProxyKey> {
        let e = (*self.slots.get(handle.into_raw_parts().0 as usize)?)?;
        (e.handle == handle).then_some(e.key)
    }

    /// The collider a key mirrors; `None` for a key this mirror does not hold.
    #[must_use]
    pub fn handle(&self, key: ProxyKey) -> Option<ColliderHandle> {
        self.handles.get(key).copied()
    }

    /// rapier's current pairs in our keys, into `out` (cleared, then sorted and deduplicated):
    /// every pair of `narrow_phase.contact_pairs()` and `intersection_pairs()` (sensors),
    /// except pairs of two static bodies, which broadleaf never reports. Returns how many
    /// pairs were left out because a collider is not mirrored (0 when `sync` ran at the
    /// documented point).
    pub fn rapier_pairs(&self, narrow_phase: &NarrowPhase, out: &mut Vec<Pair>) -> usize {
        out.clear();
        let contacts = narrow_phase
            .contact_pairs()
            .map(|p| (p.collider1, p.collider2));
        let sensors = narrow_phase.intersection_pairs().map(|(a, b, _)| (a, b));
        let mut unmapped = 0;
        for (h1, h2) in contacts.chain(sensors) {
            match (self.key(h1), self.key(h2)) {
                (Some(a), Some(b)) if a != b => {
                    if !(self.is_static(a) && self.is_static(b)) {
                        out.push(Pair::new(a, b));
                    }
                }
                _ => unmapped += 1,
            }
        }
        pair::sort_dedup(out);
        unmapped
    }

    fn is_static(&self, key: ProxyKey) -> bool {
        self.broadphase.shape(key).is_some_and(|s| s.is_static())
    }

    /// The brute-force pair set of the mirrored boxes as they are now (grown by the
    /// broadphase's margin; the exact set with margin 0), by [`brute::sweep_pairs`].
    #[must_use]
    pub fn exact_pairs(&self) -> Vec<Pair> {
        let margin = self.broadphase.config().margin;
        let proxies: Vec<brute::Proxy> = self
            .broadphase
            .iter()
            .map(|(key, shape)| brute::Proxy {
                key,
                aabb: shape.grown_aabb(margin),
                is_static: shape.is_static(),
            })
            .collect();
        brute::sweep_pairs(&proxies)
    }

    /// Steps the broadphase and compares its pairs with rapier's current pairs and with brute
    /// force. Call after the `PhysicsPipeline::step` that followed the last `sync`.
    pub fn compare(&mut self, narrow_phase: &NarrowPhase) -> Comparison {
        let mut rapier = core::mem::take(&mut self.rapier);
        let unmapped = self.rapier_pairs(narrow_phase, &mut rapier);
        let exact = self.exact_pairs();
        let ours = self.broadphase.step().pairs;
        let mut cmp = Comparison::new(ours, &rapier, &exact);
        cmp.unmapped = unmapped;
        self.rapier = rapier;
        cmp
    }
}

/// The collider's sphere (ball colliders) or box (every other shape) at the pose the next
/// step detects collisions at, classified static or dynamic by its parent.
fn world_shape(co: &Collider, bodies: &RigidBodySet) -> Shape {
    let (pose, kind) = match co.parent().and_then(|h| bodies.get(h)) {
        Some(rb) => {
            let local = co.position_wrt_parent().copied().unwrap_or(Pose::IDENTITY);
            let kind = if rb.is_fixed() {
                BodyKind::Static
            } else {
                BodyKind::Dynamic
            };
            (*rb.position() * local, kind)
        }
        None => (*co.position(), BodyKind::Static),
    };
    match co.shape().as_ball() {
        // A ball is centred on its collider's origin.
        Some(ball) => Shape::Sphere {
            center: pose.translation,
            radius: ball.radius,
        },
        None => {
            let aabb = co.shape().compute_aabb(&pose);
            Shape::Body {
                aabb: Aabb::new(aabb.mins, aabb.maxs),
                kind,
            }
        }
    }
}

/// The cross-check of one step: our pairs against rapier's and against brute force.
///
/// With margin 0 the contract is `exact ⊆ ours ⊆ rapier` and `ours == exact`:
/// [`Comparison::holds`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Comparison {
    /// Number of our pairs.
    pub ours: usize,
    /// Number of rapier's pairs (mapped to our keys, static×static left out).
    pub rapier: usize,
    /// Number of brute-force pairs.
    pub exact: usize,
    /// Exact pairs that rapier has and we lack: `|(exact ∩ rapier) \ ours|`; must be 0.
    pub missed: usize,
    /// Our pairs that rapier lacks: `|ours \ rapier|`; must be 0 with margin 0.
    pub extra: usize,
    /// Exact pairs rapier lacks: `|exact \ rapier|`. Non-zero means rapier's pairs were not
    /// computed from the same poses (e.g. `sync` called after the rapier step).
    pub rapier_lacks: usize,
    /// rapier pairs naming a collider the mirror does not hold (left out of `rapier`).
    pub unmapped: usize,
    /// True if our pair list equals the brute-force list.
    pub ours_equals_exact: bool,
}

impl Comparison {
    /// Compares three pair sets given as lists of canonical pairs (as `StepPairs::pairs`,
    /// [`brute::sweep_pairs`] and [`Mirror::rapier_pairs`] give them); unsorted or duplicated
    /// lists are sorted and deduplicated on a copy first. `unmapped` is 0.
    #[must_use]
    pub fn new(ours: &[Pair], rapier: &[Pair], exact: &[Pair]) -> Self {
        let ours = canonical(ours);
        let rapier = canonical(rapier);
        let exact = canonical(exact);
        let (ours, rapier, exact) = (&*ours, &*rapier, &*exact);
        let mut in_rapier = Vec::new();
        let mut scratch = Vec::new();
        // `diff(prev, cur, added, removed)`: added = cur \ prev, removed = prev \ cur.
        let mut exact_not_rapier = Vec::new();
        pair::diff(rapier, exact, &mut exact_not_rapier, &mut scratch);
        let mut ours_not_rapier = Vec::new();
        pair::diff(rapier, ours, &mut ours_not_rapier, &mut scratch);
        intersect(exact, rapier, &mut in_rapier);
        let mut missed = Vec::new();
        pair::diff(ours, &in_rapier, &mut missed, &mut scratch);
        Self {
            ours: ours.len(),
            rapier: rapier.len(),
            exact: exact.len(),
            missed: missed.len(),
            extra: ours_not_rapier.len(),
            rapier_lacks: exact_not_rapier.len(),
            unmapped: 0,
            ours_equals_exact: ours == exact,
        }
    }

    /// The margin-0 contract: `ours == exact`, `exact ⊆ ours ⊆ rapier`, nothing unmapped.
    #[must_use]
    pub fn holds(&self) -> bool {
        self.ours_equals_exact
            && self.missed == 0
            && self.extra == 0
            && self.rapier_lacks == 0
            && self.unmapped == 0
    }
}

impl fmt::Display for Comparison {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "ours={} rapier={} exact={} missed={} extra={} rapier_lacks={} unmapped={} ours_equals_exact={}",
            self.ours,
            self.rapier,
            self.exact,
            self.missed,
            self.extra,
            self.rapier_lacks,
            self.unmapped,
            self.ours_equals_exact
        )
    }
}

/// The list itself if sorted and duplicate-free, else a sorted, deduplicated copy.
fn canonical(pairs: &[Pair]) -> std::borrow::Cow<'_, [Pair]> {
    if pairs.windows(2).all(|w| w[0] < w[1]) {
        std::borrow::Cow::Borrowed(pairs)
    } else {
        let mut v = pairs.to_vec();
        pair::sort_dedup(&mut v);
        std::borrow::Cow::Owned(v)
    }
}

/// `a ∩ b` of two sorted, deduplicated lists into `out` (cleared first), by one merge pass.
fn intersect(a: &[Pair], b: &[Pair], out: &mut Vec<Pair>) {
    out.clear();
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        match a[i].cmp(&b[j]) {
            core::cmp::Ordering::Less => i += 1,
            core::cmp::Ordering::Greater => j += 1,
            core::cmp::Ordering::Equal => {
                out.push(a[i]);
                i += 1;
                j += 1;
            }
        }
    }
}

/// Layers of balls the `pile` scene drops; its floor is sized so the pile is about this high.
pub const PILE_LAYERS: usize = 10;

/// Records the `pile` scene with rapier: `n` dynamic balls of radius 0.5 in a jittered grid of
/// [`PILE_LAYERS`] layers (spacing 1.1 m horizontally, 1.25 m vertically) over a fixed floor
/// walled in on four sides, under gravity (−9.81 m/s² on y) with rapier's default parameters;
/// `settle` steps are run unrecorded, then `frames` frames of ball centres are recorded, one per
/// step (frame 0 is the state after settling). Seeded; deterministic for a given rapier build.
#[must_use]
pub fn record_pile(n: usize, seed: u64, settle: usize, frames: usize) -> Recorded {
    let mut rng = Rng::new(seed);
    let cols = (n as f32 / PILE_LAYERS as f32).sqrt().ceil().max(1.0) as usize;
    let spacing = 1.1;
    let half = 0.5 * cols as f32 * spacing + 0.1;
    let height = n.div_ceil(cols * cols) as f32 * 1.25 + 2.0;
    let mut bodies = RigidBodySet::new();
    let mut colliders = ColliderSet::new();
    let mut wall = |c: Vec3, h: Vec3, bodies: &mut RigidBodySet| {
        let body = bodies.insert(RigidBodyBuilder::fixed().translation(c));
        colliders.insert_with_parent(ColliderBuilder::cuboid(h.x, h.y, h.z), body, bodies);
    };
    wall(
        Vec3::new(0.0, -0.5, 0.0),
        Vec3::new(half + 1.0, 0.5, half + 1.0),
        &mut bodies,
    );
    for s in [-1.0f32, 1.0] {
        let (x, z) = (
            Vec3::new(0.5, height, half + 1.0),
            Vec3::new(half + 1.0, height, 0.5),
        );
        wall(Vec3::new(s * (half + 0.5), height, 0.0), x, &mut bodies);
        wall(Vec3::new(0.0, height, s * (half + 0.5)), z, &mut bodies);
    }
    let r = GAS_RADIUS;
    let balls: Vec<RigidBodyHandle> = (0..n)
        .map(|i| {
            let (layer, cell) = (i / (cols * cols), i % (cols * cols));
            let jitter = rng.vec3_in(Vec3::splat(-0.04), Vec3::splat(0.04));
            let c = Vec3::new(
                -half + 0.1 + spacing * (cell / cols) as f32 + 0.55,
                1.0 + 1.25 * layer as f32,
                -half + 0.1 + spacing * (cell % cols) as f32 + 0.55,
            ) + jitter;
            let body = bodies.insert(RigidBodyBuilder::dynamic().translation(c));
            colliders.insert_with_parent(ColliderBuilder::ball(r), body, &mut bodies);
            body
        })
        .collect();
    let mut pipeline = PhysicsPipeline::new();
    let params = IntegrationParameters::default();
    let (mut islands, mut broad_phase) = (IslandManager::new(), DefaultBroadPhase::new());
    let (mut narrow_phase, mut ccd) = (NarrowPhase::new(), CCDSolver::new());
    let (mut impulse_joints, mut multibody_joints) =
        (ImpulseJointSet::new(), MultibodyJointSet::new());
    let mut soft_bodies = SoftBodySet::new();
    let mut recorded = Vec::with_capacity(frames);
    for step in 0..settle + frames {
        if step >= settle {
            recorded.push(balls.iter().map(|&h| bodies[h].translation()).collect());
        }
        if step + 1 < settle + frames {
            pipeline.step(
                Vector::new(0.0, -9.81, 0.0),
                &params,
                &mut islands,
                &mut broad_phase,
                &mut narrow_phase,
                &mut bodies,
                &mut colliders,
                &mut impulse_joints,
                &mut multibody_joints,
                &mut soft_bodies,
                &mut ccd,
                &(),
                &(),
            );
        }
    }
    let bounds = Aabb::new(
        Vec3::new(-half, 0.0, -half),
        Vec3::new(half, 2.0 * height, half),
    );
    Recorded::new(bounds, r, recorded)
}

/// A [`Scene`](crate::scene::Scene) played in rapier: kinematic position-based bodies (fixed
/// ones for static objects), one collider each with `ActiveCollisionTypes::all()`, driven by
/// the scene's frames. Each collider's `user_data` is its scene id. Used by `vs_rapier` and the
/// benches to time rapier's broad phase on exactly the motion broadleaf sees.
///
/// Per frame: [`SceneWorld::set_targets`], [`SceneWorld::step`] (whose pairs are those of the
/// poses *before* the targets, see the module docs), then [`SceneWorld::apply_structure`].
pub struct SceneWorld {
    pipeline: PhysicsPipeline,
    params: IntegrationParameters,
    islands: IslandManager,
    broad_phase: DefaultBroadPhase,
    narrow_phase: NarrowPhase,
    bodies: RigidBodySet,
    colliders: ColliderSet,
    impulse_joints: ImpulseJointSet,
    multibody_joints: MultibodyJointSet,
    soft_bodies: SoftBodySet,
    ccd: CCDSolver,
    handles: Vec<Option<RigidBodyHandle>>,
}

impl SceneWorld {
    /// An empty world stepping at [`DT`], gravity off.
    #[must_use]
    pub fn new() -> Self {
        SceneWorld {
            pipeline: PhysicsPipeline::new(),
            params: IntegrationParameters {
                dt: DT,
                ..IntegrationParameters::default()
            },
            islands: IslandManager::new(),
            broad_phase: DefaultBroadPhase::new(),
            narrow_phase: NarrowPhase::new(),
            bodies: RigidBodySet::new(),
            colliders: ColliderSet::new(),
            impulse_joints: ImpulseJointSet::new(),
            multibody_joints: MultibodyJointSet::new(),
            soft_bodies: SoftBodySet::new(),
            ccd: CCDSolver::new(),
            handles: Vec::new(),
        }
    }

    /// Adds one scene object as a body with one collider.
    pub fn insert(&mut self, s: &Spawn) {
        let (pose, collider) = match s.object {
            Object::Sphere { center, radius } => (
                Pose::from_translation(center),
                ColliderBuilder::ball(radius),
            ),
            Object::Cuboid {
                center,
                half_extents: h,
                rotation,
            } => (
                Pose::from_parts(center, rotation),
                ColliderBuilder::cuboid(h.x, h.y, h.z),
            ),
        };
        let body = if s.is_static {
            RigidBodyBuilder::fixed()
        } else {
            RigidBodyBuilder::kinematic_position_based()
        };
        let h = self.bodies.insert(body.pose(pose));
        let collider = collider
            .active_collision_types(ActiveCollisionTypes::all())
            .user_data(u128::from(s.id));
        self.colliders
            .insert_with_parent(collider, h, &mut self.bodies);
        let id = s.id as usize;
        if self.handles.len() <= id {
            self.handles.resize(id + 1, None);
        }
        self.handles[id] = Some(h);
    }

    /// Sets every moved body's kinematic target.
    pub fn set_targets(&mut self, f: &Frame) {
        for &(id, o) in &f.moved {
            if let Some(&Some(h)) = self.handles.get(id as usize) {
                self.bodies[h].set_next_kinematic_translation(o.center());
            }
        }
    }

    /// Applies a frame's removes and inserts (after the step that detected the frame before).
    pub fn apply_structure(&mut self, f: &Frame) {
        for &id in &f.removed {
            if let Some(h) = self.handles.get_mut(id as usize).and_then(Option::take) {
                self.bodies.remove(
                    h,
                    &mut self.islands,
                    &mut self.colliders,
                    &mut self.impulse_joints,
                    &mut self.multibody_joints,
                    &mut self.soft_bodies,
                    true,
                );
            }
        }
        for s in &f.inserted {
            self.insert(s);
        }
    }

    /// One `PhysicsPipeline::step`; returns its broad-phase time (rapier's `profiler`
    /// counters: the broad-phase update plus the end-of-step tree refit).
    pub fn step(&mut self) -> Duration {
        self.pipeline.step(
            Vector::ZERO,
            &self.params,
            &mut self.islands,
            &mut self.broad_phase,
            &mut self.narrow_phase,
            &mut self.bodies,
            &mut self.colliders,
            &mut self.impulse_joints,
            &mut self.multibody_joints,
            &mut self.soft_bodies,
            &mut self.ccd,
            &(),
            &(),
        );
        let cd = &self.pipeline.counters.cd;
        cd.broad_phase_time.time() + cd.final_broad_phase_time.time()
    }

    /// rapier's pairs in broadleaf's keys, static×static left out, sorted; and how many pairs
    /// named an object broadleaf does not hold.
    pub fn pairs(&self, feed: &Feed) -> (Vec<Pair>, usize) {
        let mut out = Vec::new();
        let mut unmapped = 0;
        for cp in self.narrow_phase.contact_pairs() {
            let key_of = |h: ColliderHandle| {
                let co = self.colliders.get(h)?;
                let key = feed.key(u32::try_from(co.user_data).ok()?)?;
                let fixed = co
                    .parent()
                    .and_then(|p| self.bodies.get(p))
                    .is_none_or(|rb| rb.is_fixed());
                Some((key, fixed))
            };
            match (key_of(cp.collider1), key_of(cp.collider2)) {
                (Some((a, fa)), Some((b, fb))) => {
                    if !(fa && fb) {
                        out.push(Pair::new(a, b));
                    }
                }
                _ => unmapped += 1,
            }
        }
        pair::sort_dedup(&mut out);
        (out, unmapped)
    }
}

impl Default for SceneWorld {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use slotmap::SlotMap;

    #[test]
    fn comparison_counts_each_set_difference() {
        let mut sm = SlotMap::<ProxyKey, ()>::with_key();
        let k: Vec<ProxyKey> = (0..6).map(|_| sm.insert(())).collect();
        let p = |i: usize, j: usize| Pair::new(k[i], k[j]);
        let exact = [p(0, 1), p(1, 2), p(2, 3)];
        // We lack (2,3), which rapier has: missed. We add (4,5), which rapier lacks: extra.
        let ours = [p(0, 1), p(1, 2), p(4, 5)];
        // rapier lacks (1,2) (an exact pair) and has a near miss (0,5).
        let rapier = [p(0, 1), p(2, 3), p(0, 5)];
        let c = Comparison::new(&ours, &rapier, &exact);
        assert_eq!((c.ours, c.rapier, c.exact), (3, 3, 3));
        assert_eq!((c.missed, c.extra, c.rapier_lacks), (1, 2, 1));
        assert!(!c.ours_equals_exact && !c.holds());

        let ok = Comparison::new(&exact, &[p(0, 1), p(0, 5), p(1, 2), p(2, 3)], &exact);
        assert!(ok.holds(), "{ok}");
        // Unsorted input with a duplicate gives the same answer.
        let shuffled = [p(2, 3), p(0, 1), p(2, 3), p(1, 2)];
        assert_eq!(
            Comparison::new(&shuffled, &[p(0, 1), p(0, 5), p(1, 2), p(2, 3)], &exact),
            ok
        );
    }
}
