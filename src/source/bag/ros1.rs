//! ROS 1 bags (format 2.0) as a stream of messages.
//!
//! In: any [`Read`] holding `#ROSBAG V2.0\n` and its records. Out: one message at a time (its
//! connection, record time and bytes), in file order: chunk by chunk, and within a chunk in
//! the order recorded. Chunks may be uncompressed, bz2 or lz4 (the LZ4 frame format roslz4
//! writes).
//!
//! # Format (ROS wiki, "Bags/Format/2.0")
//! A record is `u32 header_len, header, u32 data_len, data`, little-endian; the header is a
//! list of `u32 len, name=value` fields and its `op` field says what the record is: 0x03 bag
//! header (`index_pos`, padded to 4096 bytes), 0x05 chunk (`compression`, uncompressed `size`;
//! data = the records inside), 0x07 connection (`conn`, `topic`; data = fields `type`,
//! `md5sum`, `message_definition`, …), 0x02 message data (`conn`, `time` = u32 sec + u32 nsec;
//! data = the serialized message), 0x04 index data and 0x06 chunk info (skipped: this reader
//! goes through the file once). The index section at `index_pos` repeats every connection;
//! [`read_index_connections`] reads it so that every topic is known before the first message.
//!
//! # Bounds
//! Record headers (in a chunk too) are at most [`MAX_HEADER_BYTES`]; a chunk's compressed and
//! uncompressed sizes at most [`MAX_CHUNK_BYTES`]; any other record at most
//! [`MAX_MESSAGE_BYTES`]. A length beyond them is
//! [`BagError::RecordTooLarge`] before anything is allocated, and buffers grow only as bytes
//! actually arrive. Connections are kept to the end: at most [`MAX_FILE_CONNECTIONS`], their
//! topic and type at most [`MAX_NAME_BYTES`] each and [`MAX_CONNECTION_NAME_BYTES`] over all,
//! else an error. One chunk is held at a time (compressed and uncompressed), the buffers are
//! reused. A chunk that does not decompress to its announced size, or whose records contradict
//! their lengths, is counted in `bad_chunks` and skipped: its length is known, the next record
//! is not lost. A record cut short by the end of the file ends the stream (`truncated_at`), as
//! does the end of the file before the index section the bag header announces (`index_pos`).
//! An `index_pos` where no index record starts (inside the data) is read past.

use std::collections::HashMap;
use std::io::{self, Read, Seek, SeekFrom};

use super::messages::Encoding;
use super::{
    inflate_exact, read_up_to, BagError, Connection, RawMessage, MAX_CHUNK_BYTES,
    MAX_CONNECTION_NAME_BYTES, MAX_FILE_CONNECTIONS, MAX_MESSAGE_BYTES, MAX_NAME_BYTES,
};

/// The first bytes of every ROS 1 bag of format 2.0.
pub const MAGIC: &[u8; 13] = b"#ROSBAG V2.0\n";
/// Largest record header accepted.
pub const MAX_HEADER_BYTES: usize = 1 << 20;

const OP_MESSAGE: u8 = 0x02;
const OP_BAG_HEADER: u8 = 0x03;
const OP_CHUNK: u8 = 0x05;
const OP_CHUNK_INFO: u8 = 0x06;
const OP_CONNECTION: u8 = 0x07;

/// The fields of a record header ringscan uses.
#[derive(Debug, Default, Clone)]
struct Header {
    op: Option<u8>,
    conn: Option<u32>,
    time_ns: Option<i64>,
    index_pos: Option<u64>,
    size: Option<u32>,
    compression: Option<String>,
    topic: Option<String>,
    type_name: Option<String>,
    /// Length of a `topic` or `type` longer than [`MAX_NAME_BYTES`] (then not kept: the
    /// fields of a connection's data may be as long as its chunk).
    long_name: Option<usize>,
}

