//! No allocation per step in steady state, and no memory growth under churn, measured with a
//! counting global allocator (this test binary only; the library itself has no `unsafe`).

use broadleaf::fixtures::scene::{Churn, Feed, Frame, Gas, Scene};
use broadleaf::{BroadPhase, Config, Pass, Passes, Placement};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::Mutex;
use std::sync::atomic::{AtomicIsize, AtomicUsize, Ordering};

/// Forwards to the system allocator and counts allocations and live bytes.
struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);
static LIVE_BYTES: AtomicIsize = AtomicIsize::new(0);

// SAFETY: every method forwards to `System` with the caller's arguments unchanged, so
// `System`'s guarantees carry over; the counters are plain atomics and never affect memory.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        LIVE_BYTES.fetch_add(layout.size() as isize, Ordering::Relaxed);
        // SAFETY: forwarded as is (see the impl's comment).
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE_BYTES.fetch_sub(layout.size() as isize, Ordering::Relaxed);
        // SAFETY: forwarded as is.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        LIVE_BYTES.fetch_add(layout.size() as isize, Ordering::Relaxed);
        // SAFETY: forwarded as is.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        LIVE_BYTES.fetch_add(
            new_size as isize - layout.size() as isize,
            Ordering::Relaxed,
        );
        // SAFETY: forwarded as is.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The counters are process-wide: tests that read them must not overlap.
static SERIAL: Mutex<()> = Mutex::new(());

fn setup(scene: &impl Scene, placement: Placement) -> (BroadPhase, Feed) {
    setup_with_skin(scene, placement, 0.0)
}

/// With a `skin`, the incremental pass is forced (fat boxes of that fixed margin); without,
/// the passes are adaptive.
fn setup_with_skin(scene: &impl Scene, placement: Placement, skin: f32) -> (BroadPhase, Feed) {
    let bounds = scene.bounds();
    let mut bp = BroadPhase::new(Config {
        bounds: Some(bounds),
        octree_placement: placement,
        skin,
        passes: if skin > 0.0 {
            Passes::Incremental
        } else {
            Passes::Adaptive
        },
        ..Config::default()
    });
    let mut feed = Feed::new(false);
    let mut spawns = Vec::new();
    scene.spawns(&mut spawns);
    feed.spawn(&mut bp, &spawns).expect("finite scene");
    (bp, feed)
}

#[test]
fn steady_gas_steps_allocate_nothing() {
    steady_gas(Placement::Strict);
}

#[test]
fn steady_gas_steps_allocate_nothing_in_a_loose_octree() {
    steady_gas(Placement::Loose);
}

/// The incremental pass, forced, on gas: most spheres leave their fat boxes within a few
/// steps, so many candidates are found anew each step.
#[test]
fn steady_incremental_steps_allocate_nothing() {
    steady_gas_with(Placement::Strict, 0.1, 1.0);
}

/// The incremental pass, forced, on slow gas: a few spheres leave their fat boxes each step,
/// so the candidate list changes a little every step.
#[test]
fn steady_slow_incremental_steps_allocate_nothing() {
    steady_gas_with(Placement::Loose, 0.05, 0.02);
}

fn steady_gas(placement: Placement) {
    steady_gas_with(placement, 0.0, 1.0);
}

/// `speed` scales the gas's velocities. With the feature `parallel` the steps run on a
/// one-thread pool: the promise is none on one thread (see `steady_parallel_steps_allocate_a_bounded_number`
/// for more threads).
fn steady_gas_with(placement: Placement, skin: f32, speed: f32) {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let counts = on_threads(1, || steady_counts(placement, skin, speed));
    assert!(
        counts.iter().all(|&c| c == 0),
        "allocations per step after warm-up: {counts:?}"
    );
}

/// Runs `f` on a pool of `threads` threads with the feature `parallel`, else on this thread.
fn on_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    #[cfg(feature = "parallel")]
    {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a thread pool")
            .install(f)
    }
    #[cfg(not(feature = "parallel"))]
    {
        let _ = threads;
        f()
    }
}

/// With threads, a parallel step hands tasks to the pool: rayon may allocate for them, a
/// number per step bounded by the tasks, not by the world's size.
#[cfg(feature = "parallel")]
#[test]
fn steady_parallel_steps_allocate_a_bounded_number() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let counts = on_threads(2, || steady_counts(Placement::Loose, 0.0, 1.0));
    assert!(
        counts.iter().all(|&c| c <= MAX_PARALLEL_ALLOCATIONS),
        "allocations per step after warm-up: {counts:?}"
    );
}

/// The bound the crate docs state for a parallel step's allocations.
#[cfg(feature = "parallel")]
const MAX_PARALLEL_ALLOCATIONS: usize = 64;

/// Allocations in each of 60 steady steps of a 10k gas after its warm-up.
fn steady_counts(placement: Placement, skin: f32, speed: f32) -> Vec<usize> {
    let mut gas = Gas::new(10_000, 7);
    for v in &mut gas.velocities {
        *v *= speed;
    }
    let (mut bp, mut feed) = setup_with_skin(&gas, placement, skin);
    let mut frame = Frame::default();
    // Warm-up: buffers reach their working sizes (and the frame its capacity). The incremental
    // pass's lists take longer: how many proxies leave their fat boxes, and so how many
    // candidates are found anew, varies from step to step, and its peaks come later.
    let warmup = if skin > 0.0 { 150 } else { 30 };
    for _ in 0..warmup {
        gas.advance(&mut frame);
        feed.apply(&mut bp, &frame).unwrap();
        bp.step();
    }
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    let probe: Vec<u64> = std::hint::black_box(Vec::with_capacity(16));
    assert_eq!(
        ALLOCATIONS.load(Ordering::Relaxed),
        before + 1,
        "the counter counts"
    );
    drop(probe);
    let mut counts = Vec::with_capacity(60);
    for _ in 0..60 {
        gas.advance(&mut frame);
        let before = ALLOCATIONS.load(Ordering::Relaxed);
        feed.apply(&mut bp, &frame).unwrap();
        bp.step();
        counts.push(ALLOCATIONS.load(Ordering::Relaxed) - before);
        assert!(!bp.pairs().is_empty());
        if skin > 0.0 {
            assert_eq!(bp.stats().pass, Pass::Incremental);
        }
    }
    counts
}

#[test]
fn churn_does_not_grow_memory() {
    churn_memory(Placement::Strict);
}

#[test]
fn churn_does_not_grow_memory_in_a_loose_octree() {
    churn_memory(Placement::Loose);
}

fn churn_memory(placement: Placement) {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let mut churn = Churn::new(10_000, 3);
    let (mut bp, mut feed) = setup(&churn, placement);
    let mut frame = Frame::default();
    let mut live_at = Vec::new();
    for step in 0..200 {
        churn.advance(&mut frame);
        feed.apply(&mut bp, &frame).unwrap();
        bp.step();
        if step % 25 == 24 {
            live_at.push(LIVE_BYTES.load(Ordering::Relaxed));
        }
    }
    // After the first 50 steps every buffer has its working size; churn (1 % removed and
    // inserted per step) then reuses slots and capacity. Allow 5 % for capacity that grows
    // to a new peak pair count.
    let settled = live_at[1];
    let last = *live_at.last().unwrap();
    assert!(
        (last as f64) <= settled as f64 * 1.05,
        "live bytes every 25 steps: {live_at:?}"
    );
}
