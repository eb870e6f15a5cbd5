//! `ringscan decode --odometry`:
//! - on the real VLP-16 capture (`vlp-16-test-90deg-1-50-frames.pcap`, VLP16db.yaml), `/tf`
//!   holds one `foxglove.FrameTransform` per sweep, parent `odom`, child the sensor's frame
//!   (the frame of its point clouds); the `--trajectory` TUM file holds one pose per
//!   registered sweep (the `--json` count) and each equals the `/tf` message of that stamp;
//!   `/map` (a point cloud in `odom`) is written every `--map-every` sweeps; every
//!   `/diagnostics` message carries the sweep's `odometry` object; `--json` has the
//!   `odometry` object with its counts adding up; with `--extrinsics` `/tf` is
//!   `odom → base_link`, the sensor's poses conjugated by the extrinsics (checked by hand for a
//!   90° yaw);
//! - on a simulated VLP-16 drive (`ringscan::sim`, the urban scene, 10 m/s turning 15 °/s,
//!   3 s) decoded with `--deskew odometry`, the trajectory ends within 1 % of the distance
//!   travelled of the simulator's true pose at the same time (the truth taken relative to
//!   the pose at the trajectory's first stamp, the odometry's `odom`).
//! - with `--serve`, a Foxglove WebSocket subscriber to `/tf` receives the MCAP's last `/tf`
//!   messages byte for byte.
//! - on a simulated Ouster with IMU over an empty floor (no yaw information), the IMU stream's
//!   rotation prior keeps every sweep-to-sweep rotation within 2σ of the truth, where without it
//!   the turn is missed.

mod common;
mod foxglove_msgs;

use std::collections::BTreeMap;
use std::net::{Ipv4Addr, SocketAddrV4};
use std::path::{Path, PathBuf};
use std::process::Command;

use foxglove_msgs::*;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use prost::Message as _;
use ringscan::sensor::velodyne::calib::builtin::builtin;
use ringscan::sensor::velodyne::sim::VelodyneSim;
use ringscan::sensor::velodyne::ReturnMode;
use ringscan::sensor::velodyne::VelodyneModel;
use ringscan::sim::motion::Trajectory;
use ringscan::sim::net::udp_frame;
use ringscan::sim::net::PcapWriter;
use ringscan::sim::scenes;

fn out_path(name: &str) -> PathBuf {
    foxglove_msgs::out_path("odometry-cli", name)
}

/// Message bodies per topic, in file order.
fn read(path: &Path) -> ByTopic {
    read_mcap(path).0
}

/// TUM lines: (t s, pose).
fn read_tum(path: &Path) -> Vec<(f64, Isometry3<f64>)> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|s| s.parse().unwrap()).collect();
            assert_eq!(v.len(), 8, "TUM line {l:?}");
            (
                v[0],
                Isometry3::from_parts(
                    Translation3::new(v[1], v[2], v[3]),
                    UnitQuaternion::from_quaternion(Quaternion::new(v[7], v[4], v[5], v[6])),
                ),
            )
        })
        .collect()
}

fn stamp_ns(t: &Option<prost_types::Timestamp>) -> i64 {
    let t = t.as_ref().unwrap();
    t.seconds * 1_000_000_000 + i64::from(t.nanos)
}

