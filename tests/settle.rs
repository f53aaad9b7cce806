//! The pass follows the motion, not how many proxies were sent (issue 40): a pile whose every
//! sphere is sent each step while its motion decays geometrically to rest enters the
//! incremental regime within a few steps of that motion dropping under the smallest skin,
//! and stays there; the same pile woken (every sphere moving fast again) leaves it and
//! comes back once it settles; a gas whose spheres all move about 8 cm a step never enters
//! it. After every step the pairs, `added` and `removed` equal the test's own sweep over its
//! own model, and `validate()` holds.

mod common;

use broadleaf::{BroadPhase, Config, Pass, ProxyKey, Vec3};
use common::{Model, ModelShape, Rng};

const RADIUS: f32 = 0.5;
/// Steps per second of the scenes.
const HZ: f32 = 60.0;

/// A dense pile: spheres of radius 0.5 on a jittered lattice of spacing 0.97 m, so each one's
/// box overlaps its lattice neighbours' (as a settled pile's do) in a `side`³ block.
fn pile(model: &mut Model, bp: &mut BroadPhase, rng: &mut Rng, side: usize) -> Vec<ProxyKey> {
    let mut keys = Vec::new();
    for i in 0..side * side * side {
        let (x, y, z) = (i % side, (i / side) % side, i / (side * side));
        let jitter = rng.offset(0.01);
        let center = Vec3::new(x as f32, y as f32, z as f32) * 0.97 + jitter;
        let shape = ModelShape::Sphere {
            center,
            radius: RADIUS,
        };
        keys.push(model.insert(bp, shape));
    }
    keys
}

/// A default broadphase holding a `side`³ [`pile`] (seeded by `seed`), stepped once against
/// its model, with the rng that goes on moving it.
fn built_pile(seed: u64, side: usize) -> (Rng, BroadPhase, Model, Vec<ProxyKey>) {
    let mut rng = Rng::new(seed);
    let mut bp = BroadPhase::new(Config::default());
    let mut model = Model::new(0.0);
    model.quadratic = false;
    let keys = pile(&mut model, &mut bp, &mut rng, side);
    model.check_step(&mut bp, "built");
    (rng, bp, model, keys)
}

/// Moves every sphere by `speed` m/s for one step in a random direction each, through
/// `update_centers` (all of them sent, as a replay of an engine's frames sends them).
fn shake(model: &mut Model, bp: &mut BroadPhase, rng: &mut Rng, keys: &[ProxyKey], speed: f32) {
    let centers: Vec<Vec3> = keys
        .iter()
        .map(|k| {
            let d = rng.offset(1.0);
            let step = d * (speed / HZ / d.length().max(1e-3));
            let moved = model.shapes[k].moved(step);
            model.shapes.insert(*k, moved);
            moved.center()
        })
        .collect();
    bp.update_centers(keys, &centers)
        .expect("live spheres, finite centres");
}

/// Decays the pile's motion geometrically from `speed` m/s by `decay` per step for `steps`
/// steps, checking every step against the model; returns each step's pass and speed.
fn settle(
    model: &mut Model,
    bp: &mut BroadPhase,
    rng: &mut Rng,
    keys: &[ProxyKey],
    (speed, decay, steps): (f32, f32, usize),
    context: &str,
) -> Vec<(Pass, f32)> {
    (0..steps)
        .map(|k| {
            let v = speed * decay.powi(k as i32);
            shake(model, bp, rng, keys, v);
            model.check_step(bp, &format!("{context}, step {k}, {v} m/s"));
            (bp.stats().pass, v)
        })
        .collect()
}

/// The first step whose motion per step is under the smallest skin a sphere of radius
/// 0.5 gets (`1/64` of its size, over `LOOKAHEAD_STEPS = 3` steps of its motion).
fn under_skin(passes: &[(Pass, f32)]) -> usize {
    let skin = 2.0 * RADIUS / 64.0 / 3.0;
    passes
        .iter()
        .position(|&(_, v)| v / HZ < skin)
        .expect("the motion decays under the skin")
}

