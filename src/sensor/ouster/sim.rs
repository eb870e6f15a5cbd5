//! Ouster packet encoder: per-pixel values → byte-exact lidar packets for every profile and
//! header layout, plus LEGACY and ACCEL32_GYRO32_NMEA IMU packets.
//!
//! Written from the layouts of FORMATS.md §5.2 (the same tables the decoder reads,
//! [`Profile::layout`]): header fields at their offsets for the standard and FUSA headers,
//! LEGACY column headers with frame id and encoder count and the trailing status word, the
//! footer CRC-64/XZ for standard headers. Values are given in the decoder's units: ranges in mm
//! (RNG15 profiles store `range_mm >> 3`, so only multiples of 8 survive), near-IR in the
//! SDK's units (NIR8 stores `near_ir >> 4`); each value is masked to its field width.

use crate::sensor::ouster::calib::OusterInfo;
use crate::sensor::ouster::model::Field;
use crate::sensor::ouster::model::HeaderKind;
use crate::sensor::ouster::model::PacketFormat;
use crate::sensor::ouster::model::Profile;
use crate::sensor::ouster::wire::crc64_xz;
use crate::sensor::ouster::wire::write_field;
use crate::sensor::ouster::wire::HEADER_BYTES;
use crate::sensor::ouster::wire::PACKET_TYPE_IMU;

/// Encoder counts per revolution of LEGACY packets.
pub const ENCODER_TICKS_PER_REV: u32 = 90_112;

/// The values of one pixel, in the decoder's units.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SimPixel {
    /// First-return range, mm (0 = no return).
    pub range_mm: u32,
    /// First-return reflectivity.
    pub reflectivity: u8,
    /// First-return signal.
    pub signal: u16,
    /// Near-IR.
    pub near_ir: u16,
    /// First-return flags.
    pub flags: u8,
    /// Second-return range, mm (dual profiles).
    pub range2_mm: u32,
    /// Second-return reflectivity.
    pub reflectivity2: u8,
    /// Second-return signal.
    pub signal2: u16,
    /// Second-return flags.
    pub flags2: u8,
}

/// One column: header values and H pixels (row 0 = top beam).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SimColumn {
    /// Column timestamp, ns.
    pub timestamp_ns: u64,
    /// Measurement id (column index in the frame).
    pub measurement_id: u16,
    /// Raw status: LEGACY writes it as the u32 trailer (a sensor sends 0xFFFFFFFF for a valid
    /// column), profile-based packets write the low 16 bits. Bit 0 = valid.
    pub status: u32,
    /// H pixels.
    pub pixels: Vec<SimPixel>,
}

/// Packet header values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SimHeader {
    /// `packet_type` (1 = lidar).
    pub packet_type: u16,
    /// Frame id (standard headers and LEGACY columns keep the low 16 bits).
    pub frame_id: u32,
    /// `init_id` (24 bits).
    pub init_id: u32,
    /// Serial (40 bits).
    pub serial: u64,
    /// `alert_flags`.
    pub alert_flags: u8,
    /// `countdown_thermal_shutdown`.
    pub countdown_thermal_shutdown: u8,
    /// `countdown_shot_limiting`.
    pub countdown_shot_limiting: u8,
    /// Thermal shutdown status (4 bits).
    pub thermal_shutdown: u8,
    /// Shot limiting status (4 bits).
    pub shot_limiting: u8,
}

impl Default for SimHeader {
    fn default() -> Self {
        Self {
            packet_type: 1,
            frame_id: 0,
            init_id: 0,
            serial: 0,
            alert_flags: 0,
            countdown_thermal_shutdown: 0,
            countdown_shot_limiting: 0,
            thermal_shutdown: 0,
            shot_limiting: 0,
        }
    }
}

/// Input that does not fit the packet format.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum EncodeError {
    /// A count differs from the format's.
    #[error("{what}: expected {expected}, found {found}")]
    Shape {
        /// What was counted.
        what: &'static str,
        /// The format's count.
        expected: usize,
        /// The count given.
        found: usize,
    },
}

/// Writes Ouster lidar packets of one format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OusterEncoder {
    format: PacketFormat,
    header: HeaderKind,
    crc: bool,
    columns_per_frame: usize,
}

