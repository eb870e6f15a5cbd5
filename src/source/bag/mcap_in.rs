//! MCAP files holding ROS messages, as a stream of messages.
//!
//! In: any [`Read`] holding an MCAP file (a bare `.mcap` from any ROS tool, or one file of a
//! rosbag2 bag with MCAP storage; a zstd-compressed file is handed in already decompressing).
//! Out: one message at a time in file order, with its channel (topic, schema name = type,
//! message encoding `ros1` or `cdr`) and `log_time`.
//!
//! Built on the `mcap` crate's sans-IO [`LinearReader`] for the file's top-level records, which
//! refuses any record larger than [`MAX_CHUNK_BYTES`](super::MAX_CHUNK_BYTES) before buffering
//! it. Chunks are handed over whole and opened here, not by the crate: its reader trusts the
//! record lengths inside an uncompressed chunk (a record longer than what is left of the chunk
//! underflows its count of remaining bytes: a panic with overflow checks, and reading past the
//! chunk without), so every size is checked against its container first: the compressed size
//! within the chunk record, the uncompressed size within [`MAX_CHUNK_BYTES`], the decompressed
//! length equal to it, the CRC, and each record's length within what is left of the chunk.
//! A file that ends early (no footer, a record cut short) ends the stream with `truncated_at` =
//! the bytes read; any other inconsistency (bad CRC, a chunk that does not decompress, an
//! unknown compression, a record past its chunk's end) is [`BagError::Mcap`] with the offset
//! reached.

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
    /// The records of the chunk being read (decompressed), and where the next one starts.
    chunk: Vec<u8>,
    chunk_at: usize,
    /// The chunk record as read (compressed), reused.
    chunk_raw: Vec<u8>,
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
            .with_emit_chunks(true)
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
            chunk: Vec::new(),
            chunk_at: 0,
            chunk_raw: Vec::new(),
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
        loop {
            // Records of the current chunk first.
            if self.chunk_at < self.chunk.len() {
                let at = self.chunk_at;
                let Some((opcode, range)) = chunk_record(&self.chunk, at) else {
                    self.chunk_at = self.chunk.len();
                    self.done = true;
                    return Err(self.mcap_error(format!(
                        "a record at byte {at} of a chunk runs past the chunk's end ({} bytes)",
                        self.chunk.len()
                    )));
                };
                self.chunk_at = range.end;
                let chunk = std::mem::take(&mut self.chunk);
                let got = self.on_record(opcode, &chunk[range], out);
                self.chunk = chunk;
                match got? {
                    Some(m) => return Ok(Some(m)),
                    None => continue,
                }
            }
            if self.done {
                return Ok(None);
            }
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
                    return Err(self.mcap_error(e.to_string()));
                }
            };
            match event {
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
                }
                LinearReadEvent::Record { opcode, data } if opcode == OP_CHUNK => {
                    self.chunk_raw.clear();
                    self.chunk_raw.extend_from_slice(data);
                    let mut chunk = std::mem::take(&mut self.chunk);
                    let opened = open_chunk(&self.chunk_raw, &mut chunk);
                    self.chunk = chunk;
                    self.chunk_at = 0;
                    if let Err(reason) = opened {
                        self.chunk.clear();
                        self.done = true;
                        return Err(self.mcap_error(reason));
                    }
                }
                LinearReadEvent::Record { opcode, data } => {
                    // Copied out of the reader's buffer: `on_record` needs `self` whole.
                    self.chunk_raw.clear();
                    self.chunk_raw.extend_from_slice(data);
                    let raw = std::mem::take(&mut self.chunk_raw);
                    let got = self.on_record(opcode, &raw, out);
                    self.chunk_raw = raw;
                    if let Some(m) = got? {
                        return Ok(Some(m));
                    }
                }
            }
        }
    }

    fn mcap_error(&self, reason: String) -> BagError {
        BagError::Mcap {
            offset: self.offset,
            reason,
        }
    }

    /// One record (top level or inside a chunk): schemas and channels are remembered, a message
    /// is returned (its bytes in `out`).
    fn on_record(
        &mut self,
        opcode: u8,
        data: &[u8],
        out: &mut Vec<u8>,
    ) -> Result<Option<RawMessage>, BagError> {
        // Only the records that matter here are parsed (the crate's parser checks their fields).
        if !matches!(opcode, OP_SCHEMA | OP_CHANNEL | OP_MESSAGE) {
            return Ok(None);
        }
        let record = match mcap::parse_record(opcode, data) {
            Ok(r) => r,
            Err(e) => {
                self.done = true;
                self.chunk_at = self.chunk.len();
                return Err(self.mcap_error(e.to_string()));
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
                    return Ok(None);
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
        Ok(None)
    }
}

const OP_SCHEMA: u8 = 0x03;
const OP_CHANNEL: u8 = 0x04;
const OP_MESSAGE: u8 = 0x05;
const OP_CHUNK: u8 = 0x06;

/// Little-endian integers at `at` of `b`, if they are there.
fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(
        b.get(at..at.checked_add(4)?)?.try_into().ok()?,
    ))
}

