//! Seeded scene generators shared by tests, examples and benches (see `benchmarks.md`): the
//! same seed gives the same motion everywhere, so a number can be reproduced with one command.

use crate::{Aabb, BodyKind, BroadPhase, Error, ProxyKey, Vec3};
use glam::{Mat3A, Quat};

mod bodies;
mod gas;
mod recorded;

pub use bodies::Bodies;
pub use gas::{Churn, Gas};
pub use recorded::Recorded;

/// A small PCG32 generator (O'Neill's `pcg32_random_r`): deterministic on every platform, no
/// dependency.
#[derive(Clone, Debug)]
pub struct Rng {
    state: u64,
    inc: u64,
}

impl Rng {
    /// A generator for `seed`; equal seeds give equal streams.
    #[must_use]
    pub fn new(seed: u64) -> Self {
        let mut rng = Rng {
            state: 0,
            inc: (seed << 1) | 1,
        };
        rng.next_u32();
        rng.state = rng.state.wrapping_add(0x853c_49e6_748f_ea9b ^ seed);
        rng.next_u32();
        rng
    }

    /// The next 32 uniformly distributed bits.
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// Uniform in `[0, 1)`, 24 bits of precision.
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }

    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next_f32()
    }

    /// Uniform in `0..n` (`n > 0`), by Lemire's multiply-shift (bias below 2⁻³² · n).
    pub fn below(&mut self, n: u32) -> u32 {
        ((u64::from(self.next_u32()) * u64::from(n)) >> 32) as u32
    }

    /// Uniform in the box spanned by `min` and `max`.
    pub fn vec3_in(&mut self, min: Vec3, max: Vec3) -> Vec3 {
        Vec3::new(
            self.range(min.x, max.x),
            self.range(min.y, max.y),
            self.range(min.z, max.z),
        )
    }

    /// Log-uniform in `[lo, hi)` (`0 < lo < hi`): `ln x` is uniform.
    pub fn log_range(&mut self, lo: f32, hi: f32) -> f32 {
        self.range(lo.ln(), hi.ln()).exp()
    }

    /// A rotation uniform over all orientations (Shoemake's subgroup algorithm), unit length.
    pub fn rotation(&mut self) -> Quat {
        let (u1, u2, u3) = (self.next_f32(), self.next_f32(), self.next_f32());
        let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
        let (t2, t3) = (core::f32::consts::TAU * u2, core::f32::consts::TAU * u3);
        Quat::from_xyzw(a * t2.sin(), a * t2.cos(), b * t3.sin(), b * t3.cos()).normalize()
    }
}

/// Radius of every sphere in the `gas`, `clustered` and `churn` scenes, in metres.
pub const GAS_RADIUS: f32 = 0.5;
/// Volume fraction of the `gas` scene.
pub const GAS_VOLUME_FRACTION: f32 = 0.1;
/// Time step of every scene, in seconds.
pub const DT: f32 = 1.0 / 60.0;
/// Speed range of the `gas` scene: each velocity component uniform in `[-GAS_SPEED, GAS_SPEED]` m/s.
pub const GAS_SPEED: f32 = 5.0;
/// Half-thickness of the slabs around the root's split planes in `clustered`, in metres.
pub const CLUSTER_HALF_WIDTH: f32 = 2.0;

/// The edge of the cube that holds `n` spheres of radius `r` at volume fraction `phi`.
#[must_use]
pub fn cube_edge(n: usize, r: f32, phi: f32) -> f32 {
    let sphere = 4.0 / 3.0 * core::f32::consts::PI * r * r * r;
    (n as f32 * sphere / phi).cbrt()
}

/// Half-extent range of the `bodies` scene's boxes, in metres: each half-extent is
/// log-uniform in `[BOX_HALF_MIN, BOX_HALF_MAX)`.
pub const BOX_HALF_MIN: f32 = 0.1;
/// See [`BOX_HALF_MIN`].
pub const BOX_HALF_MAX: f32 = 2.0;
/// Volume fraction of the `bodies` scene: the dynamic boxes' own volume over the cube's.
pub const BODIES_VOLUME_FRACTION: f32 = 0.1;
/// Half-thickness of the `bodies` scene's static floor, in metres; the floor's mid-plane is
/// the cube's bottom face, so boxes near the bottom overlap it.
pub const FLOOR_HALF_THICKNESS: f32 = 0.5;
/// Percentage of the proxies the `churn` scene removes, inserts and teleports each step
/// (each, rounded up).
pub const CHURN_PERCENT: usize = 1;

