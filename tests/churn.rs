//! Churn and teleports at scale: 10k proxies (spheres, dynamic and static bodies), 200 steps,
//! each step 1 % removed, 1 % inserted, 1 % teleported anywhere, 1 % resized and the rest
//! moved. After every step the pairs equal the sweep reference over the current boxes, the
//! events equal the set difference with the previous step, and `validate()` holds. Both octree
//! placements.

use broadleaf::fixtures::scene::{DT, Gas, Rng};
use broadleaf::octree::depth_for_loose;
use broadleaf::{
    Aabb, BodyKind, BroadPhase, Config, Pair, Placement, ProxyKey, Shape, Vec3, brute, pair,
};

/// The pairs `bp` must report: brute force over its proxies' margin-grown boxes, static bodies
/// flagged.
fn brute_pairs(bp: &BroadPhase) -> Vec<Pair> {
    let margin = bp.config().margin;
    let proxies: Vec<brute::Proxy> = bp
        .iter()
        .map(|(key, shape)| brute::Proxy {
            key,
            aabb: shape.grown_aabb(margin),
            is_static: shape.is_static(),
        })
        .collect();
    brute::sweep_pairs(&proxies)
}

const N: usize = 10_000;
const STEPS: usize = 200;

/// A random live proxy of a random kind somewhere in (or a little outside) `bounds`.
fn random_proxy(bp: &mut BroadPhase, rng: &mut Rng, bounds: &Aabb) -> ProxyKey {
    let c = rng.vec3_in(bounds.min - 2.0, bounds.max + 2.0);
    match rng.below(20) {
        0 => {
            let h = Vec3::new(rng.log_range(0.1, 2.0), rng.log_range(0.1, 2.0), 0.3);
            bp.insert_body(Aabb::from_center_half_extents(c, h), BodyKind::Static)
        }
        1..=3 => {
            let h = Vec3::splat(rng.log_range(0.1, 2.0));
            bp.insert_body(Aabb::from_center_half_extents(c, h), BodyKind::Dynamic)
        }
        _ => bp.insert_sphere(c, rng.range(0.0, 1.0)),
    }
    .expect("finite proxy")
}

fn moved(shape: Shape, to: Vec3, size: Option<f32>) -> Shape {
    match shape {
        Shape::Sphere { radius, .. } => Shape::Sphere {
            center: to,
            radius: size.unwrap_or(radius),
        },
        Shape::Body { aabb, kind } => {
            let h = size.map_or(aabb.extent() * 0.5, Vec3::splat);
            Shape::Body {
                aabb: Aabb::from_center_half_extents(to, h),
                kind,
            }
        }
    }
}

fn apply(bp: &mut BroadPhase, key: ProxyKey, shape: Shape) {
    match shape {
        Shape::Sphere { center, radius } => bp.update_sphere(key, center, radius),
        Shape::Body { aabb, .. } => bp.update_body(key, aabb),
    }
    .expect("live key, finite shape");
}

fn run(margin: f32, depth: u32, placement: Placement, steps: usize) {
    let bounds = Gas::new(N, 1).bounds;
    let mut bp = BroadPhase::new(Config {
        bounds,
        octree_depth: depth,
        octree_placement: placement,
        margin,
        ..Config::default()
    });
    let mut rng = Rng::new(2024);
    let mut live: Vec<ProxyKey> = (0..N)
        .map(|_| random_proxy(&mut bp, &mut rng, &bounds))
        .collect();
    let mut velocity: Vec<Vec3> = (0..N)
        .map(|_| rng.vec3_in(Vec3::splat(-5.0), Vec3::splat(5.0)))
        .collect();
    let mut prev: Vec<Pair> = Vec::new();
    let (mut added, mut removed) = (Vec::new(), Vec::new());
    let per_step = N / 100;
    for step in 0..steps {
        for _ in 0..per_step {
            let i = rng.below(live.len() as u32) as usize;
            bp.remove(live.swap_remove(i)).expect("live key");
            velocity.swap_remove(i);
        }
        for _ in 0..per_step {
            live.push(random_proxy(&mut bp, &mut rng, &bounds));
            velocity.push(rng.vec3_in(Vec3::splat(-5.0), Vec3::splat(5.0)));
        }
        for (i, &key) in live.iter().enumerate() {
            let shape = bp.shape(key).expect("live key");
            if matches!(
                shape,
                Shape::Body {
                    kind: BodyKind::Static,
                    ..
                }
            ) && rng.below(50) != 0
            {
                continue;
            }
            let roll = rng.below(100);
            let center = shape.aabb().center();
            let next = match roll {
                0 => moved(shape, rng.vec3_in(bounds.min, bounds.max), None),
                1 => moved(shape, center, Some(rng.range(0.0, 1.5))),
                _ => moved(shape, center + velocity[i] * DT, None),
            };
            apply(&mut bp, key, next);
        }
        let out = bp.step();
        let (pairs, got_added, got_removed) =
            (out.pairs.to_vec(), out.added.to_vec(), out.removed.to_vec());
        let expected = brute_pairs(&bp);
        assert_eq!(pairs.len(), expected.len(), "step {step}: pair count");
        assert_eq!(
            pairs, expected,
            "step {step}: pairs differ from the reference"
        );
        pair::diff(&prev, &expected, &mut added, &mut removed);
        assert_eq!(got_added, added, "step {step}: added");
        assert_eq!(got_removed, removed, "step {step}: removed");
        assert_eq!(bp.len(), N);
        if step % 10 == 0 || step + 1 == steps {
            bp.validate();
        }
        prev = expected;
    }
    bp.validate();
}

#[test]
fn churn_of_ten_thousand_proxies_matches_the_reference_every_step() {
    run(0.0, 5, Placement::Strict, STEPS);
}

#[test]
fn churn_in_a_loose_octree_matches_the_reference_every_step() {
    let depth = depth_for_loose(&Gas::new(N, 1).bounds, 0.5);
    run(0.0, depth, Placement::Loose, STEPS);
}

#[test]
fn churn_with_a_margin_and_a_shallow_tree() {
    run(0.1, 2, Placement::Strict, STEPS / 2);
    run(0.1, 2, Placement::Loose, STEPS / 2);
}
