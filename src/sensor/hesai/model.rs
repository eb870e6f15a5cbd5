//! Hesai model facts as data: packet layouts, channel counts, range limits, firing times.
//!
//! Every Hesai point-cloud packet is one of three shapes (Hesai user manuals, "Point cloud data
//! packet"; the same layouts as tier4/nebula's `hesai_packet.hpp` and `pandar_*.hpp`):
//!
//! - **no header** (Pandar40P): 10 blocks of `FF EE`, a u16 azimuth and 40 units of 3 bytes,
//!   then a 22-byte tail;
//! - **8-byte header** (Pandar64): `EE FF`, lasers, blocks, reserved, distance unit (mm), 2
//!   reserved; blocks of a u16 azimuth and 3-byte units; the Pandar40P tail;
//! - **pre-header + header, 12 bytes** (QT64 / QT128 protocol 3.x, AT128 4.x, OT128 1.4,
//!   XT16 / XT32 / XT32M 6.x): `EE FF`, protocol major, minor, 2 reserved, then lasers, blocks,
//!   reserved, distance unit (mm), return count, flags; blocks of a u16 azimuth (AT128: + a
//!   fine azimuth byte, 1/256 of 0.01°) and 3- or 4-byte units (distance u16, reflectivity,
//!   confidence); a body CRC-32/MPEG-2 on QT128 / AT128 / OT128; a 17-byte functional-safety
//!   block on QT128 / OT128; a tail (return mode, motor speed, date, µs, UDP sequence, tail
//!   CRC); an optional 32-byte cyber-security signature.
//!
//! The Pandar ATX (protocol 4.7; HesaiLidar_SDK_2.0's `udp_protocol_v4_7.h`, the only public
//! description) takes its laser and block counts from the header instead of a fixed layout:
//! blocks of a u16 azimuth (1/256°), a fine byte and 4-byte units; a body CRC; a 32-byte tail
//! (frame id at 10: bit 0 toggles each frame); the UDP sequence when flag bit 0 is set; a
//! 12-byte E2E header (always); the signature when flag bit 3 is set. Its CRCs' algorithms are
//! not published: they are skipped, not checked. [`Layout::for_header`] builds a packet's
//! layout; the spec holds the simulator's configuration (2 blocks of 100 channels, the
//! channel count of the SDK's sample correction).
//!
//! All multi-byte fields are little-endian, except the AT128's Unix seconds (big-endian).
//!
//! Firing times are each model's table of the manual's "laser firing time" appendix, relative to
//! the packet's tail time stamp as nebula applies them (`get_packet_relative_point_time_offset`).

/// The models ringscan decodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum HesaiModel {
    /// Pandar40P (40 channels, no header).
    Pandar40P,
    /// Pandar64 (64 channels, 8-byte header).
    Pandar64,
    /// PandarQT64 (protocol 3.1).
    PandarQt64,
    /// PandarQT128C2X (protocol 3.2).
    PandarQt128,
    /// PandarXT16 (protocol 6.1).
    PandarXt16,
    /// PandarXT32 (protocol 6.1).
    PandarXt32,
    /// PandarXT32M2X (protocol 6.1).
    PandarXt32m,
    /// PandarAT128E2X (protocol 4.x), mirror frames and a binary angle correction.
    PandarAt128,
    /// OT128 / Pandar128E3X / Pandar128E4X (protocol 1.4).
    PandarOt128,
    /// Pandar ATX (protocol 4.7): laser and block counts from the header, a binary angle
    /// correction with per-frame (even / odd) azimuths.
    PandarAtx,
}

/// Every model, in `--model` order.
pub const ALL_MODELS: [HesaiModel; 10] = [
    HesaiModel::Pandar40P,
    HesaiModel::Pandar64,
    HesaiModel::PandarQt64,
    HesaiModel::PandarQt128,
    HesaiModel::PandarXt16,
    HesaiModel::PandarXt32,
    HesaiModel::PandarXt32m,
    HesaiModel::PandarAt128,
    HesaiModel::PandarOt128,
    HesaiModel::PandarAtx,
];

/// Which header a packet starts with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HeaderKind {
    /// None: blocks start at byte 0 with `FF EE` (Pandar40P).
    None,
    /// `EE FF` + lasers, blocks, reserved, dis_unit, 2 reserved (Pandar64).
    Short8,
    /// The 6-byte pre-header (`EE FF`, protocol major, minor, 2 reserved) + 6-byte header.
    PreHeader12,
}

/// How the tail writes its date.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DateForm {
    /// Year (see [`year_from_byte`]), month, day, hour, minute, second: one byte each.
    Ymdhms,
    /// One zero byte, then the Unix seconds as a 40-bit big-endian number (AT128).
    UnixSeconds,
    /// [`DateForm::Ymdhms`] when the first byte is not 0, else the Unix seconds as a 32-bit
    /// big-endian number in bytes 2–5 (ATX; the SDK's `GetMicroLidarTimeU64`).
    YmdhmsOrUnix32,
}

/// Offsets of the tail's fields, from the tail's first byte.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TailLayout {
    /// Tail bytes up to its last fixed field (its CRC where it has one).
    pub len: usize,
    /// Return mode byte (0x33…0x3e).
    pub return_mode: usize,
    /// Motor speed, u16 rpm.
    pub motor_rpm: usize,
    /// The date (6 bytes).
    pub date: usize,
    /// Form of the date.
    pub date_form: DateForm,
    /// µs within the second, u32.
    pub timestamp_us: usize,
    /// Factory information byte.
    pub factory: usize,
    /// UDP sequence number, u32 (packet loss), where the tail holds it.
    pub udp_seq: Option<usize>,
    /// CRC-32/MPEG-2 over the tail's bytes before it.
    pub crc: Option<usize>,
    /// QT128's mode flag (bit 0 picks the firing loop in multi-return modes).
    pub mode_flag: Option<usize>,
    /// OT128's azimuth state (u16, 2 bits per block) and operational state.
    pub azimuth_state: Option<usize>,
    /// OT128's operational state byte.
    pub operational_state: Option<usize>,
    /// High-temperature shutdown flag.
    pub shutdown_flag: Option<usize>,
    /// Frame id (ATX: bit 0 toggles at each frame of the mirror).
    pub frame_id: Option<usize>,
}