/// One object of a scene as plain data, so the same motion can be fed to broadleaf and to
/// another engine (rapier): a sphere, or a box with an orientation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Object {
    /// A sphere: broadleaf's `insert_sphere`, rapier's ball collider.
    Sphere {
        /// Centre in world space.
        center: Vec3,
        /// Radius in metres.
        radius: f32,
    },
    /// An oriented box: broadleaf's `insert_body` with [`Object::aabb`], rapier's cuboid.
    Cuboid {
        /// Centre in world space.
        center: Vec3,
        /// Half-extents along the box's own axes, in metres.
        half_extents: Vec3,
        /// Orientation of the box's axes, a unit quaternion.
        rotation: Quat,
    },
}

impl Object {
    /// The object's centre.
    #[must_use]
    pub fn center(&self) -> Vec3 {
        match *self {
            Object::Sphere { center, .. } | Object::Cuboid { center, .. } => center,
        }
    }

    /// The object's tight world AABB: `center ± radius` for a sphere; for a box,
    /// `center ± |R|·h` (each world axis gets the absolute projections of the three rotated
    /// half-axes), the AABB of the rotated box.
    #[must_use]
    pub fn aabb(&self) -> Aabb {
        match *self {
            Object::Sphere { center, radius } => Aabb::from_center_radius(center, radius),
            Object::Cuboid {
                center,
                half_extents,
                rotation,
            } => {
                Aabb::from_center_half_extents(center, rotated_half_extents(half_extents, rotation))
            }
        }
    }
}

/// Half-extents of the AABB of a box with `half_extents` rotated by `rotation`.
#[must_use]
pub fn rotated_half_extents(half_extents: Vec3, rotation: Quat) -> Vec3 {
    // In SIMD lanes (`Mat3A`): the same operations lane by lane, so the same floats as with
    // `Mat3` (a test checks), in ~20 % fewer instructions.
    let m = Mat3A::from_quat(rotation);
    (m.x_axis.abs() * half_extents.x
        + m.y_axis.abs() * half_extents.y
        + m.z_axis.abs() * half_extents.z)
        .into()
}

/// An object entering a scene: its id (unique within the scene, never reused), the object,
/// and whether it is static (never moves; static×static pairs are never reported).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spawn {
    /// The object's id within its scene.
    pub id: u32,
    /// The object where it appears.
    pub object: Object,
    /// True for an object that never moves.
    pub is_static: bool,
}

/// What changed in one step of a [`Scene`], as plain data. Consumers apply `removed`, then
/// `inserted`, then `moved`; the lists are disjoint and each is in a deterministic order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Frame {
    /// Ids of the objects that left the scene this step.
    pub removed: Vec<u32>,
    /// Objects that entered the scene this step, at their position after the step.
    pub inserted: Vec<Spawn>,
    /// Every other dynamic object's state after the step (teleported ones included), by id.
    pub moved: Vec<(u32, Object)>,
}

impl Frame {
    /// Empties the three lists, keeping their capacity.
    pub fn clear(&mut self) {
        self.removed.clear();
        self.inserted.clear();
        self.moved.clear();
    }
}

/// A seeded, deterministic scene that yields its motion step by step as plain data.
pub trait Scene {
    /// The region the dynamic objects stay in (use it as the octree's bounds); static objects
    /// may stick out of it.
    fn bounds(&self) -> Aabb;
    /// Number of live objects (static ones included).
    fn len(&self) -> usize;
    /// True if the scene has no objects.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Appends every live object to `out`, statics included, in id order: the state to start
    /// a consumer from.
    fn spawns(&self, out: &mut Vec<Spawn>);
    /// Advances the scene by [`DT`] and writes what changed into `frame` (cleared first).
    fn advance(&mut self, frame: &mut Frame);
}

/// `c` reflected back into `w` on each axis it left, with the velocity turned inwards; clamped
/// for a step longer than the box.
fn reflect(mut c: Vec3, v: &mut Vec3, w: &Aabb) -> Vec3 {
    for axis in 0..3 {
        if c[axis] < w.min[axis] {
            c[axis] = 2.0 * w.min[axis] - c[axis];
            v[axis] = v[axis].abs();
        } else if c[axis] > w.max[axis] {
            c[axis] = 2.0 * w.max[axis] - c[axis];
            v[axis] = -v[axis].abs();
        }
        c[axis] = c[axis].clamp(w.min[axis], w.max[axis]);
    }
    c
}

