//! Times one scene step for profiling: `cargo run --release --example profile_step --
//! --scene gas|clustered|churn|idle|sparse --n 100000 --steps 30 --depth D --what octree|broadphase|feed`.
//!
//! Runs 5 warm-up steps, then `--steps` measured ones, and prints the median ns/object/step,
//! the pair count of the last step and (for `octree`) the tree's stats. Each step advances the
//! scene by `DT`, applies every sphere's new centre and collects the pairs; with `octree` the
//! pairs are `Octree::pairs_into` (unsorted), with `broadphase` the whole `BroadPhase::step`
//! (sorted list plus added / removed). `feed` runs the scene's frames (with `churn`'s removes
//! and inserts) through `scene::Feed` into a `BroadPhase`, as `vs_rapier` does, and times
//! only `Feed::apply` and `BroadPhase::step`, not the scene's motion (`idle`, `--what feed`
//! only: the `gas` spheres at rest but for `--moving P` % of them; `sparse`, `--what feed` only:
//! `gas` spread over 1 km × 40 m × 1 km). `batch` times the same
//! motion fed four ways, each into a fresh `BroadPhase`: one `update_spheres` batch per step,
//! one `update_sphere` call per sphere, and `Feed::apply` batched and per object; for each
//! it prints the median ns/object of the moves alone and of the moves plus `step()` (the
//! batch is built from the scene untimed; `Feed::apply` builds its own, timed). The placement defaults
//! to `Config::default()`'s, the depth to `depth_for` (strict) or `depth_for_loose` (loose). Under callgrind,
//! `--toggle-collect=*measured*` counts only the measured steps.

use broadleaf::fixtures::cli::{self, Flags, Stop};
use broadleaf::fixtures::scene::{Churn, DT, Feed, Frame, Gas, Idle, Scene};
use broadleaf::octree::{MAX_DEPTH, Octree, Placement};
use broadleaf::{BroadPhase, Config, Pair, Passes, ProxyKey, Vec3};
use std::hint::black_box;
use std::time::Instant;

const WARMUP: usize = 5;

const USAGE: &str = "\
usage: profile_step [--scene gas|clustered|churn|idle|sparse] [--n N] [--steps S] [--depth D]
                    [--what octree|broadphase|feed|batch] [--placement strict|loose]
                    [--moving P] [--passes adaptive|full|incremental]
  --scene S      the scene (default gas; idle only with --what feed)
  --n N          spheres (default 100000)
  --steps S      measured steps after 5 warm-up ones (default 30)
  --depth D      the octree's depth (default: depth_for / depth_for_loose of the scene)
  --what W       what to time (default octree; see the file's docs)
  --placement P  the octree's placement (default: Config::default()'s)
  --moving P     idle: the percentage of spheres that move (default 10)
  --passes P     feed: `Config::passes` (default adaptive)";

struct Args {
    scene: &'static str,
    n: usize,
    steps: usize,
    depth: Option<u32>,
    what: &'static str,
    placement: Placement,
    moving: f64,
    passes: Passes,
}

fn parse(argv: impl IntoIterator<Item = String>) -> Result<Args, Stop> {
    let mut a = Args {
        scene: "gas",
        n: 100_000,
        steps: 30,
        depth: None,
        what: "octree",
        placement: Config::default().octree_placement,
        moving: 10.0,
        passes: Passes::Adaptive,
    };
    let mut flags = Flags::new(argv);
    while let Some(flag) = flags.next_flag()? {
        match flag.as_str() {
            "--scene" => {
                let scenes = ["gas", "clustered", "churn", "idle", "sparse"].map(|s| (s, s));
                a.scene = flags.choice(&flag, &scenes)?;
            }
            "--n" => a.n = flags.parse(&flag)?,
            "--moving" => {
                a.moving = flags.parse(&flag)?;
                if !(0.0..=100.0).contains(&a.moving) {
                    return Err(Stop::Error(format!("--moving {}: 0 to 100", a.moving)));
                }
            }
            "--steps" => a.steps = flags.parse(&flag)?,
            "--depth" => {
                let depth: u32 = flags.parse(&flag)?;
                if depth > MAX_DEPTH {
                    return Err(Stop::Error(format!("--depth {depth}: at most {MAX_DEPTH}")));
                }
                a.depth = Some(depth);
            }
            "--what" => {
                let whats = ["octree", "broadphase", "feed", "batch"].map(|w| (w, w));
                a.what = flags.choice(&flag, &whats)?;
            }
            "--placement" => {
                let placements = [("strict", Placement::Strict), ("loose", Placement::Loose)];
                a.placement = flags.choice(&flag, &placements)?;
            }
            "--passes" => a.passes = flags.choice(&flag, &cli::PASSES)?,
            _ => return Err(Stop::unknown(&flag)),
        }
    }
    if (a.scene == "idle" || a.scene == "sparse") && a.what != "feed" {
        return Err(Stop::Error(format!(
            "--scene {}: only with --what feed",
            a.scene
        )));
    }
    Ok(a)
}

