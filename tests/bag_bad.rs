//! Damaged bags: a clear error or a counted skip, never a panic, memory bounded.
//!
//! Made from the bag fixtures (copies in the test's temporary directory) and from small ROS 1
//! bags written here record by record (ROS wiki "Bags/Format/2.0").

use std::path::{Path, PathBuf};

use ringscan::source::bag::{BagError, BagOptions, BagSource, BagStats};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures/bags")
        .join(name)
}

fn tmp(name: &str, bytes: &[u8]) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("bag_bad");
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// Reads a bag to its end: datagrams, stats, or the error that stopped it.
fn read_all(path: &Path) -> Result<(usize, BagStats), BagError> {
    let mut src = BagSource::open(path, BagOptions::default())?;
    let mut n = 0;
    loop {
        match src.next_datagram() {
            Ok(Some(_)) => n += 1,
            Ok(None) => return Ok((n, src.stats())),
            Err(e) => return Err(e),
        }
    }
}

/// Top-level records of a ROS 1 bag: (offset, op, header range, data-length offset, data range).
fn records(b: &[u8]) -> Vec<(usize, u8, usize, std::ops::Range<usize>)> {
    let le = |i: usize| u32::from_le_bytes(b[i..i + 4].try_into().unwrap()) as usize;
    let mut out = Vec::new();
    let mut at = 13;
    while at + 4 <= b.len() {
        let hl = le(at);
        let h = &b[at + 4..at + 4 + hl];
        let op = h
            .windows(3)
            .position(|w| w == b"op=")
            .map(|i| h[i + 3])
            .unwrap();
        let dl_at = at + 4 + hl;
        let dl = le(dl_at);
        out.push((at, op, dl_at, dl_at + 4..dl_at + 4 + dl));
        at = dl_at + 4 + dl;
    }
    out
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

/// An uncompressed, unindexed ROS 1 bag: one chunk with a connection of `type_name` on `topic`
/// and one message of `body`.
fn small_bag(topic: &str, type_name: &str, body: &[u8]) -> Vec<u8> {
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
    let mut t = 1_700_000_000u32.to_le_bytes().to_vec();
    t.extend_from_slice(&0u32.to_le_bytes());
    chunk.extend(record(
        &[
            field("op", &[2]),
            field("conn", &0u32.to_le_bytes()),
            field("time", &t),
        ],
        body,
    ));
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

/// Peak resident memory of this process (Linux), bytes.
fn peak_rss() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

#[test]
fn every_truncation_of_a_ros1_bag_ends_cleanly_with_what_was_readable() {
    let full = std::fs::read(fixture("demo-vlp16.ros1-lz4.bag")).unwrap();
    let (all, _) = read_all(&fixture("demo-vlp16.ros1-lz4.bag")).unwrap();
    let mut cuts = 0;
    for cut in (0..full.len()).step_by(997).chain([full.len() - 1]) {
        let p = tmp("cut.bag", &full[..cut]);
        match read_all(&p) {
            Ok((n, st)) => {
                assert!(n <= all, "cut {cut}");
                // Cut inside the data section: the stream says where it stopped (a cut in the
                // trailing index section loses nothing).
                if n < all {
                    assert!(st.truncated_at.is_some(), "cut {cut}: {st:?}");
                }
                cuts += 1;
            }
            Err(e) => assert!(cut < 4200, "cut {cut}: {e}"), // only inside the bag header
        }
    }
    assert!(cuts > 10);
}

#[test]
fn wrong_magic_is_not_a_bag() {
    let mut b = std::fs::read(fixture("demo-vlp16.ros1-bz2.bag")).unwrap();
    b[9..12].copy_from_slice(b"1.2");
    let e = read_all(&tmp("v12.bag", &b)).unwrap_err();
    assert!(matches!(e, BagError::NotABag { .. }), "{e}");
    assert!(e.to_string().contains("not a bag"));
}

#[test]
fn a_chunk_longer_than_the_file_is_a_truncation() {
    let mut b = std::fs::read(fixture("demo-vlp16.ros1-bz2.bag")).unwrap();
    let recs = records(&b);
    let chunks: Vec<_> = recs.iter().filter(|r| r.1 == 5).collect();
    assert!(chunks.len() >= 3, "the fixture has several chunks");
    let (at, _, dl_at, _) = chunks[2].clone();
    b[dl_at..dl_at + 4].copy_from_slice(&(100u32 << 20).to_le_bytes());
    let (n, st) = read_all(&tmp("long-chunk.bag", &b)).unwrap();
    assert!(n > 0, "the first two chunks are decoded");
    assert_eq!(st.truncated_at.map(|t| t.1), Some(at as u64));
}

#[test]
fn a_chunk_that_does_not_inflate_is_counted_and_skipped() {
    for name in ["demo-vlp16.ros1-bz2.bag", "demo-vlp16.ros1-lz4.bag"] {
        let (all, _) = read_all(&fixture(name)).unwrap();
        let mut b = std::fs::read(fixture(name)).unwrap();
        let recs = records(&b);
        let chunk = recs.iter().filter(|r| r.1 == 5).nth(1).unwrap().clone();
        let mid = chunk.3.start + chunk.3.len() / 2;
        for x in &mut b[mid..mid + 64] {
            *x ^= 0x5a;
        }
        let (n, st) = read_all(&tmp("bad-chunk.bag", &b)).unwrap();
        assert_eq!(st.bad_chunks, 1, "{name}: {st:?}");
        assert_eq!(
            st.first_bad_chunk.as_ref().map(|c| c.1),
            Some(chunk.0 as u64)
        );
        assert!(
            n > 0 && n < all,
            "{name}: the other chunks are decoded ({n} of {all})"
        );
    }
}

#[test]
fn a_gigabyte_record_claim_is_an_error_not_an_allocation() {
    let mut b = std::fs::read(fixture("demo-vlp16.ros1-lz4.bag")).unwrap();
    let recs = records(&b);
    let (at, _, dl_at, _) = recs.iter().filter(|r| r.1 == 5).nth(1).unwrap().clone();
    b[dl_at..dl_at + 4].copy_from_slice(&(1u32 << 30).to_le_bytes());
    let before = peak_rss();
    let e = read_all(&tmp("gigabyte.bag", &b)).unwrap_err();
    match &e {
        BagError::InFile { source, .. } => match **source {
            BagError::RecordTooLarge { offset, len, .. } => {
                assert_eq!((offset, len), (at as u64, 1 << 30));
            }
            ref other => panic!("{other}"),
        },
        other => panic!("{other}"),
    }
    assert!(e.to_string().contains("claims 1073741824 bytes"), "{e}");
    if let (Some(a), Some(b)) = (before, peak_rss()) {
        assert!(b < a + (64 << 20), "peak memory grew by {} bytes", b - a);
    }
}

#[test]
fn a_connection_of_an_unknown_type_is_counted() {
    let b = small_bag("/imu", "sensor_msgs/Imu", &[0; 16]);
    let (n, st) = read_all(&tmp("unknown.bag", &b)).unwrap();
    assert_eq!((n, st.messages, st.unknown_type), (0, 1, 1));
}

#[test]
fn a_message_that_does_not_fit_its_type_is_counted() {
    // A VelodyneScan claiming 1000 packets in 16 bytes.
    let mut body = vec![0u8; 16];
    body[12..16].copy_from_slice(&1000u32.to_le_bytes());
    let b = small_bag("/velodyne_packets", "velodyne_msgs/VelodyneScan", &body);
    let (n, st) = read_all(&tmp("malformed.bag", &b)).unwrap();
    assert_eq!((n, st.malformed), (0, 1));
    assert!(st.first_malformed.unwrap().contains("/velodyne_packets"));
}

#[test]
fn damaged_sqlite_and_mcap_files_give_errors_or_truncations() {
    let db3 = fixture("demo-vlp16.sqlite3-message/demo-vlp16.sqlite3-message.db3");
    let bytes = std::fs::read(&db3).unwrap();
    for cut in [100, 4096, bytes.len() / 2, bytes.len() - 1000] {
        // No panic: an SQLite error or fewer messages.
        let _ = read_all(&tmp("cut.db3", &bytes[..cut]));
    }
    let mcap = fixture("demo-vlp16.mcap-file/demo-vlp16.mcap-file.mcap.zstd");
    let mut inner = Vec::new();
    std::io::Read::read_to_end(
        &mut zstd::stream::read::Decoder::new(std::fs::File::open(mcap).unwrap()).unwrap(),
        &mut inner,
    )
    .unwrap();
    let (all, _) = read_all(&tmp("whole.mcap", &inner)).unwrap();
    for cut in [20, inner.len() / 3, inner.len() / 2, inner.len() - 10] {
        match read_all(&tmp("cut.mcap", &inner[..cut])) {
            Ok((n, st)) => {
                assert!(n <= all);
                assert!(st.truncated_at.is_some(), "cut {cut}");
            }
            Err(e) => assert!(e.to_string().contains("MCAP"), "{e}"),
        }
    }
    let mut flipped = inner.clone();
    let mid = flipped.len() / 2;
    flipped[mid] ^= 0xff;
    let _ = read_all(&tmp("flipped.mcap", &flipped));
}

/// An MCAP record, written out from the specification: opcode, u64 length, body.
fn mcap_record(op: u8, body: &[u8]) -> Vec<u8> {
    let mut r = vec![op];
    r.extend_from_slice(&(body.len() as u64).to_le_bytes());
    r.extend_from_slice(body);
    r
}

/// An uncompressed MCAP chunk whose one record claims 1000 bytes where 4 follow (the input that
/// made the mcap crate's chunk reader underflow its count): a clear error naming the chunk,
/// never a panic, and nothing read past the chunk.
#[test]
fn a_record_longer_than_its_mcap_chunk_is_an_error() {
    let mut f = b"\x89MCAP0\r\n".to_vec();
    // Header: profile "", library "t".
    f.extend(mcap_record(0x01, &[0, 0, 0, 0, 1, 0, 0, 0, b't']));
    let mut inner = vec![0x05];
    inner.extend_from_slice(&1000u64.to_le_bytes());
    inner.extend_from_slice(&[1, 2, 3, 4]);
    let mut chunk = Vec::new();
    chunk.extend_from_slice(&0u64.to_le_bytes()); // message_start_time
    chunk.extend_from_slice(&0u64.to_le_bytes()); // message_end_time
    chunk.extend_from_slice(&(inner.len() as u64).to_le_bytes()); // uncompressed_size
    chunk.extend_from_slice(&0u32.to_le_bytes()); // uncompressed_crc: none
    chunk.extend_from_slice(&0u32.to_le_bytes()); // compression: ""
    chunk.extend_from_slice(&(inner.len() as u64).to_le_bytes()); // compressed_size
    chunk.extend_from_slice(&inner);
    f.extend(mcap_record(0x06, &chunk));
    // A message record after the chunk that must not be taken for the chunk's.
    f.extend(mcap_record(0x0f, &[0; 8]));
    f.extend(mcap_record(0x02, &[0; 20])); // footer
    f.extend_from_slice(b"\x89MCAP0\r\n");
    match read_all(&tmp("record-past-chunk.mcap", &f)) {
        Err(e) => {
            let msg = e.to_string();
            assert!(msg.contains("past the chunk's end"), "{msg}");
            assert!(msg.contains("record-past-chunk.mcap"), "{msg}");
        }
        other => panic!("expected an MCAP error, got {other:?}"),
    }
}

/// An MCAP string or byte array: u32 length, then the bytes.
fn mcap_bytes(b: &[u8]) -> Vec<u8> {
    let mut r = (b.len() as u32).to_le_bytes().to_vec();
    r.extend_from_slice(b);
    r
}

/// `ringscan.RawPacket` messages (what `--raw` writes to a foxglove-format MCAP), in an MCAP
/// written record by record from the specification with messages built by hand from the
/// protobuf encoding guide: the well-formed one is one datagram with its own addresses; a
/// broken one is counted malformed; the type on a channel of another encoding, or a ROS type
/// on a protobuf channel, is a type not read.
#[test]
fn hostile_raw_packet_messages_are_counted_not_decoded() {
    let mut f = b"\x89MCAP0\r\n".to_vec();
    f.extend(mcap_record(0x01, &[0, 0, 0, 0, 1, 0, 0, 0, b't']));
    let schema = |id: u16, name: &str, encoding: &str| {
        let mut b = id.to_le_bytes().to_vec();
        b.extend(mcap_bytes(name.as_bytes()));
        b.extend(mcap_bytes(encoding.as_bytes()));
        b.extend(mcap_bytes(b""));
        mcap_record(0x03, &b)
    };
    let channel = |id: u16, schema: u16, topic: &str, encoding: &str| {
        let mut b = id.to_le_bytes().to_vec();
        b.extend_from_slice(&schema.to_le_bytes());
        b.extend(mcap_bytes(topic.as_bytes()));
        b.extend(mcap_bytes(encoding.as_bytes()));
        b.extend_from_slice(&0u32.to_le_bytes()); // metadata: no entry
        mcap_record(0x04, &b)
    };
    let message = |channel: u16, seq: u32, log_time: u64, data: &[u8]| {
        let mut b = channel.to_le_bytes().to_vec();
        b.extend_from_slice(&seq.to_le_bytes());
        b.extend_from_slice(&log_time.to_le_bytes());
        b.extend_from_slice(&log_time.to_le_bytes());
        b.extend_from_slice(data);
        mcap_record(0x05, &b)
    };
    f.extend(schema(1, "ringscan.RawPacket", "protobuf"));
    f.extend(schema(2, "velodyne_msgs/msg/VelodyneScan", "ros2msg"));
    f.extend(channel(1, 1, "/a/raw", "protobuf"));
    f.extend(channel(2, 1, "/b/raw", "cdr"));
    f.extend(channel(3, 2, "/c/velodyne_packets", "protobuf"));
    // {2: "10.0.0.7", 3: 2368, 4: 2369, 5: [1, 2, 3]}, no timestamp (2368 = 0xc0 0x12).
    let mut good = vec![0x12, 8];
    good.extend_from_slice(b"10.0.0.7");
    good.extend_from_slice(&[0x18, 0xc0, 0x12, 0x20, 0xc1, 0x12, 0x2a, 3, 1, 2, 3]);
    let mut bad_address = vec![0x12, 9];
    bad_address.extend_from_slice(b"10.0.0.7x");
    f.extend(message(1, 0, 5_000_000_000, &good));
    f.extend(message(1, 1, 5_000_000_001, &bad_address));
    f.extend(message(1, 2, 5_000_000_002, &good[..good.len() - 1]));
    f.extend(message(2, 0, 5_000_000_003, &good));
    f.extend(message(3, 0, 5_000_000_004, &good));
    f.extend(mcap_record(0x0f, &[0; 4])); // data end
    f.extend(mcap_record(0x02, &[0; 20])); // footer
    f.extend_from_slice(b"\x89MCAP0\r\n");
    let path = tmp("raw-packets.mcap", &f);
    let mut src = BagSource::open(&path, BagOptions::default()).unwrap();
    let d = src
        .next_datagram()
        .unwrap()
        .expect("the well-formed message");
    assert_eq!(d.time_ns, 5_000_000_000, "no timestamp: the log time");
    assert_eq!(d.src, "10.0.0.7:2368".parse().unwrap());
    assert_eq!(d.dst.port(), 2369);
    assert_eq!(d.payload, [1, 2, 3]);
    assert!(src.next_datagram().unwrap().is_none());
    let st = src.stats();
    assert_eq!((st.messages, st.packet_messages), (5, 1));
    assert_eq!((st.malformed, st.unknown_type), (2, 2));
    let first = st.first_malformed.unwrap();
    assert!(
        first.contains("/a/raw (ringscan.RawPacket)") && first.contains("IPv4"),
        "{first}"
    );
    assert!(src.sensors().is_empty(), "raw packets are no bag sensor");
}

/// A zstd-compressed `.db3` that decompresses to far more than its size allows (a zstd bomb:
/// 100 MiB of zeros behind a sqlite3 header, a few kB compressed) is refused with a clear
/// error once the temporary copy (SQLite reads only files) reaches its cap of 64 × the
/// compressed size + 64 MiB, and the copy is removed. Before, it was decompressed whole, twice.
#[test]
fn a_zstd_bomb_db3_is_refused_before_it_fills_the_disk() {
    let mut raw = b"SQLite format 3\0".to_vec();
    raw.resize(100 << 20, 0);
    let z = zstd::bulk::compress(&raw, 3).unwrap();
    drop(raw);
    assert!(z.len() < 64 << 10, "{} bytes compressed", z.len());
    let p = tmp("bomb.db3.zstd", &z);
    let e = read_all(&p).unwrap_err().to_string();
    assert!(e.contains("zstd bomb") && e.contains("zstd -d"), "{e}");
    let left: Vec<_> = std::fs::read_dir(std::env::temp_dir())
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(&format!("ringscan-bag-{}-", std::process::id())))
        .collect();
    assert!(left.is_empty(), "temporary copies left: {left:?}");
}

/// A ROS 1 bag of `chunks` (each the records it holds), every chunk bz2-compressed.
fn bz2_bag(chunks: &[Vec<u8>]) -> Vec<u8> {
    use std::io::Write;
    let mut b = b"#ROSBAG V2.0\n".to_vec();
    b.extend(record(
        &[field("op", &[3]), field("index_pos", &0u64.to_le_bytes())],
        &[b' '; 32],
    ));
    for records in chunks {
        let mut z = bzip2::write::BzEncoder::new(Vec::new(), bzip2::Compression::best());
        z.write_all(records).unwrap();
        let z = z.finish().unwrap();
        b.extend(record(
            &[
                field("op", &[5]),
                field("compression", b"bz2"),
                field("size", &(records.len() as u32).to_le_bytes()),
            ],
            &z,
        ));
    }
    b
}

/// A connection record inside a chunk: id, topic (in the header), type (in the data).
fn connection(id: u32, topic: &[u8], type_name: &[u8]) -> Vec<u8> {
    record(
        &[
            field("op", &[7]),
            field("conn", &id.to_le_bytes()),
            field("topic", topic),
        ],
        &field("type", type_name),
    )
}

/// Connections are kept for the whole bag, so what they hold must be bounded: a bz2 chunk of
/// a few hundred bytes decompresses to a connection with a topic or type of megabytes, and
/// one chunk can hold thousands of connections (old: every one kept, whatever its size or
/// number — a bag of such chunks grew without end). Beyond the bounds: a clear error.
#[test]
fn ros1_connections_beyond_the_bounds_are_errors() {
    use ringscan::source::bag::{MAX_CONNECTION_NAME_BYTES, MAX_FILE_CONNECTIONS, MAX_NAME_BYTES};
    let long = vec![b'a'; 512 << 10];
    for (what, records) in [
        ("topic", connection(0, &long, b"std_msgs/String")),
        ("type", connection(0, b"/t", &vec![b'b'; 8 << 20])),
    ] {
        let b = bz2_bag(&[records]);
        assert!(b.len() < 4096, "{what}: {} bytes", b.len());
        let e = read_all(&tmp("long-name.bag", &b)).unwrap_err().to_string();
        assert!(
            e.contains("connection topic or type") && e.contains(&MAX_NAME_BYTES.to_string()),
            "{what}: {e}"
        );
    }
    // A long log whose nodes come and go has a connection per node on one topic: thousands
    // of ids are read; more than MAX_FILE_CONNECTIONS, or names past their byte bound, not.
    let ids = |n: u32, topic: &[u8]| -> Vec<u8> {
        (0..n)
            .flat_map(|id| connection(id, topic, b"rosgraph_msgs/Log"))
            .collect()
    };
    assert!(read_all(&tmp("rosout.bag", &bz2_bag(&[ids(5_000, b"/rosout")]))).is_ok());
    let bound = format!("more than {MAX_FILE_CONNECTIONS} connections, or {MAX_CONNECTION_NAME_BYTES} bytes of their names");
    let many = ids(MAX_FILE_CONNECTIONS as u32 + 1, b"/rosout");
    let e = read_all(&tmp("many-connections.bag", &bz2_bag(&[many])))
        .unwrap_err()
        .to_string();
    assert!(e.contains(&bound), "{e}");
    let long_topic = vec![b'c'; 3_000];
    let heavy = ids((MAX_CONNECTION_NAME_BYTES / 3_000) as u32 + 1, &long_topic);
    let e = read_all(&tmp("heavy-connections.bag", &bz2_bag(&[heavy])))
        .unwrap_err()
        .to_string();
    assert!(e.contains(&bound), "{e}");
    // A record header inside a chunk is held to the bound of one outside: the chunk is
    // counted and skipped.
    let mut records = record(&[field("op", &[2]), field("x", &vec![0; 2 << 20])], &[]);
    records.extend(connection(0, b"/t", b"std_msgs/String"));
    let (_, st) = read_all(&tmp("long-header.bag", &bz2_bag(&[records]))).unwrap();
    assert_eq!(st.bad_chunks, 1, "{st:?}");
}

/// MCAP likewise: zstd chunks of channel and schema records with names of megabytes, or more
/// channels than any bag has, are errors (old: all kept).
#[test]
fn mcap_channels_and_schemas_beyond_the_bounds_are_errors() {
    use ringscan::source::bag::MAX_CONNECTIONS;
    let schema = |id: u16, name: &[u8]| {
        let mut b = id.to_le_bytes().to_vec();
        b.extend(mcap_bytes(name));
        b.extend(mcap_bytes(b"ros1msg"));
        b.extend(mcap_bytes(b""));
        mcap_record(0x03, &b)
    };
    let channel = |id: u16, topic: &[u8]| {
        let mut b = id.to_le_bytes().to_vec();
        b.extend_from_slice(&1u16.to_le_bytes());
        b.extend(mcap_bytes(topic));
        b.extend(mcap_bytes(b"ros1"));
        b.extend_from_slice(&0u32.to_le_bytes());
        mcap_record(0x04, &b)
    };
    let file = |records: &[u8]| {
        let z = zstd::bulk::compress(records, 3).unwrap();
        let mut chunk = Vec::new();
        chunk.extend_from_slice(&0u64.to_le_bytes());
        chunk.extend_from_slice(&0u64.to_le_bytes());
        chunk.extend_from_slice(&(records.len() as u64).to_le_bytes());
        chunk.extend_from_slice(&0u32.to_le_bytes());
        chunk.extend(mcap_bytes(b"zstd"));
        chunk.extend_from_slice(&(z.len() as u64).to_le_bytes());
        chunk.extend_from_slice(&z);
        let mut f = b"\x89MCAP0\r\n".to_vec();
        f.extend(mcap_record(0x01, &[0, 0, 0, 0, 1, 0, 0, 0, b't']));
        f.extend(mcap_record(0x06, &chunk));
        f.extend(mcap_record(0x0f, &[0; 4]));
        f.extend(mcap_record(0x02, &[0; 20]));
        f.extend_from_slice(b"\x89MCAP0\r\n");
        f
    };
    let long = vec![b'a'; 8 << 20];
    let std_string = schema(1, b"std_msgs/String");
    let many: Vec<u8> = (0..=MAX_CONNECTIONS as u16)
        .flat_map(|id| channel(id, format!("/t{id}").as_bytes()))
        .collect();
    for (what, records, says) in [
        (
            "topic",
            [std_string.clone(), channel(1, &long)].concat(),
            "topic",
        ),
        ("schema", schema(1, &long), "schema name"),
        ("channels", [std_string, many].concat(), "channels"),
    ] {
        let f = file(&records);
        assert!(f.len() < 64 << 10, "{what}: {} bytes", f.len());
        let e = read_all(&tmp("bounds.mcap", &f)).unwrap_err().to_string();
        assert!(e.contains(says) && e.contains("MCAP"), "{what}: {e}");
    }
}

/// A ROS 1 bag whose header gives where its index starts: a file that ends before that point
/// was cut, even where it ends between two records (old: a clean end, the chunks lost
/// unsaid); an index position that is no record of the index (inside the data) is not taken
/// for the end of the messages (old: the stream stopped there, silently, with none).
#[test]
fn a_ros1_bag_that_ends_before_its_index_is_truncated_and_a_wrong_index_pos_is_read_past() {
    let name = "demo-vlp16.ros1-lz4.bag";
    let full = std::fs::read(fixture(name)).unwrap();
    let (all, _) = read_all(&fixture(name)).unwrap();
    let recs = records(&full);
    let field_at = full.windows(10).position(|w| w == b"index_pos=").unwrap() + 10;
    let index_pos = u64::from_le_bytes(full[field_at..field_at + 8].try_into().unwrap()) as usize;
    assert!(recs.iter().any(|r| r.0 == index_pos && r.1 == 7));
    // Cut between records: before the second chunk, and before the index.
    let second = recs.iter().filter(|r| r.1 == 5).nth(1).unwrap().0;
    let (n, st) = read_all(&tmp("cut-between.bag", &full[..second])).unwrap();
    assert!(n > 0 && n < all, "{n} of {all}");
    assert_eq!(st.truncated_at.map(|t| t.1), Some(second as u64));
    // Every message is there, but the file ends before its index: cut all the same.
    let last = recs.iter().rfind(|r| r.0 < index_pos).unwrap().0;
    let (n, st) = read_all(&tmp("cut-before-index.bag", &full[..last])).unwrap();
    assert_eq!(n, all);
    assert_eq!(st.truncated_at.map(|t| t.1), Some(last as u64));
    // Cut at the index, or inside it: every message is there.
    for cut in [index_pos, index_pos + 20, full.len() - 1] {
        let (n, st) = read_all(&tmp("cut-in-index.bag", &full[..cut])).unwrap();
        assert_eq!((n, st.truncated_at), (all, None), "cut {cut}");
    }
    // index_pos at the first chunk, or inside it.
    for wrong in [recs[1].0, recs[1].0 + 10] {
        let mut b = full.clone();
        b[field_at..field_at + 8].copy_from_slice(&(wrong as u64).to_le_bytes());
        let (n, st) = read_all(&tmp("wrong-index-pos.bag", &b)).unwrap();
        assert_eq!((n, st.truncated_at), (all, None), "index_pos {wrong}");
    }
}

/// A message record inside a chunk, recorded at 1.7e9 s.
fn message(conn: u32, body: &[u8]) -> Vec<u8> {
    let mut t = 1_700_000_000u32.to_le_bytes().to_vec();
    t.extend_from_slice(&0u32.to_le_bytes());
    record(
        &[
            field("op", &[2]),
            field("conn", &conn.to_le_bytes()),
            field("time", &t),
        ],
        body,
    )
}

/// A ROS 1 `string` or `uint8[]`: u32 length, then the bytes.
fn ros1_bytes(b: &[u8]) -> Vec<u8> {
    let mut r = (b.len() as u32).to_le_bytes().to_vec();
    r.extend_from_slice(b);
    r
}

/// Ouster metadata is kept by namespace to the end of the bag, and a bz2 chunk of a few
/// hundred bytes holds a metadata message of megabytes: past `MAX_METADATA_BYTES` of them, a
/// namespace's is counted and not kept (old: every namespace's kept, whatever their total).
#[test]
fn ouster_metadata_past_its_bound_is_counted_not_kept() {
    use ringscan::source::bag::MAX_METADATA_BYTES;
    let text = ros1_bytes(&vec![b'x'; MAX_METADATA_BYTES * 2 / 5]);
    let mut chunks = Vec::new();
    let mut packets = Vec::new();
    for k in 0..3u32 {
        let (meta, lidar) = (format!("/os{k}/metadata"), format!("/os{k}/lidar_packets"));
        let mut records = connection(2 * k, meta.as_bytes(), b"std_msgs/String");
        records.extend(connection(
            2 * k + 1,
            lidar.as_bytes(),
            b"ouster_ros/PacketMsg",
        ));
        records.extend(message(2 * k, &text));
        chunks.push(records);
        packets.extend(message(2 * k + 1, &ros1_bytes(&[0; 16])));
    }
    chunks.push(packets);
    let b = bz2_bag(&chunks);
    assert!(b.len() < 64 << 10, "{} bytes", b.len());
    let mut src = BagSource::open(&tmp("metadata.bag", &b), BagOptions::default()).unwrap();
    while src.next_datagram().unwrap().is_some() {}
    let kept: Vec<bool> = src.sensors().iter().map(|s| s.metadata.is_some()).collect();
    assert_eq!(kept, [true, true, false]);
    assert_eq!(src.stats().metadata_dropped, 1);
}
