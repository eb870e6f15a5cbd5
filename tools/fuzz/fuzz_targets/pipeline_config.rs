//! cargo-fuzz target `pipeline_config`: see `harness::pipeline_config` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::pipeline_config(data));
