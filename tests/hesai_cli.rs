//! Hesai at the process boundary:
//!
//! - `ringscan info` on every real Hesai capture names the model, protocol version, return
//!   mode, clock state and CRC state (text and `--json`), with the facts NEBULA.md lists for
//!   that capture;
//! - `ringscan listen` decodes a Hesai sensor and a Velodyne sensor sending to the same port at
//!   once: a capture merged in the test from the XT32 and the nebula VLP-16 captures (the
//!   Velodyne re-addressed to 192.168.1.202 and shifted in time onto the Hesai), replayed on
//!   loopback (one 127.0.0.k per source); the live run must receive every datagram and give
//!   the same sweeps and points as `ringscan decode` of the merged file, one sensor per family;
//! - the angle correction fetched over PTC (`hesai-calib`, `listen --hesai-ptc`), the CSV and
//!   the AT128's binary `.dat`, which `decode --calib` also reads (simulated AT128 packets with
//!   the real file decode to exactly the simulator's returns);
//! - the Pandar ATX through `info`, `decode --calib` and `listen --hesai-ptc` (simulated
//!   packets, a correction written in the test).

mod common;
mod listen_util;

use std::path::Path;
use std::process::Command;

use listen_util::*;

const GT: &str = "tier4__nebula/src/nebula_hesai/nebula_hesai/test_resources/decoder_ground_truth";
const CALIB: &str = "tier4__nebula/src/nebula_hesai/nebula_hesai_decoders/calibration";

/// (folder, csv, model, protocol, return mode, CRC state words, UDP-sequence missing).
type Expected = (
    &'static str,
    &'static str,
    &'static str,
    Option<&'static str>,
    &'static str,
    &'static str,
    u64,
);

const CAPTURES: &[Expected] = &[
    (
        "40p",
        "Pandar40P.csv",
        "Pandar40P",
        None,
        "dual (last, strongest) (0x39)",
        "absent",
        0,
    ),
    (
        "64",
        "Pandar64.csv",
        "Pandar64",
        None,
        "dual (last, strongest) (0x39)",
        "absent",
        0,
    ),
    (
        "qt64",
        "PandarQT64.csv",
        "PandarQT64",
        Some("3.1"),
        "dual (first, last) (0x3b)",
        "absent",
        0,
    ),
    (
        "qt128",
        "PandarQT128.csv",
        "PandarQT128",
        Some("3.2"),
        "dual (last, strongest) (0x39)",
        "checked",
        0,
    ),
    (
        "xt32",
        "PandarXT32.csv",
        "PandarXT32",
        Some("6.1"),
        "dual (last, strongest) (0x39)",
        "absent",
        0,
    ),
    (
        "xt32m",
        "PandarXT32M.csv",
        "PandarXT32M",
        Some("6.1"),
        "dual (first, strongest) (0x3c)",
        "absent",
        852,
    ),
];

fn pcap_in(dir: &Path) -> std::path::PathBuf {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            for f in std::fs::read_dir(&p).unwrap().flatten() {
                if f.path().extension().is_some_and(|x| x == "pcap") {
                    return f.path();
                }
            }
        }
    }
    panic!("no pcap under {}", dir.display());
}

#[test]
fn info_names_model_protocol_return_mode_clock_and_crc() {
    let Some(c) = common::captures() else { return };
    for &(dir, csv, model, protocol, mode, crc, missing) in CAPTURES {
        let pcap = pcap_in(&c.join(GT).join(dir));
        let calib = c.join(CALIB).join(csv);
        let o = Command::new(BIN)
            .arg("info")
            .arg(&pcap)
            .arg("--calib")
            .arg(&calib)
            .arg("--json")
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{dir}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let sensors = j["sensors"].as_array().unwrap();
        assert_eq!(sensors.len(), 1, "{dir}");
        let s = &sensors[0];
        assert_eq!(s["kind"], "hesai", "{dir}");
        assert_eq!(s["model"], model, "{dir}");
        assert_eq!(s["protocol"].as_str(), protocol, "{dir}");
        assert_eq!(s["return_mode"], mode, "{dir}");
        assert!(
            s["clock_state"]
                .as_str()
                .unwrap()
                .starts_with("free-running"),
            "{dir}: {}",
            s["clock_state"]
        );
        assert!(
            s["crc"].as_str().unwrap().starts_with(crc),
            "{dir}: {}",
            s["crc"]
        );
        assert_eq!(s["crc_failures"], 0, "{dir}");
        assert_eq!(s["missing"], missing, "{dir}");
        assert_eq!(s["malformed"], 0, "{dir}");
        assert!(s["sweeps"].as_u64().unwrap() >= 1, "{dir}");
        if dir == "qt128" {
            assert_eq!(s["signed_packets"], 1800);
            assert!(s["functional_safety"].is_object());
        }
        // The text form says the same.
        let o = Command::new(BIN).arg("info").arg(&pcap).output().unwrap();
        assert!(o.status.success());
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(text.contains(&format!("Hesai {model},")), "{dir}: {text}");
        // Without its file the sensor decodes no sweep, so has no name: it is named by its
        // address alone (it was `sensor - (ADDR)`).
        let addr = s["address"].as_str().unwrap();
        assert!(
            text.contains(&format!("\n  sensor {addr}, ports [")),
            "{dir}: {text}"
        );
        assert!(text.contains(mode), "{dir}: {text}");
        assert!(text.contains("clock: free-running"), "{dir}: {text}");
        assert!(text.contains(&format!("CRC: {crc}")), "{dir}: {text}");
        match protocol {
            Some(p) => assert!(text.contains(&format!("protocol {p}")), "{dir}: {text}"),
            None => assert!(text.contains("protocol none"), "{dir}: {text}"),
        }
    }
}

