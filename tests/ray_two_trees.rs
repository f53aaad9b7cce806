//! `BroadPhase::cast_ray` and `cast_sphere` walk the dynamic and the static BVH in one walk,
//! where a hit in either tree prunes the other. These worlds make the two trees compete: each
//! holds hundreds of bodies (trees several leaves deep), many bodies have a twin of the other
//! kind with the very same box (the same entry `t` from both trees, so ties between the trees
//! go to the smaller key), and some bodies are inserted after the last step (pending in their
//! tree). Rays start inside and outside the world, along the axes, through shared faces and
//! corners, and with zero length. Every answer is compared exactly with a brute-force loop over
//! the test's own record of the boxes.

mod common;

use broadleaf::geom::{self, sphere_cast_aabb};
use broadleaf::{Aabb, BodyKind, BroadPhase, Config, ProxyKey, Vec3};
use common::Rng;

/// The first hit of `hits`: smallest `t`, ties to the smaller key.
fn first_of(hits: impl Iterator<Item = (ProxyKey, Option<f32>)>) -> Option<(ProxyKey, f32)> {
    hits.filter_map(|(k, t)| t.map(|t| (t, k)))
        .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
        .map(|(t, k)| (k, t))
}

/// A box on the integer lattice of the world's cube (faces shared between neighbours), or a
/// random one.
fn random_box(rng: &mut Rng, half: f32) -> Aabb {
    if rng.chance(0.5) {
        let lo = rng.offset(half).floor();
        let size = Vec3::new(
            1.0 + rng.below(2) as f32,
            1.0 + rng.below(2) as f32,
            1.0 + rng.below(2) as f32,
        );
        Aabb::new(lo, lo + size)
    } else {
        let c = rng.offset(half);
        let h = Vec3::new(
            rng.range(0.05, 1.5),
            rng.range(0.05, 1.5),
            rng.range(0.05, 1.5),
        );
        Aabb::new(c - h, c + h)
    }
}

/// A ray origin: inside the world, outside it, or on a lattice point (a corner of boxes).
fn random_origin(rng: &mut Rng, half: f32) -> Vec3 {
    match rng.below(3) {
        0 => rng.offset(half),
        1 => rng.offset(half).normalize_or(Vec3::X) * (half * 2.5),
        _ => rng.offset(half).round(),
    }
}

/// A direction: an axis (either sign), a lattice diagonal, random, or zero.
fn random_dir(rng: &mut Rng) -> Vec3 {
    let sign = if rng.chance(0.5) { 1.0 } else { -1.0 };
    match rng.below(6) {
        0 => Vec3::X * sign,
        1 => Vec3::Y * sign,
        2 => Vec3::Z * sign,
        3 => Vec3::new(1.0, sign, -1.0),
        4 => Vec3::ZERO,
        _ => rng.offset(1.0),
    }
}

#[test]
fn rays_and_casts_over_both_trees_equal_brute_force() {
    let half = 12.0;
    for seed in 1..=3 {
        let mut rng = Rng::new(seed);
        let mut bp = BroadPhase::new(Config::default());
        let mut bodies: Vec<(ProxyKey, Aabb)> = Vec::new();
        let insert = |bp: &mut BroadPhase, bodies: &mut Vec<_>, b: Aabb, kind: BodyKind| {
            bodies.push((bp.insert_body(b, kind).unwrap(), b));
        };
        for i in 0..600 {
            let b = random_box(&mut rng, half);
            let kind = if i % 2 == 0 {
                BodyKind::Dynamic
            } else {
                BodyKind::Static
            };
            insert(&mut bp, &mut bodies, b, kind);
            // A twin of the other kind: the same entry from both trees.
            if i % 5 == 0 {
                let other = if kind == BodyKind::Dynamic {
                    BodyKind::Static
                } else {
                    BodyKind::Dynamic
                };
                insert(&mut bp, &mut bodies, b, other);
            }
        }
        for round in 0..3 {
            bp.step();
            // Pending bodies of both kinds: inserted after the step, not yet in a tree's
            // built part.
            for i in 0..20 {
                let kind = if i % 2 == 0 {
                    BodyKind::Dynamic
                } else {
                    BodyKind::Static
                };
                insert(&mut bp, &mut bodies, random_box(&mut rng, half), kind);
            }
            for q in 0..400 {
                let what = format!("seed {seed} round {round} query {q}");
                let o = random_origin(&mut rng, half);
                let d = random_dir(&mut rng);
                let max_t = [0.0, 3.0, 40.0, f32::MAX][q % 4];
                let inv = geom::inverse_dir(d);
                let want = first_of(bodies.iter().map(|&(k, b)| (k, b.ray_entry(o, inv, max_t))));
                assert_eq!(
                    bp.cast_ray(o, d, max_t),
                    want,
                    "{what}: ray {o} {d} {max_t}"
                );
                let r = [0.0, 0.25, 1.0][q % 3];
                let want = first_of(
                    bodies
                        .iter()
                        .map(|&(k, b)| (k, sphere_cast_aabb(o, r, d, max_t, &b))),
                );
                assert_eq!(
                    bp.cast_sphere(o, r, d, max_t),
                    want,
                    "{what}: cast {o} {r} {d} {max_t}"
                );
            }
        }
        bp.validate();
    }
}

