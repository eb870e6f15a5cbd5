//! RS-LiDAR-M1 / M1 Plus (MEMS): the 1210-byte MSOP point packet, the 256-byte DIFOP and the
//! decoder. Facts from RoboSense's SDK `rs_driver` (`decoder_RSM1.hpp`, its packet-length table
//! in `doc/howto/12_how_to_configure_by_pcap_file.md` and its source introduction) and the M1
//! Plus datasheet as a third-party driver quotes it; read, not copied. Both units send the same
//! MSOP layout; they differ only in the DIFOP's device-information fields (below).
//!
//! **MSOP** (port 6699, 630 packets per 100 ms frame in single return, 1260 in dual), all
//! multi-byte fields big-endian:
//!
//! | bytes | field |
//! |---|---|
//! | 0–3 | id `55 AA 5A A5` |
//! | 4–5 | packet counter: 1 for the frame's first packet, up to 630 (1260 dual) |
//! | 6–7 | protocol version |
//! | 8 | return mode |
//! | 9 | time mode |
//! | 10–19 | time of the packet: seconds (u48) + µs (u32) |
//! | 20–29 | reserved |
//! | 30 | lidar type |
//! | 31 | temperature, °C + 80 |
//! | 32–1206 | 25 blocks of 47 bytes |
//! | 1207–1209 | reserved |
//!
//! A block is its time offset from the packet time (u8, µs), a return sequence byte, then 5
//! channels of 9 bytes: radius (u16, 5 mm), elevation and azimuth (u16 each, 0.01°, offset by
//! 32768: raw 32768 is 0°), intensity, point attribute, elongation. Every point carries its own
//! angles, so no angle table exists and packets never wait for a DIFOP.
//!
//! **Frame.** The M1's angles are spherical about its optical axis: `x = r·cos(el)·cos(az)`,
//! `y = r·cos(el)·sin(az)`, `z = r·sin(el)` (rs_driver's formula), elevation positive up,
//! azimuth positive counter-clockwise seen from above (towards +y). That is REP 103 already (x
//! forward out of the window, y left, z up), so ringscan keeps it unchanged.
//!
//! **Ring** = the channel, 0..4 (the M1's five lasers; rs_driver's `ring` is the same), not an
//! elevation rank: the five channels scan interleaved bands of the field of view.
//!
//! **Return.** rs_driver does not read the block's return sequence byte and the public
//! sources read do not say how it numbers the returns of a dual-return packet: ringscan's `ret`
//! is 0 for a byte of 0 and 1 for any other value.
//!
//! **DIFOP** (port 7788, 256 bytes): id `A5 FF 00 5A 11 11 55 55`, frame rate (byte 9),
//! sensor and destination addresses (10–17), MAC (18–23), MSOP and DIFOP ports (24–27), PL
//! and PS firmware versions (5 bytes each at 28 and 33). From byte 38 the two sources part:
//! rs_driver (since December 2023) has the serial at 38–43 and the return mode at 44, the M1
//! Plus datasheet the return mode at 54 and the time-sync fields after it. ringscan shows the
//! DIFOP's addresses, frame rate, firmware and bytes 38–43 as the serial, and takes the
//! return mode from the MSOP header (byte 8), which both agree on.

use super::decode::cs;
use super::wire::be16;
use crate::point::Point;
use crate::sensor::{DecodeOptions, WireError};

/// MSOP length.
pub const M1_MSOP_LEN: usize = 1210;
/// DIFOP length.
pub const M1_DIFOP_LEN: usize = 256;
/// MSOP id.
pub const M1_MSOP_ID: [u8; 4] = [0x55, 0xAA, 0x5A, 0xA5];
/// Blocks per MSOP packet.
pub const M1_BLOCKS: usize = 25;
/// Channels per block.
pub const M1_CHANNELS: usize = 5;
/// Header length.
pub const M1_HEADER_LEN: usize = 32;
/// Block length: time offset, return sequence, 5 × 9-byte channels.
pub const M1_BLOCK_LEN: usize = 2 + 9 * M1_CHANNELS;
/// Raw angle of 0°.
pub const M1_ANGLE_OFFSET: u16 = 32_768;
/// Radius unit, metres.
pub const M1_RADIUS_UNIT_M: f32 = 0.005;
/// Shortest and longest valid radius, metres (rs_driver's constants).
pub const M1_MIN_RANGE_M: f32 = 0.2;
/// Longest valid radius, metres.
pub const M1_MAX_RANGE_M: f32 = 200.0;
/// MSOP packets per frame in single return (rs_driver; the M1 Plus datasheet's last counter).
pub const M1_PACKETS_PER_FRAME: u16 = 630;
/// Frame period, ns (10 Hz).
pub const M1_FRAME_NS: i64 = 100_000_000;
/// Temperature byte offset, °C.
pub const M1_TEMPERATURE_OFFSET_C: i16 = 80;

