//! `insert_spheres`: a batch of spheres checked whole, then inserted with its slots handed out
//! along the Morton curve through the centres.
//!
//! - Random worlds (spheres and bodies in a ±6 m box, clumps, equal centres) grow by batches,
//!   single inserts, removes and moves, under both passes and both placements; after every
//!   step the sorted pairs, `added` and `removed` equal the test's O(n²) model, and
//!   `validate()` passes. Each batch's keys come back in the batch's order, distinct and live,
//!   each with its own shape.
//! - A batch with a bad entry (NaN or infinite coordinate or radius, a negative radius) is
//!   refused at its first bad entry with that entry's error, and nothing changes: `len()`,
//!   every shape and the next step's lists equal the model's without the batch.
//! - In an empty broadphase the batch's slots (the low half of a key's FFI form) follow the
//!   test's own Morton order: each centre's cell of the 1024³ lattice over the batch's bounding
//!   box, its bits interleaved x first, ties in batch order.

mod common;

use broadleaf::octree::Placement;
use broadleaf::{BroadPhase, Config, Error, Passes, ProxyKey, Vec3};
use common::{Model, ModelShape, Rng};
use proptest::prelude::*;
use slotmap::Key as _;

/// A batch of `n` spheres: uniform in the box, or (with `clump`) within 0.5 m of a few
/// centres, some repeating an earlier centre exactly.
fn spheres(rng: &mut Rng, n: usize, clump: bool) -> Vec<(Vec3, f32)> {
    let seeds: Vec<Vec3> = (0..3).map(|_| rng.offset(6.0)).collect();
    let mut out: Vec<(Vec3, f32)> = Vec::with_capacity(n);
    for _ in 0..n {
        let center = match (clump, rng.below(6)) {
            (_, 0) if !out.is_empty() => out[rng.below(out.len())].0,
            (true, _) => seeds[rng.below(3)] + rng.offset(0.5),
            (false, _) => rng.offset(6.0),
        };
        out.push((center, rng.range(0.0, 1.2)));
    }
    out
}

/// Spoils entry `at` of `batch` in one of four ways; returns the error `insert_sphere` gives.
fn spoil(batch: &mut [(Vec3, f32)], at: usize, how: usize) -> Error {
    let (center, radius) = &mut batch[at];
    match how % 4 {
        0 => {
            center.y = f32::NAN;
            Error::NonFinite {
                what: "center",
                value: *center,
            }
        }
        1 => {
            center.z = f32::NEG_INFINITY;
            Error::NonFinite {
                what: "center",
                value: *center,
            }
        }
        2 => {
            *radius = f32::INFINITY;
            Error::NonFinite {
                what: "radius",
                value: Vec3::new(*radius, 0.0, 0.0),
            }
        }
        _ => {
            *radius = -0.25;
            Error::NegativeRadius(-0.25)
        }
    }
}

fn run(config: Config, seed: u64, ops: &[u8]) {
    let mut bp = BroadPhase::new(config);
    let mut model = Model::new(config.margin);
    let mut rng = Rng::new(seed);
    for (n, &op) in ops.iter().enumerate() {
        let context = format!("seed {seed}, op {n} ({op})");
        match op % 6 {
            0 | 1 => {
                let size = rng.below(40);
                let batch = spheres(&mut rng, size, op % 2 == 1);
                let keys = bp.insert_spheres(&batch).expect("a good batch is accepted");
                assert_eq!(keys.len(), batch.len(), "{context}: one key an entry");
                for (&key, &(center, radius)) in keys.iter().zip(&batch) {
                    assert!(bp.contains(key), "{context}: {key:?} is live");
                    let old = model
                        .shapes
                        .insert(key, ModelShape::Sphere { center, radius });
                    assert!(
                        old.is_none(),
                        "{context}: the batch issued a live key {key:?}"
                    );
                }
            }
            2 => {
                let size = 1 + rng.below(30);
                let clump = rng.chance(0.5);
                let mut batch = spheres(&mut rng, size, clump);
                let first = rng.below(size);
                let want = spoil(&mut batch, first, rng.below(4));
                // Later entries may be bad too: the error names the first.
                if first + 1 < size && rng.chance(0.5) {
                    let later = first + 1 + rng.below(size - first - 1);
                    spoil(&mut batch, later, rng.below(4));
                }
                let len = bp.len();
                let got = bp
                    .insert_spheres(&batch)
                    .expect_err("a bad batch is refused");
                assert_eq!(got.index, first, "{context}: the first bad entry");
                match (got.error, want) {
                    (Error::NonFinite { what: g, .. }, Error::NonFinite { what: w, .. }) => {
                        assert_eq!(g, w, "{context}");
                    }
                    (g, w) => assert_eq!(g, w, "{context}"),
                }
                assert_eq!(bp.len(), len, "{context}: nothing inserted");
            }
            3 => {
                let shape = if rng.chance(0.5) {
                    ModelShape::Sphere {
                        center: rng.offset(6.0),
                        radius: rng.range(0.0, 1.2),
                    }
                } else {
                    ModelShape::body(
                        rng.offset(6.0),
                        Vec3::splat(rng.range(0.0, 1.0)),
                        rng.chance(0.3),
                    )
                };
                model.insert(&mut bp, shape);
            }
            4 => {
                let keys = model.keys();
                for _ in 0..keys.len().min(4) {
                    let key = keys[rng.below(keys.len())];
                    if model.shapes.contains_key(&key) {
                        model.remove(&mut bp, key);
                    }
                }
                for key in model.keys() {
                    if rng.chance(0.3) {
                        let shape = model.shapes[&key].moved(rng.offset(0.4));
                        model.update(&mut bp, key, shape);
                    }
                }
            }
            _ => {}
        }
        model.assert_same_proxies(&bp, &context);
        model.check_step(&mut bp, &context);
    }
}

