//! The updates' apply in the incremental regime: a step applies the stale spheres in one walk
//! (over every slot when many are stale, over the sorted movers when few are), classifies each
//! mover quiet or loud there, and gives the escaped ones new fat boxes after the walk; spheres
//! inserted since the last step, bodies and removed proxies take the other path. Here each step
//! mixes those cases: most spheres or a few updated, in random order and some twice, by
//! jitters (quiet), steps of a few centimetres (loud) or jumps (escapes); spheres inserted and
//! then updated before the step, spheres updated and then removed, bodies moved. Under
//! `Passes::Incremental` and `Passes::Adaptive`, after every step the three lists equal the
//! test's own brute force over its own copy of the shapes, and `validate()` holds.

mod common;

use broadleaf::{BroadPhase, Config, Passes, ProxyKey, Vec3};
use common::{Model, ModelShape, Rng};

const SIDE: f32 = 12.0;

fn sphere(rng: &mut Rng) -> ModelShape {
    ModelShape::Sphere {
        center: rng.vec3_in(Vec3::ZERO, Vec3::splat(SIDE)),
        radius: rng.range(0.3, 0.7),
    }
}

/// A sphere's or a body's next shape: a jitter, a short step or a jump.
fn moved(rng: &mut Rng, shape: &ModelShape) -> ModelShape {
    match rng.below(10) {
        0 => shape.teleported(rng.vec3_in(Vec3::ZERO, Vec3::splat(SIDE))),
        1..=3 => shape.moved(rng.offset(0.05)),
        _ => shape.moved(rng.offset(0.0005)),
    }
}

fn run(passes: Passes, seed: u64) {
    let mut rng = Rng::new(seed);
    let mut bp = BroadPhase::new(Config {
        passes,
        ..Config::default()
    });
    let mut model = Model::new(Config::default().margin);
    for _ in 0..300 {
        let s = sphere(&mut rng);
        model.insert(&mut bp, s);
    }
    for i in 0..6 {
        let c = rng.vec3_in(Vec3::ZERO, Vec3::splat(SIDE));
        let b = ModelShape::body(c, Vec3::splat(rng.range(0.5, 1.5)), i == 0);
        model.insert(&mut bp, b);
    }
    model.check_step(&mut bp, &format!("{passes:?} seed {seed} first step"));
    for step in 0..40 {
        let context = format!("{passes:?} seed {seed} step {step}");
        let keys: Vec<ProxyKey> = model.keys();
        // Most proxies (the walk over every slot) or a few (the sorted movers).
        let share = if step % 3 == 0 { 0.05 } else { 0.8 };
        let mut order: Vec<ProxyKey> = keys.iter().copied().filter(|_| rng.chance(share)).collect();
        for i in (1..order.len()).rev() {
            order.swap(i, rng.below(i + 1));
        }
        for &k in &order {
            let shape = model.shapes[&k];
            if shape.is_static() {
                continue;
            }
            let next = moved(&mut rng, &shape);
            model.update(&mut bp, k, next);
            if rng.chance(0.05) {
                let again = moved(&mut rng, &next);
                model.update(&mut bp, k, again);
            }
        }
        // Inserted, then updated before the step.
        for _ in 0..rng.below(4) {
            let s = sphere(&mut rng);
            let k = model.insert(&mut bp, s);
            if rng.chance(0.7) {
                let next = moved(&mut rng, &s);
                model.update(&mut bp, k, next);
            }
        }
        // Updated, then removed before the step.
        for _ in 0..rng.below(3) {
            let keys = model.keys();
            let k = keys[rng.below(keys.len())];
            let shape = model.shapes[&k];
            if !shape.is_sphere() {
                continue;
            }
            let next = moved(&mut rng, &shape);
            model.update(&mut bp, k, next);
            model.remove(&mut bp, k);
        }
        model.check_step(&mut bp, &context);
    }
}

#[test]
fn incremental_apply_paths_match_brute_force() {
    for seed in 1..=3 {
        run(Passes::Incremental, seed);
    }
}

#[test]
fn adaptive_apply_paths_match_brute_force() {
    for seed in 11..=13 {
        run(Passes::Adaptive, seed);
    }
}
