//! `BroadPhase` against the brute-force reference: after every `step()` of a random operation
//! sequence, `pairs` equals `brute::pairs` over the test's own model of the shapes, grown by
//! the margin by the test itself, and `added` / `removed` equal the set differences with the
//! previous step's pairs; the octree runs in both placements.

use broadleaf::{
    Aabb, BodyKind, BroadPhase, Config, Pair, Pass, Passes, Placement, ProxyKey, Shape, Vec3, brute,
};
use proptest::prelude::*;
use std::collections::BTreeSet;

#[derive(Clone, Debug)]
enum Op {
    InsertSphere(Vec3, f32),
    InsertBody(Vec3, Vec3, bool),
    Move(usize, Vec3),
    Teleport(usize, Vec3),
    Resize(usize, f32),
    Remove(usize),
    Step,
}

/// Coordinates on a half-metre lattice inside ±12 m (bounds are ±8 m), so exact touches,
/// coincident centres and spheres outside the bounds all happen often.
fn coord() -> impl Strategy<Value = f32> {
    (-24i32..=24).prop_map(|i| i as f32 * 0.5)
}

fn point() -> impl Strategy<Value = Vec3> {
    (coord(), coord(), coord()).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

fn size() -> impl Strategy<Value = f32> {
    prop_oneof![
        8 => (0i32..=4).prop_map(|i| i as f32 * 0.5),
        1 => Just(20.0f32),
        1 => (1i32..=9).prop_map(|i| i as f32 * 0.137),
    ]
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        4 => (point(), size()).prop_map(|(c, r)| Op::InsertSphere(c, r)),
        2 => (point(), (size(), size(), size()), any::<bool>())
            .prop_map(|(c, (x, y, z), s)| Op::InsertBody(c, Vec3::new(x, y, z), s)),
        4 => (any::<usize>(), (-2i32..=2, -2i32..=2, -2i32..=2))
            .prop_map(|(i, (x, y, z))| Op::Move(i, Vec3::new(x as f32, y as f32, z as f32) * 0.25)),
        1 => (any::<usize>(), point()).prop_map(|(i, p)| Op::Teleport(i, p)),
        1 => (any::<usize>(), size()).prop_map(|(i, r)| Op::Resize(i, r)),
        1 => any::<usize>().prop_map(Op::Remove),
        3 => Just(Op::Step),
    ]
}

/// `hint`: give the octree the lattice's central ±8 m as its region hint (spheres also lie
/// outside it), or none.
fn config(hint: bool, margin: f32, placement: Placement, skin: f32, passes: Passes) -> Config {
    Config {
        bounds: hint.then(|| Aabb::new(Vec3::splat(-8.0), Vec3::splat(8.0))),
        octree_placement: placement,
        margin,
        skin,
        passes,
        ..Config::default()
    }
}

/// The test's own reference proxy of a shape: the box the contract pairs, a sphere's
/// `center ± (radius + margin)`, a body's box with `margin` added on every side (the lattice
/// keeps every face finite), and whether it is a static body.
fn proxy(key: ProxyKey, shape: &Shape, margin: f32) -> brute::Proxy {
    let (aabb, is_static) = match *shape {
        Shape::Sphere { center, radius } => {
            let r = radius + margin;
            let min = Vec3::new(center.x - r, center.y - r, center.z - r);
            let max = Vec3::new(center.x + r, center.y + r, center.z + r);
            (Aabb { min, max }, false)
        }
        Shape::Body { aabb, kind } => {
            let min = Vec3::new(
                aabb.min.x - margin,
                aabb.min.y - margin,
                aabb.min.z - margin,
            );
            let max = Vec3::new(
                aabb.max.x + margin,
                aabb.max.y + margin,
                aabb.max.z + margin,
            );
            (Aabb { min, max }, kind == BodyKind::Static)
        }
    };
    brute::Proxy {
        key,
        aabb,
        is_static,
    }
}

