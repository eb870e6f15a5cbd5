//! The MCAP sink: channels per sensor, sweeps, raw packets, diagnostics, attachments, and the
//! atomic file commit of [`create_file`]. The records, chunks and their compression on worker
//! threads are [`super::mcap_write`]'s.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{self, BufWriter, Seek, Write};
use std::net::SocketAddrV4;
use std::path::{Path, PathBuf};

use super::foxglove::{self, PointCloudPrefix};
pub use super::mcap_write::{in_flight_limit, Behind, WriterStats};
use super::mcap_write::{ChunkedWriter, Codec, MessageHeader, WriterOptions};
use super::ros2::{self, Ros2EncodeError};
use super::ros2_msgs;
use crate::point::{Point, MINIMAL_FIELDS, MINIMAL_STRIDE, POINT_STRIDE};

/// Default target size of an uncompressed chunk (4 MiB: a few sweeps of a 64-beam sensor).
pub const DEFAULT_CHUNK_SIZE: u64 = 4 * 1024 * 1024;

/// Suffix of the temporary file [`create_file`] writes before renaming it into place.
const TEMP_SUFFIX: &str = ".tmp-ringscan";

/// Schema name of the diagnostics channels.
const DIAGNOSTICS_SCHEMA: &str = "ringscan.Diagnostics";

/// JSON schema of the diagnostics messages: an object whose members the caller chooses.
const DIAGNOSTICS_JSON_SCHEMA: &str = r#"{"$schema":"https://json-schema.org/draft/2020-12/schema","title":"ringscan.Diagnostics","description":"Per-sweep packet, loss, timing and sensor-health counters of one sensor, as written by ringscan","type":"object","additionalProperties":true}"#;

/// Schema name of the IMU channels.
const IMU_SCHEMA: &str = "ringscan.Imu";

/// JSON schema of the IMU messages.
const IMU_JSON_SCHEMA: &str = r#"{"$schema":"https://json-schema.org/draft/2020-12/schema","title":"ringscan.Imu","description":"One IMU sample in SI units","type":"object","properties":{"timestamp_ns":{"type":"integer","description":"sensor clock, ns"},"linear_acceleration":{"type":"array","items":{"type":"number"},"minItems":3,"maxItems":3,"description":"m/s^2, x y z"},"angular_velocity":{"type":"array","items":{"type":"number"},"minItems":3,"maxItems":3,"description":"rad/s, x y z"}},"required":["timestamp_ns","linear_acceleration","angular_velocity"]}"#;
/// Schema name of the zone-monitor reports (JSON).
const ZONES_SCHEMA: &str = "ringscan.ZoneStates";
/// JSON schema of the zone-monitor reports.
const ZONES_JSON_SCHEMA: &str = r#"{"$schema":"https://json-schema.org/draft/2020-12/schema","title":"ringscan.ZoneStates","description":"One Ouster zone-monitor packet: the sensor's state of each of its 16 zone slots for one frame","type":"object","properties":{"timestamp_ns":{"type":"integer","description":"sensor clock, ns"},"frame_id":{"type":"integer"},"alert_flags":{"type":"integer"},"live_zoneset_hash":{"type":"string","description":"SHA-256 of the live zone set, hex"},"zones":{"type":"array","minItems":16,"maxItems":16,"items":{"type":"object","properties":{"live":{"type":"boolean"},"id":{"type":"integer"},"error_flags":{"type":"integer"},"trigger_type":{"type":"integer"},"trigger_status":{"type":"integer","description":"1 = asserted"},"triggered_frames":{"type":"integer"},"count":{"type":"integer"},"occlusion_count":{"type":"integer"},"invalid_count":{"type":"integer"},"max_count":{"type":"integer"},"min_range_mm":{"type":"integer"},"max_range_mm":{"type":"integer"},"mean_range_mm":{"type":"integer"}}}}},"required":["timestamp_ns","frame_id","zones"]}"#;

/// Longest sensor name (frame id) accepted.
const MAX_NAME_LEN: usize = 256;

/// Message layout of the points channels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Format {
    /// `foxglove.PointCloud`, protobuf, schema embedded as a `FileDescriptorSet`.
    #[default]
    Foxglove,
    /// `sensor_msgs/msg/PointCloud2`, CDR, `ros2msg` schema.
    Ros2,
}

/// Zstandard level of [`Compression::Zstd`] unless [`SinkOptions::zstd_level`] says otherwise:
/// −3, one of zstd's fast levels. A driver records beside the perception stack on the vehicle,
/// so the default spends the least CPU that still compresses: on the HDL-32E capture level −3
/// takes 0.59× the CPU of level 1 for files 1.30× as large (ratio 1.22 vs 1.59; LZ4 is both
/// slower and larger, 1.29) (`tools/bench_mcap_e2e.sh`, BENCHMARKS.md). `--compression zstd:1`
/// (or higher) when size matters more.
pub const DEFAULT_ZSTD_LEVEL: i32 = -3;

/// Zstandard levels [`SinkOptions::zstd_level`] accepts: zstd's "fast" levels down to −7 and the
/// regular ones up to 19 (higher levels need more memory than a driver should take).
pub const ZSTD_LEVELS: core::ops::RangeInclusive<i32> = -7..=19;

/// Chunk compression.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Compression {
    /// Zstandard at [`SinkOptions::zstd_level`] ([`DEFAULT_ZSTD_LEVEL`] unless set), the
    /// default. Each chunk is one zstd frame compressed by one thread; chunks are compressed in
    /// parallel with [`SinkOptions::threads`] > 1. Levels and what they cost:
    /// `tools/bench/mcap_compression.rs`, `tools/bench_mcap_threads.sh`.
    #[default]
    Zstd,
    /// LZ4 (faster, larger).
    Lz4,
    /// Chunks stored uncompressed.
    None,
}

/// Which fields the points channels' records carry ([`McapSink::write_sweep`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PointFields {
    /// The whole [`Point`] record: x, y, z, intensity, t, ring, return (24 bytes).
    #[default]
    Default,
    /// x, y, z, intensity only ([`MINIMAL_FIELDS`], 16 bytes): `--fields minimal`.
    Minimal,
}

/// How the file is written.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SinkOptions {
    /// Message layout of the points channels.
    pub format: Format,
    /// Chunk compression.
    pub compression: Compression,
    /// Target uncompressed chunk size in bytes: a chunk is closed once it has grown past this.
    /// 0 means [`DEFAULT_CHUNK_SIZE`].
    pub chunk_size: u64,
    /// Zstandard level (with [`Compression::Zstd`]), within [`ZSTD_LEVELS`]; negative levels are
    /// zstd's fast modes.
    pub zstd_level: i32,
    /// Threads compressing chunks: 1 (the default) compresses on the caller's thread and starts
    /// none; N > 1 starts N worker threads, and the caller only fills and writes chunks, in
    /// order. The file's bytes do not depend on it (except for [`Behind::WriteUncompressed`]
    /// fallbacks). At most [`in_flight_limit`]`(threads)` sealed chunks are held at once.
    pub threads: usize,
    /// With `threads` > 1, what happens when the workers fall behind: wait for them, or write
    /// the oldest chunk uncompressed and count it ([`SinkSummary::chunks_uncompressed`]).
    pub behind: Behind,
    /// Fields of the points records written by [`McapSink::write_sweep`].
    pub fields: PointFields,
}

impl Default for SinkOptions {
    fn default() -> Self {
        Self {
            format: Format::Foxglove,
            compression: Compression::Zstd,
            chunk_size: DEFAULT_CHUNK_SIZE,
            zstd_level: DEFAULT_ZSTD_LEVEL,
            threads: 1,
            behind: Behind::Wait,
            fields: PointFields::Default,
        }
    }
}

