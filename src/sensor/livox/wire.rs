//! Typed, checked views over one Livox datagram: the SDK2 point / IMU packet (MID-360, HAP)
//! and the SDK1 one (Mid-40, Mid-70, Horizon, Tele-15, Avia). Little-endian throughout.
//!
//! SDK2 header, 36 bytes (Livox "Communication Protocol — Mid360" §2.1, and
//! `LivoxLidarEthernetPacket` of Livox-SDK2 `include/livox_lidar_def.h`, packed):
//!
//! | offset | size | field |
//! |--------|------|-------|
//! | 0  | 1  | version (0) |
//! | 1  | 2  | length of the whole UDP payload |
//! | 3  | 2  | time_interval, 0.1 µs: last point's time minus the first's |
//! | 5  | 2  | dot_num: points in the packet |
//! | 7  | 2  | udp_cnt: +1 per packet, 0 at a frame's start |
//! | 9  | 1  | frame_cnt (meaningless in non-repetitive scanning) |
//! | 10 | 1  | data_type: 0 IMU, 1 Cartesian i32 mm, 2 Cartesian i16 cm, 3 spherical, 0x11 dual Cartesian |
//! | 11 | 1  | time_type: 0 none (since power-on), 1 PTP / gPTP, 2 GPS |
//! | 12 | 12 | reserved |
//! | 24 | 4  | CRC-32 of bytes 28.. (timestamp and data) |
//! | 28 | 8  | timestamp of the first point, ns |
//! | 36 | …  | data |
//!
//! SDK1 header, 18 bytes (Livox-SDK `LivoxEthPacket`, `sdk_core/include/livox_def.h`):
//! version (5), slot, id, reserved, error code u32, timestamp type, data type, timestamp 8 B.

use thiserror::Error;

/// SDK2 header length.
pub const SDK2_HEADER_LEN: usize = 36;
/// SDK1 header length.
pub const SDK1_HEADER_LEN: usize = 18;
/// Largest datagram either protocol sends (SDK1 types 0/2/4 at 1362 B; SDK2 stays under 1500).
pub const MAX_DATAGRAM: usize = 1500;
/// Bytes of one IMU record (gyro x y z rad/s, acc x y z g, f32 each).
pub const IMU_RECORD_LEN: usize = 24;

/// Why a datagram is not a Livox packet.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum LivoxWireError {
    /// Shorter than the header.
    #[error("{what}: {found} bytes, shorter than its {expected}-byte header")]
    Short {
        /// Which protocol.
        what: &'static str,
        /// Header length.
        expected: usize,
        /// Length found.
        found: usize,
    },
    /// The version byte is not the protocol's.
    #[error("{what}: version {found}, expected {expected}")]
    Version {
        /// Which protocol.
        what: &'static str,
        /// Version expected.
        expected: u8,
        /// Version found.
        found: u8,
    },
    /// The SDK2 length field disagrees with the datagram.
    #[error("Livox SDK2 length field says {field} bytes, datagram has {found}")]
    LengthField {
        /// Length field.
        field: u16,
        /// Datagram length.
        found: usize,
    },
    /// Unknown data type.
    #[error("{what}: unknown data type {found:#04x}")]
    DataType {
        /// Which protocol.
        what: &'static str,
        /// Data type found.
        found: u8,
    },
    /// The data does not hold the number of records the header says.
    #[error("{what} data type {data_type}: {count} records of {record} bytes need {expected} data bytes, found {found}")]
    DotCount {
        /// Which protocol.
        what: &'static str,
        /// Data type.
        data_type: u8,
        /// Record count.
        count: usize,
        /// Bytes per record.
        record: usize,
        /// Bytes needed.
        expected: usize,
        /// Bytes found.
        found: usize,
    },
    /// The stored CRC-32 does not match the bytes it covers.
    #[error("Livox SDK2 CRC-32 stored {stored:#010x}, computed {computed:#010x}")]
    Crc {
        /// CRC in the packet.
        stored: u32,
        /// CRC of bytes 28..
        computed: u32,
    },
}