/// Feeds a [`Scene`]'s objects and frames into a [`BroadPhase`], keeping the key of each scene
/// id: the one adapter tests, benches and examples share.
#[derive(Clone, Debug, Default)]
pub struct Feed {
    keys: Vec<Option<ProxyKey>>,
    spheres_as_bodies: bool,
}

impl Feed {
    /// An empty feed. With `spheres_as_bodies`, spheres go to the dynamic BVH as their boxes
    /// (`insert_body`) instead of the octree, so both structures can run the same motion.
    #[must_use]
    pub fn new(spheres_as_bodies: bool) -> Self {
        Feed {
            keys: Vec::new(),
            spheres_as_bodies,
        }
    }

    /// Inserts every spawn; `Err` from the broadphase on a non-finite object.
    pub fn spawn(&mut self, bp: &mut BroadPhase, spawns: &[Spawn]) -> Result<(), Error> {
        spawns.iter().try_for_each(|s| self.insert(bp, s))
    }

    fn insert(&mut self, bp: &mut BroadPhase, s: &Spawn) -> Result<(), Error> {
        let kind = if s.is_static {
            BodyKind::Static
        } else {
            BodyKind::Dynamic
        };
        let key = match s.object {
            Object::Sphere { center, radius } if !self.spheres_as_bodies => {
                bp.insert_sphere(center, radius)?
            }
            o => bp.insert_body(o.aabb(), kind)?,
        };
        let id = s.id as usize;
        if self.keys.len() <= id {
            self.keys.resize(id + 1, None);
        }
        self.keys[id] = Some(key);
        Ok(())
    }

    /// Applies a frame: removes, then inserts, then moves. `Err(UnknownProxy)` for an id this
    /// feed does not hold, or the broadphase's error on a bad object.
    pub fn apply(&mut self, bp: &mut BroadPhase, frame: &Frame) -> Result<(), Error> {
        for &id in &frame.removed {
            let key = self.take(id).ok_or(Error::UnknownProxy)?;
            bp.remove(key)?;
        }
        for s in &frame.inserted {
            self.insert(bp, s)?;
        }
        for &(id, o) in &frame.moved {
            let key = self.key(id).ok_or(Error::UnknownProxy)?;
            match o {
                Object::Sphere { center, radius } if !self.spheres_as_bodies => {
                    bp.update_sphere(key, center, radius)?;
                }
                o => bp.update_body(key, o.aabb())?,
            }
        }
        Ok(())
    }

    /// The key of scene object `id`, if it is live.
    #[must_use]
    pub fn key(&self, id: u32) -> Option<ProxyKey> {
        self.keys.get(id as usize).copied().flatten()
    }

