//! The engine-facing query API: every `BroadPhase` query with a `QueryFilter` (collision
//! groups, an excluded key, a predicate, and all three together) equals a brute-force loop
//! over the test's own record of the shapes and groups, with the filter applied by the test's
//! own code — casts give the nearest *accepted* hit, ties to the smaller key; a visitor that
//! breaks stops the query at once (counted visits), on `BroadPhase`, `Octree` and `Bvh`; and
//! `nearest_into` equals `nearest` and the brute-force answer, reusing the caller's buffer.
//! Worlds move between steps under every pass choice, so the structures hold fat boxes too.

mod common;

use broadleaf::geom::{
    self, point_aabb_distance, point_sphere_distance, sphere_cast_aabb, sphere_cast_sphere,
};
use broadleaf::{
    Aabb, BodyKind, BroadPhase, Bvh, BvhConfig, CollisionGroups, Config, Octree, Passes, ProxyKey,
    QueryFilter, Shape, Vec3,
};
use common::Rng;
use core::ops::ControlFlow;

/// The test's record of one proxy: its shape as given and its groups.
#[derive(Clone, Copy, Debug)]
struct Rec {
    key: ProxyKey,
    shape: Shape,
    groups: CollisionGroups,
}

fn random_shape(rng: &mut Rng) -> Shape {
    let c = rng.offset(20.0);
    match rng.below(4) {
        0 | 1 => Shape::Sphere {
            center: c,
            radius: rng.range(0.0, 1.5),
        },
        k => {
            let h = rng.vec3_in(Vec3::ZERO, Vec3::splat(2.0));
            Shape::Body {
                aabb: Aabb::new(c - h, c + h),
                kind: if k == 2 {
                    BodyKind::Dynamic
                } else {
                    BodyKind::Static
                },
            }
        }
    }
}

/// Groups over four bits, sometimes empty, so that every outcome of the rule occurs.
fn random_groups(rng: &mut Rng) -> CollisionGroups {
    if rng.chance(0.3) {
        return CollisionGroups::ALL;
    }
    CollisionGroups {
        memberships: rng.below(16) as u32,
        filter: rng.below(16) as u32,
    }
}

/// The filter's rule, written from its docs: not the excluded key, groups that allow each
/// other both ways, and the predicate.
fn accepts(
    groups: Option<CollisionGroups>,
    exclude: Option<ProxyKey>,
    pred: &dyn Fn(ProxyKey, &Shape) -> bool,
    r: &Rec,
) -> bool {
    let allowed = groups.is_none_or(|g| {
        g.memberships & r.groups.filter != 0 && r.groups.memberships & g.filter != 0
    });
    exclude != Some(r.key) && allowed && pred(r.key, &r.shape)
}

fn first_of(hits: impl Iterator<Item = (ProxyKey, Option<f32>)>) -> Option<(ProxyKey, f32)> {
    hits.filter_map(|(k, t)| t.map(|t| (t, k)))
        .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
        .map(|(t, k)| (k, t))
}

fn user_box(s: &Shape) -> Aabb {
    match *s {
        Shape::Sphere { center, radius } => Aabb::new(center - radius, center + radius),
        Shape::Body { aabb, .. } => aabb,
    }
}

fn overlaps(a: &Aabb, b: &Aabb) -> bool {
    (0..3).all(|i| a.min[i] <= b.max[i] && b.min[i] <= a.max[i])
}

