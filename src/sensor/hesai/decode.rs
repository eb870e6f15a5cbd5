//! The Hesai decoder: one table-driven loop for every model, return mode and correction.
//!
//! Built once per (model, correction, options) ([`HesaiDecoder::new`]): per-channel sin / cos of
//! the elevation and of the azimuth offset, the channel's ring (rank of its elevation, 0 =
//! lowest), its azimuth offset in µ° for the sweep cut; a cos / sin table of the 36 000 block
//! azimuths (0.01°). Per block group one table look-up; per point a complex multiply (block
//! azimuth rotated by the channel's offset) and three products. The AT128's azimuth-dependent
//! correction ([`super::at128`]) and the ATX's ([`super::atx`]: per-frame azimuths, an
//! azimuth-dependent elevation) are evaluated per point instead, in the AT128's 1/25 600° unit.
//!
//! **Coordinates.** Hesai azimuth α grows clockwise seen from above with 0 on the sensor's
//! forward (Hesai's and nebula's +y); ringscan's frame is REP 103, so
//! `x = d·cos(ε)·cos(α)`, `y = −d·cos(ε)·sin(α)`, `z = d·sin(ε)` (nebula's `(x, y, z)` is ringscan's
//! `(−y, x, z)`).
//!
//! **Returns** (DESIGN.md): see [`super::model::return_index`]. Within a return group (the 1, 2
//! or 3 blocks of one firing, by the tail's return mode) a return whose raw distance and
//! reflectivity equal another's is kept only in the group's last block (one point, as Velodyne's
//! equal dual returns are one point); with [`HesaiOptions::dual_return_threshold_m`] > 0 a
//! return that is not the group's last is also dropped when within that distance of another
//! return of the group (nebula's `dual_return_distance_threshold`).

use super::at128::{At128Block, At128Correction, TURN as AT128_TURN, UNITS_PER_DEG};
use super::atx::AtxCorrection;
use super::calib::HesaiCalibration;
use super::model::{return_index, returns_of_mode, HesaiModel, TailFlags};
use super::wire::HesaiPacket;
use crate::point::Point;
use crate::sensor::{DecodeError, DecodeOptions};

/// A full turn in µ°.
pub const TURN_UDEG: i64 = 360_000_000;

/// Options of the Hesai decoder beyond the range filter every family has.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HesaiOptions {
    /// Range filter (`--min-range`, `--max-range`); a distance equal to a bound is kept.
    pub range: DecodeOptions,
    /// Also drop distances outside the model's own measuring range (the user manual's
    /// specification, nebula's sensor-class limits: Pandar40P / 64 0.3–200 m, QT64 0.1–60 m,
    /// QT128 0.05–50 m, XT16 / XT32 0.05–120 m, XT32M 0.5–300 m, AT128 1–180 m, OT128 0.1–230 m;
    /// none is published for the ATX).
    /// On by default: returns inside the blind zone are not measurements the sensor stands by
    /// (the shared QT64 capture sends thousands below 0.1 m).
    pub sensor_range: bool,
    /// Drop a return that is not its group's last when it lies within this distance (m) of
    /// another return of its group (nebula: 0.1). 0 = only identical returns are merged.
    pub dual_return_threshold_m: f32,
    /// Keep only points whose corrected azimuth lies in this range (0.01°, start → end
    /// clockwise, inclusive); `None` = all.
    pub fov_cdeg: Option<(u32, u32)>,
}

impl Default for HesaiOptions {
    fn default() -> Self {
        Self {
            range: DecodeOptions::default(),
            sensor_range: true,
            dual_return_threshold_m: 0.0,
            fov_cdeg: None,
        }
    }
}

impl HesaiOptions {
    /// The filtering nebula's decoder applies (its Hesai test configuration): the model's
    /// range, the 0.1 m dual-return threshold, the range given.
    pub fn nebula(min_range: f32, max_range: f32) -> Self {
        Self {
            range: DecodeOptions {
                min_range,
                max_range,
            },
            sensor_range: true,
            dual_return_threshold_m: 0.1,
            fov_cdeg: None,
        }
    }
}

#[derive(Clone, Copy, Debug, Default)]
struct Channel {
    cos_el: f32,
    sin_el: f32,
    cos_off: f32,
    sin_off: f32,
    /// Azimuth offset, µ°.
    off_udeg: i64,
    ring: u16,
}

