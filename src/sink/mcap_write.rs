//! The MCAP file writer under [`McapSink`](super::McapSink): records, chunks, and chunk
//! compression on a pool of worker threads.
//!
//! Why not the `mcap` crate's `Writer`: it compresses each chunk as a stream while messages are
//! added, on the caller's thread (its zstd "worker threads" only split one 4 MiB chunk into
//! ≤ 2 MiB jobs and the caller waits for them at the end of every chunk: about 1.06 cores in
//! use), and it cannot be handed a chunk compressed elsewhere. So the records are written here
//! (the [MCAP spec](https://mcap.dev/spec), checked by the `mcap` crate's reader and the
//! official Python reader in the tests and `tools/ci_mcap_check.sh`):
//!
//! ```text
//! magic  Header  [Schema | Channel | Message]* in chunks:  Chunk MessageIndex*  (Attachment)*
//!        DataEnd  Schema* Channel* Statistics ChunkIndex* AttachmentIndex* SummaryOffset*  Footer  magic
//! ```
//!
//! Messages (and the schema and channel records, as the `mcap` crate writes them) are appended
//! to the open chunk's uncompressed records on the caller's thread. Once the records pass the
//! chunk size the chunk is sealed with a sequence number and compressed: on the caller's thread
//! with `threads == 1`, else by one of `threads` workers (`std::thread`, fed through a bounded
//! `std::sync::mpsc` channel). The caller writes finished chunks strictly in sequence order, so
//! the file is the same, byte for byte, whatever the number of threads.
//!
//! **Memory bound.** At most [`in_flight_limit`]`(threads)` = 2 × `threads` sealed chunks are
//! in flight (queued, compressing, or compressed and waiting for an older one), plus the open
//! chunk: about (2 × threads + 1) × 1.5 × chunk size of record buffers (each has room for a
//! chunk and the message that passes the size; they are reused, never regrown) and at most as
//! many compressed-output buffers (zstd's bound: the chunk size and a little), plus the records
//! a worker still holds after the caller wrote its chunk uncompressed (≤ threads). With the
//! default 4 MiB chunks and 2 threads: 5 × 6 MiB + 5 × 4 MiB ≈ 50 MiB at most. When the limit is reached, [`Behind::Wait`] blocks the caller until the oldest chunk
//! is written (`decode`); [`Behind::WriteUncompressed`] never waits for compression (`listen`):
//! the oldest chunk is written uncompressed at once, which is valid MCAP, and counted in
//! [`WriterStats::chunks_uncompressed`]; nothing is dropped.
//!
//! A worker's failure (or panic) comes back as a [`SinkError`]; after any error the writer
//! refuses further writes, and [`McapSink`](super::McapSink) discards the output.

use std::collections::{BTreeMap, VecDeque};
use std::io::{self, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TryRecvError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use super::mcap::SinkError;

/// The MCAP magic at both ends of the file.
pub const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// Record opcodes (MCAP spec, "Records").
mod op {
    pub const HEADER: u8 = 0x01;
    pub const FOOTER: u8 = 0x02;
    pub const SCHEMA: u8 = 0x03;
    pub const CHANNEL: u8 = 0x04;
    pub const MESSAGE: u8 = 0x05;
    pub const CHUNK: u8 = 0x06;
    pub const MESSAGE_INDEX: u8 = 0x07;
    pub const CHUNK_INDEX: u8 = 0x08;
    pub const ATTACHMENT: u8 = 0x09;
    pub const ATTACHMENT_INDEX: u8 = 0x0A;
    pub const STATISTICS: u8 = 0x0B;
    pub const SUMMARY_OFFSET: u8 = 0x0E;
    pub const DATA_END: u8 = 0x0F;
}

/// Bytes of a message record before its data: opcode, length, channel id, sequence, log time,
/// publish time.
const MESSAGE_PREFIX: usize = 1 + 8 + 2 + 4 + 8 + 8;

/// Chunk compression with its setting.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Codec {
    /// Stored as is.
    None,
    /// Zstandard at this level (negative: its fast levels).
    Zstd(i32),
    /// LZ4 frame, default level, no block checksums (the chunk has its own CRC).
    Lz4,
}

impl Codec {
    /// The chunk record's `compression` string.
    pub fn name(self) -> &'static str {
        match self {
            Codec::None => "",
            Codec::Zstd(_) => "zstd",
            Codec::Lz4 => "lz4",
        }
    }
}

/// What to do when the workers are behind and the in-flight limit is reached.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Behind {
    /// Wait for the oldest chunk to be compressed and written (no chunk left uncompressed).
    #[default]
    Wait,
    /// Write the oldest chunk uncompressed at once and count it: the caller never waits for
    /// compression.
    WriteUncompressed,
}

/// Settings of a [`ChunkedWriter`].
#[derive(Clone, Debug)]
pub struct WriterOptions {
    /// The Header record's `library`.
    pub library: String,
    /// Chunk compression.
    pub codec: Codec,
    /// Target uncompressed chunk size: a chunk is sealed once its records pass it.
    pub chunk_size: usize,
    /// Compression threads: 1 = on the caller's thread, no worker; N > 1 = N workers.
    pub threads: usize,
    /// What to do when the workers fall behind.
    pub behind: Behind,
    /// The Header record's `profile` (`ros2` for a rosbag2's storage, else empty).
    pub profile: String,
}

