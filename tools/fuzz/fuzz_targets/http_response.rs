//! cargo-fuzz target `http_response`: see `harness::http_response` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::http_response(data));
