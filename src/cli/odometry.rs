//! `--odometry`: LiDAR odometry (`crate::registration::odometry`) run per sensor on every sweep
//! of `decode`, and its outputs:
//! - `/tf`: one `foxglove.FrameTransform` per sweep, parent `odom`, child the sensor's frame
//!   (the pose `odom_from_sensor`, stamped with the pose's time);
//! - `/map`: the local map as a `foxglove.PointCloud` in `odom`, every `--map-every` sweeps;
//! - `--trajectory FILE.tum`: one line per registered sweep (failed ones are left out),
//!   `t x y z qx qy qz qw`, `t` in seconds;
//! - per sweep, an `odometry` object in the sensor's `/diagnostics` (status, degeneracy flag
//!   and named directions);
//! - in `--json`, an `odometry` object (sweeps registered, failed, degenerate, sweeps that
//!   restarted a map too sparse to register against, points refused by a full map, ms per
//!   sweep, final pose).
//!
//! With `--extrinsics` for the sensor, `/tf` and the trajectory are `base_link`'s instead
//! (`odom` = `base_link` at the first sweep, `odom ← base_link` = B·T·B⁻¹ with B the
//! extrinsics and T the sensor's odometry pose), so the tree stays `odom → base_link → sensor`
//! with `/tf_static`.
//!
//! With several sensors each has its own odometry: frame `<name>/odom`, topic `/<name>/map`
//! and `FILE_<name>.tum`.
//!
//! With `--deskew odometry` the pipeline deskews each sweep at constant velocity from the
//! odometry's last motion ([`super::pipeline::PipelineRunner::set_relative_motion`]); the deskewed points are then
//! moved on to the sweep's middle and registered with the stamp of that middle, so poses (on
//! `/tf` and in the trajectory) are those at mid-sweep. Referred to the sweep's start (or end) the
//! fed-back velocity error alternates from sweep to sweep without decaying; at mid-sweep the
//! residual smear is centred and the loop converges (`tools/odometry.rs`, BENCHMARKS.md
//! "Odometry").
//!
//! A sensor with an IMU stream (Ouster) gives each registration a rotation prior: the gyro,
//! rotated into the sensor frame by the metadata's `imu_to_sensor_transform`, integrated from
//! the previous registered stamp to this one (on the sensor clock of both), with a covariance
//! of a gyro bias up to [`GYRO_BIAS_RADPS`]. It holds the rotation where the scene cannot (yaw
//! on an empty floor); elsewhere the lidar, far more precise than that bias, decides.
//!
//! The algorithms live in `crate::registration::odometry`; this file owns the clock, the files and
//! the MCAP channels.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::deskew::{ImuTrack, Twist};
use crate::point::Point;
use crate::registration::odometry::ImuRotation;
use crate::registration::odometry::Odometry;
use crate::registration::odometry::OdometryConfig;
use crate::registration::odometry::OdometryMethod;
use crate::registration::odometry::OdometryStep;
use crate::registration::odometry::SweepMotion;
use crate::registration::odometry::TrackStatus;
use crate::sensor::ImuSample;
use crate::sink::foxglove::PointCloudPrefix;
use crate::sink::scene;
use crate::sink::{McapSink, SensorId, SinkError, TopicId};
use crate::sweep::Sweep;
use nalgebra::{Isometry3, Point3};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use serde_json::{json, Value};

/// The gyro bias the IMU rotation prior allows for, rad/s (0.57 °/s: a MEMS gyro without
/// calibration); its standard deviation over an interval `dt` is this × `dt` per axis.
pub const GYRO_BIAS_RADPS: f64 = 0.01;

/// Integration step of the gyro between two sweeps, ns.
const IMU_STEP_NS: i64 = 1_000_000;

/// The rotation of the sensor at `t1_ns` in its frame at `t0_ns` (sensor clock), integrated
/// from the gyro by the midpoint rule, or `None` when the track does not cover the interval
/// (or it is empty or longer than a second).
fn imu_rotation(track: &ImuTrack, t0_ns: i64, t1_ns: i64) -> Option<ImuRotation> {
    let span = t1_ns.checked_sub(t0_ns)?;
    if span <= 0 || span > 1_000_000_000 {
        return None;
    }
    let steps = (span + IMU_STEP_NS - 1) / IMU_STEP_NS;
    let dt_ns = span as f64 / steps as f64;
    let mut q = UnitQuaternion::identity();
    for k in 0..steps {
        let t_mid = t0_ns + ((k as f64 + 0.5) * dt_ns) as i64;
        let w: Vector3<f64> = track.angular_velocity_at(t_mid)?;
        q *= UnitQuaternion::from_scaled_axis(w * (dt_ns * 1e-9));
    }
    let sigma = GYRO_BIAS_RADPS * span as f64 * 1e-9;
    Some(ImuRotation {
        previous_from_current: q,
        covariance_rad2: Matrix3::identity() * (sigma * sigma),
    })
}

