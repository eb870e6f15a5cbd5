//! A simulated Livox MID-360 with its IMU through the live path: `ringscan listen` on loopback,
//! fed by `ringscan replay`, with `--pipeline default --deskew imu --odometry`, against
//! `ringscan decode` of the same capture with the same flags, and both against the
//! simulator's truth.
//!
//! The sensor turns on the spot in the urban scene at a yaw rate that swings between 0 and
//! 120 °/s (1.5 Hz) with a rolling sway (±20 °/s, 2 Hz): the gyro changes within a sweep, so
//! an IMU sample that reached the deskewer in one path and not in the other shows in the
//! points. There is no translation: `--pipeline default` deskews with the IMU's rotation and
//! the configuration's linear velocity (zero); tests/livox_sim.rs covers a 15 m/s drive with
//! the velocity given.
//!
//! Proven here:
//! - live = decode: the same sweeps, their points byte for byte (deskewed), the same IMU
//!   messages, and the same pipeline (`/ground`, `/obstacles`, `/clusters`) and odometry
//!   (`/tf`, `/map`) messages, timestamps aside (`decode` stamps from the capture, `listen`
//!   from the host), across `--split-every` files.
//! - the IMU deskew against the truth: each point of the live sweeps, moved into the world
//!   with the true pose at its sweep's stamp, lands within 2 cm of the scene point the
//!   simulator's ray hit (99th percentile), where the same points undeskewed (`decode
//!   --deskew none`) miss by more than 0.5 m. The figures are printed.
//!
//! The truth (ray-cast scene, trajectory, the simulator's per-return records) is independent
//! of the decoder and the deskew; the IMU motion reaches `deskew` only through the IMU packets.
#![cfg(feature = "sim")]

mod listen_util;

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::net::{Ipv4Addr, SocketAddrV4};
use std::path::{Path, PathBuf};
use std::time::Duration;

use listen_util::*;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use prost::Message as _;
use ringscan::sensor::livox::model::LivoxModel;
use ringscan::sensor::livox::sim::{LivoxSim, LivoxTruth};
use ringscan::sim::motion::{PoseTable, Trajectory};
use ringscan::sim::net::{udp_frame, PcapWriter};
use ringscan::sim::scenes;
use ringscan::sink::read::PointCloud;

const T0: i64 = 1_714_564_800_000_000_000;
const SECONDS: f64 = 1.2;

/// Turning on the spot: yaw rate 60 + 60·sin(2π·1.5 t) °/s, roll rate 20·sin(2π·2 t) °/s,
/// sampled every ms (the simulator interpolates the table and differentiates it for the IMU).
fn swaying() -> Trajectory {
    use std::f64::consts::TAU;
    let (w0, a, f1) = (60f64.to_radians(), 60f64.to_radians(), 1.5);
    let (b, f2) = (20f64.to_radians(), 2.0);
    let poses = (-20..=((SECONDS + 0.1) * 1000.0) as i64)
        .map(|ms| {
            let t = ms as f64 * 1e-3;
            let yaw = w0 * t + a / (TAU * f1) * (1.0 - (TAU * f1 * t).cos());
            let roll = b / (TAU * f2) * (1.0 - (TAU * f2 * t).cos());
            let r = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw)
                * UnitQuaternion::from_euler_angles(roll, 0.0, 0.0);
            (
                T0 + ms * 1_000_000,
                Isometry3::from_parts(Translation3::new(40.0, 0.0, scenes::SENSOR_HEIGHT_M), r),
            )
        })
        .collect();
    Trajectory::poses(PoseTable::new(poses))
}

/// Writes the capture (points from 192.168.1.12:56300 to 56301, IMU from :56400 to 56401, as
/// the MID-360 sends them) and returns the truth of every return, in packet order.
fn simulate(pcap: &Path) -> (Vec<LivoxTruth>, Trajectory) {
    let mut sim = LivoxSim::new(LivoxModel::Mid360, T0);
    sim.trajectory = swaying();
    let (mut truth, mut imu) = (Vec::new(), Vec::new());
    let packets = sim.run_until(
        &scenes::urban(),
        T0 + (SECONDS * 1e9) as i64,
        &mut truth,
        &mut imu,
    );
    assert!(imu.len() >= 200, "{} IMU packets", imu.len());
    let ip = Ipv4Addr::new(192, 168, 1, 12);
    let mut w = PcapWriter::new(BufWriter::new(File::create(pcap).unwrap())).unwrap();
    for (i, (host, port, bytes)) in packets.iter().enumerate() {
        let src = SocketAddrV4::new(ip, port - 1);
        let dst = SocketAddrV4::new(Ipv4Addr::BROADCAST, *port);
        w.write(*host, &udp_frame(src, dst, i as u16, bytes))
            .unwrap();
    }
    w.into_inner().unwrap();
    (truth, sim.trajectory.clone())
}