/// Byte layout of one model's packets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    /// The header.
    pub header: HeaderKind,
    /// Blocks per packet.
    pub blocks: usize,
    /// Channels (units) per block.
    pub channels: usize,
    /// Bytes per unit: 3 (distance, reflectivity) or 4 (+ confidence / reserved).
    pub unit_len: usize,
    /// Whether the block has a fine azimuth byte after its azimuth (AT128: 1/25600°).
    pub fine_azimuth: bool,
    /// Whether a CRC-32/MPEG-2 of the blocks follows them.
    pub body_crc: bool,
    /// Whether the CRCs (body and tail) follow a known algorithm: false for the ATX, whose
    /// 4-byte body CRC and E2E CRC are not documented anywhere public (skipped, not checked).
    pub crc_known: bool,
    /// The header's laser and block counts define the layout (ATX): see
    /// [`Layout::for_header`]; `blocks` and `channels` here are the simulator's.
    pub counts_from_header: bool,
    /// Bytes of the functional-safety block between body and tail (0 when absent).
    pub safety_len: usize,
    /// The tail.
    pub tail: TailLayout,
    /// A 4-byte UDP sequence number may follow the tail (Pandar40P, Pandar64).
    pub trailing_udp_seq: bool,
    /// A 32-byte cyber-security signature may follow the tail.
    pub signature: bool,
}

/// Length of the cyber-security signature.
pub const SIGNATURE_LEN: usize = 32;

impl Layout {
    /// Header bytes.
    pub const fn header_len(&self) -> usize {
        match self.header {
            HeaderKind::None => 0,
            HeaderKind::Short8 => 8,
            HeaderKind::PreHeader12 => 12,
        }
    }

    /// Bytes before the units in a block: `FF EE` + azimuth, azimuth, or azimuth + fine.
    pub const fn block_prefix(&self) -> usize {
        match (self.header, self.fine_azimuth) {
            (HeaderKind::None, _) => 4,
            (_, true) => 3,
            _ => 2,
        }
    }

    /// Bytes per block.
    pub const fn block_len(&self) -> usize {
        self.block_prefix() + self.channels * self.unit_len
    }

    /// Offset of the first block.
    pub const fn body_start(&self) -> usize {
        self.header_len()
    }

    /// Offset just after the last block.
    pub const fn body_end(&self) -> usize {
        self.body_start() + self.blocks * self.block_len()
    }

    /// Offset of the functional-safety block.
    pub const fn safety_start(&self) -> usize {
        self.body_end() + if self.body_crc { 4 } else { 0 }
    }

    /// Offset of the tail.
    pub const fn tail_start(&self) -> usize {
        self.safety_start() + self.safety_len
    }

    /// Packet length without the optional trailers.
    pub const fn base_len(&self) -> usize {
        self.tail_start() + self.tail.len
    }

    /// The layout of a packet of this kind whose header gives `lasers`, `blocks` and `flags`
    /// (ATX; every other layout is returned as it is). Flag bit 0 adds the 4-byte UDP sequence
    /// after the tail, bit 3 the signature; the 12-byte E2E header always follows.
    pub fn for_header(&self, lasers: u8, blocks: u8, flags: u8) -> Layout {
        if !self.counts_from_header {
            return *self;
        }
        let seq = flags & 1 != 0;
        Layout {
            channels: usize::from(lasers),
            blocks: usize::from(blocks),
            tail: TailLayout {
                len: ATX_TAIL_LEN + if seq { 4 } else { 0 } + ATX_E2E_LEN,
                udp_seq: seq.then_some(ATX_TAIL_LEN),
                ..self.tail
            },
            signature: flags & 0b1000 != 0,
            ..*self
        }
    }

    /// The exact length of a packet of this layout (ATX, from [`Self::for_header`]).
    pub fn exact_len(&self) -> usize {
        self.base_len() + if self.signature { SIGNATURE_LEN } else { 0 }
    }

    /// Whether `len` is a length this layout's packets have (with or without the optional
    /// UDP sequence / signature).
    pub fn accepts_len(&self, len: usize) -> bool {
        let base = self.base_len();
        len == base
            || (self.trailing_udp_seq && len == base + 4)
            || (self.signature && len == base + SIGNATURE_LEN)
    }
}

const TAIL_40P: TailLayout = TailLayout {
    len: 22,
    return_mode: 14,
    motor_rpm: 8,
    date: 16,
    date_form: DateForm::Ymdhms,
    timestamp_us: 10,
    factory: 15,
    udp_seq: None,
    crc: None,
    mode_flag: None,
    azimuth_state: None,
    operational_state: None,
    shutdown_flag: Some(5),
    frame_id: None,
};

const TAIL_QT64: TailLayout = TailLayout {
    len: 28,
    return_mode: 16,
    motor_rpm: 10,
    date: 18,
    date_form: DateForm::Ymdhms,
    timestamp_us: 12,
    factory: 17,
    udp_seq: Some(24),
    crc: None,
    mode_flag: None,
    azimuth_state: None,
    operational_state: None,
    shutdown_flag: None,
    frame_id: None,
};

