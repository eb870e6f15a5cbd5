//! Per-sensor facts as data: channels, distance units, firing-time tables.
//!
//! Knows nothing of bytes or I/O.

pub mod ouster;
pub mod velodyne;

pub use velodyne::{ReturnMode, VelodyneModel};
