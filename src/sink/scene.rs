//! Pipeline outputs in MCAP: `ground` and `obstacles` point clouds, `clusters` as a
//! `foxglove.SceneUpdate` (one cube per cluster, yaw-oriented), and sensor placements as
//! `foxglove.FrameTransform` on `/tf_static`.
//!
//! Encoded by hand like [`super::foxglove`]'s point clouds; the schemas travel as
//! `FileDescriptorSet`s built here. The messages reproduce the official Foxglove schema files
//! (`SceneUpdate.proto`, `SceneEntity.proto`, `SceneEntityDeletion.proto`, `CubePrimitive.proto`,
//! `ArrowPrimitive.proto`, `SpherePrimitive.proto`, `CylinderPrimitive.proto`,
//! `LinePrimitive.proto`, `TriangleListPrimitive.proto`, `TextPrimitive.proto`,
//! `ModelPrimitive.proto`, `KeyValuePair.proto`, `Color.proto`, `Point3.proto`,
//! `FrameTransform.proto` in `schemas/proto/foxglove/` of <https://github.com/foxglove/foxglove-sdk>)
//! with their field numbers, and `google/protobuf/duration.proto` (`int64 seconds = 1;
//! int32 nanos = 2;`). The recent `message_id` / `lineage` / `uuid` fields (numbers ≥ 100) are
//! left out: readers skip what a descriptor does not name, and the messages never set them.
//!
//! Each `clusters` message first deletes every entity of the topic (`SceneEntityDeletion` of
//! type `ALL`), then adds one entity per cluster (id = the cluster's index in the sweep) holding
//! one cube: centre, size and yaw of the cluster's minimum-area box, coloured by
//! [`cluster_color`], with the point count as metadata `points`.

use std::collections::BTreeMap;
use std::io::{Seek, Write};

use nalgebra::Isometry3;
use prost::Message as _;
use prost_types::field_descriptor_proto::Type;
use prost_types::{
    EnumDescriptorProto, EnumValueDescriptorProto, FileDescriptorProto, FileDescriptorSet,
};

use super::foxglove::{
    self, file, message, point_cloud_files, put_double_field, put_len_field, put_string_field,
    put_timestamp_field, put_varint_field, repeated, timestamp_file, PointCloudPrefix,
};
use super::mcap::{Format, McapSink, SensorId, SinkError, TopicId, TopicSchema};
use super::{ros2, ros2_msgs};
use crate::pipeline::cluster::Cluster;
use crate::point::{FieldType, Point, POINT_FIELDS, POINT_STRIDE};

/// Schema name of the clusters channels.
pub const SCENE_UPDATE_SCHEMA: &str = "foxglove.SceneUpdate";
/// Schema name of the transforms channel.
pub const FRAME_TRANSFORM_SCHEMA: &str = "foxglove.FrameTransform";
/// Topic of the static sensor placements.
pub const TF_STATIC_TOPIC: &str = "/tf_static";

/// Stride of an obstacle record: a [`Point`] then its cluster index (u32).
pub const OBSTACLE_STRIDE: usize = POINT_STRIDE + 4;

/// Fields of an obstacle record, in record order.
pub const OBSTACLE_FIELDS: [(&str, usize, FieldType); 8] = [
    POINT_FIELDS[0],
    POINT_FIELDS[1],
    POINT_FIELDS[2],
    POINT_FIELDS[3],
    POINT_FIELDS[4],
    POINT_FIELDS[5],
    POINT_FIELDS[6],
    ("cluster", POINT_STRIDE, FieldType::U32),
];

