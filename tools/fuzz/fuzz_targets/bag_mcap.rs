//! cargo-fuzz target `bag_mcap`: see `harness::bag_mcap` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::bag_mcap(data));
