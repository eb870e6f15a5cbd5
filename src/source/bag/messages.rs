//! ROS packet messages → the UDP payloads they carry.
//!
//! In: a message's serialized bytes, its recorded type name and its encoding (ROS 1
//! serialization or CDR). Out: one [`PacketRef`] per packet (a range of the message bytes and
//! the packet's own stamp, when the type has one). Pure functions: no I/O, no allocation beyond
//! the caller's `Vec`, never a panic on any input.
//!
//! # The message types (fields as recorded; names learnt from the public definitions)
//!
//! | type (ROS 2 name; ROS 1 without `/msg`) | layout | packet stamp |
//! |---|---|---|
//! | `velodyne_msgs/msg/VelodyneScan` | Header, `VelodynePacket[]` = {time stamp, uint8\[1206\] data} | each packet's |
//! | `ouster_ros/PacketMsg`, `ouster_sensor_msgs/msg/PacketMsg`, `ouster_msgs/msg/PacketMsg` | uint8\[\] buf | none (record time) |
//! | `pandar_msgs/msg/PandarScan` | Header, `PandarPacket[]` = {time stamp, uint8\[1500\] data, uint32 size}: the first `size` bytes | each packet's |
//! | `nebula_msgs/msg/NebulaPackets` | Header, `NebulaPacket[]` = {time stamp, uint8\[\] data} | each packet's |
//! | `hesai_ros_driver/msg/UdpFrame` | Header, `UdpPacket[]` = {time stamp, uint8\[\] data, uint32 size}: the first `size` bytes | each packet's |
//! | `robosense_msgs/msg/RobosenseScan` | Header, `RobosensePacket[]`, either {time stamp, uint8 is_difop, uint8\[1500\] data, uint32 size} (nebula PR #79) or {time stamp, uint8\[1248\] data, uint32 size} (nebula main): the variant whose layout consumes the message exactly | each packet's |
//! | `rslidar_msg/msg/RslidarPacket` | Header, uint8 is_difop, uint8 is_frame_begin, uint8\[\] data | its header's |
//! | `std_msgs/msg/String` | string data (Ouster metadata JSON) | — |
//! | `livox_ros_driver2/msg/CustomMsg`, `livox_ros_driver/CustomMsg` | Header, uint64 timebase, uint32 point_num, uint8 lidar_id, uint8\[3\] rsvd, `CustomPoint[]` = {uint32 offset_time, float32 x y z, uint8 reflectivity, tag, line}: points, not packets ([`livox_custom`]) | its header's |
//! | `sensor_msgs/msg/Imu` (a Livox driver's IMU topic beside its `CustomMsg` one) | Header, orientation {float64 x y z w}, float64\[9\] covariance, angular_velocity {float64 x y z}, float64\[9\], linear_acceleration {float64 x y z}, float64\[9\]: one sample ([`imu`]) | its header's |
//! | `ringscan.RawPacket` (protobuf; what `--raw` writes to an MCAP of the foxglove format) | `Timestamp timestamp = 1`, `string source_address = 2`, `uint32 source_port = 3`, `uint32 destination_port = 4`, `bytes payload = 5`: one datagram with its own addresses ([`raw_packet`]) | its `timestamp` |
//!
//! ROS 1 serialization and CDR (ROS 2) are read by `crate::ros_serial`. Protobuf (the wire
//! format of protobuf.dev/programming-guides/encoding): a sequence of fields, each a varint key
//! (field number << 3 | wire type) then a varint (type 0), 8 bytes (1), a varint length and
//! that many bytes (2) or 4 bytes (5); fields in any order, a repeated scalar's last value wins,
//! an embedded message's occurrences merge, unknown fields are skipped.

use core::fmt;
use std::net::{Ipv4Addr, SocketAddrV4};

use crate::ros_serial::{Cursor, Fault};

/// A decoded message's packets are never more than this many (a bound on the caller's `Vec`).
pub const MAX_PACKETS_PER_MESSAGE: usize = 1 << 20;

/// How a message is serialized.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    /// ROS 1 serialization (ROS 1 bags; MCAP `ros1`).
    Ros1,
    /// CDR (rosbag2; MCAP `cdr`).
    Cdr,
    /// Protobuf (MCAP `protobuf`): ringscan's own `ringscan.RawPacket` only.
    Protobuf,
}

