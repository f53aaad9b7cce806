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
//! rapier filters pairs broadleaf knows nothing about: colliders sharing a parent body and
//! `ActiveCollisionTypes` (fixed×fixed and kinematic×kinematic are off by default).
//! `ours ⊆ rapier` holds for worlds with one collider per body and
//! `ActiveCollisionTypes::all()` on every collider, whatever their collision groups.
//!
//! # Collision groups
//!
//! Each collider's `collision_groups()` is copied into the broadphase
//! ([`BroadPhase::set_groups`]) when it is inserted and whenever `sync` sees them changed:
//! `memberships` and `filter` bit for bit (`Group::bits`). rapier 0.36 filters a pair by
//! `InteractionGroups::test`, which is broadleaf's rule
//! (`a.memberships & b.filter != 0 && b.memberships & a.filter != 0`,
//! `InteractionTestMode::And`, the default) unless **both** colliders use
//! `InteractionTestMode::Or`; then either half of the rule suffices (its broad phase already
//! creates no pair that `test` rejects). broadleaf has only the
//! `And` rule, and the mirror applies it to every pair: an `Or`-mode collider is approximated
//! by `And` (counted in [`SyncReport::or_mode`]). The approximation only drops pairs: the
//! mirror may lack an `Or`×`Or` pair that rapier keeps because one half of the rule holds, and
//! never reports a pair rapier filters, so `ours ⊆ rapier` still holds. [`Mirror::exact_pairs`]
//! applies the same rule, from the mirror's own record of each collider's groups.

use crate::pair::{self, Pair, ProxyKey};
use crate::{Aabb, BodyKind, BroadPhase, CollisionGroups, Config, Shape, Vec3, brute};
use core::fmt;
use rapier3d::dynamics::RigidBodySet;
use rapier3d::geometry::{Collider, ColliderHandle, ColliderSet, InteractionTestMode, NarrowPhase};
use rapier3d::math::Pose;
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
    /// The sphere or box the broadphase was last given for this collider (and accepted): the
    /// mirror's own record, from which [`Mirror::exact_pairs`] builds the reference.
    shape: Shape,
    /// The collider's collision groups as the broadphase was last given them.
    groups: CollisionGroups,
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
    /// Mirrored colliders whose collision groups changed and were pushed (not counting
    /// inserts).
    pub regrouped: usize,
    /// Mirrored colliders whose collision groups use `InteractionTestMode::Or`, which the
    /// mirror filters by the `And` rule (see the module docs).
    pub or_mode: usize,
}

/// A [`BroadPhase`] that follows a rapier `ColliderSet`: ball colliders are spheres (world
/// centre, radius), every other collider a body by its world AABB; those bodies are
/// [`BodyKind::Static`] on a fixed parent or without a parent, else [`BodyKind::Dynamic`]
/// (spheres have no kind: a ball on a fixed body is a sphere like any other). Each proxy has
/// its collider's collision groups (see the module docs for `InteractionTestMode::Or`).
#[derive(Clone, Debug)]
pub struct Mirror {
    broadphase: BroadPhase,
    /// Indexed by the collider handle's arena index.
    slots: Vec<Option<Entry>>,
    handles: SecondaryMap<ProxyKey, ColliderHandle>,
    stamp: u64,
    /// Reused buffer of rapier's mapped pairs.
    rapier: Vec<Pair>,
    /// Reused buffer of the new ball colliders of a `sync`, inserted as one batch.
    new_balls: Vec<NewBall>,
}

