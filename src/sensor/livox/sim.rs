//! Livox packet encoders (points → byte-exact SDK2 / SDK1 packets) and a simulator of the
//! MID-360 and the HAP (SDK2) and the Avia (SDK1) over a [`Scene`], with ground truth and IMU
//! packets.
//!
//! The scanning pattern is an approximation, not Livox's: the MID-360's non-repetitive
//! pattern is drawn from its published field of view (360° × −7°..+52°) and point rate
//! (200 000 points/s, 96 points a packet, so one packet per 480 µs); its 4 lines (record
//! `i % 4`) start 90° apart in azimuth and sweep the elevation range at incommensurate rates,
//! so the pattern does not repeat. The Avia's rosette covers its 70.4° circular field of view
//! at 240 000 points/s, six lines. The HAP (HAP (TX) user manual, table 1.2.1: field of view
//! 120° horizontal × 25° vertical, 452 000 points/s, 10 Hz frames) sends the same SDK2 point
//! and IMU packets as the MID-360 (Livox SDK2 protocol, HAP: the same 36-byte header and data
//! types); its six lines (livox_ros_driver2 `kLineNumberHAP`) sweep ±60° in azimuth, stacked
//! in elevation over ±12.5° and drifting through it, one record every 2220 ns (450 450
//! points/s: the published rate to the nearest step whose 95 steps are whole 0.1 µs of the
//! header's time interval). The manual places the HAP's point-cloud origin at (8, 0, 23) mm of
//! its mounting frame but publishes no IMU position: its IMU frame is taken as the lidar's.
//! Directions are on the 0.01° grid so spherical records carry
//! them exactly; distances and coordinates are rounded to the data type's unit. Record `i` of
//! an SDK2 packet is measured at `timestamp + i · time_interval / (N − 1)` (the protocol's
//! rule), of an SDK1 packet at `timestamp + i · 4167 ns`; its pose is the trajectory's at that
//! time. IMU packets (200 Hz) carry the gyro and specific force of the IMU frame (the
//! model's published position, axes as the lidar's), the latter in g.

use nalgebra::{Isometry3, Point3, Translation3, Vector3};

use super::model::{LivoxModel, Protocol};
use super::wire::{crc32, SDK1_HEADER_LEN, SDK2_HEADER_LEN};
use crate::sim::motion::{Trajectory, GRAVITY};
use crate::sim::scene::{Hit, Scene};

/// Header fields of an SDK2 packet that the encoder does not derive.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Sdk2Header {
    /// 0.1 µs.
    pub time_interval: u16,
    /// `udp_cnt`.
    pub udp_cnt: u16,
    /// `frame_cnt`.
    pub frame_cnt: u8,
    /// Data type.
    pub data_type: u8,
    /// Time type.
    pub time_type: u8,
    /// Timestamp, ns.
    pub timestamp_ns: u64,
}

/// One Cartesian or spherical return to encode, in the data type's units: Cartesian (mm for
/// types 1 and 0x11, cm for type 2), or spherical `[depth mm, theta 0.01°, phi 0.01°]`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RawPoint {
    /// Coordinates in the record's units.
    pub v: [i32; 3],
    /// Reflectivity.
    pub reflectivity: u8,
    /// Tag.
    pub tag: u8,
}

/// Writes an SDK2 packet: header (version 0, length, `dot_num` = records, CRC-32 of bytes
/// 28..) and the records of `data_type` (1, 2, 3; 0x11 takes two returns a record).
pub fn encode_sdk2(h: &Sdk2Header, returns: &[RawPoint]) -> Vec<u8> {
    let per = if h.data_type == 0x11 { 2 } else { 1 };
    let rec_len = match h.data_type {
        1 => 14,
        2 => 8,
        3 => 10,
        _ => 28,
    };
    let n = returns.len() / per;
    let mut b = vec![0u8; SDK2_HEADER_LEN + n * rec_len];
    for (i, rs) in returns.chunks_exact(per).enumerate() {
        let o = SDK2_HEADER_LEN + i * rec_len;
        let r = &mut b[o..o + rec_len];
        match h.data_type {
            2 => {
                for k in 0..3 {
                    r[2 * k..2 * k + 2].copy_from_slice(&(rs[0].v[k] as i16).to_le_bytes());
                }
                r[6] = rs[0].reflectivity;
                r[7] = rs[0].tag;
            }
            3 => {
                r[0..4].copy_from_slice(&(rs[0].v[0] as u32).to_le_bytes());
                r[4..6].copy_from_slice(&(rs[0].v[1] as u16).to_le_bytes());
                r[6..8].copy_from_slice(&(rs[0].v[2] as u16).to_le_bytes());
                r[8] = rs[0].reflectivity;
                r[9] = rs[0].tag;
            }
            _ => {
                for (j, p) in rs.iter().enumerate() {
                    let q = 14 * j;
                    for k in 0..3 {
                        r[q + 4 * k..q + 4 * k + 4].copy_from_slice(&p.v[k].to_le_bytes());
                    }
                    r[q + 12] = p.reflectivity;
                    r[q + 13] = p.tag;
                }
            }
        }
    }
    finish_sdk2(h, n as u16, b)
}

