//! The PandarAT128's binary angle correction (`.dat`, version 1.5) and its angle formulas.
//!
//! Layout (little-endian; Hesai AT128 user manual, "Angle correction file"; the same fields as
//! tier4/nebula's `HesaiCorrection` and HesaiLidar_SDK_2.0):
//!
//! | offset | field |
//! |---|---|
//! | 0 | `EE FF` |
//! | 2, 3 | version major (1), minor (5) |
//! | 4 | channels N (128) |
//! | 5 | mirrors M (3) |
//! | 6 | frames (3) |
//! | 7 | frame config, 8 bytes |
//! | 15 | resolution R (units of the file = 1/25600° × R) |
//! | 16 | start frame, u32 × M (encoder azimuth where mirror m's field starts) |
//! | 16 + 4M | end frame, u32 × M |
//! | 16 + 8M | azimuth, i32 × N (per-channel horizontal offset) |
//! | 16 + 8M + 4N | elevation, i32 × N |
//! | 16 + 8M + 8N | azimuth adjustment, i8 × 180N (per channel, every 2° of encoder azimuth) |
//! | 16 + 8M + 188N | elevation adjustment, i8 × 180N |
//! | end − 32 | SHA-256 of the file (not checked: integrity is the transport's business) |
//!
//! Angles (all in 1/25600°): for a block whose encoder azimuth `a` (16-bit 0.01° + fine byte)
//! lies in mirror m's field `[start_m, end_m)`,
//! `azimuth = 2·(a − start_m) − azimuth[ch] + 256·adj_az(ch, a)`,
//! `elevation = elevation[ch] + 256·adj_el(ch, a)`, where `adj(ch, a)` interpolates linearly
//! between the entries `i = ⌊a / 2°⌋` and `i + 1` of the channel's row (× R, in 0.01°) and rounds
//! to an integer number of 0.01°. The mirror doubles the encoder angle, hence the factor 2.

use crate::sensor::CalibError;

/// 1/25600° per degree: the AT128's angle unit (0.01° × 256).
pub const UNITS_PER_DEG: i64 = 25_600;
/// A full turn in AT128 units.
pub const TURN: i64 = 360 * UNITS_PER_DEG;
/// Encoder step between two adjustment entries: 2°.
const ADJ_STEP: i64 = 2 * UNITS_PER_DEG;

/// A checked AT128 correction, in 1/25600°.
#[derive(Clone, Debug, PartialEq)]
pub struct At128Correction {
    /// File version (major, minor).
    pub version: (u8, u8),
    /// Start of each mirror's field (encoder azimuth).
    pub start_frame: Vec<i64>,
    /// End of each mirror's field.
    pub end_frame: Vec<i64>,
    /// Per-channel azimuth.
    pub azimuth: Vec<i64>,
    /// Per-channel elevation.
    pub elevation: Vec<i64>,
    /// Per-channel azimuth adjustment, 180 per channel, 0.01° (already × resolution).
    pub azimuth_adjust: Vec<i32>,
    /// Per-channel elevation adjustment, 0.01°.
    pub elevation_adjust: Vec<i32>,
}

/// Whether the bytes look like an AT128 correction (`EE FF 01 xx`, a plausible channel count).
pub fn looks_like_dat(bytes: &[u8]) -> bool {
    matches!(bytes, [0xEE, 0xFF, 1, _, ch, m, ..] if *ch > 0 && *m > 0 && *m <= 8)
}

fn err(msg: String) -> CalibError {
    CalibError::Invalid(format!("AT128 angle correction: {msg}"))
}

