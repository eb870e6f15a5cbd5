//! `listen --serve`: sweeps published over the Foxglove WebSocket protocol reach a client
//! (tools/serve_client.py, written against the protocol's specification with the Python
//! `websockets` package) with the same points as the MCAP file written by the same run.
#![cfg(feature = "serve")]

mod common;
mod listen_util;

use std::process::{Command, Stdio};
use std::time::Duration;

use listen_util::*;

#[test]
fn sweeps_are_served_over_the_foxglove_websocket_protocol() {
    let Some(c) = common::captures() else { return };
    if Command::new("python3").arg("--version").output().is_err() {
        eprintln!("SKIP: python3 is absent: the live view client not run");
        return;
    }
    let _g = serial();
    let dir = std::env::temp_dir().join(format!("ringscan-serve-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let pcap = c.join("jerry73204__rust-lidar-utils/test_files/hdl32_example.pcap");
    let offset = free_offset(&[2368, 8308]);
    let ws_port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let out = dir.join("served.mcap");
    let l = start_listen(&[
        "--sensor".into(),
        format!("127.0.0.1:{}", 2368 + offset),
        "--sensor".into(),
        format!("127.0.0.1:{}", 8308 + offset),
        "--serve".into(),
        format!("127.0.0.1:{ws_port}"),
        "--out".into(),
        out.display().to_string(),
    ]);
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/serve_client.py");
    let client = Command::new("python3")
        .arg(script)
        .arg(format!("ws://127.0.0.1:{ws_port}"))
        .args(["--messages", "1000", "--timeout", "8"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(1500));
    // The channel is advertised with the first sweep; the client subscribes then.
    replay(&pcap, offset, "1", &["--loop", "3"]);
    let co = client.wait_with_output().unwrap();
    let (code, _, err) = l.stop("INT");
    assert_eq!(code, Some(0), "{err}");
    let j: serde_json::Value = serde_json::from_slice(&co.stdout).unwrap_or_else(|e| {
        panic!(
            "client output: {e}: {}\n{}",
            String::from_utf8_lossy(&co.stdout),
            String::from_utf8_lossy(&co.stderr)
        )
    });
    let served = j["messages"].as_array().unwrap();
    assert!(served.len() >= 10, "{} sweeps served: {j}", served.len());
    let ch = &j["channels"][0];
    assert_eq!(ch["topic"], "/points");
    assert_eq!(ch["schemaName"], "foxglove.PointCloud");
    assert_eq!(ch["encoding"], "protobuf");
    // The file's sweeps: (points, byte sum of the data).
    let file: Vec<(u64, u64)> = points_by_topic(&std::fs::read(&out).unwrap())["/points"]
        .iter()
        .map(|d| {
            (
                (d.len() / 24) as u64,
                d.iter()
                    .fold(0u32, |a, b| a.wrapping_add(u32::from(*b)))
                    .into(),
            )
        })
        .collect();
    let got: Vec<(u64, u64)> = served
        .iter()
        .map(|m| {
            assert_eq!(m["point_stride"], 24);
            assert_eq!(m["frame_id"], "hdl32e-1");
            (
                m["points"].as_u64().unwrap(),
                m["byte_sum"].as_u64().unwrap(),
            )
        })
        .collect();
    // What was served is a run of the file's sweeps: from the client's subscription (the
    // first sweep advertises the channel) to the last sweep before the client left (the
    // stream's last sweep is written when listen stops).
    assert!(
        got.len() + 3 >= file.len(),
        "{} of {} sweeps served",
        got.len(),
        file.len()
    );
    assert!(
        file.windows(got.len()).any(|w| w == &got[..]),
        "served sweeps are not a run of the file's: {got:?} vs {file:?}"
    );
    eprintln!(
        "{} of the file's {} sweeps served, identical (points and data byte sums)",
        got.len(),
        file.len()
    );
    let _ = std::fs::remove_dir_all(&dir);
}
