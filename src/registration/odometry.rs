//! LiDAR odometry: each sweep registered to a local map of the previous ones, in the manner of
//! KISS-ICP (Vizzo et al., "KISS-ICP: In Defense of Point-to-Point ICP", RA-L 2023).
//!
//! Per sweep ([`Odometry::register`]):
//! 1. points outside `(min_range_m, max_range_m)` or not finite are dropped;
//! 2. the sweep is subsampled twice with [`VoxelSampler`]: at `0.5 × voxel_size_m` (the points
//!    that go into the map) and that again at `1.5 × voxel_size_m` (the registration source);
//! 3. **prediction** by constant velocity: `T̂ₜ = Tₜ₋₁ · ΔTₜ₋₁` per sweep
//!    ([`Odometry::register`]: the poses depend on the points alone, not on the stamps, so a
//!    live run and a run from a capture of the same packets agree exactly), or in time
//!    ([`Odometry::register_timed`]: `Tₜ₋₁ · exp(s · log ΔTₜ₋₁)`, `s` the ratio of this stamp
//!    difference to the last one, within 0.25–4: after a first, partial sweep the per-sweep
//!    prediction falls short); with an IMU rotation increment, its rotation replaces the
//!    predicted one and enters ICP as a prior;
//! 4. **registration** of the source to the local map by point-to-point Gauss–Newton ICP with
//!    a Geman–McClure kernel, starting from the prediction: correspondences within `3σ`,
//!    kernel scale `k = √σ` (KISS-ICP's weight `σ²/(σ + r²)²`), where σ is the
//!    **adaptive threshold**: the RMS of the model deviations
//!    `e = ‖Δt‖ + 2·max_range·sin(‖Δθ‖/2)` of the prediction against the estimate, counted
//!    only for deviations above `min_motion_m`, seeded with `initial_threshold_m`;
//! 5. poses are composed `Tₜ = Tₜ₋₁ · ΔTₜ` (`world_from_sensor`; the world is the first
//!    sweep's sensor frame);
//! 6. **keyframes**: the sweep's map points are added to the [`VoxelMap`] (bounded: points per
//!    voxel, voxels dropped beyond `max_range_m` of the sensor, and voxels in all by
//!    [`DEFAULT_MAP_BYTES`] of memory) when the sensor has moved at least
//!    `keyframe_translation_m` or turned `keyframe_rotation_rad` since the last keyframe
//!    (both 0: every sweep, as KISS-ICP);
//! 7. optionally, the **degeneracy** of the registration ([`crate::registration::degeneracy`]), analysed at
//!    the point-to-point pose; with [`OdometryMethod::PointToPlane`] a degenerate sweep is
//!    not refined on planes (nothing holds a plane fit along a free direction).
//!
//! A registration that fails (too few correspondences, singular system) keeps the predicted
//! pose, says so in [`OdometryStep::status`], and leaves the map and the threshold untouched:
//! a pose is never silently wrong. A map of fewer points than `min_correspondences` (a first
//! sweep of a few points), or one against which `max_lost_sweeps` sweeps in a row were lost,
//! is no map: the next sweep starts it again ([`TrackStatus::Initialized`]) at the predicted
//! pose.
//!
//! **Time convention**: a sweep's pose is stamped with the sweep's timestamp (its first
//! firing, [`crate::sweep::Sweep::timestamp_ns`]). [`Odometry::last_motion`] gives the motion
//! between the last two sweeps, `previous_from_current` (points of the current sweep's frame
//! into the previous one's) with the difference of their stamps, so deskew can spread it over
//! the next sweep's firing times ([`SweepMotion::sweep_start_from_offset`]). Without deskew
//! the points of a sweep are a blend over its duration and the pose registers that blend.
//! [`Odometry::register_timed`] takes the raw points with their times instead, deskews them
//! itself and stamps the pose at the sweep's last point; with
//! [`OdometryConfig::continuous_time`] it estimates the poses at the sweep's first and last
//! points together ([`Icp::align_continuous`], after CT-ICP) instead of deskewing first.
//!
//! No I/O, no clock: callers time it.

use nalgebra::{Isometry3, Matrix3, Matrix6, UnitQuaternion, Vector3, Vector6};

use crate::registration::degeneracy::analyse;
use crate::registration::degeneracy::Degeneracy;
use crate::registration::degeneracy::DegeneracyConfig;
use crate::registration::icp::se3_exp;
use crate::registration::icp::se3_log;
use crate::registration::icp::ContinuousResult;
use crate::registration::icp::Icp;
use crate::registration::icp::IcpConfig;
use crate::registration::icp::IcpError;
use crate::registration::icp::IcpMethod;
use crate::registration::icp::IcpResult;
use crate::registration::icp::RegistrationConfigError;
use crate::registration::icp::RobustKernel;
use crate::registration::icp::RotationPrior;
use crate::registration::icp::SweepPriors;
use crate::registration::map::VoxelMap;
use crate::registration::map::VoxelMapConfig;
use crate::registration::map::VoxelSampler;
use crate::registration::map::DEFAULT_MAP_BYTES;

/// The arm at which a rotation weighs like a translation in the continuous-time priors, m.
const CT_ROTATION_ARM_M: f64 = 10.0;
use crate::point::Point;

/// The residual the odometry's ICP minimises.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum OdometryMethod {
    /// Point-to-point, as KISS-ICP (its trajectories compare sweep by sweep).
    #[default]
    PointToPoint,
    /// Point-to-point as above, then refined point-to-plane against the normals of the map's
    /// voxels (voxels with at least 3 points, a spread of at least 5 cm and a flatness ratio
    /// ≤ 0.1; others give no pair) with a gate of one voxel and a Geman–McClure scale of
    /// 0.2 voxel. Map points are not resampled between sweeps, so on large planes
    /// point-to-point pairs pull towards the predicted pose; plane residuals do not. When the
    /// refinement fails, the point-to-point pose stands.
    PointToPlane,
}

