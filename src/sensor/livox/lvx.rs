//! The Livox Viewer's recordings, `.lvx` (Livox Viewer 1, SDK1 sensors) and `.lvx2` (Livox
//! Viewer 2, SDK2 sensors), as byte layouts: pure functions over slices, no I/O (the reader
//! loop is [`crate::source::lvx`]). Little-endian throughout.
//!
//! Layout (Livox "LVX Specifications" v1.1 and "LVX2 Specifications" v2.0; the same structs
//! as `LvxFilePublicHeader` … `FrameHeader` of Livox-SDK `sample/lidar_lvx_file/lvx_file.h`):
//!
//! | block | bytes | fields |
//! |---|---|---|
//! | public header | 24 | signature `livox_tech` + NULs (16), version a.b.c.d (1.1.0.0 or 2.0.0.0), magic `0xAC0EA767` u32 |
//! | private header | 5 | frame duration u32 (ms, 50), device count u8 |
//! | device info (lvx) | 59 each | lidar SN (16), hub SN (16), device index u8, device type u8, extrinsic enable u8, roll pitch yaw (f32 °), x y z (f32 m) |
//! | device info (lvx2) | 63 each | lidar SN (16), hub SN (16), lidar id u32, lidar type u8, device type u8, extrinsic enable u8, roll pitch yaw, x y z (f32) |
//! | frame header | 24 | current offset u64 (of this header in the file), next offset u64, frame index u64 |
//! | package (lvx) | 19 + data | device index u8, then the SDK1 packet header as sent (version, slot, id, reserved, status u32, timestamp type, data type, timestamp 8 B) and its records; the data length follows from the data type (SDK1's fixed records per packet) |
//! | package (lvx2) | 27 + data | version u8, lidar id u32, lidar type u8, timestamp type u8, timestamp u64 (ns), udp counter u16, data type u8, data length u32, frame counter u8, reserved 4 B, then the records |
//!
//! Device type (Livox-SDK `DeviceType`, Livox-SDK2 `LivoxLidarDeviceType`): 1 Mid-40,
//! 2 Tele-15, 3 Horizon, 6 Mid-70, 7 Avia, 9 MID-360, 10 and 15 HAP. The version 1.0.0.0
//! layout of the first Livox Viewer (a private header without the duration, device info
//! without the extrinsic flag, frames with a packet count and float points) is refused.
//!
//! # Packages become the datagrams the sensor sent
//! Each package is turned back into the UDP payload its sensor sent, so the one Livox decoder
//! ([`super::LivoxStream`]) reads recordings as it reads captures, with the same loss, clock
//! and sweep rules, and `replay` can send them. An `.lvx` package *is* that payload after its
//! device-index byte. An `.lvx2` package carries the SDK2 header's fields but two: `dot_num`
//! follows from the data length, and `time_interval` (which the file drops) is rebuilt from
//! the model's point rate, `(N − 1)` record spacings in 0.1 µs (MID-360: 95 × 5 µs = 4750);
//! for a device type ringscan does not know it is 0 (every point at the packet's time). The
//! rebuilt header carries the CRC-32 of what it covers, so the stream's CRC check passes: the
//! file holds no CRC to check.

use super::model::LivoxModel;
use super::wire::{
    crc32, sdk1_timestamp_ns, u32_at, u64_at, Record, MAX_DATAGRAM, SDK1_HEADER_LEN,
    SDK2_HEADER_LEN,
};

/// The signature's text (the rest of its 16 bytes are NULs).
pub const SIGNATURE: &[u8; 10] = b"livox_tech";
/// The public header's magic code.
pub const MAGIC: u32 = 0xAC0E_A767;
/// Public header length.
pub const PUBLIC_HEADER_LEN: usize = 24;
/// Private header length.
pub const PRIVATE_HEADER_LEN: usize = 5;
/// Frame header length.
pub const FRAME_HEADER_LEN: usize = 24;
/// `.lvx` package header: device index + the SDK1 header.
pub const LVX1_PACKAGE_HEADER_LEN: usize = 1 + SDK1_HEADER_LEN;
/// `.lvx2` package header.
pub const LVX2_PACKAGE_HEADER_LEN: usize = 27;
/// Largest package data accepted (a package holds one UDP datagram's records).
pub const MAX_PACKAGE_DATA: usize = MAX_DATAGRAM - SDK1_HEADER_LEN;

/// Which file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LvxVersion {
    /// `.lvx` 1.1 (SDK1 sensors).
    Lvx1,
    /// `.lvx2` 2.0 (SDK2 sensors).
    Lvx2,
}

impl LvxVersion {
    /// Bytes of one device info block.
    pub const fn device_info_len(self) -> usize {
        match self {
            Self::Lvx1 => 59,
            Self::Lvx2 => 63,
        }
    }

    /// Bytes of one package header.
    pub const fn package_header_len(self) -> usize {
        match self {
            Self::Lvx1 => LVX1_PACKAGE_HEADER_LEN,
            Self::Lvx2 => LVX2_PACKAGE_HEADER_LEN,
        }
    }
}