impl OusterEncoder {
    /// The encoder of a calibration's format and header; writes a footer CRC when the
    /// calibration's firmware has one ([`OusterInfo::lidar_packets_have_crc`]).
    pub fn new(info: &OusterInfo) -> Self {
        Self {
            format: info.format,
            header: info.format.profile.header(),
            crc: info.lidar_packets_have_crc(),
            columns_per_frame: info.columns_per_frame.max(1),
        }
    }

    /// An encoder of `format` (the profile's header; CRC for standard headers) for frames of
    /// `columns_per_frame` columns (used for LEGACY encoder counts).
    pub fn from_format(format: PacketFormat, columns_per_frame: usize) -> Self {
        let header = format.profile.header();
        Self {
            format,
            header,
            crc: header == HeaderKind::Standard,
            columns_per_frame: columns_per_frame.max(1),
        }
    }

    /// Another header layout (ignored for LEGACY).
    pub fn with_header(mut self, header: HeaderKind) -> Self {
        self.header = if self.format.profile == Profile::Legacy {
            HeaderKind::Legacy
        } else if header == HeaderKind::Legacy {
            HeaderKind::Standard
        } else {
            header
        };
        self
    }

    /// Whether to write the footer CRC (standard headers of non-FUSA profiles only).
    pub fn with_crc(mut self, crc: bool) -> Self {
        self.crc = crc;
        self
    }

    /// The packet format.
    pub fn format(&self) -> &PacketFormat {
        &self.format
    }

    /// The header layout.
    pub fn header_kind(&self) -> HeaderKind {
        self.header
    }

    /// Bytes of one packet.
    pub fn packet_bytes(&self) -> usize {
        self.format.packet_bytes()
    }

    /// Writes one lidar packet into `out` (cleared first): `columns` must hold exactly
    /// `columns_per_packet` columns of `pixels_per_column` pixels.
    pub fn encode(
        &self,
        header: &SimHeader,
        columns: &[SimColumn],
        out: &mut Vec<u8>,
    ) -> Result<(), EncodeError> {
        let f = &self.format;
        if columns.len() != f.columns_per_packet {
            return Err(EncodeError::Shape {
                what: "columns per packet",
                expected: f.columns_per_packet,
                found: columns.len(),
            });
        }
        for c in columns {
            if c.pixels.len() != f.pixels_per_column {
                return Err(EncodeError::Shape {
                    what: "pixels per column",
                    expected: f.pixels_per_column,
                    found: c.pixels.len(),
                });
            }
        }
        out.clear();
        out.resize(f.packet_bytes(), 0);
        self.write_header(header, out);
        let layout = f.profile.layout();
        let (hb, cb, chb, pb) = (
            f.header_bytes(),
            f.column_bytes(),
            f.column_header_bytes(),
            layout.pixel_bytes,
        );
        let legacy = self.header == HeaderKind::Legacy;
        for (i, c) in columns.iter().enumerate() {
            let col = &mut out[hb + i * cb..hb + (i + 1) * cb];
            col[0..8].copy_from_slice(&c.timestamp_ns.to_le_bytes());
            col[8..10].copy_from_slice(&c.measurement_id.to_le_bytes());
            if legacy {
                col[10..12].copy_from_slice(&(header.frame_id as u16).to_le_bytes());
                let enc = (u64::from(c.measurement_id) * u64::from(ENCODER_TICKS_PER_REV)
                    / self.columns_per_frame as u64) as u32;
                col[12..16].copy_from_slice(&enc.to_le_bytes());
                col[cb - 4..].copy_from_slice(&c.status.to_le_bytes());
            } else {
                col[10..12].copy_from_slice(&(c.status as u16).to_le_bytes());
            }
            for (row, px) in c.pixels.iter().enumerate() {
                let b = &mut col[chb + row * pb..chb + (row + 1) * pb];
                let mut put = |f: Option<Field>, v: u32| {
                    if let Some(f) = f {
                        write_field(b, f, v);
                    }
                };
                put(Some(layout.range), px.range_mm);
                put(layout.flags, u32::from(px.flags));
                put(Some(layout.reflectivity), u32::from(px.reflectivity));
                put(layout.signal, u32::from(px.signal));
                put(layout.near_ir, u32::from(px.near_ir));
                put(layout.range2, px.range2_mm);
                put(layout.flags2, u32::from(px.flags2));
                put(layout.reflectivity2, u32::from(px.reflectivity2));
                put(layout.signal2, u32::from(px.signal2));
            }
        }
        // No CRC field with a FUSA header or the FUSA profile (ouster-sdk `PacketFormat::crc`).
        if self.crc
            && self.header == HeaderKind::Standard
            && f.profile != Profile::FusaRng15Rfl8Nir8Dual
        {
            let n = out.len();
            let crc = crc64_xz(&out[..n - 8]);
            out[n - 8..].copy_from_slice(&crc.to_le_bytes());
        }
        Ok(())
    }

