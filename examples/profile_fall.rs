//! Replays the `fall` scene for profiling: `cargo run --release --features fixtures,rapier
//! --example profile_fall -- --frames PATH [--n 4000] [--every] [--passes P] [--from K]
//! [--to K]`.
//!
//! Records rapier's drop (as `vs_rapier --scene fall` does) once and saves it to `--frames`
//! (walls, radius, rapier's broad-phase time and each frame's changed balls); later runs read
//! it back with or without the feature, so a run under callgrind replays it without stepping
//! rapier. Each frame is one `update_centers` batch (built before the measured call) and a
//! step; frame 0 inserts the balls. Prints broadleaf's and rapier's mean ns/object/step over
//! the frames `--from..--to` and over the phases. Under callgrind,
//! `--toggle-collect=*measured*` counts only the frames `--from..--to`.

use broadleaf::fixtures::cli::{self, Flags, Stop};
use broadleaf::fixtures::scene::CentersFeed;
use broadleaf::{Aabb, BodyKind, BroadPhase, Config, Passes, Vec3};
use std::time::Instant;

const USAGE: &str = "usage: profile_fall --frames PATH [--n 4000] [--every] [--passes adaptive|full|incremental] [--from K] [--to K]";

struct Args {
    frames: String,
    n: usize,
    every: bool,
    passes: Passes,
    from: usize,
    to: usize,
}

fn parse(args: impl Iterator<Item = String>) -> Result<Args, Stop> {
    let mut a = Args {
        frames: String::new(),
        n: 4000,
        every: false,
        passes: Passes::Adaptive,
        from: 0,
        to: usize::MAX,
    };
    let mut flags = Flags::new(args);
    while let Some(flag) = flags.next_flag()? {
        match flag.as_str() {
            "--frames" => a.frames = flags.value(&flag)?,
            "--n" => a.n = flags.parse(&flag)?,
            "--every" => a.every = true,
            "--passes" => a.passes = flags.choice(&flag, &cli::PASSES)?,
            "--from" => a.from = flags.parse(&flag)?,
            "--to" => a.to = flags.parse(&flag)?,
            _ => return Err(Stop::unknown(&flag)),
        }
    }
    if a.frames.is_empty() {
        return Err(Stop::Error("--frames is required".into()));
    }
    Ok(a)
}

/// A recorded drop: walls, radius, and per frame rapier's time (ns), the changed balls' ids
/// and centres.
struct Drop {
    walls: Vec<Aabb>,
    radius: f32,
    balls: usize,
    rapier_ns: Vec<f64>,
    frames: Vec<(Vec<u32>, Vec<Vec3>)>,
    /// The first frame of the settling phase.
    settle: usize,
}

fn save(path: &str, d: &Drop) -> std::io::Result<()> {
    let mut w: Vec<u32> = vec![d.walls.len() as u32, d.balls as u32, d.frames.len() as u32];
    w.push(d.settle as u32);
    w.push(d.radius.to_bits());
    for b in &d.walls {
        w.extend(b.min.to_array().map(f32::to_bits));
        w.extend(b.max.to_array().map(f32::to_bits));
    }
    for (k, (ids, cs)) in d.frames.iter().enumerate() {
        w.push((d.rapier_ns[k] as f32).to_bits());
        w.push(ids.len() as u32);
        w.extend(ids);
        w.extend(cs.iter().flat_map(|c| c.to_array().map(f32::to_bits)));
    }
    cli::write_words(path, &w)
}

fn load(path: &str) -> Option<Drop> {
    let mut it = cli::read_words(path)?.into_iter();
    let (walls, balls, frames, settle) = (
        it.next()? as usize,
        it.next()? as usize,
        it.next()? as usize,
        it.next()? as usize,
    );
    let radius = f32::from_bits(it.next()?);
    let vec3 = |it: &mut dyn Iterator<Item = u32>| {
        let mut c = [0.0f32; 3];
        for x in &mut c {
            *x = f32::from_bits(it.next()?);
        }
        Some(Vec3::from_array(c))
    };
    let mut d = Drop {
        walls: Vec::new(),
        radius,
        balls,
        rapier_ns: Vec::new(),
        frames: Vec::new(),
        settle,
    };
    for _ in 0..walls {
        let (lo, hi) = (vec3(&mut it)?, vec3(&mut it)?);
        d.walls.push(Aabb::new(lo, hi));
    }
    for _ in 0..frames {
        d.rapier_ns.push(f32::from_bits(it.next()?) as f64);
        let m = it.next()? as usize;
        let ids: Vec<u32> = (0..m).map(|_| it.next()).collect::<Option<_>>()?;
        let cs = (0..m)
            .map(|_| vec3(&mut it))
            .collect::<Option<Vec<Vec3>>>()?;
        d.frames.push((ids, cs));
    }
    Some(d)
}