/// Whether `payload` is an M1 MSOP packet (length and id).
pub fn is_m1_msop(payload: &[u8]) -> bool {
    payload.len() == M1_MSOP_LEN && payload.starts_with(&M1_MSOP_ID)
}

/// Whether `payload` is an M1 DIFOP packet (length and id).
pub fn is_m1_difop(payload: &[u8]) -> bool {
    payload.len() == M1_DIFOP_LEN && payload.starts_with(&super::wire::DIFOP_ID)
}

/// One channel of a block, raw.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct M1Channel {
    /// Radius, 5 mm.
    pub raw_radius: u16,
    /// Elevation, 0.01° + 32768.
    pub raw_elevation: u16,
    /// Azimuth, 0.01° + 32768.
    pub raw_azimuth: u16,
    /// Intensity.
    pub intensity: u8,
    /// Point attribute byte.
    pub attribute: u8,
    /// Elongation byte.
    pub elongation: u8,
}

/// A checked M1 MSOP packet.
#[derive(Clone, Copy, Debug)]
pub struct M1Msop<'a> {
    bytes: &'a [u8],
}

impl<'a> M1Msop<'a> {
    /// Checks length and id.
    pub fn new(bytes: &'a [u8]) -> Result<Self, WireError> {
        super::wire::check_len_and_id(bytes, "Robosense M1 MSOP packet", M1_MSOP_LEN, &M1_MSOP_ID)?;
        Ok(Self { bytes })
    }

    /// The bytes.
    pub fn bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// Packet counter within the frame (from 1).
    pub fn seq(&self) -> u16 {
        be16(self.bytes, 4)
    }

    /// Protocol version.
    pub fn protocol_version(&self) -> u16 {
        be16(self.bytes, 6)
    }

    /// Return-mode byte.
    pub fn return_mode(&self) -> u8 {
        self.bytes[8]
    }

    /// Time-mode byte.
    pub fn time_mode(&self) -> u8 {
        self.bytes[9]
    }

    /// Lidar-type byte.
    pub fn lidar_type(&self) -> u8 {
        self.bytes[30]
    }

    /// Temperature, °C.
    pub fn temperature_c(&self) -> i16 {
        i16::from(self.bytes[31]) - M1_TEMPERATURE_OFFSET_C
    }

    /// The packet's time, ns since the Unix epoch; `None` when the fields are out of range.
    pub fn stamp_ns(&self) -> Option<i64> {
        let t = &self.bytes[10..20];
        let secs = t[..6].iter().fold(0i64, |a, &b| (a << 8) | i64::from(b));
        let us = t[6..].iter().fold(0i64, |a, &b| (a << 8) | i64::from(b));
        // Beyond 2^33 s an i64 of ns would not hold the time plus its offsets; a µs field of
        // a second or more is corrupt.
        if secs >= 1 << 33 || us >= 1_000_000 {
            return None;
        }
        Some(secs * 1_000_000_000 + us * 1_000)
    }

    fn block_offset(b: usize) -> usize {
        M1_HEADER_LEN + b * M1_BLOCK_LEN
    }

    /// Block `b`'s time offset from the packet time, µs.
    pub fn time_offset_us(&self, b: usize) -> u8 {
        self.bytes.get(Self::block_offset(b)).copied().unwrap_or(0)
    }

    /// Block `b`'s return sequence byte.
    pub fn return_seq(&self, b: usize) -> u8 {
        self.bytes
            .get(Self::block_offset(b) + 1)
            .copied()
            .unwrap_or(0)
    }

