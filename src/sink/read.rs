//! Reading ringscan's messages back: prost mirrors of the Foxglove protobuf messages the sinks
//! write (`foxglove.PointCloud`, `foxglove.SceneUpdate`, `foxglove.FrameTransform`), as far as
//! ringscan fills them.
//!
//! The sinks encode by hand ([`super::foxglove`], [`super::scene`]); these mirrors are
//! declared from Foxglove's `.proto` files (field numbers and types) and decoded by prost, so a
//! round trip through them checks the hand encoding against an independent decoder. `ringscan
//! render` reads its pictures' data with them, and the tests read the MCAP files with them.
//!
//! ```
//! use prost::Message as _;
//! use ringscan::sink::read::FrameTransform;
//!
//! let m = FrameTransform {
//!     parent_frame_id: "odom".into(),
//!     child_frame_id: "lidar".into(),
//!     ..Default::default()
//! };
//! let back = FrameTransform::decode(m.encode_to_vec().as_slice()).unwrap();
//! assert_eq!(back.child_frame_id, "lidar");
//! ```

use crate::ros_serial::{Cursor, Fault};

/// `foxglove.PackedElementField`: one field of a point record.
#[derive(Clone, PartialEq, prost::Message)]
pub struct PackedElementField {
    /// Field name (`x`, `intensity`, …).
    #[prost(string, tag = "1")]
    pub name: String,
    /// Byte offset in the record.
    #[prost(fixed32, tag = "2")]
    pub offset: u32,
    /// `foxglove.PackedElementField.NumericType` (7 = FLOAT32, 6 = UINT32, …).
    #[prost(int32, tag = "3")]
    pub r#type: i32,
}

/// `foxglove.Vector3`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Vector3 {
    /// x.
    #[prost(double, tag = "1")]
    pub x: f64,
    /// y.
    #[prost(double, tag = "2")]
    pub y: f64,
    /// z.
    #[prost(double, tag = "3")]
    pub z: f64,
}

/// `foxglove.Quaternion`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Quaternion {
    /// x.
    #[prost(double, tag = "1")]
    pub x: f64,
    /// y.
    #[prost(double, tag = "2")]
    pub y: f64,
    /// z.
    #[prost(double, tag = "3")]
    pub z: f64,
    /// w.
    #[prost(double, tag = "4")]
    pub w: f64,
}

/// `foxglove.Pose`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Pose {
    /// Position.
    #[prost(message, optional, tag = "1")]
    pub position: Option<Vector3>,
    /// Orientation.
    #[prost(message, optional, tag = "2")]
    pub orientation: Option<Quaternion>,
}

/// `foxglove.Color`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Color {
    /// Red, 0 … 1.
    #[prost(double, tag = "1")]
    pub r: f64,
    /// Green, 0 … 1.
    #[prost(double, tag = "2")]
    pub g: f64,
    /// Blue, 0 … 1.
    #[prost(double, tag = "3")]
    pub b: f64,
    /// Alpha, 0 … 1.
    #[prost(double, tag = "4")]
    pub a: f64,
}

/// `foxglove.PointCloud`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct PointCloud {
    /// Stamp.
    #[prost(message, optional, tag = "1")]
    pub timestamp: Option<prost_types::Timestamp>,
    /// Frame of the points.
    #[prost(string, tag = "2")]
    pub frame_id: String,
    /// Origin of the points in the frame.
    #[prost(message, optional, tag = "3")]
    pub pose: Option<Pose>,
    /// Bytes per point record.
    #[prost(fixed32, tag = "4")]
    pub point_stride: u32,
    /// The record's fields.
    #[prost(message, repeated, tag = "5")]
    pub fields: Vec<PackedElementField>,
    /// The records.
    #[prost(bytes = "vec", tag = "6")]
    pub data: Vec<u8>,
}

impl PointCloud {
    /// Byte offset of the field called `name`, if the cloud has it.
    pub fn offset(&self, name: &str) -> Option<usize> {
        self.fields
            .iter()
            .find(|f| f.name == name)
            .map(|f| f.offset as usize)
    }

