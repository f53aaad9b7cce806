//! Criterion benchmarks of one broadphase step. Each iteration advances the seeded scene by
//! `DT` (`Gas::step`, a few ns per sphere, included in the figure), applies every sphere's new
//! centre with `Octree::update`, and collects all pairs with `pairs_into` into a cleared,
//! reused `Vec`. Throughput is spheres, so criterion's elements/s inverts to ns/object/step.

use broadleaf::fixtures::scene::{DT, Gas};
use broadleaf::octree::{Octree, Placement};
use broadleaf::{Pair, ProxyKey};
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;

fn octree_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("octree");
    let scenes = [
        ("gas", Gas::new(10_000, 1)),
        ("gas", Gas::new(100_000, 1)),
        ("clustered", Gas::clustered(100_000, 1)),
    ];
    let placements = [("", Placement::Strict), ("-loose", Placement::Loose)];
    for ((name, scene), (suffix, placement)) in scenes
        .into_iter()
        .flat_map(|s| placements.map(move |p| (s.clone(), p)))
    {
        let mut gas = scene;
        let depth = placement.depth_for(&gas.bounds, gas.radius);
        let mut tree =
            Octree::with_placement(gas.bounds, depth, placement).expect("scene bounds are valid");
        let keys: Vec<ProxyKey> = gas
            .centers
            .iter()
            .map(|&c| tree.insert(c, gas.radius).expect("scene spheres are valid"))
            .collect();
        let mut pairs: Vec<Pair> = Vec::new();
        group.throughput(Throughput::Elements(gas.len() as u64));
        group.bench_function(
            BenchmarkId::new(format!("{name}{suffix}"), gas.len()),
            |b| {
                b.iter(|| {
                    gas.step(DT);
                    for (&k, &c) in keys.iter().zip(&gas.centers) {
                        tree.update(k, c, gas.radius)
                            .expect("live key, valid sphere");
                    }
                    pairs.clear();
                    tree.pairs_into(&mut pairs);
                    black_box(pairs.len())
                });
            },
        );
    }
    group.finish();
}

// ---------------------------------------------------------------------------------------------
// BVH: SAH builds, and refit + self pairs of moving boxes.
// ---------------------------------------------------------------------------------------------
mod bvh_benches {
    use broadleaf::bvh::{Bvh, BvhConfig};
    use broadleaf::fixtures::scene::{DT, GAS_SPEED, Rng};
    use broadleaf::{Aabb, ProxyKey, Vec3};
    use criterion::{BatchSize, BenchmarkId, Criterion, Throughput};
    use std::hint::black_box;

    /// A local stand-in for the `bodies` scene until it lands in `scene.rs`: `n` boxes with
    /// half-extents log-uniform in [0.1, 2] m per axis, centres uniform in a cube sized so the
    /// boxes fill about 10 % of it, velocities uniform in [−5, 5]³ m/s, reflecting at the walls.
    pub struct Bodies {
        half: f32,
        centers: Vec<Vec3>,
        extents: Vec<Vec3>,
        velocities: Vec<Vec3>,
    }

    impl Bodies {
        pub fn new(n: usize, seed: u64) -> Self {
            let mut rng = Rng::new(seed);
            let (lo, hi) = (0.1f32.ln(), 2.0f32.ln());
            let extents: Vec<Vec3> = (0..n)
                .map(|_| {
                    Vec3::new(
                        rng.range(lo, hi).exp(),
                        rng.range(lo, hi).exp(),
                        rng.range(lo, hi).exp(),
                    )
                })
                .collect();
            let volume: f32 = extents.iter().map(|e| 8.0 * e.x * e.y * e.z).sum();
            let half = (volume / 0.1).cbrt() * 0.5;
            let centers = (0..n)
                .map(|_| rng.vec3_in(Vec3::splat(-half), Vec3::splat(half)))
                .collect();
            let velocities = (0..n)
                .map(|_| rng.vec3_in(Vec3::splat(-GAS_SPEED), Vec3::splat(GAS_SPEED)))
                .collect();
            Bodies {
                half,
                centers,
                extents,
                velocities,
            }
        }

