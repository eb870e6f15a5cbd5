//! The Livox control protocols as pure functions over bytes (no sockets, no clocks): frames
//! built and checked for `ringscan listen --configure`, which owns the I/O.
//!
//! **SDK2** (MID-360, HAP; "Livox LiDAR Communication Protocol — Mid360" and "Livox SDK
//! Communication Protocol HAP", §"Control Command Protocol"), little-endian:
//!
//! | offset | size | field |
//! |--------|------|-------|
//! | 0  | 1 | sof, 0xAA |
//! | 1  | 1 | version, 0 |
//! | 2  | 2 | length of the whole frame |
//! | 4  | 4 | seq_num (the ACK repeats the request's) |
//! | 8  | 2 | cmd_id |
//! | 10 | 1 | cmd_type: 0 REQ, 1 ACK |
//! | 11 | 1 | sender_type: 0 host, 1 lidar |
//! | 12 | 6 | reserved |
//! | 18 | 2 | crc16_h: CRC-16/CCITT-FALSE of bytes 0..18 |
//! | 20 | 4 | crc32_d: CRC-32 of the data (0 when there is none) |
//! | 24 | … | data |
//!
//! Discovery (cmd 0x0000, broadcast to port 56000) has no request data; its ACK is
//! `ret_code u8, dev_type u8, serial [16], lidar_ip [4], cmd_port u16`. Parameter
//! configuration (cmd 0x0100) carries `key_num u16, reserved u16` and a key-value list
//! (`key u16, length u16, value`); its ACK is `ret_code u8, error_key u16`.
//!
//! **SDK1** (Mid-40/70, Horizon, Tele-15, Avia; "Livox SDK Communication Protocol" §2):
//! `sof 0xAA, version 1, length u16 (whole frame), cmd_type u8 (0 CMD, 1 ACK, 2 MSG),
//! seq_num u16, crc_16 u16` (CRC-16/MCRF4XX seeded 0x4C49 over the 7 bytes before it), then
//! `cmd_set u8, cmd_id u8, payload`, then `crc_32 u32` over everything before it (CRC-32 seeded
//! 0x564F580A). The device broadcasts (cmd 0/0, MSG) to port 55000 from its command port
//! 65000; the host answers with a handshake (0/1: its IP and data, command and IMU ports),
//! starts sampling (0/4) and sends a heartbeat (0/3) at least once a second.

use std::net::Ipv4Addr;

use thiserror::Error;

use super::wire::{u16_at, u32_at};

/// Start of frame of both protocols.
pub const SOF: u8 = 0xAA;
/// SDK2 header length.
pub const SDK2_HEADER: usize = 24;
/// SDK1 header length (before cmd_set).
pub const SDK1_HEADER: usize = 9;
/// SDK1 frame bytes around the payload: header, cmd_set, cmd_id, CRC-32.
pub const SDK1_WRAPPER: usize = SDK1_HEADER + 2 + 4;
/// Largest control frame either protocol sends (SDK2 caps `length` at 1400).
pub const MAX_FRAME: usize = 1400;

/// SDK2 port the discovery broadcast goes to.
pub const SDK2_DISCOVERY_PORT: u16 = 56_000;
/// SDK1 host port the devices' broadcast comes to.
pub const SDK1_BROADCAST_PORT: u16 = 55_000;
/// SDK1 device command port.
pub const SDK1_DEVICE_CMD_PORT: u16 = 65_000;

/// SDK2 command ids.
pub mod cmd {
    /// Discovery by broadcast.
    pub const DISCOVERY: u16 = 0x0000;
    /// Parameter configuration (key-value list).
    pub const SET_PARAMS: u16 = 0x0100;
}

