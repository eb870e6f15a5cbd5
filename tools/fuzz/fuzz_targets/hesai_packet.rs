//! cargo-fuzz target `hesai_packet`: see `harness::hesai_packet` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::hesai_packet(data));