        pub fn aabbs(&self) -> Vec<Aabb> {
            (0..self.centers.len()).map(|i| self.aabb(i)).collect()
        }

        fn aabb(&self, i: usize) -> Aabb {
            Aabb::from_center_half_extents(self.centers[i], self.extents[i])
        }

        pub fn step(&mut self, dt: f32) {
            let h = self.half;
            for (c, v) in self.centers.iter_mut().zip(&mut self.velocities) {
                *c += *v * dt;
                for axis in 0..3 {
                    if c[axis].abs() > h {
                        c[axis] = (2.0 * h.copysign(c[axis]) - c[axis]).clamp(-h, h);
                        v[axis] = -v[axis];
                    }
                }
            }
        }
    }

    fn build(c: &mut Criterion) {
        let mut group = c.benchmark_group("bvh_build_sah");
        group.sample_size(10);
        for n in [100_000usize, 1_000_000] {
            let boxes = Bodies::new(n, 1).aabbs();
            let (mut bvh, _) = Bvh::from_aabbs(BvhConfig::default(), &boxes).unwrap();
            group.throughput(Throughput::Elements(n as u64));
            group.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
                b.iter(|| {
                    bvh.rebuild();
                    black_box(bvh.sah_cost())
                });
            });
            // A new tree: `n` inserts and the first build, from the boxes' random order. The
            // tree is dropped outside the timing (freeing its arrays is not the build).
            group.bench_with_input(BenchmarkId::new("from_aabbs", n), &n, |b, _| {
                b.iter_batched(
                    || (),
                    |()| Bvh::from_aabbs(BvhConfig::default(), &boxes).expect("valid boxes"),
                    BatchSize::PerIteration,
                );
            });
        }
        group.finish();
    }

    /// One physics step of `n` moving boxes: move them (a few ns each), update every box, refit,
    /// collect all self pairs.
    fn refit_pairs(c: &mut Criterion) {
        let mut group = c.benchmark_group("bvh_refit_pairs");
        for n in [10_000usize, 100_000] {
            let mut scene = Bodies::new(n, 2);
            let (mut bvh, keys) = Bvh::from_aabbs(BvhConfig::default(), &scene.aabbs()).unwrap();
            let mut pairs: Vec<(ProxyKey, ProxyKey)> = Vec::new();
            group.throughput(Throughput::Elements(n as u64));
            group.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
                b.iter(|| {
                    scene.step(DT);
                    for (i, &k) in keys.iter().enumerate() {
                        bvh.update(k, scene.aabb(i)).unwrap();
                    }
                    bvh.refit();
                    pairs.clear();
                    bvh.for_each_pair(|a, b| pairs.push((a, b)));
                    black_box(pairs.len())
                });
            });
            let s = bvh.stats();
            eprintln!(
                "bvh_refit_pairs/{n}: {} pairs, {} rebuilds, {} refits, cost ratio {:.3}, depth {}",
                pairs.len(),
                s.rebuilds,
                s.refits,
                s.cost_ratio,
                s.depth
            );
        }
        group.finish();
    }

    pub fn register(c: &mut Criterion) {
        build(c);
        refit_pairs(c);
    }
}

// ---------------------------------------------------------------------------------------------
// Scenes: broadleaf's whole `BroadPhase` step next to rapier's broad phase, same motion.
// ---------------------------------------------------------------------------------------------
mod scene_benches {
    use broadleaf::fixtures::scene::{Bodies, Churn, Feed, Frame, Gas, Idle, Scene, Spawn};
    use broadleaf::octree::Placement;
    use broadleaf::{BroadPhase, Config};
    use criterion::{BenchmarkId, Criterion, Throughput};
    use std::hint::black_box;
    use std::time::{Duration, Instant};

    /// Makes a fresh copy of a scene (each criterion sample starts from the same state).
    type MakeScene = Box<dyn FnMut() -> Box<dyn Scene>>;