const TAIL_QT128: TailLayout = TailLayout {
    len: 34,
    return_mode: 12,
    motor_rpm: 13,
    date: 15,
    date_form: DateForm::Ymdhms,
    timestamp_us: 21,
    factory: 25,
    udp_seq: Some(26),
    crc: Some(30),
    mode_flag: Some(5),
    azimuth_state: None,
    operational_state: None,
    shutdown_flag: None,
    frame_id: None,
};

const TAIL_XT: TailLayout = TailLayout {
    len: 28,
    return_mode: 10,
    motor_rpm: 11,
    date: 13,
    date_form: DateForm::Ymdhms,
    timestamp_us: 19,
    factory: 23,
    udp_seq: Some(24),
    crc: None,
    mode_flag: None,
    azimuth_state: None,
    operational_state: None,
    shutdown_flag: None,
    frame_id: None,
};

const TAIL_AT128: TailLayout = TailLayout {
    len: 40,
    return_mode: 24,
    motor_rpm: 18,
    date: 26,
    date_form: DateForm::UnixSeconds,
    timestamp_us: 20,
    factory: 25,
    udp_seq: Some(32),
    crc: Some(36),
    mode_flag: None,
    azimuth_state: None,
    operational_state: None,
    shutdown_flag: Some(6),
    frame_id: None,
};

const TAIL_OT128: TailLayout = TailLayout {
    len: 56,
    return_mode: 12,
    motor_rpm: 13,
    date: 15,
    date_form: DateForm::Ymdhms,
    timestamp_us: 21,
    factory: 25,
    udp_seq: Some(26),
    crc: Some(52),
    mode_flag: None,
    azimuth_state: Some(9),
    operational_state: Some(11),
    shutdown_flag: None,
    frame_id: None,
};

/// The ATX tail: the AT128's first 32 bytes (motor speed at 18, µs at 20, return mode at 24,
/// factory at 25, date at 26), with the frame id at 10; the UDP sequence (flag bit 0) and the
/// 12-byte E2E header follow it ([`Layout::for_header`]).
const TAIL_ATX: TailLayout = TailLayout {
    len: ATX_TAIL_LEN + ATX_E2E_LEN,
    return_mode: 24,
    motor_rpm: 18,
    date: 26,
    date_form: DateForm::YmdhmsOrUnix32,
    timestamp_us: 20,
    factory: 25,
    udp_seq: None,
    crc: None,
    mode_flag: None,
    azimuth_state: None,
    operational_state: None,
    shutdown_flag: None,
    frame_id: Some(10),
};

/// Bytes of the ATX tail proper.
pub const ATX_TAIL_LEN: usize = 32;
/// Bytes of the ATX E2E header (length, counter, data id, CRC; big-endian).
pub const ATX_E2E_LEN: usize = 12;

/// Bytes of the QT128 / OT128 functional-safety block.
pub const SAFETY_LEN: usize = 17;

const fn layout(
    header: HeaderKind,
    blocks: usize,
    channels: usize,
    unit_len: usize,
    tail: TailLayout,
) -> Layout {
    Layout {
        header,
        blocks,
        channels,
        unit_len,
        fine_azimuth: false,
        body_crc: false,
        crc_known: true,
        counts_from_header: false,
        safety_len: 0,
        tail,
        trailing_udp_seq: false,
        signature: false,
    }
}

/// Everything that differs between Hesai models.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelSpec {
    /// `--model` name.
    pub id: &'static str,
    /// Name as Hesai writes it.
    pub name: &'static str,
    /// Protocol major version in the pre-header (None: no pre-header).
    pub protocol_major: Option<u8>,
    /// Packet layout.
    pub layout: Layout,
    /// The sensor's own measuring range, metres (nebula's `SensorT::min_range / max_range`).
    pub min_range_m: f32,
    /// See `min_range_m`.
    pub max_range_m: f32,
    /// Distance unit when the packet has no header field for it, mm.
    pub fixed_dis_unit_mm: Option<u8>,
    /// Nominal packet rate at 600 rpm in single return, for loss counting by time.
    pub block_period_ns: u32,
    /// Default sweep cut angle, 0.01° (AT128: the end of its 30–150° field of view).
    pub default_cut_cdeg: u32,
    /// Field of view in azimuth the sensor sees, 0.01° (start, end); equal = a full turn.
    pub fov_cdeg: (u32, u32),
}

