//! Bags carry the same packets, and decode to the same points, as the captures they hold.
//!
//! - The bag fixtures (`fixtures/bags`, made from `fixtures/demo-vlp16.pcap` by
//!   `tools/make_test_bags.py`): every container gives exactly the pcap's data packets, times
//!   and ports, and the same sweeps point for point.
//! - nebula's VLP-16 / VLP-32C / VLS-128 `.db3` bags in `../shared/captures` against the pcaps
//!   converted from them (directory and bare `.db3`): same datagrams, same sweeps.
//! - Every container `tools/make_test_bags.py` writes (ROS 1 none / bz2 / lz4; rosbag2 sqlite3
//!   and MCAP, uncompressed, zstd per file and per message; the bare `.db3` / `.mcap` inside),
//!   made during the test from a shared Velodyne pcap and a shared Ouster pcap with its
//!   metadata: same datagrams, same sweeps as the pcap. Skipped (SKIP) without python3 / venv.
//!
//! Goldens (velodyne_decoder, ouster-sdk) through bags: `tests/velodyne_golden.rs` and
//! `tests/ouster_golden.rs`.

mod common;

use std::net::{Ipv4Addr, SocketAddrV4};
use std::path::{Path, PathBuf};
use std::process::Command;

use ringscan::point::Point;
use ringscan::sensor::{self, CalibrationPool, StreamSettings};
use ringscan::source::bag::{BagOptions, BagSource, Family};
use ringscan::source::pcap::PcapSource;
use ringscan::sweep::Demux;

/// One datagram: time, source, destination port, payload.
type Dgram = (i64, SocketAddrV4, u16, Vec<u8>);

fn pcap_datagrams(path: &Path) -> Vec<Dgram> {
    let mut src = PcapSource::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut out = Vec::new();
    while let Some(d) = src.next_datagram().unwrap() {
        out.push((d.time_ns, d.src, d.dst.port(), d.payload.to_vec()));
    }
    out
}

fn bag_datagrams(path: &Path) -> (Vec<Dgram>, BagSource) {
    let mut src = BagSource::open(path, BagOptions::default())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut out = Vec::new();
    while let Some(d) = src
        .next_datagram()
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
    {
        out.push((d.time_ns, d.src, d.dst.port(), d.payload.to_vec()));
    }
    let st = src.stats();
    assert_eq!(
        st.malformed,
        0,
        "{}: {:?}",
        path.display(),
        st.first_malformed
    );
    assert_eq!(st.truncated_at, None, "{}", path.display());
    assert_eq!(st.bad_chunks, 0, "{}", path.display());
    (out, src)
}

/// What a sensor is decoded with.
enum Calib {
    Velodyne(Option<PathBuf>),
    Ouster(String),
}

/// Every sweep (timestamp, points) of the datagrams, through `Demux` as `decode` does it.
fn sweeps(datagrams: &[Dgram], calib: &Calib) -> Vec<(i64, u32, Vec<Point>)> {
    // The calibration through the family registry, as `decode --calib` reads it.
    let calibs = match calib {
        Calib::Velodyne(path) => path
            .iter()
            .map(|p| sensor::parse_calibration(&std::fs::read(p).unwrap(), "calib", None).unwrap())
            .collect(),
        Calib::Ouster(text) => {
            vec![sensor::parse_calibration(text.as_bytes(), "metadata", None).unwrap()]
        }
    };
    let mut pool = CalibrationPool::new(calibs, StreamSettings::default());
    let mut demux = Demux::new(Box::new(move |d| sensor::claim(d, &mut pool)), None);
    let mut out = Vec::new();
    for (t, src, port, payload) in datagrams {
        demux
            .push(*t, *src.ip(), *port, payload, &mut |_, s, _| {
                out.push((s.timestamp_ns, s.packets, s.points.clone()))
            })
            .unwrap();
    }
    demux
        .finish(&mut |_, s, _| out.push((s.timestamp_ns, s.packets, s.points.clone())))
        .unwrap();
    out
}

