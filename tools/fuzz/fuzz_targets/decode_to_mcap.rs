//! cargo-fuzz target `decode_to_mcap`: see `harness::decode_to_mcap` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::decode_to_mcap(data));