/// The colour of cluster `k` (RGB in 0..=1): hues a golden angle apart, so neighbouring
/// indices differ clearly; shared by the MCAP cubes and `ringscan render`.
pub fn cluster_color(k: u32) -> [f32; 3] {
    let h = (f64::from(k) * 0.618_033_988_75).fract() * 6.0;
    let (s, v) = (0.75, 0.95);
    let i = h.floor();
    let f = h - i;
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    let (r, g, b) = match i as u32 {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    [r as f32, g as f32, b as f32]
}

// ---------------------------------------------------------------------------------------------
// Encoding.

fn put_message(buf: &mut Vec<u8>, field: u32, body: &[u8]) {
    put_len_field(buf, field, body);
}

fn vector3(out: &mut Vec<u8>, v: [f64; 3]) {
    out.clear();
    put_double_field(out, 1, v[0]);
    put_double_field(out, 2, v[1]);
    put_double_field(out, 3, v[2]);
}

fn quaternion(out: &mut Vec<u8>, q: [f64; 4]) {
    out.clear();
    put_double_field(out, 1, q[0]);
    put_double_field(out, 2, q[1]);
    put_double_field(out, 3, q[2]);
    put_double_field(out, 4, q[3]);
}

/// Reusable buffers for the nested messages of a scene update.
#[derive(Debug, Default)]
pub struct SceneEncoder {
    entity: Vec<u8>,
    cube: Vec<u8>,
    pose: Vec<u8>,
    part: Vec<u8>,
    kv: Vec<u8>,
    digits: String,
}

impl SceneEncoder {
    /// Encodes one `foxglove.SceneUpdate` into `buf` (cleared first): delete all, then one
    /// entity with one cube per cluster.
    pub fn encode_clusters(
        &mut self,
        buf: &mut Vec<u8>,
        timestamp_ns: u64,
        frame_id: &str,
        clusters: &[Cluster],
    ) {
        buf.clear();
        // deletions = 1: SceneEntityDeletion { timestamp = 1, type = 2 (ALL = 1) }
        self.part.clear();
        put_timestamp_field(&mut self.part, 1, timestamp_ns);
        put_varint_field(&mut self.part, 2, 1);
        put_message(buf, 1, &self.part);
        for (k, c) in clusters.iter().enumerate() {
            let b = &c.oriented;
            // CubePrimitive { pose = 1: Pose { position = 1, orientation = 2 }, size = 2, color = 3 }
            self.pose.clear();
            vector3(&mut self.part, b.center.map(f64::from));
            put_message(&mut self.pose, 1, &self.part);
            let half = f64::from(b.yaw_rad) * 0.5;
            quaternion(&mut self.part, [0.0, 0.0, half.sin(), half.cos()]);
            put_message(&mut self.pose, 2, &self.part);
            self.cube.clear();
            put_message(&mut self.cube, 1, &self.pose);
            vector3(&mut self.part, b.size_m.map(f64::from));
            put_message(&mut self.cube, 2, &self.part);
            let [r, g, bl] = cluster_color(k as u32);
            self.part.clear();
            put_double_field(&mut self.part, 1, f64::from(r));
            put_double_field(&mut self.part, 2, f64::from(g));
            put_double_field(&mut self.part, 3, f64::from(bl));
            put_double_field(&mut self.part, 4, 0.5);
            put_message(&mut self.cube, 3, &self.part);
            // SceneEntity { timestamp = 1, frame_id = 2, id = 3, metadata = 6, cubes = 8 }
            self.entity.clear();
            put_timestamp_field(&mut self.entity, 1, timestamp_ns);
            put_string_field(&mut self.entity, 2, frame_id);
            self.digits.clear();
            use std::fmt::Write as _;
            let _ = write!(self.digits, "{k}");
            put_len_field(&mut self.entity, 3, self.digits.as_bytes());
            self.kv.clear();
            put_string_field(&mut self.kv, 1, "points");
            self.digits.clear();
            let _ = write!(self.digits, "{}", c.point_count);
            put_string_field(&mut self.kv, 2, &self.digits);
            put_message(&mut self.entity, 6, &self.kv);
            put_message(&mut self.entity, 8, &self.cube);
            // entities = 2
            put_message(buf, 2, &self.entity);
        }
    }
}

/// Encodes one `foxglove.FrameTransform` (`parent_from_child`) into `buf` (cleared first).
pub fn encode_frame_transform(
    buf: &mut Vec<u8>,
    timestamp_ns: u64,
    parent: &str,
    child: &str,
    parent_from_child: &Isometry3<f64>,
) {
    buf.clear();
    put_timestamp_field(buf, 1, timestamp_ns);
    put_string_field(buf, 2, parent);
    put_string_field(buf, 3, child);
    let mut part = Vec::with_capacity(36);
    let t = parent_from_child.translation.vector;
    vector3(&mut part, [t.x, t.y, t.z]);
    put_message(buf, 4, &part);
    let q = parent_from_child.rotation;
    quaternion(&mut part, [q.i, q.j, q.k, q.w]);
    put_message(buf, 5, &part);
}

/// Interleaves obstacle points and their cluster indices into records of
/// [`OBSTACLE_FIELDS`] (`out` cleared first).
pub fn obstacle_records(points: &[Point], clusters: &[u32], out: &mut Vec<u8>) {
    out.clear();
    out.reserve(points.len() * OBSTACLE_STRIDE);
    for (i, p) in points.iter().enumerate() {
        out.extend_from_slice(bytemuck::bytes_of(p));
        out.extend_from_slice(&clusters.get(i).copied().unwrap_or(u32::MAX).to_le_bytes());
    }
}

// ---------------------------------------------------------------------------------------------
// Schemas.

fn named(files: &[FileDescriptorProto], name: &str) -> Option<FileDescriptorProto> {
    files.iter().find(|f| f.name() == name).cloned()
}

fn f(
    name: &str,
    json: &str,
    number: i32,
    ty: Type,
    type_name: Option<&str>,
) -> prost_types::FieldDescriptorProto {
    foxglove::field(name, json, number, ty, type_name)
}

fn msg_field(
    name: &str,
    json: &str,
    number: i32,
    type_name: &str,
) -> prost_types::FieldDescriptorProto {
    f(name, json, number, Type::Message, Some(type_name))
}

fn enum_type(name: &str, values: &[(&str, i32)]) -> EnumDescriptorProto {
    EnumDescriptorProto {
        name: Some(name.to_owned()),
        value: values
            .iter()
            .map(|(n, v)| EnumValueDescriptorProto {
                name: Some((*n).to_owned()),
                number: Some(*v),
                options: None,
            })
            .collect(),
        ..Default::default()
    }
}

/// Vector3, Quaternion, Pose from the point cloud's files (one definition of each).
fn geometry_files() -> Vec<FileDescriptorProto> {
    let pc = point_cloud_files();
    [
        "foxglove/Quaternion.proto",
        "foxglove/Vector3.proto",
        "foxglove/Pose.proto",
    ]
    .iter()
    .filter_map(|n| named(&pc, n))
    .collect()
}

fn simple(
    name: &str,
    fields: Vec<prost_types::FieldDescriptorProto>,
    deps: &[&str],
) -> FileDescriptorProto {
    file(
        &format!("foxglove/{name}.proto"),
        "foxglove",
        deps,
        vec![message(name, fields)],
    )
}

fn scene_update_files() -> Vec<FileDescriptorProto> {
    let pose = ".foxglove.Pose";
    let color = ".foxglove.Color";
    let vec3 = ".foxglove.Vector3";
    let point3 = ".foxglove.Point3";
    let mut files = geometry_files();
    files.push(timestamp_file());
    files.push(file(
        "google/protobuf/duration.proto",
        "google.protobuf",
        &[],
        vec![message(
            "Duration",
            vec![
                f("seconds", "seconds", 1, Type::Int64, None),
                f("nanos", "nanos", 2, Type::Int32, None),
            ],
        )],
    ));
    files.push(simple(
        "Color",
        vec![
            f("r", "r", 1, Type::Double, None),
            f("g", "g", 2, Type::Double, None),
            f("b", "b", 3, Type::Double, None),
            f("a", "a", 4, Type::Double, None),
        ],
        &[],
    ));
    files.push(simple(
        "Point3",
        vec![
            f("x", "x", 1, Type::Double, None),
            f("y", "y", 2, Type::Double, None),
            f("z", "z", 3, Type::Double, None),
        ],
        &[],
    ));
    files.push(simple(
        "KeyValuePair",
        vec![
            f("key", "key", 1, Type::String, None),
            f("value", "value", 2, Type::String, None),
        ],
        &[],
    ));
    let pcv = &[
        "foxglove/Color.proto",
        "foxglove/Pose.proto",
        "foxglove/Vector3.proto",
    ];
    let pc = &["foxglove/Color.proto", "foxglove/Pose.proto"];
    let pcp = &[
        "foxglove/Color.proto",
        "foxglove/Point3.proto",
        "foxglove/Pose.proto",
    ];
    files.push(simple(
        "ArrowPrimitive",
        vec![
            msg_field("pose", "pose", 1, pose),
            f("shaft_length", "shaftLength", 2, Type::Double, None),
            f("shaft_diameter", "shaftDiameter", 3, Type::Double, None),
            f("head_length", "headLength", 4, Type::Double, None),
            f("head_diameter", "headDiameter", 5, Type::Double, None),
            msg_field("color", "color", 6, color),
        ],
        pc,
    ));
    for name in ["CubePrimitive", "SpherePrimitive"] {
        files.push(simple(
            name,
            vec![
                msg_field("pose", "pose", 1, pose),
                msg_field("size", "size", 2, vec3),
                msg_field("color", "color", 3, color),
            ],
            pcv,
        ));
    }
    files.push(simple(
        "CylinderPrimitive",
        vec![
            msg_field("pose", "pose", 1, pose),
            msg_field("size", "size", 2, vec3),
            f("bottom_scale", "bottomScale", 3, Type::Double, None),
            f("top_scale", "topScale", 4, Type::Double, None),
            msg_field("color", "color", 5, color),
        ],
        pcv,
    ));
    let mut line = message(
        "LinePrimitive",
        vec![
            f(
                "type",
                "type",
                1,
                Type::Enum,
                Some(".foxglove.LinePrimitive.Type"),
            ),
            msg_field("pose", "pose", 2, pose),
            f("thickness", "thickness", 3, Type::Double, None),
            f("scale_invariant", "scaleInvariant", 4, Type::Bool, None),
            repeated(msg_field("points", "points", 5, point3)),
            msg_field("color", "color", 6, color),
            repeated(msg_field("colors", "colors", 7, color)),
            repeated(f("indices", "indices", 8, Type::Fixed32, None)),
        ],
    );
    line.enum_type.push(enum_type(
        "Type",
        &[("LINE_STRIP", 0), ("LINE_LOOP", 1), ("LINE_LIST", 2)],
    ));
    files.push(file(
        "foxglove/LinePrimitive.proto",
        "foxglove",
        pcp,
        vec![line],
    ));
    files.push(simple(
        "TriangleListPrimitive",
        vec![
            msg_field("pose", "pose", 1, pose),
            repeated(msg_field("points", "points", 2, point3)),
            msg_field("color", "color", 3, color),
            repeated(msg_field("colors", "colors", 4, color)),
            repeated(f("indices", "indices", 5, Type::Fixed32, None)),
        ],
        pcp,
    ));
    files.push(simple(
        "TextPrimitive",
        vec![
            msg_field("pose", "pose", 1, pose),
            f("billboard", "billboard", 2, Type::Bool, None),
            f("font_size", "fontSize", 3, Type::Double, None),
            f("scale_invariant", "scaleInvariant", 4, Type::Bool, None),
            msg_field("color", "color", 5, color),
            f("text", "text", 6, Type::String, None),
        ],
        pc,
    ));
    files.push(simple(
        "ModelPrimitive",
        vec![
            msg_field("pose", "pose", 1, pose),
            msg_field("scale", "scale", 2, vec3),
            msg_field("color", "color", 3, color),
            f("override_color", "overrideColor", 4, Type::Bool, None),
            f("url", "url", 5, Type::String, None),
            f("media_type", "mediaType", 6, Type::String, None),
            f("data", "data", 7, Type::Bytes, None),
        ],
        pcv,
    ));
    files.push(simple(
        "SceneEntity",
        vec![
            msg_field("timestamp", "timestamp", 1, ".google.protobuf.Timestamp"),
            f("frame_id", "frameId", 2, Type::String, None),
            f("id", "id", 3, Type::String, None),
            msg_field("lifetime", "lifetime", 4, ".google.protobuf.Duration"),
            f("frame_locked", "frameLocked", 5, Type::Bool, None),
            repeated(msg_field(
                "metadata",
                "metadata",
                6,
                ".foxglove.KeyValuePair",
            )),
            repeated(msg_field("arrows", "arrows", 7, ".foxglove.ArrowPrimitive")),
            repeated(msg_field("cubes", "cubes", 8, ".foxglove.CubePrimitive")),
            repeated(msg_field(
                "spheres",
                "spheres",
                9,
                ".foxglove.SpherePrimitive",
            )),
            repeated(msg_field(
                "cylinders",
                "cylinders",
                10,
                ".foxglove.CylinderPrimitive",
            )),
            repeated(msg_field("lines", "lines", 11, ".foxglove.LinePrimitive")),
            repeated(msg_field(
                "triangles",
                "triangles",
                12,
                ".foxglove.TriangleListPrimitive",
            )),
            repeated(msg_field("texts", "texts", 13, ".foxglove.TextPrimitive")),
            repeated(msg_field(
                "models",
                "models",
                14,
                ".foxglove.ModelPrimitive",
            )),
        ],
        &[
            "foxglove/ArrowPrimitive.proto",
            "foxglove/CubePrimitive.proto",
            "foxglove/CylinderPrimitive.proto",
            "foxglove/KeyValuePair.proto",
            "foxglove/LinePrimitive.proto",
            "foxglove/ModelPrimitive.proto",
            "foxglove/SpherePrimitive.proto",
            "foxglove/TextPrimitive.proto",
            "foxglove/TriangleListPrimitive.proto",
            "google/protobuf/duration.proto",
            "google/protobuf/timestamp.proto",
        ],
    ));
    let mut deletion = message(
        "SceneEntityDeletion",
        vec![
            msg_field("timestamp", "timestamp", 1, ".google.protobuf.Timestamp"),
            f(
                "type",
                "type",
                2,
                Type::Enum,
                Some(".foxglove.SceneEntityDeletion.Type"),
            ),
            f("id", "id", 3, Type::String, None),
        ],
    );
    deletion
        .enum_type
        .push(enum_type("Type", &[("MATCHING_ID", 0), ("ALL", 1)]));
    files.push(file(
        "foxglove/SceneEntityDeletion.proto",
        "foxglove",
        &["google/protobuf/timestamp.proto"],
        vec![deletion],
    ));
    files.push(simple(
        "SceneUpdate",
        vec![
            repeated(msg_field(
                "deletions",
                "deletions",
                1,
                ".foxglove.SceneEntityDeletion",
            )),
            repeated(msg_field(
                "entities",
                "entities",
                2,
                ".foxglove.SceneEntity",
            )),
        ],
        &[
            "foxglove/SceneEntity.proto",
            "foxglove/SceneEntityDeletion.proto",
        ],
    ));
    files
}

/// The serialized `FileDescriptorSet` of `foxglove.SceneUpdate` and everything it imports.
pub fn scene_update_descriptor_set() -> Vec<u8> {
    FileDescriptorSet {
        file: scene_update_files(),
    }
    .encode_to_vec()
}

/// The serialized `FileDescriptorSet` of `foxglove.FrameTransform`.
pub fn frame_transform_descriptor_set() -> Vec<u8> {
    let mut files = geometry_files();
    files.retain(|f| f.name() != "foxglove/Pose.proto");
    files.push(timestamp_file());
    files.push(simple(
        "FrameTransform",
        vec![
            msg_field("timestamp", "timestamp", 1, ".google.protobuf.Timestamp"),
            f("parent_frame_id", "parentFrameId", 2, Type::String, None),
            f("child_frame_id", "childFrameId", 3, Type::String, None),
            msg_field("translation", "translation", 4, ".foxglove.Vector3"),
            msg_field("rotation", "rotation", 5, ".foxglove.Quaternion"),
        ],
        &[
            "foxglove/Quaternion.proto",
            "foxglove/Vector3.proto",
            "google/protobuf/timestamp.proto",
        ],
    ));
    FileDescriptorSet { file: files }.encode_to_vec()
}

// ---------------------------------------------------------------------------------------------
// Channels.

/// The pipeline channels of one sensor and the buffers to encode them.
#[derive(Debug)]
pub struct PipelineTopics {
    ground: TopicId,
    obstacles: TopicId,
    clusters: TopicId,
    frame_id: String,
    ground_prefix: PointCloudPrefix,
    obstacles_prefix: PointCloudPrefix,
    scene: SceneEncoder,
    buf: Vec<u8>,
    records: Vec<u8>,
    format: Format,
}

/// The schema of point cloud channels in `format`.
pub fn points_schema(format: Format) -> TopicSchema<'static> {
    match format {
        Format::Foxglove => TopicSchema {
            name: foxglove::POINT_CLOUD_SCHEMA,
            encoding: "protobuf",
            data: &foxglove::point_cloud_descriptor_set,
            message_encoding: "protobuf",
        },
        Format::Ros2 => TopicSchema {
            name: ros2::POINT_CLOUD2_SCHEMA,
            encoding: "ros2msg",
            data: &|| ros2::point_cloud2_schema_text().into_bytes(),
            message_encoding: "cdr",
        },
    }
}