/// Parameters of [`Odometry`]. The defaults are KISS-ICP's (v1.x) for a 100 m sensor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OdometryConfig {
    /// The ICP residual.
    pub method: OdometryMethod,
    /// Points farther than this are dropped, and map voxels beyond it from the sensor, m.
    pub max_range_m: f64,
    /// Points this close or closer are dropped, m.
    pub min_range_m: f64,
    /// Map voxel edge, m (KISS-ICP: `max_range_m / 100`).
    pub voxel_size_m: f64,
    /// Points per map voxel.
    pub max_points_per_voxel: usize,
    /// The adaptive threshold before any motion was seen, m.
    pub initial_threshold_m: f64,
    /// Model deviations below this do not update the threshold, m.
    pub min_motion_m: f64,
    /// ICP iterations at most.
    pub max_iterations: usize,
    /// ICP stops when its update twist is smaller than this.
    pub convergence_update: f64,
    /// Fewer correspondences than this is a failed registration.
    pub min_correspondences: usize,
    /// A keyframe (map update) after this much translation since the last one, m.
    pub keyframe_translation_m: f64,
    /// A keyframe after this much rotation since the last one, rad.
    pub keyframe_rotation_rad: f64,
    /// Degeneracy analysis per sweep, if wanted.
    pub degeneracy: Option<DegeneracyConfig>,
    /// Registrations per sweep in [`Odometry::register_timed`] at most: the first on the
    /// sweep deskewed with the predicted motion, each further one on the sweep deskewed again
    /// with the motion just estimated (1 to 4; default 4). On the simulated urban drive
    /// (`tools/odometry_eval.sh`, point-to-plane) 1, 2, 3 and 4 passes gave 0.36, 0.34, 0.22
    /// and 0.16°/100 m, but 8 passes diverged (4.7°/100 m): a sweep determines its own
    /// forward speed poorly and the passes can drift with it, so more is not safer.
    pub deskew_passes: usize,
    /// [`Odometry::register_timed`] estimates the sweep's poses at its first and last point
    /// together (continuous-time ICP, [`Icp::align_continuous`]: every point placed by its
    /// own time along the motion between them) instead of deskewing the sweep and registering
    /// it rigidly; `deskew_passes` is then unused. Off by default (see BENCHMARKS.md
    /// "Odometry": better than the deskew passes on the VLP-16 urban drive, as good on the
    /// HDL-32E one, and sensitive to the two weights below).
    pub continuous_time: bool,
    /// Continuous time: the information holding the sweep's start pose at the previous
    /// sweep's end, per source point (in units of one point's squared residual, m², so 1 weighs
    /// like every point of the sweep once more; rotation at a 10 m arm). Default 0.3.
    pub continuous_start_weight: f64,
    /// Continuous time: the information holding the motion over the sweep at the predicted
    /// one (constant velocity), per source point, as `continuous_start_weight`; none before
    /// a motion was seen. Default 0.003. Both defaults were chosen on the simulated urban
    /// drives (BENCHMARKS.md "Odometry" has the grid); 0 leaves that part free.
    pub continuous_motion_weight: f64,
    /// After this many sweeps lost in a row the map is stale (a gap in the data while moving,
    /// a first sweep no later one sees): the next sweep starts it again at the predicted pose
    /// ([`TrackStatus::Initialized`]). 0: never, every later sweep stays lost. Default 10.
    pub max_lost_sweeps: usize,
}

impl Default for OdometryConfig {
    fn default() -> Self {
        Self::for_max_range(100.0)
    }
}

impl OdometryConfig {
    /// KISS-ICP's defaults for a sensor of the given range: voxels of `max_range_m / 100`,
    /// 20 points per voxel, threshold 2 m, min motion 0.1 m, 500 iterations, 1e-4; a
    /// keyframe every sweep; degeneracy analysis on.
    pub fn for_max_range(max_range_m: f64) -> Self {
        Self {
            method: OdometryMethod::PointToPoint,
            max_range_m,
            min_range_m: 0.0,
            voxel_size_m: max_range_m / 100.0,
            max_points_per_voxel: 20,
            initial_threshold_m: 2.0,
            min_motion_m: 0.1,
            max_iterations: 500,
            convergence_update: 1e-4,
            min_correspondences: 10,
            keyframe_translation_m: 0.0,
            keyframe_rotation_rad: 0.0,
            degeneracy: Some(DegeneracyConfig::default()),
            deskew_passes: 4,
            continuous_time: false,
            continuous_start_weight: 0.3,
            continuous_motion_weight: 0.003,
            max_lost_sweeps: 10,
        }
    }
}

/// How a sweep's registration went.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TrackStatus {
    /// The first sweep (or the first after [`Odometry::reset`]), or the first after a map of
    /// fewer points than `min_correspondences` or after `max_lost_sweeps` lost in a row: it
    /// starts the map (again, at the predicted pose, dropping the points there were).
    Initialized,
    /// ICP converged.
    Converged,
    /// ICP hit its iteration limit: the pose is its last estimate, not to be trusted blindly.
    NotConverged,
    /// ICP failed: the pose is the prediction, the map was not updated.
    Lost(IcpError),
}

impl TrackStatus {
    /// A registration's status by whether ICP converged.
    fn of(converged: bool) -> Self {
        if converged {
            Self::Converged
        } else {
            Self::NotConverged
        }
    }
}

/// The motion between two consecutive sweeps, for deskewing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SweepMotion {
    /// Maps points in the later sweep's sensor frame (at its timestamp) into the earlier
    /// one's: `T_{t-1}⁻¹ · T_t`.
    pub previous_from_current: Isometry3<f64>,
    /// Timestamp difference of the two sweeps (first firings), ns.
    pub dt_ns: i64,
}

impl SweepMotion {
    /// The constant-velocity twist `(v m/s, ω rad/s)` in the sensor frame, `None` if
    /// `dt_ns ≤ 0`.
    pub fn twist_per_s(&self) -> Option<Vector6<f64>> {
        (self.dt_ns > 0).then(|| se3_log(&self.previous_from_current) / (self.dt_ns as f64 * 1e-9))
    }

    /// The sensor pose `offset_ns` after a sweep's start, relative to the sensor at that start,
    /// assuming this motion's constant velocity: `exp(offset/dt · log ΔT)`. Identity when
    /// `dt_ns ≤ 0`. A point measured at `offset_ns` maps into the sweep-start frame as
    /// `sweep_start_from_offset(offset_ns) * p`.
    pub fn sweep_start_from_offset(&self, offset_ns: i64) -> Isometry3<f64> {
        if self.dt_ns <= 0 {
            return Isometry3::identity();
        }
        let s = offset_ns as f64 / self.dt_ns as f64;
        se3_exp(&(se3_log(&self.previous_from_current) * s))
    }
}

/// An IMU rotation increment between two sweeps, used as a prior.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuRotation {
    /// Rotation of the current sweep's sensor frame in the previous one's.
    pub previous_from_current: UnitQuaternion<f64>,
    /// Covariance of that rotation, rad² (previous sensor frame axes); must be positive definite.
    pub covariance_rad2: Matrix3<f64>,
}

/// What one sweep gave.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OdometryStep {
    /// The sweep's timestamp, ns.
    pub stamp_ns: i64,
    /// Sweeps registered before this one since the start.
    pub index: u64,
    /// The pose of the sensor: maps sensor points into the odometry (world) frame.
    pub world_from_sensor: Isometry3<f64>,
    /// The motion since the previous sweep, `T_{t-1}⁻¹ · T_t`.
    pub previous_from_current: Isometry3<f64>,
    /// How the registration went.
    pub status: TrackStatus,
    /// The ICP result (absent on the first sweep and when ICP failed).
    pub icp: Option<IcpResult>,
    /// The adaptive threshold σ used, m.
    pub threshold_m: f64,
    /// Points kept after the range filter.
    pub points: usize,
    /// Registration source points.
    pub source_points: usize,
    /// Whether the sweep's points were added to the map.
    pub keyframe: bool,
    /// Map points after the update.
    pub map_points: usize,
    /// The degeneracy analysis, when configured and the registration succeeded.
    pub degeneracy: Option<Degeneracy>,
    /// Whether `degeneracy` found a degenerate direction.
    pub degenerate: bool,
}

/// KISS-ICP's adaptive threshold (Vizzo et al. 2023, Sec. III-C).
#[derive(Clone, Copy, Debug)]
struct AdaptiveThreshold {
    sse: f64,
    samples: u64,
    min_motion_m: f64,
    max_range_m: f64,
}

impl AdaptiveThreshold {
    fn new(initial_m: f64, min_motion_m: f64, max_range_m: f64) -> Self {
        Self {
            sse: initial_m * initial_m,
            samples: 1,
            min_motion_m,
            max_range_m,
        }
    }

    fn value(&self) -> f64 {
        (self.sse / self.samples as f64).sqrt()
    }

    fn update(&mut self, deviation: &Isometry3<f64>) {
        let theta = deviation.rotation.angle();
        let e = deviation.translation.vector.norm() + 2.0 * self.max_range_m * (theta / 2.0).sin();
        if e > self.min_motion_m {
            self.sse += e * e;
            self.samples += 1;
        }
    }
}