/// A classic pcap (µs) of UDP datagrams: (time ns, source address, payload), all to port 2368.
fn write_pcap(path: &Path, datagrams: &[(i64, [u8; 4], Vec<u8>)]) {
    let mut out = Vec::new();
    out.extend_from_slice(&0xa1b2_c3d4u32.to_le_bytes());
    out.extend_from_slice(&2u16.to_le_bytes());
    out.extend_from_slice(&4u16.to_le_bytes());
    out.extend_from_slice(&[0; 8]);
    out.extend_from_slice(&65_535u32.to_le_bytes());
    out.extend_from_slice(&1u32.to_le_bytes());
    for (i, (t, src, payload)) in datagrams.iter().enumerate() {
        let mut f = Vec::new();
        f.extend_from_slice(&[2, 0, 0, 0, 0, 0x64, 2, 0, 0, 0, 0, src[3], 0x08, 0x00]);
        let total = 20 + 8 + payload.len();
        let mut ip = vec![0x45, 0];
        ip.extend_from_slice(&(total as u16).to_be_bytes());
        ip.extend_from_slice(&(i as u16).to_be_bytes());
        ip.extend_from_slice(&[0x40, 0, 64, 17, 0, 0]);
        ip.extend_from_slice(src);
        ip.extend_from_slice(&[192, 168, 1, 100]);
        let sum: u32 = ip
            .chunks(2)
            .map(|w| u32::from(u16::from_be_bytes([w[0], w[1]])))
            .sum();
        let sum = (sum & 0xFFFF) + (sum >> 16);
        let sum = !(((sum & 0xFFFF) + (sum >> 16)) as u16);
        ip[10..12].copy_from_slice(&sum.to_be_bytes());
        f.extend_from_slice(&ip);
        f.extend_from_slice(&2368u16.to_be_bytes());
        f.extend_from_slice(&2368u16.to_be_bytes());
        f.extend_from_slice(&((8 + payload.len()) as u16).to_be_bytes());
        f.extend_from_slice(&[0, 0]);
        f.extend_from_slice(payload);
        out.extend_from_slice(&((t / 1_000_000_000) as u32).to_le_bytes());
        out.extend_from_slice(&((t % 1_000_000_000 / 1_000) as u32).to_le_bytes());
        out.extend_from_slice(&(f.len() as u32).to_le_bytes());
        out.extend_from_slice(&(f.len() as u32).to_le_bytes());
        out.extend_from_slice(&f);
    }
    std::fs::write(path, out).unwrap();
}