/// A new ball collider of a [`Mirror::sync`], inserted with the others after its loop.
#[derive(Clone, Copy, Debug)]
struct NewBall {
    /// The collider handle's arena index.
    index: usize,
    handle: ColliderHandle,
    center: Vec3,
    radius: f32,
    groups: CollisionGroups,
    or_mode: bool,
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
            new_balls: Vec::new(),
        }
    }

    /// Brings the broadphase up to date with `colliders`: inserts new enabled colliders with
    /// their collision groups, pushes changed spheres, boxes and groups, removes vanished or
    /// disabled ones. Each collider's
    /// pose is its parent's current pose × `position_wrt_parent` (its own pose without a
    /// parent): the pose the next `PhysicsPipeline::step` detects collisions at. Call it right
    /// before that step (see the module docs). The new ball colliders go in as one
    /// [`BroadPhase::insert_spheres`] batch, numbered by place.
    pub fn sync(&mut self, bodies: &RigidBodySet, colliders: &ColliderSet) -> SyncReport {
        self.stamp += 1;
        let mut report = SyncReport::default();
        self.new_balls.clear();
        for (handle, co) in colliders.iter() {
            if !co.is_enabled() {
                continue;
            }
            let shape = world_shape(co, bodies);
            let groups = collision_groups(co);
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
                    if e.shape != shape {
                        let pushed = match shape {
                            Shape::Sphere { center, radius } => {
                                self.broadphase.update_sphere(e.key, center, radius)
                            }
                            Shape::Body { aabb, .. } => self.broadphase.update_body(e.key, aabb),
                        };
                        match pushed {
                            Ok(()) => {
                                e.shape = shape;
                                report.updated += 1;
                            }
                            Err(_) => report.skipped += 1,
                        }
                    }
                    if e.groups != groups {
                        let set = self.broadphase.set_groups(e.key, groups);
                        debug_assert!(set.is_ok(), "a mirrored key is live");
                        e.groups = groups;
                        report.regrouped += 1;
                    }
                }
                None => match shape {
                    Shape::Sphere { center, radius } => {
                        if crate::geom::check_sphere(center, radius).is_ok() {
                            self.new_balls.push(NewBall {
                                index: i,
                                handle,
                                center,
                                radius,
                                groups,
                                or_mode: co.collision_groups().test_mode == InteractionTestMode::Or,
                            });
                        } else {
                            report.skipped += 1;
                        }
                    }
                    Shape::Body { aabb, kind } => match self.broadphase.insert_body(aabb, kind) {
                        Ok(key) => self.keep(i, handle, key, shape, groups, &mut report),
                        Err(_) => report.skipped += 1,
                    },
                },
            }
            if self.slots[i].is_some() && co.collision_groups().test_mode == InteractionTestMode::Or
            {
                report.or_mode += 1;
            }
        }
        self.insert_new_balls(&mut report);
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

    /// Inserts the new ball colliders `sync` listed (finite, checked) in one batch.
    fn insert_new_balls(&mut self, report: &mut SyncReport) {
        if self.new_balls.is_empty() {
            return;
        }
        let batch: Vec<(Vec3, f32)> = self
            .new_balls
            .iter()
            .map(|b| (b.center, b.radius))
            .collect();
        let Ok(keys) = self.broadphase.insert_spheres(&batch) else {
            // Only a broadphase that is full refuses a checked batch.
            report.skipped += batch.len();
            return;
        };
        let balls = core::mem::take(&mut self.new_balls);
        for (b, key) in balls.iter().zip(keys) {
            let shape = Shape::Sphere {
                center: b.center,
                radius: b.radius,
            };
            self.keep(b.index, b.handle, key, shape, b.groups, report);
            report.or_mode += usize::from(b.or_mode);
        }
        self.new_balls = balls;
    }

    /// Mirrors the collider `handle` (arena index `i`) just inserted as `key`.
    fn keep(
        &mut self,
        i: usize,
        handle: ColliderHandle,
        key: ProxyKey,
        shape: Shape,
        groups: CollisionGroups,
        report: &mut SyncReport,
    ) {
        let set = self.broadphase.set_groups(key, groups);
        debug_assert!(set.is_ok(), "a key just inserted is live");
        self.slots[i] = Some(Entry {
            handle,
            key,
            class: Class::of(&shape),
            shape,
            groups,
            stamp: self.stamp,
        });
        self.handles.insert(key, handle);
        report.inserted += 1;
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

    /// The broadphase's [`BroadPhase::step`]; its lists are then read through
    /// [`Mirror::broadphase`].
    pub fn step(&mut self) {
        self.broadphase.step();
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

    /// True for a key this mirror holds as a static body.
    fn is_static(&self, key: ProxyKey) -> bool {
        self.entry(key)
            .is_some_and(|e| e.class == Class::Body(BodyKind::Static))
    }

    /// The collision groups the mirror gave the broadphase for a key it holds (its copy of
    /// the collider's groups at the last `sync`); `None` for a key this mirror does not hold.
    #[must_use]
    pub fn groups(&self, key: ProxyKey) -> Option<CollisionGroups> {
        self.entry(key).map(|e| e.groups)
    }

    fn entry(&self, key: ProxyKey) -> Option<Entry> {
        let h = self.handles.get(key)?;
        let e = (*self.slots.get(h.into_raw_parts().0 as usize)?)?;
        (e.key == key).then_some(e)
    }

    /// The brute-force pair set of the mirrored colliders as the last `sync` gave them to the
    /// broadphase, from the mirror's own record of each sphere, box and collision groups (not
    /// from the broadphase): boxes grown by the configured margin (the exact set with margin
    /// 0), paired by [`brute::sweep_pairs`], then the pairs whose groups do not allow them
    /// ([`CollisionGroups::allows`]) left out.
    #[must_use]
    pub fn exact_pairs(&self) -> Vec<Pair> {
        let margin = self.broadphase.config().margin;
        let entries = self.slots.iter().flatten();
        let proxies: Vec<brute::Proxy> = entries
            .clone()
            .map(|e| brute::Proxy {
                key: e.key,
                aabb: pair_box(&e.shape, margin),
                is_static: e.class == Class::Body(BodyKind::Static),
            })
            .collect();
        let mut pairs = brute::sweep_pairs(&proxies);
        if entries.clone().any(|e| e.groups != CollisionGroups::ALL) {
            let groups: SecondaryMap<ProxyKey, CollisionGroups> =
                entries.map(|e| (e.key, e.groups)).collect();
            pairs.retain(|p| groups[p.a].allows(groups[p.b]));
        }
        pairs
    }

    /// Steps the broadphase and compares its pairs with rapier's current pairs and with brute
    /// force. Call after the `PhysicsPipeline::step` that followed the last `sync`.
    pub fn compare(&mut self, narrow_phase: &NarrowPhase) -> Comparison {
        let mut rapier = core::mem::take(&mut self.rapier);
        let unmapped = self.rapier_pairs(narrow_phase, &mut rapier);
        let exact = self.exact_pairs();
        self.broadphase.step();
        let ours = self.broadphase.pairs();
        let mut cmp = Comparison::new(ours, &rapier, &exact);
        cmp.unmapped = unmapped;
        self.rapier = rapier;
        cmp
    }
}

/// The box `shape` pairs with, by the contract's pair semantics: a sphere's
/// `center ± (radius + margin)`, a body's box grown by `margin` on every side with faces that
/// overflow kept at `±f32::MAX`.
fn pair_box(shape: &Shape, margin: f32) -> Aabb {
    match *shape {
        Shape::Sphere { center, radius } => {
            let r = Vec3::splat(radius + margin);
            Aabb::new(center - r, center + r)
        }
        Shape::Body { aabb, .. } => {
            let m = Vec3::splat(margin);
            Aabb::new(
                (aabb.min - m).max(Vec3::splat(-f32::MAX)),
                (aabb.max + m).min(Vec3::splat(f32::MAX)),
            )
        }
    }
}

/// The collider's collision groups in broadleaf's terms: the same bits (the test mode is
/// dropped, see the module docs).
fn collision_groups(co: &Collider) -> CollisionGroups {
    let g = co.collision_groups();
    CollisionGroups {
        memberships: g.memberships.bits(),
        filter: g.filter.bits(),
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
    /// Compares three pair sets given as lists of canonical pairs (as [`BroadPhase::pairs`],
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

#[cfg(test)]
mod tests {
    use super::*;
    use slotmap::SlotMap;

    /// A sync's new balls go in as one batch, numbered along the curve through their centres;
    /// a ball at a NaN position is skipped alone; a later sync inserts only what is new.
    #[test]
    fn new_balls_are_inserted_as_one_batch() {
        use rapier3d::geometry::ColliderBuilder;
        let bodies = RigidBodySet::new();
        let mut colliders = ColliderSet::new();
        let mut rng = crate::rng::Rng::new(3);
        let mut centers = Vec::new();
        for _ in 0..300 {
            let c = rng.vec3_in(Vec3::splat(-20.0), Vec3::splat(20.0));
            centers.push(c);
            colliders.insert(ColliderBuilder::ball(0.5).translation(c).build());
        }
        colliders.insert(ColliderBuilder::ball(0.5).translation(Vec3::NAN).build());
        colliders.insert(ColliderBuilder::cuboid(1.0, 1.0, 1.0).build());
        let mut mirror = Mirror::new(Config::default());
        let report = mirror.sync(&bodies, &colliders);
        assert_eq!((report.inserted, report.skipped), (301, 1), "{report:?}");
        // The balls' slots, in slot order, follow the curve through the centres in the
        // order the set gave them.
        let mut balls: Vec<(u32, Vec3)> = mirror
            .slots
            .iter()
            .flatten()
            .filter_map(|e| match e.shape {
                Shape::Sphere { center, .. } => Some((pair::slot(e.key), center)),
                Shape::Body { .. } => None,
            })
            .collect();
        balls.sort_unstable_by_key(|b| b.0);
        let order = crate::octree::curve_order(centers.iter().copied());
        let along: Vec<Vec3> = order.iter().map(|&i| centers[i as usize]).collect();
        let got: Vec<Vec3> = balls.iter().map(|b| b.1).collect();
        assert_eq!(got, along);
        assert_eq!(mirror.sync(&bodies, &colliders).inserted, 0);
        colliders.insert(ColliderBuilder::ball(0.5).translation(Vec3::ZERO).build());
        let report = mirror.sync(&bodies, &colliders);
        assert_eq!((report.inserted, report.skipped), (1, 1), "{report:?}");
    }

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