/// Point record layouts of both protocols.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Record {
    /// IMU sample (24 B).
    Imu,
    /// x, y, z i32 mm, reflectivity (13 B; SDK1 type 0).
    CartesianMm,
    /// x, y, z i32 mm, reflectivity, tag (14 B).
    CartesianMmTag,
    /// x, y, z i16 cm, reflectivity, tag (8 B; SDK2 type 2).
    CartesianCmTag,
    /// depth u32 mm, theta u16, phi u16 (0.01°), reflectivity (9 B; SDK1 type 1).
    Spherical,
    /// depth, theta, phi, reflectivity, tag (10 B).
    SphericalTag,
    /// `n` Cartesian i32 mm returns with reflectivity and tag (14·n B).
    MultiCartesian(u8),
    /// theta, phi, then `n` × (depth u32, reflectivity, tag) (4 + 6·n B).
    MultiSpherical(u8),
}

impl Record {
    /// Bytes per record.
    pub const fn size(self) -> usize {
        match self {
            Self::Imu => IMU_RECORD_LEN,
            Self::CartesianMm => 13,
            Self::CartesianMmTag => 14,
            Self::CartesianCmTag => 8,
            Self::Spherical => 9,
            Self::SphericalTag => 10,
            Self::MultiCartesian(n) => 14 * n as usize,
            Self::MultiSpherical(n) => 4 + 6 * n as usize,
        }
    }

    /// Returns per record (0 for IMU).
    pub const fn returns(self) -> usize {
        match self {
            Self::Imu => 0,
            Self::MultiCartesian(n) | Self::MultiSpherical(n) => n as usize,
            _ => 1,
        }
    }

    /// The SDK2 record of `data_type`.
    pub const fn sdk2(data_type: u8) -> Option<Self> {
        Some(match data_type {
            0 => Self::Imu,
            1 => Self::CartesianMmTag,
            2 => Self::CartesianCmTag,
            3 => Self::SphericalTag,
            0x11 => Self::MultiCartesian(2),
            _ => return None,
        })
    }

    /// The SDK1 record of `data_type`, with its documented records per packet.
    pub const fn sdk1(data_type: u8) -> Option<(Self, usize)> {
        Some(match data_type {
            0 => (Self::CartesianMm, 100),
            1 => (Self::Spherical, 100),
            2 => (Self::CartesianMmTag, 96),
            3 => (Self::SphericalTag, 96),
            4 => (Self::MultiCartesian(2), 48),
            5 => (Self::MultiSpherical(2), 48),
            6 => (Self::Imu, 1),
            7 => (Self::MultiCartesian(3), 30),
            8 => (Self::MultiSpherical(3), 30),
            _ => return None,
        })
    }
}

/// One return of a point record, in the sensor's units.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RawReturn {
    /// Cartesian x, y, z in the record's unit (mm or cm); for spherical records, the depth
    /// (mm) in `xyz[0]` and zero elsewhere.
    pub xyz: [i32; 3],
    /// Reflectivity byte.
    pub reflectivity: u8,
    /// Tag byte (0 where the record has none).
    pub tag: u8,
}

/// One IMU record in the sensor's units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RawImu {
    /// Angular velocity, rad/s.
    pub gyro: [f32; 3],
    /// Acceleration, g.
    pub acc: [f32; 3],
}

/// An SDK1 timestamp of type `ty`, ns: nanoseconds as sent for types 0, 1, 4; for type 3 the
/// UTC form (year − 2000, month, day, hour, then µs within the hour, u32) converted to ns since
/// the Unix epoch. `None` for an impossible UTC date.
pub fn sdk1_timestamp_ns(ty: u8, t: [u8; 8]) -> Option<u64> {
    if ty != 3 {
        return Some(u64::from_le_bytes(t));
    }
    let (y, mo, d, h) = (2000 + i64::from(t[0]), t[1], t[2], t[3]);
    if !(1..=12).contains(&mo) || !(1..=31).contains(&d) || h > 23 {
        return None;
    }
    let us = u64::from(u32::from_le_bytes([t[4], t[5], t[6], t[7]]));
    if us >= 3_600_000_000 {
        return None;
    }
    let days = days_from_civil(y, u32::from(mo), u32::from(d));
    let secs = u64::try_from(days * 86_400 + i64::from(h) * 3600).ok()?;
    Some(secs * 1_000_000_000 + us * 1_000)
}