/// SDK2 parameter keys used here.
pub mod key {
    /// Point-data destination: host IP, host port, lidar port.
    pub const POINT_DEST: u16 = 0x0006;
    /// IMU-data destination: host IP, host port, lidar port.
    pub const IMU_DEST: u16 = 0x0007;
    /// Target work mode (u8).
    pub const WORK_MODE: u16 = 0x001A;
    /// IMU data on / off (u8).
    pub const IMU_EN: u16 = 0x001C;
}

/// SDK2 work mode "normal / sampling": the sensor sends point and IMU data.
pub const WORK_MODE_SAMPLING: u8 = 0x01;

/// SDK2 device types from the discovery ACK that `--configure` handles: MID-360 (9) and HAP
/// (10: industrial HAP, 15: HAP), as Livox-SDK2's `LivoxLidarDeviceType` lists them.
pub fn sdk2_model(dev_type: u8) -> Option<super::LivoxModel> {
    match dev_type {
        9 => Some(super::LivoxModel::Mid360),
        10 | 15 => Some(super::LivoxModel::Hap),
        _ => None,
    }
}

/// SDK1 device types of the broadcast: Mid-40 (1), Tele-15 (2), Horizon (3), Mid-70 (6),
/// Avia (7) (Livox-SDK `DeviceType`; 0 is a hub, not handled).
pub fn sdk1_model(dev_type: u8) -> Option<super::LivoxModel> {
    use super::LivoxModel as M;
    match dev_type {
        1 => Some(M::Mid40),
        2 => Some(M::Tele15),
        3 => Some(M::Horizon),
        6 => Some(M::Mid70),
        7 => Some(M::Avia),
        _ => None,
    }
}

/// The name of an SDK2 ACK return code (the protocol's "Return Code Description").
pub fn sdk2_return_name(code: u8) -> &'static str {
    match code {
        0x00 => "SUCCESS",
        0x01 => "FAILURE",
        0x02 => "NOT_PERMIT_NOW",
        0x03 => "OUT_OF_RANGE",
        0x20 => "PARAM_NOTSUPPORT",
        0x21 => "PARAM_REBOOT_EFFECT",
        0x22 => "PARAM_RD_ONLY",
        0x23 => "PARAM_INVALID_LEN",
        0x24 => "PARAM_KEY_NUM_ERR",
        0x30 => "UPGRADE_PUB_KEY_ERROR",
        0x31 => "UPGRADE_DIGEST_ERROR",
        0x32 => "UPGRADE_FW_TYPE_ERROR",
        0x33 => "UPGRADE_FW_OUT_OF_RANGE",
        _ => "unknown return code",
    }
}

/// The name of an SDK1 ACK return code (0 success, 1 failure).
pub fn sdk1_return_name(code: u8) -> &'static str {
    match code {
        0 => "success",
        1 => "failure",
        _ => "unknown return code",
    }
}

/// Why bytes are not a control frame.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum ControlError {
    /// Shorter than the frame's fixed part.
    #[error("{what}: {found} bytes, shorter than its {needed}-byte frame")]
    Short {
        /// Which protocol.
        what: &'static str,
        /// Bytes needed.
        needed: usize,
        /// Bytes found.
        found: usize,
    },
    /// Not 0xAA.
    #[error("{what}: start byte {found:#04x}, expected 0xaa")]
    Sof {
        /// Which protocol.
        what: &'static str,
        /// Byte found.
        found: u8,
    },
    /// Unknown protocol version.
    #[error("{what}: version {found}, expected {expected}")]
    Version {
        /// Which protocol.
        what: &'static str,
        /// Version expected.
        expected: u8,
        /// Version found.
        found: u8,
    },
    /// The length field disagrees with the datagram.
    #[error("{what}: length field {field}, datagram {found} bytes")]
    Length {
        /// Which protocol.
        what: &'static str,
        /// Length field.
        field: u16,
        /// Datagram length.
        found: usize,
    },
    /// A CRC does not match.
    #[error("{what}: {which} stored {stored:#x}, computed {computed:#x}")]
    Crc {
        /// Which protocol.
        what: &'static str,
        /// "header CRC-16" or "CRC-32".
        which: &'static str,
        /// Stored.
        stored: u32,
        /// Computed.
        computed: u32,
    },
    /// An ACK's data is shorter than the command's.
    #[error("{what}: ACK of {needed} data bytes expected, {found} found")]
    AckShort {
        /// Which command.
        what: &'static str,
        /// Bytes needed.
        needed: usize,
        /// Bytes found.
        found: usize,
    },
}

