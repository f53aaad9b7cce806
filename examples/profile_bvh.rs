//! A small driver for profiling the BVH under callgrind or a wall clock.
//!
//! `cargo run --release --example profile_bvh -- --what build --n 1000000 --steps 5`
//! rebuilds a SAH tree over `n` random boxes (the `bodies` box distribution) `steps` times and
//! prints the median build time. Each rebuild after the first starts from the tree order of
//! the one before (the boxes did not move, so no box changes place); `--shuffle true` hands
//! the keys a random permutation of the boxes before each rebuild (untimed), so every timed
//! rebuild starts from random order, as a first build does. `--what first` times
//! `Bvh::from_aabbs` itself (a new tree: `n` inserts, then the first build from the boxes'
//! random order) `steps` times. `--what step` runs the `bodies` scene through a
//! `BroadPhase` (spawn, then per step `Feed::apply` + `BroadPhase::step`) and prints the
//! median ns/object/step, the pair count and the dynamic tree's shape (`--moving P`: only P % of
//! the dynamic boxes move, as `vs_rapier --moving`). `--warmup W` steps are run (and not timed)
//! first.

use broadleaf::bvh::{Bvh, BvhConfig};
use broadleaf::fixtures::cli::{self, Flags, Stop};
use broadleaf::fixtures::scene::{Bodies, Feed, Frame, Rng, Scene};
use broadleaf::{Aabb, BroadPhase, Config};
use std::time::Instant;

const USAGE: &str = "\
usage: profile_bvh [--what build|first|step|pairs] [--n N] [--steps S] [--warmup W]
                   [--trav C] [--leaf L] [--shuffle true|false] [--moving P]
  --what W       what to time (default step; see the file's docs)
  --n N          boxes (default 10000)
  --steps S      timed repetitions (default 30)
  --warmup W     untimed steps first, for step and pairs (default 5)
  --trav C       BvhConfig::traversal_cost of the trees built
  --leaf L       BvhConfig::max_leaf_size of the trees built
  --shuffle B    build: hand the keys a random permutation before each rebuild (default false)
  --moving P     step: the percentage of dynamic boxes that move (default 100)";

struct Args {
    n: usize,
    steps: usize,
    warmup: usize,
    what: &'static str,
    shuffle: bool,
    moving: f64,
    config: BvhConfig,
}

fn parse(argv: impl IntoIterator<Item = String>) -> Result<Args, Stop> {
    let mut args = Args {
        n: 10_000,
        steps: 30,
        warmup: 5,
        what: "step",
        shuffle: false,
        moving: 100.0,
        config: BvhConfig::default(),
    };
    let mut flags = Flags::new(argv);
    while let Some(flag) = flags.next_flag()? {
        match flag.as_str() {
            "--n" => args.n = flags.parse(&flag)?,
            "--steps" => args.steps = flags.parse(&flag)?,
            "--warmup" => args.warmup = flags.parse(&flag)?,
            "--what" => {
                let whats = ["build", "first", "step", "pairs"].map(|w| (w, w));
                args.what = flags.choice(&flag, &whats)?;
            }
            "--trav" => args.config.traversal_cost = flags.parse(&flag)?,
            "--leaf" => args.config.max_leaf_size = flags.parse(&flag)?,
            "--shuffle" => args.shuffle = flags.parse(&flag)?,
            "--moving" => args.moving = flags.parse(&flag)?,
            _ => return Err(Stop::unknown(&flag)),
        }
    }
    // The trees are built with this config: refuse it here rather than in a build.
    Bvh::new(args.config).map_err(|e| Stop::Error(format!("--trav / --leaf: {e}")))?;
    Ok(args)
}

/// Nanoseconds this thread has run on a CPU (Linux `schedstat`), or `None` elsewhere: unlike the
/// wall clock it does not count the time another process held the core.
fn cpu_ns() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    s.split_whitespace().next()?.parse().ok()
}

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs.get(xs.len() / 2).copied().unwrap_or(f64::NAN)
}

fn build(args: &Args) {
    let scene = Bodies::new(args.n, 1);
    let boxes: Vec<Aabb> = scene.dynamic.iter().map(|o| o.aabb()).collect();
    let (mut bvh, keys) = Bvh::from_aabbs(args.config, &boxes).expect("valid boxes");
    let (mut ms, mut cpu_ms) = (Vec::with_capacity(args.steps), Vec::new());
    let mut rng = Rng::new(7);
    let mut order: Vec<usize> = (0..boxes.len()).collect();
    for _ in 0..args.steps {
        if args.shuffle {
            // Hand every key another key's box, so that the tree order of the last build is
            // random in space again (as for a first build) and the rebuild moves every box.
            for i in (1..order.len()).rev() {
                order.swap(i, rng.next_u32() as usize % (i + 1));
            }
            for (&key, &j) in keys.iter().zip(&order) {
                bvh.update(key, boxes[j]).expect("live key");
            }
        }
        let (t, c) = (Instant::now(), cpu_ns());
        bvh.rebuild();
        ms.push(t.elapsed().as_secs_f64() * 1e3);
        if let (Some(c0), Some(c1)) = (c, cpu_ns()) {
            cpu_ms.push((c1 - c0) as f64 * 1e-6);
        }
    }
    let s = bvh.stats();
    println!(
        "build n={}{} median {:.2} ms (min {:.2}, cpu {:.2}) over {} builds; nodes {} leaves {} \
         depth {} cost {:.1}",
        args.n,
        if args.shuffle { " shuffled" } else { "" },
        median(ms.clone()),
        ms.iter().copied().fold(f64::INFINITY, f64::min),
        median(cpu_ms),
        args.steps,
        s.nodes,
        s.leaves,
        s.depth,
        s.cost
    );
}

