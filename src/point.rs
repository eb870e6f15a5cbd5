//! The one point record every decoder emits and every sink writes.
//!
//! Layout (24 bytes, little-endian on the wire, `#[repr(C)]`):
//!
//! | offset | field       | type | meaning |
//! |--------|-------------|------|---------|
//! | 0      | `x`         | f32  | metres, sensor frame (REP 103: x forward, y left, z up) |
//! | 4      | `y`         | f32  | metres |
//! | 8      | `z`         | f32  | metres |
//! | 12     | `intensity` | f32  | raw reflectivity the sensor sent (Velodyne byte, Ouster REFLECTIVITY) |
//! | 16     | `t`         | u32  | ns since the sweep's timestamp (its first firing); never negative |
//! | 20     | `ring`      | u16  | rank of the channel's elevation angle, 0 = lowest |
//! | 22     | `ret`       | u8   | return index: 0 = strongest / only / first, 1 = last / second |
//! | 23     | padding     | u8   | 0; Livox points: the point's tag byte (confidence / noise flags) |
//!
//! The MCAP sink writes a `&[Point]` as bytes without per-point conversion, so the field
//! order here is the order of the `foxglove.PointCloud` fields.

use bytemuck::{Pod, Zeroable};

/// One measured point. See the module documentation for units and conventions.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Point {
    /// Metres, forward.
    pub x: f32,
    /// Metres, left.
    pub y: f32,
    /// Metres, up.
    pub z: f32,
    /// Raw reflectivity as sent by the sensor (0..=255 for Velodyne).
    pub intensity: f32,
    /// Nanoseconds since the sweep's timestamp.
    pub t: u32,
    /// Rank of the channel's elevation angle, 0 = lowest.
    pub ring: u16,
    /// Return index: 0 = strongest / only / first, 1 = last / second.
    pub ret: u8,
    /// Padding: 0, except for Livox points, where it keeps the record's tag byte
    /// (confidence / noise flags; `sensor::livox`).
    pub pad: u8,
}

/// Values some sensors measure beyond the [`Point`] record (Ouster: range, signal, near-IR,
/// the zone mask and colour of the profiles that carry them), kept per point in a parallel
/// buffer when asked for (`--fields all`). A value the sensor does not send is 0.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PointExtra {
    /// Range, mm.
    pub range_mm: u32,
    /// Signal photons.
    pub signal: u16,
    /// Near-infrared (ambient) photons.
    pub near_ir: u16,
    /// Zone-occupancy mask: bit `i` set when the point lies in zone `i` (Ouster ZONE16).
    pub zones: u16,
    /// Padding, 0.
    pub pad: u16,
    /// Red, as the sensor measured it (Ouster RGB16: its half float, widened exactly).
    pub red: f32,
    /// Green.
    pub green: f32,
    /// Blue.
    pub blue: f32,
}

/// Stride of the extended record written with `--fields all`: a [`Point`] then a
/// [`PointExtra`].
pub const EXTENDED_STRIDE: usize = POINT_STRIDE + core::mem::size_of::<PointExtra>();

const _: () = assert!(EXTENDED_STRIDE == 48);

/// Fields of the extended record, in record order (the [`POINT_FIELDS`] first).
pub const EXTENDED_FIELDS: [(&str, usize, FieldType); 14] = [
    ("x", 0, FieldType::F32),
    ("y", 4, FieldType::F32),
    ("z", 8, FieldType::F32),
    ("intensity", 12, FieldType::F32),
    ("t", 16, FieldType::U32),
    ("ring", 20, FieldType::U16),
    ("return", 22, FieldType::U8),
    ("range", 24, FieldType::U32),
    ("signal", 28, FieldType::U16),
    ("near_ir", 30, FieldType::U16),
    ("zones", 32, FieldType::U16),
    ("red", 36, FieldType::F32),
    ("green", 40, FieldType::F32),
    ("blue", 44, FieldType::F32),
];

/// The f32 of an IEEE half float's bits.
pub fn half_to_f32(bits: u16) -> f32 {
    half::f16::from_bits(bits).to_f32()
}

/// Interleaves points and their extras into extended records (`out` is cleared first).
pub fn interleave_extended(points: &[Point], extras: &[PointExtra], out: &mut Vec<u8>) {
    out.clear();
    out.reserve(points.len() * EXTENDED_STRIDE);
    let zero = PointExtra::default();
    for (i, p) in points.iter().enumerate() {
        out.extend_from_slice(bytemuck::bytes_of(p));
        out.extend_from_slice(bytemuck::bytes_of(extras.get(i).unwrap_or(&zero)));
    }
}

/// Size of one [`Point`] in bytes (the point stride in every sink).
pub const POINT_STRIDE: usize = core::mem::size_of::<Point>();

const _: () = assert!(POINT_STRIDE == 24);

