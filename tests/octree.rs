//! The octree against the brute-force oracle, in both placements: random operation sequences
//! on random depths and bounds, with spheres outside the bounds, zero radii, coincident centres, exactly touching
//! boxes and spheres larger than the world; after every pair pass the sorted pair set, the
//! queries and the rays equal brute force, and `validate()` holds.

mod common;

use common::uniform;

use broadleaf::brute::{self, Proxy};
use broadleaf::octree::{Octree, Placement};
use broadleaf::{Aabb, Error, Pair, ProxyKey, Vec3, pair};
use proptest::prelude::*;
use std::collections::BTreeMap;

#[derive(Clone, Debug)]
enum Op {
    Insert(Vec3, f32),
    Remove(usize),
    Move(usize, Vec3),
    Teleport(usize, Vec3),
    Resize(usize, f32),
    Bad(usize, u8),
    Pass,
}

/// Coordinates on a half-unit lattice (exact touching is common) or anywhere, including well
/// outside the bounds `[-4, 4]³` scaled by the case.
fn coord() -> impl Strategy<Value = f32> {
    prop_oneof![
        (-12i32..=12).prop_map(|i| i as f32 * 0.5),
        uniform(-7.0, 7.0),
    ]
}

fn point() -> impl Strategy<Value = Vec3> {
    (coord(), coord(), coord()).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

fn radius() -> impl Strategy<Value = f32> {
    prop_oneof![
        Just(0.0f32),
        (0i32..=4).prop_map(|i| i as f32 * 0.25),
        uniform(0.0, 1.5),
        Just(9.0f32),
    ]
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        4 => (point(), radius()).prop_map(|(c, r)| Op::Insert(c, r)),
        1 => any::<usize>().prop_map(Op::Remove),
        3 => (any::<usize>(), (-2i32..=2, -2i32..=2, -2i32..=2))
            .prop_map(|(i, (x, y, z))| Op::Move(i, Vec3::new(x as f32, y as f32, z as f32) * 0.25)),
        1 => (any::<usize>(), point()).prop_map(|(i, c)| Op::Teleport(i, c)),
        1 => (any::<usize>(), radius()).prop_map(|(i, r)| Op::Resize(i, r)),
        1 => (any::<usize>(), 0u8..6).prop_map(|(i, k)| Op::Bad(i, k)),
        2 => Just(Op::Pass),
    ]
}

fn placement() -> impl Strategy<Value = Placement> {
    prop_oneof![Just(Placement::Strict), Just(Placement::Loose)]
}

fn bounds() -> impl Strategy<Value = Aabb> {
    (uniform(-5.0, -1.0), uniform(1.0, 5.0), uniform(0.5, 2.0))
        .prop_map(|(lo, hi, s)| Aabb::new(Vec3::new(lo, lo * s, lo), Vec3::new(hi, hi, hi * s)))
}

/// The model: every live sphere by key.
type Model = BTreeMap<ProxyKey, (Vec3, f32)>;

fn proxies(model: &Model) -> Vec<Proxy> {
    model
        .iter()
        .map(|(&k, &(c, r))| Proxy::new(k, Aabb::from_center_radius(c, r)))
        .collect()
}

fn check_all(t: &mut Octree, model: &Model, removed: &[ProxyKey]) {
    t.validate();
    assert_eq!(t.len(), model.len());
    for (&k, &(c, r)) in model {
        assert_eq!(t.aabb(k), Some(Aabb::from_center_radius(c, r)));
        assert_eq!(t.sphere(k), Some((c, r)));
    }
    for &k in removed {
        assert!(!t.contains(k) && t.aabb(k).is_none());
    }
    let ps = proxies(model);
    let mut got: Vec<Pair> = Vec::new();
    t.pairs_into(&mut got);
    let n = got.len();
    pair::sort_dedup(&mut got);
    assert_eq!(n, got.len(), "a pair was reported twice");
    assert_eq!(got, brute::pairs(&ps));
    let mut each = Vec::new();
    t.for_each_pair(|a, b| each.push(Pair::new(a, b)));
    pair::sort_dedup(&mut each);
    assert_eq!(each, got);
}