    fn take(&mut self, id: u32) -> Option<ProxyKey> {
        self.keys.get_mut(id as usize).and_then(Option::take)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rng_is_deterministic_and_in_range() {
        let mut a = Rng::new(42);
        let mut b = Rng::new(42);
        let mut c = Rng::new(43);
        let xs: Vec<u32> = (0..100).map(|_| a.next_u32()).collect();
        let ys: Vec<u32> = (0..100).map(|_| b.next_u32()).collect();
        let zs: Vec<u32> = (0..100).map(|_| c.next_u32()).collect();
        assert_eq!(xs, ys);
        assert_ne!(xs, zs);
        for _ in 0..10_000 {
            let f = a.next_f32();
            assert!((0.0..1.0).contains(&f));
            assert!(a.below(7) < 7);
        }
    }

    #[test]
    fn gas_has_the_volume_fraction_and_stays_inside() {
        let mut g = Gas::new(1000, 1);
        let v = g.bounds.extent();
        let phi = 1000.0 * 4.0 / 3.0 * core::f32::consts::PI * 0.125 / (v.x * v.y * v.z);
        assert!((phi - 0.1).abs() < 1e-3, "{phi}");
        for _ in 0..200 {
            g.step(DT);
        }
        let inner = g.bounds.grown(-g.radius);
        assert!(g.centers.iter().all(|&c| inner.contains_point(c)));
    }

    #[test]
    fn clustered_stays_near_the_mid_planes() {
        let mut g = Gas::clustered(1000, 2);
        for _ in 0..200 {
            g.step(DT);
        }
        let near = |c: Vec3| c.abs().min_element() <= CLUSTER_HALF_WIDTH;
        assert!(g.centers.iter().all(|&c| near(c)));
        assert!(g.centers.iter().all(|&c| g.bounds.contains_point(c)));
    }

    /// Replays `scene`'s frames into an id → object map and checks it against `spawns`.
    fn replay_matches(mut scene: impl Scene, steps: usize) {
        use std::collections::BTreeMap;
        let mut spawns = Vec::new();
        scene.spawns(&mut spawns);
        let mut live: BTreeMap<u32, (Object, bool)> = spawns
            .iter()
            .map(|s| (s.id, (s.object, s.is_static)))
            .collect();
        let mut frame = Frame::default();
        for _ in 0..steps {
            scene.advance(&mut frame);
            for id in &frame.removed {
                assert!(live.remove(id).is_some(), "removed an unknown id {id}");
            }
            for s in &frame.inserted {
                assert!(live.insert(s.id, (s.object, s.is_static)).is_none());
            }
            for &(id, o) in &frame.moved {
                let slot = live.get_mut(&id).expect("moved an unknown id");
                assert!(!slot.1, "a static object moved");
                slot.0 = o;
            }
            spawns.clear();
            scene.spawns(&mut spawns);
            let now: BTreeMap<u32, (Object, bool)> = spawns
                .iter()
                .map(|s| (s.id, (s.object, s.is_static)))
                .collect();
            assert_eq!(live, now);
            assert_eq!(scene.len(), live.len());
            let b = scene.bounds();
            for (o, is_static) in live.values() {
                assert!(*is_static || b.contains(&o.aabb()), "{o:?} left {b:?}");
            }
        }
    }

    #[test]
    fn frames_replay_to_the_scene_state() {
        replay_matches(Gas::new(300, 4), 50);
        replay_matches(Bodies::new(300, 5), 50);
        replay_matches(Churn::new(300, 6), 50);
        let frames: Vec<Vec<Vec3>> = (0..5).map(|k| vec![Vec3::splat(k as f32); 3]).collect();
        let bounds = Aabb::new(Vec3::splat(-1.0), Vec3::splat(6.0));
        replay_matches(Recorded::new(bounds, 0.5, frames), 10);
    }

    #[test]
    fn churn_changes_one_percent_each_step() {
        let mut c = Churn::new(1000, 7);
        let mut f = Frame::default();
        c.advance(&mut f);
        assert_eq!((f.removed.len(), f.inserted.len()), (10, 10));
        assert_eq!(f.moved.len(), 990);
        assert_eq!(c.len(), 1000);
        let mut a = Churn::new(1000, 7);
        let mut g = Frame::default();
        a.advance(&mut g);
        assert_eq!(f, g, "same seed, same frame");
    }

    #[test]
    fn bodies_have_the_documented_shape() {
        let b = Bodies::new(1000, 8);
        assert_eq!(b.statics.len(), 101);
        for o in &b.dynamic {
            let Object::Cuboid {
                half_extents,
                rotation,
                ..
            } = *o
            else {
                panic!("not a box")
            };
            assert!(half_extents.cmpge(Vec3::splat(BOX_HALF_MIN * 0.999)).all());
            assert!(half_extents.cmplt(Vec3::splat(BOX_HALF_MAX * 1.001)).all());
            assert!((rotation.length() - 1.0).abs() < 1e-5);
        }
    }

    /// The rotated box's AABB is the hull of its corners, and `rotated_half_extents` (in SIMD
    /// lanes) gives the very floats of the scalar `Mat3` form.
    #[test]
    fn rotated_box_aabb_holds_its_corners() {
        let mut rng = Rng::new(9);
        for _ in 0..10_000 {
            let h = rng.vec3_in(Vec3::splat(0.1), Vec3::splat(2.0));
            let q = rng.rotation();
            let m = glam::Mat3::from_quat(q);
            let scalar = m.x_axis.abs() * h.x + m.y_axis.abs() * h.y + m.z_axis.abs() * h.z;
            assert_eq!(rotated_half_extents(h, q), scalar, "{h} {q}");
            let o = Object::Cuboid {
                center: Vec3::ONE,
                half_extents: h,
                rotation: q,
            };
            let aabb = o.aabb();
            let mut hull = Aabb::EMPTY;
            for i in 0..8 {
                let s = Vec3::new(
                    if i & 1 == 0 { -1.0 } else { 1.0 },
                    if i & 2 == 0 { -1.0 } else { 1.0 },
                    if i & 4 == 0 { -1.0 } else { 1.0 },
                );
                let p = Vec3::ONE + q * (s * h);
                hull = hull.union(&Aabb::new(p, p));
            }
            assert!((hull.min - aabb.min).abs().max_element() < 1e-4);
            assert!((hull.max - aabb.max).abs().max_element() < 1e-4);
        }
    }
}
