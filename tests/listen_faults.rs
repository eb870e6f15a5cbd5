//! Faults of the live path: SIGINT / SIGTERM / SIGHUP mid-run, a full disk, a sensor that stops and
//! starts again (Velodyne gap, Ouster re-initialised with a new init_id), `--split-every`.

mod common;
mod listen_util;

use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};
use std::path::{Path, PathBuf};
use std::time::Duration;

use listen_util::*;

fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ringscan-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The Velodyne capture these tests replay: the real HDL-32E one (0.5 s) when
/// `../shared/captures` is there, else the repository's simulated VLP-16 demo capture (1 s),
/// so a fresh clone tests the live path too. Returns (path, datagrams, seconds).
fn velodyne_capture() -> (PathBuf, u64, f64) {
    let path = match common::captures() {
        Some(c) => c.join("jerry73204__rust-lidar-utils/test_files/hdl32_example.pcap"),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo-vlp16.pcap"),
    };
    let d = common::datagrams(&path);
    let secs = match (d.first(), d.last()) {
        (Some(a), Some(b)) => (b.0 - a.0) as f64 * 1e-9,
        _ => 0.0,
    };
    (path, d.len() as u64, secs)
}

/// Reads an MCAP completely: every message, and the summary section (finalised files only).
/// Returns (messages per topic, point records in all `…/points` messages).
fn read_finalised(path: &Path) -> (std::collections::BTreeMap<String, u64>, u64) {
    let bytes = std::fs::read(path).unwrap();
    let summary = mcap::Summary::read(&bytes)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .unwrap_or_else(|| panic!("{}: no summary section (not finalised)", path.display()));
    let mut per_topic = std::collections::BTreeMap::new();
    let mut points = 0u64;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        *per_topic.entry(m.channel.topic.clone()).or_insert(0u64) += 1;
        if m.channel.topic.ends_with("/points") {
            points += (point_cloud_data(&m.data).len() / 24) as u64;
        }
    }
    let stats = summary.stats.expect("statistics record");
    assert_eq!(
        stats.message_count,
        per_topic.values().sum::<u64>(),
        "{}: statistics vs messages read",
        path.display()
    );
    (per_topic, points)
}

fn sensor_args(offset: i32, out: Option<&Path>) -> Vec<String> {
    let mut a = vec![
        "--sensor".to_string(),
        format!("127.0.0.1:{}", 2368 + offset),
        "--sensor".to_string(),
        format!("127.0.0.1:{}", 8308 + offset),
    ];
    if let Some(o) = out {
        a.push("--out".into());
        a.push(o.display().to_string());
    }
    a
}

