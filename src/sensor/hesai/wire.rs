//! Typed read-only view of one Hesai point-cloud packet (the layouts of [`super::model`]).
//!
//! [`HesaiPacket::new`] checks the length against the model's layout (with or without the
//! optional UDP sequence and cyber-security signature), the `EE FF` / `FF EE` marks and the
//! header's laser and block counts; after that no accessor can panic. CRCs are checked
//! separately ([`HesaiPacket::check_crc`]) so that a caller can count failures.

use super::model::{DateForm, HeaderKind, HesaiModel, Layout, TailFlags, SIGNATURE_LEN};
use crate::sensor::WireError;

/// CRC-32/MPEG-2: polynomial 0x04C11DB7, initial value 0xFFFFFFFF, not reflected, no final
/// XOR (the check value of "123456789" is 0x0376E6E7). Hesai's body and tail CRCs.
pub fn crc32_mpeg2(bytes: &[u8]) -> u32 {
    CRC32_MPEG2.checksum(bytes)
}

static CRC32_MPEG2: crc::Crc<u32, crc::Table<16>> =
    crc::Crc::<u32, crc::Table<16>>::new(&crc::CRC_32_MPEG_2);

fn le_u16(b: &[u8], o: usize) -> u16 {
    match b.get(o..o + 2) {
        Some(&[a, c]) => u16::from_le_bytes([a, c]),
        _ => 0,
    }
}

fn le_u32(b: &[u8], o: usize) -> u32 {
    match b.get(o..o + 4) {
        Some(&[a, c, d, e]) => u32::from_le_bytes([a, c, d, e]),
        _ => 0,
    }
}

fn byte(b: &[u8], o: usize) -> u8 {
    b.get(o).copied().unwrap_or(0)
}

/// Which CRC of a packet failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CrcPart {
    /// The blocks.
    Body,
    /// The tail.
    Tail,
}

/// The functional-safety block (QT128, OT128): the sensor's own health report.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FunctionalSafety {
    /// Version of the block.
    pub version: u8,
    /// Lidar state (bits 7–5): 0 init, 1 normal, 2 warning (QT128: "report fault"), 3
    /// pre-performance degradation, 4 performance degradation, 5 pre-shutdown, 6 shutdown,
    /// 7 standby (QT128 and Pandar128E3X manuals). The shared QT128 capture says 0 in every
    /// packet.
    pub lidar_state: u8,
    /// Fault code type (bits 4–3): 0 none, 1 current fault, 2 past fault.
    pub fault_code_type: u8,
    /// Rolling counter (bits 2–0).
    pub rolling_counter: u8,
    /// Total fault codes (bits 7–4 of the second byte).
    pub total_fault_codes: u8,
    /// Which of them this packet reports (bits 3–0).
    pub fault_code_id: u8,
    /// The fault code.
    pub fault_code: u16,
}

/// A checked view of one packet of `model`.
#[derive(Clone, Copy, Debug)]
pub struct HesaiPacket<'a> {
    bytes: &'a [u8],
    model: HesaiModel,
    /// The model's layout, or the one this packet's header gives (ATX).
    layout: Layout,
}

impl<'a> HesaiPacket<'a> {
    /// Checks `bytes` as a packet of `model`.
    pub fn new(bytes: &'a [u8], model: HesaiModel) -> Result<Self, WireError> {
        let spec_layout = &model.spec().layout;
        let layout = if spec_layout.counts_from_header {
            if !model.accepts(bytes) {
                return Err(WireError::Length {
                    what: "Hesai ATX packet (from its header's laser and block counts)",
                    expected: match bytes {
                        [_, _, _, _, _, _, l, b, _, _, _, f, ..] => {
                            spec_layout.for_header(*l, *b, *f).exact_len()
                        }
                        _ => spec_layout.base_len(),
                    },
                    found: bytes.len(),
                });
            }
            spec_layout.for_header(bytes[6], bytes[7], bytes[11])
        } else {
            *spec_layout
        };
        if !layout.counts_from_header && !layout.accepts_len(bytes.len()) {
            return Err(WireError::Length {
                what: model.name(),
                expected: layout.base_len(),
                found: bytes.len(),
            });
        }
        match layout.header {
            HeaderKind::None => {
                for b in 0..layout.blocks {
                    let o = b * layout.block_len();
                    if bytes[o..o + 2] != [0xFF, 0xEE] {
                        return Err(WireError::BlockFlag {
                            block: b,
                            offset: o,
                            found: bytes[o],
                            found2: bytes[o + 1],
                        });
                    }
                }
            }
            HeaderKind::Short8 | HeaderKind::PreHeader12 => {
                if bytes[0..2] != [0xEE, 0xFF] {
                    return Err(WireError::BlockFlag {
                        block: 0,
                        offset: 0,
                        found: bytes[0],
                        found2: bytes[1],
                    });
                }
                let at = if layout.header == HeaderKind::Short8 {
                    2
                } else {
                    6
                };
                let (lasers, blocks) = (usize::from(bytes[at]), usize::from(bytes[at + 1]));
                if layout.counts_from_header && bytes[2..4] != [4, 7] {
                    return Err(WireError::BlockFlag {
                        block: 0,
                        offset: 2,
                        found: bytes[2],
                        found2: bytes[3],
                    });
                }
                if lasers != layout.channels || blocks != layout.blocks {
                    return Err(WireError::Length {
                        what: "Hesai header laser × block count",
                        expected: layout.channels * layout.blocks,
                        found: lasers * blocks,
                    });
                }
            }
        }
        Ok(Self {
            bytes,
            model,
            layout,
        })
    }