/// Walks `name=value` fields; `f` gets each (name, value).
fn fields(buf: &[u8], mut f: impl FnMut(&[u8], &[u8])) -> Result<(), &'static str> {
    let mut at = 0usize;
    while at < buf.len() {
        let len = buf
            .get(at..at + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
            .ok_or("a field length overruns the header")?;
        at += 4;
        let field = at
            .checked_add(len)
            .and_then(|end| buf.get(at..end))
            .ok_or("a field overruns the header")?;
        at += len;
        let eq = field
            .iter()
            .position(|&b| b == b'=')
            .ok_or("a field without '='")?;
        f(&field[..eq], &field[eq + 1..]);
    }
    Ok(())
}

fn parse_header(buf: &[u8]) -> Result<Header, &'static str> {
    let mut h = Header::default();
    let le32 = |v: &[u8]| -> Option<u32> { Some(u32::from_le_bytes(v.try_into().ok()?)) };
    fields(buf, |name, value| match name {
        b"op" => h.op = value.first().copied().filter(|_| value.len() == 1),
        b"conn" => h.conn = le32(value),
        b"time" if value.len() == 8 => {
            let sec = le32(&value[..4]).unwrap_or(0);
            let nsec = le32(&value[4..]).unwrap_or(0);
            h.time_ns = Some(i64::from(sec) * 1_000_000_000 + i64::from(nsec));
        }
        b"index_pos" => h.index_pos = value.try_into().ok().map(u64::from_le_bytes),
        b"size" => h.size = le32(value),
        b"topic" | b"type" if value.len() > MAX_NAME_BYTES => h.long_name = Some(value.len()),
        // Not kept either: no compression has such a name, the chunk is counted as bad.
        b"compression" if value.len() > MAX_NAME_BYTES => {}
        b"compression" => h.compression = Some(String::from_utf8_lossy(value).into_owned()),
        b"topic" => h.topic = Some(String::from_utf8_lossy(value).into_owned()),
        b"type" => h.type_name = Some(String::from_utf8_lossy(value).into_owned()),
        _ => {}
    })?;
    Ok(h)
}

/// A record read from the file or from a chunk: its header and where its data is.
struct Record {
    header: Header,
    data_len: usize,
}

/// What reading a record's framing gave.
enum Framing {
    Record(Record),
    /// Clean end of the input (no byte of a new record).
    End,
    /// The input ended inside the record.
    Truncated,
}

/// Messages of a ROS 1 bag. See the [module documentation](self).
pub struct Ros1Reader<R: Read> {
    reader: R,
    /// File offset of the next byte to read.
    offset: u64,
    index_pos: u64,
    head: Vec<u8>,
    /// A record's data as read (a compressed chunk, a connection), valid up to `compressed_end`.
    compressed: Vec<u8>,
    compressed_end: usize,
    /// The records of the chunk being read (decompressed), valid up to `chunk_end`.
    chunk: Vec<u8>,
    chunk_end: usize,
    chunk_at: usize,
    /// Where the message last returned lies: in `chunk` (else in `compressed`), and its bytes.
    msg_in_chunk: bool,
    msg: std::ops::Range<usize>,
    /// File offset of the chunk being read (for error messages).
    chunk_offset: u64,
    connections: HashMap<u32, Connection>,
    /// Connection ids in order of first appearance.
    order: Vec<u32>,
    /// Bytes of the names of `connections`.
    name_bytes: usize,
    /// Chunks skipped because they did not decompress or their records were inconsistent.
    pub(crate) bad_chunks: u64,
    /// Offset of the first skipped chunk.
    pub(crate) first_bad_chunk: Option<u64>,
    pub(crate) truncated_at: Option<u64>,
    done: bool,
}

