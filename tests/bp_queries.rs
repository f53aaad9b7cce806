//! `BroadPhase`'s queries — `query_sphere`, `cast_sphere`, `nearest`, `cast_ray` — on random
//! worlds of spheres, dynamic and static bodies that move between steps (so that, in the
//! incremental regime, the structures hold fat boxes around the shapes), under every pass
//! choice and margins 0 and 0.1. Each answer is compared exactly with a brute-force loop over
//! the test's own record of the shapes (as given, without the margin) through `geom`'s shape
//! functions, and casts and nearest also with the test's own `f64` geometry (`reference`).
//! Bad arguments find nothing.

mod common;
mod reference;

use broadleaf::geom::{
    self, point_aabb_distance, point_sphere_distance, sphere_cast_aabb, sphere_cast_sphere,
};
use broadleaf::{Aabb, BodyKind, BroadPhase, Config, Passes, ProxyKey, Vec3};
use common::Rng;
use reference::{Cast, CastExpect, Target, check_nearest, p};

#[derive(Clone, Copy, Debug)]
enum S {
    Sphere(Vec3, f32),
    Body(Aabb, BodyKind),
}

impl S {
    fn target(&self) -> Target {
        match *self {
            S::Sphere(c, r) => Target::Sphere(c, r),
            S::Body(b, _) => Target::Box(b),
        }
    }
}

fn random_shape(rng: &mut Rng) -> S {
    match rng.below(4) {
        0 | 1 => S::Sphere(rng.offset(20.0), rng.range(0.0, 1.0)),
        2 => {
            let c = rng.offset(20.0);
            let h = Vec3::new(
                rng.range(0.0, 2.0),
                rng.range(0.0, 2.0),
                rng.range(0.0, 2.0),
            );
            S::Body(Aabb::new(c - h, c + h), BodyKind::Dynamic)
        }
        _ => {
            let c = rng.offset(20.0);
            let h = Vec3::new(
                rng.range(0.0, 3.0),
                rng.range(0.0, 0.5),
                rng.range(0.0, 3.0),
            );
            S::Body(Aabb::new(c - h, c + h), BodyKind::Static)
        }
    }
}

fn moved(rng: &mut Rng, s: S) -> S {
    match s {
        S::Sphere(c, r) => S::Sphere(c + rng.offset(0.3), r),
        S::Body(b, BodyKind::Dynamic) => {
            let d = rng.offset(0.3);
            S::Body(Aabb::new(b.min + d, b.max + d), BodyKind::Dynamic)
        }
        s => s,
    }
}

fn first_of(hits: impl Iterator<Item = (ProxyKey, Option<f32>)>) -> Option<(ProxyKey, f32)> {
    hits.filter_map(|(k, t)| t.map(|t| (t, k)))
        .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
        .map(|(t, k)| (k, t))
}