/// cos / sin of every block azimuth (0.01° steps), built once.
fn azimuth_table() -> &'static [(f32, f32)] {
    static TABLE: std::sync::OnceLock<Vec<(f32, f32)>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        (0..36_000u32)
            .map(|a| {
                let r = (f64::from(a) / 100.0).to_radians();
                (r.cos() as f32, r.sin() as f32)
            })
            .collect()
    })
}

/// cos and sin of an AT128 angle (1/25 600°), from [`azimuth_table`]: its 0.01° step is 256
/// units, interpolated linearly. The interpolation's error (h²/8 = 4e-9 for h = 0.01°) is below
/// f32's resolution, as with nebula's table of every unit; a `sin_cos` in f64 for each point was
/// the AT128 decoder's largest cost.
#[inline]
fn at128_cos_sin(units: i64) -> (f32, f32) {
    const _: () = assert!(UNITS_PER_DEG == 100 * 256);
    let u = units.rem_euclid(AT128_TURN);
    let i = (u >> 8) as usize;
    let frac = (u & 255) as f32 * (1.0 / 256.0);
    let t = azimuth_table();
    let (c0, s0) = t.get(i).copied().unwrap_or((1.0, 0.0));
    let (c1, s1) = t
        .get(i + 1)
        .or_else(|| t.first())
        .copied()
        .unwrap_or((1.0, 0.0));
    (c0 + (c1 - c0) * frac, s0 + (s1 - s0) * frac)
}

/// The corrected azimuths of one block's channels ([`HesaiDecoder::block_azimuths`]).
pub struct BlockAzimuths<'a> {
    dec: &'a HesaiDecoder,
    block_az: u32,
    at128: Option<(&'a At128Correction, At128Block)>,
}

impl BlockAzimuths<'_> {
    /// Corrected azimuth of channel `c`, µ° in `[0, 360°)`; `None` for an AT128 block outside
    /// every mirror field, and for the ATX (its sweeps are its frames, not azimuth turns).
    #[inline]
    pub fn channel_udeg(&self, c: usize) -> Option<i64> {
        if self.dec.atx.is_some() {
            return None;
        }
        match (&self.dec.at128, &self.at128) {
            (None, _) => {
                let off = self.dec.channels.get(c).map_or(0, |ch| ch.off_udeg);
                Some((i64::from(self.block_az) * 10_000 + off).rem_euclid(TURN_UDEG))
            }
            (Some(_), Some((a, b))) => Some(a.block_azimuth(b, c)? * 1_000_000 / UNITS_PER_DEG),
            (Some(_), None) => None,
        }
    }
}

