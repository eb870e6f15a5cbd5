//! The real RS-Helios-16P capture of nebula PR #79 (`../shared/captures/NEBULA.md`, section
//! "Robosense RS-Helios-16P") against the four point clouds that decoder wrote.
//!
//! The converted pcap (750 MSOP + 1 DIFOP) is streamed through [`RobosenseStream`] with
//! `RobosenseHelios16P.csv`, cut at 0°, the model's range (0.1–180 m) and nebula's driver
//! minimum of 0.2 m (`--min-range 0.2`: the clouds have no return under it, the packets do). Sweep k is
//! the scan of bag message k (each message ends with the packet where the block azimuth passes
//! 0°). Against each PCD (fields `x y z intensity return_type channel azimuth elevation distance
//! time_stamp`; nebula's frame is REP 103 like ringscan's):
//!
//! - the same number of points, and in order: intensity exact, `channel` = ring exact, x y z
//!   within 1 mm — except where nebula's elevation for a laser is not the file's: nebula turns
//!   `8.90` into 889 (0.01°) by truncating `8.90f · 100` (= 889.99994); the CSV and the
//!   sensor's own DIFOP (bytes `00 03 7A` = +8.90°) say 890, and ringscan uses 8.90°. On that
//!   laser the tolerance is 1 mm + d · sin 0.01° (the z difference the 0.01° makes at range d),
//!   and the test checks that nebula's `elevation` field there is 889 — the deviation and its
//!   cause, not a loose tolerance elsewhere. `tests/robosense_handbuilt.rs` decodes a packet
//!   with that DIFOP entry by hand.
//! - nebula's `azimuth` (0.01°) and `distance` fields against the decoder's own: exact (the
//!   distance to the 8 significant digits of the ASCII file).
//!
//! Per-point time: nebula's `time_stamp` holds only the header's whole seconds (1483724884 in
//! every point; NEBULA.md); ringscan's is checked against the packet headers as the manual
//! says — the header's Unix time (bytes 20–25 seconds, 26–29 µs, big-endian) read here by hand,
//! plus block × 55.56 µs, plus the slot's firing offset from the Helios-16P table.
//!
//! The same capture decoded without the CSV (angles from the DIFOP, the 543 packets before it
//! held) gives the same points; the rosbag2 `.db3` (`robosense_msgs/msg/RobosenseScan`) gives the
//! same points as the pcap.

mod common;

use std::path::{Path, PathBuf};

use ringscan::sensor::robosense::family::parse_robosense_calibration;
use ringscan::sensor::robosense::{RobosenseConfig, RobosenseModel, RobosenseStream};
use ringscan::sensor::DecodeOptions;
use ringscan::sweep::Sweep;

const DIR: &str = "tier4__nebula__pr79/nebula_tests/data/robosense/helios16P";
const CSV: &str =
    "tier4__nebula__pr79/nebula_decoders/calibration/robosense/RobosenseHelios16P.csv";
const PCDS: [(&str, usize); 4] = [
    ("1691031766781547066.pcd", 15_258),
    ("1691031766880833506.pcd", 15_795),
    ("1691031766980937333.pcd", 15_786),
    ("1691031767081713313.pcd", 15_708),
];

/// The clouds hold no return under 0.2 m (min 0.2025 m) though the packets do (from 0.005 m):
/// nebula's driver range, 0.2 m, on top of the decoder's own 0.1 m. ringscan's `--min-range`.
const NEBULA_RANGE: DecodeOptions = DecodeOptions {
    min_range: 0.2,
    max_range: f32::INFINITY,
};

/// The Helios-16P firing offsets of the 32 slots, µs (RoboSense's table for this model in its
/// SDK up to 1.5.13, the generation of this capture).
const FIRING_US: [f64; 32] = [
    0.00, 3.15, 6.30, 9.45, 13.26, 17.08, 20.56, 23.71, 26.53, 27.77, 31.49, 32.73, 36.46, 38.94,
    41.42, 43.91, 55.56, 58.70, 61.85, 65.00, 68.82, 72.64, 76.12, 79.27, 82.08, 83.32, 87.05,
    88.29, 92.01, 94.50, 96.98, 99.46,
];

struct PcdPoint {
    xyz: [f32; 3],
    intensity: u8,
    channel: u16,
    azimuth: f32,
    elevation: f32,
    distance: f32,
}

