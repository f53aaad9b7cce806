//! The structure-level queries of `Octree` and `Bvh` — `cast_sphere`, `nearest` and
//! `Bvh::query_sphere` — on random worlds, against a brute-force loop over the test's own list
//! of shapes with the test's own geometry (`reference`, in `f64`, with a tolerance), and
//! exactly against the same loop over `geom`'s functions (which the structures promise to
//! agree with: their traversals may prune only what those functions reject). Then the cases
//! with known answers: grazing contact, ties, zero radius and direction, starts inside, huge
//! and overflowing coordinates, and arguments that must find nothing.

mod common;
mod reference;

use broadleaf::geom::{
    point_aabb_distance, point_sphere_distance, sphere_cast_aabb, sphere_cast_sphere,
};
use broadleaf::{Aabb, Bvh, BvhConfig, Octree, Placement, ProxyKey, Vec3};
use common::Rng;
use reference::{Cast, CastExpect, Target, box_distance, check_nearest, p, sphere_distance};

/// A world of spheres: the tree and the test's own list of what is live in it.
struct Spheres {
    tree: Octree,
    shapes: Vec<(ProxyKey, Vec3, f32)>,
}

/// A world of boxes: the tree and the test's own list of what is live in it.
struct Boxes {
    bvh: Bvh,
    shapes: Vec<(ProxyKey, Aabb)>,
}

/// About 400 spheres in bounds `±scale`, some outside them, some of radius 0, some large,
/// some coincident; then removals and moves, so the lists the queries follow have churned.
fn spheres(seed: u64, placement: Placement, scale: f32) -> Spheres {
    let mut rng = Rng::new(seed);
    let bounds = Aabb::new(Vec3::splat(-scale), Vec3::splat(scale));
    let mut tree = Octree::with_placement(bounds, 5, placement).unwrap();
    let mut shapes: Vec<(ProxyKey, Vec3, f32)> = Vec::new();
    let sphere = |rng: &mut Rng| {
        let c = rng.offset(scale * 1.2);
        let r = match rng.below(20) {
            0 | 1 => 0.0,
            2 => rng.range(0.2, 0.6) * scale,
            _ => rng.range(0.002, 0.05) * scale,
        };
        (c, r)
    };
    for _ in 0..420 {
        let (c, r) = match shapes.last() {
            Some(&(_, c, r)) if rng.chance(0.03) => (c, r),
            _ => sphere(&mut rng),
        };
        shapes.push((tree.insert(c, r).unwrap(), c, r));
    }
    for _ in 0..20 {
        let i = rng.below(shapes.len());
        tree.remove(shapes.swap_remove(i).0).unwrap();
    }
    for _ in 0..60 {
        let i = rng.below(shapes.len());
        let (c, r) = sphere(&mut rng);
        tree.update(shapes[i].0, c, r).unwrap();
        (shapes[i].1, shapes[i].2) = (c, r);
    }
    tree.validate();
    Spheres { tree, shapes }
}

fn random_box(rng: &mut Rng, scale: f32) -> Aabb {
    let c = rng.offset(scale * 1.2);
    let half = match rng.below(10) {
        0 => Vec3::ZERO,
        1 => Vec3::new(rng.range(0.0, 0.5), 0.0, rng.range(0.0, 0.5)) * scale,
        2 => rng.vec3_in(Vec3::ZERO, Vec3::splat(0.3 * scale)),
        _ => rng.vec3_in(Vec3::ZERO, Vec3::splat(0.04 * scale)),
    };
    Aabb::new(c - half, c + half)
}

/// About 400 boxes: a built tree, then pending inserts, removals (tombstones and pending),
/// and moves since the last refit; some boxes flat or points, some coincident.
fn boxes(seed: u64, scale: f32) -> Boxes {
    let mut rng = Rng::new(seed);
    let mut list: Vec<Aabb> = Vec::new();
    for _ in 0..360 {
        let b = match list.last() {
            Some(&b) if rng.chance(0.03) => b,
            _ => random_box(&mut rng, scale),
        };
        list.push(b);
    }
    let config = BvhConfig {
        max_leaf_size: 4,
        ..BvhConfig::default()
    };
    let (mut bvh, keys) = Bvh::from_aabbs(config, &list).unwrap();
    let mut shapes: Vec<(ProxyKey, Aabb)> = keys.into_iter().zip(list).collect();
    for _ in 0..60 {
        let b = random_box(&mut rng, scale);
        shapes.push((bvh.insert(b).unwrap(), b));
    }
    for _ in 0..30 {
        let i = rng.below(shapes.len());
        bvh.remove(shapes.swap_remove(i).0).unwrap();
    }
    for _ in 0..40 {
        let i = rng.below(shapes.len());
        let b = random_box(&mut rng, scale);
        bvh.update(shapes[i].0, b).unwrap();
        shapes[i].1 = b;
    }
    bvh.validate();
    Boxes { bvh, shapes }
}

