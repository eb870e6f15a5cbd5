//! Robosense packet encoders (MSOP and DIFOP, byte-exact) and simulators over a [`Scene`], with
//! ground truth: [`RobosenseSim`] for the spinning models, [`M1Sim`] for the M1 (at the end).
//!
//! [`RobosenseSim`] fires every slot of every block at the model's firing time relative to the
//! packet's header time; the block azimuth is the head's azimuth at the firing, rounded to
//! 0.01°; each slot's beam points at the block azimuth plus the model's interpolation of the
//! step to the next firing (in whole 0.01° steps) plus the laser's horizontal angle — the angle
//! model of RoboSense's SDK and of the decoder, so the simulator checks layouts, units, timing and
//! geometry while the real capture checks the angle model. Beams leave from the lens centre.
//! Distances are rounded to the distance unit. Dual mode: every 5th beam also sees a surface
//! 1.5 m behind (the second return); the others send the same return twice, which the decoder
//! merges into one point.

use nalgebra::{Point3, Vector3};

use super::calib::RobosenseAngles;
use super::m1::{
    M1Channel, M1_ANGLE_OFFSET, M1_BLOCKS, M1_BLOCK_LEN, M1_CHANNELS, M1_DIFOP_LEN, M1_FRAME_NS,
    M1_HEADER_LEN, M1_MAX_RANGE_M, M1_MIN_RANGE_M, M1_MSOP_ID, M1_MSOP_LEN, M1_PACKETS_PER_FRAME,
    M1_RADIUS_UNIT_M, M1_TEMPERATURE_OFFSET_C,
};
use super::model::{
    us_to_ns, ClockForm, DualForm, RobosenseModel, Shape, PACKET_LEN, RS16_PITCH_OFFSET,
};
use super::wire::{DIFOP_ID, MSOP_ID_V1, MSOP_ID_V2};
use crate::sim::motion::Trajectory;
use crate::sim::scene::{Hit, Scene};

/// One block: azimuth (0.01°), Ruby return id, (raw distance, intensity) per slot.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BlockData {
    /// Azimuth, 0.01°.
    pub azimuth: u16,
    /// Ruby: the return id byte.
    pub return_id: u8,
    /// Per slot.
    pub slots: Vec<(u16, u8)>,
}

/// Writes one MSOP packet of a spinning `model` with header time `stamp_ns` (truncated to the
/// µs). The M1's packet is [`encode_m1_msop`]'s (for the M1 this writes only its id into a
/// spinning-size buffer, which no view accepts).
pub fn encode_msop(model: RobosenseModel, blocks: &[BlockData], stamp_ns: i64) -> Vec<u8> {
    let shape = model.spec().shape;
    let mut b = vec![0u8; PACKET_LEN];
    match shape {
        Shape::V1 => b[..8].copy_from_slice(&MSOP_ID_V1),
        Shape::Mems => b[..4].copy_from_slice(&M1_MSOP_ID),
        Shape::Helios | Shape::Ruby => {
            b[..4].copy_from_slice(&MSOP_ID_V2);
            b[4..6].copy_from_slice(&1u16.to_be_bytes());
        }
    }
    let t = shape.time_offset();
    let secs = stamp_ns.div_euclid(1_000_000_000);
    let us = stamp_ns.rem_euclid(1_000_000_000) / 1_000;
    match model.spec().clock {
        ClockForm::Unix => {
            b[t..t + 6].copy_from_slice(&secs.to_be_bytes()[2..]);
            b[t + 6..t + 10].copy_from_slice(&(us as u32).to_be_bytes());
        }
        ClockForm::Calendar => {
            let (y, mo, d) = crate::sensor::hesai::sim::civil_from_days(secs.div_euclid(86_400));
            let s = secs.rem_euclid(86_400);
            b[t..t + 6].copy_from_slice(&[
                (y - 2000) as u8,
                mo as u8,
                d as u8,
                (s / 3600) as u8,
                (s / 60 % 60) as u8,
                (s % 60) as u8,
            ]);
            b[t + 6..t + 8].copy_from_slice(&((us / 1000) as u16).to_be_bytes());
            b[t + 8..t + 10].copy_from_slice(&((us % 1000) as u16).to_be_bytes());
        }
    }
    for (i, blk) in blocks.iter().take(shape.blocks()).enumerate() {
        let o = shape.header_len() + i * shape.block_len();
        match shape {
            Shape::Ruby => {
                b[o] = 0xFE;
                b[o + 1] = blk.return_id;
            }
            _ => b[o..o + 2].copy_from_slice(&[0xFF, 0xEE]),
        }
        b[o + 2..o + 4].copy_from_slice(&blk.azimuth.to_be_bytes());
        for (s, &(d, r)) in blk.slots.iter().take(shape.slots()).enumerate() {
            let u = o + 4 + 3 * s;
            b[u..u + 2].copy_from_slice(&d.to_be_bytes());
            b[u + 2] = r;
        }
    }
    if shape != Shape::Ruby {
        b[PACKET_LEN - 2..].copy_from_slice(&[0x00, 0xFF]);
    }
    b
}

