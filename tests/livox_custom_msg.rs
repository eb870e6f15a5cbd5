//! Bags of points the Livox ROS drivers decoded (`livox_ros_driver/CustomMsg` in ROS 1,
//! `livox_ros_driver2/CustomMsg` in ROS 1 and in CDR) read into ringscan's sweeps. The bags are
//! written here byte by byte from the message definition (Header, uint64 timebase, uint32
//! point_num, uint8 lidar_id, uint8[3] rsvd, CustomPoint[] {uint32 offset_time, float32 x y z,
//! uint8 reflectivity, tag, line}) and the container formats (ROS 1 bag records, MCAP records),
//! holding what decoding a simulated MID-360's packets gives, one message per sweep. Reading
//! them back must give the same points: xyz exactly (the floats travel as they are), the time
//! exactly to the ns (timebase + offset_time), line as ring, reflectivity as intensity, the
//! tag. A rosbag2 sqlite3 / MCAP written by the `rosbags` library is checked by
//! `tools/ci_livox_custommsg_check.sh` (`tools/make_livox_custommsg_bag.py`).
#![cfg(all(feature = "sim", feature = "bag"))]

use std::path::PathBuf;

use ringscan::point::Point;
use ringscan::sensor::livox::model::LivoxModel;
use ringscan::sensor::livox::sim::LivoxSim;
use ringscan::sensor::livox::{LivoxConfig, LivoxStream};
use ringscan::sensor::{self, CalibrationPool, StreamSettings};
use ringscan::sim::motion::{Route, Trajectory};
use ringscan::sim::scenes;
use ringscan::source::bag::{BagOptions, BagSource, Family};
use ringscan::sweep::{Demux, Sweep};

const T0: i64 = 1_714_564_800_000_000_000;

/// The sweeps of decoding a simulated MID-360's packets (what `decode` of its pcap gives).
fn decoded_sweeps() -> Vec<Sweep> {
    let mut sim = LivoxSim::new(LivoxModel::Mid360, T0);
    sim.trajectory = Trajectory::route(T0, Route::urban());
    let (mut truth, mut imu) = (Vec::new(), Vec::new());
    let packets = sim.run_until(&scenes::urban(), T0 + 350_000_000, &mut truth, &mut imu);
    let mut s = LivoxStream::new(LivoxConfig::new(
        Some(LivoxModel::Mid360),
        LivoxModel::Mid360.protocol(),
    ));
    let mut out = Vec::new();
    for (host, _, b) in &packets {
        s.push(*host, b, &mut |sw, _| out.push(sw.clone()));
    }
    s.finish(&mut |sw, _| out.push(sw.clone()));
    assert!(out.len() >= 3);
    // The simulator writes no tags; give the messages some, so the tag's path is seen.
    for (i, p) in out.iter_mut().flat_map(|w| w.points.iter_mut()).enumerate() {
        p.pad = [0, 0x10, 0x24, 0x3f][i % 4];
    }
    out
}

/// Serialization of one CustomMsg: ROS 1 (no alignment, Header with seq) or CDR (4-byte
/// encapsulation, each primitive aligned to its size from its end).
fn custom_msg(cdr: bool, sweep: &Sweep, frame_id: &str) -> Vec<u8> {
    let mut m: Vec<u8> = if cdr { vec![0, 1, 0, 0] } else { Vec::new() };
    let align = |m: &mut Vec<u8>, n: usize| {
        if cdr {
            while (m.len() - 4) % n != 0 {
                m.push(0);
            }
        }
    };
    let stamp = sweep.device_time_ns;
    if !cdr {
        m.extend_from_slice(&7u32.to_le_bytes()); // seq
    }
    m.extend_from_slice(&((stamp / 1_000_000_000) as u32).to_le_bytes());
    m.extend_from_slice(&((stamp % 1_000_000_000) as u32).to_le_bytes());
    let fid_len = frame_id.len() + usize::from(cdr); // CDR strings count their NUL
    m.extend_from_slice(&(fid_len as u32).to_le_bytes());
    m.extend_from_slice(frame_id.as_bytes());
    if cdr {
        m.push(0);
    }
    align(&mut m, 8);
    m.extend_from_slice(&(sweep.device_time_ns as u64).to_le_bytes()); // timebase
    m.extend_from_slice(&(sweep.points.len() as u32).to_le_bytes()); // point_num
    m.push(3); // lidar_id
    m.extend_from_slice(&[0, 0, 0]); // rsvd
    align(&mut m, 4);
    m.extend_from_slice(&(sweep.points.len() as u32).to_le_bytes());
    for p in &sweep.points {
        align(&mut m, 4);
        m.extend_from_slice(&p.t.to_le_bytes()); // offset_time
        for v in [p.x, p.y, p.z] {
            m.extend_from_slice(&v.to_le_bytes());
        }
        m.extend_from_slice(&[p.intensity as u8, p.pad, p.ring as u8]);
    }
    m
}

