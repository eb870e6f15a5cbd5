//! Ouster sensor metadata (the JSON the sensor or the SDK writes) into one validated
//! calibration: the legacy flat form, the FW 1.12/1.13 nested form (where `lidar_data_format`
//! is a string) and the current nested form, with exactly ouster-sdk's defaults where a value
//! is absent (`ouster_core/src/metadata.cpp`, `sensor_info.cpp`, `data_format.cpp`).
//!
//! # Layouts
//!
//! ouster-sdk calls a file *nested* ("non-legacy") when it has all seven sections
//! `sensor_info`, `beam_intrinsics`, `imu_intrinsics`, `lidar_intrinsics`, `config_params`,
//! `lidar_data_format` and `calibration_status`, *legacy* (flat) when it has none of them, and
//! refuses a file with some but not all (`parse_and_validate_metadata`). The same rule holds
//! here. A legacy file is read as the SDK's `convert_legacy_to_nonlegacy` reads it: only
//! `lidar_mode`, `udp_port_lidar` and `udp_port_imu` become configuration (a flat
//! `timestamp_mode` or `udp_dest` is not looked at), `data_format` is the lidar data format, and
//! the beam intrinsics, transforms and sensor fields are top-level keys. FW 1.12/1.13 nested
//! files carry the string `"error: Command not recognized."` in `lidar_data_format` (and
//! `calibration_status`): such a data format is absent, and everything comes from the lidar mode
//! and product line.
//!
//! # Defaults (exactly ouster-sdk 1.0.1's)
//!
//! | value | when absent |
//! | --- | --- |
//! | columns per frame, fps | from `lidar_mode` (`default_data_format`) |
//! | pixels per column | the product line's beam count (`OS-1-128` → 128), else 64 |
//! | columns per packet | [`DEFAULT_COLUMNS_PER_PACKET`] (16) |
//! | column window | `[0, W − 1]` |
//! | `pixel_shift_by_row` | [`default_pixel_shift_by_row`]: `{3k, 2k, k, 0}` repeated for the first 64 rows with `k = 3·W/512` (W = 1024: 18, 12, 6, 0), zero for rows 64 and up; the beam azimuth angles play no part. Without a lidar mode the SDK has no default format, and the shifts are all zero |
//! | lidar / IMU profile | `LEGACY` / `LEGACY` |
//! | UDP ports | [`DEFAULT_UDP_PORT_LIDAR`] 7502, [`DEFAULT_UDP_PORT_IMU`] 7503 (the SDK itself leaves them unset; 7502/7503 is what its pcap source and the sensor use) |
//! | `lidar_origin_to_beam_origin_mm` | [`default_lidar_origin_to_beam_origin_mm`]: 27.67 (`OS-0-…`), 15.806 (`OS-1-…`), 13.762 (`OS-2-…`), 12.163 (anything else, including no product line) |
//! | `beam_to_lidar_transform` | identity with `[0][3]` = the beam-origin offset |
//! | `lidar_to_sensor_transform` | [`DEFAULT_LIDAR_TO_SENSOR`]: diag(−1, −1, 1) with z = 36.18 mm |
//! | `imu_to_sensor_transform` | [`DEFAULT_IMU_TO_SENSOR`]: translation (6.253, −11.775, 7.645) mm |
//! | serial, `initialization_id` | 0 |
//! | timestamp mode | [`TimestampMode::InternalOsc`] |
//!
//! The SDK reports the lidar profile as `OFF` — no lidar packets — when `udp_port_lidar` is 0
//! or `udp_dest` (else `udp_ip`) is an empty string, whatever profile the file names; so does
//! [`OusterInfo::lidar_off`].
//!
//! # Where ringscan is stricter than the SDK
//!
//! ouster-sdk logs most problems as "information" and carries on with a default; only missing
//! or miscounted beam angles and a mixed layout are fatal there. A decoder that silently uses a
//! default where the file says something else produces wrong points, so this parser refuses:
//! values of the wrong JSON type (including `null`) for any key it reads; lidar modes other than
//! `512x10`, `512x20`, `1024x10`, `1024x20`, `2048x10`, `4096x5`; `columns_per_frame` or `fps`
//! that contradict the lidar mode; W ∉ {512, 1024, 2048, 4096}; H ∉ {16, 32, 64, 128};
//! columns per packet that do not divide W; a lidar packet larger than a UDP datagram; a column
//! window outside `[0, W)`; `pixel_shift_by_row` whose length is not H (the SDK pads or cuts)
//! or with |shift| ≥ W; unknown profile names (the SDK falls back to LEGACY); the SDK's
//! `UNKNOWN` profile unless the lidar stream is off; a `header_type`
//! that contradicts the profile; a LEGACY lidar profile with the ACCEL32_GYRO32_NMEA IMU profile
//! (the SDK's `PacketFormat` throws on that pair); beam angles that are not H plain numbers, out
//! of range, or all-zero altitudes (`malformed/complete_but_all_zeros_legacy.json`: every beam at
//! one elevation is an unwritten calibration; the SDK only warns); transforms that are not 16
//! finite numbers with a `[0, 0, 0, 1]` last row, rotation entries in [−1, 1] and translations
//! within 10 m; ports above 65535; serials of more than 40 bits and `initialization_id` of more
//! than 24 bits (the widths of the packet header fields).
//!
//! Old (FW 1.12/1.13) OS-1-16 / OS-1-32 files list 64 beam angles, zeros for the beams the
//! model lacks. The SDK refuses them (the angle count must be the product line's beam count),
//! and so does this parser: which 16 or 32 of the 64 rows a packet carries is not written in the
//! file, and no capture exists here to settle it, so picking the non-zero rows would be a guess.

use serde_json::{Map, Value};

use crate::sensor::calib::check_size;
use crate::sensor::calib::CalibError;
use crate::sensor::ouster::model::HeaderKind;
use crate::sensor::ouster::model::PacketFormat;
use crate::sensor::ouster::model::Profile;

const FORMAT: &str = "JSON";

