//! The Velodyne decoder: one table-driven loop for every model and return mode.
//!
//! Everything that depends only on the model, the return mode and the calibration is computed
//! in [`VelodyneDecoder::new`]: per-laser sin/cos of elevation and rotational correction, ring
//! numbers, per-slot firing times and laser ids. Per packet, the decoder computes the rotation
//! rate from the first and last block azimuths (the packet-mean rate, as velodyne_decoder does)
//! and, per slot, the small rotation of that slot's firing within its block; per block one
//! `sin_cos` of the block azimuth. Per point it is then a table lookup, one complex multiply and
//! three fused products: no `atan2`, no allocation, no per-point trigonometry.
//!
//! Unlike the reference, ringscan does not round the interpolated azimuth to 0.01°: points are
//! placed at the exact interpolated azimuth (the reference differs by up to 0.005°).
//!
//! Coordinates: Velodyne azimuth α grows clockwise seen from above, 0 = forward;
//! `x = d·cosω·cosα`, `y = −d·cosω·sinα`, `z = d·sinω + vert_offset` (REP 103 frame).

use core::ops::Range;

use crate::point::Point;
use crate::sensor::velodyne::calib::VelodyneCalibration;
use crate::sensor::velodyne::model::ReturnMode;
use crate::sensor::velodyne::model::VelodyneModel;
use crate::sensor::velodyne::model::BLOCKS;
use crate::sensor::velodyne::model::SLOTS;
use crate::sensor::velodyne::wire::DataPacket;
use crate::sensor::{DecodeError, DecodeOptions};

/// Per-laser constants.
#[derive(Clone, Copy, Debug, Default)]
struct Laser {
    cos_vert: f32,
    sin_vert: f32,
    cos_rot: f64,
    sin_rot: f64,
    vert_offset: f32,
    dist_correction: f32,
    ring: u16,
}

/// HDL-64E style corrections for one laser (metres), for [`advanced_xyz`].
///
/// The far distance correction and the vertical offset live in [`Laser`]
/// (`dist_correction`, `vert_offset`).
#[derive(Clone, Copy, Debug, Default)]
struct Advanced {
    /// Near two-point correction along the Velodyne x axis (`dist_correction_x`).
    dist_x: f32,
    /// Near two-point correction along the Velodyne y axis (`dist_correction_y`).
    dist_y: f32,
    /// Horizontal offset of the beam origin (`horiz_offset_correction`).
    horiz_offset: f32,
    /// Whether the two-point correction applies to this laser: velodyne_decoder 3.1.0's rule
    /// `dist_correction_x != 0 && dist_correction_y != 0` (`calibration.cpp`; the yaml key
    /// `two_pt_correction_available` is not read by it). A laser whose near corrections equal
    /// its far one (how ringscan's parsers encode "no two-point correction", see `calib`) is
    /// left out: the interpolation would give exactly `dist_correction` anyway.
    two_point: bool,
}

/// Most (bank, slot) combinations: 4 banks × 32 slots (VLS-128).
const LANES: usize = 4 * SLOTS;

/// Per (bank, slot) constants: the laser that slot fires and when, relative to its block.
#[derive(Clone, Copy, Debug, Default)]
struct Lane {
    laser: Laser,
    /// Laser id (index into the advanced table).
    id: u16,
    /// Firing time after the block's first firing, ns.
    dt_ns: u32,
    /// Firing time after the firing the block's azimuth was read at, ns (VLS-128: the firing
    /// sequence's start; every other model: the block's first firing, `dt_ns`).
    az_dt_ns: u32,
    /// Firing column after the block's first column (VLP-16: the second sequence is +1).
    col_off: u16,
}

/// cos / sin of every block azimuth (0.01° steps), shared by all decoders: 288 kB, built once.
fn azimuth_table() -> &'static [(f32, f32)] {
    static TABLE: std::sync::OnceLock<Vec<(f32, f32)>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        (0..36_000u32)
            .map(|a| {
                let (s, c) = (f64::from(a) * (core::f64::consts::PI / 18_000.0)).sin_cos();
                (c as f32, s as f32)
            })
            .collect()
    })
}