/// The message types ringscan reads, by recorded type name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum MsgKind {
    /// `velodyne_msgs/VelodyneScan`.
    VelodyneScan,
    /// `ouster_ros/PacketMsg`, `ouster_sensor_msgs/PacketMsg`, `ouster_msgs/PacketMsg`.
    OusterPacket,
    /// `pandar_msgs/PandarScan`.
    PandarScan,
    /// `nebula_msgs/NebulaPackets`.
    NebulaPackets,
    /// `hesai_ros_driver/UdpFrame`.
    HesaiUdpFrame,
    /// `robosense_msgs/RobosenseScan`.
    RobosenseScan,
    /// `rslidar_msg/RslidarPacket`.
    RslidarPacket,
    /// `std_msgs/String` (Ouster metadata on `<ns>/metadata`).
    StdString,
    /// `livox_ros_driver/CustomMsg`, `livox_ros_driver2/CustomMsg`: decoded points.
    LivoxCustomMsg,
    /// `sensor_msgs/Imu`: one IMU sample (read for a Livox `CustomMsg` sensor's IMU topic).
    Imu,
    /// `ringscan.RawPacket` (protobuf): one datagram as `--raw` kept it, with its addresses.
    RawPacket,
}

impl MsgKind {
    /// The kind of a recorded type name (`pkg/Type` or `pkg/msg/Type`), if ringscan reads it.
    pub fn from_type_name(name: &str) -> Option<Self> {
        let name = name.trim();
        if name == RAW_PACKET_TYPE {
            return Some(Self::RawPacket);
        }
        let (pkg, ty) = name.split_once('/')?;
        let ty = ty.strip_prefix("msg/").unwrap_or(ty);
        Some(match (pkg, ty) {
            ("velodyne_msgs", "VelodyneScan") => Self::VelodyneScan,
            ("ouster_ros" | "ouster_sensor_msgs" | "ouster_msgs", "PacketMsg") => {
                Self::OusterPacket
            }
            ("pandar_msgs", "PandarScan") => Self::PandarScan,
            ("nebula_msgs", "NebulaPackets") => Self::NebulaPackets,
            ("hesai_ros_driver", "UdpFrame") => Self::HesaiUdpFrame,
            ("robosense_msgs", "RobosenseScan") => Self::RobosenseScan,
            ("rslidar_msg" | "rslidar_msgs", "RslidarPacket") => Self::RslidarPacket,
            ("std_msgs", "String") => Self::StdString,
            ("livox_ros_driver" | "livox_ros_driver2", "CustomMsg") => Self::LivoxCustomMsg,
            ("sensor_msgs", "Imu") => Self::Imu,
            _ => return None,
        })
    }

    /// Whether messages of this kind carry packets (all but `std_msgs/String`, the decoded
    /// points of `CustomMsg` and `sensor_msgs/Imu`).
    pub fn carries_packets(self) -> bool {
        !matches!(self, Self::StdString | Self::LivoxCustomMsg | Self::Imu)
    }

    /// Whether `enc` is this kind's serialization: protobuf for `ringscan.RawPacket`, ROS 1
    /// or CDR for the ROS types.
    pub fn serialized_as(self, enc: Encoding) -> bool {
        (self == Self::RawPacket) == (enc == Encoding::Protobuf)
    }
}

/// The schema name of ringscan's raw datagram message (the MCAP sink's
/// `RAW_PACKET_SCHEMA`, repeated here because the bag reader is built without the sink).
pub const RAW_PACKET_TYPE: &str = "ringscan.RawPacket";

/// One packet inside a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PacketRef {
    /// Byte range of the payload in the message bytes.
    pub start: usize,
    /// Payload length.
    pub len: usize,
    /// The packet's own stamp (ns since the Unix epoch), where its type has one.
    pub stamp_ns: Option<i64>,
    /// A Robosense DIFOP (device information) packet rather than MSOP data.
    pub difop: bool,
}

/// Why a message could not be read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum MsgError {
    /// The message ends before a field.
    #[error("message ends at byte {len}, a field at byte {offset} needs {need} bytes")]
    Short {
        /// Offset of the field.
        offset: usize,
        /// Bytes the field needs.
        need: usize,
        /// Message length.
        len: usize,
    },
    /// A CDR encapsulation header other than plain CDR (big or little endian).
    #[error("CDR encapsulation {0:#06x}: expected 0x0000 or 0x0001 (plain CDR)")]
    Encapsulation(u16),
    /// Bytes left over after the last field (a layout that does not fit the type).
    #[error("{extra} bytes left after the last field of the message")]
    Trailing {
        /// Bytes left.
        extra: usize,
    },
    /// More packets than a message may hold.
    #[error("{0} packets claimed, more than the bytes or the limit allow")]
    TooManyPackets(u64),
    /// A message of another serialization than the reader's (a ROS reader given protobuf).
    #[error("a {0:?} message where another serialization was expected")]
    Serialization(Encoding),
    /// A protobuf field that breaks the wire format or its type's range.
    #[error("protobuf field at byte {offset}: {what}")]
    Protobuf {
        /// Offset of the field's key.
        offset: usize,
        /// What is wrong.
        what: &'static str,
    },
}

