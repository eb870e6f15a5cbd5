//! Ouster lidar and IMU packets: checked, zero-copy views.
//!
//! Layouts (FORMATS.md §5.2; ouster-sdk `ouster_core/src/parsing.cpp`, `PacketFormat::Impl`):
//!
//! - **Lidar, LEGACY** (no packet header or footer): `C` columns of 16-byte column header
//!   (timestamp u64 ns @0, measurement id u16 @8, frame id u16 @10, encoder count u32 @12),
//!   `H` pixels, and a u32 status word (valid = bit 0; the sensor sends `0xFFFFFFFF`).
//! - **Lidar, profile-based**: 32-byte packet header, `C` columns of 12-byte column header
//!   (timestamp u64 ns @0, measurement id u16 @8, status u16 @10, valid = bit 0) and `H` pixels,
//!   then a 32-byte footer whose last 8 bytes hold a CRC-64/XZ (little-endian) from FW 2.5 on.
//!   Standard header: packet_type u16 @0, frame_id u16 @2, init_id u24 @4, prod_sn u40 @7,
//!   alert_flags u8 @12, countdowns u8 @16 / @17, thermal shutdown and shot limiting status in the
//!   low nibbles of @18 / @19. FUSA header: packet_type u8 @0, init_id u24 @1, frame_id u32 @4,
//!   alert_flags u8 @8, prod_sn u40 @11, the rest as standard.
//! - **IMU, LEGACY**: 48 bytes, see [`ImuPacketLegacy`].
//! - **IMU, ACCEL32_GYRO32_NMEA**: see [`ImuPacketNmea`].
//! - **Zone monitor** (FW 3.2+): see [`ZonePacket`].
//!
//! All multi-byte fields are little-endian. A view checks its length once in its constructor;
//! after that no accessor can panic (column and pixel accessors return `Option` or 0 for an
//! index outside the packet).

use crate::sensor::ouster::model::Field;
use crate::sensor::ouster::model::HeaderKind;
use crate::sensor::ouster::model::PacketFormat;
use crate::sensor::ouster::model::Profile;
use crate::sensor::WireError;

/// `packet_type` of lidar packets.
pub const PACKET_TYPE_LIDAR: u16 = 0x1;
/// `packet_type` of IMU packets (ACCEL32_GYRO32_NMEA).
pub const PACKET_TYPE_IMU: u16 = 0x2;
/// `packet_type` of zone-monitor packets.
pub const PACKET_TYPE_ZONE: u16 = 0x3;

/// Bytes of a LEGACY IMU packet.
pub const IMU_LEGACY_BYTES: usize = 48;
/// Bytes of the NMEA block of an ACCEL32_GYRO32_NMEA IMU packet (timestamp + sentence + pad).
pub const IMU_NMEA_BLOCK_BYTES: usize = 100;
/// Bytes of the NMEA sentence field (the SDK's `NMEA_SENTENCE_LENGTH`).
pub const NMEA_SENTENCE_BYTES: usize = 85;
/// Bytes of one ACCEL32_GYRO32_NMEA measurement.
pub const IMU_MEASUREMENT_BYTES: usize = 36;
/// Header (and footer) bytes of profile-based packets.
pub const HEADER_BYTES: usize = 32;

#[inline]
fn le_u16(b: &[u8], off: usize) -> u16 {
    match b.get(off..off + 2) {
        Some(&[a, c]) => u16::from_le_bytes([a, c]),
        _ => 0,
    }
}

#[inline]
fn le_u32(b: &[u8], off: usize) -> u32 {
    match b.get(off..off + 4) {
        Some(&[a, c, d, e]) => u32::from_le_bytes([a, c, d, e]),
        _ => 0,
    }
}

#[inline]
fn le_u64(b: &[u8], off: usize) -> u64 {
    match b.get(off..off + 8) {
        Some(s) => {
            let mut a = [0u8; 8];
            a.copy_from_slice(s);
            u64::from_le_bytes(a)
        }
        None => 0,
    }
}

/// Little-endian unsigned integer of `n` ≤ 8 bytes at `off` (0 if out of range).
#[inline]
fn le_uint(b: &[u8], off: usize, n: usize) -> u64 {
    match b.get(off..off + n) {
        Some(s) => {
            let mut a = [0u8; 8];
            a[..n].copy_from_slice(s);
            u64::from_le_bytes(a)
        }
        None => 0,
    }
}

#[inline]
fn le_f32(b: &[u8], off: usize) -> f32 {
    f32::from_bits(le_u32(b, off))
}

/// Reads one pixel field: `width` bits from bit `bit` of `pixel` (little-endian bit order),
/// shifted left by `shift`. Bits beyond the end of `pixel` read as 0; never panics.
#[inline]
pub fn read_field(pixel: &[u8], f: Field) -> u32 {
    read_field_at(pixel, 0, f)
}

/// Reads one field of the pixel that starts at byte `start` of `buf` (a column or a whole
/// packet): as [`read_field`] on `&buf[start..]`, but with one 8-byte load where `buf` has 8
/// bytes from the field's first byte on (bytes past the pixel are masked off), so the hot
/// loop copies no variable-length slices. Never panics.
#[inline]
pub fn read_field_at(buf: &[u8], start: usize, f: Field) -> u32 {
    let off = start.saturating_add(usize::from(f.bit / 8));
    let mut a = [0u8; 8];
    match buf.get(off..off.saturating_add(8)) {
        Some(s) => a.copy_from_slice(s),
        None => {
            let avail = buf.get(off..).unwrap_or(&[]);
            let n = avail.len().min(8);
            a[..n].copy_from_slice(&avail[..n]);
        }
    }
    let width = u32::from(f.width.min(32));
    let mask = if width == 0 {
        0
    } else {
        u64::MAX >> (64 - width)
    };
    let v = (u64::from_le_bytes(a) >> (f.bit % 8)) & mask;
    (v << f.shift.min(31)) as u32
}

