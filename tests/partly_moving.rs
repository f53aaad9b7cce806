//! Worlds where some of it moves: spheres and bodies at rest in a cube, with a fixed share of
//! the spheres (1, 2, 5, 10, 20 and 50 %) moving at gas speed (5 m/s at 60 steps a second,
//! bouncing off the cube's faces; they leave any fat box within a few steps) and a few bodies
//! drifting. Each world runs with the adaptive choice and with each pass forced, and after
//! every step `pairs`, `added` and `removed` equal the test's own brute force over its own
//! model, and `validate()` holds. The share moving changes between phases in both directions,
//! so the adaptive choice crosses whatever switch it makes on the way up and on the way down.

mod common;

use broadleaf::{BroadPhase, Config, Pass, Passes, ProxyKey, Vec3};
use common::{Model, ModelShape, Rng};

/// Half the side of the cube, in metres.
const HALF: f32 = 14.0;
/// Spheres in the world (radius 0.3–0.7 m): about two candidates each at rest.
const SPHERES: usize = 3000;
/// Dynamic bodies, one in fifty of them drifting with the movers.
const BODIES: usize = 150;
/// The shares moving, in percent, in the order the phases run.
const PHASES: [u32; 11] = [1, 2, 5, 10, 20, 50, 20, 10, 5, 2, 1];
/// Steps per phase: long enough for the movers to leave their fat boxes.
const STEPS: usize = 12;

struct Mover {
    key: ProxyKey,
    velocity: Vec3,
}

fn world(config: Config, seed: u64) -> Vec<Pass> {
    let mut rng = Rng::new(seed);
    let mut bp = BroadPhase::new(config);
    let mut model = Model::new(config.margin);
    model.quadratic = false;
    let corner = Vec3::splat(HALF);
    let mut movers = Vec::new();
    for _ in 0..SPHERES {
        let center = rng.vec3_in(-corner, corner);
        let radius = rng.range(0.3, 0.7);
        let key = model.insert(&mut bp, ModelShape::Sphere { center, radius });
        let v = rng.offset(1.0);
        movers.push(Mover {
            key,
            velocity: v * (5.0 / 60.0 / v.length().max(1e-3)),
        });
    }
    for i in 0..BODIES {
        let c = rng.vec3_in(-corner, corner);
        let h = Vec3::new(
            rng.range(0.2, 1.5),
            rng.range(0.2, 1.5),
            rng.range(0.2, 1.5),
        );
        let key = model.insert(&mut bp, ModelShape::body(c, h, false));
        if i % 50 == 0 {
            movers.push(Mover {
                key,
                velocity: rng.offset(0.05),
            });
        }
    }
    model.check_step(&mut bp, "inserted");
    let mut passes = Vec::new();
    for (phase, &percent) in PHASES.iter().enumerate() {
        let moving = SPHERES * percent as usize / 100;
        for step in 0..STEPS {
            let (spheres, bodies) = movers.split_at_mut(SPHERES);
            for m in spheres[..moving].iter_mut().chain(bodies) {
                let c = model.shapes[&m.key].center();
                for axis in 0..3 {
                    if (c[axis] + m.velocity[axis]).abs() > HALF {
                        m.velocity[axis] = -m.velocity[axis];
                    }
                }
                let moved = model.shapes[&m.key].moved(m.velocity);
                model.update(&mut bp, m.key, moved);
            }
            let context = format!("{config:?}, phase {phase} ({percent} % moving), step {step}");
            let want = model.check_step(&mut bp, &context);
            assert!(want.pairs.len() > 1000, "{context}: too few pairs to test");
            passes.push(bp.stats().pass);
        }
    }
    passes
}

#[test]
fn adaptive_partly_moving_worlds_equal_the_model_every_step() {
    let passes = world(Config::default(), 11);
    // At 1 % moving the incremental pass is far cheaper than the full one: after the first
    // phase's first steps the default runs it.
    assert!(
        passes[STEPS / 2..STEPS]
            .iter()
            .all(|&p| p == Pass::Incremental),
        "1 % moving, not incremental: {passes:?}"
    );
    assert_eq!(
        passes.last(),
        Some(&Pass::Incremental),
        "back at 1 %, not incremental: {passes:?}"
    );
    // Half the spheres leaving their fat boxes every few steps is a world in motion: the
    // switch is crossed on the way up and again on the way down.
    let switches = passes.windows(2).filter(|w| w[0] != w[1]).count();
    assert!(
        passes.contains(&Pass::Full),
        "never the full pass: {passes:?}"
    );
    assert!(switches >= 2, "{switches} switches: {passes:?}");
}

#[test]
fn partly_moving_worlds_in_full_passes_equal_the_model_every_step() {
    let passes = world(
        Config {
            passes: Passes::Full,
            ..Config::default()
        },
        12,
    );
    assert!(passes.iter().all(|&p| p == Pass::Full), "{passes:?}");
}

#[test]
fn partly_moving_worlds_in_incremental_passes_equal_the_model_every_step() {
    let passes = world(
        Config {
            passes: Passes::Incremental,
            ..Config::default()
        },
        13,
    );
    assert!(
        passes[1..].iter().all(|&p| p == Pass::Incremental),
        "{passes:?}"
    );
}

#[test]
fn partly_moving_worlds_with_a_margin_equal_the_model_every_step() {
    world(
        Config {
            margin: 0.02,
            ..Config::default()
        },
        14,
    );
}
