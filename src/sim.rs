//! A small, honest physics loop that drives [`BroadPhase`] the way an engine does: spheres
//! falling under gravity into static boxes, contacts from the broadphase pairs, sequential
//! impulses with restitution and Coulomb friction, and split-impulse position correction.
//!
//! # One step, in order
//! 1. **Gravity** (semi-implicit Euler): `v += g·dt`. Positions move last, with the solved
//!    velocities.
//! 2. **Broadphase update**: each sphere is handed to the broadphase at its current centre with
//!    its radius grown by `|v|·dt + speculative_margin` — the ball that holds the whole sphere
//!    wherever it goes this step at its current speed. The container's boxes are static bodies
//!    of the same broadphase, so sphere–wall pairs come from it too. Then
//!    [`BroadPhase::step`] gives the sorted pair list.
//! 3. **Narrow phase** on every pair, in the broadphase's sorted order: sphere–sphere and
//!    sphere–box (closest point on the box; nearest face when the centre is inside). A pair
//!    becomes a contact when its gap is at most the two growths, i.e. when the spheres could
//!    touch within this step. Such *speculative* contacts (Catto, GDC 2013) are what stops a
//!    fast sphere at a wall instead of letting it step through: the solver lets a contact with
//!    gap `s > 0` approach by at most `s/dt`.
//! 4. **Velocity solve**: sequential impulses over `velocity_iterations` passes, warm-started
//!    from the previous step's impulses of the same pair, rolling resistance and friction
//!    (clamped to the cone `μ·λn`) before the normal impulse. Restitution is part of the
//!    normal target, so every pass sees it together with the other contacts (a bounce
//!    applied after the solve would drive spheres into their neighbours): an impact faster
//!    than `restitution_threshold` that closes its gap within the step aims for the
//!    separating speed `e·|v_approach|`. A speculative contact thus bounces up to one step's
//!    travel before it touches: the price of never tunnelling.
//! 5. **Position correction** by split impulses: a separate pseudo-velocity removes
//!    `position_correction` of the penetration beyond `slop` per step and is thrown away after
//!    the position update, so correcting overlap never adds kinetic energy (Baumgarte in the
//!    real velocity would).
//! 6. **Integrate positions**: `x += (v + v_pseudo)·dt`.
//!
//! The growth uses the speed before the solve; a sphere that the solve speeds up (a hard push
//! from behind) can travel further than its grown box and overlap a sphere it had no contact
//! with. That overlap is found at the next step and removed by the position correction; the
//! stats' `max_penetration` shows how deep it got.
//!
//! Spheres are solid balls that spin (`I = 2/5·m·r²`; orientation itself is not tracked, a
//! sphere looks the same however it turned): friction acts at the contact point and makes
//! them roll, and a rolling resistance (an angular impulse bounded by the normal impulse
//! times a lever arm) lets a pile come to rest instead of rolling apart forever. Nothing is
//! clamped: a sphere is never moved except by its velocity and its pseudo-velocity.
//!
//! # Determinism
//! Pairs are processed in the broadphase's sorted order, contacts are kept in that order, and
//! warm-start impulses are matched by a merge of two sorted lists (no hash map is iterated), so
//! the same inputs give bit-identical positions on every run.

use crate::geom::{check_aabb, check_sphere};
use crate::octree::MAX_DEPTH;
use crate::scene::Rng;
use crate::{Aabb, BodyKind, BroadPhase, Config, Error, Pair, ProxyKey, Vec3};
use slotmap::SecondaryMap;
use std::time::{Duration, Instant};

/// Which structure of the broadphase holds the spheres.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum IndexKind {
    /// Spheres go to the octree ([`BroadPhase::insert_sphere`]).
    #[default]
    Octree,
    /// Spheres go to the dynamic BVH as boxes ([`BroadPhase::insert_body`] with
    /// [`BodyKind::Dynamic`]).
    Bvh,
}

/// Surface properties of a sphere or a box. A contact uses the larger restitution and the
/// geometric means of the two frictions and of the two rolling resistances.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    /// Coefficient of restitution, `0..=1`: the fraction of the approach speed kept as
    /// separating speed in an impact.
    pub restitution: f32,
    /// Coulomb friction coefficient, finite and `>= 0`.
    pub friction: f32,
    /// Rolling resistance, finite and `>= 0`: a contact resists the relative spin of its two
    /// sides with an angular impulse of at most `rolling_resistance · r · λn` (r the contact's
    /// reduced radius, λn its normal impulse), the lever arm of a slightly flattened contact.
    pub rolling_resistance: f32,
}

impl Default for Material {
    /// Restitution 0.3, friction 0.5, rolling resistance 0.05.
    fn default() -> Self {
        Self {
            restitution: 0.3,
            friction: 0.5,
            rolling_resistance: 0.05,
        }
    }
}

impl Material {
    fn validate(&self) -> Result<(), Error> {
        if !(0.0..=1.0).contains(&self.restitution) {
            return Err(Error::InvalidConfig {
                what: "restitution",
                value: self.restitution,
            });
        }
        for (what, value) in [
            ("friction", self.friction),
            ("rolling_resistance", self.rolling_resistance),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(Error::InvalidConfig { what, value });
            }
        }
        Ok(())
    }
}

