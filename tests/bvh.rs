//! The BVH against the brute-force oracle: random operation sequences on every split method
//! (pairs, cross pairs, box queries and ray casts after every operation, with and without
//! refit), parry-style insert/remove sweeps, degenerate inputs and the rebuild triggers.

use broadleaf::brute::{self, Proxy};
use broadleaf::bvh::{Bvh, BvhConfig, SplitMethod};
use broadleaf::fixtures::scene::Rng;
use broadleaf::pair::sort_dedup;
use broadleaf::{Aabb, Error, Pair, ProxyKey, Vec3};
use proptest::prelude::*;

const METHODS: [SplitMethod; 3] = [
    SplitMethod::Sah,
    SplitMethod::Middle,
    SplitMethod::EqualCounts,
];

fn config(split: SplitMethod, max_leaf_size: u32) -> BvhConfig {
    BvhConfig {
        split,
        max_leaf_size,
        ..BvhConfig::default()
    }
}

/// The tree's self pairs, sorted; panics if one was reported twice.
fn tree_pairs(bvh: &mut Bvh) -> Vec<Pair> {
    let mut v = Vec::new();
    bvh.for_each_pair(|a, b| v.push(Pair::new(a, b)));
    let n = v.len();
    sort_dedup(&mut v);
    assert_eq!(n, v.len(), "a pair was reported twice");
    v
}

/// The oracle's view of a model `(key, box)` list.
fn proxies(model: &[(ProxyKey, Aabb)]) -> Vec<Proxy> {
    model.iter().map(|&(k, b)| Proxy::new(k, b)).collect()
}

/// Checks every query of `bvh` (and `other` for cross pairs) against brute force.
fn check_all(
    bvh: &mut Bvh,
    model: &[(ProxyKey, Aabb)],
    other: &Bvh,
    other_model: &[(ProxyKey, Aabb)],
    rng: &mut Rng,
) {
    bvh.validate();
    assert_eq!(bvh.len(), model.len());
    let ps = proxies(model);
    assert_eq!(tree_pairs(bvh), brute::pairs(&ps));

    let mut cross = Vec::new();
    bvh.for_each_pair_with(other, |a, b| cross.push((a, b)));
    cross.sort_unstable();
    let mut expect: Vec<(ProxyKey, ProxyKey)> = model
        .iter()
        .flat_map(|&(a, ba)| {
            other_model
                .iter()
                .filter(move |(_, bb)| ba.overlaps(bb))
                .map(move |&(b, _)| (a, b))
        })
        .collect();
    expect.sort_unstable();
    assert_eq!(cross, expect, "cross pairs");

    for _ in 0..4 {
        let q = random_box(rng, 12.0);
        let mut got = Vec::new();
        bvh.query_aabb(&q, |k| got.push(k));
        got.sort_unstable();
        assert_eq!(got, brute::query_aabb(&ps, &q), "query {q:?}");

        let origin = rng.vec3_in(Vec3::splat(-14.0), Vec3::splat(14.0)).round();
        let dir = if rng.below(2) == 0 {
            // Axis-aligned, so rays slide along faces of the integer-ish boxes.
            let mut d = Vec3::ZERO;
            d[rng.below(3) as usize] = if rng.below(2) == 0 { 1.0 } else { -2.0 };
            d
        } else {
            rng.vec3_in(Vec3::splat(-1.0), Vec3::splat(1.0))
        };
        let max_t = rng.range(0.0, 40.0);
        let got = bvh.cast_ray(origin, dir, max_t);
        let want = brute::cast_ray_boxes(&ps, origin, dir, max_t);
        match (got, want) {
            (None, None) => {}
            (Some((k, t)), Some((kw, tw))) => {
                assert!(
                    (t - tw).abs() <= 1e-5 * tw.abs().max(1.0),
                    "ray t {t} vs {tw}"
                );
                assert_eq!(k, kw, "ray key at t {t}");
            }
            _ => panic!("ray {origin} {dir} {max_t}: {got:?} vs brute {want:?} in {model:?}"),
        }
        let mut all = Vec::new();
        bvh.cast_ray_all(origin, dir, max_t, |k, t| all.push((k, t)));
        all.sort_unstable_by_key(|a| a.0);
        let inv = broadleaf::geom::inverse_dir(dir);
        let mut want_all: Vec<(ProxyKey, f32)> = ps
            .iter()
            .filter_map(|p| p.aabb.ray_entry(origin, inv, max_t).map(|t| (p.key, t)))
            .collect();
        want_all.sort_unstable_by_key(|a| a.0);
        assert_eq!(all, want_all, "cast_ray_all");
    }
}