/// Writes an SDK2 IMU packet (data type 0): gyro rad/s, acceleration g.
pub fn encode_sdk2_imu(h: &Sdk2Header, gyro: [f32; 3], acc_g: [f32; 3]) -> Vec<u8> {
    let mut b = vec![0u8; SDK2_HEADER_LEN + 24];
    for (k, v) in gyro.iter().chain(acc_g.iter()).enumerate() {
        let o = SDK2_HEADER_LEN + 4 * k;
        b[o..o + 4].copy_from_slice(&v.to_le_bytes());
    }
    let mut h = *h;
    h.data_type = 0;
    finish_sdk2(&h, 1, b)
}

fn finish_sdk2(h: &Sdk2Header, dots: u16, mut b: Vec<u8>) -> Vec<u8> {
    let len = b.len() as u16;
    b[0] = 0;
    b[1..3].copy_from_slice(&len.to_le_bytes());
    b[3..5].copy_from_slice(&h.time_interval.to_le_bytes());
    b[5..7].copy_from_slice(&dots.to_le_bytes());
    b[7..9].copy_from_slice(&h.udp_cnt.to_le_bytes());
    b[9] = h.frame_cnt;
    b[10] = h.data_type;
    b[11] = h.time_type;
    b[28..36].copy_from_slice(&h.timestamp_ns.to_le_bytes());
    let crc = crc32(&b[28..]);
    b[24..28].copy_from_slice(&crc.to_le_bytes());
    b
}

/// Writes an SDK1 packet of data type 2 (extend Cartesian, 96 records, mm) or 6 (IMU).
pub fn encode_sdk1_cartesian(
    timestamp_type: u8,
    timestamp_ns: u64,
    points: &[RawPoint],
) -> Vec<u8> {
    let mut b = vec![0u8; SDK1_HEADER_LEN + 96 * 14];
    sdk1_header(&mut b, 2, timestamp_type, timestamp_ns);
    for (i, p) in points.iter().take(96).enumerate() {
        let o = SDK1_HEADER_LEN + 14 * i;
        for k in 0..3 {
            b[o + 4 * k..o + 4 * k + 4].copy_from_slice(&p.v[k].to_le_bytes());
        }
        b[o + 12] = p.reflectivity;
        b[o + 13] = p.tag;
    }
    b
}

/// Writes an SDK1 IMU packet (data type 6).
pub fn encode_sdk1_imu(
    timestamp_type: u8,
    timestamp_ns: u64,
    gyro: [f32; 3],
    acc_g: [f32; 3],
) -> Vec<u8> {
    let mut b = vec![0u8; SDK1_HEADER_LEN + 24];
    sdk1_header(&mut b, 6, timestamp_type, timestamp_ns);
    for (k, v) in gyro.iter().chain(acc_g.iter()).enumerate() {
        let o = SDK1_HEADER_LEN + 4 * k;
        b[o..o + 4].copy_from_slice(&v.to_le_bytes());
    }
    b
}

fn sdk1_header(b: &mut [u8], data_type: u8, timestamp_type: u8, timestamp_ns: u64) {
    b[0] = 5;
    b[1] = 1;
    b[2] = 1;
    b[8] = timestamp_type;
    b[9] = data_type;
    b[10..18].copy_from_slice(&timestamp_ns.to_le_bytes());
}

/// Ground truth of one simulated return.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LivoxTruth {
    /// Measurement time on the simulator's clock, ns.
    pub time_ns: i64,
    /// The point in the sensor frame at that time, metres (before rounding to the unit).
    pub xyz: [f64; 3],
    /// The point in the world, metres.
    pub world: [f64; 3],
    /// Laser line.
    pub line: u16,
    /// Reflectivity sent.
    pub reflectivity: u8,
    /// Scene label.
    pub label: u32,
    /// Record index in its packet.
    pub record: usize,
}

/// What one simulated IMU packet says, in SI units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuTruth {
    /// Time, ns.
    pub time_ns: i64,
    /// Angular velocity of the IMU frame, rad/s.
    pub gyro: [f64; 3],
    /// Specific force of the IMU frame, m/s².
    pub accel: [f64; 3],
}

