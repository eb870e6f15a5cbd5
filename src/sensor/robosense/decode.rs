//! Robosense MSOP packet + per-laser angles → points.
//!
//! For slot `s` (laser `l`) of a block with azimuth `A` (0.01°) in firing `f` of the packet:
//!
//! - `step` = the azimuth of firing `f + 1` − `A` (wrapped), or, for the packet's last firing
//!   or a step over 1° (a gap in the field of view), the nominal step of the motor speed
//!   (`round(36000 · rps · firing period)`, rps = rpm / 60 in whole turns, 10 until a DIFOP
//!   says);
//! - `h0 = A + ⌊step · fraction(s)⌋` (0.01°), the head's azimuth when the slot fired;
//! - `h = h0 + horizontal(l)`, `v = vertical(l)`;
//! - `x = d·cos v·cos h + RX·cos h0`, `y = −d·cos v·sin h − RX·sin h0`, `z = d·sin v + RZ`
//!   (REP 103: x forward, y left, z up; the azimuth grows clockwise seen from above; RX, RZ the
//!   lens centre of [`super::model::ModelSpec`]);
//! - time = the header time + `f` · firing period + the slot's firing offset.
//!
//! A distance of 0 is no return; distances outside the model's range (and the caller's) are
//! dropped. In dual-return mode a second return equal to the first is one point (return 0).

use std::sync::OnceLock;

use super::calib::RobosenseAngles;
use super::model::{us_to_ns, DualForm, ModelSpec, RobosenseModel};
use super::wire::Msop;
use crate::point::Point;
use crate::sensor::{DecodeError, DecodeOptions};

/// cos / sin of every 0.01° step of a turn.
fn trig() -> &'static [(f32, f32)] {
    static T: OnceLock<Vec<(f32, f32)>> = OnceLock::new();
    T.get_or_init(|| {
        (0..36_000)
            .map(|i| {
                let (s, c) = (f64::from(i) / 100.0).to_radians().sin_cos();
                (c as f32, s as f32)
            })
            .collect()
    })
}

#[inline]
pub(super) fn cs(cdeg: i32) -> (f32, f32) {
    let t = trig();
    t[cdeg.rem_euclid(36_000) as usize]
}

/// One decoded point with where it came from.
#[derive(Clone, Copy, Debug)]
pub struct Decoded {
    /// The point (`t` = 0; the stream sets it).
    pub point: Point,
    /// Firing time relative to the packet's header time, ns.
    pub offset_ns: i64,
    /// Firing (column) index within the packet.
    pub firing: usize,
    /// Block.
    pub block: usize,
    /// Slot.
    pub slot: usize,
    /// Raw distance.
    pub raw: u16,
    /// Final azimuth, 0.01° (before wrapping into 0..36000).
    pub azimuth_cdeg: i32,
}

/// A decoder for one model and one angle table.
#[derive(Clone, Debug)]
pub struct RobosenseDecoder {
    model: RobosenseModel,
    spec: &'static ModelSpec,
    cos_v: Vec<f32>,
    sin_v: Vec<f32>,
    horiz: Vec<i32>,
    ring: Vec<u16>,
    frac: [Vec<f32>; 2],
    slot_ns: [Vec<i64>; 2],
    min_m: f32,
    max_m: f32,
    nominal_step: [i32; 2],
}

impl RobosenseDecoder {
    /// A decoder; the angle table must have the model's laser count.
    pub fn new(
        model: RobosenseModel,
        angles: &RobosenseAngles,
        opts: DecodeOptions,
    ) -> Result<Self, DecodeError> {
        if model.spec().shape == super::model::Shape::Mems {
            // Its points carry their own angles: `super::m1::M1Decoder`.
            return Err(DecodeError::Unsupported {
                model: model.name(),
                mode: "the spinning decoder (M1 packets decode with m1::M1Decoder)",
            });
        }
        let n = model.lasers();
        if angles.lasers() != n {
            return Err(DecodeError::LaserCount {
                model: model.name(),
                expected: n,
                found: angles.lasers(),
            });
        }
        let spec = model.spec();
        let (cos_v, sin_v): (Vec<f32>, Vec<f32>) = angles
            .lasers
            .iter()
            .map(|&(v, _)| {
                let (s, c) = v.to_radians().sin_cos();
                (c as f32, s as f32)
            })
            .unzip();
        let horiz = angles
            .lasers
            .iter()
            .map(|&(_, h)| (h * 100.0).round() as i32)
            .collect();
        let ring = angles
            .lasers
            .iter()
            .map(|&(v, _)| angles.lasers.iter().filter(|&&(w, _)| w < v).count() as u16)
            .collect();
        let slots = spec.shape.slots();
        let frac = [false, true].map(|d| (0..slots).map(|s| spec.slot_fraction(s, d)).collect());
        let slot_ns =
            [false, true].map(|d| (0..slots).map(|s| us_to_ns(spec.slot_us(s, d))).collect());
        let mut dec = Self {
            model,
            spec,
            cos_v,
            sin_v,
            horiz,
            ring,
            frac,
            slot_ns,
            min_m: spec.min_range_m.max(opts.min_range),
            max_m: spec.max_range_m.min(opts.max_range),
            nominal_step: [0; 2],
        };
        dec.set_rpm(600);
        Ok(dec)
    }

