//! Ouster packet formats as data: profiles, pixel field layouts, header variants.
//!
//! Source for every offset: ouster-sdk `ouster_core/src/parsing.cpp` (tables
//! `LEGACY_FIELD_INFO`, `SINGLE_FIELD_INFO`, `DUAL_FIELD_INFO`, `LB_FIELD_INFO`,
//! `FIVE_WORD_PIXEL_INFO`; `PacketFormat::Impl`), cross-checked with the FW 1.14 / 2.x user
//! guides (FORMATS.md §5.2). One decoder serves every profile by reading these tables.

use core::fmt;

/// A pixel field: where it sits in the pixel, how wide it is, how it is scaled.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Field {
    /// Bit offset from the pixel's first byte (little-endian bit order).
    pub bit: u16,
    /// Width in bits (≤ 32).
    pub width: u8,
    /// Left shift applied after extraction (RNG15 ranges are in 8 mm units: ≪ 3; NIR8 ≪ 4).
    pub shift: u8,
}

impl Field {
    const fn new(bit: u16, width: u8, shift: u8) -> Self {
        Self { bit, width, shift }
    }
}

/// Which header / footer layout the lidar packets use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum HeaderKind {
    /// No packet header or footer; each column carries timestamp, measurement id, frame id,
    /// encoder count and a trailing status word (FW < 2.2 or profile LEGACY).
    Legacy,
    /// 32-byte packet header (packet_type u16 @0, frame_id u16 @2, init_id u24 @4,
    /// prod_sn u40 @7, …) and 32-byte footer (CRC-64 in the last 8 bytes from FW 2.5).
    Standard,
    /// FUSA header (FW 3.1+ FUSA profiles): packet_type u8 @0, init_id u24 @1,
    /// frame_id u32 @4, alert_flags @8, prod_sn u40 @11; footer without CRC.
    Fusa,
}

/// A lidar UDP profile (`udp_profile_lidar`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Profile {
    /// LEGACY: 12-byte pixels, per-column header with encoder count and status trailer.
    Legacy,
    /// RNG19_RFL8_SIG16_NIR16 (single return, 12-byte pixels).
    Rng19Rfl8Sig16Nir16,
    /// RNG19_RFL8_SIG16_NIR16_DUAL (16-byte pixels).
    Rng19Rfl8Sig16Nir16Dual,
    /// RNG15_RFL8_NIR8 (low data rate, 4-byte pixels).
    Rng15Rfl8Nir8,
    /// RNG15_RFL8_NIR8_DUAL (8-byte pixels).
    Rng15Rfl8Nir8Dual,
    /// FUSA_RNG15_RFL8_NIR8_DUAL (8-byte pixels, FUSA header).
    FusaRng15Rfl8Nir8Dual,
    /// FIVE_WORD_PIXEL (20-byte pixels, dual).
    FiveWordPixel,
    /// RNG15_RFL8_WIN8 (4-byte pixels).
    Rng15Rfl8Win8,
    /// RNG15_RFL8_NIR8_ZONE16 (FW 3.2 zone monitoring: the low-data pixel and a 16-bit zone
    /// mask, 8-byte pixels).
    Rng15Rfl8Nir8Zone16,
    /// RNG19_RFL8_SIG16_NIR16_ZONE16 (the single-return pixel with its two spare bytes
    /// holding the zone mask, 12-byte pixels).
    Rng19Rfl8Sig16Nir16Zone16,
    /// RNG19_RFL8_SIG16_ZONE16_DUAL (the dual-return pixel with the zone mask where near-IR
    /// was: no near-IR, 16-byte pixels).
    Rng19Rfl8Sig16Zone16Dual,
    /// RNG19_RFL8_SIG16_NIR16_RGB16 (a single-return pixel packed tighter than
    /// RNG19_RFL8_SIG16_NIR16, reflectivity beside the range, then three 16-bit colour
    /// channels: 16-byte pixels).
    Rng19Rfl8Sig16Nir16Rgb16,
    /// RNG19_RFL8_SIG16_NIR16_RGB16_DUAL (the dual-return pixel and three 16-bit colour
    /// channels after the near-IR: 20-byte pixels).
    Rng19Rfl8Sig16Nir16Rgb16Dual,
}