/// Query `q`'s sphere cast: origin, direction, `max_t` (zero, short, long, unbounded) and
/// radius (zero, small, large) in turn.
fn random_cast(rng: &mut Rng, half: f32, q: usize) -> (Vec3, Vec3, f32, f32) {
    let o = random_origin(rng, half);
    let d = random_dir(rng);
    (
        o,
        d,
        [0.0, 3.0, 40.0, f32::MAX][q % 4],
        [0.0, 0.25, 1.0][q % 3],
    )
}

/// `Bvh::cast_sphere` over a tree with twin boxes (each twin the same `t`): the smaller key,
/// at the same `t` as brute force, including casts whose exact `f64` time rounds down to the
/// `f32` answer.
#[test]
fn bvh_sphere_casts_keep_ties_to_the_smaller_key() {
    use broadleaf::bvh::{Bvh, BvhConfig};
    let half = 12.0;
    let mut rng = Rng::new(11);
    let mut boxes = Vec::new();
    for _ in 0..400 {
        let b = random_box(&mut rng, half);
        boxes.push(b);
        if rng.chance(0.3) {
            boxes.push(b);
        }
    }
    let (bvh, keys) = Bvh::from_aabbs(BvhConfig::default(), &boxes).unwrap();
    for q in 0..2000 {
        let (o, d, max_t, r) = random_cast(&mut rng, half, q);
        let want = first_of(
            keys.iter()
                .zip(&boxes)
                .map(|(&k, b)| (k, sphere_cast_aabb(o, r, d, max_t, b))),
        );
        assert_eq!(
            bvh.cast_sphere(o, r, d, max_t),
            want,
            "query {q}: cast {o} {r} {d} {max_t}"
        );
    }
}

/// `Octree::cast_sphere` over spheres many of which have a twin (the same
/// sphere under another key, so the same `t`) or a near twin (moved by a few ulps along a
/// random axis, whose exact time may round to the same `f32`): the smaller key at the same `t`
/// as brute force over the test's own list of spheres.
#[test]
fn octree_casts_keep_ties_to_the_smaller_key() {
    use broadleaf::Placement;
    use broadleaf::octree::Octree;
    let half = 12.0;
    for placement in [Placement::Loose, Placement::Strict] {
        let mut rng = Rng::new(13);
        let mut tree = Octree::growing(placement);
        let mut spheres: Vec<(ProxyKey, Vec3, f32)> = Vec::new();
        for _ in 0..400 {
            let c = rng.offset(half);
            let r = rng.range(0.05, 1.5);
            spheres.push((tree.insert(c, r).unwrap(), c, r));
            if rng.chance(0.3) {
                let nudge = match rng.below(3) {
                    0 => Vec3::ZERO,
                    1 => Vec3::X * (c.x.abs().max(1.0) * f32::EPSILON),
                    _ => Vec3::splat(c.abs().max_element().max(1.0) * 2.0 * f32::EPSILON),
                };
                let c2 = c + nudge;
                spheres.push((tree.insert(c2, r).unwrap(), c2, r));
            }
        }
        tree.maintain();
        for q in 0..2000 {
            let (o, d, max_t, r) = random_cast(&mut rng, half, q);
            let want = first_of(
                spheres
                    .iter()
                    .map(|&(k, c, sr)| (k, geom::sphere_cast_sphere(o, r, d, max_t, c, sr))),
            );
            assert_eq!(
                tree.cast_sphere(o, r, d, max_t),
                want,
                "{placement:?} query {q}: cast {o} {r} {d} {max_t}"
            );
        }
        tree.validate();
    }
}