/// The schema of transform channels (`/tf`, `/tf_static`) in `format`.
pub fn transform_schema(format: Format) -> TopicSchema<'static> {
    match format {
        Format::Foxglove => TopicSchema {
            name: FRAME_TRANSFORM_SCHEMA,
            encoding: "protobuf",
            data: &frame_transform_descriptor_set,
            message_encoding: "protobuf",
        },
        Format::Ros2 => TopicSchema {
            name: ros2_msgs::TF_MESSAGE_SCHEMA,
            encoding: "ros2msg",
            data: &|| {
                ros2_msgs::schema_text(ros2_msgs::TF_MESSAGE_SCHEMA)
                    .unwrap_or_default()
                    .into_bytes()
            },
            message_encoding: "cdr",
        },
    }
}

/// Encodes one transform (`parent_from_child`) into `buf` (cleared first) as `format` writes
/// it: a `foxglove.FrameTransform`, or a `tf2_msgs/msg/TFMessage` holding it.
pub fn encode_transform(
    format: Format,
    buf: &mut Vec<u8>,
    timestamp_ns: u64,
    parent: &str,
    child: &str,
    parent_from_child: &Isometry3<f64>,
) -> Result<(), SinkError> {
    match format {
        Format::Foxglove => {
            encode_frame_transform(buf, timestamp_ns, parent, child, parent_from_child);
            Ok(())
        }
        Format::Ros2 => ros2_msgs::encode_tf_message(
            buf,
            &[ros2_msgs::Transform {
                stamp_ns: timestamp_ns,
                parent,
                child,
                parent_from_child,
            }],
        )
        .map_err(|_| SinkError::TimestampOutOfRange {
            topic: "/tf".into(),
            timestamp_ns,
            format: ros2_msgs::TF_MESSAGE_SCHEMA,
        }),
    }
}

