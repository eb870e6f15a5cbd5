//! Per-model facts of the Robosense spinning sensors, as data (and the M1's few, whose layout
//! lives in [`super::m1`]).
//!
//! Every model sends 1248-byte MSOP packets. Two packet shapes exist:
//!
//! - **42-byte header, 12 blocks of 100 bytes** (RS-16, RS-32, RS-Bpearl, RS-Helios,
//!   RS-Helios-16P): each block is `FF EE`, the block azimuth (u16 big-endian, 0.01°) and 32
//!   channel slots of 3 bytes (distance u16 big-endian, intensity u8); then a 4-byte index and
//!   a 2-byte tail. The RS-16 / RS-32 / Bpearl header starts with the 8 bytes
//!   `55 AA 05 0A 5A A5 50 A0` and carries the **calendar time** at bytes 20–29 (year − 2000,
//!   month, day, hour, minute, second, ms u16, µs u16); the Helios header starts
//!   `55 AA 05 5A`, has a protocol version at bytes 4–5 and carries the **Unix time** at bytes
//!   20–29 (seconds u48, µs u32, big-endian).
//! - **80-byte header, 3 blocks of 388 bytes** (RS-Ruby 128): header `55 AA 05 5A`, Unix time
//!   at bytes 10–19; each block is `FE`, a return id, the azimuth and 128 slots of 3 bytes;
//!   4 reserved bytes close the packet.
//!
//! The time in the header is the packet's first firing. A slot's firing time is the block's
//! firing time plus the model's firing offset for that slot (the firing-time tables of the
//! user manuals' appendices, as RoboSense's SDK `rs_driver` tabulates them); its azimuth is
//! the block azimuth plus the azimuth step to the next firing scaled by that offset, truncated
//! to 0.01° (the SDK's rule), plus the laser's horizontal correction.
//!
//! RS-16 and RS-Helios-16P have 16 lasers in 32 slots: in single-return mode slots 16–31 are
//! the lasers' second firing within the block, in dual-return mode they are the second return
//! of slots 0–15. The Helios-16P's table is the one RoboSense's SDK shipped for it until
//! March 2024 (rs_driver ≤ 1.5.13, the generation of the shared capture and of the decoder
//! that wrote its expected clouds); its blocks are 55.56 µs apart (0.2° at 600 rpm in the
//! capture), and the azimuth interpolation spans two blocks, as that SDK computes it.

/// The block and channel shape of a packet.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shape {
    /// 42-byte header with the 8-byte id and the calendar clock; 12 × 32 slots.
    V1,
    /// 42-byte Helios header (4-byte id, protocol version, Unix clock); 12 × 32 slots.
    Helios,
    /// 80-byte header, 3 × 128 slots.
    Ruby,
    /// The M1's 1210-byte packet: 32-byte header, 25 blocks of 5 self-contained points
    /// ([`super::m1`]; the spinning accessors below give its counts, the spinning decoder
    /// refuses it).
    Mems,
}

impl Shape {
    /// Header length, bytes.
    pub const fn header_len(self) -> usize {
        match self {
            Self::V1 | Self::Helios => 42,
            Self::Ruby => 80,
            Self::Mems => super::m1::M1_HEADER_LEN,
        }
    }
    /// Blocks per packet.
    pub const fn blocks(self) -> usize {
        match self {
            Self::V1 | Self::Helios => 12,
            Self::Ruby => 3,
            Self::Mems => super::m1::M1_BLOCKS,
        }
    }
    /// Channel slots per block.
    pub const fn slots(self) -> usize {
        match self {
            Self::V1 | Self::Helios => 32,
            Self::Ruby => 128,
            Self::Mems => super::m1::M1_CHANNELS,
        }
    }
    /// Bytes of a block's prefix (flag and azimuth; the M1's time offset and return byte).
    pub const fn block_prefix(self) -> usize {
        match self {
            Self::Mems => 2,
            _ => 4,
        }
    }
    /// Bytes of one block.
    pub const fn block_len(self) -> usize {
        match self {
            Self::Mems => super::m1::M1_BLOCK_LEN,
            _ => self.block_prefix() + 3 * self.slots(),
        }
    }
    /// Offset of the Unix or calendar time in the header.
    pub const fn time_offset(self) -> usize {
        match self {
            Self::V1 | Self::Helios => 20,
            Self::Ruby | Self::Mems => 10,
        }
    }
    /// Packet length.
    pub const fn packet_len(self) -> usize {
        match self {
            Self::Mems => super::m1::M1_MSOP_LEN,
            _ => PACKET_LEN,
        }
    }
}

