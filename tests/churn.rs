//! Churn and teleports at scale: 10k proxies (spheres, dynamic and static bodies), 200 steps,
//! each step 1 % removed, 1 % inserted, 1 % teleported anywhere, 1 % resized and the rest
//! moved. The test keeps its own record of every proxy (`common::Model`): after every step the
//! pairs equal the model's own sort-and-sweep over its margin-grown boxes, the events the
//! model's own set difference with its previous pair set, and `validate()` holds. Both octree
//! placements.

mod common;

use broadleaf::fixtures::scene::{DT, Gas, Rng};
use broadleaf::{Aabb, BroadPhase, Config, Placement, ProxyKey, Vec3};
use common::{Model, ModelShape};

const N: usize = 10_000;
const STEPS: usize = 200;

/// A random proxy of a random kind somewhere in (or a little outside) `bounds`.
fn random_shape(rng: &mut Rng, bounds: &Aabb) -> ModelShape {
    let c = rng.vec3_in(bounds.min - 2.0, bounds.max + 2.0);
    match rng.below(20) {
        0 => {
            let h = Vec3::new(rng.log_range(0.1, 2.0), rng.log_range(0.1, 2.0), 0.3);
            ModelShape::body(c, h, true)
        }
        1..=3 => ModelShape::body(c, Vec3::splat(rng.log_range(0.1, 2.0)), false),
        _ => ModelShape::Sphere {
            center: c,
            radius: rng.range(0.0, 1.0),
        },
    }
}

/// `hint`: give the octree the scene's cube as its region hint, or none.
fn run(margin: f32, hint: bool, placement: Placement, steps: usize) {
    let bounds = Gas::new(N, 1).bounds;
    let mut bp = BroadPhase::new(Config {
        bounds: hint.then_some(bounds),
        octree_placement: placement,
        margin,
        ..Config::default()
    });
    // The test's own record of every live proxy; its pairs by sort-and-sweep (10k proxies),
    // which `tests/model.rs` checks against the model's O(n²) loop.
    let mut model = Model::new(margin);
    model.quadratic = false;
    let mut rng = Rng::new(2024);
    let mut live: Vec<ProxyKey> = (0..N)
        .map(|_| {
            let shape = random_shape(&mut rng, &bounds);
            model.insert(&mut bp, shape)
        })
        .collect();
    let mut velocity: Vec<Vec3> = (0..N)
        .map(|_| rng.vec3_in(Vec3::splat(-5.0), Vec3::splat(5.0)))
        .collect();
    let per_step = N / 100;
    for step in 0..steps {
        for _ in 0..per_step {
            let i = rng.below(live.len() as u32) as usize;
            model.remove(&mut bp, live.swap_remove(i));
            velocity.swap_remove(i);
        }
        for _ in 0..per_step {
            let shape = random_shape(&mut rng, &bounds);
            live.push(model.insert(&mut bp, shape));
            velocity.push(rng.vec3_in(Vec3::splat(-5.0), Vec3::splat(5.0)));
        }
        for (i, &key) in live.iter().enumerate() {
            let shape = model.shapes[&key];
            if shape.is_static() && rng.below(50) != 0 {
                continue;
            }
            let roll = rng.below(100);
            let center = shape.center();
            let next = match roll {
                0 => shape.teleported(rng.vec3_in(bounds.min, bounds.max)),
                1 => shape.placed(center, rng.range(0.0, 1.5)),
                _ => shape.teleported(center + velocity[i] * DT),
            };
            model.update(&mut bp, key, next);
        }
        let want = model.expect_step();
        bp.step();
        let context = format!("step {step}");
        assert_eq!(
            bp.pairs().len(),
            want.pairs.len(),
            "step {step}: pair count"
        );
        model.assert_list(&context, "pairs", bp.pairs(), &want.pairs);
        model.assert_list(&context, "added", bp.added(), &want.added);
        model.assert_list(&context, "removed", bp.removed(), &want.removed);
        assert_eq!(bp.len(), N);
        if step % 10 == 0 || step + 1 == steps {
            bp.validate();
        }
    }
    model.assert_same_proxies(&bp, "after the churn");
    bp.validate();
}

#[test]
fn churn_of_ten_thousand_proxies_matches_the_reference_every_step() {
    run(0.0, true, Placement::Strict, STEPS);
}

#[test]
fn churn_in_a_loose_octree_matches_the_reference_every_step() {
    run(0.0, false, Placement::Loose, STEPS);
}

#[test]
fn churn_with_a_margin() {
    run(0.1, false, Placement::Strict, STEPS / 2);
    run(0.1, true, Placement::Loose, STEPS / 2);
}
