//! cargo-fuzz target `bag_ros1`: see `harness::bag_ros1` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::bag_ros1(data));