/// The fields of one profile (None where the profile lacks the field).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    /// Bytes per pixel.
    pub pixel_bytes: usize,
    /// Range of the first return, mm after the shift.
    pub range: Field,
    /// Flags of the first return.
    pub flags: Option<Field>,
    /// Reflectivity of the first return.
    pub reflectivity: Field,
    /// Signal photons of the first return.
    pub signal: Option<Field>,
    /// Near-infrared (ambient) photons.
    pub near_ir: Option<Field>,
    /// Range of the second return.
    pub range2: Option<Field>,
    /// Flags of the second return.
    pub flags2: Option<Field>,
    /// Reflectivity of the second return.
    pub reflectivity2: Option<Field>,
    /// Signal of the second return.
    pub signal2: Option<Field>,
    /// The pixel's zone-occupancy mask (ZONE16 profiles; ouster-sdk `ZONE_MASK`): bit `i` set
    /// when the return lies in zone `i`. The same for both returns.
    pub zones: Option<Field>,
    /// The pixel's red channel (RGB16 profiles); green and blue follow at +16 and +32 bits.
    /// Each is an IEEE half float (ouster-sdk holds `RGB` as `FLOAT16`).
    pub red: Option<Field>,
}

impl Layout {
    /// The red, green and blue fields, where the profile has them.
    pub fn rgb(&self) -> Option<[Field; 3]> {
        self.red.map(|r| {
            let at = |k: u16| Field {
                bit: r.bit + 16 * k,
                ..r
            };
            [r, at(1), at(2)]
        })
    }
}

/// Every profile, for iteration.
pub const ALL_PROFILES: [Profile; 13] = [
    Profile::Legacy,
    Profile::Rng19Rfl8Sig16Nir16,
    Profile::Rng19Rfl8Sig16Nir16Dual,
    Profile::Rng15Rfl8Nir8,
    Profile::Rng15Rfl8Nir8Dual,
    Profile::FusaRng15Rfl8Nir8Dual,
    Profile::FiveWordPixel,
    Profile::Rng15Rfl8Win8,
    Profile::Rng15Rfl8Nir8Zone16,
    Profile::Rng19Rfl8Sig16Nir16Zone16,
    Profile::Rng19Rfl8Sig16Zone16Dual,
    Profile::Rng19Rfl8Sig16Nir16Rgb16,
    Profile::Rng19Rfl8Sig16Nir16Rgb16Dual,
];