/// Per (block, slot) constants.
#[derive(Clone, Copy, Debug, Default)]
struct Slot {
    /// Firing time from the packet's first firing, ns.
    t_ns: u32,
    /// Firing column within the packet.
    column: u16,
}

/// A Velodyne decoder for one model, return mode and calibration.
#[derive(Clone, Debug)]
pub struct VelodyneDecoder {
    model: VelodyneModel,
    mode: ReturnMode,
    lasers: Vec<Laser>,
    advanced: Option<Vec<Advanced>>,
    slots: Box<[[Slot; SLOTS]; BLOCKS]>,
    /// Per (bank, slot) — index `bank · 32 + slot` — the laser fired and its constants.
    lanes: Box<[Lane; LANES]>,
    /// Lanes in use (32 × the banks of the model).
    n_lanes: usize,
    /// Bank of each block position within its firing group, by the layout of the model.
    expected_bank: [u8; BLOCKS],
    /// Time between block 0's and block 11's first firings, ns.
    rate_span_ns: f64,
    resolution: f32,
    opts: DecodeOptions,
    blocks_per_firing: usize,
    columns_per_packet: usize,
    /// Blocks holding measurements ([`VelodyneModel::blocks_used`]).
    blocks_used: usize,
}

/// What one call decoded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Decoded {
    /// Points appended.
    pub points: usize,
    /// Measurements with no return (distance 0) or outside the range filter.
    pub empty: usize,
}

/// The rotation rate of packets that hold one firing column (the VLS-128 in dual return mode),
/// which a packet cannot give by itself: the azimuth advance since the previous packet over one
/// nominal column period. The firing times within the column use the same nominal period, so
/// their rotation is the same fraction of the advance whatever the firmware's real period
/// (velodyne_decoder 3.1.0 `unpack_vls128` measures it so too). The first packet gets 0 (no
/// rotation within its column, as the reference); a rate above 1.8 × the last one (a packet
/// lost in between) keeps the last.
#[derive(Clone, Copy, Debug, Default)]
pub struct ColumnRate {
    prev_azimuth: Option<u16>,
    rate: f64,
}

impl ColumnRate {
    /// The rate for packet `p` (0.01° per ns), `None` when the decoder does not need one.
    pub fn next(&mut self, dec: &VelodyneDecoder, p: &DataPacket<'_>) -> Option<f64> {
        if !dec.needs_rate() {
            return None;
        }
        let az = p.azimuth(0);
        let period = dec.model().column_period_ns();
        let measured = match self.prev_azimuth {
            Some(prev) => {
                f64::from((u32::from(az) + 36_000 - u32::from(prev) % 36_000) % 36_000) / period
            }
            None => 0.0,
        };
        self.prev_azimuth = Some(az);
        if self.rate > 0.0 && measured > self.rate * 1.8 {
            return Some(self.rate);
        }
        self.rate = measured;
        Some(measured)
    }

    /// Forgets the previous packet (after a discontinuity).
    pub fn reset(&mut self) {
        *self = Self::default();
    }
}

