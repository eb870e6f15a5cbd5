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

use super::wire::{u32_at, u64_at};

/// First bytes of a frame.
pub const MAGIC: [u8; 8] = [0xFF, b'R', b'S', b'L', b'X', b'P', b'T', 1];
/// Header length.
pub const HEADER_LEN: usize = 21;
/// Bytes per point.
pub const POINT_LEN: usize = 19;

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
    }
}
