//! The octree's region follows the spheres (`Config::bounds` is only a hint): worlds that
//! spread from 10 m to 100 km, drift outward, teleport to 1e7 m and back, mix 1 mm and 100 m
//! spheres, or sit 100 km from the origin stay exact. After every step of each run, under both
//! placements and every `Passes`, with and without a region hint: the three lists equal the
//! model's brute force (`tests/common`), `validate()` holds for the broadphase and its octree,
//! and the octree keeps at most `max(64, n / 64)` spheres outside its region (the bound the
//! crate guarantees between re-roots).

mod common;

use broadleaf::fixtures::scene::{Gas, cube_edge};
use broadleaf::{Aabb, BroadPhase, Config, Passes, Placement, Vec3};
use common::{Model, ModelShape, Rng};

const PLACEMENTS: [Placement; 2] = [Placement::Strict, Placement::Loose];
const PASSES: [Passes; 3] = [Passes::Adaptive, Passes::Full, Passes::Incremental];

/// The overflow the crate allows a pass to see: `max(64, n / 64)`.
fn overflow_limit(n: usize) -> u32 {
    64.max(n / 64) as u32
}

fn check(bp: &mut BroadPhase, model: &mut Model, context: &str) {
    model.check_step(bp, context);
    let octree = bp.octree();
    octree.validate();
    let stats = octree.stats();
    assert!(
        stats.overflow <= overflow_limit(octree.len()),
        "{context}: {} spheres outside the region {:?} ({} live)",
        stats.overflow,
        octree.bounds(),
        octree.len()
    );
}

/// A radius: mostly 0.5 m, sometimes 1 mm, now and then 100 m.
fn radius(rng: &mut Rng) -> f32 {
    match rng.below(20) {
        0..=13 => rng.range(0.3, 0.7),
        14..=18 => 1e-3,
        _ => 100.0,
    }
}

/// A world that starts in a 10 m cube at `origin`, spreads outward by 8 % per step (past
/// 100 km after about 120 steps) with spheres moving on their own too, teleports a few
/// spheres to 1e7 m and brings them back, inserts, removes and resizes.
fn spreading_world(config: Config, origin: Vec3, seed: u64, steps: usize) {
    let mut bp = BroadPhase::new(config);
    let mut model = Model::new(config.margin);
    let mut rng = Rng::new(seed);
    for _ in 0..240 {
        let c = origin + rng.offset(5.0);
        let r = radius(&mut rng);
        model.insert(
            &mut bp,
            ModelShape::Sphere {
                center: c,
                radius: r,
            },
        );
    }
    let name = format!("{config:?} at {origin:?}");
    check(&mut bp, &mut model, &format!("{name}, first step"));
    let mut away = Vec::new();
    for s in 0..steps {
        let keys = model.keys();
        for &key in &keys {
            let shape = model.shapes[&key];
            let c = shape.center();
            let next = if away.contains(&key) {
                // Back from 1e7 m a few steps later, near the world's middle.
                if rng.chance(0.3) {
                    away.retain(|&k| k != key);
                    shape.teleported(origin + rng.offset(10.0))
                } else {
                    continue;
                }
            } else if rng.chance(0.01) {
                away.push(key);
                shape.teleported(Vec3::new(1e7, -1e7, 1e7) * rng.range(0.5, 1.0))
            } else if rng.chance(0.7) {
                let spread = (c - origin) * 0.08;
                shape.moved(spread + rng.offset(0.3))
            } else {
                continue;
            };
            model.update(&mut bp, key, next);
        }
        for _ in 0..rng.below(4) {
            let keys = model.keys();
            let key = keys[rng.below(keys.len())];
            match rng.below(3) {
                0 => model.remove(&mut bp, key),
                1 => {
                    let shape = model.shapes[&key];
                    let r = radius(&mut rng);
                    model.update(&mut bp, key, shape.placed(shape.center(), r));
                }
                _ => {
                    let c = origin + rng.offset(50.0);
                    let r = radius(&mut rng);
                    model.insert(
                        &mut bp,
                        ModelShape::Sphere {
                            center: c,
                            radius: r,
                        },
                    );
                }
            }
        }
        check(&mut bp, &mut model, &format!("{name}, step {s}"));
    }
    if steps >= 100 {
        // Spread 1.08^100 ≈ 2200 times wider than it started.
        assert!(
            bp.octree().stats().reroots >= 2,
            "{name}: the region never moved"
        );
    }
}