    /// The model the view was built for.
    pub fn model(&self) -> HesaiModel {
        self.model
    }

    /// The packet's bytes.
    pub fn bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// The layout.
    pub fn layout(&self) -> &Layout {
        &self.layout
    }

    /// Protocol version (major, minor) of the pre-header.
    pub fn protocol(&self) -> Option<(u8, u8)> {
        (self.layout.header == HeaderKind::PreHeader12).then(|| (self.bytes[2], self.bytes[3]))
    }

    /// Distance unit, mm (header byte; 4 for the headerless Pandar40P).
    pub fn dis_unit_mm(&self) -> u8 {
        match self.layout.header {
            HeaderKind::None => self.model.spec().fixed_dis_unit_mm.unwrap_or(4),
            HeaderKind::Short8 => self.bytes[5],
            HeaderKind::PreHeader12 => self.bytes[9],
        }
    }

    /// Header `return_num` (pre-header formats).
    pub fn header_returns(&self) -> Option<u8> {
        (self.layout.header == HeaderKind::PreHeader12).then(|| self.bytes[10])
    }

    /// Header flags (pre-header formats): bit 0 UDP sequence, bit 1 IMU, bit 2 functional
    /// safety, bit 3 cyber-security signature.
    pub fn header_flags(&self) -> Option<u8> {
        (self.layout.header == HeaderKind::PreHeader12).then(|| self.bytes[11])
    }

    /// Whether a cyber-security signature follows the tail.
    pub fn has_signature(&self) -> bool {
        self.layout.signature && self.bytes.len() == self.layout.base_len() + SIGNATURE_LEN
    }

    fn block_start(&self, b: usize) -> usize {
        self.layout.body_start() + b * self.layout.block_len()
    }

    /// Block azimuth in 0.01° (AT128: in 1/25600°, the fine byte appended; ATX: the u16 in
    /// 1/256°, its fine byte unread, as the SDK leaves it).
    pub fn azimuth(&self, b: usize) -> u32 {
        let o = self.block_start(b)
            + if self.layout.header == HeaderKind::None {
                2
            } else {
                0
            };
        let az = u32::from(le_u16(self.bytes, o));
        if self.layout.fine_azimuth && !self.layout.counts_from_header {
            (az << 8) | u32::from(byte(self.bytes, o + 2))
        } else {
            az
        }
    }

    /// Unit of channel `c` in block `b`: (raw distance, reflectivity, confidence or 0).
    #[inline]
    pub fn unit(&self, b: usize, c: usize) -> (u16, u8, u8) {
        let o = self.block_start(b) + self.layout.block_prefix() + c * self.layout.unit_len;
        let conf = if self.layout.unit_len == 4 {
            byte(self.bytes, o + 3)
        } else {
            0
        };
        (le_u16(self.bytes, o), byte(self.bytes, o + 2), conf)
    }