/// A box with integer-or-half centre and half-extents in {0, 0.5, 1, 2}: exactly touching
/// and zero-size boxes are common. `spread` bounds the centre.
fn random_box(rng: &mut Rng, spread: f32) -> Aabb {
    let c = rng.vec3_in(Vec3::splat(-spread), Vec3::splat(spread));
    let c = (c * 2.0).round() * 0.5;
    let h = [0.0, 0.5, 1.0, 2.0];
    let he = Vec3::new(
        h[rng.below(4) as usize],
        h[rng.below(4) as usize],
        h[rng.below(4) as usize],
    );
    Aabb::from_center_half_extents(c, he)
}

#[derive(Clone, Debug)]
enum Op {
    Insert,
    Remove(u32),
    Move(u32),
    Refit,
    Rebuild,
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        4 => Just(Op::Insert),
        2 => any::<u32>().prop_map(Op::Remove),
        6 => any::<u32>().prop_map(Op::Move),
        2 => Just(Op::Refit),
        1 => Just(Op::Rebuild),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn random_operations_match_brute_force(
        method in 0usize..3,
        max_leaf in 1u32..10,
        trav in prop_oneof![Just(0.0f32), Just(1.0), Just(4.0), Just(9.0)],
        changes in prop_oneof![Just(0.0f32), Just(0.1), Just(0.5), Just(f32::INFINITY)],
        seed in any::<u64>(),
        n0 in 0usize..40,
        ops in prop::collection::vec(op(), 1..40),
    ) {
        let mut rng = Rng::new(seed);
        let cfg = BvhConfig {
            rebuild_after_changes: changes,
            traversal_cost: trav,
            ..config(METHODS[method], max_leaf)
        };
        let initial: Vec<Aabb> = (0..n0).map(|_| random_box(&mut rng, 10.0)).collect();
        let (mut bvh, keys) = Bvh::from_aabbs(cfg, &initial).unwrap();
        let mut model: Vec<(ProxyKey, Aabb)> = keys.into_iter().zip(initial).collect();
        // The other tree: built, then a few pending inserts.
        let other_boxes: Vec<Aabb> = (0..20).map(|_| random_box(&mut rng, 10.0)).collect();
        let (mut other, okeys) = Bvh::from_aabbs(cfg, &other_boxes).unwrap();
        let mut other_model: Vec<(ProxyKey, Aabb)> = okeys.into_iter().zip(other_boxes).collect();
        for _ in 0..3 {
            let b = random_box(&mut rng, 10.0);
            other_model.push((other.insert(b).unwrap(), b));
        }
        check_all(&mut bvh, &model, &other, &other_model, &mut rng);
        for op in ops {
            match op {
                Op::Insert => {
                    let b = random_box(&mut rng, 10.0);
                    model.push((bvh.insert(b).unwrap(), b));
                }
                Op::Remove(i) if !model.is_empty() => {
                    let (k, _) = model.swap_remove(i as usize % model.len());
                    bvh.remove(k).unwrap();
                    prop_assert_eq!(bvh.remove(k), Err(Error::UnknownProxy));
                }
                Op::Move(i) if !model.is_empty() => {
                    let i = i as usize % model.len();
                    // Half small moves, half teleports anywhere.
                    let b = if rng.below(2) == 0 {
                        let b = model[i].1;
                        let d = (rng.vec3_in(Vec3::splat(-1.0), Vec3::splat(1.0)) * 2.0).round() * 0.5;
                        Aabb::new(b.min + d, b.max + d)
                    } else {
                        random_box(&mut rng, 10.0)
                    };
                    model[i].1 = b;
                    bvh.update(model[i].0, b).unwrap();
                }
                Op::Refit => bvh.refit(),
                Op::Rebuild => bvh.rebuild(),
                _ => {}
            }
            check_all(&mut bvh, &model, &other, &other_model, &mut rng);
        }
    }
}

