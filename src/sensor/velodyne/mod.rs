//! Velodyne: VLP-16, Puck Hi-Res, HDL-32E, VLP-32C, HDL-64E S2/S3, VLS-128.
//!
//! The family's whole data flow in one folder: [`wire`] (typed views of the 1206-byte data and
//! 512-byte position packets) → [`model`] (per-model facts: lasers, firing-time tables, packet
//! cadence) → [`calib`] (ROS yaml, VeloView xml / db.xml, the built-in tables) → [`decode`]
//! (packet + calibration → points) → [`sweep`] (model detection, sweeps cut at an azimuth,
//! loss and clock accounting); [`sim`] writes the packets from a scene.

pub mod calib;
pub mod decode;
pub mod family;
pub mod model;
#[cfg(feature = "sim")]
pub mod sim;
pub mod sweep;
pub mod wire;

pub use calib::{parse_velodyne, parse_velodyne_bytes, LaserCalibration, VelodyneCalibration};
pub use decode::VelodyneDecoder;
pub use model::{ReturnMode, VelodyneModel};
pub use sweep::{SensorFacts, StreamConfig, StreamStats, VelodyneStream};
