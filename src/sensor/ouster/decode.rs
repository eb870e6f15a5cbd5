//! The Ouster decoder: one table-driven loop for every profile.
//!
//! [`OusterDecoder::new`] does all the trigonometry of a calibration once: the XYZ lookup
//! table of ouster-sdk's `make_xyz_lut` with `use_extrinsics = false` (FORMATS.md §5.2 "XYZ";
//! `ouster_core/src/xyzlut.cpp`), one direction and one offset per pixel (row, column), in f32,
//! computed in f64 from the beam intrinsics, `beam_to_lidar_transform` and
//! `lidar_to_sensor_transform`:
//!
//! ```text
//! θe = 2π − 2π·v/W                       (encoder angle of column v)
//! θa = −beam_azimuth[u]·π/180,  φ = beam_altitude[u]·π/180
//! dir = (cos(θe+θa)·cosφ, sin(θe+θa)·cosφ, sinφ)
//! n = beam_to_lidar[0][3];  n_e = hypot(b[0][3], b[2][3]) if b[2][3] ≠ 0 else n
//! off = (cosθe·n − dir.x·n_e, sinθe·n − dir.y·n_e, −dir.z·n_e + b[2][3])
//! dir, off ← R(lidar_to_sensor)·(·);  off += t(lidar_to_sensor);  both × 0.001 (mm → m)
//! xyz = range_mm·dir + off               (range 0: no point)
//! ```
//!
//! Per packet: per valid column one timestamp subtraction; per pixel the profile's fields are
//! read by their [`Field`] descriptions and the point is one
//! multiply-add per axis. No trigonometry, no allocation per packet.
//!
//! Conventions (DESIGN.md "Points"; ouster-sdk 1.0.1):
//! - Points are in the Ouster **sensor frame** (x forward toward the side opposite the
//!   connector, z up), metres.
//! - `intensity` = REFLECTIVITY (REFLECTIVITY2 for the second return); signal, near-IR, range
//!   and flags are in [`Extra`].
//! - `ring` = rank of the beam altitude, 0 = lowest (beams of equal altitude: the lower row in
//!   the image gets the lower ring). Organised images ([`OusterFrame`]) keep the sensor's row
//!   order: row 0 = beam 0 = top.
//! - `ret` 0 = first return (RANGE), 1 = second return (RANGE2, dual profiles).
//! - A column counts only when its status bit 0 is set and its measurement id is below W, as
//!   the SDK's frame batcher; a pixel is a point when its range is > 0. RNG15 ranges are in
//!   8 mm units on the wire and NIR8 values in units of 16; both are scaled as the SDK does
//!   (`range_mm`, `near_ir` come out in the SDK's units).
//! - `t` = column timestamp − the sweep start the caller gives, clamped to `0..=u32::MAX` ns.

use crate::point::Point;
use crate::sensor::ouster::calib::OusterInfo;
use crate::sensor::ouster::model::Field;
use crate::sensor::ouster::model::HeaderKind;
use crate::sensor::ouster::model::Layout;
use crate::sensor::ouster::model::PacketFormat;
use crate::sensor::ouster::wire::read_field_at;
use crate::sensor::ouster::wire::Column;
use crate::sensor::ouster::wire::LidarPacket;
use crate::sensor::DecodeError;
use std::sync::Arc;

/// The per-point values beyond the [`Point`] record.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Extra {
    /// Range, mm (RNG15 profiles: the wire value × 8).
    pub range_mm: u32,
    /// Signal photons (0 where the profile has none).
    pub signal: u16,
    /// Near-infrared photons of the pixel (NIR8 profiles: the wire value × 16; 0 where the
    /// profile has none). The same for both returns.
    pub near_ir: u16,
    /// Reflectivity (also in [`Point::intensity`]).
    pub reflectivity: u8,
    /// The return's flags field.
    pub flags: u8,
    /// Zone-occupancy mask of the pixel (ZONE16 profiles; 0 elsewhere). The same for both
    /// returns.
    pub zones: u16,
    /// Red, green and blue of the pixel as IEEE half-float bits (RGB16 profiles; 0 elsewhere).
    /// The same for both returns.
    pub rgb: [u16; 3],
}

/// An [`Extra`] without what the pixel's returns share beyond near-IR.
#[derive(Clone, Copy, Debug, Default)]
struct Lean {
    range_mm: u32,
    signal: u16,
    near_ir: u16,
    reflectivity: u8,
    flags: u8,
}

impl Lean {
    #[inline(always)]
    fn of(x: &Extra) -> Self {
        Self {
            range_mm: x.range_mm,
            signal: x.signal,
            near_ir: x.near_ir,
            reflectivity: x.reflectivity,
            flags: x.flags,
        }
    }

    #[inline(always)]
    fn extra(&self, sh: Shared) -> Extra {
        Extra {
            range_mm: self.range_mm,
            signal: self.signal,
            near_ir: self.near_ir,
            reflectivity: self.reflectivity,
            flags: self.flags,
            zones: sh.zones,
            rgb: sh.rgb,
        }
    }
}

/// The values of a pixel both its returns share.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Shared {
    near_ir: u16,
    zones: u16,
    rgb: [u16; 3],
}

/// What one packet decoded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Decoded {
    /// Points emitted (pixels with range > 0 in valid columns, both returns).
    pub points: usize,
    /// Valid columns (status bit 0 set, measurement id < W).
    pub columns: usize,
    /// Columns skipped: status bit 0 clear.
    pub invalid_columns: usize,
    /// Columns skipped: measurement id ≥ W.
    pub out_of_range_columns: usize,
}

/// Direction (m per mm of range) and offset (m) of one pixel, as four lanes each so that a
/// point is one 4-wide multiply-add: `[r, r, r, reflectivity] · dir + off` gives x, y, z and
/// the intensity (`dir[3]` = 1, `off[3]` = 0; every lane the same IEEE operations as
/// [`point_of`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct LutEntry {
    dir: [f32; 4],
    off: [f32; 4],
}

impl LutEntry {
    fn d3(&self) -> [f32; 3] {
        [self.dir[0], self.dir[1], self.dir[2]]
    }

    fn o3(&self) -> [f32; 3] {
        [self.off[0], self.off[1], self.off[2]]
    }
}

/// A [`Point`] as the decoder assembles it: x, y, z, intensity, then `t`, `ring`, `ret`
/// and `pad` as one little-endian word (two stores per point instead of one per field).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct PointWords {
    xyzi: [f32; 4],
    tail: u64,
}

/// Reads the profile's fields of one pixel.
#[derive(Clone, Copy, Debug)]
struct Pixel {
    r: [Extra; 2],
}

/// One pixel field, specialised when the decoder is built: a single 4-byte little-endian load
/// at byte `at` of the pixel (`at + 4` ≤ pixel bytes), then `>> shr`, `& mask`, `<< shl`. A
/// field the profile lacks has mask 0 and reads 0, so the hot loop has no `Option` per field.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct FieldReader {
    at: usize,
    shr: u32,
    mask: u32,
    shl: u32,
}

impl FieldReader {
    /// The reader of field `f` in pixels of `pixel_bytes` bytes; `None` when no 4-byte load
    /// inside the pixel holds the whole field (then the generic path is used).
    fn new(f: Option<Field>, pixel_bytes: usize) -> Option<Self> {
        let Some(f) = f else {
            return Some(Self::default());
        };
        let (bit, width, shl) = (usize::from(f.bit), u32::from(f.width), u32::from(f.shift));
        if pixel_bytes < 4 || width == 0 || width > 32 || shl > 31 {
            return None;
        }
        let at = (bit / 8).min(pixel_bytes - 4);
        let shr = u32::try_from(bit - 8 * at).ok()?;
        if shr + width > 32 {
            return None;
        }
        Some(Self {
            at,
            shr,
            mask: u32::MAX >> (32 - width),
            shl,
        })
    }