    fn write_header(&self, h: &SimHeader, out: &mut [u8]) {
        let init = h.init_id.to_le_bytes();
        let sn = h.serial.to_le_bytes();
        match self.header {
            HeaderKind::Legacy => return,
            HeaderKind::Standard => {
                out[0..2].copy_from_slice(&h.packet_type.to_le_bytes());
                out[2..4].copy_from_slice(&(h.frame_id as u16).to_le_bytes());
                out[4..7].copy_from_slice(&init[..3]);
                out[7..12].copy_from_slice(&sn[..5]);
                out[12] = h.alert_flags;
            }
            HeaderKind::Fusa => {
                out[0] = h.packet_type as u8;
                out[1..4].copy_from_slice(&init[..3]);
                out[4..8].copy_from_slice(&h.frame_id.to_le_bytes());
                out[8] = h.alert_flags;
                out[11..16].copy_from_slice(&sn[..5]);
            }
        }
        out[16] = h.countdown_thermal_shutdown;
        out[17] = h.countdown_shot_limiting;
        out[18] = h.thermal_shutdown & 0x0F;
        out[19] = h.shot_limiting & 0x0F;
    }
}

/// A 48-byte LEGACY IMU packet: timestamps in ns, acceleration in g, angular velocity in
/// deg/s.
pub fn encode_imu_legacy(
    sys_ts_ns: u64,
    accel_ts_ns: u64,
    gyro_ts_ns: u64,
    accel_g: [f32; 3],
    gyro_dps: [f32; 3],
) -> [u8; 48] {
    let mut b = [0u8; 48];
    b[0..8].copy_from_slice(&sys_ts_ns.to_le_bytes());
    b[8..16].copy_from_slice(&accel_ts_ns.to_le_bytes());
    b[16..24].copy_from_slice(&gyro_ts_ns.to_le_bytes());
    for (i, v) in accel_g.iter().chain(&gyro_dps).enumerate() {
        b[24 + 4 * i..28 + 4 * i].copy_from_slice(&v.to_le_bytes());
    }
    b
}

