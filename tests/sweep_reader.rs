//! `SweepReader` (the Python package's `open`) against `decode`: it counts the sensors while it
//! decodes instead of reading the first datagrams twice, and must still end with the summary
//! `decode --json` gives — the same sensors, names, topics (one sensor: `/points`; several:
//! `/<name>/points`) and counts — with and without reading ahead.

mod common;

use ringscan::cli::run::{decode_capture, DecodeArgs, SweepReader};
use serde_json::Value;

const CASES: &[(&str, &[&str])] = &[
    // One sensor.
    (
        "Kitware__VeloView/Testing/Data/monterey-first-100-packets.pcap",
        &["ros-drivers__velodyne/velodyne_pointcloud/params/32db.yaml"],
    ),
    (
        "ouster-lidar__ouster-sdk/tests/pcaps/OS-2-128-U1_v2.3.0_1024x10.pcap",
        &["ouster-lidar__ouster-sdk/tests/pcaps/OS-2-128-U1_v2.3.0_1024x10.json"],
    ),
    // Two sensors on one port.
    (
        "ouster-lidar__ouster-sdk/tests/pcaps/same_ports.pcap",
        &[
            "ouster-lidar__ouster-sdk/tests/pcaps/same_ports.1.json",
            "ouster-lidar__ouster-sdk/tests/pcaps/same_ports.2.json",
        ],
    ),
    (
        "ouster-lidar__ouster-sdk/tests/pcaps/same_ports_nonlegacy.pcap",
        &[
            "ouster-lidar__ouster-sdk/tests/pcaps/same_ports_nonlegacy.1.json",
            "ouster-lidar__ouster-sdk/tests/pcaps/same_ports_nonlegacy.2.json",
        ],
    ),
];

/// The parts of a summary that do not depend on how the input was read or how long it took.
fn comparable(mut v: Value) -> Value {
    if let Some(m) = v.as_object_mut() {
        for k in ["elapsed_s", "output", "capture"] {
            m.remove(k);
        }
    }
    v
}

#[test]
fn sweep_reader_ends_with_the_summary_decode_gives() {
    let Some(caps) = common::captures() else {
        return;
    };
    for (pcap, calib) in CASES {
        let mut args = DecodeArgs::new(caps.join(pcap));
        args.session.calib = calib
            .iter()
            .map(|c| caps.join(c).display().to_string())
            .collect();
        args.threads = 1;
        let cli = comparable(decode_capture(&args).unwrap().json);
        let topics: Vec<&str> = cli["sensors"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s["topic"].as_str().unwrap())
            .collect();
        let several = topics.len() > 1;
        assert!(
            topics
                .iter()
                .all(|t| (*t == "/points") != several && t.ends_with("/points")),
            "{pcap}: topics {topics:?}"
        );
        for read_ahead in [false, true] {
            args.read_ahead = read_ahead;
            let mut r = SweepReader::open(&args).unwrap();
            let mut points = 0u64;
            while let Some(s) = r.next_sweep().unwrap() {
                points += s.sweep.points.len() as u64;
            }
            let py = comparable(r.summary().json);
            assert_eq!(py, cli, "{pcap}, read ahead {read_ahead}");
            assert_eq!(Some(points), cli["points"].as_u64(), "{pcap}");
        }
    }
}
