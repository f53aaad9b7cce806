//! Seeded scene generators shared by tests, examples and benches (see `benchmarks.md`): the
//! same seed gives the same motion everywhere, so a number can be reproduced with one command.

use crate::{Aabb, BodyKind, BroadPhase, Error, ProxyKey, Vec3};
use glam::{Mat3, Quat};

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

/// Spheres moving in straight lines inside a box, reflecting at its walls (`gas`), or kept in
/// slabs around the box's three mid-planes (`clustered`).
#[derive(Clone, Debug)]
pub struct Gas {
    /// The box the spheres stay in; use it as the octree's bounds.
    pub bounds: Aabb,
    /// Current centres.
    pub centers: Vec<Vec3>,
    /// Velocities in m/s.
    pub velocities: Vec<Vec3>,
    /// Radius of every sphere.
    pub radius: f32,
    /// Per sphere, the box its centre is reflected in (the whole bounds shrunk by the radius
    /// for `gas`; a slab around one mid-plane for `clustered`).
    walls: Vec<Aabb>,
}

impl Gas {
    /// The `gas` scene: `n` spheres of radius 0.5, uniform in a cube sized for 10 % volume
    /// fraction and centred at the origin, velocities uniform in `[-5, 5]³` m/s.
    #[must_use]
    pub fn new(n: usize, seed: u64) -> Self {
        let half = cube_edge(n.max(1), GAS_RADIUS, GAS_VOLUME_FRACTION) * 0.5;
        let bounds = Aabb::new(Vec3::splat(-half), Vec3::splat(half));
        let inner = bounds.grown(-GAS_RADIUS);
        Self::generate(n, seed, bounds, |_| inner)
    }

    /// The `clustered` scene: the `gas` cube, but every sphere stays within 2 m of one of the
    /// root's three split planes (the planes through the cube's centre): the worst case for an
    /// octree, whose root then holds every straddler.
    #[must_use]
    pub fn clustered(n: usize, seed: u64) -> Self {
        let half = cube_edge(n.max(1), GAS_RADIUS, GAS_VOLUME_FRACTION) * 0.5;
        let bounds = Aabb::new(Vec3::splat(-half), Vec3::splat(half));
        let inner = bounds.grown(-GAS_RADIUS);
        let w = CLUSTER_HALF_WIDTH.min(half);
        Self::generate(n, seed, bounds, |rng| {
            let mut slab = inner;
            let axis = rng.below(3) as usize;
            slab.min[axis] = -w;
            slab.max[axis] = w;
            slab
        })
    }

    fn generate(
        n: usize,
        seed: u64,
        bounds: Aabb,
        mut walls_for: impl FnMut(&mut Rng) -> Aabb,
    ) -> Self {
        let mut rng = Rng::new(seed);
        let mut centers = Vec::with_capacity(n);
        let mut velocities = Vec::with_capacity(n);
        let mut walls = Vec::with_capacity(n);
        for _ in 0..n {
            let w = walls_for(&mut rng);
            centers.push(rng.vec3_in(w.min, w.max));
            velocities.push(rng.vec3_in(Vec3::splat(-GAS_SPEED), Vec3::splat(GAS_SPEED)));
            walls.push(w);
        }
        Gas {
            bounds,
            centers,
            velocities,
            radius: GAS_RADIUS,
            walls,
        }
    }

    /// Number of spheres.
    #[must_use]
    pub fn len(&self) -> usize {
        self.centers.len()
    }

