//! A sender that repeats itself (a replay looped, a mirrored switch port, duplicated
//! datagrams) adds no points and no memory: Ouster packets whose columns all arrived already
//! are dropped and counted as late, instead of being appended to the open frame again.
//!
//! Truth: the same capture decoded once (itself checked against ouster-sdk elsewhere).

mod common;

use std::path::Path;
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_ringscan");

fn decode(pcap: &Path, meta: &Path) -> serde_json::Value {
    let o = Command::new(BIN)
        .arg("decode")
        .arg(pcap)
        .arg("--calib")
        .arg(meta)
        .arg("--json")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

#[test]
fn an_ouster_capture_sent_three_times_decodes_as_once() {
    let Some(c) = common::captures() else { return };
    let o = c.join("ouster-lidar__ouster-sdk/tests/pcaps");
    let pcap = o.join("OS-2-128-U1_v2.3.0_1024x10.pcap");
    let meta = o.join("OS-2-128-U1_v2.3.0_1024x10.json");
    let bytes = std::fs::read(&pcap).unwrap();
    // Classic pcap: a 24-byte file header, then records; the records three times over.
    let mut tripled = bytes.clone();
    tripled.extend_from_slice(&bytes[24..]);
    tripled.extend_from_slice(&bytes[24..]);
    let dir = std::env::temp_dir().join(format!("ringscan-dup-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("tripled.pcap");
    std::fs::write(&path, &tripled).unwrap();

    let once = decode(&pcap, &meta);
    let thrice = decode(&path, &meta);
    let (s1, s3) = (&once["sensors"][0], &thrice["sensors"][0]);
    assert_eq!(thrice["points"], once["points"]);
    assert_eq!(thrice["sweeps"], once["sweeps"]);
    let lidar = s1["lidar_packets"].as_u64().unwrap();
    assert_eq!(s3["lidar_packets"].as_u64().unwrap(), lidar);
    // The two repeats: every lidar packet dropped as late (older frame) or duplicate (its
    // frame still open), and counted.
    assert_eq!(
        s3["late"].as_u64().unwrap(),
        s1["late"].as_u64().unwrap() + 2 * lidar
    );
    let _ = std::fs::remove_dir_all(&dir);
}
