//! ROS 2 encoding: `sensor_msgs/msg/PointCloud2` in CDR with its `ros2msg` schema.
//!
//! CDR here is XCDR1 little-endian ("CDR_LE"): the 4-byte encapsulation header `00 01 00 00`,
//! then each primitive aligned to its own size counted from the end of that header; strings
//! are a `uint32` length that includes a terminating NUL, the bytes and the NUL; sequences are a
//! `uint32` element count followed by the elements.
//!
//! The schema text follows the `ros2msg` encoding rosbag2 writes (rosbag2
//! `docs/message_definition_encoding.md` and `LocalMessageDefinitionSource`): the top-level
//! definition first, then each dependency preceded by a line of 80 `=` and a line
//! `MSG: <package>/<Type>`, dependencies in sorted order, depth first. Field lists are those of
//! `sensor_msgs/msg/PointCloud2.msg`, `sensor_msgs/msg/PointField.msg`,
//! `std_msgs/msg/Header.msg` and `builtin_interfaces/msg/Time.msg` (ros2/common_interfaces,
//! ros2/rcl_interfaces).

use crate::point::{FieldType, Point, POINT_FIELDS, POINT_STRIDE};

/// Schema name of the points channel in `--format ros2`.
pub const POINT_CLOUD2_SCHEMA: &str = "sensor_msgs/msg/PointCloud2";

/// Largest `data` length written (readers commonly refuse messages of 2 GiB and more).
pub const MAX_DATA_LEN: usize = i32::MAX as usize - 4096 - MAX_FRAME_ID_LEN;

/// Longest `frame_id` written.
pub const MAX_FRAME_ID_LEN: usize = 4096;

pub(crate) const SEPARATOR: &str =
    "================================================================================\n";

const POINT_CLOUD2_MSG: &str = "\
# A collection of N-dimensional points. The point layout is given by `fields`;
# a cloud with height 1 is unordered, otherwise it is organised in rows.
std_msgs/Header header

uint32 height
uint32 width

PointField[] fields

bool    is_bigendian # Is this data bigendian?
uint32  point_step   # Length of a point in bytes
uint32  row_step     # Length of a row in bytes
uint8[] data         # Actual point data, size is (row_step*height)

bool is_dense        # True if there are no invalid points
";

const POINT_FIELD_MSG: &str = "\
# One field of a point in a PointCloud2.
uint8 INT8    = 1
uint8 UINT8   = 2
uint8 INT16   = 3
uint8 UINT16  = 4
uint8 INT32   = 5
uint8 UINT32  = 6
uint8 FLOAT32 = 7
uint8 FLOAT64 = 8

string name      # Name of field
uint32 offset    # Offset from start of point struct
uint8  datatype  # Datatype enumeration, see above
uint32 count     # How many elements in the field
";

pub(crate) const HEADER_MSG: &str = "\
# Standard metadata for higher-level stamped data types.
builtin_interfaces/Time stamp

# Transform frame with which this data is associated.
string frame_id
";

pub(crate) const TIME_MSG: &str = "\
# Time since the epoch: seconds and nanoseconds in [0, 1e9).
int32 sec
uint32 nanosec
";

/// The `ros2msg` schema data of [`POINT_CLOUD2_SCHEMA`].
pub fn point_cloud2_schema_text() -> String {
    let mut s = String::with_capacity(2048);
    s.push_str(POINT_CLOUD2_MSG);
    for (name, text) in [
        ("sensor_msgs/PointField", POINT_FIELD_MSG),
        ("std_msgs/Header", HEADER_MSG),
        ("builtin_interfaces/Time", TIME_MSG),
    ] {
        s.push('\n');
        s.push_str(SEPARATOR);
        s.push_str("MSG: ");
        s.push_str(name);
        s.push('\n');
        s.push_str(text);
    }
    s
}

/// `sensor_msgs/msg/PointField` datatype constants.
pub mod datatype {
    /// `INT8`
    pub const INT8: u8 = 1;
    /// `UINT8`
    pub const UINT8: u8 = 2;
    /// `INT16`
    pub const INT16: u8 = 3;
    /// `UINT16`
    pub const UINT16: u8 = 4;
    /// `INT32`
    pub const INT32: u8 = 5;
    /// `UINT32`
    pub const UINT32: u8 = 6;
    /// `FLOAT32`
    pub const FLOAT32: u8 = 7;
    /// `FLOAT64`
    pub const FLOAT64: u8 = 8;
}