    /// The field's value in pixel `px` (as [`read_field_at`] gives it).
    #[inline(always)]
    fn read<const N: usize>(self, px: &[u8; N]) -> u32 {
        // `at ≤ N − 4` by construction; the `min` lets the compiler drop the bounds check.
        let at = self.at.min(N.saturating_sub(4));
        let v = match px.get(at..at + 4) {
            Some(&[a, b, c, d]) => u32::from_le_bytes([a, b, c, d]),
            _ => 0,
        };
        ((v >> self.shr) & self.mask) << self.shl
    }
}

/// Every field of a profile as [`FieldReader`]s (`None` in the decoder when a field does not
/// fit one; then the generic [`read_field_at`] path serves).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Readers {
    range: FieldReader,
    flags: FieldReader,
    reflectivity: FieldReader,
    signal: FieldReader,
    near_ir: FieldReader,
    range2: FieldReader,
    flags2: FieldReader,
    reflectivity2: FieldReader,
    signal2: FieldReader,
    zones: FieldReader,
    rgb: [FieldReader; 3],
}

impl Readers {
    fn new(l: &Layout) -> Option<Self> {
        let r = |f| FieldReader::new(f, l.pixel_bytes);
        Some(Self {
            range: r(Some(l.range))?,
            flags: r(l.flags)?,
            reflectivity: r(Some(l.reflectivity))?,
            signal: r(l.signal)?,
            near_ir: r(l.near_ir)?,
            range2: r(l.range2)?,
            flags2: r(l.flags2)?,
            reflectivity2: r(l.reflectivity2)?,
            signal2: r(l.signal2)?,
            zones: r(l.zones)?,
            rgb: {
                let [red, green, blue] = l.rgb().map_or([None; 3], |c| c.map(Some));
                [r(red)?, r(green)?, r(blue)?]
            },
        })
    }

    /// The values both returns of pixel `px` share; the zone mask and colour only when the
    /// profile has them (`MORE`), so that other profiles load nothing more per pixel.
    #[inline(always)]
    fn shared<const N: usize, const MORE: bool>(&self, px: &[u8; N]) -> Shared {
        let near_ir = self.near_ir.read(px) as u16;
        if !MORE {
            return Shared {
                near_ir,
                ..Shared::default()
            };
        }
        Shared {
            near_ir,
            zones: self.zones.read(px) as u16,
            rgb: self.rgb.map(|c| c.read(px) as u16),
        }
    }

    /// First (`SECOND` false) or second return of pixel `px`, with the values of the pixel.
    #[inline(always)]
    fn extra<const N: usize, const SECOND: bool>(&self, px: &[u8; N], sh: Shared) -> Extra {
        let (range, signal, reflectivity, flags) = if SECOND {
            (self.range2, self.signal2, self.reflectivity2, self.flags2)
        } else {
            (self.range, self.signal, self.reflectivity, self.flags)
        };
        Extra {
            range_mm: range.read(px),
            signal: signal.read(px) as u16,
            near_ir: sh.near_ir,
            reflectivity: reflectivity.read(px) as u8,
            flags: flags.read(px) as u8,
            zones: sh.zones,
            rgb: sh.rgb,
        }
    }
}

/// An Ouster decoder for one calibration (sensor metadata).
#[derive(Clone, Debug)]
pub struct OusterDecoder {
    format: PacketFormat,
    header: HeaderKind,
    layout: Layout,
    /// The layout's fields specialised to fixed loads (`None`: generic path).
    readers: Option<Readers>,
    w: usize,
    h: usize,
    /// XYZ table, column-major: entry of (row u, column v) at `v·H + u`. Shared by the clones
    /// of a decoder (4 MiB for a 128 × 1024 sensor: built once per metadata file).
    lut: Arc<[LutEntry]>,
    rings: Vec<u16>,
    /// Per row: `ring << 32`, the ring's bits in the last word of a [`PointWords`].
    ring_tails: Vec<u64>,
    shift: Vec<i32>,
    crc_check: bool,
    init_id: u32,
    serial: u64,
}

fn bad(reason: String) -> DecodeError {
    DecodeError::Calibration(reason)
}

impl OusterDecoder {
    /// Builds the lookup tables from a calibration. CRC checking follows
    /// [`OusterInfo::lidar_packets_have_crc`] (firmware ≥ 2.5 with a standard header); change it
    /// with [`Self::with_crc_check`].
    pub fn new(info: &OusterInfo) -> Result<Self, DecodeError> {
        let format = info.format;
        let h = format.pixels_per_column;
        let w = info.columns_per_frame;
        if h == 0 || w == 0 || format.columns_per_packet == 0 {
            return Err(bad(format!(
                "frame of {h} rows × {w} columns, {} columns per packet: every count must be > 0",
                format.columns_per_packet
            )));
        }
        if w > usize::from(u16::MAX) + 1 {
            return Err(bad(format!(
                "{w} columns per frame: measurement ids are 16 bits"
            )));
        }
        for (name, n) in [
            ("beam_altitude_angles", info.beam_altitude_angles.len()),
            ("beam_azimuth_angles", info.beam_azimuth_angles.len()),
            ("pixel_shift_by_row", info.pixel_shift_by_row.len()),
        ] {
            if n != h {
                return Err(bad(format!(
                    "{name} has {n} entries, expected one per pixel row ({h})"
                )));
            }
        }
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !finite(&info.beam_altitude_angles)
            || !finite(&info.beam_azimuth_angles)
            || !finite(&info.beam_to_lidar)
            || !finite(&info.lidar_to_sensor)
        {
            return Err(bad(
                "a beam angle or transform entry is not a finite number".to_owned(),
            ));
        }
        let rings = rings_by_altitude(&info.beam_altitude_angles);
        let lut = xyz_lut(
            w,
            &info.beam_altitude_angles,
            &info.beam_azimuth_angles,
            &info.beam_to_lidar,
            &info.lidar_to_sensor,
        );
        Ok(Self {
            format,
            header: format.profile.header(),
            layout: format.profile.layout(),
            readers: Readers::new(&format.profile.layout()),
            w,
            h,
            lut,
            rings: rings.clone(),
            ring_tails: rings.iter().map(|&r| u64::from(r) << 32).collect(),
            shift: info.pixel_shift_by_row.clone(),
            crc_check: info.lidar_packets_have_crc(),
            init_id: info.init_id,
            serial: info.serial,
        })
    }

    /// Another header layout than the profile's (the metadata's
    /// `lidar_data_format.header_type`; ouster-sdk allows a FUSA header with any non-LEGACY
    /// profile). Ignored for LEGACY, which has no header. A FUSA header has no CRC: the check
    /// is turned off with it.
    pub fn with_header_kind(mut self, header: HeaderKind) -> Self {
        self.header = match (self.format.profile, header) {
            (crate::sensor::ouster::model::Profile::Legacy, _) => HeaderKind::Legacy,
            (_, HeaderKind::Legacy) => HeaderKind::Standard,
            (_, h) => h,
        };
        if self.header != HeaderKind::Standard {
            self.crc_check = false;
        }
        self
    }

    /// Turns the footer CRC check of [`Self::packet`] on or off.
    pub fn with_crc_check(mut self, on: bool) -> Self {
        self.crc_check = on;
        self
    }

    /// Whether [`Self::packet`] checks the footer CRC.
    pub fn crc_check(&self) -> bool {
        self.crc_check
    }

    /// The `init_id` [`Self::packet`] expects (0: any).
    pub fn init_id(&self) -> u32 {
        self.init_id
    }

    /// Expects `init_id` from now on: the sensor re-initialised. Nothing else is rebuilt, as no
    /// table depends on it (a new XYZ table is 4 MiB of trigonometry for a 128 × 1024 sensor).
    pub fn set_init_id(&mut self, init_id: u32) {
        self.init_id = init_id;
    }