fn read_pcd(path: &Path) -> Vec<PcdPoint> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    for l in lines.by_ref() {
        if l.starts_with("DATA") {
            assert_eq!(l.trim(), "DATA ascii");
            break;
        }
    }
    lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            assert_eq!(f.len(), 10, "{l}");
            let g = |i: usize| f[i].parse::<f32>().unwrap();
            PcdPoint {
                xyz: [g(0), g(1), g(2)],
                intensity: f[3].parse().unwrap(),
                channel: f[5].parse().unwrap(),
                azimuth: g(6),
                elevation: g(7),
                distance: g(8),
            }
        })
        .collect()
}

fn root() -> Option<PathBuf> {
    let r = common::captures()?;
    if !r.join(DIR).is_dir() {
        eprintln!("SKIP: {} absent", r.join(DIR).display());
        return None;
    }
    Some(r)
}

fn pcap_path(r: &Path) -> PathBuf {
    r.join(DIR)
        .join("rosbag2_2023_08_03-11_02_46/rosbag2_2023_08_03-11_02_46_0.pcap")
}

/// Streams datagrams; returns the sweeps (owned) and the stream.
fn stream(
    dgrams: &[(i64, u16, Vec<u8>)],
    with_csv: Option<&Path>,
) -> (Vec<Sweep>, RobosenseStream) {
    let angles = with_csv.map(|p| {
        let mut a = parse_robosense_calibration(&std::fs::read(p).unwrap())
            .expect("recognised")
            .expect("valid");
        a.source = "RobosenseHelios16P.csv".into();
        a
    });
    let mut cfg = RobosenseConfig::new(angles);
    cfg.options = NEBULA_RANGE;
    let mut s = RobosenseStream::new(cfg);
    let mut out = Vec::new();
    for (t, _, p) in dgrams {
        s.push(*t, p, &mut |sw, _| out.push(sw.clone())).unwrap();
    }
    s.finish(&mut |sw, _| out.push(sw.clone()));
    (out, s)
}

/// Header time of a Helios MSOP, read by hand: bytes 20–25 seconds, 26–29 µs, big-endian.
fn header_ns(p: &[u8]) -> i64 {
    let s = p[20..26].iter().fold(0i64, |a, &b| a * 256 + i64::from(b));
    let us = p[26..30].iter().fold(0i64, |a, &b| a * 256 + i64::from(b));
    s * 1_000_000_000 + us * 1_000
}

#[test]
fn helios16p_matches_nebula_pr79() {
    let Some(r) = root() else { return };
    let dgrams = common::datagrams(&pcap_path(&r));
    assert_eq!(dgrams.len(), 751);
    let (sweeps, s) = stream(&dgrams, Some(&r.join(CSV)));
    assert_eq!(s.facts().model, Some(RobosenseModel::Helios16P));
    assert_eq!(s.facts().return_mode, Some(0x04));
    assert_eq!(s.facts().rpm, Some(600));
    assert_eq!(s.stats().malformed, 0);
    assert_eq!(s.stats().difop, 1);
    assert_eq!(s.stats().missing, 0);
    assert!(sweeps.len() >= 4, "{} sweeps", sweeps.len());
    let mut deviating = 0usize;
    for (k, (file, count)) in PCDS.iter().enumerate() {
        let exp = read_pcd(&r.join(DIR).join(file));
        assert_eq!(exp.len(), *count, "{file}");
        let got = &sweeps[k].points;
        assert_eq!(got.len(), exp.len(), "sweep {k} vs {file}");
        let mut max_err = 0f32;
        for (i, (g, e)) in got.iter().zip(&exp).enumerate() {
            assert_eq!(g.intensity, f32::from(e.intensity), "{file} point {i}");
            assert_eq!(g.ring, e.channel, "{file} point {i}");
            assert_eq!(g.ret, 0);
            let err =
                ((g.x - e.xyz[0]).powi(2) + (g.y - e.xyz[1]).powi(2) + (g.z - e.xyz[2]).powi(2))
                    .sqrt();
            let tol = if e.elevation == 889.0 {
                deviating += 1;
                1e-3 + e.distance * 0.01f32.to_radians().sin()
            } else {
                max_err = max_err.max(err);
                1e-3
            };
            assert!(
                err <= tol,
                "{file} point {i}: {:?} vs {:?} ({err} m)",
                (g.x, g.y, g.z),
                e.xyz
            );
        }
        println!(
            "{file}: {} points, max xyz error {:.3} mm (off the 8.90° laser)",
            got.len(),
            max_err * 1e3
        );
    }
    println!("points on the 8.90° laser (nebula: 8.89°): {deviating}");
    assert!(deviating > 0);
}

