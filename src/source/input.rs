//! One input file, whatever it is: a pcap / pcapng capture, a ROS bag or a Livox Viewer
//! recording (`.lvx` / `.lvx2`), told apart by its bytes ([`crate::source::bag::detect`],
//! [`crate::source::lvx::detect`]); all give the same datagrams. The command line's `decode`,
//! `info` and `replay` and the Python package read through it.

use std::fs::File;
use std::io::{BufReader, Read};
use std::path::Path;

use serde_json::{json, Value};

use crate::sensor::livox::lvx as lvx_format;
use crate::source::bag::{self, BagOptions, BagSource};
use crate::source::lvx::{self, LvxError, LvxSource};
use crate::source::pcap::{PcapSource, SourceError};
use crate::source::read_ahead::ReadAhead;
use crate::source::Datagram;

/// Why an input could not be read.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    /// A capture.
    #[error(transparent)]
    Pcap(#[from] SourceError),
    /// A bag.
    #[error(transparent)]
    Bag(#[from] bag::BagError),
    /// A Livox recording.
    #[error(transparent)]
    Lvx(#[from] LvxError),
    /// A file whose first bytes are the magic of no format ringscan reads.
    #[error(
        "not a capture, bag or Livox recording: its first bytes {} are the magic number of none \
         of pcap (a1b2c3d4 or a1b23c4d, either byte order), pcapng (0a0d0d0a), ROS 1 bag \
         (#ROSBAG V2.0), rosbag2 sqlite3 (SQLite format 3), MCAP (89 MCAP0), zstd (28b52ffd) \
         or Livox .lvx / .lvx2 (livox_tech)",
        hex(found)
    )]
    Unrecognised {
        /// The first bytes of the file (at most 16).
        found: Vec<u8>,
    },
    /// A zstd file that does not decompress to a bag's storage file.
    #[error(
        "a zstd-compressed file (magic 28 b5 2f fd) whose start does not decompress to a \
         rosbag2 storage file (sqlite3 or MCAP): {why}"
    )]
    ZstdNotABag {
        /// What decompressing its first bytes gave.
        why: String,
    },
    /// A directory that is no rosbag2 one.
    #[error("a directory without a metadata.yaml: not a rosbag2 directory")]
    NotABagDirectory,
}

