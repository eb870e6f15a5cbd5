//! End-to-end tests of the MCAP sink: write files with two sensors in both formats, read them
//! back with the `mcap` crate's reader and check channels, schemas, counts, attachments and the
//! message bytes (decoded here with a small independent protobuf / CDR reader).
#![cfg(feature = "mcap")]

use std::collections::BTreeMap;
use std::io::Cursor;
use std::net::SocketAddrV4;

use prost::Message as _;
use ringscan::point::{Point, POINT_FIELDS};
use ringscan::sink::{
    create_file, temp_path, Compression, Format, McapSink, SensorInfo, SinkError, SinkOptions,
    SinkSummary, SweepMsg,
};

const SECOND: u64 = 1_000_000_000;
const T0: u64 = 1_700_000_000 * SECOND + 250_000_000;

fn synthetic_sweep(sensor: usize, sweep: usize) -> Vec<Point> {
    let n = 50 + 17 * sweep + 5 * sensor;
    (0..n)
        .map(|i| {
            let a = i as f32 * 0.1;
            Point {
                x: a.cos() * (5.0 + sensor as f32),
                y: a.sin() * 3.0,
                z: -1.0 + (i % 16) as f32 * 0.1,
                intensity: (i % 256) as f32,
                t: (i as u32) * 1_000,
                ring: (i % 16) as u16,
                ret: (i % 2) as u8,
                pad: 0,
            }
        })
        .collect()
}

/// A `Write + Seek` over a shared buffer, so the bytes outlive the sink that wrote them.
#[derive(Clone, Default)]
struct SharedBuf(std::rc::Rc<std::cell::RefCell<Cursor<Vec<u8>>>>);

impl std::io::Write for SharedBuf {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.borrow_mut().write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl std::io::Seek for SharedBuf {
    fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
        self.0.borrow_mut().seek(pos)
    }
}

impl SharedBuf {
    fn bytes(&self) -> Vec<u8> {
        self.0.borrow().get_ref().clone()
    }
}

struct Written {
    bytes: Vec<u8>,
    /// `[sensor][sweep]` points as written.
    sweeps: Vec<Vec<Vec<Point>>>,
    summary: SinkSummary,
}

fn sensor_info(name: &str, prefix: &str, calib: Option<(&str, &[u8])>) -> SensorInfo {
    let mut metadata = BTreeMap::new();
    metadata.insert("model".to_string(), "VLP-16".to_string());
    metadata.insert("source".to_string(), format!("{name}:2368"));
    metadata.insert("clock".to_string(), "host".to_string());
    metadata.insert("family".to_string(), "velodyne".to_string());
    SensorInfo {
        name: name.into(),
        topic_prefix: prefix.into(),
        metadata,
        calibration: calib.map(|(n, b)| (n.to_string(), b.to_vec())),
    }
}

const CALIB_XML: &[u8] = b"<?xml version=\"1.0\"?><boost_serialization/>";
const CALIB_YAML: &[u8] = b"lasers: []\nnum_lasers: 16\n";
const SENSORS: [&str; 2] = ["vlp16-201", "vlp32c-7"];
const SWEEPS: usize = 4;
const PACKETS_PER_SWEEP: u16 = 3;

fn payload(sensor: usize, sweep: usize, p: u16) -> Vec<u8> {
    (0..1206)
        .map(|i| (i + sensor * 7 + sweep * 3 + usize::from(p)) as u8)
        .collect()
}