impl At128Correction {
    /// Parses a `.dat` correction (version 1.5).
    pub fn parse(bytes: &[u8]) -> Result<Self, CalibError> {
        if !looks_like_dat(bytes) || bytes.len() < 16 {
            return Err(err(format!(
                "expected EE FF 01 at the start of a 16-byte header, file has {} bytes",
                bytes.len()
            )));
        }
        let (major, minor) = (bytes[2], bytes[3]);
        if minor != 5 {
            return Err(err(format!(
                "version {major}.{minor} is not supported (1.5 is)"
            )));
        }
        let n = usize::from(bytes[4]);
        let m = usize::from(bytes[5]);
        let frames = usize::from(bytes[6]);
        let res = i64::from(bytes[15]);
        if n != 128 {
            return Err(err(format!("{n} channels; the AT128 has 128")));
        }
        if frames != m || res == 0 {
            return Err(err(format!(
                "{frames} frames for {m} mirrors, resolution {res}"
            )));
        }
        let need = 16 + 8 * m + 8 * n + 2 * 180 * n + 32;
        if bytes.len() != need {
            return Err(err(format!(
                "expected {need} bytes for {n} channels and {m} mirrors, found {}",
                bytes.len()
            )));
        }
        let u32_at = |o: usize| {
            i64::from(u32::from_le_bytes([
                bytes[o],
                bytes[o + 1],
                bytes[o + 2],
                bytes[o + 3],
            ]))
        };
        let i32_at = |o: usize| {
            i64::from(i32::from_le_bytes([
                bytes[o],
                bytes[o + 1],
                bytes[o + 2],
                bytes[o + 3],
            ]))
        };
        let mut o = 16;
        let start_frame: Vec<i64> = (0..m).map(|i| u32_at(o + 4 * i) * res).collect();
        o += 4 * m;
        let end_frame: Vec<i64> = (0..m).map(|i| u32_at(o + 4 * i) * res).collect();
        o += 4 * m;
        let azimuth: Vec<i64> = (0..n).map(|i| i32_at(o + 4 * i) * res).collect();
        o += 4 * n;
        let elevation: Vec<i64> = (0..n).map(|i| i32_at(o + 4 * i) * res).collect();
        o += 4 * n;
        let adj = |o: usize| -> Vec<i32> {
            bytes[o..o + 180 * n]
                .iter()
                .map(|&b| i32::from(b as i8) * res as i32)
                .collect()
        };
        let azimuth_adjust = adj(o);
        let elevation_adjust = adj(o + 180 * n);
        for (i, (&s, &e)) in start_frame.iter().zip(&end_frame).enumerate() {
            if s >= TURN || e >= TURN {
                return Err(err(format!(
                    "mirror {i}: field {s}–{e} lies outside one turn ({TURN})"
                )));
            }
        }
        for (i, (&a, &e)) in azimuth.iter().zip(&elevation).enumerate() {
            if a.abs() > 30 * UNITS_PER_DEG || e.abs() > 90 * UNITS_PER_DEG {
                return Err(err(format!(
                    "channel {i}: azimuth {a} / elevation {e} (1/25600°) out of range"
                )));
            }
        }
        Ok(Self {
            version: (major, minor),
            start_frame,
            end_frame,
            azimuth,
            elevation,
            azimuth_adjust,
            elevation_adjust,
        })
    }

    /// Channels.
    pub fn channels(&self) -> usize {
        self.azimuth.len()
    }

    /// The mirror whose field holds encoder azimuth `a` (1/25600°).
    pub fn field(&self, a: i64) -> Option<usize> {
        self.start_frame
            .iter()
            .zip(&self.end_frame)
            .position(|(&s, &e)| {
                if s <= e {
                    (s..e).contains(&a)
                } else {
                    a >= s || a < e
                }
            })
    }

    fn adjust(row: &[i32], a: i64) -> i64 {
        let i = (a.rem_euclid(TURN) / ADJ_STEP) as usize;
        let frac = (a.rem_euclid(TURN) - i as i64 * ADJ_STEP) as f64 / ADJ_STEP as f64;
        let v0 = f64::from(row.get(i).copied().unwrap_or(0));
        let v1 = f64::from(row.get(i + 1).copied().unwrap_or(0));
        ((1.0 - frac) * v0 + frac * v1).round() as i64
    }

    /// Corrected (azimuth, elevation) of channel `ch` at encoder azimuth `a`, 1/25600°:
    /// azimuth in `[0, TURN)`, elevation signed. `None` outside every mirror's field.
    pub fn angles(&self, ch: usize, a: i64) -> Option<(i64, i64)> {
        let f = self.field(a)?;
        let rows = ch * 180..ch * 180 + 180;
        let az_row = self.azimuth_adjust.get(rows.clone()).unwrap_or(&[]);
        let el_row = self.elevation_adjust.get(rows).unwrap_or(&[]);
        let az =
            2 * (a - self.start_frame[f]) - self.azimuth.get(ch)? + 256 * Self::adjust(az_row, a);
        let el = self.elevation.get(ch)? + 256 * Self::adjust(el_row, a);
        Some((az.rem_euclid(TURN), el))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hostile_files_are_refused() {
        assert!(At128Correction::parse(&[]).is_err());
        assert!(At128Correction::parse(&[0xEE, 0xFF, 1, 5]).is_err());
        let mut b = vec![0u8; 16 + 24 + 1024 + 46080 + 32];
        b[..7].copy_from_slice(&[0xEE, 0xFF, 1, 5, 128, 3, 3]);
        b[15] = 2;
        assert!(At128Correction::parse(&b).is_ok());
        b[15] = 0;
        assert!(At128Correction::parse(&b).is_err());
        b[15] = 2;
        assert!(At128Correction::parse(&b[..b.len() - 1]).is_err());
        b[3] = 4;
        assert!(At128Correction::parse(&b).is_err());
    }
}
