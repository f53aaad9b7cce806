//! The octree's ray walk (each cell read once, the segment clipped to where spheres can be),
//! the BVH's slab test without NaN lanes, and the nearest search's start from the typical
//! cell: `cast_ray`, `cast_sphere` and `nearest` of `Octree`, `Bvh` and `BroadPhase` equal a
//! brute-force loop over the test's own list of shapes (through `geom`'s exact functions,
//! which the structures promise to agree with), ties to the smaller key. Rays graze cell
//! faces, edges and corners (origins and sphere boxes on the lattice's planes), run along
//! the axes and diagonals, start outside the region, have zero length or a zero direction;
//! trees are strict and loose, fixed and growing.

mod common;

use broadleaf::geom::{inverse_dir, point_aabb_distance, point_sphere_distance, ray_sphere};
use broadleaf::geom::{sphere_cast_aabb, sphere_cast_sphere};
use broadleaf::{
    Aabb, BodyKind, BroadPhase, Bvh, BvhConfig, Config, Octree, Placement, ProxyKey, Vec3,
};
use common::Rng;

/// The smallest `(t, key)`, or `None`.
fn first(hits: impl Iterator<Item = (ProxyKey, Option<f32>)>) -> Option<(ProxyKey, f32)> {
    hits.filter_map(|(k, t)| Some((k, t?)))
        .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)))
}

/// The first `k` of `(key, distance)` in `(distance, key)` order.
fn nearest_k(mut all: Vec<(ProxyKey, f32)>, k: usize) -> Vec<(ProxyKey, f32)> {
    all.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    all.truncate(k);
    all
}

/// Directions along the axes, the face and space diagonals, and a few random ones.
fn directions(rng: &mut Rng) -> Vec<Vec3> {
    let mut d = Vec::new();
    for a in [-1.0f32, 0.0, 1.0] {
        for b in [-1.0f32, 0.0, 1.0] {
            for c in [-1.0f32, 0.0, 1.0] {
                d.push(Vec3::new(a, b, c));
            }
        }
    }
    for _ in 0..6 {
        d.push(rng.vec3_in(Vec3::splat(-1.0), Vec3::splat(1.0)));
    }
    d
}

/// Ray origins: on lattice corners, edges and faces (whole and half cells of `cell`), random
/// inside, and outside the region `±half`.
fn origins(rng: &mut Rng, half: f32, cell: f32) -> Vec<Vec3> {
    let mut o = vec![
        Vec3::ZERO,
        Vec3::splat(cell),
        Vec3::new(cell, 0.5 * cell, 0.0),
    ];
    for _ in 0..6 {
        let lattice = |rng: &mut Rng| (rng.below(16) as f32 - 8.0) * cell;
        o.push(Vec3::new(lattice(rng), lattice(rng), lattice(rng)));
        o.push(rng.vec3_in(Vec3::splat(-half), Vec3::splat(half)));
    }
    o.push(Vec3::new(-2.5 * half, 0.0, 0.0));
    o.push(Vec3::new(2.5 * half, 3.0 * cell, -2.5 * half));
    o.push(Vec3::splat(-3.0 * half));
    o
}

/// Spheres whose boxes lie on the lattice's planes (centres on corners, faces and mid-cells,
/// radii of whole and half cells), random ones, a few of radius 0 and a few coincident.
fn shapes(rng: &mut Rng, half: f32, cell: f32) -> Vec<(Vec3, f32)> {
    let mut s = Vec::new();
    for i in 0..150 {
        let lattice = |rng: &mut Rng| (rng.below(24) as f32 - 12.0) * 0.5 * cell;
        let c = if i % 3 == 0 {
            rng.vec3_in(Vec3::splat(-half), Vec3::splat(half))
        } else {
            Vec3::new(lattice(rng), lattice(rng), lattice(rng))
        };
        let r = match i % 7 {
            0 => 0.0,
            1 => cell,
            2 => 0.5 * cell,
            3 => rng.range(1.0, 3.0) * cell,
            _ => rng.range(0.05, 0.5) * cell,
        };
        s.push((c, r));
        if i % 25 == 0 {
            s.push((c, r));
        }
    }
    s
}