/// An ACCEL32_GYRO32_NMEA IMU packet (standard header, packet_type 2; footer CRC-64/XZ):
/// `sentence` is cut to 85 bytes; measurements are written in order.
pub fn encode_imu_nmea(
    header: &SimHeader,
    nmea_ts_ns: u64,
    sentence: &[u8],
    measurements: &[crate::sensor::ouster::wire::ImuMeasurement],
) -> Vec<u8> {
    use crate::sensor::ouster::wire::imu_nmea_packet_bytes;
    use crate::sensor::ouster::wire::IMU_MEASUREMENT_BYTES;
    use crate::sensor::ouster::wire::IMU_NMEA_BLOCK_BYTES;
    use crate::sensor::ouster::wire::NMEA_SENTENCE_BYTES;
    let mut out = vec![0u8; imu_nmea_packet_bytes(measurements.len())];
    let h = SimHeader {
        packet_type: PACKET_TYPE_IMU,
        ..*header
    };
    let enc = OusterEncoder {
        format: PacketFormat {
            profile: Profile::Rng19Rfl8Sig16Nir16,
            columns_per_packet: 1,
            pixels_per_column: 1,
        },
        header: HeaderKind::Standard,
        crc: true,
        columns_per_frame: 1,
    };
    enc.write_header(&h, &mut out);
    out[HEADER_BYTES..HEADER_BYTES + 8].copy_from_slice(&nmea_ts_ns.to_le_bytes());
    let n = sentence.len().min(NMEA_SENTENCE_BYTES);
    out[HEADER_BYTES + 8..HEADER_BYTES + 8 + n].copy_from_slice(&sentence[..n]);
    for (i, m) in measurements.iter().enumerate() {
        let o = HEADER_BYTES + IMU_NMEA_BLOCK_BYTES + i * IMU_MEASUREMENT_BYTES;
        out[o..o + 8].copy_from_slice(&m.timestamp_ns.to_le_bytes());
        out[o + 8..o + 10].copy_from_slice(&m.measurement_id.to_le_bytes());
        out[o + 10..o + 12].copy_from_slice(&m.status.to_le_bytes());
        for (k, v) in m.accel.iter().chain(&m.gyro).enumerate() {
            out[o + 12 + 4 * k..o + 16 + 4 * k].copy_from_slice(&v.to_le_bytes());
        }
    }
    let len = out.len();
    let crc = crc64_xz(&out[..len - 8]);
    out[len - 8..].copy_from_slice(&crc.to_le_bytes());
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::ouster::wire::ImuMeasurement;
    use crate::sensor::ouster::wire::ImuPacketLegacy;
    use crate::sensor::ouster::wire::ImuPacketNmea;

    #[test]
    fn imu_packets_round_trip() {
        let b = encode_imu_legacy(1, 2, 3, [0.5, -0.25, 1.0], [10.0, -20.0, 30.5]);
        let p = ImuPacketLegacy::new(&b).unwrap();
        assert_eq!((p.sys_ts_ns(), p.accel_ts_ns(), p.gyro_ts_ns()), (1, 2, 3));
        assert_eq!(p.accel_g(), [0.5, -0.25, 1.0]);
        assert_eq!(p.gyro_dps(), [10.0, -20.0, 30.5]);

        let ms: Vec<ImuMeasurement> = (0..8u16)
            .map(|i| ImuMeasurement {
                timestamp_ns: 1000 + u64::from(i),
                measurement_id: i,
                status: 1,
                accel: [f32::from(i), 0.0, 9.8],
                gyro: [0.0, f32::from(i) * 0.1, 0.0],
            })
            .collect();
        let h = SimHeader {
            frame_id: 7,
            init_id: 0xABCDEF,
            serial: 122_247_000_785,
            ..SimHeader::default()
        };
        let b = encode_imu_nmea(&h, 99, b"$GPRMC,test*00", &ms);
        assert_eq!(b.len(), 452);
        let p = ImuPacketNmea::new(&b, 8).unwrap();
        assert_eq!(p.packet_type(), 2);
        assert_eq!(p.frame_id(), 7);
        assert_eq!(p.init_id(), 0xABCDEF);
        assert_eq!(p.serial(), 122_247_000_785);
        assert_eq!(p.nmea_ts_ns(), 99);
        assert_eq!(p.nmea(), b"$GPRMC,test*00");
        assert_eq!(p.measurements().collect::<Vec<_>>(), ms);
        assert_eq!(p.crc(), p.computed_crc());
    }
}

/// Ground truth of one simulated Ouster return.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OusterTruth {
    /// Frame id.
    pub frame_id: u32,
    /// Column (measurement id).
    pub column: u16,
    /// Pixel row (0 = top beam).
    pub row: u16,
    /// 0 = first return (RANGE), 1 = second (RANGE2, dual profiles).
    pub ret: u8,
    /// Range written, mm (a multiple of the profile's unit: 8 mm for RNG15).
    pub range_mm: u32,
    /// The scene point hit, Ouster sensor frame at the column's time, metres: what the
    /// decoder must reproduce (up to the range quantisation).
    pub xyz: [f64; 3],
    /// The same point in the world frame, metres.
    pub world: [f64; 3],
    /// [`GROUND`](crate::sim::scene::GROUND) (0) or the id of the object hit.
    pub label: u32,
    /// Absolute measurement time of the column on the simulator's clock, ns; the pose is
    /// `trajectory.pose(time_ns)`.
    pub time_ns: i64,
    /// Reflectivity written.
    pub reflectivity: u8,
}

