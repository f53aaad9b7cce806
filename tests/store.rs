//! An update is a store: `update_sphere` / `update_body` only record the new shape, and the
//! next `step` applies every update in slot order. Whatever the order and mix of operations
//! between two steps — updates in random slot order, a key updated several times (singly and
//! in batches with repeated keys), removes and inserts among them, bad input refused whole —
//! the step's `pairs`, `added` and `removed` equal the test's own O(n²) model over its own
//! record of the latest shapes, and `validate()` holds after every step and between
//! operations. Queries asked between updates and the next step (and between two steps with
//! nothing updated) see the latest shapes: each equals a brute-force loop over the model's
//! shapes. Every `Passes`, both placements, spheres and dynamic and static bodies, margin 0
//! and a margin.

mod common;

use broadleaf::geom::{self, point_aabb_distance, point_sphere_distance, sphere_cast_aabb};
use broadleaf::{Aabb, BatchError, BroadPhase, Config, Error, Passes, Placement, ProxyKey, Vec3};
use common::{Model, ModelShape, Rng, overlaps};

fn random_shape(rng: &mut Rng) -> ModelShape {
    let c = rng.offset(12.0);
    match rng.below(5) {
        0..=2 => ModelShape::Sphere {
            center: c,
            radius: rng.range(0.0, 1.0),
        },
        3 => ModelShape::body(
            c,
            Vec3::new(
                rng.range(0.0, 1.5),
                rng.range(0.0, 1.5),
                rng.range(0.0, 1.5),
            ),
            false,
        ),
        _ => ModelShape::body(
            c,
            Vec3::new(
                rng.range(0.0, 3.0),
                rng.range(0.0, 0.4),
                rng.range(0.0, 3.0),
            ),
            true,
        ),
    }
}

/// A move: mostly small (fat boxes hold), sometimes far (they escape), sometimes a resize.
fn moved(rng: &mut Rng, s: &ModelShape) -> ModelShape {
    match rng.below(10) {
        0..=5 => s.moved(rng.offset(0.05)),
        6..=7 => s.moved(rng.offset(1.0)),
        8 => s.teleported(rng.offset(14.0)),
        _ => s.placed(s.center(), rng.range(0.0, 1.2)),
    }
}

fn first_of(hits: impl Iterator<Item = (ProxyKey, Option<f32>)>) -> Option<(ProxyKey, f32)> {
    hits.filter_map(|(k, t)| t.map(|t| (t, k)))
        .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
        .map(|(t, k)| (k, t))
}

/// Every query against a brute-force loop over the model's latest shapes.
fn check_queries(bp: &BroadPhase, model: &Model, rng: &mut Rng, what: &str) {
    let shapes: Vec<(ProxyKey, ModelShape)> = {
        let mut v: Vec<_> = model.shapes.iter().map(|(&k, &s)| (k, s)).collect();
        v.sort_unstable_by_key(|p| p.0);
        v
    };
    for q in 0..4 {
        let what = format!("{what} query {q}");
        // query_aabb: the margin-grown boxes.
        let c = rng.offset(14.0);
        let h = Vec3::new(
            rng.range(0.0, 3.0),
            rng.range(0.0, 3.0),
            rng.range(0.0, 3.0),
        );
        let b = Aabb::new(c - h, c + h);
        let mut got = Vec::new();
        bp.query_aabb(&b, |k| got.push(k));
        got.sort_unstable();
        let want: Vec<ProxyKey> = shapes
            .iter()
            .filter(|(_, s)| overlaps(&s.pair_box(model.margin), &b))
            .map(|s| s.0)
            .collect();
        assert_eq!(got, want, "{what}: query_aabb");
        // query_sphere: the shapes as given.
        let r = rng.range(0.0, 3.0);
        let mut got = Vec::new();
        bp.query_sphere(c, r, |k| got.push(k));
        got.sort_unstable();
        let want: Vec<ProxyKey> = shapes
            .iter()
            .filter(|(_, s)| match *s {
                ModelShape::Sphere { center, radius } => {
                    (center - c).length_squared() <= (radius + r) * (radius + r)
                }
                ModelShape::Body { aabb, .. } => point_aabb_distance(c, &aabb) <= r,
            })
            .map(|s| s.0)
            .collect();
        assert_eq!(got, want, "{what}: query_sphere");
        // cast_ray and cast_sphere.
        let (o, d, max_t) = (rng.offset(16.0), rng.offset(1.0), rng.range(0.0, 40.0));
        let inv = geom::inverse_dir(d);
        let got = bp.cast_ray(o, d, max_t);
        let want = first_of(shapes.iter().map(|&(k, s)| {
            let t = match s {
                ModelShape::Sphere { center, radius } => {
                    geom::ray_sphere(o, d, center, radius, max_t)
                }
                ModelShape::Body { aabb, .. } => aabb.ray_entry(o, inv, max_t),
            };
            (k, t)
        }));
        assert_eq!(got, want, "{what}: cast_ray");
        let cr = rng.range(0.0, 1.0);
        let got = bp.cast_sphere(o, cr, d, max_t);
        let want = first_of(shapes.iter().map(|&(k, s)| {
            let t = match s {
                ModelShape::Sphere { center, radius } => {
                    geom::sphere_cast_sphere(o, cr, d, max_t, center, radius)
                }
                ModelShape::Body { aabb, .. } => sphere_cast_aabb(o, cr, d, max_t, &aabb),
            };
            (k, t)
        }));
        assert_eq!(got, want, "{what}: cast_sphere");
        // nearest
        let k = rng.below(10);
        let got = bp.nearest(c, k);
        let mut all: Vec<(ProxyKey, f32)> = shapes
            .iter()
            .map(|&(key, s)| {
                let dist = match s {
                    ModelShape::Sphere { center, radius } => {
                        point_sphere_distance(c, center, radius)
                    }
                    ModelShape::Body { aabb, .. } => point_aabb_distance(c, &aabb),
                };
                (key, dist)
            })
            .collect();
        all.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        all.truncate(k);
        assert_eq!(got, all, "{what}: nearest {k}");
    }
}

