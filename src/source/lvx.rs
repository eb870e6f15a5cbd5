//! Livox Viewer recordings (`.lvx`, `.lvx2`) as a stream of UDP datagrams, like a pcap.
//!
//! The layouts and why each package becomes the datagram its sensor sent are in
//! [`crate::sensor::livox::lvx`]; this is the reading loop. The file is read front to back,
//! one package at a time (memory: one datagram). Each device gets a synthetic source address,
//! 127.0.0.N for the N-th device info block (N ≤ [`MAX_DEVICES`]; the packages of a 255th
//! device, which the header's u8 count allows, are counted in [`LvxStats::device_limit`] and
//! dropped), and its model's ports: MID-360 points to 56301 and
//! IMU to 56401, HAP 57000 / 58000, SDK1 models 56001 (points and IMU alike); 0.0.0.0:0 is
//! never used. A datagram's time is its package's timestamp (the file keeps no host time).
//!
//! Damage: a package whose header cannot be read (an `.lvx` data type SDK1 does not define, a
//! length beyond a datagram or beyond its frame) is counted in
//! [`LvxStats::malformed_packages`] and the rest of its frame is skipped (the frame header
//! says where the next one starts); a package of a device the headers do not list is counted
//! in `unknown_device` and skipped. A frame header that contradicts its position loses the
//! framing: an error. A file cut short ends the stream, [`LvxStats::truncated_at`] saying
//! where.

use std::io::{self, Read};
use std::net::{Ipv4Addr, SocketAddrV4};

use super::Datagram;
use crate::sensor::livox::lvx::{
    self, FrameHeader, LvxDevice, LvxHeaderError, LvxVersion, FRAME_HEADER_LEN, PRIVATE_HEADER_LEN,
    PUBLIC_HEADER_LEN,
};
use crate::sensor::livox::model::LivoxModel;

/// Largest frame accepted (a 50 ms frame of a HAP is about 1.5 MB).
pub const MAX_FRAME_BYTES: u64 = 256 << 20;
/// Devices with an address (127.0.0.1 … 127.0.0.254) at most.
pub const MAX_DEVICES: usize = 254;

/// Why a recording cannot be read (further).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LvxError {
    /// Reading failed.
    #[error("I/O error at byte {offset}: {source}")]
    Io {
        /// Offset reached.
        offset: u64,
        /// Underlying error.
        #[source]
        source: io::Error,
    },
    /// The headers are not a recording ringscan reads.
    #[error(transparent)]
    Header(#[from] LvxHeaderError),
    /// The file ends inside its headers.
    #[error("Livox recording cut short in its headers ({found} bytes of {needed})")]
    ShortHeader {
        /// Bytes the headers need.
        needed: u64,
        /// Bytes found.
        found: u64,
    },
    /// A frame header that contradicts itself: the framing is lost.
    #[error("Livox recording: frame header at byte {offset}: {reason}")]
    Frame {
        /// Offset of the frame header.
        offset: u64,
        /// What is wrong.
        reason: String,
    },
}

/// What an [`LvxSource`] saw so far.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct LvxStats {
    /// Bytes consumed.
    pub bytes: u64,
    /// Frames begun.
    pub frames: u64,
    /// Packages read.
    pub packages: u64,
    /// Datagrams returned.
    pub datagrams: u64,
    /// Packages whose header could not be read: the rest of their frame skipped.
    pub malformed_packages: u64,
    /// The first of them: offset and why.
    pub first_malformed: Option<(u64, String)>,
    /// Packages of a device the headers do not list: skipped.
    pub unknown_device: u64,
    /// Packages of devices beyond [`MAX_DEVICES`]: skipped.
    pub device_limit: u64,
    /// Where a file cut short ended the stream.
    pub truncated_at: Option<u64>,
    /// Time of the first datagram, ns.
    pub first_time_ns: Option<i64>,
    /// Time of the last datagram, ns.
    pub last_time_ns: Option<i64>,
}

/// Datagrams from a Livox recording. See the [module documentation](self).
pub struct LvxSource<R: Read> {
    reader: R,
    version: LvxVersion,
    frame_duration_ms: u32,
    devices: Vec<LvxDevice>,
    /// File offset of the next byte.
    pos: u64,
    /// The open frame's end (its next offset), `None` between frames.
    frame_end: Option<u64>,
    /// The package being read (header and data).
    pkg: Vec<u8>,
    datagram: Vec<u8>,
    done: bool,
    stats: LvxStats,
}