impl HesaiModel {
    /// The model's facts.
    pub const fn spec(self) -> &'static ModelSpec {
        match self {
            Self::Pandar40P => &SPEC_40P,
            Self::Pandar64 => &SPEC_64,
            Self::PandarQt64 => &SPEC_QT64,
            Self::PandarQt128 => &SPEC_QT128,
            Self::PandarXt16 => &SPEC_XT16,
            Self::PandarXt32 => &SPEC_XT32,
            Self::PandarXt32m => &SPEC_XT32M,
            Self::PandarAt128 => &SPEC_AT128,
            Self::PandarOt128 => &SPEC_OT128,
            Self::PandarAtx => &SPEC_ATX,
        }
    }

    /// `--model` name (`pandarxt32`).
    pub fn id(self) -> &'static str {
        self.spec().id
    }

    /// Hesai's name (`PandarXT32`).
    pub fn name(self) -> &'static str {
        self.spec().name
    }

    /// Channels.
    pub fn channels(self) -> usize {
        self.spec().layout.channels
    }

    /// The model called `id` (`--model`), case-insensitive; a few aliases.
    pub fn from_id(id: &str) -> Option<Self> {
        let id = id.to_ascii_lowercase();
        let id = match id.as_str() {
            "pandar128e3x" | "pandar128e4x" | "ot128" => "pandarot128",
            "at128" => "pandarat128",
            "atx" => "pandaratx",
            "qt64" => "pandarqt64",
            "qt128" => "pandarqt128",
            "xt16" => "pandarxt16",
            "xt32" => "pandarxt32",
            "xt32m" => "pandarxt32m",
            other => other,
        };
        ALL_MODELS.into_iter().find(|m| m.id() == id)
    }

    /// The model whose packets these bytes look like: the pre-header's protocol version and the
    /// header's laser and block counts, or (no pre-header) the Pandar64 header / the Pandar40P
    /// `FF EE` blocks; and in every case a length the layout allows.
    pub fn detect(payload: &[u8]) -> Option<Self> {
        let len = payload.len();
        match payload {
            [0xFF, 0xEE, ..] => {
                let l = &SPEC_40P.layout;
                let blocks_ok = (0..l.blocks).all(|b| {
                    let o = b * l.block_len();
                    payload.get(o..o + 2) == Some(&[0xFF, 0xEE][..])
                });
                (l.accepts_len(len) && blocks_ok).then_some(Self::Pandar40P)
            }
            [0xEE, 0xFF, 4, 7, ..] => Self::PandarAtx.accepts(payload).then_some(Self::PandarAtx),
            [0xEE, 0xFF, major, _minor, _, _, lasers, blocks, ..] => {
                let found = ALL_MODELS.into_iter().find(|m| {
                    let s = m.spec();
                    !s.layout.counts_from_header
                        && s.protocol_major == Some(*major)
                        && usize::from(*lasers) == s.layout.channels
                        && usize::from(*blocks) == s.layout.blocks
                        && s.layout.accepts_len(len)
                });
                found.or_else(|| {
                    let l = &SPEC_64.layout;
                    (usize::from(*major) == l.channels
                        && usize::from(*_minor) == l.blocks
                        && l.accepts_len(len))
                    .then_some(Self::Pandar64)
                })
            }
            _ => None,
        }
    }

    /// Whether `payload` has a length this model's packets have: the layout's, or for the ATX
    /// the one its header's counts and flags give (at least one laser and one block).
    pub fn accepts(self, payload: &[u8]) -> bool {
        let l = &self.spec().layout;
        if !l.counts_from_header {
            return l.accepts_len(payload.len());
        }
        match payload {
            [0xEE, 0xFF, _, _, _, _, lasers, blocks, _, _, _, flags, ..] => {
                *lasers > 0
                    && *blocks > 0
                    && l.for_header(*lasers, *blocks, *flags).exact_len() == payload.len()
            }
            _ => false,
        }
    }

    /// `tail` reduced to what [`Self::firing_offset_ns`] reads for `n_returns` returns: two
    /// packets with equal reduced flags have equal firing tables (the decoder keys its cached
    /// tables on it; the QT128's mode byte, for one, changes from packet to packet).
    pub fn firing_flags(self, n_returns: usize, tail: TailFlags) -> TailFlags {
        match self {
            Self::PandarQt128 if n_returns > 1 => TailFlags {
                mode_flag: tail.mode_flag & 1,
                ..TailFlags::default()
            },
            Self::PandarOt128 if tail.operational_state != 0 => TailFlags {
                operational_state: 1,
                ..TailFlags::default()
            },
            Self::PandarOt128 => {
                // Per block, only whether its 2-bit state is 0.
                let mut states = 0u16;
                for pair in 0..8 {
                    if (tail.azimuth_state >> (14 - 2 * pair)) & 0b11 != 0 {
                        states |= 1 << (14 - 2 * pair);
                    }
                }
                TailFlags {
                    azimuth_state: states,
                    ..TailFlags::default()
                }
            }
            _ => TailFlags::default(),
        }
    }

    /// Firing time of (block, channel) relative to the packet's tail time stamp, ns (negative:
    /// before it). `n_returns` = blocks per return group (1, 2 or 3); `mode_flag`, `az_state`,
    /// `op_state` are the tail bytes the QT128 / OT128 tables depend on.
    pub fn firing_offset_ns(
        self,
        block: usize,
        channel: usize,
        n_returns: usize,
        tail: TailFlags,
    ) -> i64 {
        let n = n_returns.max(1) as i64;
        let (b, c) = (block as i64, channel);
        match self {
            Self::Pandar40P => {
                -28_580 - 55_560 * ((10 - b - 1) / n) + i64::from(table(&FIRING_40P, c))
            }
            Self::Pandar64 => {
                -42_580 - 55_560 * ((6 - b - 1) / n) + i64::from(table(&FIRING_64, c))
            }
            Self::PandarQt64 => {
                25_710 + (500_000 * (b / n)) / 3 + i64::from(table(&FIRING_QT64, c))
            }
            Self::PandarQt128 => {
                let block_ns = 9_000 + 111_110 * (2 - b - 1) / n;
                let loop1 = if n == 1 {
                    b % 2 == 0
                } else {
                    tail.mode_flag & 1 == 1
                };
                let t = if loop1 {
                    &FIRING_QT128_LOOP1
                } else {
                    &FIRING_QT128_LOOP2
                };
                block_ns + i64::from(table(t, c))
            }
            Self::PandarXt16 | Self::PandarXt32 => {
                let step = if matches!(self, Self::PandarXt16) {
                    3_024
                } else {
                    1_512
                };
                5_632 - 50_000 * ((8 - b - 1) / n) + 368 + step * c as i64
            }
            Self::PandarXt32m => {
                let block_ns = if n < 3 {
                    5_632 - 50_000 * ((8 - b - 1) / n)
                } else {
                    5_632 - 50_000 * ((6 - b - 1) / 3)
                };
                block_ns + 368 + 2_888 * (c % 16) as i64
            }
            Self::PandarAt128 => {
                let block_ns = if n == 1 {
                    -9_249 - 41_666 * (2 - b)
                } else {
                    -9_249 - 41_666
                };
                block_ns + i64::from(table(&FIRING_AT128, c))
            }
            Self::PandarOt128 => {
                let block_ns = if n == 1 { -27_778 * 2 * (2 - b - 1) } else { 0 };
                let hires = tail.operational_state == 0;
                let ch = if !hires {
                    table(&FIRING_OT128_STANDARD, c)
                } else {
                    let state = (tail.azimuth_state >> (14 - 2 * block.min(7))) & 0b11;
                    let t = if state == 0 {
                        &FIRING_OT128_AS0
                    } else {
                        &FIRING_OT128_AS1
                    };
                    table(t, c).max(0)
                };
                block_ns + 43_346 + i64::from(ch)
            }
            // No firing-time table is published: every point takes the packet's time (the
            // SDK's per-point time too).
            Self::PandarAtx => 0,
        }
    }
}

