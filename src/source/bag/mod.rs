//! ROS bags as a stream of UDP datagrams, like a pcap.
//!
//! In: a ROS 1 bag, a rosbag2 directory (or its `metadata.yaml`), a bare `.db3`, or an
//! `.mcap` holding ROS packet messages; the kind is found from the bytes (magic numbers), never
//! from the file name. Out: one [`Datagram`] per packet the messages carry, so every stream,
//! sweep, loss count, pipeline and sink downstream works as it does for a capture.
//!
//! | input | detected by | read by |
//! |---|---|---|
//! | ROS 1 bag (chunks none / bz2 / lz4) | `#ROSBAG V2.0\n` | [`ros1`] |
//! | rosbag2 directory | a `metadata.yaml` with `rosbag2_bagfile_information` | [`rosbag2`]: its files in order |
//! | sqlite3 (`.db3`), also bare | `SQLite format 3\0` | [`rosbag2::SqliteReader`] |
//! | MCAP (`ros1msg` or `ros2msg` / CDR schemas; ringscan's `ringscan.RawPacket`, protobuf) | `\x89MCAP0\r\n` | [`mcap_in`] |
//! | a zstd-compressed storage file (rosbag2 `FILE` mode) | zstd magic `28 b5 2f fd`, then the inner magic | sqlite3: decompressed to a temporary file (SQLite needs one); MCAP: decompressed as it is read |
//!
//! rosbag2 `MESSAGE` compression (each message one zstd frame) is undone per message (in a
//! bare `.db3` / `.mcap` without its yaml, a CDR message that starts with the zstd magic is one).
//!
//! # Sensors, addresses and ports
//! Streams downstream are keyed by source address, so each sensor gets a synthetic loopback
//! source address: **127.0.0.N, N = 1, 2, … in order of first appearance of the sensor's first
//! packet topic** (ROS 1 connection records — all of them up front when the bag has its index —,
//! rosbag2 topic ids, MCAP channel records). A sensor is:
//! - Ouster (`*/PacketMsg`): a topic namespace: `<ns>/lidar_packets`, `<ns>/imu_packets` and
//!   `<ns>/metadata` (`std_msgs/String`, the sensor metadata JSON) are one sensor. Lidar
//!   packets go to the metadata's `udp_port_lidar`, IMU packets (a topic whose last segment
//!   names `imu`) to its `udp_port_imu`; 7502 / 7503 without metadata (or where it says 0).
//! - every other packet topic is one sensor: Velodyne (`VelodyneScan`) and Hesai
//!   (`PandarScan`, `UdpFrame`) data to 2368, Robosense MSOP to 6699 and DIFOP to 7788;
//!   `nebula_msgs/NebulaPackets` by its first packet (1206 bytes: Velodyne; `EE FF`: Hesai;
//!   `55 AA` / `A5 FF`: Robosense MSOP / DIFOP; else 2368).
//!
//! - Livox `CustomMsg` (`livox_ros_driver2`, `livox_ros_driver`): points the driver decoded,
//!   not packets. Each topic is one sensor; each message becomes one points frame
//!   ([`crate::sensor::livox::frame`], the one "datagram" of that message, to 56301) that the
//!   Livox stream turns into one sweep. The driver's IMU topic (`sensor_msgs/Imu`) belongs to
//!   the `CustomMsg` topic of the same name with `imu` for `lidar` in its last segment
//!   (`/livox/imu` → `/livox/lidar`; `/livox/imu_192_168_1_3` → `/livox/lidar_192_168_1_3`, as
//!   both drivers name them), from its first message when the bag lists that topic up front
//!   (ROS 1 index, sqlite3, an MCAP whose channels come first), else from the first after that
//!   topic's connection record (the question is asked again only when a sensor or a
//!   connection has been added, not at every message); each
//!   message becomes one IMU frame to 56401, so the samples reach
//!   the Livox stream's IMU path (deskew, `/imu`) as the sensor's own IMU packets do. The
//!   drivers publish the acceleration in g, as the sensor sends it, where the type says m/s²:
//!   a topic whose first sample's magnitude is below √9.80665 ≈ 3.13 is read as g (a sensor
//!   at rest reads 1 g; 3.13 m/s² would be a free fall of 68 %), the others as m/s². An `Imu`
//!   topic with no such `CustomMsg` topic (a vehicle's IMU) is not read: counted in
//!   [`BagStats::unknown_type`].
//!
//! The source port equals the destination port; the destination address is 127.0.0.1.
//! [`BagSource::sensors`] lists the assignment.
//!
//! `ringscan.RawPacket` messages (the `--raw` output of an MCAP in the foxglove format) need
//! none of this: each is one datagram that keeps the address and ports it was received with
//! (destination address 127.0.0.1), and belongs to no bag sensor.
//!
//! The attachments of an MCAP bag ([`BagSource::attachments`], through the summary's
//! attachment indexes) are the calibration files a bag ringscan wrote carries; the command line
//! uses them when no `--calib` is given.
//!
//! # Time
//! A datagram's time is its packet's own stamp where the message type has one
//! (`VelodynePacket`, `PandarPacket`, `NebulaPacket`, `UdpPacket`, `RobosensePacket`, the
//! header of an `RslidarPacket`), else the record time of its message (ROS 1 record `time`,
//! rosbag2 `timestamp`, MCAP `log_time`). `--start` / `--end` ([`BagOptions`]) compare record
//! times: a bound below 10⁹ s is seconds after the bag's first message, one above is absolute
//! (seconds since the Unix epoch).
//!
//! # Order
//! Messages come in storage order: ROS 1 chunk by chunk (the order recorded), rosbag2 sqlite3
//! by `timestamp` (as `ros2 bag play`), MCAP in file order; the packets of one message in
//! their order in it. Ouster metadata is looked for before the first datagram (a pre-scan of at
//! most [`PRESCAN_BYTES`] of messages, stopping as soon as every Ouster namespace known has
//! one), so a decoder can be configured before its first packet arrives.
//!
//! # Memory and errors
//! The bag is never held in memory: one ROS 1 chunk or MCAP chunk at a time, one sqlite3
//! message at a time; a record or chunk larger than
//! [`MAX_CHUNK_BYTES`], a message larger than [`MAX_MESSAGE_BYTES`], is refused before it is
//! allocated (an error for ROS 1 / MCAP records, whose framing is then lost; a counted skip for
//! sqlite3 rows). What is kept to the end is bounded: [`MAX_CONNECTIONS`] topics, MCAP channels
//! and schemas, [`MAX_FILE_CONNECTIONS`] ROS 1 connections with [`MAX_CONNECTION_NAME_BYTES`] of
//! names, names of at most [`MAX_NAME_BYTES`] (beyond them the bag is refused), and
//! [`MAX_METADATA_BYTES`] of Ouster metadata (beyond it counted in `metadata_dropped`); a message
//! without a connection record is of one placeholder topic, whatever its id. A message that
//! does not parse as its type is counted in
//! [`BagStats::malformed`] and skipped; topics of other types in `unknown_type`; a ROS 1 chunk
//! that does not decompress in `bad_chunks`. A file cut short ends the stream with
//! [`BagStats::truncated_at`] saying where; what came before is decoded.

mod lz4frame;
pub mod mcap_in;
pub mod messages;
pub mod ros1;
pub mod rosbag2;

use std::collections::{HashMap, VecDeque};
use std::fs::File;
use std::io::{self, BufReader, Read};
use std::net::{Ipv4Addr, SocketAddrV4};
use std::path::{Path, PathBuf};

use self::mcap_in::McapReader;
use self::messages::{Encoding, MsgKind, PacketRef};
use self::ros1::Ros1Reader;
use self::rosbag2::{Compression, Metadata, SqliteReader};
use super::Datagram;
use crate::sensor::livox::frame;

