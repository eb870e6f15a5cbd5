//! `ringscan listen --pipeline … --odometry`: the live path runs the same pipeline and odometry
//! as `decode`, and keeps writing their channels across `--split-every` files.
//!
//! The truth is `ringscan decode` of the same capture with the same flags: the loopback test
//! (tests/listen_loopback.rs) shows the live path yields the same sweeps, and the pipeline and
//! odometry are deterministic functions of them, so every message of `/ground`, `/obstacles`,
//! `/clusters`, `/tf` and `/map` must carry the same bytes, in the same order, once the split
//! files are read one after another. Each file must be complete on its own: the static
//! transform and every channel declared again in it.

mod common;
mod listen_util;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

use listen_util::*;

/// Payloads per topic without their stamps (and without `/diagnostics`, whose health and
/// timings depend on the host).
fn payloads(bytes: &[u8], into: &mut BTreeMap<String, Vec<Vec<u8>>>) {
    for m in mcap::MessageStream::new(bytes).expect("mcap") {
        let m = m.expect("message");
        let t = m.channel.topic.clone();
        if t != "/diagnostics" {
            let v = without_stamps(&t, &m.data);
            into.entry(t).or_default().push(v);
        }
    }
}

fn flags() -> Vec<String> {
    [
        "--name",
        "lidar",
        "--pipeline",
        "default",
        "--extrinsics",
        "lidar=1.2,0,1.9,0,0,90",
        "--odometry",
        "--map-every",
        "2",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

#[test]
fn listen_runs_the_pipeline_and_odometry_of_decode_across_split_files() {
    // The real HDL-32E capture, or without ../shared the repository's simulated VLP-16 one.
    let pcap = match common::captures() {
        Some(c) => c.join("jerry73204__rust-lidar-utils/test_files/hdl32_example.pcap"),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo-vlp16.pcap"),
    };
    let _g = serial();
    let dir = std::env::temp_dir().join(format!("ringscan-listen-pipeline-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();

    let decoded = decode(&pcap, &dir.join("d.mcap"), &flags());
    let mut want = BTreeMap::new();
    payloads(&std::fs::read(dir.join("d.mcap")).unwrap(), &mut want);
    for t in [
        "/ground",
        "/obstacles",
        "/clusters",
        "/tf",
        "/map",
        "/tf_static",
    ] {
        assert!(
            want.contains_key(t),
            "decode wrote no {t}: {:?}",
            want.keys()
        );
    }

    let offset = free_offset(&[2368, 8308]);
    let base = dir.join("live.mcap");
    let mut args = vec![
        "--sensor".to_string(),
        format!("127.0.0.1:{}", 2368 + offset),
        "--sensor".to_string(),
        format!("127.0.0.1:{}", 8308 + offset),
        "--out".to_string(),
        base.display().to_string(),
        "--split-every".to_string(),
        "0.2s".to_string(),
    ];
    args.extend(flags());
    let l = start_listen(&args);
    // 0.5 s (1 s) of packets at their own pace: several files.
    replay(&pcap, offset, "1", &[]);
    std::thread::sleep(Duration::from_millis(300));
    let (code, stdout, err) = l.stop("INT");
    assert_eq!(code, Some(0), "{err}");
    let j: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(j["receive"]["queue_dropped"], 0);
    assert_eq!(j["receive"]["kernel_dropped"], 0);
    assert_eq!(j["sweeps"], decoded["sweeps"]);
    // The summary reports the pipeline and the odometry as decode's does.
    assert_eq!(
        j["pipeline"]["sweeps"], decoded["pipeline"]["sweeps"],
        "{}",
        j["pipeline"]
    );
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
    let mut got = BTreeMap::new();
    let mut files_with_sweeps = 0;
    for p in &files {
        let mut one = BTreeMap::new();
        let bytes = std::fs::read(p).unwrap();
        payloads(&bytes, &mut one);
        let sweeps = one.get("/points").map_or(0, Vec::len);
        if sweeps > 0 {
            files_with_sweeps += 1;
            // Every pipeline and odometry output of the file's sweeps is in the file itself.
            for t in ["/ground", "/obstacles", "/clusters", "/tf"] {
                assert_eq!(one.get(t).map_or(0, Vec::len), sweeps, "{}: {t}", show(p));
            }
            assert_eq!(
                one.get("/tf_static").map_or(0, Vec::len),
                1,
                "{}: /tf_static once per file",
                show(p)
            );
        }
        for (t, v) in one {
            got.entry(t).or_insert_with(Vec::new).extend(v);
        }
    }
    assert!(
        files_with_sweeps >= 2,
        "sweeps in {files_with_sweeps} file(s) only"
    );
    for (t, v) in &want {
        if t == "/tf_static" {
            continue;
        }
        let g = got.get(t).map(Vec::as_slice).unwrap_or(&[]);
        assert_eq!(g.len(), v.len(), "{t}: messages, listen vs decode");
        for (i, (a, b)) in g.iter().zip(v).enumerate() {
            assert!(a == b, "{t}: message {i} differs from decode's");
        }
    }
    assert_eq!(
        got.keys().collect::<Vec<_>>(),
        want.keys().collect::<Vec<_>>()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

fn show(p: &Path) -> String {
    p.display().to_string()
}