/// Default UDP destination port of lidar packets.
pub const DEFAULT_UDP_PORT_LIDAR: u16 = 7502;
/// Default UDP destination port of IMU packets.
pub const DEFAULT_UDP_PORT_IMU: u16 = 7503;
/// Columns per lidar packet when the metadata does not say (`DEFAULT_COLUMNS_PER_PACKET`).
pub const DEFAULT_COLUMNS_PER_PACKET: usize = 16;
/// Pixels per column of the SDK's `default_data_format` (used when neither the data format nor
/// the product line gives the beam count).
pub const DEFAULT_PIXELS_PER_COLUMN: usize = 64;
/// Beam-origin offset of OS-0 sensors, mm.
pub const LIDAR_ORIGIN_TO_BEAM_ORIGIN_MM_OS0: f64 = 27.67;
/// Beam-origin offset of OS-1 sensors, mm.
pub const LIDAR_ORIGIN_TO_BEAM_ORIGIN_MM_OS1: f64 = 15.806;
/// Beam-origin offset of OS-2 sensors, mm.
pub const LIDAR_ORIGIN_TO_BEAM_ORIGIN_MM_OS2: f64 = 13.762;
/// Beam-origin offset of gen-1 sensors and of any other or unknown product line, mm.
pub const LIDAR_ORIGIN_TO_BEAM_ORIGIN_MM_GEN1: f64 = 12.163;
/// `lidar_to_sensor_transform` when absent (`DEFAULT_LIDAR_TO_SENSOR`), row-major, mm.
pub const DEFAULT_LIDAR_TO_SENSOR: [f64; 16] = [
    -1.0, 0.0, 0.0, 0.0, //
    0.0, -1.0, 0.0, 0.0, //
    0.0, 0.0, 1.0, 36.18, //
    0.0, 0.0, 0.0, 1.0,
];
/// `imu_to_sensor_transform` when absent (`DEFAULT_IMU_TO_SENSOR`), row-major, mm.
pub const DEFAULT_IMU_TO_SENSOR: [f64; 16] = [
    1.0, 0.0, 0.0, 6.253, //
    0.0, 1.0, 0.0, -11.775, //
    0.0, 0.0, 1.0, 7.645, //
    0.0, 0.0, 0.0, 1.0,
];
/// The lidar modes: (name, columns per frame, frames per second).
pub const LIDAR_MODES: [(&str, usize, u32); 6] = [
    ("512x10", 512, 10),
    ("512x20", 512, 20),
    ("1024x10", 1024, 10),
    ("1024x20", 1024, 20),
    ("2048x10", 2048, 10),
    ("4096x5", 4096, 5),
];
/// Columns per frame a sensor can have.
pub const COLUMNS_PER_FRAME: [usize; 4] = [512, 1024, 2048, 4096];
/// Pixels per column (beams) a sensor can have.
pub const PIXELS_PER_COLUMN: [usize; 4] = [16, 32, 64, 128];
/// Largest UDP payload over IPv4; a lidar packet must fit in one datagram.
pub const MAX_UDP_PAYLOAD: usize = 65_507;
/// Most IMU measurements an ACCEL32_GYRO32_NMEA packet can hold in one datagram
/// (32 B header + 100 B NMEA block + N × 36 B + 32 B footer ≤ 65 507 B).
pub const MAX_IMU_MEASUREMENTS_PER_PACKET: usize = 1815;
/// [`OusterInfo::layout`] of a legacy (flat) file.
pub const LAYOUT_LEGACY: &str = "legacy";
/// [`OusterInfo::layout`] of a FW 1.12/1.13 nested file (`lidar_data_format` is a string).
pub const LAYOUT_NESTED_1_12: &str = "nested-1.12";
/// [`OusterInfo::layout`] of a current nested file.
pub const LAYOUT_NESTED: &str = "nested";

/// The seven sections of the nested layout (`NONLEGACY_METADATA_FIELDS`).
const NESTED_SECTIONS: [&str; 7] = [
    "beam_intrinsics",
    "calibration_status",
    "config_params",
    "imu_intrinsics",
    "lidar_data_format",
    "lidar_intrinsics",
    "sensor_info",
];

/// Lidar profile names ouster-sdk 1.0.1 knows but ringscan does not decode.
const UNDECODED_PROFILES: [&str; 1] = ["UNKNOWN"];

/// How the sensor stamps its columns (`config_params.timestamp_mode`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum TimestampMode {
    /// `TIME_FROM_INTERNAL_OSC`: counts from boot.
    #[default]
    InternalOsc,
    /// `TIME_FROM_SYNC_PULSE_IN`: a sync pulse (and NMEA via the multipurpose IO).
    SyncPulseIn,
    /// `TIME_FROM_PTP_1588`: PTP, TAI.
    Ptp1588,
    /// Anything else the metadata names.
    Unknown,
}

/// IMU UDP profile.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum ImuProfile {
    /// 48-byte legacy IMU packets.
    #[default]
    Legacy,
    /// ACCEL32_GYRO32_NMEA: header + NMEA block + N measurements + footer.
    Accel32Gyro32Nmea,
    /// Off / unknown.
    Off,
}

impl ImuProfile {
    /// The metadata name, e.g. `ACCEL32_GYRO32_NMEA`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Legacy => "LEGACY",
            Self::Accel32Gyro32Nmea => "ACCEL32_GYRO32_NMEA",
            Self::Off => "OFF",
        }
    }
}

/// A validated Ouster calibration: everything the decoder and the frame assembler need.
/// Angles in degrees as the metadata gives them; transforms row-major 4×4, translations in mm.
#[derive(Clone, Debug, PartialEq)]
pub struct OusterInfo {
    /// Product line, e.g. `OS-1-128` (empty when the metadata lacks it).
    pub prod_line: String,
    /// Serial number (0 when absent).
    pub serial: u64,
    /// Firmware revision string, e.g. `v2.3.0`: `sensor_info.build_rev` (the SDK's `fw_rev`;
    /// on some builds a git hash), empty when absent. See also [`Self::image_rev`] and
    /// [`Self::firmware_version`].
    pub firmware: String,
    /// `initialization_id` (0 when absent).
    pub init_id: u32,
    /// Columns per frame (W), from the lidar mode.
    pub columns_per_frame: usize,
    /// Frames per second, from the lidar mode.
    pub fps: u32,
    /// Packet format (profile, columns per packet, pixels per column). When [`Self::lidar_off`]
    /// and the named profile is one ringscan does not decode, the profile here is LEGACY as a
    /// placeholder; [`Self::lidar_profile_name`] keeps the name.
    pub format: PacketFormat,
    /// Column window [first, last] (inclusive; may wrap through 0).
    pub column_window: (usize, usize),
    /// Per-row pixel shift for destaggering (length = pixels per column).
    pub pixel_shift_by_row: Vec<i32>,
    /// Beam altitude angles, degrees (length = pixels per column).
    pub beam_altitude_angles: Vec<f64>,
    /// Beam azimuth angles, degrees (length = pixels per column).
    pub beam_azimuth_angles: Vec<f64>,
    /// `beam_to_lidar_transform`, row-major 4×4 (mm translation).
    pub beam_to_lidar: [f64; 16],
    /// `lidar_to_sensor_transform`, row-major 4×4 (mm translation).
    pub lidar_to_sensor: [f64; 16],
    /// `imu_to_sensor_transform`, row-major 4×4 (mm translation).
    pub imu_to_sensor: [f64; 16],
    /// UDP port of lidar packets (SDK default 7502).
    pub udp_port_lidar: u16,
    /// UDP port of IMU packets (SDK default 7503).
    pub udp_port_imu: u16,
    /// UDP port of zone-monitor packets (`udp_port_zm`, FW 3.2+); 0 when the file names none.
    pub udp_port_zm: u16,
    /// IMU profile.
    pub imu_profile: ImuProfile,
    /// IMU measurements per packet (ACCEL32_GYRO32_NMEA).
    pub imu_measurements_per_packet: usize,
    /// Timestamp mode.
    pub timestamp_mode: TimestampMode,
    /// Which metadata layout the file used: `legacy`, `nested-1.12`, `nested`.
    pub layout: &'static str,
    /// `lidar_origin_to_beam_origin_mm` (the metadata's, else the product line's default). The
    /// XYZ formula uses `beam_to_lidar[3]`, which equals this unless the file gives both.
    pub lidar_origin_to_beam_origin_mm: f64,
    /// `sensor_info.image_rev`, e.g. `ousteros-image-prod-aries-v2.3.0+20220415163956` (empty
    /// when absent).
    pub image_rev: String,
    /// `udp_profile_lidar` as the file names it (`LEGACY` when absent).
    pub lidar_profile_name: String,
    /// The lidar stream is off, as ouster-sdk decides: profile `OFF`, `udp_port_lidar` 0, or an
    /// empty `udp_dest` / `udp_ip`. No lidar packets are expected.
    pub lidar_off: bool,
    /// Where the metadata came from (usually the file name), as given to [`parse`].
    pub source: String,
}

