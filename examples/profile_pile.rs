//! Replays the `pile` scene for profiling: `cargo run --release --features fixtures,rapier
//! --example profile_pile -- --frames PATH [--n 10000] [--steps 35] [--passes P]`.
//!
//! The scene is `vs_rapier`'s `pile`: `n` spheres settled by 240 dynamic rapier steps (seed 1),
//! then `--steps` recorded frames (`--centers`: the spheres sent by `update_centers`, else by
//! `update_spheres`). Recording needs the feature `rapier`; the frames are saved
//! to `--frames` and read back from there by later runs (with or without the feature), so a run
//! under callgrind replays them without stepping rapier. Runs 5 warm-up frames, then the rest,
//! each fed as one batch (built before the timer) and one `BroadPhase::step`, and prints the
//! median ns/object/step. Under callgrind, `--toggle-collect=*measured*` counts only the measured
//! steps.

use broadleaf::fixtures::cli::{self, Flags, Stop};
use broadleaf::fixtures::scene::{Feed, Frame, Recorded, Scene};
use broadleaf::{Aabb, BroadPhase, Config, Passes, Vec3};
use std::hint::black_box;
use std::time::Instant;

const WARMUP: usize = 5;
/// Unrecorded rapier steps that let the pile settle, as `vs_rapier` runs it.
#[cfg(feature = "rapier")]
const SETTLE_STEPS: usize = 240;

const USAGE: &str = "usage: profile_pile --frames PATH [--n 10000] [--steps 35] [--passes adaptive|full|incremental] [--centers]";

struct Args {
    frames: String,
    n: usize,
    steps: usize,
    passes: Passes,
    centers: bool,
}

fn parse(argv: impl IntoIterator<Item = String>) -> Result<Args, Stop> {
    let mut a = Args {
        frames: String::new(),
        n: 10_000,
        steps: 35,
        passes: Passes::Adaptive,
        centers: false,
    };
    let mut flags = Flags::new(argv);
    while let Some(flag) = flags.next_flag()? {
        match flag.as_str() {
            "--frames" => a.frames = flags.value(&flag)?,
            "--n" => a.n = flags.parse(&flag)?,
            "--steps" => a.steps = flags.parse(&flag)?,
            "--passes" => a.passes = flags.choice(&flag, &cli::PASSES)?,
            "--centers" => a.centers = true,
            _ => return Err(Stop::unknown(&flag)),
        }
    }
    if a.frames.is_empty() {
        return Err(Stop::Error("--frames is required".into()));
    }
    Ok(a)
}

/// The frames saved at `path` (bounds, radius, then each frame's centres, as little-endian
/// `f32`s behind a header of counts), if the file is there.
fn load(path: &str) -> Option<Recorded> {
    let mut words = cli::read_words(path)?.into_iter();
    let (frames, n) = (words.next()? as usize, words.next()? as usize);
    let mut f = || words.next().map(f32::from_bits);
    let v = |f: &mut dyn FnMut() -> Option<f32>| Some(Vec3::new(f()?, f()?, f()?));
    let bounds = Aabb::new(v(&mut f)?, v(&mut f)?);
    let radius = f()?;
    let mut all = Vec::with_capacity(frames);
    for _ in 0..frames {
        all.push((0..n).map(|_| v(&mut f)).collect::<Option<Vec<Vec3>>>()?);
    }
    Some(Recorded::new(bounds, radius, all))
}

fn save(path: &str, r: &Recorded) -> std::io::Result<()> {
    let n = r.frames.first().map_or(0, Vec::len);
    let mut out: Vec<u32> = vec![r.frames.len() as u32, n as u32];
    for v in [r.bounds.min, r.bounds.max] {
        out.extend(v.to_array().map(f32::to_bits));
    }
    out.push(r.radius.to_bits());
    for f in &r.frames {
        out.extend(f.iter().flat_map(|c| c.to_array().map(f32::to_bits)));
    }
    cli::write_words(path, &out)
}

#[cfg(feature = "rapier")]
fn record(args: &Args) -> Option<Recorded> {
    Some(broadleaf::fixtures::rapier_world::record_pile(
        args.n,
        1,
        SETTLE_STEPS,
        WARMUP + args.steps + 1,
    ))
}

#[cfg(not(feature = "rapier"))]
fn record(_: &Args) -> Option<Recorded> {
    None
}

/// One measured step; a separate function so callgrind can toggle collection on it.
#[inline(never)]
fn measured_step(run: &mut dyn FnMut() -> usize) -> usize {
    run()
}

fn main() {
    let args = cli::or_exit(USAGE, parse(std::env::args().skip(1)));
    let mut scene = cli::frames_or_exit(&args.frames, load, || record(&args), save);
    let mut bp = BroadPhase::new(Config {
        passes: args.passes,
        ..Config::default()
    });
    let mut feed = Feed::new(false).centers(args.centers);
    let (mut spawns, mut frame) = (Vec::new(), Frame::default());
    scene.spawns(&mut spawns);
    feed.spawn(&mut bp, &spawns).expect("valid scene");
    bp.step();
    let n = scene.len().max(1) as f64;
    let (mut times, mut tested, mut escaped, mut pairs) = (Vec::new(), 0usize, 0usize, 0usize);
    for i in 0..scene.frames.len().saturating_sub(1) {
        scene.advance(&mut frame);
        feed.stage(&frame).expect("valid frame");
        let t = Instant::now();
        pairs = black_box(measured_step(&mut || {
            feed.commit(&mut bp, &frame).expect("valid frame");
            bp.step();
            bp.pairs().len()
        }));
        if i >= WARMUP {
            times.push(t.elapsed().as_nanos() as f64 / n);
            tested += bp.stats().candidates_tested;
            escaped += bp.stats().escaped;
        }
    }
    times.sort_by(f64::total_cmp);
    let median = times.get(times.len() / 2).copied().unwrap_or(f64::NAN);
    println!(
        "pile n={} steps={} median_ns_per_object_step={median:.1} pairs={pairs} tested_per_step={:.0} escaped_per_step={:.1} last {:?}",
        scene.len(),
        times.len(),
        tested as f64 / times.len().max(1) as f64,
        escaped as f64 / times.len().max(1) as f64,
        bp.stats().pass
    );
}