/// What the sink needs to know about one sensor.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SensorInfo {
    /// Sensor name; also the `frame_id` of its point clouds.
    pub name: String,
    /// `""` for a single sensor (topics `/points`, …), `"/<name>"` when there are several.
    pub topic_prefix: String,
    /// Channel metadata: source address, ports, model, serial, firmware, profile, return mode,
    /// clock, calibration file name.
    pub metadata: BTreeMap<String, String>,
    /// The calibration or metadata file (file name, bytes), stored as an MCAP attachment.
    pub calibration: Option<(String, Vec<u8>)>,
}

/// One sweep to write.
#[derive(Clone, Copy, Debug)]
pub struct SweepMsg<'a> {
    /// Host receive time (ns since the Unix epoch): the MCAP `log_time` and `publish_time`.
    pub log_time_ns: u64,
    /// The sweep's first firing (sensor clock where absolute, else host), ns since the epoch:
    /// the message's own timestamp.
    pub timestamp_ns: u64,
    /// The points, in [`Point`] layout.
    pub points: &'a [Point],
}

/// Handle of a sensor added with [`McapSink::add_sensor`]. (`Default` is the first sensor's
/// handle, for callers that need a placeholder.)
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct SensorId(usize);

impl SensorId {
    /// Position of the sensor in the order it was added (0-based).
    pub fn index(self) -> usize {
        self.0
    }
}

/// The channels of one sensor.
#[derive(Debug)]
pub struct SensorChannels {
    name: String,
    prefix: String,
    metadata: BTreeMap<String, String>,
    points: Channel,
    diagnostics: Channel,
    raw: Option<Channel>,
    imu: Option<Channel>,
    zones: Option<Channel>,
    /// Constant fields of this sensor's `foxglove.PointCloud` messages.
    point_cloud_prefix: PointCloudPrefix,
    /// The same for the extended record (`--fields all`), made on first use.
    extended_prefix: Option<PointCloudPrefix>,
    /// The same for the minimal record (`--fields minimal`).
    minimal_prefix: Option<PointCloudPrefix>,
    /// `--format ros2`: the packet messages of `--raw` (see [`RawRos2`]).
    ros2_raw: RawRos2,
}

/// `--format ros2 --raw`: each packet as the ROS driver of the sensor's family records it.
/// Velodyne and Hesai packets are gathered into one `VelodyneScan` / `PandarScan` per sweep
/// (written just before the sweep's points, or when [`MAX_SCAN_PACKETS`] are held); Ouster
/// packets are one `PacketMsg` each, lidar or IMU by their size, and the sensor metadata is one
/// `std_msgs/String` on `<prefix>/metadata` before the first packet.
#[derive(Debug, Default)]
struct RawRos2 {
    /// The family's name from the sensor's channel metadata (`family`).
    family: String,
    /// Ouster: bytes of a lidar packet (`lidar_packet_bytes`).
    lidar_packet_bytes: Option<usize>,
    /// Ouster: the metadata JSON, written with the first packet.
    metadata: Option<String>,
    scan: Vec<(u64, Vec<u8>)>,
    /// Velodyne / Hesai: the scan topic; Ouster: lidar packets.
    packets: Option<Channel>,
    /// Ouster: IMU packets.
    imu_packets: Option<Channel>,
    /// Ouster: the metadata topic.
    metadata_channel: Option<Channel>,
    /// Packets that no message of the family can hold (a Velodyne position packet, a
    /// Hesai packet over 1500 bytes, a family without a ROS packet message).
    dropped: u64,
}

/// Packets gathered into one scan message at most (a sweep of the densest Velodyne is 1.8k).
pub const MAX_SCAN_PACKETS: usize = 8192;

#[derive(Debug)]
struct Channel {
    id: u16,
    sequence: u32,
}

impl Channel {
    fn next_header(&mut self, log_time: u64) -> MessageHeader {
        let header = self.header(log_time);
        self.sequence = self.sequence.wrapping_add(1);
        header
    }

    /// The next message's header, without taking its sequence number (see [`Self::advance`]).
    fn header(&self, log_time: u64) -> MessageHeader {
        MessageHeader {
            channel_id: self.id,
            sequence: self.sequence,
            log_time,
            publish_time: log_time,
        }
    }

    fn advance(&mut self) {
        self.sequence = self.sequence.wrapping_add(1);
    }
}

impl SensorChannels {
    /// Sensor name (the frame id).
    pub fn name(&self) -> &str {
        &self.name
    }
    /// Topic of the point clouds: `<prefix>/points`.
    pub fn points_topic(&self) -> String {
        format!("{}/points", self.prefix)
    }
    /// Topic of the diagnostics: `<prefix>/diagnostics`.
    pub fn diagnostics_topic(&self) -> String {
        format!("{}/diagnostics", self.prefix)
    }
    /// Topic of the raw packets: `<prefix>/raw` (created on the first raw packet).
    pub fn raw_topic(&self) -> String {
        format!("{}/raw", self.prefix)
    }

    /// Raw packets that `--format ros2` could not put in the family's packet message.
    pub fn raw_dropped(&self) -> u64 {
        self.ros2_raw.dropped
    }

    /// Topic of the IMU samples, `<prefix>/imu`.
    pub fn imu_topic(&self) -> String {
        format!("{}/imu", self.prefix)
    }

    /// Topic of the zone-monitor reports, `<prefix>/zones`.
    pub fn zones_topic(&self) -> String {
        format!("{}/zones", self.prefix)
    }

    /// The topic prefix: `""` for a single sensor, `"/<name>"` when there are several.
    pub fn prefix(&self) -> &str {
        &self.prefix
    }
}

/// Handle of a channel made by [`McapSink::add_topic`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TopicId(usize);

/// The schema of a channel made by [`McapSink::add_topic`].
#[derive(Clone, Copy)]
pub struct TopicSchema<'a> {
    /// Schema name, e.g. `foxglove.SceneUpdate`.
    pub name: &'a str,
    /// Schema encoding, e.g. `protobuf`.
    pub encoding: &'a str,
    /// Makes the schema data (called once per schema name).
    pub data: &'a dyn Fn() -> Vec<u8>,
    /// Message encoding of the channel, e.g. `protobuf`.
    pub message_encoding: &'a str,
}

/// One attachment written to the file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AttachmentSummary {
    /// File name.
    pub name: String,
    /// Media type.
    pub media_type: String,
    /// Size in bytes.
    pub size: u64,
}

/// What a finished file holds.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SinkSummary {
    /// Messages per topic, every channel listed (0 when it got none).
    pub messages: BTreeMap<String, u64>,
    /// Schema name (message type) per topic.
    pub types: BTreeMap<String, String>,
    /// Earliest and latest message log time (ns), if any message was written.
    pub bounds: Option<(u64, u64)>,
    /// Attachments in file order.
    pub attachments: Vec<AttachmentSummary>,
    /// Number of chunks.
    pub chunks: usize,
    /// Chunks written uncompressed because the compression threads were behind
    /// ([`Behind::WriteUncompressed`]).
    pub chunks_uncompressed: u64,
    /// Where the file was committed, when created with [`create_file`].
    pub path: Option<PathBuf>,
    /// `--raw` packets the file does not hold: with `--format ros2`, those its family's packet
    /// message cannot take (Robosense and Livox have none; a Velodyne or Hesai packet of
    /// another size). Counted, never hidden.
    pub raw_dropped: u64,
}

