//! cargo-fuzz target `live_view_requests`: see `harness::live_view_requests` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::live_view_requests(data));