const SDK2: &str = "Livox SDK2 control frame";
const SDK1: &str = "Livox SDK1 control frame";

/// CRC-16/CCITT-FALSE (polynomial 0x1021, initial 0xFFFF, not reflected, no final XOR): the
/// SDK2 header check.
pub fn crc16_ccitt_false(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in bytes {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// CRC-16/MCRF4XX (polynomial 0x1021 reflected, no final XOR) from `seed`: the SDK1 header
/// check with seed 0x4C49.
pub fn crc16_mcrf4xx(seed: u16, bytes: &[u8]) -> u16 {
    let mut crc = seed;
    for &b in bytes {
        crc ^= u16::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0x8408
            } else {
                crc >> 1
            };
        }
    }
    crc
}

/// SDK1's CRC-32: CRC-32/ISO-HDLC continued from 0x564F580A (its seed).
pub fn crc32_sdk1(bytes: &[u8]) -> u32 {
    let mut h = crc32fast::Hasher::new_with_initial(0x564F_580A);
    h.update(bytes);
    h.finalize()
}

/// A checked SDK2 control frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Sdk2Frame<'a> {
    /// seq_num.
    pub seq: u32,
    /// cmd_id.
    pub cmd_id: u16,
    /// 0 REQ, 1 ACK.
    pub cmd_type: u8,
    /// 0 host, 1 lidar.
    pub sender_type: u8,
    /// The data.
    pub data: &'a [u8],
}

/// Builds an SDK2 frame.
pub fn sdk2_frame(seq: u32, cmd_id: u16, cmd_type: u8, sender_type: u8, data: &[u8]) -> Vec<u8> {
    let len = SDK2_HEADER + data.len();
    let mut b = vec![0u8; len];
    b[0] = SOF;
    b[1] = 0;
    b[2..4].copy_from_slice(&(len as u16).to_le_bytes());
    b[4..8].copy_from_slice(&seq.to_le_bytes());
    b[8..10].copy_from_slice(&cmd_id.to_le_bytes());
    b[10] = cmd_type;
    b[11] = sender_type;
    let c16 = crc16_ccitt_false(&b[..18]);
    b[18..20].copy_from_slice(&c16.to_le_bytes());
    let c32 = if data.is_empty() {
        0
    } else {
        super::wire::crc32(data)
    };
    b[20..24].copy_from_slice(&c32.to_le_bytes());
    b[24..].copy_from_slice(data);
    b
}

/// Checks an SDK2 frame: start byte, version, length, both CRCs.
pub fn sdk2_parse(b: &[u8]) -> Result<Sdk2Frame<'_>, ControlError> {
    if b.len() < SDK2_HEADER {
        return Err(ControlError::Short {
            what: SDK2,
            needed: SDK2_HEADER,
            found: b.len(),
        });
    }
    if b[0] != SOF {
        return Err(ControlError::Sof {
            what: SDK2,
            found: b[0],
        });
    }
    if b[1] != 0 {
        return Err(ControlError::Version {
            what: SDK2,
            expected: 0,
            found: b[1],
        });
    }
    let len = u16_at(b, 2);
    if usize::from(len) != b.len() {
        return Err(ControlError::Length {
            what: SDK2,
            field: len,
            found: b.len(),
        });
    }
    let (stored, computed) = (u16_at(b, 18), crc16_ccitt_false(&b[..18]));
    if stored != computed {
        return Err(ControlError::Crc {
            what: SDK2,
            which: "header CRC-16",
            stored: u32::from(stored),
            computed: u32::from(computed),
        });
    }
    let data = &b[SDK2_HEADER..];
    let (stored, computed) = (
        u32_at(b, 20),
        if data.is_empty() {
            0
        } else {
            super::wire::crc32(data)
        },
    );
    if stored != computed {
        return Err(ControlError::Crc {
            what: SDK2,
            which: "CRC-32",
            stored,
            computed,
        });
    }
    Ok(Sdk2Frame {
        seq: u32_at(b, 4),
        cmd_id: u16_at(b, 8),
        cmd_type: b[10],
        sender_type: b[11],
        data,
    })
}

