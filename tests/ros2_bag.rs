//! `--format ros2` writes a rosbag2 that ringscan reads back: `decode --format ros2 --raw` of a
//! capture into a bag directory, then the bag as a source gives the capture's packets (times,
//! ports, payloads) and the same sweeps, point for point; `decode` of the bag reports the same
//! sweeps and points as `decode` of the capture.
//!
//! - the demo VLP-16 capture (`fixtures/demo-vlp16.pcap`): its data packets as
//!   `velodyne_msgs/msg/VelodyneScan` (the position packets have no place there);
//! - an Ouster capture with its IMU and metadata (`../shared/captures`, SKIP without):
//!   `ouster_sensor_msgs/msg/PacketMsg` on `/lidar_packets` and `/imu_packets`, the metadata
//!   as a `std_msgs/msg/String` on `/metadata`, which configures the decoder on the way back;
//! - a Hesai XT32 capture of nebula's tests (`../shared/captures`, SKIP without):
//!   `pandar_msgs/msg/PandarScan`, its angle-correction CSV given on both sides (the bag holds
//!   no calibration for Hesai).
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
fn sweeps(datagrams: &[Dgram], calib: Option<(&[u8], &str)>) -> Vec<(i64, u32, Vec<Point>)> {
    let calibs = calib
        .map(|(c, name)| vec![sensor::parse_calibration(c, name, None).unwrap()])
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

/// Where the decoder's calibration comes from on the way back.
#[derive(Clone, Copy, PartialEq)]
enum Back {
    /// The bag carries it (Ouster metadata): `--calib` is not given again.
    FromBag,
    /// The calibration file is given to the bag's decoding too.
    Given,
    /// The bag's MCAP carries the calibration file as an attachment (ringscan attaches the
    /// files it decodes with), which the bag's decoding uses without `--calib`.
    Attached,
}

/// `decode --format ros2 --raw` → bag → the bag's datagrams and sweeps are the capture's;
/// `decode` of the bag reports the capture's sweeps and points.
fn round_trip(
    pcap: &Path,
    calib: Option<&Path>,
    back: Back,
    keep: impl Fn(&Dgram) -> bool,
) -> (usize, usize) {
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
    let calib_bytes = calib.map(|c| std::fs::read(c).unwrap());
    let calib_name = calib.map_or(String::new(), |c| {
        c.file_name().unwrap().to_string_lossy().into_owned()
    });
    let given = calib_bytes.as_deref().map(|b| (b, calib_name.as_str()));
    let back_calib = match back {
        Back::FromBag => {
            // The metadata written into the bag is the calibration given to the run.
            assert_eq!(
                metadata.as_deref().map(str::as_bytes),
                calib_bytes.as_deref(),
                "the bag's Ouster metadata"
            );
            metadata.as_deref().map(|m| (m.as_bytes(), "metadata.json"))
        }
        Back::Given => {
            assert_eq!(metadata, None, "no calibration in the bag");
            given
        }
        Back::Attached => {
            assert_eq!(metadata, None, "no calibration topic in the bag");
            let (name, bytes) = src
                .attachments()
                .iter()
                .find(|(n, _)| *n == calib_name)
                .unwrap_or_else(|| panic!("{calib_name} attached to the bag"));
            assert_eq!(Some(bytes.as_slice()), calib_bytes.as_deref(), "{name}");
            Some((bytes.as_slice(), name.as_str()))
        }
    };
    let a = sweeps(&want, given);
    let b = sweeps(&got, back_calib);
    assert_eq!(a.len(), b.len(), "sweeps");
    let mut points = 0;
    for (k, (x, y)) in a.iter().zip(&b).enumerate() {
        assert_eq!((x.0, x.1), (y.0, y.1), "sweep {k} timestamp / packets");
        assert!(x.2 == y.2, "sweep {k}: a point differs");
        points += x.2.len();
    }
    assert!(points > 0);

    // The command line: the bag decodes (metadata from the bag) to what the capture gave.
    let bag_s = bag.display().to_string();
    let mut again_args = vec!["decode", bag_s.as_str(), "--json"];
    let calib_s = calib.map(|c| c.display().to_string()).unwrap_or_default();
    if back == Back::Given && calib.is_some() {
        again_args.extend(["--calib", calib_s.as_str()]);
    }
    let again = ringscan(&again_args);
    for k in ["sweeps", "points"] {
        assert_eq!(again[k], wrote[k], "{k}: bag vs capture");
    }
    if back == Back::Attached {
        assert_eq!(
            again["sensors"][0]["calibration"],
            calib_name.as_str(),
            "{again}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
    (a.len(), points)
}

#[test]
fn velodyne_packets_round_trip_through_a_ros2_bag() {
    let pcap = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo-vlp16.pcap");
    // VelodyneScan holds the 1206-byte data packets (port 2368) only.
    let (sweeps, points) = round_trip(&pcap, None, Back::Given, |d| d.2.len() == 1206);
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
    let (sweeps, points) = round_trip(&pcap, Some(&json), Back::FromBag, |_| true);
    eprintln!("OS-0-32: {sweeps} sweeps, {points} points through the bag");
}

#[test]
fn hesai_packets_round_trip_through_a_ros2_bag() {
    let Some(root) = common::captures() else {
        eprintln!("SKIP: ../shared/captures not found");
        return;
    };
    let nebula = root.join("tier4__nebula/src/nebula_hesai");
    let pcap = nebula.join(
        "nebula_hesai/test_resources/decoder_ground_truth/xt32/1673400677802009732/1673400677802009732_0.pcap",
    );
    let csv = nebula.join("nebula_hesai_decoders/calibration/PandarXT32.csv");
    let (sweeps, points) = round_trip(&pcap, Some(&csv), Back::Given, |_| true);
    assert!(sweeps >= 1, "{sweeps} sweeps");
    eprintln!("XT32: {sweeps} sweeps, {points} points through the bag");
    // The same bag decoded without --calib: the angle correction attached to it serves.
    let (sweeps, points) = round_trip(&pcap, Some(&csv), Back::Attached, |_| true);
    eprintln!("XT32: {sweeps} sweeps, {points} points through the bag, with its attachment");
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
    // Bad usage, as a directory or device given for an MCAP file is (exit 2).
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("already holds a rosbag2"), "{err}");
    assert_eq!(std::fs::read(bag.join("metadata.yaml")).unwrap(), b"x");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Whether ROS 2 takes `name` as a full topic name, checked from the rules of rmw's
/// `rmw_validate_full_topic_name` (written here from its documentation, not from ringscan):
/// starts with `/`, does not end with one, no empty token, only ASCII letters, digits, `_`
/// and `/`, and no token starting with a digit.
fn ros2_accepts(name: &str) -> bool {
    let Some(rest) = name.strip_prefix('/') else {
        return false;
    };
    !rest.is_empty()
        && rest.split('/').all(|token| {
            token.chars().next().is_some_and(|c| !c.is_ascii_digit())
                && token.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        })
}

/// Two sensors in one `--format ros2` bag: each sensor's topics carry its name, and ROS 2 must
/// take them (the default names hold `-`: `/vlp16-201/points` was written, which ROS 2
/// refuses, so `ros2 bag play` published none of it). The MCAP's channels and the yaml
/// agree, and the frame id keeps the sensor's name.
#[test]
fn two_sensors_get_topic_names_ros2_takes() {
    use ringscan::sim::net::{udp_frame, PcapWriter};
    use std::net::{Ipv4Addr, SocketAddrV4};
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo-vlp16.pcap");
    let dir = temp_dir("two-sensors");
    let mut w = PcapWriter::new(Vec::new()).unwrap();
    for (t, port, payload) in common::datagrams(&demo) {
        for last in [201, 202] {
            let src = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, last), port);
            let dst = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 100), port);
            w.write(t + i64::from(last - 201), &udp_frame(src, dst, 0, &payload))
                .unwrap();
        }
    }
    let pcap = dir.join("two.pcap");
    std::fs::write(&pcap, w.into_inner().unwrap()).unwrap();
    let bag = dir.join("bag");
    let j = ringscan(&[
        "decode",
        pcap.to_str().unwrap(),
        "--format",
        "ros2",
        "--json",
        "--out",
        bag.to_str().unwrap(),
    ]);
    assert_eq!(j["sensors"].as_array().map(Vec::len), Some(2), "{j}");
    let yaml = std::fs::read_to_string(bag.join("metadata.yaml")).unwrap();
    let topics: Vec<&str> = yaml
        .lines()
        .filter_map(|l| l.trim().strip_prefix("name: "))
        .map(|n| n.trim_matches('"'))
        .collect();
    assert!(topics.len() >= 4, "{yaml}");
    for t in &topics {
        assert!(ros2_accepts(t), "ROS 2 refuses the topic {t}");
    }
    for name in ["vlp16-201", "vlp16-202"] {
        let topic = format!("/{}/points", name.replace('-', "_"));
        assert!(
            topics.contains(&topic.as_str()),
            "{topic} not in {topics:?}"
        );
    }
    let bytes = std::fs::read(bag.join("bag_0.mcap")).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let mut channels: Vec<&str> = summary
        .channels
        .values()
        .map(|c| c.topic.as_str())
        .collect();
    channels.sort_unstable();
    let mut listed = topics.clone();
    listed.sort_unstable();
    assert_eq!(channels, listed);
    let _ = std::fs::remove_dir_all(&dir);
}