    /// Whether both decoders use one XYZ table (not a copy).
    #[cfg(test)]
    pub(crate) fn shares_table_with(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.lut, &other.lut)
    }

    /// The packet format.
    pub fn format(&self) -> &PacketFormat {
        &self.format
    }

    /// The header layout.
    pub fn header_kind(&self) -> HeaderKind {
        self.header
    }

    /// Columns per frame (W).
    pub fn columns_per_frame(&self) -> usize {
        self.w
    }

    /// Pixels per column (H).
    pub fn pixels_per_column(&self) -> usize {
        self.h
    }

    /// Returns per pixel: 2 for dual profiles, else 1.
    pub fn returns(&self) -> usize {
        if self.format.profile.is_dual() {
            2
        } else {
            1
        }
    }

    /// Ring of each row (rank of the beam altitude, 0 = lowest).
    pub fn rings(&self) -> &[u16] {
        &self.rings
    }

    /// `pixel_shift_by_row`.
    pub fn pixel_shift_by_row(&self) -> &[i32] {
        &self.shift
    }

    /// Direction of pixel (row, column) in metres per mm of range, and its offset in metres.
    pub fn lut(&self, row: usize, column: usize) -> Option<([f32; 3], [f32; 3])> {
        if row >= self.h {
            return None;
        }
        self.lut
            .get(column * self.h + row)
            .map(|e| (e.d3(), e.o3()))
    }

    /// The sensor-frame point of a range at pixel (row, column), metres (`None` outside the
    /// frame; range 0 gives the pixel's offset, which the decoder never emits).
    pub fn xyz(&self, row: usize, column: usize, range_mm: u32) -> Option<[f32; 3]> {
        self.lut(row, column).map(|(d, o)| point_of(range_mm, d, o))
    }

    /// A view of one datagram in this decoder's format, accepted as ouster-sdk accepts lidar
    /// packets for one sensor, in this order: the length of the format, then the sensor
    /// ([`Self::check_sensor`]: init_id and serial), then the footer CRC when
    /// [`Self::crc_check`] is on. (Use [`LidarPacket::new`] for a view without the checks.)
    pub fn packet<'a>(&self, bytes: &'a [u8]) -> Result<LidarPacket<'a>, DecodeError> {
        let p = LidarPacket::with_header(bytes, &self.format, self.header)?;
        self.check_sensor(&p)?;
        if self.crc_check {
            p.check_crc()?;
        }
        Ok(p)
    }

    /// ouster-sdk's sensor check (`validate_packet`): the packet's init_id must equal the
    /// metadata's when both are non-zero, and its serial likewise. Always passes for LEGACY.
    pub fn check_sensor(&self, p: &LidarPacket<'_>) -> Result<(), DecodeError> {
        let (init_id, serial) = (p.init_id(), p.serial());
        let init_bad = self.init_id != 0 && init_id != 0 && init_id != self.init_id;
        let sn_bad = self.serial != 0 && serial != 0 && serial != self.serial;
        if init_bad || sn_bad {
            return Err(DecodeError::SensorId {
                expected_init_id: self.init_id,
                found_init_id: init_id,
                expected_serial: self.serial,
                found_serial: serial,
            });
        }
        Ok(())
    }

    fn check_format(&self, p: &LidarPacket<'_>) -> Result<(), DecodeError> {
        if *p.format() != self.format || p.header_kind() != self.header {
            return Err(DecodeError::Format {
                expected: format!("{:?} with {:?} header", self.format, self.header),
                found: format!("{:?} with {:?} header", p.format(), p.header_kind()),
            });
        }
        Ok(())
    }

    /// The profile's fields of the pixel that starts at byte `at` of column bytes `b`.
    #[inline]
    fn pixel(&self, b: &[u8], at: usize) -> Pixel {
        let l = &self.layout;
        let get = |f| read_field_at(b, at, f);
        let opt = |f: Option<crate::sensor::ouster::model::Field>| f.map_or(0, get);
        let near_ir = opt(l.near_ir) as u16;
        let zones = opt(l.zones) as u16;
        let rgb = l.rgb().map_or([0; 3], |c| c.map(|f| get(f) as u16));
        Pixel {
            r: [
                Extra {
                    range_mm: get(l.range),
                    signal: opt(l.signal) as u16,
                    near_ir,
                    reflectivity: get(l.reflectivity) as u8,
                    flags: opt(l.flags) as u8,
                    zones,
                    rgb,
                },
                Extra {
                    range_mm: opt(l.range2),
                    signal: opt(l.signal2) as u16,
                    near_ir,
                    reflectivity: opt(l.reflectivity2) as u8,
                    flags: opt(l.flags2) as u8,
                    zones,
                    rgb,
                },
            ],
        }
    }

    /// Decodes one packet, handing every point to `emit` with its [`Extra`] values, its row
    /// (0 = top beam) and its column (measurement id). Order: column by column in packet
    /// order, row by row, the first return (`ret` 0) before the second (`ret` 1). `t` =
    /// column timestamp − `sweep_start_ns`, clamped to `0..=u32::MAX`.
    ///
    /// The packet must have been viewed in this decoder's format ([`Self::packet`]).
    ///
    /// The loop is chosen once per packet by the pixel size, so that every field is one
    /// fixed-width load at an offset set when the decoder was built and the pixels come as
    /// fixed-size arrays (no bounds check, no `Option` per pixel); the values are the same
    /// as [`read_field_at`]'s.
    #[inline]
    pub fn decode_with<F: FnMut(Point, Extra, usize, usize)>(
        &self,
        p: &LidarPacket<'_>,
        sweep_start_ns: u64,
        mut emit: F,
    ) -> Result<Decoded, DecodeError> {
        self.check_format(p)?;
        let Some(rd) = self.readers else {
            return Ok(self.decode_generic(p, sweep_start_ns, &mut emit));
        };
        Ok(match self.layout.pixel_bytes {
            4 => self.decode_fixed::<4, F>(p, sweep_start_ns, &rd, &mut emit),
            8 => self.decode_fixed::<8, F>(p, sweep_start_ns, &rd, &mut emit),
            12 => self.decode_fixed::<12, F>(p, sweep_start_ns, &rd, &mut emit),
            16 => self.decode_fixed::<16, F>(p, sweep_start_ns, &rd, &mut emit),
            20 => self.decode_fixed::<20, F>(p, sweep_start_ns, &rd, &mut emit),
            _ => self.decode_generic(p, sweep_start_ns, &mut emit),
        })
    }

    /// [`Self::decode_with`] for pixels of `N` bytes: the single- and dual-return loops apart.
    #[inline(always)]
    fn decode_fixed<const N: usize, F: FnMut(Point, Extra, usize, usize)>(
        &self,
        p: &LidarPacket<'_>,
        sweep_start_ns: u64,
        rd: &Readers,
        emit: &mut F,
    ) -> Decoded {
        let more = self.layout.zones.is_some() || self.layout.red.is_some();
        match (self.returns() == 2, more) {
            (true, false) => self.emit_returns::<N, true, false, F>(p, sweep_start_ns, rd, emit),
            (false, false) => self.emit_returns::<N, false, false, F>(p, sweep_start_ns, rd, emit),
            (true, true) => self.emit_returns::<N, true, true, F>(p, sweep_start_ns, rd, emit),
            (false, true) => self.emit_returns::<N, false, true, F>(p, sweep_start_ns, rd, emit),
        }
    }

    /// [`Self::decode_with`] for pixels of `N` bytes with one or two (`DUAL`) returns. Up to
    /// [`BLOCK_ROWS`] rows of a column are decoded into buffers on the stack without a branch
    /// per pixel, then handed to `emit` in a second, short loop: the caller's work per point
    /// does not compete with the field extraction for registers.
    ///
    /// Not inlined: with its four instances (returns × zone mask / colour) inlined into
    /// `decode_with`, the loop ran a third slower (`decode --min-range` on an OS-2-128 capture,
    /// side by side with the build before the zone mask and colour).
    #[inline(never)]
    fn emit_returns<
        const N: usize,
        const DUAL: bool,
        const MORE: bool,
        F: FnMut(Point, Extra, usize, usize),
    >(
        &self,
        p: &LidarPacket<'_>,
        sweep_start_ns: u64,
        rd: &Readers,
        emit: &mut F,
    ) -> Decoded {
        let mut n = Decoded::default();
        let h = self.h;
        let mut points = [Point::default(); STAGE];
        // The values of each return without the pixel's zone mask and colour, which are staged
        // apart and only where the profile has them: staged in one wider record, they cost a
        // third of the loop's speed on every profile (measured as above).
        let mut extras = [Lean::default(); STAGE];
        let mut mores = [Shared::default(); STAGE];
        let mut rows = [0u32; STAGE];
        for c in p.columns() {
            let Some(m) = self.column_index(&c, &mut n) else {
                continue;
            };
            let t = u64::from(column_time(c.timestamp_ns(), sweep_start_ns));
            let Some(lut) = self.lut.get(m * h..(m + 1) * h) else {
                continue;
            };
            let data = c.pixel_data();
            let mut row = 0u32;
            for (b0, b1) in blocks(h) {
                let (Some(lut), Some(tails)) = (lut.get(b0..b1), self.ring_tails.get(b0..b1))
                else {
                    break;
                };
                let pixels = data.get(b0 * N..).unwrap_or(&[]);
                let mut k = 0;
                for (i, (e, &ring)) in lut.iter().zip(tails).enumerate() {
                    let Some(px) = pixel::<N>(pixels, i) else {
                        break;
                    };
                    // At most 2 × BLOCK_ROWS = STAGE writes per block: `k < STAGE` at each
                    // write, the mask only spares the bounds check.
                    let sh = rd.shared::<N, MORE>(px);
                    let x = rd.extra::<N, false>(px, sh);
                    points[k % STAGE] = make_point(x.range_mm, x.reflectivity, e, t | ring);
                    extras[k % STAGE] = Lean::of(&x);
                    if MORE {
                        mores[k % STAGE] = sh;
                    }
                    rows[k % STAGE] = row;
                    k += usize::from(x.range_mm != 0);
                    if DUAL {
                        let x = rd.extra::<N, true>(px, sh);
                        let pt = make_point(x.range_mm, x.reflectivity, e, t | ring | RET1);
                        points[k % STAGE] = pt;
                        extras[k % STAGE] = Lean::of(&x);
                        if MORE {
                            mores[k % STAGE] = sh;
                        }
                        rows[k % STAGE] = row;
                        k += usize::from(x.range_mm != 0);
                    }
                    row += 1;
                }
                let k = k.min(STAGE);
                for (i, ((&pt, x), &r)) in points[..k]
                    .iter()
                    .zip(&extras[..k])
                    .zip(&rows[..k])
                    .enumerate()
                {
                    let sh = if MORE {
                        mores.get(i).copied().unwrap_or_default()
                    } else {
                        Shared::default()
                    };
                    emit(pt, x.extra(sh), r as usize, m);
                }
                n.points += k;
            }
        }
        n
    }

    /// [`Self::decode_with`] through [`read_field_at`], for layouts [`Readers`] cannot serve.
    fn decode_generic<F: FnMut(Point, Extra, usize, usize)>(
        &self,
        p: &LidarPacket<'_>,
        sweep_start_ns: u64,
        emit: &mut F,
    ) -> Decoded {
        let mut n = Decoded::default();
        let returns = self.returns();
        for c in p.columns() {
            let Some(m) = self.column_index(&c, &mut n) else {
                continue;
            };
            let t = u64::from(column_time(c.timestamp_ns(), sweep_start_ns));
            let lut = &self.lut[m * self.h..(m + 1) * self.h];
            let b = c.as_bytes();
            for (row, (e, &ring)) in lut.iter().zip(&self.ring_tails).enumerate() {
                let pix = self.pixel(b, c.pixel_offset(row));
                for (ret, x) in pix.r.iter().take(returns).enumerate() {
                    if x.range_mm == 0 {
                        continue;
                    }
                    let tail = t | ring | if ret == 0 { 0 } else { RET1 };
                    emit(make_point(x.range_mm, x.reflectivity, e, tail), *x, row, m);
                    n.points += 1;
                }
            }
        }
        n
    }

    /// Decodes one packet, appending its points to `out`: the same points in the same order
    /// as [`Self::decode_with`], by the fastest path (use it when every point is kept and the
    /// [`Extra`] values are not needed).
    ///
    /// Each column's points are assembled in a small buffer on the stack without a branch
    /// per pixel (every pixel is written, the write position advances only past points) and
    /// appended with one `extend_from_slice`: wide copies into `out` instead of one narrow
    /// store per field, which is what bounds this loop (BENCHMARKS.md, "Ouster").
    pub fn decode(
        &self,
        p: &LidarPacket<'_>,
        sweep_start_ns: u64,
        out: &mut Vec<Point>,
    ) -> Result<Decoded, DecodeError> {
        self.append(p, sweep_start_ns, out, None)
    }

    /// [`Self::decode`], also appending each point's column (measurement id) to `columns`:
    /// what an organised image of the sweep needs, at the speed of the append loop (one
    /// fill per block of rows instead of a call per point through [`Self::decode_with`]).
    pub fn decode_columns(
        &self,
        p: &LidarPacket<'_>,
        sweep_start_ns: u64,
        out: &mut Vec<Point>,
        columns: &mut Vec<u32>,
    ) -> Result<Decoded, DecodeError> {
        self.append(p, sweep_start_ns, out, Some(columns))
    }

    fn append(
        &self,
        p: &LidarPacket<'_>,
        sweep_start_ns: u64,
        out: &mut Vec<Point>,
        mut columns: Option<&mut Vec<u32>>,
    ) -> Result<Decoded, DecodeError> {
        self.check_format(p)?;
        let Some(rd) = self.readers else {
            return Ok(self.decode_generic(p, sweep_start_ns, &mut |pt, _, _, m| {
                out.push(pt);
                if let Some(c) = columns.as_deref_mut() {
                    c.push(m as u32);
                }
            }));
        };
        let dual = self.returns() == 2;
        let cols = &mut columns;
        Ok(match self.layout.pixel_bytes {
            4 => self.append_fixed::<4>(p, sweep_start_ns, &rd, dual, out, cols),
            8 => self.append_fixed::<8>(p, sweep_start_ns, &rd, dual, out, cols),
            12 => self.append_fixed::<12>(p, sweep_start_ns, &rd, dual, out, cols),
            16 => self.append_fixed::<16>(p, sweep_start_ns, &rd, dual, out, cols),
            20 => self.append_fixed::<20>(p, sweep_start_ns, &rd, dual, out, cols),
            _ => self.decode_generic(p, sweep_start_ns, &mut |pt, _, _, m| {
                out.push(pt);
                if let Some(c) = cols.as_deref_mut() {
                    c.push(m as u32);
                }
            }),
        })
    }

    /// [`Self::decode`] for pixels of `N` bytes: the single- and dual-return loops apart.
    fn append_fixed<const N: usize>(
        &self,
        p: &LidarPacket<'_>,
        sweep_start_ns: u64,
        rd: &Readers,
        dual: bool,
        out: &mut Vec<Point>,
        columns: &mut Option<&mut Vec<u32>>,
    ) -> Decoded {
        if dual {
            self.append_returns::<N, true>(p, sweep_start_ns, rd, out, columns)
        } else {
            self.append_returns::<N, false>(p, sweep_start_ns, rd, out, columns)
        }
    }

    /// [`Self::decode`] for pixels of `N` bytes with one or two (`DUAL`) returns.
    #[inline(always)]
    fn append_returns<const N: usize, const DUAL: bool>(
        &self,
        p: &LidarPacket<'_>,
        sweep_start_ns: u64,
        rd: &Readers,
        out: &mut Vec<Point>,
        columns: &mut Option<&mut Vec<u32>>,
    ) -> Decoded {
        let mut n = Decoded::default();
        let h = self.h;
        let mut stage = [Point::default(); STAGE];
        for c in p.columns() {
            let Some(m) = self.column_index(&c, &mut n) else {
                continue;
            };
            let t = u64::from(column_time(c.timestamp_ns(), sweep_start_ns));
            let Some(lut) = self.lut.get(m * h..(m + 1) * h) else {
                continue;
            };
            let data = c.pixel_data();
            for (b0, b1) in blocks(h) {
                let (Some(lut), Some(tails)) = (lut.get(b0..b1), self.ring_tails.get(b0..b1))
                else {
                    break;
                };
                let pixels = data.get(b0 * N..).unwrap_or(&[]);
                let mut k = 0;
                for (i, (e, &ring)) in lut.iter().zip(tails).enumerate() {
                    let Some(px) = pixel::<N>(pixels, i) else {
                        break;
                    };
                    // At most STAGE writes per block (see `emit_returns`).
                    let range = rd.range.read(px);
                    let refl = rd.reflectivity.read(px) as u8;
                    stage[k % STAGE] = make_point(range, refl, e, t | ring);
                    k += usize::from(range != 0);
                    if DUAL {
                        let range = rd.range2.read(px);
                        let refl = rd.reflectivity2.read(px) as u8;
                        stage[k % STAGE] = make_point(range, refl, e, t | ring | RET1);
                        k += usize::from(range != 0);
                    }
                }
                let k = k.min(STAGE);
                out.extend_from_slice(&stage[..k]);
                if let Some(c) = columns.as_deref_mut() {
                    c.resize(c.len() + k, m as u32);
                }
                n.points += k;
            }
        }
        n
    }

    /// Counts a column and gives its measurement id when it holds data.
    #[inline]
    fn column_index(&self, c: &Column<'_>, n: &mut Decoded) -> Option<usize> {
        if !c.valid() {
            n.invalid_columns += 1;
            return None;
        }
        let m = usize::from(c.measurement_id());
        if m >= self.w {
            n.out_of_range_columns += 1;
            return None;
        }
        n.columns += 1;
        Some(m)
    }

    /// An empty frame in this decoder's dimensions (allocates; reuse it with
    /// [`OusterFrame::clear`]).
    pub fn new_frame(&self) -> OusterFrame {
        OusterFrame::new(self.h, self.w, self.returns(), self.shift.clone())
    }

    /// Writes one packet's valid columns into `frame`, in the sensor's staggered layout (the
    /// column of a pixel is its measurement id), as ouster-sdk's frame batcher does: invalid
    /// columns (status bit 0 clear) and columns with a measurement id ≥ W are not written, so
    /// they stay zero in a cleared frame. The first packet of a cleared frame sets its
    /// `frame_id` and header values; a packet of another `frame_id` is refused with
    /// [`DecodeError::FrameId`] (finish the frame, clear it, and give the packet again).
    pub fn decode_packet_into_frame(
        &self,
        p: &LidarPacket<'_>,
        frame: &mut OusterFrame,
    ) -> Result<Decoded, DecodeError> {
        self.check_format(p)?;
        if frame.rows != self.h || frame.columns != self.w || frame.returns != self.returns() {
            return Err(DecodeError::Format {
                expected: format!(
                    "a frame of {} × {} × {} returns",
                    self.h,
                    self.w,
                    self.returns()
                ),
                found: format!(
                    "a frame of {} × {} × {} returns",
                    frame.rows, frame.columns, frame.returns
                ),
            });
        }
        let fid = p.frame_id();
        match frame.frame_id {
            Some(id) if id != fid => {
                return Err(DecodeError::FrameId {
                    expected: id,
                    found: fid,
                })
            }
            Some(_) => {}
            None => {
                frame.frame_id = Some(fid);
                frame.init_id = p.init_id();
                frame.serial = p.serial();
                frame.thermal_shutdown = p.thermal_shutdown();
                frame.shot_limiting = p.shot_limiting();
                frame.countdown_thermal_shutdown = p.countdown_thermal_shutdown();
                frame.countdown_shot_limiting = p.countdown_shot_limiting();
            }
        }
        frame.packets += 1;
        frame.alert_flags |= p.alert_flags();
        let mut n = Decoded::default();
        match (self.readers, self.layout.pixel_bytes) {
            (Some(rd), 4) => self.frame_fixed::<4>(p, frame, &rd, &mut n),
            (Some(rd), 8) => self.frame_fixed::<8>(p, frame, &rd, &mut n),
            (Some(rd), 12) => self.frame_fixed::<12>(p, frame, &rd, &mut n),
            (Some(rd), 16) => self.frame_fixed::<16>(p, frame, &rd, &mut n),
            (Some(rd), 20) => self.frame_fixed::<20>(p, frame, &rd, &mut n),
            _ => self.frame_generic(p, frame, &mut n),
        }
        Ok(n)
    }

    /// Writes the column header values of valid column `m` into `frame`.
    #[inline(always)]
    fn frame_column(frame: &mut OusterFrame, c: &Column<'_>, m: usize) {
        frame.timestamp_ns[m] = c.timestamp_ns();
        frame.measurement_id[m] = m as u16;
        frame.status[m] = c.status();
    }

    /// Writes one return of one pixel (plane index `k`) into `frame`.
    #[inline(always)]
    fn frame_pixel(frame: &mut OusterFrame, k: usize, x: &Extra, e: &LutEntry, n: &mut Decoded) {
        frame.range_mm[k] = x.range_mm;
        frame.reflectivity[k] = x.reflectivity;
        frame.signal[k] = x.signal;
        frame.flags[k] = x.flags;
        if x.range_mm == 0 {
            frame.xyz[k] = [0.0; 3];
            frame.valid[k] = false;
        } else {
            frame.xyz[k] = point_of(x.range_mm, e.d3(), e.o3());
            frame.valid[k] = true;
            n.points += 1;
        }
    }

    /// [`Self::decode_packet_into_frame`] for pixels of `N` bytes (see [`Self::decode_with`]).
    fn frame_fixed<const N: usize>(
        &self,
        p: &LidarPacket<'_>,
        frame: &mut OusterFrame,
        rd: &Readers,
        n: &mut Decoded,
    ) {
        let (h, w) = (self.h, self.w);
        let plane = h * w;
        let dual = self.returns() == 2;
        for c in p.columns() {
            let Some(m) = self.column_index(&c, n) else {
                continue;
            };
            Self::frame_column(frame, &c, m);
            let Some(lut) = self.lut.get(m * h..(m + 1) * h) else {
                continue;
            };
            for (row, (px, e)) in c.pixel_data().chunks_exact(N).zip(lut).enumerate() {
                let Ok(px) = <&[u8; N]>::try_from(px) else {
                    continue;
                };
                let i = row * w + m;
                // The frame has no planes for the zone mask or colour: not read.
                let sh = Shared {
                    near_ir: rd.near_ir.read(px) as u16,
                    ..Shared::default()
                };
                frame.near_ir[i] = sh.near_ir;
                Self::frame_pixel(frame, i, &rd.extra::<N, false>(px, sh), e, n);
                if dual {
                    let x = rd.extra::<N, true>(px, sh);
                    Self::frame_pixel(frame, plane + i, &x, e, n);
                }
            }
        }
    }

    /// [`Self::decode_packet_into_frame`] through [`read_field_at`].
    fn frame_generic(&self, p: &LidarPacket<'_>, frame: &mut OusterFrame, n: &mut Decoded) {
        let (h, w) = (self.h, self.w);
        let plane = h * w;
        let returns = self.returns();
        for c in p.columns() {
            let Some(m) = self.column_index(&c, n) else {
                continue;
            };
            Self::frame_column(frame, &c, m);
            let lut = &self.lut[m * h..(m + 1) * h];
            let b = c.as_bytes();
            for (row, e) in lut.iter().enumerate() {
                let pix = self.pixel(b, c.pixel_offset(row));
                let i = row * w + m;
                frame.near_ir[i] = pix.r[0].near_ir;
                for (ret, x) in pix.r.iter().take(returns).enumerate() {
                    Self::frame_pixel(frame, ret * plane + i, x, e, n);
                }
            }
        }
    }
}

