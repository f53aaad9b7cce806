//! The libFuzzer target: random operation sequences over the whole `BroadPhase` API against
//! the driver's own model ([`driver`], shared with the stable test `tests/fuzz_ops.rs`).
//! `cargo +nightly fuzz run ops` from the crate's root.
#![no_main]

#[path = "driver.rs"]
mod driver;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| driver::run(&driver::Input::decode(data)));