fn u64_at(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(
        b.get(at..at.checked_add(8)?)?.try_into().ok()?,
    ))
}

/// The record at `at` of a chunk's records: its opcode and the range of its body, when its
/// 9-byte opcode and length and its whole body lie within `records`.
fn chunk_record(records: &[u8], at: usize) -> Option<(u8, std::ops::Range<usize>)> {
    let opcode = *records.get(at)?;
    let len = usize::try_from(u64_at(records, at + 1)?).ok()?;
    let start = at + 9;
    let end = start.checked_add(len)?;
    (end <= records.len()).then_some((opcode, start..end))
}

/// Opens a Chunk record's body (MCAP specification, "Chunk (op=0x06)": `message_start_time`
/// u64, `message_end_time` u64, `uncompressed_size` u64, `uncompressed_crc` u32, `compression`
/// string (u32 length + bytes), `compressed_size` u64, then the records) into `out`: every size
/// checked against its container before anything is allocated or decompressed.
fn open_chunk(body: &[u8], out: &mut Vec<u8>) -> Result<(), String> {
    out.clear();
    let short = || {
        format!(
            "chunk record of {} bytes is shorter than its header",
            body.len()
        )
    };
    let uncompressed_size = u64_at(body, 16).ok_or_else(short)?;
    let crc = u32_at(body, 24).ok_or_else(short)?;
    let name_len = u32_at(body, 28).ok_or_else(short)? as usize;
    let name_end = 32usize.checked_add(name_len).ok_or_else(short)?;
    let compression = body.get(32..name_end).ok_or_else(short)?;
    let compressed_size = u64_at(body, name_end).ok_or_else(short)?;
    let records_at = name_end + 8;
    let left = body.len() - records_at;
    let records = usize::try_from(compressed_size)
        .ok()
        .and_then(|n| body.get(records_at..records_at.checked_add(n)?))
        .ok_or_else(|| {
            format!("chunk claims {compressed_size} compressed bytes; its record holds {left}")
        })?;
    let size = usize::try_from(uncompressed_size)
        .ok()
        .filter(|&n| n <= MAX_CHUNK_BYTES)
        .ok_or_else(|| {
            format!(
                "chunk claims {uncompressed_size} uncompressed bytes, more than the {MAX_CHUNK_BYTES} accepted"
            )
        })?;
    let inflated = match compression {
        b"" => {
            out.extend_from_slice(records);
            true
        }
        b"zstd" => match zstd::stream::read::Decoder::with_buffer(records) {
            Ok(d) => inflate(d, size, out),
            Err(_) => false,
        },
        b"lz4" => match lz4::Decoder::new(records) {
            Ok(d) => inflate(d, size, out),
            Err(_) => false,
        },
        other => {
            return Err(format!(
                "chunk compression {:?} is not supported (zstd, lz4 or none)",
                String::from_utf8_lossy(other)
            ))
        }
    };
    if !inflated || out.len() != size {
        return Err(format!(
            "chunk ({}) does not decompress to the {size} bytes it claims",
            String::from_utf8_lossy(compression)
        ));
    }
    if crc != 0 {
        let found = crc32fast::hash(out);
        if found != crc {
            return Err(format!(
                "chunk CRC mismatch: recorded {crc:08x}, computed {found:08x}"
            ));
        }
    }
    Ok(())
}