/// Settings of a [`World`]. Lengths are in metres, speeds in m/s.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldConfig {
    /// Gravitational acceleration in m/s²; finite.
    pub gravity: Vec3,
    /// Sequential-impulse passes over all contacts per step, `>= 1`.
    pub velocity_iterations: u32,
    /// Split-impulse passes for position correction per step, `>= 0` (0 disables correction).
    pub position_iterations: u32,
    /// Impacts slower than this (m/s) do not bounce, so resting contacts stay at rest; `>= 0`.
    pub restitution_threshold: f32,
    /// Penetration (m) left uncorrected, so resting contacts keep touching; `>= 0`.
    pub slop: f32,
    /// Fraction of the penetration beyond `slop` removed per step, `0..=1`.
    pub position_correction: f32,
    /// Cap on the correcting pseudo-speed in m/s; finite, `>= 0`.
    pub max_correction_speed: f32,
    /// Extra growth (m) of every sphere's broadphase radius beyond `|v|·dt`, so contacts are
    /// found slightly before they are needed; finite, `>= 0`.
    pub speculative_margin: f32,
    /// Start each step's solve from the previous step's impulses of the same pair.
    pub warm_start: bool,
    /// Which broadphase structure holds the spheres.
    pub index: IndexKind,
    /// The broadphase settings (bounds, octree depth). Keep `margin` at 0: the world grows the
    /// spheres itself, by their speed.
    pub broadphase: Config,
}

impl Default for WorldConfig {
    /// Earth gravity along −y, 8 velocity and 3 position iterations, restitution threshold
    /// 1 m/s, slop 5 mm, 20 % correction per step capped at 2 m/s, speculative margin 2 cm,
    /// warm starting on, octree index, default broadphase config: tuned for spheres of about
    /// 0.5 m (see [`DropConfig::new`] for settings scaled to a radius).
    fn default() -> Self {
        Self {
            gravity: Vec3::new(0.0, -9.81, 0.0),
            velocity_iterations: 8,
            position_iterations: 3,
            restitution_threshold: 1.0,
            slop: 0.005,
            position_correction: 0.2,
            max_correction_speed: 2.0,
            speculative_margin: 0.02,
            warm_start: true,
            index: IndexKind::Octree,
            broadphase: Config::default(),
        }
    }
}

impl WorldConfig {
    /// `Ok` if every field is in its documented range, else the first offending field.
    pub fn validate(&self) -> Result<(), Error> {
        if !self.gravity.is_finite() {
            return Err(Error::NonFinite {
                what: "gravity",
                value: self.gravity,
            });
        }
        let bad = |what, value: f32| Err(Error::InvalidConfig { what, value });
        if self.velocity_iterations == 0 {
            return bad("velocity_iterations", 0.0);
        }
        let nonneg = [
            ("restitution_threshold", self.restitution_threshold),
            ("slop", self.slop),
            ("max_correction_speed", self.max_correction_speed),
            ("speculative_margin", self.speculative_margin),
        ];
        for (what, value) in nonneg {
            if !(value.is_finite() && value >= 0.0) {
                return bad(what, value);
            }
        }
        if !(0.0..=1.0).contains(&self.position_correction) {
            return bad("position_correction", self.position_correction);
        }
        self.broadphase.validate()
    }
}

/// What one [`World::step`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepStats {
    /// Pairs the broadphase reported (sphere–sphere and sphere–box).
    pub pairs: usize,
    /// Pairs close enough to touch within the step: the contacts handed to the solver,
    /// speculative ones included.
    pub contacts: usize,
    /// Contacts whose spheres overlapped (gap `<= 0`) at the start of the step.
    pub touching: usize,
    /// Wall time of the broadphase: the proxy updates plus [`BroadPhase::step`].
    pub broadphase_time: Duration,
    /// Wall time of the whole step.
    pub total_time: Duration,
    /// `Σ ½·m·|v|² + ½·I·|ω|²` after the step, in joules.
    pub kinetic_energy: f64,
    /// The deepest overlap among this step's contacts at the start of the step (the narrow
    /// phase's view), in metres; 0 when nothing overlaps.
    pub max_penetration: f32,
}

/// The index of a proxy's owner in the world's arrays.
#[derive(Clone, Copy, Debug)]
enum Owner {
    Sphere(u32),
    Box(u32),
}

/// "No sphere": the other side of a sphere–box contact.
const NONE: u32 = u32::MAX;

/// One contact point between sphere `i` and sphere `j` (or a static box when `j == NONE`).
#[derive(Clone, Copy, Debug)]
struct Contact {
    pair: Pair,
    i: u32,
    j: u32,
    /// Unit normal from `j` (or the box) towards `i`.
    normal: Vec3,
    /// Gap along the normal at the start of the step; negative when overlapping.
    separation: f32,
    /// Radius of `i`, and of `j` (0 for a box): the lever arms of the tangent impulse.
    radius_i: f32,
    radius_j: f32,
    /// `1 / (1/m_i + 1/m_j)`: the normal impulse does not spin a sphere.
    normal_mass: f32,
    /// `1 / (1/m_i + r_i²/I_i + 1/m_j + r_j²/I_j)`, the same along every tangent of a sphere.
    tangent_mass: f32,
    /// `1 / (1/I_i + 1/I_j)`.
    rolling_mass: f32,
    friction: f32,
    /// `rolling_resistance · reduced radius`: the rolling impulse limit per unit normal impulse.
    rolling_arm: f32,
    restitution: f32,
    /// The normal relative velocity the solve aims for (see `World::prepare`).
    target: f32,
    normal_impulse: f32,
    tangent_impulse: Vec3,
    rolling_impulse: Vec3,
    pseudo_impulse: f32,
}

