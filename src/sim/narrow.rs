//! The narrow phase: contact geometry of sphere–sphere and sphere–box, and the pass that turns
//! the broadphase's pairs into the solver's contacts.

use super::solve::{Contact, NONE};
use super::{Owner, World};
use crate::{Aabb, Vec3};

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

impl World {
    /// Turns this step's pairs into contacts (in pair order), carrying over the impulses of
    /// the previous step's contact of the same pair. Returns the number of overlapping
    /// contacts and the deepest overlap.
    pub(super) fn narrow_phase(&mut self) -> (usize, f32) {
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
}