/// A registration's outcome: pose, status, ICP result, degeneracy of the point-to-point pose
/// with its flag.
type Estimate = (
    Isometry3<f64>,
    TrackStatus,
    Option<IcpResult>,
    Option<(Option<Degeneracy>, bool)>,
);

/// Scan-to-map LiDAR odometry. See the module documentation.
#[derive(Clone, Debug)]
pub struct Odometry {
    cfg: OdometryConfig,
    icp: Icp,
    refine: Icp,
    map: VoxelMap,
    sampler: VoxelSampler,
    threshold: AdaptiveThreshold,
    frame: Vec<Vector3<f64>>,
    frame_ds: Vec<Vector3<f64>>,
    source: Vec<Vector3<f64>>,
    timed: Vec<Point>,
    skewed: Vec<Point>,
    /// Continuous time: the sweep's raw points with their fraction of the sweep's motion,
    /// subsampled as `frame_ds` and as `source`.
    timed_ds: Vec<(Vector3<f64>, f64)>,
    timed_source: Vec<(Vector3<f64>, f64)>,
    deskewer: crate::deskew::Deskewer,
    last_pose: Isometry3<f64>,
    last_delta: Isometry3<f64>,
    last_keyframe: Option<Isometry3<f64>>,
    last_stamp_ns: Option<i64>,
    last_motion: Option<SweepMotion>,
    count: u64,
    /// Sweeps lost since the last one registered or initialised.
    lost_in_a_row: usize,
}

impl Odometry {
    /// Checks the parameters and builds an empty odometry.
    pub fn new(cfg: OdometryConfig) -> Result<Self, RegistrationConfigError> {
        RegistrationConfigError::positive("max_range_m", cfg.max_range_m)?;
        RegistrationConfigError::non_negative("min_range_m", cfg.min_range_m)?;
        RegistrationConfigError::positive("initial_threshold_m", cfg.initial_threshold_m)?;
        RegistrationConfigError::non_negative("min_motion_m", cfg.min_motion_m)?;
        RegistrationConfigError::non_negative(
            "keyframe_translation_m",
            cfg.keyframe_translation_m,
        )?;
        RegistrationConfigError::non_negative("keyframe_rotation_rad", cfg.keyframe_rotation_rad)?;
        RegistrationConfigError::non_negative(
            "continuous_start_weight",
            cfg.continuous_start_weight,
        )?;
        RegistrationConfigError::non_negative(
            "continuous_motion_weight",
            cfg.continuous_motion_weight,
        )?;
        if !(1..=4).contains(&cfg.deskew_passes) {
            return Err(RegistrationConfigError::Invalid {
                name: "deskew_passes",
                value: cfg.deskew_passes as f64,
                expected: "1 to 4",
            });
        }
        if cfg.min_range_m >= cfg.max_range_m {
            return Err(RegistrationConfigError::Invalid {
                name: "min_range_m",
                value: cfg.min_range_m,
                expected: "< max_range_m",
            });
        }
        if let Some(d) = &cfg.degeneracy {
            d.validate()?;
        }
        let map = VoxelMap::new(VoxelMapConfig {
            voxel_size_m: cfg.voxel_size_m,
            max_points_per_voxel: cfg.max_points_per_voxel,
            max_distance_m: cfg.max_range_m,
            max_voxels: VoxelMapConfig::voxels_within(DEFAULT_MAP_BYTES, cfg.max_points_per_voxel),
        })?;
        let sigma = cfg.initial_threshold_m;
        let refine = Icp::new(IcpConfig {
            method: IcpMethod::PointToPlane,
            kernel: RobustKernel::GemanMcClure {
                scale_m: 0.2 * cfg.voxel_size_m,
            },
            max_correspondence_m: cfg.voxel_size_m,
            max_iterations: 50,
            // Plane pairs switch between neighbouring voxels near the optimum: stop at 1 mm / 1 mrad.
            convergence_update: cfg.convergence_update.max(1e-3),
            min_correspondences: cfg.min_correspondences,
        })?;
        let icp = Icp::new(IcpConfig {
            method: IcpMethod::PointToPointGaussNewton,
            kernel: RobustKernel::GemanMcClure {
                scale_m: sigma.sqrt(),
            },
            max_correspondence_m: 3.0 * sigma,
            max_iterations: cfg.max_iterations,
            convergence_update: cfg.convergence_update,
            min_correspondences: cfg.min_correspondences,
        })?;
        Ok(Self {
            cfg,
            icp,
            refine,
            map,
            sampler: VoxelSampler::new(),
            threshold: AdaptiveThreshold::new(sigma, cfg.min_motion_m, cfg.max_range_m),
            frame: Vec::new(),
            frame_ds: Vec::new(),
            source: Vec::new(),
            timed: Vec::new(),
            skewed: Vec::new(),
            timed_ds: Vec::new(),
            timed_source: Vec::new(),
            deskewer: crate::deskew::Deskewer::new(crate::deskew::Reference::End),
            last_pose: Isometry3::identity(),
            last_delta: Isometry3::identity(),
            last_keyframe: None,
            last_stamp_ns: None,
            last_motion: None,
            count: 0,
            lost_in_a_row: 0,
        })
    }

    /// The parameters.
    pub fn config(&self) -> &OdometryConfig {
        &self.cfg
    }

    /// Forgets everything: the next sweep starts a new map at the identity.
    pub fn reset(&mut self) {
        self.map.clear();
        self.threshold = AdaptiveThreshold::new(
            self.cfg.initial_threshold_m,
            self.cfg.min_motion_m,
            self.cfg.max_range_m,
        );
        self.last_pose = Isometry3::identity();
        self.last_delta = Isometry3::identity();
        self.last_keyframe = None;
        self.last_stamp_ns = None;
        self.last_motion = None;
        self.count = 0;
        self.lost_in_a_row = 0;
    }

    /// The pose of the last sweep registered (`world_from_sensor`).
    pub fn world_from_sensor(&self) -> Isometry3<f64> {
        self.last_pose
    }

    /// The motion between the last two sweeps and their time difference, for deskewing the
    /// next sweep (see the time convention in the module documentation); `None` before the
    /// second sweep.
    pub fn last_motion(&self) -> Option<SweepMotion> {
        self.last_motion
    }

    /// The local map (world frame).
    pub fn map(&self) -> &VoxelMap {
        &self.map
    }

    /// The registration source points of the last sweep (sensor frame).
    pub fn last_source(&self) -> &[Vector3<f64>] {
        &self.source
    }

    /// Registers one sweep of a decoder's points (sensor frame) stamped `stamp_ns`.
    pub fn register_points(&mut self, points: &[Point], stamp_ns: i64) -> OdometryStep {
        self.register(
            points
                .iter()
                .map(|p| Vector3::new(f64::from(p.x), f64::from(p.y), f64::from(p.z))),
            stamp_ns,
            None,
        )
    }

    /// Registers a sweep ([`crate::sweep::Sweep`]) at its timestamp.
    pub fn register_sweep(&mut self, sweep: &crate::sweep::Sweep) -> OdometryStep {
        self.register_points(&sweep.points, sweep.timestamp_ns)
    }

