//! The same seeded scene and operations give bit-identical pair lists and events on every run:
//! a hash of 300 steps of a mixed scene (moving spheres, dynamic and static bodies, inserts and
//! removes) must equal a golden value. The golden value was computed from the brute-force
//! reference, so it also pins the exact pair set.

use broadleaf::fixtures::scene::{DT, Gas, Rng};
use broadleaf::{Aabb, BodyKind, BroadPhase, Config, Pair, Passes, ProxyKey, Vec3};
use slotmap::Key;

const GOLDEN: u64 = 0x76df_1956_69f5_ec7b;

/// How to insert the unrelated proxies (far from everything and from each other).
#[derive(Clone, Copy)]
enum Unrelated {
    None,
    Forward,
    Reverse,
    Interleaved,
}

/// Runs the scene and hashes every step's `pairs`, `added` and `removed`. Unrelated proxies are
/// inserted after the scene's own, so they take no key the scene uses and pair with nothing:
/// the hash must not depend on them or on their order.
fn scene_hash(unrelated: Unrelated) -> u64 {
    scene_hash_with_skin(unrelated, 0.0)
}

/// [`scene_hash`] with `Config::skin`: fat boxes of a fixed margin change the cost, never the
/// lists. A skin forces the incremental pass, so the lists it hashes are that pass's.
fn scene_hash_with_skin(unrelated: Unrelated, skin: f32) -> u64 {
    let mut gas = Gas::new(1500, 99);
    let mut bp = BroadPhase::new(Config {
        bounds: Some(gas.bounds),
        skin,
        passes: if skin > 0.0 {
            Passes::Incremental
        } else {
            Passes::Adaptive
        },
        ..Config::default()
    });
    let mut rng = Rng::new(5);
    let mut bodies: Vec<(ProxyKey, Aabb)> = Vec::new();
    let mut insert_bodies = |bp: &mut BroadPhase, rng: &mut Rng| {
        for i in 0..150 {
            let c = rng.vec3_in(gas.bounds.min, gas.bounds.max);
            let aabb = Aabb::from_center_half_extents(c, Vec3::splat(rng.range(0.1, 2.0)));
            let kind = if i % 5 == 0 {
                BodyKind::Static
            } else {
                BodyKind::Dynamic
            };
            bodies.push((bp.insert_body(aabb, kind).unwrap(), aabb));
        }
    };
    let mut spheres: Vec<ProxyKey> = gas
        .centers
        .iter()
        .map(|&c| bp.insert_sphere(c, gas.radius).unwrap())
        .collect();
    insert_bodies(&mut bp, &mut rng);
    // 200 spheres and 200 bodies on a line 10 km away, 10 m apart: they pair with nothing.
    let far = |i: u32| Vec3::new(1.0e4 + 10.0 * i as f32, -1.0e4, 0.0);
    let mut order: Vec<u32> = (0..400).collect();
    match unrelated {
        Unrelated::None => order.clear(),
        Unrelated::Forward => {}
        Unrelated::Reverse => order.reverse(),
        Unrelated::Interleaved => order.sort_by_key(|&i| (i % 7, i)),
    }
    for i in order {
        if i % 2 == 0 {
            bp.insert_sphere(far(i), 1.0).unwrap();
        } else {
            let aabb = Aabb::from_center_half_extents(far(i), Vec3::ONE);
            let kind = if i % 4 == 1 {
                BodyKind::Static
            } else {
                BodyKind::Dynamic
            };
            bp.insert_body(aabb, kind).unwrap();
        }
    }
    let mut h = Fnv::new();
    for step in 0..300 {
        gas.step(DT);
        for (i, &key) in spheres.iter().enumerate() {
            if key.is_null() {
                continue;
            }
            bp.update_sphere(key, gas.centers[i], gas.radius).unwrap();
        }
        for (key, aabb) in bodies.iter_mut().skip(step % 5).step_by(5) {
            let d = rng.vec3_in(Vec3::splat(-0.2), Vec3::splat(0.2));
            *aabb = Aabb::new(aabb.min + d, aabb.max + d);
            bp.update_body(*key, *aabb).unwrap();
        }
        // Remove one sphere and re-insert one that was removed earlier.
        let i = rng.below(spheres.len() as u32) as usize;
        if !spheres[i].is_null() {
            bp.remove(spheres[i]).unwrap();
            spheres[i] = ProxyKey::null();
        }
        let j = rng.below(spheres.len() as u32) as usize;
        if spheres[j].is_null() {
            spheres[j] = bp.insert_sphere(gas.centers[j], gas.radius).unwrap();
        }
        bp.step();
        h.pairs(1, bp.pairs());
        h.pairs(2, bp.added());
        h.pairs(3, bp.removed());
    }
    h.0
}

