//! cargo-fuzz target `velodyne_packet`: see `harness::velodyne_packet` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::velodyne_packet(data));