    /// Registers one sweep's points (sensor frame, m) stamped `stamp_ns`, with an optional
    /// IMU rotation increment since the previous sweep.
    pub fn register(
        &mut self,
        points: impl IntoIterator<Item = Vector3<f64>>,
        stamp_ns: i64,
        imu: Option<&ImuRotation>,
    ) -> OdometryStep {
        let (min_sq, max_sq) = self.range_sq();
        self.frame.clear();
        self.frame.extend(points.into_iter().filter(|p| {
            let r2 = p.norm_squared();
            r2.is_finite() && r2 > min_sq && r2 < max_sq
        }));
        self.sample_frame();
        let sigma = self.threshold.value();
        let (prediction, prior) = self.predict(stamp_ns, false, imu);
        let est = self.estimate(&prediction, prior.as_ref(), sigma);
        self.finish(prediction, est, sigma, stamp_ns, self.frame.len())
    }

    /// Registers one sweep of a decoder's points (sensor frame) WITH their time offsets
    /// ([`Point::t`], ns after `stamp_ns`, the sweep's first firing), deskewing as it goes.
    ///
    /// The pose is the sensor's at the sweep's END (its last point, `stamp_ns + max t`; the
    /// step's `stamp_ns` says so), so the motion that deskews the sweep, from the previous
    /// sweep's end (this one's start) to this end, is the very motion being estimated: the
    /// sweep is deskewed to its end with the predicted motion (constant velocity, or nothing
    /// before the second sweep) and registered; then, up to `deskew_passes − 1` times,
    /// deskewed again from the raw points with the motion half-way between the last one used
    /// and the one just estimated, and registered again from the last pose, stopping early
    /// when the two motions agree (1 cm at max range) or disagree more than at the previous
    /// pass. The map gets the last deskewed points. Stamping at
    /// the start instead would deskew each sweep with the previous sweep's motion, and every
    /// change of yaw rate would show as a transient yaw error of its size × one sweep.
    ///
    /// With [`OdometryConfig::continuous_time`], no deskew passes: the sweep's start and end
    /// poses are estimated together from its raw points (see [`Icp::align_continuous`]),
    /// the start held near the previous sweep's end and the motion near the predicted one,
    /// and the map gets the sweep deskewed to its end with the motion found.
    ///
    /// Feed a sequence either to this method or to [`Odometry::register`], not both; an IMU
    /// increment is between the ends of consecutive sweeps.
    pub fn register_timed(
        &mut self,
        points: &[Point],
        stamp_ns: i64,
        imu: Option<&ImuRotation>,
    ) -> OdometryStep {
        let (min_sq, max_sq) = self.range_sq();
        self.timed.clear();
        self.timed.extend(points.iter().copied().filter(|p| {
            let r2 = f64::from(p.x).powi(2) + f64::from(p.y).powi(2) + f64::from(p.z).powi(2);
            r2.is_finite() && r2 > min_sq && r2 < max_sq
        }));
        let end_ns =
            stamp_ns.saturating_add(i64::from(self.timed.iter().map(|p| p.t).max().unwrap_or(0)));
        let sigma = self.threshold.value();
        let (prediction, prior) = self.predict(end_ns, true, imu);
        let dt_ns = self
            .last_stamp_ns
            .map_or(0, |prev| end_ns.saturating_sub(prev));
        if self.cfg.continuous_time {
            return self.register_continuous(stamp_ns, end_ns, prediction, prior, sigma);
        }
        let passes = self.cfg.deskew_passes;
        let mut guess = prediction;
        // The motion the sweep is deskewed with: the predicted one, then half-way from the
        // last one used to the one just estimated.
        let mut motion = se3_log(&(self.last_pose.inverse() * prediction));
        let mut est = None;
        let mut last_gap = f64::INFINITY;
        for _ in 0..passes {
            self.skewed.clear();
            self.skewed.extend_from_slice(&self.timed);
            if let (Some(_), Some(tw)) = (
                self.last_stamp_ns,
                crate::deskew::Twist::from_relative_motion(&se3_exp(&motion), dt_ns as f64 * 1e-9),
            ) {
                self.deskewer
                    .deskew_constant_velocity(&mut self.skewed, &tw);
            }
            self.frame.clear();
            self.frame.extend(
                self.skewed
                    .iter()
                    .map(|p| Vector3::new(f64::from(p.x), f64::from(p.y), f64::from(p.z))),
            );
            self.sample_frame();
            let e = self.estimate(&guess, prior.as_ref(), sigma);
            guess = e.0;
            let stop = matches!(e.1, TrackStatus::Lost(_) | TrackStatus::Initialized)
                || self.last_stamp_ns.is_none();
            est = Some(e);
            if stop {
                break;
            }
            let estimated = se3_log(&(self.last_pose.inverse() * guess));
            // The disagreement of the motion the sweep was deskewed with and the one it gave,
            // as a displacement at max range. Converged: stop. Growing: the sweep does not
            // determine its own motion better than the last pass did (measured: along a street
            // the forward speed drifts pass after pass, and 8 undamped passes diverge), stop.
            let d = estimated - motion;
            let gap =
                d.fixed_rows::<3>(0).norm() + self.cfg.max_range_m * d.fixed_rows::<3>(3).norm();
            if gap < 0.01 || gap > last_gap {
                break;
            }
            last_gap = gap;
            motion = (motion + estimated) * 0.5;
        }
        let est = est.unwrap_or((prediction, TrackStatus::Initialized, None, None));
        self.finish(prediction, est, sigma, end_ns, self.frame.len())
    }

    /// [`Odometry::register_timed`] with continuous-time ICP: the filtered points are in
    /// `timed`, the sweep ends at `end_ns`.
    fn register_continuous(
        &mut self,
        stamp_ns: i64,
        end_ns: i64,
        prediction: Isometry3<f64>,
        prior: Option<RotationPrior>,
        sigma: f64,
    ) -> OdometryStep {
        // A point's fraction of the motion from the previous sweep's end to this one's.
        let (start_ns, span_ns) = match self.last_stamp_ns {
            Some(prev) if end_ns > prev => (prev, (end_ns - prev) as f64),
            _ => (end_ns, 1.0),
        };
        let vs = self.cfg.voxel_size_m;
        self.timed_source.clear();
        self.timed_source.extend(self.timed.iter().map(|p| {
            let at = stamp_ns.saturating_add(i64::from(p.t));
            let fraction = (at.saturating_sub(start_ns) as f64 / span_ns).clamp(0.0, 1.0);
            (
                Vector3::new(f64::from(p.x), f64::from(p.y), f64::from(p.z)),
                fraction,
            )
        }));
        self.sampler
            .sample_by(&self.timed_source, |p| p.0, 0.5 * vs, &mut self.timed_ds);
        self.sampler
            .sample_by(&self.timed_ds, |p| p.0, 1.5 * vs, &mut self.timed_source);
        // Until estimated, the registration source is the raw sweep (for an empty map).
        self.source.clear();
        self.source.extend(self.timed_source.iter().map(|p| p.0));
        let start = self.last_pose;
        let (est, xi) = if self.last_stamp_ns.is_some() {
            self.estimate_continuous(&start, &prediction, prior.as_ref(), sigma)
        } else {
            (
                (prediction, TrackStatus::Initialized, None, None),
                Vector6::zeros(),
            )
        };
        // The map and the source get the sweep deskewed to its end with the motion found.
        if self.last_stamp_ns.is_some() {
            self.refine
                .deskew_to_end(&self.timed_ds, &xi, &mut self.frame_ds);
            self.refine
                .deskew_to_end(&self.timed_source, &xi, &mut self.source);
        } else {
            self.frame_ds.clear();
            self.frame_ds.extend(self.timed_ds.iter().map(|p| p.0));
        }
        self.finish(prediction, est, sigma, end_ns, self.timed.len())
    }

