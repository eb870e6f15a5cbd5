//! The MCAP writer with chunks compressed on worker threads: the same messages, in the same
//! order, whatever the number of threads; the uncompressed fallback of a writer that must not
//! wait; `--fields minimal`; every CRC of the file checked by the `mcap` crate's reader.
#![cfg(feature = "mcap")]

use std::io::Cursor;
use std::path::{Path, PathBuf};
use std::process::Command;

use ringscan::point::Point;
use ringscan::sink::mcap::{
    Behind, Compression, Format, McapSink, PointFields, SensorInfo, SinkOptions, SinkSummary,
    SweepMsg,
};
use ringscan::sink::mcap_write::in_flight_limit;

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

fn sweep_points(k: usize) -> Vec<Point> {
    let n = 300 + (k * 37) % 500;
    (0..n)
        .map(|i| {
            let a = (i + k) as f32 * 0.013;
            Point {
                x: a.cos() * (2.0 + (i % 50) as f32),
                y: a.sin() * (2.0 + (i % 50) as f32),
                z: ((i * 7 + k) % 32) as f32 * 0.1 - 1.0,
                intensity: ((i * 13 + k) % 256) as f32,
                t: i as u32 * 1_300,
                ring: (i % 32) as u16,
                ret: (i % 2) as u8,
                pad: 0,
            }
        })
        .collect()
}

const T0: u64 = 1_700_000_000_000_000_000;

/// Writes 200 sweeps of two sensors (points, raw packets, diagnostics, an attachment each).
fn write(opts: SinkOptions) -> (Vec<u8>, SinkSummary) {
    let buf = SharedBuf::default();
    let mut sink = McapSink::new(buf.clone(), opts).unwrap();
    let ids = [
        sink.add_sensor(&SensorInfo {
            name: "a".into(),
            topic_prefix: "/a".into(),
            // A Velodyne: with --format ros2 its raw packets are one VelodyneScan per sweep.
            metadata: [("family".to_string(), "velodyne".to_string())].into(),
            calibration: Some(("a.yaml".into(), b"lasers: []".to_vec())),
        })
        .unwrap(),
        sink.add_sensor(&SensorInfo {
            name: "b".into(),
            topic_prefix: "/b".into(),
            // A Velodyne: with --format ros2 its raw packets are one VelodyneScan per sweep.
            metadata: [("family".to_string(), "velodyne".to_string())].into(),
            calibration: Some(("b.json".into(), b"{}".to_vec())),
        })
        .unwrap(),
    ];
    for k in 0..200 {
        for (s, &id) in ids.iter().enumerate() {
            let log = T0 + k as u64 * 50_000_000 + s as u64;
            let src = std::net::SocketAddrV4::new([10, 0, 0, 1 + s as u8].into(), 2368);
            sink.write_raw(id, log - 10, src, 2368, &[k as u8; 1206])
                .unwrap();
            let points = sweep_points(k + s);
            let msg = SweepMsg {
                log_time_ns: log,
                timestamp_ns: log - 1_000,
                points: &points,
            };
            sink.write_sweep(id, &msg).unwrap();
            sink.write_diagnostics(id, log, &serde_json::json!({"sweep": k}))
                .unwrap();
        }
    }
    let summary = sink.finish().unwrap();
    let bytes = buf.0.borrow().get_ref().clone();
    (bytes, summary)
}

fn opts(format: Format, threads: usize, compression: Compression) -> SinkOptions {
    SinkOptions {
        format,
        compression,
        chunk_size: 32 * 1024,
        threads,
        ..SinkOptions::default()
    }
}

/// Every message: (topic, sequence, log time, publish time, data), in file order.
type Msg = (String, u32, u64, u64, Vec<u8>);

fn messages(bytes: &[u8]) -> Vec<Msg> {
    mcap::MessageStream::new(bytes)
        .unwrap()
        .map(|m| {
            let m = m.unwrap();
            (
                m.channel.topic.clone(),
                m.sequence,
                m.log_time,
                m.publish_time,
                m.data.into_owned(),
            )
        })
        .collect()
}

