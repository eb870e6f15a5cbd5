//! # ringscan
//!
//! A LiDAR driver and packet decoder: raw Velodyne and Ouster traffic into timestamped,
//! ring-tagged points assembled into sweeps, with packet loss counted, never hidden.
//!
//! The data flow, one folder per step (`docs/architecture.md` draws it):
//!
//! - [`sensor`]: one folder per sensor family ([`sensor::velodyne`], [`sensor::ouster`]), each
//!   with its packet views, model facts, calibration formats, decoder, sweep rules and packet
//!   encoder, behind one interface ([`sensor::Family`], [`sensor::SensorStream`]);
//! - [`sweep`]: the sweep record and the demultiplexer that gives each sensor its stream;
//! - [`deskew`], [`pipeline`] (filters, voxel, ground, clusters) and [`registration`] (ICP,
//!   local map, odometry);
//! - edges: [`source`] (pcap, UDP), [`mod@sink`] (MCAP, live view), [`sim`] (the simulator).
//!
//! The core (`sensor`, `sweep`, `deskew`, `pipeline`, `registration`) performs no I/O, reads no
//! clock and allocates nothing per packet (nor, once their buffers are warm, per sweep in the
//! pipeline stages); it builds with `--no-default-features`. Sources (pcap), sinks (MCAP),
//! pipeline configuration files (`config`) and the command line are features on top.
//!
//! ## Decoding one packet
//!
//! The sans-IO core: give it the bytes of one UDP payload, get points. The caller names the
//! model (stream-level detection lives in [`sensor::velodyne::VelodyneStream`]; any family's
//! sensor is found by [`sensor::claim`]).
//!
//! ```
//! use ringscan::sensor::velodyne::calib::builtin::builtin;
//! use ringscan::sensor::velodyne::{ReturnMode, VelodyneDecoder, VelodyneModel};
//! use ringscan::sensor::DecodeOptions;
//! use ringscan::sensor::velodyne::wire::DataPacket;
//!
//! // A VLP-16 data packet: 12 blocks `FF EE`, azimuths 0.00°, 0.20°, …, one return.
//! let mut bytes = [0u8; 1206];
//! for b in 0..12 {
//!     bytes[b * 100] = 0xFF;
//!     bytes[b * 100 + 1] = 0xEE;
//!     bytes[b * 100 + 2..b * 100 + 4].copy_from_slice(&(20 * b as u16).to_le_bytes());
//! }
//! // Block 0, slot 1 = laser 1 (elevation +1°): 2500 × 2 mm = 5 m, reflectivity 77.
//! bytes[7..9].copy_from_slice(&2500u16.to_le_bytes());
//! bytes[9] = 77;
//! bytes[1204] = 0x37; // strongest return
//! bytes[1205] = 0x22; // VLP-16
//!
//! let calib = builtin(VelodyneModel::Vlp16).unwrap();
//! let decoder =
//!     VelodyneDecoder::new(VelodyneModel::Vlp16, ReturnMode::Strongest, &calib, DecodeOptions::default())?;
//! let packet = DataPacket::new(&bytes)?;
//! let mut points = Vec::new(); // reuse it from packet to packet: no allocation per packet
//! decoder.decode(&packet, 0, &mut points);
//!
//! assert_eq!(points.len(), 1);
//! let p = points[0];
//! assert_eq!((p.ring, p.intensity, p.t), (8, 77.0, 2_304)); // ring 8 of 16; fired 2.304 µs in
//! assert!((p.x - 5.0 * 1f32.to_radians().cos()).abs() < 1e-3); // straight ahead
//! assert!(p.y.abs() < 1e-3);
//! assert!((p.z - 5.0 * 1f32.to_radians().sin()).abs() < 2e-3); // + the beam's vertical offset
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![forbid(unsafe_code)]
#![warn(missing_docs)]

// The command line lives in the library (behind `cli`) so that the Python package runs the
// same code for `python -m ringscan` and for its readers; its items are the commands' own.
#[cfg(feature = "cli")]
#[allow(missing_docs)]
pub mod cli;
pub mod deskew;
pub mod pipeline;
pub mod point;
pub mod registration;
// ROS 1 / CDR message bytes read back: shared by the bag reader and `render`'s reader.
#[cfg(any(feature = "bag", feature = "mcap"))]
mod ros_serial;
pub mod sensor;
#[cfg(feature = "sim")]
pub mod sim;
#[cfg(feature = "mcap")]
pub mod sink;
pub mod source;
pub mod sweep;
pub mod time;

pub use point::Point;
