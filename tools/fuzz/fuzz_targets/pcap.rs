//! cargo-fuzz target `pcap`: see `harness::pcap` and FUZZING.md.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::pcap(data));