/// A simulated spinning Ouster: each column is cast from the pose at its measurement time
/// through the beam intrinsics of a real metadata file, in any profile and lidar mode.
///
/// Geometry: ouster-sdk's XYZ model (FORMATS.md §5.2, the one `decode::ouster` follows),
/// written here in f64: for column `v` of `W` and beam `u`,
/// `θe = 2π − 2π·v/W`, `θa = −beam_azimuth[u]`, `φ = beam_altitude[u]`,
/// `dir = (cos(θe+θa)·cosφ, sin(θe+θa)·cosφ, sinφ)`,
/// `off = (cosθe·n − dir.x·n_e, sinθe·n − dir.y·n_e, −dir.z·n_e + b_z)` with
/// `n = beam_to_lidar[0][3]`, `b_z = beam_to_lidar[2][3]`, `n_e = hypot(n, b_z)` (or `n` when
/// `b_z` = 0); both through `lidar_to_sensor` (mm). The ray starts at `off` (metres) along the
/// unit `dir`; the range written is the hit distance in mm, so `range·dir + off` is the hit.
///
/// Timing: column `v` of frame `f` is measured at `t0_ns + (f·W + v)·T/W` (T = 1 / fps) and
/// stamped with that time (+ 37 s, TAI, when the metadata's timestamp mode is PTP, so that
/// ringscan's UTC sweep times are on the simulator's clock); a packet is received one column
/// period after its last column. Columns outside the metadata's column window are sent with
/// status 0 (no truth). Dual profiles: every 5th pixel also sees a surface 1.5 m behind the
/// first, at a third of its reflectivity (the second return).
#[derive(Clone, Debug)]
pub struct OusterSim {
    /// The metadata the packets follow (the decoder must be given the same).
    pub info: OusterInfo,
    /// The packet encoder.
    pub encoder: OusterEncoder,
    /// `world_from_sensor` over time (default: the identity).
    pub trajectory: crate::sim::motion::Trajectory,
    /// Time of frame 0, column 0, ns on the simulator's clock.
    pub t0_ns: i64,
    /// Packets generated so far.
    pub packet_index: u64,
    /// IMU sample period, ns (default 10 ms).
    pub imu_period_ns: i64,
    /// IMU samples generated so far.
    pub imu_index: u64,
    /// Per (column, row): unit direction and origin of the beam, sensor frame, metres.
    rays: Vec<([f64; 3], [f64; 3])>,
    /// Range units of the profile: (mm per unit, largest mm).
    range_unit: (u32, u32),
}

impl OusterSim {
    /// A simulator of the sensor `info` describes, static at the world origin, starting at
    /// `t0_ns`.
    pub fn new(info: OusterInfo, t0_ns: i64) -> Self {
        let rays = beam_rays(&info);
        let f = info.format.profile.layout().range;
        let unit = 1u32 << f.shift.min(16);
        let max = ((1u64 << f.width.min(32)) - 1).saturating_mul(u64::from(unit));
        Self {
            encoder: OusterEncoder::new(&info),
            trajectory: crate::sim::motion::Trajectory::identity(),
            t0_ns,
            packet_index: 0,
            imu_period_ns: 10_000_000,
            imu_index: 0,
            rays,
            range_unit: (unit, max.min(u64::from(u32::MAX)) as u32),
            info,
        }
    }

    /// Columns per frame.
    pub fn columns_per_frame(&self) -> usize {
        self.info.columns_per_frame.max(1)
    }

    /// Time between two columns, ns.
    pub fn column_period_ns(&self) -> f64 {
        1e9 / f64::from(self.info.fps.max(1)) / self.columns_per_frame() as f64
    }

    /// Time between two lidar packets, ns.
    pub fn packet_period_ns(&self) -> f64 {
        self.column_period_ns() * self.info.format.columns_per_packet as f64
    }

    /// The unit ray (direction, origin; sensor frame, metres) of pixel (row, column).
    pub fn ray(&self, row: usize, column: usize) -> Option<([f64; 3], [f64; 3])> {
        let h = self.info.format.pixels_per_column;
        (row < h).then(|| self.rays.get(column * h + row).copied())?
    }