/// Writes one pixel field: `value >> shift`, masked to `width` bits, at bit `bit` of `pixel`
/// (other bits unchanged). Bits beyond the end of `pixel` are dropped; never panics.
#[inline]
pub fn write_field(pixel: &mut [u8], f: Field, value: u32) {
    let byte = usize::from(f.bit / 8);
    let Some(dst) = pixel.get_mut(byte..) else {
        return;
    };
    let n = dst.len().min(8);
    let mut a = [0u8; 8];
    a[..n].copy_from_slice(&dst[..n]);
    let width = u32::from(f.width.min(32));
    let mask = if width == 0 {
        0
    } else {
        u64::MAX >> (64 - width)
    };
    let sh = u32::from(f.bit % 8);
    let v = (u64::from(value) >> f.shift.min(31)) & mask;
    let word = (u64::from_le_bytes(a) & !(mask << sh)) | (v << sh);
    dst[..n].copy_from_slice(&word.to_le_bytes()[..n]);
}

static CRC64_XZ: crc::Crc<u64, crc::Table<16>> =
    crc::Crc::<u64, crc::Table<16>>::new(&crc::CRC_64_XZ);

/// CRC-64/XZ (a.k.a. CRC-64/GO-ECMA): reflected polynomial 0xC96C5795D7870F42, initial value
/// and final xor all ones. The check value of `b"123456789"` is `0x995DC9BBDF1939FA`. Ouster
/// lidar packets carry it over all bytes but the last 8 (ouster-sdk `crc64_compute`).
pub fn crc64_xz(bytes: &[u8]) -> u64 {
    CRC64_XZ.checksum(bytes)
}

/// Thermal-shutdown status nibble (header byte 18), as the SDK names it.
pub fn thermal_shutdown_name(v: u8) -> &'static str {
    match v {
        0 => "NORMAL",
        1 => "IMMINENT",
        _ => "UNKNOWN",
    }
}

/// Shot-limiting status nibble (header byte 19), as the SDK names it.
pub fn shot_limiting_name(v: u8) -> &'static str {
    match v {
        0 => "NORMAL",
        1 => "IMMINENT",
        2 => "REDUCTION_0_10",
        3 => "REDUCTION_10_20",
        4 => "REDUCTION_20_30",
        5 => "REDUCTION_30_40",
        6 => "REDUCTION_40_50",
        7 => "REDUCTION_50_60",
        8 => "REDUCTION_60_70",
        9 => "REDUCTION_70_75",
        _ => "UNKNOWN",
    }
}

/// A checked view of one Ouster lidar packet in a given [`PacketFormat`].
///
/// The header layout is the profile's ([`Profile::header`]) unless given with
/// [`Self::with_header`].
#[derive(Clone, Copy, Debug)]
pub struct LidarPacket<'a> {
    b: &'a [u8],
    format: PacketFormat,
    header: HeaderKind,
    header_bytes: usize,
    column_bytes: usize,
    column_header_bytes: usize,
    pixel_bytes: usize,
}

impl<'a> LidarPacket<'a> {
    /// Checks the length against the format (`format.packet_bytes()`).
    pub fn new(bytes: &'a [u8], format: &PacketFormat) -> Result<Self, WireError> {
        Self::with_header(bytes, format, format.profile.header())
    }

    /// As [`Self::new`], with an explicit header layout (the metadata's
    /// `lidar_data_format.header_type`; ignored for LEGACY, which has no header).
    pub fn with_header(
        bytes: &'a [u8],
        format: &PacketFormat,
        header: HeaderKind,
    ) -> Result<Self, WireError> {
        let header = if format.profile == Profile::Legacy {
            HeaderKind::Legacy
        } else if header == HeaderKind::Legacy {
            HeaderKind::Standard
        } else {
            header
        };
        let expected = format.packet_bytes();
        if bytes.len() != expected || format.columns_per_packet == 0 {
            return Err(WireError::Length {
                what: "Ouster lidar packet",
                expected,
                found: bytes.len(),
            });
        }
        Ok(Self {
            b: bytes,
            format: *format,
            header,
            header_bytes: format.header_bytes(),
            column_bytes: format.column_bytes(),
            column_header_bytes: format.column_header_bytes(),
            pixel_bytes: format.profile.layout().pixel_bytes,
        })
    }