/// Sealed chunks allowed in flight with `threads` workers (the memory bound).
pub fn in_flight_limit(threads: usize) -> usize {
    2 * threads.max(1)
}

/// One message's header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MessageHeader {
    /// Channel id.
    pub channel_id: u16,
    /// Per-channel sequence number.
    pub sequence: u32,
    /// Log time, ns.
    pub log_time: u64,
    /// Publish time, ns.
    pub publish_time: u64,
}

/// Counters of a writer.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WriterStats {
    /// Chunks written.
    pub chunks: u64,
    /// Of those, written uncompressed because compression was behind ([`Behind::WriteUncompressed`]).
    pub chunks_uncompressed: u64,
    /// Uncompressed bytes of chunk records.
    pub uncompressed_bytes: u64,
    /// Bytes of chunk data as written (compressed or not).
    pub chunk_data_bytes: u64,
}

/// What a finished file holds.
#[derive(Clone, Debug, Default)]
pub struct WriterSummary {
    /// (topic, messages) per channel, in channel order.
    pub channel_messages: Vec<(String, u64)>,
    /// (topic, schema name) per channel, in channel order.
    pub channel_schemas: Vec<(String, String)>,
    /// Earliest and latest message log time, if any message was written.
    pub bounds: Option<(u64, u64)>,
    /// Counters.
    pub stats: WriterStats,
}

// ---------------------------------------------------------------------------------------------
// Little-endian record encoding (MCAP spec, "Serialization").

fn put_u16(b: &mut Vec<u8>, v: u16) {
    b.extend_from_slice(&v.to_le_bytes());
}
fn put_u32(b: &mut Vec<u8>, v: u32) {
    b.extend_from_slice(&v.to_le_bytes());
}
fn put_u64(b: &mut Vec<u8>, v: u64) {
    b.extend_from_slice(&v.to_le_bytes());
}
/// `String`: u32 byte length, then the bytes. Callers keep strings far below 4 GiB.
fn put_str(b: &mut Vec<u8>, s: &str) {
    put_u32(b, s.len() as u32);
    b.extend_from_slice(s.as_bytes());
}
/// `Map<String, String>`: u32 byte length of the entries, then key, value pairs.
fn put_str_map(b: &mut Vec<u8>, m: &BTreeMap<String, String>) {
    let len: usize = m.iter().map(|(k, v)| 8 + k.len() + v.len()).sum();
    put_u32(b, len as u32);
    for (k, v) in m {
        put_str(b, k);
        put_str(b, v);
    }
}
/// `Map<uint16, uint64>`.
fn put_u16_u64_map(b: &mut Vec<u8>, m: &BTreeMap<u16, u64>) {
    put_u32(b, (m.len() * 10) as u32);
    for (&k, &v) in m {
        put_u16(b, k);
        put_u64(b, v);
    }
}

/// Appends one record: opcode, u64 length, then what `body` appends.
fn record(b: &mut Vec<u8>, opcode: u8, body: impl FnOnce(&mut Vec<u8>)) {
    b.push(opcode);
    let len_at = b.len();
    put_u64(b, 0);
    body(b);
    let len = (b.len() - len_at - 8) as u64;
    b[len_at..len_at + 8].copy_from_slice(&len.to_le_bytes());
}

// ---------------------------------------------------------------------------------------------
// Compression (the same function on the caller's thread and in the workers, so the bytes do not
// depend on where a chunk was compressed).

/// A chunk's data as it goes into the file.
struct Compressed {
    data: Vec<u8>,
    /// CRC-32 of the uncompressed records (the chunk's `uncompressed_crc`).
    uncompressed_crc: u32,
    /// CRC-32 state over `data`, combined into the data-section CRC without reading `data` again.
    data_crc: crc32fast::Hasher,
}

/// A reusable compression context.
struct Compressor {
    codec: Codec,
    zstd: Option<zstd::bulk::Compressor<'static>>,
}

impl Compressor {
    fn new(codec: Codec) -> Self {
        Self { codec, zstd: None }
    }

    /// Compresses `src` into `out` (cleared first).
    fn compress(&mut self, src: &[u8], mut out: Vec<u8>) -> io::Result<Compressed> {
        let mut hasher = crc32fast::Hasher::new();
        hasher.update(src);
        let uncompressed_crc = hasher.finalize();
        out.clear();
        match self.codec {
            Codec::None => out.extend_from_slice(src),
            Codec::Zstd(level) => {
                let z = match &mut self.zstd {
                    Some(z) => z,
                    None => self.zstd.insert(zstd::bulk::Compressor::new(level)?),
                };
                out.reserve(zstd::zstd_safe::compress_bound(src.len()));
                z.compress_to_buffer(src, &mut out)?;
            }
            Codec::Lz4 => {
                let mut enc = lz4::EncoderBuilder::new()
                    .level(0)
                    .block_checksum(lz4::liblz4::BlockChecksum::NoBlockChecksum)
                    .build(out)?;
                enc.write_all(src)?;
                let (o, r) = enc.finish();
                r?;
                out = o;
            }
        }
        let mut data_crc = crc32fast::Hasher::new();
        data_crc.update(&out);
        Ok(Compressed {
            data: out,
            uncompressed_crc,
            data_crc,
        })
    }
}

/// The chunk as stored uncompressed, with its CRC computed once for both uses.
fn stored(src: &[u8]) -> (u32, crc32fast::Hasher) {
    let mut h = crc32fast::Hasher::new();
    h.update(src);
    (h.clone().finalize(), h)
}