    /// The `f32` field at `offset` of every complete record (none if the offset or the stride
    /// does not fit).
    pub fn f32s(&self, offset: usize) -> impl Iterator<Item = f32> + '_ {
        self.u32s(offset).map(f32::from_bits)
    }

    /// The `u32` field at `offset` of every complete record (none if it does not fit).
    pub fn u32s(&self, offset: usize) -> impl Iterator<Item = u32> + '_ {
        let stride = self.point_stride as usize;
        let ok = stride > 0 && offset + 4 <= stride;
        self.data
            .chunks_exact(stride.max(1))
            .filter(move |_| ok)
            .map(move |r| {
                u32::from_le_bytes([r[offset], r[offset + 1], r[offset + 2], r[offset + 3]])
            })
    }
}

/// `foxglove.CubePrimitive`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct CubePrimitive {
    /// Centre and orientation.
    #[prost(message, optional, tag = "1")]
    pub pose: Option<Pose>,
    /// Edge lengths.
    #[prost(message, optional, tag = "2")]
    pub size: Option<Vector3>,
    /// Colour.
    #[prost(message, optional, tag = "3")]
    pub color: Option<Color>,
}

/// `foxglove.KeyValuePair`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct KeyValuePair {
    /// Key.
    #[prost(string, tag = "1")]
    pub key: String,
    /// Value.
    #[prost(string, tag = "2")]
    pub value: String,
}

/// `foxglove.SceneEntity` (the fields ringscan writes).
#[derive(Clone, PartialEq, prost::Message)]
pub struct SceneEntity {
    /// Stamp.
    #[prost(message, optional, tag = "1")]
    pub timestamp: Option<prost_types::Timestamp>,
    /// Frame.
    #[prost(string, tag = "2")]
    pub frame_id: String,
    /// Entity id.
    #[prost(string, tag = "3")]
    pub id: String,
    /// Whether it moves with its frame.
    #[prost(bool, tag = "5")]
    pub frame_locked: bool,
    /// Metadata.
    #[prost(message, repeated, tag = "6")]
    pub metadata: Vec<KeyValuePair>,
    /// Cubes.
    #[prost(message, repeated, tag = "8")]
    pub cubes: Vec<CubePrimitive>,
}

/// `foxglove.SceneEntityDeletion`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct SceneEntityDeletion {
    /// Stamp.
    #[prost(message, optional, tag = "1")]
    pub timestamp: Option<prost_types::Timestamp>,
    /// 0 = matching id, 1 = all.
    #[prost(int32, tag = "2")]
    pub r#type: i32,
    /// Entity id (type 0).
    #[prost(string, tag = "3")]
    pub id: String,
}

/// `foxglove.SceneUpdate`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct SceneUpdate {
    /// Deletions, applied first.
    #[prost(message, repeated, tag = "1")]
    pub deletions: Vec<SceneEntityDeletion>,
    /// Entities added or replaced.
    #[prost(message, repeated, tag = "2")]
    pub entities: Vec<SceneEntity>,
}

/// `foxglove.FrameTransform`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct FrameTransform {
    /// Stamp.
    #[prost(message, optional, tag = "1")]
    pub timestamp: Option<prost_types::Timestamp>,
    /// Parent frame.
    #[prost(string, tag = "2")]
    pub parent_frame_id: String,
    /// Child frame.
    #[prost(string, tag = "3")]
    pub child_frame_id: String,
    /// Translation of the child in the parent.
    #[prost(message, optional, tag = "4")]
    pub translation: Option<Vector3>,
    /// Rotation of the child in the parent.
    #[prost(message, optional, tag = "5")]
    pub rotation: Option<Quaternion>,
}

/// Why a CDR message could not be read back.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum CdrError {
    /// The message ends before a field it declares.
    #[error("the CDR message ends at byte {len}, a field at byte {offset} needs {need} bytes")]
    Short {
        /// Offset of the field.
        offset: usize,
        /// Bytes the field needs.
        need: usize,
        /// Message length.
        len: usize,
    },
    /// Not plain CDR (big or little endian).
    #[error("CDR encapsulation {0:#06x}: expected 0x0000 or 0x0001 (plain CDR)")]
    Encapsulation(u16),
    /// A sequence longer than the bytes left could hold (refused before any allocation).
    #[error("a sequence of {0} elements, more than the message holds")]
    Count(u64),
    /// A field holds what ringscan never writes there.
    #[error("{0}")]
    Invalid(&'static str),
}

