//! The ROS 2 messages of `--format ros2` beyond the point clouds of [`super::ros2`]: IMU
//! samples, transforms, diagnostics, cluster markers, the sensor metadata string, and the raw
//! packets as the ROS drivers' own packet messages. Each is CDR (XCDR1 little-endian, see
//! [`super::ros2`]) with its `ros2msg` schema: the message's definition, then every type it uses
//! after a line of 80 `=` and a line `MSG: <package>/<Type>` (rosbag2's concatenated form).
//!
//! Field lists are those of the `.msg` files of ros2/common_interfaces (`sensor_msgs/Imu`,
//! `geometry_msgs/{TransformStamped, Transform, Vector3, Quaternion, Pose, Point}`,
//! `diagnostic_msgs/{DiagnosticArray, DiagnosticStatus, KeyValue}`,
//! `visualization_msgs/{MarkerArray, Marker, UVCoordinate, MeshFile}` as in Humble's later
//! releases and Jazzy, `std_msgs/{String, ColorRGBA}`, `sensor_msgs/CompressedImage`),
//! ros2/geometry2 (`tf2_msgs/TFMessage`), ros2/rcl_interfaces (`builtin_interfaces/Duration`),
//! ros-drivers/velodyne (`velodyne_msgs/{VelodyneScan, VelodynePacket}`), ouster-lidar/ouster-ros
//! (`ouster_sensor_msgs/PacketMsg`) and tier4/nebula (`pandar_msgs/{PandarScan, PandarPacket}`).
//! Type names inside the definitions are written with their package, so no reader has to
//! resolve a bare name.

use nalgebra::Isometry3;

use super::ros2::{Cdr, HEADER_MSG, SEPARATOR, TIME_MSG};
use crate::pipeline::cluster::Cluster;

/// `sensor_msgs/msg/Imu`.
pub const IMU_SCHEMA: &str = "sensor_msgs/msg/Imu";
/// `tf2_msgs/msg/TFMessage`.
pub const TF_MESSAGE_SCHEMA: &str = "tf2_msgs/msg/TFMessage";
/// `diagnostic_msgs/msg/DiagnosticArray`.
pub const DIAGNOSTIC_ARRAY_SCHEMA: &str = "diagnostic_msgs/msg/DiagnosticArray";
/// `visualization_msgs/msg/MarkerArray`.
pub const MARKER_ARRAY_SCHEMA: &str = "visualization_msgs/msg/MarkerArray";
/// `std_msgs/msg/String`.
pub const STRING_SCHEMA: &str = "std_msgs/msg/String";
/// `velodyne_msgs/msg/VelodyneScan`.
pub const VELODYNE_SCAN_SCHEMA: &str = "velodyne_msgs/msg/VelodyneScan";
/// `ouster_sensor_msgs/msg/PacketMsg`.
pub const OUSTER_PACKET_SCHEMA: &str = "ouster_sensor_msgs/msg/PacketMsg";
/// `pandar_msgs/msg/PandarScan`.
pub const PANDAR_SCAN_SCHEMA: &str = "pandar_msgs/msg/PandarScan";

/// Bytes of a `VelodynePacket`'s data (fixed).
pub const VELODYNE_PACKET_BYTES: usize = 1206;
/// Bytes of a `PandarPacket`'s data array (fixed; `size` says how many are the packet's).
pub const PANDAR_PACKET_BYTES: usize = 1500;

const QUATERNION_MSG: &str = "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n";
const VECTOR3_MSG: &str = "float64 x\nfloat64 y\nfloat64 z\n";
const POINT_MSG: &str = "float64 x\nfloat64 y\nfloat64 z\n";
const POSE_MSG: &str = "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n";
const TRANSFORM_MSG: &str =
    "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n";
const TRANSFORM_STAMPED_MSG: &str = "\
std_msgs/Header header
string child_frame_id
geometry_msgs/Transform transform
";
const TF_MESSAGE_MSG: &str = "geometry_msgs/TransformStamped[] transforms\n";
const IMU_MSG: &str = "\
std_msgs/Header header

geometry_msgs/Quaternion orientation
float64[9] orientation_covariance # Row major about x, y, z axes

geometry_msgs/Vector3 angular_velocity
float64[9] angular_velocity_covariance # Row major about x, y, z axes

