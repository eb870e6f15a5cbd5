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

mod common;
use common::Scratch;

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
    decoded_run().0
}

/// One IMU sample: sensor time (ns), gyro (rad/s), acceleration (m/s²).
type Sample = (u64, [f64; 3], [f64; 3]);

/// An IMU packet's stamp (ns) and values as sent: gyro rad/s, acceleration g.
type RawImu = (i64, [f32; 6]);

/// The same run: its sweeps, its IMU packets' stamps and values as sent (gyro rad/s,
/// acceleration g; read here from the SDK2 layout: u64 ns timestamp at byte 28, six f32 from
/// byte 36), and the IMU samples the stream decoded from them.
fn decoded_run() -> (Vec<Sweep>, Vec<RawImu>, Vec<Sample>) {
    let mut sim = LivoxSim::new(LivoxModel::Mid360, T0);
    sim.trajectory = Trajectory::route(T0, Route::urban());
    let (mut truth, mut imu) = (Vec::new(), Vec::new());
    let packets = sim.run_until(&scenes::urban(), T0 + 350_000_000, &mut truth, &mut imu);
    let mut s = LivoxStream::new(LivoxConfig::new(
        Some(LivoxModel::Mid360),
        LivoxModel::Mid360.protocol(),
    ));
    let (mut out, mut raw, mut samples) = (Vec::new(), Vec::new(), Vec::new());
    for (host, port, b) in &packets {
        s.push(*host, b, &mut |sw, _| out.push(sw.clone()));
        samples.extend(s.drain_imu().map(|m| (m.sensor_ns, m.gyro, m.accel)));
        if *port == 56_401 {
            let f = |k: usize| f32::from_le_bytes(b[36 + 4 * k..40 + 4 * k].try_into().unwrap());
            let t = i64::from_le_bytes(b[28..36].try_into().unwrap());
            raw.push((t, [f(0), f(1), f(2), f(3), f(4), f(5)]));
        }
    }
    s.finish(&mut |sw, _| out.push(sw.clone()));
    assert!(out.len() >= 3);
    // The simulator writes no tags; give the messages some, so the tag's path is seen.
    for (i, p) in out.iter_mut().flat_map(|w| w.points.iter_mut()).enumerate() {
        p.pad = [0, 0x10, 0x24, 0x3f][i % 4];
    }
    assert!(raw.len() >= 50, "{} IMU packets", raw.len());
    (out, raw, samples)
}

/// A `sensor_msgs/Imu` as the Livox drivers fill it (ROS 1 or CDR): the header stamp is the
/// IMU packet's, orientation and covariances zero, angular velocity and linear acceleration the
/// packet's values as they are (acceleration in g), or × 9.80665 when `mps2`.
fn imu_msg(cdr: bool, stamp: i64, v: &[f32; 6], mps2: bool) -> Vec<u8> {
    let mut m: Vec<u8> = if cdr { vec![0, 1, 0, 0] } else { Vec::new() };
    if !cdr {
        m.extend_from_slice(&9u32.to_le_bytes()); // seq
    }
    m.extend_from_slice(&((stamp / 1_000_000_000) as u32).to_le_bytes());
    m.extend_from_slice(&((stamp % 1_000_000_000) as u32).to_le_bytes());
    let frame_id = "livox_frame";
    m.extend_from_slice(&((frame_id.len() + usize::from(cdr)) as u32).to_le_bytes());
    m.extend_from_slice(frame_id.as_bytes());
    if cdr {
        m.push(0);
        while (m.len() - 4) % 8 != 0 {
            m.push(0);
        }
    }
    let scale = if mps2 { 9.806_65 } else { 1.0 };
    let mut put = |x: f64| m.extend_from_slice(&x.to_le_bytes());
    for _ in 0..4 + 9 {
        put(0.0);
    }
    (0..3).for_each(|k| put(f64::from(v[k])));
    (0..9).for_each(|_| put(0.0));
    (3..6).for_each(|k| put(f64::from(v[k]) * scale));
    (0..9).for_each(|_| put(0.0));
    m
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
    let msgs: Vec<_> = msgs.iter().map(|(t, b)| (0, *t, b.clone())).collect();
    ros1_bag_of(&[(topic, type_name)], &msgs)
}