/// How the blocks of a dual-return packet pair up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DualForm {
    /// Slots 0–15 are the first return, slots 16–31 the second, of one firing (RS-16,
    /// Helios-16P).
    SlotHalves,
    /// Blocks 2k and 2k + 1 are the two returns of one firing (RS-32, Bpearl, Helios).
    BlockPairs,
    /// Three blocks: two of them share an azimuth (the two returns of one firing), the third
    /// is the other firing (Ruby: `AAB` or `ABB`).
    AbPairs,
}

/// The clock form of the header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClockForm {
    /// Year − 2000, month, day, hour, minute, second, ms, µs.
    Calendar,
    /// Seconds (48 bits) and µs (32 bits), big-endian.
    Unix,
}

/// Facts of one model.
#[derive(Clone, Copy, Debug)]
pub struct ModelSpec {
    /// Name as RoboSense writes it.
    pub name: &'static str,
    /// Id `--model` accepts.
    pub id: &'static str,
    /// Lasers (rows of the organised image).
    pub lasers: usize,
    /// Packet shape.
    pub shape: Shape,
    /// Distance unit, metres.
    pub distance_unit_m: f32,
    /// Shortest and longest valid range, metres (RoboSense's SDK constants).
    pub min_range_m: f32,
    /// Longest valid range, metres.
    pub max_range_m: f32,
    /// Lens centre offset from the rotation axis, forward (m) and up (m): a point is the
    /// measured vector plus this offset rotated with the head.
    pub lens_rx_m: f32,
    /// Lens centre height, m.
    pub lens_rz_m: f32,
    /// Firing offset of each slot from its block's time, µs (single-return mode).
    pub firing_us: &'static [f32],
    /// Time from one block to the next in single-return mode, µs.
    pub block_us: f32,
    /// Time the azimuth step to the next block spans for the interpolation (single mode), µs.
    pub az_span_us: f32,
    /// Time between firings in dual-return mode, µs.
    pub dual_block_us: f32,
    /// How dual-return packets pair their returns.
    pub dual: DualForm,
    /// Return-mode byte of the DIFOP meaning dual return.
    pub dual_mode_byte: u8,
    /// Header clock form.
    pub clock: ClockForm,
    /// Bytes in the DIFOP where the vertical angle table starts, and its entries (each
    /// sign byte + u16 big-endian in 0.01°, followed by as many horizontal entries). `None`:
    /// the RS-16's pitch table ([`RS16_PITCH_OFFSET`]).
    pub difop_angles: Option<(usize, usize)>,
}

/// Offset of the RS-16 DIFOP's pitch table (16 × u24 big-endian in 0.0001°; lasers 0–7 point
/// down, 8–15 up).
pub const RS16_PITCH_OFFSET: usize = 1165;

/// MSOP and DIFOP length.
pub const PACKET_LEN: usize = 1248;

