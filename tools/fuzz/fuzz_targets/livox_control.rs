//! cargo-fuzz target `livox_control`: see `harness::livox_control` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::livox_control(data));