/// Topic of the odometry poses.
pub const TF_TOPIC: &str = "/tf";

/// The odometry's ICP residual on the command line.
#[derive(Clone, Copy, Debug, clap::ValueEnum, PartialEq, Eq, Default)]
pub enum MethodArg {
    /// Point-to-point, then refined point-to-plane (0.41 % drift on the simulated urban drive
    /// against 3.2 % for point-to-point: BENCHMARKS.md "Odometry").
    #[default]
    PointToPlane,
    /// Point-to-point only, as KISS-ICP.
    PointToPoint,
    /// Continuous-time ICP on the raw sweep with its point times: the poses at the sweep's
    /// first and last points estimated together, the pose stamped at the last point (0.10 %,
    /// 0.09°/100 m on the simulated urban drive; weights tuned, and a drive that starts at
    /// 20 m/s can trap it at a standstill: BENCHMARKS.md "Odometry"). Not with `--deskew`.
    ContinuousTime,
}

/// The odometry flags of `decode`.
#[derive(clap::Args, Debug, Clone)]
pub struct OdometryArgs {
    /// LiDAR odometry on every sweep of each sensor: poses on `/tf` (parent `odom`), the local
    /// map on `/map`, the degeneracy in `/diagnostics` and an `odometry` object in `--json`.
    /// Implied by `--deskew odometry`.
    #[arg(long)]
    pub odometry: bool,
    /// With --odometry: write the trajectory (`odom` ← sensor) as TUM text
    /// (`t x y z qx qy qz qw`, t in seconds), one line per registered sweep.
    #[arg(long, value_name = "FILE.tum")]
    pub trajectory: Option<PathBuf>,
    /// With --odometry: write the local map every N sweeps.
    #[arg(
        long,
        value_name = "N",
        default_value_t = 10,
        allow_negative_numbers = true
    )]
    pub map_every: u32,
    /// With --odometry: the ICP residual.
    #[arg(long, value_enum, default_value_t = MethodArg::PointToPlane)]
    pub odometry_method: MethodArg,
    /// With --odometry: map voxel size, metres (default: max range / 100 = 1 m). The map
    /// holds 256 MiB at most (about 220 k voxels): far smaller voxels fill it, and the points
    /// it then refuses are counted (`map_refused` in --json).
    #[arg(long, value_name = "M")]
    pub odometry_voxel: Option<f64>,
    /// With --odometry: points farther than this are not registered, metres.
    #[arg(long, value_name = "M", default_value_t = 100.0)]
    pub odometry_max_range: f64,
}

impl Default for OdometryArgs {
    /// Odometry off; the other values are the flags' defaults.
    fn default() -> Self {
        Self {
            odometry: false,
            trajectory: None,
            map_every: 10,
            odometry_method: MethodArg::PointToPlane,
            odometry_voxel: None,
            odometry_max_range: 100.0,
        }
    }
}