#[inline]
pub(crate) fn u16_at(b: &[u8], o: usize) -> u16 {
    match b.get(o..o + 2) {
        Some(s) => u16::from_le_bytes([s[0], s[1]]),
        None => 0,
    }
}

#[inline]
pub(crate) fn u32_at(b: &[u8], o: usize) -> u32 {
    match b.get(o..o + 4) {
        Some(s) => u32::from_le_bytes([s[0], s[1], s[2], s[3]]),
        None => 0,
    }
}

#[inline]
fn i32_at(b: &[u8], o: usize) -> i32 {
    u32_at(b, o) as i32
}

#[inline]
fn f32_at(b: &[u8], o: usize) -> f32 {
    f32::from_bits(u32_at(b, o))
}

#[inline]
pub(crate) fn u64_at(b: &[u8], o: usize) -> u64 {
    match b.get(o..o + 8) {
        Some(s) => {
            let mut a = [0u8; 8];
            a.copy_from_slice(s);
            u64::from_le_bytes(a)
        }
        None => 0,
    }
}

/// Reads return `k` of a record.
#[inline]
pub fn read_return(rec: &[u8], kind: Record, k: usize) -> RawReturn {
    match kind {
        Record::Imu => RawReturn {
            xyz: [0; 3],
            reflectivity: 0,
            tag: 0,
        },
        Record::CartesianMm => RawReturn {
            xyz: [i32_at(rec, 0), i32_at(rec, 4), i32_at(rec, 8)],
            reflectivity: rec.get(12).copied().unwrap_or(0),
            tag: 0,
        },
        Record::CartesianMmTag | Record::MultiCartesian(_) => {
            let o = 14 * k;
            RawReturn {
                xyz: [i32_at(rec, o), i32_at(rec, o + 4), i32_at(rec, o + 8)],
                reflectivity: rec.get(o + 12).copied().unwrap_or(0),
                tag: rec.get(o + 13).copied().unwrap_or(0),
            }
        }
        Record::CartesianCmTag => RawReturn {
            xyz: [
                i32::from(u16_at(rec, 0) as i16),
                i32::from(u16_at(rec, 2) as i16),
                i32::from(u16_at(rec, 4) as i16),
            ],
            reflectivity: rec.get(6).copied().unwrap_or(0),
            tag: rec.get(7).copied().unwrap_or(0),
        },
        Record::Spherical | Record::SphericalTag => RawReturn {
            xyz: [u32_at(rec, 0).min(i32::MAX as u32) as i32, 0, 0],
            reflectivity: rec.get(8).copied().unwrap_or(0),
            tag: if kind == Record::SphericalTag {
                rec.get(9).copied().unwrap_or(0)
            } else {
                0
            },
        },
        Record::MultiSpherical(_) => {
            let o = 4 + 6 * k;
            RawReturn {
                xyz: [u32_at(rec, o).min(i32::MAX as u32) as i32, 0, 0],
                reflectivity: rec.get(o + 4).copied().unwrap_or(0),
                tag: rec.get(o + 5).copied().unwrap_or(0),
            }
        }
    }
}

/// Zenith (theta) and azimuth (phi) of a spherical record, 0.01°.
#[inline]
pub fn read_angles(rec: &[u8], kind: Record) -> (u16, u16) {
    match kind {
        Record::Spherical | Record::SphericalTag => (u16_at(rec, 4), u16_at(rec, 6)),
        Record::MultiSpherical(_) => (u16_at(rec, 0), u16_at(rec, 2)),
        _ => (0, 0),
    }
}

/// Reads an IMU record.
#[inline]
pub fn read_imu(rec: &[u8]) -> RawImu {
    RawImu {
        gyro: [f32_at(rec, 0), f32_at(rec, 4), f32_at(rec, 8)],
        acc: [f32_at(rec, 12), f32_at(rec, 16), f32_at(rec, 20)],
    }
}

/// A checked SDK2 packet.
#[derive(Clone, Copy, Debug)]
pub struct Sdk2Packet<'a> {
    bytes: &'a [u8],
    record: Record,
}