impl From<Fault> for MsgError {
    fn from(f: Fault) -> Self {
        match f {
            Fault::Short { offset, need, len } => Self::Short { offset, need, len },
            Fault::Encapsulation(k) => Self::Encapsulation(k),
            Fault::Count(n) => Self::TooManyPackets(n),
            Fault::Trailing { extra } => Self::Trailing { extra },
        }
    }
}

/// A reader of `msg` in the ROS serialization `enc`.
fn cursor(msg: &[u8], enc: Encoding) -> Result<Cursor<'_>, MsgError> {
    match enc {
        Encoding::Ros1 => Ok(Cursor::ros1(msg)),
        Encoding::Cdr => Ok(Cursor::cdr(msg)?),
        Encoding::Protobuf => Err(MsgError::Serialization(enc)),
    }
}

/// Reads the packets of a message of `kind` (not [`MsgKind::StdString`]) into `out` (cleared
/// first). On error `out` holds nothing.
pub fn packets(
    kind: MsgKind,
    enc: Encoding,
    msg: &[u8],
    out: &mut Vec<PacketRef>,
) -> Result<(), MsgError> {
    out.clear();
    let r = match kind {
        MsgKind::VelodyneScan => scan_fixed(enc, msg, 1206, false, out),
        MsgKind::OusterPacket => single_buf(enc, msg, out),
        MsgKind::PandarScan => scan_fixed(enc, msg, 1500, true, out),
        MsgKind::NebulaPackets => scan_var(enc, msg, false, out),
        MsgKind::HesaiUdpFrame => scan_var(enc, msg, true, out),
        MsgKind::RobosenseScan => robosense(enc, msg, out),
        MsgKind::RslidarPacket => rslidar(enc, msg, out),
        MsgKind::StdString | MsgKind::LivoxCustomMsg | MsgKind::Imu | MsgKind::RawPacket => Ok(()),
    };
    if r.is_err() {
        out.clear();
    }
    r
}

/// The text of a `std_msgs/String` message: the byte range of its data (without a trailing NUL).
pub fn string(enc: Encoding, msg: &[u8]) -> Result<(usize, usize), MsgError> {
    let mut c = cursor(msg, enc)?;
    let (start, len) = c.bytes()?;
    c.end()?;
    let nul =
        enc == Encoding::Cdr && msg.get(start..start + len).and_then(<[u8]>::last) == Some(&0);
    Ok((start, len - usize::from(nul)))
}

/// Reads a Livox `CustomMsg` into a points frame ([`crate::sensor::livox::frame`]) in `out`;
/// returns its header stamp (ns). `point_num` is not consulted: the sequence's own count frames
/// the bytes. On error `out` is cleared.
pub fn livox_custom(enc: Encoding, msg: &[u8], out: &mut Vec<u8>) -> Result<i64, MsgError> {
    use crate::sensor::livox::frame::{self, FramePoint};
    let r = (|| {
        let mut c = cursor(msg, enc)?;
        let stamp = c.header()?.stamp_ns;
        let timebase = c.u64()?;
        c.u32()?; // point_num
        let lidar_id = c.u8()?;
        c.take(3)?; // rsvd
        let n = c.count(frame::POINT_LEN, MAX_PACKETS_PER_MESSAGE)?;
        frame::write_header(out, timebase, lidar_id, n as u32);
        out.reserve(n * frame::POINT_LEN);
        for _ in 0..n {
            let offset_time_ns = c.u32()?;
            let x = c.f32()?;
            let y = c.f32()?;
            let z = c.f32()?;
            let b = c.take(3)?;
            frame::push_point(
                out,
                &FramePoint {
                    offset_time_ns,
                    xyz: [x, y, z],
                    reflectivity: b[0],
                    tag: b[1],
                    line: b[2],
                },
            );
        }
        c.end()?;
        Ok(stamp)
    })();
    if r.is_err() {
        out.clear();
    }
    r
}

/// One `sensor_msgs/Imu` sample, as recorded (units are the writer's: see [`imu`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuMsg {
    /// Header stamp, ns.
    pub stamp_ns: i64,
    /// `angular_velocity` (x, y, z).
    pub angular_velocity: [f64; 3],
    /// `linear_acceleration` (x, y, z).
    pub linear_acceleration: [f64; 3],
}

/// Reads a `sensor_msgs/Imu`. The orientation and the three covariances are read past, not
/// kept: the Livox drivers send none (zeros). The type says rad/s and m/s²; the Livox drivers
/// publish the acceleration in g as the sensor sends it, so the caller decides the unit.
pub fn imu(enc: Encoding, msg: &[u8]) -> Result<ImuMsg, MsgError> {
    let mut c = cursor(msg, enc)?;
    let stamp_ns = c.header()?.stamp_ns;
    c.f64s::<4>()?; // orientation
    c.f64s::<9>()?; // its covariance
    let angular_velocity = c.f64s()?;
    c.f64s::<9>()?;
    let linear_acceleration = c.f64s()?;
    c.f64s::<9>()?;
    c.end()?;
    Ok(ImuMsg {
        stamp_ns,
        angular_velocity,
        linear_acceleration,
    })
}