impl OdometryArgs {
    /// An odometry flag given without `--odometry`, if any.
    fn stray(&self) -> Option<&'static str> {
        let d = Self::default();
        if self.trajectory.is_some() {
            Some("--trajectory")
        } else if self.odometry_voxel.is_some() {
            Some("--odometry-voxel")
        } else if self.map_every != d.map_every {
            Some("--map-every")
        } else if self.odometry_method != d.odometry_method {
            Some("--odometry-method")
        } else if self.odometry_max_range != d.odometry_max_range {
            Some("--odometry-max-range")
        } else {
            None
        }
    }

    /// Resolves the flags: `Ok(None)` without odometry. `deskew` is whether the pipeline
    /// deskews with the odometry's motion (which turns the odometry on), `pipeline_deskews`
    /// whether it deskews at all.
    pub fn setup(
        &self,
        deskew: bool,
        pipeline_deskews: bool,
    ) -> Result<Option<OdometrySetup>, String> {
        if !self.odometry && !deskew {
            return match self.stray() {
                Some(flag) => Err(format!("{flag} needs --odometry")),
                None => Ok(None),
            };
        }
        if !(self.odometry_max_range.is_finite() && self.odometry_max_range > 0.0) {
            return Err(format!(
                "--odometry-max-range {}: expected a positive number of metres",
                self.odometry_max_range
            ));
        }
        let mut config = OdometryConfig::for_max_range(self.odometry_max_range);
        if let Some(v) = self.odometry_voxel {
            config.voxel_size_m = v;
        }
        config.method = match self.odometry_method {
            MethodArg::PointToPlane | MethodArg::ContinuousTime => OdometryMethod::PointToPlane,
            MethodArg::PointToPoint => OdometryMethod::PointToPoint,
        };
        if self.odometry_method == MethodArg::ContinuousTime {
            if pipeline_deskews {
                return Err(
                    "--odometry-method continuous-time registers the raw sweep with its \
                     point times: it cannot follow --deskew (give --deskew none)"
                        .into(),
                );
            }
            config.continuous_time = true;
        }
        // Checked here so that a bad value is a usage error, not a per-sensor failure.
        Odometry::new(config).map_err(|e| format!("--odometry: {e}"))?;
        if self.map_every == 0 {
            return Err("--map-every 0: expected at least 1".into());
        }
        // Said now, not after the whole run when the file is first written.
        if let Some(t) = &self.trajectory {
            match t.parent().filter(|d| !d.as_os_str().is_empty()) {
                Some(d) if !d.is_dir() => {
                    return Err(format!(
                        "--trajectory {}: its directory {} does not exist; create it first",
                        t.display(),
                        d.display()
                    ))
                }
                _ if t.is_dir() => {
                    return Err(format!(
                        "--trajectory {}: a directory, not a file",
                        t.display()
                    ))
                }
                _ => {}
            }
        }
        Ok(Some(OdometrySetup {
            config,
            trajectory: self.trajectory.clone(),
            map_every: u64::from(self.map_every),
            deskew,
        }))
    }
}

/// What the flags resolve to.
#[derive(Debug, Clone)]
pub struct OdometrySetup {
    config: OdometryConfig,
    trajectory: Option<PathBuf>,
    map_every: u64,
    deskew: bool,
}

impl OdometrySetup {
    /// The odometry's parameters.
    pub fn config(&self) -> &OdometryConfig {
        &self.config
    }
}

/// The channels of one sensor's odometry in one MCAP file.
struct Topics {
    map: TopicId,
    map_prefix: PointCloudPrefix,
}

/// Per-sensor state. The poses kept and written are `odom_from_sensor`, or with `--extrinsics`
/// for the sensor `odom_from_base` (`odom` = `base_link` at the first sweep).
struct SensorOdometry {
    name: String,
    odom_frame: String,
    odometry: Odometry,
    topics: Option<Topics>,
    trajectory: Option<(PathBuf, BufWriter<File>)>,
    sweeps: u64,
    registered: u64,
    failed: u64,
    degenerate: u64,
    not_converged: u64,
    /// Sweeps after the first that started the map again (the one before held too few points).
    reinitialized: u64,
    /// Registration time per sweep, ns (the first `TIMES_KEPT`), and the largest of all.
    times: Vec<u64>,
    max_ns: u64,
    /// Sensor-frame points moved to mid-sweep (`--deskew odometry`).
    work: Vec<Point>,
    /// The map as points, for `/map`.
    map_points: Vec<Point>,
    distance_m: f64,
    last_position: Option<nalgebra::Vector3<f64>>,
    /// The last registered sweep's pose and stamp.
    last_registered: Option<(Isometry3<f64>, i64)>,
    /// The last registration's stamp on the sensor clock (that of its IMU samples).
    last_device_ns: Option<i64>,
    /// Registrations given an IMU rotation prior.
    imu_priors: u64,
}

/// Registration times kept per sensor for the median (512 KB; later sweeps count in the max).
const TIMES_KEPT: usize = 65_536;

/// Runs the odometry on every sensor's sweeps and writes its outputs.
pub struct OdometryRunner {
    setup: OdometrySetup,
    sensors: Vec<Option<SensorOdometry>>,
    /// Gyro samples per sensor index (sensors with an IMU stream).
    imu: Vec<Option<ImuTrack>>,
    tf: Option<TopicId>,
    buf: Vec<u8>,
    /// The first error writing a trajectory file (reported at the end).
    io_error: Option<String>,
}

