//! Protobuf encodings: `foxglove.PointCloud` and `ringscan.RawPacket`.
//!
//! Messages are written by hand with a tiny protobuf writer (varints and length-delimited
//! fields) so a sweep's point bytes go from [`crate::point::as_bytes`] straight into the one
//! message buffer the sink reuses. The schemas travel in the MCAP file as serialized
//! `google.protobuf.FileDescriptorSet`s built here with `prost-types`.
//!
//! The Foxglove definitions reproduced in [`point_cloud_descriptor_set`] are those of the
//! official schema files `foxglove/PointCloud.proto`, `foxglove/PackedElementField.proto`,
//! `foxglove/Pose.proto`, `foxglove/Vector3.proto` and `foxglove/Quaternion.proto` from
//! <https://github.com/foxglove/schemas> (`schemas/proto/foxglove/`, now maintained in
//! <https://github.com/foxglove/foxglove-sdk>), and `google/protobuf/timestamp.proto` from
//! protobuf's well-known types (`int64 seconds = 1; int32 nanos = 2;`).

use std::io::Write as _;

use prost::Message as _;
use prost_types::field_descriptor_proto::{Label, Type};
use prost_types::{
    DescriptorProto, EnumDescriptorProto, EnumValueDescriptorProto, FieldDescriptorProto,
    FileDescriptorProto, FileDescriptorSet,
};

use crate::point::{FieldType, Point, POINT_FIELDS, POINT_STRIDE};

/// Schema name of the point cloud message.
pub const POINT_CLOUD_SCHEMA: &str = "foxglove.PointCloud";

/// Schema name of the raw UDP payload message.
///
/// ```text
/// // ringscan/RawPacket.proto
/// syntax = "proto3";
/// import "google/protobuf/timestamp.proto";
/// package ringscan;
/// // One UDP payload as received, so a drive can be decoded again later.
/// message RawPacket {
///   google.protobuf.Timestamp timestamp = 1; // host receive time (the capture time for pcap)
///   string source_address = 2;               // sender IPv4 address, dotted quad
///   uint32 source_port = 3;                  // sender UDP port
///   uint32 destination_port = 4;             // UDP port the datagram was sent to
///   bytes payload = 5;                       // the UDP payload, byte for byte
/// }
/// ```
pub const RAW_PACKET_SCHEMA: &str = "ringscan.RawPacket";

/// Largest message body protobuf readers accept (2 GiB − 1).
pub const MAX_MESSAGE_LEN: usize = i32::MAX as usize;

/// `foxglove.PackedElementField.NumericType` values (PackedElementField.proto).
mod numeric_type {
    pub const UINT8: u64 = 1;
    pub const UINT16: u64 = 3;
    pub const UINT32: u64 = 5;
    pub const FLOAT32: u64 = 7;
}

// ---------------------------------------------------------------------------------------------
// A minimal protobuf writer.

const WIRE_VARINT: u32 = 0;
const WIRE_FIXED64: u32 = 1;
const WIRE_LEN: u32 = 2;
const WIRE_FIXED32: u32 = 5;

/// Appends `v` as a base-128 varint.
pub fn put_varint(buf: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        buf.push((v as u8) | 0x80);
        v >>= 7;
    }
    buf.push(v as u8);
}

/// Number of bytes `v` takes as a varint.
pub fn varint_len(v: u64) -> usize {
    // 1 byte per started group of 7 bits; 0 still takes one byte.
    let bits = 64 - (v | 1).leading_zeros() as usize;
    bits.div_ceil(7)
}

pub(super) fn put_key(buf: &mut Vec<u8>, field: u32, wire: u32) {
    put_varint(buf, u64::from((field << 3) | wire));
}

pub(super) fn put_varint_field(buf: &mut Vec<u8>, field: u32, v: u64) {
    if v != 0 {
        put_key(buf, field, WIRE_VARINT);
        put_varint(buf, v);
    }
}

pub(super) fn put_fixed32_field(buf: &mut Vec<u8>, field: u32, v: u32) {
    if v != 0 {
        put_key(buf, field, WIRE_FIXED32);
        buf.extend_from_slice(&v.to_le_bytes());
    }
}

