//! The in-process pipeline: deskew → filter → voxel → ground → cluster on one sweep.
//!
//! [`Pipeline`] owns every stage and every buffer between them, so once its buffers have grown
//! to a sweep's size, a sweep runs without allocating. Deskew moves the sweep's points in place
//! (the caller then writes the deskewed sweep); the filters copy the survivors, moved into
//! `base_link`, into the pipeline's own buffer, and the later stages read from there.
//!
//! Outputs of one [`Pipeline::run`]:
//! - **ground**: the voxel points labelled ground;
//! - **obstacles**: the non-ground voxel points that belong to a kept cluster, grouped by
//!   cluster, with the cluster index of each ([`Pipeline::obstacle_clusters`]);
//! - **clusters**: one per kept component, with its boxes.
//!
//! So `ground + obstacles + unclustered = voxels` ([`SweepStats`]), and the clusters' point
//! counts sum to `obstacles`.
//!
//! Timing: the core reads no clock. [`Pipeline::run`] takes the caller's clock (any function
//! returning monotonic nanoseconds) and reads it between stages ([`StageTimes`]); pass
//! `&mut || 0` to time nothing.

use nalgebra::{Isometry3, Vector3};

use super::cluster::{Cluster, Clusterer, Clusters};
use super::config::{ConfigError, DeskewMode, PipelineConfig};
use super::filter::{Filter, FilterStats};
use super::ground::GroundSegmenter;
use super::voxel::{VoxelConfig, VoxelGrid};
use super::PipelineError;
use crate::deskew::{DeskewError, Deskewer, ImuTrack, PoseTable, Twist};
use crate::point::Point;
use crate::sweep::Sweep;

/// Nanoseconds spent in each stage of one sweep, by the caller's clock.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StageTimes {
    /// Deskew.
    pub deskew_ns: u64,
    /// Range, field-of-view, extrinsics and crop box.
    pub filter_ns: u64,
    /// Voxel downsampling.
    pub voxel_ns: u64,
    /// Ground segmentation.
    pub ground_ns: u64,
    /// Clustering and the obstacle lists.
    pub cluster_ns: u64,
}

impl StageTimes {
    /// The whole pipeline.
    pub fn total_ns(&self) -> u64 {
        self.deskew_ns + self.filter_ns + self.voxel_ns + self.ground_ns + self.cluster_ns
    }
}

/// Counts of one sweep.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SweepStats {
    /// Points of the sweep.
    pub input: usize,
    /// Whether the points were deskewed (false with mode `none`, or when the motion source had
    /// nothing for this sweep: see `deskew_error`).
    pub deskewed: bool,
    /// Why deskew was skipped for this sweep, if it was.
    pub deskew_error: Option<DeskewError>,
    /// When the pose the deskewed points are in was taken, ns after the sweep's timestamp
    /// (0, or the last point's time with `deskew.reference = "end"`).
    pub reference_ns: u32,
    /// What the filters removed.
    pub filter: FilterStats,
    /// Points after the filters.
    pub filtered: usize,
    /// Points after voxel downsampling.
    pub voxels: usize,
    /// Points the voxel grid could not key (beyond ±2^20 leaves of the origin on some axis,
    /// or not finite), left out of every output after it.
    pub voxel_skipped: usize,
    /// Of those, ground.
    pub ground: usize,
    /// Non-ground points in kept clusters.
    pub obstacles: usize,
    /// Non-ground points in no kept cluster.
    pub unclustered: usize,
    /// Clusters kept.
    pub clusters: usize,
    /// Stage times.
    pub times: StageTimes,
}

fn stage_error(section: &str, e: PipelineError) -> ConfigError {
    match e {
        PipelineError::InvalidParameter {
            name,
            value,
            expected,
        } => ConfigError::Invalid {
            key: format!("{section}.{name}"),
            value: value.to_string(),
            expected,
        },
        #[allow(unreachable_patterns)]
        other => ConfigError::Invalid {
            key: section.to_string(),
            value: other.to_string(),
            expected: "valid parameters",
        },
    }
}