/// Encodes a point cloud of `stride`-byte records laid out as `fields` into `buf` as `format`
/// writes it (`foxglove.PointCloud` with `prefix`, or `sensor_msgs/msg/PointCloud2`).
#[allow(clippy::too_many_arguments)]
pub fn encode_points(
    format: Format,
    buf: &mut Vec<u8>,
    timestamp_ns: u64,
    prefix: &PointCloudPrefix,
    frame_id: &str,
    stride: usize,
    fields: &[(&str, usize, FieldType)],
    records: &[u8],
    topic: &str,
) -> Result<(), SinkError> {
    match format {
        Format::Foxglove => foxglove::encode_point_cloud_bytes(buf, timestamp_ns, prefix, records)
            .ok_or_else(|| SinkError::TooLarge {
                topic: topic.to_string(),
                what: "point data",
                found: records.len(),
                max: foxglove::MAX_MESSAGE_LEN - 1024,
            }),
        Format::Ros2 => {
            ros2::encode_point_cloud2_fields(buf, timestamp_ns, frame_id, stride, fields, records)
                .map_err(|e| match e {
                    ros2::Ros2EncodeError::TimestampOutOfRange => SinkError::TimestampOutOfRange {
                        topic: topic.to_string(),
                        timestamp_ns,
                        format: ros2::POINT_CLOUD2_SCHEMA,
                    },
                    ros2::Ros2EncodeError::TooLarge => SinkError::TooLarge {
                        topic: topic.to_string(),
                        what: "point data",
                        found: records.len(),
                        max: ros2::MAX_DATA_LEN,
                    },
                })
        }
    }
}