    /// As [`Odometry::estimate`] for the timed source, by continuous-time ICP from `start`;
    /// also the motion over the sweep (`log(B⁻¹·E)`) found, or predicted.
    fn estimate_continuous(
        &mut self,
        start: &Isometry3<f64>,
        initial: &Isometry3<f64>,
        prior: Option<&RotationPrior>,
        sigma: f64,
    ) -> (Estimate, Vector6<f64>) {
        let prediction = *initial;
        let predicted_motion = se3_log(&(start.inverse() * prediction));
        if !self.map_registrable() {
            return (
                (prediction, TrackStatus::Initialized, None, None),
                predicted_motion,
            );
        }
        let _ = self.icp.set_gate(
            3.0 * sigma,
            RobustKernel::GemanMcClure {
                scale_m: sigma.sqrt(),
            },
        );
        let n = self.timed_source.len() as f64;
        let l2 = CT_ROTATION_ARM_M * CT_ROTATION_ARM_M;
        let diag = |w: f64| Matrix6::from_diagonal(&Vector6::new(w, w, w, w * l2, w * l2, w * l2));
        let priors = SweepPriors {
            start: *start,
            start_information: diag(self.cfg.continuous_start_weight * n),
            motion: predicted_motion,
            // No motion seen yet: nothing to hold it to.
            motion_information: if self.last_motion.is_some() {
                diag(self.cfg.continuous_motion_weight * n)
            } else {
                Matrix6::zeros()
            },
        };
        let mut aligned = self.icp.align_continuous(
            &self.timed_source,
            &self.map,
            start,
            &prediction,
            &priors,
            prior,
        );
        let mut coarse_degeneracy: Option<(Option<Degeneracy>, bool)> = None;
        if let (Some(dc), Ok(coarse)) = (&self.cfg.degeneracy, &aligned) {
            self.icp
                .deskew_to_end(&self.timed_source, &coarse.motion, &mut self.source);
            let d = analyse(dc, &self.map, &self.source, &coarse.end.target_from_source);
            coarse_degeneracy = Some((d, d.as_ref().is_some_and(|d| d.is_degenerate(dc))));
        }
        let free = coarse_degeneracy.as_ref().is_some_and(|(_, flag)| *flag);
        if let (OdometryMethod::PointToPlane, Ok(coarse), false) = (self.cfg.method, &aligned, free)
        {
            if let Ok(fine) = self.refine.align_continuous(
                &self.timed_source,
                &self.map.with_normals(),
                &coarse.start,
                &coarse.end.target_from_source,
                &priors,
                prior,
            ) {
                aligned = Ok(ContinuousResult {
                    end: IcpResult {
                        iterations: coarse.end.iterations + fine.end.iterations,
                        converged: coarse.end.converged && fine.end.converged,
                        ..fine.end
                    },
                    ..fine
                });
            }
        }
        match aligned {
            Ok(r) => (
                (
                    r.end.target_from_source,
                    TrackStatus::of(r.end.converged),
                    Some(r.end),
                    coarse_degeneracy,
                ),
                r.motion,
            ),
            Err(e) => (
                (prediction, TrackStatus::Lost(e), None, coarse_degeneracy),
                predicted_motion,
            ),
        }
    }

    fn range_sq(&self) -> (f64, f64) {
        (
            self.cfg.min_range_m * self.cfg.min_range_m,
            self.cfg.max_range_m * self.cfg.max_range_m,
        )
    }

    /// `frame` → `frame_ds` (map points) → `source` (registration points).
    fn sample_frame(&mut self) {
        let vs = self.cfg.voxel_size_m;
        self.sampler
            .sample(&self.frame, 0.5 * vs, &mut self.frame_ds);
        self.sampler
            .sample(&self.frame_ds, 1.5 * vs, &mut self.source);
    }

    /// Whether the map is one to register against: at least `min_correspondences` points, and
    /// fewer than `max_lost_sweeps` sweeps lost against it in a row. Since a lost sweep does
    /// not update the map, a map of a handful of points, or one the sensor has left, would
    /// keep every later sweep lost.
    fn map_registrable(&self) -> bool {
        let stale = self.cfg.max_lost_sweeps > 0 && self.lost_in_a_row >= self.cfg.max_lost_sweeps;
        self.map.len() >= self.cfg.min_correspondences && !stale
    }

    /// The constant-velocity prediction and the IMU rotation prior.
    /// With `scaled`, the motion is constant in time, not per sweep: the last motion is
    /// scaled by the ratio of this sweep's stamp difference to the last one's (a first,
    /// partial sweep or a gap would otherwise predict the wrong distance), within 0.25–4×.
    /// Without, the last motion as it is.
    fn predict(
        &self,
        stamp_ns: i64,
        scaled: bool,
        imu: Option<&ImuRotation>,
    ) -> (Isometry3<f64>, Option<RotationPrior>) {
        let scale = match (self.last_motion, self.last_stamp_ns) {
            (Some(m), Some(prev)) if m.dt_ns > 0 => {
                (stamp_ns.saturating_sub(prev) as f64 / m.dt_ns as f64).clamp(0.25, 4.0)
            }
            _ => 1.0,
        };
        let delta = if !scaled || scale == 1.0 {
            self.last_delta
        } else {
            se3_exp(&(se3_log(&self.last_delta) * scale))
        };
        let mut prediction = self.last_pose * delta;
        let prior = imu.and_then(|imu| {
            let rot = self.last_pose.rotation * imu.previous_from_current;
            let r_prev = self.last_pose.rotation.to_rotation_matrix().into_inner();
            let cov_world = r_prev * imu.covariance_rad2 * r_prev.transpose();
            let information = cov_world.try_inverse()?;
            Some(RotationPrior {
                rotation: rot,
                information,
            })
        });
        if let Some(p) = &prior {
            prediction.rotation = p.rotation;
        }
        (prediction, prior)
    }

    /// Registers `source` to the map from `initial`: the pose, the status, the ICP result and
    /// the degeneracy of the point-to-point pose (with its flag). The state is not touched.
    fn estimate(
        &mut self,
        initial: &Isometry3<f64>,
        prior: Option<&RotationPrior>,
        sigma: f64,
    ) -> Estimate {
        let prediction = *initial;
        let mut coarse_degeneracy: Option<(Option<Degeneracy>, bool)> = None;
        let (pose, status, icp) = if !self.map_registrable() {
            (prediction, TrackStatus::Initialized, None)
        } else {
            // σ ≥ initial·√(1/n) > 0, so the gate is valid; keep the old one otherwise.
            let _ = self.icp.set_gate(
                3.0 * sigma,
                RobustKernel::GemanMcClure {
                    scale_m: sigma.sqrt(),
                },
            );
            let mut aligned =
                self.icp
                    .align_with_prior(&self.source, &self.map, &prediction, prior);
            // The degeneracy of the point-to-point pose decides whether planes may refine it:
            // along a free direction a plane fit has nothing to hold it.
            if let (Some(dc), Ok(coarse)) = (&self.cfg.degeneracy, &aligned) {
                let d = analyse(dc, &self.map, &self.source, &coarse.target_from_source);
                coarse_degeneracy = Some((d, d.as_ref().is_some_and(|d| d.is_degenerate(dc))));
            }
            let free = coarse_degeneracy.as_ref().is_some_and(|(_, flag)| *flag);
            if let (OdometryMethod::PointToPlane, Ok(coarse), false) =
                (self.cfg.method, &aligned, free)
            {
                // Refine on the planes, from the point-to-point pose, with a gate of one voxel.
                if let Ok(fine) = self.refine.align_with_prior(
                    &self.source,
                    &self.map.with_normals(),
                    &coarse.target_from_source,
                    prior,
                ) {
                    aligned = Ok(IcpResult {
                        iterations: coarse.iterations + fine.iterations,
                        converged: coarse.converged && fine.converged,
                        ..fine
                    });
                }
            }
            match aligned {
                Ok(r) => (r.target_from_source, TrackStatus::of(r.converged), Some(r)),
                Err(e) => (prediction, TrackStatus::Lost(e), None),
            }
        };
        (pose, status, icp, coarse_degeneracy)
    }