impl OusterInfo {
    /// The lidar packet format.
    pub fn packet_format(&self) -> PacketFormat {
        self.format
    }

    /// Pixels per column (H, beams).
    pub fn pixels_per_column(&self) -> usize {
        self.format.pixels_per_column
    }

    /// Columns per packet.
    pub fn columns_per_packet(&self) -> usize {
        self.format.columns_per_packet
    }

    /// Bytes of one lidar packet (0 when [`Self::lidar_off`]).
    pub fn lidar_packet_bytes(&self) -> usize {
        if self.lidar_off {
            0
        } else {
            self.format.packet_bytes()
        }
    }

    /// Whether column (measurement id) `col` lies in the column window; the window may wrap
    /// through 0. Columns ≥ W are never in it.
    pub fn is_column_in_window(&self, col: usize) -> bool {
        let (first, last) = self.column_window;
        if col >= self.columns_per_frame {
            false
        } else if first <= last {
            (first..=last).contains(&col)
        } else {
            col >= first || col <= last
        }
    }

    /// Columns in the window (the SDK's `valid_columns_per_frame`).
    pub fn columns_in_window(&self) -> usize {
        let (first, last) = self.column_window;
        if first <= last {
            last - first + 1
        } else {
            // Saturating: the fields are public, so a hand-built value may break the invariants.
            last.saturating_add(self.columns_per_frame.saturating_sub(first)) + 1
        }
    }

    /// Lidar packets in a complete frame: the packets that hold at least one column of the
    /// window (the SDK's `lidar_packets_per_frame`, including its wrap rule); 0 when
    /// [`Self::lidar_off`].
    pub fn expected_packets_per_frame(&self) -> usize {
        if self.lidar_off {
            return 0;
        }
        let cpp = self.format.columns_per_packet.max(1);
        let (first, last) = self.column_window;
        let start_packet = first / cpp;
        let end_packet = last / cpp;
        if last < first {
            let max_packets = self.columns_per_frame.div_ceil(cpp);
            if start_packet == end_packet {
                max_packets
            } else {
                max_packets.saturating_sub(start_packet) + 1 + end_packet
            }
        } else {
            end_packet - start_packet + 1
        }
    }

    /// Firmware version `(major, minor, patch)`: from [`Self::image_rev`] (as the SDK's
    /// `get_version`), else from [`Self::firmware`]; `None` when neither holds a `vX.Y.Z`.
    /// Pre-release suffixes are dropped (`v2.5.0-omega.8` → (2, 5, 0)).
    pub fn firmware_version(&self) -> Option<(u32, u32, u32)> {
        parse_firmware_version(&self.image_rev).or_else(|| parse_firmware_version(&self.firmware))
    }

    /// The firmware as people name it, e.g. `v3.2.0-alpha.1`: [`Self::firmware`] when it is a
    /// version (`v` and a digit), else the version in [`Self::image_rev`] (FW 3.x writes a git
    /// hash in `build_rev`: `ousteros-image-dev-bootes-v3.2.0-alpha.1+2024…` → `v3.2.0-alpha.1`),
    /// else [`Self::firmware`] as it is.
    pub fn firmware_label(&self) -> String {
        let is_version = |s: &str| {
            s.strip_prefix('v')
                .is_some_and(|r| r.starts_with(|c: char| c.is_ascii_digit()))
        };
        if is_version(&self.firmware) {
            return self.firmware.clone();
        }
        let image = &self.image_rev;
        let from_image = image.match_indices("-v").find_map(|(i, _)| {
            let tail = &image[i + 1..];
            let v = tail.split('+').next().unwrap_or(tail);
            is_version(v).then(|| v.to_string())
        });
        from_image.unwrap_or_else(|| self.firmware.clone())
    }

    /// Whether lidar packets carry a CRC-64 in the last 8 bytes of the footer: firmware ≥ 2.5
    /// with a standard (not LEGACY, not FUSA) header (FORMATS.md §5.2: FW 2.3/2.4 footers are
    /// not a CRC). False when the firmware version is unknown.
    pub fn lidar_packets_have_crc(&self) -> bool {
        !self.lidar_off
            && self.format.profile.header() == HeaderKind::Standard
            && self.firmware_version().is_some_and(|v| v >= (2, 5, 0))
    }

    /// Whether zone-monitor packets carry the footer CRC-64: as lidar packets, but also when
    /// the lidar stream is off (zone monitoring runs without it).
    pub fn zone_packets_have_crc(&self) -> bool {
        self.format.profile.header() != HeaderKind::Fusa
            && self.firmware_version().is_some_and(|v| v >= (2, 5, 0))
    }
}

/// The SDK's `default_lidar_origin_to_beam_origin`: by product line prefix.
pub fn default_lidar_origin_to_beam_origin_mm(prod_line: &str) -> f64 {
    if prod_line.starts_with("OS-0-") {
        LIDAR_ORIGIN_TO_BEAM_ORIGIN_MM_OS0
    } else if prod_line.starts_with("OS-1-") {
        LIDAR_ORIGIN_TO_BEAM_ORIGIN_MM_OS1
    } else if prod_line.starts_with("OS-2-") {
        LIDAR_ORIGIN_TO_BEAM_ORIGIN_MM_OS2
    } else {
        LIDAR_ORIGIN_TO_BEAM_ORIGIN_MM_GEN1
    }
}

/// The SDK's `default_beam_to_lidar_transform`: identity with `[0][3]` = the beam-origin
/// offset of the product line.
pub fn default_beam_to_lidar(prod_line: &str) -> [f64; 16] {
    beam_to_lidar_from_offset(default_lidar_origin_to_beam_origin_mm(prod_line))
}