/// Largest chunk (ROS 1 compressed or uncompressed; MCAP record) accepted.
pub const MAX_CHUNK_BYTES: usize = 256 << 20;
/// Largest single message accepted.
pub const MAX_MESSAGE_BYTES: usize = 64 << 20;
/// Message bytes the Ouster metadata pre-scan reads at most.
pub const PRESCAN_BYTES: u64 = 64 << 20;
/// A zstd-compressed sqlite3 file is decompressed to a temporary file (SQLite reads only
/// files) of at most this many times its compressed size, plus [`ZSTD_DB3_SLACK_BYTES`]:
/// storage of packets compresses a few times, a zstd bomb by thousands, and it must not fill
/// the disk.
pub const MAX_ZSTD_DB3_RATIO: u64 = 64;
/// See [`MAX_ZSTD_DB3_RATIO`].
pub const ZSTD_DB3_SLACK_BYTES: u64 = 64 << 20;
/// Sensors (synthetic addresses 127.0.0.1 … 127.0.0.254) at most.
pub const MAX_SENSORS: usize = 254;
/// Channels and schemas (MCAP) and topics (sqlite3) of one storage file, and topics (by name
/// and type) of a whole bag, at most; beyond it the bag is refused. They are kept to the end
/// of the bag, and a compressed chunk of a kB holds thousands of them: without a bound a
/// hostile bag fills memory. Real bags have tens to a few hundred (ROS 1 connections, one per
/// topic and publishing node, have [`MAX_FILE_CONNECTIONS`]).
pub const MAX_CONNECTIONS: usize = 4096;
/// Connection ids of one ROS 1 file at most: one per topic and publishing node, so a long log
/// whose anonymous nodes come and go (each with its own `/rosout` connection) holds thousands
/// on a few hundred topics. Their names are bounded together by
/// [`MAX_CONNECTION_NAME_BYTES`].
pub const MAX_FILE_CONNECTIONS: usize = 1 << 16;
/// Bytes of topic and type names over one ROS 1 file's connections at most (real ones have
/// tens of bytes each): with [`MAX_FILE_CONNECTIONS`], what a file's connections hold.
pub const MAX_CONNECTION_NAME_BYTES: usize = 16 << 20;
/// Ouster metadata texts kept at most, all namespaces together (past it, one is counted in
/// [`BagStats::metadata_dropped`]): a sensor's is tens of kB, and a bag may have a metadata
/// topic of up to [`MAX_MESSAGE_BYTES`] for each of its namespaces.
pub const MAX_METADATA_BYTES: usize = 16 << 20;
/// Longest topic, type or schema name accepted (real ones have tens of bytes); a longer one
/// is refused, for the reason of [`MAX_CONNECTIONS`].
pub const MAX_NAME_BYTES: usize = 4096;

const ZSTD_MAGIC: [u8; 4] = [0x28, 0xb5, 0x2f, 0xfd];
const SQLITE_MAGIC: &[u8; 16] = b"SQLite format 3\0";

/// Errors of the bag source: the bag cannot be read further.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BagError {
    /// A file could not be opened.
    #[error("cannot open {path}: {source}")]
    Open {
        /// Path.
        path: PathBuf,
        /// Underlying error.
        #[source]
        source: io::Error,
    },
    /// Reading failed.
    #[error("I/O error at byte {offset}: {source}")]
    Io {
        /// Offset reached.
        offset: u64,
        /// Underlying error.
        #[source]
        source: io::Error,
    },
    /// Not the format expected.
    #[error("not a {expected} file: it starts with {found:02x?}")]
    BadMagic {
        /// Format expected.
        expected: &'static str,
        /// The first bytes found.
        found: Vec<u8>,
    },
    /// Nothing ringscan reads as a bag.
    #[error(
        "not a bag: expected a ROS 1 bag, a rosbag2 directory or metadata.yaml, a .db3 or an \
         MCAP file, found {found:02x?}"
    )]
    NotABag {
        /// The first bytes found.
        found: Vec<u8>,
    },
    /// The structure contradicts itself.
    #[error("corrupt bag at byte {offset}: {reason}")]
    Corrupt {
        /// Offset of the record at fault.
        offset: u64,
        /// What is wrong.
        reason: String,
    },
    /// A record larger than the limits.
    #[error("{what} at byte {offset} claims {len} bytes, more than the limit of {limit}")]
    RecordTooLarge {
        /// Offset of the record.
        offset: u64,
        /// What the length is of.
        what: &'static str,
        /// Length claimed.
        len: u64,
        /// Limit in force.
        limit: u64,
    },
    /// A rosbag2 `metadata.yaml` that cannot be used.
    #[error("{path}: {reason}")]
    Metadata {
        /// Path of the yaml.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// SQLite refused the file or a query.
    #[error("sqlite3 {path}: {reason}")]
    Sqlite {
        /// Path of the `.db3`.
        path: PathBuf,
        /// SQLite's message.
        reason: String,
    },
    /// The MCAP reader refused the file.
    #[error("MCAP at byte {offset}: {reason}")]
    Mcap {
        /// Bytes read when it stopped.
        offset: u64,
        /// The reader's message.
        reason: String,
    },
    /// An error in one file of a bag of several.
    #[error("{path}: {source}")]
    InFile {
        /// The file.
        path: PathBuf,
        /// The error.
        #[source]
        source: Box<BagError>,
    },
}

/// A topic as its storage describes it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Connection {
    /// Topic name.
    pub topic: String,
    /// Recorded type name (`pkg/Type` or `pkg/msg/Type`).
    pub type_name: String,
    /// Serialization; `None`: one ringscan does not read.
    pub encoding: Option<Encoding>,
}

/// A message read from storage (its bytes are in the caller's buffer).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawMessage {
    /// Connection / topic / channel id (per file).
    pub conn: u64,
    /// Record time, ns since the Unix epoch.
    pub time_ns: i64,
}