/// The stages, their buffers and the motion state. See the module documentation.
#[derive(Debug)]
pub struct Pipeline {
    mode: DeskewMode,
    deskewer: Deskewer,
    twist: Twist,
    imu: Option<ImuTrack>,
    poses: Option<PoseTable>,
    filter: Filter,
    base_from_sensor: Isometry3<f64>,
    voxel: VoxelGrid,
    ground: GroundSegmenter,
    clusterer: Clusterer,
    filtered: Vec<Point>,
    voxels: Vec<Point>,
    labels: Vec<bool>,
    clusters: Clusters,
    ground_points: Vec<Point>,
    obstacles: Vec<Point>,
    obstacle_clusters: Vec<u32>,
}

impl Pipeline {
    /// Builds every stage from a validated configuration, for a sensor placed at
    /// `base_from_sensor` on the vehicle (the identity keeps the sensor frame).
    ///
    /// With mode `poses`, give the table with [`set_poses`](Self::set_poses) (the
    /// configuration holds only its file name); with mode `imu`, feed samples with
    /// [`push_imu`](Self::push_imu) after [`set_imu_to_sensor`](Self::set_imu_to_sensor).
    pub fn new(
        config: &PipelineConfig,
        base_from_sensor: Isometry3<f64>,
    ) -> Result<Self, ConfigError> {
        config.validate()?;
        let d = &config.deskew;
        let twist = Twist {
            linear_mps: Vector3::from(d.linear_mps),
            angular_radps: Vector3::from(d.angular_degps.map(f64::to_radians)),
        };
        Ok(Self {
            mode: d.mode.clone(),
            deskewer: Deskewer::new(d.reference),
            twist,
            imu: None,
            poses: None,
            filter: Filter::new(config.filter)?,
            base_from_sensor,
            voxel: VoxelGrid::new(VoxelConfig::cubic(config.voxel_leaf_m))
                .map_err(|e| stage_error("voxel", e))?,
            ground: GroundSegmenter::new(config.ground.method())
                .map_err(|e| stage_error("ground", e))?,
            clusterer: Clusterer::new(config.cluster.params())
                .map_err(|e| stage_error("cluster", e))?,
            filtered: Vec::new(),
            voxels: Vec::new(),
            labels: Vec::new(),
            clusters: Clusters::new(),
            ground_points: Vec::new(),
            obstacles: Vec::new(),
            obstacle_clusters: Vec::new(),
        })
    }

    /// The deskew mode.
    pub fn deskew_mode(&self) -> &DeskewMode {
        &self.mode
    }

    /// Sets the constant twist (modes `constant-velocity` and `odometry`, and the linear
    /// velocity of mode `imu`).
    pub fn set_twist(&mut self, twist: Twist) {
        self.twist = twist;
    }

    /// The twist in use.
    pub fn twist(&self) -> Twist {
        self.twist
    }

    /// Feeds odometry's last estimate: the current sweep's pose in the previous sweep's frame,
    /// `dt_s` seconds apart. Ignored when `dt_s` is not positive.
    pub fn set_relative_motion(&mut self, prev_from_curr: &Isometry3<f64>, dt_s: f64) {
        if let Some(t) = Twist::from_relative_motion(prev_from_curr, dt_s) {
            self.twist = t;
        }
    }

    /// Sets the IMU's placement (Ouster metadata `imu_to_sensor_transform`, row-major 4×4);
    /// samples kept so far are dropped.
    pub fn set_imu_to_sensor(&mut self, imu_to_sensor: &[f64; 16]) {
        self.imu = Some(ImuTrack::from_imu_to_sensor(imu_to_sensor));
    }