#[test]
fn listen_decodes_hesai_and_velodyne_on_one_port() {
    let Some(c) = common::captures() else { return };
    let _guard = serial();
    let tmp = std::env::temp_dir().join(format!("ringscan-hesai-cli-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let hesai = common::datagrams(&pcap_in(&c.join(GT).join("xt32")));
    let vel_dir = c.join(
        "tier4__nebula/src/nebula_velodyne/nebula_velodyne/test_resources/decoder_ground_truth/vlp16",
    );
    let velodyne = common::datagrams(&pcap_in(&vel_dir));
    let vel_calib =
        c.join("tier4__nebula/src/nebula_velodyne/nebula_velodyne_decoders/calibration/VLP16.yaml");
    let hesai_calib = c.join(CALIB).join("PandarXT32.csv");
    // 0.4 s of each, interleaved on the Hesai's clock.
    let t0 = hesai[0].0;
    let span = hesai.last().unwrap().0 - t0;
    let shift = t0 - velodyne[0].0;
    let mut merged: Vec<(i64, [u8; 4], Vec<u8>)> = hesai
        .iter()
        .map(|(t, _, p)| (*t, [192, 168, 1, 201], p.clone()))
        .chain(
            velodyne
                .iter()
                .filter(|(t, _, _)| t + shift - t0 <= span)
                .map(|(t, _, p)| (t + shift, [192, 168, 1, 202], p.clone())),
        )
        .collect();
    merged.sort_by_key(|d| d.0);
    let pcap = tmp.join("hesai_velodyne.pcap");
    write_pcap(&pcap, &merged);

    let calib_args: Vec<String> = vec![
        "--calib".into(),
        hesai_calib.display().to_string(),
        "--calib".into(),
        vel_calib.display().to_string(),
    ];
    let decoded_path = tmp.join("decode.mcap");
    let decoded = decode(&pcap, &decoded_path, &calib_args);
    let kinds: Vec<&str> = decoded["sensors"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["kind"].as_str().unwrap())
        .collect();
    assert_eq!(kinds.len(), 2, "{decoded}");
    assert!(
        kinds.contains(&"hesai") && kinds.contains(&"velodyne"),
        "{kinds:?}"
    );

    let offset = free_offset(&[2368]);
    let port = 2368 + offset;
    let live_path = tmp.join("listen.mcap");
    let mut args: Vec<String> = vec![
        "--sensor".into(),
        format!("127.0.0.1:{port}"),
        "--sensor".into(),
        format!("127.0.0.2:{port}"),
    ];
    args.extend(calib_args.iter().cloned());
    args.push("--out".into());
    args.push(live_path.display().to_string());
    let l = start_listen(&args);
    replay(&pcap, offset, "1", &["--per-source-loopback"]);
    std::thread::sleep(std::time::Duration::from_millis(500));
    let (code, out, err) = l.stop("INT");
    assert_eq!(code, Some(0), "listen failed: {err}");
    let live: serde_json::Value =
        serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out:?} {err}"));
    assert_eq!(live["receive"]["datagrams"], merged.len() as u64, "{err}");
    assert_eq!(live["receive"]["queue_dropped"], 0);
    for k in ["sweeps", "points"] {
        assert_eq!(live[k], decoded[k], "{k}");
    }
    let live_kinds: Vec<&str> = live["sensors"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["kind"].as_str().unwrap())
        .collect();
    assert!(
        live_kinds.contains(&"hesai") && live_kinds.contains(&"velodyne"),
        "{live_kinds:?}"
    );
    for s in live["sensors"].as_array().unwrap() {
        assert!(s["points"].as_u64().unwrap() > 0, "{s}");
    }
    let a = points_by_topic(&std::fs::read(&decoded_path).unwrap());
    let b = points_by_topic(&std::fs::read(&live_path).unwrap());
    assert_eq!(a.len(), 2, "{:?}", a.keys().collect::<Vec<_>>());
    // Topics are named after the source address (192.168.1.20x in the file, 127.0.0.x live):
    // the model prefixes and the order must agree.
    let prefix = |t: &String| {
        t.rsplit_once('-')
            .map(|(p, _)| p.to_string())
            .unwrap_or_default()
    };
    assert_eq!(
        a.keys().map(prefix).collect::<Vec<_>>(),
        b.keys().map(prefix).collect::<Vec<_>>(),
        "topics"
    );
    for ((topic, sa), sb) in a.iter().zip(b.values()) {
        assert_eq!(sa.len(), sb.len(), "{topic}: sweeps");
        for (i, (x, y)) in sa.iter().zip(sb).enumerate() {
            if x == y {
                continue;
            }
            assert_eq!(x.len(), y.len(), "{topic}: sweep {i} sizes");
            let diff: Vec<usize> = (0..x.len()).filter(|&j| x[j] != y[j]).collect();
            let fields: std::collections::BTreeSet<usize> = diff.iter().map(|j| j % 24).collect();
            panic!(
                "{topic}: sweep {i} differs ({} bytes differ at record offsets {fields:?})",
                diff.len()
            );
        }
    }
    eprintln!(
        "{} datagrams (Hesai XT32 + Velodyne VLP-16) on one port: {} sweeps, {} points, identical to decode",
        merged.len(),
        decoded["sweeps"],
        decoded["points"]
    );
    let _ = std::fs::remove_dir_all(&tmp);
}

#[test]
fn hesai_calib_fetches_the_correction_from_a_fake_sensor_over_ptc() {
    use std::io::{Read, Write};
    let Some(c) = common::captures() else { return };
    let csv = std::fs::read(c.join(CALIB).join("PandarXT32.csv")).unwrap();
    // A fake sensor's PTC port: one "get angle correction" (0x05) answered with the CSV.
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = l.local_addr().unwrap();
    let served = csv.clone();
    let server = std::thread::spawn(move || {
        let (mut s, _) = l.accept().unwrap();
        let mut head = [0u8; 8];
        s.read_exact(&mut head).unwrap();
        assert_eq!(&head, &[0x47, 0x74, 0x05, 0, 0, 0, 0, 0]);
        let mut r = vec![0x47, 0x74, 0x05, 0];
        r.extend_from_slice(&(served.len() as u32).to_be_bytes());
        r.extend_from_slice(&served);
        s.write_all(&r).unwrap();
    });
    let tmp = std::env::temp_dir().join(format!("ringscan-hesai-ptc-{}.csv", std::process::id()));
    let o = Command::new(BIN)
        .args(["hesai-calib", "--sensor", &addr.to_string(), "--out"])
        .arg(&tmp)
        .output()
        .unwrap();
    server.join().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(std::fs::read(&tmp).unwrap(), csv);
    // The fetched file decodes the capture.
    let pcap = pcap_in(&c.join(GT).join("xt32"));
    let o = Command::new(BIN)
        .arg("info")
        .arg(&pcap)
        .arg("--calib")
        .arg(&tmp)
        .arg("--json")
        .output()
        .unwrap();
    assert!(o.status.success());
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(j["points"].as_u64().unwrap() > 0);
    let _ = std::fs::remove_file(&tmp);
    // No sensor listening: a clear error, exit code 1.
    let closed = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let o = Command::new(BIN)
        .args([
            "hesai-calib",
            "--timeout",
            "1",
            "--sensor",
            &closed.to_string(),
            "--out",
        ])
        .arg(std::env::temp_dir().join("ringscan-hesai-ptc-never.csv"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains(&closed.to_string()));
}

/// A Hesai sensor whose angle correction `listen` has not (no `--calib`, no `--hesai-ptc`)
/// stops the run with the reason, and the run writes nothing: a file already at `--out` is left
/// as it was. It left an empty MCAP in its place.
#[test]
fn listen_without_the_hesai_file_leaves_out_as_it_was() {
    let Some(c) = common::captures() else { return };
    let _guard = serial();
    let tmp = std::env::temp_dir().join(format!("ringscan-hesai-nofile-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let out = tmp.join("earlier.mcap");
    std::fs::write(&out, b"an earlier recording").unwrap();
    let offset = free_offset(&[2368]);
    let l = start_listen(&[
        "--sensor".into(),
        format!("127.0.0.1:{}", 2368 + offset),
        "--out".into(),
        out.display().to_string(),
    ]);
    replay(&pcap_in(&c.join(GT).join("xt32")), offset, "1", &[]);
    let (code, stdout, err) = l.wait_or_stop(std::time::Duration::from_secs(10));
    assert_eq!(code, Some(1), "{stdout} {err}");
    assert!(
        err.contains("PandarXT32") && err.contains("--calib"),
        "{err}"
    );
    assert_eq!(std::fs::read(&out).unwrap(), b"an earlier recording");
    let left: Vec<_> = std::fs::read_dir(&tmp)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left.len(), 1, "{left:?}");
    let _ = std::fs::remove_dir_all(&tmp);
}

#[test]
fn nebula_filters_are_command_line_options() {
    let Some(c) = common::captures() else { return };
    let pcap = pcap_in(&c.join(GT).join("qt128"));
    let calib = c.join(CALIB).join("PandarQT128.csv");
    let points = |extra: &[&str]| -> u64 {
        let o = Command::new(BIN)
            .arg("decode")
            .arg(&pcap)
            .arg("--calib")
            .arg(&calib)
            .arg("--json")
            .args(extra)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        j["points"].as_u64().unwrap()
    };
    let all = points(&[]);
    let ranged = points(&["--min-range", "0.3", "--max-range", "300"]);
    let nebula = points(&[
        "--min-range",
        "0.3",
        "--max-range",
        "300",
        "--dual-return-threshold",
        "0.1",
    ]);
    let half = points(&["--fov", "0:180"]);
    assert!(ranged < all && nebula < ranged, "{all} {ranged} {nebula}");
    assert!(
        half < all * 6 / 10 && half > all * 3 / 10,
        "{half} of {all}"
    );
    // Bad values are usage errors (exit code 2).
    for bad in [["--fov", "10"], ["--dual-return-threshold", "-1"]] {
        let o = Command::new(BIN)
            .arg("decode")
            .arg(&pcap)
            .args(bad)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{bad:?}");
    }
    // A range the model cannot reach keeps no point and is warned of, as in every family
    // (it failed, and once blamed the right correction: "fits none of the sensors found").
    let o = Command::new(BIN)
        .arg("decode")
        .arg(&pcap)
        .arg("--calib")
        .arg(&calib)
        .args(["--min-range", "150"])
        .output()
        .unwrap();
    let (out, err) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert_eq!(o.status.code(), Some(0), "{err}");
    assert!(
        out.contains("warning: --min-range 150: no point of the") && !out.contains("fits none"),
        "{out}"
    );
}

#[test]
fn listen_fetches_a_hesai_correction_over_ptc_and_decodes() {
    let Some(c) = common::captures() else { return };
    let _guard = serial();
    let csv = std::fs::read(c.join(CALIB).join("PandarXT32.csv")).unwrap();
    let pcap = pcap_in(&c.join(GT).join("xt32"));
    let live = listen_with_ptc(csv, &pcap, "hesai-ptc-127.0.0.1.csv");
    assert!(live["points"].as_u64().unwrap() > 200_000, "{live}");
}

/// `listen --hesai-ptc` with a fake sensor whose PTC port serves `served` and the replay of
/// `pcap` from 127.0.0.1: the fetched file (named `file`) exists while listening and its folder
/// is gone after; the run's `--json`, whose one sensor is a Hesai decoded with that file.
fn listen_with_ptc(served: Vec<u8>, pcap: &Path, file: &str) -> serde_json::Value {
    listen_with_ptc_serving(vec![(0x05, served)], pcap, file)
}

/// A fake sensor's PTC port on 127.0.0.1: one connection per `(command, payload)` of
/// `replies`, in that order, each request checked to be that command and answered with that
/// payload. Its port and the thread to join.
fn fake_ptc(replies: Vec<(u8, Vec<u8>)>) -> (u16, std::thread::JoinHandle<()>) {
    use std::io::{Read, Write};
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = l.local_addr().unwrap().port();
    let server = std::thread::spawn(move || {
        for (cmd, served) in replies {
            let (mut s, _) = l.accept().unwrap();
            let mut head = [0u8; 8];
            s.read_exact(&mut head).unwrap();
            assert_eq!(&head, &[0x47, 0x74, cmd, 0, 0, 0, 0, 0]);
            let mut r = vec![0x47, 0x74, cmd, 0];
            r.extend_from_slice(&(served.len() as u32).to_be_bytes());
            r.extend_from_slice(&served);
            s.write_all(&r).unwrap();
        }
    });
    (port, server)
}

/// [`listen_with_ptc`] with the fake sensor answering each of `replies` in turn.
fn listen_with_ptc_serving(
    replies: Vec<(u8, Vec<u8>)>,
    pcap: &Path,
    file: &str,
) -> serde_json::Value {
    // The fake sensor's PTC port, on the address the replay sends from (127.0.0.1).
    let (ptc_port, server) = fake_ptc(replies);
    let offset = free_offset(&[2368]);
    let l = start_listen(&[
        "--sensor".into(),
        format!("127.0.0.1:{}", 2368 + offset),
        "--hesai-ptc".into(),
        ptc_port.to_string(),
    ]);
    server.join().unwrap();
    // The fetched file is held in a folder of the run while it listens, and removed after.
    // The folder is private and its name not predictable from the process id alone.
    let prefix = format!("ringscan-hesai-ptc-{}-", l.child.id());
    let folders: Vec<_> = std::fs::read_dir(std::env::temp_dir())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with(&prefix))
        .map(|e| e.path())
        .collect();
    assert_eq!(folders.len(), 1, "{folders:?}");
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&folders[0]).unwrap().permissions().mode();
        assert_eq!(mode & 0o777, 0o700, "{}", folders[0].display());
    }
    let fetched = folders[0].join(file);
    assert!(fetched.is_file(), "{} while listening", fetched.display());
    replay(pcap, offset, "1", &["--per-source-loopback"]);
    std::thread::sleep(std::time::Duration::from_millis(500));
    let (code, out, err) = l.stop("INT");
    assert_eq!(code, Some(0), "{err}");
    assert!(
        !fetched.parent().unwrap().exists(),
        "{} left behind after the run",
        fetched.display()
    );
    let live: serde_json::Value =
        serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out:?} {err}"));
    let s = &live["sensors"][0];
    assert_eq!(s["kind"], "hesai", "{live}");
    let used = s["calibration"].as_str().unwrap_or_default();
    assert!(used.split(" + ").any(|f| f == file), "{live}");
    live
}