fn hex(b: &[u8]) -> String {
    b.iter()
        .map(|x| format!("{x:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// A capture, a bag or a Livox recording.
pub enum Input<R: Read> {
    /// A pcap or pcapng capture.
    Pcap(Box<PcapSource<R>>),
    /// A ROS 1 bag, a rosbag2 directory or a bare `.db3` / `.mcap` bag file.
    Bag(Box<BagSource>),
    /// A Livox Viewer recording.
    Lvx(Box<LvxSource<R>>),
}

/// Opens `path` as a bag or a Livox recording when its bytes say so (a bag read with
/// `bag_options`), else as a capture.
pub fn open(path: &Path, bag_options: BagOptions) -> Result<Input<Box<dyn Read>>, InputError> {
    open_with(path, bag_options, false)
}

/// [`open`], with a capture or a Livox recording read on a thread of its own a few blocks
/// ahead of the parser when `read_ahead` ([`super::read_ahead`]; for a caller with a spare
/// core). Bags are read by their own readers either way.
pub fn open_with(
    path: &Path,
    bag_options: BagOptions,
    read_ahead: bool,
) -> Result<Input<Box<dyn Read>>, InputError> {
    if is_lvx_file(path) {
        let reader = file_reader(path, read_ahead)?;
        return Ok(Input::Lvx(Box::new(LvxSource::new(reader)?)));
    }
    // A path that cannot be read gets the capture reader's error message.
    if let Ok(Some(_)) = bag::detect(path) {
        let source = BagSource::open(path, bag_options)?;
        return Ok(Input::Bag(Box::new(source)));
    }
    if path.is_dir() {
        return Err(InputError::NotABagDirectory);
    }
    // The capture reader is the last tried: when it finds no magic either, no format's was
    // there.
    let capture = |r: Result<PcapSource<Box<dyn Read>>, SourceError>| match r {
        Ok(p) => Ok(Input::Pcap(Box::new(p))),
        Err(SourceError::BadMagic { .. }) => {
            let mut found = Vec::with_capacity(16);
            let _ = File::open(path).and_then(|f| f.take(16).read_to_end(&mut found));
            if let Some(why) = bag::zstd_start(path) {
                return Err(InputError::ZstdNotABag { why });
            }
            Err(InputError::Unrecognised { found })
        }
        Err(e) => Err(e.into()),
    };
    if read_ahead {
        if let Ok(ahead) = ReadAhead::spawn(open_file(path)?, "ringscan-read-ahead") {
            return capture(PcapSource::read_ahead(ahead));
        }
    }
    capture(PcapSource::new(file_reader(path, false)?))
}

fn open_file(path: &Path) -> Result<File, SourceError> {
    File::open(path).map_err(|source| SourceError::Open {
        path: path.to_path_buf(),
        source,
    })
}

/// The file's bytes, buffered, or read ahead on a thread (the buffered reader if the thread
/// cannot be started).
fn file_reader(path: &Path, read_ahead: bool) -> Result<Box<dyn Read>, SourceError> {
    if read_ahead {
        if let Ok(r) = ReadAhead::spawn(open_file(path)?, "ringscan-read-ahead") {
            return Ok(Box::new(r));
        }
    }
    Ok(Box::new(BufReader::with_capacity(
        1 << 16,
        open_file(path)?,
    )))
}

/// Whether the file at `path` starts like a Livox recording.
fn is_lvx_file(path: &Path) -> bool {
    let mut head = [0u8; 24];
    File::open(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .is_ok()
        && lvx::detect(&head)
}

impl<R: Read> Input<R> {
    /// The next datagram.
    pub fn next_datagram(&mut self) -> Result<Option<Datagram<'_>>, InputError> {
        match self {
            Self::Pcap(s) => Ok(s.next_datagram()?),
            Self::Bag(s) => Ok(s.next_datagram()?),
            Self::Lvx(s) => Ok(s.next_datagram()?),
        }
    }

    /// Bytes consumed so far (progress).
    pub fn bytes(&self) -> u64 {
        match self {
            Self::Pcap(s) => s.stats().bytes,
            Self::Bag(s) => s.stats().bytes,
            Self::Lvx(s) => s.stats().bytes,
        }
    }

    /// The bag, if the input is one.
    pub fn bag(&self) -> Option<&BagSource> {
        match self {
            Self::Bag(b) => Some(b),
            _ => None,
        }
    }

    /// The `--model` the input itself names (a Livox recording's device type, when all its
    /// devices are of one known model): SDK1 packets do not name their model.
    pub fn model_hint(&self) -> Option<&'static str> {
        match self {
            Self::Lvx(s) => s.model().map(|m| m.id()),
            _ => None,
        }
    }

    /// The summary's `capture` object.
    pub fn capture_json(&self) -> Value {
        let duration = |a: Option<i64>, b: Option<i64>| match (a, b) {
            (Some(a), Some(b)) => span_s(a, b),
            _ => 0.0,
        };
        match self {
            Self::Pcap(s) => {
                let cap = s.stats();
                json!({
                    "records": cap.records,
                    "bytes": cap.bytes,
                    "datagrams": cap.datagrams,
                    "non_udp": cap.non_udp,
                    "malformed_records": cap.malformed,
                    "fragments": cap.fragments,
                    "reassembled": cap.reassembled,
                    "fragments_expired": cap.fragments_expired,
                    "truncated_records": cap.truncated_records,
                    "truncated_tail_offset": cap.truncated_tail,
                    "duration_s": duration(cap.first_time_ns, cap.last_time_ns),
                })
            }
            Self::Lvx(s) => {
                let st = s.stats();
                let devices: Vec<Value> = s
                    .devices()
                    .iter()
                    .enumerate()
                    .map(|(i, d)| {
                        json!({
                            "address": LvxSource::<R>::address(i).map(|a| a.to_string()),
                            "lidar_sn": d.lidar_sn,
                            "hub_sn": d.hub_sn,
                            "id": d.id,
                            "device_type": d.device_type,
                            "model": d.model.map(|m| m.name()),
                            "extrinsic_rpy_deg_xyz_m": d.extrinsic,
                        })
                    })
                    .collect();
                json!({
                    "records": st.packages,
                    "bytes": st.bytes,
                    "datagrams": st.datagrams,
                    "non_udp": 0,
                    "malformed_records": st.malformed_packages,
                    "fragments": 0,
                    "reassembled": 0,
                    "fragments_expired": 0,
                    "truncated_records": 0,
                    "truncated_tail_offset": st.truncated_at,
                    "duration_s": duration(st.first_time_ns, st.last_time_ns),
                    "lvx": {
                        "version": match s.version() {
                            lvx_format::LvxVersion::Lvx1 => "lvx 1.1",
                            lvx_format::LvxVersion::Lvx2 => "lvx2 2.0",
                        },
                        "frame_duration_ms": s.frame_duration_ms(),
                        "frames": st.frames,
                        "packages": st.packages,
                        "malformed_packages": st.malformed_packages,
                        "first_malformed": st.first_malformed.as_ref().map(|(o, w)| json!({"offset": o, "reason": w})),
                        "unknown_device": st.unknown_device,
                        "device_limit": st.device_limit,
                        "truncated_at": st.truncated_at,
                        "devices": devices,
                    },
                })
            }
            Self::Bag(b) => {
                let st = b.stats();
                let kind = match b.kind() {
                    bag::BagKind::File(k) => k.name(),
                    bag::BagKind::Rosbag2(_) => "rosbag2 directory",
                };
                let sensors: Vec<Value> = b
                    .sensors()
                    .iter()
                    .map(|s| {
                        json!({
                            "namespace": s.namespace,
                            "family": s.family.name(),
                            "address": s.address.to_string(),
                            "data_port": s.data_port,
                            "aux_port": s.aux_port,
                            "topics": s.topics,
                            "metadata_in_bag": s.metadata.is_some(),
                        })
                    })
                    .collect();
                json!({
                    "records": st.messages,
                    "bytes": st.bytes,
                    "datagrams": st.datagrams,
                    "non_udp": 0,
                    "malformed_records": st.malformed,
                    "fragments": 0,
                    "reassembled": 0,
                    "fragments_expired": 0,
                    "truncated_records": 0,
                    "truncated_tail_offset": st.truncated_at.as_ref().map(|t| t.1),
                    "duration_s": duration(st.first_time_ns, st.last_time_ns),
                    "bag": {
                        "kind": kind,
                        "messages": st.messages,
                        "packet_messages": st.packet_messages,
                        "metadata_messages": st.metadata_messages,
                        "metadata_dropped": st.metadata_dropped,
                        "unselected": st.unselected,
                        "outside_time": st.outside_time,
                        "unknown_type": st.unknown_type,
                        "malformed": st.malformed,
                        "first_malformed": st.first_malformed,
                        "oversized": st.oversized,
                        "bad_compressed_messages": st.bad_compressed_messages,
                        "bad_chunks": st.bad_chunks,
                        "first_bad_chunk": st.first_bad_chunk.as_ref().map(|(p, o)| json!({"file": p.display().to_string(), "offset": o})),
                        "sensor_limit": st.sensor_limit,
                        "truncated_at": st.truncated_at.as_ref().map(|(p, o)| json!({"file": p.display().to_string(), "offset": o})),
                        "sensors": sensors,
                    },
                })
            }
        }
    }
}

/// Seconds from `a` to `b` (ns). A bag's times can lie anywhere in i64 (a header stamp of −1 s,
/// an MCAP log time of 2^64 − 1 read as i64::MAX), so the difference is taken in i128.
fn span_s(a: i64, b: i64) -> f64 {
    (i128::from(b) - i128::from(a)) as f64 * 1e-9
}

#[cfg(test)]
mod tests {
    use super::span_s;

    #[test]
    fn capture_spans_at_the_ends_of_i64_do_not_overflow() {
        assert_eq!(span_s(1_000_000_000, 3_500_000_000), 2.5);
        // 2^63 − 1 ns + 1 s, and −(2^64 − 1) ns, to the µs.
        assert!((span_s(-1_000_000_000, i64::MAX) - 9_223_372_037.854_776).abs() < 1e-5);
        assert!((span_s(i64::MAX, i64::MIN) + 18_446_744_073.709_552).abs() < 1e-5);
    }
}
