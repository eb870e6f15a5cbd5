//! cargo-fuzz target `robosense_packet`: see `harness::robosense_packet` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::robosense_packet(data));