fn datatype_of(t: FieldType) -> u8 {
    match t {
        FieldType::U8 => datatype::UINT8,
        FieldType::U16 => datatype::UINT16,
        FieldType::U32 => datatype::UINT32,
        FieldType::F32 => datatype::FLOAT32,
    }
}

/// Why a sweep cannot be encoded as a `PointCloud2`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ros2EncodeError {
    /// `builtin_interfaces/Time.sec` is an `int32`: the timestamp is past 2038-01-19.
    TimestampOutOfRange,
    /// The point data would be longer than [`MAX_DATA_LEN`], or the frame id longer than
    /// [`MAX_FRAME_ID_LEN`].
    TooLarge,
}

/// CDR little-endian writer over a caller's buffer.
pub(crate) struct Cdr<'a> {
    pub(crate) buf: &'a mut Vec<u8>,
    /// Index in `buf` where alignment is counted from (just after the encapsulation header).
    origin: usize,
}

impl<'a> Cdr<'a> {
    pub(crate) fn new(buf: &'a mut Vec<u8>) -> Self {
        // Encapsulation: representation identifier CDR_LE (0x0001), options 0.
        buf.extend_from_slice(&[0x00, 0x01, 0x00, 0x00]);
        let origin = buf.len();
        Self { buf, origin }
    }
    pub(crate) fn align(&mut self, n: usize) {
        let rem = (self.buf.len() - self.origin) % n;
        if rem != 0 {
            self.buf.resize(self.buf.len() + n - rem, 0);
        }
    }
    pub(crate) fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }
    pub(crate) fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    pub(crate) fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    pub(crate) fn f32(&mut self, v: f32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    pub(crate) fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// `builtin_interfaces/Time` (or `Duration`) of `ns` nanoseconds; `None` past `int32` seconds.
    pub(crate) fn time(&mut self, ns: u64) -> Option<()> {
        let sec = i32::try_from(ns / 1_000_000_000).ok()?;
        self.i32(sec);
        self.u32((ns % 1_000_000_000) as u32);
        Some(())
    }
    /// A `uint8[]` sequence; callers keep it under 4 GiB.
    pub(crate) fn bytes(&mut self, b: &[u8]) {
        self.u32(b.len() as u32);
        self.buf.extend_from_slice(b);
    }
    /// Callers keep strings short (see [`MAX_FRAME_ID_LEN`]), so the length fits `u32`.
    pub(crate) fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }
}

/// Encodes one `sensor_msgs/msg/PointCloud2` (CDR, with encapsulation header) into `buf`
/// (cleared first): an unordered cloud (height 1, width = number of points), little-endian,
/// `point_step` 24, dense, fields from [`POINT_FIELDS`].
///
/// `frame_id` must not contain NUL (the sink checks names when a sensor is added);
/// `timestamp_ns` must fit `int32` seconds.
pub fn encode_point_cloud2(
    buf: &mut Vec<u8>,
    timestamp_ns: u64,
    frame_id: &str,
    points: &[Point],
) -> Result<(), Ros2EncodeError> {
    encode_point_cloud2_fields(
        buf,
        timestamp_ns,
        frame_id,
        POINT_STRIDE,
        &POINT_FIELDS,
        crate::point::as_bytes(points),
    )
}

/// [`encode_point_cloud2`] for records of `stride` bytes laid out as `fields` describes.
pub fn encode_point_cloud2_fields(
    buf: &mut Vec<u8>,
    timestamp_ns: u64,
    frame_id: &str,
    stride: usize,
    fields: &[(&str, usize, FieldType)],
    data: &[u8],
) -> Result<(), Ros2EncodeError> {
    buf.clear();
    append_point_cloud2_with(
        buf,
        timestamp_ns,
        frame_id,
        stride,
        fields,
        data.len(),
        |b| b.extend_from_slice(data),
    )
}