fn write_into<W: std::io::Write + std::io::Seek>(sink: &mut McapSink<W>) -> Vec<Vec<Vec<Point>>> {
    let a = sink
        .add_sensor(&sensor_info(
            SENSORS[0],
            "/vlp16-201",
            Some(("VLP16db.xml", CALIB_XML)),
        ))
        .unwrap();
    let b = sink
        .add_sensor(&sensor_info(
            SENSORS[1],
            "/vlp32c-7",
            Some(("VLP32C.yaml", CALIB_YAML)),
        ))
        .unwrap();
    let ids = [a, b];
    let mut sweeps = vec![Vec::new(), Vec::new()];
    for k in 0..SWEEPS {
        for (s, &id) in ids.iter().enumerate() {
            let log = T0 + k as u64 * 100_000_000 + s as u64 * 1_000;
            for p in 0..PACKETS_PER_SWEEP {
                let src = SocketAddrV4::new([192, 168, 1, 201 + s as u8].into(), 2368 + s as u16);
                sink.write_raw(id, log - 1000 + u64::from(p), src, 2368, &payload(s, k, p))
                    .unwrap();
            }
            let points = synthetic_sweep(s, k);
            let sweep = SweepMsg {
                log_time_ns: log,
                timestamp_ns: log - 50_000_000,
                points: &points,
            };
            sink.write_sweep(id, &sweep).unwrap();
            let diag = serde_json::json!({"sweep": k, "packets": PACKETS_PER_SWEEP, "missing": 0});
            sink.write_diagnostics(id, log, &diag).unwrap();
            sweeps[s].push(points);
        }
    }
    // An empty sweep is still a valid message.
    let empty = SweepMsg {
        log_time_ns: T0 + SECOND,
        timestamp_ns: T0 + SECOND,
        points: &[],
    };
    sink.write_sweep(a, &empty).unwrap();
    sweeps[0].push(Vec::new());
    sweeps
}

fn write_file(format: Format, compression: Compression) -> Written {
    write_file_at(format, compression, SinkOptions::default().zstd_level)
}

fn write_file_at(format: Format, compression: Compression, zstd_level: i32) -> Written {
    let buf = SharedBuf::default();
    let opts = SinkOptions {
        format,
        compression,
        chunk_size: 16 * 1024,
        zstd_level,
        ..SinkOptions::default()
    };
    let mut sink = McapSink::new(buf.clone(), opts).unwrap();
    let sweeps = write_into(&mut sink);
    let summary = sink.finish().unwrap();
    Written {
        bytes: buf.bytes(),
        sweeps,
        summary,
    }
}

/// Where to dump a test's file for the Python checker (`RINGSCAN_MCAP_OUT=dir cargo test ...`).
fn maybe_keep(name: &str, w: &Written) {
    if let Some(dir) = std::env::var_os("RINGSCAN_MCAP_OUT") {
        let dir = std::path::PathBuf::from(dir);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join(name), &w.bytes).unwrap();
        let points: usize = w.sweeps.iter().flatten().map(Vec::len).sum();
        let sweeps: usize = w.sweeps.iter().map(Vec::len).sum();
        let expect =
            serde_json::json!({"sweeps": sweeps, "points": points, "topics": w.summary.messages});
        std::fs::write(dir.join(format!("{name}.expect.json")), expect.to_string()).unwrap();
    }
}

// ---------------------------------------------------------------------------------------------
// A minimal protobuf reader, independent of the writer.

#[derive(Debug, Clone, Copy, PartialEq)]
enum Pb<'a> {
    Varint(u64),
    Fixed64(u64),
    Bytes(&'a [u8]),
    Fixed32(u32),
}

fn read_varint(b: &[u8], at: &mut usize) -> u64 {
    let mut v = 0u64;
    let mut shift = 0;
    loop {
        let byte = b[*at];
        *at += 1;
        v |= u64::from(byte & 0x7f) << shift;
        if byte < 0x80 {
            return v;
        }
        shift += 7;
    }
}

fn pb_fields(b: &[u8]) -> Vec<(u32, Pb<'_>)> {
    let mut out = Vec::new();
    let mut at = 0;
    while at < b.len() {
        let key = read_varint(b, &mut at);
        let field = (key >> 3) as u32;
        let value = match key & 7 {
            0 => Pb::Varint(read_varint(b, &mut at)),
            1 => {
                at += 8;
                Pb::Fixed64(u64::from_le_bytes(b[at - 8..at].try_into().unwrap()))
            }
            2 => {
                let len = read_varint(b, &mut at) as usize;
                at += len;
                Pb::Bytes(&b[at - len..at])
            }
            5 => {
                at += 4;
                Pb::Fixed32(u32::from_le_bytes(b[at - 4..at].try_into().unwrap()))
            }
            w => panic!("wire type {w}"),
        };
        out.push((field, value));
    }
    out
}

fn pb_one<'a>(fields: &[(u32, Pb<'a>)], n: u32) -> Option<Pb<'a>> {
    let mut found = fields.iter().filter(|(f, _)| *f == n).map(|(_, v)| *v);
    let first = found.next();
    assert!(found.next().is_none(), "field {n} repeated");
    first
}

