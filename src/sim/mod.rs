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
//!
//! # Files
//! `mod.rs` holds the world, its settings and the step; `narrow.rs` the contact geometry;
//! `solve.rs` the impulse solver; `drop.rs` the standard falling-spheres scene.

mod drop;
mod narrow;
mod solve;

pub use drop::{DropConfig, SphereDrop};
pub use narrow::{sphere_box, sphere_sphere};

use crate::geom::{check_aabb, check_sphere};
use crate::{Aabb, BodyKind, BroadPhase, Config, Error, Pair, ProxyKey, Vec3};
use slotmap::SecondaryMap;
use solve::Contact;
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

    /// `Σ −m·g·x` over all spheres, in joules: the gravitational potential energy relative to
    /// the plane through the origin perpendicular to gravity (summed in `f64`, in index order).
    #[must_use]
    pub fn potential_energy(&self) -> f64 {
        let g = self.config.gravity;
        self.positions
            .iter()
            .zip(&self.inv_masses)
            .map(|(x, w)| -f64::from(g.dot(*x)) / f64::from(*w))
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

#[cfg(test)]
mod tests {
    use super::*;

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
