//! Velodyne models as data: lasers, distance unit, block layout and firing-time tables.
//!
//! Every number here has a source (see `FORMATS.md` §5.1 in the project's shared notes):
//! - VLP-16 / Puck Hi-Res: VLP-16 manual 63-9243 §9.4 — 16 firings × 2.304 µs + 18.432 µs
//!   recharge = 55.296 µs per firing sequence, two sequences per block.
//! - VLP-32C: VLP-32C manual §8.1 — lasers fire in pairs, 16 × 2.304 µs + 18.432 µs = 55.296 µs
//!   per block.
//! - HDL-32E: HDL-32E application note 63-9277 Rev D — 32 sequential firings × 1.152 µs +
//!   9.216 µs = 46.080 µs per block (`1.152·ch`, as VeloView and velodyne_decoder; the ROS
//!   driver's `1.152·(ch/2)` is not followed).
//! - HDL-64E S2 / S3: velodyne_decoder's tables (upper and lower block fire together; groups of
//!   4 lasers): S2 `48.0·(block/2) + 6.0·(slot/4) + {0, 1.26, 2.46, 3.66}[slot%4]` µs, S3
//!   `57.6·(block/2) + 7.2·(slot/4) + {0, 1.3, 2.5, 3.7}[slot%4]` µs. The S2 manual instead
//!   subtracts offsets from the packet stamp: **the sign is unverified** (no capture with
//!   GPS + PPS exists), ringscan follows velodyne_decoder as the project decided.
//! - VLS-128: VLS-128 manual §9.4 — groups of 8 lasers, 2.665 µs per group, 53.3 µs per
//!   sequence, `group = id/8 + id/64`, packet stamp aligned 8.7 µs after the first group.

use core::fmt;

/// Number of data blocks in a Velodyne data packet.
pub const BLOCKS: usize = 12;
/// Measurement slots per block.
pub const SLOTS: usize = 32;
/// Size of a Velodyne data packet payload.
pub const DATA_PACKET_LEN: usize = 1206;
/// Size of a Velodyne position (telemetry) packet payload.
pub const POSITION_PACKET_LEN: usize = 512;

/// A Velodyne sensor model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum VelodyneModel {
    /// VLP-16 (and Puck LITE).
    Vlp16,
    /// Puck Hi-Res (VLP-16 Hi-Res).
    PuckHiRes,
    /// HDL-32E.
    Hdl32e,
    /// VLP-32C.
    Vlp32c,
    /// HDL-64E S2 / S2.1.
    Hdl64eS2,
    /// HDL-64E S3.
    Hdl64eS3,
    /// VLS-128 (Alpha Prime).
    Vls128,
}

/// How the sensor reports returns (factory byte 1204).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ReturnMode {
    /// Strongest return only (0x37).
    Strongest,
    /// Last return only (0x38).
    Last,
    /// Last and strongest (0x39): blocks come in pairs.
    Dual,
}

impl ReturnMode {
    /// From factory byte 1204.
    pub fn from_byte(b: u8) -> Option<Self> {
        match b {
            0x37 => Some(Self::Strongest),
            0x38 => Some(Self::Last),
            0x39 => Some(Self::Dual),
            _ => None,
        }
    }

    /// The factory byte for this mode.
    pub fn byte(self) -> u8 {
        match self {
            Self::Strongest => 0x37,
            Self::Last => 0x38,
            Self::Dual => 0x39,
        }
    }

    /// Name used in summaries and MCAP metadata.
    pub fn name(self) -> &'static str {
        match self {
            Self::Strongest => "strongest",
            Self::Last => "last",
            Self::Dual => "dual",
        }
    }

    /// Whether blocks come in pairs of the same firing.
    pub fn is_dual(self) -> bool {
        self == Self::Dual
    }
}

impl fmt::Display for ReturnMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Every model, for iteration in tests and command-line help.
pub const ALL_MODELS: [VelodyneModel; 7] = [
    VelodyneModel::Vlp16,
    VelodyneModel::PuckHiRes,
    VelodyneModel::Hdl32e,
    VelodyneModel::Vlp32c,
    VelodyneModel::Hdl64eS2,
    VelodyneModel::Hdl64eS3,
    VelodyneModel::Vls128,
];

