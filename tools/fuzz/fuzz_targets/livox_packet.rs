//! cargo-fuzz target `livox_packet`: see `harness::livox_packet` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::livox_packet(data));