/// One world: random operations between steps, each step checked against the model.
fn run(seed: u64, passes: Passes, placement: Placement, margin: f32, steps: usize) {
    let mut rng = Rng::new(seed);
    let mut bp = BroadPhase::new(Config {
        passes,
        octree_placement: placement,
        margin,
        ..Config::default()
    });
    let mut model = Model::new(margin);
    for _ in 0..150 {
        model.insert(&mut bp, random_shape(&mut rng));
    }
    let ctx =
        |step: usize| format!("seed {seed} {passes:?} {placement:?} margin {margin} step {step}");
    model.check_step(&mut bp, &ctx(0));
    for step in 1..=steps {
        let what = ctx(step);
        // Updates of a random subset in random order (keys shuffled, so slots come in no
        // order), some keys several times.
        let mut keys = model.keys();
        for i in (1..keys.len()).rev() {
            keys.swap(i, rng.below(i + 1));
        }
        let movers = rng.below(keys.len() + 1);
        for &key in &keys[..movers] {
            for _ in 0..1 + usize::from(rng.chance(0.2)) * rng.below(3) {
                let s = moved(&mut rng, &model.shapes[&key]);
                model.update(&mut bp, key, s);
            }
        }
        if rng.chance(0.5) {
            check_queries(&bp, &model, &mut rng, &format!("{what} after updates"));
        }
        // Removes and inserts among the updates, and a key updated after its insert.
        for _ in 0..rng.below(6) {
            let keys = model.keys();
            if !keys.is_empty() {
                model.remove(&mut bp, keys[rng.below(keys.len())]);
            }
        }
        for _ in 0..rng.below(6) {
            let key = model.insert(&mut bp, random_shape(&mut rng));
            if rng.chance(0.5) {
                let s = moved(&mut rng, &model.shapes[&key]);
                model.update(&mut bp, key, s);
            }
        }
        // A batch with a repeated key (the last entry wins), and a bad batch that changes
        // nothing.
        batches(&mut bp, &mut model, &mut rng, &what);
        bp.validate();
        check_queries(&bp, &model, &mut rng, &format!("{what} before the step"));
        model.check_step(&mut bp, &what);
        check_queries(&bp, &model, &mut rng, &format!("{what} after the step"));
        if rng.chance(0.2) {
            // A step with nothing updated, and queries after it.
            model.check_step(&mut bp, &format!("{what} (idle)"));
            check_queries(&bp, &model, &mut rng, &format!("{what} after an idle step"));
        }
    }
}