fn check_queries(t: &Octree, model: &Model, q: Aabb, origin: Vec3, dir: Vec3, max_t: f32) {
    let ps = proxies(model);
    let mut got = Vec::new();
    t.query_aabb(&q, |k| got.push(k));
    got.sort_unstable();
    assert_eq!(got, brute::query_aabb(&ps, &q));

    let (c, r) = (q.center(), q.extent().x * 0.5);
    let mut got = Vec::new();
    t.query_sphere(c, r, |k| got.push(k));
    got.sort_unstable();
    let want: Vec<ProxyKey> = model
        .iter()
        .filter(|(_, (sc, sr))| (*sc - c).length_squared() <= (sr + r) * (sr + r))
        .map(|(&k, _)| k)
        .collect();
    assert_eq!(got, want);

    let spheres: Vec<(ProxyKey, Vec3, f32)> = model.iter().map(|(&k, &(c, r))| (k, c, r)).collect();
    let want = brute::cast_ray_spheres(&spheres, origin, dir, max_t);
    let got = t.cast_ray(origin, dir, max_t);
    match (got, want) {
        (None, None) => {}
        (Some((gk, gt)), Some((wk, wt))) => {
            assert!(
                (gt - wt).abs() <= 1e-5 * wt.abs().max(1.0),
                "t {gt} vs {wt}"
            );
            if gt == wt {
                assert_eq!(gk, wk);
            }
        }
        other => panic!("cast_ray disagrees: {other:?}"),
    }
    let mut all = Vec::new();
    t.cast_ray_all(origin, dir, max_t, |k, t| all.push((k, t)));
    all.sort_by_key(|h| h.0);
    let want: Vec<(ProxyKey, f32)> = spheres
        .iter()
        .filter_map(|&(k, c, r)| {
            broadleaf::geom::ray_sphere(origin, dir, c, r, max_t).map(|t| (k, t))
        })
        .collect();
    assert_eq!(all, want);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn octree_equals_brute_force(
        depth in 0u32..=6,
        placement in placement(),
        b in bounds(),
        ops in prop::collection::vec(op(), 1..120),
        q in (point(), uniform(0.0, 4.0)),
        ray in (point(), point(), prop_oneof![Just(f32::INFINITY), uniform(0.0, 3.0)]),
    ) {
        let mut t = Octree::with_placement(b, depth, placement).unwrap();
        prop_assert_eq!(t.placement(), placement);
        let mut model = Model::new();
        let mut removed = Vec::new();
        let pick = |model: &Model, i: usize| model.keys().nth(i % model.len().max(1)).copied();
        for op in ops {
            match op {
                Op::Insert(c, r) => {
                    let k = t.insert(c, r).unwrap();
                    model.insert(k, (c, r));
                }
                Op::Remove(i) => {
                    if let Some(k) = pick(&model, i) {
                        t.remove(k).unwrap();
                        model.remove(&k);
                        removed.push(k);
                    }
                }
                Op::Move(i, d) => {
                    if let Some(k) = pick(&model, i) {
                        let (c, r) = model[&k];
                        t.update(k, c + d, r).unwrap();
                        model.insert(k, (c + d, r));
                    }
                }
                Op::Teleport(i, c) => {
                    if let Some(k) = pick(&model, i) {
                        let r = model[&k].1;
                        t.update(k, c, r).unwrap();
                        model.insert(k, (c, r));
                    }
                }
                Op::Resize(i, r) => {
                    if let Some(k) = pick(&model, i) {
                        let c = model[&k].0;
                        t.update(k, c, r).unwrap();
                        model.insert(k, (c, r));
                    }
                }
                Op::Bad(i, kind) => {
                    let k = pick(&model, i);
                    let nan = Vec3::new(0.0, f32::NAN, 0.0);
                    let err = match (kind, k) {
                        (0, _) => t.insert(nan, 1.0).map(|_| ()),
                        (1, _) => t.insert(Vec3::ZERO, -0.5).map(|_| ()),
                        (2, Some(k)) => t.update(k, Vec3::splat(f32::INFINITY), 1.0),
                        (3, Some(k)) => t.update(k, Vec3::ZERO, f32::NAN),
                        (4, _) if !removed.is_empty() => t.remove(removed[i % removed.len()]),
                        _ => t.update(removed.first().copied().unwrap_or_default(), Vec3::ZERO, 1.0),
                    };
                    prop_assert!(err.is_err());
                    if kind >= 4 {
                        prop_assert_eq!(err, Err(Error::UnknownProxy));
                    }
                }
                Op::Pass => check_all(&mut t, &model, &removed),
            }
        }
        check_all(&mut t, &model, &removed);
        let (qc, qh) = q;
        check_queries(&t, &model, Aabb::from_center_radius(qc, qh), ray.0, ray.1 - ray.0, ray.2);
    }
}