    /// Generates the next lidar packet: (host receive time ns, payload), appending its truth.
    pub fn next_packet(
        &mut self,
        scene: &dyn crate::sim::scene::Scene,
        truth: &mut Vec<OusterTruth>,
    ) -> (i64, Vec<u8>) {
        let w = self.columns_per_frame() as u64;
        let cpp = self.info.format.columns_per_packet.max(1) as u64;
        let h = self.info.format.pixels_per_column;
        let packets_per_frame = w.div_ceil(cpp);
        let frame = self.packet_index / packets_per_frame;
        let first_col = (self.packet_index % packets_per_frame) * cpp;
        let dual = self.info.format.profile.is_dual();
        let ptp = self.info.timestamp_mode == crate::sensor::ouster::calib::TimestampMode::Ptp1588;
        let col_period = self.column_period_ns();
        let mut columns = Vec::with_capacity(cpp as usize);
        let mut last_t = self.t0_ns;
        for k in 0..cpp {
            let col = first_col + k;
            let index = frame * w + col;
            let t = self.t0_ns + (index as f64 * col_period).round() as i64;
            last_t = t;
            let stamp = (t + if ptp { 37_000_000_000 } else { 0 }).max(0) as u64;
            let mut c = SimColumn {
                timestamp_ns: stamp,
                measurement_id: col.min(u64::from(u16::MAX)) as u16,
                status: 0,
                pixels: vec![SimPixel::default(); h],
            };
            if col >= w || !self.info.is_column_in_window(col as usize) {
                columns.push(c);
                continue;
            }
            c.status = if self.encoder.header_kind() == HeaderKind::Legacy {
                0xFFFF_FFFF
            } else {
                1
            };
            let posed = crate::sensor::velodyne::sim::Posed::new(scene, self.trajectory.pose(t));
            for (row, px) in c.pixels.iter_mut().enumerate() {
                let (dir, origin) = self.rays[col as usize * h + row];
                let Some(hit) = crate::sim::scene::Scene::cast(&posed, origin, dir) else {
                    continue;
                };
                let Some(mm) = self.quantise(hit.range * 1000.0) else {
                    continue;
                };
                px.range_mm = mm;
                px.reflectivity = hit.reflectivity;
                px.signal = 100 + u16::from(hit.reflectivity) * 4;
                px.near_ir = 320;
                let mut record = |ret: u8, mm: u32, refl: u8| {
                    let s = hit.range + if ret == 1 { 1.5 } else { 0.0 };
                    let xyz = [
                        origin[0] + s * dir[0],
                        origin[1] + s * dir[1],
                        origin[2] + s * dir[2],
                    ];
                    truth.push(OusterTruth {
                        frame_id: frame as u32,
                        column: col as u16,
                        row: row as u16,
                        ret,
                        range_mm: mm,
                        xyz,
                        world: posed.to_world(xyz),
                        label: hit.label,
                        time_ns: t,
                        reflectivity: refl,
                    });
                };
                record(0, mm, hit.reflectivity);
                if dual && (row + col as usize) % 5 == 0 {
                    if let Some(mm2) = self.quantise((hit.range + 1.5) * 1000.0) {
                        px.range2_mm = mm2;
                        px.reflectivity2 = hit.reflectivity / 3;
                        px.signal2 = 50;
                        record(1, mm2, hit.reflectivity / 3);
                    }
                }
            }
            columns.push(c);
        }
        let header = SimHeader {
            frame_id: frame as u32,
            init_id: self.info.init_id,
            serial: self.info.serial,
            ..SimHeader::default()
        };
        let mut out = Vec::new();
        // The shapes match the format by construction.
        if self.encoder.encode(&header, &columns, &mut out).is_err() {
            out.clear();
        }
        self.packet_index += 1;
        (last_t + col_period.round() as i64, out)
    }

    /// Range in mm to the profile's unit (8 mm for RNG15), `None` beyond the field or at 0.
    fn quantise(&self, mm: f64) -> Option<u32> {
        let (unit, max) = self.range_unit;
        let q = (mm / f64::from(unit)).round() * f64::from(unit);
        (q >= f64::from(unit) && q <= f64::from(max)).then_some(q as u32)
    }

    /// `sensor_from_imu` of the metadata, metres.
    pub fn sensor_from_imu(&self) -> nalgebra::Isometry3<f64> {
        isometry_mm(&self.info.imu_to_sensor)
    }

    /// Time of the next IMU sample (the first at `t0_ns`).
    pub fn next_imu_time_ns(&self) -> i64 {
        self.t0_ns + self.imu_index as i64 * self.imu_period_ns
    }

