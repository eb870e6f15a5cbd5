//! cargo-fuzz target `family_stream`: see `harness::family_stream` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::family_stream(data));
