//! The size and the save / restore time of a compact binary snapshot (postcard) of the `gas`
//! scene, for `benches/RESULTS.md`. After a few steps of motion: the snapshot's bytes per
//! proxy (and the JSON one's), the time to save it, to restore it, and the restored
//! broadphase's first step (the full pass over rebuilt structures) next to the original's;
//! for comparison, the time to insert the same spheres into a new broadphase and to step it
//! once. Each is the median of several runs. The restored broadphase's lists are checked
//! against the original's on that step.
//!
//! `cargo run --release --features serde --example snapshot_size -- [--n N]` (default 100000).

use broadleaf::fixtures::cli::{self, Flags, Stop};
use broadleaf::fixtures::scene::Gas;
use broadleaf::{BroadPhase, Config, ProxyKey};
use std::time::{Duration, Instant};

const RUNS: usize = 7;

const USAGE: &str = "\
usage: snapshot_size [--n N]
  --n N          spheres of the gas scene (default 100000)";

fn parse(argv: impl IntoIterator<Item = String>) -> Result<usize, Stop> {
    let mut n = 100_000;
    let mut flags = Flags::new(argv);
    while let Some(flag) = flags.next_flag()? {
        match flag.as_str() {
            "--n" => n = flags.parse(&flag)?,
            _ => return Err(Stop::unknown(&flag)),
        }
    }
    Ok(n)
}

fn median(mut t: Vec<Duration>) -> Duration {
    t.sort_unstable();
    t[t.len() / 2]
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n = cli::or_exit(USAGE, parse(std::env::args().skip(1)));
    let mut gas = Gas::new(n, 1);
    let mut bp = BroadPhase::new(Config {
        ..Config::default()
    });
    let (mut insert, mut fresh_step) = (Vec::new(), Vec::new());
    for _ in 0..RUNS {
        let mut fresh = BroadPhase::new(*bp.config());
        let t = Instant::now();
        for &c in &gas.centers {
            fresh.insert_sphere(c, gas.radius)?;
        }
        insert.push(t.elapsed());
        let t = Instant::now();
        fresh.step();
        fresh_step.push(t.elapsed());
    }
    let keys: Vec<ProxyKey> = gas
        .centers
        .iter()
        .map(|&c| bp.insert_sphere(c, gas.radius))
        .collect::<Result<_, _>>()?;
    for _ in 0..5 {
        gas.step(1.0 / 60.0);
        for (&k, &c) in keys.iter().zip(&gas.centers) {
            bp.update_sphere(k, c, gas.radius)?;
        }
        bp.step();
    }
    gas.step(1.0 / 60.0);
    for (&k, &c) in keys.iter().zip(&gas.centers) {
        bp.update_sphere(k, c, gas.radius)?;
    }

    let mut bytes = Vec::new();
    let mut save = Vec::new();
    for _ in 0..RUNS {
        let t = Instant::now();
        bytes = postcard::to_allocvec(&bp)?;
        save.push(t.elapsed());
    }
    let mut restore = Vec::new();
    let mut first_step = Vec::new();
    let mut original_step = Vec::new();
    for _ in 0..RUNS {
        let t = Instant::now();
        let mut r: BroadPhase = postcard::from_bytes(&bytes)?;
        restore.push(t.elapsed());
        let t = Instant::now();
        r.step();
        first_step.push(t.elapsed());
        let mut o = bp.clone();
        let t = Instant::now();
        o.step();
        original_step.push(t.elapsed());
    }
    let json = serde_json::to_vec(&bp)?;
    let mut restored: BroadPhase = postcard::from_bytes(&bytes)?;
    bp.step();
    restored.step();
    assert_eq!(
        (bp.pairs(), bp.added(), bp.removed()),
        (restored.pairs(), restored.added(), restored.removed()),
        "the restored broadphase's lists differ"
    );
    let pairs = bp.pairs().len();

    println!("gas {n}: {pairs} pairs at the snapshot");
    println!(
        "postcard: {} bytes, {:.2} bytes/proxy; json: {} bytes, {:.2} bytes/proxy",
        bytes.len(),
        bytes.len() as f64 / n as f64,
        json.len(),
        json.len() as f64 / n as f64
    );
    println!(
        "median of {RUNS}: save {:.2} ms, restore {:.2} ms, first step after restore {:.2} ms \
         (the original's next step: {:.2} ms)",
        ms(median(save)),
        ms(median(restore)),
        ms(median(first_step)),
        ms(median(original_step))
    );
    println!(
        "for comparison, inserting the {n} spheres into a new broadphase: {:.2} ms, its first \
         step {:.2} ms",
        ms(median(insert)),
        ms(median(fresh_step))
    );
    Ok(())
}