/// parry's `bvh_tests.rs` sweep: {bulk build, one-by-one insert} × {remove in order, reverse,
/// even then odd} × sizes 1..=100, validating after every mutation.
#[test]
fn insert_remove_sweep() {
    for (m, &method) in METHODS.iter().enumerate() {
        for n in 1..=100usize {
            let boxes: Vec<Aabb> = (0..n)
                .map(|i| Aabb::from_center_half_extents(Vec3::splat(i as f32), Vec3::ONE))
                .collect();
            for bulk in [true, false] {
                for order in 0..3 {
                    let cfg = config(method, 1 + (n as u32 + m as u32) % 4);
                    let (mut bvh, keys) = if bulk {
                        Bvh::from_aabbs(cfg, &boxes).unwrap()
                    } else {
                        let mut bvh = Bvh::new(cfg).unwrap();
                        let mut keys = Vec::new();
                        for b in &boxes {
                            keys.push(bvh.insert(*b).unwrap());
                            bvh.validate();
                            if keys.len() % 7 == 0 {
                                bvh.refit();
                                bvh.validate();
                            }
                        }
                        (bvh, keys)
                    };
                    let idx: Vec<usize> = match order {
                        0 => (0..n).collect(),
                        1 => (0..n).rev().collect(),
                        _ => (0..n).step_by(2).chain((1..n).step_by(2)).collect(),
                    };
                    for (r, &i) in idx.iter().enumerate() {
                        bvh.remove(keys[i]).unwrap();
                        bvh.validate();
                        assert!(!bvh.contains(keys[i]));
                        assert_eq!(bvh.len(), n - r - 1);
                        if r % 5 == 4 {
                            bvh.refit();
                            bvh.validate();
                        }
                    }
                    assert!(bvh.is_empty());
                    assert_eq!(tree_pairs(&mut bvh), vec![]);
                }
            }
        }
    }
}

fn check_scene(boxes: &[Aabb]) {
    for method in METHODS {
        let (mut bvh, keys) = Bvh::from_aabbs(config(method, 4), boxes).unwrap();
        bvh.validate();
        let model: Vec<(ProxyKey, Aabb)> =
            keys.iter().copied().zip(boxes.iter().copied()).collect();
        let empty = Bvh::new(BvhConfig::default()).unwrap();
        check_all(&mut bvh, &model, &empty, &[], &mut Rng::new(5));
        bvh.refit();
        let copy = bvh.clone();
        check_all(&mut bvh, &model, &copy, &model, &mut Rng::new(6));
    }
}

#[test]
fn degenerate_scenes() {
    let unit = Aabb::new(Vec3::ZERO, Vec3::ONE);
    check_scene(&[]);
    check_scene(&[unit]);
    check_scene(&[unit; 37]);
    check_scene(&[Aabb::new(Vec3::ONE, Vec3::ONE); 20]);
    let line: Vec<Aabb> = (0..50)
        .map(|i| {
            Aabb::new(
                Vec3::new(i as f32, 0.0, 0.0),
                Vec3::new(i as f32 + 1.0, 0.0, 0.0),
            )
        })
        .collect();
    check_scene(&line);
    let huge = Aabb::new(Vec3::splat(-1e30), Vec3::splat(1e30));
    let mut with_huge: Vec<Aabb> = (0..30).map(|i| unit.grown(i as f32 * 0.1)).collect();
    with_huge.push(huge);
    check_scene(&with_huge);
    // A grid of exactly touching unit cubes: every neighbour (faces, edges, corners) pairs.
    let grid: Vec<Aabb> = (0..27)
        .map(|i| {
            let p = Vec3::new((i % 3) as f32, (i / 3 % 3) as f32, (i / 9) as f32);
            Aabb::new(p, p + Vec3::ONE)
        })
        .collect();
    check_scene(&grid);
}

