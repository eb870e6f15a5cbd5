//! Velodyne data (1206 B) and position (512 B) packets.
//!
//! Data packet layout (FORMATS.md §5.1; HDL-32E manual App. B; VLP-16 manual §9): 12 blocks of
//! 100 bytes — flag (2), azimuth u16 LE in 0.01° (2), 32 × (distance u16 LE, reflectivity u8) —
//! then the timestamp u32 LE (µs since the top of the hour) at 1200 and two factory bytes
//! (return mode, product id) at 1204 / 1205 (HDL-64E: status type / value instead).

use super::WireError;
use crate::model::velodyne::{BLOCKS, DATA_PACKET_LEN, POSITION_PACKET_LEN, SLOTS};

/// Block flag of lasers 0–31 (wire bytes `FF EE`).
pub const FLAG_UPPER: u16 = 0xEEFF;
/// Block flag of lasers 32–63 (`FF DD`, HDL-64E lower block; VLS-128 bank 1).
pub const FLAG_LOWER: u16 = 0xDDFF;
/// VLS-128 bank 2 (`FF CC`).
pub const FLAG_BANK2: u16 = 0xCCFF;
/// VLS-128 bank 3 (`FF BB`).
pub const FLAG_BANK3: u16 = 0xBBFF;

const BLOCK_LEN: usize = 100;

/// A checked view of one Velodyne data packet.
#[derive(Clone, Copy, Debug)]
pub struct DataPacket<'a> {
    b: &'a [u8; DATA_PACKET_LEN],
}

impl<'a> DataPacket<'a> {
    /// Checks the length, every block flag and every azimuth.
    pub fn new(bytes: &'a [u8]) -> Result<Self, WireError> {
        let b: &[u8; DATA_PACKET_LEN] = bytes.try_into().map_err(|_| WireError::Length {
            what: "Velodyne data packet",
            expected: DATA_PACKET_LEN,
            found: bytes.len(),
        })?;
        let p = Self { b };
        for block in 0..BLOCKS {
            let off = block * BLOCK_LEN;
            if p.bank(block).is_none() {
                return Err(WireError::BlockFlag {
                    block,
                    offset: off,
                    found: b[off],
                    found2: b[off + 1],
                });
            }
            let az = p.u16_at(off + 2);
            if az > 36_000 {
                return Err(WireError::Azimuth {
                    block,
                    offset: off + 2,
                    found: az,
                });
            }
        }
        Ok(p)
    }

