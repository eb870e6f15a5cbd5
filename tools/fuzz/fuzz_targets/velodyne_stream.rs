//! cargo-fuzz target `velodyne_stream`: see `harness::velodyne_stream` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::velodyne_stream(data));
