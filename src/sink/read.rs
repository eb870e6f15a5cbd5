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
