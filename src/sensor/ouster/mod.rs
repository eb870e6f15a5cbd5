//! Ouster: OS0 / OS1 / OS2 (and gen-1 OS-1), LEGACY and profile-based packets, IMU packets.
//!
//! The family's whole data flow in one folder: [`wire`] (typed views of lidar and IMU packets,
//! the footer CRC-64) → [`model`] (profiles, pixel layouts, header kinds) → [`calib`] (the
//! sensor's metadata JSON in every form, with ouster-sdk's defaults) → [`decode`] (packet +
//! metadata → points, the XYZ lookup table) → [`sweep`] (frames by `frame_id`, missing columns,
//! IMU samples, clocks); [`sim`] writes the packets from a scene.

pub mod calib;
pub mod decode;
pub mod family;
pub mod model;
#[cfg(feature = "sim")]
pub mod sim;
pub mod sweep;
pub mod wire;

pub use calib::OusterInfo;
pub use decode::{Decoded as OusterDecoded, Extra, OusterDecoder, OusterFrame};
pub use sweep::{OusterFacts, OusterStats, OusterStream, OusterStreamConfig};
