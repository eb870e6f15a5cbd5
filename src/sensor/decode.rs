//! The errors every family's decoder and stream share, and the options every decoder takes.
//!
//! A family's `decode` module turns a packet view + its calibration's lookup table into points
//! appended to a caller's buffer. Decoders know nothing of sockets or files; they are built
//! once per calibration (all trigonometry of the calibration is done then) and allocate nothing
//! per packet.

/// Options applied while decoding, by every family.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DecodeOptions {
    /// Points closer than this (metres) are dropped. Default 0: every non-zero distance.
    pub min_range: f32,
    /// Points farther than this (metres) are dropped. Default: no limit.
    pub max_range: f32,
}

impl Default for DecodeOptions {
    fn default() -> Self {
        Self {
            min_range: 0.0,
            max_range: f32::INFINITY,
        }
    }
}

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
    Wire(#[from] crate::sensor::WireError),
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
    /// An Ouster calibration cannot build a decoder (counts, non-finite values).
    #[error("invalid Ouster calibration: {0}")]
    Calibration(String),
    /// A packet or frame is not in the decoder's format.
    #[error("expected {expected}, found {found}")]
    Format {
        /// What the decoder is built for.
        expected: String,
        /// What was given.
        found: String,
    },
    /// An Ouster packet from another sensor (ouster-sdk `validate_packet`: init_id / serial).
    #[error(
        "packet from another sensor: init_id {found_init_id} (expected {expected_init_id}), \
         serial {found_serial} (expected {expected_serial})"
    )]
    SensorId {
        /// The metadata's init_id.
        expected_init_id: u32,
        /// The packet's init_id.
        found_init_id: u32,
        /// The metadata's serial.
        expected_serial: u64,
        /// The packet's serial.
        found_serial: u64,
    },
    /// An Ouster packet of another frame than the one being filled.
    #[error("packet of frame {found} given to frame {expected}")]
    FrameId {
        /// The frame's id.
        expected: u32,
        /// The packet's frame id.
        found: u32,
    },
}

/// A sensor stream that cannot go on (every family's `SensorStream`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StreamError {
    /// A Velodyne stream: neither the product id nor the packet cadence names a model.
    #[error("cannot tell the Velodyne model (product id {product_id:#04x}, packet period {period_us:?} µs): name it with --model")]
    UnknownModel {
        /// Byte 1205.
        product_id: u8,
        /// Smallest stamp difference seen, µs.
        period_us: Option<f64>,
    },
    /// The model has no built-in calibration; `.1` says where its file may come from.
    #[error("the {0} has no built-in calibration: give its calibration file with --calib{1}")]
    NeedsCalibration(&'static str, &'static str),
    /// The decoder could not be built.
    #[error(transparent)]
    Decode(#[from] DecodeError),
}