#[test]
fn three_hundred_steps_hash_to_the_golden_value() {
    let h = scene_hash(Unrelated::None);
    assert_eq!(
        h,
        scene_hash(Unrelated::None),
        "two runs in one process differ"
    );
    assert_eq!(h, GOLDEN, "pair lists changed: got {h:#x}");
}

#[test]
fn unrelated_proxies_in_any_insertion_order_change_nothing() {
    for order in [
        Unrelated::Forward,
        Unrelated::Reverse,
        Unrelated::Interleaved,
    ] {
        assert_eq!(scene_hash(order), GOLDEN);
    }
}

#[test]
fn the_incremental_pass_gives_the_same_lists() {
    for skin in [0.02, 0.3, 2.0] {
        assert_eq!(
            scene_hash_with_skin(Unrelated::None, skin),
            GOLDEN,
            "skin {skin}"
        );
    }
    assert_eq!(scene_hash_with_skin(Unrelated::Reverse, 0.3), GOLDEN);
}

// The golden hash derived independently of the code under test: the expected value comes from
// the test's own model (its own shapes, O(n²)-equivalent sweep and set difference), not from
// the broadphase's output.

mod common;

use common::{Expected, Fnv, KeyPair, Model, ModelShape};
use std::collections::HashMap;

/// The model's hash of the scene below (every step's `pairs`, `added`, `removed` as the keys'
/// FFI bits, in `(a, b)` order). Derived from the model side of
/// [`model_scene_hashes`]: run the test; its message prints the model's value. It pins the key
/// values too (the broadphase reuses a freed slot only after the next step), so a change of key
/// issuing changes it while [`GOLDEN_BY_ORDINAL`] stays.
const GOLDEN_BY_KEY: u64 = 0x996a_3903_4845_f71d;

/// The model's hash of the same lists with each key replaced by its proxy's insertion ordinal
/// (pairs sorted by ordinals): a function of the scene script alone.
const GOLDEN_BY_ORDINAL: u64 = 0xdbaf_9233_9d8f_fe7d;

/// Hashes of one run: the broadphase's lists by key, the model's by key and by ordinal.
struct Hashes {
    library: u64,
    model: u64,
    ordinal: u64,
}

impl Fnv {
    fn ordinal_pairs(&mut self, tag: u64, pairs: &[KeyPair], ordinal: &HashMap<ProxyKey, u64>) {
        let mut o: Vec<(u64, u64)> = pairs
            .iter()
            .map(|(a, b)| {
                let (x, y) = (ordinal[a], ordinal[b]);
                (x.min(y), x.max(y))
            })
            .collect();
        o.sort_unstable();
        self.write(tag);
        self.write(o.len() as u64);
        for (x, y) in o {
            self.write(x);
            self.write(y);
        }
    }
}