#[cfg(feature = "rapier")]
fn record(n: usize) -> Option<Drop> {
    use broadleaf::fixtures::rapier_world::{fall_steps, record_fall};
    use broadleaf::fixtures::sim::DropConfig;
    let rec = record_fall(&DropConfig::new(n, 0.5, 1), fall_steps(n)).ok()?;
    let settle = rec
        .phases()
        .rows()
        .iter()
        .find(|(name, _)| *name == "settling")
        .map_or(0, |(_, r)| r.start);
    Some(Drop {
        walls: rec.walls.clone(),
        radius: rec.radius,
        balls: rec.balls(),
        rapier_ns: rec
            .broad_phase_time
            .iter()
            .map(|t| t.as_nanos() as f64)
            .collect(),
        frames: (0..rec.frames())
            .map(|k| {
                let (i, c) = rec.changed(k);
                (i.to_vec(), c.to_vec())
            })
            .collect(),
        settle,
    })
}

#[cfg(not(feature = "rapier"))]
fn record(_: usize) -> Option<Drop> {
    None
}

/// One frame: the staged batch, then the step.
#[inline(always)]
fn frame(bp: &mut BroadPhase, feed: &CentersFeed) {
    feed.commit(bp).expect("valid batch");
    bp.step();
}

/// [`frame`] for the measured frames; a separate function so callgrind can toggle collection
/// on it.
#[inline(never)]
fn measured_frame(bp: &mut BroadPhase, feed: &CentersFeed) {
    frame(bp, feed);
}

fn main() {
    let args = cli::or_exit(USAGE, parse(std::env::args().skip(1)));
    let d = cli::frames_or_exit(&args.frames, load, || record(args.n), save);
    let mut bp = BroadPhase::new(Config {
        passes: args.passes,
        ..Config::default()
    });
    for &w in &d.walls {
        bp.insert_body(w, BodyKind::Static).expect("finite walls");
    }
    let objects = (d.balls + d.walls.len()) as f64;
    let mut feed = CentersFeed::default();
    let mut ns = Vec::with_capacity(d.frames.len());
    let trace = std::env::var_os("BROADLEAF_TRACE").is_some();
    for (k, (ids, cs)) in d.frames.iter().enumerate() {
        if k == 0 {
            feed.stage_first(cs);
        } else {
            feed.stage(ids, cs, args.every);
        }
        let t = Instant::now();
        if k == 0 {
            feed.insert(&mut bp, d.radius).expect("finite balls");
            bp.step();
        } else if (args.from..args.to).contains(&k) {
            measured_frame(&mut bp, &feed);
        } else {
            frame(&mut bp, &feed);
        }
        ns.push(t.elapsed().as_nanos() as f64 / objects);
        if trace {
            eprintln!("{k}: {:.1} ns/object {:?}", ns[k], bp.stats());
        }
    }
    let mean = |r: std::ops::Range<usize>, v: &[f64]| {
        let r = r.start.min(v.len())..r.end.min(v.len());
        v[r.clone()].iter().sum::<f64>() / r.len().max(1) as f64
    };
    let rapier: Vec<f64> = d.rapier_ns.iter().map(|t| t / objects).collect();
    let n = d.frames.len();
    for (name, r) in [
        ("falling", 0..d.settle),
        ("settling", d.settle..n),
        ("whole", 0..n),
        ("measured", args.from..args.to.min(n)),
    ] {
        let (a, b) = (mean(r.clone(), &ns), mean(r.clone(), &rapier));
        println!(
            "{name:9} frames {:4}..{:4}  broadleaf {a:7.1}  rapier {b:7.1}  x{:.2}",
            r.start,
            r.end,
            b / a
        );
    }
}