fn beam_to_lidar_from_offset(mm: f64) -> [f64; 16] {
    let mut m = IDENTITY;
    m[3] = mm;
    m
}

const IDENTITY: [f64; 16] = [
    1.0, 0.0, 0.0, 0.0, //
    0.0, 1.0, 0.0, 0.0, //
    0.0, 0.0, 1.0, 0.0, //
    0.0, 0.0, 0.0, 1.0,
];

/// The SDK's default `pixel_shift_by_row` for a frame of `columns_per_frame` columns, resized to
/// `pixels_per_column` rows as the SDK resizes it: `default_data_format` repeats
/// `{3k, 2k, k, 0}` (k = 3, 6, 12, 24 for W = 512, 1024, 2048, 4096) 16 times — 64 rows — and
/// the parser then truncates or pads with zeros to H. Other W give all zeros.
pub fn default_pixel_shift_by_row(columns_per_frame: usize, pixels_per_column: usize) -> Vec<i32> {
    let k = match columns_per_frame {
        512 => 3,
        1024 => 6,
        2048 => 12,
        4096 => 24,
        _ => 0,
    };
    (0..pixels_per_column)
        .map(|row| {
            if row < DEFAULT_PIXELS_PER_COLUMN {
                // row % 4 < 4, so the cast cannot truncate.
                (3 - (row % 4) as i32) * k
            } else {
                0
            }
        })
        .collect()
}

/// Columns per frame and frames per second of a lidar mode name (`1024x10`).
pub fn parse_lidar_mode(name: &str) -> Option<(usize, u32)> {
    LIDAR_MODES
        .iter()
        .find(|(n, _, _)| *n == name)
        .map(|&(_, w, fps)| (w, fps))
}

/// The beam count of a product line as ouster-sdk's `ProductInfo::create_product_info` reads it
/// (regex `^(\w+)-(\d+|DOME)?(?:-(MAX))?(?:-(\d+))?…`): `OS-1-128` → 128, `OS-0-32-U1` → 32,
/// `OS-1-64-AH` → 64; `Some(0)` when the line parses but names no count; `None` when it does
/// not parse (the SDK then ignores the product line).
pub fn prod_line_beam_count(prod_line: &str) -> Option<usize> {
    let b = prod_line.as_bytes();
    let is_word = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    let digits_end = |from: usize| {
        let mut j = from;
        while j < b.len() && b[j].is_ascii_digit() {
            j += 1;
        }
        j
    };
    let mut i = 0;
    while i < b.len() && is_word(b[i]) {
        i += 1;
    }
    if i == 0 || b.get(i) != Some(&b'-') {
        return None;
    }
    i += 1;
    let j = digits_end(i);
    if j > i {
        i = j;
    } else if b[i..].starts_with(b"DOME") {
        i += 4;
    }
    if b[i..].starts_with(b"-MAX") {
        i += 4;
    }
    if b.get(i) == Some(&b'-') {
        let j = digits_end(i + 1);
        if j > i + 1 {
            // stoi: out of range → 0, as the SDK's catch does.
            return Some(
                prod_line[i + 1..j]
                    .parse::<i32>()
                    .ok()
                    .and_then(|v| usize::try_from(v).ok())
                    .unwrap_or(0),
            );
        }
    }
    Some(0)
}

/// The first `vX.Y.Z` in a firmware string that starts it or follows a `-`:
/// `ousteros-image-prod-aries-v2.5.0-omega.8+2023…` → (2, 5, 0), `v2.3.0` → (2, 3, 0).
pub fn parse_firmware_version(s: &str) -> Option<(u32, u32, u32)> {
    let b = s.as_bytes();
    for (i, _) in s.match_indices('v') {
        if i > 0 && b[i - 1] != b'-' {
            continue;
        }
        let mut parts = [0u32; 3];
        let mut pos = i + 1;
        let mut ok = true;
        for (n, part) in parts.iter_mut().enumerate() {
            let start = pos;
            while pos < b.len() && b[pos].is_ascii_digit() {
                pos += 1;
            }
            let Ok(v) = s[start..pos].parse::<u32>() else {
                ok = false;
                break;
            };
            *part = v;
            if n < 2 {
                if b.get(pos) != Some(&b'.') {
                    ok = false;
                    break;
                }
                pos += 1;
            }
        }
        if ok && !b.get(pos).is_some_and(u8::is_ascii_digit) {
            return Some((parts[0], parts[1], parts[2]));
        }
    }
    None
}

/// Parses Ouster metadata JSON text; `source_name` (usually the file name) is kept in
/// [`OusterInfo::source`]. See the module documentation for layouts, defaults and checks.
pub fn parse(text: &str, source_name: &str) -> Result<OusterInfo, CalibError> {
    check_size(text.len())?;
    let body = text.strip_prefix('\u{feff}').unwrap_or(text);
    let root: Value = serde_json::from_str(body).map_err(|e| CalibError::Syntax {
        format: FORMAT,
        line: e.line(),
        column: e.column(),
        message: e.to_string(),
    })?;
    let Value::Object(top) = &root else {
        return Err(CalibError::BadValue {
            key: "(document)".into(),
            context: String::new(),
            expected: "a JSON object".into(),
            found: describe(&root),
        });
    };
    let doc = Doc::new(top)?;
    doc.build(source_name)
}

/// Which metadata section a key belongs to (named as in the nested layout).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Sec {
    SensorInfo,
    Config,
    Beam,
    LidarIntrinsics,
    ImuIntrinsics,
    DataFormat,
    ImuDataFormat,
}

impl Sec {
    fn nested_name(self) -> &'static str {
        match self {
            Sec::SensorInfo => "sensor_info",
            Sec::Config => "config_params",
            Sec::Beam => "beam_intrinsics",
            Sec::LidarIntrinsics => "lidar_intrinsics",
            Sec::ImuIntrinsics => "imu_intrinsics",
            Sec::DataFormat => "lidar_data_format",
            Sec::ImuDataFormat => "imu_data_format",
        }
    }
}

/// The document with its sections resolved for the layout.
struct Doc<'a> {
    layout: &'static str,
    top: &'a Map<String, Value>,
    sensor_info: Option<&'a Map<String, Value>>,
    config: Option<&'a Map<String, Value>>,
    beam: Option<&'a Map<String, Value>>,
    lidar_intrinsics: Option<&'a Map<String, Value>>,
    imu_intrinsics: Option<&'a Map<String, Value>>,
    data_format: Option<&'a Map<String, Value>>,
    imu_data_format: Option<&'a Map<String, Value>>,
}

fn object<'a>(v: &'a Value, key: &str) -> Result<&'a Map<String, Value>, CalibError> {
    v.as_object().ok_or_else(|| CalibError::BadValue {
        key: key.into(),
        context: String::new(),
        expected: "an object".into(),
        found: describe(v),
    })
}