fn random_cast(rng: &mut Rng, scale: f32) -> Cast {
    Cast {
        o: rng.offset(scale * 1.5),
        r: match rng.below(5) {
            0 => 0.0,
            1 => rng.range(0.1, 0.3) * scale,
            _ => rng.range(0.0, 0.05) * scale,
        },
        d: match rng.below(8) {
            0 => Vec3::ZERO,
            1 => Vec3::Y * rng.range(-1.0, 1.0),
            _ => rng.offset(1.0),
        },
        max_t: if rng.chance(0.05) {
            0.0
        } else {
            rng.range(0.0, 3.0) * scale
        },
    }
}

/// A cast whose centre passes the sphere `(c, rs)` at exactly the sum of the radii (in real
/// numbers; rounding makes it a hair's touch or miss, which `geom` and the tree must agree on).
fn grazing_sphere(rng: &mut Rng, c: Vec3, rs: f32, scale: f32) -> Cast {
    let u = rng.offset(1.0).normalize_or(Vec3::X);
    let w = u
        .cross(rng.offset(1.0))
        .normalize_or(u.any_orthonormal_vector());
    let r = rng.range(0.0, 0.05) * scale;
    let (along, speed) = (rng.range(0.1, 1.0) * scale, rng.range(0.5, 2.0));
    Cast {
        o: c + w * (rs + r) - u * along,
        r,
        d: u * speed,
        max_t: 2.0 * along / speed,
    }
}

/// A cast moving along one axis whose centre passes a face or an edge of `b` at exactly the
/// radius (in real numbers).
fn grazing_box(rng: &mut Rng, b: &Aabb, scale: f32) -> Cast {
    let a = rng.below(3);
    let side = (a + 1 + rng.below(2)) % 3;
    let other = 3 - a - side;
    let r = rng.range(0.0, 0.05) * scale;
    let angle = if rng.chance(0.5) {
        0.0
    } else {
        rng.range(0.0, core::f32::consts::FRAC_PI_2)
    };
    let mut o = b.center();
    o[side] = b.max[side] + r * angle.cos();
    o[other] = if angle == 0.0 {
        rng.range(b.min[other], b.max[other])
    } else {
        b.max[other] + r * angle.sin()
    };
    let along = rng.range(0.1, 1.0) * scale;
    o[a] = b.min[a] - along;
    let mut d = Vec3::ZERO;
    d[a] = rng.range(0.5, 2.0);
    Cast {
        o,
        r,
        d,
        max_t: 2.0 * (along + b.max[a] - b.min[a]) / d[a],
    }
}

/// The smallest `(t, key)` over the shapes' own casts: what `cast_sphere` must return exactly.
fn first_of(hits: impl Iterator<Item = (ProxyKey, Option<f32>)>) -> Option<(ProxyKey, f32)> {
    hits.filter_map(|(k, t)| t.map(|t| (t, k)))
        .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
        .map(|(t, k)| (k, t))
}

/// The first `k` of `(key, distance)` in `(distance, key)` order: what `nearest` must return.
fn first_k(mut all: Vec<(ProxyKey, f32)>, k: usize) -> Vec<(ProxyKey, f32)> {
    all.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    all.truncate(k);
    all
}

fn index_of<T>(shapes: &[(ProxyKey, T)], key: ProxyKey) -> usize {
    shapes.iter().position(|s| s.0 == key).expect("a live key")
}

const SCALES: [f32; 2] = [10.0, 1e30];