    /// The raw bytes.
    pub fn bytes(&self) -> &'a [u8] {
        self.b
    }

    /// The packet format.
    pub fn format(&self) -> &PacketFormat {
        &self.format
    }

    /// The header layout in use.
    pub fn header_kind(&self) -> HeaderKind {
        self.header
    }

    /// `packet_type` (1 = lidar); 0 for LEGACY (no header).
    pub fn packet_type(&self) -> u16 {
        match self.header {
            HeaderKind::Legacy => 0,
            HeaderKind::Standard => le_u16(self.b, 0),
            HeaderKind::Fusa => u16::from(self.b.first().copied().unwrap_or(0)),
        }
    }

    /// `frame_id`: u16 in standard headers, u32 in FUSA headers; LEGACY: the first column's
    /// frame id (as the SDK reads it).
    pub fn frame_id(&self) -> u32 {
        match self.header {
            HeaderKind::Legacy => u32::from(le_u16(self.b, 10)),
            HeaderKind::Standard => u32::from(le_u16(self.b, 2)),
            HeaderKind::Fusa => le_u32(self.b, 4),
        }
    }

    /// `init_id` (24 bits); 0 for LEGACY.
    pub fn init_id(&self) -> u32 {
        match self.header {
            HeaderKind::Legacy => 0,
            HeaderKind::Standard => le_uint(self.b, 4, 3) as u32,
            HeaderKind::Fusa => le_uint(self.b, 1, 3) as u32,
        }
    }

    /// `prod_sn`, the serial number (40 bits); 0 for LEGACY.
    pub fn serial(&self) -> u64 {
        match self.header {
            HeaderKind::Legacy => 0,
            HeaderKind::Standard => le_uint(self.b, 7, 5),
            HeaderKind::Fusa => le_uint(self.b, 11, 5),
        }
    }

    /// `alert_flags`; 0 for LEGACY.
    pub fn alert_flags(&self) -> u8 {
        match self.header {
            HeaderKind::Legacy => 0,
            HeaderKind::Standard => self.byte(12),
            HeaderKind::Fusa => self.byte(8),
        }
    }

    /// `countdown_thermal_shutdown` (byte 16); 0 for LEGACY.
    pub fn countdown_thermal_shutdown(&self) -> u8 {
        self.header_byte(16)
    }

    /// `countdown_shot_limiting` (byte 17); 0 for LEGACY.
    pub fn countdown_shot_limiting(&self) -> u8 {
        self.header_byte(17)
    }

    /// Thermal shutdown status (low nibble of byte 18; 0 = NORMAL, 1 = IMMINENT); 0 for
    /// LEGACY. See [`thermal_shutdown_name`].
    pub fn thermal_shutdown(&self) -> u8 {
        self.header_byte(18) & 0x0F
    }

    /// Shot limiting status (low nibble of byte 19; 0 = NORMAL, 1 = IMMINENT,
    /// 2.. = REDUCTION_0_10 ..); 0 for LEGACY. See [`shot_limiting_name`].
    pub fn shot_limiting(&self) -> u8 {
        self.header_byte(19) & 0x0F
    }

    #[inline]
    fn byte(&self, off: usize) -> u8 {
        self.b.get(off).copied().unwrap_or(0)
    }

    #[inline]
    fn header_byte(&self, off: usize) -> u8 {
        if self.header == HeaderKind::Legacy {
            0
        } else {
            self.byte(off)
        }
    }

    /// Columns in this packet.
    pub fn columns_len(&self) -> usize {
        self.format.columns_per_packet
    }

    /// Column `i` of the packet (`None` if `i` ≥ columns per packet).
    #[inline]
    pub fn column(&self, i: usize) -> Option<Column<'a>> {
        if i >= self.format.columns_per_packet {
            return None;
        }
        let off = self.header_bytes + i * self.column_bytes;
        let b = self.b.get(off..off + self.column_bytes)?;
        Some(Column {
            b,
            legacy: self.header == HeaderKind::Legacy,
            column_header_bytes: self.column_header_bytes,
            pixel_bytes: self.pixel_bytes,
            pixels: self.format.pixels_per_column,
        })
    }

    /// Every column, in packet order.
    pub fn columns(&self) -> impl Iterator<Item = Column<'a>> + '_ {
        (0..self.format.columns_per_packet).filter_map(move |i| self.column(i))
    }

    /// The 32-byte footer (`None` for LEGACY).
    pub fn footer(&self) -> Option<&'a [u8]> {
        if self.header == HeaderKind::Legacy {
            return None;
        }
        let n = self.b.len();
        self.b.get(n.saturating_sub(HEADER_BYTES)..)
    }

    /// Whether the format defines a CRC in the footer: profile-based with a standard header
    /// (ouster-sdk `PacketFormat::crc`: none for LEGACY and FUSA). Firmware before 2.5 writes
    /// something else there (FORMATS.md §5.2); whether to check is the caller's policy.
    pub fn has_crc_field(&self) -> bool {
        self.header == HeaderKind::Standard && self.format.profile != Profile::FusaRng15Rfl8Nir8Dual
    }

    /// The CRC stored in the footer's last 8 bytes (`None` when the format defines none).
    pub fn crc(&self) -> Option<u64> {
        if !self.has_crc_field() {
            return None;
        }
        Some(le_u64(self.b, self.b.len().saturating_sub(8)))
    }

    /// CRC-64/XZ of every byte but the last 8.
    pub fn computed_crc(&self) -> u64 {
        crc64_xz(&self.b[..self.b.len().saturating_sub(8)])
    }

    /// Whether the stored CRC matches (`None` when the format defines no CRC).
    pub fn crc_ok(&self) -> Option<bool> {
        self.crc().map(|c| c == self.computed_crc())
    }

    /// [`Self::crc_ok`] as a `Result`: a format without CRC passes.
    pub fn check_crc(&self) -> Result<(), WireError> {
        match self.crc() {
            Some(stored) => {
                let computed = self.computed_crc();
                if stored == computed {
                    Ok(())
                } else {
                    Err(WireError::Crc {
                        what: "Ouster lidar packet",
                        stored,
                        computed,
                    })
                }
            }
            None => Ok(()),
        }
    }
}