geometry_msgs/Vector3 linear_acceleration
float64[9] linear_acceleration_covariance # Row major x, y z
";
const DIAGNOSTIC_ARRAY_MSG: &str = "\
std_msgs/Header header
diagnostic_msgs/DiagnosticStatus[] status
";
const DIAGNOSTIC_STATUS_MSG: &str = "\
byte OK=0
byte WARN=1
byte ERROR=2
byte STALE=3

byte level
string name
string message
string hardware_id
diagnostic_msgs/KeyValue[] values
";
const KEY_VALUE_MSG: &str = "string key\nstring value\n";
const MARKER_ARRAY_MSG: &str = "visualization_msgs/Marker[] markers\n";
const MARKER_MSG: &str = "\
int32 ARROW=0
int32 CUBE=1
int32 SPHERE=2
int32 CYLINDER=3
int32 LINE_STRIP=4
int32 LINE_LIST=5
int32 CUBE_LIST=6
int32 SPHERE_LIST=7
int32 POINTS=8
int32 TEXT_VIEW_FACING=9
int32 MESH_RESOURCE=10
int32 TRIANGLE_LIST=11

int32 ADD=0
int32 MODIFY=0
int32 DELETE=2
int32 DELETEALL=3

std_msgs/Header header
string ns
int32 id
int32 type
int32 action
geometry_msgs/Pose pose
geometry_msgs/Vector3 scale
std_msgs/ColorRGBA color
builtin_interfaces/Duration lifetime
bool frame_locked
geometry_msgs/Point[] points
std_msgs/ColorRGBA[] colors
string texture_resource
sensor_msgs/CompressedImage texture
visualization_msgs/UVCoordinate[] uv_coordinates
string text
string mesh_resource
visualization_msgs/MeshFile mesh_file
bool mesh_use_embedded_materials
";
const COLOR_RGBA_MSG: &str = "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n";
const DURATION_MSG: &str = "int32 sec\nuint32 nanosec\n";
const COMPRESSED_IMAGE_MSG: &str = "std_msgs/Header header\nstring format\nuint8[] data\n";
const UV_COORDINATE_MSG: &str = "float32 u\nfloat32 v\n";
const MESH_FILE_MSG: &str = "string filename\nuint8[] data\n";
const STRING_MSG: &str = "string data\n";
const VELODYNE_SCAN_MSG: &str = "\
std_msgs/Header header
velodyne_msgs/VelodynePacket[] packets
";
const VELODYNE_PACKET_MSG: &str = "builtin_interfaces/Time stamp\nuint8[1206] data\n";
const OUSTER_PACKET_MSG: &str = "uint8[] buf\n";
const PANDAR_SCAN_MSG: &str = "\
std_msgs/Header header
pandar_msgs/PandarPacket[] packets
";
const PANDAR_PACKET_MSG: &str = "builtin_interfaces/Time stamp\nuint8[1500] data\nuint32 size\n";

const HEADER: (&str, &str) = ("std_msgs/Header", HEADER_MSG);
const TIME: (&str, &str) = ("builtin_interfaces/Time", TIME_MSG);

/// A definition and its dependencies in rosbag2's concatenated form.
fn definition(top: &str, deps: &[(&str, &str)]) -> String {
    let mut s = String::with_capacity(4096);
    s.push_str(top);
    for (name, text) in deps {
        s.push('\n');
        s.push_str(SEPARATOR);
        s.push_str("MSG: ");
        s.push_str(name);
        s.push('\n');
        s.push_str(text);
    }
    s
}