#[test]
fn helios16p_fields_and_times_follow_the_headers() {
    let Some(r) = root() else { return };
    let dgrams = common::datagrams(&pcap_path(&r));
    let a = parse_robosense_calibration(&std::fs::read(r.join(CSV)).unwrap())
        .unwrap()
        .unwrap();
    let dec = ringscan::sensor::robosense::RobosenseDecoder::new(
        RobosenseModel::Helios16P,
        &a,
        NEBULA_RANGE,
    )
    .unwrap();
    // Expected absolute time of every decoded point, in stream order.
    let mut expect_t = Vec::new();
    let mut fields = Vec::new();
    for (_, _, p) in dgrams.iter().filter(|d| d.2[0] == 0x55) {
        let m = ringscan::sensor::robosense::Msop::new(p, RobosenseModel::Helios16P).unwrap();
        let h = header_ns(p);
        dec.decode(&m, false, |d| {
            let t = h + d.block as i64 * 55_560 + (FIRING_US[d.slot] * 1_000.0).round() as i64;
            expect_t.push(t);
            fields.push((d.azimuth_cdeg, f32::from(d.raw) * 0.0025));
        });
    }
    let (sweeps, _) = stream(&dgrams, Some(&r.join(CSV)));
    let mut i = 0;
    for sw in &sweeps {
        for p in &sw.points {
            let t = sw.device_time_ns + i64::from(p.t);
            assert!(
                (t - expect_t[i]).abs() <= 1,
                "point {i}: {t} vs {}",
                expect_t[i]
            );
            i += 1;
        }
    }
    assert_eq!(i, expect_t.len());
    // nebula's azimuth and distance fields, point for point.
    let mut j = 0;
    for (k, (file, _)) in PCDS.iter().enumerate() {
        let exp = read_pcd(&r.join(DIR).join(file));
        for e in &exp {
            let (az, dist) = fields[j];
            assert_eq!(
                az.rem_euclid(36_000) as f32,
                e.azimuth.rem_euclid(36_000.0),
                "{file}"
            );
            // The PCD is ASCII with 8 significant digits: equal to that precision.
            assert!(
                (dist - e.distance).abs() <= 1e-7 * dist.max(1.0),
                "{file}: {dist} vs {}",
                e.distance
            );
            j += 1;
        }
        assert_eq!(
            j,
            sweeps[..=k].iter().map(|s| s.points.len()).sum::<usize>()
        );
    }
}

#[test]
fn helios16p_from_difop_alone_and_from_the_bag() {
    let Some(r) = root() else { return };
    let dgrams = common::datagrams(&pcap_path(&r));
    let (with_csv, _) = stream(&dgrams, Some(&r.join(CSV)));
    let (difop_only, s) = stream(&dgrams, None);
    assert_eq!(
        s.facts().model,
        Some(RobosenseModel::Helios16P),
        "{}",
        s.facts().detection
    );
    assert_eq!(s.facts().calibration, "DIFOP");
    assert_eq!(s.stats().dropped, 0);
    assert_eq!(with_csv.len(), difop_only.len());
    for (a, b) in with_csv.iter().zip(&difop_only) {
        assert_eq!(a.points, b.points);
    }
    let bag = r
        .join(DIR)
        .join("rosbag2_2023_08_03-11_02_46/rosbag2_2023_08_03-11_02_46_0.db3");
    let bdg = common::bag_datagrams(&bag);
    assert_eq!(bdg.len(), 751);
    let (from_bag, _) = stream(&bdg, Some(&r.join(CSV)));
    assert_eq!(from_bag.len(), with_csv.len());
    for (a, b) in with_csv.iter().zip(&from_bag) {
        assert_eq!(a.points, b.points);
    }
}

