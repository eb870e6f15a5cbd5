//! Packet encoders: points → byte-exact packets, for tests, the demo fixture and the simulator.
//!
//! Knows nothing of decoding: it writes the wire formats from their specification, so a
//! round trip through the decoder checks both against the scene's ground truth.

pub mod hdl64;
pub mod motion;
pub mod net;
pub mod ouster;
pub mod scene;
pub mod scenes;
pub mod velodyne;

pub use scene::{Hit, Scene};
