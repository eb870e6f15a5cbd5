//! cargo-fuzz target `reassembly`: see `harness::reassembly` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::reassembly(data));