/// Writes a DIFOP packet: rpm, full field of view, serial, return mode and the angle table.
pub fn encode_difop(
    model: RobosenseModel,
    angles: &RobosenseAngles,
    rpm: u16,
    return_mode: u8,
    serial: [u8; 6],
) -> Vec<u8> {
    let mut b = vec![0u8; PACKET_LEN];
    b[..8].copy_from_slice(&DIFOP_ID);
    b[8..10].copy_from_slice(&rpm.to_be_bytes());
    b[24..26].copy_from_slice(&6699u16.to_be_bytes());
    b[28..30].copy_from_slice(&7788u16.to_be_bytes());
    b[32..34].copy_from_slice(&0u16.to_be_bytes());
    b[34..36].copy_from_slice(&36_000u16.to_be_bytes());
    b[292..298].copy_from_slice(&serial);
    b[300] = return_mode;
    match model.spec().difop_angles {
        None => {
            for (i, &(v, _)) in angles.lasers.iter().take(16).enumerate() {
                let raw = (v.abs() * 10_000.0).round() as u32;
                let o = RS16_PITCH_OFFSET + 3 * i;
                b[o..o + 3].copy_from_slice(&raw.to_be_bytes()[1..]);
            }
        }
        Some((start, entries)) => {
            let put = |b: &mut [u8], k: usize, a: f64| {
                let o = start + 3 * k;
                b[o] = u8::from(a < 0.0);
                b[o + 1..o + 3].copy_from_slice(&((a.abs() * 100.0).round() as u16).to_be_bytes());
            };
            for (i, &(v, h)) in angles.lasers.iter().enumerate() {
                put(&mut b, i, v);
                put(&mut b, entries + i, h);
            }
            // A Helios-16P's table has 32 entries; the unused ones hold another fan.
            for i in angles.lasers.len()..entries {
                put(&mut b, i, -10.0 - i as f64 * 0.5);
                put(&mut b, entries + i, 0.0);
            }
        }
    }
    b[PACKET_LEN - 2..].copy_from_slice(&[0x0F, 0xF0]);
    b
}

/// Ground truth of one simulated return.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RobosenseTruth {
    /// Packet index (from 0).
    pub packet: u64,
    /// Block.
    pub block: usize,
    /// Slot.
    pub slot: usize,
    /// The point, REP 103 sensor frame at its firing time, metres.
    pub xyz: [f64; 3],
    /// Absolute firing time, ns.
    pub time_ns: i64,
    /// Intensity sent.
    pub intensity: u8,
    /// Return index the decoder must give.
    pub ret: u8,
}

/// A simulated spinning Robosense sensor (the M1's simulator is [`M1Sim`]).
#[derive(Clone, Debug)]
pub struct RobosenseSim {
    /// Model.
    pub model: RobosenseModel,
    /// Angles the beams follow (give the decoder the same, or the DIFOP).
    pub angles: RobosenseAngles,
    /// Dual return.
    pub dual: bool,
    /// Head rotation, degrees per second.
    pub deg_per_s: f64,
    /// Header time of the first packet, ns (a whole µs).
    pub stamp0_ns: i64,
    /// Packets made.
    pub packet_index: u64,
    /// `world_from_sensor` over time.
    pub trajectory: Trajectory,
}