/// The `ros2msg` schema data of a message type of this module, by schema name.
pub fn schema_text(schema: &str) -> Option<String> {
    let quaternion = ("geometry_msgs/Quaternion", QUATERNION_MSG);
    let vector3 = ("geometry_msgs/Vector3", VECTOR3_MSG);
    Some(match schema {
        IMU_SCHEMA => definition(IMU_MSG, &[quaternion, HEADER, TIME, vector3]),
        TF_MESSAGE_SCHEMA => definition(
            TF_MESSAGE_MSG,
            &[
                ("geometry_msgs/Transform", TRANSFORM_MSG),
                ("geometry_msgs/TransformStamped", TRANSFORM_STAMPED_MSG),
                quaternion,
                vector3,
                HEADER,
                TIME,
            ],
        ),
        DIAGNOSTIC_ARRAY_SCHEMA => definition(
            DIAGNOSTIC_ARRAY_MSG,
            &[
                ("diagnostic_msgs/DiagnosticStatus", DIAGNOSTIC_STATUS_MSG),
                ("diagnostic_msgs/KeyValue", KEY_VALUE_MSG),
                HEADER,
                TIME,
            ],
        ),
        MARKER_ARRAY_SCHEMA => definition(
            MARKER_ARRAY_MSG,
            &[
                ("visualization_msgs/Marker", MARKER_MSG),
                ("builtin_interfaces/Duration", DURATION_MSG),
                TIME,
                ("geometry_msgs/Point", POINT_MSG),
                ("geometry_msgs/Pose", POSE_MSG),
                quaternion,
                vector3,
                ("sensor_msgs/CompressedImage", COMPRESSED_IMAGE_MSG),
                ("std_msgs/ColorRGBA", COLOR_RGBA_MSG),
                HEADER,
                ("visualization_msgs/MeshFile", MESH_FILE_MSG),
                ("visualization_msgs/UVCoordinate", UV_COORDINATE_MSG),
            ],
        ),
        STRING_SCHEMA => STRING_MSG.to_string(),
        VELODYNE_SCAN_SCHEMA => definition(
            VELODYNE_SCAN_MSG,
            &[
                TIME,
                HEADER,
                ("velodyne_msgs/VelodynePacket", VELODYNE_PACKET_MSG),
            ],
        ),
        OUSTER_PACKET_SCHEMA => OUSTER_PACKET_MSG.to_string(),
        PANDAR_SCAN_SCHEMA => definition(
            PANDAR_SCAN_MSG,
            &[
                TIME,
                ("pandar_msgs/PandarPacket", PANDAR_PACKET_MSG),
                HEADER,
            ],
        ),
        _ => return None,
    })
}

/// A time that `builtin_interfaces/Time` cannot hold (seconds past `int32`, 2038).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TimeOutOfRange;

fn header(w: &mut Cdr<'_>, stamp_ns: u64, frame_id: &str) -> Result<(), TimeOutOfRange> {
    w.time(stamp_ns).ok_or(TimeOutOfRange)?;
    w.string(frame_id);
    Ok(())
}

fn vector3(w: &mut Cdr<'_>, v: [f64; 3]) {
    for x in v {
        w.f64(x);
    }
}

/// One `sensor_msgs/msg/Imu` into `buf` (cleared first): no orientation (its covariance's
/// first element −1, as the message documents for "no estimate"), covariances unknown (0).
pub fn encode_imu(
    buf: &mut Vec<u8>,
    stamp_ns: u64,
    frame_id: &str,
    angular_velocity: [f64; 3],
    linear_acceleration: [f64; 3],
) -> Result<(), TimeOutOfRange> {
    buf.clear();
    let mut w = Cdr::new(buf);
    header(&mut w, stamp_ns, frame_id)?;
    for x in [0.0, 0.0, 0.0, 1.0] {
        w.f64(x);
    }
    w.f64(-1.0);
    for _ in 1..9 {
        w.f64(0.0);
    }
    vector3(&mut w, angular_velocity);
    for _ in 0..9 {
        w.f64(0.0);
    }
    vector3(&mut w, linear_acceleration);
    for _ in 0..9 {
        w.f64(0.0);
    }
    Ok(())
}

/// One transform of a `tf2_msgs/msg/TFMessage`: `parent_from_child` at `stamp_ns`.
#[derive(Clone, Copy, Debug)]
pub struct Transform<'a> {
    /// Stamp, ns since the epoch.
    pub stamp_ns: u64,
    /// Parent frame (`header.frame_id`).
    pub parent: &'a str,
    /// Child frame.
    pub child: &'a str,
    /// The child's pose in the parent.
    pub parent_from_child: &'a Isometry3<f64>,
}