    /// True if the scene has no spheres.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.centers.is_empty()
    }

    /// Advances every sphere by `dt` seconds, reflecting its velocity at its walls.
    pub fn step(&mut self, dt: f32) {
        for ((c, v), w) in self
            .centers
            .iter_mut()
            .zip(&mut self.velocities)
            .zip(&self.walls)
        {
            *c += *v * dt;
            for axis in 0..3 {
                if c[axis] < w.min[axis] {
                    c[axis] = 2.0 * w.min[axis] - c[axis];
                    v[axis] = v[axis].abs();
                } else if c[axis] > w.max[axis] {
                    c[axis] = 2.0 * w.max[axis] - c[axis];
                    v[axis] = -v[axis].abs();
                }
                // A very fast sphere could still be outside after one reflection.
                c[axis] = c[axis].clamp(w.min[axis], w.max[axis]);
            }
        }
    }
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
    let m = Mat3::from_quat(rotation);
    m.x_axis.abs() * half_extents.x
        + m.y_axis.abs() * half_extents.y
        + m.z_axis.abs() * half_extents.z
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

impl Scene for Gas {
    fn bounds(&self) -> Aabb {
        self.bounds
    }

    fn len(&self) -> usize {
        self.centers.len()
    }

    /// Sphere `i` has id `i`.
    fn spawns(&self, out: &mut Vec<Spawn>) {
        out.extend(self.centers.iter().enumerate().map(|(i, &center)| Spawn {
            id: i as u32,
            object: Object::Sphere {
                center,
                radius: self.radius,
            },
            is_static: false,
        }));
    }

    fn advance(&mut self, frame: &mut Frame) {
        frame.clear();
        self.step(DT);
        let radius = self.radius;
        frame.moved.extend(
            self.centers
                .iter()
                .enumerate()
                .map(|(i, &center)| (i as u32, Object::Sphere { center, radius })),
        );
    }
}

/// The `bodies` scene: dynamic oriented boxes moving like `gas` (constant orientation, the
/// AABB's centre reflected at the cube's walls), plus static boxes scattered in the cube and a
/// static floor under it.
#[derive(Clone, Debug)]
pub struct Bodies {
    /// The cube the dynamic boxes stay in.
    pub bounds: Aabb,
    /// The dynamic boxes (`Object::Cuboid`), id `i` for entry `i`.
    pub dynamic: Vec<Object>,
    /// Velocities of the dynamic boxes in m/s.
    pub velocities: Vec<Vec3>,
    /// The static boxes, floor last; ids follow the dynamic ones.
    pub statics: Vec<Object>,
    /// Per dynamic box, the box its centre is reflected in (bounds shrunk by its AABB).
    walls: Vec<Aabb>,
}

impl Bodies {
    /// `n` dynamic boxes with half-extents log-uniform in `[0.1, 2)` m and uniformly random
    /// orientation, in a cube (centred at the origin) sized for 10 % volume fraction,
    /// velocities uniform in `[-5, 5]³` m/s; plus `n / 10` static boxes of the same
    /// distribution scattered in the cube and a static floor slab on its bottom face.
    #[must_use]
    pub fn new(n: usize, seed: u64) -> Self {
        let mut rng = Rng::new(seed);
        let random_box = |rng: &mut Rng, center: Vec3| Object::Cuboid {
            center,
            half_extents: Vec3::new(
                rng.log_range(BOX_HALF_MIN, BOX_HALF_MAX),
                rng.log_range(BOX_HALF_MIN, BOX_HALF_MAX),
                rng.log_range(BOX_HALF_MIN, BOX_HALF_MAX),
            ),
            rotation: rng.rotation(),
        };
        let mut dynamic: Vec<Object> = (0..n).map(|_| random_box(&mut rng, Vec3::ZERO)).collect();
        let volume: f32 = dynamic
            .iter()
            .map(|o| match o {
                Object::Cuboid { half_extents, .. } => {
                    8.0 * half_extents.x * half_extents.y * half_extents.z
                }
                Object::Sphere { .. } => 0.0,
            })
            .sum();
        // The cube must also hold the largest rotated box (AABB half-extent up to 2·√3 m).
        let half = (0.5 * (volume / BODIES_VOLUME_FRACTION).cbrt()).max(4.0 * BOX_HALF_MAX);
        let bounds = Aabb::new(Vec3::splat(-half), Vec3::splat(half));
        let mut walls = Vec::with_capacity(n);
        let mut velocities = Vec::with_capacity(n);
        for o in &mut dynamic {
            let e = o.aabb().extent() * 0.5;
            let inner = Aabb::new(bounds.min + e, bounds.max - e);
            if let Object::Cuboid { center, .. } = o {
                *center = rng.vec3_in(inner.min, inner.max);
            }
            velocities.push(rng.vec3_in(Vec3::splat(-GAS_SPEED), Vec3::splat(GAS_SPEED)));
            walls.push(inner);
        }
        let mut statics: Vec<Object> = (0..n / 10)
            .map(|_| {
                let c = rng.vec3_in(bounds.min, bounds.max);
                random_box(&mut rng, c)
            })
            .collect();
        statics.push(Object::Cuboid {
            center: Vec3::new(0.0, -half, 0.0),
            half_extents: Vec3::new(half, FLOOR_HALF_THICKNESS, half),
            rotation: Quat::IDENTITY,
        });
        Bodies {
            bounds,
            dynamic,
            velocities,
            statics,
            walls,
        }
    }
}