#[test]
fn real_vlp16_capture_writes_tf_map_trajectory_and_summary() {
    let Some(root) = common::captures() else {
        return;
    };
    let pcap = root.join("Kitware__VeloView/Testing/Data/vlp-16-test-90deg-1-50-frames.pcap");
    let calib = root.join("ros-drivers__velodyne/velodyne_pointcloud/params/VLP16db.yaml");
    let (out, tum) = (out_path("real.mcap"), out_path("real.tum"));
    let o = ringscan(&[
        "decode",
        pcap.to_str().unwrap(),
        "--model",
        "vlp16",
        "--calib",
        calib.to_str().unwrap(),
        "--odometry",
        "--trajectory",
        tum.to_str().unwrap(),
        "--map-every",
        "10",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let odo = &summary["odometry"];
    let sweeps = summary["sweeps"].as_u64().unwrap();
    let registered = odo["registered"].as_u64().unwrap();
    let failed = odo["failed"].as_u64().unwrap();
    assert_eq!(odo["sweeps"].as_u64(), Some(sweeps), "{odo}");
    assert_eq!(registered + failed, sweeps, "{odo}");
    // The capture's last sweep is a fragment of a few hundred points; the full ones register.
    assert!(registered + 1 >= sweeps && registered >= 50, "{odo}");
    assert!(odo["degenerate"].as_u64().unwrap() <= sweeps, "{odo}");
    let (med, max) = (
        odo["median_ms"].as_f64().unwrap(),
        odo["max_ms"].as_f64().unwrap(),
    );
    assert!(med > 0.0 && med <= max, "{odo}");
    for k in ["x", "y", "z", "qx", "qy", "qz", "qw", "t_s"] {
        assert!(odo["final_pose"][k].is_f64(), "final_pose.{k}: {odo}");
    }

    let topics = read(&out);
    let frame = summary["sensors"][0]["name"].as_str().unwrap().to_string();
    let tf: Vec<FrameTransform> = topics["/tf"]
        .iter()
        .map(|b| FrameTransform::decode(b.as_slice()).unwrap())
        .collect();
    assert_eq!(tf.len() as u64, sweeps, "one /tf message per sweep");
    for m in &tf {
        assert_eq!(m.parent_frame_id, "odom");
        assert_eq!(m.child_frame_id, frame);
    }
    // The child frame is the frame of the sensor's point clouds.
    let first_cloud = PointCloud::decode(topics["/points"][0].as_slice()).unwrap();
    assert_eq!(first_cloud.frame_id, frame);

    let traj = read_tum(&tum);
    assert_eq!(
        traj.len() as u64,
        registered,
        "one TUM pose per registered sweep"
    );
    let by_stamp: BTreeMap<i64, &FrameTransform> =
        tf.iter().map(|m| (stamp_ns(&m.timestamp), m)).collect();
    for (t, pose) in &traj {
        let ns = (t * 1e9).round() as i64;
        // TUM seconds carry 9 decimals; an f64 of 1.4e9 s holds them to ~0.2 µs.
        let m = by_stamp
            .range(ns - 1_000..=ns + 1_000)
            .next()
            .unwrap_or_else(|| panic!("no /tf message at {t}"))
            .1;
        let tr = m.translation.as_ref().unwrap();
        let p = pose.translation.vector;
        assert!(
            (p - Vector3::new(tr.x, tr.y, tr.z)).norm() < 1e-6,
            "TUM {p:?} vs /tf {tr:?} at {t}"
        );
        let r = m.rotation.as_ref().unwrap();
        let q = UnitQuaternion::from_quaternion(Quaternion::new(r.w, r.x, r.y, r.z));
        assert!(q.angle_to(&pose.rotation) < 1e-6);
    }

    let maps = &topics["/map"];
    assert_eq!(maps.len() as u64, sweeps / 10, "/map every 10 sweeps");
    for b in maps {
        let pc = PointCloud::decode(b.as_slice()).unwrap();
        assert_eq!(pc.frame_id, "odom");
        assert!(!pc.data.is_empty() && pc.data.len() % pc.point_stride as usize == 0);
    }

    let diags = &topics["/diagnostics"];
    assert_eq!(diags.len() as u64, sweeps);
    let mut flagged = 0;
    for b in diags {
        let d: serde_json::Value = serde_json::from_slice(b).unwrap();
        let od = &d["odometry"];
        assert!(od["status"].is_string(), "{d}");
        let deg = od["degenerate"].as_bool().unwrap();
        if deg {
            flagged += 1;
            assert!(od["degenerate_axes"].is_array(), "{d}");
        }
    }
    assert_eq!(flagged, odo["degenerate"].as_u64().unwrap());

    // With --extrinsics (the sensor turned 90° left on the vehicle, no lever arm) /tf is
    // odom → base_link, and a pose B·T·B⁻¹ with B = Rz(90°) moves (x, y, z) to (−y, x, z).
    let extr = format!("{frame}=0,0,0,0,0,90");
    let (out_b, tum_b) = (out_path("base.mcap"), out_path("base.tum"));
    let o = ringscan(&[
        "decode",
        pcap.to_str().unwrap(),
        "--model",
        "vlp16",
        "--calib",
        calib.to_str().unwrap(),
        "--pipeline",
        "default",
        "--extrinsics",
        &extr,
        "--odometry",
        "--trajectory",
        tum_b.to_str().unwrap(),
        "--out",
        out_b.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let tf_b: Vec<FrameTransform> = read(&out_b)["/tf"]
        .iter()
        .map(|b| FrameTransform::decode(b.as_slice()).unwrap())
        .collect();
    assert_eq!(tf_b.len(), tf.len());
    for (a, b) in tf.iter().zip(&tf_b) {
        assert_eq!(b.child_frame_id, "base_link");
        let (ta, tb) = (
            a.translation.as_ref().unwrap(),
            b.translation.as_ref().unwrap(),
        );
        assert!(
            (tb.x + ta.y).abs() < 1e-6 && (tb.y - ta.x).abs() < 1e-6 && (tb.z - ta.z).abs() < 1e-6,
            "sensor {ta:?} vs base_link {tb:?}"
        );
    }
    assert_eq!(read_tum(&tum_b).len(), traj.len());
    for p in [&out_b, &tum_b] {
        let _ = std::fs::remove_file(p);
    }

    // A trajectory without --odometry is refused.
    let o = ringscan(&[
        "decode",
        pcap.to_str().unwrap(),
        "--trajectory",
        tum.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--odometry"));
    for p in [&out, &tum] {
        let _ = std::fs::remove_file(p);
    }
}

/// The simulated drive's start time (a top of the hour) and motion.
const T0_NS: i64 = 1_714_564_800_000_000_000;

fn drive() -> Trajectory {
    let start = Isometry3::from_parts(
        Translation3::new(40.0, 0.0, scenes::SENSOR_HEIGHT_M),
        UnitQuaternion::identity(),
    );
    Trajectory::twist(
        T0_NS,
        start,
        Vector3::new(10.0, 0.0, 0.0),
        Vector3::new(0.0, 0.0, 15f64.to_radians()),
    )
}

/// `seconds` of a VLP-16 (built-in calibration, 10 Hz) on `drive()` through the urban scene.
fn simulated_capture(seconds: f64) -> Vec<u8> {
    let calib = builtin(VelodyneModel::Vlp16).unwrap();
    let mut sim = VelodyneSim::new(VelodyneModel::Vlp16, ReturnMode::Strongest, calib, T0_NS);
    sim.trajectory = drive();
    let scene = scenes::urban();
    let mut w = PcapWriter::new(Vec::new()).unwrap();
    let src = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 201), 2368);
    let dst = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 100), 2368);
    let mut truth = Vec::new();
    let packets = (seconds * 1e9 / sim.period_ns()).ceil() as usize;
    for i in 0..packets {
        truth.clear();
        let (t, p) = sim.next_packet(&scene, &mut truth);
        w.write(t, &udp_frame(src, dst, i as u16, &p)).unwrap();
    }
    w.into_inner().unwrap()
}

/// (end error m, end error °, distance travelled m, summary, trajectory).
type DriveResult = (f64, f64, f64, serde_json::Value, Vec<(f64, Isometry3<f64>)>);

/// Decodes the simulated 3 s drive with `args` after the input, writing a trajectory; the
/// end pose's error (m, °) against the truth, the distance travelled, the JSON summary and the
/// trajectory written.
fn simulated_drive_end_error(name: &str, args: &[&str]) -> DriveResult {
    let pcap = out_path(&format!("{name}.pcap"));
    std::fs::write(&pcap, simulated_capture(3.0)).unwrap();
    let tum = out_path(&format!("{name}.tum"));
    let mut all = vec!["decode", pcap.to_str().unwrap(), "--model", "vlp16"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--trajectory", tum.to_str().unwrap(), "--json"]);
    let o = ringscan(&all);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let traj = read_tum(&tum);
    assert!(
        traj.len() >= 25,
        "{} poses: {}",
        traj.len(),
        summary["odometry"]
    );

    let truth = drive();
    let pose_at = |t: f64| truth.pose((t * 1e9).round() as i64);
    let (t_first, _) = traj[0];
    let (t_last, est_last) = *traj.last().unwrap();
    let odom_from_world = pose_at(t_first).inverse();
    let true_last = odom_from_world * pose_at(t_last);
    let travelled: f64 = traj
        .windows(2)
        .map(|w| (pose_at(w[1].0).translation.vector - pose_at(w[0].0).translation.vector).norm())
        .sum();
    let err = (est_last.translation.vector - true_last.translation.vector).norm();
    let rot_err = est_last.rotation.angle_to(&true_last.rotation).to_degrees();
    println!(
        "simulated drive, {args:?}: {} poses over {travelled:.2} m; end error {err:.3} m ({:.3} %), {rot_err:.3}°",
        traj.len(),
        100.0 * err / travelled
    );
    for p in [&pcap, &tum] {
        let _ = std::fs::remove_file(p);
    }
    (err, rot_err, travelled, summary, traj)
}

#[test]
fn simulated_drive_ends_within_one_percent_of_the_truth() {
    let (err, _, travelled, summary, estimated) =
        simulated_drive_end_error("sim", &["--deskew", "odometry"]);
    assert_eq!(summary["odometry"]["deskew"], true, "{summary}");
    assert!(travelled > 20.0, "travelled {travelled} m");
    assert!(
        err <= 0.01 * travelled,
        "end error {err:.3} m over {travelled:.2} m"
    );
    // The distance driven, at the top of the summary as in its sensor's entry, is the length
    // of the trajectory written (summed here from the TUM file).
    let distance = summary["odometry"]["distance_m"].as_f64().unwrap();
    assert_eq!(
        summary["odometry"]["distance_m"],
        summary["odometry"]["sensors"][0]["distance_m"]
    );
    let path: f64 = estimated
        .windows(2)
        .map(|w| (w[1].1.translation.vector - w[0].1.translation.vector).norm())
        .sum();
    assert!(
        (distance - path).abs() <= 1e-6 * path,
        "distance_m {distance} against the trajectory's {path} m: {}",
        summary["odometry"]
    );
}

/// The simulated drive of `seconds` whose first turn (the first sweep: the sensor starts at
/// azimuth 0) sees only a ball 5 m to the sensor's left, 1 m up, with nothing of the street
/// within 2 m; without `ball`, that turn is left out.
fn simulated_capture_after_a_ball(seconds: f64, ball: bool) -> Vec<u8> {
    use ringscan::sim::scene::{Object, Prim, World};
    let calib = builtin(VelodyneModel::Vlp16).unwrap();
    let mut sim = VelodyneSim::new(VelodyneModel::Vlp16, ReturnMode::Strongest, calib, T0_NS);
    sim.trajectory = drive();
    let only_ball = World::new(
        vec![Object::new(
            1,
            Prim::Sphere {
                center: [40.0, 5.0, scenes::SENSOR_HEIGHT_M + 1.0],
                radius: 0.3,
            },
        )],
        100.0,
    );
    let street = scenes::urban();
    let mut w = PcapWriter::new(Vec::new()).unwrap();
    let src = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 201), 2368);
    let dst = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 100), 2368);
    let mut truth = Vec::new();
    let first_turn = (1e8 / sim.period_ns()).ceil() as usize;
    let packets = (seconds * 1e9 / sim.period_ns()).ceil() as usize;
    for i in 0..packets {
        truth.clear();
        let scene: &World = if i < first_turn { &only_ball } else { &street };
        let (t, p) = sim.next_packet(scene, &mut truth);
        if ball || i >= first_turn {
            w.write(t, &udp_frame(src, dst, i as u16, &p)).unwrap();
        }
    }
    w.into_inner().unwrap()
}