    /// Channel `c` of block `b`.
    #[inline]
    pub fn channel(&self, b: usize, c: usize) -> M1Channel {
        let o = Self::block_offset(b) + 2 + 9 * c;
        match self.bytes.get(o..o + 9) {
            Some(&[r0, r1, e0, e1, a0, a1, i, at, el]) => M1Channel {
                raw_radius: u16::from_be_bytes([r0, r1]),
                raw_elevation: u16::from_be_bytes([e0, e1]),
                raw_azimuth: u16::from_be_bytes([a0, a1]),
                intensity: i,
                attribute: at,
                elongation: el,
            },
            _ => M1Channel {
                raw_radius: 0,
                raw_elevation: M1_ANGLE_OFFSET,
                raw_azimuth: M1_ANGLE_OFFSET,
                intensity: 0,
                attribute: 0,
                elongation: 0,
            },
        }
    }
}

/// A checked M1 DIFOP packet.
#[derive(Clone, Copy, Debug)]
pub struct M1Difop<'a> {
    bytes: &'a [u8],
}

impl<'a> M1Difop<'a> {
    /// Checks length and id.
    pub fn new(bytes: &'a [u8]) -> Result<Self, WireError> {
        super::wire::check_len_and_id(
            bytes,
            "Robosense M1 DIFOP packet",
            M1_DIFOP_LEN,
            &super::wire::DIFOP_ID,
        )?;
        Ok(Self { bytes })
    }

    /// Frame-rate byte.
    pub fn frame_rate(&self) -> u8 {
        self.bytes[9]
    }

    /// Sensor and destination addresses, MSOP and DIFOP ports.
    pub fn network(&self) -> ([u8; 4], [u8; 4], u16, u16) {
        let b = self.bytes;
        (
            [b[10], b[11], b[12], b[13]],
            [b[14], b[15], b[16], b[17]],
            be16(b, 24),
            be16(b, 26),
        )
    }

    /// PL and PS firmware versions (5 bytes each from byte 28), as hex.
    pub fn firmware(&self) -> String {
        let hex = |s: &[u8]| s.iter().map(|x| format!("{x:02x}")).collect::<String>();
        format!("{}/{}", hex(&self.bytes[28..33]), hex(&self.bytes[33..38]))
    }

    /// Serial number (rs_driver's place: 6 bytes at 38), as hex.
    pub fn serial(&self) -> String {
        self.bytes[38..44]
            .iter()
            .map(|x| format!("{x:02x}"))
            .collect()
    }
}

/// One decoded M1 point with where it came from.
#[derive(Clone, Copy, Debug)]
pub struct M1Decoded {
    /// The point (`t` = 0; the stream sets it).
    pub point: Point,
    /// Time from the packet time, ns.
    pub offset_ns: i64,
    /// Block.
    pub block: usize,
    /// Channel.
    pub channel: usize,
}

/// The M1 decoder: a packet to points. It needs no calibration.
#[derive(Clone, Copy, Debug)]
pub struct M1Decoder {
    min_m: f32,
    max_m: f32,
}

impl M1Decoder {
    /// A decoder with the caller's range filter within the M1's own.
    pub fn new(opts: DecodeOptions) -> Self {
        Self {
            min_m: M1_MIN_RANGE_M.max(opts.min_range),
            max_m: M1_MAX_RANGE_M.min(opts.max_range),
        }
    }

    /// Decodes a packet; points go to `emit` in packet order (block, then channel). A radius
    /// of 0 (no return) or outside the range is no point.
    pub fn decode(&self, p: &M1Msop<'_>, mut emit: impl FnMut(M1Decoded)) {
        for b in 0..M1_BLOCKS {
            let offset_ns = i64::from(p.time_offset_us(b)) * 1_000;
            let ret = u8::from(p.return_seq(b) != 0);
            for c in 0..M1_CHANNELS {
                let ch = p.channel(b, c);
                if ch.raw_radius == 0 {
                    continue;
                }
                let r = f32::from(ch.raw_radius) * M1_RADIUS_UNIT_M;
                if r < self.min_m || r > self.max_m {
                    continue;
                }
                // Raw angles are 0.01° steps from −327.68° to 327.67°: the turn table takes
                // any of them.
                let (ce, se) = cs(i32::from(ch.raw_elevation) - i32::from(M1_ANGLE_OFFSET));
                let (ca, sa) = cs(i32::from(ch.raw_azimuth) - i32::from(M1_ANGLE_OFFSET));
                emit(M1Decoded {
                    point: Point {
                        x: r * ce * ca,
                        y: r * ce * sa,
                        z: r * se,
                        intensity: f32::from(ch.intensity),
                        t: 0,
                        ring: c as u16,
                        ret,
                        pad: 0,
                    },
                    offset_ns,
                    block: b,
                    channel: c,
                });
            }
        }
    }
}