/// Why the headers of a file are not a recording ringscan reads.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum LvxHeaderError {
    /// Not `livox_tech` + the magic code.
    #[error("not a Livox recording: no `livox_tech` signature and magic code 0xAC0EA767")]
    Signature,
    /// A version other than 1.1 / 2.0.
    #[error("Livox recording version {0}.{1}.{2}.{3}: ringscan reads 1.1 (.lvx) and 2.0 (.lvx2)")]
    Version(u8, u8, u8, u8),
}

/// Which file the 24-byte public header names, if it is a Livox recording at all.
pub fn public_header(b: &[u8]) -> Result<LvxVersion, LvxHeaderError> {
    let Some(h) = b.get(..PUBLIC_HEADER_LEN) else {
        return Err(LvxHeaderError::Signature);
    };
    let sig_ok = h[..10] == *SIGNATURE && h[10..16].iter().all(|&c| c == 0);
    if !sig_ok || u32::from_le_bytes([h[20], h[21], h[22], h[23]]) != MAGIC {
        return Err(LvxHeaderError::Signature);
    }
    match (h[16], h[17], h[18], h[19]) {
        (1, 1, _, _) => Ok(LvxVersion::Lvx1),
        (2, 0, _, _) => Ok(LvxVersion::Lvx2),
        (a, b, c, d) => Err(LvxHeaderError::Version(a, b, c, d)),
    }
}

/// Whether `b` starts like a Livox recording (signature and magic; any version).
pub fn is_lvx(b: &[u8]) -> bool {
    !matches!(public_header(b), Err(LvxHeaderError::Signature))
}

/// The model of a device type byte.
pub fn model_of_device_type(t: u8) -> Option<LivoxModel> {
    Some(match t {
        1 => LivoxModel::Mid40,
        2 => LivoxModel::Tele15,
        3 => LivoxModel::Horizon,
        6 => LivoxModel::Mid70,
        7 => LivoxModel::Avia,
        9 => LivoxModel::Mid360,
        10 | 15 => LivoxModel::Hap,
        _ => return None,
    })
}

/// One device info block.
#[derive(Clone, Debug, PartialEq)]
pub struct LvxDevice {
    /// Lidar serial number (broadcast code), NULs removed.
    pub lidar_sn: String,
    /// Hub serial number, NULs removed.
    pub hub_sn: String,
    /// `.lvx`: the device index packages name; `.lvx2`: the lidar id packages name.
    pub id: u32,
    /// Device type byte.
    pub device_type: u8,
    /// Its model, where ringscan knows the type.
    pub model: Option<LivoxModel>,
    /// Roll, pitch, yaw (°) and x, y, z (m) when the extrinsic flag is set.
    pub extrinsic: Option<[f32; 6]>,
}

fn text(b: &[u8]) -> String {
    let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
    String::from_utf8_lossy(&b[..end]).into_owned()
}

/// Reads a device info block of `version` (`b` holds at least its length, else `None`).
pub fn device_info(version: LvxVersion, b: &[u8]) -> Option<LvxDevice> {
    let b = b.get(..version.device_info_len())?;
    let (id, device_type, ext_at) = match version {
        LvxVersion::Lvx1 => (u32::from(b[32]), b[33], 34),
        LvxVersion::Lvx2 => (u32_at(b, 32), b[37], 38),
    };
    let extrinsic = (b[ext_at] != 0).then(|| {
        let mut e = [0f32; 6];
        for (k, v) in e.iter_mut().enumerate() {
            *v = f32::from_bits(u32_at(b, ext_at + 1 + 4 * k));
        }
        e
    });
    Some(LvxDevice {
        lidar_sn: text(&b[..16]),
        hub_sn: text(&b[16..32]),
        id,
        device_type,
        model: model_of_device_type(device_type),
        extrinsic,
    })
}

/// A frame header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameHeader {
    /// File offset of this header.
    pub current_offset: u64,
    /// File offset of the next frame's header (the end of this frame's packages).
    pub next_offset: u64,
    /// Frame index.
    pub frame_index: u64,
}

/// Reads a frame header (`b` holds at least [`FRAME_HEADER_LEN`] bytes, else `None`).
pub fn frame_header(b: &[u8]) -> Option<FrameHeader> {
    b.get(..FRAME_HEADER_LEN)?;
    Some(FrameHeader {
        current_offset: u64_at(b, 0),
        next_offset: u64_at(b, 8),
        frame_index: u64_at(b, 16),
    })
}

/// What a package header says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PackageHeader {
    /// `.lvx`: device index; `.lvx2`: lidar id.
    pub device: u32,
    /// Data type byte.
    pub data_type: u8,
    /// Bytes of records after the header.
    pub data_len: usize,
}

/// Why a package cannot be read (the rest of its frame is skipped).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum PackageError {
    /// An `.lvx` data type whose length SDK1 does not define.
    #[error("data type {0} unknown to SDK1: its length is unknown")]
    DataType(u8),
    /// A data length beyond one datagram's.
    #[error("data length {0} more than one datagram holds")]
    Length(u64),
}