/// Header + Packet[] where a packet is {time, uint8[N] data[, uint32 size]}.
fn scan_fixed(
    enc: Encoding,
    msg: &[u8],
    n: usize,
    sized: bool,
    out: &mut Vec<PacketRef>,
) -> Result<(), MsgError> {
    let mut c = cursor(msg, enc)?;
    c.header()?;
    let count = c.count(8 + n, MAX_PACKETS_PER_MESSAGE)?;
    out.reserve(count);
    for _ in 0..count {
        let stamp = c.time()?;
        let start = c.at();
        c.take(n)?;
        let len = if sized { (c.u32()? as usize).min(n) } else { n };
        out.push(PacketRef {
            start,
            len,
            stamp_ns: Some(stamp),
            difop: false,
        });
    }
    Ok(c.end()?)
}

/// Header + Packet[] where a packet is {time, uint8[] data[, uint32 size]}.
fn scan_var(
    enc: Encoding,
    msg: &[u8],
    sized: bool,
    out: &mut Vec<PacketRef>,
) -> Result<(), MsgError> {
    let mut c = cursor(msg, enc)?;
    c.header()?;
    let count = c.count(12, MAX_PACKETS_PER_MESSAGE)?;
    out.reserve(count);
    for _ in 0..count {
        let stamp = c.time()?;
        let (start, mut len) = c.bytes()?;
        if sized {
            len = len.min(c.u32()? as usize);
        }
        out.push(PacketRef {
            start,
            len,
            stamp_ns: Some(stamp),
            difop: false,
        });
    }
    Ok(c.end()?)
}

/// `uint8[] buf`: the whole message is one packet.
fn single_buf(enc: Encoding, msg: &[u8], out: &mut Vec<PacketRef>) -> Result<(), MsgError> {
    let mut c = cursor(msg, enc)?;
    let (start, len) = c.bytes()?;
    c.end()?;
    out.push(PacketRef {
        start,
        len,
        stamp_ns: None,
        difop: false,
    });
    Ok(())
}

/// Both RobosensePacket layouts; the one that consumes the message exactly wins.
fn robosense(enc: Encoding, msg: &[u8], out: &mut Vec<PacketRef>) -> Result<(), MsgError> {
    let with_difop = |out: &mut Vec<PacketRef>| -> Result<(), MsgError> {
        let mut c = cursor(msg, enc)?;
        c.header()?;
        let count = c.count(8 + 1 + 1500, MAX_PACKETS_PER_MESSAGE)?;
        out.reserve(count);
        for _ in 0..count {
            let stamp = c.time()?;
            let difop = c.u8()? != 0;
            let start = c.at();
            c.take(1500)?;
            let len = (c.u32()? as usize).min(1500);
            out.push(PacketRef {
                start,
                len,
                stamp_ns: Some(stamp),
                difop,
            });
        }
        Ok(c.end()?)
    };
    match with_difop(out) {
        Ok(()) => Ok(()),
        Err(first) => {
            out.clear();
            scan_fixed(enc, msg, 1248, true, out).map_err(|_| first)
        }
    }
}

/// RslidarPacket: Header, is_difop, is_frame_begin, uint8[] data; stamp = the header's.
fn rslidar(enc: Encoding, msg: &[u8], out: &mut Vec<PacketRef>) -> Result<(), MsgError> {
    let mut c = cursor(msg, enc)?;
    let stamp = c.header()?.stamp_ns;
    let difop = c.u8()? != 0;
    c.u8()?;
    let (start, len) = c.bytes()?;
    c.end()?;
    out.push(PacketRef {
        start,
        len,
        stamp_ns: Some(stamp),
        difop,
    });
    Ok(())
}

/// One `ringscan.RawPacket`: a datagram as the `--raw` output of an MCAP kept it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawPacketMsg {
    /// The payload's byte range in the message, and its `timestamp` (ns since the Unix
    /// epoch; `None` when the field is absent, then the record time serves).
    pub packet: PacketRef,
    /// `source_address`:`source_port`.
    pub source: SocketAddrV4,
    /// `destination_port`.
    pub destination_port: u16,
}