/// The tail bytes some firing tables depend on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TailFlags {
    /// QT128 mode flag.
    pub mode_flag: u8,
    /// OT128 azimuth state (2 bits per block, block 0 in bits 15–14).
    pub azimuth_state: u16,
    /// OT128 operational state (0 = high resolution).
    pub operational_state: u8,
}

fn table<const N: usize>(t: &[i32; N], c: usize) -> i32 {
    t.get(c).copied().unwrap_or(0)
}

/// Number of blocks per return group for a tail return-mode byte (Hesai manuals, "Return
/// mode"): 0x33–0x38 single, 0x39–0x3c and 0x3e dual, 0x3d triple.
pub fn returns_of_mode(mode: u8) -> Option<usize> {
    match mode {
        0x33 | 0x34 | 0x37 | 0x38 => Some(1),
        0x39..=0x3c | 0x3e => Some(2),
        0x3d => Some(3),
        _ => None,
    }
}

/// Name of a return-mode byte.
pub fn mode_name(mode: u8) -> &'static str {
    match mode {
        0x33 => "first",
        0x34 => "second",
        0x37 => "strongest",
        0x38 => "last",
        0x39 => "dual (last, strongest)",
        0x3a => "dual (first, second)",
        0x3b => "dual (first, last)",
        0x3c => "dual (first, strongest)",
        0x3d => "triple (first, last, strongest)",
        0x3e => "dual (strongest, second strongest)",
        _ => "unknown",
    }
}

/// ringscan's `return` for block `k` of a return group in mode `mode` (DESIGN.md: 0 = strongest /
/// only / first, 1 = last / second; 2 = the third return of a triple group):
///
/// | mode | block 0 | block 1 | block 2 |
/// |---|---|---|---|
/// | single (any) | 0 | – | – |
/// | 0x39 last, strongest | 1 (last) | 0 (strongest) | – |
/// | 0x3a first, second | 0 | 1 | – |
/// | 0x3b first, last (XT32 / OT128 send last first) | 0 (1) | 1 (0) | – |
/// | 0x3c first, strongest | 1 (first) | 0 (strongest) | – |
/// | 0x3d first, last, strongest | 2 (first) | 1 (last) | 0 (strongest) |
/// | 0x3e strongest, second strongest | 0 | 1 | – |
pub fn return_index(model: HesaiModel, mode: u8, k: usize) -> u8 {
    let swapped_first_last = matches!(
        model,
        HesaiModel::PandarXt32 | HesaiModel::PandarXt16 | HesaiModel::PandarOt128
    );
    match (mode, k) {
        (0x39, 0) | (0x3c, 0) => 1,
        (0x39, _) | (0x3c, _) => 0,
        (0x3b, 0) => u8::from(swapped_first_last),
        (0x3b, _) => u8::from(!swapped_first_last),
        (0x3d, 0) => 2,
        (0x3d, 1) => 1,
        (0x3d, _) => 0,
        (_, 0) => 0,
        _ => 1,
    }
}

/// Year of a tail year byte. Hesai firmwares count it from 1900 (Pandar64 sends 120 for 2020,
/// QT / XT / OT: 117–124) or from 2000 (Pandar40P sends 17 for 2017); no sensor was made before
/// 1970, so bytes ≥ 70 count from 1900 and smaller ones from 2000. (nebula adds 2000 for the
/// Pandar40P / 64 tails and 1900 for the others, which reads the shared Pandar64's 120 as 2120.)
pub fn year_from_byte(b: u8) -> i32 {
    if b >= 70 {
        1900 + i32::from(b)
    } else {
        2000 + i32::from(b)
    }
}

const SPEC_40P: ModelSpec = ModelSpec {
    id: "pandar40p",
    name: "Pandar40P",
    protocol_major: None,
    layout: Layout {
        trailing_udp_seq: true,
        ..layout(HeaderKind::None, 10, 40, 3, TAIL_40P)
    },
    min_range_m: 0.3,
    max_range_m: 200.0,
    fixed_dis_unit_mm: Some(4),
    block_period_ns: 55_560,
    default_cut_cdeg: 0,
    fov_cdeg: (0, 0),
};

const SPEC_64: ModelSpec = ModelSpec {
    id: "pandar64",
    name: "Pandar64",
    protocol_major: None,
    layout: Layout {
        trailing_udp_seq: true,
        ..layout(HeaderKind::Short8, 6, 64, 3, TAIL_40P)
    },
    min_range_m: 0.3,
    max_range_m: 200.0,
    fixed_dis_unit_mm: None,
    block_period_ns: 55_560,
    default_cut_cdeg: 0,
    fov_cdeg: (0, 0),
};