#[test]
fn octree_cast_sphere_matches_the_reference() {
    for scale in SCALES {
        for (seed, placement) in [(1, Placement::Strict), (2, Placement::Loose)] {
            let w = spheres(seed, placement, scale);
            let targets: Vec<Target> = w.shapes.iter().map(|s| Target::Sphere(s.1, s.2)).collect();
            let by_index: Vec<(ProxyKey, ())> = w.shapes.iter().map(|s| (s.0, ())).collect();
            let mut rng = Rng::new(seed + 1000);
            let mut hits = 0;
            for q in 0..400 {
                let c = if q % 4 == 0 {
                    let s = w.shapes[rng.below(w.shapes.len())];
                    grazing_sphere(&mut rng, s.1, s.2, scale)
                } else {
                    random_cast(&mut rng, scale)
                };
                let got = w.tree.cast_sphere(c.o, c.r, c.d, c.max_t);
                let what = format!("{scale} {placement:?} query {q} {c:?} -> {got:?}");
                let want = first_of(w.shapes.iter().map(|&(k, center, r)| {
                    (k, sphere_cast_sphere(c.o, c.r, c.d, c.max_t, center, r))
                }));
                assert_eq!(got, want, "{what}: not geom's first hit");
                let eps = 1e-5 * f64::from(scale);
                let t_tol = eps / f64::from(c.d.length()).max(1e-30);
                let got = got.map(|(k, t)| (index_of(&by_index, k), t));
                CastExpect::new(&c, &targets, eps).check(&c, &targets, got, eps, t_tol, &what);
                hits += usize::from(got.is_some());
            }
            assert!(hits > 100, "{scale} {placement:?}: only {hits} hits");
        }
    }
}

#[test]
fn bvh_cast_sphere_matches_the_reference() {
    for scale in SCALES {
        let w = boxes(3, scale);
        let targets: Vec<Target> = w.shapes.iter().map(|s| Target::Box(s.1)).collect();
        let mut rng = Rng::new(1003);
        let mut hits = 0;
        for q in 0..400 {
            let c = if q % 4 == 0 {
                let s = w.shapes[rng.below(w.shapes.len())];
                grazing_box(&mut rng, &s.1, scale)
            } else {
                random_cast(&mut rng, scale)
            };
            let got = w.bvh.cast_sphere(c.o, c.r, c.d, c.max_t);
            let what = format!("{scale} query {q} {c:?} -> {got:?}");
            let want = first_of(
                w.shapes
                    .iter()
                    .map(|(k, b)| (*k, sphere_cast_aabb(c.o, c.r, c.d, c.max_t, b))),
            );
            assert_eq!(got, want, "{what}: not geom's first hit");
            let eps = 1e-5 * f64::from(scale);
            let t_tol = eps / f64::from(c.d.length()).max(1e-30);
            let got = got.map(|(k, t)| (index_of(&w.shapes, k), t));
            CastExpect::new(&c, &targets, eps).check(&c, &targets, got, eps, t_tol, &what);
            hits += usize::from(got.is_some());
        }
        assert!(hits > 100, "{scale}: only {hits} hits");
    }
}

fn random_point(rng: &mut Rng, scale: f32) -> Vec3 {
    if rng.chance(0.1) {
        rng.offset(scale * 20.0)
    } else {
        rng.offset(scale * 1.5)
    }
}

const KS: [usize; 6] = [1, 1, 2, 5, 17, 1000];

#[test]
fn octree_nearest_matches_the_reference() {
    for scale in SCALES {
        for (seed, placement) in [(4, Placement::Strict), (5, Placement::Loose)] {
            let w = spheres(seed, placement, scale);
            let by_index: Vec<(ProxyKey, ())> = w.shapes.iter().map(|s| (s.0, ())).collect();
            let mut rng = Rng::new(seed + 1000);
            for q in 0..300 {
                let (x, k) = (random_point(&mut rng, scale), KS[q % KS.len()]);
                let got = w.tree.nearest(x, k);
                let what = format!("{scale} {placement:?} query {q} {x} k {k}");
                let all = w
                    .shapes
                    .iter()
                    .map(|&(key, c, r)| (key, point_sphere_distance(x, c, r)));
                assert_eq!(got, first_k(all.collect(), k), "{what}: not geom's nearest");
                let refd: Vec<f64> = w
                    .shapes
                    .iter()
                    .map(|s| sphere_distance(p(x), s.1, s.2))
                    .collect();
                let got: Vec<(usize, f32)> = got
                    .iter()
                    .map(|&(key, d)| (index_of(&by_index, key), d))
                    .collect();
                check_nearest(&refd, k, &got, 1e-5 * f64::from(scale), &what);
            }
        }
    }
}