impl RobosenseSim {
    /// A sensor at 600 rpm, single return.
    pub fn new(model: RobosenseModel, angles: RobosenseAngles, stamp0_ns: i64) -> Self {
        Self {
            model,
            angles,
            dual: false,
            deg_per_s: 3_600.0,
            stamp0_ns: stamp0_ns - stamp0_ns.rem_euclid(1_000),
            packet_index: 0,
            trajectory: Trajectory::identity(),
        }
    }

    /// The DIFOP return-mode byte of the simulated mode.
    pub fn return_mode(&self) -> u8 {
        let spec = self.model.spec();
        match (self.dual, spec.shape) {
            (true, _) => spec.dual_mode_byte,
            (false, Shape::V1) => 1,
            (false, Shape::Helios) => 4,
            (false, Shape::Ruby) => 2,
            (false, Shape::Mems) => 4,
        }
    }

    /// The DIFOP of the simulated sensor.
    pub fn difop(&self) -> Vec<u8> {
        encode_difop(
            self.model,
            &self.angles,
            (self.deg_per_s / 6.0).round() as u16,
            self.return_mode(),
            [0x24, 0x10, 0xBA, 0xC9, 0xD5, 0x0B],
        )
    }

    /// Header time of packet `k`, ns (whole µs).
    pub fn stamp_of(&self, k: u64) -> i64 {
        let p = self.model.spec().packet_period_ns(self.dual);
        self.stamp0_ns + ((k as f64 * p) / 1_000.0).round() as i64 * 1_000
    }