fn pb_bytes<'a>(fields: &[(u32, Pb<'a>)], n: u32) -> &'a [u8] {
    match pb_one(fields, n) {
        Some(Pb::Bytes(b)) => b,
        None => &[],
        other => panic!("field {n}: {other:?}"),
    }
}

fn pb_varint(fields: &[(u32, Pb<'_>)], n: u32) -> u64 {
    match pb_one(fields, n) {
        Some(Pb::Varint(v)) => v,
        None => 0,
        other => panic!("field {n}: {other:?}"),
    }
}

fn pb_fixed32(fields: &[(u32, Pb<'_>)], n: u32) -> u32 {
    match pb_one(fields, n) {
        Some(Pb::Fixed32(v)) => v,
        None => 0,
        other => panic!("field {n}: {other:?}"),
    }
}

fn pb_timestamp_ns(b: &[u8]) -> u64 {
    let f = pb_fields(b);
    pb_varint(&f, 1) * SECOND + pb_varint(&f, 2)
}

// ---------------------------------------------------------------------------------------------
// A minimal CDR reader.

struct CdrReader<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> CdrReader<'a> {
    fn new(b: &'a [u8]) -> Self {
        assert_eq!(&b[..4], &[0, 1, 0, 0], "CDR_LE encapsulation header");
        Self { b: &b[4..], at: 0 }
    }
    fn u8(&mut self) -> u8 {
        self.at += 1;
        self.b[self.at - 1]
    }
    fn u32(&mut self) -> u32 {
        while self.at % 4 != 0 {
            assert_eq!(self.b[self.at], 0, "padding is zero");
            self.at += 1;
        }
        self.at += 4;
        u32::from_le_bytes(self.b[self.at - 4..self.at].try_into().unwrap())
    }
    fn bytes(&mut self, n: usize) -> &'a [u8] {
        self.at += n;
        &self.b[self.at - n..self.at]
    }
    fn string(&mut self) -> String {
        let n = self.u32() as usize;
        let s = self.bytes(n);
        assert_eq!(s[n - 1], 0, "NUL terminated");
        String::from_utf8(s[..n - 1].to_vec()).unwrap()
    }
    fn done(&self) -> bool {
        self.at == self.b.len()
    }
}

// ---------------------------------------------------------------------------------------------

fn expected_counts(ros2: bool) -> BTreeMap<String, u64> {
    let mut m = BTreeMap::new();
    for (s, name) in SENSORS.iter().enumerate() {
        m.insert(format!("/{name}/points"), SWEEPS as u64 + u64::from(s == 0));
        m.insert(format!("/{name}/diagnostics"), SWEEPS as u64);
        if ros2 {
            // One VelodyneScan per sweep: the packets written before it.
            m.insert(format!("/{name}/velodyne_packets"), SWEEPS as u64);
        } else {
            m.insert(
                format!("/{name}/raw"),
                SWEEPS as u64 * u64::from(PACKETS_PER_SWEEP),
            );
        }
    }
    m
}

/// Checks what both formats share: summary, channels, counts, attachments, raw packets and
/// diagnostics. Returns the points messages per sensor in order, with their log and header times.
fn check_common(
    w: &Written,
    points_schema: &str,
    schema_encoding: &str,
    message_encoding: &str,
) -> Vec<Vec<(u64, Vec<u8>)>> {
    let summary = mcap::Summary::read(&w.bytes)
        .unwrap()
        .expect("a summary section");
    let stats = summary.stats.as_ref().expect("statistics");
    assert!(!summary.chunk_indexes.is_empty(), "chunk indexes");
    assert!(
        summary.chunk_indexes.len() > 1,
        "16 KiB chunks split the file"
    );
    assert_eq!(summary.chunk_indexes.len(), w.summary.chunks);

    // Channels, schemas and metadata.
    let mut topic_of = BTreeMap::new();
    for ch in summary.channels.values() {
        topic_of.insert(ch.id, ch.topic.clone());
        let schema = ch.schema.as_ref().expect("every channel has a schema");
        let sensor = SENSORS
            .iter()
            .find(|s| ch.topic.starts_with(&format!("/{s}/")))
            .expect("sensor prefix");
        assert_eq!(
            ch.metadata.get("source").map(String::as_str),
            Some(format!("{sensor}:2368").as_str())
        );
        assert_eq!(ch.metadata.get("model").map(String::as_str), Some("VLP-16"));
        let ros2 = message_encoding == "cdr";
        if ros2 {
            assert!(
                ch.metadata
                    .get("offered_qos_profiles")
                    .is_some_and(|q| q.contains("reliability: 1")),
                "{}: QoS in the channel metadata",
                ch.topic
            );
        }
        if ch.topic.ends_with("/points") {
            assert_eq!(schema.name, points_schema);
            assert_eq!(schema.encoding, schema_encoding);
            assert_eq!(ch.message_encoding, message_encoding);
        } else if ros2 && ch.topic.ends_with("/diagnostics") {
            assert_eq!(schema.name, "diagnostic_msgs/msg/DiagnosticArray");
            assert_eq!(schema.encoding, "ros2msg");
            assert_eq!(ch.message_encoding, "cdr");
        } else if ros2 && ch.topic.ends_with("/velodyne_packets") {
            assert_eq!(schema.name, "velodyne_msgs/msg/VelodyneScan");
            assert_eq!(schema.encoding, "ros2msg");
            assert_eq!(ch.message_encoding, "cdr");
            let text = std::str::from_utf8(&schema.data).unwrap();
            assert!(text.contains("\nMSG: velodyne_msgs/VelodynePacket\nbuiltin_interfaces/Time stamp\nuint8[1206] data\n"), "{text}");
        } else if ch.topic.ends_with("/diagnostics") {
            assert_eq!(schema.name, "ringscan.Diagnostics");
            assert_eq!(schema.encoding, "jsonschema");
            assert_eq!(ch.message_encoding, "json");
            let js: serde_json::Value = serde_json::from_slice(&schema.data).unwrap();
            assert_eq!(js["type"], "object");
        } else if ch.topic.ends_with("/raw") {
            assert_eq!(schema.name, "ringscan.RawPacket");
            assert_eq!(schema.encoding, "protobuf");
            assert_eq!(ch.message_encoding, "protobuf");
            let fds = prost_types::FileDescriptorSet::decode(&schema.data[..]).unwrap();
            let raw = fds
                .file
                .iter()
                .find(|f| f.name() == "ringscan/RawPacket.proto")
                .unwrap();
            let fields: Vec<_> = raw.message_type[0]
                .field
                .iter()
                .map(|f| (f.name(), f.number()))
                .collect();
            assert_eq!(
                fields,
                [
                    ("timestamp", 1),
                    ("source_address", 2),
                    ("source_port", 3),
                    ("destination_port", 4),
                    ("payload", 5)
                ]
            );
        } else {
            panic!("unexpected topic {}", ch.topic);
        }
    }

    // Counts: statistics, the sink's own summary, and the messages actually in the file agree.
    let expected = expected_counts(message_encoding == "cdr");
    let mut stat_counts = BTreeMap::new();
    for (id, n) in &stats.channel_message_counts {
        stat_counts.insert(topic_of[id].clone(), *n);
    }
    assert_eq!(stat_counts, expected);
    assert_eq!(w.summary.messages, expected);
    assert_eq!(stats.attachment_count, 2);

    // Attachments.
    assert_eq!(summary.attachment_indexes.len(), 2);
    let mut found = Vec::new();
    for idx in &summary.attachment_indexes {
        let a = mcap::read::attachment(&w.bytes, idx).unwrap();
        found.push((a.name.clone(), a.media_type.clone(), a.data.to_vec()));
        assert_eq!(
            a.log_time,
            T0 - 1000,
            "attachments carry the first message's log time"
        );
    }
    assert_eq!(
        found,
        [
            (
                "VLP16db.xml".to_string(),
                "application/xml".to_string(),
                CALIB_XML.to_vec()
            ),
            (
                "VLP32C.yaml".to_string(),
                "text/plain".to_string(),
                CALIB_YAML.to_vec()
            ),
        ]
    );
    let names: Vec<_> = w
        .summary
        .attachments
        .iter()
        .map(|a| (a.name.as_str(), a.size))
        .collect();
    assert_eq!(
        names,
        [
            ("VLP16db.xml", CALIB_XML.len() as u64),
            ("VLP32C.yaml", CALIB_YAML.len() as u64)
        ]
    );

    // Messages, in file order.
    let mut counts = BTreeMap::new();
    let mut sequences: BTreeMap<String, u32> = BTreeMap::new();
    let mut raw_seen = [0usize; 2];
    let mut points = vec![Vec::new(), Vec::new()];
    for m in mcap::MessageStream::new(&w.bytes).unwrap() {
        let m = m.unwrap();
        let topic = m.channel.topic.clone();
        *counts.entry(topic.clone()).or_insert(0u64) += 1;
        let seq = sequences.entry(topic.clone()).or_insert(0);
        assert_eq!(
            m.sequence, *seq,
            "{topic}: sequence numbers count up from 0"
        );
        *seq += 1;
        assert_eq!(m.publish_time, m.log_time);
        let s = SENSORS
            .iter()
            .position(|s| topic.starts_with(&format!("/{s}/")))
            .unwrap();
        if topic.ends_with("/velodyne_packets") {
            // VelodyneScan: Header {stamp, frame_id}, VelodynePacket[] {stamp, uint8[1206]}.
            let mut r = CdrReader::new(&m.data);
            let (sec, ns) = (u64::from(r.u32()), u64::from(r.u32()));
            assert_eq!(r.string(), SENSORS[s]);
            assert_eq!(r.u32(), u32::from(PACKETS_PER_SWEEP));
            let k = raw_seen[s];
            raw_seen[s] += 1;
            for p in 0..PACKETS_PER_SWEEP {
                let t = u64::from(r.u32()) * SECOND + u64::from(r.u32());
                let log = T0 + k as u64 * 100_000_000 + s as u64 * 1_000;
                assert_eq!(t, log - 1000 + u64::from(p));
                if p == 0 {
                    assert_eq!(sec * SECOND + ns, t, "header stamp = first packet's");
                }
                assert_eq!(r.bytes(1206), payload(s, k, p));
                if p + 1 == PACKETS_PER_SWEEP {
                    assert_eq!(m.log_time, t, "log time = last packet's");
                }
            }
            assert!(r.done());
        } else if topic.ends_with("/diagnostics") && message_encoding == "cdr" {
            // DiagnosticArray: Header, DiagnosticStatus[] {level, name, message, hardware_id,
            // KeyValue[] values}.
            let mut r = CdrReader::new(&m.data);
            assert_eq!(u64::from(r.u32()) * SECOND + u64::from(r.u32()), m.log_time);
            assert_eq!(r.string(), "");
            assert_eq!(r.u32(), 1);
            assert_eq!(r.u8(), 0, "level OK");
            assert_eq!(r.string(), SENSORS[s]);
            assert_eq!(r.string(), "");
            assert_eq!(r.string(), SENSORS[s]);
            let n = r.u32();
            let kv: BTreeMap<String, String> = (0..n).map(|_| (r.string(), r.string())).collect();
            assert!(r.done());
            assert_eq!(kv["packets"], PACKETS_PER_SWEEP.to_string());
            assert_eq!(kv["missing"], "0");
        } else if topic.ends_with("/raw") {
            let f = pb_fields(&m.data);
            let (k, p) = (
                raw_seen[s] / PACKETS_PER_SWEEP as usize,
                raw_seen[s] % PACKETS_PER_SWEEP as usize,
            );
            raw_seen[s] += 1;
            assert_eq!(pb_timestamp_ns(pb_bytes(&f, 1)), m.log_time);
            assert_eq!(pb_bytes(&f, 2), format!("192.168.1.{}", 201 + s).as_bytes());
            assert_eq!(pb_varint(&f, 3), 2368 + s as u64);
            assert_eq!(pb_varint(&f, 4), 2368);
            assert_eq!(pb_bytes(&f, 5), payload(s, k, p as u16));
        } else if topic.ends_with("/diagnostics") {
            let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
            assert_eq!(v["packets"], u64::from(PACKETS_PER_SWEEP));
        } else {
            points[s].push((m.log_time, m.data.to_vec()));
        }
    }
    assert_eq!(counts, expected);
    points
}

fn expected_log_time(sensor: usize, sweep: usize) -> u64 {
    if sweep == SWEEPS {
        T0 + SECOND
    } else {
        T0 + sweep as u64 * 100_000_000 + sensor as u64 * 1_000
    }
}

fn expected_stamp(sensor: usize, sweep: usize) -> u64 {
    if sweep == SWEEPS {
        T0 + SECOND
    } else {
        expected_log_time(sensor, sweep) - 50_000_000
    }
}

#[test]
fn foxglove_file_reads_back_with_the_mcap_reader() {
    let w = write_file(Format::Foxglove, Compression::Zstd);
    maybe_keep("foxglove.mcap", &w);
    let points = check_common(&w, "foxglove.PointCloud", "protobuf", "protobuf");

    let summary = mcap::Summary::read(&w.bytes).unwrap().unwrap();
    for ci in &summary.chunk_indexes {
        assert_eq!(ci.compression, "zstd");
    }
    // The schema: a FileDescriptorSet with every file PointCloud.proto needs.
    let schema = summary
        .channels
        .values()
        .find(|c| c.topic.ends_with("/points"))
        .unwrap()
        .schema
        .clone()
        .unwrap();
    let fds = prost_types::FileDescriptorSet::decode(&schema.data[..]).unwrap();
    let mut files: Vec<_> = fds.file.iter().map(|f| f.name().to_owned()).collect();
    files.sort();
    assert_eq!(
        files,
        [
            "foxglove/PackedElementField.proto",
            "foxglove/PointCloud.proto",
            "foxglove/Pose.proto",
            "foxglove/Quaternion.proto",
            "foxglove/Vector3.proto",
            "google/protobuf/timestamp.proto",
        ]
    );
    let pc = fds
        .file
        .iter()
        .find(|f| f.name() == "foxglove/PointCloud.proto")
        .unwrap();
    assert_eq!(pc.package(), "foxglove");
    let fields: Vec<_> = pc.message_type[0]
        .field
        .iter()
        .map(|f| (f.name(), f.number(), f.r#type()))
        .collect();
    use prost_types::field_descriptor_proto::Type;
    assert_eq!(
        fields,
        [
            ("timestamp", 1, Type::Message),
            ("frame_id", 2, Type::String),
            ("pose", 3, Type::Message),
            ("point_stride", 4, Type::Fixed32),
            ("fields", 5, Type::Message),
            ("data", 6, Type::Bytes),
        ]
    );

    for (s, msgs) in points.iter().enumerate() {
        assert_eq!(msgs.len(), w.sweeps[s].len());
        for (k, (log_time, data)) in msgs.iter().enumerate() {
            assert_eq!(*log_time, expected_log_time(s, k));
            let f = pb_fields(data);
            assert_eq!(pb_timestamp_ns(pb_bytes(&f, 1)), expected_stamp(s, k));
            assert_eq!(pb_bytes(&f, 2), SENSORS[s].as_bytes());
            // pose: position present (zero), orientation w = 1
            let pose = pb_fields(pb_bytes(&f, 3));
            assert_eq!(pb_bytes(&pose, 1), &[] as &[u8]);
            let q = pb_fields(pb_bytes(&pose, 2));
            assert_eq!(q, [(4, Pb::Fixed64(1.0f64.to_bits()))]);
            assert_eq!(pb_fixed32(&f, 4), 24);
            let declared: Vec<_> = f
                .iter()
                .filter(|(n, _)| *n == 5)
                .map(|(_, v)| {
                    let Pb::Bytes(b) = v else {
                        panic!("fields entry")
                    };
                    let e = pb_fields(b);
                    (
                        String::from_utf8(pb_bytes(&e, 1).to_vec()).unwrap(),
                        pb_fixed32(&e, 2),
                        pb_varint(&e, 3),
                    )
                })
                .collect();
            let want: Vec<_> = POINT_FIELDS
                .iter()
                .zip([7u64, 7, 7, 7, 5, 3, 1]) // FLOAT32 ×4, UINT32, UINT16, UINT8
                .map(|((name, off, _), ty)| (name.to_string(), *off as u32, ty))
                .collect();
            assert_eq!(declared, want);
            let body = pb_bytes(&f, 6);
            assert_eq!(body, ringscan::point::as_bytes(&w.sweeps[s][k]));
            // Field by offset, as a reader would: point 3's ring and t.
            if w.sweeps[s][k].len() > 3 {
                let p = &body[3 * 24..4 * 24];
                assert_eq!(u16::from_le_bytes([p[20], p[21]]), 3);
                assert_eq!(u32::from_le_bytes(p[16..20].try_into().unwrap()), 3_000);
                assert_eq!(p[22], 1);
            }
        }
    }
}

#[test]
fn ros2_file_reads_back_with_the_mcap_reader() {
    let w = write_file(Format::Ros2, Compression::Zstd);
    maybe_keep("ros2.mcap", &w);
    let points = check_common(&w, "sensor_msgs/msg/PointCloud2", "ros2msg", "cdr");
    let summary = mcap::Summary::read(&w.bytes).unwrap().unwrap();
    let schema = summary
        .channels
        .values()
        .find(|c| c.topic.ends_with("/points"))
        .unwrap()
        .schema
        .clone()
        .unwrap();
    let text = std::str::from_utf8(&schema.data).unwrap();
    let sep = "=".repeat(80);
    for dep in [
        "sensor_msgs/PointField",
        "std_msgs/Header",
        "builtin_interfaces/Time",
    ] {
        assert!(
            text.contains(&format!("\n{sep}\nMSG: {dep}\n")),
            "{dep} in\n{text}"
        );
    }
    assert!(text.contains("\nstd_msgs/Header header\n"));
    assert!(text.contains("\nuint8 FLOAT32 = 7\n"));

    for (s, msgs) in points.iter().enumerate() {
        assert_eq!(msgs.len(), w.sweeps[s].len());
        for (k, (_, data)) in msgs.iter().enumerate() {
            let mut r = CdrReader::new(data);
            let stamp = expected_stamp(s, k);
            assert_eq!(u64::from(r.u32()), stamp / SECOND);
            assert_eq!(u64::from(r.u32()), stamp % SECOND);
            assert_eq!(r.string(), SENSORS[s]);
            let n = w.sweeps[s][k].len() as u32;
            assert_eq!(r.u32(), 1, "height");
            assert_eq!(r.u32(), n, "width");
            assert_eq!(r.u32(), 7, "fields");
            let want = [
                ("x", 0, 7),
                ("y", 4, 7),
                ("z", 8, 7),
                ("intensity", 12, 7),
                ("t", 16, 6),
                ("ring", 20, 4),
                ("return", 22, 2),
            ];
            for (name, off, ty) in want {
                assert_eq!(r.string(), name);
                assert_eq!(r.u32(), off);
                assert_eq!(r.u8(), ty);
                assert_eq!(r.u32(), 1, "count");
            }
            assert_eq!(r.u8(), 0, "is_bigendian");
            assert_eq!(r.u32(), 24, "point_step");
            assert_eq!(r.u32(), 24 * n, "row_step");
            let len = r.u32();
            assert_eq!(len, 24 * n);
            assert_eq!(
                r.bytes(len as usize),
                ringscan::point::as_bytes(&w.sweeps[s][k])
            );
            assert_eq!(r.u8(), 1, "is_dense");
            assert!(r.done());
        }
    }
}

#[test]
fn lz4_and_uncompressed_chunks_read_back() {
    for (compression, name) in [(Compression::Lz4, "lz4"), (Compression::None, "")] {
        let w = write_file(Format::Foxglove, compression);
        maybe_keep(
            &format!(
                "foxglove-{}.mcap",
                if name.is_empty() { "none" } else { name }
            ),
            &w,
        );
        let summary = mcap::Summary::read(&w.bytes).unwrap().unwrap();
        assert!(summary.chunk_indexes.iter().all(|c| c.compression == name));
        check_common(&w, "foxglove.PointCloud", "protobuf", "protobuf");
    }
}

fn scratch_dir(name: &str) -> std::path::PathBuf {
    let dir =
        std::env::temp_dir().join(format!("ringscan-mcap-sink-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn create_file_commits_only_on_finish() {
    let dir = scratch_dir("commit");
    let path = dir.join("run.mcap");

    // Dropped without finish: nothing at the target, no temporary left behind.
    {
        let mut sink = create_file(&path, SinkOptions::default()).unwrap();
        write_into(&mut sink);
        assert!(temp_path(&path).exists(), "writes go to the temporary file");
        assert!(!path.exists());
    }
    assert!(!path.exists());
    assert!(!temp_path(&path).exists());

    // Aborted: the same.
    let mut sink = create_file(&path, SinkOptions::default()).unwrap();
    write_into(&mut sink);
    sink.abort();
    assert!(!path.exists());
    assert!(!temp_path(&path).exists());

    // Finished: the file is at the target and complete.
    let mut sink = create_file(
        &path,
        SinkOptions {
            format: Format::Ros2,
            ..SinkOptions::default()
        },
    )
    .unwrap();
    write_into(&mut sink);
    let summary = sink.finish().unwrap();
    assert_eq!(summary.path.as_deref(), Some(path.as_path()));
    assert!(!temp_path(&path).exists());
    let bytes = std::fs::read(&path).unwrap();
    let read = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert_eq!(
        read.stats.unwrap().message_count,
        expected_counts(true).values().sum::<u64>()
    );

    // A later run dropped half-way leaves the earlier, complete file untouched.
    {
        let mut sink = create_file(&path, SinkOptions::default()).unwrap();
        write_into(&mut sink);
    }
    assert_eq!(std::fs::read(&path).unwrap(), bytes);
    assert!(!temp_path(&path).exists());

    // A directory that does not exist is an error that names the path.
    let err = create_file(&dir.join("missing/run.mcap"), SinkOptions::default()).unwrap_err();
    assert!(matches!(err, SinkError::Io { .. }));
    assert!(
        err.to_string().contains("missing/run.mcap.tmp-ringscan"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn ros2_refuses_timestamps_past_2038_with_context() {
    let mut sink = McapSink::new(
        Cursor::new(Vec::new()),
        SinkOptions {
            format: Format::Ros2,
            ..Default::default()
        },
    )
    .unwrap();
    let id = sink.add_sensor(&sensor_info("a", "", None)).unwrap();
    let far = (i32::MAX as u64 + 10) * SECOND;
    let err = sink
        .write_sweep(
            id,
            &SweepMsg {
                log_time_ns: 1,
                timestamp_ns: far,
                points: &[],
            },
        )
        .unwrap_err();
    assert!(matches!(err, SinkError::TimestampOutOfRange { .. }));
    assert!(err.to_string().contains("/points"), "{err}");
    // The sink stays usable after a refused message.
    sink.write_sweep(
        id,
        &SweepMsg {
            log_time_ns: 2,
            timestamp_ns: 2,
            points: &[],
        },
    )
    .unwrap();
    let summary = sink.finish().unwrap();
    assert_eq!(summary.messages.get("/points"), Some(&1));
    assert_eq!(summary.messages.get("/diagnostics"), Some(&0));
    assert!(summary.attachments.is_empty());
}

#[test]
fn single_sensor_topics_have_no_prefix() {
    let buf = SharedBuf::default();
    let mut sink = McapSink::new(buf.clone(), SinkOptions::default()).unwrap();
    let id = sink
        .add_sensor(&sensor_info("vlp16-201", "", Some(("meta.json", b"{}"))))
        .unwrap();
    let pts = synthetic_sweep(0, 0);
    sink.write_sweep(
        id,
        &SweepMsg {
            log_time_ns: T0,
            timestamp_ns: T0,
            points: &pts,
        },
    )
    .unwrap();
    sink.write_raw(
        id,
        T0,
        SocketAddrV4::new([10, 0, 0, 1].into(), 7502),
        7502,
        &[],
    )
    .unwrap();
    let summary = sink.finish().unwrap();
    let topics: Vec<_> = summary.messages.keys().cloned().collect();
    assert_eq!(topics, ["/diagnostics", "/points", "/raw"]);
    assert_eq!(summary.attachments[0].media_type, "application/json");
    let read = mcap::Summary::read(&buf.bytes()).unwrap().unwrap();
    assert_eq!(read.stats.unwrap().message_count, 2);
}

#[test]
fn every_zstd_level_reads_back_and_levels_trade_size() {
    // Fast (negative) and regular levels: zstd chunks that the official reader decompresses to
    // the same messages; a higher level never makes the file larger on these sweeps by more
    // than noise, and the fastest is larger than level 1 (so the level reaches zstd).
    let mut sizes = Vec::new();
    for level in [-7, -3, -1, 1, 3, 9] {
        let w = write_file_at(Format::Foxglove, Compression::Zstd, level);
        let summary = mcap::Summary::read(&w.bytes).unwrap().unwrap();
        assert!(summary
            .chunk_indexes
            .iter()
            .all(|c| c.compression == "zstd"));
        check_common(&w, "foxglove.PointCloud", "protobuf", "protobuf");
        sizes.push((level, w.bytes.len()));
    }
    let size = |l: i32| sizes.iter().find(|(x, _)| *x == l).unwrap().1;
    assert!(size(-7) > size(1), "{sizes:?}");
    assert!(size(9) <= size(-7), "{sizes:?}");
}