#[test]
fn spreading_drifting_and_teleporting_worlds_stay_exact() {
    let mut seed = 0;
    for placement in PLACEMENTS {
        for passes in PASSES {
            for hint in [None, Some(Aabb::new(Vec3::splat(-8.0), Vec3::splat(8.0)))] {
                seed += 1;
                let config = Config {
                    bounds: hint,
                    octree_placement: placement,
                    passes,
                    margin: if seed % 3 == 0 { 0.1 } else { 0.0 },
                    ..Config::default()
                };
                spreading_world(config, Vec3::ZERO, seed, 130);
            }
        }
    }
}

#[test]
fn a_world_100_km_from_the_origin_stays_exact() {
    // f32 spacing there is about 8 mm: pairs are still exactly those of the f32 boxes.
    let origin = Vec3::new(1.0e5, -7.0e4, 3.0e4);
    for (i, placement) in PLACEMENTS.into_iter().enumerate() {
        for (j, passes) in PASSES.into_iter().enumerate() {
            let config = Config {
                octree_placement: placement,
                passes,
                ..Config::default()
            };
            spreading_world(config, origin, 100 + (3 * i + j) as u64, 40);
        }
    }
}

/// A `gas` cube 100 km out: after the first step every sphere is inside the region and lives
/// at a level whose cells are a few diameters, as at the origin; the lists stay exact as the
/// spheres move.
#[test]
fn a_gas_cube_far_away_is_placed_as_at_the_origin() {
    for placement in PLACEMENTS {
        let mut gas = Gas::in_box(
            3000,
            5,
            0.5,
            Vec3::new(1.0e5, 2.0e4, -1.0e5),
            Vec3::splat(31.0),
        );
        let mut bp = BroadPhase::new(Config {
            octree_placement: placement,
            ..Config::default()
        });
        let mut model = Model::new(0.0);
        model.quadratic = false;
        let keys: Vec<_> = gas
            .centers
            .iter()
            .map(|&center| {
                model.insert(
                    &mut bp,
                    ModelShape::Sphere {
                        center,
                        radius: 0.5,
                    },
                )
            })
            .collect();
        for s in 0..12 {
            check(
                &mut bp,
                &mut model,
                &format!("{placement:?} far gas, step {s}"),
            );
            let octree = bp.octree();
            assert_eq!(octree.stats().overflow, 0, "{placement:?}");
            let side = octree.bounds().extent().x;
            assert!(side < 1000.0, "{placement:?}: region {:?}", octree.bounds());
            if placement == Placement::Loose {
                for &k in &keys {
                    let cell = side / (1u32 << octree.level_of(k).unwrap()) as f32;
                    assert!((1.0..4.0).contains(&cell), "cell {cell}");
                }
            }
            gas.step(1.0 / 60.0);
            for (&k, &center) in keys.iter().zip(&gas.centers) {
                model.update(
                    &mut bp,
                    k,
                    ModelShape::Sphere {
                        center,
                        radius: 0.5,
                    },
                );
            }
        }
    }
}

/// A world that crosses any fixed region at speed: the region keeps up, re-rooting far less
/// often than every step, and the lists stay exact.
#[test]
fn a_flying_cube_is_followed_without_a_reroot_per_step() {
    for placement in PLACEMENTS {
        for passes in PASSES {
            let mut gas = Gas::new(2000, 9);
            let mut bp = BroadPhase::new(Config {
                octree_placement: placement,
                passes,
                ..Config::default()
            });
            let mut model = Model::new(0.0);
            model.quadratic = false;
            let keys: Vec<_> = gas
                .centers
                .iter()
                .map(|&center| {
                    model.insert(
                        &mut bp,
                        ModelShape::Sphere {
                            center,
                            radius: 0.5,
                        },
                    )
                })
                .collect();
            let steps = 120;
            // The cube (22 m) moves 5 m per step: at least 4 steps between re-roots.
            let mut offset = Vec3::new(400.0, 0.0, 0.0);
            for s in 0..steps {
                gas.step(1.0 / 60.0);
                offset += Vec3::new(5.0, 0.5, 0.0);
                for (&k, &c) in keys.iter().zip(&gas.centers) {
                    let sphere = ModelShape::Sphere {
                        center: c + offset,
                        radius: 0.5,
                    };
                    model.update(&mut bp, k, sphere);
                }
                check(
                    &mut bp,
                    &mut model,
                    &format!("{placement:?} {passes:?} flying, step {s}"),
                );
            }
            let reroots = bp.octree().stats().reroots;
            assert!(
                reroots <= steps as u32 / 4,
                "{placement:?} {passes:?}: {reroots} re-roots in {steps} steps"
            );
        }
    }
}