/// Errors of the MCAP sink. Each says what was being done and with what.
#[derive(Debug, thiserror::Error)]
pub enum SinkError {
    /// An I/O operation on the output failed.
    #[error("{context}: {source}")]
    Io {
        /// What was being done, with the path.
        context: String,
        /// The underlying error.
        #[source]
        source: io::Error,
    },
    /// A [`SensorId`] that this sink did not hand out.
    #[error("unknown sensor id {id}: this sink has {registered} sensor(s)")]
    UnknownSensor {
        /// The id passed.
        id: usize,
        /// Number of sensors added.
        registered: usize,
    },
    /// A sensor's name or topic prefix is not usable.
    #[error("sensor {name:?}: {reason}")]
    InvalidSensor {
        /// The sensor name.
        name: String,
        /// What is wrong, with the value found.
        reason: String,
    },
    /// A message would be too large for readers (protobuf and CDR lengths are 32-bit).
    #[error("{topic}: message too large ({what}: {found} bytes, at most {max} allowed)")]
    TooLarge {
        /// Topic of the message.
        topic: String,
        /// What is too large.
        what: &'static str,
        /// Size found.
        found: usize,
        /// Largest size accepted.
        max: usize,
    },
    /// A timestamp that the message format cannot represent.
    #[error("{topic}: timestamp {timestamp_ns} ns cannot be written as {format} (int32 seconds end in 2038)")]
    TimestampOutOfRange {
        /// Topic of the message.
        topic: String,
        /// The timestamp.
        timestamp_ns: u64,
        /// The message type.
        format: &'static str,
    },
    /// Diagnostics could not be serialised as JSON.
    #[error("{topic}: serialising diagnostics as JSON failed: {source}")]
    Json {
        /// Topic of the message.
        topic: String,
        /// The underlying error.
        #[source]
        source: serde_json::Error,
    },
}

fn io_err(context: impl Into<String>) -> impl FnOnce(io::Error) -> SinkError {
    let context = context.into();
    move |source| SinkError::Io { context, source }
}

/// An attachment waiting for the first message (so it gets a meaningful `log_time`) or
/// [`McapSink::finish`].
#[derive(Debug)]
struct PendingAttachment {
    name: String,
    media_type: &'static str,
    data: Vec<u8>,
}

/// For a sink made by [`create_file`]: the temporary file and where it goes on success.
#[derive(Debug)]
struct FileCommit<W> {
    temp: PathBuf,
    target: PathBuf,
    /// Flushes `W`, syncs it to disk and closes it.
    sync: fn(W) -> io::Result<()>,
}

/// Writes sweeps and everything around them into one MCAP file.
///
/// Only [`finish`](Self::finish) completes the file. A sink dropped unfinished (or
/// [`abort`](Self::abort)ed) leaves an incomplete stream in a plain writer, and no file at all
/// when it was made by [`create_file`].
pub struct McapSink<W: Write + Seek> {
    /// `None` once finished or aborted.
    writer: Option<ChunkedWriter<W>>,
    format: Format,
    fields: PointFields,
    points_schema: u16,
    diagnostics_schema: u16,
    raw_schema: Option<u16>,
    imu_schema: Option<u16>,
    zones_schema: Option<u16>,
    sensors: Vec<SensorChannels>,
    /// The one message buffer, reused for every message.
    buf: Vec<u8>,
    /// Interleaved extended records (`--fields all`), reused.
    records: Vec<u8>,
    pending_attachments: Vec<PendingAttachment>,
    attachments: Vec<AttachmentSummary>,
    /// Every (name, bytes) attached or pending, so a file shared by sensors is stored once.
    attached: Vec<(String, Vec<u8>)>,
    first_log_time: Option<u64>,
    commit: Option<FileCommit<W>>,
    /// Schemas of [`McapSink::add_topic`] channels, by name.
    extra_schemas: Vec<(String, u16)>,
    /// Channels made by [`McapSink::add_topic`]: topic and channel.
    extra_channels: Vec<(String, Channel)>,
}

impl<W: Write + Seek> std::fmt::Debug for McapSink<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapSink")
            .field("format", &self.format)
            .field("sensors", &self.sensors)
            .field("finished", &self.writer.is_none())
            .field("temp", &self.commit.as_ref().map(|c| &c.temp))
            .finish_non_exhaustive()
    }
}

impl<W: Write + Seek> McapSink<W> {
    /// Starts an MCAP stream on `w` and registers the points and diagnostics schemas.
    pub fn new(w: W, opts: SinkOptions) -> Result<Self, SinkError> {
        let codec = match opts.compression {
            Compression::Zstd => Codec::Zstd(
                opts.zstd_level
                    .clamp(*ZSTD_LEVELS.start(), *ZSTD_LEVELS.end()),
            ),
            Compression::Lz4 => Codec::Lz4,
            Compression::None => Codec::None,
        };
        let chunk_size = if opts.chunk_size == 0 {
            DEFAULT_CHUNK_SIZE
        } else {
            opts.chunk_size
        };
        let mut writer = ChunkedWriter::new(
            w,
            WriterOptions {
                library: format!("ringscan {}", env!("CARGO_PKG_VERSION")),
                codec,
                chunk_size: usize::try_from(chunk_size).unwrap_or(usize::MAX),
                threads: opts.threads,
                behind: opts.behind,
                profile: match opts.format {
                    Format::Foxglove => String::new(),
                    Format::Ros2 => "ros2".into(),
                },
            },
        )?;
        let points_schema = match opts.format {
            Format::Foxglove => writer.add_schema(
                foxglove::POINT_CLOUD_SCHEMA,
                "protobuf",
                &foxglove::point_cloud_descriptor_set(),
            ),
            Format::Ros2 => writer.add_schema(
                ros2::POINT_CLOUD2_SCHEMA,
                "ros2msg",
                ros2::point_cloud2_schema_text().as_bytes(),
            ),
        }?;
        let diagnostics_schema = match opts.format {
            Format::Foxglove => writer.add_schema(
                DIAGNOSTICS_SCHEMA,
                "jsonschema",
                DIAGNOSTICS_JSON_SCHEMA.as_bytes(),
            ),
            Format::Ros2 => writer.add_schema(
                ros2_msgs::DIAGNOSTIC_ARRAY_SCHEMA,
                "ros2msg",
                ros2_schema(ros2_msgs::DIAGNOSTIC_ARRAY_SCHEMA).as_bytes(),
            ),
        }?;
        Ok(Self {
            writer: Some(writer),
            format: opts.format,
            fields: opts.fields,
            points_schema,
            diagnostics_schema,
            raw_schema: None,
            imu_schema: None,
            zones_schema: None,
            sensors: Vec::new(),
            buf: Vec::new(),
            records: Vec::new(),
            pending_attachments: Vec::new(),
            attachments: Vec::new(),
            attached: Vec::new(),
            first_log_time: None,
            commit: None,
            extra_schemas: Vec::new(),
            extra_channels: Vec::new(),
        })
    }

    /// The message layout of the file.
    pub fn format(&self) -> Format {
        self.format
    }

    /// Chunks written so far, and how many of them uncompressed because the compression threads
    /// were behind (`listen` reports it in its health diagnostics).
    pub fn chunk_stats(&self) -> WriterStats {
        self.writer
            .as_ref()
            .map(ChunkedWriter::stats)
            .unwrap_or_default()
    }

    /// The channels of a sensor.
    pub fn channels(&self, s: SensorId) -> Option<&SensorChannels> {
        self.sensors.get(s.0)
    }