/// One `tf2_msgs/msg/TFMessage` into `buf` (cleared first).
pub fn encode_tf_message(
    buf: &mut Vec<u8>,
    transforms: &[Transform<'_>],
) -> Result<(), TimeOutOfRange> {
    buf.clear();
    let mut w = Cdr::new(buf);
    w.u32(transforms.len() as u32);
    for t in transforms {
        header(&mut w, t.stamp_ns, t.parent)?;
        w.string(t.child);
        let v = t.parent_from_child.translation.vector;
        vector3(&mut w, [v.x, v.y, v.z]);
        let q = t.parent_from_child.rotation;
        for x in [q.i, q.j, q.k, q.w] {
            w.f64(x);
        }
    }
    Ok(())
}

/// `DiagnosticStatus.level`.
pub mod level {
    /// `OK`
    pub const OK: u8 = 0;
    /// `WARN`
    pub const WARN: u8 = 1;
}

/// One `diagnostic_msgs/msg/DiagnosticArray` holding one status into `buf` (cleared first).
pub fn encode_diagnostic_array(
    buf: &mut Vec<u8>,
    stamp_ns: u64,
    name: &str,
    hardware_id: &str,
    level: u8,
    values: &[(String, String)],
) -> Result<(), TimeOutOfRange> {
    buf.clear();
    let mut w = Cdr::new(buf);
    header(&mut w, stamp_ns, "")?;
    w.u32(1);
    w.u8(level);
    w.string(name);
    w.string("");
    w.string(hardware_id);
    w.u32(values.len() as u32);
    for (k, v) in values {
        w.string(k);
        w.string(v);
    }
    Ok(())
}

/// The key/values of a diagnostics JSON object: nested objects as `a.b` keys, arrays and
/// scalars as their JSON text (strings without quotes), in the object's order.
pub fn json_key_values(v: &serde_json::Value, out: &mut Vec<(String, String)>) {
    fn walk(prefix: &str, v: &serde_json::Value, out: &mut Vec<(String, String)>) {
        match v {
            serde_json::Value::Object(m) => {
                for (k, x) in m {
                    let key = if prefix.is_empty() {
                        k.clone()
                    } else {
                        format!("{prefix}.{k}")
                    };
                    walk(&key, x, out);
                }
            }
            serde_json::Value::String(s) => out.push((prefix.to_string(), s.clone())),
            other => out.push((prefix.to_string(), other.to_string())),
        }
    }
    out.clear();
    walk("", v, out);
}

/// `Marker.type` CUBE, `Marker.action` ADD and DELETEALL.
const MARKER_CUBE: i32 = 1;
const MARKER_ADD: i32 = 0;
const MARKER_DELETEALL: i32 = 3;

#[allow(clippy::too_many_arguments)]
fn marker(
    w: &mut Cdr<'_>,
    stamp_ns: u64,
    frame_id: &str,
    ns: &str,
    id: i32,
    action: i32,
    pose: ([f64; 3], [f64; 4]),
    scale: [f64; 3],
    color: [f32; 4],
    text: &str,
) -> Result<(), TimeOutOfRange> {
    header(w, stamp_ns, frame_id)?;
    w.string(ns);
    w.i32(id);
    w.i32(MARKER_CUBE);
    w.i32(action);
    vector3(w, pose.0);
    for x in pose.1 {
        w.f64(x);
    }
    vector3(w, scale);
    for x in color {
        w.f32(x);
    }
    w.i32(0); // lifetime: forever (until the next DELETEALL)
    w.u32(0);
    w.u8(0); // frame_locked
    w.u32(0); // points
    w.u32(0); // colors
    w.string(""); // texture_resource
    header(w, 0, "")?; // texture: sensor_msgs/CompressedImage, empty
    w.string("");
    w.u32(0);
    w.u32(0); // uv_coordinates
    w.string(text);
    w.string(""); // mesh_resource
    w.string(""); // mesh_file.filename
    w.u32(0); // mesh_file.data
    w.u8(0); // mesh_use_embedded_materials
    Ok(())
}

/// One `visualization_msgs/msg/MarkerArray` of a sweep's clusters into `buf` (cleared first):
/// a DELETEALL marker first (the previous sweep's cubes go), then one CUBE per cluster (id =
/// its index in the sweep; centre, size and yaw of its minimum-area box; colour of
/// [`super::scene::cluster_color`], alpha 0.5; its point count as the marker's `text`), as the
/// Foxglove output's `SceneUpdate` does.
pub fn encode_cluster_markers(
    buf: &mut Vec<u8>,
    stamp_ns: u64,
    frame_id: &str,
    ns: &str,
    clusters: &[Cluster],
) -> Result<(), TimeOutOfRange> {
    buf.clear();
    let mut w = Cdr::new(buf);
    w.u32(clusters.len() as u32 + 1);
    let none = ([0.0; 3], [0.0, 0.0, 0.0, 1.0]);
    marker(
        &mut w,
        stamp_ns,
        frame_id,
        ns,
        0,
        MARKER_DELETEALL,
        none,
        [0.0; 3],
        [0.0; 4],
        "",
    )?;
    let mut text = String::new();
    for (k, c) in clusters.iter().enumerate() {
        let b = &c.oriented;
        let half = f64::from(b.yaw_rad) * 0.5;
        let [r, g, bl] = super::scene::cluster_color(k as u32);
        text.clear();
        use std::fmt::Write as _;
        let _ = write!(text, "{}", c.point_count);
        marker(
            &mut w,
            stamp_ns,
            frame_id,
            ns,
            i32::try_from(k).unwrap_or(i32::MAX),
            MARKER_ADD,
            (b.center.map(f64::from), [0.0, 0.0, half.sin(), half.cos()]),
            b.size_m.map(f64::from),
            [r, g, bl, 0.5],
            &text,
        )?;
    }
    Ok(())
}

/// One `std_msgs/msg/String` into `buf` (cleared first).
pub fn encode_string(buf: &mut Vec<u8>, s: &str) {
    buf.clear();
    let mut w = Cdr::new(buf);
    w.string(s);
}

/// One `ouster_sensor_msgs/msg/PacketMsg` into `buf` (cleared first).
pub fn encode_ouster_packet(buf: &mut Vec<u8>, payload: &[u8]) {
    buf.clear();
    let mut w = Cdr::new(buf);
    w.bytes(payload);
}

/// One `velodyne_msgs/msg/VelodyneScan` (or, with `pandar`, `pandar_msgs/msg/PandarScan`)
/// into `buf` (cleared first): the header stamped with the first packet's time, then each
/// packet with its own stamp. Velodyne packets must be [`VELODYNE_PACKET_BYTES`] long, Hesai
/// packets at most [`PANDAR_PACKET_BYTES`] (zero-filled, `size` = the packet's length).
pub fn encode_packet_scan(
    buf: &mut Vec<u8>,
    pandar: bool,
    frame_id: &str,
    packets: &[(u64, Vec<u8>)],
) -> Result<(), TimeOutOfRange> {
    buf.clear();
    let mut w = Cdr::new(buf);
    header(&mut w, packets.first().map_or(0, |p| p.0), frame_id)?;
    w.u32(packets.len() as u32);
    for (t, data) in packets {
        w.time(*t).ok_or(TimeOutOfRange)?;
        if pandar {
            let n = data.len().min(PANDAR_PACKET_BYTES);
            w.buf.extend_from_slice(&data[..n]);
            w.buf.resize(w.buf.len() + PANDAR_PACKET_BYTES - n, 0);
            w.u32(n as u32);
        } else {
            let n = data.len().min(VELODYNE_PACKET_BYTES);
            w.buf.extend_from_slice(&data[..n]);
            w.buf.resize(w.buf.len() + VELODYNE_PACKET_BYTES - n, 0);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn u32_at(b: &[u8], at: usize) -> u32 {
        u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
    }

    fn f64_at(b: &[u8], at: usize) -> f64 {
        f64::from_le_bytes(b[at..at + 8].try_into().unwrap())
    }

    /// Offsets written out by hand from the XCDR1 rules (each primitive aligned to its size
    /// from the end of the 4-byte encapsulation header).
    #[test]
    fn imu_layout() {
        let mut buf = Vec::new();
        encode_imu(
            &mut buf,
            5_000_000_007,
            "ab",
            [1.0, 2.0, 3.0],
            [4.0, 5.0, 6.0],
        )
        .unwrap();
        assert_eq!(&buf[..4], &[0, 1, 0, 0]);
        let b = &buf[4..];
        assert_eq!(u32_at(b, 0), 5);
        assert_eq!(u32_at(b, 4), 7);
        assert_eq!(u32_at(b, 8), 3);
        assert_eq!(&b[12..15], b"ab\0");
        // orientation at 16 (aligned to 8): x y z w
        assert_eq!(f64_at(b, 16 + 24), 1.0);
        // orientation_covariance at 48: −1 then zeros
        assert_eq!(f64_at(b, 48), -1.0);
        // angular_velocity at 48 + 72 = 120
        assert_eq!(f64_at(b, 120), 1.0);
        assert_eq!(f64_at(b, 136), 3.0);
        // angular_velocity_covariance at 144, linear_acceleration at 216
        assert_eq!(f64_at(b, 216), 4.0);
        assert_eq!(f64_at(b, 232), 6.0);
        assert_eq!(b.len(), 240 + 72);
    }

    #[test]
    fn tf_layout() {
        let mut buf = Vec::new();
        let iso = Isometry3::translation(1.0, 2.0, 3.0);
        let t = Transform {
            stamp_ns: 1_000_000_000,
            parent: "odom",
            child: "x",
            parent_from_child: &iso,
        };
        encode_tf_message(&mut buf, &[t]).unwrap();
        let b = &buf[4..];
        assert_eq!(u32_at(b, 0), 1); // one transform
        assert_eq!(u32_at(b, 4), 1); // sec
        assert_eq!(u32_at(b, 8), 0); // nanosec
        assert_eq!(u32_at(b, 12), 5); // "odom\0"
        assert_eq!(&b[16..21], b"odom\0");
        assert_eq!(u32_at(b, 24), 2); // "x\0" at 28
                                      // translation aligned to 8: 32
        assert_eq!(f64_at(b, 32), 1.0);
        assert_eq!(f64_at(b, 48), 3.0);
        assert_eq!(f64_at(b, 56 + 24), 1.0); // rotation w
        assert_eq!(b.len(), 88);
    }

    #[test]
    fn velodyne_scan_layout() {
        let mut buf = Vec::new();
        let p = vec![7u8; VELODYNE_PACKET_BYTES];
        encode_packet_scan(&mut buf, false, "v", &[(2_000_000_003, p.clone()), (3, p)]).unwrap();
        let b = &buf[4..];
        assert_eq!(u32_at(b, 0), 2);
        assert_eq!(u32_at(b, 4), 3);
        assert_eq!(u32_at(b, 8), 2); // "v\0"
        assert_eq!(u32_at(b, 16), 2); // packets
        assert_eq!(u32_at(b, 20), 2); // first packet's sec
        assert_eq!(u32_at(b, 24), 3);
        assert_eq!(b[28], 7);
        // second packet: 28 + 1206 = 1234, aligned to 4 → 1236
        assert_eq!(u32_at(b, 1236), 0);
        assert_eq!(u32_at(b, 1240), 3);
        assert_eq!(b.len(), 1244 + 1206);
    }

    #[test]
    fn diagnostics_flatten_nested_objects() {
        let mut kv = Vec::new();
        json_key_values(
            &serde_json::json!({"a": 1, "b": {"c": "x", "d": [1, 2]}, "e": null}),
            &mut kv,
        );
        let want = [("a", "1"), ("b.c", "x"), ("b.d", "[1,2]"), ("e", "null")];
        assert_eq!(kv.len(), want.len());
        for ((k, v), (wk, wv)) in kv.iter().zip(want) {
            assert_eq!((k.as_str(), v.as_str()), (wk, wv));
        }
    }

    #[test]
    fn every_schema_names_each_dependency_once() {
        for s in [
            IMU_SCHEMA,
            TF_MESSAGE_SCHEMA,
            DIAGNOSTIC_ARRAY_SCHEMA,
            MARKER_ARRAY_SCHEMA,
            VELODYNE_SCAN_SCHEMA,
            PANDAR_SCAN_SCHEMA,
        ] {
            let text = schema_text(s).unwrap();
            let mut names: Vec<&str> = text
                .lines()
                .filter_map(|l| l.strip_prefix("MSG: "))
                .collect();
            let n = names.len();
            names.sort_unstable();
            names.dedup();
            assert_eq!(names.len(), n, "{s}");
            // Every field type with a package is defined in the text.
            for line in text.lines() {
                let Some(ty) = line.split_whitespace().next() else {
                    continue;
                };
                let ty = ty.split('[').next().unwrap_or(ty);
                if ty.contains('/') && !line.starts_with("MSG:") {
                    assert!(names.contains(&ty), "{s}: {ty} undefined");
                }
            }
        }
    }
}