impl PipelineTopics {
    /// Adds `<prefix>/ground`, `<prefix>/obstacles` and `<prefix>/clusters` for `sensor`, whose
    /// pipeline points are in `frame_id` (`base_link` with extrinsics, else the sensor's).
    pub fn add<W: Write + Seek>(
        sink: &mut McapSink<W>,
        sensor: SensorId,
        frame_id: &str,
    ) -> Result<Self, SinkError> {
        let prefix = sink
            .channels(sensor)
            .map(|c| c.prefix().to_string())
            .ok_or(SinkError::UnknownSensor {
                id: sensor.index(),
                registered: 0,
            })?;
        let mut metadata = BTreeMap::new();
        metadata.insert("frame_id".to_string(), frame_id.to_string());
        let format = sink.format();
        let points = points_schema(format);
        let ground = sink.add_topic(&format!("{prefix}/ground"), points, &metadata)?;
        let obstacles = sink.add_topic(&format!("{prefix}/obstacles"), points, &metadata)?;
        let clusters_schema = match format {
            Format::Foxglove => TopicSchema {
                name: SCENE_UPDATE_SCHEMA,
                encoding: "protobuf",
                data: &scene_update_descriptor_set,
                message_encoding: "protobuf",
            },
            Format::Ros2 => TopicSchema {
                name: ros2_msgs::MARKER_ARRAY_SCHEMA,
                encoding: "ros2msg",
                data: &|| {
                    ros2_msgs::schema_text(ros2_msgs::MARKER_ARRAY_SCHEMA)
                        .unwrap_or_default()
                        .into_bytes()
                },
                message_encoding: "cdr",
            },
        };
        let clusters = sink.add_topic(&format!("{prefix}/clusters"), clusters_schema, &metadata)?;
        Ok(Self {
            ground,
            obstacles,
            clusters,
            frame_id: frame_id.to_string(),
            ground_prefix: PointCloudPrefix::new(frame_id),
            obstacles_prefix: PointCloudPrefix::with_fields(
                frame_id,
                OBSTACLE_STRIDE,
                &OBSTACLE_FIELDS,
            ),
            scene: SceneEncoder::default(),
            buf: Vec::new(),
            records: Vec::new(),
            format,
        })
    }