impl VelodyneDecoder {
    /// Builds the lookup tables.
    pub fn new(
        model: VelodyneModel,
        mode: ReturnMode,
        calib: &VelodyneCalibration,
        opts: DecodeOptions,
    ) -> Result<Self, DecodeError> {
        if calib.num_lasers() != model.lasers() {
            return Err(DecodeError::LaserCount {
                model: model.name(),
                expected: model.lasers(),
                found: calib.num_lasers(),
            });
        }
        if opts.min_range.is_nan() || opts.max_range.is_nan() || opts.min_range > opts.max_range {
            return Err(DecodeError::Option(format!(
                "range filter [{}, {}] is empty",
                opts.min_range, opts.max_range
            )));
        }
        let rings = calib.rings();
        let lasers: Vec<Laser> = calib
            .lasers
            .iter()
            .zip(&rings)
            .map(|(l, &ring)| {
                let (sv, cv) = l.vert_correction.sin_cos();
                let (sr, cr) = l.rot_correction.sin_cos();
                Laser {
                    cos_vert: cv as f32,
                    sin_vert: sv as f32,
                    cos_rot: cr,
                    sin_rot: sr,
                    vert_offset: l.vert_offset_correction as f32,
                    dist_correction: l.dist_correction as f32,
                    ring,
                }
            })
            .collect();
        let advanced = calib.advanced.then(|| {
            calib
                .lasers
                .iter()
                .map(|l| Advanced {
                    dist_x: l.dist_correction_x as f32,
                    dist_y: l.dist_correction_y as f32,
                    horiz_offset: l.horiz_offset_correction as f32,
                    two_point: l.dist_correction_x != 0.0
                        && l.dist_correction_y != 0.0
                        && (l.dist_correction_x != l.dist_correction
                            || l.dist_correction_y != l.dist_correction),
                })
                .collect()
        });
        let bpf = model.blocks_per_firing(mode);
        let used = model.blocks_used(mode);
        let banks = model.banks();
        let mut slots = Box::new([[Slot::default(); SLOTS]; BLOCKS]);
        let mut expected_bank = [0u8; BLOCKS];
        for (b, row) in slots.iter_mut().enumerate() {
            expected_bank[b] = model.bank_of_block(mode, b) as u8;
            for (s, slot) in row.iter_mut().enumerate() {
                let (t, column) = model.firing(mode, b, s);
                *slot = Slot {
                    t_ns: t as u32,
                    column: column as u16,
                };
            }
        }
        let mut lanes = Box::new([Lane::default(); LANES]);
        for bank in 0..banks {
            // A block of this bank: the first one in the packet whose bank it is.
            let Some(b) = (0..used).find(|&b| usize::from(expected_bank[b]) == bank) else {
                continue;
            };
            let (t0, c0) = model.firing(mode, b, 0);
            // The firing at which the block's azimuth was read.
            let t_az = model.firing(mode, model.azimuth_block(mode, b), 0).0;
            for s in 0..SLOTS {
                let (t, c) = model.firing(mode, b, s);
                let id = model.laser_of(bank, s);
                lanes[bank * SLOTS + s] = Lane {
                    laser: lasers.get(id).copied().unwrap_or_default(),
                    id: id as u16,
                    dt_ns: (t - t0).round() as u32,
                    az_dt_ns: (t - t_az).round() as u32,
                    col_off: (c - c0) as u16,
                };
            }
        }
        let n_lanes = banks * SLOTS;
        let t0 = model.firing(mode, 0, 0).0;
        let rate_span_ns = model
            .firing(mode, model.azimuth_block(mode, BLOCKS - 1), 0)
            .0
            - t0;
        let resolution = model
            .fixed_distance_resolution()
            .or(calib.distance_resolution)
            .unwrap_or(model.distance_resolution()) as f32;
        Ok(Self {
            model,
            mode,
            lasers,
            advanced,
            slots,
            lanes,
            n_lanes,
            expected_bank,
            rate_span_ns,
            resolution,
            opts,
            blocks_per_firing: bpf,
            columns_per_packet: model.columns_per_packet(mode),
            blocks_used: used,
        })
    }

    /// The model.
    pub fn model(&self) -> VelodyneModel {
        self.model
    }

    /// The return mode.
    pub fn mode(&self) -> ReturnMode {
        self.mode
    }

    /// Blocks that make one firing (sweeps are cut between such groups).
    pub fn blocks_per_firing(&self) -> usize {
        self.blocks_per_firing
    }

    /// Firing columns per packet.
    pub fn columns_per_packet(&self) -> usize {
        self.columns_per_packet
    }

    /// Blocks of a packet that hold measurements (12, or 8 for the VLS-128 in dual return
    /// mode, whose blocks 8–11 are empty and not read).
    pub fn blocks_used(&self) -> usize {
        self.blocks_used
    }

    /// Whether a packet holds a single firing column, so that the rotation rate must come from
    /// the packets before it ([`ColumnRate`]; the VLS-128 in dual return mode).
    pub fn needs_rate(&self) -> bool {
        self.rate_span_ns <= 0.0
    }

