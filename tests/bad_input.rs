//! Every entry point that takes geometry or a key refuses bad input with a specific `Err` and
//! leaves the structure exactly as it was: same `len`, same `aabb(key)` for every live key,
//! same pairs at the next step.

use broadleaf::{
    Aabb, BodyKind, BroadPhase, Config, Error, Pair, Passes, Placement, ProxyKey, Vec3,
};

const NAN: f32 = f32::NAN;
const INF: f32 = f32::INFINITY;

fn bad_points() -> Vec<Vec3> {
    vec![
        Vec3::new(NAN, 0.0, 0.0),
        Vec3::new(0.0, INF, 0.0),
        Vec3::new(0.0, 0.0, -INF),
        Vec3::splat(NAN),
    ]
}

fn bad_boxes() -> Vec<(Aabb, &'static str)> {
    let mut v: Vec<(Aabb, &'static str)> = bad_points()
        .into_iter()
        .flat_map(|p| {
            [
                (Aabb::new(p, Vec3::ONE), "non-finite min"),
                (Aabb::new(Vec3::ZERO, p), "non-finite max"),
            ]
        })
        .collect();
    v.push((Aabb::new(Vec3::ONE, Vec3::ZERO), "inverted"));
    v.push((
        Aabb::new(Vec3::new(0.0, 1.0, 0.0), Vec3::new(1.0, 0.5, 1.0)),
        "inverted y",
    ));
    v
}

/// Both placements under the full pass, and both under the incremental pass (forced, with
/// fat boxes of a fixed skin, 0.25 m).
const BOTH: [(Placement, Passes); 4] = [
    (Placement::Strict, Passes::Full),
    (Placement::Loose, Passes::Full),
    (Placement::Strict, Passes::Incremental),
    (Placement::Loose, Passes::Incremental),
];

/// The fixed skin of the incremental cases.
fn skin_of(passes: Passes) -> f32 {
    if passes == Passes::Incremental {
        0.25
    } else {
        0.0
    }
}

/// A small world with one of each kind, stepped once.
fn world((placement, passes): (Placement, Passes)) -> (BroadPhase, Vec<ProxyKey>) {
    let mut bp = BroadPhase::new(Config {
        bounds: Some(Aabb::new(Vec3::splat(-4.0), Vec3::splat(4.0))),
        octree_placement: placement,
        skin: skin_of(passes),
        passes,
        ..Config::default()
    });
    let keys = vec![
        bp.insert_sphere(Vec3::ZERO, 1.0).unwrap(),
        bp.insert_sphere(Vec3::new(1.5, 0.0, 0.0), 1.0).unwrap(),
        bp.insert_sphere(Vec3::splat(100.0), 0.5).unwrap(),
        bp.insert_body(
            Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5)),
            BodyKind::Dynamic,
        )
        .unwrap(),
        bp.insert_body(
            Aabb::new(Vec3::splat(-9.0), Vec3::new(9.0, -0.5, 9.0)),
            BodyKind::Static,
        )
        .unwrap(),
    ];
    bp.step();
    (bp, keys)
}

type Snapshot = (usize, Vec<Option<Aabb>>, Vec<Pair>);

fn snapshot(bp: &mut BroadPhase, keys: &[ProxyKey]) -> Snapshot {
    let aabbs = keys.iter().map(|&k| bp.aabb(k)).collect();
    let len = bp.len();
    // Stepping twice: the second step's events must be empty if nothing changed.
    bp.step();
    let pairs = bp.pairs().to_vec();
    bp.step();
    assert!(bp.added().is_empty() && bp.removed().is_empty());
    (len, aabbs, pairs)
}