impl std::fmt::Debug for OdometryRunner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OdometryRunner")
            .field("setup", &self.setup)
            .finish_non_exhaustive()
    }
}

fn status_name(s: &TrackStatus) -> String {
    match s {
        TrackStatus::Initialized => "initialized".into(),
        TrackStatus::Converged => "converged".into(),
        TrackStatus::NotConverged => "not-converged".into(),
        TrackStatus::Lost(e) => format!("lost: {e}"),
    }
}

/// `FILE.tum` for a single sensor, `FILE_<name>.tum` for each of several.
fn trajectory_path(base: &Path, name: &str, several: bool) -> PathBuf {
    if !several {
        return base.to_path_buf();
    }
    let stem = base
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let file = match base.extension() {
        Some(ext) => format!("{stem}_{name}.{}", ext.to_string_lossy()),
        None => format!("{stem}_{name}"),
    };
    base.with_file_name(file)
}

fn pose_json(p: &Isometry3<f64>) -> Value {
    let t = p.translation.vector;
    let q = p.rotation;
    let (roll, pitch, yaw) = q.euler_angles();
    json!({
        "x": t.x, "y": t.y, "z": t.z,
        "qx": q.i, "qy": q.j, "qz": q.k, "qw": q.w,
        "roll_deg": roll.to_degrees(), "pitch_deg": pitch.to_degrees(), "yaw_deg": yaw.to_degrees(),
    })
}

/// The last registered pose with its stamp (s), or null.
fn final_pose(s: &SensorOdometry) -> Value {
    match &s.last_registered {
        Some((pose, stamp)) => {
            let mut v = pose_json(pose);
            if let Some(o) = v.as_object_mut() {
                o.insert("t_s".into(), json!(*stamp as f64 * 1e-9));
            }
            v
        }
        None => Value::Null,
    }
}