// ---------------------------------------------------------------------------------------------
// The worker pool.

/// A sealed chunk's records as the caller and the pool share them.
struct Shared {
    /// Taken by the worker that compresses the chunk, or by the caller when it writes the chunk
    /// uncompressed instead (so a queued job of a chunk already written holds no records).
    records: Mutex<Option<Arc<Vec<u8>>>>,
}

impl Shared {
    fn take(&self) -> Option<Arc<Vec<u8>>> {
        match self.records.lock() {
            Ok(mut g) => g.take(),
            Err(poisoned) => poisoned.into_inner().take(),
        }
    }
}

struct Job {
    seq: u64,
    shared: Arc<Shared>,
    /// A recycled output buffer.
    out: Vec<u8>,
}

struct Done {
    seq: u64,
    result: Result<Compressed, String>,
}

struct Pool {
    jobs: Option<SyncSender<Job>>,
    results: Receiver<Done>,
    workers: Vec<JoinHandle<()>>,
    /// Set on [`Pool::stop`]: workers skip the jobs still queued.
    stopping: Arc<AtomicBool>,
}

impl Pool {
    fn start(codec: Codec, threads: usize, queue: usize) -> Result<Self, SinkError> {
        let (job_tx, job_rx) = mpsc::sync_channel::<Job>(queue);
        let (done_tx, done_rx) = mpsc::channel::<Done>();
        let job_rx = Arc::new(Mutex::new(job_rx));
        let stopping = Arc::new(AtomicBool::new(false));
        let mut workers = Vec::with_capacity(threads);
        for i in 0..threads {
            let rx = job_rx.clone();
            let tx = done_tx.clone();
            let stop = stopping.clone();
            let handle = std::thread::Builder::new()
                .name(format!("ringscan-mcap-{i}"))
                .spawn(move || worker(codec, &rx, &tx, &stop))
                .map_err(|source| SinkError::Io {
                    context: format!("starting MCAP compression thread {i} of {threads}"),
                    source,
                })?;
            workers.push(handle);
        }
        Ok(Self {
            jobs: Some(job_tx),
            results: done_rx,
            workers,
            stopping,
        })
    }

    /// Closes the queue and joins the workers (each finishes the chunk it holds and skips the
    /// queued ones).
    fn stop(&mut self) {
        self.stopping.store(true, Ordering::Release);
        self.jobs = None;
        for w in self.workers.drain(..) {
            let _ = w.join();
        }
    }
}

impl Drop for Pool {
    fn drop(&mut self) {
        self.stop();
    }
}

fn worker(
    codec: Codec,
    jobs: &Mutex<Receiver<Job>>,
    done: &mpsc::Sender<Done>,
    stopping: &AtomicBool,
) {
    let mut compressor = Compressor::new(codec);
    loop {
        let job = {
            let rx = match jobs.lock() {
                Ok(g) => g,
                Err(poisoned) => poisoned.into_inner(),
            };
            rx.recv()
        };
        let Ok(job) = job else { return };
        if stopping.load(Ordering::Acquire) {
            continue;
        }
        // None: the caller wrote this chunk uncompressed meanwhile.
        let Some(records) = job.shared.take() else {
            continue;
        };
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            compressor.compress(&records, job.out)
        }));
        drop(records);
        let result = match result {
            Ok(Ok(c)) => Ok(c),
            Ok(Err(e)) => Err(e.to_string()),
            Err(_) => {
                // The context may be in any state after a panic: start a fresh one.
                compressor = Compressor::new(codec);
                Err("the compression thread panicked".into())
            }
        };
        if done
            .send(Done {
                seq: job.seq,
                result,
            })
            .is_err()
        {
            return;
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The writer.

/// The chunk being filled on the caller's thread.
#[derive(Default)]
struct OpenChunk {
    records: Vec<u8>,
    /// (channel id, [(log time, offset in `records`)]), channels in first-use order.
    indexes: Vec<(u16, Vec<(u64, u64)>)>,
    bounds: Option<(u64, u64)>,
}

/// A sealed chunk's index data, kept by the caller while the chunk is compressed.
struct ChunkMeta {
    indexes: Vec<(u16, Vec<(u64, u64)>)>,
    bounds: (u64, u64),
    uncompressed_size: u64,
}

enum Slot {
    Chunk {
        meta: ChunkMeta,
        records: Arc<Vec<u8>>,
        shared: Arc<Shared>,
        done: Option<Result<Compressed, String>>,
    },
    /// An attachment record, encoded, with its index fields but the offset.
    Attachment {
        record: Vec<u8>,
        index: AttachmentIndex,
    },
}

#[derive(Clone)]
struct ChunkIndex {
    bounds: (u64, u64),
    offset: u64,
    length: u64,
    message_index_offsets: BTreeMap<u16, u64>,
    message_index_length: u64,
    compression: &'static str,
    compressed_size: u64,
    uncompressed_size: u64,
}

#[derive(Clone)]
struct AttachmentIndex {
    offset: u64,
    length: u64,
    log_time: u64,
    create_time: u64,
    data_size: u64,
    name: String,
    media_type: String,
}

struct SchemaRecord {
    id: u16,
    name: String,
    encoding: String,
    data: Vec<u8>,
}

struct ChannelRecord {
    id: u16,
    schema_id: u16,
    topic: String,
    message_encoding: String,
    metadata: BTreeMap<String, String>,
    messages: u64,
}

/// The output stream with its position and the data-section CRC.
struct Out<W> {
    w: W,
    pos: u64,
    crc: crc32fast::Hasher,
    failed: bool,
}

impl<W: Write> Out<W> {
    fn write(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.crc.update(bytes);
        self.write_unhashed(bytes)
    }

    /// Writes bytes whose CRC state the caller already has (combined into the data CRC).
    fn write_hashed(&mut self, bytes: &[u8], crc: &crc32fast::Hasher) -> io::Result<()> {
        self.crc.combine(crc);
        self.write_unhashed(bytes)
    }

    fn write_unhashed(&mut self, bytes: &[u8]) -> io::Result<()> {
        if let Err(e) = self.w.write_all(bytes) {
            self.failed = true;
            return Err(e);
        }
        self.pos += bytes.len() as u64;
        Ok(())
    }
}

/// Writes an MCAP file with chunks compressed in order on `threads` threads. See the module
/// documentation.
pub struct ChunkedWriter<W: Write> {
    out: Out<W>,
    opts: WriterOptions,
    open: OpenChunk,
    /// Sealed chunks and attachments not yet written, oldest first.
    slots: VecDeque<Slot>,
    /// Sequence number of `slots[0]`.
    first_seq: u64,
    /// Sealed chunks among `slots`.
    chunks_in_flight: usize,
    pool: Option<Pool>,
    /// The caller's compressor (`threads == 1`).
    inline: Compressor,
    schemas: Vec<SchemaRecord>,
    channels: Vec<ChannelRecord>,
    chunk_indexes: Vec<ChunkIndex>,
    attachment_indexes: Vec<AttachmentIndex>,
    bounds: Option<(u64, u64)>,
    stats: WriterStats,
    /// Record buffers given back by written chunks, reused for new chunks.
    spare: Vec<Vec<u8>>,
    /// Compressed-output buffers given back, reused for new jobs.
    spare_out: Vec<Vec<u8>>,
    /// Scratch for small records.
    scratch: Vec<u8>,
}

fn failed_error() -> SinkError {
    SinkError::Io {
        context: "writing to an MCAP output that failed earlier".into(),
        source: io::Error::other("output failed"),
    }
}

fn io_error(context: &str) -> impl FnOnce(io::Error) -> SinkError + '_ {
    move |source| SinkError::Io {
        context: context.to_string(),
        source,
    }
}