/// A simulated MID-360 (SDK2) or Avia (SDK1).
#[derive(Clone, Debug)]
pub struct LivoxSim {
    /// Model: [`LivoxModel::Mid360`], [`LivoxModel::Hap`] or [`LivoxModel::Avia`].
    pub model: LivoxModel,
    /// SDK2 data type (1, 2 or 3); the Avia always sends type 2 of SDK1.
    pub data_type: u8,
    /// SDK2 time type / SDK1 timestamp type written (1: PTP, the simulator's clock).
    pub time_type: u8,
    /// First packet's first point, ns.
    pub stamp0_ns: i64,
    /// Point packets made.
    pub packet_index: u64,
    /// IMU packets made.
    pub imu_index: u64,
    /// IMU rate, Hz.
    pub imu_hz: u32,
    /// Delay from a packet's last point to its receipt, ns.
    pub latency_ns: i64,
    /// `world_from_sensor` over time.
    pub trajectory: Trajectory,
}

/// Records per packet.
pub const RECORDS: usize = 96;

impl LivoxSim {
    /// A sensor at rest, data type 1, PTP time.
    pub fn new(model: LivoxModel, stamp0_ns: i64) -> Self {
        Self {
            model,
            data_type: 1,
            time_type: 1,
            stamp0_ns,
            packet_index: 0,
            imu_index: 0,
            imu_hz: 200,
            latency_ns: 100_000,
            trajectory: Trajectory::identity(),
        }
    }

    /// Time between records, ns.
    pub fn step_ns(&self) -> i64 {
        match self.model {
            LivoxModel::Mid360 => 5_000,
            LivoxModel::Hap => 2_220,
            _ => 4_167,
        }
    }

    /// Time between point packets, ns.
    pub fn packet_period_ns(&self) -> i64 {
        self.step_ns() * RECORDS as i64
    }

    /// Direction of record `k` (global index) on `line` at time `t_s`: (azimuth, elevation),
    /// 0.01°, on the grid.
    fn direction(&self, k: u64, line: u16, t_s: f64) -> (i32, i32) {
        use std::f64::consts::TAU;
        let l = f64::from(line);
        match self.model {
            LivoxModel::Mid360 => {
                let az = (360.0 * (t_s * 9.7 + l / 4.0 + k as f64 * 0.000_37)).rem_euclid(360.0);
                let ph = t_s * 23.1 + l * 0.237 + (k as f64 * 0.618_034).fract() * 0.05;
                let el = -7.0 + 59.0 * (0.5 - 0.5 * (TAU * ph).cos());
                (
                    (az * 100.0).round() as i32 % 36_000,
                    (el * 100.0).round() as i32,
                )
            }
            LivoxModel::Hap => {
                // A triangle wave across ±60°, the six lines 4.17° apart in elevation and
                // drifting through ±12.5° at an incommensurate rate.
                let u = (t_s * 13.3 + l / 6.0 + k as f64 * 0.000_29).rem_euclid(1.0);
                let az = -60.0 + 120.0 * (1.0 - (2.0 * u - 1.0).abs());
                let ph = t_s * 7.9 + l / 6.0 + (k as f64 * 0.618_034).fract() * 0.02;
                let el = -12.5 + 25.0 * (0.5 - 0.5 * (TAU * ph).cos());
                ((az * 100.0).round() as i32, (el * 100.0).round() as i32)
            }
            _ => {
                let r = 35.2 * (TAU * (t_s * 31.3 + l / 12.0)).sin().abs();
                let th = TAU * (t_s * 107.0 + l / 6.0);
                (
                    (r * th.cos() * 100.0).round() as i32,
                    (r * th.sin() * 100.0).round() as i32,
                )
            }
        }
    }