impl<'a> Doc<'a> {
    fn new(top: &'a Map<String, Value>) -> Result<Self, CalibError> {
        let present: Vec<&str> = NESTED_SECTIONS
            .iter()
            .copied()
            .filter(|k| top.contains_key(*k))
            .collect();
        let imu_data_format = match top.get("imu_data_format") {
            Some(v) => Some(object(v, "imu_data_format")?),
            None => None,
        };
        if present.is_empty() {
            let data_format = match top.get("data_format") {
                Some(v) => Some(object(v, "data_format")?),
                None => None,
            };
            return Ok(Doc {
                layout: LAYOUT_LEGACY,
                top,
                sensor_info: Some(top),
                config: Some(top),
                beam: Some(top),
                lidar_intrinsics: Some(top),
                imu_intrinsics: Some(top),
                data_format,
                imu_data_format,
            });
        }
        if present.len() < NESTED_SECTIONS.len() {
            let missing: Vec<&str> = NESTED_SECTIONS
                .iter()
                .copied()
                .filter(|k| !top.contains_key(*k))
                .collect();
            return Err(CalibError::Invalid(format!(
                "the metadata mixes the flat (legacy) and the nested layout: nested metadata must \
                 include `{}` (it has `{}`; ouster-sdk refuses such files too)",
                missing.join("`, `"),
                present.join("`, `")
            )));
        }
        let section = |name: &str| -> Result<Option<&'a Map<String, Value>>, CalibError> {
            match top.get(name) {
                Some(v) => object(v, name).map(Some),
                None => Ok(None),
            }
        };
        // FW 1.12/1.13: `lidar_data_format` (and `calibration_status`) hold the sensor's error
        // string instead of an object.
        let (layout, data_format) = match top.get("lidar_data_format") {
            Some(Value::String(_)) => (LAYOUT_NESTED_1_12, None),
            _ => (LAYOUT_NESTED, section("lidar_data_format")?),
        };
        match top.get("calibration_status") {
            Some(Value::String(_) | Value::Object(_)) | None => {}
            Some(v) => {
                return Err(CalibError::BadValue {
                    key: "calibration_status".into(),
                    context: String::new(),
                    expected: "an object (or the FW 1.12/1.13 error string)".into(),
                    found: describe(v),
                })
            }
        }
        Ok(Doc {
            layout,
            top,
            sensor_info: section("sensor_info")?,
            config: section("config_params")?,
            beam: section("beam_intrinsics")?,
            lidar_intrinsics: section("lidar_intrinsics")?,
            imu_intrinsics: section("imu_intrinsics")?,
            data_format,
            imu_data_format,
        })
    }

    fn is_legacy(&self) -> bool {
        self.layout == LAYOUT_LEGACY
    }

    /// The key path as the file spells it, for messages.
    fn path(&self, sec: Sec, key: &str) -> String {
        if self.is_legacy() {
            match sec {
                Sec::DataFormat => format!("data_format.{key}"),
                Sec::ImuDataFormat => format!("imu_data_format.{key}"),
                _ => key.to_owned(),
            }
        } else {
            format!("{}.{key}", sec.nested_name())
        }
    }

    /// A key of a section, with its path; `None` when absent (or, in a legacy file, when the
    /// SDK's conversion does not carry the key into that section).
    fn get(&self, sec: Sec, key: &str) -> Option<(&'a Value, String)> {
        let map = match sec {
            Sec::SensorInfo => self.sensor_info,
            Sec::Config => {
                if self.is_legacy()
                    && !matches!(key, "lidar_mode" | "udp_port_lidar" | "udp_port_imu")
                {
                    None
                } else {
                    self.config
                }
            }
            Sec::Beam => self.beam,
            Sec::LidarIntrinsics => self.lidar_intrinsics,
            Sec::ImuIntrinsics => self.imu_intrinsics,
            Sec::DataFormat => self.data_format,
            Sec::ImuDataFormat => self.imu_data_format,
        }?;
        map.get(key).map(|v| (v, self.path(sec, key)))
    }

    fn string(&self, sec: Sec, key: &str) -> Result<Option<&'a str>, CalibError> {
        match self.get(sec, key) {
            None => Ok(None),
            Some((Value::String(s), _)) => Ok(Some(s.as_str())),
            Some((v, path)) => Err(bad(&path, "a string", v)),
        }
    }

    fn uint(&self, sec: Sec, key: &str, max: u64) -> Result<Option<u64>, CalibError> {
        match self.get(sec, key) {
            None => Ok(None),
            Some((v, path)) => uint_value(v, &path, max).map(Some),
        }
    }

    fn build(&self, source_name: &str) -> Result<OusterInfo, CalibError> {
        // --- sensor_info
        let prod_line = self.string(Sec::SensorInfo, "prod_line")?.unwrap_or("");
        let serial = match self.get(Sec::SensorInfo, "prod_sn") {
            None => 0,
            Some((Value::String(s), path)) => {
                if s.is_empty() {
                    0
                } else if s.bytes().all(|c| c.is_ascii_digit()) {
                    s.parse::<u64>()
                        .ok()
                        .filter(|&v| v <= MAX_SERIAL)
                        .ok_or_else(|| bad(&path, SERIAL_EXPECTED, &Value::String(s.clone())))?
                } else {
                    return Err(bad(&path, SERIAL_EXPECTED, &Value::String(s.clone())));
                }
            }
            Some((v, path)) => {
                uint_value(v, &path, MAX_SERIAL).map_err(|_| bad(&path, SERIAL_EXPECTED, v))?
            }
        };
        let init_id = self
            .uint(Sec::SensorInfo, "initialization_id", 0x00FF_FFFF)?
            .unwrap_or(0);
        let firmware = self.string(Sec::SensorInfo, "build_rev")?.unwrap_or("");
        let image_rev = self.string(Sec::SensorInfo, "image_rev")?.unwrap_or("");

        // --- config_params
        let mode = match self.get(Sec::Config, "lidar_mode") {
            None => None,
            Some((Value::String(s), path)) => Some(parse_lidar_mode(s).ok_or_else(|| {
                bad(
                    &path,
                    "one of 512x10, 512x20, 1024x10, 1024x20, 2048x10, 4096x5",
                    &Value::String(s.clone()),
                )
            })?),
            Some((v, path)) => return Err(bad(&path, "a lidar mode string such as 1024x10", v)),
        };
        let port = |key: &str, default: u16| -> Result<u16, CalibError> {
            Ok(self
                .uint(Sec::Config, key, u64::from(u16::MAX))?
                .and_then(|p| u16::try_from(p).ok())
                .unwrap_or(default))
        };
        let udp_port_lidar = port("udp_port_lidar", DEFAULT_UDP_PORT_LIDAR)?;
        let udp_port_imu = port("udp_port_imu", DEFAULT_UDP_PORT_IMU)?;
        let udp_port_zm = port("udp_port_zm", 0)?;
        let timestamp_mode = match self.string(Sec::Config, "timestamp_mode")? {
            None => TimestampMode::default(),
            Some("TIME_FROM_INTERNAL_OSC") => TimestampMode::InternalOsc,
            Some("TIME_FROM_SYNC_PULSE_IN") => TimestampMode::SyncPulseIn,
            Some("TIME_FROM_PTP_1588") => TimestampMode::Ptp1588,
            Some(_) => TimestampMode::Unknown,
        };
        let udp_dest = match self.string(Sec::Config, "udp_dest")? {
            Some(d) => Some(d),
            None => self.string(Sec::Config, "udp_ip")?,
        };

        // --- lidar_data_format
        let df_cpf = self.uint(Sec::DataFormat, "columns_per_frame", u64::MAX)?;
        let columns_per_frame = match (mode, df_cpf) {
            (Some((w, _)), Some(cpf)) if cpf != w as u64 => {
                return Err(CalibError::Invalid(format!(
                    "{} ({cpf}) does not match {} ({})",
                    self.path(Sec::DataFormat, "columns_per_frame"),
                    self.path(Sec::Config, "lidar_mode"),
                    mode_name(mode),
                )))
            }
            (Some((w, _)), _) => w,
            (None, Some(cpf)) => usize::try_from(cpf).unwrap_or(usize::MAX),
            (None, None) => {
                return Err(CalibError::MissingKey {
                    key: self.path(Sec::DataFormat, "columns_per_frame"),
                    context: format!(
                        " (and `{}`: one of them gives the columns per frame)",
                        self.path(Sec::Config, "lidar_mode")
                    ),
                })
            }
        };
        if !COLUMNS_PER_FRAME.contains(&columns_per_frame) {
            return Err(CalibError::BadValue {
                key: self.path(Sec::DataFormat, "columns_per_frame"),
                context: String::new(),
                expected: "512, 1024, 2048 or 4096".into(),
                found: columns_per_frame.to_string(),
            });
        }
        let w = columns_per_frame;

        let fps = match (
            mode,
            self.uint(Sec::DataFormat, "fps", u64::from(u32::MAX))?,
        ) {
            (Some((_, f)), Some(df)) if df != u64::from(f) => {
                return Err(CalibError::Invalid(format!(
                    "{} ({df}) does not match {} ({})",
                    self.path(Sec::DataFormat, "fps"),
                    self.path(Sec::Config, "lidar_mode"),
                    mode_name(mode),
                )))
            }
            (Some((_, f)), _) => f,
            (None, Some(df)) => {
                let f = u32::try_from(df).unwrap_or(u32::MAX);
                if !LIDAR_MODES.iter().any(|&(_, mw, mf)| mw == w && mf == f) {
                    return Err(CalibError::BadValue {
                        key: self.path(Sec::DataFormat, "fps"),
                        context: format!(" with {w} columns per frame"),
                        expected: "the frame rate of a lidar mode (512x10, 512x20, 1024x10, \
                                   1024x20, 2048x10, 4096x5)"
                            .into(),
                        found: df.to_string(),
                    });
                }
                f
            }
            (None, None) => {
                return Err(CalibError::MissingKey {
                    key: self.path(Sec::Config, "lidar_mode"),
                    context: format!(
                        " (and `{}`: one of them gives the frame rate)",
                        self.path(Sec::DataFormat, "fps")
                    ),
                })
            }
        };

        let column_window = match self.get(Sec::DataFormat, "column_window") {
            None => (0, w - 1),
            Some((v, path)) => {
                let expected = format!("two column indices in 0..={}", w - 1);
                let Some([a, b]) = v.as_array().map(Vec::as_slice).and_then(|s| match s {
                    [a, b] => Some([a, b]),
                    _ => None,
                }) else {
                    return Err(bad(&path, &expected, v));
                };
                let a =
                    uint_value(a, &path, (w - 1) as u64).map_err(|_| bad(&path, &expected, v))?;
                let b =
                    uint_value(b, &path, (w - 1) as u64).map_err(|_| bad(&path, &expected, v))?;
                // Both fit in usize: they are at most w - 1.
                (a as usize, b as usize)
            }
        };

        let columns_per_packet = match self.get(Sec::DataFormat, "columns_per_packet") {
            None => DEFAULT_COLUMNS_PER_PACKET,
            Some((v, path)) => v
                .as_u64()
                .filter(|&c| c > 0 && c <= w as u64 && (w as u64) % c == 0)
                // c ≤ w: fits in usize.
                .map(|c| c as usize)
                .ok_or_else(|| bad(&path, &format!("a divisor of the {w} columns per frame"), v))?,
        };

        let beam_count = prod_line_beam_count(prod_line);
        let pixels_per_column = match self.get(Sec::DataFormat, "pixels_per_column") {
            Some((v, path)) => v
                .as_u64()
                .and_then(|h| usize::try_from(h).ok())
                .filter(|h| PIXELS_PER_COLUMN.contains(h))
                .ok_or_else(|| bad(&path, "16, 32, 64 or 128", v))?,
            None => {
                let h = match beam_count {
                    Some(n) if n > 0 => n,
                    Some(_) => {
                        return Err(CalibError::MissingKey {
                            key: self.path(Sec::DataFormat, "pixels_per_column"),
                            context: format!(" (prod_line {prod_line:?} names no beam count)"),
                        })
                    }
                    None => DEFAULT_PIXELS_PER_COLUMN,
                };
                if !PIXELS_PER_COLUMN.contains(&h) {
                    return Err(CalibError::BadValue {
                        key: self.path(Sec::DataFormat, "pixels_per_column"),
                        context: format!(" (absent; from prod_line {prod_line:?})"),
                        expected: "16, 32, 64 or 128".into(),
                        found: h.to_string(),
                    });
                }
                h
            }
        };
        let h = pixels_per_column;

        let pixel_shift_by_row = match self.get(Sec::DataFormat, "pixel_shift_by_row") {
            None => {
                if mode.is_some() {
                    default_pixel_shift_by_row(w, h)
                } else {
                    // Without a lidar mode the SDK starts from an empty data format: zeros.
                    vec![0; h]
                }
            }
            Some((v, path)) => {
                let items = array_of_len(v, &path, h, &h_origin(self, h, prod_line))?;
                let limit = w as i64 - 1;
                let expected = format!("integers in -{limit}..={limit}");
                items
                    .iter()
                    .enumerate()
                    .map(|(i, x)| {
                        x.as_i64()
                            // Not `abs`: i64::MIN has none.
                            .filter(|s| (-limit..=limit).contains(s))
                            // |s| < w ≤ 4096: fits in i32.
                            .map(|s| s as i32)
                            .ok_or_else(|| CalibError::BadValue {
                                key: path.clone(),
                                context: format!(" at row {i}"),
                                expected: expected.clone(),
                                found: describe(x),
                            })
                    })
                    .collect::<Result<Vec<_>, _>>()?
            }
        };

        let lidar_profile_name = self
            .string(Sec::DataFormat, "udp_profile_lidar")?
            .unwrap_or("LEGACY");
        let imu_profile = match self.get(Sec::DataFormat, "udp_profile_imu") {
            None => ImuProfile::Legacy,
            Some((Value::String(s), path)) => match s.as_str() {
                "LEGACY" => ImuProfile::Legacy,
                "ACCEL32_GYRO32_NMEA" => ImuProfile::Accel32Gyro32Nmea,
                "OFF" => ImuProfile::Off,
                _ => {
                    return Err(bad(
                        &path,
                        "LEGACY, ACCEL32_GYRO32_NMEA or OFF",
                        &Value::String(s.clone()),
                    ))
                }
            },
            Some((v, path)) => return Err(bad(&path, "an IMU profile name", v)),
        };
        let lidar_off = lidar_profile_name == "OFF"
            || udp_port_lidar == 0
            || udp_dest.is_some_and(str::is_empty);
        let profile = match Profile::from_name(lidar_profile_name) {
            Some(p) => p,
            None if lidar_off
                && (lidar_profile_name == "OFF"
                    || UNDECODED_PROFILES.contains(&lidar_profile_name)) =>
            {
                Profile::Legacy
            }
            None => {
                let path = self.path(Sec::DataFormat, "udp_profile_lidar");
                let expected = format!(
                    "a lidar profile ringscan decodes ({}){}",
                    crate::sensor::ouster::model::ALL_PROFILES
                        .iter()
                        .map(|p| p.name())
                        .collect::<Vec<_>>()
                        .join(", "),
                    if UNDECODED_PROFILES.contains(&lidar_profile_name) {
                        "; ouster-sdk knows this one, ringscan does not decode it"
                    } else {
                        ""
                    }
                );
                return Err(CalibError::BadValue {
                    key: path,
                    context: String::new(),
                    expected,
                    found: format!("{lidar_profile_name:?}"),
                });
            }
        };
        if let Some(header) = self.string(Sec::DataFormat, "header_type")? {
            let kind = match header {
                "STANDARD" => HeaderKind::Standard,
                "FUSA" => HeaderKind::Fusa,
                other => {
                    return Err(bad(
                        &self.path(Sec::DataFormat, "header_type"),
                        "STANDARD or FUSA",
                        &Value::String(other.to_owned()),
                    ))
                }
            };
            let implied = profile.header();
            if !lidar_off && implied != HeaderKind::Legacy && implied != kind {
                return Err(CalibError::Invalid(format!(
                    "{} is {header} but the lidar profile {} uses the {} header",
                    self.path(Sec::DataFormat, "header_type"),
                    profile.name(),
                    if implied == HeaderKind::Fusa {
                        "FUSA"
                    } else {
                        "STANDARD"
                    }
                )));
            }
        }
        if !lidar_off && profile == Profile::Legacy && imu_profile == ImuProfile::Accel32Gyro32Nmea
        {
            return Err(CalibError::Invalid(format!(
                "{} is LEGACY but {} is ACCEL32_GYRO32_NMEA: LEGACY lidar packets cannot be mixed \
                 with a non-legacy IMU profile (ouster-sdk's PacketFormat refuses it too)",
                self.path(Sec::DataFormat, "udp_profile_lidar"),
                self.path(Sec::DataFormat, "udp_profile_imu"),
            )));
        }
        let imu_measurements_per_packet = self
            .uint(
                Sec::ImuDataFormat,
                "imu_measurements_per_packet",
                MAX_IMU_MEASUREMENTS_PER_PACKET as u64,
            )?
            .unwrap_or(0) as usize;

        let format = PacketFormat {
            profile,
            columns_per_packet,
            pixels_per_column: h,
        };
        if !lidar_off && format.packet_bytes() > MAX_UDP_PAYLOAD {
            return Err(CalibError::Invalid(format!(
                "{columns_per_packet} columns per packet of {h} {} pixels make a {}-byte lidar \
                 packet, larger than a UDP datagram ({MAX_UDP_PAYLOAD} bytes)",
                profile.name(),
                format.packet_bytes()
            )));
        }

        // --- intrinsics
        let transform = |sec: Sec, key: &str, default: [f64; 16]| match self.get(sec, key) {
            None => Ok(default),
            Some((v, path)) => transform_value(v, &path),
        };
        let imu_to_sensor = transform(
            Sec::ImuIntrinsics,
            "imu_to_sensor_transform",
            DEFAULT_IMU_TO_SENSOR,
        )?;
        let lidar_to_sensor = transform(
            Sec::LidarIntrinsics,
            "lidar_to_sensor_transform",
            DEFAULT_LIDAR_TO_SENSOR,
        )?;
        let beam_altitude_angles = self.angles("beam_altitude_angles", h, 90.0, prod_line)?;
        let beam_azimuth_angles = self.angles("beam_azimuth_angles", h, 180.0, prod_line)?;
        if beam_altitude_angles.iter().all(|&a| a == 0.0) {
            return Err(CalibError::Invalid(format!(
                "every entry of {} is 0: all beams at one elevation is an unwritten calibration",
                self.path(Sec::Beam, "beam_altitude_angles")
            )));
        }
        let lidar_origin_to_beam_origin_mm =
            match self.get(Sec::Beam, "lidar_origin_to_beam_origin_mm") {
                None => default_lidar_origin_to_beam_origin_mm(prod_line),
                Some((v, path)) => v
                    .as_f64()
                    .filter(|x| x.is_finite() && x.abs() <= 1000.0)
                    .ok_or_else(|| bad(&path, "a number of millimetres within ±1000", v))?,
            };
        let beam_to_lidar = transform(
            Sec::Beam,
            "beam_to_lidar_transform",
            beam_to_lidar_from_offset(lidar_origin_to_beam_origin_mm),
        )?;

        Ok(OusterInfo {
            prod_line: prod_line.to_owned(),
            serial,
            firmware: firmware.to_owned(),
            init_id: u32::try_from(init_id).unwrap_or(0),
            columns_per_frame,
            fps,
            format,
            column_window,
            pixel_shift_by_row,
            beam_altitude_angles,
            beam_azimuth_angles,
            beam_to_lidar,
            lidar_to_sensor,
            imu_to_sensor,
            udp_port_lidar,
            udp_port_imu,
            udp_port_zm,
            imu_profile,
            imu_measurements_per_packet,
            timestamp_mode,
            layout: self.layout,
            lidar_origin_to_beam_origin_mm,
            image_rev: image_rev.to_owned(),
            lidar_profile_name: lidar_profile_name.to_owned(),
            lidar_off,
            source: source_name.to_owned(),
        })
    }

    /// A beam angle array: required, H plain numbers within ±`limit` degrees.
    fn angles(
        &self,
        key: &str,
        h: usize,
        limit: f64,
        prod_line: &str,
    ) -> Result<Vec<f64>, CalibError> {
        let Some((v, path)) = self.get(Sec::Beam, key) else {
            return Err(CalibError::MissingKey {
                key: self.path(Sec::Beam, key),
                context: if self.top.is_empty() {
                    " (the metadata is an empty object)".into()
                } else {
                    String::new()
                },
            });
        };
        let items = array_of_len(v, &path, h, &h_origin(self, h, prod_line))?;
        items
            .iter()
            .enumerate()
            .map(|(i, x)| {
                x.as_f64()
                    .filter(|a| a.is_finite() && a.abs() <= limit)
                    .ok_or_else(|| CalibError::BadValue {
                        key: path.clone(),
                        context: format!(" at beam {i}"),
                        expected: format!("a number of degrees within ±{limit}"),
                        found: describe(x),
                    })
            })
            .collect()
    }
}