fn configs() -> impl Strategy<Value = Config> {
    let passes = prop_oneof![
        Just(Passes::Adaptive),
        Just(Passes::Full),
        Just(Passes::Incremental)
    ];
    let placement = prop_oneof![Just(Placement::Loose), Just(Placement::Strict)];
    (passes, placement).prop_map(|(passes, octree_placement)| Config {
        passes,
        octree_placement,
        ..Config::default()
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn batches_pair_like_the_model(
        config in configs(),
        seed in any::<u64>(),
        ops in prop::collection::vec(any::<u8>(), 1..24),
    ) {
        run(config, seed, &ops);
    }
}

/// The test's own Morton code of `p` on the 1024³ lattice over `lo..hi`, bit by bit.
fn morton(p: Vec3, lo: Vec3, hi: Vec3) -> u64 {
    let cell = |x: f32, l: f32, h: f32| -> u64 {
        if h > l {
            (((f64::from(x) - f64::from(l)) * 1023.0 / (f64::from(h) - f64::from(l))) as u64)
                .min(1023)
        } else {
            0
        }
    };
    let c = [
        cell(p.x, lo.x, hi.x),
        cell(p.y, lo.y, hi.y),
        cell(p.z, lo.z, hi.z),
    ];
    let mut code = 0;
    for bit in 0..10 {
        for (axis, v) in c.iter().enumerate() {
            code |= ((v >> bit) & 1) << (3 * bit + axis);
        }
    }
    code
}

#[test]
fn a_batch_numbers_its_spheres_along_the_curve() {
    for (seed, clump) in [(1, false), (2, true), (3, false)] {
        let mut rng = Rng::new(seed);
        let batch = spheres(&mut rng, 500, clump);
        let mut bp = BroadPhase::new(Config::default());
        let keys = bp.insert_spheres(&batch).unwrap();
        let slot = |k: ProxyKey| k.data().as_ffi() as u32;
        let (lo, hi) = batch
            .iter()
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &(c, _)| {
                (lo.min(c), hi.max(c))
            });
        let mut by_slot: Vec<usize> = (0..batch.len()).collect();
        by_slot.sort_by_key(|&i| slot(keys[i]));
        let mut by_curve: Vec<usize> = (0..batch.len()).collect();
        by_curve.sort_by_key(|&i| (morton(batch[i].0, lo, hi), i));
        assert_eq!(by_slot, by_curve, "seed {seed}");
    }
}

#[test]
fn an_empty_batch_inserts_nothing() {
    let mut bp = BroadPhase::new(Config::default());
    assert_eq!(bp.insert_spheres(&[]), Ok(Vec::new()));
    assert!(bp.is_empty());
    bp.step();
    assert!(bp.pairs().is_empty());
}

#[test]
fn centres_far_apart_are_numbered_without_overflow() {
    // The lattice spans ±3e38: its extent overflows `f32`, not the curve's arithmetic.
    let batch = [
        (Vec3::splat(3e38), 1.0),
        (Vec3::splat(-3e38), 1.0),
        (Vec3::ZERO, 1.0),
        (Vec3::new(3e38, -3e38, 0.0), 1.0),
    ];
    let mut bp = BroadPhase::new(Config::default());
    let keys = bp.insert_spheres(&batch).unwrap();
    assert_eq!(bp.len(), 4);
    for (k, &(c, r)) in keys.iter().zip(&batch) {
        assert_eq!(
            bp.shape(*k),
            Some(broadleaf::Shape::Sphere {
                center: c,
                radius: r
            })
        );
    }
    bp.step();
    assert!(bp.pairs().is_empty());
    bp.validate();
}