    /// Firing time of the first measurement of `block`, from the packet's first firing, ns.
    pub fn block_time_ns(&self, block: usize) -> u32 {
        self.slots[block.min(BLOCKS - 1)][0].t_ns
    }

    /// Firing column of `block` within the packet.
    pub fn block_column(&self, block: usize) -> usize {
        usize::from(self.slots[block.min(BLOCKS - 1)][0].column)
    }

    /// Ring of a laser.
    pub fn ring_of(&self, laser: usize) -> Option<u16> {
        self.lasers.get(laser).map(|l| l.ring)
    }

    /// Checks that the packet's block flags follow this model's layout.
    pub fn check_layout(&self, p: &DataPacket<'_>) -> Result<(), DecodeError> {
        for b in 0..self.blocks_used {
            let bank = p.bank(b).unwrap_or(usize::MAX);
            if bank != usize::from(self.expected_bank[b]) {
                let expected =
                    [0xEEFFu16, 0xDDFF, 0xCCFF, 0xBBFF][usize::from(self.expected_bank[b])];
                return Err(DecodeError::Layout {
                    model: self.model.name(),
                    block: b,
                    expected,
                    found: p.flag(b),
                });
            }
        }
        Ok(())
    }

    /// Decodes a whole packet, appending points with `t = t_base_ns + firing offset` (clamped
    /// to the `u32` range).
    pub fn decode(&self, p: &DataPacket<'_>, t_base_ns: i64, out: &mut Vec<Point>) -> Decoded {
        self.decode_blocks(p, 0..BLOCKS, t_base_ns, out)
    }

    /// Decodes blocks `blocks` (whole firing groups) of a packet, appending to `out`.
    pub fn decode_blocks(
        &self,
        p: &DataPacket<'_>,
        blocks: Range<usize>,
        t_base_ns: i64,
        out: &mut Vec<Point>,
    ) -> Decoded {
        out.reserve(blocks.len() * SLOTS);
        self.decode_with(p, blocks, t_base_ns, |pt, _col| out.push(pt))
    }

    /// Decodes blocks of a packet, handing every point and its firing column (within the
    /// packet) to `emit`. The order is the reference's: block by block, slot by slot; in dual
    /// mode the last return of a slot before its strongest, one point when they are equal.
    /// A packet of one firing column ([`Self::needs_rate`]) is decoded without rotation
    /// within its column: use [`Self::decode_with_rate`].
    #[inline]
    pub fn decode_with<F: FnMut(Point, usize)>(
        &self,
        p: &DataPacket<'_>,
        blocks: Range<usize>,
        t_base_ns: i64,
        emit: F,
    ) -> Decoded {
        self.decode_with_rate(p, blocks, t_base_ns, None, emit)
    }