/// Messages per topic, in file order, without stamps and without `/diagnostics` (host health).
fn payloads(files: &[PathBuf]) -> BTreeMap<String, Vec<Vec<u8>>> {
    let mut out: BTreeMap<String, Vec<Vec<u8>>> = BTreeMap::new();
    for f in files {
        let bytes = std::fs::read(f).unwrap();
        for m in mcap::MessageStream::new(&bytes).expect("mcap") {
            let m = m.expect("message");
            let t = m.channel.topic.clone();
            if !t.ends_with("/diagnostics") && t != "/tf_static" {
                let v = without_stamps(&t, &m.data);
                out.entry(t).or_default().push(v);
            }
        }
    }
    out
}

/// Each sweep of the `/points` topic: its stamp (ns) and points (x, y, z).
fn sweeps(files: &[PathBuf]) -> Vec<(i64, Vec<[f32; 3]>)> {
    let mut out = Vec::new();
    for f in files {
        let bytes = std::fs::read(f).unwrap();
        for m in mcap::MessageStream::new(&bytes).expect("mcap") {
            let m = m.expect("message");
            if !m.channel.topic.ends_with("/points") {
                continue;
            }
            let pc = PointCloud::decode(&m.data[..]).unwrap();
            let ts = pc.timestamp.unwrap();
            let off = |n: &str| {
                pc.fields
                    .iter()
                    .find(|f| f.name == n)
                    .map(|f| f.offset as usize)
                    .unwrap()
            };
            let o = [off("x"), off("y"), off("z")];
            let f32_at = |r: &[u8], o: usize| f32::from_le_bytes(r[o..o + 4].try_into().unwrap());
            let pts = pc
                .data
                .chunks_exact(pc.point_stride as usize)
                .map(|r| o.map(|o| f32_at(r, o)))
                .collect();
            out.push((ts.seconds * 1_000_000_000 + i64::from(ts.nanos), pts));
        }
    }
    out
}

/// Median and 99th percentile of |world_from_sensor(stamp) · p − truth|, metres, over every
/// point of every sweep (points and truth in the same order).
fn world_errors(
    sweeps: &[(i64, Vec<[f32; 3]>)],
    truth: &[LivoxTruth],
    traj: &Trajectory,
) -> (f64, f64) {
    let mut d = Vec::new();
    let mut k = 0;
    for (stamp, pts) in sweeps {
        let pose = traj.pose(*stamp);
        for p in pts {
            let q = pose * Point3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
            d.push((q.coords - Vector3::from(truth[k].world)).norm());
            k += 1;
        }
    }
    assert_eq!(k, truth.len());
    d.sort_by(f64::total_cmp);
    let at = |f: f64| d[((d.len() - 1) as f64 * f).round() as usize];
    (at(0.5), at(0.99))
}