pub(super) fn put_double_field(buf: &mut Vec<u8>, field: u32, v: f64) {
    if v.to_bits() != 0 {
        put_key(buf, field, WIRE_FIXED64);
        buf.extend_from_slice(&v.to_le_bytes());
    }
}

/// Writes a length-delimited field (string, bytes or an encoded sub-message), even when empty:
/// for a sub-message an empty body still marks the field as present.
pub(super) fn put_len_field(buf: &mut Vec<u8>, field: u32, bytes: &[u8]) {
    put_key(buf, field, WIRE_LEN);
    put_varint(buf, bytes.len() as u64);
    buf.extend_from_slice(bytes);
}

pub(super) fn put_string_field(buf: &mut Vec<u8>, field: u32, s: &str) {
    if !s.is_empty() {
        put_len_field(buf, field, s.as_bytes());
    }
}

/// Writes field `field` as a `google.protobuf.Timestamp` for `ns` nanoseconds since the epoch.
pub(super) fn put_timestamp_field(buf: &mut Vec<u8>, field: u32, ns: u64) {
    let seconds = ns / 1_000_000_000;
    let nanos = ns % 1_000_000_000;
    let mut len = 0;
    if seconds != 0 {
        len += 1 + varint_len(seconds);
    }
    if nanos != 0 {
        len += 1 + varint_len(nanos);
    }
    put_key(buf, field, WIRE_LEN);
    put_varint(buf, len as u64);
    // Timestamp { int64 seconds = 1; int32 nanos = 2; } — both non-negative here, so their
    // varints equal the unsigned ones.
    put_varint_field(buf, 1, seconds);
    put_varint_field(buf, 2, nanos);
}

// ---------------------------------------------------------------------------------------------
// foxglove.PointCloud

fn numeric_type_of(t: FieldType) -> u64 {
    match t {
        FieldType::U8 => numeric_type::UINT8,
        FieldType::U16 => numeric_type::UINT16,
        FieldType::U32 => numeric_type::UINT32,
        FieldType::F32 => numeric_type::FLOAT32,
    }
}

/// The fields of a `foxglove.PointCloud` that are the same for every sweep of one sensor
/// (`frame_id`, `pose`, `point_stride`, `fields`), encoded once when the sensor is added.
#[derive(Clone, Debug)]
pub struct PointCloudPrefix {
    bytes: Vec<u8>,
}

impl PointCloudPrefix {
    /// Encodes fields 2–5 for a sensor whose frame is `frame_id`: the identity pose, a stride of
    /// [`POINT_STRIDE`] and the fields of [`POINT_FIELDS`] in record order.
    pub fn new(frame_id: &str) -> Self {
        Self::with_fields(frame_id, POINT_STRIDE, &POINT_FIELDS)
    }

    /// The same for another record layout (`--fields all`: [`crate::point::EXTENDED_FIELDS`]).
    pub fn with_fields(frame_id: &str, stride: usize, fields: &[(&str, usize, FieldType)]) -> Self {
        let mut bytes = Vec::with_capacity(64 + frame_id.len() + 16 * fields.len());
        // frame_id = 2
        put_string_field(&mut bytes, 2, frame_id);
        // pose = 3: Pose { position = 1: Vector3 {0,0,0}, orientation = 2: Quaternion {w = 1} }
        let mut quaternion = Vec::with_capacity(9);
        put_double_field(&mut quaternion, 4, 1.0);
        let mut pose = Vec::with_capacity(16);
        put_len_field(&mut pose, 1, &[]);
        put_len_field(&mut pose, 2, &quaternion);
        put_len_field(&mut bytes, 3, &pose);
        // point_stride = 4 (fixed32)
        put_fixed32_field(&mut bytes, 4, stride as u32);
        // fields = 5: PackedElementField { name = 1, offset = 2 (fixed32), type = 3 }
        let mut field = Vec::with_capacity(24);
        for &(name, offset, ty) in fields {
            field.clear();
            put_string_field(&mut field, 1, name);
            put_fixed32_field(&mut field, 2, offset as u32);
            put_varint_field(&mut field, 3, numeric_type_of(ty));
            put_len_field(&mut bytes, 5, &field);
        }
        Self { bytes }
    }

    /// The encoded bytes.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes
    }
}