/// One column of a lidar packet: its header and `H` pixels.
#[derive(Clone, Copy, Debug)]
pub struct Column<'a> {
    b: &'a [u8],
    legacy: bool,
    column_header_bytes: usize,
    pixel_bytes: usize,
    pixels: usize,
}

impl<'a> Column<'a> {
    /// Column timestamp, ns (sensor clock).
    #[inline]
    pub fn timestamp_ns(&self) -> u64 {
        le_u64(self.b, 0)
    }

    /// Measurement id = column index in the frame, 0..W−1.
    #[inline]
    pub fn measurement_id(&self) -> u16 {
        le_u16(self.b, 8)
    }

    /// Raw status: LEGACY the trailing u32 (0xFFFFFFFF when valid), else the u16 @10.
    #[inline]
    pub fn status(&self) -> u32 {
        if self.legacy {
            le_u32(self.b, self.b.len().saturating_sub(4))
        } else {
            u32::from(le_u16(self.b, 10))
        }
    }

    /// Whether the column holds data: status bit 0 (as ouster-sdk tests it).
    #[inline]
    pub fn valid(&self) -> bool {
        self.status() & 1 != 0
    }

    /// LEGACY: the column's frame id (u16 @10); 0 for profile-based packets.
    pub fn frame_id(&self) -> u16 {
        if self.legacy {
            le_u16(self.b, 10)
        } else {
            0
        }
    }

    /// LEGACY: encoder count (u32 @12, 0..90111 per turn); 0 for profile-based packets.
    pub fn encoder_count(&self) -> u32 {
        if self.legacy {
            le_u32(self.b, 12)
        } else {
            0
        }
    }

    /// Pixels in the column (H).
    pub fn pixels_len(&self) -> usize {
        self.pixels
    }

    /// The bytes of pixel `row` (`None` if `row` ≥ H).
    #[inline]
    pub fn pixel(&self, row: usize) -> Option<&'a [u8]> {
        if row >= self.pixels {
            return None;
        }
        let off = self.column_header_bytes + row * self.pixel_bytes;
        self.b.get(off..off + self.pixel_bytes)
    }

    /// The column's bytes (header, pixels and, for LEGACY, the status word).
    #[inline]
    pub fn as_bytes(&self) -> &'a [u8] {
        self.b
    }

    /// The bytes of all `H` pixels, back to back (row 0 first; the column header and, for
    /// LEGACY, the status trailer excluded): `H × pixel bytes` long, so that
    /// `chunks_exact(pixel bytes)` gives every pixel.
    #[inline]
    pub fn pixel_data(&self) -> &'a [u8] {
        let b: &'a [u8] = self.b;
        let start = self.column_header_bytes.min(b.len());
        let end = start
            .saturating_add(self.pixels.saturating_mul(self.pixel_bytes))
            .min(b.len());
        &b[start..end]
    }

    /// Byte offset of pixel `row` within [`Self::as_bytes`] (for [`read_field_at`]).
    #[inline]
    pub fn pixel_offset(&self, row: usize) -> usize {
        self.column_header_bytes + row * self.pixel_bytes
    }

    /// Every pixel's bytes, row 0 (top beam) first.
    #[inline]
    pub fn pixels(&self) -> impl Iterator<Item = &'a [u8]> + 'a {
        let start = self.column_header_bytes.min(self.b.len());
        let end = (start + self.pixels * self.pixel_bytes).min(self.b.len());
        let b: &'a [u8] = &self.b[start..end];
        b.chunks_exact(self.pixel_bytes.max(1))
    }

    /// Field `f` of pixel `row` (0 if `row` ≥ H).
    #[inline]
    pub fn field(&self, row: usize, f: Field) -> u32 {
        if row >= self.pixels {
            return 0;
        }
        read_field_at(self.b, self.pixel_offset(row), f)
    }
}

/// A LEGACY IMU packet (48 bytes, no header): timestamps in ns, acceleration in g, angular
/// velocity in deg/s (ouster-sdk `ImuPacket::accel` multiplies by 9.80665 and π/180 for this
/// profile only).
#[derive(Clone, Copy, Debug)]
pub struct ImuPacketLegacy<'a> {
    b: &'a [u8; IMU_LEGACY_BYTES],
}

impl<'a> ImuPacketLegacy<'a> {
    /// Checks the length (48 bytes).
    pub fn new(bytes: &'a [u8]) -> Result<Self, WireError> {
        let b = bytes.try_into().map_err(|_| WireError::Length {
            what: "Ouster LEGACY IMU packet",
            expected: IMU_LEGACY_BYTES,
            found: bytes.len(),
        })?;
        Ok(Self { b })
    }

    /// System timestamp, ns (u64 @0).
    pub fn sys_ts_ns(&self) -> u64 {
        le_u64(self.b, 0)
    }

    /// Accelerometer read time, ns (u64 @8).
    pub fn accel_ts_ns(&self) -> u64 {
        le_u64(self.b, 8)
    }

    /// Gyroscope read time, ns (u64 @16).
    pub fn gyro_ts_ns(&self) -> u64 {
        le_u64(self.b, 16)
    }

    /// Linear acceleration x, y, z in g (f32 @24, 28, 32).
    pub fn accel_g(&self) -> [f32; 3] {
        [le_f32(self.b, 24), le_f32(self.b, 28), le_f32(self.b, 32)]
    }

    /// Angular velocity x, y, z in deg/s (f32 @36, 40, 44).
    pub fn gyro_dps(&self) -> [f32; 3] {
        [le_f32(self.b, 36), le_f32(self.b, 40), le_f32(self.b, 44)]
    }
}

