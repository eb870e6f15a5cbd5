//! MCAP files holding ROS messages, as a stream of messages.
//!
//! In: any [`Read`] holding an MCAP file (a bare `.mcap` from any ROS tool, or one file of a
//! rosbag2 bag with MCAP storage; a zstd-compressed file is handed in already decompressing).
//! Out: one message at a time in file order, with its channel (topic, schema name = type,
//! message encoding `ros1` or `cdr`) and `log_time`.
//!
//! The file's top-level records are framed here (opcode, u64 length, body), each body read once
//! into a reused buffer: a message of an uncompressed chunk is handed on where it lies in that
//! buffer, not copied (the `mcap` crate's linear reader copied every byte into buffers of its
//! own, zeroed first, which made an MCAP bag 40 % slower to decode than its pcap). A record
//! longer than [`MAX_CHUNK_BYTES`] is refused before anything is read
//! into memory, and a buffer grows only as the bytes arrive. Schema and channel records are
//! parsed by the `mcap` crate (it checks their fields); message records and chunks are opened
//! here, every size checked against its container first: the compressed size within the chunk
//! record, the uncompressed size within [`MAX_CHUNK_BYTES`], the decompressed length equal to
//! it, the CRC, and each record's length within what is left of the chunk (the crate's own
//! chunk reader trusted those lengths: a record longer than what is left of its chunk
//! underflowed its count of remaining bytes).
//! A file that ends early (no footer, a record cut short) ends the stream with `truncated_at` =
//! the bytes read; any other inconsistency (bad magic, bad CRC, a chunk that does not
//! decompress, an unknown compression, a record past its chunk's end) is [`BagError::Mcap`]
//! with the offset reached; so are more than [`MAX_CONNECTIONS`] channels or schemas, and a
//! topic or schema name longer than [`MAX_NAME_BYTES`] (they are kept to the end of the file).

use std::collections::HashMap;
use std::io::Read;

use std::ops::Range;

use mcap::records::Record;

use super::messages::Encoding;
use super::{
    fill, inflate_exact, read_up_to, BagError, Connection, RawMessage, MAX_CHUNK_BYTES,
    MAX_CONNECTIONS, MAX_MESSAGE_BYTES, MAX_NAME_BYTES,
};

/// The MCAP magic.
pub const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// Messages of an MCAP file. See the [module documentation](self).
pub struct McapReader<R: Read> {
    reader: R,
    offset: u64,
    magic_checked: bool,
    /// Schema id → name.
    schemas: HashMap<u16, String>,
    channels: HashMap<u16, Connection>,
    order: Vec<u16>,
    /// Messages larger than [`MAX_MESSAGE_BYTES`], skipped.
    pub(crate) oversized: u64,
    pub(crate) truncated_at: Option<u64>,
    done: bool,
    /// The body of the last top-level record read (a chunk as stored, a schema, ...). Buffers
    /// are never shrunk: only their first bytes, up to the record's length, are its.
    body: Vec<u8>,
    /// A compressed chunk's records, decompressed.
    inflated: Vec<u8>,
    /// The chunk records being walked: in `inflated` (else in `body`), the first one's offset,
    /// the next one's, and their end.
    records_inflated: bool,
    records_start: usize,
    chunk_at: usize,
    chunk_end: usize,
    /// The data of the message last returned: in `inflated` (else in `body`).
    msg_inflated: bool,
    msg: Range<usize>,
}

fn encoding_of(message_encoding: &str) -> Option<Encoding> {
    match message_encoding {
        "ros1" => Some(Encoding::Ros1),
        "cdr" => Some(Encoding::Cdr),
        "protobuf" => Some(Encoding::Protobuf),
        _ => None,
    }
}