    /// Registers a sensor: its `<prefix>/points` and `<prefix>/diagnostics` channels (with
    /// `info.metadata` as channel metadata) and its calibration file as an attachment.
    ///
    /// The prefix must be empty or `/`-separated ROS-style name segments (letters, digits, `_`,
    /// `-`, `.`) without a trailing `/`, and differ from every other sensor's.
    pub fn add_sensor(&mut self, info: &SensorInfo) -> Result<SensorId, SinkError> {
        validate_sensor(info)?;
        if self.sensors.iter().any(|s| s.prefix == info.topic_prefix) {
            return Err(SinkError::InvalidSensor {
                name: info.name.clone(),
                reason: format!(
                    "topic prefix {:?} is already used by another sensor; give each sensor its own \"/<name>\"",
                    info.topic_prefix
                ),
            });
        }
        let format = self.format;
        let writer = self.writer.as_mut().ok_or_else(finished_error)?;
        let points_topic = format!("{}/points", info.topic_prefix);
        let (encoding, diagnostics_encoding) = match format {
            Format::Foxglove => ("protobuf", "json"),
            Format::Ros2 => ("cdr", "cdr"),
        };
        let points = writer.add_channel(
            self.points_schema,
            &points_topic,
            encoding,
            &channel_metadata(format, &points_topic, &info.metadata),
        )?;
        let diagnostics_topic = format!("{}/diagnostics", info.topic_prefix);
        let diagnostics = writer.add_channel(
            self.diagnostics_schema,
            &diagnostics_topic,
            diagnostics_encoding,
            &channel_metadata(format, &diagnostics_topic, &info.metadata),
        )?;
        if let Some((file_name, data)) = &info.calibration {
            let already = self
                .attached
                .iter()
                .any(|(n, d)| n == file_name && d == data);
            if !already {
                self.attached.push((file_name.clone(), data.clone()));
                self.pending_attachments.push(PendingAttachment {
                    name: file_name.clone(),
                    media_type: media_type_for(file_name, data),
                    data: data.clone(),
                });
            }
        }
        self.sensors.push(SensorChannels {
            name: info.name.clone(),
            prefix: info.topic_prefix.clone(),
            metadata: info.metadata.clone(),
            points: Channel {
                id: points,
                sequence: 0,
            },
            diagnostics: Channel {
                id: diagnostics,
                sequence: 0,
            },
            raw: None,
            imu: None,
            zones: None,
            point_cloud_prefix: PointCloudPrefix::new(&info.name),
            extended_prefix: None,
            minimal_prefix: (self.fields == PointFields::Minimal).then(|| {
                PointCloudPrefix::with_fields(&info.name, MINIMAL_STRIDE, &MINIMAL_FIELDS)
            }),
            ros2_raw: RawRos2 {
                family: info.metadata.get("family").cloned().unwrap_or_default(),
                lidar_packet_bytes: info
                    .metadata
                    .get("lidar_packet_bytes")
                    .and_then(|n| n.parse().ok()),
                metadata: info
                    .calibration
                    .as_ref()
                    .filter(|_| info.metadata.get("family").is_some_and(|f| f == "ouster"))
                    .and_then(|(_, b)| String::from_utf8(b.clone()).ok()),
                ..RawRos2::default()
            },
        });
        Ok(SensorId(self.sensors.len() - 1))
    }

    /// Writes one sweep to `<prefix>/points`: `log_time` = `publish_time` = host receive time,
    /// the message's own timestamp = the sweep's first firing. The records carry the fields of
    /// [`SinkOptions::fields`]; they are encoded straight into the chunk.
    pub fn write_sweep(&mut self, s: SensorId, sweep: &SweepMsg) -> Result<(), SinkError> {
        self.before_message(sweep.log_time_ns)?;
        self.flush_scan(s)?;
        let sensor = sensor_at(&mut self.sensors, s)?;
        let writer = self.writer.as_mut().ok_or_else(finished_error)?;
        let header = sensor.points.header(sweep.log_time_ns);
        let minimal = sensor.minimal_prefix.as_ref();
        let (stride, fields): (usize, &[_]) = match minimal {
            Some(_) => (MINIMAL_STRIDE, &MINIMAL_FIELDS),
            None => (POINT_STRIDE, &crate::point::POINT_FIELDS),
        };
        let data_len = sweep.points.len().saturating_mul(stride);
        let write_data = |b: &mut Vec<u8>| match minimal {
            Some(_) => crate::point::extend_minimal(sweep.points, b),
            None => b.extend_from_slice(crate::point::as_bytes(sweep.points)),
        };
        let format = self.format;
        let sensor_ref = &*sensor;
        writer.write_message_with(&header, |buf| match format {
            Format::Foxglove => {
                let prefix = minimal.unwrap_or(&sensor_ref.point_cloud_prefix);
                foxglove::append_point_cloud_with(
                    buf,
                    sweep.timestamp_ns,
                    prefix,
                    data_len,
                    write_data,
                )
                .ok_or_else(|| SinkError::TooLarge {
                    topic: sensor_ref.points_topic(),
                    what: "point data",
                    found: data_len,
                    max: foxglove::MAX_MESSAGE_LEN - 1024,
                })
            }
            Format::Ros2 => ros2::append_point_cloud2_with(
                buf,
                sweep.timestamp_ns,
                &sensor_ref.name,
                stride,
                fields,
                data_len,
                write_data,
            )
            .map_err(|e| match e {
                Ros2EncodeError::TimestampOutOfRange => SinkError::TimestampOutOfRange {
                    topic: sensor_ref.points_topic(),
                    timestamp_ns: sweep.timestamp_ns,
                    format: ros2::POINT_CLOUD2_SCHEMA,
                },
                Ros2EncodeError::TooLarge => SinkError::TooLarge {
                    topic: sensor_ref.points_topic(),
                    what: "point data",
                    found: data_len,
                    max: ros2::MAX_DATA_LEN,
                },
            }),
        })?;
        sensor.points.advance();
        Ok(())
    }

    /// Writes one sweep with its extra fields (`--fields all`): records of
    /// [`crate::point::EXTENDED_FIELDS`], a point then its range, signal and near-IR.
    pub fn write_sweep_extended(
        &mut self,
        s: SensorId,
        sweep: &SweepMsg,
        extras: &[crate::point::PointExtra],
    ) -> Result<(), SinkError> {
        use crate::point::{interleave_extended, EXTENDED_FIELDS, EXTENDED_STRIDE};
        self.before_message(sweep.log_time_ns)?;
        self.flush_scan(s)?;
        let sensor = sensor_at(&mut self.sensors, s)?;
        let mut records = std::mem::take(&mut self.records);
        interleave_extended(sweep.points, extras, &mut records);
        let topic = sensor.points_topic();
        let found = records.len();
        let too_large = |max| SinkError::TooLarge {
            topic: topic.clone(),
            what: "point data",
            found,
            max,
        };
        if sensor.extended_prefix.is_none() {
            sensor.extended_prefix = Some(PointCloudPrefix::with_fields(
                &sensor.name,
                EXTENDED_STRIDE,
                &EXTENDED_FIELDS,
            ));
        }
        let encoded = match self.format {
            Format::Foxglove => {
                let Some(prefix) = sensor.extended_prefix.as_ref() else {
                    return Err(finished_error());
                };
                foxglove::encode_point_cloud_bytes(
                    &mut self.buf,
                    sweep.timestamp_ns,
                    prefix,
                    &records,
                )
                .ok_or_else(|| too_large(foxglove::MAX_MESSAGE_LEN - 1024))
            }
            Format::Ros2 => ros2::encode_point_cloud2_fields(
                &mut self.buf,
                sweep.timestamp_ns,
                &sensor.name,
                EXTENDED_STRIDE,
                &EXTENDED_FIELDS,
                &records,
            )
            .map_err(|e| match e {
                Ros2EncodeError::TimestampOutOfRange => SinkError::TimestampOutOfRange {
                    topic: topic.clone(),
                    timestamp_ns: sweep.timestamp_ns,
                    format: ros2::POINT_CLOUD2_SCHEMA,
                },
                Ros2EncodeError::TooLarge => too_large(ros2::MAX_DATA_LEN),
            }),
        };
        self.records = records;
        encoded?;
        let header = sensor.points.next_header(sweep.log_time_ns);
        let writer = self.writer.as_mut().ok_or_else(finished_error)?;
        write_known(writer, &header, &self.buf, || {
            format!("writing a sweep to {}", sensor.points_topic())
        })
    }

