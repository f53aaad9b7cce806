//! Feature `parallel`: a step gives the same lists at any thread count. Random worlds of
//! spheres and dynamic and static bodies (random collision groups) move, rest, churn and grow
//! under rayon pools of 1, 2, 3 and 8 threads; every run's digest of each step's `pairs`,
//! `added` and `removed` and of the keys its inserts returned must be the one-thread run's,
//! and every step's lists must be the brute force of the model in `common`, filtered by the
//! groups rule.
//!
//! The worlds are large enough (over ten thousand spheres, or for the worlds of bodies alone
//! over twenty thousand bodies) for the broadphase to split its full passes, and with more
//! than one thread every full pass must report through `StepStats` that it ran split, and
//! with one thread that it ran serially: the split passes are the ones checked (with bodies
//! alone, the BVH descents handed out in items to many tasks), whatever the crate's thresholds.

mod common;

use broadleaf::fixtures::scene::{Feed, Frame, Gas, Scene};
use broadleaf::octree::Placement;
use broadleaf::{BroadPhase, CollisionGroups, Config, Pass, Passes, ProxyKey, Vec3};
use common::{Fnv, KeyPair, Model, ModelShape, Rng};
use std::alloc::{GlobalAlloc, Layout, System};
use std::collections::{BTreeSet, HashMap};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Proxies at the start of every world: four in five are spheres.
const START: usize = 13_500;
/// Bodies at the start of a world of bodies alone (about 85 % dynamic).
const BODY_START: usize = 22_000;

/// Thread counts every world runs at.
const THREADS: [usize; 4] = [1, 2, 3, 8];

/// How a world is built and configured.
#[derive(Clone, Copy, Debug)]
struct World {
    seed: u64,
    /// Proxies at the start.
    start: usize,
    placement: Placement,
    passes: Passes,
    margin: f32,
    /// Bodies only (smaller boxes, no spheres).
    bodies_only: bool,
}

/// The model's proxies with their groups, and the pairs of the last step.
struct Checked {
    model: Model,
    groups: HashMap<ProxyKey, CollisionGroups>,
    prev: BTreeSet<KeyPair>,
    digest: Fnv,
}

/// The half side of the cube the proxies live in; `Config::bounds` is a little smaller, so
/// some spheres lie outside the octree's bounds.
const HALF: f32 = 30.0;

impl Checked {
    /// A random shape: mostly spheres of radii 0.2–2.5 (several octree levels), some
    /// dynamic and some static boxes of half extents 0.2–3.
    fn random_shape(rng: &mut Rng, bodies_only: bool) -> ModelShape {
        let center = rng.offset(HALF);
        let roll = rng.unit();
        if bodies_only {
            let half = Vec3::new(
                rng.range(0.2, 1.2),
                rng.range(0.2, 1.2),
                rng.range(0.2, 1.2),
            );
            ModelShape::body(center, half, roll > 0.85)
        } else if roll < 0.8 {
            ModelShape::Sphere {
                center,
                radius: if rng.chance(0.1) {
                    rng.range(1.0, 2.5)
                } else {
                    rng.range(0.2, 0.8)
                },
            }
        } else {
            let half = Vec3::new(
                rng.range(0.2, 3.0),
                rng.range(0.2, 3.0),
                rng.range(0.2, 3.0),
            );
            ModelShape::body(center, half, roll > 0.95)
        }
    }

    /// Random groups for one proxy in four: memberships and filters over three bits, so that
    /// some pairs are filtered and most are not.
    fn random_groups(rng: &mut Rng) -> Option<CollisionGroups> {
        rng.chance(0.25).then(|| CollisionGroups {
            memberships: 1 << rng.below(3),
            filter: (rng.next_u64() as u32 & 0b111) | 1,
        })
    }

    fn insert(&mut self, bp: &mut BroadPhase, rng: &mut Rng, bodies_only: bool) {
        let key = self.model.insert(bp, Self::random_shape(rng, bodies_only));
        self.digest.key(key);
        if let Some(g) = Self::random_groups(rng) {
            bp.set_groups(key, g).expect("a live key");
            self.groups.insert(key, g);
        }
    }

    fn group(&self, k: ProxyKey) -> CollisionGroups {
        self.groups.get(&k).copied().unwrap_or_default()
    }

