//! The PandarAT128's binary angle correction (`.dat`) and its angle formulas, in its two
//! published layouts, told apart by the version bytes (2, 3).
//!
//! **1.5** (little-endian; Hesai AT128 user manual, "Angle correction file"; read the same way
//! by tier4/nebula's `HesaiCorrection` and every HesaiLidar_SDK_2.0 release; all four shared
//! `PandarAT128.dat*` files are 1.5, resolution 1 or 2):
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
//!
//! **1.3**, the first AT128 layout (HesaiLidar_SDK_2.0 up to 2.0.7 and the AT128 ROS driver
//! read it; nebula reads it too but marks it "not worked"): the same 16-byte header, then
//!
//! | offset | field |
//! |---|---|
//! | 16 | start frame, u16 × M, 0.01° × R |
//! | 16 + 2M | end frame, u16 × M |
//! | 16 + 4M | azimuth, i16 × N, 0.01° × R |
//! | 16 + 4M + 2N | elevation, i16 × N |
//! | 16 + 4M + 4N | azimuth adjustment, i8 × 36 000, 0.01° × R |
//! | 16 + 4M + 4N + 36 000 | elevation adjustment, i8 × 36 000 |
//! | end − 32 | SHA-256 |
//!
//! The adjustment grids are not per channel: entry `⌊a / 0.01°⌋` (one per 0.01° of encoder
//! azimuth, a whole turn) applies to every channel, without interpolation (the ROS driver's
//! `azimuth_offset[u16Azimuth]`): `azimuth = 2·(a − start_m) − azimuth[ch] + adj_az[⌊a⌋]`,
//! `elevation = elevation[ch] + adj_el[⌊a⌋]`, every file value × R. (The ROS driver scales
//! the encoder azimuth by R too, which only agrees with the file's units for R = 1; here R
//! scales the file's values, as in 1.5.)
//!
//! **1.6–1.9** (HesaiLidar_SDK_2.0 2.0.10 and later declare their fields: a file length, a
//! 16-bit channel count, a channel-to-laser map, an angle division and an adjustment interval)
//! are not read by any public decoder, so their byte order is not known: refused by name.

use crate::sensor::CalibError;

/// 1/25600° per degree: the AT128's angle unit (0.01° × 256).
pub const UNITS_PER_DEG: i64 = 25_600;
/// A full turn in AT128 units.
pub const TURN: i64 = 360 * UNITS_PER_DEG;
/// Encoder step between two adjustment entries: 2°.
const ADJ_STEP: i64 = 2 * UNITS_PER_DEG;

/// Entries of a 1.3 adjustment grid: one per 0.01° of encoder azimuth.
const V13_GRID: usize = 36_000;

/// How a correction's adjustment grids are indexed (the file layout they came from).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AdjustGrid {
    /// 1.5: 180 entries per channel, every 2° of encoder azimuth, interpolated and rounded.
    PerChannel2Deg,
    /// 1.3: 36 000 entries shared by every channel, one per 0.01° of encoder azimuth.
    Shared001Deg,
}

/// A checked AT128 correction, in 1/25600°.
#[derive(Clone, Debug, PartialEq)]
pub struct At128Correction {
    /// File version (major, minor).
    pub version: (u8, u8),
    /// How [`Self::azimuth_adjust`] and [`Self::elevation_adjust`] are indexed.
    pub grid: AdjustGrid,
    /// Start of each mirror's field (encoder azimuth).
    pub start_frame: Vec<i64>,
    /// End of each mirror's field.
    pub end_frame: Vec<i64>,
    /// Per-channel azimuth.
    pub azimuth: Vec<i64>,
    /// Per-channel elevation.
    pub elevation: Vec<i64>,
    /// Azimuth adjustment, 0.01° (already × resolution): 180 per channel (1.5) or 36 000
    /// shared (1.3).
    pub azimuth_adjust: Vec<i32>,
    /// Elevation adjustment, 0.01°, indexed as [`Self::azimuth_adjust`].
    pub elevation_adjust: Vec<i32>,
}

/// Whether the bytes look like an AT128 correction (`EE FF 01 xx`, a plausible channel count).
pub fn looks_like_dat(bytes: &[u8]) -> bool {
    matches!(bytes, [0xEE, 0xFF, 1, _, ch, m, ..] if *ch > 0 && *m > 0 && *m <= 8)
}

fn err(msg: String) -> CalibError {
    CalibError::Invalid(format!("AT128 angle correction: {msg}"))
}