/// Reads until `out` is full or the reader ends; returns the bytes read.
pub(crate) fn read_up_to<R: Read + ?Sized>(reader: &mut R, out: &mut [u8]) -> io::Result<usize> {
    let mut filled = 0;
    while filled < out.len() {
        match reader.read(&mut out[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n.min(out.len() - filled),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(filled)
}

/// Reads up to `len` bytes into `buf[..len]`; returns how many arrived (fewer at the end of the
/// input). `buf` grows as the bytes arrive (a length claimed by a damaged file allocates only
/// what the file holds) and is never shrunk: the readers keep a buffer's valid length beside
/// it, so a reused buffer is written once per record instead of being zeroed first, as
/// `read_to_end` into a cleared `Vec` would.
pub(crate) fn fill<R: Read + ?Sized>(
    reader: &mut R,
    buf: &mut Vec<u8>,
    len: usize,
) -> io::Result<usize> {
    let mut got = 0;
    while got < len {
        if buf.len() <= got {
            buf.resize(len.min(got.saturating_mul(2).max(1 << 16)), 0);
        }
        let end = len.min(buf.len());
        match reader.read(&mut buf[got..end]) {
            Ok(0) => break,
            Ok(n) => got += n.min(end - got),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}

/// Decompresses into `buf[..size]` (as [`fill`]); true when exactly `size` bytes come out.
pub(crate) fn inflate_exact(mut d: impl Read, size: usize, buf: &mut Vec<u8>) -> bool {
    let mut more = [0u8; 1];
    matches!(fill(&mut d, buf, size), Ok(n) if n == size)
        && matches!(read_up_to(&mut d, &mut more), Ok(0))
}

// ----- kinds -----------------------------------------------------------------------------------

/// The kind of one storage file, from its first bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileKind {
    /// ROS 1 bag.
    Ros1,
    /// sqlite3 database.
    Sqlite3,
    /// MCAP.
    Mcap,
    /// zstd-compressed sqlite3.
    ZstdSqlite3,
    /// zstd-compressed MCAP.
    ZstdMcap,
}

impl FileKind {
    /// How summaries name it (`capture.bag.kind`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Ros1 => "ROS 1 bag",
            Self::Sqlite3 => "rosbag2 sqlite3 file",
            Self::Mcap => "MCAP file",
            Self::ZstdSqlite3 => "rosbag2 sqlite3 file (zstd)",
            Self::ZstdMcap => "MCAP file (zstd)",
        }
    }
}

/// What a path holds, as far as bags go.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BagKind {
    /// One storage file.
    File(FileKind),
    /// A rosbag2 directory; the path of its `metadata.yaml`.
    Rosbag2(PathBuf),
}

fn head(path: &Path, n: usize) -> Result<Vec<u8>, BagError> {
    let mut f = File::open(path).map_err(|source| BagError::Open {
        path: path.to_path_buf(),
        source,
    })?;
    let mut buf = vec![0u8; n];
    let got = read_up_to(&mut f, &mut buf).map_err(|source| BagError::Io { offset: 0, source })?;
    buf.truncate(got);
    Ok(buf)
}

fn kind_of_bytes(b: &[u8]) -> Option<FileKind> {
    if b.starts_with(ros1::MAGIC) {
        Some(FileKind::Ros1)
    } else if b.starts_with(SQLITE_MAGIC) {
        Some(FileKind::Sqlite3)
    } else if b.starts_with(mcap_in::MAGIC) {
        Some(FileKind::Mcap)
    } else {
        None
    }
}

/// The kind of a storage file from its bytes (a zstd file by what it decompresses to).
pub fn file_kind(path: &Path) -> Result<Option<FileKind>, BagError> {
    let b = head(path, 16)?;
    if let Some(k) = kind_of_bytes(&b) {
        return Ok(Some(k));
    }
    if b.starts_with(&ZSTD_MAGIC) {
        let f = File::open(path).map_err(|source| BagError::Open {
            path: path.to_path_buf(),
            source,
        })?;
        let Ok(mut d) = zstd::stream::read::Decoder::new(f) else {
            return Ok(None);
        };
        let mut inner = [0u8; 16];
        let n = read_up_to(&mut d, &mut inner).unwrap_or(0);
        return Ok(match kind_of_bytes(&inner[..n]) {
            Some(FileKind::Sqlite3) => Some(FileKind::ZstdSqlite3),
            Some(FileKind::Mcap) => Some(FileKind::ZstdMcap),
            _ => None,
        });
    }
    Ok(None)
}

/// For a file that starts with the zstd magic: what its first bytes decompress to, or why they
/// do not (for the error of a zstd file that is no bag storage file). `None`: not zstd.
pub fn zstd_start(path: &Path) -> Option<String> {
    if !head(path, 4).is_ok_and(|b| b.starts_with(&ZSTD_MAGIC)) {
        return None;
    }
    let mut inner = Vec::with_capacity(16);
    let read = File::open(path)
        .and_then(zstd::stream::read::Decoder::new)
        .and_then(|d| d.take(16).read_to_end(&mut inner));
    Some(match read {
        Err(e) => format!("it does not decompress ({e}; cut short or damaged)"),
        Ok(0) => "it decompresses to nothing".into(),
        Ok(_) => format!(
            "it decompresses to {}",
            inner
                .iter()
                .map(|x| format!("{x:02x}"))
                .collect::<Vec<_>>()
                .join(" ")
        ),
    })
}

/// What `path` is, if a bag: a directory with a rosbag2 `metadata.yaml`, that yaml itself, or a
/// storage file recognised by its magic number. `Ok(None)`: not a bag (a pcap, for instance).
pub fn detect(path: &Path) -> Result<Option<BagKind>, BagError> {
    if path.is_dir() {
        let yaml = path.join("metadata.yaml");
        return Ok(yaml.is_file().then_some(BagKind::Rosbag2(yaml)));
    }
    let b = head(path, 64)?;
    if String::from_utf8_lossy(&b)
        .trim_start()
        .starts_with("rosbag2_bagfile_information")
    {
        return Ok(Some(BagKind::Rosbag2(path.to_path_buf())));
    }
    Ok(file_kind(path)?.map(BagKind::File))
}

// ----- one storage file ------------------------------------------------------------------------

/// A temporary file removed when dropped (a decompressed `.db3.zstd`).
struct TempPath(PathBuf);

/// A storage file of a bag (its path) and its decompressed temporary copy.
type Decompressed = (PathBuf, TempPath);

impl Drop for TempPath {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

fn decompress_to_temp(path: &Path) -> Result<TempPath, BagError> {
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let open = |p: &Path, source| BagError::Open {
        path: p.to_path_buf(),
        source,
    };
    let name = format!(
        "ringscan-bag-{}-{}.db3",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    );
    let tmp = TempPath(std::env::temp_dir().join(name));
    let mut out = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp.0)
        .map_err(|e| open(&tmp.0, e))?;
    let f = File::open(path).map_err(|e| open(path, e))?;
    let cap = (f.metadata().map_err(|e| open(path, e))?.len())
        .saturating_mul(MAX_ZSTD_DB3_RATIO)
        .saturating_add(ZSTD_DB3_SLACK_BYTES);
    let d = zstd::stream::read::Decoder::new(f).map_err(|e| open(path, e))?;
    let written = io::copy(&mut d.take(cap.saturating_add(1)), &mut out).map_err(|source| {
        BagError::Corrupt {
            offset: 0,
            reason: format!("zstd-compressed file does not decompress: {source}"),
        }
    })?;
    if written > cap {
        return Err(BagError::Corrupt {
            offset: 0,
            reason: format!(
                "zstd-compressed sqlite3 file decompresses to more than {cap} bytes \
                 ({MAX_ZSTD_DB3_RATIO} × its size + {} MiB): refused as a zstd bomb; if it is \
                 genuine, decompress it with `zstd -d` and read the .db3",
                ZSTD_DB3_SLACK_BYTES >> 20
            ),
        });
    }
    Ok(tmp)
}

type BoxRead = Box<dyn Read>;

/// One storage file being read.
enum Inner {
    Ros1(Box<Ros1Reader<BufReader<File>>>),
    Sqlite(Box<SqliteReader>, #[allow(dead_code)] Option<TempPath>), // the file lives as long as its reader
    Mcap(Box<McapReader<BoxRead>>),
}

impl Inner {
    /// Opens a storage file; a zstd-compressed sqlite3 file uses `decompressed` when it is
    /// that file's copy (decompressed by the pre-scan), else is decompressed again.
    fn open(
        path: &Path,
        kind: FileKind,
        decompressed: &mut Option<Decompressed>,
    ) -> Result<Self, BagError> {
        let open = |source| BagError::Open {
            path: path.to_path_buf(),
            source,
        };
        Ok(match kind {
            FileKind::Ros1 => {
                let mut f = BufReader::with_capacity(1 << 16, File::open(path).map_err(open)?);
                let r = Ros1Reader::new(&mut f)?;
                let (index_pos, at) = (r.index_pos(), r.offset());
                drop(r);
                let conns = ros1::read_index_connections(&mut f, index_pos).unwrap_or_default();
                // Re-read the (small) bag header through a reader that owns the file.
                use std::io::Seek;
                f.seek(io::SeekFrom::Start(0)).map_err(open)?;
                let mut r = Ros1Reader::new(f)?;
                debug_assert_eq!(r.offset(), at);
                r.add_connections(conns);
                Self::Ros1(Box::new(r))
            }
            FileKind::Sqlite3 => Self::Sqlite(Box::new(SqliteReader::open(path)?), None),
            FileKind::ZstdSqlite3 => {
                let tmp = match decompressed.take() {
                    Some((p, tmp)) if p == path => tmp,
                    other => {
                        *decompressed = other;
                        decompress_to_temp(path)?
                    }
                };
                Self::Sqlite(Box::new(SqliteReader::open(&tmp.0)?), Some(tmp))
            }
            FileKind::Mcap => {
                let f = BufReader::with_capacity(1 << 16, File::open(path).map_err(open)?);
                Self::Mcap(Box::new(McapReader::new(Box::new(f) as BoxRead)))
            }
            FileKind::ZstdMcap => {
                let f = File::open(path).map_err(open)?;
                let d = zstd::stream::read::Decoder::new(f).map_err(open)?;
                Self::Mcap(Box::new(McapReader::new(Box::new(d) as BoxRead)))
            }
        })
    }

    fn next_message(&mut self) -> Result<Option<RawMessage>, BagError> {
        match self {
            Self::Ros1(r) => r.next_message(),
            Self::Sqlite(r, _) => r.next_message(),
            Self::Mcap(r) => r.next_message(),
        }
    }

    fn message(&self) -> &[u8] {
        match self {
            Self::Ros1(r) => r.message(),
            Self::Sqlite(r, _) => r.message(),
            Self::Mcap(r) => r.message(),
        }
    }

    fn connection(&self, id: u64) -> Option<&Connection> {
        match self {
            Self::Ros1(r) => r.connection(id),
            Self::Sqlite(r, _) => r.connection(id),
            Self::Mcap(r) => r.connection(id),
        }
    }

    fn connection_count(&self) -> usize {
        match self {
            Self::Ros1(r) => r.connection_count(),
            Self::Sqlite(r, _) => r.connection_count(),
            Self::Mcap(r) => r.connection_count(),
        }
    }

    /// The connections from the `first`-th on (in the order [`Self::connection_count`] counts).
    fn connections_from(&self, first: usize) -> Vec<(u64, Connection)> {
        match self {
            Self::Ros1(r) => r.connections_from(first),
            Self::Sqlite(r, _) => r.connections_from(first),
            Self::Mcap(r) => r.connections_from(first),
        }
    }

    fn position(&self) -> u64 {
        match self {
            Self::Ros1(r) => r.offset(),
            Self::Sqlite(r, _) => r.bytes,
            Self::Mcap(r) => r.offset(),
        }
    }

    /// (truncated at, bad chunks, first bad chunk, oversized messages)
    fn damage(&self) -> (Option<u64>, u64, Option<u64>, u64) {
        match self {
            Self::Ros1(r) => (r.truncated_at, r.bad_chunks, r.first_bad_chunk, 0),
            Self::Sqlite(r, _) => (None, 0, None, r.oversized),
            Self::Mcap(r) => (r.truncated_at, 0, None, r.oversized),
        }
    }
}

// ----- the files of a bag ----------------------------------------------------------------------

/// Damage found while reading (summed over files).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
struct Damage {
    truncated: Option<(PathBuf, u64)>,
    bad_chunks: u64,
    first_bad_chunk: Option<(PathBuf, u64)>,
    oversized: u64,
    bad_compressed: u64,
}

/// Messages of all the files of a bag, with connection ids made global (one per topic name and
/// type across files).
struct Messages {
    files: VecDeque<(PathBuf, FileKind)>,
    current: Option<(PathBuf, Inner)>,
    message_zstd: bool,
    conns: Vec<Connection>,
    by_name: HashMap<(String, String), u64>,
    local: HashMap<u64, u64>,
    /// The global ids of the Livox `CustomMsg` connections, by topic.
    custom_msgs: HashMap<String, u64>,
    /// How many of the current file's connections have been looked at for `custom_msgs`.
    scanned: usize,
    /// Serialization formats from `metadata.yaml`, by topic (for storage that lacks them).
    formats: HashMap<String, Option<Encoding>>,
    done_bytes: u64,
    damage: Damage,
    /// A zstd-compressed message (rosbag2 MESSAGE compression), decompressed.
    raw: Vec<u8>,
    /// The message last returned is `raw`.
    inflated: bool,
    /// A zstd-compressed sqlite3 file of the bag decompressed already (by the pre-scan).
    decompressed: Option<Decompressed>,
}

impl Messages {
    fn open(
        path: &Path,
        kind: &BagKind,
        decompressed: Option<Decompressed>,
    ) -> Result<Self, BagError> {
        let mut m = Self {
            files: VecDeque::new(),
            current: None,
            message_zstd: false,
            conns: Vec::new(),
            by_name: HashMap::new(),
            local: HashMap::new(),
            custom_msgs: HashMap::new(),
            scanned: 0,
            formats: HashMap::new(),
            done_bytes: 0,
            damage: Damage::default(),
            raw: Vec::new(),
            inflated: false,
            decompressed,
        };
        match kind {
            BagKind::File(k) => m.files.push_back((path.to_path_buf(), *k)),
            BagKind::Rosbag2(yaml) => {
                let text = std::fs::read_to_string(yaml).map_err(|source| BagError::Open {
                    path: yaml.clone(),
                    source,
                })?;
                let meta = Metadata::parse(&text).map_err(|reason| BagError::Metadata {
                    path: yaml.clone(),
                    reason,
                })?;
                let dir = yaml.parent().unwrap_or(Path::new("."));
                m.message_zstd = meta.compression == Compression::Message;
                for (name, ty, fmt) in &meta.topics {
                    let enc = rosbag2::encoding_of(fmt);
                    m.formats.insert(name.clone(), enc);
                    m.global(Connection {
                        topic: name.clone(),
                        type_name: ty.clone(),
                        encoding: enc,
                    })
                    .map_err(|_| BagError::Metadata {
                        path: yaml.clone(),
                        reason: format!("more than {MAX_CONNECTIONS} topics"),
                    })?;
                }
                let files: Vec<String> = if meta.files.is_empty() {
                    // No list: every storage file of the directory, by name.
                    let mut v: Vec<String> = std::fs::read_dir(dir)
                        .map(|rd| {
                            rd.filter_map(|e| e.ok())
                                .map(|e| e.file_name().to_string_lossy().into_owned())
                                .filter(|n| {
                                    n.ends_with(".db3")
                                        || n.ends_with(".mcap")
                                        || n.ends_with(".zstd")
                                })
                                .collect()
                        })
                        .unwrap_or_default();
                    v.sort();
                    v
                } else {
                    meta.files.clone()
                };
                for f in files {
                    let p = dir.join(&f);
                    let k = file_kind(&p)?.ok_or_else(|| BagError::Metadata {
                        path: yaml.clone(),
                        reason: match zstd_start(&p) {
                            Some(why) => format!(
                                "{f}: zstd-compressed, but its start does not decompress to \
                                 sqlite3 or MCAP: {why}"
                            ),
                            None => {
                                format!(
                                    "{f}: neither sqlite3 nor MCAP ({:?} storage)",
                                    meta.storage
                                )
                            }
                        },
                    })?;
                    // A file whose kind differs from the yaml's storage identifier is read by
                    // its bytes, like every input.
                    m.files.push_back((p, k));
                }
            }
        }
        m.next_file()?;
        Ok(m)
    }

    /// What the storage has told of connections so far: it changes when a connection or a
    /// file is added, so a question about them need not be asked again before.
    fn connections_seen(&self) -> (usize, usize) {
        let inner = self
            .current
            .as_ref()
            .map_or(0, |(_, i)| i.connection_count());
        (self.conns.len(), inner)
    }

    /// The global id of a Livox `CustomMsg` connection of `topic` that the storage has told
    /// of, whether or not a message of it has been read yet (the current file's connection
    /// records so far: all of an indexed ROS 1 bag's, sqlite3's topics table, the MCAP
    /// channels read). It is asked again at every new connection while an IMU topic waits for
    /// its `CustomMsg` topic, so each connection is looked at once, not at every asking.
    fn custom_msg_connection(&mut self, topic: &str) -> Option<u64> {
        if let Some(&g) = self.custom_msgs.get(topic) {
            return Some(g);
        }
        let (_, inner) = self.current.as_ref()?;
        let new = inner.connections_from(self.scanned);
        self.scanned += new.len();
        for (id, c) in new {
            if MsgKind::from_type_name(&c.type_name) == Some(MsgKind::LivoxCustomMsg) {
                let g = self.localize(c).ok()?;
                self.local.insert(id, g);
            }
        }
        self.custom_msgs.get(topic).copied()
    }

    /// The global id of a connection (by topic name and type); an error past
    /// [`MAX_CONNECTIONS`] of them.
    fn global(&mut self, c: Connection) -> Result<u64, BagError> {
        let key = (c.topic.clone(), c.type_name.clone());
        if let Some(&g) = self.by_name.get(&key) {
            return Ok(g);
        }
        if self.conns.len() >= MAX_CONNECTIONS {
            return Err(BagError::Corrupt {
                offset: self.position(),
                reason: format!("more than {MAX_CONNECTIONS} topics (by name and type)"),
            });
        }
        let g = self.conns.len() as u64;
        if MsgKind::from_type_name(&c.type_name) == Some(MsgKind::LivoxCustomMsg) {
            self.custom_msgs.insert(c.topic.clone(), g);
        }
        self.conns.push(c);
        self.by_name.insert(key, g);
        Ok(g)
    }

    /// The decompressed copy of the current file, if it is a zstd-compressed sqlite3 file.
    fn into_decompressed(mut self) -> Option<Decompressed> {
        match self.current.take()? {
            (path, Inner::Sqlite(reader, Some(tmp))) => {
                drop(reader);
                Some((path, tmp))
            }
            _ => None,
        }
    }

    fn next_file(&mut self) -> Result<bool, BagError> {
        if let Some((path, inner)) = self.current.take() {
            self.done_bytes += inner.position();
            self.note_damage(&path, &inner);
        }
        let Some((path, kind)) = self.files.pop_front() else {
            return Ok(false);
        };
        let inner =
            Inner::open(&path, kind, &mut self.decompressed).map_err(|e| in_file(&path, e))?;
        // A copy the pre-scan made of another file than the first is not kept waiting.
        self.decompressed = None;
        self.local.clear();
        for (id, c) in inner.connections_from(0) {
            let g = self.localize(c).map_err(|e| in_file(&path, e))?;
            self.local.insert(id, g);
        }
        self.scanned = inner.connection_count();
        self.current = Some((path, inner));
        Ok(true)
    }

    /// A file's connection with the yaml's serialization format where the file has none.
    fn localize(&mut self, mut c: Connection) -> Result<u64, BagError> {
        if let Some(enc) = self.formats.get(&c.topic) {
            if c.encoding.is_none() {
                c.encoding = *enc;
            }
        }
        self.global(c)
    }

    fn note_damage(&mut self, path: &Path, inner: &Inner) {
        let (t, bad, first_bad, oversized) = inner.damage();
        if let Some(t) = t {
            self.damage.truncated.get_or_insert((path.to_path_buf(), t));
        }
        self.damage.bad_chunks += bad;
        if let Some(b) = first_bad {
            self.damage
                .first_bad_chunk
                .get_or_insert((path.to_path_buf(), b));
        }
        self.damage.oversized += oversized;
    }

    fn position(&self) -> u64 {
        self.done_bytes + self.current.as_ref().map_or(0, |(_, i)| i.position())
    }

    fn damage(&self) -> Damage {
        let mut d = self.damage.clone();
        if let Some((path, inner)) = &self.current {
            let (t, bad, first_bad, oversized) = inner.damage();
            if let Some(t) = t {
                d.truncated.get_or_insert((path.clone(), t));
            }
            d.bad_chunks += bad;
            if let Some(b) = first_bad {
                d.first_bad_chunk.get_or_insert((path.clone(), b));
            }
            d.oversized += oversized;
        }
        d
    }

    fn connection(&self, g: u64) -> Option<&Connection> {
        self.conns.get(usize::try_from(g).ok()?)
    }

    fn in_current(&self, e: BagError) -> BagError {
        match &self.current {
            Some((path, _)) => in_file(path, e),
            None => e,
        }
    }

    /// The bytes of the message last returned by [`Self::next_message`].
    fn message(&self) -> &[u8] {
        match &self.current {
            _ if self.inflated => &self.raw,
            Some((_, inner)) => inner.message(),
            None => &[],
        }
    }

    /// The next message (global connection id; its bytes are [`Self::message`]).
    fn next_message(&mut self) -> Result<Option<RawMessage>, BagError> {
        loop {
            self.inflated = false;
            let Some((path, inner)) = self.current.as_mut() else {
                return Ok(None);
            };
            let m = match inner.next_message() {
                Ok(Some(m)) => m,
                Ok(None) => {
                    if self.next_file()? {
                        continue;
                    }
                    return Ok(None);
                }
                Err(e) => {
                    let e = in_file(path, e);
                    return Err(e);
                }
            };
            let g = match self.local.get(&m.conn) {
                Some(&g) => g,
                None => {
                    let Some(c) = inner.connection(m.conn).cloned() else {
                        // A message before (or without) its connection record: unknown topic.
                        // One placeholder for them all, not remembered by id: ids are as many
                        // as a file names (ROS 1's are u32).
                        let placeholder = Connection {
                            topic: "<no connection record>".into(),
                            type_name: String::new(),
                            encoding: None,
                        };
                        let g = self.global(placeholder).map_err(|e| self.in_current(e))?;
                        return Ok(Some(RawMessage {
                            conn: g,
                            time_ns: m.time_ns,
                        }));
                    };
                    let g = self.localize(c).map_err(|e| self.in_current(e))?;
                    self.local.insert(m.conn, g);
                    g
                }
            };
            // rosbag2 MESSAGE compression; also recognised without its yaml (a bare .db3 or
            // .mcap) by the zstd magic where CDR's encapsulation header belongs.
            let cdr = self.conns.get(g as usize).and_then(|c| c.encoding) == Some(Encoding::Cdr);
            let out = self.current.as_ref().map_or(&[][..], |(_, i)| i.message());
            if self.message_zstd || (cdr && out.starts_with(&ZSTD_MAGIC)) {
                self.raw.clear();
                let ok = zstd::stream::read::Decoder::with_buffer(out)
                    .and_then(|d| {
                        d.take(MAX_MESSAGE_BYTES as u64 + 1)
                            .read_to_end(&mut self.raw)
                    })
                    .is_ok_and(|n| n <= MAX_MESSAGE_BYTES);
                if !ok {
                    self.damage.bad_compressed += 1;
                    continue;
                }
                self.inflated = true;
            }
            return Ok(Some(RawMessage {
                conn: g,
                time_ns: m.time_ns,
            }));
        }
    }
}

fn in_file(path: &Path, e: BagError) -> BagError {
    match e {
        e @ (BagError::Open { .. } | BagError::Sqlite { .. } | BagError::InFile { .. }) => e,
        e => BagError::InFile {
            path: path.to_path_buf(),
            source: Box::new(e),
        },
    }
}

// ----- the source ------------------------------------------------------------------------------

/// A time bound of [`BagOptions`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TimeBound {
    /// Seconds after the bag's first message.
    Relative(f64),
    /// ns since the Unix epoch.
    Absolute(i64),
}

impl TimeBound {
    /// A bound given in seconds: below 10⁹ relative to the bag's start, else absolute.
    pub fn from_seconds(s: f64) -> Self {
        if s >= 1e9 {
            Self::Absolute((s * 1e9).round() as i64)
        } else {
            Self::Relative(s)
        }
    }

    fn ns(self, first_ns: i64) -> i64 {
        match self {
            Self::Absolute(ns) => ns,
            Self::Relative(s) => first_ns.saturating_add((s * 1e9).round() as i64),
        }
    }
}

/// What to read of a bag.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BagOptions {
    /// Topics to read (all packet topics when empty). Ouster metadata is read whatever this says.
    pub topics: Vec<String>,
    /// Messages recorded before this are skipped.
    pub start: Option<TimeBound>,
    /// Messages recorded after this are skipped.
    pub end: Option<TimeBound>,
}

