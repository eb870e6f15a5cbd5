//! Point-cloud stages applied to sweeps after decoding: registration (ICP), the odometry's
//! local map, LiDAR odometry and its degeneracy analysis. No I/O, no clock.

pub mod degeneracy;
pub mod icp;
pub mod map;
pub mod odometry;