impl<R: Read> Ros1Reader<R> {
    /// Checks the magic and the bag header record.
    pub fn new(mut reader: R) -> Result<Self, BagError> {
        let mut magic = [0u8; 13];
        let n = read_up_to(&mut reader, &mut magic)
            .map_err(|source| BagError::Io { offset: 0, source })?;
        if n < 13 || &magic != MAGIC {
            return Err(BagError::BadMagic {
                expected: "#ROSBAG V2.0",
                found: magic[..n].to_vec(),
            });
        }
        let mut r = Self {
            reader,
            offset: 13,
            index_pos: 0,
            head: Vec::new(),
            compressed: Vec::new(),
            compressed_end: 0,
            chunk: Vec::new(),
            chunk_end: 0,
            msg_in_chunk: false,
            msg: 0..0,
            chunk_at: 0,
            chunk_offset: 0,
            connections: HashMap::new(),
            order: Vec::new(),
            name_bytes: 0,
            bad_chunks: 0,
            first_bad_chunk: None,
            truncated_at: None,
            done: false,
        };
        let start = r.offset;
        match r.read_framing()? {
            Framing::Record(rec) if rec.header.op == Some(OP_BAG_HEADER) => {
                r.index_pos = rec.header.index_pos.unwrap_or(0);
                if !r.skip_data(rec.data_len)? {
                    return Err(BagError::Corrupt {
                        offset: start,
                        reason: "the file ends inside its bag header record".into(),
                    });
                }
            }
            Framing::Record(rec) => {
                return Err(BagError::Corrupt {
                    offset: start,
                    reason: format!(
                        "the first record is op {:?}, not the bag header (op 3)",
                        rec.header.op
                    ),
                })
            }
            Framing::End | Framing::Truncated => {
                return Err(BagError::Corrupt {
                    offset: start,
                    reason: "the file ends inside its bag header record".into(),
                })
            }
        }
        Ok(r)
    }

    /// Where the index section (connections, chunk infos) starts; 0 for an unindexed bag.
    pub fn index_pos(&self) -> u64 {
        self.index_pos
    }

    /// File bytes consumed so far.
    pub fn offset(&self) -> u64 {
        self.offset
    }

    /// Registers connections known beforehand (from the index), up to
    /// [`MAX_FILE_CONNECTIONS`] with [`MAX_CONNECTION_NAME_BYTES`] of names.
    pub fn add_connections(&mut self, list: Vec<(u32, Connection)>) {
        for (id, c) in list {
            if !self.add_connection(id, c) {
                break;
            }
        }
    }

    /// False when `id` would be one connection more than [`MAX_FILE_CONNECTIONS`], or its
    /// names would pass [`MAX_CONNECTION_NAME_BYTES`] over all. A connection record repeats
    /// in every chunk that uses it: a repeat replaces the one kept.
    fn add_connection(&mut self, id: u32, c: Connection) -> bool {
        let size = |c: &Connection| c.topic.len() + c.type_name.len();
        let old = self.connections.get(&id).map(size);
        if old.is_none() && self.order.len() >= MAX_FILE_CONNECTIONS {
            return false;
        }
        let bytes = self.name_bytes - old.unwrap_or(0) + size(&c);
        if bytes > MAX_CONNECTION_NAME_BYTES {
            return false;
        }
        if old.is_none() {
            self.order.push(id);
        }
        self.name_bytes = bytes;
        self.connections.insert(id, c);
        true
    }

    /// Registers the connection (if any) of the record at `offset`.
    fn register(
        &mut self,
        found: Result<Option<(u32, Connection)>, BagError>,
        offset: u64,
    ) -> Result<(), BagError> {
        let Some((id, c)) = found? else {
            return Ok(());
        };
        if self.add_connection(id, c) {
            return Ok(());
        }
        Err(BagError::Corrupt {
            offset,
            reason: format!(
                "more than {MAX_FILE_CONNECTIONS} connections, or {MAX_CONNECTION_NAME_BYTES} bytes of their names"
            ),
        })
    }

    /// The connection `id`.
    pub fn connection(&self, id: u64) -> Option<&Connection> {
        u32::try_from(id)
            .ok()
            .and_then(|i| self.connections.get(&i))
    }

    /// How many connections [`Self::connections_from`] lists from 0 (it only grows).
    pub fn connection_count(&self) -> usize {
        self.order.len()
    }

    /// The connections known so far from the `first`-th on, in order of appearance.
    pub fn connections_from(&self, first: usize) -> Vec<(u64, Connection)> {
        self.order
            .get(first..)
            .unwrap_or_default()
            .iter()
            .filter_map(|id| Some((u64::from(*id), self.connections.get(id)?.clone())))
            .collect()
    }

    fn io(&self, source: io::Error) -> BagError {
        BagError::Io {
            offset: self.offset,
            source,
        }
    }