/// Closest features of two spheres: the unit normal from `b` towards `a` and the gap along it
/// (negative when they overlap). Coincident centres get the normal `+y`.
#[must_use]
pub fn sphere_sphere(ca: Vec3, ra: f32, cb: Vec3, rb: f32) -> (Vec3, f32) {
    let d = ca - cb;
    let dist = d.length();
    let normal = if dist > 0.0 { d / dist } else { Vec3::Y };
    (normal, dist - ra - rb)
}

/// Closest features of a sphere and a box: the unit normal from the box towards the sphere's
/// centre and the gap along it (negative when they overlap). A centre outside the box is
/// measured from the closest point on the box; a centre inside it leaves through the nearest
/// face (ties go to −x, +x, −y, +y, −z, +z in that order).
#[must_use]
pub fn sphere_box(center: Vec3, radius: f32, aabb: &Aabb) -> (Vec3, f32) {
    let closest = center.clamp(aabb.min, aabb.max);
    let d = center - closest;
    let dist = d.length();
    if dist > 0.0 {
        return (d / dist, dist - radius);
    }
    let mut best = (Vec3::NEG_X, center.x - aabb.min.x);
    for axis in 0..3 {
        let unit = Vec3::AXES[axis];
        for (normal, depth) in [
            (-unit, center[axis] - aabb.min[axis]),
            (unit, aabb.max[axis] - center[axis]),
        ] {
            if depth < best.1 {
                best = (normal, depth);
            }
        }
    }
    (best.0, -best.1 - radius)
}

/// Spheres and static boxes under gravity, stepped with a [`BroadPhase`] (see the module docs
/// for the order of one step). Its per-step buffers (pairs, contacts, pseudo-velocities) are
/// reused and never shrink, so a step allocates only when the contact count reaches a new high
/// (plus whatever the broadphase's own step allocates).
#[derive(Clone, Debug)]
pub struct World {
    config: WorldConfig,
    broadphase: BroadPhase,
    positions: Vec<Vec3>,
    velocities: Vec<Vec3>,
    angular_velocities: Vec<Vec3>,
    radii: Vec<f32>,
    inv_masses: Vec<f32>,
    /// `1/I = 5 / (2·m·r²)` of a solid sphere; 0 for a point (it cannot be spun).
    inv_inertias: Vec<f32>,
    materials: Vec<Material>,
    sphere_keys: Vec<ProxyKey>,
    /// This step's growth of each sphere's broadphase radius, in metres.
    growth: Vec<f32>,
    /// Split-impulse pseudo-velocities, reset every step.
    pseudo: Vec<Vec3>,
    boxes: Vec<Aabb>,
    box_materials: Vec<Material>,
    box_keys: Vec<ProxyKey>,
    owners: SecondaryMap<ProxyKey, Owner>,
    pairs: Vec<Pair>,
    contacts: Vec<Contact>,
    prev_contacts: Vec<Contact>,
    stats: StepStats,
}

impl World {
    /// An empty world, or the first field of `config` out of range.
    pub fn new(config: WorldConfig) -> Result<Self, Error> {
        config.validate()?;
        Ok(Self {
            config,
            broadphase: BroadPhase::new(config.broadphase),
            positions: Vec::new(),
            velocities: Vec::new(),
            angular_velocities: Vec::new(),
            radii: Vec::new(),
            inv_masses: Vec::new(),
            inv_inertias: Vec::new(),
            materials: Vec::new(),
            sphere_keys: Vec::new(),
            growth: Vec::new(),
            pseudo: Vec::new(),
            boxes: Vec::new(),
            box_materials: Vec::new(),
            box_keys: Vec::new(),
            owners: SecondaryMap::new(),
            pairs: Vec::new(),
            contacts: Vec::new(),
            prev_contacts: Vec::new(),
            stats: StepStats::default(),
        })
    }

    /// Adds a sphere and returns its index (indices count up from 0 in insertion order).
    /// `Err` on a non-finite centre or velocity, a negative or non-finite radius, a mass that
    /// is not finite and positive (kg), or a material out of range; on `Err` nothing changes.
    pub fn add_sphere(
        &mut self,
        center: Vec3,
        velocity: Vec3,
        radius: f32,
        mass: f32,
        material: Material,
    ) -> Result<usize, Error> {
        check_sphere(center, radius)?;
        if !velocity.is_finite() {
            return Err(Error::NonFinite {
                what: "velocity",
                value: velocity,
            });
        }
        if !(mass.is_finite() && mass > 0.0) {
            return Err(Error::InvalidConfig {
                what: "mass",
                value: mass,
            });
        }
        material.validate()?;
        let key = match self.config.index {
            IndexKind::Octree => self.broadphase.insert_sphere(center, radius)?,
            IndexKind::Bvh => self
                .broadphase
                .insert_body(Aabb::from_center_radius(center, radius), BodyKind::Dynamic)?,
        };
        let index = self.positions.len();
        self.owners.insert(key, Owner::Sphere(index as u32));
        self.sphere_keys.push(key);
        self.positions.push(center);
        self.velocities.push(velocity);
        self.angular_velocities.push(Vec3::ZERO);
        self.radii.push(radius);
        self.inv_masses.push(1.0 / mass);
        let inertia = 0.4 * mass * radius * radius;
        self.inv_inertias
            .push(if inertia > 0.0 { 1.0 / inertia } else { 0.0 });
        self.materials.push(material);
        self.growth.push(0.0);
        self.pseudo.push(Vec3::ZERO);
        Ok(index)
    }