/// Bytes of an ACCEL32_GYRO32_NMEA IMU packet with `n` measurements.
pub const fn imu_nmea_packet_bytes(n: usize) -> usize {
    HEADER_BYTES + IMU_NMEA_BLOCK_BYTES + n * IMU_MEASUREMENT_BYTES + HEADER_BYTES
}

/// An ACCEL32_GYRO32_NMEA IMU packet: standard 32-byte header (packet_type 2), a 100-byte NMEA
/// block (timestamp u64 @32, 85-byte sentence @40), `N` measurements of 36 bytes and a 32-byte
/// footer. Per ouster-sdk (`ImuPacket::accel`, `gyro`) this profile reports m/s² and rad/s.
#[derive(Clone, Copy, Debug)]
pub struct ImuPacketNmea<'a> {
    b: &'a [u8],
    n: usize,
}

impl<'a> ImuPacketNmea<'a> {
    /// Checks the length for `measurements` per packet (`imu_measurements_per_packet`).
    pub fn new(bytes: &'a [u8], measurements: usize) -> Result<Self, WireError> {
        let expected = imu_nmea_packet_bytes(measurements);
        if bytes.len() != expected {
            return Err(WireError::Length {
                what: "Ouster ACCEL32_GYRO32_NMEA IMU packet",
                expected,
                found: bytes.len(),
            });
        }
        Ok(Self {
            b: bytes,
            n: measurements,
        })
    }

    /// `packet_type` (2 = IMU).
    pub fn packet_type(&self) -> u16 {
        le_u16(self.b, 0)
    }

    /// `frame_id` (u16 @2).
    pub fn frame_id(&self) -> u16 {
        le_u16(self.b, 2)
    }

    /// `init_id` (u24 @4).
    pub fn init_id(&self) -> u32 {
        le_uint(self.b, 4, 3) as u32
    }

    /// `prod_sn` (u40 @7).
    pub fn serial(&self) -> u64 {
        le_uint(self.b, 7, 5)
    }

    /// `alert_flags` (@12).
    pub fn alert_flags(&self) -> u8 {
        self.b.get(12).copied().unwrap_or(0)
    }

    /// NMEA timestamp, ns (u64 @32).
    pub fn nmea_ts_ns(&self) -> u64 {
        le_u64(self.b, HEADER_BYTES)
    }

    /// The NMEA sentence bytes up to the first NUL (at most 85 bytes).
    pub fn nmea(&self) -> &'a [u8] {
        let start = HEADER_BYTES + 8;
        let field = self
            .b
            .get(start..start + NMEA_SENTENCE_BYTES)
            .unwrap_or(&[]);
        let end = field.iter().position(|&c| c == 0).unwrap_or(field.len());
        &field[..end]
    }

    /// Measurements in the packet.
    pub fn measurements_len(&self) -> usize {
        self.n
    }

    /// Measurement `i` (`None` if `i` ≥ N).
    pub fn measurement(&self, i: usize) -> Option<ImuMeasurement> {
        if i >= self.n {
            return None;
        }
        let off = HEADER_BYTES + IMU_NMEA_BLOCK_BYTES + i * IMU_MEASUREMENT_BYTES;
        let m = self.b.get(off..off + IMU_MEASUREMENT_BYTES)?;
        Some(ImuMeasurement {
            timestamp_ns: le_u64(m, 0),
            measurement_id: le_u16(m, 8),
            status: le_u16(m, 10),
            accel: [le_f32(m, 12), le_f32(m, 16), le_f32(m, 20)],
            gyro: [le_f32(m, 24), le_f32(m, 28), le_f32(m, 32)],
        })
    }

    /// Every measurement.
    pub fn measurements(&self) -> impl Iterator<Item = ImuMeasurement> + '_ {
        (0..self.n).filter_map(move |i| self.measurement(i))
    }

    /// The stored footer CRC-64 (last 8 bytes).
    pub fn crc(&self) -> u64 {
        le_u64(self.b, self.b.len().saturating_sub(8))
    }

    /// CRC-64/XZ of every byte but the last 8.
    pub fn computed_crc(&self) -> u64 {
        crc64_xz(&self.b[..self.b.len().saturating_sub(8)])
    }
}

/// One measurement of an ACCEL32_GYRO32_NMEA packet.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuMeasurement {
    /// Timestamp, ns (u64 @0).
    pub timestamp_ns: u64,
    /// Measurement id (u16 @8).
    pub measurement_id: u16,
    /// Status (u16 @10; bit 0 = valid).
    pub status: u16,
    /// Linear acceleration x, y, z, m/s² (f32 @12, 16, 20).
    pub accel: [f32; 3],
    /// Angular velocity x, y, z, rad/s (f32 @24, 28, 32).
    pub gyro: [f32; 3],
}

impl ImuMeasurement {
    /// Status bit 0.
    pub fn valid(&self) -> bool {
        self.status & 1 != 0
    }
}

/// Zones in a zone-monitor packet (ouster-sdk `ZonePacket::zone_states`: always 16; unused
/// slots have `live` 0 and `id` 255).
pub const ZONE_COUNT: usize = 16;
/// Bytes of one zone's record in a zone-monitor packet.
pub const ZONE_RECORD_BYTES: usize = 36;
/// Bytes of a zone-monitor packet: header, timestamp (8), live zone set hash (32), 16 zone
/// records, footer.
pub const ZONE_PACKET_BYTES: usize =
    HEADER_BYTES + 8 + ZONE_HASH_BYTES + ZONE_COUNT * ZONE_RECORD_BYTES + HEADER_BYTES;