/// One frame as an organised image in the **sensor's staggered layout**: row 0 = beam 0 = the
/// top beam, column = measurement id; every pixel of a column shares the column's timestamp
/// but points at its own azimuth. [`Self::destagger`] gives the image a camera would show.
///
/// Pixel planes are indexed `(ret · H + row) · W + column` (`near_ir`: `row · W + column`);
/// column arrays by column. Columns that never arrived valid are all zero, as in ouster-sdk.
#[derive(Clone, Debug, PartialEq)]
pub struct OusterFrame {
    /// H, pixels per column.
    pub rows: usize,
    /// W, columns per frame.
    pub columns: usize,
    /// Returns per pixel (1 or 2).
    pub returns: usize,
    /// Whether the pixel planes are in the sensor's staggered layout (false after
    /// [`Self::destagger`]).
    pub staggered: bool,
    /// `pixel_shift_by_row` of the calibration.
    pub pixel_shift_by_row: Vec<i32>,
    /// `frame_id` of the packets (`None` until the first packet).
    pub frame_id: Option<u32>,
    /// Packets written.
    pub packets: usize,
    /// `init_id` of the first packet.
    pub init_id: u32,
    /// Serial of the first packet.
    pub serial: u64,
    /// `alert_flags` of every packet, or-ed.
    pub alert_flags: u8,
    /// Thermal shutdown status of the first packet.
    pub thermal_shutdown: u8,
    /// Shot limiting status of the first packet.
    pub shot_limiting: u8,
    /// `countdown_thermal_shutdown` of the first packet.
    pub countdown_thermal_shutdown: u8,
    /// `countdown_shot_limiting` of the first packet.
    pub countdown_shot_limiting: u8,
    /// Range, mm (returns × H × W).
    pub range_mm: Vec<u32>,
    /// Reflectivity (returns × H × W).
    pub reflectivity: Vec<u8>,
    /// Signal (returns × H × W; 0 where the profile has none).
    pub signal: Vec<u16>,
    /// Flags (returns × H × W).
    pub flags: Vec<u8>,
    /// Near-IR (H × W; 0 where the profile has none).
    pub near_ir: Vec<u16>,
    /// Sensor-frame point, metres (returns × H × W; zero where there is no point).
    pub xyz: Vec<[f32; 3]>,
    /// Whether the pixel is a point: its column arrived valid and its range is > 0
    /// (returns × H × W).
    pub valid: Vec<bool>,
    /// Column timestamps, ns (W; 0 where no valid column arrived).
    pub timestamp_ns: Vec<u64>,
    /// Measurement ids (W; 0 where no valid column arrived).
    pub measurement_id: Vec<u16>,
    /// Column status (W; 0 where no valid column arrived).
    pub status: Vec<u32>,
}

