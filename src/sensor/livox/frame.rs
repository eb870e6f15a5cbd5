//! A frame of points the Livox ROS drivers already decoded (one `livox_ros_driver/CustomMsg`
//! or `livox_ros_driver2/CustomMsg`), in the fixed layout the bag source hands the Livox
//! stream. Points, not packets: the stream copies them into a sweep as they are (no range,
//! scaling or line rule applied), one message one sweep.
//!
//! Why a layout of ringscan's own rather than a new kind of source item: everything between a
//! source and the sinks (the demultiplexer by source address, stream claims, summaries, IMU
//! drain, pipeline, deskew, MCAP) takes datagrams; a frame that travels as one, tagged by a
//! magic no Livox packet starts with (byte 0 is 0xFF: SDK2 packets start with version 0, SDK1
//! with 5), reaches the Livox stream through all of it unchanged. The bag source reads each
//! serialization (ROS 1, CDR) once into this layout, so the stream knows no ROS encoding.
//!
//! | offset | bytes | field |
//! |---|---|---|
//! | 0 | 8 | magic `FF 'R' 'S' 'L' 'X' 'P' 'T' 01` |
//! | 8 | 8 | `timebase`, ns (u64): the frame's device time |
//! | 16 | 1 | `lidar_id` |
//! | 17 | 4 | point count `n` (u32) |
//! | 21 | 19 · n | per point: `offset_time` u32 ns after `timebase`, x y z f32 m, reflectivity, tag, line |
//!
//! The driver's IMU topic (`sensor_msgs/Imu` beside the `CustomMsg` one) travels the same way,
//! one sample a frame ([`ImuFrame`]), to the same stream, so its samples join the IMU path
//! the sensor's own IMU packets take (deskew, `/imu`):
//!
//! | offset | bytes | field |
//! |---|---|---|
//! | 0 | 8 | magic `FF 'R' 'S' 'L' 'X' 'I' 'M' 01` |
//! | 8 | 8 | time, ns (u64): the message's header stamp |
//! | 16 | 24 | angular velocity x y z, f64 rad/s |
//! | 40 | 24 | linear acceleration x y z, f64 m/s² (the bag source converts from g) |

use super::wire::{u32_at, u64_at};

/// First bytes of a frame.
pub const MAGIC: [u8; 8] = [0xFF, b'R', b'S', b'L', b'X', b'P', b'T', 1];
/// Header length.
pub const HEADER_LEN: usize = 21;
/// Bytes per point.
pub const POINT_LEN: usize = 19;

/// First bytes of an IMU frame.
pub const IMU_MAGIC: [u8; 8] = [0xFF, b'R', b'S', b'L', b'X', b'I', b'M', 1];
/// An IMU frame's length.
pub const IMU_LEN: usize = 64;

/// Writes one IMU sample as a frame into `out` (cleared).
pub fn write_imu(out: &mut Vec<u8>, time_ns: u64, gyro: [f64; 3], accel_mps2: [f64; 3]) {
    out.clear();
    out.extend_from_slice(&IMU_MAGIC);
    out.extend_from_slice(&time_ns.to_le_bytes());
    for v in gyro.iter().chain(&accel_mps2) {
        out.extend_from_slice(&v.to_le_bytes());
    }
}

/// A checked IMU frame: the magic and exactly [`IMU_LEN`] bytes.
#[derive(Clone, Copy, Debug)]
pub struct ImuFrame<'a> {
    bytes: &'a [u8],
}

impl<'a> ImuFrame<'a> {
    /// `None` when `bytes` is not a whole IMU frame.
    pub fn new(bytes: &'a [u8]) -> Option<Self> {
        (bytes.len() == IMU_LEN && Self::is_frame(bytes)).then_some(Self { bytes })
    }

    /// Whether `bytes` starts with the IMU magic (a frame, whole or not).
    pub fn is_frame(bytes: &[u8]) -> bool {
        bytes.get(..8) == Some(&IMU_MAGIC[..])
    }

    /// The sample's time, ns.
    pub fn time_ns(&self) -> u64 {
        u64_at(self.bytes, 8)
    }

    fn vec3(&self, at: usize) -> [f64; 3] {
        [0, 8, 16].map(|k| f64::from_bits(u64_at(self.bytes, at + k)))
    }

    /// Angular velocity, rad/s.
    pub fn gyro(&self) -> [f64; 3] {
        self.vec3(16)
    }

    /// Linear acceleration, m/s².
    pub fn accel(&self) -> [f64; 3] {
        self.vec3(40)
    }
}