/// Bytes of the live zone set's hash (SHA-256) in a zone-monitor packet.
pub const ZONE_HASH_BYTES: usize = 32;
/// Mask of the 19-bit range fields of a zone record (mm).
const ZONE_RANGE_MASK: u32 = (1 << 19) - 1;

/// One zone's state in a zone-monitor packet (FW 3.2+ zone monitoring). Field meanings as
/// ouster-sdk's `ZoneState` gives them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ZoneState {
    /// The slot holds a live zone (bit 0 of byte 0), triggered or not.
    pub live: bool,
    /// Zone id (byte 1): the index of its configuration; 255 in unused slots.
    pub id: u8,
    /// Error flags (byte 2): missing data, low-confidence pixels, zone obscured.
    pub error_flags: u8,
    /// Trigger type (bits 2–3 of byte 3): occupancy, vacancy, ….
    pub trigger_type: u8,
    /// Trigger status (bit 7 of byte 3): 1 = asserted.
    pub trigger_status: u8,
    /// Consecutive frames triggered, saturating (u32 @4); 0 once deasserted.
    pub triggered_frames: u32,
    /// Points in the zone in the latest frame (u32 @8).
    pub count: u32,
    /// Points of the zone below the minimum range (u32 @12).
    pub occlusion_count: u32,
    /// Invalid points in the zone (u32 @16).
    pub invalid_count: u32,
    /// Most points the zone can hold (u32 @20).
    pub max_count: u32,
    /// Nearest point in the zone, mm (19 bits @24).
    pub min_range_mm: u32,
    /// Farthest point in the zone, mm (19 bits @28).
    pub max_range_mm: u32,
    /// Mean range of the zone's points, mm (19 bits @32).
    pub mean_range_mm: u32,
}

/// A zone-monitor packet (`packet_type` 3, to the metadata's `udp_port_zm`): the sensor's
/// verdict on each of up to 16 configured zones, once per frame. Layout (ouster-sdk
/// `parsing.cpp`, `zone_*_info`): 32-byte packet header, timestamp u64 ns @32, the live zone
/// set's SHA-256 @40, 16 records of [`ZONE_RECORD_BYTES`] @72, and a 32-byte footer whose last
/// 8 bytes hold a CRC-64/XZ (little-endian).
#[derive(Clone, Copy, Debug)]
pub struct ZonePacket<'a> {
    b: &'a [u8],
    header: HeaderKind,
}

impl<'a> ZonePacket<'a> {
    /// Checks the length; `header` is the sensor's header layout (the lidar profile's: FUSA
    /// profiles move `frame_id`, `init_id` and the serial).
    pub fn new(bytes: &'a [u8], header: HeaderKind) -> Result<Self, WireError> {
        if bytes.len() != ZONE_PACKET_BYTES {
            return Err(WireError::Length {
                what: "Ouster zone-monitor packet",
                expected: ZONE_PACKET_BYTES,
                found: bytes.len(),
            });
        }
        Ok(Self { b: bytes, header })
    }

    fn fusa(&self) -> bool {
        self.header == HeaderKind::Fusa
    }

    /// `packet_type` (3 = zone monitor).
    pub fn packet_type(&self) -> u16 {
        if self.fusa() {
            u16::from(self.b[0])
        } else {
            le_u16(self.b, 0)
        }
    }

    /// `frame_id` of the frame the zones were judged on (u16; FUSA u32).
    pub fn frame_id(&self) -> u32 {
        if self.fusa() {
            le_u32(self.b, 4)
        } else {
            u32::from(le_u16(self.b, 2))
        }
    }

    /// `init_id` (24 bits).
    pub fn init_id(&self) -> u32 {
        le_uint(self.b, if self.fusa() { 1 } else { 4 }, 3) as u32
    }

    /// `prod_sn`, the serial number (40 bits).
    pub fn serial(&self) -> u64 {
        le_uint(self.b, if self.fusa() { 11 } else { 7 }, 5)
    }

    /// `alert_flags` of the header.
    pub fn alert_flags(&self) -> u8 {
        self.b[if self.fusa() { 8 } else { 12 }]
    }

    /// Timestamp of the zone states, ns, sensor clock (u64 @32).
    pub fn timestamp_ns(&self) -> u64 {
        le_u64(self.b, HEADER_BYTES)
    }

    /// SHA-256 of the live zone set (@40): which configuration the states refer to.
    pub fn zoneset_hash(&self) -> [u8; ZONE_HASH_BYTES] {
        let mut h = [0; ZONE_HASH_BYTES];
        let start = HEADER_BYTES + 8;
        h.copy_from_slice(&self.b[start..start + ZONE_HASH_BYTES]);
        h
    }

    /// Zone record `i` (`None` if `i` ≥ [`ZONE_COUNT`]).
    pub fn zone(&self, i: usize) -> Option<ZoneState> {
        if i >= ZONE_COUNT {
            return None;
        }
        let off = HEADER_BYTES + 8 + ZONE_HASH_BYTES + i * ZONE_RECORD_BYTES;
        let r = self.b.get(off..off + ZONE_RECORD_BYTES)?;
        Some(ZoneState {
            live: r[0] & 1 != 0,
            id: r[1],
            error_flags: r[2],
            trigger_type: (r[3] >> 2) & 0b11,
            trigger_status: r[3] >> 7,
            triggered_frames: le_u32(r, 4),
            count: le_u32(r, 8),
            occlusion_count: le_u32(r, 12),
            invalid_count: le_u32(r, 16),
            max_count: le_u32(r, 20),
            min_range_mm: le_u32(r, 24) & ZONE_RANGE_MASK,
            max_range_mm: le_u32(r, 28) & ZONE_RANGE_MASK,
            mean_range_mm: le_u32(r, 32) & ZONE_RANGE_MASK,
        })
    }

