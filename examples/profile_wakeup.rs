//! How long rayon's second worker takes to start a job handed out after the pool sat idle, as
//! a step's first split phase meets it: `cargo run --release --features parallel --example
//! profile_wakeup -- [--idle-us 2000] [--rounds 200]`.
//!
//! Each round the pool (two threads) idles for `--idle-us` microseconds (a physics step's
//! other work, during which the workers fall asleep), then the caller runs `rayon::join` of
//! two closures. The second closure, when another thread takes it, notes when it started;
//! the printed figures are the delays from the `join` call to that start (median, 90th
//! percentile, worst), and how many rounds the caller ran both closures itself because no
//! worker took the second in time. The same with the caller spinning on a pool job first
//! (`rayon::spawn` of an empty job just before the join) shows what waking the pool ahead of
//! a phase saves.

use broadleaf::fixtures::cli::{self, Flags, Stop};
use std::sync::Mutex;
use std::time::{Duration, Instant};

const USAGE: &str = "usage: profile_wakeup [--idle-us 2000] [--rounds 200]";

fn parse(args: impl Iterator<Item = String>) -> Result<(u64, usize), Stop> {
    let (mut idle, mut rounds) = (2000, 200);
    let mut flags = Flags::new(args);
    while let Some(flag) = flags.next_flag()? {
        match flag.as_str() {
            "--idle-us" => idle = flags.parse(&flag)?,
            "--rounds" => rounds = flags.parse(&flag)?,
            _ => return Err(Stop::unknown(&flag)),
        }
    }
    Ok((idle, rounds))
}

/// Busy work of about `us` microseconds on the calling thread.
fn work(us: u64) {
    let end = Instant::now() + Duration::from_micros(us);
    while Instant::now() < end {
        std::hint::spin_loop();
    }
}

/// The delays (µs) of `rounds` joins after `idle` µs of idling, and the rounds in which the
/// caller ran the second closure itself; `prewake` spawns an empty job first.
fn measure(pool: &rayon::ThreadPool, idle: u64, rounds: usize, prewake: bool) -> (Vec<f64>, usize) {
    let (mut delays, mut own) = (Vec::with_capacity(rounds), 0);
    for _ in 0..rounds {
        std::thread::sleep(Duration::from_micros(idle));
        let started = Mutex::new(None);
        let t = pool.install(|| {
            // `install` runs this on one of the pool's threads: the caller of the join.
            let caller = std::thread::current().id();
            if prewake {
                rayon::spawn(|| {});
            }
            let t = Instant::now();
            rayon::join(
                || work(200),
                || {
                    if std::thread::current().id() != caller {
                        *started.lock().expect("not poisoned") = Some(Instant::now());
                    }
                    work(200);
                },
            );
            t
        });
        match *started.lock().expect("not poisoned") {
            Some(s) => delays.push(s.duration_since(t).as_secs_f64() * 1e6),
            None => own += 1,
        }
    }
    delays.sort_by(f64::total_cmp);
    (delays, own)
}

fn main() {
    let (idle, rounds) = cli::or_exit(USAGE, parse(std::env::args().skip(1)));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .expect("a pool of two threads");
    for prewake in [false, true] {
        let (d, own) = measure(&pool, idle, rounds, prewake);
        let at = |q: f64| d.get(((d.len() as f64 - 1.0) * q) as usize).copied();
        println!(
            "idle {idle} µs{}: second closure started after median {:.1} µs, p90 {:.1}, worst {:.1} ({} of {rounds} rounds taken by a worker)",
            if prewake { ", pool woken first" } else { "" },
            at(0.5).unwrap_or(f64::NAN),
            at(0.9).unwrap_or(f64::NAN),
            at(1.0).unwrap_or(f64::NAN),
            rounds - own
        );
    }
}