    /// Steps `bp`, checks its lists against the model's brute force (filtered by groups) and
    /// feeds them to the digest.
    fn step(&mut self, bp: &mut BroadPhase, context: &str) {
        let want: Vec<KeyPair> = self
            .model
            .pairs_sweep()
            .into_iter()
            .filter(|&(a, b)| self.group(a).allows(self.group(b)))
            .collect();
        let now: BTreeSet<KeyPair> = want.iter().copied().collect();
        let added: Vec<KeyPair> = now.difference(&self.prev).copied().collect();
        let removed: Vec<KeyPair> = self.prev.difference(&now).copied().collect();
        bp.step();
        self.model.assert_list(context, "pairs", bp.pairs(), &want);
        self.model.assert_list(context, "added", bp.added(), &added);
        self.model
            .assert_list(context, "removed", bp.removed(), &removed);
        self.digest.pairs(1, bp.pairs());
        self.digest.pairs(2, bp.added());
        self.digest.pairs(3, bp.removed());
        self.prev = now;
        bp.validate();
    }
}

/// What a run gives: its digest, its full passes, and how many of them ran split over the pool.
struct Ran {
    digest: u64,
    full: usize,
    split: usize,
}

/// Runs `world` on the current rayon pool through four phases.
fn run(world: World) -> Ran {
    let mut rng = Rng::new(world.seed);
    let mut bp = BroadPhase::new(Config {
        bounds: Some(broadleaf::Aabb::new(
            Vec3::splat(-0.9 * HALF),
            Vec3::splat(0.9 * HALF),
        )),
        octree_placement: world.placement,
        passes: world.passes,
        margin: world.margin,
        ..Config::default()
    });
    let mut c = Checked {
        model: Model::new(world.margin),
        groups: HashMap::new(),
        prev: BTreeSet::new(),
        digest: Fnv::new(),
    };
    c.model.quadratic = false;
    for _ in 0..world.start {
        c.insert(&mut bp, &mut rng, world.bodies_only);
    }
    let moves = |c: &mut Checked, bp: &mut BroadPhase, rng: &mut Rng, p: f32, reach: f32| {
        for key in c.model.keys() {
            if rng.chance(p) {
                let s = c.model.shapes[&key];
                let moved = if rng.chance(0.01) {
                    s.teleported(rng.offset(HALF))
                } else {
                    s.moved(rng.offset(reach))
                };
                c.model.update(bp, key, moved);
            }
        }
    };
    let (mut steps, mut full, mut split) = (0, 0, 0);
    let mut step = |c: &mut Checked, bp: &mut BroadPhase, phase: &str| {
        c.step(bp, &format!("{world:?} step {steps} ({phase})"));
        let stats = bp.stats();
        if matches!(stats.pass, Pass::Full | Pass::FullFat) {
            full += 1;
            split += usize::from(stats.split_tasks >= 2);
        }
        steps += 1;
    };
    step(&mut c, &mut bp, "first");
    // Everything moves: full passes.
    for _ in 0..6 {
        moves(&mut c, &mut bp, &mut rng, 1.0, 0.3);
        step(&mut c, &mut bp, "move");
    }
    // Almost everything rests: the incremental regime, entered by a full pass over fat boxes.
    for _ in 0..6 {
        moves(&mut c, &mut bp, &mut rng, 0.01, 0.3);
        step(&mut c, &mut bp, "rest");
    }
    // Churn: removes, inserts, new groups and a fifth moving.
    for _ in 0..6 {
        let keys = c.model.keys();
        for _ in 0..keys.len() / 40 {
            let key = keys[rng.below(keys.len())];
            if c.model.shapes.contains_key(&key) {
                c.model.remove(&mut bp, key);
                c.groups.remove(&key);
            }
        }
        for _ in 0..keys.len() / 40 {
            c.insert(&mut bp, &mut rng, world.bodies_only);
        }
        for &key in keys.iter().step_by(97) {
            if c.model.shapes.contains_key(&key) {
                let g = Checked::random_groups(&mut rng).unwrap_or_default();
                bp.set_groups(key, g).expect("a live key");
                c.groups.insert(key, g);
            }
        }
        moves(&mut c, &mut bp, &mut rng, 0.2, 0.5);
        step(&mut c, &mut bp, "churn");
    }
    // Growth: a twentieth more proxies each step, everything moving.
    for _ in 0..5 {
        for _ in 0..bp.len() / 20 {
            c.insert(&mut bp, &mut rng, world.bodies_only);
        }
        moves(&mut c, &mut bp, &mut rng, 1.0, 0.3);
        step(&mut c, &mut bp, "grow");
    }
    Ran {
        digest: c.digest.0,
        full,
        split,
    }
}