/// Checks one step against the model, whose boxes pair grown by `margin`; returns the step's
/// pairs.
fn check_step(
    bp: &mut BroadPhase,
    model: &[(ProxyKey, Shape)],
    prev: &[Pair],
    margin: f32,
) -> Vec<Pair> {
    let proxies: Vec<brute::Proxy> = model
        .iter()
        .map(|(key, shape)| proxy(*key, shape, margin))
        .collect();
    let expected = brute::pairs(&proxies);
    bp.step();
    let (pairs, added, removed) = (
        bp.pairs().to_vec(),
        bp.added().to_vec(),
        bp.removed().to_vec(),
    );
    bp.validate();
    assert_eq!(pairs, expected, "pairs differ from brute force");
    let p: BTreeSet<Pair> = prev.iter().copied().collect();
    let c: BTreeSet<Pair> = expected.iter().copied().collect();
    let want_added: Vec<Pair> = c.difference(&p).copied().collect();
    let want_removed: Vec<Pair> = p.difference(&c).copied().collect();
    assert_eq!(added, want_added, "added is not cur \\ prev");
    assert_eq!(removed, want_removed, "removed is not prev \\ cur");
    expected
}

fn run(hint: bool, margin: f32, placement: Placement, skin: f32, passes: Passes, ops: &[Op]) {
    let mut bp = BroadPhase::try_new(config(hint, margin, placement, skin, passes)).unwrap();
    let mut model: Vec<(ProxyKey, Shape)> = Vec::new();
    let mut prev = Vec::new();
    for op in ops {
        match *op {
            Op::InsertSphere(center, radius) => {
                let key = bp.insert_sphere(center, radius).unwrap();
                model.push((key, Shape::Sphere { center, radius }));
            }
            Op::InsertBody(c, h, is_static) => {
                let kind = if is_static {
                    BodyKind::Static
                } else {
                    BodyKind::Dynamic
                };
                let aabb = Aabb::from_center_half_extents(c, h);
                let key = bp.insert_body(aabb, kind).unwrap();
                model.push((key, Shape::Body { aabb, kind }));
            }
            Op::Move(i, d) | Op::Teleport(i, d) if !model.is_empty() => {
                let i = i % model.len();
                let teleport = matches!(op, Op::Teleport(..));
                let (key, shape) = &mut model[i];
                match shape {
                    Shape::Sphere { center, radius } => {
                        *center = if teleport { d } else { *center + d };
                        bp.update_sphere(*key, *center, *radius).unwrap();
                    }
                    Shape::Body { aabb, .. } => {
                        let h = aabb.extent() * 0.5;
                        let c = if teleport { d } else { aabb.center() + d };
                        *aabb = Aabb::from_center_half_extents(c, h);
                        bp.update_body(*key, *aabb).unwrap();
                    }
                }
            }
            Op::Resize(i, r) if !model.is_empty() => {
                let i = i % model.len();
                let (key, shape) = &mut model[i];
                match shape {
                    Shape::Sphere { center, radius } => {
                        *radius = r;
                        bp.update_sphere(*key, *center, r).unwrap();
                    }
                    Shape::Body { aabb, .. } => {
                        *aabb = Aabb::from_center_half_extents(aabb.center(), Vec3::splat(r));
                        bp.update_body(*key, *aabb).unwrap();
                    }
                }
            }
            Op::Remove(i) if !model.is_empty() => {
                let (key, _) = model.swap_remove(i % model.len());
                bp.remove(key).unwrap();
                assert!(bp.aabb(key).is_none());
            }
            Op::Step => prev = check_step(&mut bp, &model, &prev, margin),
            _ => {}
        }
        // Between steps too: queries and rays see the current boxes.
        bp.validate();
        assert_eq!(bp.len(), model.len());
    }
    check_step(&mut bp, &model, &prev, margin);
    for &(key, shape) in &model {
        assert_eq!(bp.aabb(key), Some(shape.aabb()));
        assert_eq!(bp.shape(key), Some(shape));
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(192))]

    #[test]
    fn pairs_and_events_equal_brute_force(
        hint in any::<bool>(),
        margin in prop_oneof![3 => Just(0.0f32), 1 => Just(0.25f32), 1 => Just(0.1f32)],
        placement in prop_oneof![Just(Placement::Strict), Just(Placement::Loose)],
        skin in prop_oneof![3 => Just(0.0f32), 1 => Just(0.1f32), 1 => Just(0.6f32)],
        passes in prop_oneof![Just(Passes::Adaptive), Just(Passes::Full), Just(Passes::Incremental)],
        ops in prop::collection::vec(op(), 0..160),
    ) {
        run(hint, margin, placement, skin, passes, &ops);
    }
}

