//! What every family's calibration parsers share: the error type, the size cap on hostile
//! files, and a strict decimal parser. Each family's formats live in its own folder
//! (`sensor/<family>/calib`).

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