/// Every query of the octree against brute force over `live`.
fn check_octree(
    tree: &Octree,
    live: &[(ProxyKey, Vec3, f32)],
    rng: &mut Rng,
    half: f32,
    cell: f32,
) {
    tree.validate();
    for o in origins(rng, half, cell) {
        for d in directions(rng) {
            for max_t in [0.0, 0.75 * cell, 4.0 * half] {
                let want = first(
                    live.iter()
                        .map(|&(k, c, r)| (k, ray_sphere(o, d, c, r, max_t))),
                );
                assert_eq!(tree.cast_ray(o, d, max_t), want, "ray {o} {d} {max_t}");
                let radius = [0.0, 0.3 * cell, cell][rng.below(3)];
                let want = first(
                    live.iter()
                        .map(|&(k, c, r)| (k, sphere_cast_sphere(o, radius, d, max_t, c, r))),
                );
                assert_eq!(
                    tree.cast_sphere(o, radius, d, max_t),
                    want,
                    "cast {o} {radius} {d} {max_t}"
                );
            }
        }
        for k in [1, 3, 40] {
            let all = live
                .iter()
                .map(|&(key, c, r)| (key, point_sphere_distance(o, c, r)))
                .collect();
            assert_eq!(tree.nearest(o, k), nearest_k(all, k), "nearest {o} {k}");
        }
    }
}

#[test]
fn octree_rays_casts_and_nearest_equal_brute_force_on_the_lattice() {
    let (half, cell) = (16.0, 1.0);
    for placement in [Placement::Strict, Placement::Loose] {
        for growing in [false, true] {
            let mut rng = Rng::new(7 + u64::from(growing) + 2 * (placement as u64));
            let mut tree = if growing {
                Octree::growing(placement)
            } else {
                let bounds = Aabb::new(Vec3::splat(-half), Vec3::splat(half));
                // Depth 5: cells of one `cell` at the deepest level.
                Octree::with_placement(bounds, 5, placement).unwrap()
            };
            let mut live: Vec<(ProxyKey, Vec3, f32)> = shapes(&mut rng, half, cell)
                .into_iter()
                .map(|(c, r)| (tree.insert(c, r).unwrap(), c, r))
                .collect();
            tree.maintain();
            check_octree(&tree, &live, &mut rng, half, cell);
            // Churn: removals and moves (some out of the region), then the queries again,
            // before and after the growing tree follows.
            for _ in 0..30 {
                let i = rng.below(live.len());
                tree.remove(live.swap_remove(i).0).unwrap();
            }
            for _ in 0..40 {
                let i = rng.below(live.len());
                let c = rng.vec3_in(Vec3::splat(-1.4 * half), Vec3::splat(1.4 * half));
                tree.update(live[i].0, c, live[i].2).unwrap();
                live[i].1 = c;
            }
            check_octree(&tree, &live, &mut rng, half, cell);
            tree.maintain();
            check_octree(&tree, &live, &mut rng, half, cell);
        }
    }
}

#[test]
fn octree_rays_through_one_level_of_small_spheres_read_no_sphere_twice_and_miss_exactly() {
    // A dense single-level world like `gas` (the walk's common case) with rays that miss
    // every sphere and end in empty room, and rays along the cell planes between spheres.
    for placement in [Placement::Strict, Placement::Loose] {
        let mut tree = Octree::growing(placement);
        let mut live = Vec::new();
        for x in 0..12 {
            for y in 0..12 {
                for z in 0..12 {
                    let c = Vec3::new(x as f32, y as f32, z as f32) * 2.0;
                    live.push((tree.insert(c, 0.5).unwrap(), c, 0.5));
                }
            }
        }
        tree.maintain();
        let mut rng = Rng::new(3);
        for q in 0..600 {
            let o = match q % 3 {
                0 => Vec3::new(1.0, 1.0, rng.range(-5.0, 30.0)),
                1 => rng.vec3_in(Vec3::splat(-10.0), Vec3::splat(32.0)),
                _ => Vec3::new(rng.below(12) as f32 * 2.0 + 1.0, 1.0, -4.0),
            };
            let d = match q % 4 {
                0 => Vec3::Z,
                1 => Vec3::new(0.0, 0.0, -1.0),
                2 => Vec3::new(1.0, 1.0, 0.0),
                _ => rng.vec3_in(Vec3::splat(-1.0), Vec3::splat(1.0)),
            };
            let max_t = rng.range(0.0, 60.0);
            let want = first(
                live.iter()
                    .map(|&(k, c, r)| (k, ray_sphere(o, d, c, r, max_t))),
            );
            assert_eq!(
                tree.cast_ray(o, d, max_t),
                want,
                "query {q}: ray {o} {d} {max_t}"
            );
            let mut seen = std::collections::BTreeSet::new();
            tree.cast_ray_all(o, d, max_t, |k, _| assert!(seen.insert(k), "hit twice"));
            let hits = live
                .iter()
                .filter(|&&(_, c, r)| ray_sphere(o, d, c, r, max_t).is_some())
                .count();
            assert_eq!(seen.len(), hits, "query {q}");
        }
    }
}