/// Reads a `ringscan.RawPacket` (protobuf). The sender's address must be an IPv4 dotted quad
/// and the ports below 65536: anything else is not a datagram ringscan wrote, and is refused
/// rather than guessed at.
pub fn raw_packet(enc: Encoding, msg: &[u8]) -> Result<RawPacketMsg, MsgError> {
    if enc != Encoding::Protobuf {
        return Err(MsgError::Serialization(enc));
    }
    let mut r = Proto::new(msg);
    let mut stamp: Option<(i64, i64)> = None;
    let (mut address, mut source_port, mut destination_port) = (None, 0, 0);
    let mut payload = (0, 0);
    while let Some((at, field, value)) = r.field()? {
        let bad = |what| MsgError::Protobuf { offset: at, what };
        match (field, value) {
            (1, Value::Bytes(start, len)) => {
                // Timestamp {int64 seconds = 1; int32 nanos = 2}; occurrences merge.
                let (seconds, nanos) = stamp.get_or_insert((0, 0));
                let mut t = Proto::new(&msg[start..start + len]);
                while let Some((_, f, v)) = t.field().map_err(|_| bad("a broken Timestamp"))? {
                    match (f, v) {
                        (1, Value::Varint(s)) => *seconds = s as i64,
                        (2, Value::Varint(n)) => *nanos = i64::from(n as i32),
                        (1 | 2, _) => return Err(bad("a Timestamp field of the wrong wire type")),
                        _ => {}
                    }
                }
            }
            (2, Value::Bytes(start, len)) => address = Some((at, start, len)),
            (3, Value::Varint(v)) => source_port = v as u32,
            (4, Value::Varint(v)) => destination_port = v as u32,
            (5, Value::Bytes(start, len)) => payload = (start, len),
            (1..=5, _) => return Err(bad("a known field of the wrong wire type")),
            _ => {}
        }
    }
    let stamp_ns = match stamp {
        None => None,
        Some((s, n)) if (0..1_000_000_000).contains(&n) => Some(
            s.checked_mul(1_000_000_000)
                .and_then(|t| t.checked_add(n))
                .ok_or(MsgError::Protobuf {
                    offset: 0,
                    what: "a timestamp beyond the ns range of an i64",
                })?,
        ),
        Some(_) => {
            return Err(MsgError::Protobuf {
                offset: 0,
                what: "timestamp nanos outside 0..1e9",
            })
        }
    };
    let (at, start, len) = address.ok_or(MsgError::Protobuf {
        offset: msg.len(),
        what: "no source_address",
    })?;
    let ip = core::str::from_utf8(&msg[start..start + len])
        .ok()
        .and_then(|s| s.parse::<Ipv4Addr>().ok())
        .ok_or(MsgError::Protobuf {
            offset: at,
            what: "source_address is not an IPv4 dotted quad",
        })?;
    let port = |p: u32| {
        u16::try_from(p).map_err(|_| MsgError::Protobuf {
            offset: 0,
            what: "a port above 65535",
        })
    };
    Ok(RawPacketMsg {
        packet: PacketRef {
            start: payload.0,
            len: payload.1,
            stamp_ns,
            difop: false,
        },
        source: SocketAddrV4::new(ip, port(source_port)?),
        destination_port: port(destination_port)?,
    })
}

/// A protobuf field's value: a varint, or a byte range (length-delimited); fixed-size values
/// are skipped, as no field read here has one.
#[derive(Clone, Copy)]
enum Value {
    Varint(u64),
    Bytes(usize, usize),
    Fixed,
}

/// A cursor over protobuf wire-format bytes that cannot panic.
struct Proto<'a> {
    buf: &'a [u8],
    at: usize,
}

impl<'a> Proto<'a> {
    fn new(buf: &'a [u8]) -> Self {
        Self { buf, at: 0 }
    }