#[test]
fn removed_proxy_pairs_are_reported_removed_next_step() {
    let mut bp = BroadPhase::new(Config::default());
    let a = bp.insert_sphere(Vec3::ZERO, 1.0).unwrap();
    let b = bp.insert_sphere(Vec3::X, 1.0).unwrap();
    let w = bp
        .insert_body(
            Aabb::new(Vec3::splat(-5.0), Vec3::splat(5.0)),
            BodyKind::Static,
        )
        .unwrap();
    bp.step();
    assert_eq!(bp.pairs().len(), 3);
    assert_eq!(bp.added().len(), 3);
    bp.remove(a).unwrap();
    bp.step();
    assert_eq!(bp.pairs(), &[Pair::new(b, w)]);
    assert!(bp.added().is_empty());
    assert_eq!(bp.removed(), &[Pair::new(a, b), Pair::new(a, w)]);
    bp.step();
    assert!(bp.added().is_empty() && bp.removed().is_empty());
}

#[test]
fn static_bodies_never_pair_with_each_other() {
    let mut bp = BroadPhase::new(Config::default());
    let big = Aabb::new(Vec3::splat(-1.0), Vec3::splat(1.0));
    bp.insert_body(big, BodyKind::Static).unwrap();
    bp.insert_body(big, BodyKind::Static).unwrap();
    bp.step();
    assert!(bp.pairs().is_empty());
    let d = bp.insert_body(big, BodyKind::Dynamic).unwrap();
    bp.step();
    assert_eq!(bp.pairs().len(), 2);
    assert!(bp.pairs().iter().all(|p| p.a == d || p.b == d));
}

#[test]
fn cast_ray_hits_spheres_as_spheres_and_bodies_as_boxes() {
    let mut bp = BroadPhase::new(Config::default());
    // A sphere whose box the ray would clip at the corner, but whose ball it misses.
    let s = bp.insert_sphere(Vec3::new(5.0, 0.9, 0.0), 1.0).unwrap();
    let b = bp
        .insert_body(
            Aabb::new(Vec3::new(10.0, -1.0, -1.0), Vec3::new(11.0, 1.0, 1.0)),
            BodyKind::Static,
        )
        .unwrap();
    let o = Vec3::new(0.0, 0.0, 0.0);
    let (key, t) = bp.cast_ray(o, Vec3::X, 100.0).unwrap();
    assert_eq!(key, s);
    assert!((t - (5.0 - 0.19f32.sqrt())).abs() < 1e-5, "{t}");
    bp.update_sphere(s, Vec3::new(5.0, 0.99, 0.99), 1.0)
        .unwrap();
    assert_eq!(bp.cast_ray(o, Vec3::X * 2.0, 100.0), Some((b, 5.0)));
    assert_eq!(bp.cast_ray(o, Vec3::X, 9.0), None);
    assert_eq!(bp.cast_ray(o, Vec3::X, f32::NAN), None);
}

#[test]
fn query_aabb_equals_brute_force() {
    let settings = [
        (Placement::Strict, 0.0, Passes::Full),
        (Placement::Loose, 0.0, Passes::Full),
        (Placement::Strict, 0.3, Passes::Incremental),
        (Placement::Loose, 0.3, Passes::Incremental),
    ];
    for (placement, skin, passes) in settings {
        let mut bp = BroadPhase::new(config(true, 0.0, placement, skin, passes));
        let mut rng = broadleaf::fixtures::scene::Rng::new(11);
        let mut proxies = Vec::new();
        for i in 0..300 {
            let c = rng.vec3_in(Vec3::splat(-10.0), Vec3::splat(10.0));
            let (key, aabb) = if i % 3 == 0 {
                let aabb = Aabb::from_center_half_extents(c, Vec3::splat(rng.range(0.0, 2.0)));
                (bp.insert_body(aabb, BodyKind::Dynamic).unwrap(), aabb)
            } else {
                let r = rng.range(0.0, 1.0);
                (
                    bp.insert_sphere(c, r).unwrap(),
                    Aabb::from_center_radius(c, r),
                )
            };
            proxies.push(brute::Proxy::new(key, aabb));
        }
        bp.step();
        for _ in 0..100 {
            let c = rng.vec3_in(Vec3::splat(-10.0), Vec3::splat(10.0));
            let q = Aabb::from_center_half_extents(c, Vec3::splat(rng.range(0.0, 4.0)));
            assert_query_is_brute(&bp, &proxies, &q);
        }
    }
}