fn field(name: &str, value: &[u8]) -> Vec<u8> {
    let mut f = ((name.len() + 1 + value.len()) as u32)
        .to_le_bytes()
        .to_vec();
    f.extend_from_slice(name.as_bytes());
    f.push(b'=');
    f.extend_from_slice(value);
    f
}

fn record(header: &[Vec<u8>], data: &[u8]) -> Vec<u8> {
    let h: Vec<u8> = header.concat();
    let mut r = (h.len() as u32).to_le_bytes().to_vec();
    r.extend_from_slice(&h);
    r.extend_from_slice(&(data.len() as u32).to_le_bytes());
    r.extend_from_slice(data);
    r
}

/// An uncompressed, unindexed ROS 1 bag: one chunk, one connection, the messages.
fn ros1_bag(topic: &str, type_name: &str, msgs: &[(i64, Vec<u8>)]) -> Vec<u8> {
    let mut b = b"#ROSBAG V2.0\n".to_vec();
    b.extend(record(
        &[field("op", &[3]), field("index_pos", &0u64.to_le_bytes())],
        &[b' '; 32],
    ));
    let conn = [
        field("topic", topic.as_bytes()),
        field("type", type_name.as_bytes()),
    ]
    .concat();
    let mut chunk = record(
        &[
            field("op", &[7]),
            field("conn", &0u32.to_le_bytes()),
            field("topic", topic.as_bytes()),
        ],
        &conn,
    );
    for (t, body) in msgs {
        let mut time = ((t / 1_000_000_000) as u32).to_le_bytes().to_vec();
        time.extend_from_slice(&((t % 1_000_000_000) as u32).to_le_bytes());
        chunk.extend(record(
            &[
                field("op", &[2]),
                field("conn", &0u32.to_le_bytes()),
                field("time", &time),
            ],
            body,
        ));
    }
    b.extend(record(
        &[
            field("op", &[5]),
            field("compression", b"none"),
            field("size", &(chunk.len() as u32).to_le_bytes()),
        ],
        &chunk,
    ));
    b
}

fn mcap_record(op: u8, body: &[u8]) -> Vec<u8> {
    let mut r = vec![op];
    r.extend_from_slice(&(body.len() as u64).to_le_bytes());
    r.extend_from_slice(body);
    r
}

fn mcap_str(s: &str) -> Vec<u8> {
    let mut b = (s.len() as u32).to_le_bytes().to_vec();
    b.extend_from_slice(s.as_bytes());
    b
}

/// An unchunked MCAP with a `ros2msg` schema and a `cdr` channel: header, schema, channel,
/// messages, footer (no summary).
fn cdr_mcap(topic: &str, type_name: &str, msgs: &[(i64, Vec<u8>)]) -> Vec<u8> {
    let mut f = b"\x89MCAP0\r\n".to_vec();
    f.extend(mcap_record(0x01, &[mcap_str(""), mcap_str("t")].concat()));
    let mut schema = 1u16.to_le_bytes().to_vec();
    schema.extend(mcap_str(type_name));
    schema.extend(mcap_str("ros2msg"));
    schema.extend(mcap_str("")); // data: not needed to read the fixed layout
    f.extend(mcap_record(0x03, &schema));
    let mut channel = 1u16.to_le_bytes().to_vec();
    channel.extend_from_slice(&1u16.to_le_bytes());
    channel.extend(mcap_str(topic));
    channel.extend(mcap_str("cdr"));
    channel.extend_from_slice(&0u32.to_le_bytes()); // metadata: empty map
    f.extend(mcap_record(0x04, &channel));
    for (seq, (t, body)) in msgs.iter().enumerate() {
        let mut m = 1u16.to_le_bytes().to_vec();
        m.extend_from_slice(&(seq as u32).to_le_bytes());
        m.extend_from_slice(&(*t as u64).to_le_bytes());
        m.extend_from_slice(&(*t as u64).to_le_bytes());
        m.extend_from_slice(body);
        f.extend(mcap_record(0x05, &m));
    }
    f.extend(mcap_record(0x02, &[0; 20]));
    f.extend_from_slice(b"\x89MCAP0\r\n");
    f
}