    /// Reads `u32 header_len, header, u32 data_len` of a top-level record into `self.head`.
    fn read_framing(&mut self) -> Result<Framing, BagError> {
        let start = self.offset;
        let mut len4 = [0u8; 4];
        let n = read_up_to(&mut self.reader, &mut len4).map_err(|e| self.io(e))?;
        self.offset += n as u64;
        if n == 0 {
            return Ok(Framing::End);
        }
        if n < 4 {
            return Ok(Framing::Truncated);
        }
        let header_len = u32::from_le_bytes(len4) as usize;
        if header_len > MAX_HEADER_BYTES {
            return Err(BagError::RecordTooLarge {
                offset: start,
                what: "record header",
                len: header_len as u64,
                limit: MAX_HEADER_BYTES as u64,
            });
        }
        self.head.clear();
        let got = (&mut self.reader)
            .take(header_len as u64)
            .read_to_end(&mut self.head)
            .map_err(|e| self.io(e))?;
        self.offset += got as u64;
        if got < header_len {
            return Ok(Framing::Truncated);
        }
        let n = read_up_to(&mut self.reader, &mut len4).map_err(|e| self.io(e))?;
        self.offset += n as u64;
        if n < 4 {
            return Ok(Framing::Truncated);
        }
        let data_len = u32::from_le_bytes(len4) as usize;
        let header = parse_header(&self.head).map_err(|reason| BagError::Corrupt {
            offset: start,
            reason: reason.into(),
        })?;
        let limit = if header.op == Some(OP_CHUNK) {
            MAX_CHUNK_BYTES
        } else {
            MAX_MESSAGE_BYTES
        };
        let skipped_op = matches!(header.op, Some(0x04 | 0x06));
        if data_len > limit && !skipped_op {
            return Err(BagError::RecordTooLarge {
                offset: start,
                what: "record",
                len: data_len as u64,
                limit: limit as u64,
            });
        }
        Ok(Framing::Record(Record { header, data_len }))
    }

    /// Reads `len` bytes into `buf` (grown only as bytes arrive); false if the input ends first.
    fn read_data(&mut self, len: usize, which: Buf) -> Result<bool, BagError> {
        let (buf, end) = match which {
            Buf::Compressed => (&mut self.compressed, &mut self.compressed_end),
            Buf::Chunk => (&mut self.chunk, &mut self.chunk_end),
        };
        let got = super::fill(&mut self.reader, buf, len).map_err(|source| BagError::Io {
            offset: self.offset,
            source,
        })?;
        *end = got;
        self.offset += got as u64;
        Ok(got == len)
    }

    fn skip_data(&mut self, len: usize) -> Result<bool, BagError> {
        let got = io::copy(&mut (&mut self.reader).take(len as u64), &mut io::sink())
            .map_err(|e| self.io(e))?;
        self.offset += got;
        Ok(got == len as u64)
    }

    fn bad_chunk(&mut self) {
        self.bad_chunks += 1;
        self.first_bad_chunk.get_or_insert(self.chunk_offset);
        self.chunk_end = 0;
        self.chunk_at = 0;
    }

    /// The bytes of the message last returned by [`Self::next_message`].
    pub fn message(&self) -> &[u8] {
        let buf = if self.msg_in_chunk {
            &self.chunk
        } else {
            &self.compressed
        };
        buf.get(self.msg.clone()).unwrap_or(&[])
    }

