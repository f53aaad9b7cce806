//! The step follows what moves, and the lists stay exact: with the default
//! `Config`, worlds where each step only a subset of the proxies is updated — some never
//! touched for many steps, some nudged by 0.01–1 mm, some moving a few cm per step (they leave
//! any fat box after a few steps), some teleported, some woken after a long rest, inserts and
//! removes in between — and a world that goes from rest to all moving and back, so whatever
//! switching between an incremental and a full pass happens is crossed in both directions.
//! After every step `pairs` equals the test's own brute force over its own model,
//! `added` / `removed` equal its own set difference, and `validate()` holds. Plus exact
//! touches nudged apart by one ulp and back, and keys updated several times between steps.

mod common;

use broadleaf::{Aabb, BroadPhase, Config, Pass, Passes, ProxyKey, Vec3};
use common::{Model, ModelShape, Rng};

/// How a proxy of the resting world behaves.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Role {
    /// Never updated.
    Resting,
    /// Updated every other step or so by 0.01–1 mm.
    Nudged,
    /// Moves by its velocity every step (1–5 cm), bouncing at the region's walls.
    Steady(Vec3),
    /// Rests, and once in a while jumps anywhere (sometimes far outside `Config::bounds`, now
    /// and then 1e30 m away).
    Teleporter,
    /// Rests for `period` steps, then moves 10 cm a step for three steps.
    Sleeper(usize),
}

/// Half the side of the cube the worlds live in, in metres.
const REGION: f32 = 12.0;

fn random_shape(rng: &mut Rng) -> ModelShape {
    let c = rng.offset(REGION);
    match rng.below(10) {
        0 => ModelShape::body(c, rng.vec3_in(Vec3::splat(0.2), Vec3::splat(1.5)), true),
        1..=3 => ModelShape::body(c, Vec3::splat(rng.range(0.2, 1.0)), false),
        _ => ModelShape::Sphere {
            center: c,
            radius: rng.range(0.25, 0.75),
        },
    }
}

fn random_role(rng: &mut Rng, shape: &ModelShape) -> Role {
    if shape.is_static() {
        return Role::Resting;
    }
    match rng.below(20) {
        0..=7 => Role::Resting,
        8..=12 => Role::Nudged,
        13..=16 => Role::Steady(rng.offset(0.05)),
        17 => Role::Teleporter,
        _ => Role::Sleeper(20 + rng.below(40)),
    }
}

/// Where the role moves the proxy this step, if it moves.
fn next(rng: &mut Rng, step: usize, shape: &ModelShape, role: &mut Role) -> Option<ModelShape> {
    match role {
        Role::Resting => None,
        Role::Nudged => rng.chance(0.5).then(|| {
            let len = 1e-5 * (100.0f32).powf(rng.unit());
            shape.moved(rng.offset(1.0) * len)
        }),
        Role::Steady(v) => {
            let c = shape.center();
            for axis in 0..3 {
                if (c[axis] + v[axis]).abs() > REGION {
                    v[axis] = -v[axis];
                }
            }
            Some(shape.moved(*v))
        }
        Role::Teleporter => rng.chance(0.05).then(|| {
            let to = match rng.below(20) {
                0..=2 => Vec3::new(600.0, rng.range(-900.0, 900.0), -700.0),
                3 => Vec3::new(-1e30, rng.range(-1.0, 1.0), 1e30),
                _ => rng.offset(REGION),
            };
            shape.teleported(to)
        }),
        Role::Sleeper(period) => {
            (step % *period < 3).then(|| shape.moved(Vec3::new(0.1, -0.05, 0.02)))
        }
    }
}

