//! cargo-fuzz target `calib_velodyne`: see `harness::calib_velodyne` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::calib_velodyne(data));