/// Runs `world` at every thread count; all digests must be equal.
fn same_at_every_thread_count(world: World) {
    // Not beside the allocation count, which counts every thread's allocations.
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let digests: Vec<u64> = THREADS
        .iter()
        .map(|&t| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .expect("a thread pool");
            let ran = pool.install(|| run(world));
            assert!(ran.full > 0, "{world:?}: no full pass ran");
            let want = if t > 1 { ran.full } else { 0 };
            assert_eq!(
                ran.split, want,
                "{world:?}, {t} threads: {} of {} full passes ran split",
                ran.split, ran.full
            );
            ran.digest
        })
        .collect();
    for (t, d) in THREADS.iter().zip(&digests) {
        assert_eq!(
            *d, digests[0],
            "{world:?}: {t} threads gave digest {d:#x}, one thread {:#x}",
            digests[0]
        );
    }
}

#[test]
fn loose_world_is_the_same_at_every_thread_count() {
    same_at_every_thread_count(World {
        seed: 1,
        start: START,
        placement: Placement::Loose,
        passes: Passes::Adaptive,
        margin: 0.0,
        bodies_only: false,
    });
}

#[test]
fn strict_world_with_a_margin_is_the_same_at_every_thread_count() {
    same_at_every_thread_count(World {
        seed: 2,
        start: START,
        placement: Placement::Strict,
        passes: Passes::Adaptive,
        margin: 0.05,
        bodies_only: false,
    });
}

#[test]
fn full_passes_only_are_the_same_at_every_thread_count() {
    same_at_every_thread_count(World {
        seed: 3,
        start: START,
        placement: Placement::Loose,
        passes: Passes::Full,
        margin: 0.0,
        bodies_only: false,
    });
}

#[test]
fn world_of_bodies_is_the_same_at_every_thread_count() {
    same_at_every_thread_count(World {
        seed: 4,
        start: BODY_START,
        placement: Placement::Loose,
        passes: Passes::Adaptive,
        margin: 0.0,
        bodies_only: true,
    });
}

#[test]
fn world_of_bodies_in_full_passes_with_a_margin_is_the_same_at_every_thread_count() {
    same_at_every_thread_count(World {
        seed: 5,
        start: BODY_START,
        placement: Placement::Loose,
        passes: Passes::Full,
        margin: 0.05,
        bodies_only: true,
    });
}

/// Forwards to the system allocator and counts allocations.
struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every method forwards to `System` with the caller's arguments unchanged, so
// `System`'s guarantees carry over; the counter is a plain atomic and never affects memory.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: forwarded as is (see the impl's comment).
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded as is.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: forwarded as is.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: forwarded as is.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The counter is process-wide: the test that reads it runs alone.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Spheres of the `gas` world whose allocations are counted: as many as the worlds above,
/// and more.
const GAS_SPHERES: usize = 20_000;

/// Allocations per step of a `gas` world, after a warm-up, stepped in a
/// pool of `threads` (from inside it) or, with `None`, from outside the global pool.
fn allocations_per_step(threads: Option<usize>) -> Vec<usize> {
    let run = || {
        let mut gas = Gas::new(GAS_SPHERES, 7);
        let mut bp = BroadPhase::new(Config {
            ..Config::default()
        });
        let (mut feed, mut frame, mut spawns) = (Feed::new(false), Frame::default(), Vec::new());
        gas.spawns(&mut spawns);
        feed.spawn(&mut bp, &spawns).expect("finite scene");
        for _ in 0..40 {
            gas.advance(&mut frame);
            feed.apply(&mut bp, &frame).expect("valid frame");
            bp.step();
        }
        let mut counts = Vec::with_capacity(200);
        for _ in 0..200 {
            gas.advance(&mut frame);
            let before = ALLOCATIONS.load(Ordering::Relaxed);
            feed.apply(&mut bp, &frame).expect("valid frame");
            bp.step();
            counts.push(ALLOCATIONS.load(Ordering::Relaxed) - before);
        }
        counts
    };
    match threads {
        Some(t) => rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .expect("a thread pool")
            .install(run),
        None => run(),
    }
}

/// One thread allocates nothing per step in steady state; more threads, stepped from inside
/// their pool, next to nothing (a per-task list reaching a new peak grows ahead of it); from
/// outside the pool, about one allocation per 63 steps more (rayon queues the step's job, and
/// its queue takes a new block of 63 jobs now and then).
#[test]
fn steady_steps_allocate_next_to_nothing_at_any_thread_count() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let total = |t| allocations_per_step(t).iter().sum::<usize>();
    assert_eq!(total(Some(1)), 0, "one thread");
    for t in [2, 3] {
        let n = total(Some(t));
        assert!(n <= 4, "{t} threads: {n} allocations in 200 steps");
    }
    let n = total(None);
    assert!(
        n <= 200 / 63 + 1 + 4,
        "outside the pool: {n} allocations in 200 steps"
    );
}