    /// The units of block `b` (`unit_len` bytes each).
    #[inline]
    pub fn units(&self, b: usize) -> &'a [u8] {
        let o = self.block_start(b) + self.layout.block_prefix();
        let n = self.layout.channels * self.layout.unit_len;
        self.bytes.get(o..o + n).unwrap_or(&[])
    }

    fn tail(&self, o: usize) -> usize {
        self.layout.tail_start() + o
    }

    /// Return mode byte.
    pub fn return_mode(&self) -> u8 {
        byte(self.bytes, self.tail(self.layout.tail.return_mode))
    }

    /// Motor speed, rpm.
    pub fn motor_rpm(&self) -> u16 {
        le_u16(self.bytes, self.tail(self.layout.tail.motor_rpm))
    }

    /// µs field of the tail.
    pub fn timestamp_us(&self) -> u32 {
        le_u32(self.bytes, self.tail(self.layout.tail.timestamp_us))
    }

    /// The six date bytes of the tail.
    pub fn date_bytes(&self) -> [u8; 6] {
        let o = self.tail(self.layout.tail.date);
        core::array::from_fn(|i| byte(self.bytes, o + i))
    }

    /// The tail's whole seconds since the Unix epoch (UTC), or `None` for an impossible date.
    pub fn unix_seconds(&self) -> Option<i64> {
        let d = self.date_bytes();
        match self.layout.tail.date_form {
            DateForm::UnixSeconds => Some(
                d[1..]
                    .iter()
                    .fold(0i64, |acc, &b| (acc << 8) | i64::from(b)),
            ),
            DateForm::YmdhmsOrUnix32 if d[0] == 0 => {
                Some(i64::from(u32::from_be_bytes([d[2], d[3], d[4], d[5]])))
            }
            DateForm::Ymdhms | DateForm::YmdhmsOrUnix32 => {
                let year = super::model::year_from_byte(d[0]);
                let (mo, day, h, mi, s) = (d[1], d[2], d[3], d[4], d[5]);
                if !(1..=12).contains(&mo)
                    || !(1..=31).contains(&day)
                    || h > 23
                    || mi > 59
                    || s > 60
                {
                    return None;
                }
                Some(
                    days_from_civil(year, u32::from(mo), u32::from(day)) * 86_400
                        + i64::from(h) * 3600
                        + i64::from(mi) * 60
                        + i64::from(s),
                )
            }
        }
    }

    /// The packet's time stamp (tail date + µs), ns since the Unix epoch, or `None` for an
    /// impossible date or a µs field of a second or more (the field is the fraction of the
    /// date's second in every layout; a corrupt one would move the packet by up to 71 min).
    pub fn stamp_ns(&self) -> Option<i64> {
        let s = self.unix_seconds()?;
        if self.timestamp_us() >= 1_000_000 {
            return None;
        }
        Some(
            s.saturating_mul(1_000_000_000)
                .saturating_add(i64::from(self.timestamp_us()) * 1_000),
        )
    }

    /// Factory information byte.
    pub fn factory(&self) -> u8 {
        byte(self.bytes, self.tail(self.layout.tail.factory))
    }

    /// UDP sequence number, where the packet carries one.
    pub fn udp_seq(&self) -> Option<u32> {
        if let Some(o) = self.layout.tail.udp_seq {
            return Some(le_u32(self.bytes, self.tail(o)));
        }
        (self.layout.trailing_udp_seq && self.bytes.len() == self.layout.base_len() + 4)
            .then(|| le_u32(self.bytes, self.layout.base_len()))
    }

    /// The UDP sequence number where the tail CRC covers it and passes: a packet whose body
    /// failed its CRC still tells which packet it was.
    pub fn checked_udp_seq(&self) -> Option<u32> {
        let l = &self.layout;
        let (o, c) = (l.tail.udp_seq?, l.tail.crc?);
        if !l.crc_known || o + 4 > c {
            return None;
        }
        let start = l.tail_start();
        let stored = le_u32(self.bytes, start + c);
        (stored == crc32_mpeg2(&self.bytes[start..start + c]))
            .then(|| le_u32(self.bytes, start + o))
    }

    /// Frame id, where the tail has one (ATX: bit 0 toggles at each frame).
    pub fn frame_id(&self) -> Option<u8> {
        self.layout
            .tail
            .frame_id
            .map(|o| byte(self.bytes, self.tail(o)))
    }

    /// The tail bytes the firing tables depend on.
    pub fn tail_flags(&self) -> TailFlags {
        let t = &self.layout.tail;
        TailFlags {
            mode_flag: t.mode_flag.map_or(0, |o| byte(self.bytes, self.tail(o))),
            azimuth_state: t
                .azimuth_state
                .map_or(0, |o| le_u16(self.bytes, self.tail(o))),
            operational_state: t
                .operational_state
                .map_or(0, |o| byte(self.bytes, self.tail(o))),
        }
    }

    /// High-temperature shutdown flag, where the tail has it.
    pub fn shutdown_flag(&self) -> Option<u8> {
        self.layout
            .tail
            .shutdown_flag
            .map(|o| byte(self.bytes, self.tail(o)))
    }

    /// The functional-safety block, where the packet has one.
    pub fn functional_safety(&self) -> Option<FunctionalSafety> {
        if self.layout.safety_len == 0 {
            return None;
        }
        let o = self.layout.safety_start();
        let (b1, b2) = (byte(self.bytes, o + 1), byte(self.bytes, o + 2));
        Some(FunctionalSafety {
            version: byte(self.bytes, o),
            lidar_state: b1 >> 5,
            fault_code_type: (b1 >> 3) & 0b11,
            rolling_counter: b1 & 0b111,
            total_fault_codes: b2 >> 4,
            fault_code_id: b2 & 0x0F,
            fault_code: le_u16(self.bytes, o + 3),
        })
    }

    /// Checks the functional-safety block's own CRC-32/MPEG-2 (its last four bytes,
    /// little-endian), where the packet has the block. The QT128 manual (3.2): over "the
    /// Lidar State field to the Reserved field", the 12 bytes between the version and the
    /// CRC; every one of the 1,800 packets of the shared QT128 capture (six distinct blocks)
    /// checks so, and none over the 13 bytes with the version. The Pandar128E3X manual (the
    /// OT128's 1.4 protocol) says "from the Lidar State field to the Fault Code field" (4
    /// bytes) for the same 17-byte block; with no real OT128 capture to tell a misprint from a
    /// difference, an OT128 block checks under either range (a corrupt block passes one of
    /// two 32-bit CRCs about once in 2^31).
    pub fn check_safety_crc(&self) -> Result<(), WireError> {
        let l = &self.layout;
        if l.safety_len < 5 {
            return Ok(());
        }
        let o = l.safety_start();
        let c = o + l.safety_len - 4;
        let stored = le_u32(self.bytes, c);
        let over = |end: usize| self.bytes.get(o + 1..end).map_or(!stored, crc32_mpeg2);
        let computed = over(c);
        if stored == computed || (self.model == HesaiModel::PandarOt128 && stored == over(o + 5)) {
            return Ok(());
        }
        Err(WireError::Crc {
            what: "Hesai functional safety",
            stored: u64::from(stored),
            computed: u64::from(computed),
        })
    }

    /// Whether the packet carries CRCs of a known algorithm.
    pub fn has_crc(&self) -> bool {
        self.layout.crc_known && (self.layout.body_crc || self.layout.tail.crc.is_some())
    }

    /// Checks the body and tail CRC-32/MPEG-2 where the packet has them (not the ATX's, whose
    /// algorithm is not published).
    pub fn check_crc(&self) -> Result<(), (CrcPart, WireError)> {
        let l = &self.layout;
        if !l.crc_known {
            return Ok(());
        }
        if l.body_crc {
            let stored = le_u32(self.bytes, l.body_end());
            let computed = crc32_mpeg2(&self.bytes[l.body_start()..l.body_end()]);
            if stored != computed {
                return Err((
                    CrcPart::Body,
                    WireError::Crc {
                        what: "Hesai body",
                        stored: u64::from(stored),
                        computed: u64::from(computed),
                    },
                ));
            }
        }
        if let Some(c) = l.tail.crc {
            let start = l.tail_start();
            let stored = le_u32(self.bytes, start + c);
            let computed = crc32_mpeg2(&self.bytes[start..start + c]);
            if stored != computed {
                return Err((
                    CrcPart::Tail,
                    WireError::Crc {
                        what: "Hesai tail",
                        stored: u64::from(stored),
                        computed: u64::from(computed),
                    },
                ));
            }
        }
        Ok(())
    }
}