const RS16_FIRING: [f32; 32] = [
    0.00, 2.80, 5.60, 8.40, 11.20, 14.00, 16.80, 19.60, 22.40, 25.20, 28.00, 30.80, 33.60, 36.40,
    39.20, 42.00, 55.50, 58.30, 61.10, 63.90, 66.70, 69.50, 72.30, 75.10, 77.90, 80.70, 83.50,
    86.30, 89.10, 91.90, 94.70, 97.50,
];
const RS32_FIRING: [f32; 32] = [
    0.00, 2.88, 5.76, 8.64, 11.52, 14.40, 17.28, 20.16, 23.04, 25.92, 28.80, 31.68, 34.56, 37.44,
    40.32, 44.64, 1.44, 4.32, 7.20, 10.08, 12.96, 15.84, 18.72, 21.60, 24.48, 27.36, 30.24, 33.12,
    36.00, 38.88, 41.76, 46.08,
];
const BPEARL_FIRING: [f32; 32] = [
    0.00, 2.56, 5.12, 7.68, 10.24, 12.80, 15.36, 17.92, 25.68, 28.24, 30.80, 33.36, 35.92, 38.48,
    41.04, 43.60, 1.28, 3.84, 6.40, 8.96, 11.52, 14.08, 16.64, 19.20, 26.96, 29.52, 32.08, 34.64,
    37.20, 39.76, 42.32, 44.88,
];
const HELIOS_FIRING: [f32; 32] = [
    0.00, 1.73, 3.46, 5.19, 6.92, 8.65, 10.38, 12.11, 13.84, 15.57, 17.3, 19.03, 20.76, 22.49,
    24.22, 25.95, 27.68, 29.41, 31.14, 32.87, 34.6, 36.33, 38.06, 39.79, 41.52, 43.25, 44.98,
    46.71, 48.44, 50.17, 51.9, 53.63,
];
const HELIOS16P_FIRING: [f32; 32] = [
    0.00, 3.15, 6.30, 9.45, 13.26, 17.08, 20.56, 23.71, 26.53, 27.77, 31.49, 32.73, 36.46, 38.94,
    41.42, 43.91, 55.56, 58.70, 61.85, 65.00, 68.82, 72.64, 76.12, 79.27, 82.08, 83.32, 87.05,
    88.29, 92.01, 94.50, 96.98, 99.46,
];
/// Ruby 128: four lasers fire together, 32 groups 3.236 µs apart, twice over the 128 slots.
const RUBY_FIRING: [f32; 128] = {
    let mut t = [0f32; 128];
    let mut i = 0;
    while i < 128 {
        t[i] = ((i % 64) / 4) as f32 * 3.236;
        i += 1;
    }
    t
};

/// The Robosense models ringscan decodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RobosenseModel {
    /// RS-LiDAR-16.
    Rs16,
    /// RS-LiDAR-32.
    Rs32,
    /// RS-Bpearl.
    Bpearl,
    /// RS-Helios (32 lasers; RS-Helios-5515 / 1615 / 1610).
    Helios,
    /// RS-Helios-16P.
    Helios16P,
    /// RS-Ruby (128 lasers).
    Ruby128,
    /// RS-LiDAR-M1 and M1 Plus (MEMS, 5 channels; one MSOP layout, [`super::m1`]).
    M1,
}

/// Every model, in `--model` order.
pub const ALL_MODELS: [RobosenseModel; 7] = [
    RobosenseModel::Rs16,
    RobosenseModel::Rs32,
    RobosenseModel::Bpearl,
    RobosenseModel::Helios,
    RobosenseModel::Helios16P,
    RobosenseModel::Ruby128,
    RobosenseModel::M1,
];

impl RobosenseModel {
    /// The model's facts.
    pub fn spec(self) -> &'static ModelSpec {
        match self {
            Self::Rs16 => &RS16,
            Self::Rs32 => &RS32,
            Self::Bpearl => &BPEARL,
            Self::Helios => &HELIOS,
            Self::Helios16P => &HELIOS16P,
            Self::Ruby128 => &RUBY128,
            Self::M1 => &M1,
        }
    }

    /// `--model` id.
    pub fn id(self) -> &'static str {
        self.spec().id
    }

    /// Name.
    pub fn name(self) -> &'static str {
        self.spec().name
    }

    /// Lasers.
    pub fn lasers(self) -> usize {
        self.spec().lasers
    }

    /// The model `--model` names.
    pub fn from_id(id: &str) -> Option<Self> {
        ALL_MODELS
            .iter()
            .copied()
            .find(|m| m.id().eq_ignore_ascii_case(id))
    }

    /// Laser of slot `s`.
    pub fn laser_of_slot(self, s: usize) -> usize {
        s % self.lasers()
    }

    /// Whether a DIFOP return-mode byte means dual return.
    pub fn is_dual(self, mode: u8) -> bool {
        mode == self.spec().dual_mode_byte
    }

    /// Name of a DIFOP return-mode byte.
    pub fn mode_name(self, mode: u8) -> &'static str {
        match (self.spec().shape, mode) {
            (_, m) if m == self.spec().dual_mode_byte => "dual",
            (Shape::V1, 1) => "strongest",
            (Shape::V1, 2) => "last",
            (Shape::Helios, 4) => "strongest",
            (Shape::Helios, 5) => "last",
            (Shape::Helios, 6) => "nearest",
            (Shape::Ruby, 1) => "last",
            (Shape::Ruby, 2) => "strongest",
            (Shape::Mems, 4) => "strongest",
            (Shape::Mems, 5) => "last",
            (Shape::Mems, 6) => "first",
            _ => "unknown",
        }
    }
}