    /// The next packet: (host receive time, payload), appending the truth of every return the
    /// decoder must emit.
    pub fn next_packet(
        &mut self,
        scene: &dyn Scene,
        truth: &mut Vec<RobosenseTruth>,
    ) -> (i64, Vec<u8>) {
        let spec = self.model.spec();
        let shape = spec.shape;
        let dual = self.dual;
        let stamp = self.stamp_of(self.packet_index);
        let period_ns = us_to_ns(spec.firing_period_us(dual));
        let firings = spec.firings(dual);
        let head = |t: i64| (self.deg_per_s * (t - self.stamp0_ns) as f64 * 1e-9).rem_euclid(360.0);
        let az: Vec<u16> = (0..=firings)
            .map(|f| ((head(stamp + f as i64 * period_ns) * 100.0).round() as u32 % 36_000) as u16)
            .collect();
        let rps = ((self.deg_per_s / 6.0).round() as u16 / 60).max(1);
        let nominal =
            (36_000.0 * f64::from(rps) * f64::from(spec.firing_period_us(dual)) * 1e-6).round();
        // Block → (firing, return) in packet order.
        let ab = self.packet_index % 2 == 0;
        let roles: Vec<(usize, u8)> = (0..shape.blocks())
            .map(|b| match (dual, spec.dual) {
                (false, _) | (true, DualForm::SlotHalves) => (b, 0),
                (true, DualForm::BlockPairs) => (b / 2, (b % 2) as u8),
                (true, DualForm::AbPairs) => {
                    if ab {
                        [(0, 0), (0, 1), (1, 0)][b]
                    } else {
                        [(0, 0), (1, 0), (1, 1)][b]
                    }
                }
            })
            .collect();
        let mut blocks: Vec<BlockData> = roles
            .iter()
            .map(|&(f, r)| BlockData {
                azimuth: az[f],
                return_id: r,
                slots: vec![(0, 0); shape.slots()],
            })
            .collect();
        let unit = f64::from(spec.distance_unit_m);
        let lasers = self.model.lasers();
        let (rx, rz) = (f64::from(spec.lens_rx_m), f64::from(spec.lens_rz_m));
        for f in 0..firings {
            let step = if f + 1 < firings {
                let d = (i32::from(az[f + 1]) - i32::from(az[f])).rem_euclid(36_000);
                if d > 100 {
                    nominal
                } else {
                    f64::from(d)
                }
            } else {
                nominal
            };
            // Blocks of this firing: (block, return).
            let mine: Vec<(usize, u8)> = roles
                .iter()
                .enumerate()
                .filter(|(_, r)| r.0 == f)
                .map(|(b, r)| (b, r.1))
                .collect();
            let beams = if dual && spec.dual == DualForm::SlotHalves {
                16
            } else {
                shape.slots()
            };
            for s in 0..beams {
                let l = s % lasers;
                let (v, h) = self.angles.lasers[l];
                // The slot's azimuth in whole 0.01° steps, as the protocol's angle model has it.
                let frac = spec.slot_fraction(s, dual);
                let h0 = (f64::from(az[f]) + f64::from((step as f32 * frac) as i32)) / 100.0;
                let hh = h0 + h;
                let t_ns = stamp + f as i64 * period_ns + us_to_ns(spec.slot_us(s, dual));
                let (sh, ch) = hh.to_radians().sin_cos();
                let (s0, c0) = h0.to_radians().sin_cos();
                let (sv, cv) = v.to_radians().sin_cos();
                let dir = [cv * ch, -cv * sh, sv];
                let lens = [rx * c0, -rx * s0, rz];
                let pose = self.trajectory.pose(t_ns);
                let o = pose * Point3::from(lens);
                let dw = pose.rotation * Vector3::from(dir);
                let Some(Hit {
                    range,
                    reflectivity,
                    ..
                }) = scene.cast(o.coords.into(), dw.into())
                else {
                    continue;
                };
                let second = dual && (self.packet_index as usize * 7 + f * 3 + s) % 5 == 0;
                let refl = reflectivity.max(1);
                // (range, intensity, return, emitted).
                let rets: [(f64, u8, u8, bool); 2] = if second {
                    [(range, refl, 0, true), (range + 1.5, refl / 3, 1, true)]
                } else {
                    [(range, refl, 0, true), (range, refl, 1, false)]
                };
                for &(r, i, ret, emitted) in rets.iter().take(if dual { 2 } else { 1 }) {
                    let raw = (r / unit).round();
                    if !(1.0..=65_535.0).contains(&raw) {
                        continue;
                    }
                    let (blk, slot) = if dual && spec.dual == DualForm::SlotHalves {
                        (mine[0].0, s + 16 * usize::from(ret))
                    } else {
                        match mine.iter().find(|&&(_, rr)| rr == ret) {
                            Some(&(b, _)) => (b, s),
                            None => continue,
                        }
                    };
                    blocks[blk].slots[slot] = (raw as u16, i);
                    let rr = raw * unit;
                    if !emitted
                        || rr < f64::from(spec.min_range_m)
                        || rr > f64::from(spec.max_range_m)
                    {
                        continue;
                    }
                    truth.push(RobosenseTruth {
                        packet: self.packet_index,
                        block: blk,
                        slot,
                        xyz: [
                            lens[0] + rr * dir[0],
                            lens[1] + rr * dir[1],
                            lens[2] + rr * dir[2],
                        ],
                        time_ns: t_ns,
                        intensity: i,
                        ret,
                    });
                }
            }
        }
        self.packet_index += 1;
        let next = self.stamp_of(self.packet_index);
        (next, encode_msop(self.model, &blocks, stamp))
    }
}

/// One M1 block: time offset (µs), return sequence byte, 5 channels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct M1Block {
    /// Time offset from the packet time, µs.
    pub time_offset_us: u8,
    /// Return sequence byte.
    pub return_seq: u8,
    /// Channels.
    pub channels: [M1Channel; M1_CHANNELS],
}