    /// Adds a static box (a floor, a wall) and returns its index. `Err` on a non-finite or
    /// inverted box or a material out of range; on `Err` nothing changes.
    pub fn add_box(&mut self, aabb: Aabb, material: Material) -> Result<usize, Error> {
        check_aabb(&aabb)?;
        material.validate()?;
        let key = self.broadphase.insert_body(aabb, BodyKind::Static)?;
        let index = self.boxes.len();
        self.owners.insert(key, Owner::Box(index as u32));
        self.box_keys.push(key);
        self.boxes.push(aabb);
        self.box_materials.push(material);
        Ok(index)
    }

    /// Advances the world by `dt` seconds and returns what the step did. `Err` for a `dt` that
    /// is not finite and positive (nothing changes), or `Err(NonFinite)` if the motion
    /// overflowed to infinity (the world is then left mid-step).
    pub fn step(&mut self, dt: f32) -> Result<StepStats, Error> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(Error::InvalidConfig {
                what: "dt",
                value: dt,
            });
        }
        let start = Instant::now();
        let g = self.config.gravity * dt;
        for v in &mut self.velocities {
            *v += g;
        }

        let bp_start = Instant::now();
        self.update_proxies(dt)?;
        let step = self.broadphase.step();
        self.pairs.clear();
        self.pairs.extend_from_slice(step.pairs);
        let broadphase_time = bp_start.elapsed();

        let (touching, max_penetration) = self.narrow_phase();
        self.prepare(dt);
        for _ in 0..self.config.velocity_iterations {
            self.solve_velocities();
        }
        self.solve_positions(dt);
        for ((x, v), p) in self
            .positions
            .iter_mut()
            .zip(&self.velocities)
            .zip(&self.pseudo)
        {
            *x += (*v + *p) * dt;
        }

        self.stats = StepStats {
            pairs: self.pairs.len(),
            contacts: self.contacts.len(),
            touching,
            broadphase_time,
            total_time: start.elapsed(),
            kinetic_energy: self.kinetic_energy(),
            max_penetration,
        };
        Ok(self.stats)
    }

    /// Hands every sphere to the broadphase grown by how far it can move this step.
    fn update_proxies(&mut self, dt: f32) -> Result<(), Error> {
        for i in 0..self.positions.len() {
            let growth = self.velocities[i].length() * dt + self.config.speculative_margin;
            self.growth[i] = growth;
            let (key, center, radius) = (
                self.sphere_keys[i],
                self.positions[i],
                self.radii[i] + growth,
            );
            match self.config.index {
                IndexKind::Octree => self.broadphase.update_sphere(key, center, radius)?,
                IndexKind::Bvh => self
                    .broadphase
                    .update_body(key, Aabb::from_center_radius(center, radius))?,
            }
        }
        Ok(())
    }

    /// Turns this step's pairs into contacts (in pair order), carrying over the impulses of
    /// the previous step's contact of the same pair. Returns the number of overlapping
    /// contacts and the deepest overlap.
    fn narrow_phase(&mut self) -> (usize, f32) {
        core::mem::swap(&mut self.contacts, &mut self.prev_contacts);
        self.contacts.clear();
        let (mut touching, mut deepest) = (0, 0.0f32);
        // Both lists are sorted by pair: walk the previous one alongside (a merge).
        let mut prev = 0;
        for &pair in &self.pairs {
            let (Some(&oa), Some(&ob)) = (self.owners.get(pair.a), self.owners.get(pair.b)) else {
                debug_assert!(
                    false,
                    "the broadphase reported a key the world does not own"
                );
                continue;
            };
            let (i, other, normal, separation, reach) = match (oa, ob) {
                (Owner::Sphere(i), Owner::Sphere(j)) => {
                    let (iu, ju) = (i as usize, j as usize);
                    let (n, s) = sphere_sphere(
                        self.positions[iu],
                        self.radii[iu],
                        self.positions[ju],
                        self.radii[ju],
                    );
                    (i, Owner::Sphere(j), n, s, self.growth[iu] + self.growth[ju])
                }
                (Owner::Sphere(i), Owner::Box(b)) | (Owner::Box(b), Owner::Sphere(i)) => {
                    let iu = i as usize;
                    let (n, s) =
                        sphere_box(self.positions[iu], self.radii[iu], &self.boxes[b as usize]);
                    (i, Owner::Box(b), n, s, self.growth[iu])
                }
                (Owner::Box(_), Owner::Box(_)) => continue,
            };
            if separation > reach {
                continue;
            }
            let iu = i as usize;
            let (j, radius_j, inv_mass_j, inv_inertia_j, material_j) = match other {
                Owner::Sphere(j) => {
                    let ju = j as usize;
                    let (r, m, w) = (self.radii[ju], self.inv_masses[ju], self.inv_inertias[ju]);
                    (j, r, m, w, self.materials[ju])
                }
                Owner::Box(b) => (NONE, 0.0, 0.0, 0.0, self.box_materials[b as usize]),
            };
            let (radius_i, inv_mass_i, inv_inertia_i, material_i) = (
                self.radii[iu],
                self.inv_masses[iu],
                self.inv_inertias[iu],
                self.materials[iu],
            );
            while prev < self.prev_contacts.len() && self.prev_contacts[prev].pair < pair {
                prev += 1;
            }
            let (normal_impulse, tangent_impulse, rolling_impulse) =
                match self.prev_contacts.get(prev) {
                    Some(c) if c.pair == pair && self.config.warm_start => (
                        c.normal_impulse,
                        c.tangent_impulse - normal * c.tangent_impulse.dot(normal),
                        c.rolling_impulse,
                    ),
                    _ => (0.0, Vec3::ZERO, Vec3::ZERO),
                };
            // The reduced radius 1/(1/r_i + 1/r_j): r_i against a flat box.
            let reduced_radius = if j == NONE {
                radius_i
            } else if radius_i + radius_j > 0.0 {
                radius_i * radius_j / (radius_i + radius_j)
            } else {
                0.0
            };
            let inverse = |x: f32| if x > 0.0 { 1.0 / x } else { 0.0 };
            if separation <= 0.0 {
                touching += 1;
                deepest = deepest.max(-separation);
            }
            self.contacts.push(Contact {
                pair,
                i,
                j,
                normal,
                separation,
                radius_i,
                radius_j,
                normal_mass: inverse(inv_mass_i + inv_mass_j),
                tangent_mass: inverse(
                    inv_mass_i
                        + radius_i * radius_i * inv_inertia_i
                        + inv_mass_j
                        + radius_j * radius_j * inv_inertia_j,
                ),
                rolling_mass: inverse(inv_inertia_i + inv_inertia_j),
                friction: (material_i.friction * material_j.friction).sqrt(),
                rolling_arm: (material_i.rolling_resistance * material_j.rolling_resistance).sqrt()
                    * reduced_radius,
                restitution: material_i.restitution.max(material_j.restitution),
                target: 0.0,
                normal_impulse,
                tangent_impulse,
                rolling_impulse,
                pseudo_impulse: 0.0,
            });
        }
        (touching, deepest)
    }

    /// The velocity of `i`'s surface point at the contact relative to `j`'s (or to the static
    /// box): `(v_i − r_i·ω_i×n) − (v_j + r_j·ω_j×n)`.
    fn contact_velocity(&self, c: &Contact) -> Vec3 {
        let (i, n) = (c.i as usize, c.normal);
        let vi = self.velocities[i] - c.radius_i * self.angular_velocities[i].cross(n);
        if c.j == NONE {
            vi
        } else {
            let j = c.j as usize;
            vi - (self.velocities[j] + c.radius_j * self.angular_velocities[j].cross(n))
        }
    }

    /// The spin of `i` relative to `j` (or to the static box).
    fn relative_spin(&self, c: &Contact) -> Vec3 {
        let wi = self.angular_velocities[c.i as usize];
        if c.j == NONE {
            wi
        } else {
            wi - self.angular_velocities[c.j as usize]
        }
    }

    /// Applies the linear impulse `p` at the contact to `i` and `−p` to `j`, with the torques
    /// of their lever arms `−r_i·n` and `+r_j·n`.
    fn apply_impulse(&mut self, c: &Contact, p: Vec3) {
        let (i, arm) = (c.i as usize, c.normal.cross(p));
        self.velocities[i] += p * self.inv_masses[i];
        self.angular_velocities[i] -= arm * (c.radius_i * self.inv_inertias[i]);
        if c.j != NONE {
            let j = c.j as usize;
            self.velocities[j] -= p * self.inv_masses[j];
            self.angular_velocities[j] -= arm * (c.radius_j * self.inv_inertias[j]);
        }
    }

    /// Applies the angular impulse `l` to `i` and `−l` to `j`.
    fn apply_spin(&mut self, c: &Contact, l: Vec3) {
        let i = c.i as usize;
        self.angular_velocities[i] += l * self.inv_inertias[i];
        if c.j != NONE {
            let j = c.j as usize;
            self.angular_velocities[j] -= l * self.inv_inertias[j];
        }
    }

    /// Sets every contact's target normal velocity from its approach speed (before any
    /// impulse), then applies the warm-start impulses.
    ///
    /// The target: an impact faster than `restitution_threshold` that closes the gap within
    /// this step separates at `e·|approach|`; otherwise a contact with gap `s > 0` may close at
    /// most `s/dt`, and a touching one must not approach.
    fn prepare(&mut self, dt: f32) {
        let threshold = self.config.restitution_threshold;
        for k in 0..self.contacts.len() {
            let c = self.contacts[k];
            let approach = self.contact_velocity(&c).dot(c.normal);
            let hits = approach < -threshold && approach * dt <= -c.separation;
            self.contacts[k].target = if hits && c.restitution > 0.0 {
                -c.restitution * approach
            } else if c.separation > 0.0 {
                -c.separation / dt
            } else {
                0.0
            };
        }
        for k in 0..self.contacts.len() {
            let c = self.contacts[k];
            self.apply_impulse(&c, c.normal * c.normal_impulse + c.tangent_impulse);
            self.apply_spin(&c, c.rolling_impulse);
        }
    }

    /// One sequential-impulse pass: per contact, rolling resistance and friction within the
    /// limits set by the current normal impulse, then the normal impulse towards the
    /// contact's target velocity. Impulses are accumulated and clamped as totals (Catto 2005).
    fn solve_velocities(&mut self) {
        for k in 0..self.contacts.len() {
            let mut c = self.contacts[k];

            let max_roll = c.rolling_arm * c.normal_impulse;
            let mut roll = c.rolling_impulse - self.relative_spin(&c) * c.rolling_mass;
            let len = roll.length();
            if len > max_roll {
                roll *= max_roll / len;
            }
            self.apply_spin(&c, roll - c.rolling_impulse);
            c.rolling_impulse = roll;

            let vr = self.contact_velocity(&c);
            let vt = vr - c.normal * vr.dot(c.normal);
            let max_t = c.friction * c.normal_impulse;
            let mut t = c.tangent_impulse - vt * c.tangent_mass;
            let len = t.length();
            if len > max_t {
                t *= max_t / len;
            }
            self.apply_impulse(&c, t - c.tangent_impulse);
            c.tangent_impulse = t;

            let vn = self.contact_velocity(&c).dot(c.normal);
            let n = (c.normal_impulse + c.normal_mass * (c.target - vn)).max(0.0);
            self.apply_impulse(&c, c.normal * (n - c.normal_impulse));
            c.normal_impulse = n;
            self.contacts[k] = c;
        }
    }

    /// Split impulses: pseudo-velocities that push overlapping contacts apart by
    /// `position_correction` of their overlap beyond `slop` this step, never faster than
    /// `max_correction_speed`. They move positions once and are then discarded.
    fn solve_positions(&mut self, dt: f32) {
        self.pseudo.fill(Vec3::ZERO);
        let cfg = self.config;
        for _ in 0..cfg.position_iterations {
            for c in &mut self.contacts {
                let excess = -c.separation - cfg.slop;
                if excess <= 0.0 {
                    continue;
                }
                let target = (cfg.position_correction * excess / dt).min(cfg.max_correction_speed);
                let pi = self.pseudo[c.i as usize];
                let rel = if c.j == NONE {
                    pi
                } else {
                    pi - self.pseudo[c.j as usize]
                };
                let p = (c.pseudo_impulse + c.normal_mass * (target - rel.dot(c.normal))).max(0.0);
                let dp = c.normal * (p - c.pseudo_impulse);
                self.pseudo[c.i as usize] += dp * self.inv_masses[c.i as usize];
                if c.j != NONE {
                    self.pseudo[c.j as usize] -= dp * self.inv_masses[c.j as usize];
                }
                c.pseudo_impulse = p;
            }
        }
    }

    /// `Σ ½·m·|v|² + ½·I·|ω|²` over all spheres, in joules (summed in `f64`, in index order).
    #[must_use]
    pub fn kinetic_energy(&self) -> f64 {
        let linear = self.velocities.iter().zip(&self.inv_masses);
        let angular = self.angular_velocities.iter().zip(&self.inv_inertias);
        linear
            .chain(angular)
            .filter(|(_, w)| **w > 0.0)
            .map(|(v, w)| 0.5 * f64::from(v.length_squared()) / f64::from(*w))
            .sum()
    }

    /// The settings in force.
    #[must_use]
    pub fn config(&self) -> &WorldConfig {
        &self.config
    }

    /// The broadphase, for queries (`query_aabb`, `cast_ray`, `aabb`) on the world's keys.
    #[must_use]
    pub fn broadphase(&self) -> &BroadPhase {
        &self.broadphase
    }

    /// Number of spheres.
    #[must_use]
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True if the world has no spheres.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Sphere centres, by sphere index.
    #[must_use]
    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }

    /// Sphere velocities in m/s, by sphere index.
    #[must_use]
    pub fn velocities(&self) -> &[Vec3] {
        &self.velocities
    }

    /// Sphere angular velocities in rad/s, by sphere index. Orientation is not tracked: a
    /// sphere looks the same however it has turned.
    #[must_use]
    pub fn angular_velocities(&self) -> &[Vec3] {
        &self.angular_velocities
    }

    /// Sphere radii, by sphere index.
    #[must_use]
    pub fn radii(&self) -> &[f32] {
        &self.radii
    }

    /// Each sphere's broadphase key, by sphere index. Its broadphase box is the sphere grown
    /// by the last step's speculative growth.
    #[must_use]
    pub fn sphere_keys(&self) -> &[ProxyKey] {
        &self.sphere_keys
    }

    /// The static boxes, by box index.
    #[must_use]
    pub fn boxes(&self) -> &[Aabb] {
        &self.boxes
    }

    /// Each box's broadphase key, by box index.
    #[must_use]
    pub fn box_keys(&self) -> &[ProxyKey] {
        &self.box_keys
    }

    /// The sphere index of a key, or `None` for a box's key or a key the world does not own.
    #[must_use]
    pub fn sphere_of(&self, key: ProxyKey) -> Option<usize> {
        match self.owners.get(key) {
            Some(Owner::Sphere(i)) => Some(*i as usize),
            _ => None,
        }
    }

    /// The broadphase pairs of the last step, sorted (empty before the first step).
    #[must_use]
    pub fn pairs(&self) -> &[Pair] {
        &self.pairs
    }

    /// The last step's statistics (all zero before the first step).
    #[must_use]
    pub fn stats(&self) -> &StepStats {
        &self.stats
    }
}