#[test]
fn bad_input_leaves_the_tree_unchanged() {
    let boxes: Vec<Aabb> = (0..10)
        .map(|i| Aabb::from_center_radius(Vec3::splat(i as f32), 1.0))
        .collect();
    let (mut bvh, keys) = Bvh::from_aabbs(BvhConfig::default(), &boxes).unwrap();
    let before = format!("{bvh:?}");
    let nan = Aabb::new(Vec3::new(f32::NAN, 0.0, 0.0), Vec3::ONE);
    let inf = Aabb::new(Vec3::ZERO, Vec3::splat(f32::INFINITY));
    let inverted = Aabb::new(Vec3::ONE, Vec3::ZERO);
    for bad in [nan, inf, inverted] {
        assert!(bvh.insert(bad).is_err());
        assert!(bvh.update(keys[3], bad).is_err());
    }
    assert!(matches!(
        bvh.insert(nan),
        Err(Error::NonFinite {
            what: "aabb.min",
            ..
        })
    ));
    assert!(matches!(
        bvh.insert(inverted),
        Err(Error::InvertedAabb { .. })
    ));
    bvh.remove(keys[0]).unwrap();
    let after_remove = format!("{bvh:?}");
    assert_eq!(bvh.remove(keys[0]), Err(Error::UnknownProxy));
    assert_eq!(bvh.update(keys[0], boxes[0]), Err(Error::UnknownProxy));
    assert_eq!(bvh.aabb(keys[0]), None);
    assert_eq!(format!("{bvh:?}"), after_remove);
    assert_ne!(before, after_remove);
    assert!(Bvh::from_aabbs(BvhConfig::default(), &[boxes[0], nan]).is_err());
    assert_eq!(bvh.cast_ray(Vec3::ZERO, Vec3::X, f32::NAN), None);
    assert_eq!(bvh.cast_ray(Vec3::ZERO, Vec3::X, -1.0), None);
    assert_eq!(bvh.cast_ray(Vec3::splat(f32::NAN), Vec3::X, 1.0), None);
    bvh.validate();
}

#[test]
fn config_ranges_are_checked() {
    let ok = BvhConfig::default();
    let cases = [
        (
            BvhConfig {
                max_leaf_size: 0,
                ..ok
            },
            "max_leaf_size",
        ),
        (
            BvhConfig {
                max_leaf_size: 256,
                ..ok
            },
            "max_leaf_size",
        ),
        (
            BvhConfig {
                sah_buckets: 1,
                ..ok
            },
            "sah_buckets",
        ),
        (
            BvhConfig {
                sah_buckets: 65,
                ..ok
            },
            "sah_buckets",
        ),
        (
            BvhConfig {
                traversal_cost: -0.5,
                ..ok
            },
            "traversal_cost",
        ),
        (
            BvhConfig {
                traversal_cost: 64.5,
                ..ok
            },
            "traversal_cost",
        ),
        (
            BvhConfig {
                traversal_cost: f32::NAN,
                ..ok
            },
            "traversal_cost",
        ),
        (
            BvhConfig {
                rebuild_threshold: 0.5,
                ..ok
            },
            "rebuild_threshold",
        ),
        (
            BvhConfig {
                rebuild_threshold: f32::INFINITY,
                ..ok
            },
            "rebuild_threshold",
        ),
        (
            BvhConfig {
                rebuild_after_changes: -0.1,
                ..ok
            },
            "rebuild_after_changes",
        ),
        (
            BvhConfig {
                rebuild_after_changes: f32::NAN,
                ..ok
            },
            "rebuild_after_changes",
        ),
    ];
    for (cfg, field) in cases {
        assert!(matches!(Bvh::new(cfg), Err(Error::InvalidConfig { what, .. }) if what == field));
    }
    assert!(
        Bvh::new(BvhConfig {
            max_leaf_size: 255,
            sah_buckets: 64,
            traversal_cost: 64.0,
            ..ok
        })
        .is_ok()
    );
}