fn check_queries(bp: &BroadPhase, shapes: &[(ProxyKey, S)], rng: &mut Rng, what: &str) {
    let targets: Vec<Target> = shapes.iter().map(|s| s.1.target()).collect();
    for q in 0..30 {
        let what = format!("{what} query {q}");
        // query_sphere
        let (x, r) = (rng.offset(25.0), rng.range(0.0, 4.0));
        let mut got = Vec::new();
        bp.query_sphere(x, r, |k| got.push(k));
        got.sort();
        let mut want: Vec<ProxyKey> = shapes
            .iter()
            .filter(|(_, s)| match *s {
                S::Sphere(c, rs) => (c - x).length_squared() <= (rs + r) * (rs + r),
                S::Body(b, _) => point_aabb_distance(x, &b) <= r,
            })
            .map(|s| s.0)
            .collect();
        want.sort();
        assert_eq!(got, want, "{what}: query_sphere");
        // cast_sphere
        let c = Cast {
            o: rng.offset(25.0),
            r: if rng.chance(0.2) {
                0.0
            } else {
                rng.range(0.0, 1.0)
            },
            d: rng.offset(1.0),
            max_t: rng.range(0.0, 40.0),
        };
        let got = bp.cast_sphere(c.o, c.r, c.d, c.max_t);
        let want = first_of(shapes.iter().map(|&(k, s)| {
            let t = match s {
                S::Sphere(cc, rr) => sphere_cast_sphere(c.o, c.r, c.d, c.max_t, cc, rr),
                S::Body(b, _) => sphere_cast_aabb(c.o, c.r, c.d, c.max_t, &b),
            };
            (k, t)
        }));
        assert_eq!(got, want, "{what}: cast_sphere {c:?}");
        let eps = 1e-4;
        let t_tol = eps / f64::from(c.d.length()).max(1e-30);
        let index = |k: ProxyKey| shapes.iter().position(|s| s.0 == k).expect("live");
        let got_i = got.map(|(k, t)| (index(k), t));
        CastExpect::new(&c, &targets, eps).check(&c, &targets, got_i, eps, t_tol, &what);
        // cast_ray
        let got = bp.cast_ray(c.o, c.d, c.max_t);
        let inv = geom::inverse_dir(c.d);
        let want = first_of(shapes.iter().map(|&(k, s)| {
            let t = match s {
                S::Sphere(cc, rr) => geom::ray_sphere(c.o, c.d, cc, rr, c.max_t),
                S::Body(b, _) => b.ray_entry(c.o, inv, c.max_t),
            };
            (k, t)
        }));
        assert_eq!(got, want, "{what}: cast_ray");
        // nearest
        let k = rng.below(12);
        let got = bp.nearest(x, k);
        let mut all: Vec<(ProxyKey, f32)> = shapes
            .iter()
            .map(|&(key, s)| {
                let d = match s {
                    S::Sphere(cc, rr) => point_sphere_distance(x, cc, rr),
                    S::Body(b, _) => point_aabb_distance(x, &b),
                };
                (key, d)
            })
            .collect();
        all.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        all.truncate(k);
        assert_eq!(got, all, "{what}: nearest {k}");
        let refd: Vec<f64> = targets.iter().map(|t| t.distance(p(x))).collect();
        let got_i: Vec<(usize, f32)> = got.iter().map(|&(key, d)| (index(key), d)).collect();
        check_nearest(&refd, k, &got_i, 1e-4, &what);
    }
}

#[test]
fn queries_equal_brute_force_on_moving_worlds() {
    for (seed, passes, margin) in [
        (1, Passes::Adaptive, 0.0),
        (2, Passes::Full, 0.1),
        (3, Passes::Incremental, 0.0),
        (4, Passes::Incremental, 0.1),
    ] {
        let mut rng = Rng::new(seed);
        let mut bp = BroadPhase::new(Config {
            bounds: Some(Aabb::new(Vec3::splat(-16.0), Vec3::splat(16.0))),
            margin,
            passes,
            ..Config::default()
        });
        let mut shapes: Vec<(ProxyKey, S)> = Vec::new();
        for _ in 0..200 {
            let s = random_shape(&mut rng);
            let key = match s {
                S::Sphere(c, r) => bp.insert_sphere(c, r),
                S::Body(b, kind) => bp.insert_body(b, kind),
            }
            .unwrap();
            shapes.push((key, s));
        }
        for step in 0..12 {
            for (key, shape) in shapes.iter_mut() {
                if rng.chance(0.5) {
                    let s = moved(&mut rng, *shape);
                    match s {
                        S::Sphere(c, r) => bp.update_sphere(*key, c, r).unwrap(),
                        S::Body(b, _) => bp.update_body(*key, b).unwrap(),
                    }
                    *shape = s;
                }
            }
            if rng.chance(0.3) && !shapes.is_empty() {
                let (k, _) = shapes.swap_remove(rng.below(shapes.len()));
                bp.remove(k).unwrap();
            }
            bp.step();
            bp.validate();
            check_queries(&bp, &shapes, &mut rng, &format!("seed {seed} step {step}"));
        }
        // Bad arguments find nothing.
        let nan = f32::NAN;
        let mut n = 0;
        bp.query_sphere(Vec3::new(nan, 0.0, 0.0), 1.0, |_| n += 1);
        bp.query_sphere(Vec3::ZERO, -1.0, |_| n += 1);
        bp.query_sphere(Vec3::ZERO, f32::INFINITY, |_| n += 1);
        assert_eq!(n, 0);
        assert_eq!(bp.cast_sphere(Vec3::ZERO, -1.0, Vec3::X, 10.0), None);
        assert_eq!(bp.cast_sphere(Vec3::ZERO, 1.0, Vec3::X, -1.0), None);
        assert_eq!(
            bp.cast_sphere(Vec3::ZERO, 1.0, Vec3::new(nan, 0.0, 0.0), 1.0),
            None
        );
        assert_eq!(bp.cast_ray(Vec3::ZERO, Vec3::X, nan), None);
        assert!(bp.nearest(Vec3::new(f32::INFINITY, 0.0, 0.0), 3).is_empty());
        assert!(bp.nearest(Vec3::ZERO, 0).is_empty());
    }
}