#[test]
fn bad_geometry_is_refused_and_changes_nothing() {
    for p in BOTH {
        let (mut bp, keys) = world(p);
        let before = snapshot(&mut bp, &keys);
        let (sphere, body) = (keys[0], keys[3]);
        for p in bad_points() {
            let e = bp.insert_sphere(p, 1.0).unwrap_err();
            assert!(matches!(e, Error::NonFinite { what: "center", .. }), "{e}");
            let e = bp.update_sphere(sphere, p, 1.0).unwrap_err();
            assert!(matches!(e, Error::NonFinite { what: "center", .. }), "{e}");
        }
        for r in [NAN, INF, -INF] {
            let e = bp.insert_sphere(Vec3::ZERO, r).unwrap_err();
            assert!(matches!(e, Error::NonFinite { what: "radius", .. }), "{e}");
            assert!(bp.update_sphere(sphere, Vec3::ZERO, r).is_err());
        }
        for r in [-1.0, -f32::MIN_POSITIVE] {
            assert_eq!(
                bp.insert_sphere(Vec3::ZERO, r),
                Err(Error::NegativeRadius(r))
            );
            assert_eq!(
                bp.update_sphere(sphere, Vec3::ZERO, r),
                Err(Error::NegativeRadius(r))
            );
        }
        for (aabb, what) in bad_boxes() {
            for kind in [BodyKind::Dynamic, BodyKind::Static] {
                let e = bp.insert_body(aabb, kind).unwrap_err();
                assert!(
                    matches!(e, Error::NonFinite { .. } | Error::InvertedAabb { .. }),
                    "{what}: {e}"
                );
            }
            assert!(bp.update_body(body, aabb).is_err(), "{what}");
        }
        assert_eq!(snapshot(&mut bp, &keys), before);
    }
}

#[test]
fn stale_and_wrong_kind_keys_are_refused_and_change_nothing() {
    for p in BOTH {
        let (mut bp, keys) = world(p);
        let doomed = bp.insert_sphere(Vec3::ZERO, 0.25).unwrap();
        bp.remove(doomed).unwrap();
        bp.step();
        let before = snapshot(&mut bp, &keys);
        let good = Aabb::new(Vec3::ZERO, Vec3::ONE);
        assert_eq!(bp.remove(doomed), Err(Error::UnknownProxy));
        assert_eq!(
            bp.update_sphere(doomed, Vec3::ZERO, 1.0),
            Err(Error::UnknownProxy)
        );
        assert_eq!(bp.update_body(doomed, good), Err(Error::UnknownProxy));
        assert_eq!(
            bp.update_body(ProxyKey::default(), good),
            Err(Error::UnknownProxy)
        );
        assert_eq!(bp.aabb(doomed), None);
        assert_eq!(
            bp.update_sphere(keys[3], Vec3::ZERO, 1.0),
            Err(Error::WrongKind)
        );
        assert_eq!(bp.update_body(keys[0], good), Err(Error::WrongKind));
        assert_eq!(snapshot(&mut bp, &keys), before);
    }
}

/// Keys carry no instance tag (they are plain slotmap keys): a key of another broadphase is
/// refused when it names no live proxy here, which this checks; one whose slot and version
/// happen to be live here cannot be told apart (documented in the crate docs).
#[test]
fn keys_of_another_instance_naming_no_live_proxy_are_refused() {
    for p in BOTH {
        let (mut bp, keys) = world(p);
        let mut other = BroadPhase::new(Config::default());
        let foreign: Vec<ProxyKey> = (0..12)
            .map(|i| other.insert_sphere(Vec3::splat(i as f32), 1.0).unwrap())
            .collect();
        let before = snapshot(&mut bp, &keys);
        for &k in &foreign[keys.len()..] {
            assert_eq!(bp.remove(k), Err(Error::UnknownProxy));
            assert_eq!(
                bp.update_sphere(k, Vec3::ZERO, 1.0),
                Err(Error::UnknownProxy)
            );
            assert_eq!(bp.aabb(k), None);
        }
        assert_eq!(snapshot(&mut bp, &keys), before);
    }
}