/// The standard scene: `count` spheres on a jittered grid above an open box that fits them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DropConfig {
    /// Number of spheres.
    pub count: usize,
    /// Radius of every sphere in metres, finite and `> 0`.
    pub radius: f32,
    /// Distance between neighbouring grid points in metres, `>= 2·radius`.
    pub spacing: f32,
    /// Each coordinate of a start position is jittered uniformly by up to this many metres;
    /// keep it `<= spacing/2 − radius` so no two spheres start overlapping.
    pub jitter: f32,
    /// Sphere density in kg/m³, `> 0`; the mass is `density · 4/3·π·r³`.
    pub density: f32,
    /// The spheres' material.
    pub material: Material,
    /// The container's material.
    pub wall_material: Material,
    /// Thickness of the floor and the walls in metres, `> 0`; a sphere must not cross it
    /// within one step's speculative reach.
    pub wall_thickness: f32,
    /// The pile's expected height over the container's width (it sets the width); `> 0`.
    pub pile_aspect: f32,
    /// Octree depth is chosen so the deepest cells are at least this many diameters wide.
    pub min_cell_diameters: f32,
    /// Seed of the jitter.
    pub seed: u64,
    /// World settings; the broadphase bounds and octree depth are set by [`DropConfig::build`].
    pub world: WorldConfig,
}