/// A first sweep of a few points: the second sweep starts the map again, counted in
/// `reinitialized`, and from there every pose is the one of a run that never saw the first
/// sweep. A map of a few points used to leave every later sweep lost.
#[test]
fn a_sparse_first_sweep_restarts_the_map() {
    let mut runs = Vec::new();
    for ball in [true, false] {
        let pcap = out_path(&format!("sparse-first-{ball}.pcap"));
        std::fs::write(&pcap, simulated_capture_after_a_ball(1.5, ball)).unwrap();
        let out = out_path(&format!("sparse-first-{ball}.mcap"));
        let tum = out_path(&format!("sparse-first-{ball}.tum"));
        let o = ringscan(&[
            "decode",
            pcap.to_str().unwrap(),
            "--model",
            "vlp16",
            "--odometry",
            "--trajectory",
            tum.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--json",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let diags: Vec<serde_json::Value> = read(&out)["/diagnostics"]
            .iter()
            .map(|b| serde_json::from_slice(b).unwrap())
            .collect();
        runs.push((summary["odometry"].clone(), diags, read_tum(&tum)));
        for p in [&pcap, &out, &tum] {
            let _ = std::fs::remove_file(p);
        }
    }
    let (odo, diags, traj) = &runs[0];
    let map_points = |i: usize| diags[i]["odometry"]["map_points"].as_u64().unwrap();
    // The setup: a first map of fewer points than a registration's 10 correspondences.
    assert!((1..10).contains(&map_points(0)), "{}", diags[0]);
    assert_eq!(
        diags[1]["odometry"]["status"], "initialized",
        "{}",
        diags[1]
    );
    assert!(map_points(1) > 1000, "{}", diags[1]);
    let sweeps = odo["sweeps"].as_u64().unwrap();
    assert!(sweeps >= 14, "{odo}");
    assert_eq!(odo["reinitialized"], 1, "{odo}");
    assert_eq!(odo["failed"], 0, "{odo}");
    assert_eq!(odo["map_refused"], 0, "{odo}");
    assert_eq!(traj.len() as u64, sweeps, "{odo}");
    // Poses depend on the points alone (not the stamps): from the second sweep on, those of
    // the run without the first.
    let (plain, _, plain_traj) = &runs[1];
    assert_eq!(plain["reinitialized"], 0, "{plain}");
    assert_eq!(plain_traj.len() + 1, traj.len(), "{plain}");
    for ((_, a), (_, b)) in traj[1..].iter().zip(plain_traj) {
        let d = a.inverse() * b;
        assert!(
            d.translation.vector.norm() < 1e-6 && d.rotation.angle() < 1e-6,
            "{a:?} vs {b:?}"
        );
    }
}

/// `--odometry-method continuous-time`: the raw sweeps with their point times, poses at each
/// sweep's last point; the same drive, the same bound. With a pipeline deskew it is refused.
#[test]
fn continuous_time_odometry_from_the_cli() {
    let (err, _, travelled, summary, _) = simulated_drive_end_error(
        "sim-ct",
        &["--odometry", "--odometry-method", "continuous-time"],
    );
    assert_eq!(summary["odometry"]["deskew"], false, "{summary}");
    assert!(travelled > 20.0, "travelled {travelled} m");
    assert!(
        err <= 0.01 * travelled,
        "end error {err:.3} m over {travelled:.2} m"
    );
    let pcap = out_path("sim-ct-refused.pcap");
    std::fs::write(&pcap, simulated_capture(0.3)).unwrap();
    for deskew in ["odometry", "constant-velocity"] {
        let o = ringscan(&[
            "decode",
            pcap.to_str().unwrap(),
            "--model",
            "vlp16",
            "--odometry",
            "--odometry-method",
            "continuous-time",
            "--deskew",
            deskew,
            "--json",
        ]);
        assert!(!o.status.success(), "--deskew {deskew} accepted");
        assert!(
            String::from_utf8_lossy(&o.stderr).contains("continuous-time"),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    let _ = std::fs::remove_file(&pcap);
}

/// `decode --odometry --serve`: the live view advertises `/tf` and a subscriber receives the
/// same FrameTransform bytes the MCAP file holds (a Foxglove WebSocket client, `tungstenite`).
#[test]
fn live_view_publishes_the_tf_of_the_mcap() {
    use std::io::{BufRead, BufReader};
    use std::process::Stdio;
    use std::time::{Duration, Instant};
    use tungstenite::client::IntoClientRequest;
    use tungstenite::Message;

    let pcap = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo-vlp16.pcap");
    let out = out_path("live.mcap");
    let mut child = Command::new(env!("CARGO_BIN_EXE_ringscan"))
        .args([
            "decode",
            pcap.to_str().unwrap(),
            "--odometry",
            "--out",
            out.to_str().unwrap(),
            "--serve",
            "127.0.0.1:0",
            "--serve-rate",
            "1",
        ])
        .env("RINGSCAN_LOG", "info")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let err = child.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    std::thread::spawn(move || {
        for line in BufReader::new(err).lines().map_while(Result::ok) {
            if let Some(at) = line.find("ws://") {
                let _ = tx.send(
                    line[at + 5..]
                        .split_whitespace()
                        .next()
                        .unwrap_or("")
                        .into(),
                );
            }
        }
    });
    let addr = rx
        .recv_timeout(Duration::from_secs(30))
        .expect("no live view address");
    let stream = std::net::TcpStream::connect(&addr).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    let mut req = format!("ws://{addr}/").into_client_request().unwrap();
    req.headers_mut().insert(
        "sec-websocket-protocol",
        "foxglove.websocket.v1".parse().unwrap(),
    );
    let (mut ws, _) = tungstenite::client::client(req, stream).unwrap();
    let started = Instant::now();
    let mut tf_channel = None;
    let mut received: Vec<Vec<u8>> = Vec::new();
    loop {
        match ws.read() {
            Ok(Message::Text(t)) => {
                let v: serde_json::Value = serde_json::from_str(t.as_str()).unwrap();
                if v["op"] == "advertise" {
                    for c in v["channels"].as_array().unwrap() {
                        if c["topic"] == "/tf" && tf_channel.is_none() {
                            assert_eq!(c["schemaName"], "foxglove.FrameTransform");
                            let id = c["id"].as_u64().unwrap();
                            tf_channel = Some(id);
                            let sub = serde_json::json!({"op": "subscribe",
                                "subscriptions": [{"id": 7, "channelId": id}]});
                            ws.send(Message::text(sub.to_string())).unwrap();
                        }
                    }
                }
            }
            Ok(Message::Binary(b)) => {
                assert_eq!(b[0], 0x01);
                assert_eq!(u32::from_le_bytes(b[1..5].try_into().unwrap()), 7);
                received.push(b[13..].to_vec());
            }
            Ok(_) => {}
            Err(_) => break,
        }
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "live view did not end"
        );
    }
    assert!(child.wait().unwrap().success());
    assert!(tf_channel.is_some(), "/tf was not advertised");
    let file = read(&out).remove("/tf").unwrap();
    assert!(
        received.len() >= 2,
        "{} /tf messages received",
        received.len()
    );
    // The last messages of the file, byte for byte.
    assert_eq!(received[..], file[file.len() - received.len()..]);
    let _ = std::fs::remove_file(&out);
}

/// `seconds` of a simulated Ouster OS-1-32 (real metadata, 1024 × 10, IMU at 100 Hz) driving
/// at 5 m/s and turning 10 °/s over an empty flat floor: lidar (and IMU) datagrams in time
/// order.
fn simulated_ouster_on_a_floor(
    info: &ringscan::sensor::ouster::calib::OusterInfo,
    seconds: f64,
    with_imu: bool,
) -> Vec<u8> {
    let mut sim = ringscan::sensor::ouster::sim::OusterSim::new(info.clone(), T0_NS);
    sim.trajectory = floor_drive();
    let scene = scenes::flat_floor();
    let mut w = PcapWriter::new(Vec::new()).unwrap();
    let src = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 202), 7502);
    let dst = |port: u16| SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 100), port);
    let mut truth = Vec::new();
    let packets = (seconds * 1e9 / sim.packet_period_ns()).ceil() as usize;
    let mut id = 0u16;
    for _ in 0..packets {
        truth.clear();
        let (t, p) = sim.next_packet(&scene, &mut truth);
        while with_imu && sim.next_imu_time_ns() <= t {
            let (ti, b) = sim.next_imu_packet().unwrap();
            id = id.wrapping_add(1);
            w.write(ti, &udp_frame(src, dst(info.udp_port_imu), id, &b))
                .unwrap();
        }
        id = id.wrapping_add(1);
        w.write(t, &udp_frame(src, dst(info.udp_port_lidar), id, &p))
            .unwrap();
    }
    w.into_inner().unwrap()
}