impl<'a> Sdk2Packet<'a> {
    /// Checks the header: version 0, the length field equal to the datagram's length, a known
    /// data type, and `dot_num` records filling the data exactly (IMU: one or more 24-byte
    /// records, `dot_num` not consulted). The CRC is checked separately ([`Self::crc_ok`]).
    pub fn new(bytes: &'a [u8]) -> Result<Self, LivoxWireError> {
        const WHAT: &str = "Livox SDK2";
        if bytes.len() < SDK2_HEADER_LEN {
            return Err(LivoxWireError::Short {
                what: WHAT,
                expected: SDK2_HEADER_LEN,
                found: bytes.len(),
            });
        }
        if bytes[0] != 0 {
            return Err(LivoxWireError::Version {
                what: WHAT,
                expected: 0,
                found: bytes[0],
            });
        }
        let field = u16_at(bytes, 1);
        if usize::from(field) != bytes.len() {
            return Err(LivoxWireError::LengthField {
                field,
                found: bytes.len(),
            });
        }
        let dt = bytes[10];
        let record = Record::sdk2(dt).ok_or(LivoxWireError::DataType {
            what: WHAT,
            found: dt,
        })?;
        let data = bytes.len() - SDK2_HEADER_LEN;
        let count = if record == Record::Imu {
            (data / IMU_RECORD_LEN).max(1)
        } else {
            usize::from(u16_at(bytes, 5))
        };
        if count * record.size() != data {
            return Err(LivoxWireError::DotCount {
                what: WHAT,
                data_type: dt,
                count,
                record: record.size(),
                expected: count * record.size(),
                found: data,
            });
        }
        Ok(Self { bytes, record })
    }

    /// The datagram.
    pub fn bytes(&self) -> &'a [u8] {
        self.bytes
    }
    /// Record layout.
    pub fn record(&self) -> Record {
        self.record
    }
    /// Data type byte.
    pub fn data_type(&self) -> u8 {
        self.bytes[10]
    }
    /// Time type byte.
    pub fn time_type(&self) -> u8 {
        self.bytes[11]
    }
    /// Time from the first point to the last, ns.
    pub fn time_interval_ns(&self) -> u64 {
        u64::from(u16_at(self.bytes, 3)) * 100
    }
    /// `dot_num` field.
    pub fn dot_num(&self) -> u16 {
        u16_at(self.bytes, 5)
    }
    /// `udp_cnt` field.
    pub fn udp_cnt(&self) -> u16 {
        u16_at(self.bytes, 7)
    }
    /// `frame_cnt` field.
    pub fn frame_cnt(&self) -> u8 {
        self.bytes[9]
    }
    /// Stored CRC-32.
    pub fn stored_crc(&self) -> u32 {
        u32_at(self.bytes, 24)
    }
    /// CRC-32 of bytes 28.. (timestamp and data).
    pub fn computed_crc(&self) -> u32 {
        crc32(&self.bytes[28..])
    }
    /// Whether the stored CRC matches.
    pub fn crc_ok(&self) -> bool {
        self.stored_crc() == self.computed_crc()
    }
    /// Timestamp of the first point, ns in the clock of [`Self::time_type`].
    pub fn timestamp_ns(&self) -> u64 {
        u64_at(self.bytes, 28)
    }
    /// Number of records.
    pub fn records(&self) -> usize {
        (self.bytes.len() - SDK2_HEADER_LEN) / self.record.size()
    }
    /// Record `i` (empty past the end).
    #[inline]
    pub fn record_bytes(&self, i: usize) -> &'a [u8] {
        let l = self.record.size();
        let o = SDK2_HEADER_LEN + i * l;
        self.bytes.get(o..o + l).unwrap_or(&[])
    }
}

/// A checked SDK1 packet.
#[derive(Clone, Copy, Debug)]
pub struct Sdk1Packet<'a> {
    bytes: &'a [u8],
    record: Record,
    count: usize,
}