    fn varint(&mut self, key_at: usize) -> Result<u64, MsgError> {
        let mut v = 0u64;
        for i in 0..=9 {
            let Some(&b) = self.buf.get(self.at) else {
                return Err(MsgError::Protobuf {
                    offset: key_at,
                    what: "the message ends inside a varint",
                });
            };
            self.at += 1;
            // The tenth byte holds bit 63 only.
            if i == 9 && b > 1 {
                return Err(MsgError::Protobuf {
                    offset: key_at,
                    what: "a varint longer than 64 bits",
                });
            }
            v |= u64::from(b & 0x7f) << (7 * i);
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        // Not reached: the tenth byte is either ≤ 1 (and ends the varint) or refused.
        Err(MsgError::Protobuf {
            offset: key_at,
            what: "a varint longer than 64 bits",
        })
    }

    fn skip(&mut self, n: u64, key_at: usize) -> Result<(usize, usize), MsgError> {
        let start = self.at;
        let left = self.buf.len() - start;
        match usize::try_from(n).ok().filter(|&n| n <= left) {
            Some(n) => {
                self.at += n;
                Ok((start, n))
            }
            None => Err(MsgError::Protobuf {
                offset: key_at,
                what: "a field longer than the bytes left",
            }),
        }
    }

    /// The next field: the offset of its key, its number and its value; `None` at the end.
    fn field(&mut self) -> Result<Option<(usize, u64, Value)>, MsgError> {
        if self.at >= self.buf.len() {
            return Ok(None);
        }
        let at = self.at;
        let key = self.varint(at)?;
        let (field, wire) = (key >> 3, key & 7);
        if field == 0 || field > (1 << 29) - 1 {
            return Err(MsgError::Protobuf {
                offset: at,
                what: "a field number outside 1..2^29",
            });
        }
        let value = match wire {
            0 => Value::Varint(self.varint(at)?),
            1 => {
                self.skip(8, at)?;
                Value::Fixed
            }
            2 => {
                let n = self.varint(at)?;
                let (start, len) = self.skip(n, at)?;
                Value::Bytes(start, len)
            }
            5 => {
                self.skip(4, at)?;
                Value::Fixed
            }
            _ => {
                // 3 and 4 are the deprecated groups, 6 and 7 do not exist.
                return Err(MsgError::Protobuf {
                    offset: at,
                    what: "a group or unknown wire type",
                });
            }
        };
        Ok(Some((at, field, value)))
    }
}

impl fmt::Display for MsgKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = match self {
            Self::VelodyneScan => "velodyne_msgs/VelodyneScan",
            Self::OusterPacket => "ouster PacketMsg",
            Self::PandarScan => "pandar_msgs/PandarScan",
            Self::NebulaPackets => "nebula_msgs/NebulaPackets",
            Self::HesaiUdpFrame => "hesai_ros_driver/UdpFrame",
            Self::RobosenseScan => "robosense_msgs/RobosenseScan",
            Self::RslidarPacket => "rslidar_msg/RslidarPacket",
            Self::StdString => "std_msgs/String",
            Self::LivoxCustomMsg => "livox_ros_driver CustomMsg",
            Self::Imu => "sensor_msgs/Imu",
            Self::RawPacket => RAW_PACKET_TYPE,
        };
        f.write_str(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A CDR VelodyneScan with `n` packets, written field by field from the layout above.
    fn cdr_velodyne(n: usize, frame_id: &str) -> Vec<u8> {
        let mut m = vec![0, 1, 0, 0];
        m.extend_from_slice(&7_i32.to_le_bytes());
        m.extend_from_slice(&9_u32.to_le_bytes());
        m.extend_from_slice(&(frame_id.len() as u32 + 1).to_le_bytes());
        m.extend_from_slice(frame_id.as_bytes());
        m.push(0);
        while (m.len() - 4) % 4 != 0 {
            m.push(0);
        }
        m.extend_from_slice(&(n as u32).to_le_bytes());
        for i in 0..n {
            m.extend_from_slice(&(100 + i as i32).to_le_bytes());
            m.extend_from_slice(&5_u32.to_le_bytes());
            m.extend(std::iter::repeat_n(i as u8, 1206));
            while (m.len() - 4) % 4 != 0 {
                m.push(0);
            }
        }
        m
    }

    #[test]
    fn type_names_of_both_ros_versions() {
        assert_eq!(
            MsgKind::from_type_name("velodyne_msgs/msg/VelodyneScan"),
            Some(MsgKind::VelodyneScan)
        );
        assert_eq!(
            MsgKind::from_type_name("velodyne_msgs/VelodyneScan"),
            Some(MsgKind::VelodyneScan)
        );
        assert_eq!(
            MsgKind::from_type_name("ouster_sensor_msgs/msg/PacketMsg"),
            Some(MsgKind::OusterPacket)
        );
        assert_eq!(
            MsgKind::from_type_name("sensor_msgs/msg/Imu"),
            Some(MsgKind::Imu)
        );
        assert_eq!(
            MsgKind::from_type_name("sensor_msgs/Imu"),
            Some(MsgKind::Imu)
        );
        assert_eq!(MsgKind::from_type_name("sensor_msgs/msg/PointCloud2"), None);
        assert_eq!(MsgKind::from_type_name("garbage"), None);
    }

    #[test]
    fn cdr_velodyne_scan_packets_and_stamps() {
        // Header frame_id "velodyne" = 9 bytes with NUL: the packet count then needs padding.
        let m = cdr_velodyne(3, "velodyne");
        let mut out = Vec::new();
        packets(MsgKind::VelodyneScan, Encoding::Cdr, &m, &mut out).unwrap();
        assert_eq!(out.len(), 3);
        for (i, p) in out.iter().enumerate() {
            assert_eq!(p.len, 1206);
            assert_eq!(p.stamp_ns, Some((100 + i as i64) * 1_000_000_000 + 5));
            assert!(m[p.start..p.start + p.len].iter().all(|&b| b == i as u8));
        }
    }

    #[test]
    fn truncated_and_oversized_counts_are_errors_not_panics() {
        let m = cdr_velodyne(2, "v");
        let mut out = Vec::new();
        // The last 2 bytes are padding to a multiple of 4, which a writer may leave out.
        for cut in 0..m.len() - 2 {
            assert!(packets(MsgKind::VelodyneScan, Encoding::Cdr, &m[..cut], &mut out).is_err());
            assert!(out.is_empty());
        }
        let mut big = m.clone();
        // The packet count sits after the 4-byte encapsulation, 8-byte stamp, 4+2 frame id, pad.
        big[20..24].copy_from_slice(&u32::MAX.to_le_bytes());
        assert_eq!(
            packets(MsgKind::VelodyneScan, Encoding::Cdr, &big, &mut out),
            Err(MsgError::TooManyPackets(u64::from(u32::MAX)))
        );
    }

    #[test]
    fn ros1_ouster_packet_msg_and_string() {
        let mut m = 5_u32.to_le_bytes().to_vec();
        m.extend_from_slice(b"abcde");
        let mut out = Vec::new();
        packets(MsgKind::OusterPacket, Encoding::Ros1, &m, &mut out).unwrap();
        assert_eq!(
            out,
            vec![PacketRef {
                start: 4,
                len: 5,
                stamp_ns: None,
                difop: false
            }]
        );
        assert_eq!(string(Encoding::Ros1, &m), Ok((4, 5)));
        let cdr = [0, 1, 0, 0, 3, 0, 0, 0, b'{', b'}', 0];
        assert_eq!(string(Encoding::Cdr, &cdr), Ok((8, 2)));
    }

    /// A `sensor_msgs/Imu` written field by field from its definition: orientation,
    /// angular velocity and linear acceleration, each followed by a 3 × 3 covariance.
    fn imu_msg(cdr: bool, frame_id: &str) -> Vec<u8> {
        let mut m: Vec<u8> = if cdr { vec![0, 1, 0, 0] } else { Vec::new() };
        if !cdr {
            m.extend_from_slice(&3_u32.to_le_bytes()); // seq
        }
        m.extend_from_slice(&1_700_000_000_u32.to_le_bytes());
        m.extend_from_slice(&250_000_000_u32.to_le_bytes());
        m.extend_from_slice(&((frame_id.len() + usize::from(cdr)) as u32).to_le_bytes());
        m.extend_from_slice(frame_id.as_bytes());
        if cdr {
            m.push(0);
            while (m.len() - 4) % 8 != 0 {
                m.push(0);
            }
        }
        let mut put = |vals: &[f64]| {
            for v in vals {
                m.extend_from_slice(&v.to_le_bytes());
            }
        };
        put(&[0.0, 0.0, 0.0, 1.0]);
        put(&[-1.0; 9]);
        put(&[0.125, -0.5, 2.0]);
        put(&[7.0; 9]);
        put(&[0.01, -0.02, 0.998]);
        put(&[9.0; 9]);
        m
    }

    #[test]
    fn imu_samples_of_both_encodings() {
        // "imu_link" + NUL leaves the CDR doubles 3 bytes of padding to skip.
        for (enc, m) in [
            (Encoding::Ros1, imu_msg(false, "imu_link")),
            (Encoding::Cdr, imu_msg(true, "imu_link")),
            (Encoding::Cdr, imu_msg(true, "livox_frame")),
        ] {
            let got = imu(enc, &m).unwrap();
            assert_eq!(got.stamp_ns, 1_700_000_000_250_000_000);
            assert_eq!(got.angular_velocity, [0.125, -0.5, 2.0]);
            assert_eq!(got.linear_acceleration, [0.01, -0.02, 0.998]);
            for cut in 0..m.len() {
                assert!(imu(enc, &m[..cut]).is_err(), "{enc:?} cut at {cut}");
            }
            let mut long = m.clone();
            long.extend_from_slice(&[1; 8]);
            assert_eq!(imu(enc, &long), Err(MsgError::Trailing { extra: 8 }));
        }
    }

    #[test]
    fn pandar_packet_is_its_first_size_bytes() {
        let mut m = vec![0, 1, 0, 0];
        m.extend_from_slice(&[0; 8]); // stamp
        m.extend_from_slice(&1_u32.to_le_bytes()); // frame_id: "" with NUL
        m.extend_from_slice(&[0, 0, 0, 0]); // NUL + pad
        m.extend_from_slice(&1_u32.to_le_bytes());
        m.extend_from_slice(&1_i32.to_le_bytes());
        m.extend_from_slice(&2_u32.to_le_bytes());
        m.extend(std::iter::repeat_n(0xab, 1500));
        m.extend_from_slice(&1080_u32.to_le_bytes());
        let mut out = Vec::new();
        packets(MsgKind::PandarScan, Encoding::Cdr, &m, &mut out).unwrap();
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].len, 1080);
        assert_eq!(out[0].stamp_ns, Some(1_000_000_002));
    }

    /// A `ringscan.RawPacket` written byte by byte from the protobuf encoding guide (varints
    /// worked out by hand), its fields out of order and with an unknown field between.
    fn raw_packet_bytes() -> Vec<u8> {
        let mut m = vec![0x2a, 3, 0xde, 0xad, 0x01]; // 5 payload: LEN 3
        m.extend_from_slice(&[0x12, 13]); // 2 source_address: LEN 13
        m.extend_from_slice(b"169.254.92.15");
        m.extend_from_slice(&[0x18, 0xce, 0x3a]); // 3 source_port: 7502
        m.extend_from_slice(&[0x35, 1, 2, 3, 4]); // 6 (unknown): I32, skipped
        m.extend_from_slice(&[0x20, 0xce, 0x3a]); // 4 destination_port: 7502
                                                  // 1 timestamp: {1 seconds: 1_700_000_000, 2 nanos: 250_000_001}
        m.extend_from_slice(&[0x0a, 11, 0x08, 0x80, 0xe2, 0xcf, 0xaa, 0x06]);
        m.extend_from_slice(&[0x10, 0x81, 0xe5, 0x9a, 0x77]);
        m
    }

    #[test]
    fn raw_packet_fields_in_any_order() {
        let m = raw_packet_bytes();
        let r = raw_packet(Encoding::Protobuf, &m).unwrap();
        assert_eq!(
            &m[r.packet.start..r.packet.start + r.packet.len],
            [0xde, 0xad, 0x01]
        );
        assert_eq!(r.packet.stamp_ns, Some(1_700_000_000_250_000_001));
        assert_eq!(r.source, "169.254.92.15:7502".parse().unwrap());
        assert_eq!(r.destination_port, 7502);
        assert_eq!(
            MsgKind::from_type_name("ringscan.RawPacket"),
            Some(MsgKind::RawPacket)
        );
        // Not a ROS message, and no ROS message is protobuf.
        assert!(raw_packet(Encoding::Cdr, &m).is_err());
        assert!(!MsgKind::RawPacket.serialized_as(Encoding::Ros1));
        assert!(!MsgKind::VelodyneScan.serialized_as(Encoding::Protobuf));
        let mut out = Vec::new();
        assert!(packets(MsgKind::VelodyneScan, Encoding::Protobuf, &m, &mut out).is_err());
        // A later scalar wins; a later Timestamp merges into the first (nanos only here).
        let mut later = m.clone();
        later.extend_from_slice(&[0x20, 0xb0, 0xea, 0x01, 0x0a, 2, 0x10, 0x05]);
        let r = raw_packet(Encoding::Protobuf, &later).unwrap();
        assert_eq!(r.destination_port, 30_000);
        assert_eq!(r.packet.stamp_ns, Some(1_700_000_000_000_000_005));
        // No timestamp: the record time serves.
        let r = raw_packet(Encoding::Protobuf, &m[..m.len() - 13]).unwrap();
        assert_eq!(r.packet.stamp_ns, None);
    }

    #[test]
    fn hostile_raw_packets_are_errors_not_panics() {
        let m = raw_packet_bytes();
        // Every cut but the ones at a field's end breaks a field.
        let ends = [5, 20, 23, 28, 31, 44];
        for cut in 0..m.len() {
            let r = raw_packet(Encoding::Protobuf, &m[..cut]);
            let whole = ends.contains(&cut);
            // Before the source address there is none.
            assert_eq!(r.is_ok(), whole && cut >= 20, "cut at {cut}: {r:?}");
        }
        let with = |extra: &[u8]| {
            let mut b = m.clone();
            b.extend_from_slice(extra);
            raw_packet(Encoding::Protobuf, &b)
        };
        for (extra, what) in [
            (&[0x18, 0xf0, 0xa2, 0x04][..], "a port above 65535"),
            (
                &[0x12, 3, b'a', b'b', b'c'],
                "source_address is not an IPv4 dotted quad",
            ),
            (
                &[0x12, 2, b':', b':'],
                "source_address is not an IPv4 dotted quad",
            ),
            (&[0x1a, 2, 0, 0], "a known field of the wrong wire type"),
            (&[0x0b], "a group or unknown wire type"),
            (&[0x07, 0], "a field number outside 1..2^29"),
            (
                &[0x2a, 0x80, 0x80, 0x80, 0x80, 0x10],
                "a field longer than the bytes left",
            ),
            (
                &[
                    0x20, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x02,
                ],
                "a varint longer than 64 bits",
            ),
            (&[0x0a, 2, 0x10, 0x80], "a broken Timestamp"),
        ] {
            match with(extra) {
                Err(MsgError::Protobuf { what: w, .. }) => assert_eq!(w, what, "{extra:02x?}"),
                r => panic!("{extra:02x?}: {r:?}"),
            }
        }
        // nanos out of range (2^31 − 1) and seconds whose ns overflow an i64.
        assert!(with(&[0x0a, 6, 0x10, 0xff, 0xff, 0xff, 0xff, 0x07]).is_err());
        let big = [
            0x0a, 10, 0x08, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x7f,
        ];
        assert!(with(&big).is_err());
    }
}