/// A sphere batch and a body batch with repeated keys, then one bad batch of each kind.
fn batches(bp: &mut BroadPhase, model: &mut Model, rng: &mut Rng, what: &str) {
    let keys = model.keys();
    if keys.is_empty() {
        return;
    }
    let mut spheres = Vec::new();
    let mut bodies = Vec::new();
    for _ in 0..rng.below(12) {
        let key = keys[rng.below(keys.len())];
        match moved(rng, &model.shapes[&key]) {
            ModelShape::Sphere { center, radius } => spheres.push((key, center, radius)),
            ModelShape::Body { aabb, .. } => bodies.push((key, aabb)),
        }
    }
    // Bad batches first: a non-finite entry after good ones changes nothing.
    let before: Vec<_> = keys.iter().map(|&k| bp.shape(k)).collect();
    if !spheres.is_empty() {
        let mut bad = spheres.clone();
        bad.push((spheres[0].0, Vec3::new(f32::NAN, 0.0, 0.0), 1.0));
        let index = bad.len() - 1;
        assert!(
            matches!(
                bp.update_spheres(&bad),
                Err(BatchError { index: i, error: Error::NonFinite { .. } }) if i == index
            ),
            "{what}: bad sphere batch"
        );
    }
    if !bodies.is_empty() {
        let mut bad = bodies.clone();
        let b = bodies[0].1;
        bad.push((
            bodies[0].0,
            Aabb {
                min: b.max + Vec3::ONE,
                max: b.min,
            },
        ));
        let index = bad.len() - 1;
        assert!(
            matches!(bp.update_bodies(&bad), Err(BatchError { index: i, .. }) if i == index),
            "{what}: bad body batch"
        );
    }
    let after: Vec<_> = keys.iter().map(|&k| bp.shape(k)).collect();
    assert_eq!(before, after, "{what}: a refused batch changed a shape");
    bp.update_spheres(&spheres).expect("a good sphere batch");
    bp.update_bodies(&bodies).expect("a good body batch");
    for &(key, center, radius) in &spheres {
        model
            .shapes
            .insert(key, ModelShape::Sphere { center, radius });
    }
    for &(key, aabb) in &bodies {
        let is_static = model.shapes[&key].is_static();
        model
            .shapes
            .insert(key, ModelShape::Body { aabb, is_static });
    }
    model.assert_same_proxies(bp, what);
}

#[test]
fn updates_in_any_order_equal_brute_force_every_pass_and_placement() {
    let mut seed = 1;
    for passes in [Passes::Adaptive, Passes::Full, Passes::Incremental] {
        for placement in [Placement::Strict, Placement::Loose] {
            for margin in [0.0, 0.1] {
                run(seed, passes, placement, margin, 12);
                seed += 1;
            }
        }
    }
}

/// A key updated many times before one step counts as one mover, moved from where the last
/// step applied it to its last shape: a sphere that wanders far and comes back to where it
/// was pairs exactly as if it had not moved, and one that ends far away pairs there.
#[test]
fn repeated_updates_before_one_step_apply_the_last() {
    for passes in [Passes::Adaptive, Passes::Full, Passes::Incremental] {
        let mut bp = BroadPhase::new(Config {
            passes,
            ..Config::default()
        });
        let mut model = Model::new(0.0);
        let mut rng = Rng::new(77);
        for _ in 0..60 {
            model.insert(&mut bp, random_shape(&mut rng));
        }
        model.check_step(&mut bp, "first");
        for step in 0..6 {
            for key in model.keys() {
                let home = model.shapes[&key];
                for _ in 0..3 {
                    let far = home.teleported(rng.offset(50.0));
                    model.update(&mut bp, key, far);
                }
                let last = if rng.chance(0.5) {
                    home
                } else {
                    moved(&mut rng, &home)
                };
                model.update(&mut bp, key, last);
            }
            check_queries(&bp, &model, &mut rng, &format!("{passes:?} {step} pending"));
            model.check_step(&mut bp, &format!("{passes:?} step {step}"));
            assert_eq!(bp.stats().updated, model.shapes.len(), "each key once");
        }
    }
}

/// A snapshot taken between updates and the next step holds the latest shapes: restored, its
/// next step's lists equal the original's (and the model's).
#[cfg(feature = "serde")]
#[test]
fn snapshot_between_an_update_and_a_step_holds_the_latest_shapes() {
    let mut rng = Rng::new(5);
    let mut bp = BroadPhase::new(Config::default());
    let mut model = Model::new(0.0);
    for _ in 0..100 {
        model.insert(&mut bp, random_shape(&mut rng));
    }
    for step in 0..8 {
        for key in model.keys() {
            if rng.chance(0.6) {
                let s = moved(&mut rng, &model.shapes[&key]);
                model.update(&mut bp, key, s);
            }
        }
        let json = serde_json::to_string(&bp).expect("serialises");
        let mut restored: BroadPhase = serde_json::from_str(&json).expect("restores");
        restored.validate();
        model.assert_same_proxies(&restored, "restored");
        let mut twin = model.clone();
        model.check_step(&mut bp, &format!("original {step}"));
        twin.check_step(&mut restored, &format!("restored {step}"));
    }
}

/// A world for the split apply (feature `parallel`): `Passes::Full` (never the incremental
/// regime) and 12 000 small spheres in a 120 m cube, more than `PARALLEL_MIN_SPHERES`.
#[cfg(feature = "parallel")]
fn split_apply_world(rng: &mut Rng) -> (BroadPhase, Model) {
    let mut bp = BroadPhase::new(Config {
        passes: Passes::Full,
        ..Config::default()
    });
    let mut model = Model::new(0.0);
    model.quadratic = false;
    for _ in 0..12_000 {
        let s = ModelShape::Sphere {
            center: rng.offset(60.0),
            radius: rng.range(0.1, 0.6),
        };
        model.insert(&mut bp, s);
    }
    (bp, model)
}