/// A sensor family, as the bag's message types tell it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Family {
    /// Velodyne.
    Velodyne,
    /// Ouster.
    Ouster,
    /// Hesai.
    Hesai,
    /// Robosense.
    Robosense,
    /// Livox (`CustomMsg` points).
    Livox,
    /// Not known (nebula packets whose first packet says nothing).
    Unknown,
}

impl Family {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Velodyne => "velodyne",
            Self::Ouster => "ouster",
            Self::Hesai => "hesai",
            Self::Robosense => "robosense",
            Self::Livox => "livox",
            Self::Unknown => "unknown",
        }
    }
}

/// One sensor of a bag and the synthetic address its packets come from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BagSensor {
    /// Topic namespace (Ouster) or topic (the others).
    pub namespace: String,
    /// Family.
    pub family: Family,
    /// Synthetic source address, 127.0.0.N.
    pub address: Ipv4Addr,
    /// Destination port of its main packets (lidar / MSOP / data).
    pub data_port: u16,
    /// Destination port of its other packets (Ouster IMU, Robosense DIFOP).
    pub aux_port: u16,
    /// Packet topics read for it.
    pub topics: Vec<String>,
    /// Ouster metadata JSON found in the bag (its `<ns>/metadata` topic).
    pub metadata: Option<String>,
}

