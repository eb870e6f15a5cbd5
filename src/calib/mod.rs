//! Calibration tables and their file formats, into one validated per-channel lookup table.
//!
//! Knows nothing of packets or I/O beyond parsing a text it is given.

pub mod builtin;
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