/// The discovery request.
pub fn sdk2_discovery(seq: u32) -> Vec<u8> {
    sdk2_frame(seq, cmd::DISCOVERY, 0, 0, &[])
}

/// A parameter-configuration request of `(key, value)` pairs.
pub fn sdk2_set_params(seq: u32, kv: &[(u16, Vec<u8>)]) -> Vec<u8> {
    let mut d = Vec::with_capacity(4 + kv.iter().map(|(_, v)| 4 + v.len()).sum::<usize>());
    d.extend_from_slice(&(kv.len() as u16).to_le_bytes());
    d.extend_from_slice(&[0, 0]);
    for (k, v) in kv {
        d.extend_from_slice(&k.to_le_bytes());
        d.extend_from_slice(&(v.len() as u16).to_le_bytes());
        d.extend_from_slice(v);
    }
    sdk2_frame(seq, cmd::SET_PARAMS, 0, 0, &d)
}

/// The value of a destination key (0x0006, 0x0007): host IP, host port, lidar port (0: the
/// sensor keeps its own).
pub fn sdk2_dest(host: Ipv4Addr, host_port: u16, lidar_port: u16) -> Vec<u8> {
    let mut v = host.octets().to_vec();
    v.extend_from_slice(&host_port.to_le_bytes());
    v.extend_from_slice(&lidar_port.to_le_bytes());
    v
}

/// What a discovery ACK says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DiscoveryAck {
    /// ret_code.
    pub ret_code: u8,
    /// Device type.
    pub dev_type: u8,
    /// Serial number, NUL-padded.
    pub serial: [u8; 16],
    /// The sensor's IP.
    pub ip: Ipv4Addr,
    /// Its control command port.
    pub cmd_port: u16,
}

impl DiscoveryAck {
    /// The serial number as text.
    pub fn serial_str(&self) -> String {
        let end = self.serial.iter().position(|&c| c == 0).unwrap_or(16);
        String::from_utf8_lossy(&self.serial[..end]).into_owned()
    }
}

/// Parses a discovery ACK's data.
pub fn sdk2_discovery_ack(d: &[u8]) -> Result<DiscoveryAck, ControlError> {
    let Some(&[ret_code, dev_type, ..]) = d.get(..24) else {
        return Err(ControlError::AckShort {
            what: "Livox SDK2 discovery",
            needed: 24,
            found: d.len(),
        });
    };
    let mut serial = [0u8; 16];
    serial.copy_from_slice(&d[2..18]);
    Ok(DiscoveryAck {
        ret_code,
        dev_type,
        serial,
        ip: Ipv4Addr::new(d[18], d[19], d[20], d[21]),
        cmd_port: u16_at(d, 22),
    })
}

/// Parses a parameter-configuration ACK's data: (ret_code, error_key).
pub fn sdk2_params_ack(d: &[u8]) -> Result<(u8, u16), ControlError> {
    match d.get(..3) {
        Some(&[r, a, b]) => Ok((r, u16::from_le_bytes([a, b]))),
        _ => Err(ControlError::AckShort {
            what: "Livox SDK2 parameter configuration",
            needed: 3,
            found: d.len(),
        }),
    }
}