    /// Updates the threshold, the map and the motion with the estimate of the sweep now in
    /// `frame_ds` (`points` in range before subsampling).
    fn finish(
        &mut self,
        prediction: Isometry3<f64>,
        est: Estimate,
        sigma: f64,
        stamp_ns: i64,
        points: usize,
    ) -> OdometryStep {
        let (pose, status, icp, coarse_degeneracy) = est;
        let mut pose = pose;
        // Compositions drift off the unit sphere, and the drift compounds through the
        // prediction (Tₜ₋₁·ΔT): renormalise every stored rotation.
        pose.rotation.renormalize();
        let lost = matches!(status, TrackStatus::Lost(_));
        self.lost_in_a_row = if lost { self.lost_in_a_row + 1 } else { 0 };
        if !lost && status != TrackStatus::Initialized {
            self.threshold.update(&(prediction.inverse() * pose));
        }
        let (degeneracy, degenerate) = match (coarse_degeneracy, lost || icp.is_none()) {
            (Some(d), false) => d,
            _ => (None, false),
        };
        let initialized = status == TrackStatus::Initialized;
        if initialized {
            // A sweep registered against nothing: the few points before it were placed by no
            // registration either.
            self.map.clear();
        }
        let keyframe = initialized
            || (!lost
                && match &self.last_keyframe {
                    None => true,
                    Some(k) => {
                        let d = k.inverse() * pose;
                        d.translation.vector.norm() >= self.cfg.keyframe_translation_m
                            || d.rotation.angle() >= self.cfg.keyframe_rotation_rad
                    }
                });
        if keyframe {
            self.map.update(&self.frame_ds, &pose);
            if self.cfg.method == OdometryMethod::PointToPlane {
                self.map.refresh_normals(3, 0.1, 0.05);
            }
            self.last_keyframe = Some(pose);
        }
        let mut delta = self.last_pose.inverse() * pose;
        delta.rotation.renormalize();
        if let Some(prev) = self.last_stamp_ns {
            self.last_motion = Some(SweepMotion {
                previous_from_current: delta,
                dt_ns: stamp_ns.saturating_sub(prev),
            });
        }
        self.last_delta = delta;
        self.last_pose = pose;
        self.last_stamp_ns = Some(stamp_ns);
        let index = self.count;
        self.count += 1;
        OdometryStep {
            stamp_ns,
            index,
            world_from_sensor: pose,
            previous_from_current: delta,
            status,
            icp,
            threshold_m: sigma,
            points,
            source_points: self.source.len(),
            keyframe,
            map_points: self.map.len(),
            degeneracy,
            degenerate,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Translation3};

    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
        fn range(&mut self, a: f64, b: f64) -> f64 {
            a + (b - a) * self.next()
        }
    }

    /// A surface patch: `corner + u·a + v·b`, u, v ∈ [0, 1].
    type Patch = (Vector3<f64>, Vector3<f64>, Vector3<f64>);

    /// A street 200 m long: road, two façades, 200 parked boxes (cars, kiosks) and poles.
    fn street() -> Vec<Patch> {
        let v = Vector3::new;
        let mut s: Vec<Patch> = vec![
            (v(-100.0, -12.0, 0.0), v(200.0, 0.0, 0.0), v(0.0, 24.0, 0.0)),
            (v(-100.0, 12.0, 0.0), v(200.0, 0.0, 0.0), v(0.0, 0.0, 8.0)),
            (v(-100.0, -12.0, 0.0), v(200.0, 0.0, 0.0), v(0.0, 0.0, 8.0)),
        ];
        let mut rng = Lcg(99);
        for _ in 0..200 {
            let (x, side) = (
                rng.range(-95.0, 95.0),
                if rng.next() < 0.5 { 1.0 } else { -1.0 },
            );
            let y = side * rng.range(4.0, 9.0);
            let (lx, ly, h) = (
                rng.range(1.0, 4.5),
                rng.range(1.0, 2.5),
                rng.range(1.0, 3.0),
            );
            let c = v(x, y, 0.0);
            s.push((c, v(lx, 0.0, 0.0), v(0.0, 0.0, h)));
            s.push((c + v(0.0, ly, 0.0), v(lx, 0.0, 0.0), v(0.0, 0.0, h)));
            s.push((c, v(0.0, ly, 0.0), v(0.0, 0.0, h)));
            s.push((c + v(lx, 0.0, 0.0), v(0.0, ly, 0.0), v(0.0, 0.0, h)));
            s.push((c + v(0.0, 0.0, h), v(lx, 0.0, 0.0), v(0.0, ly, 0.0)));
        }
        // Square poles every 3 m on both sides.
        let mut x = -96.0;
        while x < 100.0 {
            for y in [-3.5, 3.5] {
                let c = v(x, y, 0.0);
                s.push((c, v(0.3, 0.0, 0.0), v(0.0, 0.0, 4.0)));
                s.push((c, v(0.0, 0.3, 0.0), v(0.0, 0.0, 4.0)));
                s.push((c + v(0.3, 0.0, 0.0), v(0.0, 0.3, 0.0), v(0.0, 0.0, 4.0)));
                s.push((c + v(0.0, 0.3, 0.0), v(0.3, 0.0, 0.0), v(0.0, 0.0, 4.0)));
            }
            x += 3.0;
        }
        // Tiles of at most 4 m × 4 m, so a sweep samples only what is near.
        let mut tiles = Vec::new();
        for (c, a, b) in s {
            let (na, nb) = (
                (a.norm() / 4.0).ceil().max(1.0),
                (b.norm() / 4.0).ceil().max(1.0),
            );
            for i in 0..na as usize {
                for j in 0..nb as usize {
                    let (i, j) = (i as f64, j as f64);
                    tiles.push((c + a * (i / na) + b * (j / nb), a / na, b / nb));
                }
            }
        }
        tiles
    }

    /// A new random sampling (no noise) of the tiles within 30 m of the sensor at `pose`, in
    /// the sensor frame, 40 points / m² up to 8 m and falling as 1/r² beyond (per tile, by its
    /// centre's range): every sweep sees other surface points, as a LiDAR does.
    fn observe(world: &[Patch], pose: &Isometry3<f64>, seed: u64) -> Vec<Vector3<f64>> {
        let inv = pose.inverse();
        let mut rng = Lcg(seed);
        let mut out = Vec::new();
        for (c, a, b) in world {
            let centre = (inv * Point3::from(c + a * 0.5 + b * 0.5)).coords.norm();
            if centre > 33.0 {
                continue;
            }
            let density = 40.0 * (64.0 / (centre * centre)).min(1.0);
            let n = (a.cross(b).norm() * density + rng.next()) as usize;
            for _ in 0..n {
                let p = c + a * rng.next() + b * rng.next();
                let q = (inv * Point3::from(p)).coords;
                if q.norm() < 30.0 {
                    out.push(q);
                }
            }
        }
        out
    }