impl OusterFrame {
    /// An empty frame of H rows, W columns and `returns` returns (allocates).
    pub fn new(rows: usize, columns: usize, returns: usize, pixel_shift_by_row: Vec<i32>) -> Self {
        let px = rows * columns;
        let all = px * returns;
        Self {
            rows,
            columns,
            returns,
            staggered: true,
            pixel_shift_by_row,
            frame_id: None,
            packets: 0,
            init_id: 0,
            serial: 0,
            alert_flags: 0,
            thermal_shutdown: 0,
            shot_limiting: 0,
            countdown_thermal_shutdown: 0,
            countdown_shot_limiting: 0,
            range_mm: vec![0; all],
            reflectivity: vec![0; all],
            signal: vec![0; all],
            flags: vec![0; all],
            near_ir: vec![0; px],
            xyz: vec![[0.0; 3]; all],
            valid: vec![false; all],
            timestamp_ns: vec![0; columns],
            measurement_id: vec![0; columns],
            status: vec![0; columns],
        }
    }

    /// Zeroes every value for the next frame, keeping the buffers (and the layout flag reset
    /// to staggered).
    pub fn clear(&mut self) {
        self.staggered = true;
        self.frame_id = None;
        self.packets = 0;
        self.init_id = 0;
        self.serial = 0;
        self.alert_flags = 0;
        self.thermal_shutdown = 0;
        self.shot_limiting = 0;
        self.countdown_thermal_shutdown = 0;
        self.countdown_shot_limiting = 0;
        self.range_mm.fill(0);
        self.reflectivity.fill(0);
        self.signal.fill(0);
        self.flags.fill(0);
        self.near_ir.fill(0);
        self.xyz.fill([0.0; 3]);
        self.valid.fill(false);
        self.timestamp_ns.fill(0);
        self.measurement_id.fill(0);
        self.status.fill(0);
    }