/// What a [`BagSource`] saw so far.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BagStats {
    /// Messages read (every topic).
    pub messages: u64,
    /// Messages whose packets were returned.
    pub packet_messages: u64,
    /// Datagrams returned.
    pub datagrams: u64,
    /// Ouster metadata messages read.
    pub metadata_messages: u64,
    /// Ouster metadata messages of a namespace without one, not kept: past
    /// [`MAX_METADATA_BYTES`].
    pub metadata_dropped: u64,
    /// Messages of topics not selected (`--topic`).
    pub unselected: u64,
    /// Messages recorded outside `--start` / `--end`.
    pub outside_time: u64,
    /// Messages of types (or serializations) ringscan does not read.
    pub unknown_type: u64,
    /// Messages that did not parse as their type: skipped.
    pub malformed: u64,
    /// The first malformed message: topic and why.
    pub first_malformed: Option<String>,
    /// Messages larger than [`MAX_MESSAGE_BYTES`]: skipped.
    pub oversized: u64,
    /// Compressed messages (rosbag2 `MESSAGE` mode) that did not decompress: skipped.
    pub bad_compressed_messages: u64,
    /// ROS 1 chunks that did not decompress or whose records were inconsistent: skipped.
    pub bad_chunks: u64,
    /// File and byte offset of the first skipped chunk.
    pub first_bad_chunk: Option<(PathBuf, u64)>,
    /// Packets of sensors beyond [`MAX_SENSORS`]: dropped.
    pub sensor_limit: u64,
    /// Storage bytes consumed (for progress).
    pub bytes: u64,
    /// Where a file cut short ended the stream: the file and its byte offset.
    pub truncated_at: Option<(PathBuf, u64)>,
    /// Time of the first datagram returned, ns since the Unix epoch.
    pub first_time_ns: Option<i64>,
    /// Time of the last datagram returned.
    pub last_time_ns: Option<i64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    /// Packets of a sensor: its data port, or its aux port for difop / IMU packets.
    Packets {
        sensor: usize,
        imu: bool,
    },
    /// Ouster metadata of a namespace.
    Metadata,
    /// A `sensor_msgs/Imu` topic whose Livox `CustomMsg` topic has not been seen (yet): not
    /// read, and asked again once the sensors or the connections known have changed since
    /// `seen` (sensor count, [`Messages::connections_seen`]).
    Unpaired {
        seen: (usize, (usize, usize)),
    },
    Unselected,
    Unknown,
    /// Over the sensor limit.
    Dropped,
    /// `ringscan.RawPacket`: each message is one datagram with its own addresses, of no
    /// sensor of the bag's.
    Raw,
}

#[derive(Debug, Clone, Copy)]
struct Route {
    kind: Option<MsgKind>,
    encoding: Encoding,
    role: Role,
}

/// Ouster metadata texts by namespace, the first of each, at most [`MAX_METADATA_BYTES`].
#[derive(Default)]
struct MetadataTexts {
    by_ns: HashMap<String, String>,
    bytes: usize,
}

impl MetadataTexts {
    /// Keeps `text` for `ns` if none is kept for it; false when it is not kept for want of room.
    fn keep(&mut self, ns: &str, text: &[u8]) -> bool {
        if self.by_ns.contains_key(ns) {
            return true;
        }
        let text = String::from_utf8_lossy(text);
        if self.bytes + text.len() > MAX_METADATA_BYTES {
            return false;
        }
        self.bytes += text.len();
        self.by_ns.insert(ns.to_string(), text.into_owned());
        true
    }
}