impl<W: Write> ChunkedWriter<W> {
    /// Writes the magic and the Header record; starts the workers when `threads > 1` and the
    /// chunks are compressed.
    pub fn new(w: W, mut opts: WriterOptions) -> Result<Self, SinkError> {
        opts.threads = opts.threads.max(1);
        opts.chunk_size = opts.chunk_size.max(1);
        let pool = if opts.threads > 1 && opts.codec != Codec::None {
            Some(Pool::start(
                opts.codec,
                opts.threads,
                in_flight_limit(opts.threads),
            )?)
        } else {
            None
        };
        let mut me = Self {
            out: Out {
                w,
                pos: 0,
                crc: crc32fast::Hasher::new(),
                failed: false,
            },
            inline: Compressor::new(opts.codec),
            open: OpenChunk {
                records: Vec::with_capacity(opts.chunk_size + opts.chunk_size / 2),
                ..OpenChunk::default()
            },
            opts,
            slots: VecDeque::new(),
            first_seq: 0,
            chunks_in_flight: 0,
            pool,
            schemas: Vec::new(),
            channels: Vec::new(),
            chunk_indexes: Vec::new(),
            attachment_indexes: Vec::new(),
            bounds: None,
            stats: WriterStats::default(),
            spare: Vec::new(),
            spare_out: Vec::new(),
            scratch: Vec::new(),
        };
        let mut b = Vec::with_capacity(64);
        b.extend_from_slice(MAGIC);
        let library = me.opts.library.clone();
        let profile = me.opts.profile.clone();
        record(&mut b, op::HEADER, |b| {
            put_str(b, &profile);
            put_str(b, &library);
        });
        me.out
            .write(&b)
            .map_err(io_error("writing the MCAP header"))?;
        Ok(me)
    }

    /// Counters so far.
    pub fn stats(&self) -> WriterStats {
        self.stats
    }

    fn check(&self) -> Result<(), SinkError> {
        if self.out.failed {
            Err(failed_error())
        } else {
            Ok(())
        }
    }

    /// Adds a schema (ids from 1; 0 means "no schema" in MCAP). Its record goes into the open
    /// chunk, ahead of the messages that use it.
    pub fn add_schema(
        &mut self,
        name: &str,
        encoding: &str,
        data: &[u8],
    ) -> Result<u16, SinkError> {
        self.check()?;
        let id = u16::try_from(self.schemas.len() + 1).map_err(|_| SinkError::Io {
            context: format!("adding schema {name}"),
            source: io::Error::other("more than 65535 schemas"),
        })?;
        record(&mut self.open.records, op::SCHEMA, |b| {
            put_u16(b, id);
            put_str(b, name);
            put_str(b, encoding);
            put_u32(b, data.len() as u32);
            b.extend_from_slice(data);
        });
        self.schemas.push(SchemaRecord {
            id,
            name: name.into(),
            encoding: encoding.into(),
            data: data.into(),
        });
        Ok(id)
    }