fn flags() -> Vec<String> {
    [
        "--name",
        "mid360",
        "--pipeline",
        "default",
        "--deskew",
        "imu",
        "--odometry",
        "--map-every",
        "2",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

#[test]
fn mid360_with_imu_listen_equals_decode_and_imu_deskew_meets_the_truth() {
    let _g = serial();
    let dir = std::env::temp_dir().join(format!("ringscan-livox-live-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let pcap = dir.join("mid360.pcap");
    let (truth, traj) = simulate(&pcap);

    let decoded = decode(&pcap, &dir.join("d.mcap"), &flags());
    let want = payloads(&[dir.join("d.mcap")]);
    for t in [
        "/points",
        "/imu",
        "/ground",
        "/obstacles",
        "/clusters",
        "/tf",
        "/map",
    ] {
        assert!(
            want.iter().any(|(k, v)| k.ends_with(t) && !v.is_empty()),
            "decode wrote no {t}: {:?}",
            want.keys()
        );
    }
    assert_eq!(decoded["pipeline"]["deskew"], "imu");
    assert_eq!(
        decoded["pipeline"]["deskew_skipped"], 0,
        "{}",
        decoded["pipeline"]
    );

    let offset = free_offset(&[56_301, 56_401]);
    let base = dir.join("live.mcap");
    let mut args = vec![
        "--sensor".to_string(),
        format!("127.0.0.1:{}", 56_301 + offset),
        "--sensor".to_string(),
        format!("127.0.0.1:{}", 56_401 + offset),
        "--out".to_string(),
        base.display().to_string(),
        "--split-every".to_string(),
        "0.4s".to_string(),
    ];
    if offset != 0 {
        // The MID-360 is told by its ports; moved ports need the model named.
        args.extend(["--model".to_string(), "mid360".to_string()]);
    }
    args.extend(flags());
    let l = start_listen(&args);
    replay(&pcap, offset, "1", &[]);
    std::thread::sleep(Duration::from_millis(300));
    let (code, stdout, err) = l.stop("INT");
    assert_eq!(code, Some(0), "{err}");
    let j: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(j["receive"]["queue_dropped"], 0);
    assert_eq!(j["receive"]["kernel_dropped"], 0);
    assert_eq!(j["sweeps"], decoded["sweeps"]);
    assert_eq!(j["points"], decoded["points"]);
    assert_eq!(j["pipeline"]["sweeps"], decoded["pipeline"]["sweeps"]);
    assert_eq!(j["pipeline"]["deskew_skipped"], 0, "{}", j["pipeline"]);
    assert_eq!(
        j["odometry"]["registered"], decoded["odometry"]["registered"],
        "{}",
        j["odometry"]
    );
    let files: Vec<PathBuf> = j["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| PathBuf::from(f["path"].as_str().unwrap()))
        .collect();
    assert!(files.len() >= 2, "{} files: no split to test", files.len());
    let got = payloads(&files);
    assert_eq!(
        got.keys().collect::<Vec<_>>(),
        want.keys().collect::<Vec<_>>()
    );
    // Sweeps and IMU first: a difference there explains any downstream.
    let mut topics: Vec<&String> = want.keys().collect();
    topics.sort_by_key(|t| !(t.ends_with("/points") || t.ends_with("/imu")));
    for t in topics {
        let (g, v) = (&got[t], &want[t]);
        assert_eq!(g.len(), v.len(), "{t}: messages, listen vs decode");
        for (i, (a, b)) in g.iter().zip(v).enumerate() {
            assert!(a == b, "{t}: message {i} differs from decode's");
        }
    }

    // Against the truth: the live sweeps (IMU-deskewed) and the same capture undeskewed.
    let live = sweeps(&files);
    let n: usize = live.iter().map(|s| s.1.len()).sum();
    assert_eq!(n, truth.len(), "every simulated return once");
    let mut raw_flags = flags();
    raw_flags[5] = "none".to_string();
    decode(&pcap, &dir.join("raw.mcap"), &raw_flags);
    let raw = sweeps(&[dir.join("raw.mcap")]);
    // The undeskewed points are the sensor-frame truth (1 mm records): the order matches.
    let mut k = 0;
    for (_, pts) in &raw {
        for p in pts {
            let t = truth[k].xyz;
            for c in 0..3 {
                assert!(
                    (f64::from(p[c]) - t[c]).abs() <= 0.000_6 + 1e-6 * t[c].abs(),
                    "point {k}: {p:?} vs {t:?}"
                );
            }
            k += 1;
        }
    }
    let none = world_errors(&raw, &truth, &traj);
    let got = world_errors(&live, &truth, &traj);
    eprintln!(
        "MID-360 listen --deskew imu ({} sweeps, {n} points): median {:.2} mm, p99 {:.2} mm; \
         without deskew median {:.1} mm, p99 {:.1} mm",
        live.len(),
        got.0 * 1e3,
        got.1 * 1e3,
        none.0 * 1e3,
        none.1 * 1e3
    );
    assert!(got.1 <= 0.02, "IMU deskew p99 {} m > 2 cm", got.1);
    assert!(none.1 > 0.5, "the rotation must matter without deskew");
    let _ = std::fs::remove_dir_all(&dir);
}
