//! cargo-fuzz target `tum_poses`: see `harness::tum_poses` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::tum_poses(data));
