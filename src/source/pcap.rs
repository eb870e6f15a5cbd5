//! pcap and pcapng captures as a stream of UDP datagrams.
//!
//! In: any [`Read`] holding a classic pcap (µs or ns timestamps, either byte order) or a pcapng
//! file (any number of sections and interfaces, either byte order). Out: one [`Datagram`] at a
//! time, IPv4 fragments reassembled ([`super::reassembly`]), with [`SourceStats`] counting
//! everything that was skipped.
//!
//! # Contract
//! - **Streaming, bounded memory.** The file is read record by record into one reused buffer
//!   (or, with [`PcapSource::read_ahead`], parsed where it lies in a few MiB-sized blocks read
//!   by a thread of its own); the file is never held in memory. A record or block header is
//!   checked against the limits *before* its body is read: classic records may hold at most
//!   max(snaplen, [`DEFAULT_RECORD_LIMIT`]) bytes, capped at [`MAX_RECORD_LIMIT`]; pcapng blocks
//!   at most [`MAX_RECORD_LIMIT`] bytes (packet blocks: the largest interface limit plus 64 KiB of
//!   header and options). Beyond that: [`SourceError::RecordTooLarge`]. Even below the limit the
//!   buffer grows only as bytes actually arrive, so a short file cannot make it allocate what a
//!   header merely claims.
//! - **No allocation per packet** once the buffers have grown to the largest record (the
//!   reassembler reuses its buffers too); the returned [`Datagram`] borrows from them.
//! - **Bad packets are counted, bad files are errors.** A packet whose link, IPv4 or UDP headers
//!   contradict themselves is counted in [`SourceStats::malformed`] and skipped. A file whose
//!   structure is broken (bad magic, impossible block length, a record larger than the limits,
//!   an unknown interface, …) is a [`SourceError`] naming the byte offset of the record or block.
//!   After an error the source is fused: further calls return `Ok(None)`.
//! - **A last record cut short by the end of the file is not an error**: it is reported in
//!   [`SourceStats::truncated_tail`] (its byte offset) and the stream ends with `Ok(None)`;
//!   capture tools killed mid-write leave exactly that.
//! - A record longer than the file's (non-zero) snaplen but within the limits is counted in
//!   `malformed` and skipped: no conforming writer produces one, and a hostile or corrupt one
//!   must not end the stream when the rest of the file is fine.
//! - Classic pcap with a link type ringscan does not understand is an error at
//!   [`PcapSource::new`] (nothing in the file could be read). In pcapng, interfaces of unknown
//!   link types may sit beside useful ones: their packets are counted in `non_udp`.
//! - pcapng Simple Packet Blocks carry no timestamp: they get the time of the previous record
//!   (0 if none).
//! - A datagram reassembled from fragments carries the capture time of the fragment that
//!   completed it (when a receiving kernel would have delivered it).
//!
//! # Why the record parsing is written here rather than taken from `pcap-file`
//! `pcap-file` 2 (`PcapParser`, `PcapNgParser`) parses complete slices, so the record length
//! has to be read and bounded by hand before any slice exists anyway, and it cannot give the
//! guarantees above: its Enhanced Packet Block ignores `if_tsresol` (raw timestamps are taken as
//! nanoseconds, while the pcapng default is microseconds), it allocates a `Vec` of options for
//! every packet, and its errors are static strings without the file offset. The formats are
//! small (classic pcap: a 24-byte header and 16-byte record headers; pcapng: SHB, IDB, EPB, SPB,
//! OPB), so they are parsed here with bounds-checked reads. References: the pcap and pcapng
//! IETF drafts (draft-ietf-opsawg-pcap, draft-ietf-opsawg-pcapng) and the tcpdump.org link-type
//! list.

use std::fs::File;
use std::io::{self, BufReader, Read};
use std::net::SocketAddrV4;
use std::ops::Range;
use std::path::{Path, PathBuf};

use super::link::{self, IpError, Ipv4Header, Link, UdpHeader, IPPROTO_UDP, UDP_HEADER_LEN};
use super::read_ahead::ReadAhead;
use super::reassembly::{FragmentKey, Push, Reassembler, ReassemblyConfig, ReassemblyStats};
use super::Datagram;

/// Record size allowed whatever the snaplen says (libpcap's largest snaplen).
pub const DEFAULT_RECORD_LIMIT: usize = 262_144;
/// Absolute cap on a record or block, whatever the header says.
pub const MAX_RECORD_LIMIT: usize = 16 << 20;
/// Interfaces allowed in one pcapng section.
pub const MAX_INTERFACES: usize = 4096;
/// Room for the fixed fields and options of a packet block beyond its captured bytes.
const PACKET_BLOCK_SLACK: usize = 64 << 10;
/// The body buffer grows at most this far ahead of the bytes actually read.
const READ_CHUNK: usize = 64 << 10;

const PCAPNG_SHB: u32 = 0x0a0d_0d0a;
const PCAPNG_IDB: u32 = 1;
const PCAPNG_OPB: u32 = 2;
const PCAPNG_SPB: u32 = 3;
const PCAPNG_EPB: u32 = 6;
const IDB_OPT_TSRESOL: u16 = 9;
const IDB_OPT_TSOFFSET: u16 = 14;