const SPEC_QT64: ModelSpec = ModelSpec {
    id: "pandarqt64",
    name: "PandarQT64",
    protocol_major: Some(3),
    layout: layout(HeaderKind::PreHeader12, 4, 64, 4, TAIL_QT64),
    min_range_m: 0.1,
    max_range_m: 60.0,
    fixed_dis_unit_mm: None,
    block_period_ns: 166_667,
    default_cut_cdeg: 0,
    fov_cdeg: (0, 0),
};

const SPEC_QT128: ModelSpec = ModelSpec {
    id: "pandarqt128",
    name: "PandarQT128",
    protocol_major: Some(3),
    layout: Layout {
        body_crc: true,
        safety_len: SAFETY_LEN,
        signature: true,
        ..layout(HeaderKind::PreHeader12, 2, 128, 4, TAIL_QT128)
    },
    min_range_m: 0.05,
    max_range_m: 50.0,
    fixed_dis_unit_mm: None,
    block_period_ns: 111_110,
    default_cut_cdeg: 0,
    fov_cdeg: (0, 0),
};

const SPEC_XT16: ModelSpec = ModelSpec {
    id: "pandarxt16",
    name: "PandarXT16",
    protocol_major: Some(6),
    layout: layout(HeaderKind::PreHeader12, 8, 16, 4, TAIL_XT),
    min_range_m: 0.05,
    max_range_m: 120.0,
    fixed_dis_unit_mm: None,
    block_period_ns: 50_000,
    default_cut_cdeg: 0,
    fov_cdeg: (0, 0),
};

const SPEC_XT32: ModelSpec = ModelSpec {
    id: "pandarxt32",
    name: "PandarXT32",
    protocol_major: Some(6),
    layout: layout(HeaderKind::PreHeader12, 8, 32, 4, TAIL_XT),
    min_range_m: 0.05,
    max_range_m: 120.0,
    fixed_dis_unit_mm: None,
    block_period_ns: 50_000,
    default_cut_cdeg: 0,
    fov_cdeg: (0, 0),
};

const SPEC_XT32M: ModelSpec = ModelSpec {
    id: "pandarxt32m",
    name: "PandarXT32M",
    protocol_major: Some(6),
    layout: layout(HeaderKind::PreHeader12, 6, 32, 4, TAIL_XT),
    min_range_m: 0.5,
    max_range_m: 300.0,
    fixed_dis_unit_mm: None,
    block_period_ns: 50_000,
    default_cut_cdeg: 0,
    fov_cdeg: (0, 0),
};

const SPEC_AT128: ModelSpec = ModelSpec {
    id: "pandarat128",
    name: "PandarAT128",
    protocol_major: Some(4),
    layout: Layout {
        fine_azimuth: true,
        body_crc: true,
        signature: true,
        ..layout(HeaderKind::PreHeader12, 2, 128, 4, TAIL_AT128)
    },
    min_range_m: 1.0,
    max_range_m: 180.0,
    fixed_dis_unit_mm: None,
    block_period_ns: 41_666,
    default_cut_cdeg: 15_000,
    fov_cdeg: (3_000, 15_000),
};

const SPEC_OT128: ModelSpec = ModelSpec {
    id: "pandarot128",
    name: "OT128 (Pandar128E3X/E4X)",
    protocol_major: Some(1),
    layout: Layout {
        body_crc: true,
        safety_len: SAFETY_LEN,
        signature: true,
        ..layout(HeaderKind::PreHeader12, 2, 128, 3, TAIL_OT128)
    },
    min_range_m: 0.1,
    max_range_m: 230.0,
    fixed_dis_unit_mm: None,
    block_period_ns: 55_556,
    default_cut_cdeg: 0,
    fov_cdeg: (0, 0),
};

const SPEC_ATX: ModelSpec = ModelSpec {
    id: "pandaratx",
    name: "Pandar ATX",
    protocol_major: Some(4),
    layout: Layout {
        fine_azimuth: true,
        body_crc: true,
        crc_known: false,
        counts_from_header: true,
        signature: true,
        ..layout(HeaderKind::PreHeader12, 2, 100, 4, TAIL_ATX)
    },
    // No measuring range is published for the ATX: every return is kept.
    min_range_m: 0.0,
    max_range_m: f32::INFINITY,
    fixed_dis_unit_mm: None,
    // Not published either: loss is counted from the UDP sequence only.
    block_period_ns: 0,
    default_cut_cdeg: 0,
    fov_cdeg: (0, 0),
};

// Firing-time tables (ns), from the user manuals' firing-time appendices (the values nebula's
// decoders carry). Pandar40P and Pandar64: relative to the block; the block term is above.
static FIRING_40P: [i32; 40] = [
    -42220, -28470, -16040, -3620, -45490, -31740, -47460, -54670, -20620, -33710, -40910, -8190,
    -20620, -27160, -50730, -8190, -14740, -36980, -45490, -52700, -23890, -31740, -38950, -11470,
    -18650, -25190, -48760, -6230, -12770, -35010, -21920, -9500, -43520, -29770, -17350, -4920,
    -42220, -28470, -16040, -3620,
];

static FIRING_64: [i32; 64] = [
    -23180, -21876, -20572, -19268, -17964, -16660, -11444, -46796, -7532, -36956, -50732, -54668,
    -40892, -44828, -31052, -34988, -48764, -52700, -38924, -42860, -29084, -33020, -46796, -25148,
    -36956, -50732, -27116, -40892, -44828, -31052, -34988, -48764, -25148, -38924, -42860, -29084,
    -33020, -52700, -6228, -54668, -15356, -27116, -10140, -23180, -4924, -21876, -14052, -17964,
    -8836, -19268, -3620, -20572, -12748, -16660, -7532, -11444, -6228, -15356, -10140, -4924,
    -3620, -14052, -8836, -12748,
];

