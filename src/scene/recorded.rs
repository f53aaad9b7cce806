//! Spheres replayed from recorded centres (the `pile` scene).

use super::{Frame, Object, Scene, Spawn};
use crate::{Aabb, Vec3};

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