fn temp_file(name: &str, bytes: &[u8]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("ringscan-custommsg-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// The bag's sweeps, through the bag source, the family registry and `Demux` as `decode`
/// does it (no `--model`: the messages do not name one).
fn bag_sweeps(path: &std::path::Path) -> (Vec<Sweep>, BagSource) {
    let mut src = BagSource::open(path, BagOptions::default()).unwrap();
    let mut pool = CalibrationPool::new(Vec::new(), StreamSettings::default());
    let mut demux = Demux::new(Box::new(move |d| sensor::claim(d, &mut pool)), None);
    let mut out = Vec::new();
    while let Some(d) = src.next_datagram().unwrap() {
        demux
            .push(
                d.time_ns,
                *d.src.ip(),
                d.dst.port(),
                d.payload,
                &mut |_, s, _| out.push(s.clone()),
            )
            .unwrap();
    }
    demux.finish(&mut |_, s, _| out.push(s.clone())).unwrap();
    assert_eq!(
        src.stats().malformed,
        0,
        "{:?}",
        src.stats().first_malformed
    );
    (out, src)
}

fn abs_points(sweeps: &[Sweep]) -> Vec<(i64, Point)> {
    sweeps
        .iter()
        .flat_map(|w| {
            w.points
                .iter()
                .map(move |p| (w.device_time_ns + i64::from(p.t), *p))
        })
        .collect()
}

fn check(what: &str, expected: &[Sweep], got: &[Sweep]) {
    assert_eq!(got.len(), expected.len(), "{what}: one sweep per message");
    let (a, b) = (abs_points(expected), abs_points(got));
    assert!(a.len() > 10_000, "{what}: {} points", a.len());
    assert_eq!(a.len(), b.len(), "{what}: points");
    for (k, ((ta, pa), (tb, pb))) in a.iter().zip(&b).enumerate() {
        assert_eq!(ta, tb, "{what}: time of point {k}");
        assert_eq!(
            (pa.x, pa.y, pa.z, pa.intensity, pa.ring, pa.pad),
            (pb.x, pb.y, pb.z, pb.intensity, pb.ring, pb.pad),
            "{what}: point {k}"
        );
    }
    assert!(b.iter().any(|(_, p)| p.pad == 0x3f), "{what}: tags");
    for (e, g) in expected.iter().zip(got) {
        assert_eq!(g.device_time_ns, e.device_time_ns, "{what}: timebase");
    }
}

#[test]
fn ros1_bags_of_both_drivers_give_the_decoded_points() {
    let sweeps = decoded_sweeps();
    let msgs: Vec<(i64, Vec<u8>)> = sweeps
        .iter()
        .map(|s| (s.device_time_ns, custom_msg(false, s, "livox_frame")))
        .collect();
    for ty in ["livox_ros_driver/CustomMsg", "livox_ros_driver2/CustomMsg"] {
        let path = temp_file("custom.bag", &ros1_bag("/livox/lidar", ty, &msgs));
        let (got, src) = bag_sweeps(&path);
        assert_eq!(src.sensors().len(), 1);
        assert_eq!(src.sensors()[0].family, Family::Livox);
        check(ty, &sweeps, &got);
        // The header stamp is the sweep's time, as the driver set it.
        assert_eq!(got[0].timestamp_ns, sweeps[0].device_time_ns);
    }
}

#[test]
fn cdr_mcap_gives_the_decoded_points() {
    let sweeps = decoded_sweeps();
    // A frame id whose length makes the timebase need padding to 8.
    let msgs: Vec<(i64, Vec<u8>)> = sweeps
        .iter()
        .map(|s| (s.device_time_ns, custom_msg(true, s, "livox")))
        .collect();
    let path = temp_file(
        "custom.mcap",
        &cdr_mcap("/livox/lidar", "livox_ros_driver2/msg/CustomMsg", &msgs),
    );
    let (got, _) = bag_sweeps(&path);
    check("CDR MCAP", &sweeps, &got);
}

#[test]
fn a_cut_or_inconsistent_message_is_counted_not_read() {
    use ringscan::source::bag::messages::{livox_custom, Encoding};
    let sweeps = decoded_sweeps();
    let mut small = sweeps[0].clone();
    small.points.truncate(3);
    for cdr in [false, true] {
        let enc = if cdr { Encoding::Cdr } else { Encoding::Ros1 };
        let m = custom_msg(cdr, &small, "f");
        let mut out = Vec::new();
        let stamp = livox_custom(enc, &m, &mut out).unwrap();
        assert_eq!(stamp, small.device_time_ns);
        for cut in 0..m.len() {
            assert!(livox_custom(enc, &m[..cut], &mut out).is_err(), "cut {cut}");
            assert!(out.is_empty());
        }
        // A point count beyond the bytes: refused before anything is reserved.
        let mut big = m.clone();
        let at = m.len() - 3 * 19 - if cdr { 2 } else { 0 } - 4;
        big[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(livox_custom(enc, &big, &mut out).is_err());
    }
}

/// Runs `tools/make_livox_custommsg_bag.py`; `None` (after a SKIP line) when Python or its
/// venv (`rosbags` from PyPI) cannot be had.
fn make_custommsg_bags(truth: &std::path::Path, out: &std::path::Path) -> Option<Vec<PathBuf>> {
    let script =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/make_livox_custommsg_bag.py");
    match std::process::Command::new("python3")
        .arg(&script)
        .arg("--truth")
        .arg(truth)
        .arg("--out")
        .arg(out)
        .output()
    {
        Ok(o) if o.status.success() => Some(
            String::from_utf8_lossy(&o.stdout)
                .lines()
                .map(PathBuf::from)
                .collect(),
        ),
        Ok(o) => {
            eprintln!(
                "SKIP: tools/make_livox_custommsg_bag.py failed (no venv / rosbags?): {}",
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

/// Bags written by an independent writer (`rosbags`: ROS 1 with both drivers' type names,
/// rosbag2 sqlite3 and MCAP) from the simulator's truth file hold exactly what the truth and
/// the script's reflectivity / tag rule say, and match decoding the same run's packets: xyz
/// within the packets' 1 mm unit, time to the ns, line as ring.
#[test]
fn rosbags_written_bags_give_the_truth_and_the_packets_points() {
    use ringscan::sim::truth::{TruthRecord, TruthWriter};
    let mut sim = LivoxSim::new(LivoxModel::Mid360, T0);
    sim.trajectory = Trajectory::route(T0, Route::urban());
    let (mut truth, mut imu) = (Vec::new(), Vec::new());
    let packets = sim.run_until(&scenes::urban(), T0 + 350_000_000, &mut truth, &mut imu);
    let dir = std::env::temp_dir().join(format!("ringscan-custommsg-py-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let truth_path = dir.join("run.truth");
    let mut w = TruthWriter::new(std::fs::File::create(&truth_path).unwrap()).unwrap();
    for t in &truth {
        w.write(&TruthRecord {
            sensor: t.xyz.map(|v| v as f32),
            world: t.world.map(|v| v as f32),
            time_ns: t.time_ns,
            label: t.label,
            channel: t.line,
            ring: t.line as u8,
            ret: 0,
        })
        .unwrap();
    }
    w.into_inner().unwrap();
    let Some(bags) = make_custommsg_bags(&truth_path, &dir) else {
        return;
    };
    assert_eq!(bags.len(), 4, "{bags:?}");
    // The packets, decoded.
    let mut s = LivoxStream::new(LivoxConfig::new(
        Some(LivoxModel::Mid360),
        LivoxModel::Mid360.protocol(),
    ));
    let mut decoded = Vec::new();
    for (host, _, b) in &packets {
        s.push(*host, b, &mut |sw, _| decoded.push(sw.clone()));
    }
    s.finish(&mut |sw, _| decoded.push(sw.clone()));
    let decoded = abs_points(&decoded);
    assert_eq!(decoded.len(), truth.len());
    for bag in &bags {
        let what = bag.display().to_string();
        let (sweeps, _) = bag_sweeps(bag);
        assert!(sweeps.len() >= 4, "{what}: {} sweeps", sweeps.len());
        let got = abs_points(&sweeps);
        assert_eq!(got.len(), truth.len(), "{what}: points");
        for (i, ((t, p), tr)) in got.iter().zip(&truth).enumerate() {
            assert_eq!(*t, tr.time_ns, "{what}: time of point {i}");
            assert_eq!(
                [p.x, p.y, p.z],
                tr.xyz.map(|v| v as f32),
                "{what}: point {i}"
            );
            assert_eq!(p.ring, tr.line, "{what}: point {i}");
            assert_eq!(
                p.intensity,
                ((37 * i + 11) % 256) as f32,
                "{what}: point {i}"
            );
            assert_eq!(p.pad, ((i % 4) * 16) as u8, "{what}: point {i}");
            let (td, d) = decoded[i];
            assert_eq!(td, *t, "{what}: decoded time of point {i}");
            assert_eq!(d.ring, p.ring);
            for (a, b) in [p.x, p.y, p.z].into_iter().zip([d.x, d.y, d.z]) {
                assert!(
                    (a - b).abs() <= 0.000_5 + 2e-6 * a.abs(),
                    "{what}: {p:?} vs {d:?}"
                );
            }
        }
    }
}
