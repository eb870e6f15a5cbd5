//! Packet view + lookup table ➜ points appended to a caller's buffer.
//!
//! Knows nothing of sockets or files. Decoders are built once per calibration (all trigonometry
//! of the calibration is done then) and allocate nothing per packet.

pub mod velodyne;

pub use velodyne::{DecodeOptions, VelodyneDecoder};

/// Errors building a decoder or decoding a packet.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    /// The calibration does not fit the model.
    #[error("calibration has {found} lasers but the {model} has {expected}")]
    LaserCount {
        /// Model name.
        model: &'static str,
        /// Lasers the model has.
        expected: usize,
        /// Lasers the calibration has.
        found: usize,
    },
    /// The model / return mode combination is not supported.
    #[error("{model} in {mode} return mode is not supported")]
    Unsupported {
        /// Model name.
        model: &'static str,
        /// Return mode name.
        mode: &'static str,
    },
    /// The packet does not have the shape required.
    #[error(transparent)]
    Wire(#[from] crate::wire::WireError),
    /// The packet's blocks do not match the model's layout.
    #[error("block {block}: flag {found:#06x} does not fit the {model} layout (expected {expected:#06x})")]
    Layout {
        /// Model name.
        model: &'static str,
        /// Block index.
        block: usize,
        /// Flag expected.
        expected: u16,
        /// Flag found.
        found: u16,
    },
    /// A configuration value is unusable.
    #[error("invalid option: {0}")]
    Option(String),
}