impl Scene for Bodies {
    fn bounds(&self) -> Aabb {
        self.bounds
    }

    fn len(&self) -> usize {
        self.dynamic.len() + self.statics.len()
    }

    /// Dynamic box `i` has id `i`; static box `j` (the floor last) has id `dynamic.len() + j`.
    fn spawns(&self, out: &mut Vec<Spawn>) {
        let d = self.dynamic.iter().map(|&o| (o, false));
        let s = self.statics.iter().map(|&o| (o, true));
        out.extend(
            d.chain(s)
                .enumerate()
                .map(|(i, (object, is_static))| Spawn {
                    id: i as u32,
                    object,
                    is_static,
                }),
        );
    }

    fn advance(&mut self, frame: &mut Frame) {
        frame.clear();
        for ((o, v), w) in self
            .dynamic
            .iter_mut()
            .zip(&mut self.velocities)
            .zip(&self.walls)
        {
            if let Object::Cuboid { center, .. } = o {
                *center = reflect(*center + *v * DT, v, w);
            }
        }
        frame
            .moved
            .extend(self.dynamic.iter().enumerate().map(|(i, &o)| (i as u32, o)));
    }
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

/// The `churn` scene: `gas`, where each step 1 % of the spheres (rounded up) are removed,
/// as many new ones inserted (new ids, uniform position and velocity), and as many teleported
/// to a uniform position anywhere in the cube.
#[derive(Clone, Debug)]
pub struct Churn {
    /// The moving spheres; entry `i` has id `ids[i]`.
    pub gas: Gas,
    /// Id of each sphere of `gas`.
    pub ids: Vec<u32>,
    next_id: u32,
    per_step: usize,
    rng: Rng,
}

impl Churn {
    /// The `gas` scene of `n` spheres (seeded with `seed`) with churn driven by a second
    /// stream of the same seed.
    #[must_use]
    pub fn new(n: usize, seed: u64) -> Self {
        Churn {
            gas: Gas::new(n, seed),
            ids: (0..n as u32).collect(),
            next_id: n as u32,
            per_step: (n * CHURN_PERCENT).div_ceil(100),
            rng: Rng::new(seed ^ 0x00c4_u64.rotate_left(40)),
        }
    }
}

impl Scene for Churn {
    fn bounds(&self) -> Aabb {
        self.gas.bounds
    }

    fn len(&self) -> usize {
        self.ids.len()
    }

    /// Ids in the scene's current order (increasing before the first step).
    fn spawns(&self, out: &mut Vec<Spawn>) {
        let radius = self.gas.radius;
        out.extend(
            self.gas
                .centers
                .iter()
                .zip(&self.ids)
                .map(|(&center, &id)| Spawn {
                    id,
                    object: Object::Sphere { center, radius },
                    is_static: false,
                }),
        );
    }