/// One point of a frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FramePoint {
    /// ns after the frame's `timebase`.
    pub offset_time_ns: u32,
    /// Coordinates, m, sensor frame.
    pub xyz: [f32; 3],
    /// Reflectivity.
    pub reflectivity: u8,
    /// Livox tag byte.
    pub tag: u8,
    /// Laser line.
    pub line: u8,
}

/// Starts a frame in `out` (cleared) for `n` points; [`push_point`] then adds them.
pub fn write_header(out: &mut Vec<u8>, timebase_ns: u64, lidar_id: u8, n: u32) {
    out.clear();
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&timebase_ns.to_le_bytes());
    out.push(lidar_id);
    out.extend_from_slice(&n.to_le_bytes());
}

/// Appends one point.
pub fn push_point(out: &mut Vec<u8>, p: &FramePoint) {
    out.extend_from_slice(&p.offset_time_ns.to_le_bytes());
    for v in p.xyz {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&[p.reflectivity, p.tag, p.line]);
}

/// A checked frame: the magic, and exactly `n` points after the header.
#[derive(Clone, Copy, Debug)]
pub struct PointsFrame<'a> {
    bytes: &'a [u8],
}

impl<'a> PointsFrame<'a> {
    /// `None` when `bytes` is not a whole frame.
    pub fn new(bytes: &'a [u8]) -> Option<Self> {
        if bytes.get(..8)? != MAGIC || bytes.len() < HEADER_LEN {
            return None;
        }
        let n = u32_at(bytes, 17) as usize;
        (n.checked_mul(POINT_LEN)? == bytes.len() - HEADER_LEN).then_some(Self { bytes })
    }

    /// Whether `bytes` starts with the magic (a frame, whole or not).
    pub fn is_frame(bytes: &[u8]) -> bool {
        bytes.get(..8) == Some(&MAGIC[..])
    }

    /// Device time of the frame, ns.
    pub fn timebase_ns(&self) -> u64 {
        u64_at(self.bytes, 8)
    }

    /// `lidar_id`.
    pub fn lidar_id(&self) -> u8 {
        self.bytes[16]
    }

    /// Point count.
    pub fn len(&self) -> usize {
        (self.bytes.len() - HEADER_LEN) / POINT_LEN
    }

    /// Whether it holds no point.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The points.
    pub fn points(&self) -> impl Iterator<Item = FramePoint> + 'a {
        self.bytes[HEADER_LEN..]
            .chunks_exact(POINT_LEN)
            .map(|c| FramePoint {
                offset_time_ns: u32_at(c, 0),
                xyz: [
                    f32::from_bits(u32_at(c, 4)),
                    f32::from_bits(u32_at(c, 8)),
                    f32::from_bits(u32_at(c, 12)),
                ],
                reflectivity: c[16],
                tag: c[17],
                line: c[18],
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_reads_back_and_a_cut_one_is_refused() {
        let p = FramePoint {
            offset_time_ns: 7,
            xyz: [1.0, -2.5, 3.25],
            reflectivity: 9,
            tag: 0x30,
            line: 3,
        };
        let mut b = Vec::new();
        write_header(&mut b, 42, 5, 2);
        push_point(&mut b, &p);
        push_point(&mut b, &p);
        let f = PointsFrame::new(&b).unwrap();
        assert_eq!((f.timebase_ns(), f.lidar_id(), f.len()), (42, 5, 2));
        assert!(f.points().all(|q| q == p));
        assert!(PointsFrame::new(&b[..b.len() - 1]).is_none());
        assert!(PointsFrame::is_frame(&b[..9]));
        assert!(ImuFrame::new(&b).is_none());
    }

    #[test]
    fn an_imu_frame_reads_back_and_a_cut_one_is_refused() {
        let mut b = Vec::new();
        write_imu(&mut b, 1_234, [0.5, -1.0, 2.25], [0.1, 0.2, 9.8]);
        assert_eq!(b.len(), IMU_LEN);
        let f = ImuFrame::new(&b).unwrap();
        assert_eq!(f.time_ns(), 1_234);
        assert_eq!(f.gyro(), [0.5, -1.0, 2.25]);
        assert_eq!(f.accel(), [0.1, 0.2, 9.8]);
        assert!(ImuFrame::new(&b[..IMU_LEN - 1]).is_none());
        assert!(ImuFrame::is_frame(&b[..8]));
        assert!(PointsFrame::new(&b).is_none() && !PointsFrame::is_frame(&b));
    }
}