    /// The next message ([`Self::message`]). `Ok(None)` at the end (or where the file is cut).
    pub fn next_message(&mut self) -> Result<Option<RawMessage>, BagError> {
        loop {
            if self.done {
                return Ok(None);
            }
            if self.chunk_at < self.chunk_end {
                match self.next_in_chunk() {
                    Ok(Some(m)) => return Ok(Some(m)),
                    Ok(None) => continue,
                    Err(e) => {
                        self.done = true;
                        return Err(e);
                    }
                }
            }
            let start = self.offset;
            let at_index = self.index_pos > 0 && start == self.index_pos;
            if self.index_pos > 0 && start > self.index_pos {
                // It pointed inside a record: no index is there, the data goes on.
                self.index_pos = 0;
            }
            let rec = match self.read_framing() {
                Ok(Framing::Record(r)) => r,
                // Every message came before: only the index is cut short.
                Ok(Framing::End | Framing::Truncated) if at_index => {
                    self.done = true;
                    return Ok(None);
                }
                // Ending before the index announced is ending cut, at a record's start or not.
                Ok(Framing::End) if start >= self.index_pos => {
                    self.done = true;
                    return Ok(None);
                }
                Ok(Framing::End | Framing::Truncated) => {
                    self.truncated_at = Some(start);
                    self.done = true;
                    return Ok(None);
                }
                Err(e) => {
                    self.done = true;
                    return Err(e);
                }
            };
            let h = rec.header;
            if at_index {
                if matches!(h.op, Some(OP_CONNECTION | OP_CHUNK_INFO)) {
                    self.done = true;
                    return Ok(None);
                }
                // Data where the index should start: the position is wrong, not the data.
                self.index_pos = 0;
            }
            match h.op {
                Some(OP_CHUNK) => {
                    self.chunk_offset = start;
                    let size = h.size.unwrap_or(0) as usize;
                    if size > MAX_CHUNK_BYTES {
                        self.done = true;
                        return Err(BagError::RecordTooLarge {
                            offset: start,
                            what: "uncompressed chunk",
                            len: size as u64,
                            limit: MAX_CHUNK_BYTES as u64,
                        });
                    }
                    let compression = h.compression.unwrap_or_default();
                    let complete = if compression == "none" {
                        self.read_data(rec.data_len, Buf::Chunk)?
                    } else {
                        self.read_data(rec.data_len, Buf::Compressed)?
                    };
                    if !complete {
                        self.chunk_end = 0;
                        self.truncated_at = Some(start);
                        self.done = true;
                        return Ok(None);
                    }
                    self.chunk_at = 0;
                    let packed = &self.compressed[..self.compressed_end];
                    let ok = match compression.as_str() {
                        "none" => self.chunk_end == size,
                        "bz2" => inflate_exact(
                            bzip2::read::BzDecoder::new(packed),
                            size,
                            &mut self.chunk,
                        ),
                        "lz4" => super::lz4frame::decompress(packed, size, &mut self.chunk).is_ok(),
                        _ => false,
                    };
                    if ok && compression != "none" {
                        self.chunk_end = size;
                    }
                    if !ok {
                        self.bad_chunk();
                    }
                }
                Some(OP_CONNECTION) => {
                    if !self.read_data(rec.data_len, Buf::Compressed)? {
                        self.truncated_at = Some(start);
                        self.done = true;
                        return Ok(None);
                    }
                    let found = connection(&h, &self.compressed[..self.compressed_end], start);
                    if let Err(e) = self.register(found, start) {
                        self.done = true;
                        return Err(e);
                    }
                }
                Some(OP_MESSAGE) => {
                    // Unchunked message data (not written by rosbag, accepted anyway).
                    if !self.read_data(rec.data_len, Buf::Compressed)? {
                        self.truncated_at = Some(start);
                        self.done = true;
                        return Ok(None);
                    }
                    if let (Some(conn), Some(time_ns)) = (h.conn, h.time_ns) {
                        (self.msg_in_chunk, self.msg) = (false, 0..self.compressed_end);
                        return Ok(Some(RawMessage {
                            conn: u64::from(conn),
                            time_ns,
                        }));
                    }
                }
                _ => {
                    if !self.skip_data(rec.data_len)? {
                        self.truncated_at = Some(start);
                        self.done = true;
                        return Ok(None);
                    }
                }
            }
        }
    }