static FIRING_QT64: [i32; 64] = [
    12310, 14370, 16430, 18490, 20540, 22600, 24660, 26710, 29160, 31220, 33280, 35340, 37390,
    39450, 41500, 43560, 46610, 48670, 50730, 52780, 54840, 56900, 58950, 61010, 63450, 65520,
    67580, 69630, 71690, 73740, 75800, 77860, 80900, 82970, 85020, 87080, 89140, 91190, 93250,
    95300, 97750, 99820, 101870, 103930, 105980, 108040, 110100, 112150, 115200, 117260, 119320,
    121380, 123430, 125490, 127540, 129600, 132050, 134110, 136170, 138220, 140280, 142340, 144390,
    146450,
];

static FIRING_QT128_LOOP1: [i32; 128] = [
    0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
    27656, 53000, 2312, 78344, 81512, 5480, 56168, 30824, 33992, 59336, 8648, 84680, 87848, 11816,
    62504, 37160, 40328, 65672, 14984, 91016, 94184, 18152, 68840, 43496, 46664, 72008, 21320,
    97352, 100520, 24488, 75176, 49832, 1456, 77488, 26800, 52144, 55312, 29968, 80656, 4624, 7792,
    83824, 33136, 58480, 61648, 36304, 86992, 10960, 14128, 90160, 39472, 64816, 67984, 42640,
    93328, 17296, 20464, 96496, 45808, 71152, 74320, 48976, 99664, 23632, 25944, 51288, 600, 76632,
    79800, 3768, 54456, 29112, 32280, 57624, 6936, 82968, 86136, 10104, 60792, 35448, 38616, 63960,
    13272, 89304, 92472, 16440, 67128, 41784, 44952, 70296, 19608, 95640, 98808, 22776, 73464,
    48120,
];

static FIRING_QT128_LOOP2: [i32; 128] = [
    2312, 78344, 27656, 53000, 56168, 30824, 81512, 5480, 8648, 84680, 33992, 59336, 62504, 37160,
    87848, 11816, 14984, 91016, 40328, 65672, 68840, 43496, 94184, 18152, 21320, 97352, 46664,
    72008, 75176, 49832, 100520, 24488, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
    0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 600, 76632, 25944, 51288, 54456, 29112, 79800, 3768, 6936,
    82968, 32280, 57624, 60792, 35448, 86136, 10104, 13272, 89304, 38616, 63960, 67128, 41784,
    92472, 16440, 19608, 95640, 44952, 70296, 73464, 48120, 98808, 22776, 26800, 52144, 1456,
    77488, 80656, 4624, 55312, 29968, 33136, 58480, 7792, 83824, 86992, 10960, 61648, 36304, 39472,
    64816, 14128, 90160, 93328, 17296, 67984, 42640, 45808, 71152, 20464, 96496, 99664, 23632,
    74320, 48976,
];

static FIRING_AT128: [i32; 128] = [
    0, 0, 8240, 4112, 4144, 8240, 0, 0, 12424, 4144, 4112, 8264, 12376, 12376, 8264, 12424, 0, 0,
    4112, 8240, 4144, 0, 0, 4144, 12424, 8264, 4112, 12376, 12376, 12424, 8264, 848, 2504, 4976,
    6616, 6616, 9112, 2504, 848, 10768, 13280, 13280, 4976, 9112, 14928, 14928, 10768, 2504, 848,
    6616, 4976, 9112, 6616, 848, 2504, 13280, 10768, 4976, 13280, 14928, 9112, 10768, 14928, 13280,
    848, 9112, 13280, 2504, 4976, 848, 2504, 14928, 10768, 10768, 14928, 4976, 6616, 6616, 9112,
    848, 13280, 13280, 9112, 4976, 2504, 2504, 848, 10768, 14928, 14928, 10768, 6616, 4976, 9112,
    6616, 4112, 12424, 0, 4144, 0, 0, 12424, 0, 8264, 4112, 4144, 8240, 8240, 8264, 12376, 12376,
    12424, 4112, 4144, 0, 0, 0, 0, 0, 12424, 8264, 8240, 4144, 8264, 8240, 12376, 12376, 8264,
];

static FIRING_OT128_STANDARD: [i32; 128] = [
    49758, 43224, 36690, 30156, 21980, 15446, 8912, 2378, 49758, 43224, 36690, 30156, 2378, 15446,
    8912, 21980, 43224, 30156, 49758, 15446, 36690, 2378, 21980, 8912, 34312, 45002, 38468, 40846,
    40846, 34312, 51536, 47380, 31934, 47380, 31934, 51536, 38468, 27778, 27778, 45002, 38468,
    40846, 51536, 45002, 31934, 47380, 34312, 27778, 38468, 40846, 51536, 45002, 31934, 34312,
    27778, 38468, 40846, 51536, 45002, 31934, 47380, 34312, 27778, 45002, 45002, 51536, 38468,
    40846, 47380, 40846, 31934, 45002, 27778, 38468, 40846, 31934, 27778, 38468, 34312, 34312,
    34312, 47380, 51536, 31934, 51536, 47380, 27778, 49758, 21980, 43224, 15446, 43224, 36690,
    8912, 30156, 2378, 49758, 21980, 36690, 15446, 8912, 30156, 2378, 49758, 43224, 36690, 30156,
    21980, 15446, 8912, 2378, 43224, 49758, 30156, 36690, 21980, 15446, 2378, 8912, 49758, 43224,
    36690, 30156, 21980, 15446, 8912, 2378, 30156,
];