    /// Index of pixel (ret, row, column) in the pixel planes (`None` outside the frame).
    #[inline]
    pub fn index(&self, ret: usize, row: usize, column: usize) -> Option<usize> {
        (ret < self.returns && row < self.rows && column < self.columns)
            .then(|| (ret * self.rows + row) * self.columns + column)
    }

    /// Whether column `c` arrived valid (status bit 0).
    pub fn column_valid(&self, c: usize) -> bool {
        self.status.get(c).is_some_and(|s| s & 1 != 0)
    }

    /// Valid columns.
    pub fn valid_columns(&self) -> usize {
        self.status.iter().filter(|&&s| s & 1 != 0).count()
    }

    /// Points (pixels with range > 0 in valid columns) of return `ret`.
    pub fn points(&self, ret: usize) -> usize {
        let plane = self.rows * self.columns;
        self.valid
            .get(ret * plane..(ret + 1) * plane)
            .map_or(0, |v| v.iter().filter(|&&b| b).count())
    }

    /// The destaggered image (allocates): every pixel plane with row `u` moved right by
    /// `pixel_shift_by_row[u]` (mod W), FORMATS.md §5.2 / ouster-sdk `destagger`:
    /// `destaggered[u][(v + shift[u]) mod W] = staggered[u][v]`. Column arrays are unchanged
    /// (they describe the staggered columns; see [`Self::pixel_timestamp_ns`]). A frame that
    /// is already destaggered is returned as it is.
    pub fn destagger(&self) -> OusterFrame {
        if !self.staggered {
            return self.clone();
        }
        let mut out = self.clone();
        let (w, s) = (self.columns, &self.pixel_shift_by_row);
        destagger_into(&self.range_mm, &mut out.range_mm, w, s);
        destagger_into(&self.reflectivity, &mut out.reflectivity, w, s);
        destagger_into(&self.signal, &mut out.signal, w, s);
        destagger_into(&self.flags, &mut out.flags, w, s);
        destagger_into(&self.near_ir, &mut out.near_ir, w, s);
        destagger_into(&self.xyz, &mut out.xyz, w, s);
        destagger_into(&self.valid, &mut out.valid, w, s);
        out.staggered = false;
        out
    }