    /// The next message record inside the current chunk (connections are registered on the
    /// way); `None` when the chunk is used up or found inconsistent (then counted).
    fn next_in_chunk(&mut self) -> Result<Option<RawMessage>, BagError> {
        while self.chunk_at < self.chunk_end {
            let Some((header, data)) = inner_record(&self.chunk[..self.chunk_end], self.chunk_at)
            else {
                self.bad_chunk();
                return Ok(None);
            };
            let (hs, he) = header;
            let (ds, de) = data;
            self.chunk_at = de;
            let parsed = (he - hs <= MAX_HEADER_BYTES)
                .then(|| parse_header(&self.chunk[hs..he]).ok())
                .flatten();
            let Some(h) = parsed else {
                self.bad_chunk();
                return Ok(None);
            };
            match h.op {
                Some(OP_CONNECTION) => {
                    let found = connection(&h, &self.chunk[ds..de], self.chunk_offset);
                    self.register(found, self.chunk_offset)?;
                }
                Some(OP_MESSAGE) => {
                    if let (Some(conn), Some(time_ns)) = (h.conn, h.time_ns) {
                        (self.msg_in_chunk, self.msg) = (true, ds..de);
                        return Ok(Some(RawMessage {
                            conn: u64::from(conn),
                            time_ns,
                        }));
                    }
                }
                _ => {}
            }
        }
        Ok(None)
    }
}

#[derive(Clone, Copy)]
enum Buf {
    Compressed,
    Chunk,
}

/// Header and data ranges of the record at `at` inside a chunk.
fn inner_record(buf: &[u8], at: usize) -> Option<((usize, usize), (usize, usize))> {
    let le = |i: usize| -> Option<usize> {
        let b = buf.get(i..i.checked_add(4)?)?;
        Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
    };
    let hl = le(at)?;
    let hs = at + 4;
    let he = hs.checked_add(hl)?;
    let dl = le(he)?;
    let ds = he + 4;
    let de = ds.checked_add(dl)?;
    (de <= buf.len()).then_some(((hs, he), (ds, de)))
}

/// The connection record at `offset`: its id and what it carries (the type is in the data's
/// fields); `None` without an id or a topic.
fn connection(h: &Header, data: &[u8], offset: u64) -> Result<Option<(u32, Connection)>, BagError> {
    let Some(id) = h.conn else { return Ok(None) };
    let inner = parse_header(data).ok();
    if let Some(len) = h.long_name.or(inner.as_ref().and_then(|i| i.long_name)) {
        return Err(BagError::RecordTooLarge {
            offset,
            what: "connection topic or type",
            len: len as u64,
            limit: MAX_NAME_BYTES as u64,
        });
    }
    let Some(topic) = h
        .topic
        .clone()
        .or_else(|| inner.as_ref().and_then(|i| i.topic.clone()))
    else {
        return Ok(None);
    };
    let type_name = inner.and_then(|i| i.type_name).unwrap_or_default();
    Ok(Some((
        id,
        Connection {
            topic,
            type_name,
            encoding: Some(Encoding::Ros1),
        },
    )))
}