/// 3,600 packets (0.15 s) of the simulated AT128, urban scene, with the real `PandarAT128.dat`:
/// the pcap and the number of returns the decoder must give.
fn at128_capture(c: &Path, dir: &Path) -> (std::path::PathBuf, usize) {
    use ringscan::sensor::hesai::family::parse_hesai_calibration;
    use ringscan::sensor::hesai::HesaiModel;

    let dat = c.join(CALIB).join("PandarAT128.dat");
    let calib = parse_hesai_calibration(&std::fs::read(dat).unwrap())
        .unwrap()
        .unwrap();
    sim_capture(
        HesaiModel::PandarAt128,
        calib,
        3_600,
        &dir.join("at128.pcap"),
    )
}

/// `packets` packets of the simulated `model` with `calib`, at rest in the urban scene, written
/// to `pcap`: the pcap and the number of returns the decoder must give.
fn sim_capture(
    model: ringscan::sensor::hesai::HesaiModel,
    calib: ringscan::sensor::hesai::HesaiCalibration,
    packets: usize,
    pcap: &Path,
) -> (std::path::PathBuf, usize) {
    use ringscan::sensor::hesai::sim::HesaiSim;
    use ringscan::sim::{motion::Trajectory, scenes};

    let mut sim = HesaiSim::new(model, calib, 1_714_564_800_000_000_000);
    sim.trajectory = Trajectory::fixed(nalgebra::Isometry3::translation(
        40.0,
        0.0,
        scenes::SENSOR_HEIGHT_M,
    ));
    let scene = scenes::named("urban").unwrap();
    let (mut truth, mut datagrams) = (Vec::new(), Vec::new());
    while datagrams.len() < packets {
        let (host_ns, payload) = sim.next_packet(&scene, &mut truth);
        datagrams.push((host_ns, [192, 168, 1, 201], payload));
    }
    write_pcap(pcap, &datagrams);
    (pcap.to_path_buf(), truth.len())
}