    /// The stored footer CRC-64 (last 8 bytes).
    pub fn crc(&self) -> u64 {
        le_u64(self.b, ZONE_PACKET_BYTES - 8)
    }

    /// CRC-64/XZ of every byte but the last 8.
    pub fn computed_crc(&self) -> u64 {
        crc64_xz(&self.b[..ZONE_PACKET_BYTES - 8])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::ouster::model::ALL_PROFILES;

    #[test]
    fn crc64_xz_check_value() {
        assert_eq!(crc64_xz(b"123456789"), 0x995D_C9BB_DF19_39FA);
        assert_eq!(crc64_xz(b""), 0);
    }

    #[test]
    fn fields_round_trip_at_their_width_limits() {
        for p in ALL_PROFILES {
            let l = p.layout();
            let mut fields = vec![l.range, l.reflectivity];
            fields.extend(
                [
                    l.flags,
                    l.signal,
                    l.near_ir,
                    l.range2,
                    l.flags2,
                    l.reflectivity2,
                    l.signal2,
                ]
                .into_iter()
                .flatten(),
            );
            for f in fields {
                let max = ((1u64 << f.width) - 1) as u32;
                let mut px = vec![0u8; l.pixel_bytes];
                write_field(&mut px, f, max << f.shift);
                assert_eq!(read_field(&px, f), max << f.shift, "{p} {f:?}");
                // Nothing else was touched.
                let mut bits = 0u32;
                for b in &px {
                    bits += b.count_ones();
                }
                assert_eq!(bits, u32::from(f.width), "{p} {f:?}");
            }
        }
    }

    #[test]
    fn read_field_past_the_end_is_zero_not_a_panic() {
        let f = Field {
            bit: 96,
            width: 16,
            shift: 0,
        };
        assert_eq!(read_field(&[0xFF; 4], f), 0);
        assert_eq!(read_field(&[0xFF; 13], f), 0xFF);
        let mut short = [0u8; 3];
        write_field(&mut short, f, 0xFFFF);
        assert_eq!(short, [0; 3]);
    }

    #[test]
    fn standard_and_fusa_headers_are_read_at_their_offsets() {
        let fmt = PacketFormat {
            profile: Profile::Rng15Rfl8Nir8,
            columns_per_packet: 1,
            pixels_per_column: 1,
        };
        let mut b = vec![0u8; fmt.packet_bytes()];
        b[0..2].copy_from_slice(&1u16.to_le_bytes());
        b[2..4].copy_from_slice(&0xBEEFu16.to_le_bytes());
        b[4..7].copy_from_slice(&[0x56, 0x34, 0x12]);
        b[7..12].copy_from_slice(&[0x05, 0x04, 0x03, 0x02, 0x01]);
        b[12] = 152;
        b[16] = 5;
        b[17] = 7;
        b[18] = 0xF1;
        b[19] = 0x02;
        let p = LidarPacket::new(&b, &fmt).unwrap();
        assert_eq!(p.packet_type(), 1);
        assert_eq!(p.frame_id(), 0xBEEF);
        assert_eq!(p.init_id(), 0x12_3456);
        assert_eq!(p.serial(), 0x01_0203_0405);
        assert_eq!(p.alert_flags(), 152);
        assert_eq!(p.countdown_thermal_shutdown(), 5);
        assert_eq!(p.countdown_shot_limiting(), 7);
        assert_eq!(p.thermal_shutdown(), 1);
        assert_eq!(p.shot_limiting(), 2);

        let mut f = vec![0u8; fmt.packet_bytes()];
        f[0] = 1;
        f[1..4].copy_from_slice(&[0x56, 0x34, 0x12]);
        f[4..8].copy_from_slice(&0x0102_0304u32.to_le_bytes());
        f[8] = 9;
        f[11..16].copy_from_slice(&[0x05, 0x04, 0x03, 0x02, 0x01]);
        let p = LidarPacket::with_header(&f, &fmt, HeaderKind::Fusa).unwrap();
        assert_eq!(p.packet_type(), 1);
        assert_eq!(p.frame_id(), 0x0102_0304);
        assert_eq!(p.init_id(), 0x12_3456);
        assert_eq!(p.serial(), 0x01_0203_0405);
        assert_eq!(p.alert_flags(), 9);
        assert_eq!(p.crc(), None);
    }

    #[test]
    fn wrong_length_is_an_error() {
        let fmt = PacketFormat {
            profile: Profile::Legacy,
            columns_per_packet: 16,
            pixels_per_column: 16,
        };
        let b = vec![0u8; 3391];
        assert_eq!(
            LidarPacket::new(&b, &fmt).unwrap_err(),
            WireError::Length {
                what: "Ouster lidar packet",
                expected: 3392,
                found: 3391
            }
        );
        assert!(ImuPacketLegacy::new(&b[..47]).is_err());
        assert!(ImuPacketNmea::new(&b[..451], 8).is_err());
        assert!(ImuPacketNmea::new(&b[..452], 8).is_ok());
    }

    #[test]
    fn legacy_column_header_and_status() {
        let fmt = PacketFormat {
            profile: Profile::Legacy,
            columns_per_packet: 2,
            pixels_per_column: 16,
        };
        let mut b = vec![0u8; fmt.packet_bytes()];
        let cb = fmt.column_bytes();
        b[0..8].copy_from_slice(&123_456_789u64.to_le_bytes());
        b[8..10].copy_from_slice(&1000u16.to_le_bytes());
        b[10..12].copy_from_slice(&77u16.to_le_bytes());
        b[12..16].copy_from_slice(&88_000u32.to_le_bytes());
        b[cb - 4..cb].copy_from_slice(&0xFFFF_FFFFu32.to_le_bytes());
        let p = LidarPacket::new(&b, &fmt).unwrap();
        assert_eq!(p.frame_id(), 77);
        let c0 = p.column(0).unwrap();
        assert_eq!(c0.timestamp_ns(), 123_456_789);
        assert_eq!(c0.measurement_id(), 1000);
        assert_eq!(c0.frame_id(), 77);
        assert_eq!(c0.encoder_count(), 88_000);
        assert!(c0.valid());
        assert!(!p.column(1).unwrap().valid());
        assert!(p.column(2).is_none());
        assert!(c0.pixel(16).is_none());
        assert_eq!(c0.pixels().count(), 16);
        assert_eq!(p.crc_ok(), None);
    }

    /// A zone-monitor packet written byte by byte from ouster-sdk's field table (bit offsets
    /// of `zone_*_info` in `parsing.cpp`), with the bits next to every field set, so a wrong
    /// offset, width or mask shows.
    #[test]
    fn zone_packet_fields_from_the_sdk_bit_table() {
        let mut b = vec![0u8; 680];
        b[0..2].copy_from_slice(&3u16.to_le_bytes()); // packet_type
        b[2..4].copy_from_slice(&30_002u16.to_le_bytes()); // frame_id
        b[4..7].copy_from_slice(&[0xF8, 0x16, 0xE6]); // init_id 0xE616F8
        b[7..12].copy_from_slice(&[0xD1, 0x32, 0x7D, 0x76, 0x1C]); // prod_sn 0x1C767D32D1
        b[12] = 0x02; // alert_flags
        b[32..40].copy_from_slice(&0x0000_0EB6_93D7_2E68u64.to_le_bytes());
        for (i, v) in b[40..72].iter_mut().enumerate() {
            *v = i as u8 + 1;
        }
        // Zone 0: live, every neighbour bit set.
        let z = &mut b[72..108];
        z[0] = 0xFF; // live = bit 0 only
        z[1] = 7;
        z[2] = 0x05;
        z[3] = 0b1000_1000; // trigger_type (bits 26–27) = 2, trigger_status (bit 31) = 1
        z[4..8].copy_from_slice(&161_074u32.to_le_bytes());
        z[8..12].copy_from_slice(&742u32.to_le_bytes());
        z[12..16].copy_from_slice(&369u32.to_le_bytes());
        z[16..20].copy_from_slice(&5_182u32.to_le_bytes());
        z[20..24].copy_from_slice(&6_883u32.to_le_bytes());
        // 19-bit ranges with the 13 bits above them set.
        z[24..28].copy_from_slice(&(0xFFF8_0000u32 | 817).to_le_bytes());
        z[28..32].copy_from_slice(&(0xFFF8_0000u32 | 524_287).to_le_bytes());
        z[32..36].copy_from_slice(&(0xFFF8_0000u32 | 1_161).to_le_bytes());
        // Zone 15 (the last record, ending where the footer starts): not live, but every
        // other bit of byte 0 and of byte 3 set.
        let z = &mut b[72 + 15 * 36..72 + 16 * 36];
        z[0] = 0xFE;
        z[1] = 255;
        z[3] = 0b0111_0011; // trigger_type = 0, trigger_status = 0
        assert_eq!(72 + 16 * 36, 680 - 32);
        let crc = crc64_xz(&b[..672]);
        b[672..].copy_from_slice(&crc.to_le_bytes());

        let p = ZonePacket::new(&b, HeaderKind::Standard).unwrap();
        assert_eq!(p.packet_type(), PACKET_TYPE_ZONE);
        assert_eq!(p.frame_id(), 30_002);
        assert_eq!(p.init_id(), 15_079_160);
        assert_eq!(p.serial(), 122_247_000_785);
        assert_eq!(p.alert_flags(), 2);
        assert_eq!(p.timestamp_ns(), 16_177_327_189_608);
        assert_eq!(p.zoneset_hash()[0], 1);
        assert_eq!(p.zoneset_hash()[31], 32);
        assert_eq!(
            p.zone(0),
            Some(ZoneState {
                live: true,
                id: 7,
                error_flags: 5,
                trigger_type: 2,
                trigger_status: 1,
                triggered_frames: 161_074,
                count: 742,
                occlusion_count: 369,
                invalid_count: 5_182,
                max_count: 6_883,
                min_range_mm: 817,
                max_range_mm: 524_287,
                mean_range_mm: 1_161,
            })
        );
        let last = p.zone(15).unwrap();
        assert!(!last.live);
        assert_eq!(
            (last.id, last.trigger_type, last.trigger_status),
            (255, 0, 0)
        );
        assert_eq!(p.zone(16), None);
        assert_eq!(p.crc(), p.computed_crc());
        for len in [0, 679, 681, 1024] {
            let long = vec![0u8; len];
            assert!(matches!(
                ZonePacket::new(&long, HeaderKind::Standard),
                Err(WireError::Length { expected: 680, .. })
            ));
        }
    }
}