/// Volume fraction of a random loose pile of equal spheres, used to size the container.
const PILE_PACKING: f32 = 0.6;

impl DropConfig {
    /// The scene with settings scaled to `radius`: grid spacing 2.5 r, jitter 0.2 r, density
    /// 1000 kg/m³, walls 2 r thick, a pile half as high as wide, deepest octree cells at least
    /// 2 diameters; solver slop 1 % of r, speculative margin 5 % of r, correction capped at
    /// 4 r per second.
    #[must_use]
    pub fn new(count: usize, radius: f32, seed: u64) -> Self {
        Self {
            count,
            radius,
            spacing: 2.5 * radius,
            jitter: 0.2 * radius,
            density: 1000.0,
            material: Material::default(),
            wall_material: Material::default(),
            wall_thickness: 2.0 * radius,
            pile_aspect: 0.5,
            min_cell_diameters: 2.0,
            seed,
            world: WorldConfig {
                slop: 0.01 * radius,
                speculative_margin: 0.05 * radius,
                max_correction_speed: 4.0 * radius,
                ..WorldConfig::default()
            },
        }
    }

    /// The world, or the first setting out of range. The container's inner floor is the plane
    /// `y = 0`, centred on the y axis; its walls rise one grid spacing above the highest
    /// sphere, so a sphere that bounces (restitution `< 1`) cannot leave over them.
    pub fn build(&self) -> Result<SphereDrop, Error> {
        let r = self.radius;
        let bad = |what, value: f32| Err(Error::InvalidConfig { what, value });
        if !(r.is_finite() && r > 0.0) {
            return bad("radius", r);
        }
        if !(self.spacing.is_finite() && self.spacing >= 2.0 * r) {
            return bad("spacing", self.spacing);
        }
        for (what, value) in [
            ("wall_thickness", self.wall_thickness),
            ("pile_aspect", self.pile_aspect),
            ("density", self.density),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return bad(what, value);
            }
        }
        for (what, value) in [
            ("jitter", self.jitter),
            ("min_cell_diameters", self.min_cell_diameters),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return bad(what, value);
            }
        }
        let volume = 4.0 / 3.0 * core::f32::consts::PI * r * r * r;
        // Width w of a square container holding a pile of height pile_aspect·w.
        let pile = self.count.max(1) as f32 * volume / PILE_PACKING;
        let width = (pile / self.pile_aspect).cbrt();
        let columns = ((width / self.spacing).floor() as usize).max(1);
        let layers = self.count.div_ceil(columns * columns);
        let half = columns as f32 * self.spacing * 0.5;
        let top = self.spacing * (layers as f32 + 1.0);
        let t = self.wall_thickness;
        let interior = Aabb::new(Vec3::new(-half, 0.0, -half), Vec3::new(half, top, half));
        let outer = Aabb::new(
            Vec3::new(-half - t, -t, -half - t),
            Vec3::new(half + t, top, half + t),
        );

        let mut world_config = self.world;
        world_config.broadphase.bounds = outer;
        let cell = self.min_cell_diameters * 2.0 * r;
        let extent = outer.extent().max_element();
        world_config.broadphase.octree_depth = if cell > 0.0 && extent > cell {
            ((extent / cell).log2().floor() as u32).min(MAX_DEPTH)
        } else {
            0
        };
        let mut world = World::new(world_config)?;
        for b in [
            Aabb::new(outer.min, Vec3::new(outer.max.x, 0.0, outer.max.z)),
            Aabb::new(outer.min, Vec3::new(-half, top, outer.max.z)),
            Aabb::new(Vec3::new(half, -t, outer.min.z), outer.max),
            Aabb::new(outer.min, Vec3::new(outer.max.x, top, -half)),
            Aabb::new(Vec3::new(outer.min.x, -t, half), outer.max),
        ] {
            world.add_box(b, self.wall_material)?;
        }

        let mut rng = Rng::new(self.seed);
        let mass = self.density * volume;
        for k in 0..self.count {
            let (layer, cell) = (k / (columns * columns), k % (columns * columns));
            let (ix, iz) = (cell % columns, cell / columns);
            let grid = Vec3::new(
                -half + self.spacing * (ix as f32 + 0.5),
                self.spacing * (layer as f32 + 1.0),
                -half + self.spacing * (iz as f32 + 0.5),
            );
            let jitter = rng.vec3_in(Vec3::splat(-self.jitter), Vec3::splat(self.jitter));
            world.add_sphere(grid + jitter, Vec3::ZERO, r, mass, self.material)?;
        }
        Ok(SphereDrop { world, interior })
    }
}

