//! Loopback end to end: `ringscan replay` of every real capture into `ringscan listen` gives the
//! same point payloads as `ringscan decode` of that capture, with no datagram lost.
//!
//! The truth is `decode` reading the pcap file (itself checked against velodyne_decoder and
//! ouster-sdk elsewhere); here the packets take the live path instead: UDP sockets on
//! 127.0.0.1, the receive task, the queue, the decode thread, the continuously written MCAP,
//! finalised on SIGINT. Each original source address is replayed from its own loopback
//! address (127.0.0.k), so the two-sensors-on-one-port captures stay two sensors.

mod common;
mod listen_util;

use std::net::Ipv4Addr;
use std::path::Path;

use listen_util::*;

/// (capture, --calib files) relative to the captures folder.
const CAPTURES: &[(&str, &[&str])] = &[
    (
        "Kitware__VeloView/Testing/Data/monterey-first-100-packets.pcap",
        &["ros-drivers__velodyne/velodyne_pointcloud/params/32db.yaml"],
    ),
    ("Kitware__VeloView/Testing/Data/vlp-16-test-90deg-1-50-frames.pcap", &[]),
    ("jerry73204__rust-lidar-utils/test_files/hdl32_example.pcap", &[]),
    ("jerry73204__rust-lidar-utils/test_files/velodyne_example.pcap", &[]),
    ("jerry73204__rust-lidar-utils/velodyne-test/test_files/velodyne_vlp16.pcap", &[]),
    ("jerry73204__rust-lidar-utils/velodyne-test/test_files/velodyne_vlp32.pcap", &[]),
    (
        "tier4__nebula/src/nebula_velodyne/nebula_velodyne/test_resources/decoder_ground_truth/vlp16/1673400471837873222/1673400471837873222_0.pcap",
        &["tier4__nebula/src/nebula_velodyne/nebula_velodyne_decoders/calibration/VLP16.yaml"],
    ),
    (
        "tier4__nebula/src/nebula_velodyne/nebula_velodyne/test_resources/decoder_ground_truth/vlp32/1713492677464078412/1713492677464078412_0.pcap",
        &["tier4__nebula/src/nebula_velodyne/nebula_velodyne_decoders/calibration/VLP32.yaml"],
    ),
    (
        "ouster-lidar__ouster-sdk/tests/pcaps/OS-0-32-U1_v2.2.0_1024x10.pcap",
        &["ouster-lidar__ouster-sdk/tests/pcaps/OS-0-32-U1_v2.2.0_1024x10.json"],
    ),
    (
        "ouster-lidar__ouster-sdk/tests/pcaps/OS-1-128_767798045_1024x10_20230712_120049.pcap",
        &["ouster-lidar__ouster-sdk/tests/pcaps/OS-1-128_767798045_1024x10_20230712_120049.json"],
    ),
    (
        "ouster-lidar__ouster-sdk/tests/pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap",
        &["ouster-lidar__ouster-sdk/tests/pcaps/OS-1-128_v2.3.0_1024x10.json"],
    ),
    (
        "ouster-lidar__ouster-sdk/tests/pcaps/OS-1-32-G_v2.1.1_1024x10.pcap",
        &["ouster-lidar__ouster-sdk/tests/pcaps/OS-1-32-G_v2.1.1_1024x10.json"],
    ),
    (
        "ouster-lidar__ouster-sdk/tests/pcaps/OS-1-64_1024x10_fw20.pcap",
        &["ouster-lidar__ouster-sdk/tests/pcaps/OS-1-64_sensor_config_reduced.json"],
    ),
    (
        "ouster-lidar__ouster-sdk/tests/pcaps/OS-2-128-U1_v2.3.0_1024x10.pcap",
        &["ouster-lidar__ouster-sdk/tests/pcaps/OS-2-128-U1_v2.3.0_1024x10.json"],
    ),
    (
        "ouster-lidar__ouster-sdk/tests/pcaps/OS-2-32-U0_v2.0.0_1024x10.pcap",
        &["ouster-lidar__ouster-sdk/tests/pcaps/OS-2-32-U0_v2.0.0_1024x10.json"],
    ),
    (
        "ouster-lidar__ouster-sdk/tests/pcaps/crc_test.pcap",
        &["ouster-lidar__ouster-sdk/tests/pcaps/crc_test.json"],
    ),
    (
        "ouster-lidar__ouster-sdk/tests/pcaps/duplicate_id.pcap",
        &["ouster-lidar__ouster-sdk/tests/pcaps/duplicate_id.json"],
    ),
    (
        "ouster-lidar__ouster-sdk/tests/pcaps/shot_limiting_test.pcap",
        &["ouster-lidar__ouster-sdk/tests/pcaps/shot_limiting_test.json"],
    ),
    (
        "ouster-lidar__ouster-sdk/tests/pcaps/windowed_frame1.pcap",
        &["ouster-lidar__ouster-sdk/tests/pcaps/windowed_frame1_0.json"],
    ),
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

/// Sources (in order of appearance), destination ports and the number of datagrams.
fn layout(pcap: &Path) -> (Vec<Ipv4Addr>, Vec<u16>, u64) {
    let mut src = ringscan::source::pcap::PcapSource::open(pcap).unwrap();
    let (mut sources, mut ports, mut n) = (Vec::new(), Vec::new(), 0u64);
    while let Some(d) = src.next_datagram().unwrap() {
        if !sources.contains(d.src.ip()) {
            sources.push(*d.src.ip());
        }
        if !ports.contains(&d.dst.port()) {
            ports.push(d.dst.port());
        }
        n += 1;
    }
    (sources, ports, n)
}

fn loopback(c: &Path, rel: &str, calibs: &[&str], tmp: &Path) {
    let pcap = c.join(rel);
    let name = Path::new(rel)
        .file_stem()
        .unwrap()
        .to_string_lossy()
        .into_owned();
    let calib_args: Vec<String> = calibs
        .iter()
        .flat_map(|f| ["--calib".to_string(), c.join(f).display().to_string()])
        .collect();
    let decoded_path = tmp.join(format!("{name}.decode.mcap"));
    let decoded = decode(&pcap, &decoded_path, &calib_args);

    let (sources, ports, datagrams) = layout(&pcap);
    let offset = free_offset(&ports);
    let live_path = tmp.join(format!("{name}.listen.mcap"));
    let mut args: Vec<String> = Vec::new();
    for k in 0..sources.len() {
        for p in &ports {
            args.push("--sensor".into());
            args.push(format!("127.0.0.{}:{}", k + 1, i32::from(*p) + offset));
        }
    }
    args.extend(calib_args.iter().cloned());
    args.push("--out".into());
    args.push(live_path.display().to_string());
    let l = start_listen(&args);
    replay(&pcap, offset, "1", &["--per-source-loopback"]);
    std::thread::sleep(std::time::Duration::from_millis(500));
    let (code, out, err) = l.stop("INT");
    assert_eq!(code, Some(0), "{name}: listen failed: {err}");
    let live: serde_json::Value =
        serde_json::from_str(&out).unwrap_or_else(|e| panic!("{name}: {e}: {out:?} {err}"));

    // Nothing lost on the way.
    let r = &live["receive"];
    assert_eq!(
        r["datagrams"], datagrams,
        "{name}: datagrams received\n{err}"
    );
    assert_eq!(r["queue_dropped"], 0, "{name}");
    assert_eq!(r["kernel_dropped"], 0, "{name}");
    assert_eq!(r["other_source"], 0, "{name}");
    assert_eq!(live["stop"], "SIGINT");
    // Every sensor has its `--calib` file: none is asked for its metadata (an Ouster IMU
    // packet before the first lidar packet once made listen ask), and nothing is left held.
    assert!(
        !err.contains("/api/v1/sensor/metadata"),
        "{name}: asked a sensor that has a --calib file\n{err}"
    );
    assert_eq!(r["held_for_metadata"]["left"], 0, "{name}");
    // The same counts as the file decode.
    for k in ["sweeps", "points", "imu_samples"] {
        assert_eq!(live[k], decoded[k], "{name}: {k}");
    }
    for k in ["decoded", "dropped", "malformed", "missing", "position"] {
        assert_eq!(
            live["packets"][k], decoded["packets"][k],
            "{name}: packets.{k}"
        );
    }
    // The same point payloads, sweep by sweep, per topic.
    let a = points_by_topic(&std::fs::read(&decoded_path).unwrap());
    let b = points_by_topic(&std::fs::read(&live_path).unwrap());
    assert_eq!(
        a.keys().collect::<Vec<_>>(),
        b.keys().collect::<Vec<_>>(),
        "{name}: topics"
    );
    let mut sweeps = 0;
    for (topic, sa) in &a {
        let sb = &b[topic];
        assert_eq!(sa.len(), sb.len(), "{name} {topic}: sweeps");
        for (i, (x, y)) in sa.iter().zip(sb).enumerate() {
            if x == y {
                continue;
            }
            assert_eq!(x.len(), y.len(), "{name} {topic}: sweep {i} sizes");
            let diff: Vec<usize> = (0..x.len()).filter(|&j| x[j] != y[j]).collect();
            let fields: std::collections::BTreeSet<usize> = diff.iter().map(|j| j % 24).collect();
            panic!(
                "{name} {topic}: sweep {i} differs ({} bytes differ at record offsets {fields:?})",
                diff.len()
            );
        }
        sweeps += sa.len();
    }
    eprintln!(
        "{name}: {datagrams} datagrams from {} source(s) to ports {ports:?} (+{offset}); {sweeps} sweeps, {} points identical",
        sources.len(),
        decoded["points"]
    );
}

#[test]
fn replay_into_listen_gives_the_points_of_decode() {
    let Some(c) = common::captures() else { return };
    let tmp = std::env::temp_dir().join(format!("ringscan-listen-loopback-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    for (rel, calibs) in CAPTURES {
        loopback(&c, rel, calibs, &tmp);
    }
    let _ = std::fs::remove_dir_all(&tmp);
}
