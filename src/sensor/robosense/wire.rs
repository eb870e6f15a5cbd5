//! Read-only views of the two Robosense packets: MSOP (points) and DIFOP (device information).
//! Both are 1248 bytes with big-endian fields; see [`super::model`] for the MSOP layouts.
//!
//! DIFOP (every model, port 7788 by default, about once a second): the 8-byte id
//! `A5 FF 00 5A 11 11 55 55`, motor speed (rpm, u16 at byte 8), the network settings (bytes
//! 10–31: sensor and host address, MAC, ports), the field of view (start and end azimuth, u16
//! 0.01°, bytes 32–35), the motor phase lock (38–39), firmware versions (from byte 40), the
//! serial number (6 bytes at 292), the return mode (byte 300), and the per-laser vertical and
//! horizontal angles (from byte 468: each a sign byte — 0 positive, 1 negative — and a u16 in
//! 0.01°; all vertical entries, then all horizontal). The RS-16 keeps its vertical angles as
//! 16 u24 values in 0.0001° at byte 1165 instead, lower eight lasers pointing down.

use super::model::{ClockForm, RobosenseModel, Shape, PACKET_LEN, RS16_PITCH_OFFSET};
use crate::sensor::WireError;

/// MSOP id of the RS-16 / RS-32 / Bpearl header.
pub const MSOP_ID_V1: [u8; 8] = [0x55, 0xAA, 0x05, 0x0A, 0x5A, 0xA5, 0x50, 0xA0];
/// MSOP id of the Helios and Ruby headers.
pub const MSOP_ID_V2: [u8; 4] = [0x55, 0xAA, 0x05, 0x5A];
/// DIFOP id.
pub const DIFOP_ID: [u8; 8] = [0xA5, 0xFF, 0x00, 0x5A, 0x11, 0x11, 0x55, 0x55];

pub(crate) fn be16(b: &[u8], o: usize) -> u16 {
    match b.get(o..o + 2) {
        Some(s) => u16::from_be_bytes([s[0], s[1]]),
        None => 0,
    }
}

/// Whether `payload` is a DIFOP packet.
pub fn is_difop(payload: &[u8]) -> bool {
    payload.len() == PACKET_LEN && payload.starts_with(&DIFOP_ID)
}

/// The header family of an MSOP packet from its bytes: V1 (8-byte id, calendar clock), Helios
/// (`55 AA 05 5A`, `FF EE` blocks from byte 42), Ruby (`55 AA 05 5A`, `FE` blocks from byte
/// 80) or the M1 (1210 bytes, `55 AA 5A A5`). `None` for anything else.
pub fn msop_shape(payload: &[u8]) -> Option<Shape> {
    if super::m1::is_m1_msop(payload) {
        return Some(Shape::Mems);
    }
    if payload.len() != PACKET_LEN {
        return None;
    }
    if payload.starts_with(&MSOP_ID_V1) && payload[42..44] == [0xFF, 0xEE] {
        return Some(Shape::V1);
    }
    if !payload.starts_with(&MSOP_ID_V2) {
        return None;
    }
    if payload[42..44] == [0xFF, 0xEE] && payload[142..144] == [0xFF, 0xEE] {
        Some(Shape::Helios)
    } else if payload[80] == 0xFE && payload[80 + 388] == 0xFE {
        Some(Shape::Ruby)
    } else {
        None
    }
}

/// A checked MSOP packet of one model.
#[derive(Clone, Copy, Debug)]
pub struct Msop<'a> {
    bytes: &'a [u8],
    shape: Shape,
}

impl<'a> Msop<'a> {
    /// Checks length, id and every block's flag and azimuth for `model`'s layout.
    pub fn new(bytes: &'a [u8], model: RobosenseModel) -> Result<Self, WireError> {
        let shape = model.spec().shape;
        if shape == Shape::Mems {
            // The M1's view is `super::m1::M1Msop`; none of this view's accessors fit it.
            return Err(WireError::Length {
                what: "Robosense spinning MSOP packet (the M1's is m1::M1Msop)",
                expected: PACKET_LEN,
                found: bytes.len(),
            });
        }
        if bytes.len() != PACKET_LEN {
            return Err(WireError::Length {
                what: "Robosense MSOP packet",
                expected: PACKET_LEN,
                found: bytes.len(),
            });
        }
        let id_ok = match shape {
            Shape::V1 => bytes.starts_with(&MSOP_ID_V1),
            Shape::Helios | Shape::Ruby => bytes.starts_with(&MSOP_ID_V2),
            Shape::Mems => false,
        };
        if !id_ok {
            return Err(WireError::BlockFlag {
                block: 0,
                offset: 0,
                found: bytes[0],
                found2: bytes[1],
            });
        }
        let p = Self { bytes, shape };
        for b in 0..shape.blocks() {
            let o = p.block_offset(b);
            let flag_ok = match shape {
                Shape::Ruby => bytes[o] == 0xFE,
                _ => bytes[o..o + 2] == [0xFF, 0xEE],
            };
            if !flag_ok {
                return Err(WireError::BlockFlag {
                    block: b,
                    offset: o,
                    found: bytes[o],
                    found2: bytes[o + 1],
                });
            }
            let az = be16(bytes, o + 2);
            if az >= 36_000 {
                return Err(WireError::Azimuth {
                    block: b,
                    offset: o + 2,
                    found: az,
                });
            }
        }
        Ok(p)
    }