    /// [`Self::decode_with`], with the rotation rate (0.01° per ns, [`ColumnRate`]) for a
    /// packet that cannot give its own ([`Self::needs_rate`]); ignored for every other packet.
    #[inline]
    pub fn decode_with_rate<F: FnMut(Point, usize)>(
        &self,
        p: &DataPacket<'_>,
        blocks: Range<usize>,
        t_base_ns: i64,
        column_rate: Option<f64>,
        mut emit: F,
    ) -> Decoded {
        let mut n = Decoded::default();
        let end = blocks.end.min(self.blocks_used);
        let start = blocks.start.min(end);
        if start == end {
            return n;
        }
        // Packet-mean rotation rate, 0.01° per ns (velodyne_decoder's rule).
        let rate = if self.rate_span_ns > 0.0 {
            let az0 = f64::from(p.azimuth(0));
            let az_last = f64::from(p.azimuth(BLOCKS - 1));
            (az_last - az0).rem_euclid(36_000.0) / self.rate_span_ns
        } else {
            column_rate.filter(|r| r.is_finite()).unwrap_or(0.0)
        };
        // Per lane: rotation of the lane's firing after the firing its block's azimuth was read
        // at, minus the laser's rotational correction, as one (cos, sin) pair.
        let mut rot = [(1f32, 0f32); LANES];
        let to_rad = core::f64::consts::PI / 18_000.0;
        for (r, lane) in rot.iter_mut().zip(self.lanes.iter()).take(self.n_lanes) {
            let (cd, sd) = small_sin_cos(rate * f64::from(lane.az_dt_ns) * to_rad);
            let (cr, sr) = (lane.laser.cos_rot, lane.laser.sin_rot);
            // cos(δ − r), sin(δ − r)
            *r = ((cd * cr + sd * sr) as f32, (sd * cr - cd * sr) as f32);
        }
        let dual = self.mode.is_dual();
        let step = if dual { self.blocks_per_firing } else { 1 };
        let half = self.blocks_per_firing / 2;
        let mut b = start;
        while b < end {
            if dual {
                // The group's blocks carry the two returns of each bank in the model's
                // order (`VelodyneModel::dual_pair`).
                for k in 0..half {
                    let (last, strongest) = self.model.dual_pair(b, k);
                    if last.max(strongest) < self.blocks_used {
                        self.block_dual(p, last, strongest, &rot, t_base_ns, &mut n, &mut emit);
                    }
                }
            } else {
                self.block_single(p, b, &rot, t_base_ns, &mut n, &mut emit);
            }
            b += step;
        }
        n
    }

    #[inline]
    fn block_frame(&self, p: &DataPacket<'_>, block: usize) -> (f32, f32) {
        azimuth_table()
            .get(usize::from(p.azimuth(block)))
            .copied()
            .unwrap_or((1.0, 0.0))
    }

    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn point(
        &self,
        block: usize,
        lane: &Lane,
        rot: (f32, f32),
        raw: u16,
        refl: u8,
        ret: u8,
        frame: (f32, f32),
        t_base_ns: i64,
    ) -> Option<(Point, usize)> {
        let laser = &lane.laser;
        let measured = f32::from(raw) * self.resolution;
        let d = measured + laser.dist_correction;
        if !(d >= self.opts.min_range && d <= self.opts.max_range) {
            return None;
        }
        // cos/sin of (block azimuth + lane rotation − rot_correction).
        let (cb, sb) = frame;
        let (cl, sl) = rot;
        let ca = cb * cl - sb * sl;
        let sa = sb * cl + cb * sl;
        let (x, y, z) = match &self.advanced {
            None => {
                let xy = d * laser.cos_vert;
                (xy * ca, -xy * sa, d * laser.sin_vert + laser.vert_offset)
            }
            Some(adv) => {
                let a = adv.get(usize::from(lane.id))?;
                advanced_xyz(measured, laser, a, ca, sa)
            }
        };
        let sl0 = &self.slots[block][0];
        let pt = Point {
            x,
            y,
            z,
            intensity: f32::from(refl),
            t: t_base_ns
                .saturating_add(i64::from(sl0.t_ns) + i64::from(lane.dt_ns))
                .clamp(0, i64::from(u32::MAX)) as u32,
            ring: laser.ring,
            ret,
            pad: 0,
        };
        Some((pt, usize::from(sl0.column) + usize::from(lane.col_off)))
    }

    #[inline]
    fn block_single<F: FnMut(Point, usize)>(
        &self,
        p: &DataPacket<'_>,
        block: usize,
        rot: &[(f32, f32); LANES],
        t_base_ns: i64,
        n: &mut Decoded,
        emit: &mut F,
    ) {
        let frame = self.block_frame(p, block);
        let base = usize::from(self.expected_bank[block]) * SLOTS;
        let lanes = &self.lanes[base..base + SLOTS];
        let rots = &rot[base..base + SLOTS];
        let m = p.measurements(block);
        for ((meas, lane), &r) in m.chunks_exact(3).zip(lanes).zip(rots) {
            let raw = u16::from_le_bytes([meas[0], meas[1]]);
            if raw == 0 {
                n.empty += 1;
                continue;
            }
            match self.point(block, lane, r, raw, meas[2], 0, frame, t_base_ns) {
                Some((pt, col)) => {
                    emit(pt, col);
                    n.points += 1;
                }
                None => n.empty += 1,
            }
        }
    }

