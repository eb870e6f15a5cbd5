//! `ringscan decode --pipeline default` on a real capture (the HDL-32E Monterey drive): every
//! pipeline channel is written, the `--json` summary has per-stage timings and counts, and the
//! file agrees with itself and with the summary:
//! - per sweep, the clusters' point counts (SceneUpdate metadata) sum to the obstacle points,
//!   every obstacle point's `cluster` names one of that sweep's cubes, and lies inside that
//!   cube (the cube is the cluster's minimum-area box);
//! - over the run, ground + obstacles + unclustered = points after voxel, and the ground,
//!   obstacle and cluster totals read back from the file equal the summary's.
//!
//! Also: `--extrinsics` puts the outputs in `base_link` and writes `/tf_static`; bad
//! configuration is refused (exit 2) naming the key; `ringscan render` draws a PNG.

mod common;
mod foxglove_msgs;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use foxglove_msgs::*;
use prost::Message as _;

fn inputs() -> Option<(PathBuf, PathBuf)> {
    let root = common::captures()?;
    Some((
        root.join("Kitware__VeloView/Testing/Data/monterey-first-100-packets.pcap"),
        root.join("ros-drivers__velodyne/velodyne_pointcloud/params/32db.yaml"),
    ))
}

fn out_path(name: &str) -> PathBuf {
    foxglove_msgs::out_path("pipeline-cli", name)
}

/// Points of a cloud as (x, y, z, cluster).
fn points(pc: &PointCloud) -> Vec<(f32, f32, f32, Option<u32>)> {
    let off = |n: &str| {
        pc.fields
            .iter()
            .find(|f| f.name == n)
            .map(|f| f.offset as usize)
    };
    let (x, y, z) = (off("x").unwrap(), off("y").unwrap(), off("z").unwrap());
    let c = off("cluster");
    let f = |r: &[u8], o: usize| f32::from_le_bytes(r[o..o + 4].try_into().unwrap());
    pc.data
        .chunks_exact(pc.point_stride as usize)
        .map(|r| {
            (
                f(r, x),
                f(r, y),
                f(r, z),
                c.map(|o| u32::from_le_bytes(r[o..o + 4].try_into().unwrap())),
            )
        })
        .collect()
}

fn read(path: &Path) -> (ByTopic, BTreeMap<String, String>) {
    read_mcap(path)
}