impl<R: Read> McapReader<R> {
    /// A reader at the start of an MCAP file (the magic is checked on the first read).
    pub fn new(reader: R) -> Self {
        Self {
            reader,
            offset: 0,
            magic_checked: false,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            order: Vec::new(),
            oversized: 0,
            truncated_at: None,
            done: false,
            body: Vec::new(),
            inflated: Vec::new(),
            records_inflated: false,
            records_start: 0,
            chunk_at: 0,
            chunk_end: 0,
            msg_inflated: false,
            msg: 0..0,
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

    /// How many channels [`Self::connections_from`] lists from 0 (it only grows).
    pub fn connection_count(&self) -> usize {
        self.order.len()
    }

    /// The channels known so far from the `first`-th on, in order of appearance.
    pub fn connections_from(&self, first: usize) -> Vec<(u64, Connection)> {
        self.order
            .get(first..)
            .unwrap_or_default()
            .iter()
            .filter_map(|id| Some((u64::from(*id), self.channels.get(id)?.clone())))
            .collect()
    }

    /// The bytes of the message last returned by [`Self::next_message`].
    pub fn message(&self) -> &[u8] {
        let buf = if self.msg_inflated {
            &self.inflated
        } else {
            &self.body
        };
        buf.get(self.msg.clone()).unwrap_or(&[])
    }

    fn io_error(&mut self, source: std::io::Error) -> BagError {
        self.done = true;
        BagError::Io {
            offset: self.offset,
            source,
        }
    }

    /// The file ends here, early.
    fn cut(&mut self) -> Result<Option<RawMessage>, BagError> {
        self.done = true;
        self.truncated_at = Some(self.offset);
        Ok(None)
    }

    /// The next message ([`Self::message`]); `Ok(None)` at the end (or where the file is cut).
    pub fn next_message(&mut self) -> Result<Option<RawMessage>, BagError> {
        loop {
            // Records of the current chunk first.
            if self.chunk_at < self.chunk_end {
                let at = self.chunk_at;
                let records = if self.records_inflated {
                    &self.inflated[..self.chunk_end]
                } else {
                    &self.body[..self.chunk_end]
                };
                let Some((opcode, range)) = chunk_record(records, at) else {
                    let (at, len) = (at - self.records_start, self.chunk_end - self.records_start);
                    self.chunk_at = self.chunk_end;
                    self.done = true;
                    return Err(self.mcap_error(format!(
                        "a record at byte {at} of a chunk runs past the chunk's end ({len} bytes)"
                    )));
                };
                self.chunk_at = range.end;
                match self.on_record(opcode, self.records_inflated, range)? {
                    Some(m) => return Ok(Some(m)),
                    None => continue,
                }
            }
            if self.done {
                return Ok(None);
            }
            if !self.magic_checked {
                let mut magic = [0u8; 8];
                let n = read_up_to(&mut self.reader, &mut magic).map_err(|e| self.io_error(e))?;
                self.offset += n as u64;
                if magic[..n] != MAGIC[..n] {
                    self.done = true;
                    return Err(self.mcap_error("not an MCAP file (its magic differs)".into()));
                }
                if n < MAGIC.len() {
                    return self.cut();
                }
                self.magic_checked = true;
            }
            let mut head = [0u8; 9];
            let n = read_up_to(&mut self.reader, &mut head).map_err(|e| self.io_error(e))?;
            self.offset += n as u64;
            if n < head.len() {
                // No footer: the file was cut (a recorder killed), between records or in one.
                return self.cut();
            }
            let opcode = head[0];
            let len = u64::from_le_bytes(head[1..9].try_into().unwrap_or([0xff; 8]));
            let Some(len) = usize::try_from(len).ok().filter(|&l| l <= MAX_CHUNK_BYTES) else {
                self.done = true;
                return Err(self.mcap_error(format!(
                    "record (opcode 0x{opcode:02x}) of {len} bytes, more than the {MAX_CHUNK_BYTES} accepted"
                )));
            };
            match opcode {
                OP_FOOTER => {
                    // The footer and the closing magic, read so that a file cut inside them
                    // is reported as cut like any other.
                    let got = std::io::copy(
                        &mut (&mut self.reader).take(len as u64),
                        &mut std::io::sink(),
                    )
                    .map_err(|e| self.io_error(e))?;
                    self.offset += got;
                    let mut magic = [0u8; 8];
                    let n =
                        read_up_to(&mut self.reader, &mut magic).map_err(|e| self.io_error(e))?;
                    self.offset += n as u64;
                    if got < len as u64 || n < MAGIC.len() {
                        return self.cut();
                    }
                    self.done = true;
                    if &magic != MAGIC {
                        return Err(
                            self.mcap_error("the file does not end with the MCAP magic".into())
                        );
                    }
                    return Ok(None);
                }
                OP_CHUNK | OP_SCHEMA | OP_CHANNEL | OP_MESSAGE => {
                    let got = fill(&mut self.reader, &mut self.body, len)
                        .map_err(|e| self.io_error(e))?;
                    self.offset += got as u64;
                    if got < len {
                        return self.cut();
                    }
                    if opcode != OP_CHUNK {
                        match self.on_record(opcode, false, 0..len)? {
                            Some(m) => return Ok(Some(m)),
                            None => continue,
                        }
                    }
                    match open_chunk(&self.body[..len], &mut self.inflated) {
                        Ok(Records::Stored(r)) => {
                            self.records_inflated = false;
                            (self.records_start, self.chunk_at, self.chunk_end) =
                                (r.start, r.start, r.end);
                        }
                        Ok(Records::Inflated(size)) => {
                            self.records_inflated = true;
                            (self.records_start, self.chunk_at, self.chunk_end) = (0, 0, size);
                        }
                        Err(reason) => {
                            self.done = true;
                            return Err(self.mcap_error(reason));
                        }
                    }
                }
                _ => {
                    let got = std::io::copy(
                        &mut (&mut self.reader).take(len as u64),
                        &mut std::io::sink(),
                    )
                    .map_err(|e| self.io_error(e))?;
                    self.offset += got;
                    if got < len as u64 {
                        return self.cut();
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

    /// One record (top level or inside a chunk) whose body is `range` of `inflated` (else of
    /// `body`): schemas and channels are remembered, a message is returned.
    fn on_record(
        &mut self,
        opcode: u8,
        in_inflated: bool,
        range: Range<usize>,
    ) -> Result<Option<RawMessage>, BagError> {
        let data = if in_inflated {
            &self.inflated[range.clone()]
        } else {
            &self.body[range.clone()]
        };
        match opcode {
            OP_MESSAGE => {
                // channel_id u16, sequence u32, log_time u64, publish_time u64, then the data.
                let (Some(channel), Some(log_time), Some(len)) = (
                    data.get(..2)
                        .and_then(|b| b.try_into().ok())
                        .map(u16::from_le_bytes),
                    u64_at(data, 6),
                    data.len().checked_sub(MESSAGE_HEADER),
                ) else {
                    let reason = format!(
                        "message record of {} bytes is shorter than its header",
                        data.len()
                    );
                    self.done = true;
                    self.chunk_at = self.chunk_end;
                    return Err(self.mcap_error(reason));
                };
                if len > MAX_MESSAGE_BYTES {
                    self.oversized += 1;
                    return Ok(None);
                }
                self.msg_inflated = in_inflated;
                self.msg = range.start + MESSAGE_HEADER..range.end;
                Ok(Some(RawMessage {
                    conn: u64::from(channel),
                    time_ns: i64::try_from(log_time).unwrap_or(i64::MAX),
                }))
            }
            // Only the records that matter here are parsed (the crate's parser checks their
            // fields).
            OP_SCHEMA | OP_CHANNEL => {
                let record = match mcap::parse_record(opcode, data) {
                    Ok(r) => r,
                    Err(e) => {
                        let reason = e.to_string();
                        self.done = true;
                        self.chunk_at = self.chunk_end;
                        return Err(self.mcap_error(reason));
                    }
                };
                let refused = match &record {
                    Record::Schema { header, .. } if header.name.len() > MAX_NAME_BYTES => {
                        Some(format!(
                            "schema name of {} bytes, more than the {MAX_NAME_BYTES} accepted",
                            header.name.len()
                        ))
                    }
                    Record::Schema { header, .. }
                        if !self.schemas.contains_key(&header.id)
                            && self.schemas.len() >= MAX_CONNECTIONS =>
                    {
                        Some(format!("more than {MAX_CONNECTIONS} schemas"))
                    }
                    Record::Channel(c) if c.topic.len() > MAX_NAME_BYTES => Some(format!(
                        "channel topic of {} bytes, more than the {MAX_NAME_BYTES} accepted",
                        c.topic.len()
                    )),
                    Record::Channel(c)
                        if !self.channels.contains_key(&c.id)
                            && self.order.len() >= MAX_CONNECTIONS =>
                    {
                        Some(format!("more than {MAX_CONNECTIONS} channels"))
                    }
                    _ => None,
                };
                if let Some(reason) = refused {
                    self.done = true;
                    self.chunk_at = self.chunk_end;
                    return Err(self.mcap_error(reason));
                }
                match record {
                    Record::Schema { header, .. } => {
                        self.schemas.insert(header.id, header.name);
                    }
                    Record::Channel(c) => {
                        let type_name = self.schemas.get(&c.schema_id).cloned().unwrap_or_default();
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
                    _ => {}
                }
                Ok(None)
            }
            _ => Ok(None),
        }
    }
}

/// Bytes of a message record before its data.
const MESSAGE_HEADER: usize = 2 + 4 + 8 + 8;

const OP_FOOTER: u8 = 0x02;
const OP_SCHEMA: u8 = 0x03;
const OP_CHANNEL: u8 = 0x04;
const OP_MESSAGE: u8 = 0x05;
const OP_CHUNK: u8 = 0x06;
const OP_ATTACHMENT: u8 = 0x09;
const OP_ATTACHMENT_INDEX: u8 = 0x0A;

/// Attachments read from an MCAP file's summary at most: a bag written by ringscan holds one
/// calibration file per sensor.
const MAX_ATTACHMENTS: usize = 16;
/// Summary section bytes read at most to find the attachment indexes.
const MAX_SUMMARY_BYTES: u64 = 16 << 20;

/// The attachments (name, bytes) of an MCAP file, each of at most `max_bytes`, found through
/// the summary's attachment indexes (footer → summary → index → record) without reading the
/// messages. ringscan attaches the calibration files it decoded with, which makes a bag it
/// wrote decodable without them. Anything missing, damaged or too large gives fewer
/// attachments, never an error: the main pass reports a damaged file.
pub fn attachments<F: Read + std::io::Seek>(f: &mut F, max_bytes: usize) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let _ = read_attachments(f, max_bytes, &mut out);
    out
}

fn read_attachments<F: Read + std::io::Seek>(
    f: &mut F,
    max_bytes: usize,
    out: &mut Vec<(String, Vec<u8>)>,
) -> Option<()> {
    use std::io::SeekFrom;
    let file_len = f.seek(SeekFrom::End(0)).ok()?;
    let mut read_at = |at: u64, n: u64| -> Option<Vec<u8>> {
        f.seek(SeekFrom::Start(at)).ok()?;
        let mut b = Vec::new();
        f.by_ref().take(n).read_to_end(&mut b).ok()?;
        (b.len() as u64 == n).then_some(b)
    };
    // Footer record (opcode, length 20, summary start, summary offset start, CRC), then magic.
    let footer_at = file_len.checked_sub(8 + 9 + 20)?;
    let tail = read_at(footer_at, 37)?;
    if tail[0] != OP_FOOTER || u64_at(&tail, 1)? != 20 || &tail[29..] != MAGIC {
        return None;
    }
    let summary_start = u64_at(&tail, 9)?;
    let offsets_start = u64_at(&tail, 17)?;
    let summary_end = if offsets_start == 0 {
        footer_at
    } else {
        offsets_start
    };
    if summary_start == 0 || summary_start > summary_end || summary_end > footer_at {
        return None;
    }
    let summary = read_at(
        summary_start,
        (summary_end - summary_start).min(MAX_SUMMARY_BYTES),
    )?;
    let string_at = |b: &[u8], at: usize| -> Option<(String, usize)> {
        let n = u32_at(b, at)? as usize;
        let text = b.get(at + 4..(at + 4).checked_add(n)?)?;
        Some((String::from_utf8_lossy(text).into_owned(), at + 4 + n))
    };
    let mut at = 0usize;
    while let Some((op, body)) = chunk_record(&summary, at) {
        at = body.end;
        if op != OP_ATTACHMENT_INDEX || out.len() >= MAX_ATTACHMENTS {
            continue;
        }
        // Attachment index: offset, length (the whole record), log time, create time, data
        // size, name, media type.
        let b = &summary[body];
        let (offset, length, data_size) = (u64_at(b, 0)?, u64_at(b, 8)?, u64_at(b, 32)?);
        if data_size > max_bytes as u64 || length > data_size.saturating_add(64 << 10) {
            continue;
        }
        // The index's length must be the record's own (opcode, length field, body).
        let Some(rec) = read_at(offset, length)
            .filter(|r| u64_at(r, 1).and_then(|n| n.checked_add(9)) == Some(length))
        else {
            continue;
        };
        // Attachment record: opcode, length, log time, create time, name, media type, data
        // (u64 length + bytes), CRC.
        let Some((name, next)) = (rec.first() == Some(&OP_ATTACHMENT))
            .then(|| string_at(&rec, 9 + 16))
            .flatten()
        else {
            continue;
        };
        let Some((_media, next)) = string_at(&rec, next) else {
            continue;
        };
        let Some(n) = u64_at(&rec, next).filter(|&n| n == data_size) else {
            continue;
        };
        if let Some(data) = rec.get(next + 8..next + 8 + n as usize) {
            out.push((name, data.to_vec()));
        }
    }
    Some(())
}

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

/// Where a chunk's records are, once it is opened.
#[derive(Debug, PartialEq, Eq)]
enum Records {
    /// Stored uncompressed: this range of the chunk record's body.
    Stored(Range<usize>),
    /// Decompressed: the first this many bytes of the buffer given to [`open_chunk`].
    Inflated(usize),
}

/// Opens a Chunk record's body (MCAP specification, "Chunk (op=0x06)": `message_start_time`
/// u64, `message_end_time` u64, `uncompressed_size` u64, `uncompressed_crc` u32, `compression`
/// string (u32 length + bytes), `compressed_size` u64, then the records), decompressing into
/// `inflated` (its first bytes; the buffer is not shrunk): every size checked against its
/// container before anything is allocated or decompressed.
fn open_chunk(body: &[u8], inflated: &mut Vec<u8>) -> Result<Records, String> {
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
    let stored = usize::try_from(compressed_size)
        .ok()
        .and_then(|n| Some(records_at..records_at.checked_add(n)?))
        .filter(|r| r.end <= body.len())
        .ok_or_else(|| {
            format!("chunk claims {compressed_size} compressed bytes; its record holds {left}")
        })?;
    let records = &body[stored.clone()];
    let size = usize::try_from(uncompressed_size)
        .ok()
        .filter(|&n| n <= MAX_CHUNK_BYTES)
        .ok_or_else(|| {
            format!(
                "chunk claims {uncompressed_size} uncompressed bytes, more than the {MAX_CHUNK_BYTES} accepted"
            )
        })?;
    let opened = match compression {
        b"" => (records.len() == size).then_some(Records::Stored(stored)),
        b"zstd" => zstd::stream::read::Decoder::with_buffer(records)
            .is_ok_and(|d| inflate_exact(d, size, inflated))
            .then_some(Records::Inflated(size)),
        b"lz4" => super::lz4frame::decompress(records, size, inflated)
            .is_ok()
            .then_some(Records::Inflated(size)),
        other => {
            return Err(format!(
                "chunk compression {:?} is not supported (zstd, lz4 or none)",
                String::from_utf8_lossy(other)
            ))
        }
    };
    let Some(opened) = opened else {
        return Err(format!(
            "chunk ({}) does not decompress to the {size} bytes it claims",
            String::from_utf8_lossy(compression)
        ));
    };
    if crc != 0 {
        let found = crc32fast::hash(match &opened {
            Records::Stored(r) => &body[r.clone()],
            Records::Inflated(n) => &inflated[..*n],
        });
        if found != crc {
            return Err(format!(
                "chunk CRC mismatch: recorded {crc:08x}, computed {found:08x}"
            ));
        }
    }
    Ok(opened)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(op: u8, body: &[u8]) -> Vec<u8> {
        let mut r = vec![op];
        r.extend_from_slice(&(body.len() as u64).to_le_bytes());
        r.extend_from_slice(body);
        r
    }

    fn string(s: &str) -> Vec<u8> {
        let mut b = (s.len() as u32).to_le_bytes().to_vec();
        b.extend_from_slice(s.as_bytes());
        b
    }

    /// An MCAP file written by hand from the specification: magic, one attachment record per
    /// `(name, data)`, a summary of their attachment indexes (each index's offset, length and
    /// data size passed through `lie`), the footer and magic.
    fn with_attachments(
        files: &[(&str, &[u8])],
        lie: impl Fn(u64, u64, u64) -> (u64, u64, u64),
    ) -> Vec<u8> {
        let mut out = MAGIC.to_vec();
        let mut summary = Vec::new();
        for (name, data) in files {
            let mut body = [0u8; 16].to_vec();
            body.extend(string(name));
            body.extend(string("text/plain"));
            body.extend_from_slice(&(data.len() as u64).to_le_bytes());
            body.extend_from_slice(data);
            body.extend_from_slice(&[0; 4]);
            let rec = record(OP_ATTACHMENT, &body);
            let (offset, length, size) = lie(out.len() as u64, rec.len() as u64, data.len() as u64);
            let mut index = Vec::new();
            for v in [offset, length, 0, 0, size] {
                index.extend_from_slice(&v.to_le_bytes());
            }
            index.extend(string(name));
            index.extend(string("text/plain"));
            summary.extend(record(OP_ATTACHMENT_INDEX, &index));
            out.extend(rec);
        }
        let summary_start = out.len() as u64;
        out.extend(summary);
        let mut footer = summary_start.to_le_bytes().to_vec();
        footer.extend_from_slice(&[0; 12]);
        out.extend(record(OP_FOOTER, &footer));
        out.extend_from_slice(MAGIC);
        out
    }

    /// What an attachment index says instead of (offset, length, data size).
    type Lie = fn(u64, u64, u64) -> (u64, u64, u64);

    fn read(bytes: &[u8], max: usize) -> Vec<(String, Vec<u8>)> {
        attachments(&mut std::io::Cursor::new(bytes), max)
    }

    #[test]
    fn attachments_are_read_through_the_summary() {
        let honest = |o, l, s| (o, l, s);
        let f = with_attachments(&[("a.csv", b"1,2,3"), ("b.dat", &[0xEE, 0xFF, 0])], honest);
        assert_eq!(
            read(&f, 100),
            [
                ("a.csv".to_string(), b"1,2,3".to_vec()),
                ("b.dat".to_string(), vec![0xEE, 0xFF, 0])
            ]
        );
        // Over the size asked: left out, the others kept.
        assert_eq!(read(&f, 4).len(), 1);
        // At most MAX_ATTACHMENTS, whatever the summary lists.
        let many: Vec<(&str, &[u8])> = (0..40).map(|_| ("x", &b"x"[..])).collect();
        assert_eq!(
            read(&with_attachments(&many, honest), 100).len(),
            MAX_ATTACHMENTS
        );
    }

    #[test]
    fn hostile_attachment_indexes_give_fewer_attachments() {
        let one: &[(&str, &[u8])] = &[("a.csv", b"1,2,3")];
        // Offsets past the end or into the middle of a record, lengths too short or huge, a
        // data size that disagrees with the record's, a huge data size.
        let lies: [Lie; 7] = [
            |_, l, s| (u64::MAX - 3, l, s),
            |o, l, s| (o + 1, l, s),
            |o, l, s| (o, l - 1, s),
            |o, _, s| (o, u64::MAX, s),
            |o, l, s| (o, l, s + 1),
            |o, l, _| (o, l, u64::MAX),
            |o, l, s| (o, l + 4096, s),
        ];
        for (k, lie) in lies.iter().enumerate() {
            assert!(
                read(&with_attachments(one, lie), 1 << 20).is_empty(),
                "lie {k}"
            );
        }
        // Damaged footers and summaries: cut short, no magic, summary start beyond the footer.
        let f = with_attachments(one, |o, l, s| (o, l, s));
        for cut in [1, 8, 20, 37, f.len()] {
            assert!(read(&f[..f.len() - cut], 1 << 20).is_empty(), "cut {cut}");
        }
        let mut g = f.clone();
        let at = g.len() - 8 - 28;
        g[at..at + 8].copy_from_slice(&u64::MAX.to_le_bytes());
        assert!(read(&g, 1 << 20).is_empty());
        assert!(read(b"", 1 << 20).is_empty());
    }

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

    /// The records of a chunk, opened.
    fn open(body: &[u8]) -> Result<Vec<u8>, String> {
        let mut inflated = Vec::new();
        Ok(match open_chunk(body, &mut inflated)? {
            Records::Stored(r) => body[r].to_vec(),
            Records::Inflated(n) => inflated[..n].to_vec(),
        })
    }

    #[test]
    fn a_record_longer_than_its_chunk_is_refused() {
        // One record: opcode 0x05, length 1000, but only 4 body bytes follow.
        let mut records = vec![0x05];
        records.extend_from_slice(&1000u64.to_le_bytes());
        records.extend_from_slice(&[1, 2, 3, 4]);
        let out = open(&chunk_body("", 13, 0, &records)).unwrap();
        assert_eq!(chunk_record(&out, 0), None);
        // Length 4 fits exactly.
        records[1..9].copy_from_slice(&4u64.to_le_bytes());
        let out = open(&chunk_body("", 13, 0, &records)).unwrap();
        assert_eq!(chunk_record(&out, 0), Some((0x05, 9..13)));
        assert_eq!(chunk_record(&out, 13), None);
        // A length whose end overflows usize.
        records[1..9].copy_from_slice(&u64::MAX.to_le_bytes());
        let out = open(&chunk_body("", 13, 0, &records)).unwrap();
        assert_eq!(chunk_record(&out, 0), None);
    }

    #[test]
    fn chunk_sizes_are_checked_against_their_container() {
        // compressed_size past the record's end.
        let mut b = chunk_body("", 4, 0, &[0; 4]);
        let at = b.len() - 12;
        b[at..at + 8].copy_from_slice(&5u64.to_le_bytes());
        assert!(open(&b).unwrap_err().contains("compressed bytes"));
        // A 1 TB uncompressed claim.
        let e = open(&chunk_body("zstd", 1 << 40, 0, &[0; 4])).unwrap_err();
        assert!(e.contains("uncompressed bytes"), "{e}");
        // Uncompressed: the size must match the records.
        assert!(open(&chunk_body("", 3, 0, &[0; 4])).is_err());
        // Garbage that is not zstd / lz4; an unknown compression; a header cut short.
        assert!(open(&chunk_body("zstd", 4, 0, &[1, 2, 3, 4])).is_err());
        assert!(open(&chunk_body("lz4", 4, 0, &[1, 2, 3, 4])).is_err());
        assert!(open(&chunk_body("bz2", 4, 0, &[0; 4])).is_err());
        assert!(open(&[0; 20]).is_err());
        // CRC-32 (IEEE) of "123456789" is 0xcbf43926 (the check value of the CRC catalogue).
        assert!(open(&chunk_body("", 9, 0xcbf4_3926, b"123456789")).is_ok());
        assert!(open(&chunk_body("", 9, 0xcbf4_3927, b"123456789")).is_err());
    }
}