/// Largest serial number: the packet header's `prod_sn` is 40 bits.
const MAX_SERIAL: u64 = (1 << 40) - 1;
const SERIAL_EXPECTED: &str = "a serial number (decimal digits, below 2^40)";

fn mode_name(mode: Option<(usize, u32)>) -> String {
    mode.map_or_else(|| "none".into(), |(w, f)| format!("{w}x{f}"))
}

/// Says where H came from, for messages about array lengths.
fn h_origin(doc: &Doc<'_>, h: usize, prod_line: &str) -> String {
    if doc.get(Sec::DataFormat, "pixels_per_column").is_some() {
        format!(
            " (pixels_per_column {h}, from `{}`)",
            doc.path(Sec::DataFormat, "pixels_per_column")
        )
    } else if prod_line_beam_count(prod_line).is_some_and(|n| n > 0) {
        format!(" (pixels_per_column {h}, from prod_line {prod_line:?})")
    } else {
        format!(" (pixels_per_column {h}, the default)")
    }
}

fn array_of_len<'v>(
    v: &'v Value,
    path: &str,
    len: usize,
    context: &str,
) -> Result<&'v [Value], CalibError> {
    match v {
        Value::Array(items) if items.len() == len => Ok(items),
        Value::Array(items) => Err(CalibError::BadValue {
            key: path.into(),
            context: context.into(),
            expected: format!("{len} entries"),
            found: format!("{} entries", items.len()),
        }),
        _ => Err(CalibError::BadValue {
            key: path.into(),
            context: context.into(),
            expected: format!("an array of {len} numbers"),
            found: describe(v),
        }),
    }
}