#[test]
fn default_pipeline_on_a_real_capture_writes_consistent_channels() {
    let Some((pcap, calib)) = inputs() else {
        return;
    };
    let out = out_path("default.mcap");
    let o = ringscan(&[
        "decode",
        pcap.to_str().unwrap(),
        "--calib",
        calib.to_str().unwrap(),
        "--pipeline",
        "default",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let p = &j["pipeline"];
    let sweeps = j["sweeps"].as_u64().unwrap();
    assert!(sweeps >= 15, "{j}");
    assert_eq!(p["sweeps"].as_u64(), Some(sweeps));
    for stage in ["deskew", "filter", "voxel", "ground", "cluster", "total"] {
        let t = &p["timings"][stage];
        let (med, max) = (
            t["median_ms"].as_f64().unwrap(),
            t["max_ms"].as_f64().unwrap(),
        );
        assert!(med >= 0.0 && max >= med, "{stage}: {t}");
    }
    let c = &p["counts"];
    let n = |k: &str| c[k].as_u64().unwrap();
    assert_eq!(n("points_in"), j["points"].as_u64().unwrap());
    assert_eq!(
        n("ground") + n("obstacles") + n("unclustered"),
        n("after_voxel"),
        "{c}"
    );
    assert!(n("after_voxel") < n("after_filter") && n("after_filter") <= n("points_in"));
    assert!(
        n("ground") > 0 && n("obstacles") > 0 && n("clusters") > 0,
        "{c}"
    );

    let (msgs, schemas) = read(&out);
    for (topic, schema) in [
        ("/points", "foxglove.PointCloud"),
        ("/ground", "foxglove.PointCloud"),
        ("/obstacles", "foxglove.PointCloud"),
        ("/clusters", "foxglove.SceneUpdate"),
    ] {
        assert_eq!(
            schemas.get(topic).map(String::as_str),
            Some(schema),
            "{topic}"
        );
        assert_eq!(
            msgs[topic].len() as u64,
            sweeps,
            "{topic}: one message per sweep"
        );
    }
    let (mut ground, mut obstacles, mut clusters) = (0u64, 0u64, 0u64);
    for ((g, o), u) in msgs["/ground"]
        .iter()
        .zip(&msgs["/obstacles"])
        .zip(&msgs["/clusters"])
    {
        let g = PointCloud::decode(&g[..]).unwrap();
        let o = PointCloud::decode(&o[..]).unwrap();
        let u = SceneUpdate::decode(&u[..]).unwrap();
        assert_eq!(g.frame_id, "hdl32e-201");
        assert_eq!(
            u.deletions.len(),
            1,
            "each update first deletes the previous boxes"
        );
        ground += points(&g).len() as u64;
        let obs = points(&o);
        obstacles += obs.len() as u64;
        clusters += u.entities.len() as u64;
        // The clusters' point counts sum to the obstacle points.
        let mut per_cluster = vec![0u64; u.entities.len()];
        let mut sum = 0u64;
        for (k, e) in u.entities.iter().enumerate() {
            assert_eq!(e.id, k.to_string());
            assert_eq!(e.cubes.len(), 1);
            let pts: u64 = e
                .metadata
                .iter()
                .find(|kv| kv.key == "points")
                .unwrap()
                .value
                .parse()
                .unwrap();
            sum += pts;
            per_cluster[k] = pts;
        }
        assert_eq!(sum, obs.len() as u64);
        // Every obstacle point is in its cluster's cube (a cube is the minimum-area box).
        let mut seen = vec![0u64; u.entities.len()];
        for &(x, y, z, k) in &obs {
            let k = k.expect("obstacles carry a cluster field") as usize;
            assert!(k < u.entities.len());
            seen[k] += 1;
            let cube = &u.entities[k].cubes[0];
            let pose = cube.pose.clone().unwrap();
            let c = pose.position.unwrap_or_default();
            let q = pose.orientation.unwrap();
            let yaw = 2.0 * q.z.atan2(q.w);
            let s = cube.size.clone().unwrap();
            let (dx, dy, dz) = (f64::from(x) - c.x, f64::from(y) - c.y, f64::from(z) - c.z);
            let (a, b) = (
                dx * yaw.cos() + dy * yaw.sin(),
                -dx * yaw.sin() + dy * yaw.cos(),
            );
            let tol = 1e-3;
            assert!(
                a.abs() <= s.x / 2.0 + tol
                    && b.abs() <= s.y / 2.0 + tol
                    && dz.abs() <= s.z / 2.0 + tol,
                "point ({x}, {y}, {z}) outside cube {k}"
            );
        }
        assert_eq!(seen, per_cluster);
    }
    assert_eq!(ground, n("ground"));
    assert_eq!(obstacles, n("obstacles"));
    assert_eq!(clusters, n("clusters"));

    // render: a PNG of the requested size.
    let png = out_path("bev.png");
    let r = ringscan(&[
        "render",
        out.to_str().unwrap(),
        "--sweep",
        "3",
        "--out",
        png.to_str().unwrap(),
        "--size-px",
        "400",
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let bytes = std::fs::read(&png).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    assert_eq!(&bytes[16..24], &[0, 0, 1, 144, 0, 0, 1, 144], "400 × 400");
    let r = ringscan(&[
        "render",
        out.to_str().unwrap(),
        "--sweep",
        "999",
        "--out",
        png.to_str().unwrap(),
    ]);
    assert!(!r.status.success());
    assert!(String::from_utf8_lossy(&r.stderr).contains("sweep 999"));
    let r = ringscan(&[
        "render",
        out.to_str().unwrap(),
        "--sensor",
        "/nope",
        "--out",
        png.to_str().unwrap(),
    ]);
    assert_eq!(r.status.code(), Some(2));
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(
        err.contains("/nope/ground") && err.contains("--sensor \"\""),
        "{err}"
    );
    let _ = std::fs::remove_file(&out);
    let _ = std::fs::remove_file(&png);
}

#[test]
fn extrinsics_write_tf_static_and_base_link_outputs() {
    let Some((pcap, calib)) = inputs() else {
        return;
    };
    let out = out_path("extrinsics.mcap");
    let o = ringscan(&[
        "decode",
        pcap.to_str().unwrap(),
        "--calib",
        calib.to_str().unwrap(),
        "--pipeline",
        "default",
        "--extrinsics",
        "hdl32e-201=0.5,0,1.9,0,0,0",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["pipeline"]["extrinsics_unused"], serde_json::json!([]));
    let (msgs, schemas) = read(&out);
    assert_eq!(
        schemas.get("/tf_static").map(String::as_str),
        Some("foxglove.FrameTransform")
    );
    let tf = FrameTransform::decode(&msgs["/tf_static"][0][..]).unwrap();
    assert_eq!(
        (tf.parent_frame_id.as_str(), tf.child_frame_id.as_str()),
        ("base_link", "hdl32e-201")
    );
    let t = tf.translation.unwrap();
    assert_eq!((t.x, t.y, t.z), (0.5, 0.0, 1.9));
    let g = PointCloud::decode(&msgs["/ground"][2][..]).unwrap();
    assert_eq!(g.frame_id, "base_link");
    // The sensor is 1.9 m up: the ground it sees lies near z = 0 in base_link.
    let pts = points(&g);
    let mut z: Vec<f32> = pts.iter().map(|p| p.2).collect();
    z.sort_by(f32::total_cmp);
    let median = z[z.len() / 2];
    assert!(median.abs() < 0.5, "median ground z in base_link {median}");
    let _ = std::fs::remove_file(&out);
}

#[test]
fn bad_pipeline_settings_are_refused_with_the_key() {
    let dir = out_path("cfg");
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("bad.toml");
    std::fs::write(&cfg, "[voxel]\nleaf_m = -1\n").unwrap();
    let tiny_leaf = dir.join("tiny-leaf.toml");
    std::fs::write(&tiny_leaf, "[voxel]\nleaf_m = 0.0001\n").unwrap();
    let pcap = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo-vlp16.pcap");
    for (args, needle) in [
        (vec!["--pipeline", cfg.to_str().unwrap()], "voxel.leaf_m"),
        (
            vec![
                "--pipeline",
                "default",
                "--deskew",
                "odometry",
                "--map-every",
                "0",
            ],
            "--map-every 0",
        ),
        (
            vec!["--pipeline", "default", "--deskew", "gps"],
            "--deskew gps",
        ),
        (
            vec!["--pipeline", "default", "--extrinsics", "a=1,2,3"],
            "found 3",
        ),
        // 2^20 leaves of 0.1 mm reach 105 m, short of the filter's 120 m.
        (
            vec!["--pipeline", tiny_leaf.to_str().unwrap()],
            "voxel.leaf_m = 0.0001: expected >= filter.max_range_m / 2^20",
        ),
    ] {
        let mut all = vec!["decode", pcap.to_str().unwrap()];
        all.extend(args);
        let o = ringscan(&all);
        assert_eq!(o.status.code(), Some(2), "{all:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(needle), "{all:?}: {err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Point records of every `/points` message, in order.
fn sweep_points(path: &Path) -> Vec<Vec<(f32, f32, f32, u32)>> {
    let (msgs, _) = read(path);
    msgs["/points"]
        .iter()
        .map(|m| {
            let pc = PointCloud::decode(&m[..]).unwrap();
            let t_off = pc.fields.iter().find(|f| f.name == "t").unwrap().offset as usize;
            pc.data
                .chunks_exact(pc.point_stride as usize)
                .map(|r| {
                    let f = |o: usize| f32::from_le_bytes(r[o..o + 4].try_into().unwrap());
                    (
                        f(0),
                        f(4),
                        f(8),
                        u32::from_le_bytes(r[t_off..t_off + 4].try_into().unwrap()),
                    )
                })
                .collect()
        })
        .collect()
}

/// `--deskew poses:FILE` on a real capture: a TUM file moving straight ahead at 2 m/s (and
/// one standing still) must shift every point by exactly the distance driven since the sweep's
/// timestamp, `x' = x + 2 m/s · t`: this checks the file's parsing, the time base (TUM seconds
/// against the sweeps' timestamps) and the deskew direction through the command line.
#[test]
fn a_poses_file_moves_the_points_by_its_motion() {
    let Some((pcap, calib)) = inputs() else {
        return;
    };
    let dir = out_path("poses");
    std::fs::create_dir_all(&dir).unwrap();
    // Two poses 4·10⁹ s apart bracket any capture time.
    let v = 2.0f64;
    let moving = dir.join("moving.tum");
    std::fs::write(
        &moving,
        format!(
            "# t x y z qx qy qz qw\n0 0 0 0 0 0 0 1\n4000000000 {} 0 0 0 0 0 1\n",
            v * 4e9
        ),
    )
    .unwrap();
    let still = dir.join("still.tum");
    std::fs::write(&still, "0 5 5 5 0 0 0 1\n4000000000 5 5 5 0 0 0 1\n").unwrap();
    let run = |extra: &[&str], name: &str| {
        let out = dir.join(name);
        let mut args = vec![
            "decode",
            pcap.to_str().unwrap(),
            "--calib",
            calib.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--json",
        ];
        args.extend(extra);
        let o = ringscan(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        (sweep_points(&out), j)
    };
    let (plain, _) = run(&[], "plain.mcap");
    let poses_still = format!("poses:{}", still.display());
    let (same, j) = run(&["--deskew", &poses_still], "still.mcap");
    assert_eq!(j["pipeline"]["deskew"], "poses");
    assert_eq!(j["pipeline"]["deskew_skipped"], 0);
    assert_eq!(same, plain, "standing still changes nothing");
    let poses_moving = format!("poses:{}", moving.display());
    let (moved, j) = run(&["--deskew", &poses_moving], "moving.mcap");
    assert_eq!(j["pipeline"]["deskew_skipped"], 0);
    assert_eq!(moved.len(), plain.len());
    let mut worst = 0f64;
    for (a, b) in plain.iter().zip(&moved) {
        assert_eq!(a.len(), b.len());
        for (p, q) in a.iter().zip(b) {
            assert_eq!(p.3, q.3);
            let want = f64::from(p.0) + v * f64::from(p.3) * 1e-9;
            let err = (f64::from(q.0) - want)
                .abs()
                .max(f64::from(q.1 - p.1).abs())
                .max(f64::from(q.2 - p.2).abs());
            worst = worst.max(err);
        }
    }
    assert!(worst < 1e-4, "worst deviation {worst} m");
    // Without --pipeline only the deskew runs (the later stages' outputs would be thrown
    // away: the audit found ground and clusters computed for nothing); the points are those
    // the full pipeline writes.
    assert_eq!(j["pipeline"]["outputs"], false);
    for k in ["after_voxel", "ground", "clusters"] {
        assert_eq!(j["pipeline"]["counts"][k], 0, "{k}");
    }
    let (full, j) = run(
        &["--pipeline", "default", "--deskew", &poses_moving],
        "moving-full.mcap",
    );
    assert!(j["pipeline"]["counts"]["ground"].as_u64().unwrap() > 0);
    assert_eq!(
        full, moved,
        "the deskewed points do not depend on the later stages"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--deskew imu` on a real Ouster capture with IMU packets: every sweep is deskewed (the gyro
/// covers each sweep), none skipped.
#[test]
fn imu_deskew_runs_on_a_real_ouster_capture() {
    let Some(root) = common::captures() else {
        return;
    };
    let dir = root.join("ouster-lidar__ouster-sdk/tests/pcaps");
    let o = ringscan(&[
        "decode",
        dir.join("OS-1-128_v2.3.0_1024x10_lb_n3.pcap")
            .to_str()
            .unwrap(),
        "--calib",
        dir.join("OS-1-128_v2.3.0_1024x10.json").to_str().unwrap(),
        "--pipeline",
        "default",
        "--deskew",
        "imu",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["pipeline"]["deskew"], "imu");
    assert_eq!(j["pipeline"]["sweeps"], 3);
    assert_eq!(j["pipeline"]["deskew_skipped"], 0, "{}", j["pipeline"]);
    // A Velodyne has no IMU: each sweep is counted as skipped, with the reason.
    let Some((pcap, calib)) = inputs() else {
        return;
    };
    let o = ringscan(&[
        "decode",
        pcap.to_str().unwrap(),
        "--calib",
        calib.to_str().unwrap(),
        "--pipeline",
        "default",
        "--deskew",
        "imu",
        "--json",
    ]);
    assert!(o.status.success());
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let p = &j["pipeline"];
    assert_eq!(p["deskew_skipped"], p["sweeps"]);
    assert!(p["sensors"][0]["deskew_last_error"]
        .as_str()
        .unwrap()
        .contains("IMU"));
}

/// `deskew.reference = "end"` with a constant twist from a TOML file: every point goes to the
/// pose at the sweep's last point, `x' = x + v·(t − t_end)` for straight motion, and the
/// messages are stamped `t_end` later than the sweep's first firing.
#[test]
fn end_reference_moves_points_to_the_last_pose_and_restamps() {
    let Some((pcap, calib)) = inputs() else {
        return;
    };
    let dir = out_path("end");
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("end.toml");
    std::fs::write(
        &cfg,
        "[deskew]\nmode = \"constant-velocity\"\nreference = \"end\"\nlinear_mps = [3.0, 0, 0]\n",
    )
    .unwrap();
    let stamps_and_points = |extra: &[&str], name: &str| {
        let out = dir.join(name);
        let mut args = vec![
            "decode",
            pcap.to_str().unwrap(),
            "--calib",
            calib.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend(extra);
        let o = ringscan(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let (msgs, _) = read(&out);
        let stamps: Vec<i128> = msgs["/points"]
            .iter()
            .map(|m| {
                let t = PointCloud::decode(&m[..]).unwrap().timestamp.unwrap();
                i128::from(t.seconds) * 1_000_000_000 + i128::from(t.nanos)
            })
            .collect();
        (stamps, sweep_points(&out))
    };
    let (s0, plain) = stamps_and_points(&[], "plain.mcap");
    let (s1, moved) = stamps_and_points(&["--pipeline", cfg.to_str().unwrap()], "end.mcap");
    assert_eq!(plain.len(), moved.len());
    let mut worst = 0f64;
    for k in 0..plain.len() {
        let t_end = plain[k].iter().map(|p| p.3).max().unwrap();
        assert_eq!(
            s1[k] - s0[k],
            i128::from(t_end),
            "sweep {k} restamped by its span"
        );
        for (p, q) in plain[k].iter().zip(&moved[k]) {
            let want = f64::from(p.0) + 3.0 * (f64::from(p.3) - f64::from(t_end)) * 1e-9;
            worst = worst.max((f64::from(q.0) - want).abs());
        }
    }
    assert!(worst < 1e-4, "worst deviation {worst} m");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Extrinsics naming no sensor are reported, not silently ignored.
#[test]
fn extrinsics_for_an_unknown_sensor_are_reported() {
    let pcap = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo-vlp16.pcap");
    let o = ringscan(&[
        "decode",
        pcap.to_str().unwrap(),
        "--pipeline",
        "default",
        "--extrinsics",
        "nobody=0,0,1,0,0,0",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        j["pipeline"]["extrinsics_unused"],
        serde_json::json!(["nobody"])
    );
    assert!(String::from_utf8_lossy(&o.stderr).contains("nobody"));
}

/// `render` draws a `--format ros2` file (CDR `PointCloud2` and `MarkerArray`) as it draws the
/// same run written in the foxglove format (protobuf, read by prost): the same picture, byte
/// for byte, so the two writers and the CDR reader agree. It failed with `invalid tag value:
/// 0`. An input that is not an MCAP is named as such (it was `Bad magic number`).
#[test]
fn render_draws_a_ros2_file_as_the_foxglove_one() {
    let pcap = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo-vlp16.pcap");
    let bin = env!("CARGO_BIN_EXE_ringscan");
    let mut pngs = Vec::new();
    let mut lines = Vec::new();
    for format in ["foxglove", "ros2"] {
        let mcap = out_path(&format!("render-{format}.mcap"));
        let o = std::process::Command::new(bin)
            .arg("decode")
            .arg(&pcap)
            .args(["--pipeline", "default", "--format", format, "--out"])
            .arg(&mcap)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let png = out_path(&format!("render-{format}.png"));
        let o = std::process::Command::new(bin)
            .arg("render")
            .arg(&mcap)
            .args(["--sweep", "4", "--out"])
            .arg(&png)
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{format}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let line = String::from_utf8_lossy(&o.stdout).into_owned();
        lines.push(
            line.split_once(": ")
                .unwrap()
                .1
                .replace(&*mcap.to_string_lossy(), "RUN"),
        );
        pngs.push(std::fs::read(&png).unwrap());
    }
    assert_eq!(lines[0], lines[1]);
    let clusters: u32 = lines[0]
        .trim_end()
        .strip_suffix(" clusters")
        .and_then(|l| l.rsplit(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{}", lines[0]));
    assert!(clusters > 0, "{}", lines[0]);
    assert!(pngs[0] == pngs[1], "the two pictures differ");
    let o = std::process::Command::new(bin)
        .arg("render")
        .arg(&pcap)
        .arg("--out")
        .arg(out_path("render-pcap.png"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("not an MCAP file"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// Points the voxel grid cannot key (more than 2^20 leaves from the origin on some axis) are
/// counted (`pipeline.counts.voxel_skipped`) and warned of; they left every output after the
/// voxel stage without a word (second audit). The count is the points of `/points` (the sweep
/// as decoded, no deskew motion) that the filter keeps (≥ 0.5 m) and that lie beyond
/// 2^20 × 1 µm = 1.048576 m on some axis, counted here from the file.
#[test]
fn points_beyond_the_voxel_grid_are_counted_and_warned_of() {
    let dir = out_path("tiny-voxel");
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("leaf.toml");
    std::fs::write(
        &cfg,
        "[voxel]\nleaf_m = 0.000001\n[filter]\nmax_range_m = inf\n",
    )
    .unwrap();
    let out = dir.join("run.mcap");
    let pcap = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo-vlp16.pcap");
    let o = ringscan(&[
        "decode",
        pcap.to_str().unwrap(),
        "--pipeline",
        cfg.to_str().unwrap(),
        "--json",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let skipped = j["pipeline"]["counts"]["voxel_skipped"].as_u64().unwrap();
    let reach = f64::from(1u32 << 20) * 1e-6;
    let beyond = |margin: f64| -> u64 {
        sweep_points(&out)
            .iter()
            .flatten()
            .filter(|&&(x, y, z, _)| {
                let (x, y, z) = (f64::from(x), f64::from(y), f64::from(z));
                (x * x + y * y + z * z).sqrt() >= 0.5
                    && [x, y, z].iter().any(|v| v.abs() >= reach * margin)
            })
            .count() as u64
    };
    let (fewest, most) = (beyond(1.0 + 1e-6), beyond(1.0 - 1e-6));
    assert!(fewest > 0);
    assert!(
        (fewest..=most).contains(&skipped),
        "skipped {skipped}, expected {fewest} … {most}"
    );
    let o = ringscan(&[
        "decode",
        pcap.to_str().unwrap(),
        "--pipeline",
        cfg.to_str().unwrap(),
    ]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains(&format!(
            "warning: the voxel grid left out {skipped} points beyond ±2^20 leaves"
        )),
        "{text}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
