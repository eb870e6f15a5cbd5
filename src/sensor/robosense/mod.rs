//! Robosense: RS-16, RS-32, RS-Bpearl, RS-Helios (32), RS-Helios-16P, RS-Ruby (128), and the
//! MEMS RS-LiDAR-M1 / M1 Plus ([`m1`]: its own 1210-byte packet, points with their own angles).
//!
//! The family's whole data flow in one folder: [`wire`] (views of the 1248-byte MSOP point
//! packet in its two header forms and of the 1248-byte DIFOP device-information packet) →
//! [`model`] (per-model layouts, distance units, firing-time tables, return modes, lens
//! centres) → [`calib`] (per-laser vertical / horizontal angles, from the angle CSV or from a
//! DIFOP packet) → [`decode`] (packet + angles → points) → [`sweep`] (packets held until the
//! angles are known, azimuth cut, clock, loss); [`sim`] writes byte-exact packets from known
//! points; [`family`] is the interface the rest of ringscan uses.
//!
//! Facts come from RoboSense's user manuals and its SDK `rs_driver` (decoder headers:
//! packet structs, firing tables, lens centres), read, not copied.

pub mod calib;
pub mod decode;
pub mod family;
pub mod m1;
pub mod model;
#[cfg(feature = "sim")]
pub mod sim;
pub mod sweep;
pub mod wire;

pub use calib::RobosenseAngles;
pub use decode::RobosenseDecoder;
pub use model::RobosenseModel;
pub use sweep::{RobosenseConfig, RobosenseFacts, RobosenseStats, RobosenseStream};
pub use wire::{Difop, Msop};