/// Writes one M1 MSOP packet: counter `seq`, time `stamp_ns` (truncated to the µs), return-mode
/// byte, temperature and up to 25 blocks.
pub fn encode_m1_msop(
    seq: u16,
    stamp_ns: i64,
    return_mode: u8,
    temperature_c: i16,
    blocks: &[M1Block],
) -> Vec<u8> {
    let mut b = vec![0u8; M1_MSOP_LEN];
    b[..4].copy_from_slice(&M1_MSOP_ID);
    b[4..6].copy_from_slice(&seq.to_be_bytes());
    b[6..8].copy_from_slice(&1u16.to_be_bytes());
    b[8] = return_mode;
    let secs = stamp_ns.div_euclid(1_000_000_000);
    let us = stamp_ns.rem_euclid(1_000_000_000) / 1_000;
    b[10..16].copy_from_slice(&secs.to_be_bytes()[2..]);
    b[16..20].copy_from_slice(&(us as u32).to_be_bytes());
    b[31] = (temperature_c + M1_TEMPERATURE_OFFSET_C).clamp(0, 255) as u8;
    for (i, blk) in blocks.iter().take(M1_BLOCKS).enumerate() {
        let o = M1_HEADER_LEN + i * M1_BLOCK_LEN;
        b[o] = blk.time_offset_us;
        b[o + 1] = blk.return_seq;
        for (c, ch) in blk.channels.iter().enumerate() {
            let u = o + 2 + 9 * c;
            b[u..u + 2].copy_from_slice(&ch.raw_radius.to_be_bytes());
            b[u + 2..u + 4].copy_from_slice(&ch.raw_elevation.to_be_bytes());
            b[u + 4..u + 6].copy_from_slice(&ch.raw_azimuth.to_be_bytes());
            b[u + 6] = ch.intensity;
            b[u + 7] = ch.attribute;
            b[u + 8] = ch.elongation;
        }
    }
    b
}

/// Writes an M1 DIFOP: frame-rate byte, addresses, ports 6699 / 7788, firmware, serial.
pub fn encode_m1_difop(frame_rate: u8, firmware: [u8; 10], serial: [u8; 6]) -> Vec<u8> {
    let mut b = vec![0u8; M1_DIFOP_LEN];
    b[..8].copy_from_slice(&DIFOP_ID);
    b[9] = frame_rate;
    b[10..14].copy_from_slice(&[192, 168, 1, 200]);
    b[14..18].copy_from_slice(&[192, 168, 1, 102]);
    b[24..26].copy_from_slice(&6699u16.to_be_bytes());
    b[26..28].copy_from_slice(&7788u16.to_be_bytes());
    b[28..38].copy_from_slice(&firmware);
    b[38..44].copy_from_slice(&serial);
    b
}

/// Single-return packets per second: 630 per 100 ms frame (rs_driver), which with 125 points a
/// packet is the datasheet's 787 500 points/s.
pub const M1_PACKETS_PER_S: u32 = 6_300;
/// The simulated time between blocks, µs: 25 blocks in 150 of the packet's 158.7 µs.
pub const M1_SIM_BLOCK_US: u8 = 6;

/// A simulated M1 over a [`Scene`], with ground truth. The scan pattern approximates the
/// published field of view (120° × 25°, 10 Hz, 0.2° × 0.2°): each of the 5 channels covers
/// one 24°-wide zone of the 120°, all 25° high; a frame is 126 rows (630 packets, 5 per row)
/// of 125 columns per zone, the mirror going back and forth, so rows alternate direction.
/// Angles are whole 0.01° steps (what the packet carries), and the beam follows them exactly;
/// radii are rounded to 5 mm. Single return.
#[derive(Clone, Debug)]
pub struct M1Sim {
    /// Header time of the first packet, ns (a whole µs).
    pub stamp0_ns: i64,
    /// Packets made.
    pub packet_index: u64,
    /// `world_from_sensor` over time.
    pub trajectory: Trajectory,
}

impl M1Sim {
    /// A sensor whose first packet is at `stamp0_ns` (truncated to the µs).
    pub fn new(stamp0_ns: i64) -> Self {
        Self {
            stamp0_ns: stamp0_ns - stamp0_ns.rem_euclid(1_000),
            packet_index: 0,
            trajectory: Trajectory::identity(),
        }
    }

    /// Header time of packet `k`, ns (whole µs).
    pub fn stamp_of(&self, k: u64) -> i64 {
        let per_frame = u64::from(M1_PACKETS_PER_FRAME);
        let (frame, q) = (k / per_frame, k % per_frame);
        let in_frame_us = (q as f64 * M1_FRAME_NS as f64 / per_frame as f64 / 1_000.0).round();
        self.stamp0_ns + frame as i64 * M1_FRAME_NS + in_frame_us as i64 * 1_000
    }