    /// Timestamp of pixel (row, column) in the current layout: in a staggered frame the
    /// column's; in a destaggered one `ts[(v − shift[u]) mod W]` (ouster-sdk
    /// `column_timestamp_at_destaggered_pixel`). `None` outside the frame.
    pub fn pixel_timestamp_ns(&self, row: usize, column: usize) -> Option<u64> {
        if row >= self.rows || column >= self.columns {
            return None;
        }
        if self.staggered {
            return self.timestamp_ns.get(column).copied();
        }
        let w = self.columns as i64;
        let s = i64::from(self.pixel_shift_by_row.get(row).copied().unwrap_or(0));
        let v = (column as i64 - s).rem_euclid(w) as usize;
        self.timestamp_ns.get(v).copied()
    }
}

/// Destaggers image planes of width `w` (any number of rows, planes stacked: row `r` of the
/// buffer uses `shift[r mod shift.len()]`): `dst[u][(v + shift[u]) mod W] = src[u][v]`.
/// Rows beyond the shorter of `src` and `dst` are left alone; an empty `shift` copies.
pub fn destagger_into<T: Copy>(src: &[T], dst: &mut [T], w: usize, shift: &[i32]) {
    if w == 0 {
        return;
    }
    for (r, (s, d)) in src.chunks_exact(w).zip(dst.chunks_exact_mut(w)).enumerate() {
        let k = if shift.is_empty() {
            0
        } else {
            i64::from(shift[r % shift.len()]).rem_euclid(w as i64) as usize
        };
        // dst[(v + k) mod w] = src[v]
        d[k..].copy_from_slice(&s[..w - k]);
        d[..k].copy_from_slice(&s[w - k..]);
    }
}

#[inline]
fn point_of(range_mm: u32, d: [f32; 3], o: [f32; 3]) -> [f32; 3] {
    let r = range_mm as f32;
    [r * d[0] + o[0], r * d[1] + o[1], r * d[2] + o[2]]
}

/// Rows of a column decoded per block by the fixed-size loops.
const BLOCK_ROWS: usize = 128;
/// Points held per block: two returns of [`BLOCK_ROWS`] rows.
const STAGE: usize = 2 * BLOCK_ROWS;

/// The row ranges `[b0, b1)` of the blocks of a column of `h` rows. Index ranges rather than
/// `chunks().zip()`: the zip of chunk iterators was not inlined and divided by the chunk size
/// at run time, four divisions a column, 9 % of the decoding thread (perf, 128-row columns).
#[inline]
fn blocks(h: usize) -> impl Iterator<Item = (usize, usize)> {
    (0..h.div_ceil(BLOCK_ROWS)).map(move |b| (b * BLOCK_ROWS, ((b + 1) * BLOCK_ROWS).min(h)))
}

/// Pixel `i` of a block's pixel bytes, if they hold it whole.
#[inline(always)]
fn pixel<const N: usize>(pixels: &[u8], i: usize) -> Option<&[u8; N]> {
    pixels.get(i * N..i * N + N)?.try_into().ok()
}

/// `ret` = 1 in the last word of a [`PointWords`].
const RET1: u64 = 1 << 48;

/// The point of a return of range `range_mm` and reflectivity `refl` at a pixel whose table
/// entry is `e`; `tail` = `t | ring << 32 | ret << 48` (the last 8 bytes of the record).
///
/// x, y, z and the intensity are one 4-wide multiply-add (`[r, r, r, refl] · dir + off`,
/// the same rounding as [`point_of`] lane by lane) and the record is written as two words: the
/// stores of the points are much of what the decoder's loop costs (BENCHMARKS.md, "Ouster").
#[inline(always)]
fn make_point(range_mm: u32, refl: u8, e: &LutEntry, tail: u64) -> Point {
    let r = range_mm as f32;
    let m = [r, r, r, f32::from(refl)];
    let mut xyzi = [0f32; 4];
    for (((v, m), d), o) in xyzi.iter_mut().zip(m).zip(e.dir).zip(e.off) {
        *v = m * d + o;
    }
    if cfg!(target_endian = "little") {
        bytemuck::cast(PointWords { xyzi, tail })
    } else {
        Point {
            x: xyzi[0],
            y: xyzi[1],
            z: xyzi[2],
            intensity: xyzi[3],
            t: tail as u32,
            ring: (tail >> 32) as u16,
            ret: (tail >> 48) as u8,
            pad: 0,
        }
    }
}

/// `t` of a column: its timestamp − the sweep start, clamped to `0..=u32::MAX` ns.
#[inline(always)]
fn column_time(timestamp_ns: u64, sweep_start_ns: u64) -> u32 {
    timestamp_ns
        .saturating_sub(sweep_start_ns)
        .min(u64::from(u32::MAX)) as u32
}

/// Ring of each row: rank of the altitude, 0 = lowest; equal altitudes: the higher row index
/// (lower in the image) gets the lower ring.
fn rings_by_altitude(alt: &[f64]) -> Vec<u16> {
    let mut order: Vec<usize> = (0..alt.len()).collect();
    order.sort_by(|&a, &b| alt[a].total_cmp(&alt[b]).then(b.cmp(&a)));
    let mut rings = vec![0u16; alt.len()];
    for (rank, &row) in order.iter().enumerate() {
        rings[row] = rank as u16;
    }
    rings
}