/// Errors of the pcap source: the file cannot be read further. Offsets are byte offsets in
/// the file of the record or block at fault.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SourceError {
    /// The file could not be opened.
    #[error("cannot open {path}: {source}")]
    Open {
        /// Path given.
        path: PathBuf,
        /// Underlying error.
        #[source]
        source: io::Error,
    },
    /// Reading failed.
    #[error("I/O error at byte {offset}: {source}")]
    Io {
        /// File offset where the read started.
        offset: u64,
        /// Underlying error.
        #[source]
        source: io::Error,
    },
    /// The file holds no byte at all.
    #[error("empty file: expected a pcap or pcapng header, found 0 bytes")]
    Empty,
    /// The file ends inside its file header (or first section header).
    #[error("file too short: expected a header of {expected} bytes, found {found}")]
    ShortHeader {
        /// Bytes the header needs.
        expected: u64,
        /// Bytes present.
        found: u64,
    },
    /// The first four bytes are no pcap or pcapng magic number.
    #[error(
        "not a pcap or pcapng file: expected magic a1b2c3d4 or a1b23c4d (either byte order) \
         or 0a0d0d0a, found {:02x}{:02x}{:02x}{:02x}",
        found[0], found[1], found[2], found[3]
    )]
    BadMagic {
        /// The four bytes found, in file order.
        found: [u8; 4],
    },
    /// A format version ringscan does not read (classic pcap 2.x, pcapng 1.x are read).
    #[error("unsupported format version {major}.{minor} at byte {offset}")]
    UnsupportedVersion {
        /// Offset of the version field.
        offset: u64,
        /// Major version found.
        major: u16,
        /// Minor version found.
        minor: u16,
    },
    /// A classic pcap whose link type is none of those in [`link`].
    #[error(
        "unsupported link type {linktype} at byte {offset}: expected Ethernet (1), NULL (0), \
         raw IP (101, 228), LOOP (108), Linux SLL (113) or SLL2 (276)"
    )]
    UnsupportedLinkType {
        /// Offset of the link-type field.
        offset: u64,
        /// Link type found.
        linktype: u32,
    },
    /// A record or block longer than the limits.
    #[error("record at byte {offset} claims {len} bytes, more than the limit of {limit}")]
    RecordTooLarge {
        /// Offset of the record or block.
        offset: u64,
        /// Length claimed.
        len: u64,
        /// Limit in force.
        limit: u64,
    },
    /// A pcapng block length that is not a multiple of 4 or below the block's minimum.
    #[error(
        "pcapng block of type {block_type:#x} at byte {offset}: length {len} is not a multiple \
         of 4 of at least {min} bytes"
    )]
    BadBlockLength {
        /// Offset of the block.
        offset: u64,
        /// Block type.
        block_type: u32,
        /// Length found.
        len: u64,
        /// Minimum length of this block type.
        min: u64,
    },
    /// A pcapng block whose trailing length differs from its leading length.
    #[error(
        "pcapng block of type {block_type:#x} at byte {offset}: trailing length {trailing} \
         differs from leading length {leading}"
    )]
    BlockLengthMismatch {
        /// Offset of the block.
        offset: u64,
        /// Block type.
        block_type: u32,
        /// Leading length.
        leading: u32,
        /// Trailing length.
        trailing: u32,
    },
    /// A pcapng block whose content contradicts its own length or the format.
    #[error("pcapng block of type {block_type:#x} at byte {offset}: {reason}")]
    BadBlock {
        /// Offset of the block.
        offset: u64,
        /// Block type.
        block_type: u32,
        /// What is wrong.
        reason: &'static str,
    },
    /// A pcapng packet block naming an interface no IDB of its section described.
    #[error(
        "pcapng packet block at byte {offset} names interface {interface}, but its section \
         describes {interfaces}"
    )]
    UnknownInterface {
        /// Offset of the block.
        offset: u64,
        /// Interface id found.
        interface: u32,
        /// Interfaces described so far in the section.
        interfaces: usize,
    },
}

/// What a [`PcapSource`] saw so far.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SourceStats {
    /// Packet records read (classic records; pcapng EPB, SPB, OPB). A truncated last record
    /// is not counted.
    pub records: u64,
    /// File bytes consumed so far, headers and skipped blocks included: the current file
    /// offset, for progress against the file size.
    pub bytes: u64,
    /// Complete UDP datagrams returned.
    pub datagrams: u64,
    /// Records skipped because they carry no IPv4 UDP: other IP protocols, ARP, IPv6, unknown
    /// pcapng link types, …
    pub non_udp: u64,
    /// Records skipped because their link, IPv4 or UDP headers contradict themselves or the
    /// record (for instance a UDP length beyond the bytes present in an untruncated record), or
    /// longer than the snaplen; and fragments the reassembler rejected as inconsistent.
    pub malformed: u64,
    /// Datagrams returned although the IPv4 total length of their (untruncated) record claims
    /// more bytes than the frame holds; their UDP length fits and delimits the payload. Early
    /// VLP-16 firmware does this in every position packet (total length 1234 in a 554-byte
    /// frame); other readers (VeloView, dpkt) accept those packets too. Included in `datagrams`.
    pub ip_length_overruns: u64,
    /// IPv4 UDP fragments accepted by the reassembler (duplicates included).
    pub fragments: u64,
    /// Datagrams reassembled from fragments (included in `datagrams`).
    pub reassembled: u64,
    /// Accepted fragments dropped without producing a datagram: timeout, memory bound,
    /// contradiction, or still incomplete at the end of the file.
    pub fragments_expired: u64,
    /// Records whose captured length is below the original length and whose IPv4 or UDP
    /// payload is therefore incomplete: skipped.
    pub truncated_records: u64,
    /// Byte offset of a last record or block cut short by the end of the file.
    pub truncated_tail: Option<u64>,
    /// Capture time of the first packet record, ns since the Unix epoch.
    pub first_time_ns: Option<i64>,
    /// Capture time of the last packet record, ns since the Unix epoch.
    pub last_time_ns: Option<i64>,
}

/// The container format of a capture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum FileFormat {
    /// Classic libpcap format.
    Pcap {
        /// Nanosecond timestamps (magic a1b23c4d) rather than microseconds.
        nanosecond: bool,
        /// Big-endian file.
        big_endian: bool,
        /// Snapshot length from the header (0: unspecified).
        snaplen: u32,
        /// Link type.
        linktype: u32,
    },
    /// pcapng.
    PcapNg {
        /// Big-endian current section.
        big_endian: bool,
        /// Interfaces described so far in the current section.
        interfaces: usize,
    },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Endian {
    Little,
    Big,
}