impl From<Fault> for CdrError {
    fn from(f: Fault) -> Self {
        match f {
            Fault::Short { offset, need, len } => Self::Short { offset, need, len },
            Fault::Encapsulation(k) => Self::Encapsulation(k),
            Fault::Count(n) => Self::Count(n),
            Fault::Trailing { .. } => Self::Invalid("bytes left after the last field"),
        }
    }
}

/// A CDR string as text (a frame id, a field name).
fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

impl PointCloud {
    /// A `sensor_msgs/msg/PointCloud2` in CDR (the `--format ros2` sinks' `…/points`,
    /// `…/ground`, `…/obstacles`), as the foxglove mirror: frame, record stride, fields (name
    /// and offset; ROS `PointField` datatypes, which agree with Foxglove's for `FLOAT32` = 7)
    /// and records. Big-endian records are refused.
    pub fn from_cdr(msg: &[u8]) -> Result<Self, CdrError> {
        let mut r = Cursor::cdr(msg)?;
        let frame_id = text(r.header()?.frame_id);
        r.u32()?; // height
        r.u32()?; // width
                  // A field is at least a 4-byte name length, an offset, a datatype and a count.
        let n = r.count(13, usize::MAX)?;
        let mut fields = Vec::with_capacity(n);
        for _ in 0..n {
            let name = text(r.string()?);
            let offset = r.u32()?;
            let datatype = r.u8()?;
            r.u32()?; // count
            fields.push(PackedElementField {
                name,
                offset,
                r#type: i32::from(datatype),
            });
        }
        if r.u8()? != 0 {
            return Err(CdrError::Invalid("big-endian point records are not read"));
        }
        let point_stride = r.u32()?;
        r.u32()?; // row_step
        let (start, len) = r.bytes()?;
        let data = msg[start..start + len].to_vec();
        Ok(Self {
            timestamp: None,
            frame_id,
            pose: None,
            point_stride,
            fields,
            data,
        })
    }
}