impl VelodyneModel {
    /// Display name, e.g. `VLP-16`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Vlp16 => "VLP-16",
            Self::PuckHiRes => "Puck Hi-Res",
            Self::Hdl32e => "HDL-32E",
            Self::Vlp32c => "VLP-32C",
            Self::Hdl64eS2 => "HDL-64E S2",
            Self::Hdl64eS3 => "HDL-64E S3",
            Self::Vls128 => "VLS-128",
        }
    }

    /// Command-line / file-name id, e.g. `vlp16`.
    pub fn id(self) -> &'static str {
        match self {
            Self::Vlp16 => "vlp16",
            Self::PuckHiRes => "puck-hires",
            Self::Hdl32e => "hdl32e",
            Self::Vlp32c => "vlp32c",
            Self::Hdl64eS2 => "hdl64e-s2",
            Self::Hdl64eS3 => "hdl64e-s3",
            Self::Vls128 => "vls128",
        }
    }

    /// Parses a command-line id (`vlp16`, `hdl32e`, …; case-insensitive, `-`/`_` optional).
    pub fn from_id(s: &str) -> Option<Self> {
        let norm: String = s
            .chars()
            .filter(|c| c.is_ascii_alphanumeric())
            .map(|c| c.to_ascii_lowercase())
            .collect();
        ALL_MODELS.into_iter().find(|m| {
            let id: String = m
                .id()
                .chars()
                .filter(|c| c.is_ascii_alphanumeric())
                .collect();
            id == norm
        })
    }

    /// Number of lasers.
    pub fn lasers(self) -> usize {
        match self {
            Self::Vlp16 | Self::PuckHiRes => 16,
            Self::Hdl32e | Self::Vlp32c => 32,
            Self::Hdl64eS2 | Self::Hdl64eS3 => 64,
            Self::Vls128 => 128,
        }
    }

    /// Product id (factory byte 1205), where the model sends one.
    pub fn product_id(self) -> Option<u8> {
        match self {
            Self::Hdl32e => Some(0x21),
            Self::Vlp16 => Some(0x22),
            Self::PuckHiRes => Some(0x24),
            Self::Vlp32c => Some(0x28),
            Self::Vls128 => Some(0xA1),
            Self::Hdl64eS2 | Self::Hdl64eS3 => None,
        }
    }

    /// Model for a product id (factory byte 1205). 0x23 (VLP-32A/B) is read as VLP-32C, whose
    /// layout and timing it shares (velodyne_decoder and VeloView do the same).
    pub fn from_product_id(b: u8) -> Option<Self> {
        match b {
            0x21 => Some(Self::Hdl32e),
            0x22 => Some(Self::Vlp16),
            0x23 | 0x28 => Some(Self::Vlp32c),
            0x24 => Some(Self::PuckHiRes),
            0xA1 => Some(Self::Vls128),
            _ => None,
        }
    }

    /// Whether this is an HDL-64E (upper / lower blocks, status bytes instead of factory bytes).
    pub fn is_hdl64(self) -> bool {
        matches!(self, Self::Hdl64eS2 | Self::Hdl64eS3)
    }

    /// The distance unit when the packet format fixes it, whatever a calibration file says.
    ///
    /// VLS-128: 4 mm (VLS-128 manual, data packet format). Every reference decoder uses this
    /// constant for the VLS-128 and ignores the calibration's `distance_resolution` (ROS
    /// velodyne `VLS128_DISTANCE_RESOLUTION`, velodyne_decoder, nebula), and the VLS-128 yaml
    /// nebula ships says 0.007: reading it scaled every range by 1.75 (on nebula's real
    /// capture, medians over 2 m off).
    pub fn fixed_distance_resolution(self) -> Option<f64> {
        match self {
            Self::Vls128 => Some(0.004),
            _ => None,
        }
    }

    /// Default distance unit in metres (a calibration's own value wins, unless the packet format
    /// fixes it: [`Self::fixed_distance_resolution`]).
    pub fn distance_resolution(self) -> f64 {
        match self {
            Self::Vlp32c | Self::Vls128 => 0.004,
            _ => 0.002,
        }
    }

    /// Blocks of a packet that carry measurements: all 12, except the VLS-128 in dual return
    /// mode, whose one firing column fills blocks 0–7 (two per bank) and leaves 8–11 empty
    /// (velodyne_decoder 3.1.0 `unpack_vls128`: "The last 4 blocks are empty in dual-return
    /// mode"; their content is not read).
    pub fn blocks_used(self, mode: ReturnMode) -> usize {
        if self == Self::Vls128 && mode.is_dual() {
            8
        } else {
            BLOCKS
        }
    }

    /// Banks of 32 slots in one firing: HDL-64E upper and lower, the VLS-128's four, one for
    /// every other model ([`Self::bank_of_block`] gives each block's).
    pub fn banks(self) -> usize {
        match self {
            Self::Hdl64eS2 | Self::Hdl64eS3 => 2,
            Self::Vls128 => 4,
            _ => 1,
        }
    }

    /// The bank (position in its firing: HDL-64E upper 0 / lower 1, VLS-128 banks 0–3, 0 for
    /// every other model) of block `block` in a packet of this return mode.
    pub fn bank_of_block(self, mode: ReturnMode, block: usize) -> usize {
        match self {
            Self::Hdl64eS2 | Self::Hdl64eS3 => block % 2,
            // Single: four banks a column. Dual: bank b's last and strongest returns in
            // blocks 2b and 2b + 1.
            Self::Vls128 if mode.is_dual() => (block / 2) % 4,
            Self::Vls128 => block % 4,
            _ => 0,
        }
    }

    /// In dual return mode, the blocks of the last and of the strongest return of pair `k` of
    /// the firing group that starts at block `group` (`k` < half the group's blocks).
    pub fn dual_pair(self, group: usize, k: usize) -> (usize, usize) {
        let half = self.blocks_per_firing(ReturnMode::Dual) / 2;
        match self {
            // Bank by bank: last, strongest (velodyne_decoder `unpack_vls128`).
            Self::Vls128 => (group + 2 * k, group + 2 * k + 1),
            _ if self.dual_strongest_first() => (group + half + k, group + k),
            _ => (group + k, group + half + k),
        }
    }

    /// Blocks that belong to one firing (same azimuth): the unit sweeps are cut on.
    pub fn blocks_per_firing(self, mode: ReturnMode) -> usize {
        let base = match self {
            Self::Hdl64eS2 | Self::Hdl64eS3 => 2,
            Self::Vls128 => 4,
            _ => 1,
        };
        if mode.is_dual() {
            base * 2
        } else {
            base
        }
    }

    /// In dual-return mode, whether the first half of a firing's blocks carries the
    /// **strongest** return and the second half the last one (else the other way round).
    ///
    /// - HDL-64E S2 / S3: blocks `i` and `i + 2` (`i % 4 ∈ {0, 1}`) are the two returns of one
    ///   firing; velodyne_decoder 3.1.0 (`PacketDecoder::unpack_hdl64e`) reads block `i` as the
    ///   strongest and block `i + 2` as the last return: `true`.
    /// - VLP-16, Puck Hi-Res, HDL-32E, VLP-32C: even blocks last, odd blocks strongest (VLP-16 and
    ///   VLP-32C manuals §9.3.2; velodyne_decoder `unpack_16_32_beam`): `false`.
    pub fn dual_strongest_first(self) -> bool {
        self.is_hdl64()
    }

    /// Laser id measured in `slot` of a block whose position in its firing is `bank`
    /// (0 = upper / first bank; HDL-64E lower = 1; VLS-128 banks 0..3).
    #[inline]
    pub fn laser_of(self, bank: usize, slot: usize) -> usize {
        match self {
            Self::Vlp16 | Self::PuckHiRes => slot % 16,
            _ => bank * SLOTS + slot,
        }
    }

    /// Offset of a measurement's firing from the packet's first firing, in nanoseconds, and the
    /// index of its firing column within the packet.
    ///
    /// `block` is the block index in the packet (0..12), `slot` the measurement index (0..32).
    pub fn firing(self, mode: ReturnMode, block: usize, slot: usize) -> (f64, usize) {
        let dual = mode.is_dual();
        match self {
            Self::Vlp16 | Self::PuckHiRes => {
                let b = if dual { block / 2 } else { block };
                let seq = 2 * b + slot / 16;
                (55_296.0 * seq as f64 + 2_304.0 * (slot % 16) as f64, seq)
            }
            Self::Vlp32c => {
                let b = if dual { block / 2 } else { block };
                (55_296.0 * b as f64 + 2_304.0 * (slot / 2) as f64, b)
            }
            Self::Hdl32e => {
                let b = if dual { block / 2 } else { block };
                (46_080.0 * b as f64 + 1_152.0 * slot as f64, b)
            }
            Self::Hdl64eS2 | Self::Hdl64eS3 => {
                let b = if dual { block / 4 } else { block / 2 };
                let (cycle, group, within): (f64, f64, [f64; 4]) = if self == Self::Hdl64eS2 {
                    (48_000.0, 6_000.0, [0.0, 1_260.0, 2_460.0, 3_660.0])
                } else {
                    (57_600.0, 7_200.0, [0.0, 1_300.0, 2_500.0, 3_700.0])
                };
                (
                    cycle * b as f64 + group * (slot / 4) as f64 + within[slot % 4],
                    b,
                )
            }
            Self::Vls128 => {
                // Dual: one column a packet (sequence 0), blocks 2b and 2b + 1 of bank b.
                let (seq, bank) = if dual {
                    (0, (block / 2) % 4)
                } else {
                    (block / 4, block % 4)
                };
                let laser = bank * SLOTS + slot;
                let group = laser / 8 + laser / 64;
                (53_300.0 * seq as f64 + 2_665.0 * group as f64, seq)
            }
        }
    }

    /// The block at whose first firing `block`'s azimuth was read: the block itself, except on
    /// the VLS-128, whose four blocks of one firing sequence (banks 0–3) all carry the azimuth
    /// of the sequence's start (VLS-128 manual, packet format; on nebula's real capture every
    /// run of four blocks has one azimuth). Interpolating from a bank's own first firing would
    /// lose its offset in the sequence: up to 13 firing groups, 35 µs, 0.12° at 600 rpm.
    #[inline]
    pub fn azimuth_block(self, mode: ReturnMode, block: usize) -> usize {
        match self {
            // Dual: the packet's one column starts at block 0.
            Self::Vls128 if mode.is_dual() => 0,
            Self::Vls128 => block - block % 4,
            _ => block,
        }
    }

    /// Offset from the packet's time stamp (bytes 1200..1204) to its first firing, ns.
    pub fn stamp_to_first_firing_ns(self) -> i64 {
        match self {
            Self::Vls128 => -8_700,
            _ => 0,
        }
    }

    /// Firing columns per packet (the largest column index of any slot, plus one).
    pub fn columns_per_packet(self, mode: ReturnMode) -> usize {
        (0..SLOTS)
            .map(|s| self.firing(mode, BLOCKS - 1, s).1)
            .max()
            .unwrap_or(0)
            + 1
    }

    /// Time between the first firings of two consecutive columns, ns (datasheet constants).
    pub fn column_period_ns(self) -> f64 {
        match self {
            Self::Vlp16 | Self::PuckHiRes | Self::Vlp32c => 55_296.0,
            Self::Hdl32e => 46_080.0,
            Self::Hdl64eS2 => 48_000.0,
            Self::Hdl64eS3 => 57_600.0,
            Self::Vls128 => 53_300.0,
        }
    }

    /// Nominal time between two packets' stamps, ns (columns × column period).
    pub fn packet_period_ns(self, mode: ReturnMode) -> f64 {
        self.column_period_ns() * self.columns_per_packet(mode) as f64
    }
}

