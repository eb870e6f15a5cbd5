//! MCAP files holding ROS messages, as a stream of messages.
//!
//! In: any [`Read`] holding an MCAP file (a bare `.mcap` from any ROS tool, or one file of a
//! rosbag2 bag with MCAP storage; a zstd-compressed file is handed in already decompressing).
//! Out: one message at a time in file order, with its channel (topic, schema name = type,
//! message encoding `ros1` or `cdr`) and `log_time`.
//!
//! Built on the `mcap` crate's sans-IO [`LinearReader`]: it decompresses one chunk at a time
//! (zstd, lz4), checks chunk CRCs, and refuses any record or chunk larger than
//! [`MAX_CHUNK_BYTES`](super::MAX_CHUNK_BYTES) before buffering it. A file that ends early
//! (no footer, a record cut short) ends the stream with `truncated_at` = the bytes read; any
//! other inconsistency (bad CRC, a chunk that does not decompress, an unknown compression) is
//! [`BagError::Mcap`] with the offset reached.

use std::collections::HashMap;
use std::io::Read;

use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
use mcap::McapError;

use super::messages::Encoding;
use super::{BagError, Connection, RawMessage, MAX_CHUNK_BYTES, MAX_MESSAGE_BYTES};

/// The MCAP magic.
pub const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// Bytes asked of the input at most per read.
const READ_SIZE: usize = 1 << 20;

/// Messages of an MCAP file. See the [module documentation](self).
pub struct McapReader<R: Read> {
    reader: R,
    linear: LinearReader,
    offset: u64,
    /// Schema id → (name, encoding).
    schemas: HashMap<u16, (String, String)>,
    channels: HashMap<u16, Connection>,
    order: Vec<u16>,
    /// Messages larger than [`MAX_MESSAGE_BYTES`], skipped.
    pub(crate) oversized: u64,
    pub(crate) truncated_at: Option<u64>,
    done: bool,
}

fn encoding_of(message_encoding: &str) -> Option<Encoding> {
    match message_encoding {
        "ros1" => Some(Encoding::Ros1),
        "cdr" => Some(Encoding::Cdr),
        _ => None,
    }
}

impl<R: Read> McapReader<R> {
    /// A reader at the start of an MCAP file (the magic is checked on the first read).
    pub fn new(reader: R) -> Self {
        let options = LinearReaderOptions::default()
            .with_validate_chunk_crcs(true)
            .with_record_length_limit(MAX_CHUNK_BYTES);
        Self {
            reader,
            linear: LinearReader::new_with_options(options),
            offset: 0,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            order: Vec::new(),
            oversized: 0,
            truncated_at: None,
            done: false,
        }
    }

    /// File bytes read so far.
    pub fn offset(&self) -> u64 {
        self.offset
    }

    /// The channel `id`.
    pub fn connection(&self, id: u64) -> Option<&Connection> {
        u16::try_from(id).ok().and_then(|i| self.channels.get(&i))
    }

    /// Every channel known so far, in order of appearance.
    pub fn connections(&self) -> Vec<(u64, Connection)> {
        self.order
            .iter()
            .filter_map(|id| Some((u64::from(*id), self.channels.get(id)?.clone())))
            .collect()
    }

    /// The next message: its bytes go to `out`.
    pub fn next_message(&mut self, out: &mut Vec<u8>) -> Result<Option<RawMessage>, BagError> {
        if self.done {
            return Ok(None);
        }
        loop {
            let event = match self.linear.next_event() {
                None => {
                    self.done = true;
                    return Ok(None);
                }
                Some(Ok(e)) => e,
                Some(Err(McapError::UnexpectedEof)) => {
                    self.done = true;
                    self.truncated_at = Some(self.offset);
                    return Ok(None);
                }
                Some(Err(e)) => {
                    self.done = true;
                    return Err(BagError::Mcap {
                        offset: self.offset,
                        reason: e.to_string(),
                    });
                }
            };
            let (opcode, data) = match event {
                LinearReadEvent::ReadRequest(need) => {
                    let need = need.clamp(1, READ_SIZE);
                    let buf = self.linear.insert(need);
                    let got = loop {
                        match self.reader.read(buf) {
                            Ok(n) => break n.min(need),
                            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                            Err(source) => {
                                self.done = true;
                                return Err(BagError::Io {
                                    offset: self.offset,
                                    source,
                                });
                            }
                        }
                    };
                    self.offset += got as u64;
                    self.linear.notify_read(got);
                    continue;
                }
                LinearReadEvent::Record { opcode, data } => (opcode, data),
            };
            let record = match mcap::parse_record(opcode, data) {
                Ok(r) => r,
                Err(e) => {
                    self.done = true;
                    return Err(BagError::Mcap {
                        offset: self.offset,
                        reason: e.to_string(),
                    });
                }
            };
            match record {
                Record::Schema { header, .. } => {
                    self.schemas
                        .insert(header.id, (header.name, header.encoding));
                }
                Record::Channel(c) => {
                    let type_name = self
                        .schemas
                        .get(&c.schema_id)
                        .map(|(n, _)| n.clone())
                        .unwrap_or_default();
                    if !self.channels.contains_key(&c.id) {
                        self.order.push(c.id);
                    }
                    self.channels.insert(
                        c.id,
                        Connection {
                            topic: c.topic,
                            type_name,
                            encoding: encoding_of(&c.message_encoding),
                        },
                    );
                }
                Record::Message { header, data } => {
                    if data.len() > MAX_MESSAGE_BYTES {
                        self.oversized += 1;
                        continue;
                    }
                    out.clear();
                    out.extend_from_slice(&data);
                    return Ok(Some(RawMessage {
                        conn: u64::from(header.channel_id),
                        time_ns: i64::try_from(header.log_time).unwrap_or(i64::MAX),
                    }));
                }
                _ => {}
            }
        }
    }
}