/// A world of `n` proxies run for `steps` steps under `config`, checked after every step.
fn resting_world(config: Config, n: usize, steps: usize, seed: u64) {
    let mut rng = Rng::new(seed);
    let mut bp = BroadPhase::new(config);
    let mut model = Model::new(config.margin);
    model.quadratic = false;
    let mut roles: Vec<(ProxyKey, Role)> = Vec::new();
    for _ in 0..n {
        let shape = random_shape(&mut rng);
        let role = random_role(&mut rng, &shape);
        roles.push((model.insert(&mut bp, shape), role));
    }
    let mut pairs_seen = 0;
    for step in 0..steps {
        let mut batch = Vec::new();
        for (key, role) in &mut roles {
            let Some(moved) = next(&mut rng, step, &model.shapes[key], role) else {
                continue;
            };
            match moved {
                // A third of the moving spheres go through one batch.
                ModelShape::Sphere { center, radius } if rng.below(3) == 0 => {
                    model.shapes.insert(*key, moved);
                    batch.push((*key, center, radius));
                }
                _ => model.update(&mut bp, *key, moved),
            }
        }
        assert_eq!(bp.update_spheres(&batch), Ok(()));
        // Churn: removes, inserts, and a proxy replaced by a new one at its exact place.
        for _ in 0..rng.below(6) {
            let (key, _) = roles.swap_remove(rng.below(roles.len()));
            model.remove(&mut bp, key);
        }
        for _ in 0..rng.below(6) {
            let shape = random_shape(&mut rng);
            let role = random_role(&mut rng, &shape);
            roles.push((model.insert(&mut bp, shape), role));
        }
        if rng.chance(0.3) {
            let i = rng.below(roles.len());
            let shape = model.shapes[&roles[i].0];
            model.remove(&mut bp, roles[i].0);
            roles[i].0 = model.insert(&mut bp, shape);
        }
        let want = model.check_step(&mut bp, &format!("step {step}"));
        pairs_seen += want.pairs.len();
    }
    // Not a vacuous world: on average more than one pair per two proxies each step.
    assert!(
        pairs_seen > steps * n / 2,
        "{pairs_seen} pairs in {steps} steps"
    );
}

#[test]
fn resting_world_with_few_movers_equals_the_model_every_step() {
    resting_world(Config::default(), 5000, 150, 1);
}

/// The same world with an explicit skin (the override of the default's adaptation).
#[test]
fn resting_world_with_a_skin_equals_the_model_every_step() {
    resting_world(
        Config {
            skin: 0.05,
            ..Config::default()
        },
        3000,
        100,
        6,
    );
}

#[test]
fn resting_world_with_a_margin_equals_the_model_every_step() {
    resting_world(
        Config {
            margin: 0.05,
            ..Config::default()
        },
        2000,
        80,
        2,
    );
}

/// 40 steps at rest, 40 all moving at gas speed (5 m/s × 1/60 s), 40 with 1 % moving (a
/// fixed subset), 20 all moving, 40 at rest.
#[test]
fn rest_to_all_moving_and_back_equals_the_model_every_step() {
    rest_to_all_moving_and_back(Config::default());
}

/// The same with an explicit skin.
#[test]
fn rest_to_all_moving_and_back_with_a_skin_equals_the_model_every_step() {
    rest_to_all_moving_and_back(Config {
        skin: 0.05,
        ..Config::default()
    });
}

fn rest_to_all_moving_and_back(config: Config) {
    let mut rng = Rng::new(3);
    let mut bp = BroadPhase::new(config);
    let mut model = Model::new(0.0);
    model.quadratic = false;
    let mut movers: Vec<(ProxyKey, Vec3)> = Vec::new();
    for _ in 0..2500 {
        let shape = random_shape(&mut rng);
        let key = model.insert(&mut bp, shape);
        if !shape.is_static() {
            let v = rng.offset(1.0);
            movers.push((key, v * (5.0 / 60.0 / v.length().max(1e-3))));
        }
    }
    let phases = [(40, 0.0), (40, 1.0), (40, 0.01), (20, 1.0), (40, 0.0)];
    let mut step = 0;
    let mut passes = Vec::new();
    for (steps, fraction) in phases {
        let moving = (movers.len() as f32 * fraction) as usize;
        for _ in 0..steps {
            for (key, v) in &mut movers[..moving] {
                let c = model.shapes[key].center();
                for axis in 0..3 {
                    if (c[axis] + v[axis]).abs() > REGION {
                        v[axis] = -v[axis];
                    }
                }
                let moved = model.shapes[key].moved(*v);
                model.update(&mut bp, *key, moved);
            }
            let context = format!("step {step}, {fraction} moving");
            let want = model.check_step(&mut bp, &context);
            passes.push(bp.stats().pass);
            assert!(want.pairs.len() > 1000, "{context}: too few pairs to test");
            if fraction == 0.0 && step % 40 > 0 {
                assert!(want.added.is_empty() && want.removed.is_empty());
            }
            step += 1;
        }
    }
    // The default adapts: the resting and 1 % phases run the incremental pass, the all-moving
    // phases the full one, and the switch happens both ways.
    if config.passes == Passes::Adaptive && config.skin == 0.0 {
        let switches = passes.windows(2).filter(|w| w[0] != w[1]).count();
        assert!(
            passes.contains(&Pass::Incremental),
            "never incremental: {passes:?}"
        );
        assert!(
            passes.contains(&Pass::Full),
            "never the full pass: {passes:?}"
        );
        assert!(switches >= 4, "{switches} switches: {passes:?}");
    }
}