    /// Adds a channel (ids from 1). Its record goes into the open chunk.
    pub fn add_channel(
        &mut self,
        schema_id: u16,
        topic: &str,
        message_encoding: &str,
        metadata: &BTreeMap<String, String>,
    ) -> Result<u16, SinkError> {
        self.check()?;
        let id = u16::try_from(self.channels.len() + 1).map_err(|_| SinkError::Io {
            context: format!("adding channel {topic}"),
            source: io::Error::other("more than 65535 channels"),
        })?;
        record(&mut self.open.records, op::CHANNEL, |b| {
            encode_channel(b, id, schema_id, topic, message_encoding, metadata);
        });
        self.channels.push(ChannelRecord {
            id,
            schema_id,
            topic: topic.into(),
            message_encoding: message_encoding.into(),
            metadata: metadata.clone(),
            messages: 0,
        });
        Ok(id)
    }

    /// Writes one message whose data is `data`.
    pub fn write_message(&mut self, header: &MessageHeader, data: &[u8]) -> Result<(), SinkError> {
        self.write_message_with(header, |b| {
            b.extend_from_slice(data);
            Ok(())
        })
    }

    /// Writes one message whose data `encode` appends to the chunk's records (no copy through
    /// another buffer). If `encode` fails, the message is left out and its error returned.
    pub fn write_message_with(
        &mut self,
        header: &MessageHeader,
        encode: impl FnOnce(&mut Vec<u8>) -> Result<(), SinkError>,
    ) -> Result<(), SinkError> {
        self.check()?;
        let channel = usize::from(header.channel_id)
            .checked_sub(1)
            .filter(|&i| i < self.channels.len())
            .ok_or_else(|| SinkError::Io {
                context: format!("writing a message to channel {}", header.channel_id),
                source: io::Error::other("no such channel"),
            })?;
        let records = &mut self.open.records;
        let start = records.len();
        records.reserve(MESSAGE_PREFIX);
        records.push(op::MESSAGE);
        put_u64(records, 0);
        put_u16(records, header.channel_id);
        put_u32(records, header.sequence);
        put_u64(records, header.log_time);
        put_u64(records, header.publish_time);
        if let Err(e) = encode(records) {
            records.truncate(start);
            return Err(e);
        }
        let len = (records.len() - start - 9) as u64;
        records[start + 1..start + 9].copy_from_slice(&len.to_le_bytes());
        let t = header.log_time;
        let entry = (t, start as u64);
        match self
            .open
            .indexes
            .iter_mut()
            .find(|(c, _)| *c == header.channel_id)
        {
            Some((_, v)) => v.push(entry),
            None => self.open.indexes.push((header.channel_id, vec![entry])),
        }
        self.open.bounds = Some(match self.open.bounds {
            None => (t, t),
            Some((a, b)) => (a.min(t), b.max(t)),
        });
        self.bounds = Some(match self.bounds {
            None => (t, t),
            Some((a, b)) => (a.min(t), b.max(t)),
        });
        self.channels[channel].messages += 1;
        if self.open.records.len() >= self.opts.chunk_size {
            self.seal()?;
        } else if self.chunks_in_flight > 0 {
            self.poll()?;
        }
        Ok(())
    }

    /// Writes an attachment record after the chunks sealed so far (the open chunk is sealed
    /// first, as attachments may not sit inside chunks).
    pub fn attach(
        &mut self,
        log_time: u64,
        create_time: u64,
        name: &str,
        media_type: &str,
        data: &[u8],
    ) -> Result<(), SinkError> {
        self.check()?;
        self.seal()?;
        let mut record_bytes = Vec::with_capacity(64 + name.len() + media_type.len() + data.len());
        record(&mut record_bytes, op::ATTACHMENT, |b| {
            let from = b.len();
            put_u64(b, log_time);
            put_u64(b, create_time);
            put_str(b, name);
            put_str(b, media_type);
            put_u64(b, data.len() as u64);
            b.extend_from_slice(data);
            // CRC-32 of every preceding field of the record.
            let crc = crc32fast::hash(&b[from..]);
            put_u32(b, crc);
        });
        let index = AttachmentIndex {
            offset: 0,
            length: record_bytes.len() as u64,
            log_time,
            create_time,
            data_size: data.len() as u64,
            name: name.into(),
            media_type: media_type.into(),
        };
        self.slots.push_back(Slot::Attachment {
            record: record_bytes,
            index,
        });
        self.write_ready()
    }

    /// Writes whatever chunks are compressed and next in order, without waiting.
    pub fn poll(&mut self) -> Result<(), SinkError> {
        self.check()?;
        while let Some(pool) = &self.pool {
            match pool.results.try_recv() {
                Ok(d) => self.absorb(d),
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => return Err(workers_gone()),
            }
        }
        self.write_ready()
    }

    /// Seals the open chunk (if it holds anything) and hands it to compression.
    fn seal(&mut self) -> Result<(), SinkError> {
        if self.open.records.is_empty() {
            return Ok(());
        }
        let spare = self.spare.pop().unwrap_or_else(|| {
            // Room for a chunk and the message that passes the size, without regrowing.
            Vec::with_capacity(self.opts.chunk_size + self.opts.chunk_size / 2)
        });
        let mut open = std::mem::replace(
            &mut self.open,
            OpenChunk {
                records: spare,
                ..OpenChunk::default()
            },
        );
        // Message index records list channels in ascending id order.
        open.indexes.sort_unstable_by_key(|(c, _)| *c);
        let meta = ChunkMeta {
            indexes: open.indexes,
            bounds: open.bounds.unwrap_or((0, 0)),
            uncompressed_size: open.records.len() as u64,
        };
        // The chunk's messages are already counted in the channels' statistics and the file's
        // time bounds: if it does not reach the file, neither may the summary that counts them.
        let r = self.hand_over(meta, open.records);
        if r.is_err() {
            self.out.failed = true;
        }
        r
    }

