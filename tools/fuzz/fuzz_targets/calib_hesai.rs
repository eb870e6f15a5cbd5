//! cargo-fuzz target `calib_hesai`: see `harness::calib_hesai` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::calib_hesai(data));