    /// Adds a gyro sample (sensor clock ns, rad/s in the IMU frame). Without
    /// [`set_imu_to_sensor`](Self::set_imu_to_sensor), the IMU frame is taken as the sensor's.
    pub fn push_imu(&mut self, sensor_ns: i64, gyro_radps: [f64; 3]) {
        self.imu
            .get_or_insert_with(|| {
                ImuTrack::new(
                    nalgebra::UnitQuaternion::identity(),
                    crate::deskew::imu::DEFAULT_CAPACITY,
                )
            })
            .push(sensor_ns, gyro_radps);
    }

    /// Sets the poses of mode `poses` (times in the clock of [`Sweep::timestamp_ns`]).
    pub fn set_poses(&mut self, poses: PoseTable) {
        self.poses = Some(poses);
    }

    /// Runs every stage on `sweep` (its points are deskewed in place), reading `clock` (ns,
    /// monotonic) between stages.
    pub fn run(&mut self, sweep: &mut Sweep, clock: &mut dyn FnMut() -> u64) -> SweepStats {
        let mut stats = SweepStats {
            input: sweep.points.len(),
            ..SweepStats::default()
        };
        let t0 = clock();
        self.deskew_stage(sweep, &mut stats);
        let t1 = clock();
        self.later_stages(sweep, &mut stats, clock, t0, t1);
        stats
    }

    /// Only the deskew stage (a caller that wants the deskewed points and no other output):
    /// the later stages' counts stay 0.
    pub fn run_deskew(&mut self, sweep: &mut Sweep, clock: &mut dyn FnMut() -> u64) -> SweepStats {
        let mut stats = SweepStats {
            input: sweep.points.len(),
            ..SweepStats::default()
        };
        let t0 = clock();
        self.deskew_stage(sweep, &mut stats);
        stats.times.deskew_ns = clock().saturating_sub(t0);
        stats
    }

    fn deskew_stage(&mut self, sweep: &mut Sweep, stats: &mut SweepStats) {
        let deskewed = match &self.mode {
            DeskewMode::None => Ok(false),
            DeskewMode::ConstantVelocity | DeskewMode::Odometry => {
                self.deskewer
                    .deskew_constant_velocity(&mut sweep.points, &self.twist);
                Ok(true)
            }
            DeskewMode::Imu => match &self.imu {
                Some(track) => self
                    .deskewer
                    .deskew_imu(
                        &mut sweep.points,
                        sweep.device_time_ns,
                        track,
                        &self.twist.linear_mps,
                    )
                    .map(|()| true),
                None => Err(DeskewError::NoImu {
                    t_ns: sweep.device_time_ns,
                    samples: 0,
                }),
            },
            DeskewMode::Poses(_) => match &self.poses {
                Some(table) => self
                    .deskewer
                    .deskew_poses(&mut sweep.points, sweep.timestamp_ns, table)
                    .map(|()| true),
                None => Err(DeskewError::Poses(crate::deskew::PosesError::TooFew {
                    found: 0,
                })),
            },
        };
        match deskewed {
            Ok(d) => {
                stats.deskewed = d;
                if d {
                    stats.reference_ns = self.deskewer.reference_ns();
                }
            }
            Err(e) => stats.deskew_error = Some(e),
        }
    }

    fn later_stages(
        &mut self,
        sweep: &Sweep,
        stats: &mut SweepStats,
        clock: &mut dyn FnMut() -> u64,
        t0: u64,
        t1: u64,
    ) {
        stats.filter = self
            .filter
            .apply(&sweep.points, &mut self.filtered, &self.base_from_sensor);
        stats.filtered = self.filtered.len();
        let t2 = clock();
        let v = self.voxel.downsample(&self.filtered, &mut self.voxels);
        stats.voxels = self.voxels.len();
        stats.voxel_skipped = v.out_of_range + v.non_finite;
        let t3 = clock();
        self.ground.segment(&self.voxels, &mut self.labels);
        self.ground_points.clear();
        self.ground_points.extend(
            self.voxels
                .iter()
                .zip(&self.labels)
                .filter(|(_, &g)| g)
                .map(|(p, _)| *p),
        );
        stats.ground = self.ground_points.len();
        let t4 = clock();
        self.clusterer
            .cluster_excluding(&self.voxels, &self.labels, &mut self.clusters);
        self.obstacles.clear();
        self.obstacle_clusters.clear();
        for k in 0..self.clusters.len() {
            for &i in self.clusters.points_of(k) {
                if let Some(p) = self.voxels.get(i as usize) {
                    self.obstacles.push(*p);
                    self.obstacle_clusters.push(k as u32);
                }
            }
        }
        stats.obstacles = self.obstacles.len();
        stats.clusters = self.clusters.len();
        stats.unclustered = stats.voxels - stats.ground - stats.obstacles;
        let t5 = clock();
        stats.times = StageTimes {
            deskew_ns: t1.saturating_sub(t0),
            filter_ns: t2.saturating_sub(t1),
            voxel_ns: t3.saturating_sub(t2),
            ground_ns: t4.saturating_sub(t3),
            cluster_ns: t5.saturating_sub(t4),
        };
    }