const RS16: ModelSpec = ModelSpec {
    name: "RS-LiDAR-16",
    id: "rs16",
    lasers: 16,
    shape: Shape::V1,
    distance_unit_m: 0.005,
    min_range_m: 0.4,
    max_range_m: 230.0,
    lens_rx_m: 0.03825,
    lens_rz_m: 0.0,
    firing_us: &RS16_FIRING,
    block_us: 111.0,
    az_span_us: 111.0,
    dual_block_us: 55.5,
    dual: DualForm::SlotHalves,
    dual_mode_byte: 0,
    clock: ClockForm::Calendar,
    difop_angles: None,
};
const RS32: ModelSpec = ModelSpec {
    name: "RS-LiDAR-32",
    id: "rs32",
    lasers: 32,
    shape: Shape::V1,
    distance_unit_m: 0.005,
    min_range_m: 0.4,
    max_range_m: 230.0,
    lens_rx_m: 0.03997,
    lens_rz_m: 0.0,
    firing_us: &RS32_FIRING,
    block_us: 55.52,
    az_span_us: 55.52,
    dual_block_us: 55.52,
    dual: DualForm::BlockPairs,
    dual_mode_byte: 0,
    clock: ClockForm::Calendar,
    difop_angles: Some((468, 32)),
};
const BPEARL: ModelSpec = ModelSpec {
    name: "RS-Bpearl",
    id: "rsbpearl",
    lasers: 32,
    shape: Shape::V1,
    distance_unit_m: 0.005,
    min_range_m: 0.1,
    max_range_m: 150.0,
    lens_rx_m: 0.01473,
    lens_rz_m: 0.09427,
    firing_us: &BPEARL_FIRING,
    block_us: 55.52,
    az_span_us: 55.52,
    dual_block_us: 55.52,
    dual: DualForm::BlockPairs,
    dual_mode_byte: 0,
    clock: ClockForm::Calendar,
    difop_angles: Some((468, 32)),
};
const HELIOS: ModelSpec = ModelSpec {
    name: "RS-Helios",
    id: "rshelios",
    lasers: 32,
    shape: Shape::Helios,
    distance_unit_m: 0.0025,
    min_range_m: 0.1,
    max_range_m: 180.0,
    lens_rx_m: 0.03498,
    lens_rz_m: 0.0,
    firing_us: &HELIOS_FIRING,
    block_us: 55.56,
    az_span_us: 55.56,
    dual_block_us: 55.56,
    dual: DualForm::BlockPairs,
    dual_mode_byte: 0,
    clock: ClockForm::Unix,
    difop_angles: Some((468, 32)),
};
const HELIOS16P: ModelSpec = ModelSpec {
    name: "RS-Helios-16P",
    id: "rshelios16p",
    lasers: 16,
    shape: Shape::Helios,
    distance_unit_m: 0.0025,
    min_range_m: 0.1,
    max_range_m: 180.0,
    lens_rx_m: 0.03498,
    lens_rz_m: 0.0,
    firing_us: &HELIOS16P_FIRING,
    block_us: 55.56,
    az_span_us: 111.12,
    dual_block_us: 55.56,
    dual: DualForm::SlotHalves,
    dual_mode_byte: 0,
    clock: ClockForm::Unix,
    difop_angles: Some((468, 32)),
};
const RUBY128: ModelSpec = ModelSpec {
    name: "RS-Ruby-128",
    id: "rsruby128",
    lasers: 128,
    shape: Shape::Ruby,
    distance_unit_m: 0.005,
    min_range_m: 0.4,
    max_range_m: 250.0,
    lens_rx_m: 0.03615,
    lens_rz_m: 0.0,
    firing_us: &RUBY_FIRING,
    block_us: 55.55,
    az_span_us: 55.55,
    dual_block_us: 55.55,
    dual: DualForm::AbPairs,
    dual_mode_byte: 3,
    clock: ClockForm::Unix,
    difop_angles: Some((468, 128)),
};