const BOTH: [Placement; 2] = [Placement::Strict, Placement::Loose];

#[test]
fn coincident_and_huge_spheres_pair_with_everything() {
    for p in BOTH {
        let mut t = Octree::with_placement(Aabb::new(Vec3::splat(-1.0), Vec3::ONE), 4, p).unwrap();
        let mut model = Model::new();
        for _ in 0..40 {
            let k = t.insert(Vec3::splat(0.3), 0.0).unwrap();
            model.insert(k, (Vec3::splat(0.3), 0.0));
        }
        let huge = t.insert(Vec3::ZERO, 50.0).unwrap();
        model.insert(huge, (Vec3::ZERO, 50.0));
        check_all(&mut t, &model, &[]);
        assert_eq!(t.level_of(huge), Some(0));
    }
}

/// Loose trees with mixed radii (so pairs cross levels), crowds, touching boxes on a lattice
/// and overflow spheres, moved for several passes: every pass equals brute force.
#[test]
fn loose_mixed_radii_cross_levels_exactly() {
    let b = Aabb::new(Vec3::splat(-4.0), Vec3::splat(4.0));
    let mut rng = broadleaf::fixtures::scene::Rng::new(5);
    for depth in [2, 4, 6] {
        let mut t = Octree::with_placement(b, depth, Placement::Loose).unwrap();
        let mut model = Model::new();
        for i in 0..400 {
            let (c, r) = match i % 5 {
                0 => (
                    rng.vec3_in(Vec3::splat(-4.5), Vec3::splat(4.5)),
                    rng.range(0.0, 2.5),
                ),
                1 => (
                    (rng.vec3_in(Vec3::splat(-8.0), Vec3::splat(8.0)) * 2.0).round() * 0.25,
                    0.25,
                ),
                2 => (rng.vec3_in(Vec3::splat(-0.1), Vec3::splat(0.1)), 0.01),
                _ => (
                    rng.vec3_in(Vec3::splat(-4.0), Vec3::splat(4.0)),
                    rng.log_range(0.001, 1.0),
                ),
            };
            let k = t.insert(c, r).unwrap();
            model.insert(k, (c, r));
        }
        let levels = t.stats().per_level;
        assert!(
            levels.iter().filter(|&&n| n > 0).count() >= 3,
            "levels {levels:?}"
        );
        for _ in 0..4 {
            check_all(&mut t, &model, &[]);
            for (k, (c, r)) in model.iter_mut() {
                *c += rng.vec3_in(Vec3::splat(-0.3), Vec3::splat(0.3));
                t.update(*k, *c, *r).unwrap();
            }
        }
        let q = Aabb::new(Vec3::new(-1.0, -2.0, -0.5), Vec3::new(0.5, 1.0, 3.0));
        check_queries(
            &t,
            &model,
            q,
            Vec3::new(-5.0, -0.3, 0.2),
            Vec3::new(1.0, 0.1, 0.05),
            20.0,
        );
    }
}

#[test]
fn empty_and_single_trees_answer_nothing() {
    for p in BOTH {
        let mut t = Octree::with_placement(Aabb::new(Vec3::ZERO, Vec3::ONE), 3, p).unwrap();
        check_all(&mut t, &Model::new(), &[]);
        assert_eq!(t.cast_ray(Vec3::ZERO, Vec3::X, 10.0), None);
        let k = t.insert(Vec3::splat(0.5), 0.1).unwrap();
        assert_eq!(
            t.cast_ray(Vec3::new(-1.0, 0.5, 0.5), Vec3::X, 10.0)
                .map(|h| h.0),
            Some(k)
        );
        assert_eq!(t.cast_ray(Vec3::ZERO, Vec3::X, f32::NAN), None);
        assert_eq!(t.cast_ray(Vec3::ZERO, Vec3::X, -1.0), None);
        let mut model = Model::new();
        model.insert(k, (Vec3::splat(0.5), 0.1));
        check_all(&mut t, &model, &[]);
    }
}