#[test]
fn bvh_rays_along_axes_and_faces_equal_brute_force() {
    // Boxes with faces on integer planes; rays with zero direction components lying in those
    // planes (the NaN lanes of the slab test) and rays without any (the NaN-free test).
    let mut rng = Rng::new(11);
    let mut boxes = Vec::new();
    for i in 0..300 {
        let lo = Vec3::new(
            rng.below(20) as f32 - 10.0,
            rng.below(20) as f32 - 10.0,
            rng.below(20) as f32 - 10.0,
        );
        let size = if i % 9 == 0 {
            Vec3::new(0.0, rng.below(3) as f32, 1.0)
        } else {
            Vec3::new(
                1.0 + rng.below(2) as f32,
                1.0 + rng.below(2) as f32,
                rng.range(0.25, 2.0),
            )
        };
        boxes.push(Aabb::new(lo, lo + size));
    }
    let config = BvhConfig {
        max_leaf_size: 3,
        ..BvhConfig::default()
    };
    let (mut bvh, keys) = Bvh::from_aabbs(config, &boxes).unwrap();
    let mut live: Vec<(ProxyKey, Aabb)> = keys.into_iter().zip(boxes).collect();
    // Pending inserts and tombstones beside the built tree.
    for _ in 0..20 {
        let lo = rng.vec3_in(Vec3::splat(-10.0), Vec3::splat(10.0));
        let b = Aabb::new(lo, lo + Vec3::ONE);
        live.push((bvh.insert(b).unwrap(), b));
    }
    for _ in 0..20 {
        let i = rng.below(live.len());
        bvh.remove(live.swap_remove(i).0).unwrap();
    }
    bvh.validate();
    for q in 0..2000 {
        let o = match q % 3 {
            0 => Vec3::new(
                rng.below(24) as f32 - 12.0,
                rng.below(24) as f32 - 12.0,
                rng.below(24) as f32 - 12.0,
            ),
            1 => rng.vec3_in(Vec3::splat(-15.0), Vec3::splat(15.0)),
            _ => Vec3::new(-30.0, rng.below(20) as f32 - 10.0, 0.5),
        };
        let d = match q % 5 {
            0 => Vec3::X,
            1 => Vec3::new(0.0, -1.0, 0.0),
            2 => Vec3::new(1.0, 1.0, 0.0),
            3 => Vec3::ZERO,
            _ => rng.vec3_in(Vec3::splat(-1.0), Vec3::splat(1.0)),
        };
        let max_t = [0.0, 3.0, 100.0][q % 3];
        let inv = inverse_dir(d);
        let want = first(live.iter().map(|&(k, b)| (k, b.ray_entry(o, inv, max_t))));
        assert_eq!(
            bvh.cast_ray(o, d, max_t),
            want,
            "query {q}: ray {o} {d} {max_t}"
        );
        let radius = [0.0, 0.5][q % 2];
        let want = first(
            live.iter()
                .map(|&(k, b)| (k, sphere_cast_aabb(o, radius, d, max_t, &b))),
        );
        assert_eq!(
            bvh.cast_sphere(o, radius, d, max_t),
            want,
            "query {q}: cast"
        );
        let k = 1 + q % 4;
        let all = live
            .iter()
            .map(|&(key, b)| (key, point_aabb_distance(o, &b)))
            .collect();
        assert_eq!(bvh.nearest(o, k), nearest_k(all, k), "query {q}: nearest");
    }
}