/// Encodes one `foxglove.PointCloud` into `buf` (cleared first): `timestamp` from
/// `timestamp_ns`, the sensor's constant fields from `prefix`, then `data` = the points' bytes.
///
/// Returns `None` when the message would exceed [`MAX_MESSAGE_LEN`].
pub fn encode_point_cloud(
    buf: &mut Vec<u8>,
    timestamp_ns: u64,
    prefix: &PointCloudPrefix,
    points: &[Point],
) -> Option<()> {
    encode_point_cloud_bytes(buf, timestamp_ns, prefix, crate::point::as_bytes(points))
}

/// [`encode_point_cloud`] from record bytes already laid out as `prefix` describes.
pub fn encode_point_cloud_bytes(
    buf: &mut Vec<u8>,
    timestamp_ns: u64,
    prefix: &PointCloudPrefix,
    data: &[u8],
) -> Option<()> {
    buf.clear();
    append_point_cloud_with(buf, timestamp_ns, prefix, data.len(), |b| {
        b.extend_from_slice(data)
    })
}

/// Appends one `foxglove.PointCloud` to `buf` (not cleared: the MCAP sink encodes into the
/// chunk itself), whose `data` is the `data_len` bytes `write_data` appends.
///
/// Returns `None` (and appends nothing) when the message would exceed [`MAX_MESSAGE_LEN`].
pub fn append_point_cloud_with(
    buf: &mut Vec<u8>,
    timestamp_ns: u64,
    prefix: &PointCloudPrefix,
    data_len: usize,
    write_data: impl FnOnce(&mut Vec<u8>),
) -> Option<()> {
    // timestamp (≤ 2 + 2·10 bytes) + prefix + data key and length (≤ 1 + 10) + data
    let len = 22usize
        .checked_add(prefix.bytes.len() + 11)?
        .checked_add(data_len)?;
    if len > MAX_MESSAGE_LEN {
        return None;
    }
    buf.reserve(len);
    put_timestamp_field(buf, 1, timestamp_ns);
    buf.extend_from_slice(&prefix.bytes);
    put_key(buf, 6, WIRE_LEN);
    put_varint(buf, data_len as u64);
    let at = buf.len();
    write_data(buf);
    debug_assert_eq!(buf.len() - at, data_len);
    Some(())
}

/// Encodes one `ringscan.RawPacket` into `buf` (cleared first).
///
/// Returns `None` when the message would exceed [`MAX_MESSAGE_LEN`].
pub fn encode_raw_packet(
    buf: &mut Vec<u8>,
    receive_time_ns: u64,
    src: std::net::SocketAddrV4,
    dst_port: u16,
    payload: &[u8],
) -> Option<()> {
    let len = 22 + 2 + 15 + 2 * 4 + 11 + payload.len();
    if len > MAX_MESSAGE_LEN {
        return None;
    }
    buf.clear();
    buf.reserve(len);
    put_timestamp_field(buf, 1, receive_time_ns);
    // A dotted quad is at most 15 bytes: format it on the stack, not into a String.
    let mut ip = [0u8; 15];
    let ip_len = {
        let mut rest = &mut ip[..];
        // Cannot fail: 15 bytes always suffice.
        let _ = write!(rest, "{}", src.ip());
        15 - rest.len()
    };
    put_len_field(buf, 2, &ip[..ip_len]);
    put_varint_field(buf, 3, u64::from(src.port()));
    put_varint_field(buf, 4, u64::from(dst_port));
    put_len_field(buf, 5, payload);
    Some(())
}

// ---------------------------------------------------------------------------------------------
// Schemas as FileDescriptorSets.

pub(super) fn field(
    name: &str,
    json_name: &str,
    number: i32,
    ty: Type,
    type_name: Option<&str>,
) -> FieldDescriptorProto {
    FieldDescriptorProto {
        name: Some(name.to_owned()),
        number: Some(number),
        label: Some(Label::Optional as i32),
        r#type: Some(ty as i32),
        type_name: type_name.map(str::to_owned),
        json_name: Some(json_name.to_owned()),
        ..Default::default()
    }
}

pub(super) fn repeated(mut f: FieldDescriptorProto) -> FieldDescriptorProto {
    f.label = Some(Label::Repeated as i32);
    f
}

