//! Calibration tables and their file formats, into one validated per-channel lookup table.
//!
//! Knows nothing of packets or I/O beyond parsing a text it is given: the caller reads the file
//! and hands over its text ([`parse_velodyne`]) or bytes ([`parse_velodyne_bytes`]).
//!
//! # Velodyne conventions shared by every source
//!
//! - **Units**: radians and metres inside ringscan. ROS yaml is already in radians and metres
//!   (including `focal_distance`, see [`ros_yaml`]); VeloView xml / db.xml is in degrees and
//!   centimetres and is converted on load ([`veloview_xml`]).
//! - **Two-point distance correction** (HDL-64E): the ROS and velodyne_decoder decoders apply
//!   the near/far interpolation only to lasers whose `two_pt_correction_available` is true. The
//!   parsers fold that flag into the values: a laser without two-point correction gets
//!   `dist_correction_x = dist_correction_y = dist_correction`, for which the interpolation
//!   `(dc - dcx)·(xx - 2.40)/(25.04 - 2.40) + dcx` is exactly `dc`. A decoder can therefore apply
//!   the two-point formula to every laser of an [`VelodyneCalibration::advanced`] table and get
//!   what the references get, with no extra flag.
//! - **`advanced`** is true when any laser has a non-zero distance correction (`dist_correction`,
//!   `dist_correction_x`, `dist_correction_y`) or offset (`vert_offset_correction`,
//!   `horiz_offset_correction`) — the HDL-64E model. Built-in tables are not advanced: their only
//!   extra is a pure vertical beam-origin offset, applied as `z += vert_offset_correction`
//!   ([`builtin`]).
//! - **Intensity limits** default to `min_intensity = 0`, `max_intensity = 255` when a file does
//!   not state them (ROS `calibration.cc`, and db.xml files without `minIntensity_` /
//!   `maxIntensity_`).

pub mod builtin;
pub mod ouster;
pub mod ros_yaml;
pub mod velodyne;
pub mod veloview_xml;

pub use velodyne::{LaserCalibration, VelodyneCalibration};

/// Errors from reading or validating a calibration.
#[derive(Debug, thiserror::Error)]
pub enum CalibError {
    /// The text is not well-formed in its format (YAML, XML, JSON).
    #[error("{format} syntax error at line {line}, column {column}: {message}")]
    Syntax {
        /// Format name.
        format: &'static str,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What the parser said.
        message: String,
    },
    /// A required key is absent.
    #[error("missing key `{key}`{context}")]
    MissingKey {
        /// Key path.
        key: String,
        /// Where (e.g. " in laser 5").
        context: String,
    },
    /// A key holds a value of the wrong type or out of range.
    #[error("key `{key}`{context}: expected {expected}, found {found}")]
    BadValue {
        /// Key path.
        key: String,
        /// Where (e.g. " in laser 5").
        context: String,
        /// What was expected.
        expected: String,
        /// What was found.
        found: String,
    },
    /// The table as a whole is unusable.
    #[error("invalid calibration: {0}")]
    Invalid(String),
    /// The input is larger than any real calibration file.
    #[error("calibration text is {0} bytes; refusing anything over {1} bytes")]
    TooLarge(usize, usize),
    /// The format could not be recognised.
    #[error("unrecognised calibration format: {0}")]
    UnknownFormat(String),
}

/// Largest calibration text accepted (real files are < 100 kB).
pub const MAX_CALIB_BYTES: usize = 4 << 20;

/// Refuses texts longer than [`MAX_CALIB_BYTES`].
pub(crate) fn check_size(len: usize) -> Result<(), CalibError> {
    if len > MAX_CALIB_BYTES {
        Err(CalibError::TooLarge(len, MAX_CALIB_BYTES))
    } else {
        Ok(())
    }
}

/// Whether any laser carries a distance or offset correction (the HDL-64E model).
pub(crate) fn has_advanced_corrections(lasers: &[LaserCalibration]) -> bool {
    lasers.iter().any(|l| {
        [
            l.dist_correction,
            l.dist_correction_x,
            l.dist_correction_y,
            l.vert_offset_correction,
            l.horiz_offset_correction,
        ]
        .iter()
        .any(|&v| v != 0.0)
    })
}

/// Parses a decimal number as calibration files write them: optional sign, digits with an
/// optional fraction, optional exponent (`-7.1559157`, `1200`, `.5`, `1e-3`). Words that Rust
/// would also accept (`inf`, `NaN`, `infinity`) and anything else return `None`.
pub(crate) fn parse_decimal(s: &str) -> Option<f64> {
    let b = s.as_bytes();
    let mut i = 0;
    if matches!(b.first(), Some(b'+' | b'-')) {
        i += 1;
    }
    let int_start = i;
    while i < b.len() && b[i].is_ascii_digit() {
        i += 1;
    }
    let mut digits = i - int_start;
    if i < b.len() && b[i] == b'.' {
        i += 1;
        let frac_start = i;
        while i < b.len() && b[i].is_ascii_digit() {
            i += 1;
        }
        digits += i - frac_start;
    }
    if digits == 0 {
        return None;
    }
    if i < b.len() && matches!(b[i], b'e' | b'E') {
        i += 1;
        if i < b.len() && matches!(b[i], b'+' | b'-') {
            i += 1;
        }
        let exp_start = i;
        while i < b.len() && b[i].is_ascii_digit() {
            i += 1;
        }
        if i == exp_start {
            return None;
        }
    }
    if i != b.len() {
        return None;
    }
    s.parse().ok()
}

/// Parses a Velodyne calibration text of either format: VeloView xml / db.xml when the first
/// non-blank character is `<`, ROS yaml otherwise. `source_name` (usually the file name) is kept
/// in [`VelodyneCalibration::source`].
pub fn parse_velodyne(text: &str, source_name: &str) -> Result<VelodyneCalibration, CalibError> {
    check_size(text.len())?;
    let body = text.strip_prefix('\u{feff}').unwrap_or(text);
    if body.trim_start().starts_with('<') {
        veloview_xml::parse(text, source_name)
    } else {
        ros_yaml::parse(text, source_name)
    }
}

/// Like [`parse_velodyne`], for the raw bytes of a file: refuses oversized input before looking
/// at it and reports text that is not UTF-8 with the line and column of the first bad byte.
pub fn parse_velodyne_bytes(
    bytes: &[u8],
    source_name: &str,
) -> Result<VelodyneCalibration, CalibError> {
    check_size(bytes.len())?;
    match core::str::from_utf8(bytes) {
        Ok(text) => parse_velodyne(text, source_name),
        Err(e) => {
            let good = &bytes[..e.valid_up_to()];
            let line = 1 + good.iter().filter(|&&b| b == b'\n').count();
            let line_start = good.iter().rposition(|&b| b == b'\n').map_or(0, |p| p + 1);
            // Column in characters of the valid prefix of this line, 1-based.
            let column = 1 + String::from_utf8_lossy(&good[line_start..]).chars().count();
            Err(CalibError::Syntax {
                format: "text",
                line,
                column,
                message: format!("not UTF-8 text (bad byte at offset {})", e.valid_up_to()),
            })
        }
    }
}