    /// The bytes.
    pub fn bytes(&self) -> &'a [u8] {
        self.bytes
    }

    fn block_offset(&self, b: usize) -> usize {
        self.shape.header_len() + b * self.shape.block_len()
    }

    /// Block `b`'s azimuth, 0.01° (0..36000).
    pub fn azimuth(&self, b: usize) -> u16 {
        be16(self.bytes, self.block_offset(b) + 2)
    }

    /// Ruby: block `b`'s return id byte.
    pub fn return_id(&self, b: usize) -> u8 {
        match self.shape {
            Shape::Ruby => self.bytes[self.block_offset(b) + 1],
            _ => 0,
        }
    }

    /// Slot `s` of block `b`: (raw distance, intensity).
    #[inline]
    pub fn slot(&self, b: usize, s: usize) -> (u16, u8) {
        let o = self.block_offset(b) + self.shape.block_prefix() + 3 * s;
        match self.bytes.get(o..o + 3) {
            Some(u) => (u16::from_be_bytes([u[0], u[1]]), u[2]),
            None => (0, 0),
        }
    }

    /// The block's slots as 3-byte units.
    #[inline]
    pub fn block_units(&self, b: usize) -> &'a [u8] {
        let o = self.block_offset(b) + self.shape.block_prefix();
        self.bytes.get(o..o + 3 * self.shape.slots()).unwrap_or(&[])
    }

    /// Helios: protocol version (bytes 4–5).
    pub fn protocol_version(&self) -> Option<u16> {
        (self.shape != Shape::V1).then(|| be16(self.bytes, 4))
    }

    /// The header's time of the packet's first firing, ns since the Unix epoch; `None` when
    /// the calendar fields are out of range.
    pub fn stamp_ns(&self, form: ClockForm) -> Option<i64> {
        let t = &self.bytes[self.shape.time_offset()..self.shape.time_offset() + 10];
        match form {
            ClockForm::Unix => {
                let secs = t[..6].iter().fold(0i64, |a, &b| (a << 8) | i64::from(b));
                let us = t[6..].iter().fold(0i64, |a, &b| (a << 8) | i64::from(b));
                // Beyond 2^33 s (year 2242; 2^34 s in ns would not fit an i64) or a µs field
                // of a second or more: corrupt.
                if secs >= 1 << 33 || us >= 1_000_000 {
                    return None;
                }
                Some(secs * 1_000_000_000 + us * 1_000)
            }
            ClockForm::Calendar => calendar_ns(t),
        }
    }
}

/// ns since the epoch of the calendar form (year − 2000, month, day, hour, minute, second,
/// ms u16, µs u16), read as UTC.
pub fn calendar_ns(t: &[u8]) -> Option<i64> {
    let [y, mo, d, h, mi, s, ms0, ms1, us0, us1] = *t else {
        return None;
    };
    let (ms, us) = (
        u16::from_be_bytes([ms0, ms1]),
        u16::from_be_bytes([us0, us1]),
    );
    if !(1..=12).contains(&mo) || !(1..=31).contains(&d) || h > 23 || mi > 59 || s > 60 {
        return None;
    }
    if ms > 999 || us > 999 {
        return None;
    }
    let days = crate::sensor::hesai::wire::days_from_civil(
        2000 + i32::from(y),
        u32::from(mo),
        u32::from(d),
    );
    let secs = days * 86_400 + i64::from(h) * 3600 + i64::from(mi) * 60 + i64::from(s);
    Some(secs * 1_000_000_000 + i64::from(ms) * 1_000_000 + i64::from(us) * 1_000)
}

/// A fixed-size packet's length and leading id, checked: a wrong length, then a wrong id.
pub(crate) fn check_len_and_id(
    bytes: &[u8],
    what: &'static str,
    len: usize,
    id: &[u8],
) -> Result<(), WireError> {
    if bytes.len() != len {
        return Err(WireError::Length {
            what,
            expected: len,
            found: bytes.len(),
        });
    }
    if !bytes.starts_with(id) {
        return Err(WireError::BlockFlag {
            block: 0,
            offset: 0,
            found: bytes.first().copied().unwrap_or(0),
            found2: bytes.get(1).copied().unwrap_or(0),
        });
    }
    Ok(())
}