/// One measured step; a separate function so callgrind can toggle collection on it.
#[inline(never)]
fn measured_step(run: &mut dyn FnMut() -> usize) -> usize {
    run()
}

fn main() {
    let args = cli::or_exit(USAGE, parse(std::env::args().skip(1)));
    let mut gas = match args.scene {
        "clustered" => Gas::clustered(args.n, 1),
        _ => Gas::new(args.n, 1),
    };
    let depth = args
        .depth
        .unwrap_or_else(|| args.placement.depth_for(&gas.bounds, gas.radius));
    let n = gas.len();
    let mut times = Vec::with_capacity(args.steps);
    let mut pair_count = 0;
    let mut time = |run: &mut dyn FnMut() -> usize| {
        for i in 0..WARMUP + args.steps {
            let t = Instant::now();
            pair_count = black_box(measured_step(run));
            if i >= WARMUP {
                times.push(t.elapsed().as_nanos() as f64 / n as f64);
            }
        }
    };
    let mut stats = None;
    match args.what {
        "octree" => {
            let mut tree = Octree::with_placement(gas.bounds, depth, args.placement)
                .expect("scene bounds are valid");
            let keys: Vec<ProxyKey> = gas
                .centers
                .iter()
                .map(|&c| tree.insert(c, gas.radius).expect("valid sphere"))
                .collect();
            let mut pairs: Vec<Pair> = Vec::new();
            time(&mut || {
                gas.step(DT);
                for (&k, &c) in keys.iter().zip(&gas.centers) {
                    tree.update(k, c, gas.radius).expect("live key");
                }
                pairs.clear();
                tree.pairs_into(&mut pairs);
                pairs.len()
            });
            stats = Some(tree.stats());
        }
        "broadphase" => {
            let mut bp = BroadPhase::new(Config {
                octree_placement: args.placement,
                ..Config::default()
            });
            let keys: Vec<ProxyKey> = gas
                .centers
                .iter()
                .map(|&c| bp.insert_sphere(c, gas.radius).expect("valid sphere"))
                .collect();
            time(&mut || {
                gas.step(DT);
                for (&k, &c) in keys.iter().zip(&gas.centers) {
                    bp.update_sphere(k, c, gas.radius).expect("live key");
                }
                bp.step();
                black_box((bp.added().len(), bp.removed().len()));
                bp.pairs().len()
            });
        }
        "feed" => {
            let mut scene: Box<dyn Scene> = match args.scene {
                "churn" => Box::new(Churn::new(args.n, 1)),
                "idle" => Box::new(Idle::new(args.n, 1, args.moving)),
                "sparse" => Box::new(Gas::sparse(args.n, 1)),
                _ => Box::new(gas.clone()),
            };
            let mut bp = BroadPhase::new(Config {
                octree_placement: args.placement,
                passes: args.passes,
                ..Config::default()
            });
            let (mut feed, mut spawns, mut frame) =
                (Feed::new(false), Vec::new(), Frame::default());
            // `BROADLEAF_TRACE=1` prints every step's time and `StepStats` on stderr.
            let trace = std::env::var_os("BROADLEAF_TRACE").is_some();
            scene.spawns(&mut spawns);
            feed.spawn(&mut bp, &spawns).expect("valid scene");
            for i in 0..WARMUP + args.steps {
                scene.advance(&mut frame);
                let t = Instant::now();
                pair_count = black_box(measured_step(&mut || {
                    feed.apply(&mut bp, &frame).expect("valid frame");
                    bp.step();
                    bp.pairs().len()
                }));
                let ns = t.elapsed().as_nanos() as f64 / n as f64;
                if i >= WARMUP {
                    times.push(ns);
                }
                if trace {
                    eprintln!("{i}: {ns:.1} ns/object {:?}", bp.stats());
                }
            }
            println!(
                "memory: {:.1} heap bytes per proxy ({} proxies), last step {:?}",
                bp.heap_bytes() as f64 / bp.len().max(1) as f64,
                bp.len(),
                bp.stats()
            );
            stats = Some(bp.octree().stats());
        }
        _ => {
            for way in [Way::Batch, Way::PerCall, Way::FeedBatch, Way::FeedPerCall] {
                let (apply, total) = time_feeding(&gas, way, args.steps);
                println!(
                    "scene={} n={n} what=batch way={way:?} steps={} median_apply_ns_per_object={apply:.1} median_apply_step_ns_per_object={total:.1}",
                    args.scene, args.steps
                );
            }
            return;
        }
    }
    times.sort_by(f64::total_cmp);
    let median = times.get(times.len() / 2).copied().unwrap_or(f64::NAN);
    println!(
        "scene={} n={n} placement={:?} depth={depth} what={} steps={} median_ns_per_object_step={median:.1} pairs={pair_count}",
        args.scene, args.placement, args.what, args.steps
    );
    if let Some(s) = stats {
        println!(
            "aabb_tests_per_object={:.2} nodes_visited={} per_level={:?} overflow={}",
            s.aabb_tests as f64 / n as f64,
            s.nodes_visited,
            s.per_level,
            s.overflow
        );
    }
}