/// SDK1 packet types.
pub mod sdk1_type {
    /// A command.
    pub const CMD: u8 = 0;
    /// Its acknowledgement.
    pub const ACK: u8 = 1;
    /// A message (the broadcast).
    pub const MSG: u8 = 2;
}

/// SDK1 general command ids (cmd_set 0).
pub mod sdk1_cmd {
    /// Broadcast message.
    pub const BROADCAST: u8 = 0x00;
    /// Handshake.
    pub const HANDSHAKE: u8 = 0x01;
    /// Heartbeat.
    pub const HEARTBEAT: u8 = 0x03;
    /// Start / stop sampling.
    pub const SAMPLING: u8 = 0x04;
    /// Disconnect.
    pub const DISCONNECT: u8 = 0x06;
}

/// A checked SDK1 control frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Sdk1Frame<'a> {
    /// 0 CMD, 1 ACK, 2 MSG.
    pub cmd_type: u8,
    /// seq_num.
    pub seq: u16,
    /// Command set.
    pub cmd_set: u8,
    /// Command id.
    pub cmd_id: u8,
    /// Payload after cmd_set and cmd_id.
    pub payload: &'a [u8],
}

/// Builds an SDK1 frame.
pub fn sdk1_frame(cmd_type: u8, seq: u16, cmd_set: u8, cmd_id: u8, payload: &[u8]) -> Vec<u8> {
    let len = SDK1_WRAPPER + payload.len();
    let mut b = Vec::with_capacity(len);
    b.push(SOF);
    b.push(1);
    b.extend_from_slice(&(len as u16).to_le_bytes());
    b.push(cmd_type);
    b.extend_from_slice(&seq.to_le_bytes());
    let c16 = crc16_mcrf4xx(0x4C49, &b[..7]);
    b.extend_from_slice(&c16.to_le_bytes());
    b.push(cmd_set);
    b.push(cmd_id);
    b.extend_from_slice(payload);
    let c32 = crc32_sdk1(&b);
    b.extend_from_slice(&c32.to_le_bytes());
    b
}

/// Checks an SDK1 frame: start byte, version, length, both CRCs.
pub fn sdk1_parse(b: &[u8]) -> Result<Sdk1Frame<'_>, ControlError> {
    if b.len() < SDK1_WRAPPER {
        return Err(ControlError::Short {
            what: SDK1,
            needed: SDK1_WRAPPER,
            found: b.len(),
        });
    }
    if b[0] != SOF {
        return Err(ControlError::Sof {
            what: SDK1,
            found: b[0],
        });
    }
    if b[1] != 1 {
        return Err(ControlError::Version {
            what: SDK1,
            expected: 1,
            found: b[1],
        });
    }
    let len = u16_at(b, 2);
    if usize::from(len) != b.len() {
        return Err(ControlError::Length {
            what: SDK1,
            field: len,
            found: b.len(),
        });
    }
    let (stored, computed) = (u16_at(b, 7), crc16_mcrf4xx(0x4C49, &b[..7]));
    if stored != computed {
        return Err(ControlError::Crc {
            what: SDK1,
            which: "header CRC-16",
            stored: u32::from(stored),
            computed: u32::from(computed),
        });
    }
    let end = b.len() - 4;
    let (stored, computed) = (u32_at(b, end), crc32_sdk1(&b[..end]));
    if stored != computed {
        return Err(ControlError::Crc {
            what: SDK1,
            which: "CRC-32",
            stored,
            computed,
        });
    }
    Ok(Sdk1Frame {
        cmd_type: b[4],
        seq: u16_at(b, 5),
        cmd_set: b[9],
        cmd_id: b[10],
        payload: &b[11..end],
    })
}

/// What a device's broadcast says: its broadcast code (serial) and device type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Broadcast {
    /// Broadcast code, NUL-padded.
    pub code: [u8; 16],
    /// Device type.
    pub dev_type: u8,
}