/// The bag's datagrams are the expected ones (time, port, payload; source 127.0.0.1) and decode
/// to the same sweeps, point for point.
fn check_same(what: &str, expected: &[Dgram], got: &[Dgram], calib: &Calib) -> (usize, usize) {
    assert_eq!(got.len(), expected.len(), "{what}: datagrams");
    for (i, (e, g)) in expected.iter().zip(got).enumerate() {
        assert_eq!(e.0, g.0, "{what}: time of datagram {i}");
        assert_eq!(e.2, g.2, "{what}: port of datagram {i}");
        assert!(e.3 == g.3, "{what}: payload of datagram {i}");
        assert_eq!(*g.1.ip(), Ipv4Addr::new(127, 0, 0, 1), "{what}: source");
    }
    let a = sweeps(expected, calib);
    let b = sweeps(got, calib);
    assert_eq!(a.len(), b.len(), "{what}: sweeps");
    let mut points = 0;
    for (k, (x, y)) in a.iter().zip(&b).enumerate() {
        assert_eq!(
            (x.0, x.1),
            (y.0, y.1),
            "{what}: sweep {k} timestamp / packets"
        );
        assert_eq!(x.2.len(), y.2.len(), "{what}: sweep {k} points");
        assert!(x.2 == y.2, "{what}: sweep {k}: a point differs");
        points += x.2.len();
    }
    assert!(points > 0, "{what}: no point decoded");
    (a.len(), points)
}

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures")
}

#[test]
fn fixture_bags_carry_the_demo_packets_and_points() {
    let pcap: Vec<Dgram> = pcap_datagrams(&fixtures().join("demo-vlp16.pcap"))
        .into_iter()
        .take(64)
        .filter(|d| d.3.len() == 1206)
        .collect();
    let dir = fixtures().join("bags");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "md") {
            continue;
        }
        let (got, src) = bag_datagrams(&path);
        assert_eq!(src.sensors().len(), 1);
        assert_eq!(src.sensors()[0].family, Family::Velodyne);
        let (s, p) = check_same(
            &path.display().to_string(),
            &pcap,
            &got,
            &Calib::Velodyne(None),
        );
        println!(
            "{}: {} datagrams, {s} sweeps, {p} points",
            path.display(),
            got.len()
        );
        n += 1;
    }
    assert_eq!(n, 4, "four bag fixtures");
}

#[test]
fn nebula_velodyne_bags_decode_like_their_pcaps() {
    let Some(root) = common::captures() else {
        return;
    };
    let base = root.join("tier4__nebula/src/nebula_velodyne");
    let truth = base.join("nebula_velodyne/test_resources/decoder_ground_truth");
    let calib = base.join("nebula_velodyne_decoders/calibration");
    for (dir, cal) in [
        ("vlp16/1673400471837873222", "VLP16.yaml"),
        ("vlp32/1713492677464078412", "VLP32.yaml"),
        ("vls128/1614315746471294674", "VLS128.yaml"),
    ] {
        let d = truth.join(dir);
        let stem = dir.rsplit('/').next().unwrap();
        let pcap = pcap_datagrams(&d.join(format!("{stem}_0.pcap")));
        let c = Calib::Velodyne(Some(calib.join(cal)));
        for input in [d.clone(), d.join(format!("{stem}_0.db3"))] {
            let (got, _) = bag_datagrams(&input);
            let (s, p) = check_same(&input.display().to_string(), &pcap, &got, &c);
            println!(
                "{}: {} datagrams, {s} sweeps, {p} points",
                input.display(),
                got.len()
            );
        }
    }
}

/// Runs `tools/make_test_bags.py`; `None` (after a SKIP line) when Python or its venv cannot.
fn make_bags(args: &[&str], out: &Path) -> Option<Vec<PathBuf>> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/make_test_bags.py");
    let run = Command::new("python3")
        .arg(&script)
        .args(args)
        .arg("--out")
        .arg(out)
        .output();
    match run {
        Ok(o) if o.status.success() => Some(
            String::from_utf8_lossy(&o.stdout)
                .lines()
                .map(PathBuf::from)
                .collect(),
        ),
        Ok(o) => {
            eprintln!(
                "SKIP: tools/make_test_bags.py failed (no venv / rosbags?): {}",
                String::from_utf8_lossy(&o.stderr)
                    .lines()
                    .last()
                    .unwrap_or("")
            );
            None
        }
        Err(e) => {
            eprintln!("SKIP: python3 not available: {e}");
            None
        }
    }
}