/// The M1: only the fields that apply to it are meaningful (name, id, channels, shape, unit,
/// range, return-mode byte, clock); the firing fields are zero because each M1 block carries
/// its own time offset, and the spinning decoder refuses the model.
const M1: ModelSpec = ModelSpec {
    name: "RS-LiDAR-M1",
    id: "rsm1",
    lasers: super::m1::M1_CHANNELS,
    shape: Shape::Mems,
    distance_unit_m: super::m1::M1_RADIUS_UNIT_M,
    min_range_m: super::m1::M1_MIN_RANGE_M,
    max_range_m: super::m1::M1_MAX_RANGE_M,
    lens_rx_m: 0.0,
    lens_rz_m: 0.0,
    firing_us: &[0.0; super::m1::M1_CHANNELS],
    block_us: 0.0,
    az_span_us: 0.0,
    dual_block_us: 0.0,
    dual: DualForm::BlockPairs,
    dual_mode_byte: 0,
    clock: ClockForm::Unix,
    difop_angles: None,
};

/// One block's place in time: its firing index in the packet and the return it holds
/// (`None` for [`DualForm::SlotHalves`], where the slot says).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BlockRole {
    /// Firing (column) index within the packet.
    pub firing: usize,
    /// Return index (0 = first / strongest, 1 = second), when the block says.
    pub ret: Option<u8>,
}

impl ModelSpec {
    /// Time between firings, µs.
    pub fn firing_period_us(&self, dual: bool) -> f32 {
        if dual {
            self.dual_block_us
        } else {
            self.block_us
        }
    }

    /// Firing offset of slot `s` within its firing, µs.
    pub fn slot_us(&self, s: usize, dual: bool) -> f32 {
        let s = if dual && self.dual == DualForm::SlotHalves {
            s % 16
        } else {
            s
        };
        self.firing_us.get(s).copied().unwrap_or(0.0)
    }

    /// Fraction of the azimuth step to the next firing at which slot `s` fires (f32, as the
    /// SDK computes it: the truncation of `step × fraction` depends on it).
    pub fn slot_fraction(&self, s: usize, dual: bool) -> f32 {
        let span = if dual {
            self.dual_block_us
        } else {
            self.az_span_us
        };
        self.slot_us(s, dual) / span
    }

    /// Firings per packet.
    pub fn firings(&self, dual: bool) -> usize {
        let b = self.shape.blocks();
        match (dual, self.dual) {
            (false, _) | (true, DualForm::SlotHalves) => b,
            (true, DualForm::BlockPairs) => b / 2,
            (true, DualForm::AbPairs) => 2,
        }
    }

    /// Time a packet covers, ns.
    pub fn packet_period_ns(&self, dual: bool) -> f64 {
        if self.shape == Shape::Mems {
            let per_frame =
                f64::from(super::m1::M1_PACKETS_PER_FRAME) * if dual { 2.0 } else { 1.0 };
            return super::m1::M1_FRAME_NS as f64 / per_frame;
        }
        f64::from(self.firing_period_us(dual)) * 1_000.0 * self.firings(dual) as f64
    }
}

/// `ns` of a µs value from a firing table.
pub fn us_to_ns(us: f32) -> i64 {
    (f64::from(us) * 1_000.0).round() as i64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_fill_the_packet() {
        for m in ALL_MODELS {
            let s = m.spec().shape;
            let tail = match s {
                Shape::Ruby => 4,
                Shape::Mems => 3,
                _ => 6,
            };
            assert_eq!(
                s.header_len() + s.blocks() * s.block_len() + tail,
                s.packet_len()
            );
            assert_eq!(m.spec().firing_us.len(), s.slots());
        }
    }

    #[test]
    fn ruby_groups_of_four() {
        assert_eq!(RUBY_FIRING[4], 3.236);
        assert_eq!(RUBY_FIRING[63], 15.0 * 3.236);
        assert_eq!(RUBY_FIRING[64], 0.0);
    }
}