fn median_ms(v: &[u64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let mut s = v.to_vec();
    s.sort_unstable();
    let n = s.len();
    let m = if n % 2 == 1 {
        s[n / 2] as f64
    } else {
        (s[n / 2 - 1] + s[n / 2]) as f64 / 2.0
    };
    Some(m * 1e-6)
}

impl OdometryRunner {
    /// The output moved to a new file (`listen --split-every`): `/tf` and the maps are added
    /// again there before the next message.
    pub fn new_file(&mut self) {
        self.tf = None;
        for so in self.sensors.iter_mut().flatten() {
            so.topics = None;
        }
    }

    /// A runner for the resolved flags.
    pub fn new(setup: OdometrySetup) -> Self {
        Self {
            setup,
            sensors: Vec::new(),
            imu: Vec::new(),
            tf: None,
            buf: Vec::new(),
            io_error: None,
        }
    }

    /// Adds a gyro sample of sensor `idx` (its metadata's `imu_to_sensor_transform`).
    pub fn push_imu(&mut self, idx: usize, imu_to_sensor: &[f64; 16], s: &ImuSample) {
        if idx >= crate::sweep::demux::MAX_SENSORS {
            return;
        }
        while self.imu.len() <= idx {
            self.imu.push(None);
        }
        let track =
            self.imu[idx].get_or_insert_with(|| ImuTrack::from_imu_to_sensor(imu_to_sensor));
        track.push(i64::try_from(s.sensor_ns).unwrap_or(i64::MAX), s.gyro);
    }

    /// The motion between sensor `idx`'s last two sweeps (for the next sweep's deskew).
    pub fn last_motion(&self, idx: usize) -> Option<SweepMotion> {
        self.sensors
            .get(idx)
            .and_then(Option::as_ref)
            .and_then(|s| s.odometry.last_motion())
    }

    fn sensor(&mut self, idx: usize, name: &str, several: bool) -> Option<&mut SensorOdometry> {
        while self.sensors.len() <= idx {
            self.sensors.push(None);
        }
        if self.sensors[idx].is_none() {
            let odometry = match Odometry::new(self.setup.config) {
                Ok(o) => o,
                Err(e) => {
                    self.io_error.get_or_insert(format!("odometry: {e}"));
                    return None;
                }
            };
            let trajectory = match &self.setup.trajectory {
                Some(base) => {
                    let path = trajectory_path(base, name, several);
                    match File::create(&path) {
                        Ok(f) => Some((path, BufWriter::new(f))),
                        Err(e) => {
                            self.io_error
                                .get_or_insert(format!("--trajectory {}: {e}", path.display()));
                            None
                        }
                    }
                }
                None => None,
            };
            self.sensors[idx] = Some(SensorOdometry {
                name: name.to_string(),
                odom_frame: if several {
                    format!("{name}/odom")
                } else {
                    "odom".to_string()
                },
                odometry,
                topics: None,
                trajectory,
                sweeps: 0,
                registered: 0,
                failed: 0,
                degenerate: 0,
                not_converged: 0,
                reinitialized: 0,
                times: Vec::new(),
                max_ns: 0,
                work: Vec::new(),
                map_points: Vec::new(),
                distance_m: 0.0,
                last_position: None,
                last_registered: None,
                last_device_ns: None,
                imu_priors: 0,
            });
        }
        self.sensors[idx].as_mut()
    }

    /// Registers one sweep of sensor `idx` (as written: deskewed when the pipeline deskews,
    /// stamped with its reference time) and writes the outputs to `sink` when there is one.
    /// `deskew` is the twist the pipeline deskewed the sweep with and the original sweep's
    /// timestamp (`--deskew odometry`). Returns the `odometry` object of the sweep's
    /// diagnostics.
    #[allow(clippy::too_many_arguments)]
    pub fn process<W: Write + Seek>(
        &mut self,
        idx: usize,
        name: &str,
        several: bool,
        sweep: &Sweep,
        deskew: Option<(Twist, i64)>,
        base_from_sensor: Option<&Isometry3<f64>>,
        live: Option<&super::serve::SharedPublisher>,
        sink: Option<(&mut McapSink<W>, SensorId)>,
    ) -> Result<Option<Value>, SinkError> {
        let map_every = self.setup.map_every;
        let continuous = self.setup.config.continuous_time;
        // The registration's stamp: mid-sweep when deskewed here, the last point's with
        // continuous time, else the sweep's.
        let span = sweep.points.iter().map(|p| p.t).max().unwrap_or(0);
        let stamp_ns = match deskew {
            Some((_, start_ns)) => start_ns.saturating_add(i64::from(span / 2)),
            None if continuous => sweep.timestamp_ns.saturating_add(i64::from(span)),
            None => sweep.timestamp_ns,
        };
        // The same instant on the sensor clock, and the gyro's rotation since the last one.
        let device_ns = sweep
            .device_time_ns
            .saturating_add(stamp_ns.saturating_sub(sweep.timestamp_ns));
        let previous = self
            .sensors
            .get(idx)
            .and_then(Option::as_ref)
            .and_then(|s| s.last_device_ns);
        let prior = match (self.imu.get(idx).and_then(Option::as_ref), previous) {
            (Some(track), Some(t0)) => imu_rotation(track, t0, device_ns),
            _ => None,
        };
        let Some(so) = self.sensor(idx, name, several) else {
            return Ok(None);
        };
        let t0 = Instant::now();
        let source: &[Point] = match deskew {
            Some((twist, _)) => {
                // The points are at the pose of `sweep.timestamp_ns`; move them on to mid-sweep.
                let dt_s = stamp_ns.saturating_sub(sweep.timestamp_ns) as f64 * 1e-9;
                let mid_from_ref = twist.integrate(dt_s).inverse();
                so.work.clear();
                so.work.extend(sweep.points.iter().map(|p| {
                    let q =
                        mid_from_ref * Point3::new(f64::from(p.x), f64::from(p.y), f64::from(p.z));
                    Point {
                        x: q.x as f32,
                        y: q.y as f32,
                        z: q.z as f32,
                        ..*p
                    }
                }));
                &so.work
            }
            None => &sweep.points,
        };
        let step: OdometryStep = if continuous {
            so.odometry
                .register_timed(source, sweep.timestamp_ns, prior.as_ref())
        } else {
            so.odometry.register(
                source
                    .iter()
                    .map(|p| Vector3::new(f64::from(p.x), f64::from(p.y), f64::from(p.z))),
                stamp_ns,
                prior.as_ref(),
            )
        };
        if !matches!(step.status, TrackStatus::Lost(_)) {
            so.last_device_ns = Some(device_ns);
            so.imu_priors += u64::from(prior.is_some());
        }
        let ns = t0.elapsed().as_nanos() as u64;
        so.sweeps += 1;
        if so.times.len() < TIMES_KEPT {
            so.times.push(ns);
        }
        so.max_ns = so.max_ns.max(ns);
        // With extrinsics the poses are the vehicle's: odom = `base_link` at the first sweep.
        let pose = match base_from_sensor {
            Some(b) => b * step.world_from_sensor * b.inverse(),
            None => step.world_from_sensor,
        };
        let lost = matches!(step.status, TrackStatus::Lost(_));
        if lost {
            so.failed += 1;
        } else {
            so.registered += 1;
            so.last_registered = Some((pose, step.stamp_ns));
        }
        if step.status == TrackStatus::NotConverged {
            so.not_converged += 1;
        }
        if step.status == TrackStatus::Initialized && step.index > 0 {
            so.reinitialized += 1;
        }
        if step.degenerate {
            so.degenerate += 1;
        }
        // The length of the trajectory written: a lost sweep's pose is a prediction, and not
        // in it.
        let position = pose.translation.vector;
        if !lost {
            if let Some(last) = so.last_position {
                so.distance_m += (position - last).norm();
            }
            so.last_position = Some(position);
        }
        let mut write_error = None;
        if let (false, Some((path, w))) = (lost, so.trajectory.as_mut()) {
            let q = pose.rotation;
            if let Err(e) = writeln!(
                w,
                "{:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9}",
                step.stamp_ns as f64 * 1e-9,
                position.x,
                position.y,
                position.z,
                q.i,
                q.j,
                q.k,
                q.w
            ) {
                write_error = Some(format!("--trajectory {}: {e}", path.display()));
            }
        }
        if let Some(e) = write_error {
            self.io_error.get_or_insert(e);
        }
        let diag = json!({
            "status": status_name(&step.status),
            "stamp_ns": step.stamp_ns,
            "ms": ns as f64 * 1e-6,
            "iterations": step.icp.map(|r| r.iterations),
            "threshold_m": step.threshold_m,
            "source_points": step.source_points,
            "map_points": step.map_points,
            "degenerate": step.degenerate,
            "degenerate_axes": step.degeneracy.map(|d| d.degenerate_axes().collect::<Vec<_>>()),
            "min_eigenvalue": step.degeneracy.map(|d| d.eigenvalues[0]),
            "pose": pose_json(&pose),
        });
        let frame = match (base_from_sensor, &sink) {
            (Some(_), _) => "base_link".to_string(),
            (None, Some((sink, id))) => sink
                .channels(*id)
                .map(|c| c.name().to_string())
                .unwrap_or_else(|| name.to_string()),
            (None, None) => name.to_string(),
        };
        let log_time = sweep.last_host_ns.max(0) as u64;
        let stamp = step.stamp_ns.max(0) as u64;
        let odom_frame = self
            .sensors
            .get(idx)
            .and_then(Option::as_ref)
            .map_or_else(|| "odom".to_string(), |s| s.odom_frame.clone());
        scene::encode_frame_transform(&mut self.buf, stamp, &odom_frame, &frame, &pose);
        if let Some(live) = live {
            live.borrow_mut().tf(log_time, &self.buf);
        }
        let Some((sink, id)) = sink else {
            return Ok(Some(diag));
        };
        let format = sink.format();
        if format != crate::sink::Format::Foxglove {
            scene::encode_transform(format, &mut self.buf, stamp, &odom_frame, &frame, &pose)?;
        }
        let tf = match self.tf {
            Some(t) => t,
            None => {
                let t =
                    sink.add_topic(TF_TOPIC, scene::transform_schema(format), &BTreeMap::new())?;
                self.tf = Some(t);
                t
            }
        };
        // `self.sensor` borrowed `self` mutably above; take the sensor again.
        let Some(so) = self.sensors.get_mut(idx).and_then(Option::as_mut) else {
            return Ok(Some(diag));
        };
        sink.write_message(tf, log_time, &self.buf)?;
        if so.sweeps % map_every == 0 {
            if so.topics.is_none() {
                let prefix = sink
                    .channels(id)
                    .map(|c| c.prefix().to_string())
                    .unwrap_or_default();
                let mut metadata = BTreeMap::new();
                metadata.insert("frame_id".to_string(), so.odom_frame.clone());
                let map = sink.add_topic(
                    &format!("{prefix}/map"),
                    scene::points_schema(format),
                    &metadata,
                )?;
                so.topics = Some(Topics {
                    map,
                    map_prefix: PointCloudPrefix::new(&so.odom_frame),
                });
            }
            if let Some(t) = &so.topics {
                // The map is in the first sweep's sensor frame; `odom` is `base_link` there
                // with extrinsics.
                let odom_from_map = base_from_sensor
                    .copied()
                    .unwrap_or_else(Isometry3::identity);
                so.map_points.clear();
                so.map_points.extend(so.odometry.map().points().map(|p| {
                    let q = odom_from_map * Point3::from(*p);
                    Point {
                        x: q.x as f32,
                        y: q.y as f32,
                        z: q.z as f32,
                        ..Point::default()
                    }
                }));
                scene::encode_points(
                    format,
                    &mut self.buf,
                    stamp,
                    &t.map_prefix,
                    &so.odom_frame,
                    crate::point::POINT_STRIDE,
                    &crate::point::POINT_FIELDS,
                    crate::point::as_bytes(&so.map_points),
                    "map",
                )?;
                sink.write_message(t.map, log_time, &self.buf)?;
            }
        }
        Ok(Some(diag))
    }

    /// Flushes the trajectory files; the first error writing one.
    pub fn finish(&mut self) -> Result<(), String> {
        for so in self.sensors.iter_mut().flatten() {
            if let Some((path, w)) = so.trajectory.as_mut() {
                if let Err(e) = w.flush() {
                    self.io_error
                        .get_or_insert(format!("--trajectory {}: {e}", path.display()));
                }
            }
        }
        match &self.io_error {
            Some(e) => Err(e.clone()),
            None => Ok(()),
        }
    }

    /// The `odometry` object of the `--json` summary.
    pub fn summary(&self) -> Value {
        let all: Vec<&SensorOdometry> = self.sensors.iter().flatten().collect();
        let times: Vec<u64> = all.iter().flat_map(|s| s.times.iter().copied()).collect();
        let per_sensor: Vec<Value> = all
            .iter()
            .map(|s| {
                json!({
                    "name": s.name,
                    "frame": s.odom_frame,
                    "sweeps": s.sweeps,
                    "registered": s.registered,
                    "failed": s.failed,
                    "not_converged": s.not_converged,
                    "reinitialized": s.reinitialized,
                    "map_refused": s.odometry.map().refused(),
                    "degenerate": s.degenerate,
                    "imu_priors": s.imu_priors,
                    "median_ms": median_ms(&s.times),
                    "max_ms": (s.sweeps > 0).then_some(s.max_ns as f64 * 1e-6),
                    "distance_m": s.distance_m,
                    "final_pose": final_pose(s),
                    "trajectory": s.trajectory.as_ref().map(|(p, _)| p.display().to_string()),
                })
            })
            .collect();
        let cfg = &self.setup.config;
        json!({
            "method": match cfg.method {
                OdometryMethod::PointToPlane => "point-to-plane",
                OdometryMethod::PointToPoint => "point-to-point",
            },
            "voxel_m": cfg.voxel_size_m,
            "max_range_m": cfg.max_range_m,
            "deskew": self.setup.deskew,
            "map_every": self.setup.map_every,
            "sweeps": all.iter().map(|s| s.sweeps).sum::<u64>(),
            "registered": all.iter().map(|s| s.registered).sum::<u64>(),
            "failed": all.iter().map(|s| s.failed).sum::<u64>(),
            "not_converged": all.iter().map(|s| s.not_converged).sum::<u64>(),
            "reinitialized": all.iter().map(|s| s.reinitialized).sum::<u64>(),
            "map_refused": all.iter().map(|s| s.odometry.map().refused()).sum::<u64>(),
            "degenerate": all.iter().map(|s| s.degenerate).sum::<u64>(),
            "imu_priors": all.iter().map(|s| s.imu_priors).sum::<u64>(),
            "median_ms": median_ms(&times),
            "max_ms": all.iter().map(|s| s.max_ns).max().filter(|_| !times.is_empty()).map(|n| n as f64 * 1e-6),
            // The first sensor's, as `final_pose` (each sensor's are in `sensors`).
            "distance_m": all.first().map(|s| s.distance_m),
            "final_pose": all.first().map(|s| final_pose(s)),
            "sensors": per_sensor,
        })
    }
}
