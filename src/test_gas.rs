//! The `gas` and `clustered` spheres for the library's own unit tests, which must not depend on
//! the `fixtures` feature. It draws from [`Rng`] in the order `fixtures::scene::Gas` does, so a
//! seed gives the same spheres as the scene of benchmarks.md (a fixtures test checks they agree).

use crate::rng::Rng;
use crate::{Aabb, Vec3};

/// Radius of every sphere, in metres.
const RADIUS: f32 = 0.5;
/// Volume fraction the cube is sized for.
const VOLUME_FRACTION: f32 = 0.1;
/// Each velocity component is uniform in `[-SPEED, SPEED]` m/s.
const SPEED: f32 = 5.0;
/// Half-thickness of the `clustered` slabs around the cube's mid-planes, in metres.
const CLUSTER_HALF_WIDTH: f32 = 2.0;

/// Spheres moving in straight lines inside a cube, reflecting at their walls.
#[derive(Clone, Debug)]
pub(crate) struct Gas {
    pub(crate) bounds: Aabb,
    pub(crate) centers: Vec<Vec3>,
    pub(crate) radius: f32,
    velocities: Vec<Vec3>,
    walls: Vec<Aabb>,
}

impl Gas {
    /// `n` spheres uniform in a cube sized for 10 % volume fraction, centred at the origin.
    pub(crate) fn new(n: usize, seed: u64) -> Self {
        let bounds = cube(n);
        let inner = bounds.grown(-RADIUS);
        Self::generate(n, seed, bounds, |_| inner)
    }

    /// The same cube, every sphere within 2 m of one of its three mid-planes.
    pub(crate) fn clustered(n: usize, seed: u64) -> Self {
        let bounds = cube(n);
        let inner = bounds.grown(-RADIUS);
        let w = CLUSTER_HALF_WIDTH.min(bounds.max.x);
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
        let (mut centers, mut velocities, mut walls) = (Vec::new(), Vec::new(), Vec::new());
        for _ in 0..n {
            let w = walls_for(&mut rng);
            centers.push(rng.vec3_in(w.min, w.max));
            velocities.push(rng.vec3_in(Vec3::splat(-SPEED), Vec3::splat(SPEED)));
            walls.push(w);
        }
        Gas {
            bounds,
            centers,
            radius: RADIUS,
            velocities,
            walls,
        }
    }

    pub(crate) fn len(&self) -> usize {
        self.centers.len()
    }

    /// Advances every sphere by `dt` seconds, reflecting it back into its walls.
    pub(crate) fn step(&mut self, dt: f32) {
        for ((c, v), w) in self
            .centers
            .iter_mut()
            .zip(&mut self.velocities)
            .zip(&self.walls)
        {
            let mut p = *c + *v * dt;
            for axis in 0..3 {
                if p[axis] < w.min[axis] {
                    p[axis] = 2.0 * w.min[axis] - p[axis];
                    v[axis] = v[axis].abs();
                } else if p[axis] > w.max[axis] {
                    p[axis] = 2.0 * w.max[axis] - p[axis];
                    v[axis] = -v[axis].abs();
                }
                p[axis] = p[axis].clamp(w.min[axis], w.max[axis]);
            }
            *c = p;
        }
    }
}

/// The cube, centred at the origin, that holds `n` spheres at the volume fraction.
fn cube(n: usize) -> Aabb {
    let sphere = 4.0 / 3.0 * core::f32::consts::PI * RADIUS * RADIUS * RADIUS;
    let half = (n.max(1) as f32 * sphere / VOLUME_FRACTION).cbrt() * 0.5;
    Aabb::new(Vec3::splat(-half), Vec3::splat(half))
}
