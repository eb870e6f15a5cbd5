//! cargo-fuzz target `calib_ouster`: see `harness::calib_ouster` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::calib_ouster(data));
