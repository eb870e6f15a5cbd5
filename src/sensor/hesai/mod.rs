//! Hesai: Pandar40P, Pandar64, PandarQT64, PandarQT128, PandarXT16 / XT32 / XT32M, PandarAT128,
//! OT128 (Pandar128E3X / E4X), Pandar ATX.
//!
//! The family's whole data flow in one folder: [`wire`] (typed view of every packet layout,
//! CRC-32/MPEG-2, functional safety) → [`model`] (per-model layouts, ranges, firing-time tables,
//! return modes) → [`calib`] (the angle-correction CSV) and [`at128`] (the AT128's binary
//! correction) and [`atx`] (the ATX's) → [`decode`] (packet + correction → points) → [`sweep`] (per-channel cut, clock,
//! loss, health); [`sim`] writes byte-exact packets from known points; [`family`] is the
//! interface the rest of ringscan uses.

pub mod at128;
pub mod atx;
pub mod calib;
pub mod decode;
pub mod family;
pub mod model;
#[cfg(feature = "sim")]
pub mod sim;
pub mod sweep;
pub mod wire;

pub use calib::{ChannelAngles, HesaiCalibration};
pub use decode::{HesaiDecoder, HesaiOptions};
pub use model::HesaiModel;
pub use sweep::{HesaiConfig, HesaiFacts, HesaiStats, HesaiStream};
pub use wire::HesaiPacket;
