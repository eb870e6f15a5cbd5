//! Velodyne data (1206 B) and position (512 B) packets.
//!
//! Data packet layout (FORMATS.md §5.1; HDL-32E manual App. B; VLP-16 manual §9): 12 blocks of
//! 100 bytes — flag (2), azimuth u16 LE in 0.01° (2), 32 × (distance u16 LE, reflectivity u8) —
//! then the timestamp u32 LE (µs since the top of the hour) at 1200 and two factory bytes
//! (return mode, product id) at 1204 / 1205 (HDL-64E: status type / value instead).

use crate::sensor::velodyne::model::BLOCKS;
use crate::sensor::velodyne::model::DATA_PACKET_LEN;
use crate::sensor::velodyne::model::POSITION_PACKET_LEN;
use crate::sensor::velodyne::model::SLOTS;
use crate::sensor::WireError;

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

/// Telemetry of a position packet (newer firmware), as the sensor sends it: temperatures in
/// whole °C, offsets 0xBB–0xC5 and 0xCB–0xCD.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Telemetry {
    /// Temperature of the top board, °C (0xBB).
    pub temp_top_c: u8,
    /// Temperature of the bottom board, °C (0xBC).
    pub temp_bottom_c: u8,
    /// Temperature at the last ADC calibration, °C (0xBD).
    pub temp_at_adc_calibration_c: u8,
    /// Temperature change since the last ADC calibration (0xBE, i16).
    pub temp_change_since_adc_calibration: i16,
    /// Seconds since the last ADC calibration (0xC0, u32).
    pub seconds_since_adc_calibration: u32,
    /// Reason of the last ADC calibration (0xC4).
    pub adc_calibration_reason: u8,
    /// ADC calibration flags (0xC5).
    pub adc_calibration_flags: u8,
    /// Thermal shutdown state (0xCB; 0 = none).
    pub thermal_shutdown: u8,
    /// Temperature at the last thermal shutdown, °C (0xCC).
    pub temp_at_shutdown_c: u8,
    /// Temperature at power-up, °C (0xCD).
    pub temp_at_power_up_c: u8,
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

    /// The telemetry of newer firmware (VLP-16, VLP-32C, HDL-32E; FORMATS.md "Position /
    /// telemetry packet"), or `None` when every telemetry byte is zero (older firmware sends
    /// nothing there).
    pub fn telemetry(&self) -> Option<Telemetry> {
        let b = self.b;
        let zero = b[0xBB..0xC6].iter().chain(&b[0xCB..0xCE]).all(|&x| x == 0);
        (!zero).then(|| Telemetry {
            temp_top_c: b[0xBB],
            temp_bottom_c: b[0xBC],
            temp_at_adc_calibration_c: b[0xBD],
            temp_change_since_adc_calibration: i16::from_le_bytes([b[0xBE], b[0xBF]]),
            seconds_since_adc_calibration: u32::from_le_bytes([b[0xC0], b[0xC1], b[0xC2], b[0xC3]]),
            adc_calibration_reason: b[0xC4],
            adc_calibration_flags: b[0xC5],
            thermal_shutdown: b[0xCB],
            temp_at_shutdown_c: b[0xCC],
            temp_at_power_up_c: b[0xCD],
        })
    }

    /// The NMEA sentence bytes (up to the first NUL, at most 128 bytes); empty if none.
    pub fn nmea(&self) -> &'a [u8] {
        let field = &self.b[0xCE..0xCE + 128];
        let end = field.iter().position(|&c| c == 0).unwrap_or(field.len());
        &field[..end]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn telemetry_reads_the_documented_offsets_and_is_absent_when_zero() {
        // Values placed by hand at FORMATS.md's offsets.
        let mut b = [0u8; POSITION_PACKET_LEN];
        b[0xBB] = 46;
        b[0xBC] = 41;
        b[0xBD] = 38;
        b[0xBE..0xC0].copy_from_slice(&(-3i16).to_le_bytes());
        b[0xC0..0xC4].copy_from_slice(&7_200u32.to_le_bytes());
        b[0xC4] = 2;
        b[0xC5] = 0x81;
        b[0xCB] = 1;
        b[0xCC] = 95;
        b[0xCD] = 21;
        b[0xCA] = 2;
        let t = PositionPacket::new(&b).unwrap().telemetry().unwrap();
        assert_eq!(
            t,
            Telemetry {
                temp_top_c: 46,
                temp_bottom_c: 41,
                temp_at_adc_calibration_c: 38,
                temp_change_since_adc_calibration: -3,
                seconds_since_adc_calibration: 7_200,
                adc_calibration_reason: 2,
                adc_calibration_flags: 0x81,
                thermal_shutdown: 1,
                temp_at_shutdown_c: 95,
                temp_at_power_up_c: 21,
            }
        );
        // Old firmware: time, PPS and NMEA only.
        let mut old = [0u8; POSITION_PACKET_LEN];
        old[0xC6..0xCA].copy_from_slice(&123_456u32.to_le_bytes());
        old[0xCA] = 2;
        old[0xCE..0xD3].copy_from_slice(b"$GPRM");
        assert_eq!(PositionPacket::new(&old).unwrap().telemetry(), None);
    }
}
