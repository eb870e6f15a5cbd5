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
#[derive(Debug, thiserror::Error)]
pub enum CdrError {
    /// The message ends before a field it declares.
    #[error("the CDR message ends at byte {at}, inside its {what}")]
    Short {
        /// Offset reached (after the 4-byte encapsulation header).
        at: usize,
        /// The field being read.
        what: &'static str,
    },
    /// Not little-endian plain CDR (the only encapsulation the ROS 2 sinks write).
    #[error("CDR encapsulation {0:02x?}: only little-endian plain CDR (00 01) is read")]
    Encapsulation([u8; 2]),
    /// A field holds what ringscan never writes there.
    #[error("{0}")]
    Invalid(&'static str),
}

/// A little-endian CDR cursor over a message body (alignment counts from the body's start,
/// after the encapsulation header, as the ROS 2 middleware writes it).
struct CdrReader<'a> {
    body: &'a [u8],
    at: usize,
}

impl<'a> CdrReader<'a> {
    fn new(msg: &'a [u8]) -> Result<Self, CdrError> {
        let head = msg.get(..4).ok_or(CdrError::Short {
            at: 0,
            what: "encapsulation header",
        })?;
        if head[..2] != [0, 1] {
            return Err(CdrError::Encapsulation([head[0], head[1]]));
        }
        Ok(Self {
            body: &msg[4..],
            at: 0,
        })
    }

    fn take(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], CdrError> {
        let short = CdrError::Short { at: self.at, what };
        let end = self
            .at
            .checked_add(n)
            .ok_or(CdrError::Short { at: self.at, what })?;
        let b = self.body.get(self.at..end).ok_or(short)?;
        self.at = end;
        Ok(b)
    }

    fn align(&mut self, n: usize) {
        self.at = self.at.next_multiple_of(n);
    }

    fn u8(&mut self, what: &'static str) -> Result<u8, CdrError> {
        Ok(self.take(1, what)?[0])
    }

