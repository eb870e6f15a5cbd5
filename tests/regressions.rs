//! Every input the fuzzers found (`fixtures/regressions/<target>-<short>.bin`), replayed through
//! the very harness its fuzz target runs (`tools/fuzz/harness.rs`), with every check on —
//! including those of issues still open, which the fuzz targets step around.
//!
//! A crash that is reported and not fixed yet has its own `#[ignore]`d test naming the file to
//! fix. When the fix lands: remove the issue from `harness::OPEN_ISSUES`, drop the `#[ignore]`.
//! FUZZING.md tells how to add a new one.
#![cfg(all(feature = "pcap", feature = "mcap", feature = "sim"))]

#[path = "../tools/fuzz/harness.rs"]
mod harness;

use std::path::PathBuf;

/// Every regression input and the open issue (in `harness::OPEN_ISSUES`) it reproduces, if any.
const REGRESSIONS: &[(&str, Option<&str>)] = &[
    ("velodyne_packet-t-base-overflow.bin", None),
    ("velodyne_stream-demux-finish-first-error.bin", None),
    ("decode_to_mcap-sensor-name-collision.bin", None),
    ("velodyne_stream-host-time-overflow.bin", None),
    ("decode_to_mcap-host-time-overflow.bin", None),
    ("velodyne_packet-nmea-date-char-boundary.bin", None),
    ("velodyne_packet-nmea-time-char-boundary.bin", None),
    ("decode_to_mcap-nmea-char-boundary.bin", None),
    ("ouster_packet-duplicate-measurement-id.bin", None),
    ("http_response-chunk-size-overflow.bin", None),
    ("velodyne_packet-vls128-fixed-distance-unit.bin", None),
    ("bag_mcap-mcap-crate-chunk-length-overflow.bin", None),
    ("calib_hesai-atx-one-channel.bin", None),
    ("family_stream-robosense-difop-counted-twice.bin", None),
    ("family_stream-hesai-late-packet-time.bin", None),
    ("family_stream-robosense-held-packet-uncounted.bin", None),
    ("family_stream-robosense-ring-beyond-model.bin", None),
];

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("fixtures/regressions")
}

/// Runs one saved input through its target's harness, strictly.
fn replay(file: &str) {
    let data = std::fs::read(dir().join(file)).unwrap_or_else(|e| panic!("{file}: {e}"));
    let target = file.split('-').next().unwrap_or_default();
    harness::set_strict(true);
    match target {
        "pcap" => harness::pcap(&data),
        "reassembly" => harness::reassembly(&data),
        "velodyne_packet" => harness::velodyne_packet(&data),
        "velodyne_stream" => harness::velodyne_stream(&data),
        "calib_velodyne" => harness::calib_velodyne(&data),
        "decode_to_mcap" => harness::decode_to_mcap(&data),
        "calib_ouster" => harness::calib_ouster(&data),
        "ouster_packet" => harness::ouster_packet(&data),
        "ouster_stream" => harness::ouster_stream(&data),
        "pipeline_config" => harness::pipeline_config(&data),
        "tum_poses" => harness::tum_poses(&data),
        "http_response" => harness::http_response(&data),
        "live_view_requests" => harness::live_view_requests(&data),
        "bag_ros1" => harness::bag_ros1(&data),
        "bag_messages" => harness::bag_messages(&data),
        "bag_metadata" => harness::bag_metadata(&data),
        "bag_mcap" => harness::bag_mcap(&data),
        "hesai_packet" => harness::hesai_packet(&data),
        "calib_hesai" => harness::calib_hesai(&data),
        "livox_packet" => harness::livox_packet(&data),
        "livox_control" => harness::livox_control(&data),
        "lvx" => harness::lvx(&data),
        "render_messages" => harness::render_messages(&data),
        "family_stream" => harness::family_stream(&data),
        other => panic!("{file}: no fuzz target named {other:?}"),
    }
}

#[test]
fn every_regression_file_is_listed() {
    let mut on_disk: Vec<String> = std::fs::read_dir(dir())
        .expect("fixtures/regressions")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".bin"))
        .collect();
    on_disk.sort();
    let mut listed: Vec<String> = REGRESSIONS.iter().map(|(f, _)| f.to_string()).collect();
    listed.sort();
    assert_eq!(
        on_disk, listed,
        "fixtures/regressions and REGRESSIONS differ"
    );
    for (file, issue) in REGRESSIONS {
        if let Some(issue) = issue {
            assert!(
                harness::OPEN_ISSUES.contains(issue),
                "{file}: issue {issue:?} is not in harness::OPEN_ISSUES (fixed? then list it as None)"
            );
        }
    }
}

/// Inputs whose issue is fixed (or never was open) must pass, strictly.
#[test]
fn fixed_regressions_replay_cleanly() {
    for (file, issue) in REGRESSIONS {
        if issue.is_none_or(|i| !harness::OPEN_ISSUES.contains(&i)) {
            replay(file);
        }
    }
}

/// `t_base_ns + firing offset` overflowed for a time base near i64::MAX (src/sensor/velodyne/decode.rs;
/// fixed in 8664547).
#[test]
fn velodyne_packet_t_base_overflow() {
    replay("velodyne_packet-t-base-overflow.bin");
}

#[test]
fn velodyne_stream_demux_finish_first_error() {
    replay("velodyne_stream-demux-finish-first-error.bin");
}

/// Two VLP-16s at 192.168.1.200 and 192.164.1.200 were both named vlp16-200 and the sink refused
/// the second (src/cli; fixed in 8664547: the second is named by its whole address).
#[test]
fn decode_to_mcap_sensor_name_collision() {
    replay("decode_to_mcap-sensor-name-collision.bin");
}

/// Host times 1.7e18 then -8.4e18 ns overflowed the sweep time arithmetic (src/sensor/velodyne/sweep.rs;
/// fixed in 8664547).
#[test]
fn velodyne_stream_host_time_overflow() {
    replay("velodyne_stream-host-time-overflow.bin");
}

/// A pcapng whose 4th packet has a corrupt stamp (i64::MAX ns) overflowed `complete_toh`
/// (src/time.rs; fixed in 8664547).
#[test]
fn decode_to_mcap_host_time_overflow() {
    replay("decode_to_mcap-host-time-overflow.bin");
}

/// The RMC date `721Ҫ1` (6 bytes, not ASCII) was sliced off a char boundary: panic
/// (src/sensor/nmea.rs; fixed in 8664547).
#[test]
fn velodyne_packet_nmea_date_char_boundary() {
    replay("velodyne_packet-nmea-date-char-boundary.bin");
}

/// The RMC time `0Ҫ000` (6 bytes, not ASCII) was sliced off a char boundary: panic
/// (src/sensor/nmea.rs; fixed in 8664547).
#[test]
fn velodyne_packet_nmea_time_char_boundary() {
    replay("velodyne_packet-nmea-time-char-boundary.bin");
}

/// A 594-byte pcap with one position packet whose RMC date is not ASCII made `ringscan decode`
/// panic, release builds too (src/sensor/nmea.rs; fixed in 8664547).
#[test]
fn decode_to_mcap_nmea_char_boundary() {
    replay("decode_to_mcap-nmea-char-boundary.bin");
}

/// A chunk size near `usize::MAX` in an HTTP reply (the Ouster metadata fetch of `listen`)
/// overflowed `size + 2`; in release builds the check wrapped and the slice panicked
/// (src/source/udp.rs `dechunk`; found by the `http_response` target, fixed in session 3).
#[test]
fn http_response_chunk_size_overflow() {
    replay("http_response-chunk-size-overflow.bin");
}
