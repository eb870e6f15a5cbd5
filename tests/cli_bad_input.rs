//! Bad input through the whole `ringscan decode` path: a clear message naming the position,
//! a counted drop where the stream can go on, never a panic, never a corrupt output file.

mod common;
use common::Scratch;

use std::net::{Ipv4Addr, SocketAddrV4};
use std::path::{Path, PathBuf};
use std::process::Command;

use ringscan::sensor::velodyne::calib::builtin::builtin;
use ringscan::sensor::velodyne::sim::VelodyneSim;
use ringscan::sensor::velodyne::ReturnMode;
use ringscan::sensor::velodyne::VelodyneModel;
use ringscan::sim::net::udp_frame;
use ringscan::sim::net::PcapWriter;
use ringscan::sim::scene::Shapes;

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_ringscan")
}

fn tmp(name: &str) -> Scratch {
    Scratch::file("bad", name)
}

/// A valid VLP-16 capture of `n` packets, with `edit(i, payload)` applied to each payload.
fn capture(n: usize, edit: &dyn Fn(usize, &mut Vec<u8>)) -> Vec<u8> {
    capture_with_copy(n, edit, None)
}

/// [`capture`], packet `copy` (if any) captured twice in a row.
fn capture_with_copy(n: usize, edit: &dyn Fn(usize, &mut Vec<u8>), copy: Option<usize>) -> Vec<u8> {
    let calib = builtin(VelodyneModel::Vlp16).unwrap();
    let mut sim = VelodyneSim::new(
        VelodyneModel::Vlp16,
        ReturnMode::Strongest,
        calib,
        1_700_000_000_000_000_000,
    );
    let scene = Shapes::room(10.0, 8.0, 1.5, 3.0);
    let mut w = PcapWriter::new(Vec::new()).unwrap();
    let src = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 201), 2368);
    let dst = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 100), 2368);
    let mut truth = Vec::new();
    for i in 0..n {
        let (t, p) = sim.next_packet(&scene, &mut truth);
        let mut payload = p.to_vec();
        edit(i, &mut payload);
        for _ in 0..1 + usize::from(copy == Some(i)) {
            w.write(t, &udp_frame(src, dst, i as u16, &payload))
                .unwrap();
        }
    }
    w.into_inner().unwrap()
}

struct Run {
    code: i32,
    stdout: String,
    stderr: String,
}