/// `query_aabb` finds exactly what brute force over `proxies` finds.
fn assert_query_is_brute(bp: &BroadPhase, proxies: &[brute::Proxy], q: &Aabb) {
    let mut got = Vec::new();
    bp.query_aabb(q, |k| got.push(k));
    got.sort_unstable();
    assert_eq!(got, brute::query_aabb(proxies, q), "query {q:?}");
}

/// Inserts `shape` (a sphere or a body) and returns its key.
fn insert(bp: &mut BroadPhase, shape: Shape) -> ProxyKey {
    match shape {
        Shape::Sphere { center, radius } => bp.insert_sphere(center, radius),
        Shape::Body { aabb, kind } => bp.insert_body(aabb, kind),
    }
    .unwrap()
}

/// Under the full pass, and under the incremental pass after moves small enough to stay inside
/// the skin (so the structures still hold the old fat boxes) and some that leave it:
/// `query_aabb` equals brute force over the exact boxes, and `cast_ray` equals the brute-force
/// closest hit (spheres as balls, bodies as boxes; same key, same `t`).
#[test]
fn queries_and_rays_see_exact_shapes_while_fat_boxes_are_held() {
    for (placement, skin, passes) in [
        (Placement::Strict, 0.0, Passes::Full),
        (Placement::Strict, 0.4, Passes::Incremental),
        (Placement::Loose, 0.4, Passes::Incremental),
        (Placement::Loose, 2.0, Passes::Incremental),
    ] {
        let mut bp = BroadPhase::new(config(true, 0.0, placement, skin, passes));
        let mut rng = broadleaf::fixtures::scene::Rng::new(29);
        let mut model: Vec<(ProxyKey, Shape)> = Vec::new();
        for i in 0..240 {
            let c = rng.vec3_in(Vec3::splat(-10.0), Vec3::splat(10.0));
            let shape = if i % 4 == 0 {
                let h = Vec3::splat(rng.range(0.0, 1.5));
                Shape::Body {
                    aabb: Aabb::from_center_half_extents(c, h),
                    kind: if i % 8 == 0 {
                        BodyKind::Static
                    } else {
                        BodyKind::Dynamic
                    },
                }
            } else {
                Shape::Sphere {
                    center: c,
                    radius: rng.range(0.0, 1.0),
                }
            };
            model.push((insert(&mut bp, shape), shape));
        }
        for round in 0..6 {
            bp.step();
            for (key, shape) in &mut model {
                // Mostly diagonal moves within the skin; one in eight jumps further.
                let reach = if rng.below(8) == 0 { 3.0 } else { 0.3 };
                let d = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), 1.0) * reach;
                match shape {
                    Shape::Sphere { center, radius } => {
                        *center += d;
                        bp.update_sphere(*key, *center, *radius).unwrap();
                    }
                    Shape::Body { aabb, .. } => {
                        *aabb = Aabb::new(aabb.min + d, aabb.max + d);
                        bp.update_body(*key, *aabb).unwrap();
                    }
                }
            }
            bp.validate();
            let proxies: Vec<brute::Proxy> = model.iter().map(|(k, s)| proxy(*k, s, 0.0)).collect();
            for _ in 0..60 {
                let c = rng.vec3_in(Vec3::splat(-12.0), Vec3::splat(12.0));
                let q = Aabb::from_center_half_extents(c, Vec3::splat(rng.range(0.0, 3.0)));
                assert_query_is_brute(&bp, &proxies, &q);

                let o = rng.vec3_in(Vec3::splat(-14.0), Vec3::splat(14.0));
                let dir = rng.vec3_in(Vec3::splat(-1.0), Vec3::splat(1.0));
                let inv = broadleaf::geom::inverse_dir(dir);
                let want = model
                    .iter()
                    .filter_map(|(k, s)| {
                        let t = match *s {
                            Shape::Sphere { center, radius } => {
                                broadleaf::geom::ray_sphere(o, dir, center, radius, 40.0)
                            }
                            Shape::Body { aabb, .. } => aabb.ray_entry(o, inv, 40.0),
                        };
                        t.map(|t| (*k, t))
                    })
                    .min_by(|x, y| x.1.total_cmp(&y.1).then(x.0.cmp(&y.0)));
                assert_eq!(
                    bp.cast_ray(o, dir, 40.0),
                    want,
                    "round {round}, skin {skin}"
                );
            }
        }
    }
}