pub(super) fn message(name: &str, fields: Vec<FieldDescriptorProto>) -> DescriptorProto {
    DescriptorProto {
        name: Some(name.to_owned()),
        field: fields,
        ..Default::default()
    }
}

pub(super) fn file(
    name: &str,
    package: &str,
    deps: &[&str],
    messages: Vec<DescriptorProto>,
) -> FileDescriptorProto {
    FileDescriptorProto {
        name: Some(name.to_owned()),
        package: Some(package.to_owned()),
        dependency: deps.iter().map(|d| (*d).to_owned()).collect(),
        message_type: messages,
        syntax: Some("proto3".to_owned()),
        ..Default::default()
    }
}

/// `google/protobuf/timestamp.proto`.
pub(super) fn timestamp_file() -> FileDescriptorProto {
    file(
        "google/protobuf/timestamp.proto",
        "google.protobuf",
        &[],
        vec![message(
            "Timestamp",
            vec![
                field("seconds", "seconds", 1, Type::Int64, None),
                field("nanos", "nanos", 2, Type::Int32, None),
            ],
        )],
    )
}

/// The files of `foxglove.PointCloud`, dependencies first (as `protoc --include_imports` orders
/// them).
pub(super) fn point_cloud_files() -> Vec<FileDescriptorProto> {
    let vector3 = file(
        "foxglove/Vector3.proto",
        "foxglove",
        &[],
        vec![message(
            "Vector3",
            vec![
                field("x", "x", 1, Type::Double, None),
                field("y", "y", 2, Type::Double, None),
                field("z", "z", 3, Type::Double, None),
            ],
        )],
    );
    let quaternion = file(
        "foxglove/Quaternion.proto",
        "foxglove",
        &[],
        vec![message(
            "Quaternion",
            vec![
                field("x", "x", 1, Type::Double, None),
                field("y", "y", 2, Type::Double, None),
                field("z", "z", 3, Type::Double, None),
                field("w", "w", 4, Type::Double, None),
            ],
        )],
    );
    let pose = file(
        "foxglove/Pose.proto",
        "foxglove",
        &["foxglove/Quaternion.proto", "foxglove/Vector3.proto"],
        vec![message(
            "Pose",
            vec![
                field(
                    "position",
                    "position",
                    1,
                    Type::Message,
                    Some(".foxglove.Vector3"),
                ),
                field(
                    "orientation",
                    "orientation",
                    2,
                    Type::Message,
                    Some(".foxglove.Quaternion"),
                ),
            ],
        )],
    );
    let numeric_type = EnumDescriptorProto {
        name: Some("NumericType".to_owned()),
        value: [
            ("UNKNOWN", 0),
            ("UINT8", 1),
            ("INT8", 2),
            ("UINT16", 3),
            ("INT16", 4),
            ("UINT32", 5),
            ("INT32", 6),
            ("FLOAT32", 7),
            ("FLOAT64", 8),
        ]
        .iter()
        .map(|(name, number)| EnumValueDescriptorProto {
            name: Some((*name).to_owned()),
            number: Some(*number),
            options: None,
        })
        .collect(),
        ..Default::default()
    };
    let mut packed_element_field = message(
        "PackedElementField",
        vec![
            field("name", "name", 1, Type::String, None),
            field("offset", "offset", 2, Type::Fixed32, None),
            field(
                "type",
                "type",
                3,
                Type::Enum,
                Some(".foxglove.PackedElementField.NumericType"),
            ),
        ],
    );
    packed_element_field.enum_type.push(numeric_type);
    let packed_element_field = file(
        "foxglove/PackedElementField.proto",
        "foxglove",
        &[],
        vec![packed_element_field],
    );
    let point_cloud = file(
        "foxglove/PointCloud.proto",
        "foxglove",
        &[
            "foxglove/PackedElementField.proto",
            "foxglove/Pose.proto",
            "google/protobuf/timestamp.proto",
        ],
        vec![message(
            "PointCloud",
            vec![
                field(
                    "timestamp",
                    "timestamp",
                    1,
                    Type::Message,
                    Some(".google.protobuf.Timestamp"),
                ),
                field("frame_id", "frameId", 2, Type::String, None),
                field("pose", "pose", 3, Type::Message, Some(".foxglove.Pose")),
                field("point_stride", "pointStride", 4, Type::Fixed32, None),
                repeated(field(
                    "fields",
                    "fields",
                    5,
                    Type::Message,
                    Some(".foxglove.PackedElementField"),
                )),
                field("data", "data", 6, Type::Bytes, None),
            ],
        )],
    );
    vec![
        packed_element_field,
        quaternion,
        vector3,
        pose,
        timestamp_file(),
        point_cloud,
    ]
}

