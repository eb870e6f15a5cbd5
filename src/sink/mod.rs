//! Sinks: where decoded sweeps go.
//!
//! [`McapSink`] writes an [MCAP](https://mcap.dev) file that Foxglove, the `mcap` CLI and the
//! official MCAP readers open directly:
//!
//! | topic | schema | message encoding |
//! | --- | --- | --- |
//! | `<prefix>/points` | `foxglove.PointCloud` (protobuf) or `sensor_msgs/msg/PointCloud2` (`ros2msg`) | `protobuf` / `cdr` |
//! | `<prefix>/diagnostics` | `ringscan.Diagnostics` (`jsonschema`) | `json` |
//! | `<prefix>/raw` | `ringscan.RawPacket` (protobuf, see [`foxglove::RAW_PACKET_SCHEMA`]) | `protobuf` |
//! | `<prefix>/ground`, `<prefix>/obstacles` | `foxglove.PointCloud` (protobuf; obstacles add a `cluster` field) | `protobuf` |
//! | `<prefix>/clusters` | `foxglove.SceneUpdate` (protobuf, one cube per cluster, see [`scene`]) | `protobuf` |
//! | `/tf_static` | `foxglove.FrameTransform` (protobuf: `base_link` → each sensor with `--extrinsics`) | `protobuf` |
//!
//! `<prefix>` is [`SensorInfo::topic_prefix`]: empty for a single sensor, `/<name>` when there are
//! several. Calibration files are stored as MCAP attachments. The file is chunked, compressed
//! (zstd by default; on [`SinkOptions::threads`] worker threads, written in order: see
//! [`mcap_write`]) and ends with a summary section (schemas, channels, statistics, chunk and
//! attachment indexes), so readers seek instead of scanning.
//!
//! [`live_view`] (feature `serve`) publishes the same messages live over the Foxglove WebSocket
//! protocol.
//!
//! [`create_file`] writes to `<path>.tmp-ringscan` and renames it into place only when
//! [`McapSink::finish`] succeeds; a sink that is dropped or aborted removes its temporary file, so
//! a half-written MCAP never appears at the target path.

pub mod foxglove;
#[cfg(feature = "serve")]
pub mod live_view;
pub mod mcap;
pub mod mcap_write;
pub mod read;
pub mod ros2;
pub mod ros2_msgs;
pub mod rosbag2;
pub mod scene;

pub use self::mcap::{
    create_file, temp_path, AttachmentSummary, Behind, Compression, Format, McapSink, PointFields,
    SensorChannels, SensorId, SensorInfo, SinkError, SinkOptions, SinkSummary, SweepMsg, TopicId,
    TopicSchema, DEFAULT_CHUNK_SIZE,
};