    /// Writes one sweep's outputs.
    #[allow(clippy::too_many_arguments)]
    pub fn write<W: Write + Seek>(
        &mut self,
        sink: &mut McapSink<W>,
        log_time_ns: u64,
        timestamp_ns: u64,
        ground: &[Point],
        obstacles: &[Point],
        obstacle_clusters: &[u32],
        clusters: &[Cluster],
    ) -> Result<(), SinkError> {
        encode_points(
            self.format,
            &mut self.buf,
            timestamp_ns,
            &self.ground_prefix,
            &self.frame_id,
            POINT_STRIDE,
            &POINT_FIELDS,
            crate::point::as_bytes(ground),
            "ground",
        )?;
        sink.write_message(self.ground, log_time_ns, &self.buf)?;
        obstacle_records(obstacles, obstacle_clusters, &mut self.records);
        encode_points(
            self.format,
            &mut self.buf,
            timestamp_ns,
            &self.obstacles_prefix,
            &self.frame_id,
            OBSTACLE_STRIDE,
            &OBSTACLE_FIELDS,
            &self.records,
            "obstacles",
        )?;
        sink.write_message(self.obstacles, log_time_ns, &self.buf)?;
        match self.format {
            Format::Foxglove => {
                self.scene
                    .encode_clusters(&mut self.buf, timestamp_ns, &self.frame_id, clusters);
            }
            Format::Ros2 => ros2_msgs::encode_cluster_markers(
                &mut self.buf,
                timestamp_ns,
                &self.frame_id,
                "clusters",
                clusters,
            )
            .map_err(|_| SinkError::TimestampOutOfRange {
                topic: "clusters".into(),
                timestamp_ns,
                format: ros2_msgs::MARKER_ARRAY_SCHEMA,
            })?,
        }
        sink.write_message(self.clusters, log_time_ns, &self.buf)
    }
}