#[test]
fn sigint_sigterm_and_sighup_mid_run_leave_a_finalised_mcap() {
    let (pcap, n, secs) = velodyne_capture();
    let _g = serial();
    let dir = tmpdir("signals");
    // SIGHUP: a closed SSH session; by default it killed the run with the file unfinished.
    for sig in ["INT", "TERM", "HUP"] {
        let offset = free_offset(&[2368, 8308]);
        let out = dir.join(format!("{sig}.mcap"));
        let l = start_listen(&sensor_args(offset, Some(&out)));
        // About 3 s of packets; the signal comes after 1.2 s, in the middle.
        let loops = (3.0 / secs).ceil() as u64;
        let pcap = pcap.clone();
        let sender =
            std::thread::spawn(move || replay(&pcap, offset, "1", &["--loop", &loops.to_string()]));
        std::thread::sleep(Duration::from_millis(1200));
        let (code, stdout, err) = l.stop(sig);
        sender.join().unwrap();
        assert_eq!(code, Some(0), "SIG{sig}: {err}");
        let j: serde_json::Value = serde_json::from_str(&stdout).unwrap();
        assert_eq!(j["stop"], format!("SIG{sig}"));
        let (topics, points) = read_finalised(&out);
        assert!(
            j["sweeps"].as_u64().unwrap() > 0,
            "SIG{sig}: no sweep before the signal"
        );
        assert!(
            j["receive"]["datagrams"].as_u64().unwrap() < loops * n,
            "not mid-run"
        );
        // What the file holds is what the summary says was written.
        for (t, n) in j["output"]["topics"].as_object().unwrap() {
            assert_eq!(topics.get(t).copied(), n.as_u64(), "SIG{sig}: {t}");
        }
        assert_eq!(points, j["points"].as_u64().unwrap(), "SIG{sig}: points");
        eprintln!("SIG{sig}: {topics:?}, {points} points, file finalised");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `listen --duration 3` with `args`, the VLP-16 capture replayed to it: its output.
fn listen_to_the_capture(args: &[&std::ffi::OsStr]) -> std::process::Output {
    let (pcap, _, _) = velodyne_capture();
    let _g = serial();
    let offset = free_offset(&[2368, 8308]);
    let child = std::process::Command::new(BIN)
        .args(["listen", "--duration", "3"])
        .args(args)
        .args(sensor_args(offset, None))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(300));
    replay(&pcap, offset, "max", &[]);
    child.wait_with_output().unwrap()
}

#[test]
fn a_full_disk_is_a_clear_error() {
    // The first file is written as `<out>.tmp-ringscan` until the sensor is recognised: a link
    // there to /dev/full takes the file's creation and fails every write with ENOSPC, at the
    // start (the header and schemas fill the write buffer) or at the latest when a chunk is
    // written.
    let dir = tmpdir("full-disk");
    let out = dir.join("live.mcap");
    std::os::unix::fs::symlink("/dev/full", dir.join("live.mcap.tmp-ringscan")).unwrap();
    let o = listen_to_the_capture(&["--out".as_ref(), out.as_os_str()]);
    let (code, stdout, err) = (
        o.status.code(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert_eq!(code, Some(1), "stdout {stdout}\nstderr {err}");
    assert!(
        err.contains(&out.display().to_string()) && err.contains("No space left on device"),
        "error does not say what and where: {err}"
    );
    // The device itself is not an output: renaming onto it would replace it.
    let o = std::process::Command::new(BIN)
        .args(["listen", "--sensor", "127.0.0.1:9", "--out", "/dev/full"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("a device, pipe or socket, not a file"),
        "{err}"
    );
    assert!(std::fs::metadata("/dev/full").is_ok_and(|m| !m.is_file()));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_velodyne_that_stops_and_starts_again_resumes() {
    let (pcap, n, _) = velodyne_capture();
    let _g = serial();
    let dir = tmpdir("gap");
    let decoded = decode(&pcap, &dir.join("d.mcap"), &[]);
    let offset = free_offset(&[2368, 8308]);
    let l = start_listen(&sensor_args(offset, None));
    replay(&pcap, offset, "1", &[]);
    // The sensor is silent for 1.5 s, then sends again (its clock starts over).
    std::thread::sleep(Duration::from_millis(1500));
    replay(&pcap, offset, "1", &[]);
    std::thread::sleep(Duration::from_millis(300));
    let (code, stdout, err) = l.stop("INT");
    assert_eq!(code, Some(0), "{err}");
    let j: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(j["receive"]["datagrams"], 2 * n);
    assert_eq!(j["receive"]["queue_dropped"], 0);
    assert_eq!(j["receive"]["kernel_dropped"], 0);
    let d = |k: &str| decoded["packets"][k].as_u64().unwrap();
    // Every data packet of both runs decoded, every point of both runs emitted.
    assert_eq!(j["packets"]["decoded"].as_u64().unwrap(), 2 * d("decoded"));
    assert_eq!(
        j["points"].as_u64().unwrap(),
        2 * decoded["points"].as_u64().unwrap()
    );
    assert!(j["sweeps"].as_u64().unwrap() >= 2 * decoded["sweeps"].as_u64().unwrap() - 1);
    let _ = std::fs::remove_dir_all(&dir);
}

/// `listen --out OUT --split-every` 1.4 × the capture's length, with `extra`, while the capture
/// is replayed four times (two or three files); the run's JSON summary.
fn listen_split(pcap: &Path, secs: f64, out: &Path, extra: &[&str]) -> serde_json::Value {
    let offset = free_offset(&[2368, 8308]);
    let mut args = sensor_args(offset, Some(out));
    args.extend(extra.iter().map(|a| a.to_string()));
    args.extend(["--split-every".to_string(), format!("{:.2}s", 1.4 * secs)]);
    let l = start_listen(&args);
    replay(pcap, offset, "1", &["--loop", "4"]);
    std::thread::sleep(Duration::from_millis(300));
    let (code, stdout, err) = l.stop("INT");
    assert_eq!(code, Some(0), "{err}");
    serde_json::from_str(&stdout).unwrap()
}

#[test]
fn split_every_rotates_files_without_losing_a_sweep() {
    let (pcap, _, secs) = velodyne_capture();
    let _g = serial();
    let dir = tmpdir("split");
    let decoded = decode(&pcap, &dir.join("d.mcap"), &[]);
    let j = listen_split(&pcap, secs, &dir.join("drive.mcap"), &[]);
    assert_eq!(j["receive"]["queue_dropped"], 0);
    assert_eq!(j["receive"]["kernel_dropped"], 0);
    let files = j["files"].as_array().unwrap();
    assert!(files.len() >= 2, "{} files", files.len());
    let (mut points, mut sweeps) = (0u64, 0u64);
    for (i, f) in files.iter().enumerate() {
        let p = PathBuf::from(f["path"].as_str().unwrap());
        assert_eq!(p, dir.join(format!("drive_{i:04}.mcap")));
        let (topics, n) = read_finalised(&p);
        points += n;
        sweeps += topics.get("/points").copied().unwrap_or(0);
    }
    assert_eq!(points, j["points"].as_u64().unwrap());
    assert_eq!(sweeps, j["sweeps"].as_u64().unwrap());
    assert_eq!(points, 4 * decoded["points"].as_u64().unwrap());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--format ros2` with `--split-every`: each closed file is synced and named in
/// `metadata.yaml` on a thread of its own (off the decode thread), and the run's last yaml
/// names every file, in order, with each file's own message count; every file is finalised.
#[test]
fn a_split_rosbag2_names_every_file_in_its_metadata() {
    let (pcap, _, secs) = velodyne_capture();
    let _g = serial();
    let dir = tmpdir("split-ros2");
    let bag = dir.join("drive");
    let j = listen_split(&pcap, secs, &bag, &["--format", "ros2"]);
    let files = j["files"].as_array().unwrap();
    assert!(files.len() >= 2, "{} files", files.len());
    let yaml = std::fs::read_to_string(bag.join("metadata.yaml")).unwrap();
    let mut listed = Vec::new();
    let mut total = 0u64;
    for f in files {
        let p = PathBuf::from(f["path"].as_str().unwrap());
        assert_eq!(p.parent(), Some(bag.as_path()));
        // Finalised (a summary), and its statistics count the messages it holds (CDR here,
        // which `read_finalised` does not parse).
        let bytes = std::fs::read(&p).unwrap();
        let stats = mcap::Summary::read(&bytes)
            .unwrap()
            .and_then(|s| s.stats)
            .unwrap_or_else(|| panic!("{}: not finalised", p.display()));
        let n = mcap::MessageStream::new(&bytes).unwrap().count() as u64;
        assert_eq!(stats.message_count, n, "{}", p.display());
        total += n;
        let name = p.file_name().unwrap().to_string_lossy().into_owned();
        listed.push(format!("    - path: \"{name}\"\n"));
        assert!(
            yaml.contains(&format!("    - path: \"{name}\"")),
            "{name} not in {yaml}"
        );
        // Its own count follows its path.
        let at = yaml.find(&format!("    - path: \"{name}\"")).unwrap();
        let count = yaml[at..]
            .lines()
            .find_map(|l| l.trim().strip_prefix("message_count: "))
            .unwrap();
        assert_eq!(count.parse::<u64>().unwrap(), n, "{name}");
    }
    let order: Vec<usize> = listed
        .iter()
        .map(|l| yaml.find(l.as_str()).unwrap())
        .collect();
    assert!(
        order.windows(2).all(|w| w[0] < w[1]),
        "files out of order: {yaml}"
    );
    assert!(
        yaml.contains(&format!("  message_count: {total}\n")),
        "{yaml}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A `--format ros2` recording that ends in an error (here the `--trajectory`'s disk is full,
/// found when it is flushed at the end) still names its finalised last file in
/// `metadata.yaml`: the yaml listed only the files of earlier checkpoints (none within the
/// first 10 s), a bag that opened empty beside a complete file.
#[test]
fn a_rosbag2_recording_that_ends_in_an_error_names_its_last_file() {
    if !Path::new("/dev/full").exists() {
        eprintln!("SKIP: /dev/full is absent");
        return;
    }
    let (pcap, _, _) = velodyne_capture();
    let _g = serial();
    let dir = tmpdir("ros2-error");
    let bag = dir.join("drive");
    let offset = free_offset(&[2368, 8308]);
    let mut args = sensor_args(offset, Some(&bag));
    args.extend(
        [
            "--format",
            "ros2",
            "--odometry",
            "--trajectory",
            "/dev/full",
        ]
        .map(String::from),
    );
    let l = start_listen(&args);
    replay(&pcap, offset, "1", &[]);
    std::thread::sleep(Duration::from_millis(300));
    let (code, _, err) = l.stop("INT");
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("--trajectory /dev/full"), "{err}");
    let file = bag.join("drive_0.mcap");
    let bytes = std::fs::read(&file).unwrap();
    let stats = mcap::Summary::read(&bytes)
        .unwrap()
        .and_then(|s| s.stats)
        .expect("the last file finalised");
    let yaml = std::fs::read_to_string(bag.join("metadata.yaml")).unwrap();
    assert!(yaml.contains("    - path: \"drive_0.mcap\""), "{yaml}");
    assert!(
        yaml.contains(&format!("  message_count: {}\n", stats.message_count)),
        "{yaml}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Sends datagrams to 127.0.0.1 at about the capture's pace.
fn send_all(sock: &UdpSocket, dgrams: &[(i64, u16, Vec<u8>)], port_of: impl Fn(u16) -> u16) {
    let t0 = dgrams.first().map_or(0, |d| d.0);
    let start = std::time::Instant::now();
    for (t, port, payload) in dgrams {
        let due = Duration::from_nanos((t - t0).max(0) as u64);
        if let Some(w) = due.checked_sub(start.elapsed()) {
            std::thread::sleep(w);
        }
        sock.send_to(
            payload,
            SocketAddrV4::new(Ipv4Addr::LOCALHOST, port_of(*port)),
        )
        .unwrap();
    }
}

/// A minimal HTTP server serving `body` at the Ouster metadata path; counts the requests.
fn serve_metadata(body: Vec<u8>) -> (u16, std::sync::Arc<std::sync::atomic::AtomicUsize>) {
    use std::io::{Read, Write};
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let count = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let n = count.clone();
    std::thread::spawn(move || {
        for stream in listener.incoming() {
            let Ok(mut s) = stream else { continue };
            let mut req = Vec::new();
            let mut buf = [0u8; 1024];
            while !req.windows(4).any(|w| w == b"\r\n\r\n") {
                match s.read(&mut buf) {
                    Ok(0) | Err(_) => break,
                    Ok(k) => req.extend_from_slice(&buf[..k]),
                }
            }
            let line = String::from_utf8_lossy(&req)
                .lines()
                .next()
                .unwrap_or("")
                .to_string();
            if line.starts_with("GET /api/v1/sensor/metadata ") {
                n.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                // Chunked, as some sensor firmware sends it.
                let mut resp = b"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nTransfer-Encoding: chunked\r\n\r\n".to_vec();
                for part in body.chunks(3000) {
                    resp.extend_from_slice(format!("{:x}\r\n", part.len()).as_bytes());
                    resp.extend_from_slice(part);
                    resp.extend_from_slice(b"\r\n");
                }
                resp.extend_from_slice(b"0\r\n\r\n");
                let _ = s.write_all(&resp);
            } else {
                let _ = s.write_all(b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\n\r\n");
            }
        }
    });
    (port, count)
}

#[test]
fn ouster_metadata_from_its_http_api_and_again_after_a_new_init_id() {
    let Some(c) = common::captures() else { return };
    let _g = serial();
    let dir = tmpdir("ouster-http");
    let o = c.join("ouster-lidar__ouster-sdk/tests/pcaps");
    // v2.3.0: no CRC in the packets, so the init_id can be rewritten.
    let pcap = o.join("OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
    let meta = o.join("OS-1-128_v2.3.0_1024x10.json");
    let decoded_path = dir.join("d.mcap");
    let decoded = decode(
        &pcap,
        &decoded_path,
        &["--calib".into(), meta.display().to_string()],
    );
    let truth = points_by_topic(&std::fs::read(&decoded_path).unwrap())["/points"].clone();
    assert_eq!(truth.len(), 3);

    let (api_port, requests) = serve_metadata(std::fs::read(&meta).unwrap());
    let dgrams = common::datagrams(&pcap);
    let offset = free_offset(&[7502, 7503]);
    let out = dir.join("live.mcap");
    let args = vec![
        "--sensor".to_string(),
        format!("127.0.0.1:{}", 7502 + offset),
        "--sensor".to_string(),
        format!("127.0.0.1:{}", 7503 + offset),
        "--api-port".to_string(),
        api_port.to_string(),
        "--out".to_string(),
        out.display().to_string(),
    ];
    let l = start_listen(&args);
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    let port_of = |p: u16| (i32::from(p) + offset) as u16;
    // Run 1: no metadata yet; the first packets start the request and wait for it.
    send_all(&sock, &dgrams, port_of);
    // Runs 2 and 3: the sensor re-initialised (init_id u24 @4 of each lidar packet changed).
    for k in 1..=2u32 {
        std::thread::sleep(Duration::from_millis(700));
        let mut changed = dgrams.clone();
        for (_, _, p) in changed.iter_mut().filter(|d| d.2.len() > 48) {
            let id = u32::from_le_bytes([p[4], p[5], p[6], 0]) ^ (0x5a5a00 + k);
            p[4..7].copy_from_slice(&id.to_le_bytes()[..3]);
        }
        send_all(&sock, &changed, port_of);
    }
    std::thread::sleep(Duration::from_millis(700));
    let (code, stdout, err) = l.stop("INT");
    assert_eq!(code, Some(0), "{err}");
    let j: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(j["receive"]["queue_dropped"], 0);
    assert_eq!(j["receive"]["kernel_dropped"], 0);
    assert_eq!(j["receive"]["datagrams"], 3 * dgrams.len());
    let s = &j["sensors"][0];
    assert_eq!(s["serial"], decoded["sensors"][0]["serial"]);
    assert_eq!(s["epochs"], 2, "{s}");
    assert_eq!(s["calibration_file"], "metadata-127.0.0.1.json");
    // Once at the start, once after each init_id change.
    assert_eq!(
        requests.load(std::sync::atomic::Ordering::SeqCst),
        3,
        "{err}"
    );
    // The metadata is attached to the file like a --calib file.
    let att = &j["output"]["attachments"];
    assert_eq!(att[0]["name"], "metadata-127.0.0.1.json", "{att}");
    // The datagrams that came before the metadata were held and decoded once it arrived:
    // none is lost to the request's round trip.
    let held = &j["receive"]["held_for_metadata"];
    assert!(held["held"].as_u64().unwrap() > 0, "{held}");
    assert_eq!(held["decoded"], held["held"], "{held}");
    assert_eq!(held["evicted"], 0, "{held}");
    assert_eq!(j["packets"]["ignored"], 0);
    // Every run decodes to exactly the sweeps of `decode` with the metadata file.
    let live = points_by_topic(&std::fs::read(&out).unwrap())["/points"].clone();
    assert_eq!(live.len(), 9, "sweeps");
    assert!(live[..3] == truth[..], "run 1 differs from decode");
    assert!(live[3..6] == truth[..], "run 2 differs from decode");
    assert!(live[6..] == truth[..], "run 3 differs from decode");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The `/diagnostics` messages with `"health": true`, in file order.
fn health_messages(path: &Path) -> Vec<serde_json::Value> {
    let bytes = std::fs::read(path).unwrap();
    mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| m.unwrap())
        .filter(|m| m.channel.topic.ends_with("/diagnostics"))
        .map(|m| serde_json::from_slice::<serde_json::Value>(&m.data).unwrap())
        .filter(|v| v["health"] == true)
        .collect()
}

#[test]
fn health_goes_to_diagnostics_once_a_second() {
    let Some(c) = common::captures() else { return };
    let _g = serial();
    let dir = tmpdir("health");
    let o = c.join("ouster-lidar__ouster-sdk/tests/pcaps");
    let pcap = o.join("OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
    let meta = o.join("OS-1-128_v2.3.0_1024x10.json");
    // The truth: alert_flags, byte 12 of each lidar packet's standard header.
    let dgrams = common::datagrams(&pcap);
    let seen = dgrams
        .iter()
        .filter(|d| d.2.len() == 8448)
        .fold(0u8, |a, d| a | d.2[12]);
    let offset = free_offset(&[7502, 7503]);
    let out = dir.join("health.mcap");
    let l = start_listen(&[
        "--sensor".into(),
        format!("127.0.0.1:{}", 7502 + offset),
        "--sensor".into(),
        format!("127.0.0.1:{}", 7503 + offset),
        "--calib".into(),
        meta.display().to_string(),
        "--out".into(),
        out.display().to_string(),
    ]);
    // 0.3 s of packets at a tenth of real time: 3 s.
    replay(&pcap, offset, "0.1", &[]);
    std::thread::sleep(Duration::from_millis(1200));
    let (code, _, err) = l.stop("INT");
    assert_eq!(code, Some(0), "{err}");
    let h = health_messages(&out);
    assert!(h.len() >= 2, "{} health messages", h.len());
    let last = h.last().unwrap();
    assert_eq!(last["kind"], "ouster");
    assert_eq!(last["receive"]["datagrams"], dgrams.len());
    assert_eq!(last["alert_flags"]["seen"], seen);
    assert_eq!(last["lidar_packets"], 192);
    for k in ["shot_limiting", "thermal_shutdown", "init_id"] {
        assert!(!last[k].is_null(), "{k}: {last}");
    }
    // Counters only grow.
    let n: Vec<u64> = h
        .iter()
        .map(|v| v["receive"]["datagrams"].as_u64().unwrap())
        .collect();
    assert!(n.windows(2).all(|w| w[0] <= w[1]), "{n:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `listen`'s text summary warns of a calibration no sensor took, as `decode`'s does, and
/// counts the ignored datagrams (it said neither: a sensor could vanish from it without a
/// word, only `--json` telling). A VLP-16 replayed with a Hesai correction given.
#[test]
fn the_text_summary_warns_of_an_unused_calibration() {
    let dir = tmpdir("unused-calib");
    let csv = dir.join("hesai32.csv");
    let mut text = String::from("Laser id,Elevation,Azimuth\n");
    for i in 0..32 {
        text.push_str(&format!("{},{},0\n", i + 1, 15.0 - i as f64));
    }
    std::fs::write(&csv, text).unwrap();
    let o = listen_to_the_capture(&["--calib".as_ref(), csv.as_os_str()]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{out} {}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        out.contains("warning: calibration hesai32.csv was used by no sensor"),
        "{out}"
    );
    assert!(out.contains(", ignored 0,"), "{out}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The text summary's `wrote FILE: {…}` is the topics' counts as JSON, as `decode` prints
/// them (it was Rust's debug form, `{"/points": 3, …}`), and they are the file's.
#[test]
fn the_text_summary_names_the_file_and_its_topics_as_json() {
    let dir = tmpdir("wrote-json");
    let out = dir.join("live.mcap");
    let o = listen_to_the_capture(&["--out".as_ref(), out.as_os_str()]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(0), "{text}");
    let prefix = format!("  wrote {}: ", out.display());
    let line = text
        .lines()
        .find_map(|l| l.strip_prefix(&prefix))
        .unwrap_or_else(|| panic!("no wrote line: {text}"));
    let counts: std::collections::BTreeMap<String, u64> =
        serde_json::from_str(line).unwrap_or_else(|e| panic!("{line}: {e}"));
    assert!(!line.contains(": "), "not compact JSON: {line}");
    assert_eq!(counts, read_finalised(&out).0);
    let _ = std::fs::remove_dir_all(&dir);
}

/// An `--out` in a directory that does not exist is bad usage named before any socket is
/// opened (exit 2), as in `decode`; it was exit 1 once the first file was created.
#[test]
fn an_out_in_a_missing_directory_is_refused_first() {
    let o = std::process::Command::new(BIN)
        .args([
            "listen",
            "--sensor",
            "127.0.0.1:9",
            "--duration",
            "5",
            "--out",
        ])
        .arg("/nonexistent-ringscan-dir/live.mcap")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("its directory /nonexistent-ringscan-dir does not exist; create it first"),
        "{err}"
    );
}

/// A run that receives nothing of a sensor (a wrong port, a sensor switched off) fails as
/// `decode` finding no sensor does (exit 1, with what came), and writes nothing: a file already
/// at `--out` is left as it was, no temporary file stays, and a rosbag2 directory it would have
/// made is not left behind. It exited 0 over an empty MCAP that replaced the file.
#[test]
fn a_run_that_receives_nothing_writes_nothing() {
    let _guard = serial();
    let dir = tmpdir("nothing");
    let offset = free_offset(&[2368]);
    let port = (2368 + offset).to_string();
    let earlier = dir.join("earlier.mcap");
    std::fs::write(&earlier, b"an earlier recording").unwrap();
    let bag = dir.join("bag");
    for (out, format) in [(&earlier, "foxglove"), (&bag, "ros2")] {
        let o = std::process::Command::new(BIN)
            .args(["listen", "--sensor"])
            .arg(format!("127.0.0.1:{port}"))
            .args(["--duration", "1", "--json", "--format", format, "--out"])
            .arg(out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{format}: {err}");
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(j["kind"], "no_sensor", "{j}");
        assert_eq!(
            j["no_sensor"].as_str().unwrap(),
            format!("in 1.0 s, no datagram came to UDP port {port}"),
            "{j}"
        );
        assert!(
            j["error"].as_str().unwrap().ends_with("; nothing written"),
            "{j}"
        );
    }
    assert_eq!(std::fs::read(&earlier).unwrap(), b"an earlier recording");
    assert!(!bag.exists(), "the rosbag2 directory was left");
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left, vec![std::ffi::OsString::from("earlier.mcap")]);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Datagrams from another address than `--sensor`'s are counted, not recorded, and the
/// failure says so.
#[test]
fn datagrams_from_other_addresses_only_are_explained() {
    let _guard = serial();
    let offset = free_offset(&[2368]);
    let port = 2368 + offset;
    let l = start_listen(&["--sensor".into(), format!("127.0.0.9:{port}")]);
    let sock = UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).unwrap();
    for _ in 0..5 {
        sock.send_to(
            &[0u8; 1206],
            SocketAddrV4::new(Ipv4Addr::LOCALHOST, port as u16),
        )
        .unwrap();
    }
    std::thread::sleep(Duration::from_millis(300));
    let (code, out, err) = l.stop("INT");
    assert_eq!(code, Some(1), "{err}");
    let j: serde_json::Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"));
    let why = j["no_sensor"].as_str().unwrap();
    assert!(
        why.contains(&format!(
            "no datagram came from 127.0.0.9 to UDP port {port}; 5 came from other addresses"
        )),
        "{why}"
    );
}

/// `replay --duration` ends on time across a gap in the capture: it slept the whole gap (here
/// 30 s) before looking at the clock.
#[test]
fn replay_ends_at_its_duration_inside_a_gap() {
    let (pcap, _, _) = velodyne_capture();
    let d = common::datagrams(&pcap);
    let dir = tmpdir("replay-gap");
    let gapped = dir.join("gap.pcap");
    let mut w = ringscan::sim::net::PcapWriter::new(Vec::new()).unwrap();
    let src = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 201), 2368);
    let dst = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 100), 2368);
    for (i, t) in [0i64, 30_000_000_000].into_iter().enumerate() {
        let frame = ringscan::sim::net::udp_frame(src, dst, i as u16, &d[i].2);
        w.write(1_700_000_000_000_000_000 + t, &frame).unwrap();
    }
    std::fs::write(&gapped, w.into_inner().unwrap()).unwrap();
    let receiver = UdpSocket::bind("127.0.0.1:0").unwrap();
    let offset = i32::from(receiver.local_addr().unwrap().port()) - 2368;
    let started = std::time::Instant::now();
    let o = std::process::Command::new(BIN)
        .arg("replay")
        .arg(&gapped)
        .args(["--to", "127.0.0.1", "--port-offset", &offset.to_string()])
        .args(["--rate", "1", "--duration", "1", "--json"])
        .output()
        .unwrap();
    let took = started.elapsed();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["sent"], 1, "{j}");
    assert!(
        took < Duration::from_secs(10),
        "{took:?}: slept through the gap"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
