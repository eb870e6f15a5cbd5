//! cargo-fuzz target `bag_metadata`: see `harness::bag_metadata` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::bag_metadata(data));
