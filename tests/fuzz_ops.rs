//! The fuzz target's driver (`fuzz/fuzz_targets/driver.rs`) on stable: seeded random byte
//! strings decoded through `arbitrary::Unstructured` into operation sequences over the whole
//! `BroadPhase` API — groups, batches with bad entries, every query kind with filters and early
//! exit, snapshots clean and damaged, every `Passes` — each checked against the driver's own
//! model. The libFuzzer target (`cargo +nightly fuzz run ops`) runs the same driver on the
//! fuzzer's inputs; this test keeps it compiling and running under `cargo test`, and replays
//! the seeds kept from the fuzzer's corpus (`fuzz/seeds/`, its smallest inputs).

#[path = "../fuzz/fuzz_targets/driver.rs"]
mod driver;

mod common;

use common::Rng;

/// Random inputs per run, and the byte length of each: long enough for a few hundred
/// operations; as many inputs as keep the test near 40 s at opt-level 1 on a busy 2-core
/// machine (see `benches/RESULTS.md`).
const INPUTS: u64 = 140_000;
const BYTES: usize = 4096;

/// The input decoded from `seed`'s bytes.
fn input(seed: u64) -> driver::Input {
    let mut rng = Rng::new(seed);
    let bytes: Vec<u8> = (0..BYTES).map(|_| rng.next_u64() as u8).collect();
    driver::Input::decode(&bytes)
}

#[test]
fn random_operation_sequences_match_the_model() {
    for seed in 0..INPUTS {
        println!("seed {seed}");
        driver::run(&input(seed));
    }
}

/// Every file of `fuzz/seeds/`, decoded and run as the fuzz target runs it.
#[test]
fn the_fuzzers_seeds_match_the_model() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/seeds");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("fuzz/seeds exists")
        .map(|e| e.expect("a readable entry").path())
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no seeds in {}", dir.display());
    for path in files {
        println!("{}", path.display());
        let bytes = std::fs::read(&path).expect("a readable seed");
        driver::run(&driver::Input::decode(&bytes));
    }
}

/// The seeds given in `FUZZ_SEEDS` (`a..b`), for long runs in release:
/// `FUZZ_SEEDS=0..1000000 cargo test --release --all-features --test fuzz_ops -- --ignored`.
#[test]
#[ignore = "a long run, by hand"]
fn seeds_from_the_environment() {
    let range = std::env::var("FUZZ_SEEDS").unwrap_or_else(|_| "0..1000".into());
    let (a, b) = range.split_once("..").expect("FUZZ_SEEDS is a..b");
    let (a, b): (u64, u64) = (a.parse().expect("a number"), b.parse().expect("a number"));
    for seed in a..b {
        driver::run(&input(seed));
    }
}
