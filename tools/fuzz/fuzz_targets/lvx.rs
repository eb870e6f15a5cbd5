//! cargo-fuzz target `lvx`: see `harness::lvx` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::lvx(data));
