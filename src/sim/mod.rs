//! The simulator: labelled ray-cast scenes, sensor motion, and packet encoders (points →
//! byte-exact packets) for Velodyne and Ouster, with per-measurement ground truth.
//!
//! Knows nothing of decoding: it writes the wire formats from their specification, so a
//! round trip through the decoder checks both against the scene's ground truth.
//!
//! - [`scene`]: the [`Scene`] trait, [`Hit`] (range, reflectivity, label — [`scene::GROUND`]
//!   = 0 or an object id — and the surface normal), primitives and the grid-culled
//!   [`scene::World`]; [`scenes`]: ready-made worlds (`urban`, `corridor`, `flat_floor`,
//!   `flat`, `slope10`, `ramp`, `kerbs`).
//! - [`motion`]: [`motion::Trajectory`] (`world_from_sensor` at any ns; constant twist, route,
//!   TUM pose table) and IMU kinematics.
//! - each family's encoder lives in its folder: [`crate::sensor::velodyne::sim`]
//!   (`VelodyneSim`, every model and return mode, per-firing poses, `Truth`; `hdl64`: the
//!   HDL-64E correction model) and [`crate::sensor::ouster::sim`] (`OusterEncoder` and
//!   `OusterSim`: any metadata, profile and mode; per-pixel `OusterTruth`; IMU packets from the
//!   motion).
//! - [`truth`]: the compact binary truth file (writer and reader); [`net`]: UDP frames, pcap.
//!
//! A moving VLP-16 in the urban scene, one packet:
//!
//! ```
//! use nalgebra::{Isometry3, Vector3};
//! use ringscan::sensor::velodyne::calib::builtin::builtin;
//! use ringscan::sensor::velodyne::sim::VelodyneSim;
//! use ringscan::sensor::velodyne::{ReturnMode, VelodyneModel};
//! use ringscan::sim::{motion::Trajectory, scenes};
//!
//! let t0 = 1_714_564_800_000_000_000; // ns, the simulator's clock
//! let model = VelodyneModel::Vlp16;
//! let mut sim = VelodyneSim::new(model, ReturnMode::Strongest, builtin(model).unwrap(), t0);
//! sim.trajectory = Trajectory::route(t0, ringscan::sim::motion::Route::urban());
//! let world = scenes::urban();
//! let mut truth = Vec::new();
//! let (host_ns, payload) = sim.next_packet(&world, &mut truth);
//! assert!(host_ns > t0 && payload.len() == 1206 && !truth.is_empty());
//! // Per measurement: sensor-frame point, world point, label, absolute firing time.
//! let t = &truth[0];
//! let pose = sim.trajectory.pose(t.time_ns);
//! let w = pose * nalgebra::Point3::from(t.xyz);
//! assert!((w.coords - Vector3::from(t.world)).norm() < 1e-9);
//! ```

pub mod motion;
pub mod net;
pub mod scene;
pub mod scenes;
pub mod truth;

pub use scene::{Hit, Scene};