/// An AT128 serves its binary `.dat` over PTC; `listen --hesai-ptc` decodes with it (the
/// command line refused binary calibrations before, so this run failed at the start).
#[test]
fn listen_fetches_an_at128_dat_over_ptc_and_decodes() {
    let Some(c) = common::captures() else { return };
    let _guard = serial();
    let dir = common::Scratch::dir("hesai-at128-ptc");
    let (pcap, returns) = at128_capture(&c, &dir);
    let dat = std::fs::read(c.join(CALIB).join("PandarAT128.dat")).unwrap();
    let live = listen_with_ptc(dat, &pcap, "hesai-ptc-127.0.0.1.dat");
    assert_eq!(live["sensors"][0]["model"], "PandarAT128", "{live}");
    // Loopback at the capture's own rate: every packet is expected, a few lost are tolerated
    // on a loaded machine (the exact count is `decode`'s test below).
    let points = live["points"].as_u64().unwrap();
    assert!(
        points as f64 > 0.9 * returns as f64 && points <= returns as u64,
        "{points} of {returns}: {live}"
    );
}

/// The AT128's binary `.dat` through `--calib`, as the README offers it (the command line once
/// refused every calibration that was not UTF-8 text, so only the library could read it): 0.3 s
/// of simulated AT128 packets made with the real `PandarAT128.dat` decode to exactly the
/// simulator's returns, and the file is attached to the MCAP as binary.
#[test]
fn decode_reads_the_at128_dat_through_calib() {
    let Some(c) = common::captures() else { return };
    let dat = c.join(CALIB).join("PandarAT128.dat");
    let dir = common::Scratch::dir("hesai-at128-cli");
    let (pcap, returns) = at128_capture(&c, &dir);
    let out = dir.join("at128.mcap");
    let o = Command::new(BIN)
        .arg("decode")
        .arg(&pcap)
        .arg("--calib")
        .arg(&dat)
        .arg("--out")
        .arg(&out)
        .arg("--json")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["points"].as_u64(), Some(returns as u64), "{j}");
    assert_eq!(j["packets"]["decoded"].as_u64(), Some(3_600), "{j}");
    let s = &j["sensors"][0];
    assert_eq!(s["model"], "PandarAT128", "{s}");
    assert_eq!(s["calibration"], "PandarAT128.dat", "{s}");
    let att = &j["output"]["attachments"][0];
    assert_eq!(att["name"], "PandarAT128.dat", "{att}");
    assert_eq!(att["media_type"], "application/octet-stream", "{att}");
    assert_eq!(att["size"].as_u64(), Some(47_176), "{att}");

    // Binary garbage is still refused with a message that says what is read.
    let junk = dir.join("junk.dat");
    std::fs::write(&junk, [0xEE, 0xFF, 0x01, 0x05, 0x80, 0x03, 0x03, 0xFF]).unwrap();
    let o = Command::new(BIN)
        .arg("decode")
        .arg(&pcap)
        .arg("--calib")
        .arg(&junk)
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("AT128"), "{err}");
}

/// A calibration no sensor takes is named, not passed over: the XT32 capture with the QT128's
/// correction file (128 rows for a 32-laser sensor). `info` reads the packets and reports the
/// file unused; `decode` stops (exit 1, nothing written), names the sensor's need and the
/// file given; with its own file, nothing is reported unused.
#[test]
fn a_calibration_no_sensor_takes_is_reported() {
    let Some(c) = common::captures() else {
        return;
    };
    let pcap = pcap_in(&c.join(GT).join("xt32"));
    let run = |cmd: &str, csv: &str, json: bool| {
        let mut c2 = Command::new(env!("CARGO_BIN_EXE_ringscan"));
        c2.arg(cmd)
            .arg(&pcap)
            .arg("--calib")
            .arg(c.join(CALIB).join(csv));
        if json {
            c2.arg("--json");
        }
        c2.output().unwrap()
    };
    let o = run("info", "PandarQT128.csv", true);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        j["unused_calibrations"],
        serde_json::json!(["PandarQT128.csv"])
    );
    assert_eq!(j["points"], 0);
    let o = run("info", "PandarQT128.csv", false);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("warning: calibration PandarQT128.csv was used by no sensor"),
        "{text}"
    );
    let out = common::Scratch::file("hesai-nocalib", "x.mcap");
    let o = Command::new(env!("CARGO_BIN_EXE_ringscan"))
        .arg("decode")
        .arg(&pcap)
        .arg("--calib")
        .arg(c.join(CALIB).join("PandarQT128.csv"))
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("PandarXT32 has no built-in calibration")
            && err.contains("PandarQT128.csv given, but it fits none of the sensors found"),
        "{err}"
    );
    assert!(!out.exists(), "a failed run wrote {}", out.display());
    let o = run("decode", "PandarXT32.csv", true);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["unused_calibrations"], serde_json::json!([]));
    assert!(j["points"].as_u64().unwrap() > 0);
}