/// Reads every record with the `mcap` crate's linear reader, checking the chunk, data-section
/// and summary-section CRCs and that nothing follows the end magic; returns the chunks'
/// compression names.
fn check_crcs(bytes: &[u8]) -> Vec<String> {
    use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_emit_chunks(true)
            .with_validate_chunk_crcs(true)
            .with_validate_data_section_crc(true)
            .with_validate_summary_section_crc(true)
            .with_check_finishes_after_end_magic(true),
    );
    let mut at = 0;
    let mut compressions = Vec::new();
    let mut footer = false;
    while let Some(event) = reader.next_event() {
        match event.expect("a valid record") {
            LinearReadEvent::ReadRequest(n) => {
                let n = n.min(bytes.len() - at);
                reader.insert(n).copy_from_slice(&bytes[at..at + n]);
                reader.notify_read(n);
                at += n;
            }
            LinearReadEvent::Record { opcode, data } => {
                match mcap::parse_record(opcode, data).expect("a record that parses") {
                    mcap::records::Record::Chunk { header, .. } => {
                        compressions.push(header.compression)
                    }
                    mcap::records::Record::Footer(_) => footer = true,
                    _ => {}
                }
            }
        }
    }
    assert!(footer, "the file ends with a footer");
    // The summary agrees: one chunk index per chunk, with the same compression.
    let summary = mcap::Summary::read(bytes).unwrap().expect("a summary");
    let indexed: Vec<String> = summary
        .chunk_indexes
        .iter()
        .map(|c| c.compression.clone())
        .collect();
    assert_eq!(indexed, compressions);
    compressions
}

#[test]
fn one_two_and_four_threads_write_the_same_messages_in_order() {
    for format in [Format::Foxglove, Format::Ros2] {
        for compression in [Compression::Zstd, Compression::Lz4, Compression::None] {
            let (one, s1) = write(opts(format, 1, compression));
            let m1 = messages(&one);
            assert_eq!(m1.len(), 200 * 2 * 3);
            assert!(s1.chunks > 20, "small chunks: {} of them", s1.chunks);
            check_crcs(&one);
            for threads in [2, 4] {
                let (n, sn) = write(opts(format, threads, compression));
                check_crcs(&n);
                let mn = messages(&n);
                assert_eq!(mn.len(), m1.len());
                for (i, (a, b)) in m1.iter().zip(&mn).enumerate() {
                    assert_eq!(
                        a, b,
                        "{format:?} {compression:?}, {threads} threads: message {i}"
                    );
                }
                assert_eq!(sn.messages, s1.messages);
                assert_eq!(sn.attachments, s1.attachments);
                assert_eq!((sn.chunks, sn.chunks_uncompressed), (s1.chunks, 0));
                // Stronger than asked: the chunks are compressed alike, so the files are equal.
                assert!(
                    n == one,
                    "{format:?} {compression:?}: {threads} threads, other bytes"
                );
            }
        }
    }
}

#[test]
fn a_writer_that_must_not_wait_stores_late_chunks_uncompressed_and_counts_them() {
    // zstd 19 on 32 KiB chunks takes far longer than filling one: the two workers fall behind
    // at once and the in-flight limit (4 chunks) is reached.
    let slow = |behind| SinkOptions {
        zstd_level: 19,
        behind,
        ..opts(Format::Foxglove, 2, Compression::Zstd)
    };
    let (reference, _) = write(opts(Format::Foxglove, 1, Compression::None));
    let (bytes, summary) = write(slow(Behind::WriteUncompressed));
    let compressions = check_crcs(&bytes);
    let stored = compressions.iter().filter(|c| c.is_empty()).count();
    println!(
        "{} chunks, {} written uncompressed",
        compressions.len(),
        summary.chunks_uncompressed
    );
    assert!(summary.chunks_uncompressed > 0, "the fallback was taken");
    assert_eq!(summary.chunks_uncompressed as usize, stored);
    // How many of them the workers finished in time depends on the CPU they got (on a loaded
    // machine, none): the test below shows they are compressed when there is room.
    assert!(compressions.iter().all(|c| c.is_empty() || c == "zstd"));
    assert_eq!(summary.chunks, compressions.len());
    // Nothing dropped, nothing reordered.
    assert_eq!(messages(&bytes), messages(&reference));
    // Waiting instead: every chunk compressed.
    let (bytes, summary) = write(slow(Behind::Wait));
    assert_eq!(summary.chunks_uncompressed, 0);
    assert!(check_crcs(&bytes).iter().all(|c| c == "zstd"));
    assert_eq!(messages(&bytes), messages(&reference));
}