/// A bag directory, and the storage file inside it read bare.
fn with_bare_files(list: Vec<PathBuf>) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for p in list {
        if p.is_dir() {
            for e in std::fs::read_dir(&p).unwrap() {
                let f = e.unwrap().path();
                if f.file_name().is_some_and(|n| n != "metadata.yaml") {
                    out.push(f);
                }
            }
        }
        out.push(p);
    }
    out
}

#[test]
fn every_container_gives_the_pcaps_packets_and_points() {
    let Some(root) = common::captures() else {
        return;
    };
    let tmp = Path::new(env!("CARGO_TARGET_TMPDIR")).join("bags-every-container");
    let _ = std::fs::remove_dir_all(&tmp);
    // Velodyne: an HDL-32E capture (data and position packets; the bag holds the data packets).
    let vpcap =
        root.join("jerry73204__rust-lidar-utils/velodyne-test/test_files/velodyne_vlp32.pcap");
    let Some(vbags) = make_bags(
        &["--pcap", vpcap.to_str().unwrap(), "--chunk-bytes", "65536"],
        &tmp,
    ) else {
        return;
    };
    let vcal = root.join("ros-drivers__velodyne/velodyne_pointcloud/params/32db.yaml");
    let expected: Vec<Dgram> = pcap_datagrams(&vpcap)
        .into_iter()
        .filter(|d| d.3.len() == 1206)
        .collect();
    let mut rows = Vec::new();
    for b in with_bare_files(vbags) {
        let (got, _) = bag_datagrams(&b);
        let (s, p) = check_same(
            &b.display().to_string(),
            &expected,
            &got,
            &Calib::Velodyne(Some(vcal.clone())),
        );
        rows.push(format!("{}: {s} sweeps, {p} points", b.display()));
    }
    // Ouster: OS-0-32 dual return, lidar and IMU packets, metadata inside the bag.
    let odir = root.join("ouster-lidar__ouster-sdk/tests/pcaps");
    let opcap = odir.join("OS-0-32-U1_v2.2.0_1024x10.pcap");
    let ometa = odir.join("OS-0-32-U1_v2.2.0_1024x10.json");
    let Some(obags) = make_bags(
        &[
            "--pcap",
            opcap.to_str().unwrap(),
            "--metadata",
            ometa.to_str().unwrap(),
        ],
        &tmp,
    ) else {
        return;
    };
    let text = std::fs::read_to_string(&ometa).unwrap();
    let expected = pcap_datagrams(&opcap);
    for b in with_bare_files(obags) {
        let (got, src) = bag_datagrams(&b);
        assert_eq!(src.sensors().len(), 1);
        assert_eq!(src.sensors()[0].family, Family::Ouster);
        assert_eq!(src.sensors()[0].metadata.as_deref(), Some(text.as_str()));
        let (s, p) = check_same(
            &b.display().to_string(),
            &expected,
            &got,
            &Calib::Ouster(text.clone()),
        );
        rows.push(format!("{}: {s} sweeps, {p} points", b.display()));
    }
    assert_eq!(
        rows.len(),
        2 * (9 + 6),
        "9 bags and 6 bare files per capture"
    );
    for r in rows {
        println!("{r}");
    }
}

