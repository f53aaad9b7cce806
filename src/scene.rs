//! Seeded scene generators shared by tests, examples and benches (see `benchmarks.md`): the
//! same seed gives the same motion everywhere, so a number can be reproduced with one command.

use crate::{Aabb, Vec3};

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
}
