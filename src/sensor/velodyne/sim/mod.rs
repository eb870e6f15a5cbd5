//! Velodyne packet encoder and a spinning-sensor simulator over a [`Scene`].
//!
//! The encoder writes the data-packet layout of FORMATS.md §5.1 byte for byte. The simulator
//! fires every laser at its datasheet firing time, at the azimuth the head has reached then
//! (constant rotation rate), casts the beam into the scene and records the ground truth of each
//! measurement next to the packet, so a decode can be checked against geometry, not against
//! itself. Block azimuths are rounded to 0.01° as a sensor reports them; distances to the
//! model's unit.
//!
//! The sensor moves along [`VelodyneSim::trajectory`] (default: the identity, a static sensor
//! at the world origin): each firing is cast from the pose at that firing's exact time, so a
//! sweep shows the motion distortion a real one does. [`Truth`] records, per measurement, the
//! point in the sensor frame at its firing time (what a decoder must reproduce), the same point
//! in the world, its label and its absolute firing time; the pose is
//! `trajectory.pose(truth.time_ns)`.
//!
//! ```
//! use nalgebra::{Isometry3, Vector3};
//! use ringscan::sensor::velodyne::calib::builtin::builtin;
//! use ringscan::sensor::velodyne::sim::VelodyneSim;
//! use ringscan::sensor::velodyne::{ReturnMode, VelodyneModel};
//! use ringscan::sim::{motion::Trajectory, scenes};
//! let t0 = 1_714_564_800_000_000_000;
//! let calib = builtin(VelodyneModel::Vlp16).unwrap();
//! let mut sim = VelodyneSim::new(VelodyneModel::Vlp16, ReturnMode::Strongest, calib, t0);
//! sim.trajectory = Trajectory::twist(
//!     t0,
//!     Isometry3::translation(0.0, 0.0, 1.8),
//!     Vector3::new(15.0, 0.0, 0.0),
//!     Vector3::new(0.0, 0.0, 60f64.to_radians()),
//! );
//! let scene = scenes::named("flat").unwrap();
//! let mut truth = Vec::new();
//! let (_host_ns, packet) = sim.next_packet(&scene, &mut truth);
//! assert_eq!(packet.len(), 1206);
//! let t = &truth[0];
//! let p = sim.trajectory.pose(t.time_ns) * nalgebra::Point3::from(t.xyz);
//! assert!((p.coords - Vector3::from(t.world)).norm() < 1e-9);
//! ```

pub mod hdl64;

use crate::sensor::velodyne::calib::VelodyneCalibration;
use crate::sensor::velodyne::model::ReturnMode;
use crate::sensor::velodyne::model::VelodyneModel;
use crate::sensor::velodyne::model::BLOCKS;
use crate::sensor::velodyne::model::DATA_PACKET_LEN;
use crate::sensor::velodyne::model::SLOTS;
use crate::sensor::velodyne::wire::FLAG_BANK2;
use crate::sensor::velodyne::wire::FLAG_BANK3;
use crate::sensor::velodyne::wire::FLAG_LOWER;
use crate::sensor::velodyne::wire::FLAG_UPPER;
use crate::sim::motion::Trajectory;
use crate::sim::scene::Hit;
use crate::sim::scene::Scene;
use nalgebra::{Isometry3, Point3, Vector3};

/// One block's content.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Block {
    /// Block flag (LE u16, e.g. `0xEEFF`).
    pub flag: u16,
    /// Azimuth, 0.01°.
    pub azimuth: u16,
    /// 32 × (raw distance, reflectivity).
    pub meas: [(u16, u8); SLOTS],
}

impl Default for Block {
    fn default() -> Self {
        Self {
            flag: FLAG_UPPER,
            azimuth: 0,
            meas: [(0, 0); SLOTS],
        }
    }
}