    /// Ground points of the last sweep (`base_link`, or the sensor frame without extrinsics).
    pub fn ground(&self) -> &[Point] {
        &self.ground_points
    }

    /// Obstacle points of the last sweep, grouped by cluster.
    pub fn obstacles(&self) -> &[Point] {
        &self.obstacles
    }

    /// The cluster index of each obstacle point.
    pub fn obstacle_clusters(&self) -> &[u32] {
        &self.obstacle_clusters
    }

    /// Clusters of the last sweep.
    pub fn clusters(&self) -> &[Cluster] {
        self.clusters.as_slice()
    }

    /// Points after voxel downsampling, and their ground labels, of the last sweep.
    pub fn voxels(&self) -> (&[Point], &[bool]) {
        (&self.voxels, &self.labels)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::config::DeskewConfig;

    /// A flat floor 1.5 m below the sensor (10 × 10 m, 0.1 m spacing) and two boxes of points
    /// standing on it: the ground is the floor, the obstacles the two boxes.
    fn scene() -> Sweep {
        let mut points = Vec::new();
        let mut t = 0;
        let mut push = |x: f32, y: f32, z: f32| {
            points.push(Point {
                x,
                y,
                z,
                t,
                ..Point::default()
            });
            t += 1000;
        };
        for i in -50..50 {
            for j in -50..50 {
                push(i as f32 * 0.1 + 0.05, j as f32 * 0.1 + 0.05, -1.5);
            }
        }
        for (cx, cy) in [(3.0f32, 2.0f32), (-2.5, -3.0)] {
            for i in 0..5 {
                for j in 0..5 {
                    for k in 0..8 {
                        push(
                            cx + i as f32 * 0.1,
                            cy + j as f32 * 0.1,
                            -1.2 + k as f32 * 0.1,
                        );
                    }
                }
            }
        }
        Sweep {
            points,
            ..Sweep::default()
        }
    }

    #[test]
    fn a_floor_with_two_boxes_gives_ground_and_two_clusters() {
        let cfg = PipelineConfig {
            deskew: DeskewConfig {
                mode: DeskewMode::None,
                ..DeskewConfig::default()
            },
            voxel_leaf_m: 0.2,
            ..PipelineConfig::default()
        };
        let mut cfg = cfg;
        cfg.ground.sensor_height_m = Some(1.5);
        let mut p = Pipeline::new(&cfg, Isometry3::identity()).unwrap();
        let mut sweep = scene();
        let mut now = 0u64;
        let mut clock = || {
            now += 1_000;
            now
        };
        let s = p.run(&mut sweep, &mut clock);
        assert!(!s.deskewed);
        assert_eq!(s.clusters, 2, "{s:?}");
        assert_eq!(s.ground + s.obstacles + s.unclustered, s.voxels);
        let per_cluster: usize = p.clusters().iter().map(|c| c.point_count).sum();
        assert_eq!(per_cluster, s.obstacles);
        assert_eq!(p.obstacle_clusters().len(), p.obstacles().len());
        // Every ground point is on the floor, every obstacle point above it.
        // Ground labels are the ground stage's business (tested there); here: the floor is
        // ground and the ground is (nearly all) floor.
        let on_floor = p
            .ground()
            .iter()
            .filter(|q| (q.z + 1.5).abs() < 0.05)
            .count();
        assert!(
            on_floor * 100 >= p.ground().len() * 95,
            "{on_floor} of {}",
            p.ground().len()
        );
        let floor_voxels = p
            .voxels()
            .0
            .iter()
            .filter(|q| (q.z + 1.5).abs() < 0.05)
            .count();
        assert!(
            on_floor * 100 >= floor_voxels * 95,
            "{on_floor} of {floor_voxels}"
        );
        assert!(p.obstacles().iter().all(|q| q.z > -1.35));
        // One cluster per box, around the box's xy centre, reaching its top (z = −0.5 m);
        // how much of its bottom the ground stage keeps is that stage's business.
        for c in p.clusters() {
            let near =
                |x: f32, y: f32| (c.centroid[0] - x).abs() < 0.3 && (c.centroid[1] - y).abs() < 0.3;
            assert!(near(3.2, 2.2) || near(-2.3, -2.8), "{c:?}");
            assert!((c.max[2] + 0.5).abs() < 0.11, "{c:?}");
        }
        // The clock was read between the five stages, 1 µs apart.
        assert_eq!(s.times.total_ns(), 5_000);
        assert_eq!(s.times.voxel_ns, 1_000);
    }

    #[test]
    fn extrinsics_lift_the_points_into_base_link() {
        let cfg = PipelineConfig {
            deskew: DeskewConfig {
                mode: DeskewMode::None,
                ..DeskewConfig::default()
            },
            ..PipelineConfig::default()
        };
        // Sensor 1.5 m above base_link: the floor lands at z = 0.
        let base = Isometry3::translation(0.0, 0.0, 1.5);
        let mut p = Pipeline::new(&cfg, base).unwrap();
        let mut sweep = scene();
        p.run(&mut sweep, &mut || 0);
        assert!(!p.ground().is_empty());
        let mut z: Vec<f32> = p.ground().iter().map(|q| q.z).collect();
        z.sort_by(f32::total_cmp);
        assert!(
            z[z.len() / 2].abs() < 0.05,
            "median ground z {}",
            z[z.len() / 2]
        );
    }

    #[test]
    fn empty_and_degenerate_sweeps_run_without_panic() {
        let mut p = Pipeline::new(&PipelineConfig::default(), Isometry3::identity()).unwrap();
        let mut empty = Sweep::default();
        let s = p.run(&mut empty, &mut || 0);
        assert_eq!(
            (s.input, s.voxels, s.ground, s.obstacles, s.clusters),
            (0, 0, 0, 0, 0)
        );
        // One point, all points at one time, non-finite coordinates.
        let mut odd = Sweep {
            points: vec![
                Point {
                    x: f32::NAN,
                    ..Point::default()
                },
                Point {
                    x: 5.0,
                    y: f32::INFINITY,
                    ..Point::default()
                },
                Point {
                    x: 5.0,
                    z: -1.0,
                    ..Point::default()
                },
            ],
            ..Sweep::default()
        };
        let s = p.run(&mut odd, &mut || 0);
        assert_eq!(s.filter.range, 2, "non-finite points go");
        assert_eq!(s.ground + s.obstacles + s.unclustered, s.voxels);
    }

    #[test]
    fn missing_motion_data_skips_deskew_and_says_why() {
        let mut cfg = PipelineConfig::default();
        cfg.deskew.mode = DeskewMode::Imu;
        let mut p = Pipeline::new(&cfg, Isometry3::identity()).unwrap();
        let mut sweep = scene();
        let before = sweep.points.clone();
        let s = p.run(&mut sweep, &mut || 0);
        assert!(!s.deskewed);
        assert!(matches!(s.deskew_error, Some(DeskewError::NoImu { .. })));
        assert_eq!(sweep.points, before);
    }
}