/// Little-endian reader over a buffer whose length was checked against the layout first.
struct Le<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Le<'_> {
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let mut v = [0u8; N];
        if let Some(s) = self.bytes.get(self.at..self.at + N) {
            v.copy_from_slice(s);
        }
        self.at += N;
        v
    }
    fn u16s(&mut self, n: usize, scale: i64) -> Vec<i64> {
        (0..n)
            .map(|_| i64::from(u16::from_le_bytes(self.take())) * scale)
            .collect()
    }
    fn i16s(&mut self, n: usize, scale: i64) -> Vec<i64> {
        (0..n)
            .map(|_| i64::from(i16::from_le_bytes(self.take())) * scale)
            .collect()
    }
    fn u32s(&mut self, n: usize, scale: i64) -> Vec<i64> {
        (0..n)
            .map(|_| i64::from(u32::from_le_bytes(self.take())) * scale)
            .collect()
    }
    fn i32s(&mut self, n: usize, scale: i64) -> Vec<i64> {
        (0..n)
            .map(|_| i64::from(i32::from_le_bytes(self.take())) * scale)
            .collect()
    }
    fn i8s(&mut self, n: usize, scale: i32) -> Vec<i32> {
        let v = self
            .bytes
            .get(self.at..self.at + n)
            .unwrap_or(&[])
            .iter()
            .map(|&b| i32::from(b as i8) * scale)
            .collect();
        self.at += n;
        v
    }
}