fn decode(input: &Path, extra: &[&str]) -> Run {
    let out = Command::new(bin())
        .arg("decode")
        .arg(input)
        .args(extra)
        .output()
        .unwrap();
    Run {
        code: out.status.code().unwrap_or(-1),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

fn json(r: &Run) -> serde_json::Value {
    serde_json::from_str(r.stdout.trim()).unwrap_or_else(|e| panic!("not JSON ({e}): {}", r.stdout))
}

/// The output is absent or a complete MCAP (magic at both ends, summary readable).
fn assert_not_corrupt(path: &Path) {
    if !path.exists() {
        return;
    }
    let bytes = std::fs::read(path).unwrap();
    assert!(
        bytes.starts_with(b"\x89MCAP0\r\n"),
        "{}: no MCAP magic",
        path.display()
    );
    assert!(
        bytes.ends_with(b"\x89MCAP0\r\n"),
        "{}: not finalised",
        path.display()
    );
    mcap::Summary::read(&bytes).unwrap().expect("summary");
}

/// The `/points` messages of a finished MCAP (one per sweep), from its summary section.
fn points_messages(path: &Path) -> u64 {
    let summary = mcap::Summary::read(&std::fs::read(path).unwrap())
        .unwrap()
        .unwrap();
    let points = summary
        .channels
        .values()
        .find(|c| c.topic == "/points")
        .expect("a /points channel");
    summary.stats.as_ref().unwrap().channel_message_counts[&points.id]
}

fn write(name: &str, bytes: &[u8]) -> Scratch {
    let p = tmp(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn empty_file_is_a_clear_error() {
    let p = write("empty.pcap", b"");
    let out = tmp("empty.mcap");
    let r = decode(&p, &["--out", out.to_str().unwrap()]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert!(r.stderr.to_lowercase().contains("empty"), "{}", r.stderr);
    assert!(!r.stderr.contains("panicked"));
    assert_not_corrupt(&out);
}

#[test]
fn wrong_magic_names_the_bytes_found() {
    let p = write(
        "magic.pcap",
        b"GIF89a this is not a capture at all, not even close.......",
    );
    let r = decode(&p, &[]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    let e = r.stderr.to_lowercase();
    assert!(e.contains("magic"), "{}", r.stderr);
    assert!(
        e.contains("47 49 46 38")
            || e.contains("47494638")
            || e.contains("0x38464947")
            || e.contains("0x47494638"),
        "{}",
        r.stderr
    );
    // Every format the input may be is named, not pcap alone (a `.bag`, `.mcap` or `.db3`
    // of random bytes was told it was no pcap).
    for format in ["pcapng", "ROS 1 bag", "sqlite3", "MCAP", "lvx2"] {
        assert!(r.stderr.contains(format), "{format}: {}", r.stderr);
    }
    // A zstd file that does not decompress to a bag is said to be one, with why (it was told
    // its zstd magic was none of the formats', zstd's among them).
    let zstd = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures/bags/demo-vlp16.mcap-file/demo-vlp16.mcap-file.mcap.zstd");
    let whole = std::fs::read(&zstd).unwrap();
    let cut = write("cut.mcap.zstd", &whole[..whole.len() / 2]);
    let r = decode(&cut, &[]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert!(
        r.stderr.contains(
            "a zstd-compressed file (magic 28 b5 2f fd) whose start does not decompress to a \
             rosbag2 storage file (sqlite3 or MCAP): it does not decompress ("
        ) && r.stderr.contains("; cut short or damaged)"),
        "{}",
        r.stderr
    );
    // `echo hello | zstd`: one frame, a raw block, its checksum.
    let hello = [
        0x28, 0xb5, 0x2f, 0xfd, 0x04, 0x58, 0x31, 0x00, 0x00, b'h', b'e', b'l', b'l', b'o', b'\n',
        0x53, 0x88, 0xbd, 0x91,
    ];
    let r = decode(&write("hello.zst", &hello), &[]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert!(
        r.stderr.contains("it decompresses to 68 65 6c 6c 6f 0a"),
        "{}",
        r.stderr
    );
    // A directory is no rosbag2 one without its metadata.yaml (it was "Is a directory").
    let dir = Scratch::dir("plain-dir");
    let r = decode(&dir, &[]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert!(
        r.stderr
            .contains("a directory without a metadata.yaml: not a rosbag2 directory"),
        "{}",
        r.stderr
    );
}

#[test]
fn truncated_last_record_is_reported_not_fatal() {
    let mut bytes = capture(50, &|_, _| {});
    let full = bytes.len();
    bytes.truncate(full - 500);
    let p = write("trunc.pcap", &bytes);
    let out = tmp("trunc.mcap");
    let r = decode(&p, &["--json", "--out", out.to_str().unwrap()]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let j = json(&r);
    assert_eq!(j["packets"]["decoded"], 49);
    // The last record starts 16 + 1248 bytes before the original end.
    assert_eq!(
        j["capture"]["truncated_tail_offset"].as_u64(),
        Some((full - 1248 - 16) as u64)
    );
    assert_not_corrupt(&out);
    // --strict fails on it: the tail is lost, though no packet counter sees it (it exited 0).
    let r = decode(&p, &["--strict"]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert!(
        r.stderr.contains(&format!(
            "--strict: the input is cut short at byte {}",
            full - 1248 - 16
        )),
        "{}",
        r.stderr
    );
}

#[test]
fn a_record_claiming_a_gigabyte_is_an_error_with_its_offset() {
    let mut bytes = capture(5, &|_, _| {});
    // Record 3's header: 24 + 2 × (16 + 1248).
    let off = 24 + 2 * (16 + 1248);
    bytes[off + 8..off + 12].copy_from_slice(&1_000_000_000u32.to_le_bytes());
    bytes[off + 12..off + 16].copy_from_slice(&1_000_000_000u32.to_le_bytes());
    let p = write("huge.pcap", &bytes);
    let out = tmp("huge.mcap");
    let r = decode(&p, &["--out", out.to_str().unwrap()]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert!(
        r.stderr.contains(&off.to_string()),
        "offset {off} not named: {}",
        r.stderr
    );
    assert_not_corrupt(&out);
}

#[test]
fn a_record_longer_than_its_snaplen_is_caught() {
    let mut bytes = capture(5, &|_, _| {});
    // Snaplen 1000 < the 1248-byte frames.
    bytes[16..20].copy_from_slice(&1000u32.to_le_bytes());
    let p = write("snap.pcap", &bytes);
    let r = decode(&p, &["--json"]);
    assert!(!r.stderr.contains("panicked"), "{}", r.stderr);
    if r.code == 0 {
        // Accepted as a lenient reader would, but then it must say so in the counters.
        let j = json(&r);
        let c = &j["capture"];
        assert!(
            c["malformed_records"].as_u64().unwrap() + c["truncated_records"].as_u64().unwrap() > 0
                || j["packets"]["decoded"] == 5,
            "{j}"
        );
    } else {
        assert_eq!(r.code, 1);
        assert!(
            r.stderr.contains("snaplen") || r.stderr.contains("1000"),
            "{}",
            r.stderr
        );
    }
}

#[test]
fn wrong_sizes_and_bad_flags_are_counted_and_skipped() {
    let bytes = capture(60, &|i, p| match i {
        10 => p.truncate(1205),                                      // wrong size
        20 => p.extend_from_slice(&[0; 6]), // 1212 bytes, like the VLI-16 packet
        30 => p[500] = 0x00,                // block 5 flag FF EE → 00 EE
        40 => p[302..304].copy_from_slice(&40_000u16.to_le_bytes()), // azimuth out of range
        _ => {}
    });
    let p = write("sizes.pcap", &bytes);
    let out = tmp("sizes.mcap");
    let r = decode(&p, &["--json", "--out", out.to_str().unwrap()]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let j = json(&r);
    assert_eq!(j["packets"]["decoded"], 56);
    assert_eq!(j["packets"]["malformed"], 4);
    assert_not_corrupt(&out);
    // --strict turns the loss into an error, and the file is still complete.
    let r = decode(&p, &["--strict", "--out", out.to_str().unwrap()]);
    assert_eq!(r.code, 1);
    assert!(r.stderr.contains("strict"), "{}", r.stderr);
    assert_not_corrupt(&out);
}

/// A packet captured twice (a mirror port, a capture tool repeating itself) is decoded once:
/// the copy is counted in the sensor's `duplicates`, the points and sweeps are those of the
/// capture without it, and `--strict` passes, as a copy is no loss. (The copy stepped the time
/// back: a discontinuity cutting the sweep, and its points twice.)
#[test]
fn a_packet_captured_twice_is_decoded_once_and_is_no_loss() {
    let once = write("once.pcap", &capture(120, &|_, _| {}));
    let twice = write("twice.pcap", &capture_with_copy(120, &|_, _| {}, Some(50)));
    let (a, b) = (
        decode(&once, &["--json"]),
        decode(&twice, &["--json", "--strict"]),
    );
    assert_eq!((a.code, b.code), (0, 0), "{}", b.stderr);
    let (a, b) = (json(&a), json(&b));
    let s = &b["sensors"][0];
    assert_eq!(
        (&s["duplicates"], &s["discontinuities"]),
        (&1.into(), &0.into()),
        "{s}"
    );
    for k in ["points", "sweeps"] {
        assert_eq!(a[k], b[k], "{k}");
    }
    assert_eq!(a["packets"]["decoded"], b["packets"]["decoded"]);
    assert_eq!(b["packets"]["dropped"], 0);
}

#[test]
fn garbage_calibration_files_are_errors_naming_the_file_and_place() {
    let cap = write("ok.pcap", &capture(10, &|_, _| {}));
    let cases: [(&str, &[u8]); 4] = [
        ("garbage.yaml", b"lasers: [ {laser_id: 0, rot_correction: 0.0, vert_correction: oops"),
        ("binary.xml", &[0xff, 0xfe, 0x00, 0x01, 0x80]),
        ("empty.yaml", b""),
        ("wrong.xml", b"<boost_serialization><DB><points_><count>1</count></points_></DB></boost_serialization>"),
    ];
    for (name, body) in cases {
        let c = write(name, body);
        let out = tmp("calib.mcap");
        let _ = std::fs::remove_file(&out);
        let r = decode(
            &cap,
            &[
                "--calib",
                c.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
            ],
        );
        assert_eq!(r.code, 1, "{name}: {}", r.stderr);
        assert!(
            r.stderr.contains(name),
            "{name}: file not named: {}",
            r.stderr
        );
        assert!(!r.stderr.contains("panicked"), "{}", r.stderr);
        assert!(
            !out.exists(),
            "{name}: an output was created before the calibration was checked"
        );
    }
}

#[test]
fn bad_usage_exits_with_2() {
    let cap = write("ok2.pcap", &capture(5, &|_, _| {}));
    let r = decode(&cap, &["--model", "vlp99"]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    // The names accepted, grouped by family in `decode --help`'s order (it listed Hesai's
    // first, ungrouped).
    let help = Command::new(bin())
        .args(["decode", "--help"])
        .output()
        .unwrap();
    let help = String::from_utf8_lossy(&help.stdout);
    let listed = help
        .split("Sensor model, overriding detection. ")
        .nth(1)
        .and_then(|h| h.lines().next())
        .unwrap_or_else(|| panic!("no --model list in {help}"));
    assert!(
        r.stderr
            .contains(&format!("--model vlp99: expected one of {listed}")),
        "{}\nhelp: {listed}",
        r.stderr
    );
    let out = Command::new(bin()).args(["decode"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let out = Command::new(bin()).args(["frobnicate"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    // A negative value reaches its option's own check (second audit: clap took `-1` for a
    // flag and said `unexpected argument '-1'`, so `--start=-1` was needed to see it).
    let o = tmp("negative.mcap");
    for (args, said) in [
        (
            vec!["--start", "-1"],
            "--start: expected a non-negative number of seconds",
        ),
        (
            vec!["--end", "-1"],
            "--end: expected a non-negative number of seconds",
        ),
        (
            vec!["--out", o.to_str().unwrap(), "--chunk-size", "-1"],
            "expected MiB",
        ),
        (
            vec!["--out", o.to_str().unwrap(), "--threads", "-1"],
            "'-1' for '--threads",
        ),
        (
            vec!["--odometry", "--map-every", "-1"],
            "'-1' for '--map-every",
        ),
    ] {
        let r = decode(&cap, &args);
        assert_eq!(r.code, 2, "{args:?}: {}", r.stderr);
        assert!(r.stderr.contains(said), "{args:?}: {}", r.stderr);
        assert!(!r.stderr.contains("unexpected argument"), "{}", r.stderr);
    }
    let r = Command::new(bin())
        .args(["render", "x.mcap", "--out", "x.png", "--range-m", "-1"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(2), "{err}");
    assert!(err.contains("expected metres, 0.5 … 10000"), "{err}");
    // A unicast address is no multicast group: bad usage, before any socket (it was exit 1,
    // from the kernel's refusal to join).
    let r = Command::new(bin())
        .args([
            "listen",
            "--sensor",
            "127.0.0.1:9",
            "--multicast",
            "192.168.1.77",
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(2), "{err}");
    assert!(
        err.contains("--multicast 192.168.1.77: not a multicast group"),
        "{err}"
    );
}

#[test]
fn random_bytes_after_a_valid_header_never_panic() {
    // A valid header, then pseudo-random bytes (xorshift): an error or a clean end, no panic.
    let mut bytes = capture(3, &|_, _| {});
    let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
    for _ in 0..200_000 {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        bytes.push(x as u8);
    }
    let p = write("random.pcap", &bytes);
    let out = tmp("random.mcap");
    let r = decode(&p, &["--out", out.to_str().unwrap()]);
    assert!(r.code == 0 || r.code == 1, "{}", r.stderr);
    assert!(!r.stderr.contains("panicked"), "{}", r.stderr);
    assert_not_corrupt(&out);
}

/// `--out` is written beside the path and renamed over it, so a path that is not a regular
/// file is refused before anything is decoded (a device such as `/dev/null` would otherwise be
/// replaced by the MCAP); a symbolic link to a file writes that file and stays a link.
#[cfg(unix)]
#[test]
fn out_that_is_not_a_file_is_refused_and_a_link_writes_its_target() {
    let p = write("ok.pcap", &capture(80, &|_, _| {}));
    let dir = Scratch::dir("bad-out");
    let fifo = dir.join("fifo");
    let made = Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(made.success());
    for (what, path) in [
        ("a device, pipe or socket", fifo.as_path()),
        ("a directory", &*dir),
    ] {
        let r = decode(&p, &["--out", path.to_str().unwrap()]);
        assert_eq!(r.code, 2, "{}", r.stderr);
        assert!(r.stderr.contains(what), "{}", r.stderr);
    }
    use std::os::unix::fs::FileTypeExt;
    assert!(std::fs::symlink_metadata(&fifo)
        .unwrap()
        .file_type()
        .is_fifo());
    let target = dir.join("target.mcap");
    std::fs::write(&target, b"old").unwrap();
    let link = dir.join("link.mcap");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let r = decode(&p, &["--out", link.to_str().unwrap()]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(std::fs::symlink_metadata(&link)
        .unwrap()
        .file_type()
        .is_symlink());
    assert_not_corrupt(&target);
    assert!(std::fs::metadata(&target).unwrap().len() > 1000);
}

/// A run that fails before any sweep is decoded writes no output: no empty MCAP, and a file
/// already at the path (or a rosbag2 folder's absence) stays as it was. One that fails later
/// keeps what it decoded, finalised.
#[test]
fn a_run_that_decodes_nothing_leaves_the_output_path_as_it_was() {
    let mut bytes = capture(80, &|_, _| {});
    // The first record claims a gigabyte: an error before any sweep.
    bytes[24 + 8..24 + 12].copy_from_slice(&1_000_000_000u32.to_le_bytes());
    bytes[24 + 12..24 + 16].copy_from_slice(&1_000_000_000u32.to_le_bytes());
    let p = write("first-huge.pcap", &bytes);
    let out = tmp("keep.mcap");
    std::fs::write(&out, b"an earlier run's file").unwrap();
    let r = decode(&p, &["--out", out.to_str().unwrap()]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert_eq!(std::fs::read(&out).unwrap(), b"an earlier run's file");
    let bag = Scratch::dir("bad-bag");
    let bag_dir = bag.join("run");
    let r = decode(
        &p,
        &["--format", "ros2", "--out", bag_dir.to_str().unwrap()],
    );
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert!(!bag_dir.exists(), "an empty bag folder was left");

    // The damage after 200 packets (over two sweeps): the sweeps before it are written.
    let mut bytes = capture(240, &|_, _| {});
    let off = 24 + 200 * (16 + 42 + 1206);
    bytes[off + 8..off + 12].copy_from_slice(&1_000_000_000u32.to_le_bytes());
    bytes[off + 12..off + 16].copy_from_slice(&1_000_000_000u32.to_le_bytes());
    let p = write("late-huge.pcap", &bytes);
    let r = decode(&p, &["--out", out.to_str().unwrap()]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert_not_corrupt(&out);
    // The error says the file was written after all, with the sweeps it holds.
    let sweeps = points_messages(&out);
    assert!(sweeps > 0);
    assert!(
        r.stderr.trim_end().ends_with(&format!(
            "; {} was written with the {sweeps} sweeps decoded before",
            out.display()
        )),
        "{}",
        r.stderr
    );
}

/// `replay` says in its text output how many datagrams an offset pushed past port 65535 (they
/// are skipped), and refuses an offset no port survives.
#[test]
fn replay_reports_datagrams_its_port_offset_skips() {
    let p = write("replay.pcap", &capture(20, &|_, _| {}));
    let run = |offset: &str| {
        let o = Command::new(bin())
            .args(["replay", p.to_str().unwrap(), "--to", "127.0.0.1"])
            .args(["--rate", "max", "--port-offset", offset])
            .output()
            .unwrap();
        (
            o.status.code().unwrap_or(-1),
            String::from_utf8_lossy(&o.stdout).into_owned(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    // 2368 + 63200 = 65568: every data packet is skipped, so the replay failed at its one
    // job: exit 1 (it was 0), after the summary that says why.
    let (code, out, err) = run("63200");
    assert_eq!(code, 1, "{err}");
    assert!(out.contains("sent 0 datagrams"), "{out}");
    assert!(out.contains("skipped 20 datagrams"), "{out}");
    assert!(
        err.contains("no datagram was sent (20 outside the port range with --port-offset 63200"),
        "{err}"
    );
    let (code, _, err) = run("70000");
    assert_eq!(code, 2, "{err}");
    // One port in range: sent, exit 0.
    let (code, out, err) = run("1");
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("sent 20 datagrams"), "{out}");
}

/// Values that would do nothing, or something other than asked, are bad usage (exit 2) with a
/// message naming them, instead of being replaced or accepted without a word (from the audit):
/// an empty or `/`-bearing `--name` (an empty frame id breaks TF), a negative `--min-range`
/// (it said "empty range"), a bag window that ends before it starts, `replay --loop 0` (sent
/// once), `render --range-m 0` / `nan` (drawn at 40 m) and `--size-px 8192` (clamped).
#[test]
fn values_that_would_be_ignored_are_refused() {
    let cap = write("ok3.pcap", &capture(5, &|_, _| {}));
    for (args, says) in [
        (&["--name", ""][..], "--name"),
        (&["--name", "a/b"], "--name"),
        (&["--min-range=-1"], "0 m or more"),
        (&["--start", "5", "--end", "1"], "ends before it starts"),
    ] {
        let r = decode(&cap, args);
        assert_eq!(r.code, 2, "{args:?}: {}", r.stderr);
        assert!(r.stderr.contains(says), "{args:?}: {}", r.stderr);
    }
    let code = |args: &[&str]| {
        let o = Command::new(bin()).args(args).output().unwrap();
        (
            o.status.code(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    let p = cap.to_str().unwrap();
    for args in [
        &["replay", p, "--to", "127.0.0.1", "--loop", "0"][..],
        &[
            "render",
            p,
            "--sweep",
            "0",
            "--out",
            "x.png",
            "--range-m",
            "0",
        ],
        &[
            "render",
            p,
            "--sweep",
            "0",
            "--out",
            "x.png",
            "--range-m",
            "nan",
        ],
        &[
            "render",
            p,
            "--sweep",
            "0",
            "--out",
            "x.png",
            "--size-px",
            "8192",
        ],
        // Seconds past what a clock deadline holds panicked (`Duration::from_secs_f64`,
        // `Instant + Duration`) instead of being refused.
        &["replay", p, "--to", "127.0.0.1", "--duration", "1e20"][..],
        &["listen", "--sensor", "127.0.0.1:1", "--duration", "1e20"][..],
        &["listen", "--sensor", "127.0.0.1:1", "--duration", "1.5e19"][..],
        &[
            "hesai-calib",
            "--sensor",
            "127.0.0.1:1",
            "--out",
            "x.csv",
            "--timeout",
            "1e20",
        ][..],
    ] {
        let (c, err) = code(args);
        assert_eq!(c, Some(2), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}

/// `info` says why it found no sensor: nothing read (an empty capture), or datagrams that no
/// family recognised, counted (an Ouster capture without its metadata: every datagram of the
/// pcap). It used to give the Ouster hint whatever the cause.
#[test]
fn no_sensor_found_says_why() {
    let Some(root) = common::captures() else {
        return;
    };
    let dir = root.join("ouster-lidar__ouster-sdk/tests/pcaps");
    let info = |p: &Path| {
        let o = Command::new(bin()).arg("info").arg(p).output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let empty = info(&dir.join("empty_pcap.pcap"));
    assert!(
        empty.contains("no sensor found: no datagram was read"),
        "{empty}"
    );
    let pcap = dir.join("OS-2-128-U1_v2.3.0_1024x10.pcap");
    let n = common::datagrams(&pcap).len();
    assert!(n > 0);
    let out = info(&pcap);
    assert!(
        out.contains(&format!(
            "no sensor found: {n} datagrams that no sensor family recognised"
        )) && out.contains("--calib META.json"),
        "{out}"
    );
}

/// An option that only one family reads, on a capture of another family, is reported instead
/// of passing for applied (`--fov` on a Velodyne capture left its 872,800 points unchanged
/// without a word); on a capture of that family it is not. A deskew that could not run (no IMU
/// on an HDL-32E) is said in the text output, not only in `--json`.
#[test]
fn options_of_another_family_and_a_skipped_deskew_are_reported() {
    let Some(root) = common::captures() else {
        return;
    };
    let velodyne = root.join("Kitware__VeloView/Testing/Data/monterey-first-100-packets.pcap");
    let hesai = root.join(
        "tier4__nebula/src/nebula_hesai/nebula_hesai/test_resources/decoder_ground_truth/xt32/1673400677802009732/1673400677802009732_0.pcap",
    );
    let out = tmp("family-options.mcap");
    let run = |input: &Path, extra: &[&str]| {
        let o = Command::new(bin())
            .arg("decode")
            .arg(input)
            .arg("--out")
            .arg(&*out)
            .args(extra)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let j: serde_json::Value = serde_json::from_str(&run(
        &velodyne,
        &["--fov", "30:150", "--integration-ms", "50", "--json"],
    ))
    .unwrap();
    let unused: Vec<&str> = j["unused_options"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|v| v.as_str())
        .collect();
    assert_eq!(unused.len(), 2, "{unused:?}");
    assert!(
        unused[0].starts_with("--fov applies to Hesai sensors only"),
        "{unused:?}"
    );
    assert!(
        unused[1].starts_with("--integration-ms applies to Livox"),
        "{unused:?}"
    );
    let text = run(&velodyne, &["--fov", "30:150"]);
    assert!(text.contains("warning: --fov applies to Hesai"), "{text}");

    let xt32_csv = root
        .join("tier4__nebula/src/nebula_hesai/nebula_hesai_decoders/calibration/PandarXT32.csv");
    let j: serde_json::Value = serde_json::from_str(&run(
        &hesai,
        &[
            "--fov",
            "30:150",
            "--json",
            "--calib",
            xt32_csv.to_str().unwrap(),
        ],
    ))
    .unwrap();
    assert_eq!(j["unused_options"], serde_json::json!([]));

    let text = run(&velodyne, &["--pipeline", "default", "--deskew", "imu"]);
    assert!(
        text.contains("warning: deskew skipped on 19 sweeps"),
        "{text}"
    );
}

/// `render`'s exit codes follow the other commands (from the audit: every failure was 2): a file
/// it cannot read or write is an error (1), asking for what the file does not hold or for an
/// output path that is a directory is bad usage (2). The PNG is renamed into place, so a
/// directory or device at `--out` is refused before anything is drawn and no temporary file is
/// left behind.
#[test]
fn render_exit_codes_and_output_path() {
    let cap = write("render.pcap", &capture(400, &|_, _| {}));
    let mcap = tmp("render.mcap");
    let r = decode(
        &cap,
        &["--pipeline", "default", "--out", mcap.to_str().unwrap()],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let png = tmp("render.png");
    let render = |input: &Path, sweep: &str, out: &Path| {
        let o = Command::new(bin())
            .arg("render")
            .arg(input)
            .args(["--sweep", sweep, "--out"])
            .arg(out)
            .output()
            .unwrap();
        (
            o.status.code(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    let (c, err) = render(&mcap, "0", &png);
    assert_eq!(c, Some(0), "{err}");
    let drawn = std::fs::read(&*png).unwrap();
    assert_eq!(&drawn[1..4], b"PNG");
    let dir = png.parent().unwrap();
    let leftovers: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains("tmp-ringscan"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");

    let (c, err) = render(&mcap, "0", dir);
    assert_eq!(c, Some(2), "a directory: {err}");
    // A directory that does not exist is a mistake in the path, named before drawing.
    let (c, err) = render(&mcap, "0", &dir.join("no/such/dir/b.png"));
    assert_eq!(c, Some(2), "a path whose directory does not exist: {err}");
    assert!(err.contains("does not exist; create it first"), "{err}");
    let (c, err) = render(&cap, "0", &png);
    assert_eq!(c, Some(1), "not an MCAP: {err}");
    // A name another format's readers would open: refused, nothing written (it wrote PNG
    // bytes into a .jpg).
    let jpg = tmp("render.jpg");
    let (c, err) = render(&mcap, "0", &jpg);
    assert_eq!(c, Some(2), "a .jpg: {err}");
    assert!(err.contains("render writes PNG only"), "{err}");
    assert!(!jpg.exists());
    // Nor a name without an extension (it wrote PNG bytes there).
    let bare = tmp("render-bare");
    let (c, err) = render(&mcap, "0", &bare);
    assert_eq!(c, Some(2), "no extension: {err}");
    assert!(err.contains("render writes PNG only"), "{err}");
    assert!(!bare.exists());
    let upper = tmp("render.PNG");
    assert_eq!(render(&mcap, "0", &upper).0, Some(0));
    let (c, err) = render(&mcap, "9999", &png);
    assert_eq!(c, Some(2), "a sweep the file does not hold: {err}");
    // It says how many the file holds: its sweeps, as decode counted them.
    let sweeps = json(&decode(&cap, &["--json"]))["sweeps"].as_u64().unwrap();
    assert!(
        err.contains(&format!(
            "which holds {sweeps} (--sweep 0 … {})",
            sweeps - 1
        )),
        "{err}"
    );
    assert_eq!(
        std::fs::read(&*png).unwrap(),
        drawn,
        "the picture already there is kept"
    );
}

/// `--port` that no data packet went to: the run found no sensor to decode, so it fails (exit
/// 1, nothing written) naming the port the packets went to, in text and in the `--json` error
/// object. It exited 0 over an empty MCAP, with a sensor line of gaps
/// (`sensor - (…), ports []: model unknown (no data packet decoded) -, `, `calibration: ;`).
#[test]
fn a_port_no_data_packet_went_to_is_explained() {
    let Some(c) = common::captures() else {
        return;
    };
    let pcap = c.join("jerry73204__rust-lidar-utils/test_files/hdl32_example.pcap");
    let data: Vec<u16> = common::datagrams(&pcap)
        .iter()
        .filter(|(_, _, p)| p.len() == 1206)
        .map(|(_, port, _)| *port)
        .collect();
    assert!(!data.is_empty());
    let out = tmp("port.mcap");
    let run = |json: bool| {
        let mut args = vec!["--port", "9999", "--out", out.to_str().unwrap()];
        if json {
            args.push("--json");
        }
        decode(&pcap, &args)
    };
    let r = run(false);
    let why = format!(
        "{} data packets, none of them to --port 9999 (the first went to port {})",
        data.len(),
        data[0]
    );
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert!(r.stderr.contains(&why), "{}", r.stderr);
    assert!(!out.exists());
    let r = run(true);
    assert_eq!(r.code, 1, "{}", r.stderr);
    let j = json(&r);
    assert_eq!(j["kind"], "no_sensor", "{j}");
    assert_eq!(j["no_sensor"], why.as_str(), "{j}");
    assert!(!out.exists());
}

/// Two sensors, one sending to `--port` and one to another: the run decodes the first, and
/// the second is named by its address with what happened to its packets, not with the gaps of
/// a sensor line (`sensor - (…)`, `ports []`, `model unknown … -, `, `calibration: ;`).
#[test]
fn a_sensor_whose_packets_all_went_to_another_port_is_one_plain_line() {
    let one = capture(60, &|_, _| {});
    // Each packet sent again by a second address, to port 2369.
    let mut w = PcapWriter::new(Vec::new()).unwrap();
    let mut r = ringscan::source::pcap::PcapSource::new(std::io::Cursor::new(one)).unwrap();
    while let Some(d) = r.next_datagram().unwrap() {
        let src = *d.src.ip();
        w.write(
            d.time_ns,
            &udp_frame(
                SocketAddrV4::new(src, 2368),
                SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 100), 2368),
                0,
                d.payload,
            ),
        )
        .unwrap();
        w.write(
            d.time_ns + 1000,
            &udp_frame(
                SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 202), 2368),
                SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 100), 2369),
                0,
                d.payload,
            ),
        )
        .unwrap();
    }
    let p = write("two-ports.pcap", &w.into_inner().unwrap());
    let r = decode(&p, &["--port", "2368"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout
            .contains("sensor 192.168.1.202: velodyne, no datagram decoded (none to --port)"),
        "{}",
        r.stdout
    );
    assert!(
        r.stdout
            .contains("sensor vlp16-201 (192.168.1.201), ports [2368]: VLP-16"),
        "{}",
        r.stdout
    );
    for gap in ["sensor - (", "ports []", " -, ", "calibration: ;"] {
        assert!(!r.stdout.contains(gap), "{gap:?} in {}", r.stdout);
    }
    assert!(
        r.stdout
            .contains("60 data packets went to other ports than --port: dropped, not decoded"),
        "{}",
        r.stdout
    );
}

/// A reader that goes away (`ringscan info X | head -1`) or a full device on stdout: the command
/// panicked (exit 101, "failed printing to stdout") on its summary. Now a closed pipe ends the
/// output quietly with the run's own exit code, as `cat` does, and a full device is an error
/// (exit 1) that says so; the MCAP is written either way.
#[test]
fn stdout_closed_or_full_is_no_panic() {
    use std::process::Stdio;
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo-vlp16.pcap");
    for args in [&["info"][..], &["info", "--json"], &["decode", "--json"]] {
        // A pipe whose reading end is closed before the command writes.
        let out = tmp("closed-pipe.mcap");
        let mut child = Command::new(bin())
            .args(args)
            .arg(&demo)
            .args(if args[0] == "decode" {
                vec!["--out".as_ref(), out.as_os_str()]
            } else {
                vec![]
            })
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take());
        let o = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(0), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        if args[0] == "decode" {
            assert_not_corrupt(&out);
        }
        // A full device.
        if Path::new("/dev/full").exists() {
            let full = std::fs::OpenOptions::new()
                .write(true)
                .open("/dev/full")
                .unwrap();
            let o = Command::new(bin())
                .args(args)
                .arg(&demo)
                .stdout(full)
                .output()
                .unwrap();
            let err = String::from_utf8_lossy(&o.stderr);
            assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
            assert!(
                err.contains("writing the output to stdout"),
                "{args:?}: {err}"
            );
            assert!(!err.contains("panicked"), "{args:?}: {err}");
        } else {
            eprintln!("SKIP: /dev/full is absent");
        }
    }
}

/// A `--format ros2` bag whose MCAP cannot be finished (its disk full: the file is written
/// through a link to /dev/full here) leaves no `metadata.yaml` behind: before, the empty one
/// written at the start stayed, a directory that looked like a bag and made the next run into
/// the same --out refuse ("already holds a rosbag2").
#[test]
fn a_bag_that_could_not_be_written_leaves_no_metadata() {
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo-vlp16.pcap");
    if !Path::new("/dev/full").exists() {
        eprintln!("SKIP: /dev/full is absent");
        return;
    }
    let dir = Scratch::dir("bag-full");
    let bag = dir.join("drive");
    std::fs::create_dir(&bag).unwrap();
    std::os::unix::fs::symlink("/dev/full", bag.join("drive_0.mcap.tmp-ringscan")).unwrap();
    let run = || {
        Command::new(bin())
            .arg("decode")
            .arg(&demo)
            .args(["--format", "ros2", "--out"])
            .arg(&bag)
            .output()
            .unwrap()
    };
    let o = run();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("No space left on device"), "{err}");
    assert!(!bag.join("metadata.yaml").exists(), "{err}");
    // The same --out again (the link went with the failed file): a bag.
    let o = run();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(bag.join("metadata.yaml").is_file());
    assert_not_corrupt(&bag.join("drive_0.mcap"));
}

/// A `--format ros2` bag whose MCAP was finished but whose `metadata.yaml` then cannot be
/// written (the yaml's temporary file a link to /dev/full, made once the run has started)
/// leaves nothing: the MCAP stayed, without the yaml that makes the directory a bag.
#[test]
fn a_bag_whose_metadata_cannot_be_written_at_the_end_leaves_nothing() {
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo-vlp16.pcap");
    if !Path::new("/dev/full").exists() {
        eprintln!("SKIP: /dev/full is absent");
        return;
    }
    let dir = Scratch::dir("bag-yaml-full");
    let bag = dir.join("drive");
    // Paced by the live view at the capture's own speed (1 s), so the link can be made after
    // the yaml of the start and before the one of the end.
    let child = Command::new(bin())
        .arg("decode")
        .arg(&demo)
        .args(["--format", "ros2", "--serve", "127.0.0.1:0", "--out"])
        .arg(&bag)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    while !bag.join("metadata.yaml").exists() {
        assert!(
            started.elapsed().as_secs() < 20,
            "no metadata.yaml at the start"
        );
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    std::os::unix::fs::symlink("/dev/full", bag.join("metadata.yaml.tmp-ringscan")).unwrap();
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        started.elapsed().as_millis() > 300,
        "the run ended before the link was made: {err}"
    );
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("metadata.yaml"), "{err}");
    assert!(!bag.join("metadata.yaml").exists(), "{err}");
    assert!(!bag.join("drive_0.mcap").exists(), "{err}");
}

/// A `--format ros2` run refused after its checks (a `--serve` that cannot start) leaves no
/// bag behind: the empty `metadata.yaml` and the directory it made stayed, and made the next
/// run into the same --out refuse ("already holds a rosbag2").
#[test]
fn a_bag_run_that_fails_at_its_start_leaves_nothing() {
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo-vlp16.pcap");
    let dir = Scratch::dir("bag-start");
    let bag = dir.join("drive");
    let o = Command::new(bin())
        .arg("decode")
        .arg(&demo)
        .args([
            "--format",
            "ros2",
            "--serve",
            "127.0.0.1:0",
            "--serve-queue",
            "0",
            "--out",
        ])
        .arg(&bag)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("--serve-queue"), "{err}");
    assert!(!bag.exists(), "{err}");
}

/// A run that finds no sensor has decoded nothing: exit 1 with the reason, and nothing written
/// (a file already at `--out` is left as it was; no bag directory is made), as a sensor that
/// cannot be decoded (Hesai or VLS-128 without their file) already was. It used to exit 0 and
/// write an empty MCAP over `--out`. `info` still reports the reason and exits 0; of an MCAP
/// of decoded points that ringscan wrote, it says so, and no longer warns that the
/// calibration attached to it "was used by no sensor", as if the user had given it.
#[test]
fn a_run_that_finds_no_sensor_fails_and_writes_nothing() {
    let bytes = capture(40, &|_, _| {});
    let vlp16 = write("nosensor-vlp16.pcap", &bytes);
    // The file header and the start of the first record: no datagram.
    let header_only = write("nosensor-header.pcap", &bytes[..30]);
    let bag = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/bags/demo-vlp16.ros1-lz4.bag");
    let dir = Scratch::dir("no-sensor");
    let points_of = |capture: &Path, calib: Option<&Path>, name: &str| {
        let out = dir.join(name);
        let mut c = Command::new(bin());
        c.arg("decode").arg(capture).arg("--out").arg(&out);
        if let Some(calib) = calib {
            c.arg("--calib").arg(calib);
        }
        assert!(c.output().unwrap().status.success());
        out
    };
    let points = points_of(&vlp16, None, "points.mcap");
    let mut cases: Vec<(PathBuf, Vec<&str>, String)> = vec![
        (
            points,
            vec![],
            "the bag holds decoded point clouds (/points), not packets".into(),
        ),
        (
            header_only.to_path_buf(),
            vec![],
            "no datagram was read: the capture ends at byte 24, inside its first record".into(),
        ),
        (
            vlp16.to_path_buf(),
            vec!["--model", "pandarxt32"],
            "40 datagrams, none of them a packet of --model pandarxt32".into(),
        ),
        (
            bag,
            vec!["--topic", "/velodyne_packet"],
            "--topic /velodyne_packet is none of the bag's packet topics (/velodyne_packets)"
                .into(),
        ),
    ];
    match common::captures() {
        Some(root) => {
            let pcap =
                root.join("ouster-lidar__ouster-sdk/tests/pcaps/OS-2-128-U1_v2.3.0_1024x10.pcap");
            let n = common::datagrams(&pcap).len();
            cases.push((
                pcap,
                vec![],
                format!("{n} datagrams that no sensor family recognised"),
            ));
            let nv = root.join("tier4__nebula/src/nebula_velodyne");
            let points = points_of(
                &nv.join("nebula_velodyne/test_resources/decoder_ground_truth/vlp16/1673400471837873222/1673400471837873222_0.pcap"),
                Some(&nv.join("nebula_velodyne_decoders/calibration/VLP16.yaml")),
                "points-attached.mcap",
            );
            cases.push((
                points,
                vec![],
                "the bag holds decoded point clouds (/points), not packets".into(),
            ));
        }
        None => eprintln!("SKIP: ../shared/captures not found: the Ouster case"),
    }
    for (input, extra, why) in &cases {
        let out = dir.join("keep.mcap");
        std::fs::write(&out, b"an earlier run's file").unwrap();
        let mut args = extra.clone();
        args.extend(["--out", out.to_str().unwrap()]);
        let r = decode(input, &args);
        assert_eq!(r.code, 1, "{input:?} {extra:?}: {}", r.stderr);
        assert!(
            r.stderr.contains(&format!("no sensor found: {why}"))
                && r.stderr.trim_end().ends_with("; nothing written"),
            "{input:?} {extra:?}: {}",
            r.stderr
        );
        assert_eq!(std::fs::read(&out).unwrap(), b"an earlier run's file");
        let bag_dir = dir.join("bag");
        let mut args = extra.clone();
        args.extend(["--format", "ros2", "--out", bag_dir.to_str().unwrap()]);
        let r = decode(input, &args);
        assert_eq!(r.code, 1, "{input:?} {extra:?}: {}", r.stderr);
        assert!(
            !bag_dir.exists(),
            "{input:?} {extra:?}: a bag directory was left"
        );
        let o = Command::new(bin())
            .arg("info")
            .arg(input)
            .args(extra)
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(text.contains(&format!("no sensor found: {why}")), "{text}");
        assert!(!text.contains("was used by no sensor"), "{text}");
    }
}

/// A `--model` that the packets contradict still wins, but is warned of: a VLP-16 capture
/// (product id 0x22) decoded as an HDL-32E gave wrong points without a word. The right model
/// gives no warning.
#[test]
fn a_model_the_packets_contradict_is_warned_of() {
    let p = write("contradicted.pcap", &capture(40, &|_, _| {}));
    let r = decode(&p, &["--model", "hdl32e"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout.contains(
            "warning: sensor 192.168.1.201: --model hdl32e, though the packets say VLP-16: \
             product id 0x22"
        ),
        "{}",
        r.stdout
    );
    // Told from the first packet (a forced model is not waited on): not "one packet" of 40.
    assert!(
        r.stdout
            .contains("not checked against the cadence (told from the first packet alone)"),
        "{}",
        r.stdout
    );
    let r = decode(&p, &["--model", "vlp16"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(!r.stdout.contains("warning"), "{}", r.stdout);
}

/// A pipe as the input (`cat X | ringscan info /dev/stdin`) is refused with the reason: the
/// input is opened more than once, and the second reader met bytes from the middle of the
/// stream ("expected magic … found 39093634"). `-` says standard input is not read. The same
/// path redirected from a file is a file, and works.
#[test]
fn a_pipe_as_input_is_refused_with_the_reason() {
    use std::io::Write as _;
    use std::process::Stdio;
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo-vlp16.pcap");
    let mut child = Command::new(bin())
        .args(["info", "/dev/stdin"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let bytes = std::fs::read(&demo).unwrap();
    // The reader may refuse before reading: a closed pipe is no failure here.
    let _ = child.stdin.take().unwrap().write_all(&bytes);
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("/dev/stdin: a pipe, socket or device, not a file"),
        "{err}"
    );
    let out = Command::new(bin()).args(["info", "-"]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("-: standard input, not a file"), "{err}");
    let out = Command::new(bin())
        .args(["info", "/dev/stdin"])
        .stdin(std::fs::File::open(&demo).unwrap())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// An `--extrinsics` for a sensor name that does not exist is a warning of the summary (it was
/// only a log line, and `--json`'s `pipeline.extrinsics_unused`), and that log line, written
/// to a file or pipe, carries no terminal colour codes.
#[test]
fn unused_extrinsics_are_warned_of_and_logs_to_a_pipe_have_no_colours() {
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo-vlp16.pcap");
    let r = decode(
        &demo,
        &[
            "--pipeline",
            "default",
            "--extrinsics",
            "wrongname=0,0,1.8,0,0,0",
        ],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout.contains(
            "warning: --extrinsics wrongname=…: no sensor of that name (sensor names: \
             vlp16-201); not applied"
        ),
        "{}",
        r.stdout
    );
    assert!(r.stderr.contains("WARN"), "the log line: {}", r.stderr);
    assert!(!r.stderr.contains('\x1b'), "colour codes: {:?}", r.stderr);
}

/// `--out` mistakes are bad usage (exit 2), named before decoding: a directory that does not
/// exist (it was exit 1, naming ringscan's temporary file), `--format ros2` onto an existing
/// file (exit 1, "File exists"); negative numbers reach the options' own checks (clap took
/// `-1` for an option and asked for `--min-range=-1`).
#[test]
fn out_mistakes_and_negative_values_are_named() {
    let p = write("out-mistakes.pcap", &capture(20, &|_, _| {}));
    let dir = Scratch::dir("out-mistakes");
    let missing = dir.join("no/such/dir/x.mcap");
    let r = decode(&p, &["--out", missing.to_str().unwrap()]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr.contains(&format!(
            "its directory {} does not exist; create it first",
            missing.parent().unwrap().display()
        )),
        "{}",
        r.stderr
    );
    let file = dir.join("afile");
    std::fs::write(&file, b"kept").unwrap();
    let r = decode(&p, &["--format", "ros2", "--out", file.to_str().unwrap()]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("it is a file"), "{}", r.stderr);
    assert_eq!(std::fs::read(&file).unwrap(), b"kept");
    for (args, says) in [
        (
            ["--min-range", "-1"],
            "--min-range -1: expected a distance of 0 m or more",
        ),
        (
            ["--cut-angle", "-10"],
            "--cut-angle -10: expected [0, 360) degrees",
        ),
    ] {
        let r = decode(&p, &args);
        assert_eq!(r.code, 2, "{args:?}: {}", r.stderr);
        assert!(r.stderr.contains(says), "{args:?}: {}", r.stderr);
    }
}

/// A bag reader's error names its file once (it was `error: x.bag: x.bag: record header …`).
#[test]
fn a_damaged_bag_is_named_once() {
    let mut bag = b"#ROSBAG V2.0\n".to_vec();
    // A record header length far beyond the limit.
    bag.extend_from_slice(&0x0435_6870_u32.to_le_bytes());
    bag.extend_from_slice(&[0; 64]);
    let p = write("damaged.bag", &bag);
    let r = decode(&p, &[]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    let name = p.display().to_string();
    assert_eq!(r.stderr.matches(&name).count(), 1, "{}", r.stderr);
    assert!(
        r.stderr.contains("record header at byte 13"),
        "{}",
        r.stderr
    );
}

/// With `--json`, a run that fails prints one JSON object on stdout as a run that succeeds
/// does (it printed nothing, leaving a script only the exit code and a line of text): the
/// error, its kind, the exit code, and for a run that kept its first sweeps the file and their
/// count. `--strict`, which fails on what its summary reports, prints that summary alone.
#[test]
fn a_failed_run_with_json_prints_an_error_object() {
    let one_object = |r: &Run| {
        assert_eq!(r.stdout.trim().lines().count(), 1, "{}", r.stdout);
        let j = json(r);
        assert_eq!(
            j["error"].as_str().map(|e| format!("error: {e}\n")),
            Some(r.stderr.clone()),
            "the object and stderr differ: {j} / {}",
            r.stderr
        );
        assert_eq!(j["exit_code"], r.code, "{j}");
        j
    };
    // Input that cannot be read: exit 1.
    let missing = tmp("nothing-here.pcap");
    let r = decode(&missing, &["--json"]);
    assert_eq!(r.code, 1);
    assert_eq!(one_object(&r)["kind"], "input");
    // Bad usage found after the arguments were parsed: exit 2.
    let p = write("json-fail.pcap", &capture(240, &|_, _| {}));
    let r = decode(&p, &["--json", "--out", "/nonexistent-dir/x.mcap"]);
    assert_eq!(r.code, 2);
    assert_eq!(one_object(&r)["kind"], "usage");
    // `info` too.
    let o = Command::new(bin())
        .args(["info", "--json"])
        .arg(&missing)
        .output()
        .unwrap();
    let r = Run {
        code: o.status.code().unwrap_or(-1),
        stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
    };
    assert_eq!(r.code, 1);
    assert_eq!(one_object(&r)["kind"], "input");
    // Damage after 200 packets: the sweeps before it are kept, and the object says so.
    let mut bytes = capture(240, &|_, _| {});
    let off = 24 + 200 * (16 + 42 + 1206);
    bytes[off + 8..off + 12].copy_from_slice(&1_000_000_000u32.to_le_bytes());
    let p = write("json-late-huge.pcap", &bytes);
    let out = tmp("json-kept.mcap");
    let r = decode(&p, &["--json", "--out", out.to_str().unwrap()]);
    assert_eq!(r.code, 1);
    let j = one_object(&r);
    assert_eq!(j["kind"], "input", "{j}");
    assert_eq!(j["output"]["path"], out.to_str().unwrap(), "{j}");
    assert_eq!(j["output"]["sweeps"], points_messages(&out), "{j}");
    // --strict: the summary is the one object.
    let bytes = capture(60, &|i, p| {
        if i == 10 {
            p.truncate(1205)
        }
    });
    let p = write("json-strict.pcap", &bytes);
    let r = decode(&p, &["--json", "--strict"]);
    assert_eq!(r.code, 1);
    assert_eq!(r.stdout.trim().lines().count(), 1, "{}", r.stdout);
    let j = json(&r);
    assert_eq!(j["packets"]["malformed"], 1, "{j}");
    assert!(j.get("error").is_none(), "{j}");
}

/// An output that cannot grow (a disk full; here a file-size limit, `ulimit -f`, which fails
/// the write the same way without filling a disk) is an error that names the file. It said
/// `writing an MCAP chunk: No space left on device`, without saying where. Nothing is left at
/// the path, in either format.
#[cfg(unix)]
#[test]
fn an_output_that_cannot_grow_is_named() {
    let p = write("grow.pcap", &capture(2000, &|_, _| {}));
    let dir = Scratch::dir("grow");
    for (out, format) in [
        (dir.join("big.mcap"), "foxglove"),
        (dir.join("bag"), "ros2"),
    ] {
        // SIGXFSZ ignored (an ignored signal stays ignored across exec): the write fails
        // with EFBIG instead of the process being killed. 64 blocks of 512 bytes.
        let o = Command::new("sh")
            .arg("-c")
            .arg("trap '' XFSZ; ulimit -f 64; exec \"$@\"")
            .arg("sh")
            .arg(bin())
            .arg("decode")
            .arg(&p)
            .args(["--compression", "none", "--format", format, "--out"])
            .arg(&out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(
            err.starts_with(&format!("error: {}: ", out.display())),
            "{err}"
        );
        assert!(!out.exists(), "{} was left", out.display());
    }
}

/// A range option that keeps no point of the packets decoded is warned of, one rule for every
/// family: a Hesai XT32 (120 m) with `--min-range 150` failed with `invalid option: range
/// 150–120 m is empty` (exit 1, and once blaming its calibration), a Velodyne exited 0 with
/// 0 points and no word.
#[test]
fn a_range_that_keeps_no_point_is_warned_of_in_every_family() {
    let p = write("range.pcap", &capture(200, &|_, _| {}));
    let warned = |r: &Run, n: u64, opt: &str| {
        assert_eq!(r.code, 0, "{}", r.stderr);
        assert!(
            r.stdout.contains(&format!(
                "  warning: {opt}: no point of the {n} packets decoded is in that range"
            )),
            "{}",
            r.stdout
        );
    };
    // The simulated room is 10 × 8 m: nothing is 150 m away, nor within 1 cm.
    warned(&decode(&p, &["--min-range", "150"]), 200, "--min-range 150");
    warned(
        &decode(&p, &["--max-range", "0.01"]),
        200,
        "--max-range 0.01",
    );
    let r = decode(&p, &["--max-range", "50"]);
    assert!(!r.stdout.contains("warning"), "{}", r.stdout);
    let j = json(&decode(&p, &["--min-range", "150", "--json"]));
    assert_eq!(j["points"], 0);
    assert_eq!(j["warnings"].as_array().map(Vec::len), Some(1), "{j}");
    let Some(c) = common::captures() else {
        return;
    };
    let nh = c.join("tier4__nebula/src/nebula_hesai");
    let pcap = nh.join(
        "nebula_hesai/test_resources/decoder_ground_truth/xt32/1673400677802009732/1673400677802009732_0.pcap",
    );
    let n = common::datagrams(&pcap).len() as u64;
    let csv = nh.join("nebula_hesai_decoders/calibration/PandarXT32.csv");
    warned(
        &decode(
            &pcap,
            &["--calib", csv.to_str().unwrap(), "--min-range", "150"],
        ),
        n,
        "--min-range 150",
    );
}

/// An output path that names a file the run reads (the input, a calibration, through a link
/// or not) or another output of the run is bad usage, refused before anything is written: the
/// capture was replaced by the MCAP (or by the trajectory's text), exit 0.
#[test]
fn an_output_over_an_input_is_refused() {
    let dir = Scratch::dir("over-input");
    let cap = dir.join("in.pcap");
    let bytes = capture(240, &|_, _| {});
    std::fs::write(&cap, &bytes).unwrap();
    let yaml = dir.join("vlp16.yaml");
    let mut text = String::from("lasers:\n");
    for i in 0..16 {
        text.push_str(&format!(
            "- {{laser_id: {i}, rot_correction: 0.0, vert_correction: {}, dist_correction: 0.0, vert_offset_correction: 0.0, horiz_offset_correction: 0.0}}\n",
            (-15.0 + 2.0 * i as f64).to_radians()
        ));
    }
    std::fs::write(&yaml, &text).unwrap();
    #[cfg(unix)]
    std::os::unix::fs::symlink(&cap, dir.join("link.mcap")).unwrap();
    let p = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let cases: Vec<(Vec<String>, &str)> = vec![
        (vec!["--out".into(), p("in.pcap")], "--out"),
        (
            vec!["--out".into(), format!("{}/./in.pcap", dir.display())],
            "--out",
        ),
        (
            vec![
                "--calib".into(),
                p("vlp16.yaml"),
                "--out".into(),
                p("vlp16.yaml"),
            ],
            "--out",
        ),
        (
            vec!["--odometry".into(), "--trajectory".into(), p("in.pcap")],
            "--trajectory",
        ),
        (
            vec![
                "--odometry".into(),
                "--trajectory".into(),
                p("o.mcap"),
                "--out".into(),
                p("o.mcap"),
            ],
            "--trajectory",
        ),
        #[cfg(unix)]
        (vec!["--out".into(), p("link.mcap")], "--out"),
    ];
    for (args, flag) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let r = decode(&cap, &args);
        assert_eq!(r.code, 2, "{args:?}: {}", r.stderr);
        assert!(
            r.stderr.starts_with(&format!("error: {flag} "))
                && r.stderr.contains("the same file as"),
            "{args:?}: {}",
            r.stderr
        );
        assert_eq!(
            std::fs::read(&cap).unwrap(),
            bytes,
            "{args:?}: the capture changed"
        );
        assert_eq!(std::fs::read_to_string(&yaml).unwrap(), text);
        assert!(!dir.join("o.mcap").exists());
    }
    // A bag directory's MCAP over INPUT (a capture named as the bag's first file): the
    // rename at the end replaced the capture with the bag's file.
    let bagdir = dir.join("bag");
    std::fs::create_dir(&bagdir).unwrap();
    let inside = bagdir.join("bag_0.mcap");
    std::fs::write(&inside, &bytes).unwrap();
    let r = decode(
        &inside,
        &["--format", "ros2", "--out", bagdir.to_str().unwrap()],
    );
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr.starts_with("error: --out ") && r.stderr.contains("the same file as INPUT"),
        "{}",
        r.stderr
    );
    assert_eq!(
        std::fs::read(&inside).unwrap(),
        bytes,
        "the capture changed"
    );
    assert!(!bagdir.join("metadata.yaml").exists());
    // render: its PNG over the MCAP it reads.
    let mcap = dir.join("run");
    let r = decode(
        &cap,
        &["--pipeline", "default", "--out", mcap.to_str().unwrap()],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let before = std::fs::read(&mcap).unwrap();
    let o = Command::new(bin())
        .arg("render")
        .arg(&mcap)
        .arg("--out")
        .arg(&mcap)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert_eq!(std::fs::read(&mcap).unwrap(), before);
}

/// Flags named before any work: `--trajectory` in a missing directory (the whole capture was
/// decoded and written, then the run failed), odometry flags without `--odometry` (the method
/// and range were accepted and did nothing), `--format ros2` in a missing directory (made
/// silently, where every other `--out` is refused).
#[test]
fn odometry_and_bag_paths_are_checked_first() {
    let p = write("first.pcap", &capture(240, &|_, _| {}));
    let dir = Scratch::dir("checked-first");
    let out = dir.join("o.mcap");
    let r = decode(
        &p,
        &[
            "--odometry",
            "--trajectory",
            dir.join("nodir/t.tum").to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
    );
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr.contains("does not exist; create it first"),
        "{}",
        r.stderr
    );
    assert!(!out.exists());
    for flag in [
        ["--odometry-method", "point-to-point"],
        ["--odometry-max-range", "5"],
    ] {
        let r = decode(&p, &flag);
        assert_eq!(r.code, 2, "{flag:?}: {}", r.stderr);
        assert!(
            r.stderr.contains(&format!("{} needs --odometry", flag[0])),
            "{}",
            r.stderr
        );
    }
    let bag = dir.join("nodir/bag");
    let r = decode(&p, &["--format", "ros2", "--out", bag.to_str().unwrap()]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(!dir.join("nodir").exists());
}

/// `--json` with arguments that do not parse (an unknown value, a missing INPUT) prints the
/// error object too; `--help` is not an error. A `replay` of an input with nothing to send
/// exits 1 (it exited 0 unless an offset had pushed ports out of range).
#[test]
fn json_usage_errors_and_a_replay_with_nothing_to_send() {
    let p = write("usage.pcap", &capture(5, &|_, _| {}));
    let run = |args: &[&str]| {
        let o = Command::new(bin()).args(args).output().unwrap();
        Run {
            code: o.status.code().unwrap_or(-1),
            stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
            stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
        }
    };
    let ps = p.to_str().unwrap();
    for args in [
        vec!["decode", ps, "--json", "--compression", "gzip"],
        vec!["decode", "--json"],
        vec!["info", "--json", ps, "--bogus"],
    ] {
        let r = run(&args);
        assert_eq!(r.code, 2, "{args:?}");
        let j = json(&r);
        assert_eq!(j["kind"], "usage", "{j}");
        assert_eq!(j["exit_code"], 2, "{j}");
        let first = r
            .stderr
            .lines()
            .next()
            .unwrap()
            .trim_start_matches("error: ");
        assert!(
            j["error"].as_str().unwrap().starts_with(first),
            "{j} / {}",
            r.stderr
        );
    }
    // Not an error, and `--json` after `--` is no flag.
    assert_eq!(run(&["decode", "--help", "--json"]).code, 0);
    let r = run(&["decode", "--", "--json"]);
    assert_eq!(r.code, 1);
    assert!(r.stdout.is_empty(), "{}", r.stdout);
    // A capture of no datagram: nothing to send.
    let empty = write("nothing.pcap", &capture(0, &|_, _| {}));
    let r = run(&[
        "replay",
        empty.to_str().unwrap(),
        "--to",
        "127.0.0.1",
        "--rate",
        "max",
    ]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert!(r.stdout.contains("sent 0 datagrams"), "{}", r.stdout);
    assert!(
        r.stderr
            .contains("no datagram was sent: the input holds none"),
        "{}",
        r.stderr
    );
}

/// Flags that only work with another: `--serve-rate` and `--serve-queue` without `--serve`
/// were accepted and did nothing; one sensor placed twice with `--extrinsics` kept the first
/// placement without a word.
#[test]
fn flags_that_would_do_nothing_are_refused() {
    let p = write("nothing-done.pcap", &capture(5, &|_, _| {}));
    for args in [
        vec!["--serve-rate", "2"],
        vec!["--serve-queue", "3"],
        vec![
            "--pipeline",
            "default",
            "--extrinsics",
            "vlp16-201=1,0,0,0,0,0",
            "--extrinsics",
            "vlp16-201=5,0,0,0,0,0",
        ],
        // Output options without an output (second audit: they were accepted and did nothing).
        vec!["--raw"],
        vec!["--format", "ros2"],
        vec!["--compression", "lz4"],
        vec!["--threads", "2"],
        vec!["--chunk-size", "1"],
        // A field of view beyond a turn was taken modulo 360.
        vec!["--fov", "400:10"],
        vec!["--fov", "-10:90"],
    ] {
        let r = decode(&p, &args);
        assert_eq!(r.code, 2, "{args:?}: {}", r.stderr);
    }
    // A constant-velocity deskew with no twist moves no point.
    let r = decode(&p, &["--deskew", "constant-velocity"]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("the twist is zero"), "{}", r.stderr);
    let twist = tmp("twist.toml");
    std::fs::write(&*twist, "[deskew]\nlinear_mps = [3.0, 0, 0]\n").unwrap();
    let r = decode(
        &p,
        &[
            "--pipeline",
            twist.to_str().unwrap(),
            "--deskew",
            "constant-velocity",
        ],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let r = decode(
        &p,
        &[
            "--pipeline",
            "default",
            "--extrinsics",
            "vlp16-201=1,0,0,0,0,0",
            "--extrinsics",
            "vlp16-201=5,0,0,0,0,0",
        ],
    );
    assert!(
        r.stderr.contains("--extrinsics vlp16-201=…: given twice"),
        "{}",
        r.stderr
    );
}

/// A `--topic` the bag does not have, beside one it has, is warned of (a typo selected
/// nothing, silently; second audit); the run reads the bag's topic as it would alone.
#[test]
fn an_unknown_topic_beside_a_known_one_is_warned_of() {
    let bag = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/bags/demo-vlp16.ros1-lz4.bag");
    let run = |extra: &[&str]| {
        let mut args = vec!["--json"];
        args.extend(extra);
        let r = decode(&bag, &args);
        assert_eq!(r.code, 0, "{}", r.stderr);
        serde_json::from_str::<serde_json::Value>(&r.stdout).unwrap()
    };
    let both = run(&[
        "--topic",
        "/velodyne_packets",
        "--topic",
        "/velodyne_packet",
    ]);
    let known = run(&["--topic", "/velodyne_packets"]);
    assert_eq!(
        both["unused_options"],
        serde_json::json!([
            "--topic /velodyne_packet: the bag has no such topic (the other --topic values were read)"
        ])
    );
    assert_eq!(known["unused_options"], serde_json::json!([]));
    assert!(known["points"].as_u64().unwrap() > 0);
    assert_eq!(both["points"], known["points"]);
}