/// Two boxes sharing a face (and two spheres whose boxes share one, and a sphere on a body) pair;
/// one ulp apart they do not; back, they pair again. Among a resting world, so the step that
/// sees the ulp is one where almost nothing moved; with a margin too (the grown boxes touch).
#[test]
fn touching_faces_pair_and_one_ulp_apart_do_not() {
    for margin in [0.0, 0.25] {
        let mut rng = Rng::new(4);
        let mut bp = BroadPhase::new(Config {
            margin,
            ..Config::default()
        });
        let mut model = Model::new(margin);
        model.quadratic = false;
        for _ in 0..1500 {
            model.insert(&mut bp, random_shape(&mut rng));
        }
        // Gaps of 2·margin, so the grown boxes touch exactly (all values dyadic).
        let g = 2.0 * margin;
        let at = Vec3::new(40.0, 0.0, 0.0);
        let body = |min: Vec3, max: Vec3| ModelShape::Body {
            aabb: Aabb::new(at + min, at + max),
            is_static: false,
        };
        let sphere = |x: f32| ModelShape::Sphere {
            center: at + Vec3::new(x, 5.0, 0.0),
            radius: 0.5,
        };
        let a = model.insert(&mut bp, body(Vec3::ZERO, Vec3::ONE));
        let b = model.insert(
            &mut bp,
            body(Vec3::new(1.0 + g, 0.0, 0.0), Vec3::new(2.0 + g, 1.0, 1.0)),
        );
        let s = model.insert(&mut bp, sphere(0.0));
        let t = model.insert(&mut bp, sphere(1.0 + g));
        // A sphere resting on top of body `a` (its box's bottom face on `a`'s top face).
        let u = model.insert(
            &mut bp,
            ModelShape::Sphere {
                center: at + Vec3::new(0.5, 1.5 + g, 0.5),
                radius: 0.5,
            },
        );
        let touching = [(a, b), (s, t), (a, u)];
        for round in 0..6 {
            let context = format!("margin {margin}, round {round}");
            for _ in 0..5 {
                let want = model.check_step(&mut bp, &context);
                for (x, y) in touching {
                    assert!(want.pairs.contains(&(x.min(y), x.max(y))), "{context}");
                }
            }
            // One ulp apart: `b`'s faces, `t`'s centre and `u`'s centre up one ulp.
            let (sb, st, su) = (model.shapes[&b], model.shapes[&t], model.shapes[&u]);
            let ModelShape::Body { aabb, .. } = sb else {
                unreachable!()
            };
            let up = Aabb::new(
                Vec3::new(aabb.min.x.next_up(), aabb.min.y, aabb.min.z),
                aabb.max,
            );
            model.update(
                &mut bp,
                b,
                ModelShape::Body {
                    aabb: up,
                    is_static: false,
                },
            );
            let c = st.center();
            model.update(
                &mut bp,
                t,
                st.placed(Vec3::new(c.x.next_up(), c.y, c.z), 0.5),
            );
            let c = su.center();
            model.update(
                &mut bp,
                u,
                su.placed(Vec3::new(c.x, c.y.next_up(), c.z), 0.5),
            );
            let want = model.check_step(&mut bp, &context);
            for (x, y) in touching {
                assert!(want.removed.contains(&(x.min(y), x.max(y))), "{context}");
            }
            for (key, shape) in [(b, sb), (t, st), (u, su)] {
                model.update(&mut bp, key, shape);
            }
        }
    }
}