    /// Compresses and writes a sealed chunk here, or queues it for the workers.
    fn hand_over(&mut self, meta: ChunkMeta, records: Vec<u8>) -> Result<(), SinkError> {
        if self.pool.is_none() {
            // One thread (or no compression): compress here and write at once. Nothing is in
            // flight, so the order is kept.
            self.write_ready()?;
            return self.write_here(&meta, records);
        }
        // Make room: the memory bound.
        let limit = in_flight_limit(self.opts.threads);
        while self.chunks_in_flight >= limit {
            self.poll()?;
            if self.chunks_in_flight < limit {
                break;
            }
            match self.opts.behind {
                Behind::Wait => {
                    let d = self.recv()?;
                    self.absorb(d);
                    self.write_ready()?;
                }
                Behind::WriteUncompressed => self.write_oldest_uncompressed()?,
            }
        }
        let records = Arc::new(records);
        let shared = Arc::new(Shared {
            records: Mutex::new(Some(records.clone())),
        });
        let job = Job {
            seq: self.first_seq + self.slots.len() as u64,
            shared: shared.clone(),
            out: self.spare_out.pop().unwrap_or_default(),
        };
        let jobs = self
            .pool
            .as_ref()
            .and_then(|p| p.jobs.as_ref())
            .ok_or_else(workers_gone)?;
        // The queue holds the chunks in flight and, at worst, jobs of chunks already written
        // uncompressed that no worker has reached yet: full only when the workers get no CPU.
        let queued = match jobs.try_send(job) {
            Ok(()) => true,
            Err(mpsc::TrySendError::Full(job)) => match self.opts.behind {
                Behind::Wait => {
                    jobs.send(job).map_err(|_| workers_gone())?;
                    true
                }
                Behind::WriteUncompressed => false,
            },
            Err(mpsc::TrySendError::Disconnected(_)) => return Err(workers_gone()),
        };
        if !queued {
            // Everything older goes out uncompressed first, then this chunk.
            while self.chunks_in_flight > 0 {
                self.write_oldest_uncompressed()?;
            }
            self.write_ready()?;
            shared.take();
            let (uncompressed_crc, data_crc) = stored(&records);
            self.write_chunk(
                &meta,
                Codec::None.name(),
                &records,
                uncompressed_crc,
                &data_crc,
            )?;
            self.stats.chunks_uncompressed += 1;
            return Ok(());
        }
        self.slots.push_back(Slot::Chunk {
            meta,
            records,
            shared,
            done: None,
        });
        self.chunks_in_flight += 1;
        self.poll()
    }

    /// Compresses (unless the codec is `None`) and writes a chunk on the caller's thread.
    fn write_here(&mut self, meta: &ChunkMeta, records: Vec<u8>) -> Result<(), SinkError> {
        if self.opts.codec == Codec::None {
            let (uncompressed_crc, data_crc) = stored(&records);
            self.write_chunk(meta, "", &records, uncompressed_crc, &data_crc)?;
            self.recycle(records);
            return Ok(());
        }
        let out = self.spare_out.pop().unwrap_or_default();
        let c = self
            .inline
            .compress(&records, out)
            .map_err(|source| SinkError::Io {
                context: "compressing an MCAP chunk".into(),
                source,
            })?;
        self.recycle(records);
        let name = self.opts.codec.name();
        self.write_chunk(meta, name, &c.data, c.uncompressed_crc, &c.data_crc)?;
        self.recycle_out(c.data);
        Ok(())
    }

    /// Waits for the next worker result.
    fn recv(&self) -> Result<Done, SinkError> {
        let pool = self.pool.as_ref().ok_or_else(workers_gone)?;
        pool.results.recv().map_err(|_| workers_gone())
    }

    /// Files a worker's result with its chunk (results of chunks already written are dropped).
    fn absorb(&mut self, d: Done) {
        let Some(i) = d.seq.checked_sub(self.first_seq) else {
            return;
        };
        if let Some(Slot::Chunk { done, .. }) = self.slots.get_mut(i as usize) {
            if done.is_none() {
                *done = Some(d.result);
            }
        }
    }

    /// Writes the slots at the front that are ready, in order.
    fn write_ready(&mut self) -> Result<(), SinkError> {
        loop {
            let ready = match self.slots.front() {
                None => return Ok(()),
                Some(Slot::Attachment { .. }) => true,
                Some(Slot::Chunk { done, .. }) => done.is_some(),
            };
            if !ready {
                return Ok(());
            }
            let Some(slot) = self.slots.pop_front() else {
                return Ok(());
            };
            self.first_seq += 1;
            match slot {
                Slot::Attachment { record, mut index } => {
                    index.offset = self.out.pos;
                    self.out
                        .write(&record)
                        .map_err(io_error(&format!("writing attachment {}", index.name)))?;
                    self.attachment_indexes.push(index);
                }
                Slot::Chunk {
                    meta,
                    records,
                    done,
                    ..
                } => {
                    self.chunks_in_flight -= 1;
                    let c = match done {
                        Some(Ok(c)) => c,
                        Some(Err(e)) => {
                            self.out.failed = true;
                            return Err(SinkError::Io {
                                context: "compressing an MCAP chunk".into(),
                                source: io::Error::other(e),
                            });
                        }
                        None => return Err(workers_gone()),
                    };
                    let name = self.opts.codec.name();
                    self.write_chunk(&meta, name, &c.data, c.uncompressed_crc, &c.data_crc)?;
                    self.recycle_out(c.data);
                    if let Ok(v) = Arc::try_unwrap(records) {
                        self.recycle(v);
                    }
                }
            }
        }
    }