#[cfg(target_endian = "big")]
compile_error!(
    "ringscan writes point buffers as little-endian bytes; big-endian targets are not supported"
);

/// Byte offsets and types of the point fields, in record order, for sinks that describe them.
pub const POINT_FIELDS: [(&str, usize, FieldType); 7] = [
    ("x", 0, FieldType::F32),
    ("y", 4, FieldType::F32),
    ("z", 8, FieldType::F32),
    ("intensity", 12, FieldType::F32),
    ("t", 16, FieldType::U32),
    ("ring", 20, FieldType::U16),
    ("return", 22, FieldType::U8),
];

/// Stride of the minimal record written with `--fields minimal`: x, y, z, intensity.
pub const MINIMAL_STRIDE: usize = 16;

/// Fields of the minimal record: the first four of [`POINT_FIELDS`], at the same offsets.
pub const MINIMAL_FIELDS: [(&str, usize, FieldType); 4] = [
    ("x", 0, FieldType::F32),
    ("y", 4, FieldType::F32),
    ("z", 8, FieldType::F32),
    ("intensity", 12, FieldType::F32),
];

/// Appends the minimal records (x, y, z, intensity: the first [`MINIMAL_STRIDE`] bytes of each
/// point) to `out`.
pub fn extend_minimal(points: &[Point], out: &mut Vec<u8>) {
    out.reserve(points.len() * MINIMAL_STRIDE);
    for p in points {
        out.extend_from_slice(&bytemuck::bytes_of(p)[..MINIMAL_STRIDE]);
    }
}

/// Scalar type of a point field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FieldType {
    /// 8-bit unsigned integer.
    U8,
    /// 16-bit unsigned integer.
    U16,
    /// 32-bit unsigned integer.
    U32,
    /// 32-bit IEEE float.
    F32,
}

/// Views a point slice as the bytes a sink writes (no copy).
pub fn as_bytes(points: &[Point]) -> &[u8] {
    bytemuck::cast_slice(points)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_matches_the_documented_offsets() {
        let p = Point {
            x: 1.0,
            y: 2.0,
            z: 3.0,
            intensity: 4.0,
            t: 0x0102_0304,
            ring: 0x0506,
            ret: 7,
            pad: 0,
        };
        let b = as_bytes(core::slice::from_ref(&p));
        assert_eq!(b.len(), 24);
        assert_eq!(&b[0..4], &1.0f32.to_le_bytes());
        assert_eq!(&b[12..16], &4.0f32.to_le_bytes());
        assert_eq!(&b[16..20], &0x0102_0304u32.to_le_bytes());
        assert_eq!(&b[20..22], &0x0506u16.to_le_bytes());
        assert_eq!(b[22], 7);
        for (name, off, _) in POINT_FIELDS {
            assert!(off < POINT_STRIDE, "{name}");
        }
    }

    /// Each extended field's offset and type hold the value `interleave_extended` wrote there.
    #[test]
    fn extended_fields_describe_the_interleaved_record() {
        let p = Point {
            x: 1.5,
            ret: 1,
            ..Point::default()
        };
        let e = PointExtra {
            range_mm: 0x0A0B_0C0D,
            signal: 0x1112,
            near_ir: 0x2122,
            zones: 0x3132,
            pad: 0,
            red: 0.25,
            green: half_to_f32(0x3C00),
            blue: half_to_f32(0xC000),
        };
        let mut out = Vec::new();
        interleave_extended(&[p, p], &[e], &mut out);
        assert_eq!(out.len(), 2 * EXTENDED_STRIDE);
        let want: [(&str, u64); 7] = [
            ("range", 0x0A0B_0C0D),
            ("signal", 0x1112),
            ("near_ir", 0x2122),
            ("zones", 0x3132),
            ("red", u64::from(0.25f32.to_bits())),
            ("green", u64::from(1.0f32.to_bits())),
            ("blue", u64::from((-2.0f32).to_bits())),
        ];
        let read = |rec: &[u8], off: usize, t: FieldType| -> u64 {
            let n = match t {
                FieldType::U8 => 1,
                FieldType::U16 => 2,
                FieldType::U32 | FieldType::F32 => 4,
            };
            rec[off..off + n]
                .iter()
                .rev()
                .fold(0, |a, &b| (a << 8) | u64::from(b))
        };
        for (name, v) in want {
            let (_, off, t) = EXTENDED_FIELDS.iter().find(|f| f.0 == name).unwrap();
            assert_eq!(read(&out, *off, *t), v, "{name}");
            // The second point has no extras: zeros.
            assert_eq!(read(&out[EXTENDED_STRIDE..], *off, *t), 0, "{name}");
        }
        assert_eq!(read(&out, 0, FieldType::F32), u64::from(1.5f32.to_bits()));
        assert_eq!(read(&out, 22, FieldType::U8), 1);
    }
}