fn uint_value(v: &Value, path: &str, max: u64) -> Result<u64, CalibError> {
    v.as_u64()
        .filter(|&x| x <= max)
        .ok_or_else(|| bad(path, &format!("an integer in 0..={max}"), v))
}

/// A 4×4 row-major transform: 16 finite numbers, last row `[0, 0, 0, 1]`, rotation entries in
/// [−1, 1], translations within ±10 000 mm.
fn transform_value(v: &Value, path: &str) -> Result<[f64; 16], CalibError> {
    let items = array_of_len(v, path, 16, "")?;
    let mut m = [0.0; 16];
    for (i, (slot, x)) in m.iter_mut().zip(items).enumerate() {
        let (row, col) = (i / 4, i % 4);
        let (limit, what) = if row == 3 {
            (1.0, "0 or 1 (last row 0, 0, 0, 1)")
        } else if col == 3 {
            (10_000.0, "a translation within ±10000 mm")
        } else {
            (1.0 + 1e-6, "a rotation entry within ±1")
        };
        *slot = x
            .as_f64()
            .filter(|a| a.is_finite() && a.abs() <= limit)
            .ok_or_else(|| CalibError::BadValue {
                key: path.into(),
                context: format!(" at [{row}][{col}]"),
                expected: what.into(),
                found: describe(x),
            })?;
    }
    if m[12..] != [0.0, 0.0, 0.0, 1.0] {
        return Err(CalibError::BadValue {
            key: path.into(),
            context: " (last row)".into(),
            expected: "0, 0, 0, 1".into(),
            found: format!("{}, {}, {}, {}", m[12], m[13], m[14], m[15]),
        });
    }
    Ok(m)
}