impl Broadcast {
    /// The broadcast code as text.
    pub fn code_str(&self) -> String {
        let end = self.code.iter().position(|&c| c == 0).unwrap_or(16);
        String::from_utf8_lossy(&self.code[..end]).into_owned()
    }
}

/// The broadcast in a frame, if it is one.
pub fn sdk1_broadcast(f: &Sdk1Frame<'_>) -> Option<Broadcast> {
    if f.cmd_type != sdk1_type::MSG || f.cmd_set != 0 || f.cmd_id != sdk1_cmd::BROADCAST {
        return None;
    }
    let p = f.payload.get(..17)?;
    let mut code = [0u8; 16];
    code.copy_from_slice(&p[..16]);
    Some(Broadcast {
        code,
        dev_type: p[16],
    })
}

/// The handshake: the host's IP and its data, command and IMU ports.
pub fn sdk1_handshake(
    seq: u16,
    host: Ipv4Addr,
    data_port: u16,
    cmd_port: u16,
    imu_port: u16,
) -> Vec<u8> {
    let mut p = host.octets().to_vec();
    p.extend_from_slice(&data_port.to_le_bytes());
    p.extend_from_slice(&cmd_port.to_le_bytes());
    p.extend_from_slice(&imu_port.to_le_bytes());
    sdk1_frame(sdk1_type::CMD, seq, 0, sdk1_cmd::HANDSHAKE, &p)
}

/// A heartbeat.
pub fn sdk1_heartbeat(seq: u16) -> Vec<u8> {
    sdk1_frame(sdk1_type::CMD, seq, 0, sdk1_cmd::HEARTBEAT, &[])
}

/// Start (`true`) or stop sampling.
pub fn sdk1_sampling(seq: u16, start: bool) -> Vec<u8> {
    sdk1_frame(
        sdk1_type::CMD,
        seq,
        0,
        sdk1_cmd::SAMPLING,
        &[u8::from(start)],
    )
}

/// Disconnect.
pub fn sdk1_disconnect(seq: u16) -> Vec<u8> {
    sdk1_frame(sdk1_type::CMD, seq, 0, sdk1_cmd::DISCONNECT, &[])
}

/// The return code of an SDK1 ACK to `cmd_id` (its first payload byte).
pub fn sdk1_ack_code(f: &Sdk1Frame<'_>, cmd_id: u8) -> Option<u8> {
    if f.cmd_type != sdk1_type::ACK || f.cmd_set != 0 || f.cmd_id != cmd_id {
        return None;
    }
    f.payload.first().copied()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_check_values() {
        // Catalogue check values over "123456789".
        assert_eq!(crc16_ccitt_false(b"123456789"), 0x29B1);
        assert_eq!(crc16_mcrf4xx(0xFFFF, b"123456789"), 0x6F91);
    }

    #[test]
    fn frames_round_trip_and_reject_a_flipped_bit() {
        let f = sdk2_set_params(7, &[(key::WORK_MODE, vec![1])]);
        let p = sdk2_parse(&f).unwrap();
        assert_eq!((p.seq, p.cmd_id, p.cmd_type), (7, cmd::SET_PARAMS, 0));
        for i in 0..f.len() {
            let mut g = f.clone();
            g[i] ^= 0x10;
            assert!(sdk2_parse(&g).is_err(), "byte {i}");
        }
        let h = sdk1_handshake(3, Ipv4Addr::LOCALHOST, 1, 2, 3);
        let q = sdk1_parse(&h).unwrap();
        assert_eq!(
            (q.seq, q.cmd_id, q.payload.len()),
            (3, sdk1_cmd::HANDSHAKE, 10)
        );
        for i in 0..h.len() {
            let mut g = h.clone();
            g[i] ^= 0x10;
            assert!(sdk1_parse(&g).is_err(), "byte {i}");
        }
    }
}