/// Every query kind under one filter, against the brute-force loop.
fn check_filtered(bp: &BroadPhase, recs: &[Rec], rng: &mut Rng, what: &str) {
    // Predicates from the shape and from the key alone (a hash of it).
    let spheres_only = |_: ProxyKey, s: &Shape| matches!(s, Shape::Sphere { .. });
    let odd_hash = |k: ProxyKey, _: &Shape| {
        use std::hash::{Hash, Hasher};
        let mut h = std::collections::hash_map::DefaultHasher::new();
        k.hash(&mut h);
        h.finish() % 3 != 0
    };
    let everything = |_: ProxyKey, _: &Shape| true;
    for q in 0..24 {
        let what = format!("{what} filter {q}");
        let groups = rng.chance(0.5).then(|| random_groups(rng));
        let exclude =
            (rng.chance(0.5) && !recs.is_empty()).then(|| recs[rng.below(recs.len())].key);
        let pred: &dyn Fn(ProxyKey, &Shape) -> bool = match rng.below(3) {
            0 => &spheres_only,
            1 => &odd_hash,
            _ => &everything,
        };
        let mut filter = QueryFilter::new();
        if let Some(g) = groups {
            filter = filter.groups(g);
        }
        if let Some(k) = exclude {
            filter = filter.exclude(k);
        }
        if rng.chance(0.6) {
            filter = filter.predicate(pred);
        }
        let pred: &dyn Fn(ProxyKey, &Shape) -> bool = match filter.predicate {
            Some(p) => p,
            None => &everything,
        };
        let ok = |r: &Rec| accepts(groups, exclude, pred, r);

        // query_aabb_with
        let c = rng.offset(25.0);
        let query = Aabb::new(c, c + rng.vec3_in(Vec3::ZERO, Vec3::splat(8.0)));
        let mut got = Vec::new();
        let flow = bp.query_aabb_with(&query, &filter, |k| {
            got.push(k);
            ControlFlow::Continue(())
        });
        assert_eq!(flow, ControlFlow::Continue(()));
        got.sort();
        let want: Vec<ProxyKey> = recs
            .iter()
            .filter(|r| overlaps(&user_box(&r.shape), &query) && ok(r))
            .map(|r| r.key)
            .collect();
        assert_eq!(got, want, "{what}: query_aabb_with");

        // query_sphere_with
        let (x, radius) = (rng.offset(25.0), rng.range(0.0, 5.0));
        let mut got = Vec::new();
        let _ = bp.query_sphere_with(x, radius, &filter, |k| {
            got.push(k);
            ControlFlow::Continue(())
        });
        got.sort();
        let want: Vec<ProxyKey> = recs
            .iter()
            .filter(|r| {
                let inside = match r.shape {
                    Shape::Sphere { center, radius: rs } => {
                        (center - x).length_squared() <= (rs + radius) * (rs + radius)
                    }
                    Shape::Body { aabb, .. } => point_aabb_distance(x, &aabb) <= radius,
                };
                inside && ok(r)
            })
            .map(|r| r.key)
            .collect();
        assert_eq!(got, want, "{what}: query_sphere_with");

        // cast_ray_with: the nearest accepted hit, whatever is rejected in front of it.
        let (o, d, max_t) = (rng.offset(25.0), rng.offset(1.0), rng.range(0.0, 60.0));
        let inv = geom::inverse_dir(d);
        let got = bp.cast_ray_with(o, d, max_t, &filter);
        let want = first_of(recs.iter().filter(|r| ok(r)).map(|r| {
            let t = match r.shape {
                Shape::Sphere { center, radius } => geom::ray_sphere(o, d, center, radius, max_t),
                Shape::Body { aabb, .. } => aabb.ray_entry(o, inv, max_t),
            };
            (r.key, t)
        }));
        assert_eq!(got, want, "{what}: cast_ray_with");

        // cast_sphere_with
        let cr = rng.range(0.0, 1.0);
        let got = bp.cast_sphere_with(o, cr, d, max_t, &filter);
        let want = first_of(recs.iter().filter(|r| ok(r)).map(|r| {
            let t = match r.shape {
                Shape::Sphere { center, radius } => {
                    sphere_cast_sphere(o, cr, d, max_t, center, radius)
                }
                Shape::Body { aabb, .. } => sphere_cast_aabb(o, cr, d, max_t, &aabb),
            };
            (r.key, t)
        }));
        assert_eq!(got, want, "{what}: cast_sphere_with");

        // nearest_into
        let k = rng.below(10);
        let mut out = vec![(ProxyKey::default(), -1.0)];
        bp.nearest_into(x, k, &filter, &mut out);
        let mut all: Vec<(ProxyKey, f32)> = recs
            .iter()
            .filter(|r| ok(r))
            .map(|r| {
                let d = match r.shape {
                    Shape::Sphere { center, radius } => point_sphere_distance(x, center, radius),
                    Shape::Body { aabb, .. } => point_aabb_distance(x, &aabb),
                };
                (r.key, d)
            })
            .collect();
        all.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        all.truncate(k);
        assert_eq!(out, all, "{what}: nearest_into {k}");
    }
}