#[test]
fn bad_queries_answer_nothing_and_do_not_panic() {
    for p in BOTH {
        let (bp, _) = world(p);
        for p in bad_points() {
            assert_eq!(bp.cast_ray(p, Vec3::X, 10.0), None);
            assert_eq!(bp.cast_ray(Vec3::ZERO, p, 10.0), None);
        }
        assert_eq!(bp.cast_ray(Vec3::ZERO, Vec3::X, NAN), None);
        assert_eq!(bp.cast_ray(Vec3::ZERO, Vec3::X, -1.0), None);
        for (aabb, what) in bad_boxes() {
            let mut n = 0;
            bp.query_aabb(&aabb, |_| n += 1);
            assert_eq!(n, 0, "{what}");
        }
    }
}

#[test]
fn bad_config_is_refused_by_try_new_and_corrected_by_new() {
    let bad = [
        Config {
            margin: -1.0,
            ..Config::default()
        },
        Config {
            margin: NAN,
            ..Config::default()
        },
        Config {
            rebuild_threshold: 0.5,
            ..Config::default()
        },
        Config {
            skin: -0.1,
            ..Config::default()
        },
        Config {
            skin: f32::INFINITY,
            ..Config::default()
        },
        Config {
            bounds: Some(Aabb::new(Vec3::ONE, Vec3::ZERO)),
            ..Config::default()
        },
        Config {
            bounds: Some(Aabb::new(Vec3::ZERO, Vec3::new(1.0, 0.0, 1.0))),
            ..Config::default()
        },
        Config {
            bounds: Some(Aabb::new(Vec3::ZERO, Vec3::splat(INF))),
            ..Config::default()
        },
    ];
    for config in bad {
        let e = BroadPhase::try_new(config).unwrap_err();
        assert!(!e.to_string().is_empty());
        let bp = BroadPhase::new(config);
        assert!(
            bp.config().validate().is_ok(),
            "{config:?} -> {:?}",
            bp.config()
        );
    }
}

#[test]
fn errors_name_the_bad_value() {
    let mut bp = BroadPhase::new(Config::default());
    let e = bp.insert_sphere(Vec3::new(NAN, 1.0, 2.0), 1.0).unwrap_err();
    assert!(
        e.to_string().contains("center") && e.to_string().contains("NaN"),
        "{e}"
    );
    let e = bp.insert_sphere(Vec3::ZERO, -2.5).unwrap_err();
    assert!(e.to_string().contains("-2.5"), "{e}");
    let e = bp
        .insert_body(Aabb::new(Vec3::ONE, Vec3::ZERO), BodyKind::Dynamic)
        .unwrap_err();
    assert!(e.to_string().contains("inverted"), "{e}");
    let _: &dyn std::error::Error = &e;
}

mod structures {
    //! The same refusals on `Octree` and `Bvh` used on their own.

    use super::{INF, NAN, bad_boxes, bad_points};
    use broadleaf::{Aabb, Bvh, BvhConfig, Error, Octree, Pair, Placement, ProxyKey, Vec3};

    fn octree_snapshot(t: &mut Octree, keys: &[ProxyKey]) -> (usize, Vec<Option<Aabb>>, Vec<Pair>) {
        t.validate();
        let mut pairs = Vec::new();
        t.pairs_into(&mut pairs);
        pairs.sort_unstable();
        (t.len(), keys.iter().map(|&k| t.aabb(k)).collect(), pairs)
    }

    fn bvh_snapshot(t: &mut Bvh, keys: &[ProxyKey]) -> (usize, Vec<Option<Aabb>>, Vec<Pair>) {
        t.validate();
        let mut pairs = Vec::new();
        t.for_each_pair(|a, b| pairs.push(Pair::new(a, b)));
        pairs.sort_unstable();
        (t.len(), keys.iter().map(|&k| t.aabb(k)).collect(), pairs)
    }