/// Writes a 1206-byte data packet.
pub fn encode_data_packet(
    blocks: &[Block; BLOCKS],
    toh_us: u32,
    factory: [u8; 2],
) -> [u8; DATA_PACKET_LEN] {
    let mut out = [0u8; DATA_PACKET_LEN];
    for (b, blk) in blocks.iter().enumerate() {
        let o = b * 100;
        out[o..o + 2].copy_from_slice(&blk.flag.to_le_bytes());
        out[o + 2..o + 4].copy_from_slice(&blk.azimuth.to_le_bytes());
        for (s, &(d, r)) in blk.meas.iter().enumerate() {
            let m = o + 4 + 3 * s;
            out[m..m + 2].copy_from_slice(&d.to_le_bytes());
            out[m + 2] = r;
        }
    }
    out[1200..1204].copy_from_slice(&toh_us.to_le_bytes());
    out[1204] = factory[0];
    out[1205] = factory[1];
    out
}

/// Writes a 512-byte position packet with a top-of-hour stamp, PPS state byte and NMEA text.
pub fn encode_position_packet(toh_us: u32, pps: u8, nmea: &str) -> [u8; 512] {
    let mut out = [0u8; 512];
    out[0xC6..0xCA].copy_from_slice(&toh_us.to_le_bytes());
    out[0xCA] = pps;
    let n = nmea.len().min(127);
    out[0xCE..0xCE + n].copy_from_slice(&nmea.as_bytes()[..n]);
    out
}

/// Ground truth of one simulated measurement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Truth {
    /// Block index in the packet.
    pub block: usize,
    /// Slot index in the block.
    pub slot: usize,
    /// Laser id.
    pub laser: usize,
    /// The scene point hit, REP 103 sensor frame at the firing time, metres: what the
    /// decoder must reproduce.
    pub xyz: [f64; 3],
    /// The same point in the world frame, metres.
    pub world: [f64; 3],
    /// [`GROUND`](crate::sim::scene::GROUND) (0) or the id of the object hit. A dual-return last
    /// return (a surface 1.5 m behind, which the scene does not hold) keeps the first's label.
    pub label: u32,
    /// Absolute firing time on the simulator's clock, ns (`host0_ns` + offset from the first
    /// packet's first firing, rounded to the ns); the pose is `trajectory.pose(time_ns)`. The
    /// packet's top-of-hour stamp is its first firing's time rounded to the µs (`toh0_us` at
    /// `host0_ns`), so a decoder's absolute point time differs from this by < 0.5 µs.
    pub time_ns: i64,
    /// Range along the beam, metres.
    pub range: f64,
    /// Reflectivity sent.
    pub reflectivity: u8,
    /// Firing time from the packet's first firing, ns.
    pub t_ns: f64,
    /// Return: 0 = strongest, 1 = last (only differing in dual mode).
    pub ret: u8,
}

/// A simulated spinning Velodyne.
#[derive(Clone, Debug)]
pub struct VelodyneSim {
    /// Model.
    pub model: VelodyneModel,
    /// Return mode.
    pub mode: ReturnMode,
    /// Calibration the beams follow (the decoder must be given the same).
    pub calib: VelodyneCalibration,
    /// Rotation rate, degrees per second (3600 = 600 rpm = 10 Hz).
    pub deg_per_s: f64,
    /// Azimuth at the first packet's first firing, degrees.
    pub azimuth0_deg: f64,
    /// Top-of-hour µs of the first packet.
    pub toh0_us: u32,
    /// Host receive time of the first packet, ns since the epoch.
    pub host0_ns: i64,
    /// Product id byte to write (defaults to the model's).
    pub product_id: Option<u8>,
    /// Packets generated so far.
    pub packet_index: u64,
    /// `world_from_sensor` over time (default: the identity, a static sensor).
    pub trajectory: Trajectory,
}

/// A scene seen from a sensor pose: rays given in the sensor frame are cast in the world, the
/// hit normal comes back in the sensor frame.
pub struct Posed<'a> {
    /// The world.
    pub scene: &'a dyn Scene,
    /// `world_from_sensor` (`None`: the identity, no transform).
    pub pose: Option<Isometry3<f64>>,
}