#[test]
fn filtered_queries_equal_brute_force_on_moving_worlds() {
    for (seed, passes) in [
        (1, Passes::Adaptive),
        (2, Passes::Full),
        (3, Passes::Incremental),
    ] {
        let mut rng = Rng::new(seed);
        let mut bp = BroadPhase::new(Config {
            passes,
            ..Config::default()
        });
        let mut recs: Vec<Rec> = Vec::new();
        for _ in 0..160 {
            let shape = random_shape(&mut rng);
            let key = match shape {
                Shape::Sphere { center, radius } => bp.insert_sphere(center, radius),
                Shape::Body { aabb, kind } => bp.insert_body(aabb, kind),
            }
            .unwrap();
            let groups = random_groups(&mut rng);
            bp.set_groups(key, groups).unwrap();
            recs.push(Rec { key, shape, groups });
        }
        for step in 0..8 {
            for r in recs.iter_mut() {
                if rng.chance(0.4) {
                    match r.shape {
                        Shape::Sphere { center, radius } => {
                            let center = center + rng.offset(0.4);
                            bp.update_sphere(r.key, center, radius).unwrap();
                            r.shape = Shape::Sphere { center, radius };
                        }
                        Shape::Body {
                            aabb,
                            kind: BodyKind::Dynamic,
                        } => {
                            let d = rng.offset(0.4);
                            let aabb = Aabb::new(aabb.min + d, aabb.max + d);
                            bp.update_body(r.key, aabb).unwrap();
                            r.shape = Shape::Body {
                                aabb,
                                kind: BodyKind::Dynamic,
                            };
                        }
                        Shape::Body { .. } => {}
                    }
                }
                if rng.chance(0.05) {
                    r.groups = random_groups(&mut rng);
                    bp.set_groups(r.key, r.groups).unwrap();
                }
            }
            if rng.chance(0.5) {
                let r = recs.swap_remove(rng.below(recs.len()));
                bp.remove(r.key).unwrap();
            }
            bp.step();
            if passes != Passes::Adaptive && step > 0 {
                let pass = bp.stats().pass;
                let forced = match passes {
                    Passes::Full => broadleaf::Pass::Full,
                    _ => broadleaf::Pass::Incremental,
                };
                assert_eq!(pass, forced, "seed {seed} step {step}");
            }
            bp.validate();
            recs.sort_by_key(|r| r.key);
            check_filtered(&bp, &recs, &mut rng, &format!("seed {seed} step {step}"));
        }
    }
}

/// A stopping visitor: counts its calls and breaks at call `stop`.
fn stopper(calls: &mut usize, stop: usize) -> impl FnMut(ProxyKey) -> ControlFlow<()> + '_ {
    move |_| {
        *calls += 1;
        if *calls >= stop {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    }
}

/// Runs `query` with a visitor that never stops (counting `total` matches), then with one
/// that breaks at each call `1..=total + 1`: it must be called exactly `min(stop, total)`
/// times and report `Break` exactly when it broke.
fn check_early_exit(
    what: &str,
    mut query: impl FnMut(&mut dyn FnMut(ProxyKey) -> ControlFlow<()>) -> ControlFlow<()>,
) {
    let mut total = 0;
    let flow = query(&mut |_| {
        total += 1;
        ControlFlow::Continue(())
    });
    assert_eq!(flow, ControlFlow::Continue(()), "{what}");
    assert!(total > 3, "{what}: the query should find several ({total})");
    for stop in [1, 2, total / 2, total, total + 1] {
        let mut calls = 0;
        let flow = query(&mut stopper(&mut calls, stop));
        assert_eq!(calls, stop.min(total), "{what}: break at {stop} of {total}");
        let broke = stop <= total;
        assert_eq!(flow.is_break(), broke, "{what}: break at {stop} of {total}");
    }
}

