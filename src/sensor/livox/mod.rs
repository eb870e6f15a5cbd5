//! Livox: MID-360 and HAP (Livox-SDK2 protocol); Avia, Horizon, Tele-15, Mid-40, Mid-70
//! (Livox-SDK protocol).
//!
//! The family's whole data flow in one folder: [`wire`] (typed views of both protocols'
//! point / IMU packets, CRC-32) → [`model`] (lines, point rates, ports, IMU position) →
//! [`decode`] (records → points, per-point time, line, tag) → [`sweep`] (integration-period
//! or frame cut, loss, IMU samples in SI units); [`sim`] writes byte-exact packets from known
//! points; [`family`] is the interface the rest of ringscan uses; [`lvx`] reads the layouts
//! of the Livox Viewer's recordings; [`frame`] carries points the ROS drivers decoded. No calibration files: the
//! sensors send Cartesian (or spherical) points in their own frame.

pub mod control;
pub mod decode;
pub mod family;
pub mod frame;
pub mod lvx;
pub mod model;
#[cfg(feature = "sim")]
pub mod sim;
pub mod sweep;
pub mod wire;

pub use decode::LivoxDecoder;
pub use model::{LivoxModel, Protocol};
pub use sweep::{LivoxConfig, LivoxFacts, LivoxStats, LivoxStream};
pub use wire::{Sdk1Packet, Sdk2Packet};
