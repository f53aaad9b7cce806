//! The `bodies` scene: oriented boxes moving like `gas`, plus static boxes and a floor.

use super::{
    BODIES_VOLUME_FRACTION, BOX_HALF_MAX, BOX_HALF_MIN, DT, FLOOR_HALF_THICKNESS, Frame, GAS_SPEED,
    Object, Rng, Scene, Spawn, reflect,
};
use crate::{Aabb, Vec3};
use glam::Quat;

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