/// `decode` of a Hesai capture without its angle correction stops with exit 1 and writes
/// nothing, as a VLS-128 without its calibration does: an empty file and exit 0 would pass
/// for a decoded capture. `info` still describes it.
#[test]
fn decode_without_the_correction_fails_and_writes_nothing() {
    let Some(c) = common::captures() else {
        return;
    };
    let pcap = pcap_in(&c.join(GT).join("xt32"));
    let out = common::Scratch::file("hesai-nocalib", "x.mcap");
    let o = Command::new(env!("CARGO_BIN_EXE_ringscan"))
        .arg("decode")
        .arg(&pcap)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains(
            "the PandarXT32 has no built-in calibration: give its calibration file with --calib"
        ) && err.contains("ringscan hesai-calib --sensor IP --out FILE"),
        "{err}"
    );
    assert!(!out.exists());
    let o = Command::new(env!("CARGO_BIN_EXE_ringscan"))
        .args(["info", "--json"])
        .arg(&pcap)
        .output()
        .unwrap();
    assert!(o.status.success());
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["sensors"][0]["model"], "PandarXT32");
    assert_eq!(j["sensors"][0]["data_packets"], 2000);
}

/// A Pandar ATX correction written here (version 4.3, 100 channels in 1/256°: azimuths ±2°,
/// odd frames 0.05° more; elevations 12.5° … −12.5°; an elevation adjustment of ±0.2°).
fn atx_dat() -> Vec<u8> {
    atx_dat_of(100)
}

/// [`atx_dat`] with `n` channels.
fn atx_dat_of(n: u8) -> Vec<u8> {
    let mut b = vec![0xEE, 0xFF, 4, 3, 0, 0, n];
    b.extend_from_slice(&256u16.to_le_bytes());
    let mut put = |v: f64| b.extend_from_slice(&((v * 256.0).round() as i16).to_le_bytes());
    for odd in [0.0, 0.05] {
        for c in 0..n {
            put((c % 4) as f64 - 2.0 + odd);
        }
    }
    for c in 0..n {
        put(12.5 - 25.0 * f64::from(c) / f64::from(n - 1));
    }
    for i in 0..70 {
        put(0.04 * ((i % 10) as f64 - 5.0));
    }
    b.extend_from_slice(&[0x5A; 32]);
    b
}

/// 2,100 packets of the simulated ATX (three frames of 700), urban scene, with `dat`: the pcap
/// and the number of returns the decoder must give.
fn atx_capture(dat: &[u8], dir: &Path) -> (std::path::PathBuf, usize) {
    use ringscan::sensor::hesai::family::parse_hesai_calibration;
    atx_capture_with(parse_hesai_calibration(dat).unwrap().unwrap(), dir)
}

fn atx_capture_with(
    calib: ringscan::sensor::hesai::HesaiCalibration,
    dir: &Path,
) -> (std::path::PathBuf, usize) {
    use ringscan::sensor::hesai::HesaiModel;
    sim_capture(HesaiModel::PandarAtx, calib, 2_100, &dir.join("atx.pcap"))
}

/// The Pandar ATX at the process boundary (no real ATX packet exists: the simulator's, with a
/// correction written in the test). `info` without its file names the model, protocol 4.7 and
/// the CRC state (present, algorithm unpublished); `decode` without it stops; with `--calib`
/// it gives exactly the simulator's returns, one sweep per frame; `listen --hesai-ptc` fetches
/// the `.dat` from a fake sensor and decodes.
#[test]
fn the_atx_decodes_through_the_command_line() {
    let dir = common::Scratch::dir("hesai-atx-cli");
    let dat = dir.join("atx.dat");
    std::fs::write(&dat, atx_dat()).unwrap();
    let (pcap, returns) = atx_capture(&atx_dat(), &dir);
    let o = Command::new(BIN)
        .arg("info")
        .arg(&pcap)
        .arg("--json")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let s = &j["sensors"][0];
    assert_eq!(s["model"], "Pandar ATX", "{s}");
    assert_eq!(s["protocol"], "4.7", "{s}");
    assert_eq!(s["return_mode"], "strongest (0x37)", "{s}");
    assert!(s["crc"].as_str().unwrap().contains("not published"), "{s}");
    assert_eq!(s["malformed"], 0, "{s}");
    assert_eq!(s["signed_packets"], 2_100, "{s}");

    let out = dir.join("atx.mcap");
    let o = Command::new(BIN)
        .arg("decode")
        .arg(&pcap)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(!out.exists());

    let o = Command::new(BIN)
        .arg("decode")
        .arg(&pcap)
        .arg("--calib")
        .arg(&dat)
        .arg("--out")
        .arg(&out)
        .arg("--json")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["points"].as_u64(), Some(returns as u64), "{j}");
    assert_eq!(j["packets"]["decoded"].as_u64(), Some(2_100), "{j}");
    assert_eq!(j["sweeps"].as_u64(), Some(3), "{j}");
    let s = &j["sensors"][0];
    assert_eq!(s["calibration"], "atx.dat", "{s}");
    assert_eq!(s["missing"], 0, "{s}");

    let _guard = serial();
    let live = listen_with_ptc(atx_dat(), &pcap, "hesai-ptc-127.0.0.1.dat");
    assert_eq!(live["sensors"][0]["model"], "Pandar ATX", "{live}");
    let points = live["points"].as_u64().unwrap();
    assert!(
        points as f64 > 0.9 * returns as f64 && points <= returns as u64,
        "{points} of {returns}: {live}"
    );
}