/// Decompresses into `out`; false when it fails or gives more than `size` bytes.
fn inflate(d: impl Read, size: usize, out: &mut Vec<u8>) -> bool {
    match d.take(size as u64 + 1).read_to_end(out) {
        Ok(n) => n <= size,
        Err(_) => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chunk record body written out by hand from the MCAP specification.
    fn chunk_body(compression: &str, uncompressed: u64, crc: u32, records: &[u8]) -> Vec<u8> {
        let mut b = Vec::new();
        b.extend_from_slice(&1u64.to_le_bytes()); // message_start_time
        b.extend_from_slice(&2u64.to_le_bytes()); // message_end_time
        b.extend_from_slice(&uncompressed.to_le_bytes());
        b.extend_from_slice(&crc.to_le_bytes());
        b.extend_from_slice(&(compression.len() as u32).to_le_bytes());
        b.extend_from_slice(compression.as_bytes());
        b.extend_from_slice(&(records.len() as u64).to_le_bytes());
        b.extend_from_slice(records);
        b
    }

    #[test]
    fn a_record_longer_than_its_chunk_is_refused() {
        // One record: opcode 0x05, length 1000, but only 4 body bytes follow.
        let mut records = vec![0x05];
        records.extend_from_slice(&1000u64.to_le_bytes());
        records.extend_from_slice(&[1, 2, 3, 4]);
        let mut out = Vec::new();
        open_chunk(&chunk_body("", 13, 0, &records), &mut out).unwrap();
        assert_eq!(chunk_record(&out, 0), None);
        // Length 4 fits exactly.
        records[1..9].copy_from_slice(&4u64.to_le_bytes());
        open_chunk(&chunk_body("", 13, 0, &records), &mut out).unwrap();
        assert_eq!(chunk_record(&out, 0), Some((0x05, 9..13)));
        assert_eq!(chunk_record(&out, 13), None);
        // A length whose end overflows usize.
        records[1..9].copy_from_slice(&u64::MAX.to_le_bytes());
        open_chunk(&chunk_body("", 13, 0, &records), &mut out).unwrap();
        assert_eq!(chunk_record(&out, 0), None);
    }

    #[test]
    fn chunk_sizes_are_checked_against_their_container() {
        let mut out = Vec::new();
        // compressed_size past the record's end.
        let mut b = chunk_body("", 4, 0, &[0; 4]);
        let at = b.len() - 12;
        b[at..at + 8].copy_from_slice(&5u64.to_le_bytes());
        assert!(open_chunk(&b, &mut out)
            .unwrap_err()
            .contains("compressed bytes"));
        // A 1 TB uncompressed claim.
        let e = open_chunk(&chunk_body("zstd", 1 << 40, 0, &[0; 4]), &mut out).unwrap_err();
        assert!(e.contains("uncompressed bytes"), "{e}");
        // Uncompressed: the size must match the records.
        assert!(open_chunk(&chunk_body("", 3, 0, &[0; 4]), &mut out).is_err());
        // Garbage that is not zstd / lz4; an unknown compression; a header cut short.
        assert!(open_chunk(&chunk_body("zstd", 4, 0, &[1, 2, 3, 4]), &mut out).is_err());
        assert!(open_chunk(&chunk_body("lz4", 4, 0, &[1, 2, 3, 4]), &mut out).is_err());
        assert!(open_chunk(&chunk_body("bz2", 4, 0, &[0; 4]), &mut out).is_err());
        assert!(open_chunk(&[0; 20], &mut out).is_err());
        // CRC-32 (IEEE) of "123456789" is 0xcbf43926 (the check value of the CRC catalogue).
        assert!(open_chunk(&chunk_body("", 9, 0xcbf4_3926, b"123456789"), &mut out).is_ok());
        assert!(open_chunk(&chunk_body("", 9, 0xcbf4_3927, b"123456789"), &mut out).is_err());
    }
}
