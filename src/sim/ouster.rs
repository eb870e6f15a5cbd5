//! Ouster packet encoder: per-pixel values → byte-exact lidar packets for every profile and
//! header layout, plus LEGACY and ACCEL32_GYRO32_NMEA IMU packets.
//!
//! Written from the layouts of FORMATS.md §5.2 (the same tables the decoder reads,
//! [`Profile::layout`]): header fields at their offsets for the standard and FUSA headers,
//! LEGACY column headers with frame id and encoder count and the trailing status word, the
//! footer CRC-64/XZ for standard headers. Values are given in the decoder's units: ranges in mm
//! (RNG15 profiles store `range_mm >> 3`, so only multiples of 8 survive), near-IR in the
//! SDK's units (NIR8 stores `near_ir >> 4`); each value is masked to its field width.

use crate::calib::ouster::OusterInfo;
use crate::model::ouster::{Field, HeaderKind, PacketFormat, Profile};
use crate::wire::ouster::{crc64_xz, write_field, HEADER_BYTES, PACKET_TYPE_IMU};

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
    measurements: &[crate::wire::ouster::ImuMeasurement],
) -> Vec<u8> {
    use crate::wire::ouster::{
        imu_nmea_packet_bytes, IMU_MEASUREMENT_BYTES, IMU_NMEA_BLOCK_BYTES, NMEA_SENTENCE_BYTES,
    };
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
    use crate::wire::ouster::{ImuMeasurement, ImuPacketLegacy, ImuPacketNmea};

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