#[test]
fn scattering_boxes_trigger_a_rebuild() {
    // Boxes start packed and scatter in random directions: refitted node boxes swell and
    // overlap, the SAH cost ratio passes 1.5 and refit rebuilds.
    let mut rng = Rng::new(11);
    let n = 2000;
    let mut boxes: Vec<Aabb> = (0..n)
        .map(|_| Aabb::from_center_radius(rng.vec3_in(Vec3::splat(-10.0), Vec3::splat(10.0)), 0.3))
        .collect();
    let vel: Vec<Vec3> = (0..n)
        .map(|_| rng.vec3_in(Vec3::splat(-1.0), Vec3::splat(1.0)))
        .collect();
    let (mut bvh, keys) = Bvh::from_aabbs(BvhConfig::default(), &boxes).unwrap();
    assert_eq!(bvh.stats().rebuilds, 1);
    let mut steps = 0;
    while bvh.stats().rebuilds == 1 {
        steps += 1;
        assert!(steps < 200, "no rebuild after {steps} steps");
        for ((b, v), k) in boxes.iter_mut().zip(&vel).zip(&keys) {
            *b = Aabb::new(b.min + *v, b.max + *v);
            bvh.update(*k, *b).unwrap();
        }
        bvh.refit();
        bvh.validate();
    }
    let s = bvh.stats();
    assert_eq!(s.refits, steps);
    assert!(
        s.cost_ratio <= 1.0 + 1e-6,
        "fresh tree ratio {}",
        s.cost_ratio
    );
    let model: Vec<(ProxyKey, Aabb)> = keys.into_iter().zip(boxes).collect();
    assert_eq!(tree_pairs(&mut bvh), brute::sweep_pairs(&proxies(&model)));
}

#[test]
fn many_changes_trigger_a_rebuild() {
    let boxes: Vec<Aabb> = (0..100)
        .map(|i| Aabb::from_center_radius(Vec3::splat(i as f32), 0.4))
        .collect();
    let (mut bvh, keys) = Bvh::from_aabbs(BvhConfig::default(), &boxes).unwrap();
    // 10 changes of 100 is not more than the default fraction 0.1: refit only.
    for k in &keys[..5] {
        bvh.remove(*k).unwrap();
    }
    for i in 0..5 {
        bvh.insert(Aabb::from_center_radius(Vec3::splat(i as f32 + 0.5), 0.4))
            .unwrap();
    }
    bvh.refit();
    assert_eq!(
        (
            bvh.stats().rebuilds,
            bvh.stats().pending,
            bvh.stats().tombstones
        ),
        (1, 5, 5)
    );
    bvh.remove(keys[50]).unwrap();
    bvh.refit();
    let s = bvh.stats();
    assert_eq!(
        (s.rebuilds, s.pending, s.tombstones, s.primitives),
        (2, 0, 0, 99)
    );
    bvh.validate();
}

#[test]
fn deep_tree_spills_the_inline_stacks() {
    // Middle splits of exponentially spaced boxes peel one or two boxes per level: deeper than
    // the inline stacks (64), so queries must spill to the heap and still be exact.
    let boxes: Vec<Aabb> = (0..120)
        .map(|i| {
            let x = 2f32.powi(i);
            Aabb::new(Vec3::new(x, 0.0, 0.0), Vec3::new(x * 1.2, 1.0, 1.0))
        })
        .collect();
    let (mut bvh, keys) = Bvh::from_aabbs(config(SplitMethod::Middle, 1), &boxes).unwrap();
    assert!(bvh.stats().depth > 64, "depth {}", bvh.stats().depth);
    let model: Vec<(ProxyKey, Aabb)> = keys.into_iter().zip(boxes).collect();
    let copy = bvh.clone();
    check_all(&mut bvh, &model, &copy, &model, &mut Rng::new(8));
    // A ray along the line from beyond the far end hits the last box first.
    let far = Vec3::new(2f32.powi(121), 0.5, 0.5);
    let hit = bvh.cast_ray(far, -Vec3::X, f32::INFINITY);
    assert_eq!(hit.map(|h| h.0), Some(model[119].0));
}