/// A key updated several times between two steps ends where its last update puts it: moved
/// away and back to its exact place (no events), to a touch and away, away and to a touch;
/// through per-object calls and batches mixed.
#[test]
fn repeated_updates_between_steps_only_the_last_counts() {
    let mut rng = Rng::new(5);
    let mut bp = BroadPhase::new(Config::default());
    let mut model = Model::new(0.0);
    model.quadratic = false;
    for _ in 0..1500 {
        model.insert(&mut bp, random_shape(&mut rng));
    }
    let at = Vec3::new(0.0, 40.0, 0.0);
    let wall = ModelShape::body(at, Vec3::splat(1.0), true);
    model.insert(&mut bp, wall);
    let home = at + Vec3::new(2.5, 0.0, 0.0);
    let key = model.insert(
        &mut bp,
        ModelShape::Sphere {
            center: home,
            radius: 1.0,
        },
    );
    let touch = at + Vec3::new(2.0, 0.0, 0.0);
    let far = at + Vec3::new(30.0, 0.0, 0.0);
    let places = [home, touch, far, touch + Vec3::splat(1e-4), home];
    for round in 0..40 {
        let context = format!("round {round}");
        model.check_step(&mut bp, &context);
        let last = places[round % places.len()];
        for _ in 0..rng.below(4) {
            let p = places[rng.below(places.len())];
            bp.update_sphere(key, p, 1.0).unwrap();
        }
        let mid = places[rng.below(places.len())];
        let batch = [(key, mid, 1.0), (key, far, 3.0), (key, last, 1.0)];
        if rng.chance(0.5) {
            assert_eq!(bp.update_spheres(&batch), Ok(()));
        } else {
            bp.update_spheres(&batch[..2]).unwrap();
            bp.update_sphere(key, last, 1.0).unwrap();
        }
        let before = model.shapes[&key];
        model.shapes.insert(
            key,
            ModelShape::Sphere {
                center: last,
                radius: 1.0,
            },
        );
        let want = model.check_step(&mut bp, &context);
        if before == model.shapes[&key] {
            assert!(
                want.added.is_empty() && want.removed.is_empty(),
                "{context}"
            );
        }
    }
}

/// Each pass forced on its own gives the same exact lists: the incremental pass through
/// bursts of all-moving steps, the full pass through the resting ones.
#[test]
fn each_pass_forced_equals_the_model_every_step() {
    for passes in [Passes::Incremental, Passes::Full] {
        rest_to_all_moving_and_back(Config {
            passes,
            ..Config::default()
        });
        resting_world(
            Config {
                passes,
                ..Config::default()
            },
            2000,
            60,
            5,
        );
    }
}

/// A world waking up (every sphere moving far at once, right after the step that entered the
/// incremental regime) runs the full pass at its next step instead of re-testing and querying
/// every escaped proxy: a step estimated far over the full pass leaves the regime at once. Its
/// pairs equal brute force either way.
#[test]
fn a_world_waking_up_runs_the_full_pass_at_once() {
    let mut rng = Rng::new(29);
    let mut bp = BroadPhase::new(Config::default());
    let mut spheres: Vec<(ProxyKey, Vec3)> = (0..6000)
        .map(|_| {
            let c = Vec3::new(
                rng.range(0.0, 40.0),
                rng.range(0.0, 40.0),
                rng.range(0.0, 40.0),
            );
            (bp.insert_sphere(c, 0.5).unwrap(), c)
        })
        .collect();
    bp.step();
    for (key, c) in &mut spheres {
        *c += Vec3::new(
            rng.range(-2.0, 2.0),
            rng.range(-2.0, 2.0),
            rng.range(-2.0, 2.0),
        );
        bp.update_sphere(*key, *c, 0.5).unwrap();
    }
    bp.step();
    assert_eq!(bp.stats().pass, Pass::Full, "{:?}", bp.stats());
    let proxies: Vec<broadleaf::brute::Proxy> = spheres
        .iter()
        .map(|&(k, c)| broadleaf::brute::Proxy::new(k, Aabb::from_center_radius(c, 0.5)))
        .collect();
    let mut want = broadleaf::brute::pairs(&proxies);
    want.sort();
    assert_eq!(bp.pairs(), &want[..]);
}

/// A sphere moving at gas speed (5 m/s at 60 steps a second) inside the box `±half`.
struct Mover {
    key: ProxyKey,
    velocity: Vec3,
    half: Vec3,
}

/// `n` spheres of radius 0.5 spread over the box `±half`, each moving at gas speed in a
/// random direction.
fn spread_movers(
    rng: &mut Rng,
    model: &mut Model,
    bp: &mut BroadPhase,
    n: usize,
    half: Vec3,
) -> Vec<Mover> {
    (0..n)
        .map(|_| {
            let center = rng.vec3_in(-half, half);
            let key = model.insert(
                bp,
                ModelShape::Sphere {
                    center,
                    radius: 0.5,
                },
            );
            let v = rng.offset(1.0);
            let velocity = v * (5.0 / 60.0 / v.length().max(1e-3));
            Mover {
                key,
                velocity,
                half,
            }
        })
        .collect()
}