    /// Elevation and azimuth of channel `c` in block `b` of the frame's packet `q`, 0.01°.
    pub fn angles_cdeg(q: u16, b: usize, c: usize) -> (i32, i32) {
        let row = i32::from(q / 5);
        let mut col = i32::from(q % 5) * M1_BLOCKS as i32 + b as i32;
        if row % 2 == 1 {
            col = 124 - col;
        }
        let el = (1250.0 - 2500.0 * (f64::from(row) + 0.5) / 126.0).round() as i32;
        let az =
            (-6000.0 + 2400.0 * c as f64 + 2400.0 * (f64::from(col) + 0.5) / 125.0).round() as i32;
        (el, az)
    }

    /// The DIFOP of the simulated sensor.
    pub fn difop(&self) -> Vec<u8> {
        encode_m1_difop(
            10,
            [1, 2, 3, 4, 5, 6, 7, 8, 9, 10],
            [0x31, 0x42, 0x53, 0x64, 0x75, 0x86],
        )
    }

    /// The next packet: (host receive time, payload), appending the truth of every return the
    /// decoder must emit (`block`, `slot` = channel).
    pub fn next_packet(
        &mut self,
        scene: &dyn Scene,
        truth: &mut Vec<RobosenseTruth>,
    ) -> (i64, Vec<u8>) {
        let k = self.packet_index;
        let q = (k % u64::from(M1_PACKETS_PER_FRAME)) as u16;
        let stamp = self.stamp_of(k);
        let unit = f64::from(M1_RADIUS_UNIT_M);
        let empty = M1Channel {
            raw_radius: 0,
            raw_elevation: M1_ANGLE_OFFSET,
            raw_azimuth: M1_ANGLE_OFFSET,
            intensity: 0,
            attribute: 0,
            elongation: 0,
        };
        let mut blocks = Vec::with_capacity(M1_BLOCKS);
        for b in 0..M1_BLOCKS {
            let off = b as u8 * M1_SIM_BLOCK_US;
            let t_ns = stamp + i64::from(off) * 1_000;
            let pose = self.trajectory.pose(t_ns);
            let mut blk = M1Block {
                time_offset_us: off,
                return_seq: 0,
                channels: [empty; M1_CHANNELS],
            };
            for (c, ch) in blk.channels.iter_mut().enumerate() {
                let (el, az) = Self::angles_cdeg(q, b, c);
                ch.raw_elevation = (el + i32::from(M1_ANGLE_OFFSET)) as u16;
                ch.raw_azimuth = (az + i32::from(M1_ANGLE_OFFSET)) as u16;
                let (se, ce) = (f64::from(el) / 100.0).to_radians().sin_cos();
                let (sa, ca) = (f64::from(az) / 100.0).to_radians().sin_cos();
                let dir = [ce * ca, ce * sa, se];
                let o = pose * Point3::origin();
                let dw = pose.rotation * Vector3::from(dir);
                let Some(Hit {
                    range,
                    reflectivity,
                    ..
                }) = scene.cast(o.coords.into(), dw.into())
                else {
                    continue;
                };
                let raw = (range / unit).round();
                if !(1.0..=65_535.0).contains(&raw) {
                    continue;
                }
                ch.raw_radius = raw as u16;
                ch.intensity = reflectivity.max(1);
                let r = raw * unit;
                if r < f64::from(M1_MIN_RANGE_M) || r > f64::from(M1_MAX_RANGE_M) {
                    continue;
                }
                truth.push(RobosenseTruth {
                    packet: k,
                    block: b,
                    slot: c,
                    xyz: [r * dir[0], r * dir[1], r * dir[2]],
                    time_ns: t_ns,
                    intensity: ch.intensity,
                    ret: 0,
                });
            }
            blocks.push(blk);
        }
        self.packet_index += 1;
        let next = self.stamp_of(self.packet_index);
        (next, encode_m1_msop(q + 1, stamp, 4, 40, &blocks))
    }
}
