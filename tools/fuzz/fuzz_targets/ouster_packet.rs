//! cargo-fuzz target `ouster_packet`: see `harness::ouster_packet` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::ouster_packet(data));
