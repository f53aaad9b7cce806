//! Nudges: in the incremental regime, an update whose proxy stays in its fat box and drifts
//! under half its slack is applied by the update call itself (see the crate docs' "Queries").
//! Here a pile of spheres and a few dynamic bodies rest in the regime and are sent every step
//! in slot order: most updates are jitters (nudges), some proxies are sent twice (jittered
//! twice, nudged then moved out of reach, moved then jittered; a second update is out of slot
//! order, which ends the nudges until the step), some are inserted or removed. Between the
//! updates and the step, `validate()` holds and box queries equal the test's own brute force
//! over its copy of the shapes. After every step the three lists equal the brute force,
//! `stats().updated` counts each updated, inserted or removed proxy once, and a step whose
//! updates were all nudges reports the incremental pass.

mod common;

use broadleaf::{Aabb, BroadPhase, Config, Pass, ProxyKey, Vec3};
use common::{Model, ModelShape, Rng, overlaps};
use std::collections::BTreeSet;

/// The pile: spheres of radius 0.5 on a grid of 0.95 m, so neighbours overlap.
fn pile(bp: &mut BroadPhase, model: &mut Model) {
    for i in 0..512 {
        let at = Vec3::new((i % 8) as f32, ((i / 8) % 8) as f32, (i / 64) as f32) * 0.95;
        model.insert(
            bp,
            ModelShape::Sphere {
                center: at,
                radius: 0.5,
            },
        );
    }
    for i in 0..4 {
        let c = Vec3::new(2.0 * i as f32, 8.0, 3.0);
        model.insert(bp, ModelShape::body(c, Vec3::splat(0.6), false));
    }
}

/// Every proxy whose pair box overlaps `q`, by the model.
fn brute_query(model: &Model, q: &Aabb) -> BTreeSet<ProxyKey> {
    model
        .shapes
        .iter()
        .filter(|(_, s)| overlaps(&s.pair_box(model.margin), q))
        .map(|(&k, _)| k)
        .collect()
}

/// Box queries between the updates and the step equal the brute force over the latest shapes.
fn check_queries(bp: &BroadPhase, model: &Model, rng: &mut Rng, context: &str) {
    for q in 0..20 {
        let lo = rng.vec3_in(Vec3::splat(-1.0), Vec3::splat(8.0));
        let aabb = Aabb {
            min: lo,
            max: lo + Vec3::splat(rng.range(0.0, 2.0)),
        };
        let mut got = BTreeSet::new();
        bp.query_aabb(&aabb, |k| {
            got.insert(k);
        });
        assert_eq!(got, brute_query(model, &aabb), "{context}: query {q}");
    }
}

fn run(seed: u64) {
    let mut rng = Rng::new(seed);
    let mut bp = BroadPhase::new(Config::default());
    let mut model = Model::new(Config::default().margin);
    pile(&mut bp, &mut model);
    model.check_step(&mut bp, &format!("seed {seed} first step"));
    // At rest, sent every step: the regime is entered.
    for step in 0..6 {
        for k in model.keys() {
            let s = model.shapes[&k];
            model.update(&mut bp, k, s);
        }
        model.check_step(&mut bp, &format!("seed {seed} rest {step}"));
    }
    assert_eq!(
        bp.stats().pass,
        Pass::Incremental,
        "seed {seed}: not in the regime at rest"
    );
    let (mut all_nudged_steps, mut in_regime) = (0, true);
    for step in 0..40 {
        let context = format!("seed {seed} step {step}");
        // Every fourth step sends jitters only; the others mix in moves, inserts and removals.
        let calm = step % 4 == 0;
        let mut updated = BTreeSet::new();
        for k in model.keys() {
            let s = model.shapes[&k];
            let jitter = s.moved(rng.offset(0.0002));
            model.update(&mut bp, k, jitter);
            updated.insert(k);
            if calm {
                continue;
            }
            match rng.below(40) {
                // Jittered twice.
                0 => model.update(&mut bp, k, jitter.moved(rng.offset(0.0002))),
                // Nudged, then moved out of its fat box.
                1 => model.update(&mut bp, k, jitter.moved(rng.offset(0.8))),
                // Nudged, then moved a few centimetres (loud, maybe escaped).
                2 => model.update(&mut bp, k, jitter.moved(rng.offset(0.04))),
                _ => {}
            }
        }
        if !calm {
            // Moved first, then jittered back near where it was.
            for k in model.keys() {
                if !rng.chance(0.03) {
                    continue;
                }
                let s = model.shapes[&k];
                model.update(&mut bp, k, s.moved(rng.offset(0.3)));
                model.update(&mut bp, k, s.moved(rng.offset(0.0002)));
            }
            if rng.chance(0.5) {
                let keys = model.keys();
                let k = keys[rng.below(keys.len())];
                if model.shapes[&k].is_sphere() {
                    model.remove(&mut bp, k);
                    updated.remove(&k);
                    updated.insert(k);
                }
            }
            if rng.chance(0.5) {
                let at = rng.vec3_in(Vec3::ZERO, Vec3::splat(7.0));
                let k = model.insert(
                    &mut bp,
                    ModelShape::Sphere {
                        center: at,
                        radius: 0.5,
                    },
                );
                updated.insert(k);
            }
        }
        bp.validate();
        check_queries(&bp, &model, &mut rng, &context);
        model.check_step(&mut bp, &context);
        assert_eq!(bp.stats().updated, updated.len(), "{context}: updated");
        // Updated proxies always make a pass; in the regime, nudges alone make the
        // incremental one.
        assert_ne!(bp.stats().pass, Pass::Unchanged, "{context}: pass");
        if calm && in_regime {
            assert_eq!(bp.stats().pass, Pass::Incremental, "{context}: pass");
            all_nudged_steps += 1;
        }
        in_regime = matches!(bp.stats().pass, Pass::Incremental | Pass::FullFat);
    }
    assert!(
        all_nudged_steps >= 5,
        "seed {seed}: {all_nudged_steps} calm steps"
    );
}

#[test]
fn nudged_updates_keep_queries_lists_and_counts_exact() {
    for seed in 1..=3 {
        run(seed);
    }
}