    #[inline]
    #[allow(clippy::too_many_arguments)]
    fn block_dual<F: FnMut(Point, usize)>(
        &self,
        p: &DataPacket<'_>,
        last_block: usize,
        strong_block: usize,
        rot: &[(f32, f32); LANES],
        t_base_ns: i64,
        n: &mut Decoded,
        emit: &mut F,
    ) {
        let frame = self.block_frame(p, last_block);
        let base = usize::from(self.expected_bank[last_block]) * SLOTS;
        let lanes = &self.lanes[base..base + SLOTS];
        let rots = &rot[base..base + SLOTS];
        let ml = p.measurements(last_block);
        let ms = p.measurements(strong_block);
        for (((l, s), lane), &r) in ml
            .chunks_exact(3)
            .zip(ms.chunks_exact(3))
            .zip(lanes)
            .zip(rots)
        {
            let dl = u16::from_le_bytes([l[0], l[1]]);
            let ds = u16::from_le_bytes([s[0], s[1]]);
            let mut one = |raw: u16, refl: u8, ret: u8, n: &mut Decoded| {
                if raw == 0 {
                    n.empty += 1;
                    return;
                }
                match self.point(last_block, lane, r, raw, refl, ret, frame, t_base_ns) {
                    Some((pt, col)) => {
                        emit(pt, col);
                        n.points += 1;
                    }
                    None => n.empty += 1,
                }
            };
            if dl == ds {
                // The strongest return is also the last: one point, return 0.
                one(ds, s[2], 0, n);
            } else {
                one(dl, l[2], 1, n);
                one(ds, s[2], 0, n);
            }
        }
    }
}

/// sin/cos of a small angle: a short series when |x| < 0.05 rad (error < 1e-12), else libm.
#[inline]
fn small_sin_cos(x: f64) -> (f64, f64) {
    if x.abs() < 0.05 {
        let x2 = x * x;
        let c = 1.0 - x2 * (0.5 - x2 * (1.0 / 24.0 - x2 / 720.0));
        let s = x * (1.0 - x2 * (1.0 / 6.0 - x2 * (1.0 / 120.0 - x2 / 5040.0)));
        (c, s)
    } else {
        let (s, c) = x.sin_cos();
        (c, s)
    }
}

/// Far calibration point of the HDL-64E two-point distance correction, metres.
const TWO_POINT_FAR_M: f32 = 25.04;
/// Near calibration point along the Velodyne x axis, metres.
const TWO_POINT_NEAR_X_M: f32 = 2.40;
/// Near calibration point along the Velodyne y axis, metres.
const TWO_POINT_NEAR_Y_M: f32 = 1.93;