#[test]
fn bvh_nearest_matches_the_reference() {
    for scale in SCALES {
        let w = boxes(6, scale);
        let mut rng = Rng::new(1006);
        for q in 0..300 {
            let (x, k) = (random_point(&mut rng, scale), KS[q % KS.len()]);
            let got = w.bvh.nearest(x, k);
            let what = format!("{scale} query {q} {x} k {k}");
            let all = w
                .shapes
                .iter()
                .map(|(key, b)| (*key, point_aabb_distance(x, b)));
            assert_eq!(got, first_k(all.collect(), k), "{what}: not geom's nearest");
            let refd: Vec<f64> = w.shapes.iter().map(|s| box_distance(p(x), &s.1)).collect();
            let got: Vec<(usize, f32)> = got
                .iter()
                .map(|&(key, d)| (index_of(&w.shapes, key), d))
                .collect();
            check_nearest(&refd, k, &got, 1e-5 * f64::from(scale), &what);
        }
    }
}

#[test]
fn bvh_query_sphere_matches_the_reference() {
    for scale in SCALES {
        let w = boxes(7, scale);
        let mut rng = Rng::new(1007);
        let mut found = 0;
        for q in 0..400 {
            let x = random_point(&mut rng, scale);
            let r = match q % 4 {
                0 => 0.0,
                1 => rng.range(0.3, 2.0) * scale,
                _ => rng.range(0.0, 0.2) * scale,
            };
            let mut got = Vec::new();
            w.bvh.query_sphere(x, r, |k| got.push(k));
            got.sort();
            let mut want: Vec<ProxyKey> = w
                .shapes
                .iter()
                .filter(|(_, b)| point_aabb_distance(x, b) <= r)
                .map(|s| s.0)
                .collect();
            want.sort();
            assert_eq!(got, want, "{scale} query {q}: not geom's set");
            let tol = 1e-5 * f64::from(scale);
            let r = f64::from(r);
            for (key, b) in &w.shapes {
                let d = box_distance(p(x), b);
                let hit = got.binary_search(key).is_ok();
                assert!(
                    !hit || d <= r + tol,
                    "{scale} query {q}: found a box at {d} > {r}"
                );
                assert!(
                    hit || d > r - tol,
                    "{scale} query {q}: missed a box at {d} <= {r}"
                );
            }
            found += got.len();
        }
        assert!(found > 400, "{scale}: only {found} found");
    }
}

