//! `--format ros2` writes a rosbag2 that ringscan reads back: `decode --format ros2 --raw` of a
//! capture into a bag directory, then the bag as a source gives the capture's packets (times,
//! ports, payloads) and the same sweeps, point for point; `decode` of the bag reports the same
//! sweeps and points as `decode` of the capture.
//!
//! - the demo VLP-16 capture (`fixtures/demo-vlp16.pcap`): its data packets as
//!   `velodyne_msgs/msg/VelodyneScan` (the position packets have no place there);
//! - an Ouster capture with its IMU and metadata (`../shared/captures`, SKIP without):
//!   `ouster_sensor_msgs/msg/PacketMsg` on `/lidar_packets` and `/imu_packets`, the metadata
//!   as a `std_msgs/msg/String` on `/metadata`, which configures the decoder on the way back.
//!
//! The bags are also opened by an independent reader (`rosbags`): `tools/ci_ros2_bag_check.sh`.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use ringscan::point::Point;
use ringscan::sensor::{self, CalibrationPool, StreamSettings};
use ringscan::source::bag::{BagOptions, BagSource};
use ringscan::source::pcap::PcapSource;
use ringscan::sweep::Demux;
use serde_json::Value;

/// One datagram: time, destination port, payload.
type Dgram = (i64, u16, Vec<u8>);

fn pcap_datagrams(path: &Path) -> Vec<Dgram> {
    let mut src = PcapSource::open(path).unwrap();
    let mut out = Vec::new();
    while let Some(d) = src.next_datagram().unwrap() {
        out.push((d.time_ns, d.dst.port(), d.payload.to_vec()));
    }
    out
}

fn bag_datagrams(path: &Path) -> (Vec<Dgram>, BagSource) {
    let mut src = BagSource::open(path, BagOptions::default()).unwrap();
    let mut out = Vec::new();
    while let Some(d) = src.next_datagram().unwrap() {
        out.push((d.time_ns, d.dst.port(), d.payload.to_vec()));
    }
    let st = src.stats();
    assert_eq!(st.malformed, 0, "{:?}", st.first_malformed);
    assert_eq!(st.truncated_at, None);
    (out, src)
}

/// Every sweep (timestamp, packets, points) of the datagrams from one source address.
fn sweeps(datagrams: &[Dgram], calib: Option<&[u8]>) -> Vec<(i64, u32, Vec<Point>)> {
    let calibs = calib
        .map(|c| vec![sensor::parse_calibration(c, "metadata", None).unwrap()])
        .unwrap_or_default();
    let mut pool = CalibrationPool::new(calibs, StreamSettings::default());
    let mut demux = Demux::new(Box::new(move |d| sensor::claim(d, &mut pool)), None);
    let mut out = Vec::new();
    let src = std::net::Ipv4Addr::new(127, 0, 0, 1);
    for (t, port, payload) in datagrams {
        demux
            .push(*t, src, *port, payload, &mut |_, s, _| {
                out.push((s.timestamp_ns, s.packets, s.points.clone()))
            })
            .unwrap();
    }
    demux
        .finish(&mut |_, s, _| out.push((s.timestamp_ns, s.packets, s.points.clone())))
        .unwrap();
    out
}