/// ouster-sdk `make_xyz_lut` (OS sensors, `use_extrinsics = false`), column-major.
fn xyz_lut(
    w: usize,
    alt_deg: &[f64],
    az_deg: &[f64],
    b2l: &[f64; 16],
    l2s: &[f64; 16],
) -> Arc<[LutEntry]> {
    use core::f64::consts::PI;
    let h = alt_deg.len();
    let n = b2l[3];
    let bz = b2l[11];
    let n_e = if bz != 0.0 { n.hypot(bz) } else { n };
    let rot = |v: [f64; 3]| {
        [
            l2s[0] * v[0] + l2s[1] * v[1] + l2s[2] * v[2],
            l2s[4] * v[0] + l2s[5] * v[1] + l2s[6] * v[2],
            l2s[8] * v[0] + l2s[9] * v[1] + l2s[10] * v[2],
        ]
    };
    let t = [l2s[3], l2s[7], l2s[11]];
    let step = 2.0 * PI / w as f64;
    // The beams' angles once, and sin/cos of (encoder + beam azimuth) by the angle-sum rule:
    // w + 2h sine pairs instead of 2wh (4 ms of every Ouster open of a 128 × 1024 sensor);
    // the difference, ~1e-16, is far below the f32 the table is kept in.
    let beams: Vec<((f64, f64), (f64, f64))> = az_deg
        .iter()
        .zip(alt_deg)
        .map(|(&az, &alt)| ((-az * PI / 180.0).sin_cos(), (alt * PI / 180.0).sin_cos()))
        .collect();
    let encoders: Vec<(f64, f64)> = (0..w)
        .map(|v| (2.0 * PI - v as f64 * step).sin_cos())
        .collect();
    // Entry i is (column i / h, beam i % h), walked in order. A map over a range has a known
    // length, so the shared table is written where it stays: collecting into a Vec and
    // converting copied its 4 MiB (128 × 1024) once more, onto fresh pages.
    let (mut v, mut b) = (0usize, 0usize);
    (0..w * h)
        .map(|_| {
            let (se, ce) = encoders.get(v).copied().unwrap_or((0.0, 1.0));
            let ((sb, cb), (sp, cp)) = beams.get(b).copied().unwrap_or(((0.0, 1.0), (0.0, 1.0)));
            b += 1;
            if b == h {
                (v, b) = (v + 1, 0);
            }
            let (sa, ca) = (se * cb + ce * sb, ce * cb - se * sb);
            let dir = [ca * cp, sa * cp, sp];
            let off = [
                ce * n - dir[0] * n_e,
                se * n - dir[1] * n_e,
                -dir[2] * n_e + bz,
            ];
            let d = rot(dir);
            let o = rot(off);
            LutEntry {
                dir: [
                    (d[0] * 1e-3) as f32,
                    (d[1] * 1e-3) as f32,
                    (d[2] * 1e-3) as f32,
                    1.0,
                ],
                off: [
                    ((o[0] + t[0]) * 1e-3) as f32,
                    ((o[1] + t[1]) * 1e-3) as f32,
                    ((o[2] + t[2]) * 1e-3) as f32,
                    0.0,
                ],
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const IDENTITY: [f64; 16] = [
        1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
    ];

    fn close(a: [f32; 3], b: [f64; 3], tol: f64) -> bool {
        (0..3).all(|i| (f64::from(a[i]) - b[i]).abs() <= tol)
    }

    #[test]
    fn encoder_angle_runs_clockwise_from_column_zero() {
        // No beam offset, identity transforms: column 0 looks along +x, column W/4 along −y
        // (θe = 2π − 2π·v/W), column W/2 along −x.
        let lut = xyz_lut(4, &[0.0], &[0.0], &IDENTITY, &IDENTITY);
        let p = |v: usize, r: u32| point_of(r, lut[v].d3(), lut[v].o3());
        assert!(close(p(0, 1000), [1.0, 0.0, 0.0], 1e-6));
        assert!(close(p(1, 1000), [0.0, -1.0, 0.0], 1e-6));
        assert!(close(p(2, 2000), [-2.0, 0.0, 0.0], 1e-6));
        assert!(close(p(3, 1000), [0.0, 1.0, 0.0], 1e-6));
    }

    #[test]
    fn beam_origin_offset_follows_the_legacy_guide_formula() {
        // x = (r − n)·cos(θe+θa)·cosφ + n·cosθe, z = (r − n)·sinφ (lidar frame), here with
        // θe = 0, θa = −10°, φ = 30°, n = 15.806 mm, r = 5000 mm, then the default
        // lidar_to_sensor transform diag(−1, −1, 1) + 36.18 mm in z.
        let mut b2l = IDENTITY;
        b2l[3] = 15.806;
        let mut l2s = IDENTITY;
        l2s[0] = -1.0;
        l2s[5] = -1.0;
        l2s[11] = 36.18;
        let lut = xyz_lut(1024, &[30.0], &[10.0], &b2l, &l2s);
        let (r, n) = (5000.0f64, 15.806f64);
        let (a, phi) = ((-10.0f64).to_radians(), 30.0f64.to_radians());
        let x = (r - n) * a.cos() * phi.cos() + n;
        let y = (r - n) * a.sin() * phi.cos();
        let z = (r - n) * phi.sin();
        let want = [-x * 1e-3, -y * 1e-3, (z + 36.18) * 1e-3];
        assert!(close(point_of(5000, lut[0].d3(), lut[0].o3()), want, 1e-6));
    }

    #[test]
    fn beam_to_lidar_z_offset_uses_the_euclidean_distance() {
        // b[0][3] = 3, b[2][3] = 4 → n_e = 5; φ = 0, θa = 0, column 0:
        // x = r − 5 + 3, z = 4 (mm).
        let mut b2l = IDENTITY;
        b2l[3] = 3.0;
        b2l[11] = 4.0;
        let lut = xyz_lut(8, &[0.0], &[0.0], &b2l, &IDENTITY);
        assert!(close(
            point_of(1000, lut[0].d3(), lut[0].o3()),
            [0.998, 0.0, 0.004],
            1e-7
        ));
    }

    /// Pixel bytes of `n` bytes from a simple xorshift generator.
    fn noise(seed: &mut u64, n: usize) -> Vec<u8> {
        (0..n)
            .map(|_| {
                *seed ^= *seed << 13;
                *seed ^= *seed >> 7;
                *seed ^= *seed << 17;
                *seed as u8
            })
            .collect()
    }

    fn fixed_reads_equal_generic<const N: usize>(l: &Layout, rd: &Readers, seed: &mut u64) {
        let fields = [
            (Some(l.range), rd.range),
            (l.flags, rd.flags),
            (Some(l.reflectivity), rd.reflectivity),
            (l.signal, rd.signal),
            (l.near_ir, rd.near_ir),
            (l.range2, rd.range2),
            (l.flags2, rd.flags2),
            (l.reflectivity2, rd.reflectivity2),
            (l.signal2, rd.signal2),
        ];
        for _ in 0..200 {
            let px = noise(seed, N);
            let arr: &[u8; N] = px.as_slice().try_into().unwrap();
            for (f, r) in fields {
                let want = f.map_or(0, |f| read_field_at(&px, 0, f));
                assert_eq!(r.read(arr), want, "{f:?} {r:?} {px:?}");
            }
        }
    }

    #[test]
    fn fixed_field_readers_serve_every_profile_and_read_as_the_generic_path() {
        let mut seed = 0x9E37_79B9_7F4A_7C15u64;
        for p in crate::sensor::ouster::model::ALL_PROFILES {
            let l = p.layout();
            let rd = Readers::new(&l).unwrap_or_else(|| panic!("{p}: no fixed readers"));
            match l.pixel_bytes {
                4 => fixed_reads_equal_generic::<4>(&l, &rd, &mut seed),
                8 => fixed_reads_equal_generic::<8>(&l, &rd, &mut seed),
                12 => fixed_reads_equal_generic::<12>(&l, &rd, &mut seed),
                16 => fixed_reads_equal_generic::<16>(&l, &rd, &mut seed),
                20 => fixed_reads_equal_generic::<20>(&l, &rd, &mut seed),
                n => panic!("{p}: pixels of {n} bytes have no fixed loop"),
            }
        }
    }

    #[test]
    fn field_readers_refuse_what_one_load_cannot_hold() {
        let f = |bit, width| {
            Some(Field {
                bit,
                width,
                shift: 0,
            })
        };
        assert!(FieldReader::new(f(0, 32), 4).is_some());
        assert!(FieldReader::new(f(4, 32), 8).is_none());
        assert!(FieldReader::new(f(0, 8), 3).is_none());
        assert_eq!(FieldReader::new(None, 4), Some(FieldReader::default()));
    }

    #[test]
    fn rings_rank_altitudes_lowest_first() {
        assert_eq!(
            rings_by_altitude(&[10.0, 5.0, -1.0, -7.5]),
            vec![3, 2, 1, 0]
        );
        assert_eq!(rings_by_altitude(&[1.0, 3.0, 2.0]), vec![0, 2, 1]);
        // Equal altitudes: the lower row of the image gets the lower ring.
        assert_eq!(rings_by_altitude(&[2.0, 2.0, 0.0]), vec![2, 1, 0]);
    }

    #[test]
    fn destagger_moves_each_row_by_its_shift() {
        // dst[u][(v + s[u]) mod W] = src[u][v]
        let src: Vec<u32> = (0..8).collect(); // two rows of four
        let mut dst = vec![0; 8];
        destagger_into(&src, &mut dst, 4, &[1, -1]);
        assert_eq!(dst, vec![3, 0, 1, 2, 5, 6, 7, 4]);
        destagger_into(&src, &mut dst, 4, &[4, 9]);
        assert_eq!(dst, vec![0, 1, 2, 3, 7, 4, 5, 6]);
    }

    #[test]
    fn frame_pixel_timestamps_after_destagger() {
        let mut f = OusterFrame::new(2, 4, 1, vec![1, -1]);
        f.timestamp_ns = vec![10, 20, 30, 40];
        f.range_mm = (1..=8).collect();
        let d = f.destagger();
        assert!(!d.staggered);
        assert_eq!(d.range_mm, vec![4, 1, 2, 3, 6, 7, 8, 5]);
        // Destaggered pixel (0, 1) came from staggered column 0, (1, 3) from column 0 too.
        assert_eq!(d.pixel_timestamp_ns(0, 1), Some(10));
        assert_eq!(d.pixel_timestamp_ns(1, 3), Some(10));
        assert_eq!(f.pixel_timestamp_ns(1, 3), Some(40));
        assert_eq!(d.pixel_timestamp_ns(2, 0), None);
    }
}