/// How `--what batch` feeds a step's moves to the broadphase.
#[derive(Clone, Copy, Debug)]
enum Way {
    /// One `update_spheres` call with every sphere.
    Batch,
    /// One `update_sphere` call per sphere.
    PerCall,
    /// `Feed::apply` (one `update_spheres` batch).
    FeedBatch,
    /// `Feed::apply` with `Feed::per_object`.
    FeedPerCall,
}

/// Runs `gas`'s motion (a copy) into a fresh default `BroadPhase`, fed `way`; the medians of
/// ns/object for the moves alone and for the moves plus `step()`.
fn time_feeding(gas: &Gas, way: Way, steps: usize) -> (f64, f64) {
    let mut gas = gas.clone();
    let n = gas.len().max(1) as f64;
    let mut bp = BroadPhase::new(Config {
        ..Config::default()
    });
    let per_object = matches!(way, Way::FeedPerCall);
    let (mut feed, mut spawns, mut frame) = (
        Feed::new(false).per_object(per_object),
        Vec::new(),
        Frame::default(),
    );
    gas.spawns(&mut spawns);
    feed.spawn(&mut bp, &spawns).expect("valid scene");
    bp.step();
    let mut batch: Vec<(ProxyKey, Vec3, f32)> = Vec::with_capacity(gas.len());
    let (mut apply, mut total) = (Vec::new(), Vec::new());
    for i in 0..WARMUP + steps {
        gas.advance(&mut frame);
        batch.clear();
        batch.extend(frame.moved.iter().map(|&(id, o)| {
            let key = feed.key(id).expect("live id");
            (key, o.center(), gas.radius)
        }));
        let t = Instant::now();
        match way {
            Way::Batch => bp.update_spheres(&batch).expect("valid batch"),
            Way::PerCall => {
                for &(k, c, r) in &batch {
                    bp.update_sphere(k, c, r).expect("valid sphere");
                }
            }
            Way::FeedBatch | Way::FeedPerCall => feed.apply(&mut bp, &frame).expect("valid frame"),
        }
        let moved = t.elapsed();
        bp.step();
        black_box(bp.pairs().len());
        let stepped = t.elapsed();
        if i >= WARMUP {
            apply.push(moved.as_nanos() as f64 / n);
            total.push(stepped.as_nanos() as f64 / n);
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
    };
    (median(&mut apply), median(&mut total))
}
