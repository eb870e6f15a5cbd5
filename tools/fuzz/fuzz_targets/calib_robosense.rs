//! cargo-fuzz target `calib_robosense`: see `harness::calib_robosense` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::calib_robosense(data));