/// Reads a package header of `version` (`b` holds at least its length).
pub fn package_header(
    version: LvxVersion,
    b: &[u8],
) -> Option<Result<PackageHeader, PackageError>> {
    let b = b.get(..version.package_header_len())?;
    Some(match version {
        LvxVersion::Lvx1 => {
            let dt = b[10];
            match Record::sdk1(dt) {
                Some((r, n)) => Ok(PackageHeader {
                    device: u32::from(b[0]),
                    data_type: dt,
                    data_len: r.size() * n,
                }),
                None => Err(PackageError::DataType(dt)),
            }
        }
        LvxVersion::Lvx2 => {
            let len = u32_at(b, 18);
            if len as usize > MAX_DATAGRAM - SDK2_HEADER_LEN {
                Err(PackageError::Length(u64::from(len)))
            } else {
                Ok(PackageHeader {
                    device: u32_at(b, 1),
                    data_type: b[17],
                    data_len: len as usize,
                })
            }
        }
    })
}

/// `.lvx2`: the SDK2 time interval (0.1 µs) of `records` records of `model`.
pub fn sdk2_time_interval(model: Option<LivoxModel>, records: usize) -> u16 {
    let Some(m) = model else { return 0 };
    let spacing_ns = 1e9 / f64::from(m.point_rate());
    let v = (records.saturating_sub(1) as f64 * spacing_ns / 100.0).round();
    v.clamp(0.0, f64::from(u16::MAX)) as u16
}

/// Writes the datagram of a whole package (`pkg` = header + data, as [`package_header`]
/// measured it) into `out` (cleared first): the SDK1 payload of an `.lvx` package, an SDK2
/// payload rebuilt from an `.lvx2` one (module doc). `model` is the package's device's.
pub fn package_datagram(
    version: LvxVersion,
    pkg: &[u8],
    model: Option<LivoxModel>,
    out: &mut Vec<u8>,
) {
    out.clear();
    match version {
        LvxVersion::Lvx1 => out.extend_from_slice(pkg.get(1..).unwrap_or(&[])),
        LvxVersion::Lvx2 => {
            let Some(h) = pkg.get(..LVX2_PACKAGE_HEADER_LEN) else {
                return;
            };
            let data = &pkg[LVX2_PACKAGE_HEADER_LEN..];
            let dt = h[17];
            let records = Record::sdk2(dt).map_or(0, |r| data.len() / r.size());
            let interval = if dt == 0 {
                0
            } else {
                sdk2_time_interval(model, records)
            };
            let len = (SDK2_HEADER_LEN + data.len()).min(usize::from(u16::MAX)) as u16;
            out.push(h[0]); // version
            out.extend_from_slice(&len.to_le_bytes());
            out.extend_from_slice(&interval.to_le_bytes());
            out.extend_from_slice(&(records.min(usize::from(u16::MAX)) as u16).to_le_bytes());
            out.extend_from_slice(&h[15..17]); // udp_cnt
            out.push(h[22]); // frame_cnt
            out.push(dt);
            out.push(h[6]); // time type
            out.extend_from_slice(&[0; 12]);
            out.extend_from_slice(&[0; 4]); // CRC, below
            out.extend_from_slice(&h[7..15]); // timestamp
            out.extend_from_slice(data);
            let crc = crc32(&out[28..]);
            out[24..28].copy_from_slice(&crc.to_le_bytes());
        }
    }
}

/// The device time of a package, ns (its timestamp; SDK1 UTC timestamps converted), for the
/// datagram's receive time: a recording keeps no host time.
pub fn package_time_ns(version: LvxVersion, pkg: &[u8]) -> i64 {
    match version {
        LvxVersion::Lvx1 => pkg
            .get(1..)
            .and_then(|p| {
                // The header alone gives the time (the SDK1 view needs the whole packet).
                let ty = *p.get(8)?;
                sdk1_timestamp_ns(ty, p.get(10..18)?.try_into().ok()?)
            })
            .map_or(0, |t| i64::try_from(t).unwrap_or(i64::MAX)),
        LvxVersion::Lvx2 => i64::try_from(u64_at(pkg, 7)).unwrap_or(i64::MAX),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mid360_interval_is_95_spacings_of_5_us() {
        assert_eq!(sdk2_time_interval(Some(LivoxModel::Mid360), 96), 4750);
        assert_eq!(sdk2_time_interval(None, 96), 0);
    }

    #[test]
    fn other_versions_are_named() {
        let mut h = [0u8; 24];
        h[..10].copy_from_slice(SIGNATURE);
        h[16] = 1;
        h[20..24].copy_from_slice(&MAGIC.to_le_bytes());
        assert_eq!(public_header(&h), Err(LvxHeaderError::Version(1, 0, 0, 0)));
        assert!(is_lvx(&h));
        h[20] ^= 1;
        assert!(!is_lvx(&h));
    }
}