/// The incremental pass, forced: many proxies, few of them changing per step (so the pass
/// re-tests candidates instead of running the structures' pair passes), small moves inside
/// the skin and jumps out of it, resizes, inserts and removes; every step equals brute force,
/// events included, and every step after the first ran the incremental pass.
#[test]
fn incremental_pass_equals_brute_force_step_by_step() {
    for (placement, skin, margin) in [
        (Placement::Strict, 0.2, 0.0),
        (Placement::Loose, 0.2, 0.1),
        (Placement::Loose, 1.0, 0.0),
    ] {
        let passes = Passes::Incremental;
        let mut bp = BroadPhase::try_new(config(false, margin, placement, skin, passes)).unwrap();
        let mut rng = broadleaf::fixtures::scene::Rng::new(41);
        let mut model: Vec<(ProxyKey, Shape)> = Vec::new();
        let add = |bp: &mut BroadPhase, rng: &mut broadleaf::fixtures::scene::Rng| {
            let c = rng.vec3_in(Vec3::splat(-9.0), Vec3::splat(9.0));
            let shape = match rng.below(6) {
                0 => Shape::Body {
                    aabb: Aabb::from_center_half_extents(c, Vec3::splat(rng.range(0.0, 1.0))),
                    kind: BodyKind::Static,
                },
                1 | 2 => Shape::Body {
                    aabb: Aabb::from_center_half_extents(c, Vec3::splat(rng.range(0.0, 1.0))),
                    kind: BodyKind::Dynamic,
                },
                _ => Shape::Sphere {
                    center: c,
                    radius: rng.range(0.0, 0.8),
                },
            };
            (insert(bp, shape), shape)
        };
        for _ in 0..400 {
            model.push(add(&mut bp, &mut rng));
        }
        let mut prev = check_step(&mut bp, &model, &[], margin);
        for _ in 0..150 {
            for _ in 0..rng.below(12) {
                let i = rng.below(model.len() as u32) as usize;
                let (key, shape) = &mut model[i];
                let d = rng.vec3_in(Vec3::splat(-1.0), Vec3::splat(1.0))
                    * if rng.below(4) == 0 { 2.0 } else { 0.1 };
                match shape {
                    Shape::Sphere { center, radius } => {
                        *center += d;
                        if rng.below(6) == 0 {
                            *radius = rng.range(0.0, 0.8);
                        }
                        bp.update_sphere(*key, *center, *radius).unwrap();
                    }
                    Shape::Body { aabb, .. } => {
                        *aabb = Aabb::new(aabb.min + d, aabb.max + d);
                        bp.update_body(*key, *aabb).unwrap();
                    }
                }
            }
            if rng.below(3) == 0 {
                let i = rng.below(model.len() as u32) as usize;
                let (key, _) = model.swap_remove(i);
                bp.remove(key).unwrap();
            }
            if rng.below(3) == 0 {
                model.push(add(&mut bp, &mut rng));
            }
            prev = check_step(&mut bp, &model, &prev, margin);
            let pass = bp.stats().pass;
            assert!(
                matches!(pass, Pass::Incremental | Pass::Unchanged),
                "{pass:?}"
            );
        }
    }
}
