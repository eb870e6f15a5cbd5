//! One input file, whatever it is: a pcap / pcapng capture or a ROS bag, told apart by its bytes
//! ([`crate::source::bag::detect`]); both give the same datagrams. The command line's `decode`,
//! `info` and `replay` and the Python package read through it.

use std::fs::File;
use std::io::{BufReader, Read};
use std::path::Path;

use serde_json::{json, Value};

use crate::source::bag::{self, BagOptions, BagSource};
use crate::source::pcap::{PcapSource, SourceError};
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
}

/// A capture or a bag.
pub enum Input<R: Read> {
    /// A pcap or pcapng capture.
    Pcap(Box<PcapSource<R>>),
    /// A ROS 1 bag, a rosbag2 directory or a bare `.db3` / `.mcap` bag file.
    Bag(Box<BagSource>),
}

/// Opens `path` as a bag when its bytes say so (read with `bag_options`), else as a capture.
pub fn open(path: &Path, bag_options: BagOptions) -> Result<Input<Box<dyn Read>>, InputError> {
    // A path that cannot be read gets the capture reader's error message.
    if let Ok(Some(_)) = bag::detect(path) {
        let source = BagSource::open(path, bag_options)?;
        return Ok(Input::Bag(Box::new(source)));
    }
    let file = File::open(path).map_err(|source| SourceError::Open {
        path: path.to_path_buf(),
        source,
    })?;
    let reader: Box<dyn Read> = Box::new(BufReader::with_capacity(1 << 16, file));
    Ok(Input::Pcap(Box::new(PcapSource::new(reader)?)))
}

impl<R: Read> Input<R> {
    /// The next datagram.
    pub fn next_datagram(&mut self) -> Result<Option<Datagram<'_>>, InputError> {
        match self {
            Self::Pcap(s) => Ok(s.next_datagram()?),
            Self::Bag(s) => Ok(s.next_datagram()?),
        }
    }

    /// Bytes consumed so far (progress).
    pub fn bytes(&self) -> u64 {
        match self {
            Self::Pcap(s) => s.stats().bytes,
            Self::Bag(s) => s.stats().bytes,
        }
    }

    /// The bag, if the input is one.
    pub fn bag(&self) -> Option<&BagSource> {
        match self {
            Self::Pcap(_) => None,
            Self::Bag(b) => Some(b),
        }
    }

    /// The summary's `capture` object.
    pub fn capture_json(&self) -> Value {
        let duration = |a: Option<i64>, b: Option<i64>| match (a, b) {
            (Some(a), Some(b)) => (b - a) as f64 * 1e-9,
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
            Self::Bag(b) => {
                let st = b.stats();
                let kind = match b.kind() {
                    bag::BagKind::File(k) => format!("{k:?}"),
                    bag::BagKind::Rosbag2(_) => "rosbag2".to_string(),
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