fn bad(path: &str, expected: &str, v: &Value) -> CalibError {
    CalibError::BadValue {
        key: path.into(),
        context: String::new(),
        expected: expected.into(),
        found: describe(v),
    }
}

/// A short description of a JSON value for messages.
fn describe(v: &Value) -> String {
    match v {
        Value::Null => "null".into(),
        Value::Bool(b) => format!("boolean {b}"),
        Value::Number(n) => format!("number {n}"),
        Value::String(s) => {
            let mut t: String = s.chars().take(40).collect();
            if s.chars().count() > 40 {
                t.push('…');
            }
            format!("string {t:?}")
        }
        Value::Array(a) if a.len() <= 4 && a.iter().all(|x| !x.is_array() && !x.is_object()) => {
            let t = v.to_string();
            if t.chars().count() > 60 {
                format!("an array of {} entries", a.len())
            } else {
                t
            }
        }
        Value::Array(a) => format!("an array of {} entries", a.len()),
        Value::Object(_) => "an object".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Legacy-layout metadata of 16 beams at 512 columns, with `shift` as row 3's pixel shift.
    fn with_shift(shift: serde_json::Value) -> String {
        let mut rows = vec![serde_json::json!(0); 16];
        rows[3] = shift;
        serde_json::json!({
            "beam_altitude_angles": (0..16).map(|u| 15.0 - 2.0 * f64::from(u)).collect::<Vec<_>>(),
            "beam_azimuth_angles": vec![0.0; 16],
            "lidar_mode": "512x10",
            "data_format": {
                "pixels_per_column": 16,
                "columns_per_packet": 16,
                "columns_per_frame": 512,
                "pixel_shift_by_row": rows,
            },
        })
        .to_string()
    }

    #[test]
    fn a_pixel_shift_of_i64_min_is_refused_not_a_panic() {
        // The bounds: −(W − 1) and W − 1 are taken, one beyond is refused.
        let ok = parse(&with_shift(serde_json::json!(-511)), "m.json").unwrap();
        assert_eq!(ok.pixel_shift_by_row[3], -511);
        assert!(parse(&with_shift(serde_json::json!(512)), "m.json").is_err());
        for v in [i64::MIN, i64::MIN + 1, i64::MAX] {
            let e = parse(&with_shift(serde_json::json!(v)), "m.json").unwrap_err();
            assert!(
                matches!(&e, CalibError::BadValue { context, .. } if context == " at row 3"),
                "{v}: {e:?}"
            );
        }
    }
}
