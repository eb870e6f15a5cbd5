//! cargo-fuzz target `ouster_stream`: see `harness::ouster_stream` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::ouster_stream(data));