    /// The model.
    pub fn model(&self) -> RobosenseModel {
        self.model
    }

    /// Sets the motor speed the nominal azimuth step follows (a DIFOP's rpm; 0 keeps 600).
    pub fn set_rpm(&mut self, rpm: u16) {
        let rps = match rpm / 60 {
            0 => 10,
            r => r,
        };
        for (i, d) in [false, true].into_iter().enumerate() {
            let p = f64::from(self.spec.firing_period_us(d)) * 1e-6;
            self.nominal_step[i] = (36_000.0 * f64::from(rps) * p).round() as i32;
        }
    }

    /// Ring (elevation rank) of each laser.
    pub fn rings(&self) -> &[u16] {
        &self.ring
    }

    /// Firing index and return (when the block says) of each block.
    pub fn roles(&self, p: &Msop<'_>, dual: bool, out: &mut [(usize, Option<u8>)]) {
        let blocks = self.spec.shape.blocks();
        for (b, o) in out.iter_mut().enumerate().take(blocks) {
            *o = match (dual, self.spec.dual) {
                (false, _) | (true, DualForm::SlotHalves) => (b, None),
                (true, DualForm::BlockPairs) => (b / 2, Some((b % 2) as u8)),
                (true, DualForm::AbPairs) => {
                    if p.azimuth(0) == p.azimuth(1) {
                        // A A B: the first two are one firing's returns.
                        [(0, Some(0)), (0, Some(1)), (1, Some(0))][b.min(2)]
                    } else {
                        [(0, Some(0)), (1, Some(0)), (1, Some(1))][b.min(2)]
                    }
                }
            };
        }
    }

    /// Decodes a packet; `dual` = the DIFOP's return mode is dual. Points go to `emit` in
    /// packet order (block, then slot).
    pub fn decode(&self, p: &Msop<'_>, dual: bool, mut emit: impl FnMut(Decoded)) {
        let blocks = self.spec.shape.blocks();
        let slots = self.spec.shape.slots();
        let lasers = self.model.lasers();
        let di = usize::from(dual);
        let mut roles = [(0usize, None); 12];
        self.roles(p, dual, &mut roles);
        // First block of each firing, for the azimuth steps.
        let mut first = [usize::MAX; 12];
        for (b, &(f, _)) in roles.iter().enumerate().take(blocks) {
            if first[f] == usize::MAX {
                first[f] = b;
            }
        }
        let period_ns = us_to_ns(self.spec.firing_period_us(dual));
        let nominal = self.nominal_step[di];
        let (frac, slot_ns) = (&self.frac[di], &self.slot_ns[di]);
        let unit = self.spec.distance_unit_m;
        let (rx, rz) = (self.spec.lens_rx_m, self.spec.lens_rz_m);
        for (b, &(f, ret)) in roles.iter().enumerate().take(blocks) {
            let az = i32::from(p.azimuth(b));
            let step = match first.get(f + 1) {
                Some(&nb) if nb != usize::MAX => {
                    let d = (i32::from(p.azimuth(nb)) - az).rem_euclid(36_000);
                    if d > 100 {
                        nominal
                    } else {
                        d
                    }
                }
                _ => nominal,
            };
            let partner = match ret {
                Some(1) => roles
                    .iter()
                    .take(blocks)
                    .position(|&(g, r)| g == f && r == Some(0)),
                _ => None,
            };
            let units = p.block_units(b);
            let base_ns = f as i64 * period_ns;
            for (s, u) in units.chunks_exact(3).enumerate().take(slots) {
                let raw = u16::from_be_bytes([u[0], u[1]]);
                if raw == 0 {
                    continue;
                }
                let (l, r) = if dual && self.spec.dual == DualForm::SlotHalves {
                    let r = (s / 16) as u8;
                    if r == 1 && p.slot(b, s - 16).0 == raw {
                        continue;
                    }
                    (s % 16, r)
                } else {
                    if let Some(pb) = partner {
                        if p.slot(pb, s).0 == raw {
                            continue;
                        }
                    }
                    (s % lasers, ret.unwrap_or(0))
                };
                let d = f32::from(raw) * unit;
                if d < self.min_m || d > self.max_m {
                    continue;
                }
                let h0 = az + (step as f32 * frac[s]) as i32;
                let h = h0 + self.horiz[l];
                let (ch, sh) = cs(h);
                let (c0, s0) = cs(h0);
                let (cv, sv) = (self.cos_v[l], self.sin_v[l]);
                let point = Point {
                    x: d * cv * ch + rx * c0,
                    y: -d * cv * sh - rx * s0,
                    z: d * sv + rz,
                    intensity: f32::from(u[2]),
                    t: 0,
                    ring: self.ring[l],
                    ret: r,
                    pad: 0,
                };
                emit(Decoded {
                    point,
                    offset_ns: base_ns + slot_ns[s],
                    firing: f,
                    block: b,
                    slot: s,
                    raw,
                    azimuth_cdeg: h,
                });
            }
        }
    }
}