/// Moves every mover by its velocity, bouncing off the faces of its box.
fn move_all(model: &mut Model, bp: &mut BroadPhase, movers: &mut [Mover]) {
    for m in movers {
        let c = model.shapes[&m.key].center();
        for axis in 0..3 {
            if (c[axis] + m.velocity[axis]).abs() > m.half[axis] {
                m.velocity[axis] = -m.velocity[axis];
            }
        }
        let moved = model.shapes[&m.key].moved(m.velocity);
        model.update(bp, m.key, moved);
    }
}

/// A sparse world in motion (every sphere moving at gas speed in a wide flat box, about one
/// pair per hundred spheres): an escape's queries find next to nothing there, so the
/// incremental pass is the cheaper one even with every proxy moving, and the default runs it
/// once it has entered, with pairs, events and `validate()` equal to the model every step.
#[test]
fn a_sparse_world_in_motion_runs_the_incremental_pass() {
    let mut rng = Rng::new(31);
    let mut bp = BroadPhase::new(Config::default());
    let mut model = Model::new(0.0);
    model.quadratic = false;
    let half = Vec3::new(160.0, 20.0, 160.0);
    let mut movers = spread_movers(&mut rng, &mut model, &mut bp, 10_000, half);
    let mut passes = Vec::new();
    let mut pairs = 0;
    for step in 0..40 {
        move_all(&mut model, &mut bp, &mut movers);
        pairs += model
            .check_step(&mut bp, &format!("step {step}"))
            .pairs
            .len();
        passes.push(bp.stats().pass);
    }
    assert!(pairs > 40 * 20, "too few pairs to test: {pairs}");
    let incremental = passes.iter().filter(|&&p| p == Pass::Incremental).count();
    assert!(
        incremental >= 30,
        "{incremental} incremental steps: {passes:?}"
    );
}

/// A dense world's first steps run the full pass: before any pass has listed the pairs, an
/// escape is priced as a dense world's, so an empty pair list does not pass the world off as
/// sparse and make it enter (and soon leave) the incremental regime.
#[test]
fn a_dense_world_in_motion_runs_the_full_pass_from_its_first_step() {
    let mut rng = Rng::new(37);
    let mut bp = BroadPhase::new(Config::default());
    let mut model = Model::new(0.0);
    model.quadratic = false;
    // 8 000 spheres at about 10 % volume fraction, like `gas`.
    let mut movers = spread_movers(&mut rng, &mut model, &mut bp, 8000, Vec3::splat(16.0));
    for step in 0..10 {
        move_all(&mut model, &mut bp, &mut movers);
        let want = model.check_step(&mut bp, &format!("step {step}"));
        assert!(
            want.pairs.len() > 4000,
            "step {step}: too few pairs to test"
        );
        assert_eq!(bp.stats().pass, Pass::Full, "step {step}: {:?}", bp.stats());
    }
}

/// A sparse world that gathers into a dense cluster leaves the incremental regime: an
/// escape's price follows the candidates per proxy, so the dense world's escapes are not
/// priced as the sparse world's were.
/// 10k spheres in a wide flat box, every one moving at gas speed (the incremental pass), then
/// a tenth of them a step teleported into a cube at about 10 % volume fraction, where they go
/// on moving: once they are all there the full pass is the cheaper, and runs.
#[test]
fn a_sparse_world_gathering_into_a_cluster_leaves_the_incremental_regime() {
    let mut rng = Rng::new(41);
    let mut bp = BroadPhase::new(Config::default());
    let mut model = Model::new(0.0);
    model.quadratic = false;
    let (wide, dense) = (Vec3::new(160.0, 20.0, 160.0), Vec3::splat(18.0));
    let mut movers = spread_movers(&mut rng, &mut model, &mut bp, 10_000, wide);
    let mut passes = Vec::new();
    for step in 0..60 {
        if (20..30).contains(&step) {
            for m in movers.iter_mut().skip(step - 20).step_by(10) {
                let to = rng.vec3_in(-dense, dense);
                let moved = model.shapes[&m.key].teleported(to);
                model.update(&mut bp, m.key, moved);
                m.half = dense;
            }
        }
        move_all(&mut model, &mut bp, &mut movers);
        model.check_step(&mut bp, &format!("step {step}"));
        passes.push(bp.stats().pass);
    }
    let sparse = passes[5..20]
        .iter()
        .filter(|&&p| p == Pass::Incremental)
        .count();
    assert!(
        sparse >= 10,
        "{sparse} incremental steps while sparse: {passes:?}"
    );
    let full = passes[45..].iter().filter(|&&p| p == Pass::Full).count();
    assert!(full >= 10, "{full} full passes once dense: {passes:?}");
}