/// The connections listed in the index section at `index_pos` (all of the bag's), restoring
/// the reader's position afterwards. An unreadable index gives what it could read.
pub fn read_index_connections<R: Read + Seek>(
    reader: &mut R,
    index_pos: u64,
) -> io::Result<Vec<(u32, Connection)>> {
    let here = reader.stream_position()?;
    let mut out = Vec::new();
    let mut bytes = 0usize;
    if index_pos > 0 && reader.seek(SeekFrom::Start(index_pos)).is_ok() {
        let mut buf = Vec::new();
        loop {
            let mut len4 = [0u8; 4];
            if read_up_to(reader, &mut len4)? < 4 {
                break;
            }
            let hl = u32::from_le_bytes(len4) as usize;
            if hl > MAX_HEADER_BYTES {
                break;
            }
            buf.clear();
            if reader.by_ref().take(hl as u64).read_to_end(&mut buf)? < hl {
                break;
            }
            let Ok(h) = parse_header(&buf) else { break };
            if read_up_to(reader, &mut len4)? < 4 {
                break;
            }
            let dl = u32::from_le_bytes(len4) as usize;
            if h.op != Some(OP_CONNECTION) {
                // Chunk infos follow the connections: nothing more to learn.
                break;
            }
            if dl > MAX_MESSAGE_BYTES {
                break;
            }
            buf.clear();
            if reader.by_ref().take(dl as u64).read_to_end(&mut buf)? < dl {
                break;
            }
            // The main pass refuses what is out of bounds, where it meets it in the data.
            if let Ok(Some(c)) = connection(&h, &buf, 0) {
                bytes += c.1.topic.len() + c.1.type_name.len();
                if out.len() >= MAX_FILE_CONNECTIONS || bytes > MAX_CONNECTION_NAME_BYTES {
                    break;
                }
                out.push(c);
            }
        }
    }
    reader.seek(SeekFrom::Start(here))?;
    Ok(out)
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// A `name=value` header field.
    pub(in crate::source::bag) fn field(name: &str, value: &[u8]) -> Vec<u8> {
        let mut f = ((name.len() + 1 + value.len()) as u32)
            .to_le_bytes()
            .to_vec();
        f.extend_from_slice(name.as_bytes());
        f.push(b'=');
        f.extend_from_slice(value);
        f
    }

    /// A record of `header` fields and `data`.
    pub(in crate::source::bag) fn record(header: &[Vec<u8>], data: &[u8]) -> Vec<u8> {
        let h: Vec<u8> = header.concat();
        let mut r = (h.len() as u32).to_le_bytes().to_vec();
        r.extend_from_slice(&h);
        r.extend_from_slice(&(data.len() as u32).to_le_bytes());
        r.extend_from_slice(data);
        r
    }

    /// A bag with one uncompressed chunk holding a connection and two messages.
    fn bag() -> Vec<u8> {
        let mut b = MAGIC.to_vec();
        b.extend(record(
            &[field("op", &[3]), field("index_pos", &0u64.to_le_bytes())],
            &[b' '; 16],
        ));
        let conn_data = [
            field("type", b"ouster_ros/PacketMsg"),
            field("topic", b"/os/lidar_packets"),
        ]
        .concat();
        let mut chunk = record(
            &[
                field("op", &[7]),
                field("conn", &0u32.to_le_bytes()),
                field("topic", b"/os/lidar_packets"),
            ],
            &conn_data,
        );
        for i in 0..2u32 {
            let mut t = (10 + i).to_le_bytes().to_vec();
            t.extend_from_slice(&7u32.to_le_bytes());
            chunk.extend(record(
                &[
                    field("op", &[2]),
                    field("conn", &0u32.to_le_bytes()),
                    field("time", &t),
                ],
                &[1, 0, 0, 0, i as u8],
            ));
        }
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

    #[test]
    fn reads_messages_of_an_uncompressed_chunk() {
        let b = bag();
        let mut r = Ros1Reader::new(&b[..]).unwrap();
        let m = r.next_message().unwrap().unwrap();
        assert_eq!((m.conn, m.time_ns), (0, 10_000_000_007));
        assert_eq!(r.message(), [1, 0, 0, 0, 0]);
        assert_eq!(r.connection(0).unwrap().type_name, "ouster_ros/PacketMsg");
        let m = r.next_message().unwrap().unwrap();
        assert_eq!(m.time_ns, 11_000_000_007);
        assert!(r.next_message().unwrap().is_none());
        assert_eq!(r.truncated_at, None);
    }

    #[test]
    fn every_cut_ends_cleanly_or_with_an_error() {
        let b = bag();
        for cut in 0..b.len() {
            if let Ok(mut r) = Ros1Reader::new(&b[..cut]) {
                while let Ok(Some(_)) = r.next_message() {}
                // A cut right after the bag header record is a clean (empty) bag.
                let header_end = 13 + 4 + (4 + 4) + (4 + 10 + 8) + 4 + 16;
                assert!(r.truncated_at.is_some() || cut == header_end, "cut {cut}");
            }
        }
    }

    #[test]
    fn a_huge_record_claim_is_an_error_without_allocation() {
        let mut b = bag();
        let n = b.len();
        b.extend(record(&[field("op", &[2])], &[]));
        // data_len of the appended record: 1 GiB.
        let at = b.len() - 4;
        b[at..].copy_from_slice(&(1u32 << 30).to_le_bytes());
        let mut r = Ros1Reader::new(&b[..]).unwrap();
        r.next_message().unwrap();
        r.next_message().unwrap();
        match r.next_message() {
            Err(BagError::RecordTooLarge { offset, .. }) => assert_eq!(offset, n as u64),
            other => panic!("{other:?}"),
        }
    }
}