/// UDP datagrams from a ROS bag. See the [module documentation](self).
///
/// ```no_run
/// # fn main() -> Result<(), ringscan::source::bag::BagError> {
/// use ringscan::source::bag::{BagOptions, BagSource};
/// let mut source = BagSource::open("drive.bag".as_ref(), BagOptions::default())?;
/// for s in source.sensors() {
///     println!("{} ({}) from {}", s.namespace, s.family.name(), s.address);
/// }
/// while let Some(d) = source.next_datagram()? {
///     println!("{} bytes from {} to port {}", d.payload.len(), d.src, d.dst.port());
/// }
/// # Ok(()) }
/// ```
pub struct BagSource {
    kind: BagKind,
    messages: Messages,
    options: BagOptions,
    routes: HashMap<u64, Route>,
    sensors: Vec<BagSensor>,
    /// Ouster metadata by namespace (from the pre-scan and the stream).
    metadata: MetadataTexts,
    /// The MCAP attachments ([`Self::attachments`]).
    attachments: Vec<(String, Vec<u8>)>,
    packets: Vec<PacketRef>,
    /// The points frame of the current message when it is a Livox `CustomMsg` (or the IMU
    /// frame of a `sensor_msgs/Imu`): its one "packet" is this, not a range of the message.
    frame: Vec<u8>,
    /// Per sensor (by index): the factor from its `Imu` messages' acceleration to m/s², once
    /// its first sample has told the unit.
    imu_accel_scale: Vec<Option<f64>>,
    frame_current: bool,
    /// The source and destination port of the current message when it is a
    /// `ringscan.RawPacket`, which carries its own.
    raw_current: Option<(SocketAddrV4, u16)>,
    cursor: usize,
    current: (usize, i64, bool),
    first_message_ns: Option<i64>,
    bounds: Option<(i64, i64)>,
    stats: BagStats,
}

/// The Livox `CustomMsg` topic an IMU topic belongs to: its last segment's leading `imu`
/// replaced by `lidar` (the drivers' `/livox/imu[_<id>]` beside `/livox/lidar[_<id>]`).
fn livox_lidar_topic(imu_topic: &str) -> Option<String> {
    let (ns, leaf) = imu_topic.rsplit_once('/').unwrap_or(("", imu_topic));
    let rest = leaf.strip_prefix("imu")?;
    Some(format!("{ns}/lidar{rest}"))
}

/// The factor from a Livox driver's `Imu` acceleration to m/s², told by its first sample:
/// the drivers publish g (the sensor's unit) where `sensor_msgs/Imu` says m/s². Below
/// √g₀ ≈ 3.13 in magnitude it is g (at rest: 1), else m/s² (at rest: 9.8).
fn accel_scale(a: [f64; 3]) -> f64 {
    let g0 = crate::sensor::livox::model::STANDARD_GRAVITY;
    let norm = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    if norm < g0.sqrt() {
        g0
    } else {
        1.0
    }
}

/// The namespace of a topic (`/a/b/lidar_packets` → `/a/b`; `/lidar_packets` → `/`).
fn namespace(topic: &str) -> &str {
    match topic.rfind('/') {
        Some(0) | None => "/",
        Some(i) => &topic[..i],
    }
}

/// The udp_port_lidar / udp_port_imu of Ouster metadata JSON (flat or nested layout).
fn ouster_ports(json: &str) -> (Option<u16>, Option<u16>) {
    let Ok(v) = serde_json::from_str::<serde_json::Value>(json) else {
        return (None, None);
    };
    let port = |key: &str| {
        [&v[key], &v["config_params"][key]]
            .into_iter()
            .find_map(|x| x.as_u64())
            .and_then(|p| u16::try_from(p).ok())
            .filter(|&p| p != 0)
    };
    (port("udp_port_lidar"), port("udp_port_imu"))
}

/// Nebula packets: a family (and its data / aux ports) from a packet's bytes.
fn sniff(payload: &[u8]) -> Option<(Family, u16, u16)> {
    match payload {
        p if p.len() == 1206 => Some((Family::Velodyne, 2368, 2368)),
        [0xee, 0xff, ..] | [0xff, 0xee, ..] => Some((Family::Hesai, 2368, 2368)),
        [0x55, 0xaa, ..] | [0xa5, 0xff, ..] => Some((Family::Robosense, 6699, 7788)),
        _ => None,
    }
}

impl BagSource {
    /// Opens a bag of any kind ([`detect`]), looks for Ouster metadata, and lists the topics
    /// known up front.
    pub fn open(path: &Path, options: BagOptions) -> Result<Self, BagError> {
        let kind = detect(path)?.ok_or_else(|| {
            let found = head(path, 16).unwrap_or_default();
            BagError::NotABag { found }
        })?;
        let (metadata, decompressed) = prescan_metadata(path, &kind)?;
        let attachments = mcap_attachments(path, &kind);
        let messages = Messages::open(path, &kind, decompressed)?;
        let mut s = Self {
            kind,
            messages,
            options,
            routes: HashMap::new(),
            sensors: Vec::new(),
            metadata,
            attachments,
            packets: Vec::new(),
            frame: Vec::new(),
            frame_current: false,
            raw_current: None,
            imu_accel_scale: Vec::new(),
            cursor: 0,
            current: (0, 0, false),
            first_message_ns: None,
            bounds: None,
            stats: BagStats::default(),
        };
        for g in 0..s.messages.conns.len() as u64 {
            s.route(g);
        }
        Ok(s)
    }

    /// What the path is.
    pub fn kind(&self) -> &BagKind {
        &self.kind
    }

    /// The MCAP attachments (name, bytes) of the bag's first MCAP file that has any, each of
    /// at most [`MAX_CALIB_BYTES`](crate::sensor::MAX_CALIB_BYTES): the calibration files of a
    /// bag ringscan wrote.
    pub fn attachments(&self) -> &[(String, Vec<u8>)] {
        &self.attachments
    }

    /// The topics of point clouds (`foxglove.PointCloud`, `sensor_msgs/PointCloud2`) among
    /// the connections seen so far, sorted: what a bag of decoded points, not packets, holds
    /// (an MCAP ringscan wrote without `--raw`).
    pub fn point_cloud_topics(&self) -> Vec<String> {
        let mut t: Vec<String> = (self.messages.conns.iter())
            .filter(|c| {
                matches!(
                    c.type_name.trim(),
                    "foxglove.PointCloud"
                        | "sensor_msgs/msg/PointCloud2"
                        | "sensor_msgs/PointCloud2"
                )
            })
            .map(|c| c.topic.clone())
            .collect();
        t.sort();
        t.dedup();
        t
    }

    /// When `--topic` ([`BagOptions::topics`]) names none of the packet topics seen so far:
    /// what it named and those topics, sorted (say, a mistyped name).
    pub fn topics_missed(&self) -> Option<(Vec<String>, Vec<String>)> {
        let given = &self.options.topics;
        let mut known: Vec<String> = (self.messages.conns.iter())
            .filter(|c| {
                MsgKind::from_type_name(&c.type_name)
                    .is_some_and(|k| !matches!(k, MsgKind::StdString | MsgKind::Imu))
            })
            .map(|c| c.topic.clone())
            .collect();
        known.sort();
        known.dedup();
        if given.is_empty() || given.iter().any(|t| known.contains(t)) {
            return None;
        }
        Some((given.clone(), known))
    }

    /// The topics `--topic` selects (empty: all).
    pub fn topics_given(&self) -> &[String] {
        &self.options.topics
    }

    /// The topics of `--topic` that are none of the bag's (of any type), when another one is
    /// a packet topic of the bag (else [`Self::topics_missed`] tells it).
    pub fn topics_unknown(&self) -> Vec<String> {
        if self.topics_missed().is_some() {
            return Vec::new();
        }
        (self.options.topics.iter())
            .filter(|t| !self.messages.conns.iter().any(|c| &c.topic == *t))
            .cloned()
            .collect()
    }

    /// The sensors known so far, in address order.
    pub fn sensors(&self) -> &[BagSensor] {
        &self.sensors
    }

    /// Counters so far.
    pub fn stats(&self) -> BagStats {
        let mut s = self.stats.clone();
        let d = self.messages.damage();
        s.bytes = self.messages.position();
        s.truncated_at = d.truncated;
        s.bad_chunks = d.bad_chunks;
        s.first_bad_chunk = d.first_bad_chunk;
        s.oversized = d.oversized;
        s.bad_compressed_messages = d.bad_compressed;
        s
    }

    /// The route of a (global) connection, made on first sight: this is where sensors get
    /// their addresses.
    fn route(&mut self, g: u64) -> Route {
        if let Some(r) = self.routes.get(&g) {
            match r.role {
                Role::Unpaired { seen } if seen != self.pairing_state() => {}
                _ => return *r,
            }
        }
        let conn = self.messages.connection(g).cloned();
        let route = match conn {
            None => Route {
                kind: None,
                encoding: Encoding::Cdr,
                role: Role::Unknown,
            },
            Some(c) => self.new_route(&c),
        };
        self.routes.insert(g, route);
        route
    }

    /// What an unpaired `Imu` topic's answer depends on.
    fn pairing_state(&self) -> (usize, (usize, usize)) {
        (self.sensors.len(), self.messages.connections_seen())
    }