/// The pass entered the incremental regime within `within` steps of `from`, and every step
/// from `stay` on ran the incremental pass.
fn assert_settles(passes: &[(Pass, f32)], from: usize, within: usize, stay: usize) {
    let entered = passes[from..]
        .iter()
        .position(|&(p, _)| p == Pass::Incremental)
        .unwrap_or_else(|| panic!("never entered the incremental regime: {passes:?}"));
    assert!(
        entered <= within,
        "entered {entered} steps after the motion dropped under the margin (step {from}): \
         {passes:?}"
    );
    assert!(
        passes[stay..].iter().all(|&(p, _)| p == Pass::Incremental),
        "left the incremental regime after step {stay}: {passes:?}"
    );
}

#[test]
fn a_settling_pile_sent_every_step_enters_the_incremental_regime() {
    let (mut rng, mut bp, mut model, keys) = built_pile(43, 14);
    let passes = settle(
        &mut model,
        &mut bp,
        &mut rng,
        &keys,
        (1.0, 0.9, 120),
        "settling",
    );
    let from = under_skin(&passes);
    assert_settles(&passes, from, 6, from + 25);
    assert!(
        passes[..from.saturating_sub(8)]
            .iter()
            .all(|&(p, _)| p == Pass::Full),
        "the pile in motion ran another pass than the full one: {passes:?}"
    );
}

#[test]
fn a_woken_pile_leaves_the_incremental_regime_and_comes_back() {
    let (mut rng, mut bp, mut model, keys) = built_pile(47, 12);
    let settled = settle(
        &mut model,
        &mut bp,
        &mut rng,
        &keys,
        (0.05, 0.9, 30),
        "resting",
    );
    assert!(
        settled[10..].iter().all(|&(p, _)| p == Pass::Incremental),
        "a pile at rest runs the incremental pass: {settled:?}"
    );
    // A ball dropped on it wakes it: every sphere moves at up to 2 m/s, then settles again.
    let woken = settle(
        &mut model,
        &mut bp,
        &mut rng,
        &keys,
        (2.0, 0.9, 120),
        "woken",
    );
    assert!(
        woken[..5].iter().any(|&(p, _)| p == Pass::Full),
        "the woken pile stayed in the incremental regime: {woken:?}"
    );
    let from = under_skin(&woken);
    assert_settles(&woken, from, 8, from + 30);
}

#[test]
fn a_gas_moving_8_cm_a_step_never_enters_the_incremental_regime() {
    let mut rng = Rng::new(53);
    let mut bp = BroadPhase::new(Config::default());
    let mut model = Model::new(0.0);
    model.quadratic = false;
    // 8000 spheres at about 10 % volume fraction in a 32 m cube, like the `gas` scene.
    let half = 16.0;
    let mut balls: Vec<(ProxyKey, Vec3)> = (0..8000)
        .map(|_| {
            let center = rng.vec3_in(Vec3::splat(-half), Vec3::splat(half));
            let shape = ModelShape::Sphere {
                center,
                radius: RADIUS,
            };
            let d = rng.offset(1.0);
            (
                model.insert(&mut bp, shape),
                d * (5.0 / HZ / d.length().max(1e-3)),
            )
        })
        .collect();
    for step in 0..60 {
        let mut keys = Vec::with_capacity(balls.len());
        let mut centers = Vec::with_capacity(balls.len());
        for (key, v) in &mut balls {
            let c = model.shapes[key].center();
            for axis in 0..3 {
                if (c[axis] + v[axis]).abs() > half {
                    v[axis] = -v[axis];
                }
            }
            let moved = model.shapes[key].moved(*v);
            model.shapes.insert(*key, moved);
            keys.push(*key);
            centers.push(moved.center());
        }
        bp.update_centers(&keys, &centers).expect("a valid batch");
        model.check_step(&mut bp, &format!("gas step {step}"));
        assert_eq!(bp.stats().pass, Pass::Full, "step {step}: {:?}", bp.stats());
    }
}