/// `Bvh::from_aabbs` over the scene's boxes in their random order, timed whole.
fn first(args: &Args) {
    let scene = Bodies::new(args.n, 1);
    let boxes: Vec<Aabb> = scene.dynamic.iter().map(|o| o.aabb()).collect();
    let mut ms = Vec::with_capacity(args.steps);
    let mut cost = 0.0;
    for _ in 0..args.steps {
        let t = Instant::now();
        let (bvh, keys) = Bvh::from_aabbs(args.config, &boxes).expect("valid boxes");
        ms.push(t.elapsed().as_secs_f64() * 1e3);
        cost = bvh.sah_cost();
        drop((bvh, keys));
    }
    println!(
        "first build n={} (from_aabbs: inserts + build) median {:.2} ms (min {:.2}) over {} builds; cost {:.1}",
        args.n,
        median(ms.clone()),
        ms.iter().copied().fold(f64::INFINITY, f64::min),
        args.steps,
        cost
    );
}

fn step(args: &Args) {
    let mut scene = Bodies::with_moving(args.n, 2, args.moving);
    let mut bp = BroadPhase::new(Config {
        ..Config::default()
    });
    let mut feed = Feed::new(false);
    let mut spawns = Vec::new();
    scene.spawns(&mut spawns);
    feed.spawn(&mut bp, &spawns).expect("valid scene");
    let mut frame = Frame::default();
    let objects = scene.len() as f64;
    let mut ns = Vec::with_capacity(args.steps);
    let mut pairs = 0;
    for i in 0..args.warmup + args.steps {
        scene.advance(&mut frame);
        let t = Instant::now();
        feed.apply(&mut bp, &frame).expect("valid frame");
        bp.step();
        pairs = bp.pairs().len();
        let dt = t.elapsed().as_secs_f64();
        if i >= args.warmup {
            ns.push(dt * 1e9 / objects);
        }
    }
    let s = bp.stats();
    println!(
        "step bodies n={} ({} objects) median {:.1} ns/object/step over {} steps; pairs {}",
        args.n,
        scene.len(),
        median(ns),
        args.steps,
        pairs
    );
    println!(
        "last step: {:?}, updated {}, escaped {}, candidates {} (tested {})",
        s.pass, s.updated, s.escaped, s.candidates, s.candidates_tested
    );
}

/// The dynamic boxes of `bodies` in a bare [`Bvh`] (with `--trav` / `--leaf`): per step,
/// update every box, refit, collect the self pairs.
fn pairs(args: &Args) {
    let mut scene = Bodies::new(args.n, 2);
    let boxes: Vec<Aabb> = scene.dynamic.iter().map(|o| o.aabb()).collect();
    let (mut bvh, keys) = Bvh::from_aabbs(args.config, &boxes).expect("valid boxes");
    let mut frame = Frame::default();
    let mut out = Vec::new();
    let mut ns = Vec::with_capacity(args.steps);
    for i in 0..args.warmup + args.steps {
        scene.advance(&mut frame);
        let t = Instant::now();
        for &(id, o) in &frame.moved {
            bvh.update(keys[id as usize], o.aabb()).expect("live key");
        }
        bvh.refit();
        out.clear();
        bvh.for_each_pair(|a, b| out.push((a, b)));
        let dt = t.elapsed().as_secs_f64();
        if i >= args.warmup {
            ns.push(dt * 1e9 / args.n as f64);
        }
    }
    let s = bvh.stats();
    println!(
        "pairs n={} trav {} leaf {}: median {:.1} ns/object/step; pairs {}; nodes {} leaves {} \
         depth {} rebuilds {}",
        args.n,
        args.config.traversal_cost,
        args.config.max_leaf_size,
        median(ns),
        out.len(),
        s.nodes,
        s.leaves,
        s.depth,
        s.rebuilds
    );
}

fn main() {
    let args = cli::or_exit(USAGE, parse(std::env::args().skip(1)));
    match args.what {
        "build" => build(&args),
        "first" => first(&args),
        "step" => step(&args),
        _ => pairs(&args),
    }
}