/// Whether `head` (a file's first bytes) is a Livox recording (signature and magic).
pub fn detect(head: &[u8]) -> bool {
    lvx::is_lvx(head)
}

/// Reads up to `out.len()` bytes; fewer only at the end of the input.
fn fill<R: Read>(r: &mut R, out: &mut [u8]) -> io::Result<usize> {
    let mut n = 0;
    while n < out.len() {
        match r.read(&mut out[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

impl<R: Read> LvxSource<R> {
    /// Reads the headers and device info blocks.
    pub fn new(mut reader: R) -> Result<Self, LvxError> {
        let io = |offset: u64| move |source| LvxError::Io { offset, source };
        let mut head = [0u8; PUBLIC_HEADER_LEN + PRIVATE_HEADER_LEN];
        let got = fill(&mut reader, &mut head).map_err(io(0))?;
        let version = lvx::public_header(&head[..got])?;
        if got < head.len() {
            return Err(LvxError::ShortHeader {
                needed: head.len() as u64,
                found: got as u64,
            });
        }
        let p = PUBLIC_HEADER_LEN;
        let frame_duration_ms =
            u32::from_le_bytes([head[p], head[p + 1], head[p + 2], head[p + 3]]);
        let count = usize::from(head[p + 4]);
        let mut pos = head.len() as u64;
        let mut block = vec![0u8; version.device_info_len()];
        let mut devices = Vec::with_capacity(count);
        for _ in 0..count {
            let got = fill(&mut reader, &mut block).map_err(io(pos))?;
            pos += got as u64;
            match lvx::device_info(version, &block[..got]) {
                Some(d) => devices.push(d),
                None => {
                    return Err(LvxError::ShortHeader {
                        needed: (head.len() + count * block.len()) as u64,
                        found: pos,
                    })
                }
            }
        }
        Ok(Self {
            reader,
            version,
            frame_duration_ms,
            devices,
            pos,
            frame_end: None,
            pkg: Vec::with_capacity(lvx::LVX2_PACKAGE_HEADER_LEN + lvx::MAX_PACKAGE_DATA),
            datagram: Vec::with_capacity(lvx::MAX_PACKAGE_DATA + 64),
            done: false,
            stats: LvxStats {
                bytes: pos,
                ..LvxStats::default()
            },
        })
    }

    /// `.lvx` or `.lvx2`.
    pub fn version(&self) -> LvxVersion {
        self.version
    }

    /// The frame duration the headers give, ms.
    pub fn frame_duration_ms(&self) -> u32 {
        self.frame_duration_ms
    }

    /// The device info blocks.
    pub fn devices(&self) -> &[LvxDevice] {
        &self.devices
    }

    /// The model every device is, when they agree and ringscan knows it.
    pub fn model(&self) -> Option<LivoxModel> {
        let first = self.devices.first()?.model?;
        self.devices
            .iter()
            .all(|d| d.model == Some(first))
            .then_some(first)
    }

    /// Counters so far.
    pub fn stats(&self) -> &LvxStats {
        &self.stats
    }

    /// Synthetic source address of device block `i`; `None` beyond [`MAX_DEVICES`].
    pub fn address(i: usize) -> Option<Ipv4Addr> {
        (i < MAX_DEVICES).then(|| Ipv4Addr::new(127, 0, 0, i as u8 + 1))
    }

    fn io(&self, source: io::Error) -> LvxError {
        LvxError::Io {
            offset: self.pos,
            source,
        }
    }

    /// Reads `n` bytes onto the package buffer; false (and the stream ended) when the file
    /// ends first.
    fn read_onto_pkg(&mut self, n: usize) -> Result<bool, LvxError> {
        let at = self.pkg.len();
        self.pkg.resize(at + n, 0);
        let got = fill(&mut self.reader, &mut self.pkg[at..]).map_err(|e| self.io(e))?;
        self.pos += got as u64;
        self.stats.bytes = self.pos;
        if got < n {
            self.pkg.truncate(at + got);
            self.done = true;
            self.stats.truncated_at = Some(self.pos);
            return Ok(false);
        }
        Ok(true)
    }

    /// Skips to `end` (the open frame's end); false when the file ends first.
    fn skip_to(&mut self, end: u64) -> Result<bool, LvxError> {
        let n = end.saturating_sub(self.pos);
        let got =
            io::copy(&mut (&mut self.reader).take(n), &mut io::sink()).map_err(|e| self.io(e))?;
        self.pos += got;
        self.stats.bytes = self.pos;
        if got < n {
            self.done = true;
            self.stats.truncated_at = Some(self.pos);
            return Ok(false);
        }
        Ok(true)
    }

    /// Reads the next frame header; false at the end of the file.
    fn open_frame(&mut self) -> Result<bool, LvxError> {
        self.pkg.clear();
        let mut b = [0u8; FRAME_HEADER_LEN];
        let got = fill(&mut self.reader, &mut b).map_err(|e| self.io(e))?;
        let at = self.pos;
        self.pos += got as u64;
        self.stats.bytes = self.pos;
        if got < FRAME_HEADER_LEN {
            self.done = true;
            if got > 0 {
                self.stats.truncated_at = Some(self.pos);
            }
            return Ok(false);
        }
        let Some(FrameHeader {
            current_offset,
            next_offset,
            ..
        }) = lvx::frame_header(&b)
        else {
            return Ok(false);
        };
        let frame = |reason: String| LvxError::Frame { offset: at, reason };
        if current_offset != at {
            return Err(frame(format!("says it is at byte {current_offset}")));
        }
        let len = next_offset.saturating_sub(at);
        if len < FRAME_HEADER_LEN as u64 || len > MAX_FRAME_BYTES {
            return Err(frame(format!(
                "next frame at byte {next_offset}: not after this header, or more than {MAX_FRAME_BYTES} bytes on"
            )));
        }
        self.stats.frames += 1;
        self.frame_end = Some(next_offset);
        Ok(true)
    }

    /// The next datagram; `Ok(None)` at the end of the file (or where it is cut short).
    pub fn next_datagram(&mut self) -> Result<Option<Datagram<'_>>, LvxError> {
        loop {
            if self.done {
                return Ok(None);
            }
            let end = match self.frame_end {
                Some(e) if self.pos < e => e,
                _ => {
                    self.frame_end = None;
                    if !self.open_frame()? {
                        return Ok(None);
                    }
                    continue;
                }
            };
            let start = self.pos;
            self.pkg.clear();
            let hl = self.version.package_header_len();
            if start + hl as u64 > end {
                self.malformed(start, "package header runs past its frame's end".into());
                if !self.skip_to(end)? {
                    return Ok(None);
                }
                continue;
            }
            if !self.read_onto_pkg(hl)? {
                return Ok(None);
            }
            let header = match lvx::package_header(self.version, &self.pkg) {
                Some(Ok(h)) => h,
                Some(Err(e)) => {
                    self.malformed(start, e.to_string());
                    if !self.skip_to(end)? {
                        return Ok(None);
                    }
                    continue;
                }
                None => return Ok(None),
            };
            if self.pos + header.data_len as u64 > end {
                self.malformed(start, "package data runs past its frame's end".into());
                if !self.skip_to(end)? {
                    return Ok(None);
                }
                continue;
            }
            if !self.read_onto_pkg(header.data_len)? {
                return Ok(None);
            }
            self.stats.packages += 1;
            let Some(device) = self.devices.iter().position(|d| d.id == header.device) else {
                self.stats.unknown_device += 1;
                continue;
            };
            let Some(addr) = Self::address(device) else {
                self.stats.device_limit += 1;
                continue;
            };
            let model = self.devices[device].model;
            lvx::package_datagram(self.version, &self.pkg, model, &mut self.datagram);
            let time_ns = lvx::package_time_ns(self.version, &self.pkg);
            let imu = header.data_type == self.imu_data_type();
            let port = port_of(model, imu);
            self.stats.datagrams += 1;
            self.stats.first_time_ns.get_or_insert(time_ns);
            self.stats.last_time_ns = Some(time_ns);
            return Ok(Some(Datagram {
                time_ns,
                src: SocketAddrV4::new(addr, port),
                dst: SocketAddrV4::new(Ipv4Addr::LOCALHOST, port),
                payload: &self.datagram,
            }));
        }
    }

    fn imu_data_type(&self) -> u8 {
        match self.version {
            LvxVersion::Lvx1 => 6,
            LvxVersion::Lvx2 => 0,
        }
    }

    fn malformed(&mut self, offset: u64, why: String) {
        self.stats.malformed_packages += 1;
        self.stats.first_malformed.get_or_insert((offset, why));
    }
}

/// The host port a device's datagrams went to.
fn port_of(model: Option<LivoxModel>, imu: bool) -> u16 {
    match model {
        Some(m) if imu => m.imu_port().unwrap_or(m.point_port()),
        Some(m) => m.point_port(),
        None => crate::sensor::livox::model::SDK1_FIRST_DATA_PORT,
    }
}