/// The serialized `google.protobuf.FileDescriptorSet` of `foxglove.PointCloud` and everything it
/// imports: the MCAP schema data of the points channels.
pub fn point_cloud_descriptor_set() -> Vec<u8> {
    FileDescriptorSet {
        file: point_cloud_files(),
    }
    .encode_to_vec()
}

/// The serialized `google.protobuf.FileDescriptorSet` of [`RAW_PACKET_SCHEMA`].
pub fn raw_packet_descriptor_set() -> Vec<u8> {
    let raw = file(
        "ringscan/RawPacket.proto",
        "ringscan",
        &["google/protobuf/timestamp.proto"],
        vec![message(
            "RawPacket",
            vec![
                field(
                    "timestamp",
                    "timestamp",
                    1,
                    Type::Message,
                    Some(".google.protobuf.Timestamp"),
                ),
                field("source_address", "sourceAddress", 2, Type::String, None),
                field("source_port", "sourcePort", 3, Type::Uint32, None),
                field("destination_port", "destinationPort", 4, Type::Uint32, None),
                field("payload", "payload", 5, Type::Bytes, None),
            ],
        )],
    );
    FileDescriptorSet {
        file: vec![timestamp_file(), raw],
    }
    .encode_to_vec()
}

#[cfg(test)]
mod tests {
    use super::*;
    use prost_types::FileDescriptorSet;

    #[test]
    fn varints_match_the_protobuf_encoding() {
        for (v, bytes) in [
            (0u64, &[0x00u8][..]),
            (1, &[0x01]),
            (127, &[0x7f]),
            (128, &[0x80, 0x01]),
            (300, &[0xac, 0x02]),
            (
                u64::MAX,
                &[0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x01],
            ),
        ] {
            let mut buf = Vec::new();
            put_varint(&mut buf, v);
            assert_eq!(buf, bytes, "{v}");
            assert_eq!(varint_len(v), bytes.len(), "{v}");
        }
    }