impl At128Correction {
    /// Parses a `.dat` correction, version 1.5 or 1.3 (by its version bytes).
    pub fn parse(bytes: &[u8]) -> Result<Self, CalibError> {
        if !looks_like_dat(bytes) || bytes.len() < 16 {
            return Err(err(format!(
                "expected EE FF 01 at the start of a 16-byte header, file has {} bytes",
                bytes.len()
            )));
        }
        let (major, minor) = (bytes[2], bytes[3]);
        let grid = match minor {
            5 => AdjustGrid::PerChannel2Deg,
            3 => AdjustGrid::Shared001Deg,
            6..=9 => {
                return Err(err(format!(
                    "version {major}.{minor}: HesaiLidar_SDK_2.0 declares this layout's fields \
                     but no public decoder reads it, so its byte order is unknown (1.3 and 1.5 \
                     are supported)"
                )))
            }
            _ => {
                return Err(err(format!(
                    "version {major}.{minor} is not supported (1.3 and 1.5 are)"
                )))
            }
        };
        let n = usize::from(bytes[4]);
        let m = usize::from(bytes[5]);
        let frames = usize::from(bytes[6]);
        let res = i64::from(bytes[15]);
        if n != 128 {
            return Err(err(format!("{n} channels; the AT128 has 128")));
        }
        // nebula counts the field arrays by mirrors, the SDK by frames: a file where they
        // differ would be read two ways.
        if frames != m || res == 0 {
            return Err(err(format!(
                "{frames} frames for {m} mirrors, resolution {res}"
            )));
        }
        let need = match grid {
            AdjustGrid::PerChannel2Deg => 16 + 8 * m + 8 * n + 2 * 180 * n + 32,
            AdjustGrid::Shared001Deg => 16 + 4 * m + 4 * n + 2 * V13_GRID + 32,
        };
        if bytes.len() != need {
            return Err(err(format!(
                "version {major}.{minor} with {n} channels and {m} mirrors is {need} bytes, \
                 found {}",
                bytes.len()
            )));
        }
        let mut r = Le { bytes, at: 16 };
        let (start_frame, end_frame, azimuth, elevation, azimuth_adjust, elevation_adjust) =
            match grid {
                AdjustGrid::PerChannel2Deg => (
                    r.u32s(m, res),
                    r.u32s(m, res),
                    r.i32s(n, res),
                    r.i32s(n, res),
                    r.i8s(180 * n, res as i32),
                    r.i8s(180 * n, res as i32),
                ),
                // 0.01° × R, to 1/25600°.
                AdjustGrid::Shared001Deg => (
                    r.u16s(m, 256 * res),
                    r.u16s(m, 256 * res),
                    r.i16s(n, 256 * res),
                    r.i16s(n, 256 * res),
                    r.i8s(V13_GRID, res as i32),
                    r.i8s(V13_GRID, res as i32),
                ),
            };
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
            grid,
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

    /// What every channel's angles share at encoder azimuth `a` (1/25600°): the mirror field
    /// and the adjustment grid's position. A block's 128 channels share its encoder azimuth,
    /// so the field search and the grid position are done once per block, not per point.
    /// `None` outside every mirror's field.
    #[inline]
    pub fn block(&self, a: i64) -> Option<At128Block> {
        let f = self.field(a)?;
        let base = 2 * (a - self.start_frame.get(f)?);
        let a = a.rem_euclid(TURN);
        let grid = match self.grid {
            AdjustGrid::PerChannel2Deg => {
                let i = (a / ADJ_STEP) as usize;
                let frac = (a - i as i64 * ADJ_STEP) as f64 / ADJ_STEP as f64;
                BlockGrid::PerChannel { i, frac }
            }
            AdjustGrid::Shared001Deg => {
                let i = (a / 256) as usize;
                let at = |g: &[i32]| i64::from(g.get(i).copied().unwrap_or(0));
                BlockGrid::Shared {
                    az: at(&self.azimuth_adjust),
                    el: at(&self.elevation_adjust),
                }
            }
        };
        Some(At128Block { base, grid })
    }

    /// Channel `ch`'s adjustment from its row of a 1.5 grid: linear between entries `i` and
    /// `i + 1` (0 past the row's end), rounded to 0.01°.
    #[inline]
    fn adjust(&self, grid: &[i32], ch: usize, i: usize, frac: f64) -> i64 {
        let at = |k: usize| f64::from(grid.get(ch * 180 + k).copied().unwrap_or(0));
        let v1 = if i + 1 < 180 { at(i + 1) } else { 0.0 };
        round_half_away((1.0 - frac) * at(i) + frac * v1)
    }

    /// Corrected azimuth of channel `ch` in block `b`, 1/25600° in `[0, TURN)`.
    #[inline]
    pub fn block_azimuth(&self, b: &At128Block, ch: usize) -> Option<i64> {
        let adj = match b.grid {
            BlockGrid::PerChannel { i, frac } => self.adjust(&self.azimuth_adjust, ch, i, frac),
            BlockGrid::Shared { az, .. } => az,
        };
        Some((b.base - self.azimuth.get(ch)? + 256 * adj).rem_euclid(TURN))
    }

    /// Corrected (azimuth, elevation) of channel `ch` in block `b`, 1/25600°: azimuth in
    /// `[0, TURN)`, elevation signed.
    #[inline]
    pub fn block_angles(&self, b: &At128Block, ch: usize) -> Option<(i64, i64)> {
        let adj_el = match b.grid {
            BlockGrid::PerChannel { i, frac } => self.adjust(&self.elevation_adjust, ch, i, frac),
            BlockGrid::Shared { el, .. } => el,
        };
        let el = self.elevation.get(ch)? + 256 * adj_el;
        Some((self.block_azimuth(b, ch)?, el))
    }

    /// Corrected (azimuth, elevation) of channel `ch` at encoder azimuth `a`, 1/25600°:
    /// azimuth in `[0, TURN)`, elevation signed. `None` outside every mirror's field.
    pub fn angles(&self, ch: usize, a: i64) -> Option<(i64, i64)> {
        self.block_angles(&self.block(a)?, ch)
    }
}

/// The per-block part of the AT128 angles ([`At128Correction::block`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct At128Block {
    /// `2·(a − start_m)`: the mirror doubles the encoder angle.
    base: i64,
    grid: BlockGrid,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum BlockGrid {
    /// 1.5: entry `i` of each channel's row and the fraction of the way to `i + 1`.
    PerChannel { i: usize, frac: f64 },
    /// 1.3: the adjustments every channel shares.
    Shared { az: i64, el: i64 },
}

/// `x.round() as i64` for |x| < 2^52, without the libm call `round` is on x86-64's baseline
/// (it was a sixth of the AT128 decoder's time): x minus its truncation is exact there, so the
/// comparison with ½ decides as `round` does (halves away from zero).
#[inline]
fn round_half_away(x: f64) -> i64 {
    let t = x as i64;
    let d = x - t as f64;
    if d >= 0.5 {
        t.saturating_add(1)
    } else if d <= -0.5 {
        t.saturating_sub(1)
    } else {
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_half_away_is_f64_round() {
        let mut xs = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            -2.5,
            1e15 + 0.5,
            -1e15 - 0.5,
        ];
        // Ties and their neighbours one ulp either side, and a spread of ordinary values.
        for k in -300i32..300 {
            let tie = f64::from(k) + 0.5;
            xs.extend([
                tie,
                f64::from_bits(tie.to_bits() + 1),
                f64::from_bits(tie.to_bits() - 1),
            ]);
            xs.push(f64::from(k) * 0.37 + 0.001);
        }
        xs.push(0.499_999_999_999_999_94);
        xs.push(-0.499_999_999_999_999_94);
        for x in xs {
            assert_eq!(round_half_away(x), x.round() as i64, "{x:e}");
        }
    }

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
