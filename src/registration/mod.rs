//! Registration: aligning sweeps to each other and to a local map, and what that tells of the
//! sensor's motion. A layer beside the per-sweep `pipeline`: it takes the pipeline's (or the
//! decoder's) points and keeps state from sweep to sweep.
//!
//! [`icp`] (point-to-point and point-to-plane ICP, continuous-time ICP), [`map`] (the
//! odometry's bounded voxel-hash local map and KISS-ICP's subsampling), [`odometry`]
//! (scan-to-map LiDAR odometry) and [`degeneracy`] (which motions a sweep leaves free).

pub mod degeneracy;
pub mod icp;
pub mod map;
pub mod odometry;