/// The scene [`DropConfig::build`] makes: the world and the inside of its container.
#[derive(Clone, Debug)]
pub struct SphereDrop {
    /// The world, spheres `0..count` and the five container boxes (floor first).
    pub world: World,
    /// The container's inside: floor at `y = 0`, walls at `±x`, `±z`, open at the top.
    pub interior: Aabb,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_sphere_overlap_gap_and_coincident_centres() {
        let (n, s) = sphere_sphere(Vec3::new(1.5, 0.0, 0.0), 1.0, Vec3::ZERO, 1.0);
        assert_eq!(n, Vec3::X);
        assert_eq!(s, -0.5);
        let (n, s) = sphere_sphere(Vec3::ZERO, 0.5, Vec3::new(0.0, 0.0, 3.0), 0.5);
        assert_eq!(n, Vec3::NEG_Z);
        assert_eq!(s, 2.0);
        let (n, s) = sphere_sphere(Vec3::ONE, 0.5, Vec3::ONE, 0.25);
        assert_eq!(n, Vec3::Y);
        assert_eq!(s, -0.75);
    }

    #[test]
    fn sphere_box_face_edge_and_corner() {
        let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        // Above the top face, 0.5 away from it, radius 0.25: a gap of 0.25.
        let (n, s) = sphere_box(Vec3::new(0.5, 1.5, 0.5), 0.25, &b);
        assert_eq!(n, Vec3::Y);
        assert_eq!(s, 0.25);
        // Off a corner along the diagonal.
        let (n, s) = sphere_box(Vec3::splat(2.0), 1.0, &b);
        assert!((n - Vec3::splat(1.0 / 3f32.sqrt())).length() < 1e-6);
        assert!((s - (3f32.sqrt() - 1.0)).abs() < 1e-6);
        // Off an edge, overlapping.
        let (n, s) = sphere_box(Vec3::new(1.3, 1.4, 0.5), 1.0, &b);
        assert!((n - Vec3::new(0.6, 0.8, 0.0)).length() < 1e-6);
        assert!((s + 0.5).abs() < 1e-6);
    }