/// Days from 1970-01-01 to the given civil date (proleptic Gregorian; Howard Hinnant's
/// `days_from_civil`).
pub fn days_from_civil(y: i32, m: u32, d: u32) -> i64 {
    let y = i64::from(y) - i64::from(m <= 2);
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let m = i64::from(m);
    let doy = (153 * (if m > 2 { m - 3 } else { m + 9 }) + 2) / 5 + i64::from(d) - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_mpeg2_check_value() {
        assert_eq!(crc32_mpeg2(b"123456789"), 0x0376_E6E7);
    }

    #[test]
    fn civil_days() {
        assert_eq!(days_from_civil(1970, 1, 1), 0);
        assert_eq!(days_from_civil(2000, 3, 1), 11_017);
        assert_eq!(days_from_civil(2020, 10, 9), 18_544);
    }

    #[test]
    fn short_and_wrong_packets_are_refused() {
        for m in super::super::model::ALL_MODELS {
            let len = m.spec().layout.base_len();
            assert!(HesaiPacket::new(&vec![0u8; len - 1], m).is_err());
            assert!(HesaiPacket::new(&[], m).is_err());
            // Right size, zero bytes: no marks.
            assert!(HesaiPacket::new(&vec![0u8; len], m).is_err());
        }
    }
}