/// A DIFOP packet.
#[derive(Clone, Copy, Debug)]
pub struct Difop<'a> {
    bytes: &'a [u8],
}

impl<'a> Difop<'a> {
    /// Checks length and id.
    pub fn new(bytes: &'a [u8]) -> Result<Self, WireError> {
        check_len_and_id(bytes, "Robosense DIFOP packet", PACKET_LEN, &DIFOP_ID)?;
        Ok(Self { bytes })
    }

    /// Motor speed, rpm.
    pub fn rpm(&self) -> u16 {
        be16(self.bytes, 8)
    }

    /// Field of view: start and end azimuth, 0.01°.
    pub fn fov(&self) -> (u16, u16) {
        (be16(self.bytes, 32), be16(self.bytes, 34))
    }

    /// Sensor and destination addresses, and MSOP / DIFOP ports (Helios / Ruby form).
    pub fn network(&self) -> ([u8; 4], [u8; 4], u16, u16) {
        let b = self.bytes;
        (
            [b[10], b[11], b[12], b[13]],
            [b[14], b[15], b[16], b[17]],
            be16(b, 24),
            be16(b, 28),
        )
    }

    /// Top and bottom board firmware versions (5 bytes each, from byte 40), as hex.
    pub fn firmware(&self) -> String {
        let mut s = String::new();
        self.write_firmware(&mut s);
        s
    }

    /// [`Self::firmware`] written over `out`, which keeps its capacity: the stream re-reads it
    /// from every DIFOP (1 Hz) without allocating.
    pub fn write_firmware(&self, out: &mut String) {
        out.clear();
        push_hex(out, &self.bytes[40..45]);
        out.push('/');
        push_hex(out, &self.bytes[45..50]);
    }

    /// Serial number (6 bytes at 292), as hex.
    pub fn serial(&self) -> String {
        let mut s = String::new();
        self.write_serial(&mut s);
        s
    }

    /// [`Self::serial`] written over `out` (see [`Self::write_firmware`]).
    pub fn write_serial(&self, out: &mut String) {
        out.clear();
        push_hex(out, &self.bytes[292..298]);
    }

    /// Return-mode byte (300).
    pub fn return_mode(&self) -> u8 {
        self.bytes[300]
    }

    /// The per-laser angles of `model`, degrees (vertical, horizontal), or why they cannot be
    /// used (a sign byte other than 0 / 1 — an unprogrammed table reads `FF` — or an angle
    /// outside −90°..180°).
    pub fn angles(&self, model: RobosenseModel) -> Result<Vec<(f64, f64)>, String> {
        if model.spec().shape == Shape::Mems {
            return Err("the M1 has no angle table (its points carry their angles)".into());
        }
        let n = model.lasers();
        let Some((start, entries)) = model.spec().difop_angles else {
            let mut v = Vec::with_capacity(16);
            for i in 0..16 {
                let o = RS16_PITCH_OFFSET + 3 * i;
                let raw =
                    u32::from_be_bytes([0, self.bytes[o], self.bytes[o + 1], self.bytes[o + 2]]);
                let deg = f64::from(raw) / 10_000.0;
                if deg > 90.0 {
                    return Err(format!("RS-16 pitch {i}: {deg}° is out of range"));
                }
                v.push((if i < 8 { -deg } else { deg }, 0.0));
            }
            return Ok(v);
        };
        let read = |k: usize| -> Result<f64, String> {
            let o = start + 3 * k;
            let sign = self.bytes[o];
            let v = f64::from(be16(self.bytes, o + 1)) / 100.0;
            let v = match sign {
                0 => v,
                1 => -v,
                s => return Err(format!("angle entry {k}: sign byte {s:#04x}")),
            };
            if !(-90.0..180.0).contains(&v) {
                return Err(format!("angle entry {k}: {v}° is out of range"));
            }
            Ok(v)
        };
        let mut out = Vec::with_capacity(n);
        for i in 0..n {
            out.push((read(i)?, read(entries + i)?));
        }
        Ok(out)
    }
}

/// Appends `bytes` as lower-case hex.
fn push_hex(out: &mut String, bytes: &[u8]) {
    const HEX: &[u8; 16] = b"0123456789abcdef";
    for &b in bytes {
        out.push(char::from(HEX[usize::from(b >> 4)]));
        out.push(char::from(HEX[usize::from(b & 15)]));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn calendar_form() {
        // 2024-03-01 12:34:56.789012 UTC.
        let t = [24, 3, 1, 12, 34, 56, 0x03, 0x15, 0x00, 0x0C];
        assert_eq!(calendar_ns(&t), Some(1_709_296_496_789_012_000));
        assert_eq!(calendar_ns(&[24, 13, 1, 0, 0, 0, 0, 0, 0, 0]), None);
    }
}