    /// The raw bytes.
    pub fn bytes(&self) -> &'a [u8; DATA_PACKET_LEN] {
        self.b
    }

    #[inline]
    fn u16_at(&self, off: usize) -> u16 {
        u16::from_le_bytes([self.b[off], self.b[off + 1]])
    }

    /// Block flag as a little-endian u16 (`0xEEFF` for wire bytes `FF EE`).
    #[inline]
    pub fn flag(&self, block: usize) -> u16 {
        self.u16_at(block * BLOCK_LEN)
    }

    /// Bank of a block from its flag: 0 = `FF EE`, 1 = `FF DD`, 2 = `FF CC`, 3 = `FF BB`.
    #[inline]
    pub fn bank(&self, block: usize) -> Option<usize> {
        match self.flag(block) {
            FLAG_UPPER => Some(0),
            FLAG_LOWER => Some(1),
            FLAG_BANK2 => Some(2),
            FLAG_BANK3 => Some(3),
            _ => None,
        }
    }

    /// Block azimuth, hundredths of a degree, in 0..36000.
    ///
    /// Real sensors sometimes send 36000 for a firing at 360.00° (seen in two captures, an
    /// HDL-32E and a VLP-16): it is read as 0. Values above 36000 are rejected by [`Self::new`].
    #[inline]
    pub fn azimuth(&self, block: usize) -> u16 {
        let az = self.u16_at(block * BLOCK_LEN + 2);
        if az >= 36_000 {
            az - 36_000
        } else {
            az
        }
    }

    /// Raw distance of one measurement (units per model / calibration; 0 = no return).
    #[inline]
    pub fn distance(&self, block: usize, slot: usize) -> u16 {
        self.u16_at(block * BLOCK_LEN + 4 + 3 * slot)
    }

    /// Reflectivity of one measurement.
    #[inline]
    pub fn reflectivity(&self, block: usize, slot: usize) -> u8 {
        self.b[block * BLOCK_LEN + 6 + 3 * slot]
    }

    /// The 96 bytes of one block's measurements (32 × distance u16 + reflectivity u8).
    #[inline]
    pub fn measurements(&self, block: usize) -> &'a [u8] {
        let off = block * BLOCK_LEN + 4;
        &self.b[off..off + 3 * SLOTS]
    }

    /// Packet timestamp: µs since the top of the hour.
    #[inline]
    pub fn timestamp_us(&self) -> u32 {
        u32::from_le_bytes([self.b[1200], self.b[1201], self.b[1202], self.b[1203]])
    }

    /// Factory byte 1 (return mode; HDL-64E: status type).
    #[inline]
    pub fn factory_mode(&self) -> u8 {
        self.b[1204]
    }

    /// Factory byte 2 (product id; HDL-64E: status value).
    #[inline]
    pub fn factory_product(&self) -> u8 {
        self.b[1205]
    }

    /// Whether the block layout is the HDL-64E's: block 0 upper, block 1 lower
    /// (VeloView `isHDL64()`).
    pub fn looks_like_hdl64(&self) -> bool {
        self.flag(0) == FLAG_UPPER && self.flag(1) == FLAG_LOWER && self.flag(2) == FLAG_UPPER
    }

    /// Whether consecutive blocks repeat azimuths the way dual-return packets do
    /// (16/32 lasers: `az[0] == az[1]`; HDL-64E: `az[0] == az[2]`).
    pub fn looks_dual(&self) -> bool {
        if self.looks_like_hdl64() {
            self.azimuth(0) == self.azimuth(2)
        } else {
            self.azimuth(0) == self.azimuth(1)
        }
    }
}

/// PPS state reported by a position packet (byte 0xCA).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PpsState {
    /// No PPS signal (0).
    Absent,
    /// Synchronising to PPS (1).
    Synchronizing,
    /// Locked to PPS (2).
    Locked,
    /// Error (3).
    Error,
    /// Any other byte value.
    Unknown(u8),
}

impl PpsState {
    /// Name used in summaries.
    pub fn name(self) -> &'static str {
        match self {
            Self::Absent => "absent",
            Self::Synchronizing => "synchronizing",
            Self::Locked => "locked",
            Self::Error => "error",
            Self::Unknown(_) => "unknown",
        }
    }
}

/// A checked view of one Velodyne position (telemetry) packet, 512 bytes.
///
/// Offsets (velodyne_decoder `telemetry_packet.cpp`; VLP-16 manual §9.3.3): 0xC6 µs since the
/// top of the hour (u32 LE), 0xCA PPS status, 0xCE NMEA sentence (≤ 128 bytes, NUL-terminated).
#[derive(Clone, Copy, Debug)]
pub struct PositionPacket<'a> {
    b: &'a [u8; POSITION_PACKET_LEN],
}

impl<'a> PositionPacket<'a> {
    /// Checks the length.
    pub fn new(bytes: &'a [u8]) -> Result<Self, WireError> {
        let b = bytes.try_into().map_err(|_| WireError::Length {
            what: "Velodyne position packet",
            expected: POSITION_PACKET_LEN,
            found: bytes.len(),
        })?;
        Ok(Self { b })
    }

    /// µs since the top of the hour.
    pub fn timestamp_us(&self) -> u32 {
        u32::from_le_bytes([self.b[0xC6], self.b[0xC7], self.b[0xC8], self.b[0xC9]])
    }

    /// PPS status.
    pub fn pps(&self) -> PpsState {
        match self.b[0xCA] {
            0 => PpsState::Absent,
            1 => PpsState::Synchronizing,
            2 => PpsState::Locked,
            3 => PpsState::Error,
            x => PpsState::Unknown(x),
        }
    }

    /// The NMEA sentence bytes (up to the first NUL, at most 128 bytes); empty if none.
    pub fn nmea(&self) -> &'a [u8] {
        let field = &self.b[0xCE..0xCE + 128];
        let end = field.iter().position(|&c| c == 0).unwrap_or(field.len());
        &field[..end]
    }
}
