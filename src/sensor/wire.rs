//! The error every family's packet views share.
//!
//! A family's `wire` module holds typed, read-only, zero-copy views over one datagram's bytes.
//! They know nothing of calibration, time zones or I/O; once a view is constructed its
//! accessors cannot fail or panic: every length is checked up front.

/// A datagram that does not have the shape its format requires.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    /// The payload length is not the format's.
    #[error("{what}: expected {expected} bytes, found {found}")]
    Length {
        /// Which packet kind.
        what: &'static str,
        /// Required length.
        expected: usize,
        /// Actual length.
        found: usize,
    },
    /// A data block does not start with a known flag.
    #[error("block {block} (offset {offset}): expected flag FF EE/DD/CC/BB, found {found:02X} {found2:02X}")]
    BlockFlag {
        /// Block index.
        block: usize,
        /// Byte offset of the flag.
        offset: usize,
        /// First byte found.
        found: u8,
        /// Second byte found.
        found2: u8,
    },
    /// A block azimuth is out of range (0..=36000 hundredths of a degree; 36000 means 0).
    #[error("block {block} (offset {offset}): azimuth {found} is above 36000")]
    Azimuth {
        /// Block index.
        block: usize,
        /// Byte offset of the azimuth.
        offset: usize,
        /// Value found.
        found: u16,
    },
    /// A packet's stored checksum does not match its bytes.
    #[error("{what}: stored CRC {stored:#018x}, computed {computed:#018x}")]
    Crc {
        /// Which packet kind.
        what: &'static str,
        /// CRC stored in the packet.
        stored: u64,
        /// CRC of the bytes.
        computed: u64,
    },
}