    #[test]
    fn the_prediction_is_constant_velocity_in_time() {
        // 10 m/s along x; the first interval is 40 ms (a partial first sweep), then 100 ms.
        let world = street();
        let mut odo = Odometry::new(OdometryConfig {
            method: OdometryMethod::PointToPlane,
            ..OdometryConfig::for_max_range(100.0)
        })
        .unwrap();
        let at = |x: f64| {
            Isometry3::from_parts(
                Translation3::new(-45.0 + x, 0.0, 1.8),
                UnitQuaternion::identity(),
            )
        };
        odo.register(observe(&world, &at(0.0), 1), 0, None);
        let step = odo.register(observe(&world, &at(0.4), 2), 40_000_000, None);
        assert_eq!(step.status, TrackStatus::Converged);
        assert!(
            (step.previous_from_current.translation.x - 0.4).abs() < 0.03,
            "{step:?}"
        );
        // 100 ms on: 1 m further (2.5× the last motion), not 0.4 m.
        let (p, _) = odo.predict(140_000_000, true, None);
        let ahead = (odo.world_from_sensor().inverse() * p).translation.vector;
        let expect = step.previous_from_current.translation.vector * 2.5;
        assert!((ahead - expect).norm() < 1e-3, "{ahead:?} vs {expect:?}");
        // A long gap is capped at 4× the last motion; a stamp at or before the last, 0.25×.
        let (p, _) = odo.predict(1_040_000_000, true, None);
        let ahead = (odo.world_from_sensor().inverse() * p).translation.vector;
        assert!((ahead - step.previous_from_current.translation.vector * 4.0).norm() < 1e-3);
        let (p, _) = odo.predict(40_000_000, true, None);
        let ahead = (odo.world_from_sensor().inverse() * p).translation.vector;
        assert!((ahead - step.previous_from_current.translation.vector * 0.25).norm() < 1e-3);
        // Untimed registration predicts per sweep, whatever the stamps.
        let (p, _) = odo.predict(140_000_000, false, None);
        let ahead = (odo.world_from_sensor().inverse() * p).translation.vector;
        assert!((ahead - step.previous_from_current.translation.vector).norm() < 1e-12);
    }

    #[test]
    fn tracks_a_known_trajectory_on_exact_data() {
        track_known_trajectory(OdometryMethod::PointToPoint, 0.1);
    }

    #[test]
    fn point_to_plane_tracks_a_known_trajectory_closer() {
        track_known_trajectory(OdometryMethod::PointToPlane, 0.03);
    }

    fn track_known_trajectory(method: OdometryMethod, max_step_error_m: f64) {
        let world = street();
        let mut odo = Odometry::new(OdometryConfig {
            method,
            ..OdometryConfig::for_max_range(100.0)
        })
        .unwrap();
        // 24 sweeps at 10 Hz: from rest, +1.25 m/s per sweep to 10 m/s, then a left turn whose
        // yaw rate ramps to 30°/s, then straight again; a slight drift to the left.
        let mut truth = Vec::new();
        let mut pose = Isometry3::from_parts(
            Translation3::new(-45.0, 0.0, 1.8),
            UnitQuaternion::identity(),
        );
        for i in 0..24 {
            truth.push(pose);
            let speed = f64::from(i.min(8)) * 0.125;
            let yaw_deg = match i {
                0..=9 => 0.0,
                10..=12 => f64::from(i - 9),
                13..=15 => 3.0,
                16..=18 => f64::from(19 - i),
                _ => 0.0,
            };
            pose *= Isometry3::from_parts(
                Translation3::new(speed, 0.01 * speed, 0.0),
                UnitQuaternion::from_scaled_axis(Vector3::z() * yaw_deg.to_radians()),
            );
        }
        let mut prev: Option<Isometry3<f64>> = None;
        let mut worst = (0.0f64, 0.0f64);
        for (i, t) in truth.iter().enumerate() {
            let step = odo.register(observe(&world, t, i as u64), i as i64 * 100_000_000, None);
            if i > 0 {
                assert_eq!(step.status, TrackStatus::Converged, "sweep {i}");
                // The relative motion against the truth's.
                let true_delta = prev.unwrap().inverse() * t;
                let d = true_delta.inverse() * step.previous_from_current;
                eprintln!(
                    "sweep {i}: {:.4} m {:.4} deg off the true motion",
                    d.translation.vector.norm(),
                    d.rotation.angle().to_degrees()
                );
                worst.0 = worst.0.max(d.translation.vector.norm());
                worst.1 = worst.1.max(d.rotation.angle().to_degrees());
            }
            prev = Some(*t);
        }
        // Point-to-point ICP on a 1 m voxel map is a few cm off per sweep on these randomly
        // resampled surfaces (point-to-plane a few mm); a registration that fails to track is
        // off by a whole step (≥ 0.125 m) or diverges.
        assert!(
            worst.0 < max_step_error_m && worst.1 < 0.2,
            "worst per-sweep error {worst:?}"
        );
        let end = truth[0].inverse() * truth[23];
        let est = odo.world_from_sensor();
        let drift = (end.inverse() * est).translation.vector.norm();
        let length: f64 = truth
            .windows(2)
            .map(|w| (w[1].translation.vector - w[0].translation.vector).norm())
            .sum();
        assert!(drift < 0.01 * length, "drift {drift} m over {length} m");
        let m = odo.last_motion().unwrap();
        assert_eq!(m.dt_ns, 100_000_000);
        // The last motion: 1 m forward (+1 cm left) in 0.1 s, no turn; within the per-sweep
        // bounds above (0.1 m and 0.2° per 0.1 s).
        let tw = m.twist_per_s().unwrap();
        assert!(
            (tw[0] - 10.0).abs() < 1.0 && tw[5].abs() < 2f64.to_radians(),
            "{tw}"
        );
        let half = m.sweep_start_from_offset(50_000_000);
        assert!((half.translation.vector.x - 0.5).abs() < 0.05);
    }

    #[test]
    fn an_imu_rotation_prior_holds_the_rotation() {
        let world = street();
        let mut odo = Odometry::new(OdometryConfig::for_max_range(100.0)).unwrap();
        let mut pose = Isometry3::from_parts(
            Translation3::new(-20.0, 0.0, 1.8),
            UnitQuaternion::identity(),
        );
        let step = Isometry3::from_parts(
            Translation3::new(0.3, 0.0, 0.0),
            UnitQuaternion::from_scaled_axis(Vector3::z() * 4f64.to_radians()),
        );
        let first = pose;
        for i in 0..8 {
            // The gyro's increment since the previous sweep, 0.01° (1σ) on each axis.
            let imu = (i > 0).then(|| ImuRotation {
                previous_from_current: step.rotation,
                covariance_rad2: Matrix3::identity() * 0.01f64.to_radians().powi(2),
            });
            let st = odo.register(
                observe(&world, &pose, i),
                i as i64 * 100_000_000,
                imu.as_ref(),
            );
            let truth = first.inverse() * pose;
            let err = truth
                .rotation
                .angle_to(&st.world_from_sensor.rotation)
                .to_degrees();
            // 8 increments of 4° each held to the prior's 0.01°: well under 0.1° at the end.
            assert!(err < 0.1, "sweep {i}: {err}°");
            pose *= step;
        }
        // A gyro biased by +0.5° per sweep with an overconfident covariance (1e-4°) pulls the
        // estimate with it: the prior really enters the normal equations.
        let mut odo = Odometry::new(OdometryConfig::for_max_range(100.0)).unwrap();
        let mut pose = first;
        let biased = UnitQuaternion::from_scaled_axis(Vector3::z() * 4.5f64.to_radians());
        let mut last = Isometry3::identity();
        for i in 0..8 {
            let imu = (i > 0).then(|| ImuRotation {
                previous_from_current: biased,
                covariance_rad2: Matrix3::identity() * 1e-4f64.to_radians().powi(2),
            });
            last = odo
                .register(
                    observe(&world, &pose, i),
                    i as i64 * 100_000_000,
                    imu.as_ref(),
                )
                .world_from_sensor;
            pose *= step;
        }
        let truth = first.inverse() * pose * step.inverse();
        let err = truth.rotation.angle_to(&last.rotation).to_degrees();
        assert!((err - 3.5).abs() < 0.1, "{err}° (7 × 0.5° expected)");
    }