impl Profile {
    /// The metadata name, e.g. `RNG19_RFL8_SIG16_NIR16_DUAL`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Legacy => "LEGACY",
            Self::Rng19Rfl8Sig16Nir16 => "RNG19_RFL8_SIG16_NIR16",
            Self::Rng19Rfl8Sig16Nir16Dual => "RNG19_RFL8_SIG16_NIR16_DUAL",
            Self::Rng15Rfl8Nir8 => "RNG15_RFL8_NIR8",
            Self::Rng15Rfl8Nir8Dual => "RNG15_RFL8_NIR8_DUAL",
            Self::FusaRng15Rfl8Nir8Dual => "FUSA_RNG15_RFL8_NIR8_DUAL",
            Self::FiveWordPixel => "FIVE_WORD_PIXEL",
            Self::Rng15Rfl8Win8 => "RNG15_RFL8_WIN8",
            Self::Rng15Rfl8Nir8Zone16 => "RNG15_RFL8_NIR8_ZONE16",
            Self::Rng19Rfl8Sig16Nir16Zone16 => "RNG19_RFL8_SIG16_NIR16_ZONE16",
            Self::Rng19Rfl8Sig16Zone16Dual => "RNG19_RFL8_SIG16_ZONE16_DUAL",
            Self::Rng19Rfl8Sig16Nir16Rgb16 => "RNG19_RFL8_SIG16_NIR16_RGB16",
            Self::Rng19Rfl8Sig16Nir16Rgb16Dual => "RNG19_RFL8_SIG16_NIR16_RGB16_DUAL",
        }
    }

    /// Parses a metadata name (exact, as `udp_profile_lidar` writes it).
    pub fn from_name(s: &str) -> Option<Self> {
        ALL_PROFILES.into_iter().find(|p| p.name() == s)
    }

    /// Header layout: none for LEGACY, FUSA for the FUSA profile, else standard. This is
    /// ouster-sdk's default; the SDK reads the layout from the metadata's
    /// `lidar_data_format.header_type` (`STANDARD` / `FUSA`) when present, and both layouts
    /// have the same size, so only the field offsets differ (the decoder and the encoder
    /// accept another layout: `OusterDecoder::with_header_kind`, `OusterEncoder::with_header`).
    pub fn header(self) -> HeaderKind {
        match self {
            Self::Legacy => HeaderKind::Legacy,
            Self::FusaRng15Rfl8Nir8Dual => HeaderKind::Fusa,
            _ => HeaderKind::Standard,
        }
    }

    /// Whether the profile carries two returns.
    pub fn is_dual(self) -> bool {
        self.layout().range2.is_some()
    }

    /// The pixel layout.
    pub fn layout(self) -> Layout {
        let f = Field::new;
        let mut l = match self {
            Self::Legacy => Layout {
                pixel_bytes: 12,
                range: f(0, 20, 0),
                flags: Some(f(28, 4, 0)),
                reflectivity: f(32, 8, 0),
                signal: Some(f(48, 16, 0)),
                near_ir: Some(f(64, 16, 0)),
                range2: None,
                flags2: None,
                reflectivity2: None,
                signal2: None,
                zones: None,
                red: None,
            },
            Self::Rng19Rfl8Sig16Nir16 | Self::Rng19Rfl8Sig16Nir16Zone16 => Layout {
                pixel_bytes: 12,
                range: f(0, 19, 0),
                flags: Some(f(19, 5, 0)),
                reflectivity: f(32, 8, 0),
                signal: Some(f(48, 16, 0)),
                near_ir: Some(f(64, 16, 0)),
                range2: None,
                flags2: None,
                reflectivity2: None,
                signal2: None,
                zones: None,
                red: None,
            },
            Self::Rng19Rfl8Sig16Nir16Dual | Self::Rng19Rfl8Sig16Zone16Dual => Layout {
                pixel_bytes: 16,
                range: f(0, 19, 0),
                flags: Some(f(19, 5, 0)),
                reflectivity: f(24, 8, 0),
                signal: Some(f(64, 16, 0)),
                near_ir: (self == Self::Rng19Rfl8Sig16Nir16Dual).then_some(f(96, 16, 0)),
                range2: Some(f(32, 19, 0)),
                flags2: Some(f(51, 5, 0)),
                reflectivity2: Some(f(56, 8, 0)),
                signal2: Some(f(80, 16, 0)),
                zones: None,
                red: None,
            },
            Self::Rng15Rfl8Nir8 | Self::Rng15Rfl8Win8 | Self::Rng15Rfl8Nir8Zone16 => Layout {
                pixel_bytes: if self == Self::Rng15Rfl8Nir8Zone16 {
                    8
                } else {
                    4
                },
                range: f(0, 15, 3),
                flags: Some(f(15, 1, 0)),
                reflectivity: f(16, 8, 0),
                signal: None,
                near_ir: if self != Self::Rng15Rfl8Win8 {
                    Some(f(24, 8, 4))
                } else {
                    None
                },
                range2: None,
                flags2: None,
                reflectivity2: None,
                signal2: None,
                zones: None,
                red: None,
            },
            Self::Rng15Rfl8Nir8Dual | Self::FusaRng15Rfl8Nir8Dual => Layout {
                pixel_bytes: 8,
                range: f(0, 15, 3),
                flags: Some(f(15, 1, 0)),
                reflectivity: f(16, 8, 0),
                signal: None,
                near_ir: Some(f(24, 8, 4)),
                range2: Some(f(32, 15, 3)),
                flags2: Some(f(47, 1, 0)),
                reflectivity2: Some(f(48, 8, 0)),
                signal2: None,
                zones: None,
                red: None,
            },
            Self::Rng19Rfl8Sig16Nir16Rgb16 => Layout {
                pixel_bytes: 16,
                range: f(0, 19, 0),
                flags: Some(f(19, 5, 0)),
                reflectivity: f(24, 8, 0),
                signal: Some(f(32, 16, 0)),
                near_ir: Some(f(48, 16, 0)),
                range2: None,
                flags2: None,
                reflectivity2: None,
                signal2: None,
                zones: None,
                red: None,
            },
            Self::FiveWordPixel | Self::Rng19Rfl8Sig16Nir16Rgb16Dual => Layout {
                pixel_bytes: 20,
                range: f(0, 19, 0),
                flags: Some(f(19, 5, 0)),
                reflectivity: f(24, 8, 0),
                signal: Some(f(64, 16, 0)),
                near_ir: Some(f(96, 16, 0)),
                range2: Some(f(32, 19, 0)),
                flags2: Some(f(51, 5, 0)),
                reflectivity2: Some(f(56, 8, 0)),
                signal2: Some(f(80, 16, 0)),
                zones: None,
                red: None,
            },
        };
        // ouster-sdk's `ZM_LB_FIELD_INFO`, `ZM_SINGLE_FIELD_INFO`, `DUAL_ZONE_FIELD_INFO`,
        // `RGB_FIELD_INFO`, `DUAL_RGB_FIELD_INFO`.
        l.zones = match self {
            Self::Rng15Rfl8Nir8Zone16 => Some(f(32, 16, 0)),
            Self::Rng19Rfl8Sig16Nir16Zone16 => Some(f(80, 16, 0)),
            Self::Rng19Rfl8Sig16Zone16Dual => Some(f(96, 16, 0)),
            _ => None,
        };
        l.red = match self {
            Self::Rng19Rfl8Sig16Nir16Rgb16 => Some(f(64, 16, 0)),
            Self::Rng19Rfl8Sig16Nir16Rgb16Dual => Some(f(112, 16, 0)),
            _ => None,
        };
        l
    }
}