    /// The hand-written encoding decodes with prost into a mirror of the official messages.
    #[test]
    fn point_cloud_round_trips_through_prost() {
        use crate::sink::read::{PointCloud, Quaternion, Vector3};
        let points = [
            Point {
                x: 1.0,
                y: -2.0,
                z: 0.5,
                intensity: 77.0,
                t: 1234,
                ring: 15,
                ret: 1,
                pad: 0,
            },
            Point {
                x: 3.0,
                y: 4.0,
                z: -0.25,
                intensity: 0.0,
                t: 99_000,
                ring: 0,
                ret: 0,
                pad: 0,
            },
        ];
        let prefix = PointCloudPrefix::new("vlp16-201");
        let mut buf = Vec::new();
        encode_point_cloud(&mut buf, 1_700_000_000_123_456_789, &prefix, &points).unwrap();
        let pc = PointCloud::decode(buf.as_slice()).unwrap();
        let ts = pc.timestamp.unwrap();
        assert_eq!((ts.seconds, ts.nanos), (1_700_000_000, 123_456_789));
        assert_eq!(pc.frame_id, "vlp16-201");
        let pose = pc.pose.unwrap();
        assert_eq!(
            pose.position.unwrap(),
            Vector3 {
                x: 0.0,
                y: 0.0,
                z: 0.0
            }
        );
        assert_eq!(
            pose.orientation.unwrap(),
            Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0
            }
        );
        assert_eq!(pc.point_stride, 24);
        let fields: Vec<_> = pc
            .fields
            .iter()
            .map(|f| (f.name.as_str(), f.offset, f.r#type))
            .collect();
        assert_eq!(
            fields,
            [
                ("x", 0, 7),
                ("y", 4, 7),
                ("z", 8, 7),
                ("intensity", 12, 7),
                ("t", 16, 5),
                ("ring", 20, 3),
                ("return", 22, 1)
            ]
        );
        assert_eq!(pc.data, crate::point::as_bytes(&points));

        // Timestamp zero and no points still encode a valid message.
        encode_point_cloud(&mut buf, 0, &prefix, &[]).unwrap();
        let pc = PointCloud::decode(buf.as_slice()).unwrap();
        assert_eq!(
            pc.timestamp.unwrap(),
            prost_types::Timestamp {
                seconds: 0,
                nanos: 0
            }
        );
        assert!(pc.data.is_empty());
    }

    #[test]
    fn descriptor_sets_decode_and_name_every_dependency() {
        for data in [point_cloud_descriptor_set(), raw_packet_descriptor_set()] {
            let fds = FileDescriptorSet::decode(data.as_slice()).unwrap();
            let names: Vec<_> = fds.file.iter().map(|f| f.name().to_owned()).collect();
            for (i, f) in fds.file.iter().enumerate() {
                for dep in &f.dependency {
                    let at = names.iter().position(|n| n == dep).expect(dep);
                    assert!(at < i, "{dep} must come before {}", f.name());
                }
            }
        }
    }

    /// The schema of [`RAW_PACKET_SCHEMA`], as prost derives it from the `.proto` text.
    #[derive(Clone, PartialEq, prost::Message)]
    struct RawPacket {
        #[prost(message, optional, tag = "1")]
        timestamp: Option<prost_types::Timestamp>,
        #[prost(string, tag = "2")]
        source_address: String,
        #[prost(uint32, tag = "3")]
        source_port: u32,
        #[prost(uint32, tag = "4")]
        destination_port: u32,
        #[prost(bytes = "vec", tag = "5")]
        payload: Vec<u8>,
    }

    /// The bag reader (which `decode drive.mcap` uses) reads what prost writes, and knows
    /// the schema by this module's name.
    #[cfg(feature = "bag")]
    #[test]
    fn the_bag_reader_reads_raw_packets_prost_writes() {
        use crate::source::bag::messages::{raw_packet, Encoding, RAW_PACKET_TYPE};
        assert_eq!(RAW_PACKET_SCHEMA, RAW_PACKET_TYPE);
        for (seconds, nanos, addr, sport, dport, payload) in [
            (
                1_700_000_000,
                999_999_999,
                "10.1.2.3",
                65_535,
                0,
                vec![7; 1206],
            ),
            (0, 0, "0.0.0.0", 0, 7502, vec![]),
            (-5, 1, "255.255.255.255", 2368, 2369, vec![0]),
        ] {
            let m = RawPacket {
                timestamp: Some(prost_types::Timestamp { seconds, nanos }),
                source_address: addr.into(),
                source_port: sport,
                destination_port: dport,
                payload: payload.clone(),
            };
            let bytes = m.encode_to_vec();
            let r = raw_packet(Encoding::Protobuf, &bytes).unwrap();
            let p = r.packet;
            assert_eq!(p.stamp_ns, Some(seconds * 1_000_000_000 + i64::from(nanos)));
            assert_eq!(r.source.to_string(), format!("{addr}:{sport}"));
            assert_eq!(u32::from(r.destination_port), dport);
            assert_eq!(bytes[p.start..p.start + p.len], payload[..]);
        }
        // A port prost can write but no UDP datagram has.
        let m = RawPacket {
            source_address: "10.1.2.3".into(),
            source_port: 65_536,
            ..Default::default()
        };
        assert!(raw_packet(Encoding::Protobuf, &m.encode_to_vec()).is_err());
    }

    #[test]
    fn raw_packet_round_trips_through_prost() {
        let mut buf = Vec::new();
        let src = std::net::SocketAddrV4::new([192, 168, 1, 201].into(), 2368);
        encode_raw_packet(&mut buf, 5_000_000_001, src, 2368, &[1, 2, 3]).unwrap();
        let raw = RawPacket::decode(buf.as_slice()).unwrap();
        assert_eq!(
            raw.timestamp.unwrap(),
            prost_types::Timestamp {
                seconds: 5,
                nanos: 1
            }
        );
        assert_eq!(raw.source_address, "192.168.1.201");
        assert_eq!((raw.source_port, raw.destination_port), (2368, 2368));
        assert_eq!(raw.payload, [1, 2, 3]);
    }
}