#[test]
fn grazing_contact_counts_and_ties_go_to_the_smaller_key() {
    let bounds = Aabb::new(Vec3::splat(-10.0), Vec3::splat(10.0));
    for placement in [Placement::Strict, Placement::Loose] {
        let mut tree = Octree::with_placement(bounds, 4, placement).unwrap();
        let a = tree.insert(Vec3::ZERO, 1.0).unwrap();
        let b = tree.insert(Vec3::ZERO, 1.0).unwrap();
        let far = tree.insert(Vec3::new(6.0, 0.0, 0.0), 0.5).unwrap();
        let first = a.min(b);
        // Passing at exactly the sum of the radii touches at closest approach.
        let o = Vec3::new(-8.0, 2.0, 0.0);
        assert_eq!(tree.cast_sphere(o, 1.0, Vec3::X, 20.0), Some((first, 8.0)));
        assert_eq!(tree.cast_sphere(o, 0.99, Vec3::X, 20.0), None);
        // Head on, zero radius (a ray), a slow direction, max_t just short.
        let o = Vec3::new(-8.0, 0.0, 0.0);
        assert_eq!(tree.cast_sphere(o, 0.0, Vec3::X, 20.0), Some((first, 7.0)));
        assert_eq!(
            tree.cast_sphere(o, 0.5, Vec3::X * 0.5, 20.0),
            Some((first, 13.0))
        );
        assert_eq!(tree.cast_sphere(o, 0.5, Vec3::X, 6.4), None);
        // Starting inside, or touching with no motion: t = 0.
        assert_eq!(
            tree.cast_sphere(Vec3::new(0.5, 0.0, 0.0), 0.1, Vec3::Y, 5.0),
            Some((first, 0.0))
        );
        assert_eq!(
            tree.cast_sphere(Vec3::new(8.0, 0.0, 0.0), 1.5, Vec3::ZERO, 5.0),
            Some((far, 0.0))
        );
        assert_eq!(
            tree.cast_sphere(Vec3::new(8.0, 0.0, 0.0), 1.4, Vec3::ZERO, 5.0),
            None
        );
        // Nearest: inside both twins (0, by key), then the far one from its surface.
        let near = tree.nearest(Vec3::new(0.5, 0.0, 0.0), 3);
        assert_eq!(near, [(first, 0.0), (a.max(b), 0.0), (far, 5.0)]);
        assert_eq!(tree.nearest(Vec3::new(9.0, 0.0, 0.0), 1), [(far, 2.5)]);
        assert_eq!(tree.nearest(Vec3::new(3.0, 0.0, 0.0), 10).len(), 3);
    }

    let mut bvh = Bvh::new(BvhConfig::default()).unwrap();
    let unit = Aabb::new(Vec3::splat(-1.0), Vec3::ONE);
    let a = bvh.insert(unit).unwrap();
    let b = bvh.insert(unit).unwrap();
    let side = bvh
        .insert(Aabb::new(
            Vec3::new(4.0, -1.0, -1.0),
            Vec3::new(5.0, 1.0, 1.0),
        ))
        .unwrap();
    let first = a.min(b);
    for rebuilt in [false, true] {
        if rebuilt {
            bvh.rebuild();
        }
        // Along the top face at height 1 + radius: touches the edge at x = −1.
        let o = Vec3::new(-8.0, 2.0, 0.0);
        assert_eq!(bvh.cast_sphere(o, 1.0, Vec3::X, 20.0), Some((first, 7.0)));
        assert_eq!(bvh.cast_sphere(o, 0.99, Vec3::X, 20.0), None);
        // Towards the corner (1, 1, 1) on the diagonal.
        let (t_key, t) = bvh
            .cast_sphere(Vec3::splat(5.0), 1.0, Vec3::splat(-1.0), 9.0)
            .unwrap();
        assert_eq!(t_key, first);
        assert!(
            (f64::from(t) - (4.0 - 1.0 / 3f64.sqrt())).abs() < 1e-6,
            "{t}"
        );
        // Between the unit boxes and `side`: the gap from x = 1 to 4 is exactly 3.
        let smallest = first.min(side);
        assert_eq!(
            bvh.cast_sphere(Vec3::new(2.5, 0.0, 0.0), 1.5, Vec3::ZERO, 1.0),
            Some((smallest, 0.0))
        );
        let (key, t) = bvh
            .cast_sphere(Vec3::new(2.5, 0.0, 0.0), 1.4, Vec3::X, 1.0)
            .unwrap();
        assert_eq!(key, side);
        assert!((t - 0.1).abs() < 1e-6, "{t}");
        let mut got = Vec::new();
        bvh.query_sphere(Vec3::new(2.5, 0.0, 0.0), 1.5, |k| got.push(k));
        got.sort();
        let mut want = vec![a, b, side];
        want.sort();
        assert_eq!(got, want, "both faces touch the query sphere");
        got.clear();
        bvh.query_sphere(Vec3::new(2.5, 0.0, 0.0), 1.4999, |k| got.push(k));
        assert!(got.is_empty());
        // Zero radius: the boxes holding the point, faces included.
        bvh.query_sphere(Vec3::new(1.0, 1.0, -1.0), 0.0, |k| got.push(k));
        assert_eq!(got.len(), 2);
        let near = bvh.nearest(Vec3::new(3.0, 0.0, 0.0), 3);
        assert_eq!(near, [(side, 1.0), (first, 2.0), (a.max(b), 2.0)]);
    }
}