impl fmt::Display for Profile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Sizes of one lidar packet, from the profile and the metadata's column / pixel counts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PacketFormat {
    /// The profile.
    pub profile: Profile,
    /// Columns per packet (16 typical).
    pub columns_per_packet: usize,
    /// Pixels per column = channels (16, 32, 64, 128).
    pub pixels_per_column: usize,
}

impl PacketFormat {
    /// Packet header bytes (0 for LEGACY).
    pub fn header_bytes(&self) -> usize {
        if self.profile.header() == HeaderKind::Legacy {
            0
        } else {
            32
        }
    }

    /// Footer bytes (0 for LEGACY).
    pub fn footer_bytes(&self) -> usize {
        self.header_bytes()
    }

    /// Column header bytes: LEGACY 16 (ts, measurement id, frame id, encoder), else 12.
    pub fn column_header_bytes(&self) -> usize {
        if self.profile == Profile::Legacy {
            16
        } else {
            12
        }
    }

    /// Column trailer bytes: LEGACY 4 (status word), else 0.
    pub fn column_trailer_bytes(&self) -> usize {
        if self.profile == Profile::Legacy {
            4
        } else {
            0
        }
    }

    /// Bytes of one column.
    pub fn column_bytes(&self) -> usize {
        self.column_header_bytes()
            + self.pixels_per_column * self.profile.layout().pixel_bytes
            + self.column_trailer_bytes()
    }

