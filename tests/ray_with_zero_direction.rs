//! A ray with a zero direction is a point test at its origin, and answers at once: the
//! octree's piecewise ray walk once cut it into pieces of length `cell / 0 = ∞`, whose first
//! piece (at `t = 0 · ∞ = NaN`) was a box over every cell of the deepest level, so a cast
//! from beside a single sphere of radius 0 ran for minutes (found by the fuzz target).

use broadleaf::{BroadPhase, Config, Vec3};

#[test]
fn a_ray_with_zero_direction_hits_the_sphere_it_starts_in() {
    let mut bp = BroadPhase::new(Config::default());
    let key = bp.insert_sphere(Vec3::ZERO, 0.0).unwrap();
    let beside = bp.insert_sphere(Vec3::new(3.0, 0.0, 0.0), 0.0).unwrap();
    bp.step();
    assert_eq!(bp.cast_ray(Vec3::ZERO, Vec3::ZERO, 0.0), Some((key, 0.0)));
    assert_eq!(bp.cast_ray(Vec3::ZERO, Vec3::ZERO, 10.0), Some((key, 0.0)));
    assert_eq!(
        bp.cast_ray(Vec3::new(3.0, 0.0, 0.0), Vec3::ZERO, 1.0),
        Some((beside, 0.0))
    );
    assert_eq!(bp.cast_ray(Vec3::new(1.0, 0.0, 0.0), Vec3::ZERO, 1.0), None);
}