#[test]
fn broadphase_rays_and_nearest_equal_brute_force_over_spheres_and_bodies() {
    // The broadphase's growing octree (its nearest search starts from the typical cell) with
    // bodies beside it, after steps that move the spheres.
    let mut rng = Rng::new(5);
    let mut bp = BroadPhase::new(Config::default());
    let mut spheres: Vec<(ProxyKey, Vec3, f32)> = Vec::new();
    let mut bodies: Vec<(ProxyKey, Aabb)> = Vec::new();
    for i in 0..400 {
        let c = rng.vec3_in(Vec3::splat(-20.0), Vec3::splat(20.0));
        let r = if i % 10 == 0 { 2.0 } else { 0.5 };
        spheres.push((bp.insert_sphere(c, r).unwrap(), c, r));
    }
    for i in 0..40 {
        let lo = rng.vec3_in(Vec3::splat(-25.0), Vec3::splat(25.0));
        let b = Aabb::new(lo, lo + rng.vec3_in(Vec3::splat(0.1), Vec3::splat(3.0)));
        let kind = if i % 3 == 0 {
            BodyKind::Static
        } else {
            BodyKind::Dynamic
        };
        bodies.push((bp.insert_body(b, kind).unwrap(), b));
    }
    for step in 0..4 {
        bp.step();
        for q in 0..300 {
            let o = rng.vec3_in(Vec3::splat(-30.0), Vec3::splat(30.0));
            let d = match q % 4 {
                0 => Vec3::Y,
                1 => Vec3::ZERO,
                _ => rng.vec3_in(Vec3::splat(-1.0), Vec3::splat(1.0)),
            };
            let max_t = [0.0, 10.0, 100.0][q % 3];
            let inv = inverse_dir(d);
            let want = first(
                spheres
                    .iter()
                    .map(|&(k, c, r)| (k, ray_sphere(o, d, c, r, max_t)))
                    .chain(bodies.iter().map(|&(k, b)| (k, b.ray_entry(o, inv, max_t)))),
            );
            assert_eq!(bp.cast_ray(o, d, max_t), want, "step {step} query {q}: ray");
            let k = [1, 2, 7][q % 3];
            let all = spheres
                .iter()
                .map(|&(key, c, r)| (key, point_sphere_distance(o, c, r)))
                .chain(
                    bodies
                        .iter()
                        .map(|&(key, b)| (key, point_aabb_distance(o, &b))),
                )
                .collect();
            assert_eq!(
                bp.nearest(o, k),
                nearest_k(all, k),
                "step {step} query {q}: nearest"
            );
        }
        for s in &mut spheres {
            s.1 += rng.vec3_in(Vec3::splat(-1.0), Vec3::splat(1.0));
            bp.update_sphere(s.0, s.1, s.2).unwrap();
        }
    }
}

#[test]
fn loose_spheres_poking_out_of_the_bounds_are_hit_by_rays_passing_outside_them() {
    // A loose sphere's box reaches half a cell of its level past the bounds: rays that run
    // outside the bounds but through that half cell must find it, for each level.
    let half = 16.0;
    let bounds = Aabb::new(Vec3::splat(-half), Vec3::splat(half));
    let mut tree = Octree::with_placement(bounds, 5, Placement::Loose).unwrap();
    let mut live = Vec::new();
    for (i, r) in [7.9f32, 3.9, 1.9, 0.9, 0.45].into_iter().enumerate() {
        let c = Vec3::new(half - 0.01, 6.0 * i as f32 - 12.0, 0.3);
        live.push((tree.insert(c, r).unwrap(), c, r));
    }
    tree.validate();
    for &(_, c, r) in &live {
        for dx in [0.25f32, 0.5, 0.9] {
            let x = half + (r - 0.01) * dx;
            for (o, d) in [
                (Vec3::new(x, -3.0 * half, c.z), Vec3::Y),
                (Vec3::new(x, c.y, 3.0 * half), Vec3::new(0.0, 0.0, -1.0)),
                (
                    Vec3::new(x, c.y - 2.0 * half, c.z + 0.1),
                    Vec3::new(0.0, 1.0, 0.01),
                ),
            ] {
                let max_t = 8.0 * half;
                let want = first(
                    live.iter()
                        .map(|&(k, c, r)| (k, ray_sphere(o, d, c, r, max_t))),
                );
                assert!(want.is_some(), "the ray {o} {d} was meant to hit");
                assert_eq!(tree.cast_ray(o, d, max_t), want, "ray {o} {d}");
                let want = first(
                    live.iter()
                        .map(|&(k, c, r)| (k, sphere_cast_sphere(o, 0.0, d, max_t, c, r))),
                );
                assert_eq!(tree.cast_sphere(o, 0.0, d, max_t), want, "cast {o} {d}");
            }
        }
    }
}