    fn u32(&mut self, what: &'static str) -> Result<u32, CdrError> {
        self.align(4);
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn f32(&mut self, what: &'static str) -> Result<f32, CdrError> {
        self.u32(what).map(f32::from_bits)
    }

    fn f64(&mut self, what: &'static str) -> Result<f64, CdrError> {
        self.align(8);
        let b = self.take(8, what)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(f64::from_le_bytes(a))
    }

    /// A sequence's length, bounded by the bytes left at `min_bytes` per element (a hostile
    /// length allocates nothing).
    fn len(&mut self, min_bytes: usize, what: &'static str) -> Result<usize, CdrError> {
        let n = self.u32(what)? as usize;
        let left = self.body.len().saturating_sub(self.at);
        if n.saturating_mul(min_bytes.max(1)) > left {
            return Err(CdrError::Short { at: self.at, what });
        }
        Ok(n)
    }

    fn bytes(&mut self, what: &'static str) -> Result<&'a [u8], CdrError> {
        let n = self.len(1, what)?;
        self.take(n, what)
    }

    /// A string: its length with the terminating NUL, then its bytes.
    fn string(&mut self, what: &'static str) -> Result<String, CdrError> {
        let b = self.bytes(what)?;
        let b = b.strip_suffix(&[0]).unwrap_or(b);
        Ok(String::from_utf8_lossy(b).into_owned())
    }

    /// `std_msgs/Header`: its frame id (the stamp is skipped).
    fn header(&mut self) -> Result<String, CdrError> {
        self.u32("header stamp")?;
        self.u32("header stamp")?;
        self.string("header frame_id")
    }

    fn f64s<const N: usize>(&mut self, what: &'static str) -> Result<[f64; N], CdrError> {
        let mut v = [0.0; N];
        for x in &mut v {
            *x = self.f64(what)?;
        }
        Ok(v)
    }
}

impl PointCloud {
    /// A `sensor_msgs/msg/PointCloud2` in CDR (the `--format ros2` sinks' `…/points`,
    /// `…/ground`, `…/obstacles`), as the foxglove mirror: frame, record stride, fields (name
    /// and offset; ROS `PointField` datatypes, which agree with Foxglove's for `FLOAT32` = 7)
    /// and records. Big-endian records are refused.
    pub fn from_cdr(msg: &[u8]) -> Result<Self, CdrError> {
        let mut r = CdrReader::new(msg)?;
        let frame_id = r.header()?;
        r.u32("height")?;
        r.u32("width")?;
        let n = r.len(13, "fields")?;
        let mut fields = Vec::with_capacity(n);
        for _ in 0..n {
            let name = r.string("field name")?;
            let offset = r.u32("field offset")?;
            let datatype = r.u8("field datatype")?;
            r.u32("field count")?;
            fields.push(PackedElementField {
                name,
                offset,
                r#type: i32::from(datatype),
            });
        }
        if r.u8("is_bigendian")? != 0 {
            return Err(CdrError::Invalid("big-endian point records are not read"));
        }
        let point_stride = r.u32("point_step")?;
        r.u32("row_step")?;
        let data = r.bytes("data")?.to_vec();
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
        let mut r = CdrReader::new(msg)?;
        // A marker is more than 100 bytes; 16 bounds the count for the allocation.
        let n = r.len(16, "markers")?;
        let mut out = SceneUpdate::default();
        for _ in 0..n {
            let frame_id = r.header()?;
            r.string("marker ns")?;
            let id = r.u32("marker id")? as i32;
            let kind = r.u32("marker type")?;
            let action = r.u32("marker action")?;
            let [px, py, pz, qx, qy, qz, qw] = r.f64s::<7>("marker pose")?;
            let [sx, sy, sz] = r.f64s::<3>("marker scale")?;
            let [cr, cg, cb, ca] = [
                r.f32("marker color")?,
                r.f32("marker color")?,
                r.f32("marker color")?,
                r.f32("marker color")?,
            ];
            r.u32("marker lifetime")?;
            r.u32("marker lifetime")?;
            r.u8("marker frame_locked")?;
            let points = r.len(24, "marker points")?;
            for _ in 0..points {
                r.f64s::<3>("marker points")?;
            }
            let colors = r.len(16, "marker colors")?;
            r.take(colors * 16, "marker colors")?;
            r.string("marker texture_resource")?;
            r.header()?;
            r.string("marker texture format")?;
            r.bytes("marker texture data")?;
            let uv = r.len(8, "marker uv_coordinates")?;
            r.take(uv * 8, "marker uv_coordinates")?;
            r.string("marker text")?;
            r.string("marker mesh_resource")?;
            r.string("marker mesh_file filename")?;
            r.bytes("marker mesh_file data")?;
            r.u8("marker mesh_use_embedded_materials")?;
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
    /// alignment rules), not one from the project's encoder.
    fn cloud() -> Vec<u8> {
        let mut b = vec![0u8, 1, 0, 0];
        let mut body = Vec::new();
        body.extend(7i32.to_le_bytes()); // stamp.sec
        body.extend(9u32.to_le_bytes()); // stamp.nanosec
        body.extend(4u32.to_le_bytes());
        body.extend(b"map\0");
        body.extend(1u32.to_le_bytes()); // height
        body.extend(2u32.to_le_bytes()); // width
        body.extend(2u32.to_le_bytes()); // fields
        for (name, off) in [("x", 0u32), ("y", 4)] {
            body.extend(2u32.to_le_bytes());
            body.extend(name.as_bytes());
            body.push(0);
            while body.len() % 4 != 0 {
                body.push(0);
            }
            body.extend(off.to_le_bytes());
            body.push(7); // FLOAT32
            while body.len() % 4 != 0 {
                body.push(0);
            }
            body.extend(1u32.to_le_bytes());
        }
        body.push(0); // is_bigendian
        while body.len() % 4 != 0 {
            body.push(0);
        }
        body.extend(8u32.to_le_bytes()); // point_step
        body.extend(16u32.to_le_bytes()); // row_step
        body.extend(16u32.to_le_bytes());
        for v in [1.5f32, -2.0, 3.25, 4.0] {
            body.extend(v.to_le_bytes());
        }
        body.push(1); // is_dense
        b.extend(body);
        b
    }

    #[test]
    fn a_hand_written_point_cloud2_reads_back() {
        let pc = PointCloud::from_cdr(&cloud()).unwrap();
        assert_eq!(pc.frame_id, "map");
        assert_eq!(pc.point_stride, 8);
        assert_eq!((pc.offset("x"), pc.offset("y")), (Some(0), Some(4)));
        assert_eq!(pc.f32s(0).collect::<Vec<_>>(), [1.5, 3.25]);
        assert_eq!(pc.f32s(4).collect::<Vec<_>>(), [-2.0, 4.0]);
    }

    #[test]
    fn cut_or_lying_messages_are_errors() {
        let full = cloud();
        for n in 0..full.len() - 1 {
            assert!(PointCloud::from_cdr(&full[..n]).is_err(), "cut at {n}");
        }
        // The field count claims 2^32 - 1 fields: refused before anything is allocated.
        let mut lying = full.clone();
        lying[4 + 24..4 + 28].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(PointCloud::from_cdr(&lying).is_err());
        let mut big_endian = full;
        big_endian[1] = 0;
        assert!(matches!(
            PointCloud::from_cdr(&big_endian),
            Err(CdrError::Encapsulation(_))
        ));
        for n in 0..64 {
            let m = vec![0u8, 1, 0, 0, 0xff, 0xff, 0xff, 0x7f][..n.min(8)].to_vec();
            assert!(SceneUpdate::from_cdr_markers(&m).is_err());
        }
    }
}