impl Endian {
    fn u16(self, bytes: &[u8], at: usize) -> Option<u16> {
        let b: [u8; 2] = bytes.get(at..at.checked_add(2)?)?.try_into().ok()?;
        Some(match self {
            Self::Little => u16::from_le_bytes(b),
            Self::Big => u16::from_be_bytes(b),
        })
    }

    fn u32(self, bytes: &[u8], at: usize) -> Option<u32> {
        let b: [u8; 4] = bytes.get(at..at.checked_add(4)?)?.try_into().ok()?;
        Some(match self {
            Self::Little => u32::from_le_bytes(b),
            Self::Big => u32::from_be_bytes(b),
        })
    }

    fn u64(self, bytes: &[u8], at: usize) -> Option<u64> {
        let b: [u8; 8] = bytes.get(at..at.checked_add(8)?)?.try_into().ok()?;
        Some(match self {
            Self::Little => u64::from_le_bytes(b),
            Self::Big => u64::from_be_bytes(b),
        })
    }
}

/// Timestamp unit of a pcapng interface (`if_tsresol`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum TsResolution {
    /// 10^-n s.
    Decimal(u8),
    /// 2^-n s.
    Binary(u8),
}

impl TsResolution {
    fn from_option(byte: u8) -> Self {
        if byte & 0x80 != 0 {
            Self::Binary(byte & 0x7f)
        } else {
            Self::Decimal(byte)
        }
    }

    /// Converts a raw timestamp into ns, saturating at the `i64` range.
    fn to_ns(self, raw: u64, offset_s: i64) -> i64 {
        let raw = i128::from(raw);
        let ns = match self {
            Self::Decimal(n) if n <= 9 => raw * 10_i128.pow(9 - u32::from(n)),
            Self::Decimal(n) => 10_i128.checked_pow(u32::from(n) - 9).map_or(0, |d| raw / d),
            // raw < 2^64 and 1e9 < 2^30: the product fits an i128; n ≤ 127.
            Self::Binary(n) => (raw * 1_000_000_000) >> n,
        };
        let ns = ns.saturating_add(i128::from(offset_s) * 1_000_000_000);
        i64::try_from(ns).unwrap_or(if ns < 0 { i64::MIN } else { i64::MAX })
    }
}

#[derive(Debug, Clone, Copy)]
struct Interface {
    linktype: u32,
    snaplen: u32,
    limit: usize,
    tsresol: TsResolution,
    tsoffset_s: i64,
}

#[derive(Debug)]
enum Format {
    Pcap {
        endian: Endian,
        nanosecond: bool,
        snaplen: u32,
        linktype: u32,
        limit: usize,
    },
    PcapNg {
        endian: Endian,
        interfaces: Vec<Interface>,
        packet_block_limit: usize,
    },
}

/// A packet record read into the buffer.
#[derive(Debug, Clone, Copy)]
struct Packet {
    time_ns: i64,
    linktype: u32,
    /// Frame bytes: `buf[start..start + len]`.
    start: usize,
    len: usize,
    /// Captured length below the original length.
    truncated: bool,
    /// Captured length above the (non-zero) snaplen.
    oversized: bool,
}

/// Where the payload of a found datagram lies.
#[derive(Debug, Clone, Copy)]
enum Loc {
    Record(usize, usize),
    Reassembled(usize, usize),
}

#[derive(Debug, Clone, Copy)]
struct Found {
    time_ns: i64,
    src: SocketAddrV4,
    dst: SocketAddrV4,
    loc: Loc,
}

/// Outcome of reading one pcapng block.
enum Block {
    Packet(Packet),
    Other,
    End,
}

fn record_limit(snaplen: u32) -> usize {
    usize::try_from(snaplen)
        .unwrap_or(usize::MAX)
        .clamp(DEFAULT_RECORD_LIMIT, MAX_RECORD_LIMIT)
}

