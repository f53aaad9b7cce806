//! The standard scene: spheres dropped on a jittered grid into an open box sized for them.

use super::{Material, World, WorldConfig};
use crate::scene::Rng;
use crate::{Aabb, Error, Vec3};

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
    /// Octree depth is chosen so the deepest cells are at least this many diameters wide
    /// along the container's longest side; with a loose octree
    /// ([`Placement::Loose`](crate::octree::Placement::Loose) in
    /// `world.broadphase.octree_placement`), half as many along its shortest side, as
    /// [`crate::octree::depth_for_loose`] does (a loose cell holds spheres up to its width).
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
        // Strict cells of at least `cell` (along the longest side) and loose ones of at least
        // `cell / 2` (along the shortest) are the ones the placements pick for spheres of
        // radius `cell / 4`.
        world_config.broadphase.octree_depth = if cell > 0.0 {
            world_config
                .broadphase
                .octree_placement
                .depth_for(&outer, cell / 4.0)
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