fn ringscan(args: &[&str]) -> Value {
    let out = Command::new(env!("CARGO_BIN_EXE_ringscan"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "ringscan {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ringscan-ros2bag-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `decode --format ros2 --raw` → bag → the bag's datagrams and sweeps are the capture's;
/// `decode` of the bag reports the capture's sweeps and points.
fn round_trip(pcap: &Path, calib: Option<&Path>, keep: impl Fn(&Dgram) -> bool) -> (usize, usize) {
    let dir = temp_dir(
        &pcap
            .file_stem()
            .unwrap()
            .to_string_lossy()
            .replace('.', "_"),
    );
    let bag = dir.join("bag");
    let mut args = vec![
        "decode".to_string(),
        pcap.display().to_string(),
        "--format".into(),
        "ros2".into(),
        "--raw".into(),
        "--out".into(),
        bag.display().to_string(),
        "--json".into(),
    ];
    if let Some(c) = calib {
        args.extend(["--calib".into(), c.display().to_string()]);
    }
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    let wrote = ringscan(&refs);
    assert!(bag.join("metadata.yaml").is_file(), "a rosbag2 directory");
    assert!(bag.join("bag_0.mcap").is_file(), "its MCAP storage file");

    let want: Vec<Dgram> = pcap_datagrams(pcap)
        .into_iter()
        .filter(|d| keep(d))
        .collect();
    let (got, src) = bag_datagrams(&bag);
    assert_eq!(src.sensors().len(), 1, "one sensor in the bag");
    let metadata = src.sensors()[0].metadata.clone();
    assert_eq!(got.len(), want.len(), "datagrams");
    for (i, (w, g)) in want.iter().zip(&got).enumerate() {
        assert_eq!(w.0, g.0, "time of datagram {i}");
        assert_eq!(w.1, g.1, "port of datagram {i}");
        assert!(w.2 == g.2, "payload of datagram {i}");
    }
    // The metadata written into the bag is the calibration given to the run.
    let calib_bytes = calib.map(|c| std::fs::read(c).unwrap());
    assert_eq!(
        metadata.as_deref().map(str::as_bytes),
        calib_bytes.as_deref(),
        "the bag's Ouster metadata"
    );
    let a = sweeps(&want, calib_bytes.as_deref());
    let b = sweeps(&got, metadata.as_deref().map(str::as_bytes));
    assert_eq!(a.len(), b.len(), "sweeps");
    let mut points = 0;
    for (k, (x, y)) in a.iter().zip(&b).enumerate() {
        assert_eq!((x.0, x.1), (y.0, y.1), "sweep {k} timestamp / packets");
        assert!(x.2 == y.2, "sweep {k}: a point differs");
        points += x.2.len();
    }
    assert!(points > 0);

    // The command line: the bag decodes (metadata from the bag) to what the capture gave.
    let again = ringscan(&["decode", &bag.display().to_string(), "--json"]);
    for k in ["sweeps", "points"] {
        assert_eq!(again[k], wrote[k], "{k}: bag vs capture");
    }
    let _ = std::fs::remove_dir_all(&dir);
    (a.len(), points)
}

#[test]
fn velodyne_packets_round_trip_through_a_ros2_bag() {
    let pcap = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo-vlp16.pcap");
    // VelodyneScan holds the 1206-byte data packets (port 2368) only.
    let (sweeps, points) = round_trip(&pcap, None, |d| d.2.len() == 1206);
    assert!(sweeps >= 9, "{sweeps} sweeps");
    eprintln!("demo VLP-16: {sweeps} sweeps, {points} points through the bag");
}

#[test]
fn ouster_packets_and_metadata_round_trip_through_a_ros2_bag() {
    let Some(root) = common::captures() else {
        eprintln!("SKIP: ../shared/captures not found");
        return;
    };
    let dir = root.join("ouster-lidar__ouster-sdk/tests/pcaps");
    let pcap = dir.join("OS-0-32-U1_v2.2.0_1024x10.pcap");
    let json = dir.join("OS-0-32-U1_v2.2.0_1024x10.json");
    let (sweeps, points) = round_trip(&pcap, Some(&json), |_| true);
    eprintln!("OS-0-32: {sweeps} sweeps, {points} points through the bag");
}

#[test]
fn an_existing_bag_is_not_overwritten() {
    let dir = temp_dir("exists");
    let bag = dir.join("bag");
    std::fs::create_dir_all(&bag).unwrap();
    std::fs::write(bag.join("metadata.yaml"), "x").unwrap();
    let pcap = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo-vlp16.pcap");
    let out = Command::new(env!("CARGO_BIN_EXE_ringscan"))
        .args(["decode", &pcap.display().to_string(), "--format", "ros2"])
        .arg("--out")
        .arg(&bag)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("already holds a rosbag2"), "{err}");
    assert_eq!(std::fs::read(bag.join("metadata.yaml")).unwrap(), b"x");
    let _ = std::fs::remove_dir_all(&dir);
}