impl<'a> Posed<'a> {
    /// `scene` seen from `pose` (the identity skips the transform).
    pub fn new(scene: &'a dyn Scene, pose: Isometry3<f64>) -> Self {
        let pose = (pose != Isometry3::identity()).then_some(pose);
        Self { scene, pose }
    }

    /// A sensor-frame point in the world.
    pub fn to_world(&self, p: [f64; 3]) -> [f64; 3] {
        match &self.pose {
            None => p,
            Some(t) => (t * Point3::from(p)).coords.into(),
        }
    }
}

impl Scene for Posed<'_> {
    fn cast(&self, origin: [f64; 3], dir: [f64; 3]) -> Option<Hit> {
        let Some(t) = &self.pose else {
            return self.scene.cast(origin, dir);
        };
        let o = t * Point3::from(origin);
        let d = t.rotation * Vector3::from(dir);
        let mut h = self.scene.cast(o.coords.into(), d.into())?;
        h.normal = (t.rotation.inverse() * Vector3::from(h.normal)).into();
        Some(h)
    }
}

impl VelodyneSim {
    /// A sensor spinning at 10 Hz from azimuth 0, top of hour 0, host time `host0_ns`.
    pub fn new(
        model: VelodyneModel,
        mode: ReturnMode,
        calib: VelodyneCalibration,
        host0_ns: i64,
    ) -> Self {
        Self {
            model,
            mode,
            calib,
            deg_per_s: 3600.0,
            azimuth0_deg: 0.0,
            toh0_us: 0,
            host0_ns,
            product_id: None,
            packet_index: 0,
            trajectory: Trajectory::identity(),
        }
    }

    /// Nominal packet period, ns.
    pub fn period_ns(&self) -> f64 {
        self.model.packet_period_ns(self.mode)
    }