/// The summary names the container as a reader would: a rosbag2 directory and the bare
/// `.db3` inside it are both rosbag2 (from the audit: `rosbag2` and `Sqlite3`), a fixture
/// ROS 1 bag is a ROS 1 bag.
#[test]
fn summaries_name_the_bag_container() {
    let kind = |input: &Path| -> String {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_ringscan"))
            .args(["info", "--json"])
            .arg(input)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        j["capture"]["bag"]["kind"].as_str().unwrap().to_string()
    };
    let ros1 = std::fs::read_dir(fixtures().join("bags"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "bag"));
    if let Some(bag) = ros1 {
        assert_eq!(kind(&bag), "ROS 1 bag");
    }
    let Some(root) = common::captures() else {
        return;
    };
    let d = root.join(
        "tier4__nebula/src/nebula_velodyne/nebula_velodyne/test_resources/decoder_ground_truth/vlp16/1673400471837873222",
    );
    assert_eq!(kind(&d), "rosbag2 directory");
    assert_eq!(
        kind(&d.join("1673400471837873222_0.db3")),
        "rosbag2 sqlite3 file"
    );
}

/// `decode --raw` keeps every datagram of its sensors in the MCAP it writes (`<sensor>/raw`,
/// `ringscan.RawPacket`), so that MCAP is a source again: the same datagrams as the capture
/// (time, source address and port, destination port, payload), and `decode` of it, with the
/// calibrations the MCAP carries as attachments, gives the capture's sensors, sweeps and
/// points. Two Ouster units sending to the same ports (`same_ports_nonlegacy.pcap`) are told
/// apart only by their addresses, which the raw messages keep.
#[test]
fn a_raw_mcap_gives_back_the_captures_datagrams() {
    let mut cases = vec![(fixtures().join("demo-vlp16.pcap"), Vec::new())];
    match common::captures() {
        Some(root) => {
            let d = root.join("ouster-lidar__ouster-sdk/tests/pcaps");
            cases.push((
                d.join("same_ports_nonlegacy.pcap"),
                vec![
                    d.join("same_ports_nonlegacy.1.json"),
                    d.join("same_ports_nonlegacy.2.json"),
                ],
            ));
        }
        None => eprintln!("SKIP: ../shared/captures not found: the two-Ouster case"),
    }
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("raw_mcap");
    std::fs::create_dir_all(&dir).unwrap();
    let run = |args: &[&std::ffi::OsStr]| -> serde_json::Value {
        let o = Command::new(env!("CARGO_BIN_EXE_ringscan"))
            .args(args)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let sensors = |j: &serde_json::Value| -> Vec<(String, u64, u64, String)> {
        let mut v: Vec<_> = (j["sensors"].as_array().unwrap().iter())
            .map(|s| {
                (
                    s["address"].as_str().unwrap().to_string(),
                    s["sweeps"].as_u64().unwrap(),
                    s["points"].as_u64().unwrap(),
                    s["calibration_file"].to_string(),
                )
            })
            .collect();
        v.sort();
        v
    };
    for (pcap, calibs) in cases {
        let out = dir.join(pcap.file_stem().unwrap()).with_extension("mcap");
        let _ = std::fs::remove_file(&out);
        let mut args: Vec<&std::ffi::OsStr> = vec![
            "decode".as_ref(),
            pcap.as_os_str(),
            "--raw".as_ref(),
            "--json".as_ref(),
            "--out".as_ref(),
            out.as_os_str(),
        ];
        for c in &calibs {
            args.extend(["--calib".as_ref(), c.as_os_str()]);
        }
        let wrote = run(&args);
        let want = pcap_datagrams(&pcap);
        let (got, _) = bag_datagrams(&out);
        assert_eq!(got.len(), want.len(), "{}: datagrams", pcap.display());
        for (i, (w, g)) in want.iter().zip(&got).enumerate() {
            assert_eq!((w.0, w.1, w.2), (g.0, g.1, g.2), "datagram {i}");
            assert!(w.3 == g.3, "payload of datagram {i}");
        }
        let again = run(&["decode".as_ref(), out.as_os_str(), "--json".as_ref()]);
        let (a, b) = (sensors(&wrote), sensors(&again));
        assert_eq!(a.len(), calibs.len().max(1), "{wrote}");
        assert_eq!(
            a,
            b,
            "{}: the capture's sensors, then the MCAP's",
            pcap.display()
        );
        assert!(a.iter().all(|s| s.2 > 0), "{a:?}");
        eprintln!("{}: {} datagrams, sensors {b:?}", pcap.display(), got.len());
    }
}