/// Adds the `/tf_static` channel.
pub fn add_tf_static<W: Write + Seek>(sink: &mut McapSink<W>) -> Result<TopicId, SinkError> {
    let schema = transform_schema(sink.format());
    sink.add_topic(TF_STATIC_TOPIC, schema, &BTreeMap::new())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::cluster::OrientedBox;
    use crate::sink::read::{FrameTransform, KeyValuePair, SceneUpdate, Vector3};

    /// The hand encoding decodes with prost into mirrors of the official messages.
    #[test]
    fn scene_update_round_trips_through_prost() {
        let mut a = Cluster::default();
        a.point_count = 42;
        a.oriented = OrientedBox {
            center: [3.0, -1.0, 0.5],
            size_m: [4.5, 1.8, 1.5],
            yaw_rad: std::f32::consts::FRAC_PI_2,
        };
        let mut b = Cluster::default();
        b.point_count = 7;
        let clusters = [a, b];
        let mut buf = Vec::new();
        SceneEncoder::default().encode_clusters(&mut buf, 2_500_000_001, "base_link", &clusters);
        let u = SceneUpdate::decode(buf.as_slice()).unwrap();
        assert_eq!(u.deletions.len(), 1);
        assert_eq!(u.deletions[0].r#type, 1, "ALL");
        assert_eq!(u.entities.len(), 2);
        let e = &u.entities[0];
        assert_eq!((e.frame_id.as_str(), e.id.as_str()), ("base_link", "0"));
        assert_eq!(
            e.timestamp,
            Some(prost_types::Timestamp {
                seconds: 2,
                nanos: 500_000_001
            })
        );
        assert_eq!(
            e.metadata,
            [KeyValuePair {
                key: "points".into(),
                value: "42".into()
            }]
        );
        let cube = &e.cubes[0];
        let pose = cube.pose.clone().unwrap();
        assert_eq!(
            pose.position,
            Some(Vector3 {
                x: 3.0,
                y: -1.0,
                z: 0.5
            })
        );
        let q = pose.orientation.unwrap();
        let h = std::f64::consts::FRAC_1_SQRT_2;
        assert!((q.z - h).abs() < 1e-7 && (q.w - h).abs() < 1e-7 && q.x == 0.0);
        let s = cube.size.clone().unwrap();
        assert!((s.x - 4.5).abs() < 1e-6 && (s.y - 1.8).abs() < 1e-6 && (s.z - 1.5).abs() < 1e-6);
        let c = cube.color.clone().unwrap();
        assert_eq!(c.a, 0.5);
        let expected = cluster_color(0);
        assert!((c.r - f64::from(expected[0])).abs() < 1e-7);
        assert_eq!(u.entities[1].id, "1");
        // An empty sweep still deletes the previous boxes.
        SceneEncoder::default().encode_clusters(&mut buf, 1, "x", &[]);
        let u = SceneUpdate::decode(buf.as_slice()).unwrap();
        assert_eq!((u.deletions.len(), u.entities.len()), (1, 0));
    }

    #[test]
    fn frame_transform_round_trips_through_prost() {
        let pose = Isometry3::new(
            nalgebra::Vector3::new(1.2, 0.0, 1.8),
            nalgebra::Vector3::new(0.0, 0.0, std::f64::consts::FRAC_PI_2),
        );
        let mut buf = Vec::new();
        encode_frame_transform(&mut buf, 7, "base_link", "os1", &pose);
        let t = FrameTransform::decode(buf.as_slice()).unwrap();
        assert_eq!(
            (t.parent_frame_id.as_str(), t.child_frame_id.as_str()),
            ("base_link", "os1")
        );
        assert_eq!(
            t.translation,
            Some(Vector3 {
                x: 1.2,
                y: 0.0,
                z: 1.8
            })
        );
        let q = t.rotation.unwrap();
        let h = std::f64::consts::FRAC_1_SQRT_2;
        assert!((q.z - h).abs() < 1e-12 && (q.w - h).abs() < 1e-12);
    }

    #[test]
    fn descriptor_sets_are_complete_and_ordered() {
        for data in [
            scene_update_descriptor_set(),
            frame_transform_descriptor_set(),
        ] {
            let fds = FileDescriptorSet::decode(data.as_slice()).unwrap();
            let names: Vec<_> = fds.file.iter().map(|f| f.name().to_owned()).collect();
            let mut types = Vec::new();
            for fdp in &fds.file {
                for m in &fdp.message_type {
                    types.push(format!(".{}.{}", fdp.package(), m.name()));
                    for e in &m.enum_type {
                        types.push(format!(".{}.{}.{}", fdp.package(), m.name(), e.name()));
                    }
                }
            }
            for (i, fdp) in fds.file.iter().enumerate() {
                for dep in &fdp.dependency {
                    let at = names.iter().position(|n| n == dep).expect(dep);
                    assert!(at < i, "{dep} must come before {}", fdp.name());
                }
                for m in &fdp.message_type {
                    for fld in &m.field {
                        if let Some(t) = &fld.type_name {
                            assert!(types.contains(t), "{t} used by {} is defined", m.name());
                        }
                    }
                }
            }
            let unique: std::collections::BTreeSet<_> = names.iter().collect();
            assert_eq!(unique.len(), names.len(), "each file once");
        }
    }

    #[test]
    fn obstacle_records_carry_the_cluster() {
        let p = Point {
            x: 1.0,
            t: 5,
            ..Point::default()
        };
        let mut out = Vec::new();
        obstacle_records(&[p, p], &[3, 9], &mut out);
        assert_eq!(out.len(), 2 * OBSTACLE_STRIDE);
        assert_eq!(&out[24..28], &3u32.to_le_bytes());
        assert_eq!(&out[52..56], &9u32.to_le_bytes());
        assert_eq!(&out[0..4], &1.0f32.to_le_bytes());
    }
}