/// Reads until `out` is full or the reader reports the end; returns the bytes read.
fn read_up_to<R: Read>(reader: &mut R, out: &mut [u8]) -> io::Result<usize> {
    let mut filled = 0;
    while let Some(rest) = out.get_mut(filled..).filter(|r| !r.is_empty()) {
        match reader.read(rest) {
            Ok(0) => break,
            Ok(n) => filled += n.min(rest.len()),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(filled)
}

/// UDP datagrams from a pcap or pcapng capture. See the [module documentation](self).
///
/// ```no_run
/// # fn main() -> Result<(), ringscan::source::pcap::SourceError> {
/// use ringscan::source::pcap::PcapSource;
/// let mut source = PcapSource::open("capture.pcap".as_ref())?;
/// while let Some(datagram) = source.next_datagram()? {
///     println!("{} bytes from {}", datagram.payload.len(), datagram.src);
/// }
/// println!("{:?}", source.stats());
/// # Ok(()) }
/// ```
pub struct PcapSource<R: Read> {
    reader: Feed<R>,
    format: Format,
    /// The current record or block body, at its high-water length.
    buf: Vec<u8>,
    /// The current classic record's place in the read-ahead block when it was read there
    /// without a copy (then `buf` does not hold it).
    lent: Option<Range<usize>>,
    reassembler: Reassembler,
    /// `stats.bytes` is also the file offset of the next byte to read.
    stats: SourceStats,
    finished: bool,
}

impl PcapSource<BufReader<File>> {
    /// Opens a capture file and reads its header.
    pub fn open(path: &Path) -> Result<Self, SourceError> {
        let file = File::open(path).map_err(|source| SourceError::Open {
            path: path.to_path_buf(),
            source,
        })?;
        Self::new(BufReader::with_capacity(1 << 16, file))
    }
}

/// Where a capture's bytes come from.
enum Feed<R> {
    Reader(R),
    /// Read on a thread of its own; classic records are parsed where they lie in its blocks.
    Ahead(Box<ReadAhead>),
}

impl<R: Read> Read for Feed<R> {
    fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
        match self {
            Feed::Reader(r) => r.read(out),
            Feed::Ahead(a) => a.read(out),
        }
    }
}

/// The bytes `Packet::start` and `Loc::Record` index: the lent range of the read-ahead block,
/// or the record buffer. (A function of the fields, not a method, so that the caller can
/// still change the counters while holding the slice.)
fn record_bytes<'a, R>(lent: &Option<Range<usize>>, feed: &'a Feed<R>, buf: &'a [u8]) -> &'a [u8] {
    match (lent, feed) {
        (Some(r), Feed::Ahead(a)) => a.block().get(r.clone()).unwrap_or(&[]),
        _ => buf,
    }
}

impl<R: Read> PcapSource<R> {
    /// Reads and checks the file header (classic pcap µs / ns in either byte order, or a pcapng
    /// section header block), with the default [`ReassemblyConfig`].
    pub fn new(reader: R) -> Result<Self, SourceError> {
        Self::with_reassembly(reader, ReassemblyConfig::default())
    }

    /// As [`new`](Self::new), with the given fragment reassembly limits.
    pub fn with_reassembly(reader: R, config: ReassemblyConfig) -> Result<Self, SourceError> {
        Self::with_feed(Feed::Reader(reader), config)
    }

    /// As [`new`](Self::new), the file read ahead on a thread ([`ReadAhead`]): classic pcap
    /// records whole inside one of its blocks are parsed there, without the copy into the
    /// record buffer (`R` is then not used).
    pub fn read_ahead(ahead: ReadAhead) -> Result<Self, SourceError> {
        Self::with_feed(Feed::Ahead(Box::new(ahead)), ReassemblyConfig::default())
    }

    fn with_feed(reader: Feed<R>, config: ReassemblyConfig) -> Result<Self, SourceError> {
        let mut source = Self {
            reader,
            lent: None,
            format: Format::PcapNg {
                endian: Endian::Little,
                interfaces: Vec::new(),
                packet_block_limit: DEFAULT_RECORD_LIMIT,
            },
            buf: Vec::new(),
            reassembler: Reassembler::new(config),
            stats: SourceStats::default(),
            finished: false,
        };
        source.read_file_header()?;
        Ok(source)
    }

    /// The next complete UDP datagram, `Ok(None)` at the end of the file. Records that carry
    /// none are counted in [`stats`](Self::stats) and skipped.
    pub fn next_datagram(&mut self) -> Result<Option<Datagram<'_>>, SourceError> {
        let found = loop {
            if self.finished {
                return Ok(None);
            }
            let packet = match self.next_packet() {
                Ok(Some(packet)) => packet,
                Ok(None) => {
                    self.finish();
                    return Ok(None);
                }
                Err(e) => {
                    self.finished = true;
                    return Err(e);
                }
            };
            if let Some(found) = self.handle_packet(packet) {
                break found;
            }
        };
        self.stats.datagrams += 1;
        let payload = match found.loc {
            Loc::Record(a, b) => record_bytes(&self.lent, &self.reader, &self.buf).get(a..b),
            Loc::Reassembled(a, b) => self.reassembler.completed().get(a..b),
        };
        Ok(Some(Datagram {
            time_ns: found.time_ns,
            src: found.src,
            dst: found.dst,
            payload: payload.unwrap_or(&[]),
        }))
    }

    /// Counters so far.
    pub fn stats(&self) -> &SourceStats {
        &self.stats
    }

    /// Counters of the fragment reassembler (duplicates, overlaps, rejected fragments, …).
    pub fn reassembly_stats(&self) -> &ReassemblyStats {
        self.reassembler.stats()
    }

    /// The fragment reassembler (pending sets and bytes).
    pub fn reassembler(&self) -> &Reassembler {
        &self.reassembler
    }

    /// The container format.
    pub fn format(&self) -> FileFormat {
        match &self.format {
            Format::Pcap {
                endian,
                nanosecond,
                snaplen,
                linktype,
                ..
            } => FileFormat::Pcap {
                nanosecond: *nanosecond,
                big_endian: *endian == Endian::Big,
                snaplen: *snaplen,
                linktype: *linktype,
            },
            Format::PcapNg {
                endian, interfaces, ..
            } => FileFormat::PcapNg {
                big_endian: *endian == Endian::Big,
                interfaces: interfaces.len(),
            },
        }
    }

    /// End of the file: fragments still waiting will never be completed.
    fn finish(&mut self) {
        self.reassembler.expire_all();
        self.sync_reassembly_stats();
        self.finished = true;
    }

    fn sync_reassembly_stats(&mut self) {
        let r = self.reassembler.stats();
        self.stats.fragments = r.fragments;
        self.stats.reassembled = r.reassembled;
        self.stats.fragments_expired = r.expired_fragments;
    }

    // ----- reading --------------------------------------------------------------------------

    fn offset(&self) -> u64 {
        self.stats.bytes
    }

    /// Reads into `out` until full or the end of the file; returns the bytes read.
    fn read_array(&mut self, out: &mut [u8]) -> Result<usize, SourceError> {
        let offset = self.offset();
        let n = read_up_to(&mut self.reader, out)
            .map_err(|source| SourceError::Io { offset, source })?;
        self.stats.bytes += n as u64;
        Ok(n)
    }

    /// Reads `n` bytes into `buf[..n]`; false if the file ended first. The buffer grows only as
    /// bytes arrive (at most [`READ_CHUNK`] or twice the bytes read ahead of them).
    fn read_body(&mut self, n: usize) -> Result<bool, SourceError> {
        let offset = self.offset();
        let mut filled = 0;
        while filled < n {
            let target = n.min(filled.saturating_mul(2).max(READ_CHUNK));
            if self.buf.len() < target {
                self.buf.resize(target, 0);
            }
            let Some(chunk) = self.buf.get_mut(filled..target) else {
                break;
            };
            let got = read_up_to(&mut self.reader, chunk)
                .map_err(|source| SourceError::Io { offset, source })?;
            filled += got;
            if got < chunk.len() {
                break;
            }
        }
        self.stats.bytes += filled as u64;
        Ok(filled == n)
    }

    /// [`Self::read_body`], or the record's place in the read-ahead block when it lies whole
    /// there (`lent`).
    fn read_record_body(&mut self, n: usize) -> Result<bool, SourceError> {
        if let Feed::Ahead(a) = &mut self.reader {
            let offset = self.stats.bytes;
            if let Some(r) = a
                .lend(n)
                .map_err(|source| SourceError::Io { offset, source })?
            {
                self.stats.bytes += n as u64;
                self.lent = Some(r);
                return Ok(true);
            }
        }
        self.read_body(n)
    }

    /// Skips `n` bytes; false if the file ended first.
    fn skip(&mut self, n: u64) -> Result<bool, SourceError> {
        let offset = self.offset();
        let skipped = io::copy(&mut (&mut self.reader).take(n), &mut io::sink())
            .map_err(|source| SourceError::Io { offset, source })?;
        self.stats.bytes += skipped;
        Ok(skipped == n)
    }

    fn read_file_header(&mut self) -> Result<(), SourceError> {
        let mut magic = [0_u8; 4];
        let n = self.read_array(&mut magic)?;
        if n == 0 {
            return Err(SourceError::Empty);
        }
        let classic = match magic {
            [0xd4, 0xc3, 0xb2, 0xa1] => Some((Endian::Little, false)),
            [0xa1, 0xb2, 0xc3, 0xd4] => Some((Endian::Big, false)),
            [0x4d, 0x3c, 0xb2, 0xa1] => Some((Endian::Little, true)),
            [0xa1, 0xb2, 0x3c, 0x4d] => Some((Endian::Big, true)),
            _ => None,
        };
        if n < 4 {
            return Err(SourceError::ShortHeader {
                expected: 24,
                found: n as u64,
            });
        }
        if let Some((endian, nanosecond)) = classic {
            return self.read_classic_header(endian, nanosecond);
        }
        if magic != PCAPNG_SHB.to_be_bytes() {
            return Err(SourceError::BadMagic { found: magic });
        }
        let mut len = [0_u8; 4];
        let got = self.read_array(&mut len)?;
        if got < 4 || !self.read_section_header(0, len)? {
            return Err(SourceError::ShortHeader {
                expected: 28,
                found: self.offset(),
            });
        }
        Ok(())
    }

    fn read_classic_header(&mut self, endian: Endian, nanosecond: bool) -> Result<(), SourceError> {
        let mut rest = [0_u8; 20];
        let n = self.read_array(&mut rest)?;
        if n < rest.len() {
            return Err(SourceError::ShortHeader {
                expected: 24,
                found: 4 + n as u64,
            });
        }
        let field = |at| endian.u32(&rest, at).unwrap_or(0);
        let major = endian.u16(&rest, 0).unwrap_or(0);
        let minor = endian.u16(&rest, 2).unwrap_or(0);
        if major != 2 {
            return Err(SourceError::UnsupportedVersion {
                offset: 4,
                major,
                minor,
            });
        }
        let snaplen = field(12);
        // The upper bits of the link-type field carry FCS information (pcap draft §4).
        let linktype = field(16) & 0xffff;
        if !link::is_supported_linktype(linktype) {
            return Err(SourceError::UnsupportedLinkType {
                offset: 20,
                linktype,
            });
        }
        self.format = Format::Pcap {
            endian,
            nanosecond,
            snaplen,
            linktype,
            limit: record_limit(snaplen),
        };
        Ok(())
    }

    /// The next packet record, `None` at the end of the file (or at a truncated tail).
    fn next_packet(&mut self) -> Result<Option<Packet>, SourceError> {
        loop {
            let start = self.offset();
            self.lent = None;
            let block = match &self.format {
                Format::Pcap { .. } => self.read_classic_record(start)?,
                Format::PcapNg { .. } => self.read_block(start)?,
            };
            match block {
                Block::Packet(packet) => {
                    self.stats.records += 1;
                    self.stats.first_time_ns.get_or_insert(packet.time_ns);
                    self.stats.last_time_ns = Some(packet.time_ns);
                    return Ok(Some(packet));
                }
                Block::Other => {}
                Block::End => return Ok(None),
            }
        }
    }

    /// Marks a record or block cut short by the end of the file.
    fn tail(&mut self, start: u64) -> Block {
        self.stats.truncated_tail = Some(start);
        Block::End
    }

    fn read_classic_record(&mut self, start: u64) -> Result<Block, SourceError> {
        let Format::Pcap {
            endian,
            nanosecond,
            snaplen,
            linktype,
            limit,
        } = self.format
        else {
            return Ok(Block::End);
        };
        let mut head = [0_u8; 16];
        match self.read_array(&mut head)? {
            0 => return Ok(Block::End),
            16 => {}
            _ => return Ok(self.tail(start)),
        }
        let field = |at| endian.u32(&head, at).unwrap_or(0);
        let (secs, frac, caplen, origlen) = (field(0), field(4), field(8), field(12));
        let len = usize::try_from(caplen).unwrap_or(usize::MAX);
        if len > limit {
            return Err(SourceError::RecordTooLarge {
                offset: start,
                len: u64::from(caplen),
                limit: limit as u64,
            });
        }
        if !self.read_record_body(len)? {
            return Ok(self.tail(start));
        }
        let frac_ns = if nanosecond {
            i64::from(frac)
        } else {
            i64::from(frac) * 1000
        };
        Ok(Block::Packet(Packet {
            time_ns: i64::from(secs) * 1_000_000_000 + frac_ns,
            linktype,
            start: 0,
            len,
            truncated: caplen < origlen,
            oversized: snaplen != 0 && caplen > snaplen,
        }))
    }

    fn ng_endian(&self) -> Endian {
        match self.format {
            Format::PcapNg { endian, .. } => endian,
            Format::Pcap { endian, .. } => endian,
        }
    }

    fn check_block_len(
        start: u64,
        block_type: u32,
        len: u32,
        min: u32,
        limit: usize,
    ) -> Result<usize, SourceError> {
        if len % 4 != 0 || len < min {
            return Err(SourceError::BadBlockLength {
                offset: start,
                block_type,
                len: u64::from(len),
                min: u64::from(min),
            });
        }
        let size = usize::try_from(len).unwrap_or(usize::MAX);
        if size > limit {
            return Err(SourceError::RecordTooLarge {
                offset: start,
                len: u64::from(len),
                limit: limit as u64,
            });
        }
        Ok(size)
    }

    /// Checks the trailing length at the end of a block body of `body_len` bytes in `buf`.
    fn check_trailer(
        &self,
        start: u64,
        block_type: u32,
        len: u32,
        body_len: usize,
    ) -> Result<(), SourceError> {
        let trailing = body_len
            .checked_sub(4)
            .and_then(|at| self.ng_endian().u32(&self.buf, at))
            .unwrap_or(0);
        if trailing != len {
            return Err(SourceError::BlockLengthMismatch {
                offset: start,
                block_type,
                leading: len,
                trailing,
            });
        }
        Ok(())
    }

    /// Reads a section header block whose type (4 bytes) was read and whose length field is
    /// `len_raw`. False at a truncated tail.
    fn read_section_header(&mut self, start: u64, len_raw: [u8; 4]) -> Result<bool, SourceError> {
        let mut bom = [0_u8; 4];
        if self.read_array(&mut bom)? < 4 {
            return Ok(false);
        }
        let endian = match bom {
            [0x4d, 0x3c, 0x2b, 0x1a] => Endian::Little,
            [0x1a, 0x2b, 0x3c, 0x4d] => Endian::Big,
            _ => {
                return Err(SourceError::BadBlock {
                    offset: start,
                    block_type: PCAPNG_SHB,
                    reason: "byte-order magic is neither 1a2b3c4d nor 4d3c2b1a",
                })
            }
        };
        let len = endian.u32(&len_raw, 0).unwrap_or(0);
        let size = Self::check_block_len(start, PCAPNG_SHB, len, 28, MAX_RECORD_LIMIT)?;
        // Body after type, length and byte-order magic: version, section length, options,
        // trailing length.
        let body_len = size - 12;
        if !self.read_body(body_len)? {
            return Ok(false);
        }
        let major = endian.u16(&self.buf, 0).unwrap_or(0);
        let minor = endian.u16(&self.buf, 2).unwrap_or(0);
        if major != 1 {
            return Err(SourceError::UnsupportedVersion {
                offset: start + 12,
                major,
                minor,
            });
        }
        self.format = Format::PcapNg {
            endian,
            interfaces: Vec::new(),
            packet_block_limit: DEFAULT_RECORD_LIMIT + PACKET_BLOCK_SLACK,
        };
        self.check_trailer(start, PCAPNG_SHB, len, body_len)?;
        Ok(true)
    }

    fn read_block(&mut self, start: u64) -> Result<Block, SourceError> {
        let mut head = [0_u8; 8];
        match self.read_array(&mut head)? {
            0 => return Ok(Block::End),
            8 => {}
            _ => return Ok(self.tail(start)),
        }
        let endian = self.ng_endian();
        let block_type = endian.u32(&head, 0).unwrap_or(0);
        let len_raw = [head[4], head[5], head[6], head[7]];
        if block_type == PCAPNG_SHB {
            // A new section, possibly of the other byte order.
            return Ok(if self.read_section_header(start, len_raw)? {
                Block::Other
            } else {
                self.tail(start)
            });
        }
        let len = endian.u32(&len_raw, 0).unwrap_or(0);
        let packet_block = matches!(block_type, PCAPNG_EPB | PCAPNG_SPB | PCAPNG_OPB);
        let limit = match &self.format {
            Format::PcapNg {
                packet_block_limit, ..
            } if packet_block => *packet_block_limit,
            _ => MAX_RECORD_LIMIT,
        };
        let min = match block_type {
            PCAPNG_EPB | PCAPNG_OPB => 32,
            PCAPNG_IDB | PCAPNG_SPB => 20,
            _ => 12,
        };
        let size = Self::check_block_len(start, block_type, len, min, limit)?;
        let body_len = size - 8;
        if !matches!(
            block_type,
            PCAPNG_IDB | PCAPNG_EPB | PCAPNG_SPB | PCAPNG_OPB
        ) {
            // Skipped without buffering; its trailing length still has to match.
            let mut trailer = [0_u8; 4];
            if !self.skip(body_len as u64 - 4)? || self.read_array(&mut trailer)? < 4 {
                return Ok(self.tail(start));
            }
            let trailing = endian.u32(&trailer, 0).unwrap_or(0);
            if trailing != len {
                return Err(SourceError::BlockLengthMismatch {
                    offset: start,
                    block_type,
                    leading: len,
                    trailing,
                });
            }
            return Ok(Block::Other);
        }
        if !self.read_body(body_len)? {
            return Ok(self.tail(start));
        }
        self.check_trailer(start, block_type, len, body_len)?;
        // Content ends before the trailing length.
        let content = body_len - 4;
        match block_type {
            PCAPNG_IDB => {
                self.parse_interface(start, endian, content)?;
                Ok(Block::Other)
            }
            PCAPNG_SPB => self
                .parse_simple_packet(start, endian, content)
                .map(Block::Packet),
            _ => self
                .parse_packet(start, block_type, endian, content)
                .map(Block::Packet),
        }
    }

    fn parse_interface(
        &mut self,
        start: u64,
        e: Endian,
        content: usize,
    ) -> Result<(), SourceError> {
        let bad = |reason| SourceError::BadBlock {
            offset: start,
            block_type: PCAPNG_IDB,
            reason,
        };
        let buf = self.buf.get(..content).unwrap_or(&[]);
        let linktype = u32::from(
            e.u16(buf, 0)
                .ok_or_else(|| bad("shorter than its fields"))?,
        );
        let snaplen = e
            .u32(buf, 4)
            .ok_or_else(|| bad("shorter than its fields"))?;
        let mut tsresol = TsResolution::Decimal(6);
        let mut tsoffset_s = 0_i64;
        let mut at = 8;
        while let (Some(code), Some(olen)) = (e.u16(buf, at), e.u16(buf, at + 2)) {
            at += 4;
            if code == 0 {
                break;
            }
            let olen = usize::from(olen);
            let value = buf
                .get(at..at + olen)
                .ok_or_else(|| bad("an option overruns the block"))?;
            match (code, value) {
                (IDB_OPT_TSRESOL, &[v]) => tsresol = TsResolution::from_option(v),
                (IDB_OPT_TSOFFSET, v) if v.len() == 8 => {
                    tsoffset_s = e.u64(v, 0).map_or(0, |v| v as i64);
                }
                _ => {}
            }
            at += (olen + 3) & !3;
        }
        let Format::PcapNg {
            interfaces,
            packet_block_limit,
            ..
        } = &mut self.format
        else {
            return Ok(());
        };
        if interfaces.len() >= MAX_INTERFACES {
            return Err(bad(
                "more interfaces in one section than ringscan accepts (4096)",
            ));
        }
        let limit = record_limit(snaplen);
        *packet_block_limit = (*packet_block_limit).max(limit + PACKET_BLOCK_SLACK);
        interfaces.push(Interface {
            linktype,
            snaplen,
            limit,
            tsresol,
            tsoffset_s,
        });
        Ok(())
    }

    fn interface(&self, start: u64, id: u32) -> Result<Interface, SourceError> {
        let Format::PcapNg { interfaces, .. } = &self.format else {
            return Err(SourceError::UnknownInterface {
                offset: start,
                interface: id,
                interfaces: 0,
            });
        };
        usize::try_from(id)
            .ok()
            .and_then(|i| interfaces.get(i))
            .copied()
            .ok_or(SourceError::UnknownInterface {
                offset: start,
                interface: id,
                interfaces: interfaces.len(),
            })
    }

    /// Enhanced (type 6) and obsolete (type 2) packet blocks: same fields but the interface id
    /// (u32, or u16 + u16 drop count).
    fn parse_packet(
        &self,
        start: u64,
        block_type: u32,
        e: Endian,
        content: usize,
    ) -> Result<Packet, SourceError> {
        let bad = |reason| SourceError::BadBlock {
            offset: start,
            block_type,
            reason,
        };
        let buf = self.buf.get(..content).unwrap_or(&[]);
        let field = |at| {
            e.u32(buf, at)
                .ok_or_else(|| bad("shorter than its fixed fields"))
        };
        let id = if block_type == PCAPNG_EPB {
            field(0)?
        } else {
            u32::from(
                e.u16(buf, 0)
                    .ok_or_else(|| bad("shorter than its fixed fields"))?,
            )
        };
        let (ts_high, ts_low, caplen, origlen) = (field(4)?, field(8)?, field(12)?, field(16)?);
        let len = usize::try_from(caplen).unwrap_or(usize::MAX);
        if len > content - 20 {
            return Err(bad("captured length overruns the block"));
        }
        let iface = self.interface(start, id)?;
        if len > iface.limit {
            return Err(SourceError::RecordTooLarge {
                offset: start,
                len: u64::from(caplen),
                limit: iface.limit as u64,
            });
        }
        let raw = (u64::from(ts_high) << 32) | u64::from(ts_low);
        Ok(Packet {
            time_ns: iface.tsresol.to_ns(raw, iface.tsoffset_s),
            linktype: iface.linktype,
            start: 20,
            len,
            truncated: caplen < origlen,
            oversized: iface.snaplen != 0 && caplen > iface.snaplen,
        })
    }

    /// Simple packet block: no interface id (always 0), no timestamp, captured length implied.
    fn parse_simple_packet(
        &self,
        start: u64,
        e: Endian,
        content: usize,
    ) -> Result<Packet, SourceError> {
        let origlen = e.u32(&self.buf, 0).unwrap_or(0);
        let iface = self.interface(start, 0)?;
        let mut len = (content - 4).min(usize::try_from(origlen).unwrap_or(usize::MAX));
        if iface.snaplen != 0 {
            len = len.min(usize::try_from(iface.snaplen).unwrap_or(usize::MAX));
        }
        Ok(Packet {
            time_ns: self.stats.last_time_ns.unwrap_or(0),
            linktype: iface.linktype,
            start: 4,
            len,
            truncated: (len as u64) < u64::from(origlen),
            oversized: false,
        })
    }

    // ----- packets --------------------------------------------------------------------------

    /// Counts a record whose headers stop early: truncated if the capture cut it, else malformed.
    fn count_short(&mut self, packet: &Packet) {
        if packet.truncated {
            self.stats.truncated_records += 1;
        } else {
            self.stats.malformed += 1;
        }
    }

    /// Finds the UDP datagram in a packet record, through the reassembler for fragments.
    fn handle_packet(&mut self, packet: Packet) -> Option<Found> {
        if packet.oversized {
            self.stats.malformed += 1;
            return None;
        }
        let frame = record_bytes(&self.lent, &self.reader, &self.buf)
            .get(packet.start..packet.start + packet.len)
            .unwrap_or(&[]);
        let ip_start = match link::ipv4_in_frame(packet.linktype, frame) {
            Link::Ipv4 { offset } => offset,
            Link::NotIpv4 => {
                self.stats.non_udp += 1;
                return None;
            }
            Link::Short { .. } => {
                self.count_short(&packet);
                return None;
            }
        };
        let ip_bytes = frame.get(ip_start..).unwrap_or(&[]);
        let mut overrun = false;
        let ip = match Ipv4Header::parse(ip_bytes) {
            Ok(ip) => ip,
            // A complete frame whose IPv4 total length claims more than it holds: accepted
            // for unfragmented datagrams if the UDP length fits (see `ip_length_overruns`).
            Err(IpError::Truncated { .. }) if !packet.truncated => {
                match Ipv4Header::parse_overrun(ip_bytes) {
                    Ok(ip) if !ip.is_fragment() => {
                        overrun = true;
                        ip
                    }
                    _ => {
                        self.stats.malformed += 1;
                        return None;
                    }
                }
            }
            Err(e) if e.is_short() => {
                self.count_short(&packet);
                return None;
            }
            Err(_) => {
                self.stats.malformed += 1;
                return None;
            }
        };
        if ip.protocol != IPPROTO_UDP {
            self.stats.non_udp += 1;
            return None;
        }
        let src = ip.src;
        let dst = ip.dst;
        let ip_payload = ip.payload(ip_bytes);
        if ip.is_fragment() {
            let key = FragmentKey {
                src,
                dst,
                protocol: ip.protocol,
                id: ip.id,
            };
            let pushed = self.reassembler.push(
                packet.time_ns,
                key,
                ip.fragment_offset,
                ip.more_fragments,
                ip_payload,
            );
            self.sync_reassembly_stats();
            let len = match pushed {
                Push::Complete { len } => len,
                Push::Pending | Push::Dropped => return None,
                Push::Rejected(_) => {
                    self.stats.malformed += 1;
                    return None;
                }
            };
            let datagram = self.reassembler.completed().get(..len).unwrap_or(&[]);
            let Ok(udp) = UdpHeader::parse(datagram) else {
                // A reassembled datagram is complete by construction: any mismatch is malformed.
                self.stats.malformed += 1;
                return None;
            };
            return Some(Found {
                time_ns: packet.time_ns,
                src: SocketAddrV4::new(src, udp.src_port),
                dst: SocketAddrV4::new(dst, udp.dst_port),
                loc: Loc::Reassembled(UDP_HEADER_LEN, udp.len),
            });
        }
        let udp = match UdpHeader::parse(ip_payload) {
            Ok(udp) => udp,
            Err(e) if e.is_short() => {
                self.count_short(&packet);
                return None;
            }
            Err(_) => {
                self.stats.malformed += 1;
                return None;
            }
        };
        if overrun {
            self.stats.ip_length_overruns += 1;
        }
        let udp_start = packet.start + ip_start + ip.header_len;
        Some(Found {
            time_ns: packet.time_ns,
            src: SocketAddrV4::new(src, udp.src_port),
            dst: SocketAddrV4::new(dst, udp.dst_port),
            loc: Loc::Record(udp_start + UDP_HEADER_LEN, udp_start + udp.len),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tsresol_decimal_and_binary() {
        assert_eq!(TsResolution::from_option(6), TsResolution::Decimal(6));
        assert_eq!(TsResolution::from_option(0x8a), TsResolution::Binary(10));
        assert_eq!(TsResolution::Decimal(6).to_ns(1_500_000, 0), 1_500_000_000);
        assert_eq!(TsResolution::Decimal(9).to_ns(7, 0), 7);
        assert_eq!(TsResolution::Decimal(12).to_ns(7_000, 0), 7);
        assert_eq!(TsResolution::Decimal(127).to_ns(u64::MAX, 0), 0);
        assert_eq!(
            TsResolution::Binary(10).to_ns(1024 * 3 + 512, 0),
            3_500_000_000
        );
        assert_eq!(TsResolution::Binary(127).to_ns(u64::MAX, 0), 0);
        assert_eq!(TsResolution::Decimal(0).to_ns(u64::MAX, 0), i64::MAX);
        assert_eq!(TsResolution::Decimal(6).to_ns(0, 100), 100_000_000_000);
        assert_eq!(TsResolution::Decimal(6).to_ns(0, i64::MIN), i64::MIN);
    }

    #[test]
    fn record_limit_is_bounded_both_ways() {
        assert_eq!(record_limit(0), DEFAULT_RECORD_LIMIT);
        assert_eq!(record_limit(65_535), DEFAULT_RECORD_LIMIT);
        assert_eq!(record_limit(1 << 20), 1 << 20);
        assert_eq!(record_limit(u32::MAX), MAX_RECORD_LIMIT);
    }

    /// A reader that hands out one byte per call and is interrupted in between.
    struct Trickle<'a> {
        data: &'a [u8],
        interrupt: bool,
    }

    impl Read for Trickle<'_> {
        fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
            self.interrupt = !self.interrupt;
            if self.interrupt {
                return Err(io::ErrorKind::Interrupted.into());
            }
            match (self.data.split_first(), out.first_mut()) {
                (Some((&b, rest)), Some(slot)) => {
                    *slot = b;
                    self.data = rest;
                    Ok(1)
                }
                _ => Ok(0),
            }
        }
    }

    #[test]
    fn short_reads_and_interrupts_are_retried() {
        // Classic pcap header, Ethernet, then one record holding a 60-byte frame of zeros.
        let mut file = vec![0xd4, 0xc3, 0xb2, 0xa1, 2, 0, 4, 0, 0, 0, 0, 0, 0, 0, 0, 0];
        file.extend_from_slice(&[0xff, 0xff, 0, 0, 1, 0, 0, 0]);
        file.extend_from_slice(&[1, 0, 0, 0, 0, 0, 0, 0, 60, 0, 0, 0, 60, 0, 0, 0]);
        file.extend_from_slice(&[0; 60]);
        let mut source = PcapSource::new(Trickle {
            data: &file,
            interrupt: false,
        })
        .unwrap();
        assert!(source.next_datagram().unwrap().is_none());
        assert_eq!(source.stats().records, 1);
        assert_eq!(source.stats().non_udp, 1); // EtherType 0
        assert_eq!(source.stats().bytes, file.len() as u64);
        assert_eq!(source.stats().truncated_tail, None);
    }
}