/// Feature `parallel`: the apply pass splits its spheres over the pool when most slots are
/// stale in a world of more than `PARALLEL_MIN_SPHERES` (10 000) spheres outside the
/// incremental regime. Updated in random slot order, with bodies among them and removes and
/// inserts between, every step's lists equal the model's brute force (a sweep) at one thread
/// and at two, and `validate()` holds.
#[cfg(feature = "parallel")]
#[test]
fn parallel_apply_equals_brute_force_at_one_and_two_threads() {
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a pool");
        pool.install(|| {
            let mut rng = Rng::new(11);
            let (mut bp, mut model) = split_apply_world(&mut rng);
            for _ in 0..200 {
                model.insert(&mut bp, random_shape(&mut rng));
            }
            model.check_step(&mut bp, "first");
            for step in 0..5 {
                let what = format!("{threads} threads step {step}");
                let mut keys = model.keys();
                for i in (1..keys.len()).rev() {
                    keys.swap(i, rng.below(i + 1));
                }
                for &key in &keys[..keys.len() * 3 / 4] {
                    let s = moved(&mut rng, &model.shapes[&key]);
                    model.update(&mut bp, key, s);
                }
                for _ in 0..20 {
                    let keys = model.keys();
                    model.remove(&mut bp, keys[rng.below(keys.len())]);
                    model.insert(&mut bp, random_shape(&mut rng));
                }
                model.check_step(&mut bp, &what);
            }
        });
    }
}

/// Feature `parallel`: spheres held in the octree's root move while the apply runs split
/// over two threads. The region follows the bulk of the spheres and leaves a few far outliers
/// out (kept in the root, counted as outside); some of those move a little and stay outside,
/// others cycle through small in the bulk, too big for any child of the root (in the root,
/// inside the region), the same teleported far (in the root, outside), small and far, big in
/// the bulk again, and back. Every
/// step's lists equal the model's brute force, and `validate()` (which recounts the spheres
/// outside the region from the shapes) holds; the tree keeps outliers out throughout.
#[cfg(feature = "parallel")]
#[test]
fn parallel_apply_moves_root_and_outside_spheres_exactly() {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .expect("a pool");
    pool.install(|| {
        let mut rng = Rng::new(12);
        let (mut bp, mut model) = split_apply_world(&mut rng);
        let far = Vec3::new(2.0e4, -1.5e4, 3.0e4);
        let sphere = |center, radius| ModelShape::Sphere { center, radius };
        let outliers: Vec<ProxyKey> = (0..4)
            .map(|_| model.insert(&mut bp, sphere(far + rng.offset(3.0), 0.5)))
            .collect();
        let cyclers: Vec<(ProxyKey, usize)> = (0..3)
            .map(|i| (model.insert(&mut bp, sphere(rng.offset(60.0), 0.5)), i))
            .collect();
        model.check_step(&mut bp, "first");
        // Too big for the root's children, small enough for the root: a root cell's loose
        // bounds reach half its side beyond it.
        let region = bp.octree().bounds();
        let (mid, big) = (region.center(), 0.35 * (region.max.x - region.min.x));
        let (mut saw_outside, mut saw_root_inside) = (false, false);
        for step in 0..8 {
            // Most of the bulk moves, so the apply is the dense one split over the pool.
            for key in model.keys() {
                let mine = outliers.contains(&key) || cyclers.iter().any(|c| c.0 == key);
                if !mine && rng.below(4) != 0 {
                    let s = model.shapes[&key].moved(rng.offset(0.05));
                    model.update(&mut bp, key, s);
                }
            }
            for &key in &outliers {
                let s = model.shapes[&key].moved(rng.offset(0.5));
                model.update(&mut bp, key, s);
            }
            // Each cycler moves to its next state every step.
            for &(key, phase) in &cyclers {
                let s = match (phase + step) % 5 {
                    0 => sphere(rng.offset(60.0), 0.5),
                    1 | 4 => sphere(mid + rng.offset(5.0), big),
                    2 => sphere(far + rng.offset(3.0), big),
                    _ => sphere(far + rng.offset(3.0), 0.5),
                };
                model.update(&mut bp, key, s);
            }
            model.check_step(&mut bp, &format!("step {step}"));
            let stats = bp.octree().stats();
            saw_outside |= stats.overflow > 0;
            saw_root_inside |= stats.per_level[0] > stats.overflow;
        }
        assert!(
            saw_outside,
            "the region took the outliers in: nothing tested outside"
        );
        assert!(
            saw_root_inside,
            "no sphere was ever in the root inside the region"
        );
    });
}
