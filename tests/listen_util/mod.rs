//! Helpers of the `listen` / `replay` tests: free ports, running `ringscan listen` in the
//! background until it is ready, stopping it with a signal, reading point payloads from MCAP.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Read};
use std::net::{Ipv4Addr, UdpSocket};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

pub const BIN: &str = env!("CARGO_BIN_EXE_ringscan");

/// Tests of one binary run one at a time: they use fixed ports.
pub fn serial() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

/// An offset N such that every `port + N` is free on 127.0.0.1 right now: 0 (the capture's own
/// ports, which LEGACY Ouster metadata needs) when they are free.
pub fn free_offset(ports: &[u16]) -> i32 {
    if ports
        .iter()
        .all(|p| UdpSocket::bind((Ipv4Addr::UNSPECIFIED, *p)).is_ok())
    {
        return 0;
    }
    let max = ports.iter().copied().max().unwrap_or(0) as i32;
    let seed = (std::process::id() as i32)
        .wrapping_mul(7919)
        .rem_euclid(9000);
    for i in 0..2000 {
        let n = 1000 + (seed + i * 37).rem_euclid(20_000);
        if max + n > 65_000 {
            continue;
        }
        let ok = ports.iter().all(|p| {
            let port = (*p as i32 + n) as u16;
            UdpSocket::bind((Ipv4Addr::UNSPECIFIED, port)).is_ok()
        });
        if ok {
            return n;
        }
    }
    panic!("no free port offset for {ports:?}");
}

/// A `ringscan listen` running in the background.
pub struct Listener {
    pub child: Child,
    stderr: Arc<Mutex<String>>,
}

/// Starts `ringscan -v listen ARGS… --json` and waits until it says it listens.
pub fn start_listen(args: &[String]) -> Listener {
    let mut child = Command::new(BIN)
        .arg("-v")
        .arg("listen")
        .args(args)
        .arg("--json")
        .env("RINGSCAN_LOG", "info")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn ringscan listen");
    let stderr = Arc::new(Mutex::new(String::new()));
    let (tx, rx) = std::sync::mpsc::channel();
    let err = child.stderr.take().expect("stderr");
    let buf = stderr.clone();
    std::thread::spawn(move || {
        for line in BufReader::new(err).lines().map_while(Result::ok) {
            if line.contains("listening on UDP ports") {
                let _ = tx.send(());
            }
            let mut b = buf.lock().unwrap();
            b.push_str(&line);
            b.push('\n');
        }
    });
    let started = Instant::now();
    loop {
        if rx.recv_timeout(Duration::from_millis(50)).is_ok() {
            break;
        }
        if let Ok(Some(st)) = child.try_wait() {
            panic!(
                "listen exited early ({st}): {}",
                stderr.lock().unwrap().as_str()
            );
        }
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "listen not ready after 30 s: {}",
            stderr.lock().unwrap().as_str()
        );
    }
    Listener { child, stderr }
}

impl Listener {
    /// Sends `signal` (e.g. "INT", "TERM", "KILL") and waits for the exit; returns (exit code,
    /// stdout, stderr).
    pub fn stop(self, signal: &str) -> (Option<i32>, String, String) {
        let st = Command::new("kill")
            .arg(format!("-{signal}"))
            .arg(self.child.id().to_string())
            .status()
            .expect("kill");
        assert!(st.success());
        self.wait()
    }