    #[test]
    fn sphere_box_centre_inside_leaves_through_the_nearest_face() {
        let floor = Aabb::new(Vec3::new(-10.0, -1.0, -10.0), Vec3::new(10.0, 0.0, 10.0));
        let (n, s) = sphere_box(Vec3::new(3.0, -0.25, 2.0), 0.5, &floor);
        assert_eq!(n, Vec3::Y);
        assert_eq!(s, -0.75);
        let (n, s) = sphere_box(Vec3::new(9.9, -0.5, 0.0), 0.5, &floor);
        assert_eq!(n, Vec3::X);
        assert!((s + 0.6).abs() < 1e-5);
        // Exactly at the centre: the tie goes to −x.
        let cube = Aabb::new(Vec3::ZERO, Vec3::splat(2.0));
        let (n, s) = sphere_box(Vec3::ONE, 0.5, &cube);
        assert_eq!(n, Vec3::NEG_X);
        assert_eq!(s, -1.5);
    }

    #[test]
    fn a_dropped_sphere_bounces_and_comes_to_rest_on_the_floor() {
        let mut world = World::new(WorldConfig::default()).unwrap();
        let floor = Aabb::new(Vec3::new(-5.0, -1.0, -5.0), Vec3::new(5.0, 0.0, 5.0));
        world.add_box(floor, Material::default()).unwrap();
        world
            .add_sphere(
                Vec3::new(0.0, 3.0, 0.0),
                Vec3::ZERO,
                0.5,
                1.0,
                Material::default(),
            )
            .unwrap();
        let mut highest_after_bounce = 0.0f32;
        let mut bounced = false;
        for _ in 0..600 {
            world.step(1.0 / 60.0).unwrap();
            let (y, vy) = (world.positions()[0].y, world.velocities()[0].y);
            assert!(y > 0.5 - 0.05, "sank into the floor: y = {y}");
            bounced |= vy > 0.5;
            if bounced {
                highest_after_bounce = highest_after_bounce.max(y);
            }
        }
        assert!(bounced, "restitution 0.3 from 3 m must bounce");
        assert!(highest_after_bounce < 3.0 * 0.3f32.powi(2) * 2.0 + 0.5);
        assert!((world.positions()[0].y - 0.5).abs() < 0.01);
        assert!(world.kinetic_energy() < 1e-6);
    }

    #[test]
    fn a_fast_sphere_does_not_tunnel_through_a_thin_wall() {
        let mut world = World::new(WorldConfig {
            gravity: Vec3::ZERO,
            ..WorldConfig::default()
        })
        .unwrap();
        let wall = Aabb::new(Vec3::new(1.0, -5.0, -5.0), Vec3::new(1.1, 5.0, 5.0));
        world.add_box(wall, Material::default()).unwrap();
        // 200 m/s at 60 Hz: 3.3 m per step, thirty times the wall's thickness.
        world
            .add_sphere(
                Vec3::ZERO,
                Vec3::new(200.0, 0.0, 0.0),
                0.1,
                1.0,
                Material::default(),
            )
            .unwrap();
        for _ in 0..30 {
            world.step(1.0 / 60.0).unwrap();
            assert!(world.positions()[0].x < 1.0, "{}", world.positions()[0].x);
        }
        assert!(world.velocities()[0].x < 0.0, "it bounced back");
    }

    #[test]
    fn bad_inputs_are_refused() {
        let mut world = World::new(WorldConfig::default()).unwrap();
        let m = Material::default();
        assert!(
            world
                .add_sphere(Vec3::ZERO, Vec3::ZERO, 1.0, 0.0, m)
                .is_err()
        );
        assert!(
            world
                .add_sphere(Vec3::ZERO, Vec3::splat(f32::NAN), 1.0, 1.0, m)
                .is_err()
        );
        let bouncy = Material {
            restitution: 1.5,
            ..Material::default()
        };
        assert!(
            world
                .add_sphere(Vec3::ZERO, Vec3::ZERO, 1.0, 1.0, bouncy)
                .is_err()
        );
        assert!(world.step(0.0).is_err() && world.step(f32::NAN).is_err());
        assert!(world.is_empty() && world.broadphase().is_empty());
        let bad = WorldConfig {
            position_correction: 2.0,
            ..WorldConfig::default()
        };
        assert!(World::new(bad).is_err());
    }
}