/// HDL-64E S2 / S3 point from a measured distance, following velodyne_decoder 3.1.0
/// (`src/packet_decoder.cpp`, `PacketDecoder::unpackPoint`, advanced branch), which follows the
/// HDL-64E S3 manual's formulas with two documented departures. Per laser: far distance
/// correction `dc`, near corrections `dcx`, `dcy`, horizontal and vertical offsets `h`, `v`,
/// elevation ω; α = azimuth − rotational correction (`ca`, `sa` = cos α, sin α); `measured_m` =
/// raw distance × distance resolution, metres (no correction yet):
///
/// ```text
/// corr_x = corr_y = corr_z = dc
/// if two_point && measured < 25.04:                        # velodyne_decoder: near range only
///     xy = (measured + dc)·cos ω                           # no offsets here (S3 manual order)
///     kx = (|xy·sin α| − 2.40) / (25.04 − 2.40)
///     ky = (|xy·cos α| − 1.93) / (25.04 − 1.93)
///     corr_x = kx·dc + (1 − kx)·dcx
///     corr_y = ky·dc + (1 − ky)·dcy
///     corr_z = (corr_x + corr_y) / 2                       # manual: corr_y; velodyne_decoder: mean
/// x_v = (measured + corr_x)·cos ω·sin α − h·cos α           # Velodyne frame: x right, y forward
/// y_v = (measured + corr_y)·cos ω·cos α + h·sin α
/// z_v = (measured + corr_z)·sin ω + v                      # offset added last, not v·cos ω
/// (x, y, z) = (y_v, −x_v, z_v)                             # REP 103
/// ```
///
/// Differences from the other references, all deliberate: the ROS driver (`rawdata.cc`) uses
/// `xy = d·cos ω − v·sin ω` and the offsets inside `xx`/`yy`, extrapolates the two-point line
/// beyond 25.04 m and uses `z = d_y·sin ω + v·cos ω`; VeloView differs again. With every
/// correction zero the formula is the plain one (`z = d·sin ω + v`), so tables with only a
/// vertical offset give the same points on both paths. The two-point line is not continuous at
/// 25.04 m (e.g. laser 0 of `64e_s2.1-sztaki.yaml` jumps by 3.7 mm between raw 12519 and 12520),
/// hence `measured_m` is the f32 product `raw · resolution` exactly as velodyne_decoder forms it.
/// All arithmetic in f32, like velodyne_decoder (f64 changes the points by < 0.01 mm).
#[inline]
fn advanced_xyz(measured_m: f32, l: &Laser, a: &Advanced, ca: f32, sa: f32) -> (f32, f32, f32) {
    let (cv, sv) = (l.cos_vert, l.sin_vert);
    let dc = l.dist_correction;
    let (mut corr_x, mut corr_y, mut corr_z) = (dc, dc, dc);
    if a.two_point && measured_m < TWO_POINT_FAR_M {
        let xy = (measured_m + dc) * cv;
        let kx = ((xy * sa).abs() - TWO_POINT_NEAR_X_M) / (TWO_POINT_FAR_M - TWO_POINT_NEAR_X_M);
        let ky = ((xy * ca).abs() - TWO_POINT_NEAR_Y_M) / (TWO_POINT_FAR_M - TWO_POINT_NEAR_Y_M);
        corr_x = kx * dc + (1.0 - kx) * a.dist_x;
        corr_y = ky * dc + (1.0 - ky) * a.dist_y;
        corr_z = 0.5 * (corr_x + corr_y);
    }
    let hoff = a.horiz_offset;
    let xv = (measured_m + corr_x) * cv * sa - hoff * ca;
    let yv = (measured_m + corr_y) * cv * ca + hoff * sa;
    let zv = (measured_m + corr_z) * sv + l.vert_offset;
    (yv, -xv, zv)
}

/// HDL-64E corrected intensity (HDL-64E S3 manual App. F "focal" formula, in
/// velodyne_decoder 3.1.0's form, `PacketDecoder::unpackPoint`):
///
/// ```text
/// I = I_raw + 256·focal_slope·|(1 − focal_distance/131)² − (1 − raw_distance/65535)²|
/// I = clamp(I, min_intensity, max_intensity)
/// ```
///
/// `focal_distance` in metres (ringscan's unit; the manual's `focalDistance/13100` with
/// centimetres is the same number; the ROS driver divides a metre value by 13100, its issue
/// #499). `raw_distance` is the packet's u16 distance, not metres. velodyne_decoder emits this
/// as the point intensity for HDL-64E calibrations; ringscan keeps the raw reflectivity in
/// [`Point::intensity`] and offers this as an extra (f32, like the reference).
pub fn corrected_intensity(
    laser: &crate::sensor::velodyne::calib::LaserCalibration,
    raw_intensity: u8,
    raw_distance: u16,
) -> f32 {
    let focal = 1.0 - laser.focal_distance as f32 / 131.0;
    let dist = 1.0 - f32::from(raw_distance) / 65_535.0;
    let i = f32::from(raw_intensity)
        + 256.0 * laser.focal_slope as f32 * (focal * focal - dist * dist).abs();
    i.clamp(
        f32::from(laser.min_intensity),
        f32::from(laser.max_intensity),
    )
}