#[test]
fn huge_and_overflowing_coordinates() {
    let m = 3e38f32;
    let bounds = Aabb::new(Vec3::splat(-10.0), Vec3::splat(10.0));
    let mut tree = Octree::new(bounds, 3).unwrap();
    // A sphere whose box overflows to ±∞ from finite input, and a small one inside.
    let huge = tree.insert(Vec3::splat(m), m).unwrap();
    let small = tree.insert(Vec3::ZERO, 1.0).unwrap();
    assert_eq!(tree.aabb(huge).unwrap().max, Vec3::splat(f32::INFINITY));
    assert_eq!(tree.nearest(Vec3::splat(m), 1), [(huge, 0.0)]);
    assert_eq!(tree.nearest(Vec3::ZERO, 2)[0], (small, 0.0));
    let d = tree.nearest(Vec3::ZERO, 2)[1];
    assert_eq!(d.0, huge);
    assert!(
        (f64::from(d.1) - (3f64.sqrt() - 1.0) * 3e38).abs() < 1e32,
        "{d:?}"
    );
    let hit = tree.cast_sphere(Vec3::splat(-m), 0.0, Vec3::splat(m), 10.0);
    let (key, t) = hit.expect("a ray across the world meets the small sphere first");
    assert_eq!(key, small);
    assert!((t - 1.0).abs() < 1e-6, "{t}");
    let away = tree.cast_sphere(Vec3::splat(-m), m, Vec3::splat(m), 10.0);
    assert_eq!(away.map(|h| h.0), Some(small));

    let mut bvh = Bvh::new(BvhConfig::default()).unwrap();
    let edge = bvh
        .insert(Aabb::new(Vec3::splat(m), Vec3::splat(f32::MAX)))
        .unwrap();
    let mid = bvh.insert(Aabb::new(Vec3::splat(-1.0), Vec3::ONE)).unwrap();
    for _ in 0..2 {
        let near = bvh.nearest(Vec3::splat(-1e38), 2);
        assert_eq!(near.iter().map(|n| n.0).collect::<Vec<_>>(), [mid, edge]);
        assert!(near.iter().all(|n| !n.1.is_nan()));
        let hit = bvh
            .cast_sphere(Vec3::splat(2.0), 0.5, Vec3::splat(m), 10.0)
            .unwrap();
        assert_eq!(hit.0, edge);
        let mut got = Vec::new();
        bvh.query_sphere(Vec3::splat(1.5e38), f32::MAX, |k| got.push(k));
        assert_eq!(got.len(), 2);
        bvh.rebuild();
    }
}

#[test]
fn bad_arguments_find_nothing() {
    let w = spheres(8, Placement::Strict, 10.0);
    let b = boxes(9, 10.0);
    let empty_tree = Octree::new(Aabb::new(Vec3::splat(-1.0), Vec3::ONE), 2).unwrap();
    let empty_bvh = Bvh::new(BvhConfig::default()).unwrap();
    let (nan, inf) = (f32::NAN, f32::INFINITY);
    let o = Vec3::ZERO;
    let casts = [
        (Vec3::new(nan, 0.0, 0.0), 1.0, Vec3::X, 10.0),
        (Vec3::new(0.0, -inf, 0.0), 1.0, Vec3::X, 10.0),
        (o, nan, Vec3::X, 10.0),
        (o, inf, Vec3::X, 10.0),
        (o, -1.0, Vec3::X, 10.0),
        (o, 1.0, Vec3::new(nan, 1.0, 0.0), 10.0),
        (o, 1.0, Vec3::new(0.0, 0.0, inf), 10.0),
        (o, 1.0, Vec3::X, nan),
        (o, 1.0, Vec3::X, inf),
        (o, 1.0, Vec3::X, -1.0),
    ];
    for (c, r, d, max_t) in casts {
        assert_eq!(
            w.tree.cast_sphere(c, r, d, max_t),
            None,
            "{c} {r} {d} {max_t}"
        );
        assert_eq!(
            b.bvh.cast_sphere(c, r, d, max_t),
            None,
            "{c} {r} {d} {max_t}"
        );
    }
    assert_eq!(empty_tree.cast_sphere(o, 1.0, Vec3::X, 10.0), None);
    assert_eq!(empty_bvh.cast_sphere(o, 1.0, Vec3::X, 10.0), None);
    for x in [
        Vec3::new(nan, 0.0, 0.0),
        Vec3::new(0.0, inf, 0.0),
        Vec3::splat(-inf),
    ] {
        assert!(w.tree.nearest(x, 5).is_empty());
        assert!(b.bvh.nearest(x, 5).is_empty());
    }
    assert!(w.tree.nearest(o, 0).is_empty());
    assert!(b.bvh.nearest(o, 0).is_empty());
    assert!(empty_tree.nearest(o, 3).is_empty());
    assert!(empty_bvh.nearest(o, 3).is_empty());
    let mut n = 0;
    for (x, r) in [
        (Vec3::new(nan, 0.0, 0.0), 100.0),
        (Vec3::splat(inf), 100.0),
        (o, -1.0),
        (o, nan),
        (o, inf),
    ] {
        b.bvh.query_sphere(x, r, |_| n += 1);
    }
    assert_eq!(n, 0);
}