    /// The next point packet: host receive time and bytes; its returns' truth is appended.
    pub fn next_packet(
        &mut self,
        scene: &dyn Scene,
        truth: &mut Vec<LivoxTruth>,
    ) -> (i64, Vec<u8>) {
        let step = self.step_ns();
        let ts = self.stamp0_ns + self.packet_index as i64 * self.packet_period_ns();
        let lines = self.model.lines();
        let sdk2 = self.model.protocol() == Protocol::Sdk2;
        let mut raw = vec![RawPoint::default(); RECORDS];
        for (i, slot) in raw.iter_mut().enumerate() {
            let t = ts + step * i as i64;
            let line = (i % usize::from(lines)) as u16;
            let k = self.packet_index * RECORDS as u64 + i as u64;
            let (az, el) = self.direction(k, line, (t - self.stamp0_ns) as f64 * 1e-9);
            let (sa, ca) = (f64::from(az) * 0.01).to_radians().sin_cos();
            let (se, ce) = (f64::from(el) * 0.01).to_radians().sin_cos();
            let dir = Vector3::new(ce * ca, ce * sa, se);
            let pose = self.trajectory.pose(t);
            let o = pose * Point3::origin();
            let d = pose.rotation * dir;
            let Some(Hit {
                range,
                reflectivity,
                label,
                ..
            }) = scene.cast(o.coords.into(), d.into())
            else {
                continue;
            };
            // Spherical records carry whole millimetres of depth: the truth is that depth.
            let range = if sdk2 && self.data_type == 3 {
                (range * 1000.0).round() / 1000.0
            } else {
                range
            };
            let xyz = dir * range;
            let w = pose * Point3::from(xyz);
            let v = match (sdk2, self.data_type) {
                (true, 2) => xyz.map(|c| (c * 100.0).round() as i32),
                (true, 3) => Vector3::new(
                    (range * 1000.0).round() as i32,
                    9_000 - el,
                    az.rem_euclid(36_000),
                ),
                _ => xyz.map(|c| (c * 1000.0).round() as i32),
            };
            if v == Vector3::zeros() {
                continue;
            }
            *slot = RawPoint {
                v: [v[0], v[1], v[2]],
                reflectivity,
                tag: 0,
            };
            truth.push(LivoxTruth {
                time_ns: t,
                xyz: xyz.into(),
                world: w.coords.into(),
                line,
                reflectivity,
                label,
                record: i,
            });
        }
        let bytes = if sdk2 {
            let h = Sdk2Header {
                time_interval: ((step * (RECORDS as i64 - 1)) / 100) as u16,
                udp_cnt: self.packet_index as u16,
                frame_cnt: 0,
                data_type: self.data_type,
                time_type: self.time_type,
                timestamp_ns: ts.max(0) as u64,
            };
            encode_sdk2(&h, &raw)
        } else {
            encode_sdk1_cartesian(self.time_type, ts.max(0) as u64, &raw)
        };
        self.packet_index += 1;
        let host = ts + step * (RECORDS as i64 - 1) + self.latency_ns;
        (host, bytes)
    }

    /// The IMU frame in the sensor frame.
    pub fn sensor_from_imu(&self) -> Isometry3<f64> {
        let t = self.model.imu_position_mm().unwrap_or([0.0; 3]);
        Isometry3::from_parts(
            Translation3::new(t[0] / 1000.0, t[1] / 1000.0, t[2] / 1000.0),
            nalgebra::UnitQuaternion::identity(),
        )
    }

    /// Time of IMU packet `n`, ns.
    pub fn imu_time_ns(&self, n: u64) -> i64 {
        self.stamp0_ns + (n as i64) * (1_000_000_000 / i64::from(self.imu_hz.max(1)))
    }

    /// The next IMU packet: host time, bytes, and what it says in SI units (from the f32 values
    /// written).
    pub fn next_imu(&mut self) -> (i64, Vec<u8>, ImuTruth) {
        let t = self.imu_time_ns(self.imu_index);
        let k = self.trajectory.kinematics_of(t, &self.sensor_from_imu());
        let g = k.angular_velocity_body();
        let f = k.specific_force_body() / GRAVITY;
        let gyro = [g.x as f32, g.y as f32, g.z as f32];
        let acc = [f.x as f32, f.y as f32, f.z as f32];
        let bytes = if self.model.protocol() == Protocol::Sdk2 {
            let h = Sdk2Header {
                udp_cnt: self.imu_index as u16,
                time_type: self.time_type,
                timestamp_ns: t.max(0) as u64,
                ..Sdk2Header::default()
            };
            encode_sdk2_imu(&h, gyro, acc)
        } else {
            encode_sdk1_imu(self.time_type, t.max(0) as u64, gyro, acc)
        };
        self.imu_index += 1;
        let truth = ImuTruth {
            time_ns: t,
            gyro: [g.x, g.y, g.z],
            accel: [f.x * GRAVITY, f.y * GRAVITY, f.z * GRAVITY],
        };
        (t + self.latency_ns, bytes, truth)
    }

    /// Point and IMU packets in receive order from now until `until_ns` (host time).
    pub fn run_until(
        &mut self,
        scene: &dyn Scene,
        until_ns: i64,
        truth: &mut Vec<LivoxTruth>,
        imu: &mut Vec<ImuTruth>,
    ) -> Vec<(i64, u16, Vec<u8>)> {
        let (pport, iport) = (self.model.point_port(), self.model.imu_port().unwrap_or(0));
        let mut out = Vec::new();
        loop {
            let next_pt = self.stamp0_ns
                + self.packet_index as i64 * self.packet_period_ns()
                + self.step_ns() * (RECORDS as i64 - 1)
                + self.latency_ns;
            let next_imu = if self.model.has_imu() {
                self.imu_time_ns(self.imu_index) + self.latency_ns
            } else {
                i64::MAX
            };
            if next_pt.min(next_imu) > until_ns {
                break;
            }
            if next_imu <= next_pt {
                let (h, b, t) = self.next_imu();
                imu.push(t);
                out.push((h, iport, b));
            } else {
                let (h, b) = self.next_packet(scene, truth);
                out.push((h, pport, b));
            }
        }
        out
    }
}