impl<'a> Sdk1Packet<'a> {
    /// Checks version 5, a known data type and the documented length of that type.
    pub fn new(bytes: &'a [u8]) -> Result<Self, LivoxWireError> {
        const WHAT: &str = "Livox SDK1";
        if bytes.len() < SDK1_HEADER_LEN {
            return Err(LivoxWireError::Short {
                what: WHAT,
                expected: SDK1_HEADER_LEN,
                found: bytes.len(),
            });
        }
        if bytes[0] != 5 {
            return Err(LivoxWireError::Version {
                what: WHAT,
                expected: 5,
                found: bytes[0],
            });
        }
        let dt = bytes[9];
        let (record, count) = Record::sdk1(dt).ok_or(LivoxWireError::DataType {
            what: WHAT,
            found: dt,
        })?;
        let data = bytes.len() - SDK1_HEADER_LEN;
        if count * record.size() != data {
            return Err(LivoxWireError::DotCount {
                what: WHAT,
                data_type: dt,
                count,
                record: record.size(),
                expected: count * record.size(),
                found: data,
            });
        }
        Ok(Self {
            bytes,
            record,
            count,
        })
    }

    /// Record layout.
    pub fn record(&self) -> Record {
        self.record
    }
    /// Slot (hub port).
    pub fn slot(&self) -> u8 {
        self.bytes[1]
    }
    /// LiDAR id.
    pub fn id(&self) -> u8 {
        self.bytes[2]
    }
    /// Error / status code.
    pub fn status_code(&self) -> u32 {
        u32_at(self.bytes, 4)
    }
    /// Timestamp type: 0 none, 1 PTP, 3 PPS + GPS (UTC), 4 PPS.
    pub fn timestamp_type(&self) -> u8 {
        self.bytes[8]
    }
    /// Data type byte.
    pub fn data_type(&self) -> u8 {
        self.bytes[9]
    }
    /// The raw 8 timestamp bytes.
    pub fn timestamp_bytes(&self) -> [u8; 8] {
        let mut a = [0u8; 8];
        a.copy_from_slice(&self.bytes[10..18]);
        a
    }
    /// Timestamp of the first point, ns: nanoseconds as sent for types 0, 1, 4; for type 3
    /// the UTC form (year − 2000, month, day, hour, then µs within the hour, u32) converted to
    /// ns since the Unix epoch. `None` for an impossible UTC date.
    pub fn timestamp_ns(&self) -> Option<u64> {
        sdk1_timestamp_ns(self.timestamp_type(), self.timestamp_bytes())
    }
    /// Number of records.
    pub fn records(&self) -> usize {
        self.count
    }
    /// Record `i` (empty past the end).
    #[inline]
    pub fn record_bytes(&self, i: usize) -> &'a [u8] {
        let l = self.record.size();
        let o = SDK1_HEADER_LEN + i * l;
        self.bytes.get(o..o + l).unwrap_or(&[])
    }
}

/// Days from 1970-01-01 to the given civil date (proleptic Gregorian; H. Hinnant's method).
fn days_from_civil(y: i64, m: u32, d: u32) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let m = i64::from(m);
    let doy = (153 * (if m > 2 { m - 3 } else { m + 9 }) + 2) / 5 + i64::from(d) - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// CRC-32 as Livox's protocol table gives it (polynomial 0x04C11DB7, initial and final XOR
/// 0xFFFFFFFF, input and output reflected: CRC-32/ISO-HDLC), which is the CRC `crc32fast`
/// computes with the CPU's carry-less multiply: a table walk a byte at a time was most of the
/// stream's time.
pub fn crc32(bytes: &[u8]) -> u32 {
    crc32fast::hash(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_check_value() {
        // The catalogue check value of CRC-32/ISO-HDLC over "123456789".
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn utc_days() {
        assert_eq!(days_from_civil(1970, 1, 1), 0);
        // 2000-03-01 is day 11017 since the epoch.
        assert_eq!(days_from_civil(2000, 3, 1), 11_017);
    }

    #[test]
    fn record_sizes_match_the_documented_packet_lengths() {
        // livox_ros_driver's table of SDK1 packet lengths per data type.
        let lens = [1318, 918, 1362, 978, 1362, 786, 42, 1278, 678];
        for (dt, &l) in lens.iter().enumerate() {
            let (r, n) = Record::sdk1(dt as u8).unwrap();
            assert_eq!(SDK1_HEADER_LEN + n * r.size(), l, "type {dt}");
        }
    }
}
