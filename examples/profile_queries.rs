//! A small driver for profiling scene queries under callgrind: broadleaf's side of
//! `vs_rapier --queries`, one query kind at a time, no rapier and no checks.
//!
//! `cargo run --release --example profile_queries -- --scene gas --n 20000 --what ray`
//! builds the scene as `vs_rapier --queries` does (`gas` after `--warmup` steps of motion, or
//! `bodies` after one step with every box as its world AABB), then runs `--count` queries of
//! kind `--what` drawn like `vs_rapier`'s (boxes of 1–4 m edge, unit-direction rays and sphere
//! casts of radius 0.25 with `max_t` the scene's edge, nearest points; all uniform in the
//! scene's cube) and prints their hit count and the time per query.

use broadleaf::fixtures::cli::{self, Flags, Stop};
use broadleaf::fixtures::scene::{Bodies, Feed, Frame, Gas, Rng, Scene};
use broadleaf::{Aabb, BroadPhase, Config, Vec3};
use std::hint::black_box;
use std::time::Instant;

const USAGE: &str = "\
usage: profile_queries [--scene gas|bodies] [--n N] [--what box|ray|cast|nearest]
                       [--count Q] [--warmup W] [--seed S]
  --scene S      gas (default) or bodies
  --n N          objects (default 20000)
  --what W       the query kind (default ray)
  --count Q      queries (default 20000)
  --warmup W     gas: steps of motion before the queries (default 5)
  --seed S       scene and query seed (default 1)";

/// Radius of the spheres `--what cast` casts, in metres (as `vs_rapier`).
const CAST_RADIUS: f32 = 0.25;
/// Edge range of the query cubes, in metres (as `vs_rapier`).
const QUERY_EDGE: (f32, f32) = (1.0, 4.0);

struct Args {
    scene: &'static str,
    n: usize,
    what: &'static str,
    count: usize,
    warmup: usize,
    seed: u64,
}

fn parse(argv: impl IntoIterator<Item = String>) -> Result<Args, Stop> {
    let mut args = Args {
        scene: "gas",
        n: 20_000,
        what: "ray",
        count: 20_000,
        warmup: 5,
        seed: 1,
    };
    let mut flags = Flags::new(argv);
    while let Some(flag) = flags.next_flag()? {
        match flag.as_str() {
            "--scene" => {
                args.scene = flags.choice(&flag, &[("gas", "gas"), ("bodies", "bodies")])?
            }
            "--n" => args.n = flags.parse(&flag)?,
            "--what" => {
                let whats = ["box", "ray", "cast", "nearest"].map(|w| (w, w));
                args.what = flags.choice(&flag, &whats)?;
            }
            "--count" => args.count = flags.parse(&flag)?,
            "--warmup" => args.warmup = flags.parse(&flag)?,
            "--seed" => args.seed = flags.parse(&flag)?,
            _ => return Err(Stop::unknown(&flag)),
        }
    }
    Ok(args)
}

/// A direction uniform on the unit sphere (rejection from the cube, then normalised).
fn unit_dir(rng: &mut Rng) -> Vec3 {
    loop {
        let v = rng.vec3_in(Vec3::splat(-1.0), Vec3::splat(1.0));
        let l2 = v.length_squared();
        if l2 > 1e-6 && l2 <= 1.0 {
            return v / l2.sqrt();
        }
    }
}

/// The scene's broadphase and the cube the queries are drawn in.
fn world(args: &Args) -> (BroadPhase, Aabb) {
    let mut bp = BroadPhase::new(Config::default());
    let mut feed = Feed::new(false);
    let mut spawns = Vec::new();
    if args.scene == "gas" {
        let mut scene = Gas::new(args.n, args.seed);
        scene.spawns(&mut spawns);
        feed.spawn(&mut bp, &spawns)
            .expect("scene objects are finite");
        bp.step();
        let mut frame = Frame::default();
        for _ in 0..args.warmup.max(1) {
            scene.advance(&mut frame);
            feed.apply(&mut bp, &frame).expect("scene frames are valid");
            bp.step();
        }
        (bp, scene.bounds)
    } else {
        let mut scene = Bodies::new(args.n, args.seed);
        scene.advance(&mut Frame::default());
        scene.spawns(&mut spawns);
        for s in &mut spawns {
            s.object = s.object.boxed();
        }
        feed.spawn(&mut bp, &spawns)
            .expect("scene objects are finite");
        bp.step();
        (bp, scene.bounds)
    }
}

fn main() {
    let args = cli::or_exit(USAGE, parse(std::env::args().skip(1)));
    let (bp, bounds) = world(&args);
    let mut rng = Rng::new(args.seed ^ 0x7175_6572_7973);
    let max_t = bounds.extent().x;
    let mut hits = 0usize;
    let t = Instant::now();
    for _ in 0..args.count {
        let p = rng.vec3_in(bounds.min, bounds.max);
        hits += match args.what {
            "box" => {
                let half = 0.5 * rng.range(QUERY_EDGE.0, QUERY_EDGE.1);
                let mut n = 0;
                bp.query_aabb(
                    &Aabb::from_center_half_extents(p, Vec3::splat(half)),
                    |_| n += 1,
                );
                n
            }
            "ray" => usize::from(black_box(bp.cast_ray(p, unit_dir(&mut rng), max_t)).is_some()),
            "cast" => {
                let d = unit_dir(&mut rng);
                usize::from(black_box(bp.cast_sphere(p, CAST_RADIUS, d, max_t)).is_some())
            }
            _ => black_box(bp.nearest(p, 1)).len(),
        };
    }
    let ns = t.elapsed().as_nanos() as f64 / args.count.max(1) as f64;
    println!(
        "{} n={} {} x{}: hits {hits}, {ns:.0} ns/query",
        args.scene, args.n, args.what, args.count
    );
}