    /// Writes one UDP payload to `<prefix>/raw` as a `ringscan.RawPacket` (protobuf; see
    /// [`foxglove::RAW_PACKET_SCHEMA`]), creating the channel on first use.
    pub fn write_raw(
        &mut self,
        s: SensorId,
        log_time_ns: u64,
        src: SocketAddrV4,
        dst_port: u16,
        payload: &[u8],
    ) -> Result<(), SinkError> {
        self.before_message(log_time_ns)?;
        if self.format == Format::Ros2 {
            return self.write_raw_ros2(s, log_time_ns, payload);
        }
        let sensor = sensor_at(&mut self.sensors, s)?;
        let writer = self.writer.as_mut().ok_or_else(finished_error)?;
        if sensor.raw.is_none() {
            let topic = sensor.raw_topic();
            lazy_channel(
                writer,
                &mut self.raw_schema,
                (
                    foxglove::RAW_PACKET_SCHEMA,
                    "protobuf",
                    &foxglove::raw_packet_descriptor_set,
                ),
                &mut sensor.raw,
                &topic,
                "protobuf",
                &sensor.metadata,
            )?;
        }
        foxglove::encode_raw_packet(&mut self.buf, log_time_ns, src, dst_port, payload)
            .ok_or_else(|| SinkError::TooLarge {
                topic: sensor.raw_topic(),
                what: "payload",
                found: payload.len(),
                max: foxglove::MAX_MESSAGE_LEN - 1024,
            })?;
        let Some(channel) = sensor.raw.as_mut() else {
            return Err(finished_error());
        };
        let header = channel.next_header(log_time_ns);
        write_known(writer, &header, &self.buf, || {
            format!("writing a packet to {}", sensor.raw_topic())
        })
    }

    /// Writes one IMU sample to `<prefix>/imu` (JSON, schema `ringscan.Imu`: `timestamp_ns`
    /// (sensor clock), `linear_acceleration` m/s², `angular_velocity` rad/s), creating the
    /// channel on first use.
    pub fn write_imu(
        &mut self,
        s: SensorId,
        log_time_ns: u64,
        json: &serde_json::Value,
    ) -> Result<(), SinkError> {
        self.before_message(log_time_ns)?;
        let format = self.format;
        let sensor = sensor_at(&mut self.sensors, s)?;
        let writer = self.writer.as_mut().ok_or_else(finished_error)?;
        if sensor.imu.is_none() {
            let topic = sensor.imu_topic();
            let md = channel_metadata(format, &topic, &sensor.metadata);
            match format {
                Format::Foxglove => lazy_channel(
                    writer,
                    &mut self.imu_schema,
                    (IMU_SCHEMA, "jsonschema", &|| {
                        IMU_JSON_SCHEMA.as_bytes().to_vec()
                    }),
                    &mut sensor.imu,
                    &topic,
                    "json",
                    &md,
                )?,
                Format::Ros2 => lazy_channel(
                    writer,
                    &mut self.imu_schema,
                    (ros2_msgs::IMU_SCHEMA, "ros2msg", &|| {
                        ros2_schema(ros2_msgs::IMU_SCHEMA).into_bytes()
                    }),
                    &mut sensor.imu,
                    &topic,
                    "cdr",
                    &md,
                )?,
            }
        }
        match format {
            Format::Foxglove => {
                self.buf.clear();
                serde_json::to_writer(&mut self.buf, json).map_err(|source| SinkError::Json {
                    topic: sensor.imu_topic(),
                    source,
                })?;
            }
            Format::Ros2 => {
                let v3 = |k: &str| {
                    let a = json.get(k).and_then(serde_json::Value::as_array);
                    let f = |i: usize| {
                        a.and_then(|a| a.get(i))
                            .and_then(serde_json::Value::as_f64)
                            .unwrap_or(f64::NAN)
                    };
                    [f(0), f(1), f(2)]
                };
                // The sensor's clock where it is absolute (PTP / GPS: after 2001), else host.
                let stamp = json
                    .get("timestamp_ns")
                    .and_then(serde_json::Value::as_u64)
                    .filter(|&t| t >= 1_000_000_000_000_000_000)
                    .unwrap_or(log_time_ns);
                ros2_msgs::encode_imu(
                    &mut self.buf,
                    stamp,
                    &sensor.name,
                    v3("angular_velocity"),
                    v3("linear_acceleration"),
                )
                .map_err(|_| SinkError::TimestampOutOfRange {
                    topic: sensor.imu_topic(),
                    timestamp_ns: stamp,
                    format: ros2_msgs::IMU_SCHEMA,
                })?;
            }
        }
        let Some(channel) = sensor.imu.as_mut() else {
            return Err(finished_error());
        };
        let header = channel.next_header(log_time_ns);
        write_known(writer, &header, &self.buf, || {
            format!("writing an IMU sample to {}", sensor.imu_topic())
        })
    }

    /// Writes one zone-monitor report to `<prefix>/zones`, creating the channel on first use:
    /// JSON with schema `ringscan.ZoneStates` (`--format foxglove`), or the same JSON text in a
    /// `std_msgs/msg/String` (`--format ros2`: ROS 2 has no message for zone states).
    pub fn write_zones(
        &mut self,
        s: SensorId,
        log_time_ns: u64,
        json: &serde_json::Value,
    ) -> Result<(), SinkError> {
        self.before_message(log_time_ns)?;
        let format = self.format;
        let sensor = sensor_at(&mut self.sensors, s)?;
        let writer = self.writer.as_mut().ok_or_else(finished_error)?;
        let topic = sensor.zones_topic();
        if sensor.zones.is_none() {
            let md = channel_metadata(format, &topic, &sensor.metadata);
            match format {
                Format::Foxglove => lazy_channel(
                    writer,
                    &mut self.zones_schema,
                    (ZONES_SCHEMA, "jsonschema", &|| {
                        ZONES_JSON_SCHEMA.as_bytes().to_vec()
                    }),
                    &mut sensor.zones,
                    &topic,
                    "json",
                    &md,
                )?,
                Format::Ros2 => lazy_ros2_channel(
                    writer,
                    &mut self.extra_schemas,
                    ros2_msgs::STRING_SCHEMA,
                    &mut sensor.zones,
                    &topic,
                    &md,
                )?,
            }
        }
        let text = serde_json::to_string(json).map_err(|source| SinkError::Json {
            topic: topic.clone(),
            source,
        })?;
        match format {
            Format::Foxglove => {
                self.buf.clear();
                self.buf.extend_from_slice(text.as_bytes());
            }
            Format::Ros2 => ros2_msgs::encode_string(&mut self.buf, &text),
        }
        let Some(channel) = sensor.zones.as_mut() else {
            return Err(finished_error());
        };
        let header = channel.next_header(log_time_ns);
        write_known(writer, &header, &self.buf, || {
            format!("writing a zone-monitor report to {topic}")
        })
    }

