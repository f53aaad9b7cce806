//! `query_sphere` reports a sphere iff the distance between the centres is at most the sum of
//! the radii, also for coordinates whose `f32` squares overflow: the test once compared
//! `|c − q|²` with `(r + R)²` in `f32`, where both became `+∞` and `∞ <= ∞` took spheres
//! `1.7e20` apart with radii summing to `1.05e20` for touching (found by the fuzz target).

use broadleaf::{BroadPhase, Config, Octree, Placement, Vec3};

/// The query `0 ± 3e19`; a far sphere whose box overlaps the query's box but whose ball is
/// `1.73e20 − 1.05e20` away; and a near sphere it does touch.
const QUERY: (Vec3, f32) = (Vec3::ZERO, 3e19);
const FAR: (Vec3, f32) = (Vec3::splat(1e20), 7.5e19);
const NEAR: (Vec3, f32) = (Vec3::new(1e20, 0.0, 0.0), 7.5e19);

#[test]
fn broadphase_query_sphere_misses_a_far_sphere_whose_squares_overflow() {
    let mut bp = BroadPhase::new(Config::default());
    let _far = bp.insert_sphere(FAR.0, FAR.1).unwrap();
    let near = bp.insert_sphere(NEAR.0, NEAR.1).unwrap();
    bp.step();
    let mut got = Vec::new();
    bp.query_sphere(QUERY.0, QUERY.1, |k| got.push(k));
    assert_eq!(got, [near]);
}

#[test]
fn octree_query_sphere_misses_a_far_sphere_whose_squares_overflow() {
    for placement in [Placement::Strict, Placement::Loose] {
        let mut tree = Octree::growing(placement);
        let _far = tree.insert(FAR.0, FAR.1).unwrap();
        let near = tree.insert(NEAR.0, NEAR.1).unwrap();
        tree.maintain();
        let mut got = Vec::new();
        tree.query_sphere(QUERY.0, QUERY.1, |k| got.push(k));
        assert_eq!(got, [near], "{placement:?}");
    }
}