/// Raw distances `lo..=hi` whose distance (raw × unit in f64, rounded to f32: nebula's
/// arithmetic) lies in `[min_m, max_m]`, for a unit of `unit_mm` mm; raw 0 (no return) is never
/// inside. An empty range is `(1, 0)`.
fn raw_bounds(unit_mm: u8, min_m: f32, max_m: f32) -> (u16, u16) {
    let d = |raw: u32| (f64::from(raw) * f64::from(unit_mm) / 1000.0) as f32;
    // First raw with d ≥ min, last raw with d ≤ max (d is non-decreasing in raw).
    let first = |pred: &dyn Fn(u32) -> bool| {
        let (mut lo, mut hi) = (1u32, 65_536u32);
        while lo < hi {
            let mid = (lo + hi) / 2;
            if pred(mid) {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        lo
    };
    let lo = first(&|r| d(r) >= min_m);
    let hi = first(&|r| d(r) > max_m) - 1;
    if lo > hi || lo > 65_535 {
        (1, 0)
    } else {
        (lo as u16, hi.min(65_535) as u16)
    }
}

/// One decoded return before it is placed in a sweep.
#[derive(Clone, Copy, Debug)]
pub struct Decoded {
    /// The point (its `t` is 0: the stream sets it).
    pub point: Point,
    /// Channel index.
    pub channel: usize,
    /// Block index in the packet.
    pub block: usize,
    /// Firing time relative to the packet's tail time, ns: [`HesaiDecoder::firing_ns`] of
    /// (block, channel), looked up here where the block's row is at hand.
    pub firing_ns: i32,
}

/// Decoder for one sensor.
#[derive(Clone, Debug)]
pub struct HesaiDecoder {
    model: HesaiModel,
    channels: Vec<Channel>,
    at128: Option<At128Correction>,
    atx: Option<AtxCorrection>,
    opts: HesaiOptions,
    /// Per distance unit (mm, the header byte): the raw distances inside the range filter,
    /// `lo..=hi`, decided with nebula's arithmetic (raw × unit in f64, then f32) so that a
    /// bound cuts at the same raw value; the per-point distance is then an f32 product.
    raw_bounds: Vec<(u16, u16)>,
    fov_udeg: Option<(i64, i64)>,
    /// Firing tables of the (returns, flags) keys met, at most [`FIRING_TABLES`]; the one of
    /// the current packet is `tables[current]`. Kept, not rebuilt, when the key alternates
    /// (the QT128's dual-return loops): no work and no allocation per packet.
    tables: Vec<FiringTable>,
    current: usize,
    /// The table a new key replaces once `tables` is full (round robin).
    evict: usize,
}

/// Correction kinds of [`HesaiDecoder::group`]: the CSV's constant offsets, the AT128's
/// mirror fields, the ATX's per-frame rows.
const CSV: u8 = 0;
const AT128: u8 = 1;
const ATX: u8 = 2;

/// Most firing tables a decoder keeps.
const FIRING_TABLES: usize = 4;

/// The firing offsets of one (returns, reduced tail flags) key.
#[derive(Clone, Debug)]
struct FiringTable {
    key: (usize, TailFlags),
    /// Firing offsets, ns relative to the tail time, `block × channels + channel`.
    firing: Vec<i32>,
    /// Per block: the earliest of `firing` over the return group starting there (the stream
    /// asks for it once per group; a scan of the group's rows cost as much as its points).
    group_earliest: Vec<i32>,
}

impl FiringTable {
    fn new(model: HesaiModel, channels: usize, key: (usize, TailFlags)) -> Self {
        let (n_returns, flags) = key;
        let blocks = model.spec().layout.blocks;
        let mut firing = Vec::with_capacity(blocks * channels);
        for b in 0..blocks {
            for c in 0..channels {
                firing.push(model.firing_offset_ns(b, c, n_returns, flags) as i32);
            }
        }
        let group_earliest = (0..blocks)
            .map(|b| {
                firing
                    .get(b * channels..((b + n_returns.max(1)) * channels).min(firing.len()))
                    .and_then(|s| s.iter().min().copied())
                    .unwrap_or(0)
            })
            .collect();
        Self {
            key,
            firing,
            group_earliest,
        }
    }
}

impl HesaiDecoder {
    /// Builds the decoder; the correction must have the model's channel count (the ATX's
    /// gives it: its packets must then have as many lasers).
    pub fn new(
        model: HesaiModel,
        calib: &HesaiCalibration,
        opts: HesaiOptions,
    ) -> Result<Self, DecodeError> {
        let n = model.channels();
        if !model.spec().layout.counts_from_header && calib.channels() != n {
            return Err(DecodeError::LaserCount {
                model: model.name(),
                expected: n,
                found: calib.channels(),
            });
        }
        let (mut channels, at128, atx) = match calib {
            HesaiCalibration::Csv(rows) => {
                if matches!(model, HesaiModel::PandarAt128 | HesaiModel::PandarAtx) {
                    return Err(DecodeError::Calibration(format!(
                        "the {} needs its binary .dat angle correction",
                        model.name()
                    )));
                }
                let ch: Vec<Channel> = rows
                    .iter()
                    .map(|r| {
                        let (se, ce) = r.elevation_deg.to_radians().sin_cos();
                        let (so, co) = r.azimuth_deg.to_radians().sin_cos();
                        Channel {
                            cos_el: ce as f32,
                            sin_el: se as f32,
                            cos_off: co as f32,
                            sin_off: so as f32,
                            off_udeg: (r.azimuth_deg * 1e6).round() as i64,
                            ring: 0,
                        }
                    })
                    .collect();
                (ch, None, None)
            }
            HesaiCalibration::At128(a) => {
                if model != HesaiModel::PandarAt128 {
                    return Err(DecodeError::Calibration(format!(
                        "an AT128 .dat correction cannot serve the {}",
                        model.name()
                    )));
                }
                let ch: Vec<Channel> = a
                    .elevation
                    .iter()
                    .map(|&e| {
                        let (se, ce) = (e as f64 / UNITS_PER_DEG as f64).to_radians().sin_cos();
                        Channel {
                            cos_el: ce as f32,
                            sin_el: se as f32,
                            ..Channel::default()
                        }
                    })
                    .collect();
                (ch, Some(a.clone()), None)
            }
            HesaiCalibration::Atx(a) => {
                if model != HesaiModel::PandarAtx {
                    return Err(DecodeError::Calibration(format!(
                        "an ATX .dat correction cannot serve the {}",
                        model.name()
                    )));
                }
                // Rings rank the elevations before their azimuth-dependent adjustment.
                let ch: Vec<Channel> = a
                    .elevation_deg
                    .iter()
                    .map(|&e| {
                        let (se, ce) = e.to_radians().sin_cos();
                        Channel {
                            cos_el: ce as f32,
                            sin_el: se as f32,
                            ..Channel::default()
                        }
                    })
                    .collect();
                (ch, None, Some(a.clone()))
            }
            HesaiCalibration::AtxFiretimes(_) => {
                return Err(DecodeError::Calibration(
                    "an ATX firetime file serves with the ATX's angle correction (.dat), not alone"
                        .into(),
                ));
            }
        };
        // Ring = rank of the elevation (ties by channel index), 0 = lowest.
        let mut order: Vec<usize> = (0..channels.len()).collect();
        order.sort_by(|&a, &b| {
            channels[a]
                .sin_el
                .total_cmp(&channels[b].sin_el)
                .then(a.cmp(&b))
        });
        for (rank, &c) in order.iter().enumerate() {
            channels[c].ring = rank as u16;
        }
        let spec = model.spec();
        let (mut min_m, mut max_m) = (opts.range.min_range, opts.range.max_range);
        if opts.sensor_range {
            min_m = min_m.max(spec.min_range_m);
            max_m = max_m.min(spec.max_range_m);
        }
        // A range the model cannot reach (`--min-range 150` on a 120 m sensor) is no error:
        // it keeps no point, as it does for every family, and the run warns of it.
        if min_m.is_nan() || max_m.is_nan() {
            return Err(DecodeError::Option(format!(
                "range {min_m}–{max_m} m is not a number"
            )));
        }
        if opts.dual_return_threshold_m.is_nan() || opts.dual_return_threshold_m < 0.0 {
            return Err(DecodeError::Option(
                "dual-return threshold must be ≥ 0".into(),
            ));
        }
        let fov_udeg = opts.fov_cdeg.map(|(s, e)| {
            (
                i64::from(s % 36_000) * 10_000,
                i64::from(e % 36_000) * 10_000,
            )
        });
        Ok(Self {
            model,
            channels,
            at128,
            atx,
            opts,
            raw_bounds: (0..=255u8).map(|u| raw_bounds(u, min_m, max_m)).collect(),
            fov_udeg,
            tables: Vec::with_capacity(FIRING_TABLES),
            current: 0,
            evict: 0,
        })
    }

    /// The model.
    pub fn model(&self) -> HesaiModel {
        self.model
    }

    /// The options.
    pub fn options(&self) -> &HesaiOptions {
        &self.opts
    }

    /// Channel count.
    pub fn channels(&self) -> usize {
        self.channels.len()
    }

    /// Ring of channel `c`.
    pub fn ring(&self, c: usize) -> u16 {
        self.channels.get(c).map_or(0, |ch| ch.ring)
    }

    /// Prepares the firing table for a packet's return count and tail flags (cheap when they
    /// did not change).
    pub fn prepare(&mut self, n_returns: usize, flags: TailFlags) {
        if self.atx.is_some() {
            // No firing table (every offset 0): nothing to prepare.
            return;
        }
        let key = (n_returns, self.model.firing_flags(n_returns, flags));
        if self.tables.get(self.current).is_some_and(|t| t.key == key) {
            return;
        }
        if let Some(i) = self.tables.iter().position(|t| t.key == key) {
            self.current = i;
            return;
        }
        let table = FiringTable::new(self.model, self.channels.len(), key);
        if self.tables.len() < FIRING_TABLES {
            self.tables.push(table);
            self.current = self.tables.len() - 1;
        } else {
            self.current = self.evict;
            self.tables[self.evict] = table;
            self.evict = (self.evict + 1) % FIRING_TABLES;
        }
    }

    /// The firing offsets of the current key (empty before [`Self::prepare`]).
    #[inline]
    fn firing(&self) -> &[i32] {
        self.tables.get(self.current).map_or(&[], |t| &t.firing)
    }

    /// Firing time of (block, channel) relative to the packet's tail time, ns ([`Self::prepare`]
    /// first).
    #[inline]
    pub fn firing_ns(&self, block: usize, c: usize) -> i64 {
        i64::from(
            self.firing()
                .get(block * self.channels.len() + c)
                .copied()
                .unwrap_or(0),
        )
    }

    /// Earliest firing of the return group starting at `block`, relative to the tail (the
    /// group of the return count given to [`Self::prepare`]).
    #[inline]
    pub fn group_earliest_ns(&self, block: usize) -> i64 {
        let table = self.tables.get(self.current);
        i64::from(
            table
                .and_then(|t| t.group_earliest.get(block))
                .copied()
                .unwrap_or(0),
        )
    }

    /// Corrected azimuth of channel `c` for a block azimuth (packet units), µ° in `[0, 360°)`;
    /// `None` for an AT128 block outside every mirror field.
    pub fn channel_azimuth_udeg(&self, block_az: u32, c: usize) -> Option<i64> {
        self.block_azimuths(block_az).channel_udeg(c)
    }

    /// The corrected azimuths of a block's channels, with what they share (the AT128's mirror
    /// field and grid position) worked out once for the block.
    #[inline]
    pub fn block_azimuths(&self, block_az: u32) -> BlockAzimuths<'_> {
        BlockAzimuths {
            dec: self,
            block_az,
            at128: self
                .at128
                .as_ref()
                .and_then(|a| Some((a, a.block(i64::from(block_az))?))),
        }
    }

    /// A block azimuth in 0.01° of a turn, the unit of a sweep's first and last azimuth
    /// (the AT128's block azimuth counts 1/25 600°, the ATX's 1/256°).
    pub fn block_azimuth_cdeg(&self, block_az: u32) -> u16 {
        let cdeg = if self.at128.is_some() {
            block_az / 256
        } else if self.atx.is_some() {
            (u64::from(block_az) * 100 / 256) as u32
        } else {
            block_az
        };
        (cdeg % 36_000) as u16
    }

    /// Per-channel azimuth offsets, µ° (`None` for the AT128 and the ATX, whose channel
    /// azimuths are not the block azimuth plus a constant).
    pub fn azimuth_offsets_udeg(&self) -> Option<Vec<i64>> {
        (self.at128.is_none() && self.atx.is_none())
            .then(|| self.channels.iter().map(|c| c.off_udeg).collect())
    }

    fn in_fov(&self, az_udeg: i64) -> bool {
        match self.fov_udeg {
            None => true,
            Some((s, e)) if s == e => true,
            Some((s, e)) => (az_udeg - s).rem_euclid(TURN_UDEG) <= (e - s).rem_euclid(TURN_UDEG),
        }
    }

    /// Decodes return group `first..first + n` of a packet, calling `out` with each point in
    /// nebula's order (channel, then block within the group). `p` must be of the decoder's
    /// model; the caller has checked its return mode ([`returns_of_mode`]).
    #[inline]
    pub fn decode_group(
        &self,
        p: &HesaiPacket<'_>,
        first: usize,
        n: usize,
        out: impl FnMut(Decoded),
    ) {
        // One loop per (returns, correction kind): the per-channel work then has no dispatch
        // and fixed-size arrays.
        let n = n.clamp(1, 3).min(p.layout().blocks.saturating_sub(first));
        let kind = if self.at128.is_some() {
            AT128
        } else if self.atx.is_some() {
            ATX
        } else {
            CSV
        };
        match (n, kind) {
            (0, _) => {}
            (1, CSV) => self.group::<1, CSV>(p, first, out),
            (2, CSV) => self.group::<2, CSV>(p, first, out),
            (_, CSV) => self.group::<3, CSV>(p, first, out),
            (1, AT128) => self.group::<1, AT128>(p, first, out),
            (2, AT128) => self.group::<2, AT128>(p, first, out),
            (_, AT128) => self.group::<3, AT128>(p, first, out),
            (1, _) => self.group::<1, ATX>(p, first, out),
            (2, _) => self.group::<2, ATX>(p, first, out),
            (_, _) => self.group::<3, ATX>(p, first, out),
        }
    }

    #[inline(always)]
    fn group<const N: usize, const KIND: u8>(
        &self,
        p: &HesaiPacket<'_>,
        first: usize,
        mut out: impl FnMut(Decoded),
    ) {
        let unit_mm = p.dis_unit_mm();
        let unit_m = f64::from(unit_mm) / 1000.0;
        let unit_f32 = unit_m as f32;
        let (raw_lo, raw_hi) = self
            .raw_bounds
            .get(usize::from(unit_mm))
            .copied()
            .unwrap_or((1, 0));
        let mode = p.return_mode();
        let ul = p.layout().unit_len.max(3);
        let units: [&[u8]; N] = core::array::from_fn(|k| p.units(first + k));
        // Every block of a checked packet has the same length.
        let n_channels = units
            .iter()
            .fold(self.channels.len(), |n, u| n.min(u.len() / ul));
        let units: [&[u8]; N] = core::array::from_fn(|k| &units[k][..n_channels * ul]);
        let block_az = p.azimuth(first);
        let (cb, sb) = if KIND != CSV {
            (1.0, 0.0)
        } else {
            azimuth_table()
                .get((block_az % 36_000) as usize)
                .copied()
                .unwrap_or((1.0, 0.0))
        };
        // AT128: what the block's channels share (mirror field, grid position); a block
        // outside every mirror's field has no point.
        let at128 = if KIND == AT128 {
            let Some(a) = &self.at128 else { return };
            let Some(b) = a.block(i64::from(block_az)) else {
                return;
            };
            Some((a, b))
        } else {
            None
        };
        // ATX: the frame's parity picks the azimuth row; the block azimuth is in 1/256°.
        let atx = if KIND == ATX {
            let Some(a) = &self.atx else { return };
            let speed = p.motor_rpm() as i16;
            Some((
                a,
                p.frame_id().unwrap_or(0) & 1 == 1,
                block_az as u16,
                speed,
            ))
        } else {
            None
        };
        let rets: [u8; N] = core::array::from_fn(|k| return_index(self.model, mode, k));
        let thr = self.opts.dual_return_threshold_m;
        // Distances as nebula computes them, for the dual-return threshold.
        let exact = |raw: u16| (f64::from(raw) * unit_m) as f32;
        let fov = self.fov_udeg.is_some();
        let nc = self.channels.len();
        let firing = self.firing();
        let fire: [&[i32]; N] = core::array::from_fn(|k| {
            firing
                .get((first + k) * nc..(first + k + 1) * nc)
                .unwrap_or(&[])
        });
        for (c, ch) in self.channels[..n_channels].iter().enumerate() {
            let o = c * ul;
            // Raw (distance, reflectivity) of each return.
            let raw: [(u16, u8); N] = core::array::from_fn(|k| {
                let u = &units[k][o..o + 3];
                (u16::from_le_bytes([u[0], u[1]]), u[2])
            });
            if raw.iter().all(|r| r.0 == 0) {
                continue;
            }
            // Angles of this channel (AT128: per point).
            let (cos_az, sin_az, cos_el, sin_el) = if let Some((a, b)) = &at128 {
                match a.block_angles(b, c) {
                    Some((az, el)) => {
                        if fov && !self.in_fov(az * 1_000_000 / UNITS_PER_DEG) {
                            continue;
                        }
                        let (co, s) = at128_cos_sin(az);
                        let (ce, se) = at128_cos_sin(el);
                        (co, s, ce, se)
                    }
                    None => continue,
                }
            } else if let Some((a, odd, raw_az, speed)) = &atx {
                let Some((az, el)) = a.angles(c, *raw_az, *odd, *speed) else {
                    continue;
                };
                if fov && !self.in_fov((az * 1_000_000 / UNITS_PER_DEG).rem_euclid(TURN_UDEG)) {
                    continue;
                }
                let (co, s) = at128_cos_sin(az);
                let (ce, se) = at128_cos_sin(el);
                (co, s, ce, se)
            } else {
                if fov
                    && !self
                        .in_fov((i64::from(block_az) * 10_000 + ch.off_udeg).rem_euclid(TURN_UDEG))
                {
                    continue;
                }
                (
                    cb * ch.cos_off - sb * ch.sin_off,
                    sb * ch.cos_off + cb * ch.sin_off,
                    ch.cos_el,
                    ch.sin_el,
                )
            };
            let mut emit = |k: usize| {
                let d = f32::from(raw[k].0) * unit_f32;
                let xy = d * cos_el;
                out(Decoded {
                    point: Point {
                        x: xy * cos_az,
                        y: -xy * sin_az,
                        z: d * sin_el,
                        intensity: f32::from(raw[k].1),
                        t: 0,
                        ring: ch.ring,
                        ret: rets[k],
                        pad: 0,
                    },
                    channel: c,
                    block: first + k,
                    firing_ns: fire[k].get(c).copied().unwrap_or(0),
                });
            };
            let valid = |k: usize| raw[k].0 >= raw_lo && raw[k].0 <= raw_hi;
            match N {
                1 => {
                    if valid(0) {
                        emit(0);
                    }
                }
                2 => {
                    // The first return is dropped when identical to the second or (with a
                    // threshold) within it of the second; the group's last is always kept.
                    let (a, b) = (raw[0], raw[N - 1]);
                    let merged = a == b || (thr > 0.0 && (exact(a.0) - exact(b.0)).abs() < thr);
                    if valid(0) && !merged {
                        emit(0);
                    }
                    if valid(N - 1) {
                        emit(N - 1);
                    }
                }
                _ => {
                    for k in 0..N {
                        if !valid(k) {
                            continue;
                        }
                        if k + 1 < N {
                            let dropped = (0..N).any(|j| {
                                j != k
                                    && (raw[j] == raw[k]
                                        || (thr > 0.0
                                            && (exact(raw[j].0) - exact(raw[k].0)).abs() < thr))
                            });
                            if dropped {
                                continue;
                            }
                        }
                        emit(k);
                    }
                }
            }
        }
    }

    /// Decodes a whole packet into `out` with `t` = firing time − `t0_ns` (ns, clamped to ≥ 0),
    /// where firing time = `stamp_ns` + the model's firing offset. Returns the points added,
    /// or `None` for a packet whose return mode is unknown, or whose laser count is not the
    /// correction's (ATX).
    pub fn decode_packet(
        &mut self,
        p: &HesaiPacket<'_>,
        stamp_ns: i64,
        t0_ns: i64,
        out: &mut Vec<Point>,
    ) -> Option<usize> {
        let n = returns_of_mode(p.return_mode())?;
        if p.layout().channels != self.channels.len() {
            return None;
        }
        self.prepare(n, p.tail_flags());
        let before = out.len();
        let blocks = p.layout().blocks;
        out.reserve(blocks * self.channels.len());
        // Both times are the caller's: any i64, so the difference saturates.
        let base = stamp_ns.saturating_sub(t0_ns);
        let this = &*self;
        let mut g = 0;
        while g < blocks {
            this.decode_group(p, g, n, |d| {
                let t = base.saturating_add(i64::from(d.firing_ns));
                let mut pt = d.point;
                pt.t = t.clamp(0, i64::from(u32::MAX)) as u32;
                out.push(pt);
            });
            g += n;
        }
        Some(out.len() - before)
    }
}

#[cfg(all(test, feature = "sim"))]
mod tests {
    use super::*;
    use crate::sensor::hesai::calib::ChannelAngles;
    use crate::sensor::hesai::model::TailFlags;
    use crate::sensor::hesai::sim::{encode_packet, BlockData, TailData};

    fn flat(n: usize) -> HesaiCalibration {
        HesaiCalibration::Csv(
            (0..n)
                .map(|i| ChannelAngles {
                    elevation_deg: -(i as f64),
                    azimuth_deg: 0.0,
                })
                .collect(),
        )
    }

    fn packet(mode: u8, units: [(u16, u8); 3]) -> Vec<u8> {
        let m = HesaiModel::PandarXt32m;
        let blocks: Vec<BlockData> = (0..6)
            .map(|b| BlockData {
                azimuth: 9_000,
                units: vec![units[b % 3]; 32],
            })
            .collect();
        let tail = TailData {
            return_mode: mode,
            motor_rpm: 600,
            stamp_ns: 1_700_000_000_000_000_000,
            udp_seq: 1,
            dis_unit_mm: 5,
            flags: TailFlags::default(),
            signature: false,
            frame_id: 0,
        };
        encode_packet(m, &blocks, &tail)
    }

    fn decode(opts: HesaiOptions, bytes: &[u8]) -> Vec<Point> {
        let m = HesaiModel::PandarXt32m;
        let mut dec = HesaiDecoder::new(m, &flat(32), opts).unwrap();
        let p = HesaiPacket::new(bytes, m).unwrap();
        let mut out = Vec::new();
        dec.decode_packet(&p, 0, 0, &mut out).unwrap();
        out
    }

    #[test]
    fn at128_cos_sin_is_within_f32_resolution_of_f64_trigonometry() {
        // Every 7th unit of a turn and a few beyond both ends (negative elevations, wraps).
        let mut worst = 0f64;
        for u in (-40_000..AT128_TURN + 40_000).step_by(7) {
            let (c, s) = at128_cos_sin(u);
            let (ts, tc) = (u as f64 / 25_600.0).to_radians().sin_cos();
            worst = worst.max((f64::from(c) - tc).abs().max((f64::from(s) - ts).abs()));
        }
        // 1e-6 at 180 m is 0.18 mm; f32 itself rounds at 6e-8.
        assert!(worst < 2e-7, "{worst}");
    }

    #[test]
    fn triple_return_keeps_first_last_strongest_as_returns_2_1_0() {
        // 0x3d: blocks (first, last, strongest) per firing; distances 10 m, 30 m, 20 m.
        let b = packet(0x3d, [(2_000, 10), (6_000, 20), (4_000, 90)]);
        let pts = decode(HesaiOptions::default(), &b);
        // 2 groups × 32 channels × 3 returns.
        assert_eq!(pts.len(), 2 * 32 * 3);
        assert_eq!(
            pts[..3].iter().map(|p| p.ret).collect::<Vec<_>>(),
            vec![2, 1, 0]
        );
        // Azimuth 90°: the points lie on −y (clockwise from forward).
        assert!(
            (pts[0].y + 10.0).abs() < 1e-4 && pts[0].x.abs() < 1e-4,
            "{:?}",
            pts[0]
        );
        assert_eq!(pts[2].intensity, 90.0);
    }

    #[test]
    fn identical_returns_are_one_point_and_the_threshold_drops_near_ones() {
        // First == strongest: one point (from the group's last block, the strongest).
        let b = packet(0x3d, [(4_000, 90), (6_000, 20), (4_000, 90)]);
        let pts = decode(HesaiOptions::default(), &b);
        assert_eq!(pts.len(), 2 * 32 * 2);
        // With nebula's 0.1 m threshold, returns that are not the group's last are dropped when
        // within 0.1 m of another: first (29.95 m) and last (30 m) both go, strongest stays.
        let b = packet(0x3d, [(5_990, 10), (6_000, 20), (4_000, 90)]);
        assert_eq!(decode(HesaiOptions::default(), &b).len(), 2 * 32 * 3);
        let opts = HesaiOptions {
            dual_return_threshold_m: 0.1,
            ..HesaiOptions::default()
        };
        let pts = decode(opts, &b);
        assert_eq!(pts.len(), 2 * 32);
        assert!(pts.iter().all(|p| p.ret == 0));
    }

    #[test]
    fn range_bounds_cut_at_nebulas_raw_values() {
        // 5 mm unit: raw 100 = 0.5 m is kept by a 0.5 m minimum (a bound is inclusive), 99 not.
        assert_eq!(raw_bounds(5, 0.5, 300.0), (100, 60_000));
        assert_eq!(raw_bounds(4, 0.3, 200.0), (75, 50_000));
        assert_eq!(raw_bounds(4, 0.1, 60.0), (25, 15_000));
        assert_eq!(raw_bounds(4, 10.0, 1.0), (1, 0));
        // A zero unit (hostile header): every distance is 0 m.
        assert_eq!(raw_bounds(0, 0.0, f32::INFINITY), (1, 65_535));
    }
}