/// Appends one `PointCloud2` to `buf` (not cleared: the MCAP sink encodes into the chunk
/// itself; CDR alignment counts from the encapsulation header, wherever it starts), whose `data`
/// is the `data_len` bytes `write_data` appends. On an error nothing is appended.
pub fn append_point_cloud2_with(
    buf: &mut Vec<u8>,
    timestamp_ns: u64,
    frame_id: &str,
    stride: usize,
    fields: &[(&str, usize, FieldType)],
    data_len: usize,
    write_data: impl FnOnce(&mut Vec<u8>),
) -> Result<(), Ros2EncodeError> {
    if stride == 0 {
        return Err(Ros2EncodeError::TooLarge);
    }
    if data_len > MAX_DATA_LEN || frame_id.len() > MAX_FRAME_ID_LEN {
        return Err(Ros2EncodeError::TooLarge);
    }
    let sec = i32::try_from(timestamp_ns / 1_000_000_000)
        .map_err(|_| Ros2EncodeError::TimestampOutOfRange)?;
    let nanosec = (timestamp_ns % 1_000_000_000) as u32;
    // Both fit: data_len < 2^31.
    let width = (data_len / stride) as u32;
    let row_step = data_len as u32;

    buf.reserve(4 + 16 + frame_id.len() + 16 + fields.len() * 28 + 16 + data_len + 4);
    let mut w = Cdr::new(buf);
    // header: std_msgs/Header { builtin_interfaces/Time stamp; string frame_id }
    w.i32(sec);
    w.u32(nanosec);
    w.string(frame_id);
    w.u32(1); // height
    w.u32(width);
    w.u32(fields.len() as u32);
    for &(name, offset, ty) in fields {
        w.string(name);
        w.u32(offset as u32);
        w.u8(datatype_of(ty));
        w.u32(1); // count
    }
    w.u8(0); // is_bigendian
    w.u32(stride as u32); // point_step
    w.u32(row_step);
    w.u32(row_step); // data: sequence<uint8> length
    let at = w.buf.len();
    write_data(w.buf);
    debug_assert_eq!(w.buf.len() - at, data_len);
    w.u8(1); // is_dense
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn u32_at(b: &[u8], at: usize) -> u32 {
        u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
    }

    #[test]
    fn layout_is_aligned_cdr() {
        let points = [Point {
            x: 1.5,
            y: 2.0,
            z: 3.0,
            intensity: 9.0,
            t: 7,
            ring: 3,
            ret: 1,
            pad: 0,
        }];
        let mut buf = Vec::new();
        encode_point_cloud2(&mut buf, 12_000_000_034, "ab", &points).unwrap();
        assert_eq!(&buf[..4], &[0, 1, 0, 0]);
        let b = &buf[4..];
        assert_eq!(u32_at(b, 0), 12); // sec
        assert_eq!(u32_at(b, 4), 34); // nanosec
        assert_eq!(u32_at(b, 8), 3); // "ab\0"
        assert_eq!(&b[12..15], b"ab\0");
        // pad to 16
        assert_eq!(u32_at(b, 16), 1); // height
        assert_eq!(u32_at(b, 20), 1); // width
        assert_eq!(u32_at(b, 24), 7); // fields
                                      // field 0: "x": len 2 at 28, "x\0" at 32..34, pad, offset at 36, datatype at 40, count at 44
        assert_eq!(u32_at(b, 28), 2);
        assert_eq!(&b[32..34], b"x\0");
        assert_eq!(u32_at(b, 36), 0);
        assert_eq!(b[40], datatype::FLOAT32);
        assert_eq!(u32_at(b, 44), 1);
        // The tail: data length, the 24 point bytes, is_dense.
        let n = b.len();
        assert_eq!(b[n - 1], 1);
        assert_eq!(&b[n - 25..n - 1], crate::point::as_bytes(&points));
        assert_eq!(u32_at(b, n - 29), 24); // data length
        assert_eq!(u32_at(b, n - 33), 24); // row_step
        assert_eq!(u32_at(b, n - 37), 24); // point_step
        assert_eq!((n - 29) % 4, 0);
    }

    #[test]
    fn far_future_timestamps_are_refused() {
        let mut buf = Vec::new();
        assert_eq!(
            encode_point_cloud2(&mut buf, (i32::MAX as u64 + 1) * 1_000_000_000, "a", &[]),
            Err(Ros2EncodeError::TimestampOutOfRange)
        );
    }

    #[test]
    fn schema_text_has_every_dependency_once() {
        let s = point_cloud2_schema_text();
        assert!(s.starts_with("# A collection"));
        for dep in [
            "sensor_msgs/PointField",
            "std_msgs/Header",
            "builtin_interfaces/Time",
        ] {
            assert_eq!(s.matches(&format!("\nMSG: {dep}\n")).count(), 1, "{dep}");
        }
        assert_eq!(s.matches(SEPARATOR).count(), 3);
    }
}