    /// Writes one diagnostics object to `<prefix>/diagnostics` (JSON).
    pub fn write_diagnostics(
        &mut self,
        s: SensorId,
        log_time_ns: u64,
        json: &serde_json::Value,
    ) -> Result<(), SinkError> {
        self.before_message(log_time_ns)?;
        let sensor = sensor_at(&mut self.sensors, s)?;
        match self.format {
            Format::Foxglove => {
                self.buf.clear();
                serde_json::to_writer(&mut self.buf, json).map_err(|source| SinkError::Json {
                    topic: sensor.diagnostics_topic(),
                    source,
                })?;
            }
            Format::Ros2 => {
                let mut kv = Vec::new();
                ros2_msgs::json_key_values(json, &mut kv);
                let missing = json
                    .get("missing_packets")
                    .and_then(serde_json::Value::as_u64)
                    .unwrap_or(0);
                let level = if missing > 0 {
                    ros2_msgs::level::WARN
                } else {
                    ros2_msgs::level::OK
                };
                let hardware_id = sensor
                    .metadata
                    .get("serial")
                    .filter(|s| !s.is_empty() && *s != "0")
                    .unwrap_or(&sensor.name);
                ros2_msgs::encode_diagnostic_array(
                    &mut self.buf,
                    log_time_ns,
                    &sensor.name,
                    hardware_id,
                    level,
                    &kv,
                )
                .map_err(|_| SinkError::TimestampOutOfRange {
                    topic: sensor.diagnostics_topic(),
                    timestamp_ns: log_time_ns,
                    format: ros2_msgs::DIAGNOSTIC_ARRAY_SCHEMA,
                })?;
            }
        }
        let header = sensor.diagnostics.next_header(log_time_ns);
        let writer = self.writer.as_mut().ok_or_else(finished_error)?;
        write_known(writer, &header, &self.buf, || {
            format!("writing diagnostics to {}", sensor.diagnostics_topic())
        })
    }

    /// Adds a channel on `topic` with `schema` (the schema is written once per name) and
    /// `metadata`: for outputs beyond a sensor's own channels (pipeline outputs, transforms).
    pub fn add_topic(
        &mut self,
        topic: &str,
        schema: TopicSchema<'_>,
        metadata: &BTreeMap<String, String>,
    ) -> Result<TopicId, SinkError> {
        let writer = self.writer.as_mut().ok_or_else(finished_error)?;
        let schema_id = match self.extra_schemas.iter().find(|(n, _)| n == schema.name) {
            Some(&(_, id)) => id,
            None => {
                let id = writer.add_schema(schema.name, schema.encoding, &(schema.data)())?;
                self.extra_schemas.push((schema.name.to_string(), id));
                id
            }
        };
        let md = channel_metadata(self.format, topic, metadata);
        let id = writer.add_channel(schema_id, topic, schema.message_encoding, &md)?;
        self.extra_channels
            .push((topic.to_string(), Channel { id, sequence: 0 }));
        Ok(TopicId(self.extra_channels.len() - 1))
    }

    /// Writes one already encoded message to a channel made by [`add_topic`](Self::add_topic).
    pub fn write_message(
        &mut self,
        topic: TopicId,
        log_time_ns: u64,
        data: &[u8],
    ) -> Result<(), SinkError> {
        self.before_message(log_time_ns)?;
        let registered = self.extra_channels.len();
        let (name, channel) =
            self.extra_channels
                .get_mut(topic.0)
                .ok_or(SinkError::UnknownSensor {
                    id: topic.0,
                    registered,
                })?;
        let header = channel.next_header(log_time_ns);
        let writer = self.writer.as_mut().ok_or_else(finished_error)?;
        write_known(writer, &header, data, || {
            format!("writing a message to {name}")
        })
    }

    /// Writes the summary section and footer. For a sink made by [`create_file`], then flushes,
    /// syncs and renames the file into place; on any error the temporary file is removed.
    pub fn finish(mut self) -> Result<SinkSummary, SinkError> {
        let result = self.finish_inner();
        if result.is_err() {
            self.discard();
        }
        result
    }

    fn finish_inner(&mut self) -> Result<SinkSummary, SinkError> {
        for i in 0..self.sensors.len() {
            self.flush_scan(SensorId(i))?;
        }
        let log_time = self.first_log_time.unwrap_or(0);
        self.write_pending_attachments(log_time)?;
        let writer = self.writer.take().ok_or_else(finished_error)?;
        // On an error the writer is gone (its stream closed); `discard` removes a temporary file.
        let (inner, summary) = writer.finish()?;
        let mut messages = BTreeMap::new();
        for (topic, n) in summary.channel_messages {
            *messages.entry(topic).or_insert(0) += n;
        }
        let types = summary.channel_schemas.into_iter().collect();
        let mut out = SinkSummary {
            messages,
            types,
            bounds: summary.bounds,
            attachments: std::mem::take(&mut self.attachments),
            chunks: summary.stats.chunks as usize,
            chunks_uncompressed: summary.stats.chunks_uncompressed,
            path: None,
            raw_dropped: self.sensors.iter().map(SensorChannels::raw_dropped).sum(),
        };
        match self.commit.take() {
            None => {
                let mut inner = inner;
                inner.flush().map_err(io_err("flushing the MCAP output"))?;
            }
            Some(commit) => {
                let synced = (commit.sync)(inner);
                let renamed = synced
                    .map_err(io_err(format!("writing {}", commit.temp.display())))
                    .and_then(|()| {
                        std::fs::rename(&commit.temp, &commit.target).map_err(io_err(format!(
                            "renaming {} to {}",
                            commit.temp.display(),
                            commit.target.display()
                        )))
                    });
                if let Err(e) = renamed {
                    let _ = std::fs::remove_file(&commit.temp);
                    return Err(e);
                }
                sync_parent_dir(&commit.target);
                out.path = Some(commit.target);
            }
        }
        Ok(out)
    }

    /// Gives up on the output: nothing more is written, and a temporary file made by
    /// [`create_file`] is removed (dropping the sink does the same).
    pub fn abort(mut self) {
        self.discard();
    }

    /// Closes the output without a summary and removes the temporary file, if any.
    fn discard(&mut self) {
        if let Some(writer) = self.writer.take() {
            // `into_inner` stops the compression threads and hands back the stream as it is,
            // without a summary.
            drop(writer.into_inner());
        }
        if let Some(commit) = self.commit.take() {
            let _ = std::fs::remove_file(&commit.temp);
        }
    }