    /// The benchmarked scenes at their criterion sizes (vs_rapier runs the larger ones).
    fn scenes() -> Vec<(&'static str, MakeScene)> {
        vec![
            ("gas", Box::new(|| Box::new(Gas::new(10_000, 1)))),
            ("gas", Box::new(|| Box::new(Gas::new(100_000, 1)))),
            (
                "clustered",
                Box::new(|| Box::new(Gas::clustered(10_000, 1))),
            ),
            ("bodies", Box::new(|| Box::new(Bodies::new(10_000, 1)))),
            ("churn", Box::new(|| Box::new(Churn::new(10_000, 1)))),
        ]
    }

    /// broadleaf: each iteration advances the scene (untimed) and times applying the frame
    /// plus `step()` — the full step of `benchmarks.md`.
    fn broadleaf(scene: &mut dyn Scene, iters: u64, placement: Placement, skin: f32) -> Duration {
        let mut bp = BroadPhase::new(Config {
            octree_placement: placement,
            skin,
            ..Config::default()
        });
        let mut feed = Feed::new(false);
        let mut spawns: Vec<Spawn> = Vec::new();
        scene.spawns(&mut spawns);
        feed.spawn(&mut bp, &spawns).expect("finite scene");
        bp.step();
        let mut frame = Frame::default();
        let mut total = Duration::ZERO;
        for _ in 0..iters {
            scene.advance(&mut frame);
            let t = Instant::now();
            feed.apply(&mut bp, &frame).expect("valid frame");
            bp.step();
            black_box(bp.pairs().len());
            total += t.elapsed();
        }
        total
    }

    /// rapier: the same frames as kinematic targets; the time is rapier's own broad-phase
    /// counter for each `PhysicsPipeline::step`.
    #[cfg(feature = "profiler")]
    fn rapier(scene: &mut dyn Scene, iters: u64) -> Duration {
        let mut world = broadleaf::fixtures::rapier_world::SceneWorld::new();
        let mut spawns: Vec<Spawn> = Vec::new();
        scene.spawns(&mut spawns);
        for s in &spawns {
            world.insert(s);
        }
        world.step();
        let mut frame = Frame::default();
        let mut total = Duration::ZERO;
        for _ in 0..iters {
            scene.advance(&mut frame);
            world.set_targets(&frame);
            total += world.step();
            world.apply_structure(&frame);
        }
        total
    }

    /// The recorded `pile` (rapier feature): 10 000 settled spheres, replayed forwards and
    /// backwards so that every timed step moves them however many steps criterion asks for.
    #[cfg(feature = "profiler")]
    mod pile {
        use broadleaf::fixtures::scene::{Frame, Object, Scene, Spawn};
        use broadleaf::{Aabb, Vec3};
        use std::rc::Rc;

        /// Frames recorded once, shared by every copy.
        #[derive(Clone)]
        pub struct PingPong {
            pub bounds: Aabb,
            pub radius: f32,
            pub frames: Rc<Vec<Vec<Vec3>>>,
            pub at: usize,
            pub forward: bool,
        }

        impl Scene for PingPong {
            fn bounds(&self) -> Aabb {
                self.bounds
            }

            fn len(&self) -> usize {
                self.frames[0].len()
            }

            fn spawns(&self, out: &mut Vec<Spawn>) {
                let radius = self.radius;
                out.extend(
                    self.frames[self.at]
                        .iter()
                        .enumerate()
                        .map(|(i, &center)| Spawn {
                            id: i as u32,
                            object: Object::Sphere { center, radius },
                            is_static: false,
                        }),
                );
            }

            fn advance(&mut self, frame: &mut Frame) {
                frame.clear();
                let last = self.frames.len() - 1;
                if (self.forward && self.at == last) || (!self.forward && self.at == 0) {
                    self.forward = !self.forward;
                }
                self.at = if self.forward {
                    self.at + 1
                } else {
                    self.at - 1
                };
                let radius = self.radius;
                frame.moved.extend(
                    self.frames[self.at]
                        .iter()
                        .enumerate()
                        .map(|(i, &center)| (i as u32, Object::Sphere { center, radius })),
                );
            }
        }