    /// Waits for the exit, stopping the run with SIGINT if it has not ended within `limit`.
    pub fn wait_or_stop(mut self, limit: Duration) -> (Option<i32>, String, String) {
        let started = Instant::now();
        while started.elapsed() < limit {
            if let Ok(Some(_)) = self.child.try_wait() {
                return self.wait();
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        self.stop("INT")
    }

    /// Waits for the exit.
    pub fn wait(mut self) -> (Option<i32>, String, String) {
        let mut out = String::new();
        if let Some(mut o) = self.child.stdout.take() {
            let _ = o.read_to_string(&mut out);
        }
        let status = self.child.wait().expect("wait");
        // Let the stderr thread catch up.
        std::thread::sleep(Duration::from_millis(50));
        let err = self.stderr.lock().unwrap().clone();
        (status.code(), out, err)
    }
}

/// `ringscan replay PCAP --to 127.0.0.1 --port-offset N --rate R [extra]`.
pub fn replay(pcap: &Path, offset: i32, rate: &str, extra: &[&str]) {
    let st = Command::new(BIN)
        .arg("replay")
        .arg(pcap)
        .args(["--to", "127.0.0.1", "--port-offset", &offset.to_string()])
        .args(["--rate", rate])
        .args(extra)
        .stdout(Stdio::null())
        .status()
        .expect("replay");
    assert!(st.success(), "replay {} failed", pcap.display());
}

fn varint(b: &[u8], at: &mut usize) -> Option<u64> {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let byte = *b.get(*at)?;
        *at += 1;
        v |= u64::from(byte & 0x7f) << shift;
        if byte & 0x80 == 0 {
            return Some(v);
        }
    }
    None
}

/// Field 6 (`data`) of a foxglove.PointCloud protobuf message.
pub fn point_cloud_data(msg: &[u8]) -> Vec<u8> {
    let mut at = 0;
    while at < msg.len() {
        let key = varint(msg, &mut at).expect("key");
        let (field, wire) = (key >> 3, key & 7);
        match wire {
            0 => {
                varint(msg, &mut at).expect("varint");
            }
            1 => at += 8,
            5 => at += 4,
            2 => {
                let len = varint(msg, &mut at).expect("len") as usize;
                if field == 6 {
                    return msg[at..at + len].to_vec();
                }
                at += len;
            }
            w => panic!("wire type {w}"),
        }
    }
    Vec::new()
}

/// The point payloads of every `…/points` topic, in file order.
pub fn points_by_topic(mcap: &[u8]) -> BTreeMap<String, Vec<Vec<u8>>> {
    let mut out: BTreeMap<String, Vec<Vec<u8>>> = BTreeMap::new();
    for m in mcap::MessageStream::new(mcap).expect("mcap") {
        let m = m.expect("message");
        if m.channel.topic.ends_with("/points") {
            out.entry(m.channel.topic.clone())
                .or_default()
                .push(point_cloud_data(&m.data));
        }
    }
    out
}

/// Runs `ringscan decode PCAP --out OUT --json [extra]` and returns the JSON.
pub fn decode(pcap: &Path, out: &Path, extra: &[String]) -> serde_json::Value {
    let o = Command::new(BIN)
        .arg("decode")
        .arg(pcap)
        .arg("--out")
        .arg(out)
        .arg("--json")
        .args(extra)
        .output()
        .expect("decode");
    assert!(
        o.status.success(),
        "decode {}: {}",
        pcap.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).expect("decode json")
}

// ----- comparing decode's and listen's MCAP messages -----------------------------------------

/// Top-level protobuf fields: (number, raw bytes with the key, payload if length-delimited).
pub fn fields(msg: &[u8]) -> Vec<(u64, &[u8], &[u8])> {
    let mut out = Vec::new();
    let mut at = 0;
    while at < msg.len() {
        let start = at;
        let key = varint(msg, &mut at).expect("a protobuf varint");
        let mut payload: &[u8] = &[];
        match key & 7 {
            0 => {
                varint(msg, &mut at).expect("a protobuf varint");
            }
            1 => at += 8,
            5 => at += 4,
            2 => {
                let len = varint(msg, &mut at).expect("a protobuf varint") as usize;
                payload = &msg[at..at + len];
                at += len;
            }
            w => panic!("wire type {w}"),
        }
        out.push((key >> 3, &msg[start..at], payload));
    }
    out
}

/// A protobuf message without its timestamps (field 1 of a PointCloud or FrameTransform, of
/// every entity of a SceneUpdate); the JSON IMU samples as they are (their `timestamp_ns` is
/// the sensor's, the same in both paths).
pub fn without_stamps(topic: &str, msg: &[u8]) -> Vec<u8> {
    if topic.ends_with("/imu") {
        return msg.to_vec();
    }
    let scene = topic.ends_with("/clusters");
    let mut out = Vec::new();
    for (field, raw, payload) in fields(msg) {
        if scene {
            out.push(field as u8);
            for (f, r, _) in fields(payload) {
                if f != 1 {
                    out.extend_from_slice(r);
                }
            }
        } else if field != 1 {
            out.extend_from_slice(raw);
        }
    }
    out
}