#[test]
fn a_long_line_builds_refits_and_traverses_iteratively() {
    // 200k boxes on a line (1M in release takes the same code path): build, update, refit,
    // pairs, queries and rays all run on explicit stacks. Neighbours touch, so the pair set
    // is exactly the n − 1 consecutive pairs.
    let n = 200_000;
    let boxes: Vec<Aabb> = (0..n)
        .map(|i| {
            Aabb::new(
                Vec3::new(i as f32, 0.0, 0.0),
                Vec3::new(i as f32 + 1.0, 1.0, 1.0),
            )
        })
        .collect();
    for method in [SplitMethod::Sah, SplitMethod::Middle] {
        let (mut bvh, keys) = Bvh::from_aabbs(config(method, 4), &boxes).unwrap();
        bvh.validate();
        for (k, b) in keys.iter().zip(&boxes).step_by(3) {
            bvh.update(*k, Aabb::new(b.min, b.max + Vec3::new(0.0, 0.5, 0.0)))
                .unwrap();
        }
        bvh.refit();
        bvh.validate();
        let mut count = 0usize;
        let mut ok = true;
        bvh.for_each_pair(|a, b| {
            count += 1;
            let (i, j) = (
                keys.binary_search(&a).unwrap(),
                keys.binary_search(&b).unwrap(),
            );
            ok &= i.abs_diff(j) == 1;
        });
        assert!(ok, "a pair of non-neighbours");
        assert_eq!(count, n - 1);
        let mut hits = Vec::new();
        bvh.query_aabb(
            &Aabb::new(Vec3::new(10.5, 0.0, 0.0), Vec3::new(12.5, 0.0, 0.0)),
            |k| hits.push(k),
        );
        hits.sort_unstable();
        assert_eq!(hits, keys[10..=12]);
        let hit = bvh.cast_ray(Vec3::new(-5.0, 0.5, 0.5), Vec3::X, f32::INFINITY);
        assert_eq!(hit, Some((keys[0], 5.0)));
    }
}

/// Leaves whose masks do not fit 64 bits (more than 61 boxes, or 62–64 starting past a block
/// boundary of the 4-box lanes) take the leaf × leaf loop without the bit mask of the boxes
/// near the other leaf: both loops must give brute force's pairs, self and cross, before and
/// after the boxes move.
#[test]
fn big_leaves_pair_like_brute_force() {
    let mut rng = Rng::new(23);
    for (max_leaf_size, traversal_cost) in [
        (255, 64.0),
        (70, 64.0),
        (64, 64.0),
        (61, 64.0),
        (33, 16.0),
        (16, 8.0),
    ] {
        let cfg = BvhConfig {
            max_leaf_size,
            traversal_cost,
            sah_buckets: 64,
            ..BvhConfig::default()
        };
        let mut model: Vec<(ProxyKey, Aabb)> = Vec::new();
        let boxes: Vec<Aabb> = (0..900).map(|_| random_box(&mut rng, 14.0)).collect();
        let (mut bvh, keys) = Bvh::from_aabbs(cfg, &boxes).unwrap();
        model.extend(keys.iter().copied().zip(boxes.iter().copied()));
        let statics: Vec<Aabb> = (0..300).map(|_| random_box(&mut rng, 14.0)).collect();
        let (other, other_keys) = Bvh::from_aabbs(cfg, &statics).unwrap();
        let other_model: Vec<(ProxyKey, Aabb)> = other_keys
            .iter()
            .copied()
            .zip(statics.iter().copied())
            .collect();
        let s = bvh.stats();
        if max_leaf_size == 255 {
            assert!(
                s.primitives / s.leaves > 64,
                "leaves of {max_leaf_size}: {} boxes in {} leaves",
                s.primitives,
                s.leaves
            );
        }
        check_all(&mut bvh, &model, &other, &other_model, &mut rng);
        for (k, b) in &mut model {
            *b = random_box(&mut rng, 14.0);
            bvh.update(*k, *b).unwrap();
        }
        bvh.refit();
        check_all(&mut bvh, &model, &other, &other_model, &mut rng);
    }
}