/// Runs `worlds` (moving like `gas`) together through a default broadphase of `placement` for
/// a few steps, checking the lists against brute force after each; `cells(octree, keys)` is
/// asserted after each step too.
fn run_worlds(
    placement: Placement,
    mut worlds: Vec<Gas>,
    context: &str,
    cells: impl Fn(&broadleaf::octree::Octree, &[broadleaf::ProxyKey]),
) {
    let mut bp = BroadPhase::new(Config {
        octree_placement: placement,
        ..Config::default()
    });
    let mut model = Model::new(0.0);
    model.quadratic = false;
    let keys: Vec<Vec<_>> = worlds
        .iter()
        .map(|gas| {
            gas.centers
                .iter()
                .map(|&center| {
                    let radius = gas.radius;
                    model.insert(&mut bp, ModelShape::Sphere { center, radius })
                })
                .collect()
        })
        .collect();
    let all: Vec<_> = keys.iter().flatten().copied().collect();
    for s in 0..6 {
        check(
            &mut bp,
            &mut model,
            &format!("{placement:?} {context}, step {s}"),
        );
        cells(bp.octree(), &all);
        for (gas, keys) in worlds.iter_mut().zip(&keys) {
            gas.step(1.0 / 60.0);
            for (&k, &center) in keys.iter().zip(&gas.centers) {
                let radius = gas.radius;
                model.update(&mut bp, k, ModelShape::Sphere { center, radius });
            }
        }
    }
}

/// A thin sparse world (8000 spheres of r = 0.5 m over 400 m × 10 m × 400 m, one per 200 m³,
/// spacing about 5.8 m) gets cells near its spacing, not near the spheres' diameter: the
/// deepest cells are at least 4 m, and every loose sphere lives in cells between 2.5 m and
/// twice the spacing.
#[test]
fn a_sparse_slab_gets_cells_near_its_spacing() {
    let n = 8000;
    let extent = Vec3::new(400.0, 10.0, 400.0);
    let spacing = (extent.x * extent.y * extent.z / n as f32).cbrt();
    for placement in PLACEMENTS {
        let slab = Gas::in_box(n, 3, 0.5, Vec3::new(30.0, -5.0, 70.0), extent);
        run_worlds(placement, vec![slab], "sparse slab", |octree, keys| {
            let side = octree.bounds().extent().x;
            let deepest = side / (1u32 << octree.depth()) as f32;
            assert!(deepest >= 4.0, "{placement:?}: deepest cells {deepest}");
            // Strict spheres that straddle a plane live higher up, by design.
            if placement == Placement::Loose {
                for &k in keys {
                    let cell = side / (1u32 << octree.level_of(k).unwrap()) as f32;
                    assert!(
                        (2.5..=2.0 * spacing).contains(&cell),
                        "cell {cell}, spacing {spacing}"
                    );
                }
            }
        });
    }
}

/// Two dense `gas` cubes (10 % volume fraction) 300 m apart keep cells that fit their
/// spheres: the empty space between them does not make the cells coarse.
#[test]
fn two_dense_clusters_far_apart_keep_fine_cells() {
    let n = 3000;
    let edge = Vec3::splat(cube_edge(n, 0.5, 0.1));
    for placement in PLACEMENTS {
        let a = Gas::in_box(n, 11, 0.5, Vec3::new(-150.0, 20.0, 0.0), edge);
        let b = Gas::in_box(n, 12, 0.5, Vec3::new(150.0, -20.0, 10.0), edge);
        run_worlds(placement, vec![a, b], "two clusters", |octree, keys| {
            let side = octree.bounds().extent().x;
            let deepest = side / (1u32 << octree.depth()) as f32;
            // Loose trees keep a level below the median sphere's unless their cells were
            // coarsened for a sparse world.
            let finest = match placement {
                Placement::Loose => 1.0,
                Placement::Strict => 4.0,
            };
            assert!(
                deepest < finest,
                "{placement:?}: deepest cells {deepest}, region {:?}, depth {}",
                octree.bounds(),
                octree.depth()
            );
            if placement == Placement::Loose {
                for &k in keys {
                    let cell = side / (1u32 << octree.level_of(k).unwrap()) as f32;
                    assert!((1.0..4.0).contains(&cell), "{placement:?}: cell {cell}");
                }
            }
        });
    }
}