    fn advance(&mut self, frame: &mut Frame) {
        frame.clear();
        let inner = self.gas.bounds.grown(-self.gas.radius);
        let g = &mut self.gas;
        for _ in 0..self.per_step.min(self.ids.len()) {
            let i = self.rng.below(self.ids.len() as u32) as usize;
            frame.removed.push(self.ids.swap_remove(i));
            g.centers.swap_remove(i);
            g.velocities.swap_remove(i);
            g.walls.swap_remove(i);
        }
        let first_new = self.ids.len();
        for _ in 0..self.per_step {
            g.centers.push(self.rng.vec3_in(inner.min, inner.max));
            g.velocities.push(
                self.rng
                    .vec3_in(Vec3::splat(-GAS_SPEED), Vec3::splat(GAS_SPEED)),
            );
            g.walls.push(inner);
            self.ids.push(self.next_id);
            self.next_id += 1;
        }
        for _ in 0..self.per_step.min(first_new) {
            let i = self.rng.below(first_new as u32) as usize;
            g.centers[i] = self.rng.vec3_in(inner.min, inner.max);
        }
        g.step(DT);
        let radius = g.radius;
        for (i, (&center, &id)) in g.centers.iter().zip(&self.ids).enumerate() {
            let object = Object::Sphere { center, radius };
            if i < first_new {
                frame.moved.push((id, object));
            } else {
                frame.inserted.push(Spawn {
                    id,
                    object,
                    is_static: false,
                });
            }
        }
    }
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

/// Spheres replayed from recorded centres, e.g. the `pile` scene recorded from a rapier
/// simulation (`broadleaf::rapier::record_pile`, feature `rapier`). Frame 0 is the start; each
/// `advance` moves every sphere to the next frame's centre, and after the last frame they
/// stay where they are.
#[derive(Clone, Debug)]
pub struct Recorded {
    /// The region the spheres stay in.
    pub bounds: Aabb,
    /// Radius of every sphere.
    pub radius: f32,
    /// Per frame, the centre of sphere `i` (id `i`) at index `i`; every frame has as many
    /// centres as frame 0 (longer frames are cut, shorter ones leave the rest in place).
    pub frames: Vec<Vec<Vec3>>,
    cursor: usize,
    centers: Vec<Vec3>,
}

impl Recorded {
    /// A replay of `frames` (none: an empty scene) of spheres of `radius` inside `bounds`.
    #[must_use]
    pub fn new(bounds: Aabb, radius: f32, frames: Vec<Vec<Vec3>>) -> Self {
        let centers = frames.first().cloned().unwrap_or_default();
        Recorded {
            bounds,
            radius,
            frames,
            cursor: 0,
            centers,
        }
    }
}

impl Scene for Recorded {
    fn bounds(&self) -> Aabb {
        self.bounds
    }

    fn len(&self) -> usize {
        self.centers.len()
    }

    /// Sphere `i` has id `i`.
    fn spawns(&self, out: &mut Vec<Spawn>) {
        let radius = self.radius;
        out.extend(self.centers.iter().enumerate().map(|(i, &center)| Spawn {
            id: i as u32,
            object: Object::Sphere { center, radius },
            is_static: false,
        }));
    }

    fn advance(&mut self, frame: &mut Frame) {
        frame.clear();
        if self.cursor + 1 < self.frames.len() {
            self.cursor += 1;
            for (c, &r) in self.centers.iter_mut().zip(&self.frames[self.cursor]) {
                *c = r;
            }
        }
        let radius = self.radius;
        frame.moved.extend(
            self.centers
                .iter()
                .enumerate()
                .map(|(i, &center)| (i as u32, Object::Sphere { center, radius })),
        );
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

    #[test]
    fn rotated_box_aabb_holds_its_corners() {
        let mut rng = Rng::new(9);
        for _ in 0..100 {
            let h = rng.vec3_in(Vec3::splat(0.1), Vec3::splat(2.0));
            let q = rng.rotation();
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