    #[test]
    fn octree_refuses_bad_input_and_changes_nothing() {
        let bounds = Aabb::new(Vec3::splat(-4.0), Vec3::splat(4.0));
        assert_eq!(
            Octree::new(bounds, 11).unwrap_err(),
            Error::DepthOutOfRange { depth: 11, max: 10 }
        );
        let flat = Aabb::new(Vec3::ZERO, Vec3::new(1.0, 0.0, 1.0));
        assert!(matches!(
            Octree::new(flat, 3),
            Err(Error::InvalidBounds { .. })
        ));
        for p in [Placement::Strict, Placement::Loose] {
            let mut t = Octree::with_placement(bounds, 3, p).unwrap();
            let mut keys: Vec<ProxyKey> = (0..20)
                .map(|i| {
                    t.insert(Vec3::new(i as f32 * 0.4 - 4.0, 0.0, 0.0), 0.3)
                        .unwrap()
                })
                .collect();
            let gone = keys.pop().unwrap();
            t.remove(gone).unwrap();
            let before = octree_snapshot(&mut t, &keys);
            for p in bad_points() {
                assert!(matches!(
                    t.insert(p, 1.0),
                    Err(Error::NonFinite { what: "center", .. })
                ));
                assert!(matches!(
                    t.update(keys[0], p, 1.0),
                    Err(Error::NonFinite { .. })
                ));
                let mut hits = 0;
                t.query_sphere(p, 1.0, |_| hits += 1);
                assert_eq!(t.cast_ray(p, Vec3::X, 10.0), None);
                assert_eq!(t.cast_ray(Vec3::ZERO, p, 10.0), None);
                assert_eq!(hits, 0);
            }
            for r in [NAN, INF, -1.0] {
                assert!(t.insert(Vec3::ZERO, r).is_err());
                assert!(t.update(keys[0], Vec3::ZERO, r).is_err());
            }
            for (aabb, what) in bad_boxes() {
                let mut hits = 0;
                t.query_aabb(&aabb, |_| hits += 1);
                assert_eq!(hits, 0, "{what}");
            }
            assert_eq!(t.remove(gone), Err(Error::UnknownProxy));
            assert_eq!(t.update(gone, Vec3::ZERO, 1.0), Err(Error::UnknownProxy));
            assert_eq!(t.remove(ProxyKey::default()), Err(Error::UnknownProxy));
            assert_eq!(t.aabb(gone), None);
            assert_eq!(octree_snapshot(&mut t, &keys), before);
        }
    }

    #[test]
    fn bvh_refuses_bad_input_and_changes_nothing() {
        assert!(matches!(
            Bvh::new(BvhConfig {
                max_leaf_size: 0,
                ..BvhConfig::default()
            }),
            Err(Error::InvalidConfig {
                what: "max_leaf_size",
                ..
            })
        ));
        let mut t = Bvh::new(BvhConfig::default()).unwrap();
        let mut keys: Vec<ProxyKey> = (0..40)
            .map(|i| {
                let min = Vec3::new(i as f32 * 0.5, 0.0, 0.0);
                t.insert(Aabb::new(min, min + Vec3::ONE)).unwrap()
            })
            .collect();
        t.refit();
        let gone = keys.pop().unwrap();
        t.remove(gone).unwrap();
        let before = bvh_snapshot(&mut t, &keys);
        for (aabb, what) in bad_boxes() {
            let e = t.insert(aabb).unwrap_err();
            assert!(
                matches!(e, Error::NonFinite { .. } | Error::InvertedAabb { .. }),
                "{what}: {e}"
            );
            assert!(t.update(keys[0], aabb).is_err(), "{what}");
            let mut hits = 0;
            t.query_aabb(&aabb, |_| hits += 1);
            assert_eq!(hits, 0, "{what}");
        }
        for p in bad_points() {
            assert_eq!(t.cast_ray(p, Vec3::X, 10.0), None);
            assert_eq!(t.cast_ray(Vec3::ZERO, p, 10.0), None);
        }
        assert_eq!(t.cast_ray(Vec3::ZERO, Vec3::X, -1.0), None);
        assert_eq!(t.remove(gone), Err(Error::UnknownProxy));
        assert_eq!(t.update(gone, Aabb::default()), Err(Error::UnknownProxy));
        assert_eq!(t.aabb(gone), None);
        assert_eq!(bvh_snapshot(&mut t, &keys), before);
        t.refit();
        assert_eq!(bvh_snapshot(&mut t, &keys), before);
    }
}
