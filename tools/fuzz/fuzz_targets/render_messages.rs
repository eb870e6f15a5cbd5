//! cargo-fuzz target `render_messages`: see `harness::render_messages` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::render_messages(data));