    fn new_route(&mut self, c: &Connection) -> Route {
        let kind = MsgKind::from_type_name(&c.type_name);
        let (Some(kind), Some(encoding)) = (kind, c.encoding) else {
            return Route {
                kind: None,
                encoding: Encoding::Cdr,
                role: Role::Unknown,
            };
        };
        let unknown = Route {
            kind: None,
            encoding,
            role: Role::Unknown,
        };
        if !kind.serialized_as(encoding) {
            return unknown;
        }
        if kind == MsgKind::StdString {
            return if c.topic.ends_with("/metadata") {
                Route {
                    kind: Some(kind),
                    encoding,
                    role: Role::Metadata,
                }
            } else {
                unknown
            };
        }
        if !self.options.topics.is_empty() && !self.options.topics.contains(&c.topic) {
            return Route {
                kind: Some(kind),
                encoding,
                role: Role::Unselected,
            };
        }
        if kind == MsgKind::RawPacket {
            return Route {
                kind: Some(kind),
                encoding,
                role: Role::Raw,
            };
        }
        if kind == MsgKind::Imu {
            let lidar = livox_lidar_topic(&c.topic).unwrap_or_default();
            let find = |me: &Self| {
                me.sensors
                    .iter()
                    .position(|s| s.family == Family::Livox && s.namespace == lidar)
            };
            if find(self).is_none() {
                // The CustomMsg topic may be known before its first message (a ROS 1 index,
                // the sqlite3 topics table): its sensor is made now, so the IMU samples that
                // come first (the drivers publish a frame only once it is complete) are kept.
                if let Some(g) = self.messages.custom_msg_connection(&lidar) {
                    self.route(g);
                }
            }
            let Some(sensor) = find(self) else {
                return Route {
                    kind: Some(kind),
                    encoding,
                    role: Role::Unpaired {
                        seen: self.pairing_state(),
                    },
                };
            };
            self.sensors[sensor].topics.push(c.topic.clone());
            return Route {
                kind: Some(kind),
                encoding,
                role: Role::Packets { sensor, imu: true },
            };
        }
        let (key, family) = match kind {
            MsgKind::OusterPacket => (namespace(&c.topic).to_string(), Family::Ouster),
            MsgKind::VelodyneScan => (c.topic.clone(), Family::Velodyne),
            MsgKind::PandarScan | MsgKind::HesaiUdpFrame => (c.topic.clone(), Family::Hesai),
            MsgKind::RobosenseScan | MsgKind::RslidarPacket => (c.topic.clone(), Family::Robosense),
            MsgKind::LivoxCustomMsg => (c.topic.clone(), Family::Livox),
            _ => (c.topic.clone(), Family::Unknown),
        };
        let imu = kind == MsgKind::OusterPacket
            && c.topic
                .rsplit('/')
                .next()
                .is_some_and(|l| l.contains("imu"));
        let sensor = match self.sensors.iter().position(|s| s.namespace == key) {
            Some(i) => i,
            None => {
                if self.sensors.len() >= MAX_SENSORS {
                    return Route {
                        kind: Some(kind),
                        encoding,
                        role: Role::Dropped,
                    };
                }
                let n = self.sensors.len() as u8 + 1;
                let mut s = BagSensor {
                    namespace: key.clone(),
                    family,
                    address: Ipv4Addr::new(127, 0, 0, n),
                    data_port: 2368,
                    aux_port: 2368,
                    topics: Vec::new(),
                    metadata: None,
                };
                match family {
                    Family::Ouster => {
                        s.data_port = 7502;
                        s.aux_port = 7503;
                        if let Some(m) = self.metadata.by_ns.get(&key) {
                            let (l, i) = ouster_ports(m);
                            s.data_port = l.unwrap_or(7502);
                            s.aux_port = i.unwrap_or(7503);
                            s.metadata = Some(m.clone());
                        }
                    }
                    Family::Robosense => {
                        s.data_port = 6699;
                        s.aux_port = 7788;
                    }
                    Family::Livox => {
                        s.data_port = 56_301;
                        s.aux_port = 56_401;
                    }
                    _ => {}
                }
                self.sensors.push(s);
                self.sensors.len() - 1
            }
        };
        self.sensors[sensor].topics.push(c.topic.clone());
        Route {
            kind: Some(kind),
            encoding,
            role: Role::Packets { sensor, imu },
        }
    }

    /// The next datagram, `Ok(None)` at the end of the bag (or where it is cut short: see
    /// [`BagStats::truncated_at`]).
    pub fn next_datagram(&mut self) -> Result<Option<Datagram<'_>>, BagError> {
        while self.cursor >= self.packets.len() {
            if !self.next_packet_message()? {
                return Ok(None);
            }
        }
        let p = self.packets[self.cursor];
        self.cursor += 1;
        let (sensor, msg_time, imu) = self.current;
        let (src, port) = match self.raw_current {
            Some(addresses) => addresses,
            None => {
                if self.sensors[sensor].family == Family::Unknown {
                    let payload = (self.messages.message())
                        .get(p.start..p.start + p.len)
                        .unwrap_or(&[]);
                    if let Some((family, data, aux)) = sniff(payload) {
                        let s = &mut self.sensors[sensor];
                        (s.family, s.data_port, s.aux_port) = (family, data, aux);
                    }
                }
                let s = &self.sensors[sensor];
                let port = if imu || p.difop {
                    s.aux_port
                } else {
                    s.data_port
                };
                (SocketAddrV4::new(s.address, port), port)
            }
        };
        let time_ns = p.stamp_ns.unwrap_or(msg_time);
        self.stats.datagrams += 1;
        self.stats.first_time_ns.get_or_insert(time_ns);
        self.stats.last_time_ns = Some(time_ns);
        let bytes = if self.frame_current {
            &self.frame[..]
        } else {
            self.messages.message()
        };
        Ok(Some(Datagram {
            time_ns,
            src,
            dst: SocketAddrV4::new(Ipv4Addr::LOCALHOST, port),
            payload: bytes.get(p.start..p.start + p.len).unwrap_or(&[]),
        }))
    }

    /// Reads messages until one with packets; false at the end.
    fn next_packet_message(&mut self) -> Result<bool, BagError> {
        self.packets.clear();
        self.cursor = 0;
        loop {
            let Some(m) = self.messages.next_message()? else {
                return Ok(false);
            };
            self.stats.messages += 1;
            let first = *self.first_message_ns.get_or_insert(m.time_ns);
            let route = self.route(m.conn);
            let (start, end) = *self.bounds.get_or_insert_with(|| {
                (
                    self.options.start.map_or(i64::MIN, |b| b.ns(first)),
                    self.options.end.map_or(i64::MAX, |b| b.ns(first)),
                )
            });
            match route.role {
                Role::Unknown | Role::Unpaired { .. } => self.stats.unknown_type += 1,
                Role::Unselected => self.stats.unselected += 1,
                Role::Metadata => {
                    self.stats.metadata_messages += 1;
                    let msg = self.messages.message();
                    if let Ok((a, n)) = messages::string(route.encoding, msg) {
                        let ns =
                            (self.messages.connection(m.conn)).map_or("", |c| namespace(&c.topic));
                        if !self.metadata.keep(ns, &msg[a..a + n]) {
                            self.stats.metadata_dropped += 1;
                        }
                    }
                }
                Role::Dropped => self.stats.sensor_limit += 1,
                Role::Packets { .. } | Role::Raw if m.time_ns < start || m.time_ns > end => {
                    self.stats.outside_time += 1;
                }
                Role::Raw => match messages::raw_packet(route.encoding, self.messages.message()) {
                    Ok(r) => {
                        self.stats.packet_messages += 1;
                        self.packets.push(r.packet);
                        self.raw_current = Some((r.source, r.destination_port));
                        self.frame_current = false;
                        self.current = (0, m.time_ns, false);
                        return Ok(true);
                    }
                    Err(e) => self.count_malformed(m, MsgKind::RawPacket, e),
                },
                Role::Packets { sensor, imu } => {
                    let kind = route.kind.unwrap_or(MsgKind::StdString);
                    let msg = self.messages.message();
                    self.raw_current = None;
                    self.frame_current = matches!(kind, MsgKind::LivoxCustomMsg | MsgKind::Imu);
                    let stamp = match kind {
                        MsgKind::LivoxCustomMsg => {
                            messages::livox_custom(route.encoding, msg, &mut self.frame).map(Some)
                        }
                        MsgKind::Imu => messages::imu(route.encoding, msg).map(|m| {
                            if self.imu_accel_scale.len() <= sensor {
                                self.imu_accel_scale.resize(sensor + 1, None);
                            }
                            let scale = *self.imu_accel_scale[sensor]
                                .get_or_insert_with(|| accel_scale(m.linear_acceleration));
                            frame::write_imu(
                                &mut self.frame,
                                u64::try_from(m.stamp_ns).unwrap_or(0),
                                m.angular_velocity,
                                m.linear_acceleration.map(|a| a * scale),
                            );
                            Some(m.stamp_ns)
                        }),
                        _ => messages::packets(kind, route.encoding, msg, &mut self.packets)
                            .map(|()| None),
                    };
                    let read = stamp.map(|stamp| {
                        if let Some(stamp) = stamp {
                            self.packets.push(PacketRef {
                                start: 0,
                                len: self.frame.len(),
                                stamp_ns: Some(stamp),
                                difop: false,
                            });
                        }
                    });
                    match read {
                        Ok(()) => {
                            self.stats.packet_messages += 1;
                            self.current = (sensor, m.time_ns, imu);
                            if !self.packets.is_empty() {
                                return Ok(true);
                            }
                        }
                        Err(e) => self.count_malformed(m, kind, e),
                    }
                }
            }
        }
    }

    /// Counts a message that does not parse as its type; the first one is described.
    fn count_malformed(&mut self, m: RawMessage, kind: MsgKind, e: messages::MsgError) {
        self.stats.malformed += 1;
        if self.stats.first_malformed.is_none() {
            let topic = self
                .messages
                .connection(m.conn)
                .map(|c| c.topic.clone())
                .unwrap_or_default();
            self.stats.first_malformed = Some(format!("{topic} ({kind}) at {} ns: {e}", m.time_ns));
        }
    }
}

