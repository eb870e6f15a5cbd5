//! Sensor families. Each family is one folder holding its whole data flow — packet views
//! (`wire`), model facts (`model`), calibration formats (`calib`), decoder (`decode`), sweep
//! rules (`sweep`) and packet encoder (`sim`) — behind the small interface of this module.

pub mod calib;
pub mod decode;
pub mod nmea;
pub mod ouster;
pub mod velodyne;
pub mod wire;

pub use calib::{CalibError, MAX_CALIB_BYTES};
pub use decode::{DecodeError, DecodeOptions};
pub use ouster::sweep::ImuSample;
pub use velodyne::sweep::StreamError;
pub use wire::WireError;