    #[test]
    fn a_sweep_with_no_overlap_is_lost_not_guessed() {
        let world = street();
        let mut odo = Odometry::new(OdometryConfig::for_max_range(100.0)).unwrap();
        let p0 =
            Isometry3::from_parts(Translation3::new(0.0, 0.0, 1.8), UnitQuaternion::identity());
        odo.register(observe(&world, &p0, 1), 0, None);
        // The next sweep sees only points far from anything in the map.
        let far: Vec<_> = (0..200)
            .map(|i| Vector3::new(30.0, f64::from(i) * 0.1 - 10.0, 20.0))
            .collect();
        let step = odo.register(far, 100_000_000, None);
        assert!(matches!(
            step.status,
            TrackStatus::Lost(IcpError::TooFewCorrespondences { .. })
        ));
        assert!(!step.keyframe);
        assert_eq!(step.world_from_sensor, Isometry3::identity()); // the prediction
    }

    #[test]
    fn a_map_lost_against_max_lost_sweeps_times_in_a_row_is_started_again() {
        let world = street();
        let p0 =
            Isometry3::from_parts(Translation3::new(0.0, 0.0, 1.8), UnitQuaternion::identity());
        // A wall no sweep of the street sees, dense enough to register against itself.
        let far: Vec<_> = (0..400)
            .map(|i| {
                let (u, v) = (f64::from(i % 20), f64::from(i / 20));
                Vector3::new(30.0 + 0.05 * u * v.sin(), u * 0.5 - 5.0, 15.0 + v * 0.5)
            })
            .collect();
        for max_lost_sweeps in [0, 3] {
            let mut odo = Odometry::new(OdometryConfig {
                max_lost_sweeps,
                ..OdometryConfig::for_max_range(100.0)
            })
            .unwrap();
            odo.register(observe(&world, &p0, 1), 0, None);
            let statuses: Vec<_> = (1..8)
                .map(|i| odo.register(far.clone(), i * 100_000_000, None).status)
                .collect();
            let lost = |s: &TrackStatus| matches!(s, TrackStatus::Lost(_));
            if max_lost_sweeps == 0 {
                assert!(statuses.iter().all(lost), "{statuses:?}");
            } else {
                assert!(statuses[..3].iter().all(lost), "{statuses:?}");
                assert_eq!(statuses[3], TrackStatus::Initialized, "{statuses:?}");
                assert!(
                    statuses[4..].iter().all(|s| *s == TrackStatus::Converged),
                    "{statuses:?}"
                );
            }
        }
    }

    #[test]
    fn a_sparse_first_sweep_is_no_map_to_be_lost_against() {
        let world = street();
        let at = Isometry3::from_parts(
            Translation3::new(-45.0, 0.0, 1.8),
            UnitQuaternion::identity(),
        );
        let timed = |pts: Vec<Vector3<f64>>| -> Vec<Point> {
            pts.iter()
                .map(|p| Point {
                    x: p.x as f32,
                    y: p.y as f32,
                    z: p.z as f32,
                    ..Point::default()
                })
                .collect()
        };
        for (way, continuous_time) in [(0, false), (1, false), (1, true)] {
            let mut odo = Odometry::new(OdometryConfig {
                continuous_time,
                // At rest: the sweep that restarts the map must fill it, keyframe or not.
                keyframe_translation_m: 1.0,
                ..OdometryConfig::for_max_range(100.0)
            })
            .unwrap();
            let mut register = |pts: Vec<Vector3<f64>>, i: i64| {
                if way == 0 {
                    odo.register(pts, i * 100_000_000, None)
                } else {
                    odo.register_timed(&timed(pts), i * 100_000_000, None)
                }
            };
            // One point, far from everything the next sweeps see.
            let first = register(vec![Vector3::new(50.0, 50.0, 50.0)], 0);
            assert_eq!(
                (first.status, first.map_points),
                (TrackStatus::Initialized, 1)
            );
            let again = register(observe(&world, &at, 1), 1);
            assert_eq!(
                again.status,
                TrackStatus::Initialized,
                "{way} {continuous_time}"
            );
            assert!(again.keyframe && again.map_points > 1000, "{again:?}");
            for i in 2..5 {
                let step = register(observe(&world, &at, i as u64), i);
                assert_eq!(step.status, TrackStatus::Converged, "sweep {i}: {step:?}");
                // Point-to-point on these resampled surfaces: a few cm (see above).
                let off = step.world_from_sensor.translation.vector.norm();
                assert!(off < 0.1, "{way} {continuous_time} sweep {i}: {off} m");
            }
            // The lone point went with the map it made.
            assert!(odo.map().points().all(|p| p.norm() < 40.0));
        }
    }

    #[test]
    fn keyframes_follow_motion() {
        let world = street();
        let mut odo = Odometry::new(OdometryConfig {
            keyframe_translation_m: 0.4,
            keyframe_rotation_rad: 10f64.to_radians(),
            ..OdometryConfig::for_max_range(100.0)
        })
        .unwrap();
        // At rest for four sweeps, then moving off: 0.05, 0.15, 0.30, 0.50, 0.75, 1.05 m.
        let xs = [0.0, 0.0, 0.0, 0.0, 0.05, 0.15, 0.30, 0.50, 0.75, 1.05];
        let mut flags = Vec::new();
        for (i, x) in xs.iter().enumerate() {
            let pose =
                Isometry3::from_parts(Translation3::new(*x, 0.0, 1.8), UnitQuaternion::identity());
            flags.push(
                odo.register(observe(&world, &pose, i as u64), i as i64, None)
                    .keyframe,
            );
        }
        // Keyframes at 0 m, at 0.50 m (≥ 0.4 from 0) and at 1.05 m (0.55 from 0.50).
        let expected = [
            true, false, false, false, false, false, false, true, false, true,
        ];
        assert_eq!(flags, expected);
    }

    #[test]
    fn bad_config_is_rejected() {
        let d = OdometryConfig::default();
        assert!(Odometry::new(OdometryConfig {
            max_range_m: 0.0,
            ..d
        })
        .is_err());
        assert!(Odometry::new(OdometryConfig {
            min_range_m: 200.0,
            ..d
        })
        .is_err());
        assert!(Odometry::new(OdometryConfig {
            voxel_size_m: -1.0,
            ..d
        })
        .is_err());
        assert!(Odometry::new(OdometryConfig {
            initial_threshold_m: 0.0,
            ..d
        })
        .is_err());
        for passes in [0, 5] {
            assert!(Odometry::new(OdometryConfig {
                deskew_passes: passes,
                ..d
            })
            .is_err());
        }
        for w in [-1.0, f64::NAN, f64::INFINITY] {
            for cfg in [
                OdometryConfig {
                    continuous_start_weight: w,
                    ..d
                },
                OdometryConfig {
                    continuous_motion_weight: w,
                    ..d
                },
            ] {
                assert!(Odometry::new(cfg).is_err(), "{cfg:?}");
            }
        }
    }
}