    /// Bytes of one lidar packet.
    pub fn packet_bytes(&self) -> usize {
        self.header_bytes() + self.columns_per_packet * self.column_bytes() + self.footer_bytes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packet_sizes_match_the_documented_ones() {
        // FORMATS.md §5.2 (C = 16 columns).
        let size = |profile, h| {
            PacketFormat {
                profile,
                columns_per_packet: 16,
                pixels_per_column: h,
            }
            .packet_bytes()
        };
        assert_eq!(size(Profile::Legacy, 16), 3392);
        assert_eq!(size(Profile::Legacy, 32), 6464);
        assert_eq!(size(Profile::Legacy, 64), 12608);
        assert_eq!(size(Profile::Legacy, 128), 24896);
        assert_eq!(size(Profile::Rng19Rfl8Sig16Nir16, 64), 12544);
        assert_eq!(size(Profile::Rng19Rfl8Sig16Nir16Dual, 64), 16640);
        assert_eq!(size(Profile::Rng15Rfl8Nir8, 64), 4352);
        assert_eq!(size(Profile::FiveWordPixel, 64), 20736);
        assert_eq!(size(Profile::Rng19Rfl8Sig16Nir16, 128), 24832);
        assert_eq!(size(Profile::Rng19Rfl8Sig16Nir16Dual, 128), 33024);
        assert_eq!(size(Profile::Rng15Rfl8Nir8, 128), 8448);
        assert_eq!(size(Profile::FusaRng15Rfl8Nir8Dual, 128), 16640);
        assert_eq!(size(Profile::Rng19Rfl8Sig16Nir16, 32), 6400);
        assert_eq!(size(Profile::Rng19Rfl8Sig16Nir16Dual, 32), 8448);
        assert_eq!(size(Profile::Rng15Rfl8Nir8, 32), 2304);
    }

    #[test]
    fn names_round_trip() {
        for p in ALL_PROFILES {
            assert_eq!(Profile::from_name(p.name()), Some(p));
        }
    }

    /// The zone mask and the colour channels at ouster-sdk's offsets (`ZONE_MASK`, `R`, `G`,
    /// `B` of `ZM_LB_FIELD_INFO`, `ZM_SINGLE_FIELD_INFO`, `DUAL_ZONE_FIELD_INFO`,
    /// `RGB_FIELD_INFO`, `DUAL_RGB_FIELD_INFO`), each written into a pixel whose other bytes
    /// are all ones; the other profiles have neither.
    #[test]
    fn zone_mask_and_colour_read_the_sdk_offsets() {
        use crate::sensor::ouster::wire::read_field_at;
        let zoned = [
            (Profile::Rng15Rfl8Nir8Zone16, 8, 4),
            (Profile::Rng19Rfl8Sig16Nir16Zone16, 12, 10),
            (Profile::Rng19Rfl8Sig16Zone16Dual, 16, 12),
        ];
        for (p, n, at) in zoned {
            let l = p.layout();
            let mut px = vec![0xFFu8; n];
            px[at..at + 2].copy_from_slice(&0xA5C3u16.to_le_bytes());
            assert_eq!(l.pixel_bytes, n);
            assert_eq!(
                l.zones.map(|f| read_field_at(&px, 0, f)),
                Some(0xA5C3),
                "{p}"
            );
            assert_eq!(l.rgb(), None, "{p}");
        }
        let coloured = [
            (Profile::Rng19Rfl8Sig16Nir16Rgb16, 16, 8),
            (Profile::Rng19Rfl8Sig16Nir16Rgb16Dual, 20, 14),
        ];
        for (p, n, at) in coloured {
            let l = p.layout();
            let mut px = vec![0xFFu8; n];
            for (k, v) in [0x3C00u16, 0x4000, 0x4200].into_iter().enumerate() {
                px[at + 2 * k..at + 2 * k + 2].copy_from_slice(&v.to_le_bytes());
            }
            let rgb = l.rgb().map(|c| c.map(|f| read_field_at(&px, 0, f)));
            assert_eq!(rgb, Some([0x3C00, 0x4000, 0x4200]), "{p}");
            assert_eq!(l.zones, None, "{p}");
        }
        for p in ALL_PROFILES {
            if !zoned.iter().any(|z| z.0 == p) && !coloured.iter().any(|c| c.0 == p) {
                assert_eq!((p.layout().zones, p.layout().rgb()), (None, None), "{p}");
            }
        }
    }

    /// One pixel of each zone-monitoring profile written byte by byte from ouster-sdk's
    /// tables (`ZM_LB_FIELD_INFO`, `ZM_SINGLE_FIELD_INFO`, `DUAL_ZONE_FIELD_INFO`), the zone
    /// mask and the window byte all ones: no field reads into them.
    #[test]
    fn zone_profile_pixels_read_the_sdk_offsets() {
        use crate::sensor::ouster::wire::read_field_at;
        let read = |px: &[u8], f: Option<Field>| f.map(|f| read_field_at(px, 0, f));

        // RNG15_RFL8_NIR8_ZONE16: range/8 (15 bits) + flag, reflectivity, near-IR/16, zone
        // mask u16 @4, window @6, one spare byte.
        let l = Profile::Rng15Rfl8Nir8Zone16.layout();
        let px = [0x39, 0x30 | 0x80, 200, 77, 0xFF, 0xFF, 0xFF, 0x00];
        assert_eq!(l.pixel_bytes, 8);
        assert_eq!(read(&px, Some(l.range)), Some(0x3039 * 8));
        assert_eq!(read(&px, l.flags), Some(1));
        assert_eq!(read(&px, Some(l.reflectivity)), Some(200));
        assert_eq!(read(&px, l.near_ir), Some(77 * 16));
        assert_eq!((read(&px, l.signal), read(&px, l.range2)), (None, None));

        // RNG19_RFL8_SIG16_NIR16_ZONE16: range (19 bits) + flags, reflectivity @4, window @5,
        // signal @6, near-IR @8, zone mask @10.
        let l = Profile::Rng19Rfl8Sig16Nir16Zone16.layout();
        let mut px = [0u8; 12];
        px[..4].copy_from_slice(&(123_456u32 | 0b10101 << 19 | 0xFF << 24).to_le_bytes());
        px[4] = 201;
        px[5] = 0xFF;
        px[6..8].copy_from_slice(&0x1234u16.to_le_bytes());
        px[8..10].copy_from_slice(&0x5678u16.to_le_bytes());
        px[10..12].copy_from_slice(&[0xFF, 0xFF]);
        assert_eq!(l.pixel_bytes, 12);
        assert_eq!(read(&px, Some(l.range)), Some(123_456));
        assert_eq!(read(&px, l.flags), Some(0b10101));
        assert_eq!(read(&px, Some(l.reflectivity)), Some(201));
        assert_eq!(read(&px, l.signal), Some(0x1234));
        assert_eq!(read(&px, l.near_ir), Some(0x5678));

        // RNG19_RFL8_SIG16_ZONE16_DUAL: two returns (range, flags, reflectivity) @0 and @4,
        // signals @8 and @10, zone mask @12 where the dual profile has near-IR, window @15.
        let l = Profile::Rng19Rfl8Sig16Zone16Dual.layout();
        let mut px = [0u8; 16];
        px[..4].copy_from_slice(&(4_000u32 | 3 << 19 | 17 << 24).to_le_bytes());
        px[4..8].copy_from_slice(&(524_287u32 | 0b11111 << 19 | 250 << 24).to_le_bytes());
        px[8..10].copy_from_slice(&1_000u16.to_le_bytes());
        px[10..12].copy_from_slice(&2_000u16.to_le_bytes());
        px[12..14].copy_from_slice(&[0xFF, 0xFF]);
        px[14] = 0xFF;
        px[15] = 0xFF;
        assert_eq!(l.pixel_bytes, 16);
        assert_eq!(read(&px, Some(l.range)), Some(4_000));
        assert_eq!(read(&px, l.flags), Some(3));
        assert_eq!(read(&px, Some(l.reflectivity)), Some(17));
        assert_eq!(read(&px, l.range2), Some(524_287));
        assert_eq!(read(&px, l.flags2), Some(0b11111));
        assert_eq!(read(&px, l.reflectivity2), Some(250));
        assert_eq!(
            (read(&px, l.signal), read(&px, l.signal2)),
            (Some(1_000), Some(2_000))
        );
        assert_eq!(l.near_ir, None);
    }

    /// One pixel of each colour profile written byte by byte from ouster-sdk's tables
    /// (`RGB_FIELD_INFO`, `DUAL_RGB_FIELD_INFO`), the colour channels all ones: no field reads
    /// into them.
    #[test]
    fn rgb_profile_pixels_read_the_sdk_offsets() {
        use crate::sensor::ouster::wire::read_field_at;
        let read = |px: &[u8], f: Option<Field>| f.map(|f| read_field_at(px, 0, f));

        // RNG19_RFL8_SIG16_NIR16_RGB16: range (19 bits) + flags, reflectivity @3, signal @4,
        // near-IR @6, R G B @8, @10, @12, two spare bytes.
        let l = Profile::Rng19Rfl8Sig16Nir16Rgb16.layout();
        let mut px = [0xFFu8; 16];
        px[..4].copy_from_slice(&(98_765u32 | 0b01010 << 19 | 199 << 24).to_le_bytes());
        px[4..6].copy_from_slice(&0x4321u16.to_le_bytes());
        px[6..8].copy_from_slice(&0x8765u16.to_le_bytes());
        assert_eq!(l.pixel_bytes, 16);
        assert_eq!(read(&px, Some(l.range)), Some(98_765));
        assert_eq!(read(&px, l.flags), Some(0b01010));
        assert_eq!(read(&px, Some(l.reflectivity)), Some(199));
        assert_eq!(read(&px, l.signal), Some(0x4321));
        assert_eq!(read(&px, l.near_ir), Some(0x8765));
        assert_eq!((read(&px, l.range2), read(&px, l.signal2)), (None, None));

        // RNG19_RFL8_SIG16_NIR16_RGB16_DUAL: two returns @0 and @4, signals @8 and @10,
        // near-IR @12, R G B @14, @16, @18.
        let l = Profile::Rng19Rfl8Sig16Nir16Rgb16Dual.layout();
        let mut px = [0xFFu8; 20];
        px[..4].copy_from_slice(&(7_000u32 | 1 << 19 | 33 << 24).to_le_bytes());
        px[4..8].copy_from_slice(&(300_000u32 | 0b00110 << 19 | 44 << 24).to_le_bytes());
        px[8..10].copy_from_slice(&1_111u16.to_le_bytes());
        px[10..12].copy_from_slice(&2_222u16.to_le_bytes());
        px[12..14].copy_from_slice(&3_333u16.to_le_bytes());
        assert_eq!(l.pixel_bytes, 20);
        assert_eq!(read(&px, Some(l.range)), Some(7_000));
        assert_eq!(read(&px, l.flags), Some(1));
        assert_eq!(read(&px, Some(l.reflectivity)), Some(33));
        assert_eq!(read(&px, l.range2), Some(300_000));
        assert_eq!(read(&px, l.flags2), Some(0b00110));
        assert_eq!(read(&px, l.reflectivity2), Some(44));
        assert_eq!(
            (
                read(&px, l.signal),
                read(&px, l.signal2),
                read(&px, l.near_ir)
            ),
            (Some(1_111), Some(2_222), Some(3_333))
        );
    }
}