#[test]
fn helios16p_through_the_family_interface() {
    use ringscan::sensor::{
        claim, parse_calibration, CalibrationPool, FirstDatagram, StreamSettings,
    };
    let Some(r) = root() else { return };
    let dgrams = common::datagrams(&pcap_path(&r));
    let csv = std::fs::read(r.join(CSV)).unwrap();
    let cal = parse_calibration(&csv, "RobosenseHelios16P.csv", None).unwrap();
    assert_eq!(cal.family, "robosense");
    let f = ringscan::sensor::family("robosense").unwrap();
    assert_eq!(f.default_ports(), &[6699, 7788]);
    assert_eq!(f.calibration_ports(&cal), vec![6699, 7788]);
    let settings = StreamSettings {
        decode: NEBULA_RANGE,
        ..StreamSettings::default()
    };
    let mut pool = CalibrationPool::new(vec![cal], settings);
    let first = FirstDatagram {
        src: std::net::Ipv4Addr::new(192, 168, 1, 200),
        port: dgrams[0].1,
        payload: &dgrams[0].2,
    };
    assert_eq!(dgrams[0].1, 6699);
    let mut s = claim(&first, &mut pool).expect("claimed").expect("stream");
    let mut sizes = Vec::new();
    for (t, _, p) in &dgrams {
        s.push(*t, p, &mut |sw, _| sizes.push(sw.points.len()))
            .unwrap();
    }
    s.finish(&mut |sw, _| sizes.push(sw.points.len())).unwrap();
    assert_eq!(&sizes[..4], &[15_258, 15_795, 15_786, 15_708]);
    let (v, counts) = s.summary();
    assert_eq!(v["kind"], "robosense");
    assert_eq!(v["model"], "RS-Helios-16P");
    assert_eq!(v["return_mode"], "strongest (0x04)");
    assert_eq!(v["motor_rpm"], 600);
    assert_eq!(v["serial"], "2410bac9d50b");
    assert!(
        v["clock_state"]
            .as_str()
            .unwrap()
            .starts_with("header Unix time"),
        "{v}"
    );
    assert!(
        v["clock_state"].as_str().unwrap().contains("free-running"),
        "{v}"
    );
    assert_eq!(
        (counts.decoded, counts.missing, counts.malformed),
        (750, 0, 0)
    );
    assert_eq!(
        s.facts().default_name(first.src),
        "rshelios16p-2410bac9d50b"
    );
    assert_eq!(s.channels(), Some(16));
}

/// `ringscan info` words the DIFOP's facts: the motor speed read here by hand from the DIFOP's
/// bytes 8–9 (big-endian rpm, after the 8-byte header `A5 FF 00 5A 11 11 55 55`), and the
/// firmware and serial of the same run's `--json` summary.
#[test]
fn info_names_the_difop_facts() {
    let Some(r) = root() else { return };
    let pcap = pcap_path(&r);
    let difop = common::datagrams(&pcap)
        .into_iter()
        .find(|(_, port, _)| *port == 7788)
        .expect("a DIFOP on port 7788")
        .2;
    assert_eq!(difop[..8], [0xA5, 0xFF, 0x00, 0x5A, 0x11, 0x11, 0x55, 0x55]);
    let rpm = u16::from_be_bytes([difop[8], difop[9]]);
    let run = |json: bool| {
        let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_ringscan"));
        c.arg("info").arg(&pcap);
        if json {
            c.arg("--json");
        }
        let out = c.output().unwrap();
        assert!(out.status.success());
        String::from_utf8(out.stdout).unwrap()
    };
    let text = run(false);
    let j: serde_json::Value = serde_json::from_str(&run(true)).unwrap();
    let s = &j["sensors"][0];
    for want in [
        "Robosense RS-Helios-16P".to_string(),
        "750 MSOP + 1 DIFOP packets".to_string(),
        format!("motor {rpm} rpm"),
        format!("firmware {}", s["firmware"].as_str().unwrap()),
        format!("serial {}", s["serial"].as_str().unwrap()),
    ] {
        assert!(text.contains(&want), "{want:?} not in:\n{text}");
    }
    eprintln!("{text}");
}

/// `--raw` keeps every datagram, also the 543 MSOP packets that arrive before the DIFOP tells
/// the model (held, then written once the sensor is known); `--format ros2`, which has no
/// Robosense packet message, writes none and says how many.
#[test]
fn raw_keeps_every_datagram_and_ros2_counts_what_it_cannot_hold() {
    let Some(r) = root() else { return };
    let pcap = pcap_path(&r);
    let datagrams = common::datagrams(&pcap).len() as u64;
    let dir = common::Scratch::dir("robosense-raw");
    for format in ["foxglove", "ros2"] {
        let out = dir.join(format!("{format}.mcap"));
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_ringscan"))
            .arg("decode")
            .arg(&pcap)
            .args(["--raw", "--json", "--format", format, "--out"])
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let (written, dropped) = (&j["output"]["topics"]["/raw"], &j["output"]["raw_dropped"]);
        assert_eq!(j["sensors"][0]["raw_dropped"], 0, "{format}");
        match format {
            "foxglove" => assert_eq!(
                (written.as_u64(), dropped.as_u64()),
                (Some(datagrams), Some(0))
            ),
            _ => assert_eq!(
                (written.as_u64(), dropped.as_u64()),
                (None, Some(datagrams))
            ),
        }
    }
}
