//! cargo-fuzz target `bag_messages`: see `harness::bag_messages` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::bag_messages(data));
