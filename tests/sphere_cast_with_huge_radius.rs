//! A sphere cast whose radius dwarfs the octree's cells is exact and reads each cell once: the
//! octree's piecewise ray walk once grew every piece of the segment by the cast's radius, so
//! each of up to 65 536 pieces read every cell of the deepest level (a cast of radius 6.5e19
//! beside two spheres ran past the fuzz target's time limit; this world took seconds per cast).
//! Such casts now walk the occupied subtrees once; this test checks their answers.

use broadleaf::{BroadPhase, Config, Vec3};

#[test]
fn a_sphere_cast_of_huge_radius_touches_the_smaller_key_at_its_start() {
    let mut bp = BroadPhase::new(Config::default());
    let a = bp.insert_sphere(Vec3::ZERO, 0.5).unwrap();
    let b = bp.insert_sphere(Vec3::new(3.0, 0.0, 0.0), 0.5).unwrap();
    // Enough small spheres for a deep octree: the pieces are a fraction of a metre.
    for i in 0..2000 {
        let p = Vec3::new((i % 20) as f32, ((i / 20) % 10) as f32, (i / 200) as f32) * 0.3;
        bp.insert_sphere(p + Vec3::new(10.0, 0.0, 0.0), 0.01)
            .unwrap();
    }
    bp.step();
    let first = a.min(b);
    for (dir, max_t) in [
        (Vec3::X, 0.0),
        (Vec3::X, 50.0),
        (Vec3::new(0.3, -1.0, 0.2), 1e3),
    ] {
        let hit = bp.cast_sphere(Vec3::new(-5.0, 0.0, 0.0), 6.5e19, dir, max_t);
        // Every sphere is inside the cast sphere at t = 0: the smallest key is the answer.
        let smallest = bp.iter().map(|(k, _)| k).min().unwrap();
        assert_eq!(hit, Some((smallest, 0.0)), "dir {dir} max_t {max_t}");
        assert!(smallest <= first);
    }
}