#[test]
fn a_writer_that_must_not_wait_compresses_every_chunk_while_it_has_room() {
    // The same slow compression, but chunks so large that the file is fewer chunks than the
    // in-flight limit: the fallback is never due, so however slow the workers (or starved of
    // CPU), every chunk is compressed, the last ones waited for at the end.
    let roomy = SinkOptions {
        zstd_level: 19,
        behind: Behind::WriteUncompressed,
        chunk_size: 4 << 20,
        ..opts(Format::Foxglove, 2, Compression::Zstd)
    };
    let (reference, _) = write(opts(Format::Foxglove, 1, Compression::None));
    let (bytes, summary) = write(roomy);
    let compressions = check_crcs(&bytes);
    assert!(
        compressions.len() >= 2 && compressions.len() < in_flight_limit(2),
        "{} chunks",
        compressions.len()
    );
    assert_eq!(summary.chunks_uncompressed, 0);
    assert!(compressions.iter().all(|c| c == "zstd"), "{compressions:?}");
    assert_eq!(messages(&bytes), messages(&reference));
}

/// A stream that fails once it holds `limit` bytes.
struct Failing {
    written: usize,
    limit: usize,
}

impl std::io::Write for Failing {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if self.written + buf.len() > self.limit {
            return Err(std::io::Error::other("disk full"));
        }
        self.written += buf.len();
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl std::io::Seek for Failing {
    fn seek(&mut self, _: std::io::SeekFrom) -> std::io::Result<u64> {
        Ok(self.written as u64)
    }
}

#[test]
fn an_output_error_with_workers_is_an_error_not_a_panic() {
    for threads in [1, 3] {
        let mut sink = McapSink::new(
            Failing {
                written: 0,
                limit: 200_000,
            },
            opts(Format::Foxglove, threads, Compression::Zstd),
        )
        .unwrap();
        let id = sink
            .add_sensor(&SensorInfo {
                name: "a".into(),
                ..SensorInfo::default()
            })
            .unwrap();
        let mut failed = None;
        for k in 0..400 {
            let points = sweep_points(k);
            let msg = SweepMsg {
                log_time_ns: T0 + k as u64,
                timestamp_ns: T0,
                points: &points,
            };
            if let Err(e) = sink.write_sweep(id, &msg) {
                failed = Some(e);
                break;
            }
        }
        let err = match failed {
            Some(e) => e,
            None => sink.finish().unwrap_err(),
        };
        assert!(err.to_string().contains("disk full"), "{threads}: {err}");
    }
}

/// One points message: stride, (name, offset) of x, y, z and intensity, the record bytes.
type Cloud = (u32, Vec<(String, u32)>, Vec<u8>);

/// The `foxglove.PointCloud` (or `PointCloud2`) of each `/points` message.
fn point_records(bytes: &[u8], format: Format) -> Vec<Cloud> {
    use prost::Message as _;
    messages(bytes)
        .into_iter()
        .filter(|m| m.0.ends_with("/points"))
        .map(|m| match format {
            Format::Foxglove => {
                let pc = ringscan::sink::read::PointCloud::decode(&m.4[..]).unwrap();
                let fields = pc
                    .fields
                    .iter()
                    .filter(|f| ["x", "y", "z", "intensity"].contains(&f.name.as_str()))
                    .map(|f| {
                        assert_eq!(f.r#type, 7, "FLOAT32: {}", f.name);
                        (f.name.clone(), f.offset)
                    })
                    .collect();
                (pc.point_stride, fields, pc.data)
            }
            Format::Ros2 => ros2_cloud(&m.4),
        })
        .collect()
}

/// A small CDR reader for `sensor_msgs/msg/PointCloud2` (little-endian, as written).
fn ros2_cloud(b: &[u8]) -> Cloud {
    let b = &b[4..];
    let mut at = 0usize;
    let u32_at = |at: &mut usize| {
        *at = at.next_multiple_of(4);
        let v = u32::from_le_bytes(b[*at..*at + 4].try_into().unwrap());
        *at += 4;
        v
    };
    let string = |at: &mut usize| {
        let n = u32_at(at) as usize;
        let s = String::from_utf8(b[*at..*at + n - 1].to_vec()).unwrap();
        *at += n;
        s
    };
    u32_at(&mut at); // sec
    u32_at(&mut at); // nanosec
    string(&mut at); // frame_id
    assert_eq!(u32_at(&mut at), 1); // height
    let width = u32_at(&mut at);
    let nfields = u32_at(&mut at);
    let mut fields = Vec::new();
    for _ in 0..nfields {
        let name = string(&mut at);
        let offset = u32_at(&mut at);
        let datatype = b[at];
        at += 1;
        assert_eq!(u32_at(&mut at), 1); // count
        if name == "t" {
            continue;
        }
        if ["x", "y", "z", "intensity"].contains(&name.as_str()) {
            assert_eq!(datatype, 7, "FLOAT32: {name}");
            fields.push((name, offset));
        }
    }
    at += 1; // is_bigendian
    let step = u32_at(&mut at);
    let row = u32_at(&mut at);
    let len = u32_at(&mut at) as usize;
    assert_eq!(row as usize, len);
    assert_eq!(width as usize * step as usize, len);
    (step, fields, b[at..at + len].to_vec())
}

#[test]
fn minimal_fields_are_the_first_four_of_the_default_record() {
    for format in [Format::Foxglove, Format::Ros2] {
        for threads in [1, 2] {
            let (full, _) = write(opts(format, threads, Compression::Zstd));
            let (min, summary) = write(SinkOptions {
                fields: PointFields::Minimal,
                ..opts(format, threads, Compression::Zstd)
            });
            check_crcs(&min);
            assert_eq!(summary.chunks_uncompressed, 0);
            let full = point_records(&full, format);
            let min = point_records(&min, format);
            assert_eq!(full.len(), 400);
            assert_eq!(min.len(), full.len());
            let xyzi: Vec<(String, u32)> = [("x", 0), ("y", 4), ("z", 8), ("intensity", 12)]
                .iter()
                .map(|&(n, o)| (n.to_string(), o))
                .collect();
            for ((fs, ff, fd), (ms, mf, md)) in full.iter().zip(&min) {
                assert_eq!((*fs, *ms), (24, 16));
                assert_eq!(ff, &xyzi);
                assert_eq!(mf, &xyzi);
                assert_eq!(fd.len() / 24, md.len() / 16);
                for (f, m) in fd.chunks_exact(24).zip(md.chunks_exact(16)) {
                    assert_eq!(&f[..16], m);
                }
            }
        }
    }
}

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_ringscan")
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!(
        "ringscan-mcap-threads-{}-{name}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `ringscan decode INPUT ARGS --out DIR/tN.mcap --threads N --json` for N = 1, 2, 4: the same
/// messages in the same order, no chunk uncompressed.
fn decode_with_threads(name: &str, input: &Path, args: &[&str]) {
    let dir = scratch(name);
    let mut first: Option<Vec<Msg>> = None;
    for threads in ["1", "2", "4"] {
        let out = dir.join(format!("t{threads}.mcap"));
        let o = Command::new(bin())
            .arg("decode")
            .arg(input)
            .args(args)
            .arg("--out")
            .arg(&out)
            .args(["--threads", threads, "--chunk-size", "0.25", "--json"])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(j["output"]["threads"], threads.parse::<u64>().unwrap());
        assert_eq!(j["output"]["chunks_uncompressed"], 0);
        assert!(
            j["output"]["chunks"].as_u64().unwrap() > 4,
            "{}",
            j["output"]
        );
        let bytes = std::fs::read(&out).unwrap();
        check_crcs(&bytes);
        let m = messages(&bytes);
        match &first {
            None => {
                assert!(!m.is_empty());
                first = Some(m);
            }
            Some(f) => {
                assert_eq!(f.len(), m.len(), "{name}: {threads} threads");
                for (i, (a, b)) in f.iter().zip(&m).enumerate() {
                    assert!(
                        a == b,
                        "{name}: {threads} threads, message {i} ({}) differs",
                        a.0
                    );
                }
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn decode_writes_the_same_messages_with_one_two_and_four_threads() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    decode_with_threads("demo", &root.join("fixtures/demo-vlp16.pcap"), &["--raw"]);
    let o = root.join("../shared/captures/ouster-lidar__ouster-sdk/tests/pcaps");
    let pcap = o.join("OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
    let meta = o.join("OS-1-128_v2.3.0_1024x10.json");
    if pcap.exists() && meta.exists() {
        let meta = meta.to_string_lossy().into_owned();
        decode_with_threads("ouster", &pcap, &["--calib", &meta]);
    } else {
        println!(
            "SKIP: {} is absent: the Ouster capture is not decoded",
            pcap.display()
        );
    }
}