/// The ATX's firetime CSV given beside its `.dat` (two `--calib` files, one sensor): the
/// stream joins them (`calibration` names both) and decodes exactly the returns of a simulator
/// whose beams follow the firetime-shifted azimuths; without the CSV the same points come out
/// elsewhere; the CSV alone serves no sensor and is named.
#[test]
fn the_atx_firetime_csv_joins_its_angle_correction() {
    use ringscan::sensor::hesai::family::parse_hesai_calibration;
    use ringscan::sensor::hesai::HesaiCalibration;

    let dir = common::Scratch::dir("hesai-atx-firetimes");
    let dat = dir.join("atx.dat");
    std::fs::write(&dat, atx_dat()).unwrap();
    let mut csv = String::from("Channel,Even_fire time(ns),Odd_fire time(ns)\n");
    for c in 0..100 {
        csv.push_str(&format!(
            "{},{},{}\n",
            c + 1,
            4_960 + 480 * c,
            7_560 + 80 * c
        ));
    }
    let ft = dir.join("atx_firetimes.csv");
    std::fs::write(&ft, &csv).unwrap();
    let Some(Ok(HesaiCalibration::Atx(a))) = parse_hesai_calibration(&atx_dat()) else {
        panic!()
    };
    let Some(Ok(HesaiCalibration::AtxFiretimes(f))) = parse_hesai_calibration(csv.as_bytes())
    else {
        panic!()
    };
    let joined = HesaiCalibration::Atx(a.with_firetimes(f).unwrap());
    let (pcap, returns) = atx_capture_with(joined, &dir);
    let run = |calibs: &[&Path]| {
        let mut c = Command::new(BIN);
        c.arg("decode").arg(&pcap).arg("--json");
        for f in calibs {
            c.arg("--calib").arg(f);
        }
        c.output().unwrap()
    };
    // Either order of the two files.
    for files in [[&dat, &ft], [&ft, &dat]] {
        let o = run(&[files[0].as_path(), files[1].as_path()]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(j["points"].as_u64(), Some(returns as u64), "{j}");
        assert_eq!(
            j["sensors"][0]["calibration"], "atx.dat + atx_firetimes.csv",
            "{j}"
        );
        assert_eq!(
            j["unused_calibrations"].as_array().map_or(0, |v| v.len()),
            0,
            "{j}"
        );
    }
    // The CSV alone: no angle correction, the run stops and names the file it could not use.
    let o = run(&[ft.as_path()]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("atx_firetimes.csv"), "{err}");
}

/// Sensors are counted before decoding (one sensor: topic `/points`; several: `/<name>/points`
/// each). The ATX's length follows its header, so it is counted by its bytes: a capture of an
/// ATX and a simulated XT32 names both topics, not one `/points` and one `/<name>/points`.
#[test]
fn an_atx_is_counted_among_the_sensors_of_a_capture() {
    use ringscan::sensor::hesai::family::parse_hesai_calibration;
    use ringscan::sensor::hesai::HesaiModel;

    let dir = common::Scratch::dir("hesai-atx-count");
    let dat = dir.join("atx.dat");
    std::fs::write(&dat, atx_dat()).unwrap();
    let mut csv = String::from("Laser id,Elevation,Azimuth\n");
    for i in 0..32 {
        csv.push_str(&format!("{},{},0\n", i + 1, 15.0 - i as f64));
    }
    let xt = dir.join("xt32.csv");
    std::fs::write(&xt, &csv).unwrap();
    let calib = parse_hesai_calibration(csv.as_bytes()).unwrap().unwrap();
    let (xt_pcap, _) = sim_capture(HesaiModel::PandarXt32, calib, 400, &dir.join("xt.pcap"));
    let (atx_pcap, _) = atx_capture(&atx_dat(), &dir);
    // The XT32 at 192.168.1.202, its first packet after the ATX's: the ATX is registered first.
    let j = decode_merged(
        &dir,
        &[(atx_pcap.as_path(), 201), (xt_pcap.as_path(), 202)],
        &[dat.as_path(), xt.as_path()],
    );
    let sensors = j["sensors"].as_array().unwrap();
    assert_eq!(sensors.len(), 2, "{j}");
    for s in sensors {
        let topic = s["topic"].as_str().unwrap();
        assert_eq!(
            topic,
            format!("/{}/points", s["name"].as_str().unwrap()),
            "{j}"
        );
    }
}

/// `pcaps` merged in time order into one capture, each re-addressed to 192.168.1.`octet` and
/// each later one 1 µs later (so the sensors register in this order), decoded with `calibs`:
/// the run's `--json`.
fn decode_merged(dir: &Path, pcaps: &[(&Path, u8)], calibs: &[&Path]) -> serde_json::Value {
    let mut all: Vec<(i64, [u8; 4], Vec<u8>)> = Vec::new();
    for (i, (pcap, octet)) in pcaps.iter().enumerate() {
        for (t, _, p) in common::datagrams(pcap) {
            all.push((t + i as i64 * 1_000, [192, 168, 1, *octet], p));
        }
    }
    all.sort_by_key(|d| d.0);
    let merged = dir.join("merged.pcap");
    write_pcap(&merged, &all);
    let mut c = Command::new(BIN);
    c.arg("decode").arg(&merged).arg("--json");
    for f in calibs {
        c.arg("--calib").arg(f);
    }
    let o = c.output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// Two ATX units of different channel counts in one capture, their `.dat` files given unbound
/// and in the opposite order to the sensors': each file goes to the sensor whose header has its
/// laser count (before, the first ATX took the first ATX file, and decoded nothing with it),
/// so every simulated return of both comes out, each sensor naming its own file.
#[test]
fn atx_corrections_go_to_the_sensor_of_their_channel_count() {
    use ringscan::sensor::hesai::family::parse_hesai_calibration;
    use ringscan::sensor::hesai::HesaiModel;

    let dir = common::Scratch::dir("hesai-atx-two");
    let (wide, narrow) = (dir.join("wide.dat"), dir.join("narrow.dat"));
    std::fs::write(&wide, atx_dat_of(100)).unwrap();
    std::fs::write(&narrow, atx_dat_of(64)).unwrap();
    let mut returns = 0;
    let mut pcaps = Vec::new();
    for n in [100, 64] {
        let calib = parse_hesai_calibration(&atx_dat_of(n)).unwrap().unwrap();
        let pcap = dir.join(format!("atx{n}.pcap"));
        let (pcap, r) = sim_capture(HesaiModel::PandarAtx, calib, 1_400, &pcap);
        returns += r;
        pcaps.push(pcap);
    }
    let j = decode_merged(
        &dir,
        &[(pcaps[0].as_path(), 201), (pcaps[1].as_path(), 202)],
        &[narrow.as_path(), wide.as_path()],
    );
    assert_eq!(j["points"].as_u64(), Some(returns as u64), "{j}");
    let by_addr = |a: &str| {
        j["sensors"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["address"] == a)
            .unwrap_or_else(|| panic!("{a}: {j}"))
            .clone()
    };
    assert_eq!(by_addr("192.168.1.201")["calibration"], "wide.dat", "{j}");
    assert_eq!(by_addr("192.168.1.202")["calibration"], "narrow.dat", "{j}");
    assert_eq!(by_addr("192.168.1.202")["malformed"], 0, "{j}");
}

/// The ATX's firetimes fetched over PTC (command 0xA9, answered in the binary form built here
/// from the SDK's `ATXFiretimes`: division 10, so each u16 is tens of ns): `hesai-calib
/// --firetimes` writes them as the CSV, whose times are the ones written by hand below, and
/// with the `.dat` it decodes exactly the returns of a simulator whose beams follow the
/// firetime-shifted azimuths; `listen --hesai-ptc` fetches both and joins them.
#[test]
fn the_atx_firetimes_are_fetched_over_ptc() {
    use ringscan::sensor::hesai::family::parse_hesai_calibration;
    use ringscan::sensor::hesai::HesaiCalibration;

    let dir = common::Scratch::dir("hesai-atx-ptc-firetimes");
    let mut bin = vec![0xEE, 0xFF, 4, 1, 0, 0, 100, 10, 0];
    for c in 0..100u16 {
        bin.extend_from_slice(&(496 + 48 * c).to_le_bytes());
    }
    for c in 0..100u16 {
        bin.extend_from_slice(&(756 + 8 * c).to_le_bytes());
    }
    bin.extend_from_slice(&[0x3C; 32]);
    let (port, server) = fake_ptc(vec![(0x05, atx_dat()), (0xA9, bin.clone())]);
    let (dat, ft) = (dir.join("fetched.dat"), dir.join("fetched-firetimes.csv"));
    let o = Command::new(BIN)
        .args([
            "hesai-calib",
            "--sensor",
            &format!("127.0.0.1:{port}"),
            "--out",
        ])
        .arg(&dat)
        .arg("--firetimes")
        .arg(&ft)
        .output()
        .unwrap();
    server.join().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(std::fs::read(&dat).unwrap(), atx_dat());
    let Some(Ok(HesaiCalibration::AtxFiretimes(f))) =
        parse_hesai_calibration(&std::fs::read(&ft).unwrap())
    else {
        panic!("{} is not a firetime CSV", ft.display())
    };
    let even: Vec<f64> = (0..100).map(|c| f64::from(4_960 + 480 * c)).collect();
    let odd: Vec<f64> = (0..100).map(|c| f64::from(7_560 + 80 * c)).collect();
    assert_eq!((&f.even_ns, &f.odd_ns), (&even, &odd));

    let Some(Ok(HesaiCalibration::Atx(a))) = parse_hesai_calibration(&atx_dat()) else {
        panic!()
    };
    let (pcap, returns) =
        atx_capture_with(HesaiCalibration::Atx(a.with_firetimes(f).unwrap()), &dir);
    let o = Command::new(BIN)
        .arg("decode")
        .arg(&pcap)
        .arg("--calib")
        .arg(&dat)
        .arg("--calib")
        .arg(&ft)
        .arg("--json")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["points"].as_u64(), Some(returns as u64), "{j}");
    assert_eq!(
        j["sensors"][0]["calibration"], "fetched.dat + fetched-firetimes.csv",
        "{j}"
    );

    let _guard = serial();
    let live = listen_with_ptc_serving(
        vec![(0x05, atx_dat()), (0xA9, bin)],
        &pcap,
        "hesai-ptc-127.0.0.1-firetimes.csv",
    );
    assert_eq!(
        live["sensors"][0]["calibration"],
        "hesai-ptc-127.0.0.1.dat + hesai-ptc-127.0.0.1-firetimes.csv",
        "{live}"
    );
    let points = live["points"].as_u64().unwrap();
    assert!(
        points as f64 > 0.9 * returns as f64 && points <= returns as u64,
        "{points} of {returns}: {live}"
    );
}