/// The attachments of the first of a bag's MCAP files (at most four looked at) that has any;
/// none for other storage or a zstd-compressed file.
fn mcap_attachments(path: &Path, kind: &BagKind) -> Vec<(String, Vec<u8>)> {
    let files: Vec<PathBuf> = match kind {
        BagKind::File(FileKind::Mcap) => vec![path.to_path_buf()],
        BagKind::Rosbag2(yaml) => {
            let meta = std::fs::read_to_string(yaml)
                .ok()
                .and_then(|t| Metadata::parse(&t).ok());
            let dir = yaml.parent().unwrap_or(Path::new("."));
            match meta {
                Some(m)
                    if m.storage == rosbag2::Storage::Mcap
                        && m.compression != Compression::File =>
                {
                    m.files.iter().map(|f| dir.join(f)).collect()
                }
                _ => Vec::new(),
            }
        }
        _ => Vec::new(),
    };
    files
        .iter()
        .take(4)
        .filter_map(|f| File::open(f).ok())
        .map(|mut f| mcap_in::attachments(&mut f, crate::sensor::MAX_CALIB_BYTES))
        .find(|a| !a.is_empty())
        .unwrap_or_default()
}

/// Ouster metadata (`std_msgs/String` on `<ns>/metadata`) by namespace, read from the start of
/// the bag until every Ouster namespace known has one, or [`PRESCAN_BYTES`] of messages.
/// The Ouster metadata strings of a bag (by namespace) found near its start, and the file the
/// pre-scan stopped in if it had to be decompressed (for the main pass to read, not to
/// decompress twice).
fn prescan_metadata(
    path: &Path,
    kind: &BagKind,
) -> Result<(MetadataTexts, Option<Decompressed>), BagError> {
    let mut m = Messages::open(path, kind, None)?;
    let mut found = MetadataTexts::default();
    let is_ouster =
        |c: &Connection| MsgKind::from_type_name(&c.type_name) == Some(MsgKind::OusterPacket);
    let is_meta = |c: &Connection| {
        MsgKind::from_type_name(&c.type_name) == Some(MsgKind::StdString)
            && c.topic.ends_with("/metadata")
    };
    let wanted = |m: &Messages| -> Vec<String> {
        m.conns
            .iter()
            .filter(|c| is_ouster(c))
            .map(|c| namespace(&c.topic).to_string())
            .collect()
    };
    // Nothing to look for when every topic is known up front and none is Ouster's.
    let upfront_complete =
        !matches!(kind, BagKind::File(FileKind::Mcap | FileKind::ZstdMcap)) && !m.conns.is_empty();
    if upfront_complete && wanted(&m).is_empty() {
        return Ok((found, m.into_decompressed()));
    }
    let mut read = 0u64;
    let mut asked = None;
    // A damaged bag is reported by the main pass; the pre-scan keeps what it found.
    while let Ok(Some(msg)) = m.next_message() {
        let buf = m.message();
        read += buf.len() as u64;
        if let Some(c) = m.connection(msg.conn).filter(|c| is_meta(c)) {
            let text = c.encoding.and_then(|enc| messages::string(enc, buf).ok());
            if let Some((a, n)) = text {
                found.keep(namespace(&c.topic), &buf[a..a + n]);
            }
        }
        // The answer changes only with the topics or the texts found: not asked at every
        // message (a bag may have thousands of topics).
        let state = Some((m.conns.len(), found.by_ns.len()));
        if state != asked {
            asked = state;
            let want = wanted(&m);
            if !want.is_empty() && want.iter().all(|ns| found.by_ns.contains_key(ns)) {
                break;
            }
        }
        if read > PRESCAN_BYTES {
            break;
        }
    }
    Ok((found, m.into_decompressed()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn namespaces_of_topics() {
        assert_eq!(namespace("/os_node0/lidar_packets"), "/os_node0");
        assert_eq!(namespace("/a/b/imu_packets"), "/a/b");
        assert_eq!(namespace("/lidar_packets"), "/");
        assert_eq!(namespace("lidar_packets"), "/");
    }

    #[test]
    fn ouster_ports_flat_and_nested() {
        assert_eq!(
            ouster_ports(r#"{"udp_port_lidar": 53750, "udp_port_imu": 7503}"#),
            (Some(53750), Some(7503))
        );
        assert_eq!(
            ouster_ports(r#"{"config_params": {"udp_port_lidar": 7502, "udp_port_imu": 0}}"#),
            (Some(7502), None)
        );
        assert_eq!(ouster_ports("not json"), (None, None));
    }

    use super::ros1::tests::{field, record};

    fn connection(id: u32, topic: &str, type_name: &str) -> Vec<u8> {
        record(
            &[
                field("op", &[7]),
                field("conn", &id.to_le_bytes()),
                field("topic", topic.as_bytes()),
            ],
            &field("type", type_name.as_bytes()),
        )
    }

    fn message(id: u32) -> Vec<u8> {
        let time = [0, 0x65, 0xcd, 0x1d, 0, 0, 0, 0];
        record(
            &[
                field("op", &[2]),
                field("conn", &id.to_le_bytes()),
                field("time", &time),
            ],
            &[],
        )
    }

    /// An unindexed ROS 1 bag of one uncompressed chunk holding `records`, read to its end.
    fn read_ros1(name: &str, records: &[u8]) -> BagSource {
        let mut b = ros1::MAGIC.to_vec();
        b.extend(record(
            &[field("op", &[3]), field("index_pos", &0u64.to_le_bytes())],
            &[b' '; 32],
        ));
        b.extend(record(
            &[
                field("op", &[5]),
                field("compression", b"none"),
                field("size", &(records.len() as u32).to_le_bytes()),
            ],
            records,
        ));
        let path = std::env::temp_dir().join(format!("ringscan-{}-{name}", std::process::id()));
        std::fs::write(&path, b).unwrap();
        let mut s = BagSource::open(&path, BagOptions::default()).unwrap();
        while s.next_datagram().unwrap().is_some() {}
        let _ = std::fs::remove_file(&path);
        s
    }

    /// Messages of ids no connection record names share one placeholder (old: one per id in
    /// four tables; ROS 1 ids are u32, so such a bag grew them without end).
    #[test]
    fn messages_without_a_connection_record_share_one_placeholder() {
        let records: Vec<u8> = (0..5000).flat_map(message).collect();
        let s = read_ros1("orphans.bag", &records);
        assert_eq!((s.stats().messages, s.stats().unknown_type), (5000, 5000));
        let m = &s.messages;
        assert_eq!((m.conns.len(), m.local.len(), s.routes.len()), (1, 0, 1));
    }

    /// An IMU topic waits for its `CustomMsg` connection through thousands of other
    /// connections (each one re-asks the question: that must not cost a look at all of them),
    /// and is paired by the first message after it.
    #[test]
    fn an_imu_topic_is_paired_after_many_other_connections() {
        let mut records = connection(0, "/livox/imu", "sensor_msgs/Imu");
        for id in 2..3000 {
            records.extend(connection(id, &format!("/x{id}"), "std_msgs/Int32"));
            records.extend(message(0));
        }
        records.extend(connection(1, "/livox/lidar", "livox_ros_driver2/CustomMsg"));
        records.extend(message(0));
        let s = read_ros1("pairing.bag", &records);
        let st = s.stats();
        // The last IMU message is read as one (and is no IMU sample: it is empty).
        assert_eq!((st.unknown_type, st.malformed), (2998, 1), "{st:?}");
        assert_eq!(s.sensors().len(), 1);
        assert_eq!(s.sensors()[0].topics, ["/livox/lidar", "/livox/imu"]);
        assert_eq!(s.messages.scanned, 3000);
    }

    #[test]
    fn time_bounds() {
        assert_eq!(TimeBound::from_seconds(1.5).ns(10), 1_500_000_010);
        assert_eq!(
            TimeBound::from_seconds(1_700_000_000.0).ns(10),
            1_700_000_000_000_000_000
        );
    }
}