        /// Records the pile (240 settling steps, then 120 frames).
        pub fn record() -> PingPong {
            let rec = broadleaf::fixtures::rapier_world::record_pile(10_000, 1, 240, 120);
            PingPong {
                bounds: rec.bounds,
                radius: rec.radius,
                frames: Rc::new(rec.frames),
                at: 0,
                forward: true,
            }
        }
    }

    /// `pile/10000`: broadleaf in both placements with adaptive fat margins, with a fixed skin
    /// of 0.05 m (loose), and rapier.
    #[cfg(feature = "profiler")]
    fn register_pile(c: &mut Criterion) {
        let recorded = pile::record();
        let n = recorded.len();
        let mut group = c.benchmark_group(format!("pile/{n}"));
        group.sample_size(10);
        group.warm_up_time(Duration::from_secs(1));
        group.measurement_time(Duration::from_secs(3));
        group.throughput(Throughput::Elements(n as u64));
        let runs = [
            ("broadleaf", Placement::Strict, 0.0),
            ("broadleaf-loose", Placement::Loose, 0.0),
            ("broadleaf-loose-skin0.05", Placement::Loose, 0.05),
        ];
        for (name, placement, skin) in runs {
            group.bench_function(BenchmarkId::new(name, n), |b| {
                b.iter_custom(|iters| broadleaf(&mut recorded.clone(), iters, placement, skin));
            });
        }
        group.bench_function(BenchmarkId::new("rapier", n), |b| {
            b.iter_custom(|iters| rapier(&mut recorded.clone(), iters));
        });
        group.finish();
    }

    /// Spheres of the `idle` bench: 100 000, since one step of broadleaf or rapier stays far
    /// under the ~1 s an iteration may take (building the world is outside the timing).
    const IDLE_N: usize = 100_000;
    /// Percentages of movers the `idle` bench runs.
    const IDLE_MOVING: [f64; 3] = [0.0, 1.0, 10.0];

    /// `idle`: the `gas` spheres at rest but for a fixed P % that move (the rest are never
    /// updated, in either engine); one benchmark per engine and P.
    fn register_idle(c: &mut Criterion) {
        let mut group = c.benchmark_group("idle");
        group.sample_size(10);
        group.warm_up_time(Duration::from_secs(1));
        group.measurement_time(Duration::from_secs(3));
        group.throughput(Throughput::Elements(IDLE_N as u64));
        for p in IDLE_MOVING {
            group.bench_function(BenchmarkId::new("broadleaf", p), |b| {
                b.iter_custom(|iters| {
                    broadleaf(&mut Idle::new(IDLE_N, 1, p), iters, Placement::Strict, 0.0)
                });
            });
            #[cfg(feature = "profiler")]
            group.bench_function(BenchmarkId::new("rapier", p), |b| {
                b.iter_custom(|iters| rapier(&mut Idle::new(IDLE_N, 1, p), iters));
            });
        }
        group.finish();
    }

    pub fn register(c: &mut Criterion) {
        register_idle(c);
        #[cfg(feature = "profiler")]
        register_pile(c);
        for (name, mut make) in scenes() {
            let n = make().len();
            let mut group = c.benchmark_group(format!("{name}/{n}"));
            group.sample_size(10);
            group.warm_up_time(Duration::from_secs(1));
            group.measurement_time(Duration::from_secs(3));
            group.throughput(Throughput::Elements(n as u64));
            group.bench_function(BenchmarkId::new("broadleaf", n), |b| {
                b.iter_custom(|iters| broadleaf(&mut *make(), iters, Placement::Strict, 0.0));
            });
            if name != "bodies" {
                group.bench_function(BenchmarkId::new("broadleaf-loose", n), |b| {
                    b.iter_custom(|iters| broadleaf(&mut *make(), iters, Placement::Loose, 0.0));
                });
            }
            #[cfg(feature = "profiler")]
            group.bench_function(BenchmarkId::new("rapier", n), |b| {
                b.iter_custom(|iters| rapier(&mut *make(), iters));
            });
            group.finish();
        }
    }
}

fn benches(c: &mut Criterion) {
    scene_benches::register(c);
    octree_step(c);
    bvh_benches::register(c);
}

criterion_group!(broadphase, benches);
criterion_main!(broadphase);