#[test]
fn a_breaking_visitor_stops_every_query() {
    let mut rng = Rng::new(7);
    let bounds = Aabb::new(Vec3::splat(-10.0), Vec3::splat(10.0));
    let mut bp = BroadPhase::new(Config::default());
    let mut tree = Octree::new(bounds, 5).unwrap();
    let mut bvh = Bvh::new(BvhConfig::default()).unwrap();
    for _ in 0..300 {
        let (c, r) = (rng.offset(10.0), rng.range(0.1, 1.0));
        bp.insert_sphere(c, r).unwrap();
        tree.insert(c, r).unwrap();
        let b = Aabb::new(c, c + rng.vec3_in(Vec3::ZERO, Vec3::splat(1.0)));
        bp.insert_body(b, BodyKind::Dynamic).unwrap();
        bvh.insert(b).unwrap();
    }
    bp.step();
    let q = Aabb::new(Vec3::splat(-6.0), Vec3::splat(6.0));
    let all = QueryFilter::new();
    check_early_exit("BroadPhase::query_aabb_with", |f| {
        bp.query_aabb_with(&q, &all, f)
    });
    check_early_exit("BroadPhase::query_sphere_with", |f| {
        bp.query_sphere_with(Vec3::ZERO, 6.0, &all, f)
    });
    check_early_exit("Octree::query_aabb_with", |f| tree.query_aabb_with(&q, f));
    check_early_exit("Octree::query_sphere_with", |f| {
        tree.query_sphere_with(Vec3::ZERO, 6.0, f)
    });
    // A query box large enough for the octree's walk rather than its direct cell lists.
    let wide = Aabb::new(Vec3::splat(-40.0), Vec3::splat(40.0));
    check_early_exit("Octree::query_aabb_with (wide)", |f| {
        tree.query_aabb_with(&wide, f)
    });
    check_early_exit("Bvh::query_aabb_with", |f| bvh.query_aabb_with(&q, f));
    check_early_exit("Bvh::query_sphere_with", |f| {
        bvh.query_sphere_with(Vec3::ZERO, 6.0, f)
    });
    // A bvh with pending boxes (inserted since the last refit) stops in them too.
    for _ in 0..20 {
        bvh.insert(Aabb::new(Vec3::ZERO, Vec3::ONE)).unwrap();
    }
    check_early_exit("Bvh::query_aabb_with (pending)", |f| {
        bvh.query_aabb_with(&q, f)
    });
}

#[test]
fn nearest_into_equals_nearest_and_reuses_the_buffer() {
    let mut rng = Rng::new(11);
    let mut bp = BroadPhase::new(Config::default());
    for _ in 0..400 {
        let shape = random_shape(&mut rng);
        match shape {
            Shape::Sphere { center, radius } => bp.insert_sphere(center, radius),
            Shape::Body { aabb, kind } => bp.insert_body(aabb, kind),
        }
        .unwrap();
    }
    bp.step();
    let mut out = Vec::with_capacity(1024);
    let ptr = out.as_ptr();
    for q in 0..200 {
        let (x, k) = (rng.offset(30.0), rng.below(20));
        bp.nearest_into(x, k, &QueryFilter::new(), &mut out);
        assert_eq!(out, bp.nearest(x, k), "query {q}");
        assert_eq!(out.as_ptr(), ptr, "query {q}: the buffer was reallocated");
    }
    // Bad arguments leave it empty.
    bp.nearest_into(Vec3::NAN, 3, &QueryFilter::new(), &mut out);
    assert!(out.is_empty());
}
