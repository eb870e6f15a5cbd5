//! # ringscan
//!
//! A LiDAR driver and packet decoder: raw Velodyne and Ouster traffic into timestamped,
//! ring-tagged points assembled into sweeps, with packet loss counted, never hidden.
//!
//! The core (`wire`, `model`, `calib`, `decode`, `sweep`) performs no I/O, reads no clock and
//! allocates nothing per packet; it builds with `--no-default-features`. Sources (pcap), sinks
//! (MCAP) and the command line are features on top.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod calib;
pub mod decode;
pub mod model;
pub mod point;
#[cfg(feature = "sim")]
pub mod sim;
#[cfg(feature = "mcap")]
pub mod sink;
pub mod source;
pub mod sweep;
pub mod time;
pub mod wire;

pub use point::Point;