    /// `--format ros2`: one packet into the family's ROS packet message (see [`RawRos2`]).
    fn write_raw_ros2(
        &mut self,
        s: SensorId,
        log_time_ns: u64,
        payload: &[u8],
    ) -> Result<(), SinkError> {
        let sensor = sensor_at(&mut self.sensors, s)?;
        let writer = self.writer.as_mut().ok_or_else(finished_error)?;
        let raw = &mut sensor.ros2_raw;
        let prefix = sensor.prefix.clone();
        let too_long = |found: usize, max: usize| SinkError::TooLarge {
            topic: format!("{prefix}/raw"),
            what: "packet",
            found,
            max,
        };
        match raw.family.as_str() {
            "velodyne" | "hesai" => {
                let pandar = raw.family == "hesai";
                let fits = if pandar {
                    payload.len() <= ros2_msgs::PANDAR_PACKET_BYTES
                } else {
                    payload.len() == ros2_msgs::VELODYNE_PACKET_BYTES
                };
                if !fits {
                    raw.dropped += 1;
                    return Ok(());
                }
                raw.scan.push((log_time_ns, payload.to_vec()));
                if raw.scan.len() >= MAX_SCAN_PACKETS {
                    self.flush_scan(s)?;
                }
                Ok(())
            }
            "ouster" => {
                if let Some(text) = raw.metadata.take() {
                    let topic = format!("{prefix}/metadata");
                    let md = channel_metadata(Format::Ros2, &topic, &sensor.metadata);
                    lazy_ros2_channel(
                        writer,
                        &mut self.extra_schemas,
                        ros2_msgs::STRING_SCHEMA,
                        &mut raw.metadata_channel,
                        &topic,
                        &md,
                    )?;
                    ros2_msgs::encode_string(&mut self.buf, &text);
                    if let Some(c) = raw.metadata_channel.as_mut() {
                        let header = c.next_header(log_time_ns);
                        write_known(writer, &header, &self.buf, || {
                            format!("writing the sensor metadata to {topic}")
                        })?;
                    }
                }
                if u32::try_from(payload.len()).is_err() {
                    return Err(too_long(payload.len(), u32::MAX as usize));
                }
                let lidar = raw.lidar_packet_bytes.is_none_or(|n| n == payload.len());
                let (channel, topic) = if lidar {
                    (&mut raw.packets, format!("{prefix}/lidar_packets"))
                } else {
                    (&mut raw.imu_packets, format!("{prefix}/imu_packets"))
                };
                let md = channel_metadata(Format::Ros2, &topic, &sensor.metadata);
                lazy_ros2_channel(
                    writer,
                    &mut self.extra_schemas,
                    ros2_msgs::OUSTER_PACKET_SCHEMA,
                    channel,
                    &topic,
                    &md,
                )?;
                let Some(c) = channel.as_mut() else {
                    return Err(finished_error());
                };
                let header = c.next_header(log_time_ns);
                writer.write_message_with(&header, |b| {
                    // PacketMsg { uint8[] buf }: the encapsulation header, the length, the bytes.
                    b.extend_from_slice(&[0, 1, 0, 0]);
                    b.extend_from_slice(&(payload.len() as u32).to_le_bytes());
                    b.extend_from_slice(payload);
                    Ok(())
                })
            }
            _ => {
                raw.dropped += 1;
                Ok(())
            }
        }
    }

    /// Writes the Velodyne / Hesai packets gathered for sensor `s` as one scan message.
    fn flush_scan(&mut self, s: SensorId) -> Result<(), SinkError> {
        let sensor = sensor_at(&mut self.sensors, s)?;
        if sensor.ros2_raw.scan.is_empty() {
            return Ok(());
        }
        let writer = self.writer.as_mut().ok_or_else(finished_error)?;
        let raw = &mut sensor.ros2_raw;
        let pandar = raw.family == "hesai";
        let (schema, topic) = if pandar {
            (
                ros2_msgs::PANDAR_SCAN_SCHEMA,
                format!("{}/pandar_packets", sensor.prefix),
            )
        } else {
            (
                ros2_msgs::VELODYNE_SCAN_SCHEMA,
                format!("{}/velodyne_packets", sensor.prefix),
            )
        };
        let md = channel_metadata(Format::Ros2, &topic, &sensor.metadata);
        lazy_ros2_channel(
            writer,
            &mut self.extra_schemas,
            schema,
            &mut raw.packets,
            &topic,
            &md,
        )?;
        let scan = std::mem::take(&mut raw.scan);
        let log_time = scan.last().map_or(0, |p| p.0);
        let encoded = ros2_msgs::encode_packet_scan(&mut self.buf, pandar, &sensor.name, &scan);
        raw.scan = scan;
        raw.scan.clear();
        encoded.map_err(|_| SinkError::TimestampOutOfRange {
            topic: topic.clone(),
            timestamp_ns: log_time,
            format: schema,
        })?;
        let Some(c) = raw.packets.as_mut() else {
            return Err(finished_error());
        };
        let header = c.next_header(log_time);
        write_known(writer, &header, &self.buf, || {
            format!("writing packets to {topic}")
        })
    }

    /// Bookkeeping before every message: remember the first log time and write pending
    /// attachments with it.
    fn before_message(&mut self, log_time: u64) -> Result<(), SinkError> {
        if self.first_log_time.is_none() {
            self.first_log_time = Some(log_time);
        }
        if !self.pending_attachments.is_empty() {
            self.write_pending_attachments(log_time)?;
        }
        Ok(())
    }

    fn write_pending_attachments(&mut self, log_time: u64) -> Result<(), SinkError> {
        let pending = std::mem::take(&mut self.pending_attachments);
        let writer = self.writer.as_mut().ok_or_else(finished_error)?;
        for a in pending {
            writer.attach(log_time, log_time, &a.name, a.media_type, &a.data)?;
            self.attachments.push(AttachmentSummary {
                name: a.name,
                media_type: a.media_type.to_owned(),
                size: a.data.len() as u64,
            });
        }
        Ok(())
    }
}

impl<W: Write + Seek> Drop for McapSink<W> {
    fn drop(&mut self) {
        self.discard();
    }
}

/// Creates a channel on its first use (and its schema on the first use of any such channel).
fn lazy_channel<W: Write>(
    writer: &mut ChunkedWriter<W>,
    schema_id: &mut Option<u16>,
    schema: (&str, &str, &dyn Fn() -> Vec<u8>),
    channel: &mut Option<Channel>,
    topic: &str,
    message_encoding: &str,
    metadata: &BTreeMap<String, String>,
) -> Result<(), SinkError> {
    if channel.is_some() {
        return Ok(());
    }
    let (name, encoding, data) = schema;
    let id = match *schema_id {
        Some(id) => id,
        None => {
            let id = writer.add_schema(name, encoding, &data())?;
            *schema_id = Some(id);
            id
        }
    };
    let id = writer.add_channel(id, topic, message_encoding, metadata)?;
    *channel = Some(Channel { id, sequence: 0 });
    Ok(())
}

/// The `ros2msg` schema text of one of [`ros2_msgs`]'s types.
fn ros2_schema(name: &str) -> String {
    ros2_msgs::schema_text(name).unwrap_or_default()
}

/// Channel metadata: with `--format ros2`, the topic's QoS profile too (rosbag2's MCAP storage
/// keeps it there as `offered_qos_profiles`, and `ros2 bag play` offers it).
fn channel_metadata(
    format: Format,
    topic: &str,
    md: &BTreeMap<String, String>,
) -> BTreeMap<String, String> {
    let mut md = md.clone();
    if format == Format::Ros2 {
        md.insert(
            "offered_qos_profiles".into(),
            super::rosbag2::qos_of(topic).into(),
        );
    }
    md
}

/// Creates a `--format ros2` channel of one of [`ros2_msgs`]'s types on first use (its schema
/// once per file, shared with [`McapSink::add_topic`]'s).
fn lazy_ros2_channel<W: Write>(
    writer: &mut ChunkedWriter<W>,
    schemas: &mut Vec<(String, u16)>,
    schema: &str,
    channel: &mut Option<Channel>,
    topic: &str,
    metadata: &BTreeMap<String, String>,
) -> Result<(), SinkError> {
    if channel.is_some() {
        return Ok(());
    }
    let schema_id = match schemas.iter().find(|(n, _)| n == schema) {
        Some(&(_, id)) => id,
        None => {
            let id = writer.add_schema(schema, "ros2msg", ros2_schema(schema).as_bytes())?;
            schemas.push((schema.to_string(), id));
            id
        }
    };
    let id = writer.add_channel(schema_id, topic, "cdr", metadata)?;
    *channel = Some(Channel { id, sequence: 0 });
    Ok(())
}