fn floor_drive() -> Trajectory {
    let start = Isometry3::from_parts(
        Translation3::new(0.0, 0.0, scenes::SENSOR_HEIGHT_M),
        UnitQuaternion::identity(),
    );
    Trajectory::twist(
        T0_NS,
        start,
        Vector3::new(5.0, 0.0, 0.0),
        Vector3::new(0.0, 0.0, 10f64.to_radians()),
    )
}

/// On an empty floor the lidar sees neither yaw nor x, y (the degeneracy the odometry names):
/// without the IMU the estimated heading stays where the constant-velocity prediction puts it;
/// with the IMU stream of the same capture as a rotation prior it follows the turn. Truth: the
/// simulator's trajectory (a 10 °/s turn, 40° over the 4 s), relative to the first pose.
#[test]
fn an_imu_rotation_prior_holds_the_heading_the_floor_cannot() {
    let Some(root) = common::captures() else {
        eprintln!("skipped: needs the Ouster metadata of ../shared/captures");
        return;
    };
    let rel = "ouster-lidar__ouster-sdk/tests/pcaps/OS-1-32-G_v2.1.1_1024x10.json";
    let meta = root.join(rel);
    let info =
        ringscan::sensor::ouster::calib::parse(&std::fs::read_to_string(&meta).unwrap(), rel)
            .unwrap();
    let truth = floor_drive();
    let mut worst: Vec<(f64, f64)> = Vec::new();
    for imu in [false, true] {
        // The same drive, with and without the sensor's IMU datagrams.
        let pcap = out_path(&format!("floor-{imu}.pcap"));
        std::fs::write(&pcap, simulated_ouster_on_a_floor(&info, 4.0, imu)).unwrap();
        let tum = out_path(&format!("floor-{imu}.tum"));
        let args = [
            "decode".to_string(),
            pcap.display().to_string(),
            "--calib".into(),
            meta.display().to_string(),
            "--odometry".into(),
            "--trajectory".into(),
            tum.display().to_string(),
            "--json".into(),
        ];
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = ringscan(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let odo = &j["odometry"];
        let traj = read_tum(&tum);
        assert!(traj.len() >= 35, "{} poses: {odo}", traj.len());
        assert_eq!(
            odo["degenerate"],
            odo["registered"].as_u64().unwrap() - 1,
            "{odo}"
        );
        let priors = odo["imu_priors"].as_u64().unwrap();
        if imu {
            assert_eq!(priors, traj.len() as u64 - 1, "{odo}");
        } else {
            assert_eq!(priors, 0, "{odo}");
        }
        let pose_at = |t: f64| truth.pose((t * 1e9).round() as i64);
        let odom_from_world = pose_at(traj[0].0).inverse();
        let heading_err = traj
            .iter()
            .map(|(t, est)| {
                let want = odom_from_world * pose_at(*t);
                est.rotation.angle_to(&want.rotation).to_degrees()
            })
            .fold(0.0, f64::max);
        // Sweep to sweep: the estimated rotation against the true one.
        let step_err = traj
            .windows(2)
            .map(|w| {
                let est = w[0].1.rotation.inverse() * w[1].1.rotation;
                let want = pose_at(w[0].0).rotation.inverse() * pose_at(w[1].0).rotation;
                est.angle_to(&want).to_degrees()
            })
            .fold(0.0, f64::max);
        println!(
            "flat floor, IMU prior {imu}: worst heading error {heading_err:.3}°, worst sweep-to-sweep rotation error {step_err:.4}° over {} poses",
            traj.len()
        );
        worst.push((heading_err, step_err));
        let _ = std::fs::remove_file(&tum);
        let _ = std::fs::remove_file(&pcap);
    }
    // Without the IMU the turn is not seen: 1° missed every sweep, ~40° by the end. With it
    // every sweep's rotation is within two standard deviations of the prior (a gyro bias of
    // GYRO_BIAS_RADPS over the 0.1 s between sweeps); what is left is the pull of the floor's
    // ring pattern, which carries no true yaw information.
    let sigma_deg = (0.01f64 * 0.1).to_degrees();
    assert!(worst[0].1 > 0.9, "without IMU: {:?}", worst[0]);
    assert!(worst[0].0 > 20.0, "without IMU: {:?}", worst[0]);
    assert!(worst[1].1 < 2.0 * sigma_deg, "with IMU: {:?}", worst[1]);
}