/// The same with several connections (topic, type), written first in the chunk, and messages
/// (connection index, record time, body).
fn ros1_bag_of(conns: &[(&str, &str)], msgs: &[(usize, i64, Vec<u8>)]) -> Vec<u8> {
    let mut b = b"#ROSBAG V2.0\n".to_vec();
    b.extend(record(
        &[field("op", &[3]), field("index_pos", &0u64.to_le_bytes())],
        &[b' '; 32],
    ));
    let mut chunk = Vec::new();
    for (i, (topic, type_name)) in conns.iter().enumerate() {
        let conn = [
            field("topic", topic.as_bytes()),
            field("type", type_name.as_bytes()),
        ]
        .concat();
        chunk.extend(record(
            &[
                field("op", &[7]),
                field("conn", &(i as u32).to_le_bytes()),
                field("topic", topic.as_bytes()),
            ],
            &conn,
        ));
    }
    for (c, t, body) in msgs {
        let mut time = ((t / 1_000_000_000) as u32).to_le_bytes().to_vec();
        time.extend_from_slice(&((t % 1_000_000_000) as u32).to_le_bytes());
        chunk.extend(record(
            &[
                field("op", &[2]),
                field("conn", &(*c as u32).to_le_bytes()),
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
    let msgs: Vec<_> = msgs.iter().map(|(t, b)| (0, *t, b.clone())).collect();
    cdr_mcap_of(&[(topic, type_name)], &msgs, true)
}

/// The same with several channels (topic, type), their schema and channel records first (as
/// a recorder that subscribed to every topic at its start writes them), or, `!upfront`, each
/// just before its channel's first message; messages (channel index, log time, body).
fn cdr_mcap_of(chans: &[(&str, &str)], msgs: &[(usize, i64, Vec<u8>)], upfront: bool) -> Vec<u8> {
    let mut f = b"\x89MCAP0\r\n".to_vec();
    f.extend(mcap_record(0x01, &[mcap_str(""), mcap_str("t")].concat()));
    let channel = |f: &mut Vec<u8>, i: usize| {
        let (topic, type_name) = chans[i];
        let id = i as u16 + 1;
        let mut schema = id.to_le_bytes().to_vec();
        schema.extend(mcap_str(type_name));
        schema.extend(mcap_str("ros2msg"));
        schema.extend(mcap_str("")); // data: not needed to read the fixed layout
        f.extend(mcap_record(0x03, &schema));
        let mut channel = id.to_le_bytes().to_vec();
        channel.extend_from_slice(&id.to_le_bytes());
        channel.extend(mcap_str(topic));
        channel.extend(mcap_str("cdr"));
        channel.extend_from_slice(&0u32.to_le_bytes()); // metadata: empty map
        f.extend(mcap_record(0x04, &channel));
    };
    let mut written = vec![upfront; chans.len()];
    if upfront {
        (0..chans.len()).for_each(|i| channel(&mut f, i));
    }
    for (seq, (c, t, body)) in msgs.iter().enumerate() {
        if !written[*c] {
            written[*c] = true;
            channel(&mut f, *c);
        }
        let id = *c as u16 + 1;
        let mut m = id.to_le_bytes().to_vec();
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

fn temp_file(name: &str, bytes: &[u8]) -> Scratch {
    let p = Scratch::file("custommsg", name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// The bag's sweeps, through the bag source, the family registry and `Demux` as `decode`
/// does it (no `--model`: the messages do not name one).
fn bag_sweeps(path: &std::path::Path) -> (Vec<Sweep>, BagSource) {
    let (sweeps, _, src) = bag_run(path);
    (sweeps, src)
}

/// The same, with the IMU samples the streams hand on after each datagram (as `decode`
/// drains them for the deskew and `/imu`).
fn bag_run(path: &std::path::Path) -> (Vec<Sweep>, Vec<Sample>, BagSource) {
    let mut src = BagSource::open(path, BagOptions::default()).unwrap();
    let mut pool = CalibrationPool::new(Vec::new(), StreamSettings::default());
    let mut demux = Demux::new(Box::new(move |d| sensor::claim(d, &mut pool)), None);
    let (mut out, mut imu) = (Vec::new(), Vec::new());
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
        for i in 0..demux.sensors().count() {
            if let Some(s) = demux.stream_mut(i) {
                s.drain_imu(&mut |m, _| imu.push((m.sensor_ns, m.gyro, m.accel)));
            }
        }
    }
    demux.finish(&mut |_, s, _| out.push(s.clone())).unwrap();
    assert_eq!(
        src.stats().malformed,
        0,
        "{:?}",
        src.stats().first_malformed
    );
    (out, imu, src)
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

/// A driver's bag as recorded: `/livox/lidar` CustomMsgs (each once its frame is complete),
/// `/livox/imu` with a `sensor_msgs/Imu` per IMU packet (stamp and values as the packet sent
/// them; acceleration in g as the drivers publish it, or in m/s²), and a vehicle's IMU on
/// `/vehicle/imu`. The IMU samples the Livox stream hands on (what deskew and `/imu` get) must
/// be exactly those of decoding the IMU packets, the vehicle's IMU not read but counted, and
/// the sweeps unchanged.
#[test]
fn the_drivers_imu_topic_gives_the_imu_packets_samples() {
    let (sweeps, raw, samples) = decoded_run();
    let build = |cdr: bool, mps2: bool| {
        let mut msgs = Vec::new();
        for s in &sweeps {
            let last = s.points.iter().map(|p| i64::from(p.t)).max().unwrap_or(0);
            msgs.push((
                0,
                s.device_time_ns + last,
                custom_msg(cdr, s, "livox_frame"),
            ));
        }
        for (t, v) in &raw {
            msgs.push((1, *t, imu_msg(cdr, *t, v, mps2)));
        }
        for k in 0..3 {
            let t = T0 + k * 1_000_000;
            let v = [0.5, 0.0, 0.0, 0.0, 0.0, 1.0];
            msgs.push((2, t, imu_msg(cdr, t, &v, false)));
        }
        msgs.sort_by_key(|m| m.1);
        msgs
    };
    let ros1 = [
        ("/livox/lidar", "livox_ros_driver2/CustomMsg"),
        ("/livox/imu", "sensor_msgs/Imu"),
        ("/vehicle/imu", "sensor_msgs/Imu"),
    ];
    let ros2 = [
        ("/livox/lidar", "livox_ros_driver2/msg/CustomMsg"),
        ("/livox/imu", "sensor_msgs/msg/Imu"),
        ("/vehicle/imu", "sensor_msgs/msg/Imu"),
    ];
    for (what, name, bytes) in [
        (
            "ROS 1, g",
            "imu.bag",
            ros1_bag_of(&ros1, &build(false, false)),
        ),
        (
            "ROS 1, m/s²",
            "imu-mps2.bag",
            ros1_bag_of(&ros1, &build(false, true)),
        ),
        (
            "CDR MCAP, g",
            "imu.mcap",
            cdr_mcap_of(&ros2, &build(true, false), true),
        ),
        (
            "CDR MCAP, m/s²",
            "imu-mps2.mcap",
            cdr_mcap_of(&ros2, &build(true, true), true),
        ),
    ] {
        let (got, imu, src) = bag_run(&temp_file(name, &bytes));
        check(what, &sweeps, &got);
        assert_eq!(imu.len(), raw.len(), "{what}: every IMU message a sample");
        assert_eq!(imu, samples, "{what}: the IMU packets' samples");
        assert_eq!(src.stats().unknown_type, 3, "{what}: the vehicle's IMU");
        let s = src.sensors();
        assert_eq!(s.len(), 1, "{what}");
        assert_eq!(s[0].topics, ["/livox/lidar", "/livox/imu"], "{what}");
    }
    // An MCAP whose CustomMsg channel is written only before its first message: the IMU
    // messages before that cannot be paired (counted), and every one from there on is read.
    let msgs = build(true, false);
    let first_frame = msgs.iter().find(|m| m.0 == 0).map(|m| m.1).unwrap();
    let (got, imu, src) = bag_run(&temp_file(
        "imu-late.mcap",
        &cdr_mcap_of(&ros2, &msgs, false),
    ));
    check("late channel", &sweeps, &got);
    let after: Vec<Sample> = samples
        .iter()
        .filter(|m| m.0 as i64 >= first_frame)
        .copied()
        .collect();
    assert!(!after.is_empty() && after.len() < samples.len());
    assert_eq!(
        imu, after,
        "late channel: the samples from the first frame on"
    );
    let before = (samples.len() - after.len()) as u64;
    assert_eq!(src.stats().unknown_type, 3 + before, "late channel");
    // Through `decode`: the samples reach the IMU deskew and `/imu`; the same CustomMsgs
    // without their IMU topic leave `--deskew imu` nothing to deskew with.
    #[cfg(feature = "cli")]
    {
        let lidar_only: Vec<_> = build(false, false)
            .into_iter()
            .filter(|m| m.0 == 0)
            .collect();
        for (name, bytes, imu, skipped) in [
            (
                "cli-imu.bag",
                ros1_bag_of(&ros1, &build(false, false)),
                raw.len(),
                0,
            ),
            (
                "cli-no-imu.bag",
                ros1_bag_of(&ros1[..1], &lidar_only),
                0,
                sweeps.len(),
            ),
        ] {
            let path = temp_file(name, &bytes);
            let mcap = path.with_extension("mcap");
            let out = std::process::Command::new(env!("CARGO_BIN_EXE_ringscan"))
                .arg("decode")
                .arg(&path)
                .args([
                    "--pipeline",
                    "default",
                    "--deskew",
                    "imu",
                    "--json",
                    "--out",
                ])
                .arg(&mcap)
                .output()
                .unwrap();
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
            let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
            assert_eq!(j["sweeps"], sweeps.len(), "{name}");
            assert_eq!(j["imu_samples"], imu, "{name}");
            let imu_msgs = j["output"]["topics"]["/imu"].as_u64().unwrap_or(0);
            assert_eq!(imu_msgs, imu as u64, "{name}");
            assert_eq!(j["pipeline"]["deskew"], "imu", "{name}");
            // `replay` sends none of it: points and IMU samples a driver decoded were never
            // on the wire. Having sent nothing, it fails (exit 1) after its summary.
            let out = std::process::Command::new(env!("CARGO_BIN_EXE_ringscan"))
                .arg("replay")
                .arg(&path)
                .args([
                    "--to",
                    "127.0.0.1",
                    "--port-offset",
                    "1000",
                    "--rate",
                    "max",
                    "--json",
                ])
                .output()
                .unwrap();
            let err = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(1), "{err}");
            assert!(
                err.contains(&format!(
                    "no datagram was sent: the input holds no packet, only {} messages a \
                     driver had decoded",
                    sweeps.len() + imu
                )),
                "{err}"
            );
            let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
            assert_eq!(r["sent"], 0, "{name}: {r}");
            assert_eq!(
                r["skipped_decoded_messages"],
                sweeps.len() + imu,
                "{name}: {r}"
            );
            assert_eq!(
                j["pipeline"]["deskew_skipped"], skipped,
                "{name}: {}",
                j["pipeline"]
            );
        }
    }
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
fn make_custommsg_bags(
    truth: &std::path::Path,
    imu: &std::path::Path,
    out: &std::path::Path,
) -> Option<Vec<PathBuf>> {
    let script =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/make_livox_custommsg_bag.py");
    match std::process::Command::new("python3")
        .arg(&script)
        .arg("--truth")
        .arg(truth)
        .arg("--imu")
        .arg(imu)
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
    let dir = Scratch::dir("custommsg-py");
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
    // The packets, decoded; the IMU packets' values (gyro rad/s, acceleration g, from the SDK2
    // layout: u64 ns timestamp at byte 28, six f32 from byte 36) for the script's /livox/imu.
    let mut s = LivoxStream::new(LivoxConfig::new(
        Some(LivoxModel::Mid360),
        LivoxModel::Mid360.protocol(),
    ));
    let (mut decoded, mut samples, mut imu_file) = (Vec::new(), Vec::new(), Vec::new());
    for (host, port, b) in &packets {
        s.push(*host, b, &mut |sw, _| decoded.push(sw.clone()));
        samples.extend(s.drain_imu().map(|m| (m.sensor_ns, m.gyro, m.accel)));
        if *port == 56_401 {
            imu_file.extend_from_slice(&b[28..36]);
            for k in 0..6 {
                let v = f32::from_le_bytes(b[36 + 4 * k..40 + 4 * k].try_into().unwrap());
                imu_file.extend_from_slice(&f64::from(v).to_le_bytes());
            }
        }
    }
    s.finish(&mut |sw, _| decoded.push(sw.clone()));
    assert!(samples.len() >= 50, "{} IMU samples", samples.len());
    let imu_path = dir.join("run.imu");
    std::fs::write(&imu_path, &imu_file).unwrap();
    let Some(bags) = make_custommsg_bags(&truth_path, &imu_path, &dir) else {
        return;
    };
    assert_eq!(bags.len(), 4, "{bags:?}");
    let decoded = abs_points(&decoded);
    assert_eq!(decoded.len(), truth.len());
    for bag in &bags {
        let what = bag.display().to_string();
        let (sweeps, imu, src) = bag_run(bag);
        assert!(sweeps.len() >= 4, "{what}: {} sweeps", sweeps.len());
        // rosbags' sensor_msgs/Imu (acceleration in g, as the drivers publish it): every one
        // of the IMU packets' samples, exactly.
        assert_eq!(imu, samples, "{what}: IMU samples");
        assert_eq!(src.stats().unknown_type, 0, "{what}");
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