/// Inserts the scene's `i`-th kind of proxy at a random place; returns its key and velocity.
fn insert(
    bp: &mut BroadPhase,
    model: &mut Model,
    rng: &mut common::Rng,
    ordinal: &mut HashMap<ProxyKey, u64>,
    i: usize,
) -> (ProxyKey, Vec3) {
    let c = rng.offset(8.0);
    let shape = match i % 7 {
        0 => ModelShape::body(
            c,
            rng.vec3_in(Vec3::splat(0.1), Vec3::splat(1.0)),
            i % 35 == 0,
        ),
        _ => ModelShape::Sphere {
            center: c,
            radius: rng.range(0.1, 0.6),
        },
    };
    let key = model.insert(bp, shape);
    ordinal.insert(key, ordinal.len() as u64);
    let v = if shape.is_static() {
        Vec3::ZERO
    } else {
        rng.offset(0.08)
    };
    (key, v)
}

/// 1200 spheres and 200 bodies (40 static) in a 16 m cube, 200 steps: each step a third of
/// the dynamic proxies move by their velocity (a quarter of the spheres through one batch), one
/// in fifty teleports, two are removed and two inserted. Floats only through `+ - * /`.
fn model_scene_hashes(config: Config) -> Hashes {
    let mut rng = common::Rng::new(0x5eed);
    let mut bp = BroadPhase::new(config);
    let mut model = Model::new(config.margin);
    model.quadratic = false;
    let mut ordinal: HashMap<ProxyKey, u64> = HashMap::new();
    let mut live: Vec<(ProxyKey, Vec3)> = Vec::new();
    for i in 0..1400 {
        live.push(insert(&mut bp, &mut model, &mut rng, &mut ordinal, i));
    }
    let (mut lib, mut own, mut ord) = (Fnv::new(), Fnv::new(), Fnv::new());
    for step in 0..200 {
        let mut batch = Vec::new();
        for &(key, v) in live.iter().skip(step % 3).step_by(3) {
            let shape = model.shapes[&key];
            if v == Vec3::ZERO {
                continue;
            }
            let moved = if rng.below(50) == 0 {
                shape.moved(rng.offset(8.0) - shape.center())
            } else {
                shape.moved(v)
            };
            match moved {
                ModelShape::Sphere { center, radius } if rng.below(4) == 0 => {
                    model.shapes.insert(key, moved);
                    batch.push((key, center, radius));
                }
                _ => model.update(&mut bp, key, moved),
            }
        }
        bp.update_spheres(&batch).unwrap();
        for _ in 0..2 {
            let (key, _) = live.swap_remove(rng.below(live.len()));
            model.remove(&mut bp, key);
        }
        for _ in 0..2 {
            let i = rng.below(7);
            live.push(insert(&mut bp, &mut model, &mut rng, &mut ordinal, i));
        }
        let Expected {
            pairs,
            added,
            removed,
        } = model.expect_step();
        bp.step();
        lib.pairs(1, bp.pairs());
        lib.pairs(2, bp.added());
        lib.pairs(3, bp.removed());
        for (tag, list) in [(1, &pairs), (2, &added), (3, &removed)] {
            let as_pairs: Vec<Pair> = list.iter().map(|&(a, b)| Pair { a, b }).collect();
            own.pairs(tag, &as_pairs);
            ord.ordinal_pairs(tag, list, &ordinal);
        }
    }
    Hashes {
        library: lib.0,
        model: own.0,
        ordinal: ord.0,
    }
}

#[test]
fn scene_hash_equals_the_models_and_the_golden_values() {
    for config in [
        Config::default(),
        Config {
            bounds: Some(Aabb::new(Vec3::splat(-8.0), Vec3::splat(8.0))),
            ..Config::default()
        },
        Config {
            skin: 0.05,
            passes: Passes::Incremental,
            ..Config::default()
        },
        Config {
            passes: Passes::Full,
            ..Config::default()
        },
    ] {
        let h = model_scene_hashes(config);
        assert_eq!(
            (h.model, h.ordinal),
            (GOLDEN_BY_KEY, GOLDEN_BY_ORDINAL),
            "the model's hashes changed (the scene script or key issuing changed): {:#x}, {:#x}",
            h.model,
            h.ordinal
        );
        assert_eq!(
            h.library, h.model,
            "{config:?}: the broadphase's lists differ from the model's"
        );
    }
}