    /// The next IMU packet in the metadata's IMU profile: (host receive time ns, payload), or
    /// `None` when the metadata has no IMU profile. LEGACY: one sample per packet (g, deg/s);
    /// ACCEL32_GYRO32_NMEA: `imu_measurements_per_packet` samples (m/s², rad/s). Readings are
    /// the trajectory's specific force and angular rate at the IMU (lever arm included), in the
    /// IMU frame of `imu_to_sensor_transform`; timestamps as the lidar's.
    pub fn next_imu_packet(&mut self) -> Option<(i64, Vec<u8>)> {
        use crate::sensor::ouster::calib::ImuProfile;
        let ptp = self.info.timestamp_mode == crate::sensor::ouster::calib::TimestampMode::Ptp1588;
        let off = if ptp { 37_000_000_000 } else { 0 };
        let s_from_i = self.sensor_from_imu();
        let sample = |sim: &mut Self| {
            let t = sim.next_imu_time_ns();
            sim.imu_index += 1;
            let k = sim.trajectory.kinematics_of(t, &s_from_i);
            (t, k.specific_force_body(), k.angular_velocity_body())
        };
        match self.info.imu_profile {
            ImuProfile::Legacy => {
                let (t, f, w) = sample(self);
                let ts = (t + off).max(0) as u64;
                let g = crate::sim::motion::GRAVITY;
                let b = encode_imu_legacy(
                    ts,
                    ts,
                    ts,
                    [(f.x / g) as f32, (f.y / g) as f32, (f.z / g) as f32],
                    [
                        w.x.to_degrees() as f32,
                        w.y.to_degrees() as f32,
                        w.z.to_degrees() as f32,
                    ],
                );
                Some((t + 200_000, b.to_vec()))
            }
            ImuProfile::Accel32Gyro32Nmea => {
                let n = self.info.imu_measurements_per_packet.max(1);
                let mut ms = Vec::with_capacity(n);
                let mut last = 0;
                for i in 0..n {
                    let (t, f, w) = sample(self);
                    last = t;
                    ms.push(crate::sensor::ouster::wire::ImuMeasurement {
                        timestamp_ns: (t + off).max(0) as u64,
                        measurement_id: i as u16,
                        status: 1,
                        accel: [f.x as f32, f.y as f32, f.z as f32],
                        gyro: [w.x as f32, w.y as f32, w.z as f32],
                    });
                }
                let h = SimHeader {
                    init_id: self.info.init_id,
                    serial: self.info.serial,
                    ..SimHeader::default()
                };
                Some((last + 200_000, encode_imu_nmea(&h, 0, b"", &ms)))
            }
            ImuProfile::Off => None,
        }
    }
}

/// A row-major 4×4 transform with mm translation as an isometry in metres (the rotation
/// re-orthonormalised).
fn isometry_mm(m: &[f64; 16]) -> nalgebra::Isometry3<f64> {
    let r = nalgebra::Matrix3::new(m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]);
    let rot = nalgebra::UnitQuaternion::from_matrix(&r);
    nalgebra::Isometry3::from_parts(
        nalgebra::Translation3::new(m[3] * 1e-3, m[7] * 1e-3, m[11] * 1e-3),
        rot,
    )
}

/// Unit direction and origin (metres) of every pixel, column-major (`column·H + row`).
fn beam_rays(info: &OusterInfo) -> Vec<([f64; 3], [f64; 3])> {
    use std::f64::consts::PI;
    let w = info.columns_per_frame.max(1);
    let h = info.format.pixels_per_column;
    let b = &info.beam_to_lidar;
    let l = &info.lidar_to_sensor;
    let (n, bz) = (b[3], b[11]);
    let n_e = if bz != 0.0 { n.hypot(bz) } else { n };
    let rot = |v: [f64; 3]| {
        [
            l[0] * v[0] + l[1] * v[1] + l[2] * v[2],
            l[4] * v[0] + l[5] * v[1] + l[6] * v[2],
            l[8] * v[0] + l[9] * v[1] + l[10] * v[2],
        ]
    };
    let mut out = Vec::with_capacity(w * h);
    for v in 0..w {
        let enc = 2.0 * PI * (1.0 - v as f64 / w as f64);
        for u in 0..h {
            let az = -info
                .beam_azimuth_angles
                .get(u)
                .copied()
                .unwrap_or(0.0)
                .to_radians();
            let phi = info
                .beam_altitude_angles
                .get(u)
                .copied()
                .unwrap_or(0.0)
                .to_radians();
            let d = [
                (enc + az).cos() * phi.cos(),
                (enc + az).sin() * phi.cos(),
                phi.sin(),
            ];
            let o = [
                enc.cos() * n - d[0] * n_e,
                enc.sin() * n - d[1] * n_e,
                -d[2] * n_e + bz,
            ];
            let (d, o) = (rot(d), rot(o));
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let dir = if len > 0.0 {
                [d[0] / len, d[1] / len, d[2] / len]
            } else {
                [1.0, 0.0, 0.0]
            };
            let origin = [
                (o[0] + l[3]) * 1e-3,
                (o[1] + l[7]) * 1e-3,
                (o[2] + l[11]) * 1e-3,
            ];
            out.push((dir, origin));
        }
    }
    out
}
