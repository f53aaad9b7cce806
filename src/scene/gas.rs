//! The `gas`, `clustered` and `churn` scenes: spheres moving in straight lines in a box.

use super::{
    CHURN_PERCENT, CLUSTER_HALF_WIDTH, DT, Frame, GAS_RADIUS, GAS_SPEED, GAS_VOLUME_FRACTION,
    Object, Rng, Scene, Spawn, cube_edge, reflect,
};
use crate::{Aabb, Vec3};

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
            *c = reflect(*c + *v * dt, v, w);
        }
    }
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