impl fmt::Display for VelodyneModel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packet_periods_match_the_datasheets() {
        // VLP-16 manual: 24 firing sequences of 55.296 µs per packet = 1327.104 µs.
        assert_eq!(
            VelodyneModel::Vlp16.packet_period_ns(ReturnMode::Strongest),
            1_327_104.0
        );
        // Dual: 12 sequences.
        assert_eq!(
            VelodyneModel::Vlp16.packet_period_ns(ReturnMode::Dual),
            663_552.0
        );
        // HDL-32E: 12 blocks × 46.08 µs = 552.96 µs (the captures show 552-553 µs).
        assert_eq!(
            VelodyneModel::Hdl32e.packet_period_ns(ReturnMode::Strongest),
            552_960.0
        );
        // VLP-32C: 12 × 55.296 = 663.552 µs (664 µs in the nebula capture).
        assert_eq!(
            VelodyneModel::Vlp32c.packet_period_ns(ReturnMode::Strongest),
            663_552.0
        );
        // HDL-64E S2: 6 firings × 48 µs.
        assert_eq!(
            VelodyneModel::Hdl64eS2.packet_period_ns(ReturnMode::Strongest),
            288_000.0
        );
        assert_eq!(
            VelodyneModel::Hdl64eS3.packet_period_ns(ReturnMode::Dual),
            172_800.0
        );
        // VLS-128: three 53.3 µs sequences a packet; in dual return one, in blocks 0-7.
        let v = VelodyneModel::Vls128;
        assert_eq!(v.packet_period_ns(ReturnMode::Strongest), 159_900.0);
        assert_eq!(v.packet_period_ns(ReturnMode::Dual), 53_300.0);
        assert_eq!(v.columns_per_packet(ReturnMode::Dual), 1);
        assert_eq!(v.blocks_used(ReturnMode::Dual), 8);
        assert_eq!(v.blocks_used(ReturnMode::Strongest), 12);
    }

    #[test]
    fn vls128_dual_return_pairs_blocks_bank_by_bank() {
        let v = VelodyneModel::Vls128;
        let d = ReturnMode::Dual;
        for bank in 0..4 {
            // Last return in block 2·bank, strongest in 2·bank + 1, both of that bank.
            assert_eq!(v.dual_pair(0, bank), (2 * bank, 2 * bank + 1));
            assert_eq!(v.bank_of_block(d, 2 * bank), bank);
            assert_eq!(v.bank_of_block(d, 2 * bank + 1), bank);
            for slot in [0, 7, 8, 31] {
                // Laser 32·bank + slot fires in group laser/8 + laser/64, 2.665 µs apart,
                // in the packet's one sequence: as in the first column of a single-return
                // packet.
                let laser = 32 * bank + slot;
                let t = 2_665.0 * (laser / 8 + laser / 64) as f64;
                assert_eq!(v.firing(d, 2 * bank, slot), (t, 0));
                assert_eq!(v.firing(d, 2 * bank + 1, slot), (t, 0));
                assert_eq!(v.firing(ReturnMode::Strongest, bank, slot), (t, 0));
            }
        }
        // Every block's azimuth is the sequence start's.
        assert!((0..12).all(|b| v.azimuth_block(d, b) == 0));
        // Other models: the two halves of a group (HDL-64E: strongest first).
        assert_eq!(VelodyneModel::Hdl32e.dual_pair(4, 0), (4, 5));
        assert_eq!(VelodyneModel::Hdl64eS3.dual_pair(4, 1), (7, 5));
    }

    #[test]
    fn firing_offsets_follow_the_manual_formulas() {
        let m = VelodyneModel::Vlp16;
        // t = 55.296·(2·block + ch/16) + 2.304·(ch%16) µs.
        assert_eq!(
            m.firing(ReturnMode::Strongest, 3, 20),
            (55_296.0 * 7.0 + 2_304.0 * 4.0, 7)
        );
        assert_eq!(
            m.firing(ReturnMode::Dual, 3, 20),
            (55_296.0 * 3.0 + 2_304.0 * 4.0, 3)
        );
        assert_eq!(
            VelodyneModel::Vlp32c.firing(ReturnMode::Strongest, 2, 5).0,
            55_296.0 * 2.0 + 2_304.0 * 2.0
        );
        assert_eq!(
            VelodyneModel::Hdl32e.firing(ReturnMode::Strongest, 2, 5).0,
            46_080.0 * 2.0 + 1_152.0 * 5.0
        );
        assert_eq!(
            VelodyneModel::Hdl64eS2
                .firing(ReturnMode::Strongest, 3, 6)
                .0,
            48_000.0 + 6_000.0 + 2_460.0
        );
    }

    #[test]
    fn ids_round_trip() {
        for m in ALL_MODELS {
            assert_eq!(VelodyneModel::from_id(m.id()), Some(m));
            if let Some(p) = m.product_id() {
                assert_eq!(VelodyneModel::from_product_id(p), Some(m));
            }
        }
        assert_eq!(
            VelodyneModel::from_id("HDL-64E_S3"),
            Some(VelodyneModel::Hdl64eS3)
        );
        assert_eq!(VelodyneModel::from_id("nope"), None);
    }
}