    /// Generates the next packet: (host receive time ns, payload), appending its ground truth.
    ///
    /// Calibrations with HDL-64E corrections are cast with their beam origin offsets; the
    /// distance written is the one the datasheet equations map back onto the scene point.
    pub fn next_packet(
        &mut self,
        scene: &dyn Scene,
        truth: &mut Vec<Truth>,
    ) -> (i64, [u8; DATA_PACKET_LEN]) {
        let period = self.period_ns();
        let t_packet_ns = self.packet_index as f64 * period;
        let toh_us = ((f64::from(self.toh0_us) + t_packet_ns / 1_000.0).round() as u64
            % 3_600_000_000) as u32;
        // The packet stamp is the first firing; it leaves the sensor one period later.
        let host_ns = self.host0_ns + (t_packet_ns + period).round() as i64;
        let res = self
            .calib
            .distance_resolution
            .unwrap_or(self.model.distance_resolution());
        let bpf = self.model.blocks_per_firing(self.mode);
        let used = self.model.blocks_used(self.mode);
        let dual = self.mode.is_dual();
        let mut blocks = [Block::default(); BLOCKS];
        // Blocks past `used` (VLS-128 dual: 8-11) stay empty: flag, azimuth and data all zero.
        for (b, blk) in blocks.iter_mut().enumerate().take(used) {
            let bank = self.model.bank_of_block(self.mode, b);
            blk.flag = [FLAG_UPPER, FLAG_LOWER, FLAG_BANK2, FLAG_BANK3][bank];
            // The azimuth the sensor reads for this block (VLS-128: the firing sequence's).
            let t_block = t_packet_ns
                + self
                    .model
                    .firing(self.mode, self.model.azimuth_block(self.mode, b), 0)
                    .0;
            blk.azimuth = azimuth_cdeg(self.azimuth_at(t_block));
            // In dual mode, which block of its firing group's pairs holds the last return
            // (`VelodyneModel::dual_pair`).
            let group = b - b % bpf;
            let is_last_block = dual && (0..bpf / 2).any(|k| self.model.dual_pair(group, k).0 == b);
            for s in 0..SLOTS {
                let (t_rel, _) = self.model.firing(self.mode, b, s);
                let laser = self.model.laser_of(bank, s);
                let Some(l) = self.calib.lasers.get(laser) else {
                    continue;
                };
                let az = self.azimuth_at(t_packet_ns + t_rel).to_radians() - l.rot_correction;
                let time_ns = self.host0_ns + (t_packet_ns + t_rel).round() as i64;
                let posed = Posed::new(scene, self.trajectory.pose(time_ns));
                let second_surface = (self.packet_index as usize * 7 + b / bpf * 3 + s) % 5 == 0;
                if self.calib.advanced {
                    // HDL-64E corrections: the raw distance whose corrected point is on the
                    // scene (sim::hdl64); dual: a weaker surface 1.5 m behind, as below.
                    let Some(first) =
                        crate::sensor::velodyne::sim::hdl64::measure(l, az, res, &posed)
                    else {
                        continue;
                    };
                    let (m, ret) = if dual && is_last_block {
                        if !second_surface {
                            blk.meas[s] = (first.raw, first.reflectivity);
                            continue;
                        }
                        let Some(m) =
                            crate::sensor::velodyne::sim::hdl64::behind(l, az, res, &first, 1.5)
                        else {
                            continue;
                        };
                        (m, 1)
                    } else {
                        (first, 0)
                    };
                    blk.meas[s] = (m.raw, m.reflectivity);
                    let range = m.xyz.iter().map(|v| v * v).sum::<f64>().sqrt();
                    truth.push(Truth {
                        block: b,
                        slot: s,
                        laser,
                        xyz: m.xyz,
                        world: posed.to_world(m.xyz),
                        // The surface behind is imaginary: it keeps the first hit's label.
                        label: m.label,
                        time_ns,
                        range,
                        reflectivity: m.reflectivity,
                        t_ns: t_rel,
                        ret,
                    });
                    continue;
                }
                let (sw, cw) = l.vert_correction.sin_cos();
                let (sa, ca) = az.sin_cos();
                let dir = [cw * ca, -cw * sa, sw];
                let origin = [0.0, 0.0, l.vert_offset_correction];
                let Some(hit) = posed.cast(origin, dir) else {
                    continue;
                };
                // Dual: every 5th ray also sees a surface 1.5 m behind, weaker: the last return.
                let mut range = hit.range;
                let mut refl = hit.reflectivity;
                let mut ret = 0u8;
                if dual && is_last_block {
                    if !second_surface {
                        // Same as the strongest block: the decoder emits one point, whose truth
                        // the strongest block records.
                        let raw = ((range - l.dist_correction) / res).round();
                        if (1.0..=65535.0).contains(&raw) {
                            blk.meas[s] = (raw as u16, refl);
                        }
                        continue;
                    }
                    range += 1.5;
                    refl /= 3;
                    ret = 1;
                }
                let raw = ((range - l.dist_correction) / res).round();
                if !(1.0..=65535.0).contains(&raw) {
                    continue;
                }
                blk.meas[s] = (raw as u16, refl);
                let xyz = [
                    origin[0] + range * dir[0],
                    origin[1] + range * dir[1],
                    origin[2] + range * dir[2],
                ];
                truth.push(Truth {
                    block: b,
                    slot: s,
                    laser,
                    xyz,
                    world: posed.to_world(xyz),
                    label: hit.label,
                    time_ns,
                    range,
                    reflectivity: refl,
                    t_ns: t_rel,
                    ret,
                });
            }
        }
        let factory = if self.model.is_hdl64() {
            // HDL-64E: status type / value bytes instead of factory bytes.
            [0, 0]
        } else {
            [
                self.mode.byte(),
                self.product_id.or(self.model.product_id()).unwrap_or(0),
            ]
        };
        self.packet_index += 1;
        (host_ns, encode_data_packet(&blocks, toh_us, factory))
    }

    fn azimuth_at(&self, t_ns: f64) -> f64 {
        (self.azimuth0_deg + self.deg_per_s * t_ns * 1e-9).rem_euclid(360.0)
    }
}

fn azimuth_cdeg(deg: f64) -> u16 {
    ((deg * 100.0).round() as i64).rem_euclid(36_000) as u16
}