/// The sensor registered as `s`.
fn sensor_at(
    sensors: &mut [SensorChannels],
    s: SensorId,
) -> Result<&mut SensorChannels, SinkError> {
    let registered = sensors.len();
    sensors.get_mut(s.0).ok_or(SinkError::UnknownSensor {
        id: s.0,
        registered,
    })
}

/// Writes `data` to a channel already added; `context` (which names the topic) is built only
/// when the write fails, so a message costs no formatting.
fn write_known<W: Write>(
    writer: &mut ChunkedWriter<W>,
    header: &MessageHeader,
    data: &[u8],
    context: impl FnOnce() -> String,
) -> Result<(), SinkError> {
    writer.write_message(header, data).map_err(|e| match e {
        SinkError::Io { context: c, source } => SinkError::Io {
            context: format!("{}: {c}", context()),
            source,
        },
        e => e,
    })
}

fn finished_error() -> SinkError {
    // Only reachable after a failed `finish`, which consumed the sink; kept as an error rather
    // than a panic all the same.
    SinkError::Io {
        context: "writing to an MCAP sink that is already closed".into(),
        source: io::Error::other("sink closed"),
    }
}

fn validate_sensor(info: &SensorInfo) -> Result<(), SinkError> {
    let invalid = |reason: String| SinkError::InvalidSensor {
        name: info.name.clone(),
        reason,
    };
    if info.name.len() > MAX_NAME_LEN {
        return Err(invalid(format!(
            "name is {} bytes long, at most {MAX_NAME_LEN} allowed",
            info.name.len()
        )));
    }
    if info.name.chars().any(char::is_control) {
        return Err(invalid("name contains a control character".into()));
    }
    let prefix = &info.topic_prefix;
    if prefix.is_empty() {
        return Ok(());
    }
    if prefix.len() > MAX_NAME_LEN {
        return Err(invalid(format!(
            "topic prefix is {} bytes long, at most {MAX_NAME_LEN} allowed",
            prefix.len()
        )));
    }
    let Some(rest) = prefix.strip_prefix('/') else {
        return Err(invalid(format!(
            "topic prefix {prefix:?} must be empty or start with '/'"
        )));
    };
    for segment in rest.split('/') {
        let ok = !segment.is_empty()
            && segment
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'));
        if !ok {
            return Err(invalid(format!(
                "topic prefix {prefix:?}: segment {segment:?} must be non-empty ASCII letters, digits, '_', '-' or '.'"
            )));
        }
    }
    Ok(())
}

/// Media type of an attachment, by file extension.
fn media_type_for(name: &str, data: &[u8]) -> &'static str {
    let ext = Path::new(name)
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    match ext.as_str() {
        "xml" => "application/xml",
        "json" => "application/json",
        _ if std::str::from_utf8(data).is_ok() => "text/plain",
        _ => "application/octet-stream",
    }
}

/// The temporary path [`create_file`] writes to: `<path>.tmp-ringscan`.
pub fn temp_path(path: &Path) -> PathBuf {
    let mut os = path.as_os_str().to_owned();
    os.push(TEMP_SUFFIX);
    PathBuf::from(os)
}

fn sync_buf_file(w: BufWriter<File>) -> io::Result<()> {
    let file = w.into_inner().map_err(io::IntoInnerError::into_error)?;
    file.sync_all()
}

/// Best effort: make the rename durable (POSIX needs the directory synced; elsewhere a no-op).
pub(crate) fn sync_parent_dir(path: &Path) {
    #[cfg(unix)]
    if let Some(dir) = path.parent() {
        let dir = if dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            dir
        };
        if let Ok(d) = File::open(dir) {
            let _ = d.sync_all();
        }
    }
    #[cfg(not(unix))]
    let _ = path;
}

/// Creates the output at `path` atomically: the sink writes `<path>.tmp-ringscan`, and
/// [`McapSink::finish`] syncs it and renames it to `path`. If the sink is dropped or
/// [`abort`](McapSink::abort)ed before that, or finishing fails, the temporary file is removed, so
/// a partial MCAP never appears at `path`. An existing file at `path` is replaced only on
/// success.
pub fn create_file(path: &Path, opts: SinkOptions) -> Result<McapSink<BufWriter<File>>, SinkError> {
    let temp = temp_path(path);
    let file = File::create(&temp).map_err(io_err(format!(
        "creating {} (written first as {})",
        path.display(),
        temp.display()
    )))?;
    let commit = FileCommit {
        temp: temp.clone(),
        target: path.to_path_buf(),
        sync: sync_buf_file,
    };
    match McapSink::new(BufWriter::with_capacity(1 << 20, file), opts) {
        Ok(mut sink) => {
            sink.commit = Some(commit);
            Ok(sink)
        }
        Err(e) => {
            let _ = std::fs::remove_file(&temp);
            Err(e)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    fn info(name: &str, prefix: &str) -> SensorInfo {
        SensorInfo {
            name: name.into(),
            topic_prefix: prefix.into(),
            ..Default::default()
        }
    }

    #[test]
    fn prefixes_are_checked() {
        let mut sink = McapSink::new(Cursor::new(Vec::new()), SinkOptions::default()).unwrap();
        for bad in ["points", "/", "/a/", "//a", "/a b", "/é"] {
            assert!(sink.add_sensor(&info("a", bad)).is_err(), "{bad:?}");
        }
        assert!(sink.add_sensor(&info("bad\0name", "")).is_err());
        let a = sink.add_sensor(&info("a", "/vlp16-201")).unwrap();
        assert_eq!(
            sink.channels(a).unwrap().points_topic(),
            "/vlp16-201/points"
        );
        let err = sink.add_sensor(&info("b", "/vlp16-201")).unwrap_err();
        assert!(err.to_string().contains("already used"), "{err}");
        let b = sink.add_sensor(&info("b", "")).unwrap();
        assert_eq!(
            sink.channels(b).unwrap().diagnostics_topic(),
            "/diagnostics"
        );
    }

    #[test]
    fn unknown_sensor_is_an_error() {
        let mut sink = McapSink::new(Cursor::new(Vec::new()), SinkOptions::default()).unwrap();
        let sweep = SweepMsg {
            log_time_ns: 1,
            timestamp_ns: 1,
            points: &[],
        };
        let err = sink.write_sweep(SensorId(3), &sweep).unwrap_err();
        assert!(
            matches!(
                err,
                SinkError::UnknownSensor {
                    id: 3,
                    registered: 0
                }
            ),
            "{err}"
        );
        let summary = sink.finish().unwrap();
        assert!(summary.messages.is_empty());
    }

    #[test]
    fn media_types_follow_the_extension() {
        assert_eq!(media_type_for("db.XML", b"<x/>"), "application/xml");
        assert_eq!(media_type_for("meta.json", b"{}"), "application/json");
        assert_eq!(media_type_for("VLP16.yaml", b"lasers: []"), "text/plain");
        assert_eq!(
            media_type_for("blob", &[0xff, 0xfe]),
            "application/octet-stream"
        );
    }

    #[test]
    fn a_file_sink_can_move_to_another_thread() {
        fn assert_send<T: Send>() {}
        assert_send::<McapSink<BufWriter<File>>>();
    }

    #[test]
    fn temp_path_appends_the_suffix() {
        assert_eq!(
            temp_path(Path::new("/x/run.mcap")),
            PathBuf::from("/x/run.mcap.tmp-ringscan")
        );
    }
}