    /// [`Behind::WriteUncompressed`]: the oldest chunk goes out as it is, now.
    fn write_oldest_uncompressed(&mut self) -> Result<(), SinkError> {
        self.write_ready()?;
        let Some(Slot::Chunk {
            meta,
            records,
            shared,
            ..
        }) = self.slots.pop_front()
        else {
            return Ok(());
        };
        // A worker that has not started it will skip it (and hold no records meanwhile).
        shared.take();
        self.first_seq += 1;
        self.chunks_in_flight -= 1;
        let (uncompressed_crc, data_crc) = stored(&records);
        self.write_chunk(
            &meta,
            Codec::None.name(),
            &records,
            uncompressed_crc,
            &data_crc,
        )?;
        self.stats.chunks_uncompressed += 1;
        if let Ok(v) = Arc::try_unwrap(records) {
            self.recycle(v);
        }
        self.write_ready()
    }

    /// Buffers circulate: a new one is allocated only when no spare is left, so at most
    /// `in_flight_limit + 1` record buffers (and as many output buffers) ever exist, plus those a
    /// worker still holds after its chunk was written uncompressed.
    fn recycle(&mut self, mut v: Vec<u8>) {
        if self.spare.len() <= in_flight_limit(self.opts.threads) {
            v.clear();
            self.spare.push(v);
        }
    }

    fn recycle_out(&mut self, mut v: Vec<u8>) {
        if self.spare_out.len() <= in_flight_limit(self.opts.threads) {
            v.clear();
            self.spare_out.push(v);
        }
    }

    /// Writes a Chunk record (`data` compressed as `compression` says, `data_crc` its CRC state)
    /// and its Message Index records.
    fn write_chunk(
        &mut self,
        meta: &ChunkMeta,
        compression: &'static str,
        data: &[u8],
        uncompressed_crc: u32,
        data_crc: &crc32fast::Hasher,
    ) -> Result<(), SinkError> {
        let offset = self.out.pos;
        let mut head = std::mem::take(&mut self.scratch);
        head.clear();
        // The record length counts the fields and the data that follows this head.
        let body_len = 8 + 8 + 8 + 4 + 4 + compression.len() as u64 + 8 + data.len() as u64;
        head.push(op::CHUNK);
        put_u64(&mut head, body_len);
        put_u64(&mut head, meta.bounds.0);
        put_u64(&mut head, meta.bounds.1);
        put_u64(&mut head, meta.uncompressed_size);
        put_u32(&mut head, uncompressed_crc);
        put_str(&mut head, compression);
        put_u64(&mut head, data.len() as u64);
        let ctx = "writing an MCAP chunk";
        self.out.write(&head).map_err(io_error(ctx))?;
        self.out
            .write_hashed(data, data_crc)
            .map_err(io_error(ctx))?;
        let length = self.out.pos - offset;
        // Message indexes, channels in ascending order.
        head.clear();
        let index_start = self.out.pos;
        let mut message_index_offsets = BTreeMap::new();
        for (channel, entries) in &meta.indexes {
            message_index_offsets.insert(*channel, index_start + head.len() as u64);
            record(&mut head, op::MESSAGE_INDEX, |b| {
                put_u16(b, *channel);
                put_u32(b, (entries.len() * 16) as u32);
                for &(t, o) in entries {
                    put_u64(b, t);
                    put_u64(b, o);
                }
            });
        }
        self.out.write(&head).map_err(io_error(ctx))?;
        self.chunk_indexes.push(ChunkIndex {
            bounds: meta.bounds,
            offset,
            length,
            message_index_offsets,
            message_index_length: head.len() as u64,
            compression,
            compressed_size: data.len() as u64,
            uncompressed_size: meta.uncompressed_size,
        });
        self.scratch = head;
        self.stats.chunks += 1;
        self.stats.uncompressed_bytes += meta.uncompressed_size;
        self.stats.chunk_data_bytes += data.len() as u64;
        Ok(())
    }