static FIRING_OT128_AS0: [i32; 128] = [
    -1, -1, -1, -1, 21980, 15446, 8912, 2378, -1, -1, -1, -1, 2378, 15446, 8912, 21980, -1, 2378,
    21980, 8912, 6534, 17224, 10690, 13068, 13068, 6534, 23758, 19602, 4156, 19602, 4156, 23758,
    13068, 13068, 23758, 10690, 4156, 19602, 19602, 0, 10690, 6534, 23758, 17224, 23758, 19602,
    6534, 17224, 4156, 0, 6534, 0, 17224, 10690, 17224, 17224, 23758, 23758, 10690, 13068, 13068,
    13068, 19602, 19602, 6534, 13068, 4156, 4156, 17224, 17224, 17224, 0, 10690, 10690, 13068,
    13068, 4156, 0, 10690, 6534, 6534, 6534, 19602, 23758, 4156, 23758, 19602, 0, -1, 21980, -1,
    15446, -1, 8912, -1, 2378, -1, -1, 21980, -1, 15446, 8912, -1, 2378, -1, -1, -1, -1, 21980,
    15446, 8912, 2378, -1, -1, -1, -1, 21980, 15446, 2378, 8912, -1, -1, -1, -1, 21980, 15446,
    8912, 2378,
];

static FIRING_OT128_AS1: [i32; 128] = [
    21980, 15446, 8912, 2378, -1, -1, -1, -1, 21980, 15446, 8912, 2378, -1, -1, -1, -1, 8912, -1,
    -1, -1, 6534, 17224, 10690, 13068, 13068, 6534, 23758, 19602, 4156, 19602, 4156, 23758, 13068,
    13068, 23758, 10690, 4156, 19602, 19602, 0, 10690, 6534, 23758, 17224, 23758, 19602, 6534,
    17224, 4156, 0, 6534, 0, 17224, 10690, 17224, 17224, 23758, 23758, 10690, 13068, 13068, 13068,
    19602, 19602, 6534, 13068, 4156, 4156, 17224, 17224, 17224, 0, 10690, 10690, 13068, 13068,
    4156, 0, 10690, 6534, 6534, 6534, 19602, 23758, 4156, 23758, 19602, 0, 21980, -1, 15446, -1,
    8912, -1, 2378, -1, 21980, 15446, -1, 8912, -1, -1, 2378, -1, 21980, 15446, 8912, 2378, -1, -1,
    -1, -1, 15446, 21980, 2378, 8912, -1, -1, -1, -1, 21980, 15446, 8912, 2378, -1, -1, -1, -1,
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts_have_the_documented_sizes() {
        let base = |m: HesaiModel| m.spec().layout.base_len();
        assert_eq!(base(HesaiModel::Pandar40P), 1262);
        assert_eq!(base(HesaiModel::Pandar64) + 4, 1198);
        assert_eq!(base(HesaiModel::PandarQt64), 1072);
        assert_eq!(base(HesaiModel::PandarQt128) + SIGNATURE_LEN, 1127);
        assert_eq!(base(HesaiModel::PandarXt32), 1080);
        assert_eq!(base(HesaiModel::PandarXt32m), 820);
        assert_eq!(base(HesaiModel::PandarXt16), 568);
        assert_eq!(base(HesaiModel::PandarAt128) + SIGNATURE_LEN, 1118);
        assert_eq!(base(HesaiModel::PandarOt128), 861);
        // ATX, the SDK's `GetPacketSize`: 12 + blocks × (3 + 4 × lasers) + body CRC 4 + tail 32
        // (+ sequence 4) + E2E 12 (+ signature 32).
        let atx = &HesaiModel::PandarAtx.spec().layout;
        assert_eq!(atx.for_header(100, 2, 0).exact_len(), 866);
        assert_eq!(atx.for_header(100, 2, 0b1001).exact_len(), 902);
        assert_eq!(
            atx.for_header(128, 2, 0b0001).exact_len(),
            12 + 2 * 515 + 4 + 32 + 4 + 12
        );
    }

    #[test]
    fn year_byte_counts_from_1900_or_2000() {
        assert_eq!(year_from_byte(17), 2017);
        assert_eq!(year_from_byte(120), 2020);
        assert_eq!(year_from_byte(69), 2069);
    }

    #[test]
    fn every_model_id_round_trips() {
        for m in ALL_MODELS {
            assert_eq!(HesaiModel::from_id(m.id()), Some(m));
        }
    }

    /// The reduced flags the decoder keys its firing tables on give every model the same
    /// firing times as the full tail flags, for every return count, block and channel.
    #[test]
    fn firing_flags_keep_every_firing_time() {
        let mut x = 0x2545_F491_4F6C_DD1Du64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        for m in ALL_MODELS {
            for n in 1..=3 {
                for _ in 0..64 {
                    let v = next();
                    let tail = TailFlags {
                        mode_flag: v as u8,
                        azimuth_state: (v >> 8) as u16,
                        operational_state: if v >> 24 & 1 == 0 { 0 } else { (v >> 25) as u8 },
                    };
                    let reduced = m.firing_flags(n, tail);
                    for b in 0..m.spec().layout.blocks {
                        for c in 0..m.channels() {
                            assert_eq!(
                                m.firing_offset_ns(b, c, n, tail),
                                m.firing_offset_ns(b, c, n, reduced),
                                "{m:?} n {n} block {b} channel {c} {tail:?}"
                            );
                        }
                    }
                }
            }
        }
    }
}