impl SceneUpdate {
    /// A `visualization_msgs/msg/MarkerArray` in CDR, in the `Marker` layout the
    /// `--format ros2` sinks write (Humble's later and newer distributions: with `texture`,
    /// `uv_coordinates` and `mesh_file`), as the foxglove mirror: each added `CUBE` is an
    /// entity (id = the marker's, one cube with its pose and scale); a `DELETEALL` marker is a
    /// deletion of all.
    pub fn from_cdr_markers(msg: &[u8]) -> Result<Self, CdrError> {
        const CUBE: u32 = 1;
        const ADD: u32 = 0;
        const DELETEALL: u32 = 3;
        let mut r = Cursor::cdr(msg)?;
        // A marker is more than 100 bytes; 16 bounds the count for the allocation.
        let n = r.count(16, usize::MAX)?;
        let mut out = SceneUpdate::default();
        for _ in 0..n {
            let frame_id = text(r.header()?.frame_id);
            r.string()?; // ns
            let id = r.u32()? as i32;
            let kind = r.u32()?;
            let action = r.u32()?;
            let [px, py, pz, qx, qy, qz, qw] = r.f64s::<7>()?; // pose
            let [sx, sy, sz] = r.f64s::<3>()?; // scale
            let [cr, cg, cb, ca] = [r.f32()?, r.f32()?, r.f32()?, r.f32()?];
            r.time()?; // lifetime
            r.u8()?; // frame_locked
            let points = r.count(24, usize::MAX)?;
            for _ in 0..points {
                r.f64s::<3>()?;
            }
            let colors = r.count(16, usize::MAX)?;
            r.take(colors * 16)?;
            r.string()?; // texture_resource
            r.header()?; // texture (sensor_msgs/CompressedImage): header,
            r.string()?; // format
            r.bytes()?; // and data
            let uv = r.count(8, usize::MAX)?;
            r.take(uv * 8)?; // uv_coordinates
            r.string()?; // text
            r.string()?; // mesh_resource
            r.string()?; // mesh_file: filename
            r.bytes()?; // and data
            r.u8()?; // mesh_use_embedded_materials
            match (action, kind) {
                (DELETEALL, _) => out.deletions.push(SceneEntityDeletion {
                    timestamp: None,
                    r#type: 1,
                    id: String::new(),
                }),
                (ADD, CUBE) => out.entities.push(SceneEntity {
                    timestamp: None,
                    frame_id,
                    id: id.to_string(),
                    frame_locked: false,
                    metadata: Vec::new(),
                    cubes: vec![CubePrimitive {
                        pose: Some(Pose {
                            position: Some(Vector3 {
                                x: px,
                                y: py,
                                z: pz,
                            }),
                            orientation: Some(Quaternion {
                                x: qx,
                                y: qy,
                                z: qz,
                                w: qw,
                            }),
                        }),
                        size: Some(Vector3 {
                            x: sx,
                            y: sy,
                            z: sz,
                        }),
                        color: Some(Color {
                            r: f64::from(cr),
                            g: f64::from(cg),
                            b: f64::from(cb),
                            a: f64::from(ca),
                        }),
                    }],
                }),
                _ => {}
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-written `PointCloud2` (layout of `sensor_msgs/msg/PointCloud2.msg`, CDR
    /// alignment rules), not one from the project's encoder; its CDR in either byte order, its
    /// point records little-endian.
    fn cloud(big: bool) -> Vec<u8> {
        let u32b = |v: u32| {
            if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        let mut b = vec![0u8, u8::from(!big), 0, 0];
        let mut body = Vec::new();
        body.extend(u32b(7)); // stamp.sec
        body.extend(u32b(9)); // stamp.nanosec
        body.extend(u32b(4));
        body.extend(b"map\0");
        body.extend(u32b(1)); // height
        body.extend(u32b(2)); // width
        body.extend(u32b(2)); // fields
        for (name, off) in [("x", 0u32), ("y", 4)] {
            body.extend(u32b(2));
            body.extend(name.as_bytes());
            body.push(0);
            while body.len() % 4 != 0 {
                body.push(0);
            }
            body.extend(u32b(off));
            body.push(7); // FLOAT32
            while body.len() % 4 != 0 {
                body.push(0);
            }
            body.extend(u32b(1));
        }
        body.push(0); // is_bigendian
        while body.len() % 4 != 0 {
            body.push(0);
        }
        body.extend(u32b(8)); // point_step
        body.extend(u32b(16)); // row_step
        body.extend(u32b(16));
        for v in [1.5f32, -2.0, 3.25, 4.0] {
            body.extend(v.to_le_bytes());
        }
        body.push(1); // is_dense
        b.extend(body);
        b
    }

    #[test]
    fn a_hand_written_point_cloud2_reads_back() {
        for big in [false, true] {
            let pc = PointCloud::from_cdr(&cloud(big)).unwrap();
            assert_eq!(pc.frame_id, "map");
            assert_eq!(pc.point_stride, 8);
            assert_eq!((pc.offset("x"), pc.offset("y")), (Some(0), Some(4)));
            assert_eq!(pc.f32s(0).collect::<Vec<_>>(), [1.5, 3.25]);
            assert_eq!(pc.f32s(4).collect::<Vec<_>>(), [-2.0, 4.0]);
        }
    }

    #[test]
    fn cut_or_lying_messages_are_errors() {
        let full = cloud(false);
        for n in 0..full.len() - 1 {
            assert!(PointCloud::from_cdr(&full[..n]).is_err(), "cut at {n}");
        }
        // The field count claims 2^32 - 1 fields: refused before anything is allocated.
        let mut lying = full.clone();
        lying[4 + 24..4 + 28].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(PointCloud::from_cdr(&lying).is_err());
        let mut parameter_list = full;
        parameter_list[1] = 2; // PL_CDR_BE: not the plain CDR of ROS 2 messages
        assert_eq!(
            PointCloud::from_cdr(&parameter_list),
            Err(CdrError::Encapsulation(2))
        );
        for n in 0..64 {
            let m = vec![0u8, 1, 0, 0, 0xff, 0xff, 0xff, 0x7f][..n.min(8)].to_vec();
            assert!(SceneUpdate::from_cdr_markers(&m).is_err());
        }
    }
}