    /// Seals the last chunk, waits for every chunk in flight, stops the workers and writes the
    /// Data End record, the summary section and the footer; returns the stream.
    pub fn finish(mut self) -> Result<(W, WriterSummary), SinkError> {
        self.check()?;
        self.seal()?;
        while !self.slots.is_empty() {
            self.write_ready()?;
            if self.slots.is_empty() {
                break;
            }
            let d = self.recv()?;
            self.absorb(d);
        }
        if let Some(mut pool) = self.pool.take() {
            pool.stop();
        }
        let data_crc = self.out.crc.clone().finalize();
        let mut b = Vec::new();
        record(&mut b, op::DATA_END, |b| put_u32(b, data_crc));
        self.out
            .write(&b)
            .map_err(io_error("writing the MCAP data end"))?;
        let summary_start = self.out.pos;
        let summary = self.summary_section(summary_start);
        self.out
            .write_unhashed(&summary)
            .map_err(io_error("writing the MCAP summary section"))?;
        self.out
            .w
            .flush()
            .map_err(io_error("flushing the MCAP output"))?;
        let channel_messages = self
            .channels
            .iter()
            .map(|c| (c.topic.clone(), c.messages))
            .collect();
        let channel_schemas = self
            .channels
            .iter()
            .map(|c| {
                let schema = self
                    .schemas
                    .iter()
                    .find(|s| s.id == c.schema_id)
                    .map(|s| s.name.clone())
                    .unwrap_or_default();
                (c.topic.clone(), schema)
            })
            .collect();
        let stats = self.stats;
        Ok((
            self.out.w,
            WriterSummary {
                channel_messages,
                channel_schemas,
                bounds: self.bounds,
                stats,
            },
        ))
    }

    /// The summary section, footer and closing magic, for a section starting at `start`.
    fn summary_section(&self, start: u64) -> Vec<u8> {
        let mut b = Vec::with_capacity(4096 + 100 * self.chunk_indexes.len());
        let mut groups: Vec<(u8, u64, u64)> = Vec::new();
        let mut group = |b: &Vec<u8>, opcode: u8, from: usize| {
            if b.len() > from {
                groups.push((opcode, start + from as u64, (b.len() - from) as u64));
            }
        };
        let from = b.len();
        for s in &self.schemas {
            record(&mut b, op::SCHEMA, |b| {
                put_u16(b, s.id);
                put_str(b, &s.name);
                put_str(b, &s.encoding);
                put_u32(b, s.data.len() as u32);
                b.extend_from_slice(&s.data);
            });
        }
        group(&b, op::SCHEMA, from);
        let from = b.len();
        for c in &self.channels {
            record(&mut b, op::CHANNEL, |b| {
                encode_channel(
                    b,
                    c.id,
                    c.schema_id,
                    &c.topic,
                    &c.message_encoding,
                    &c.metadata,
                );
            });
        }
        group(&b, op::CHANNEL, from);
        let from = b.len();
        let (t0, t1) = self.bounds.unwrap_or((0, 0));
        let counts: BTreeMap<u16, u64> = self
            .channels
            .iter()
            .filter(|c| c.messages > 0)
            .map(|c| (c.id, c.messages))
            .collect();
        record(&mut b, op::STATISTICS, |b| {
            put_u64(b, counts.values().sum());
            put_u16(b, self.schemas.len() as u16);
            put_u32(b, self.channels.len() as u32);
            put_u32(b, self.attachment_indexes.len() as u32);
            put_u32(b, 0); // metadata
            put_u32(b, self.chunk_indexes.len() as u32);
            put_u64(b, t0);
            put_u64(b, t1);
            put_u16_u64_map(b, &counts);
        });
        group(&b, op::STATISTICS, from);
        let from = b.len();
        for c in &self.chunk_indexes {
            record(&mut b, op::CHUNK_INDEX, |b| {
                put_u64(b, c.bounds.0);
                put_u64(b, c.bounds.1);
                put_u64(b, c.offset);
                put_u64(b, c.length);
                put_u16_u64_map(b, &c.message_index_offsets);
                put_u64(b, c.message_index_length);
                put_str(b, c.compression);
                put_u64(b, c.compressed_size);
                put_u64(b, c.uncompressed_size);
            });
        }
        group(&b, op::CHUNK_INDEX, from);
        let from = b.len();
        for a in &self.attachment_indexes {
            record(&mut b, op::ATTACHMENT_INDEX, |b| {
                put_u64(b, a.offset);
                put_u64(b, a.length);
                put_u64(b, a.log_time);
                put_u64(b, a.create_time);
                put_u64(b, a.data_size);
                put_str(b, &a.name);
                put_str(b, &a.media_type);
            });
        }
        group(&b, op::ATTACHMENT_INDEX, from);
        let offsets_at = b.len();
        for (opcode, group_start, group_length) in groups {
            record(&mut b, op::SUMMARY_OFFSET, |b| {
                b.push(opcode);
                put_u64(b, group_start);
                put_u64(b, group_length);
            });
        }
        // Footer: the summary CRC covers the summary section and the footer up to the CRC.
        b.push(op::FOOTER);
        put_u64(&mut b, 8 + 8 + 4);
        put_u64(&mut b, start);
        put_u64(&mut b, start + offsets_at as u64);
        let crc = crc32fast::hash(&b);
        put_u32(&mut b, crc);
        b.extend_from_slice(MAGIC);
        b
    }

    /// Gives up: stops the workers and returns the stream as it is (no summary).
    pub fn into_inner(mut self) -> W {
        if let Some(mut pool) = self.pool.take() {
            pool.stop();
        }
        self.out.w
    }
}

fn encode_channel(
    b: &mut Vec<u8>,
    id: u16,
    schema_id: u16,
    topic: &str,
    message_encoding: &str,
    metadata: &BTreeMap<String, String>,
) {
    put_u16(b, id);
    put_u16(b, schema_id);
    put_str(b, topic);
    put_str(b, message_encoding);
    put_str_map(b, metadata);
}

fn workers_gone() -> SinkError {
    SinkError::Io {
        context: "compressing MCAP chunks".into(),
        source: io::Error::other("the compression threads stopped"),
    }
}
