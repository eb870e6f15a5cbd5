//! `--pipeline`, `--deskew`, `--extrinsics`: the perception pipeline run on every decoded sweep,
//! its MCAP outputs and its `--json` figures. The algorithms live in `crate::pipeline` and
//! `crate::deskew`; this file reads files, owns the clock and writes.

use std::io::{Seek, Write};
use std::time::Instant;

use crate::deskew::PoseTable;
use crate::pipeline::config::DeskewMode;
use crate::pipeline::config::PipelineConfig;
use crate::pipeline::filter::Extrinsics;
use crate::pipeline::run::Pipeline;
use crate::pipeline::run::StageTimes;
use crate::pipeline::run::SweepStats;
use crate::sensor::ImuSample;
use crate::sink::scene::{self, PipelineTopics};
use crate::sink::{McapSink, SensorId, SinkError, TopicId};
use crate::sweep::Sweep;
use nalgebra::Isometry3;
use serde_json::{json, Value};

/// The pipeline flags of `decode`.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct PipelineArgs {
    /// Perception pipeline run on every sweep: `none`, `default`, or a TOML file of
    /// parameters (`deskew.*`, `filter.*`, `voxel.leaf_m`, `ground.*`, `cluster.*`: the
    /// README's "Perception pipeline" lists them). Writes `ground`, `obstacles` and `clusters`
    /// per sensor.
    #[arg(long, value_name = "none|default|FILE.toml")]
    pub pipeline: Option<String>,
    /// Motion correction of every sweep: `none`, `constant-velocity` (the twist of the
    /// pipeline configuration), `imu` (the sensor's gyro: Ouster, Livox), `poses:FILE` (TUM poses), `odometry`.
    /// Overrides the configuration's `deskew.mode`.
    #[arg(long, value_name = "MODE")]
    pub deskew: Option<String>,
    /// Sensor placement on the vehicle, `NAME=x,y,z,roll,pitch,yaw` (metres, degrees):
    /// pipeline outputs of that sensor are in `base_link`, and `/tf_static` gets the transform.
    /// Repeatable.
    #[arg(long, value_name = "NAME=x,y,z,roll,pitch,yaw")]
    pub extrinsics: Vec<String>,
}

/// What the flags resolve to, before any sensor is seen.
#[derive(Debug)]
pub struct PipelineSetup {
    /// `default` or the file name.
    pub source: String,
    /// The parameters.
    pub config: PipelineConfig,
    /// Whether outputs beyond the deskewed sweep are produced.
    pub outputs: bool,
    poses: Option<PoseTable>,
    extrinsics: Vec<Extrinsics>,
}

impl PipelineArgs {
    /// Resolves the flags; `Ok(None)` when neither a pipeline nor a deskew mode is asked for.
    pub fn setup(&self) -> Result<Option<PipelineSetup>, String> {
        let (source, mut config, outputs) = match self.pipeline.as_deref() {
            None | Some("none") => ("none".to_string(), PipelineConfig::default(), false),
            Some("default") => ("default".to_string(), PipelineConfig::default(), true),
            Some(file) => {
                let text =
                    std::fs::read_to_string(file).map_err(|e| format!("--pipeline {file}: {e}"))?;
                let cfg = PipelineConfig::from_toml(&text)
                    .map_err(|e| format!("--pipeline {file}: {e}"))?;
                (file.to_string(), cfg, true)
            }
        };
        if !outputs {
            // Without a pipeline, only an explicit --deskew does anything.
            config.deskew.mode = DeskewMode::None;
        }
        if let Some(mode) = self.deskew.as_deref() {
            config.deskew.mode = match mode {
                "none" => DeskewMode::None,
                "constant-velocity" => DeskewMode::ConstantVelocity,
                "imu" => DeskewMode::Imu,
                "odometry" => DeskewMode::Odometry,
                m => match m.strip_prefix("poses:") {
                    Some(f) if !f.is_empty() => DeskewMode::Poses(f.to_string()),
                    _ => {
                        return Err(format!(
                            "--deskew {m}: expected none, constant-velocity, imu, odometry or poses:FILE"
                        ))
                    }
                },
            };
        }
        let poses = match &config.deskew.mode {
            DeskewMode::Poses(file) => {
                let text = std::fs::read_to_string(file)
                    .map_err(|e| format!("--deskew poses:{file}: {e}"))?;
                Some(PoseTable::from_tum(&text).map_err(|e| format!("{file}: {e}"))?)
            }
            _ => None,
        };
        let extrinsics = self
            .extrinsics
            .iter()
            .map(|e| Extrinsics::parse(e).map_err(|e| format!("--extrinsics: {e}")))
            .collect::<Result<Vec<_>, _>>()?;
        // A sensor placed twice: only the first would be used.
        for (i, e) in extrinsics.iter().enumerate() {
            if extrinsics[..i].iter().any(|o| o.name == e.name) {
                return Err(format!(
                    "--extrinsics {}=…: given twice; one placement per sensor",
                    e.name
                ));
            }
        }
        if !outputs && config.deskew.mode == DeskewMode::None {
            if !extrinsics.is_empty() {
                return Err("--extrinsics needs --pipeline".to_string());
            }
            return Ok(None);
        }
        Ok(Some(PipelineSetup {
            source,
            config,
            outputs,
            poses,
            extrinsics,
        }))
    }
}

/// Per-sensor state.
struct SensorPipeline {
    name: String,
    pipeline: Pipeline,
    frame_id: String,
    base_from_sensor: Option<Isometry3<f64>>,
    topics: Option<PipelineTopics>,
    work: Sweep,
    times: Vec<StageTimes>,
    /// Sweeps run, and the largest stage times (also of sweeps past `TIMES_KEPT`).
    sweeps: u64,
    max: StageTimes,
    totals: SweepStats,
    deskew_skipped: u64,
    last_deskew_error: Option<String>,
    imu_set: bool,
}

/// Runs the pipeline on every sensor's sweeps and writes its outputs.
pub struct PipelineRunner {
    setup: PipelineSetup,
    sensors: Vec<Option<SensorPipeline>>,
    tf_static: Option<TopicId>,
    clock_origin: Instant,
    /// IMU samples seen before a sensor's first sweep (the pipeline is made then).
    pending_imu: Vec<Vec<HeldImu>>,
    /// `--serve`: outputs are published there too.
    live: Option<super::serve::SharedPublisher>,
}

impl std::fmt::Debug for PipelineRunner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PipelineRunner")
            .field("source", &self.setup.source)
            .finish_non_exhaustive()
    }
}

/// An IMU sample held before its sensor's first sweep: sensor ns, gyro rad/s, the metadata's
/// `imu_to_sensor_transform`.
type HeldImu = (i64, [f64; 3], [f64; 16]);

/// Stage times kept per sensor for the medians (2.6 MB; a 10 Hz sensor fills it in 1.8 h);
/// later sweeps still count in the maxima and totals.
const TIMES_KEPT: usize = 65_536;

/// IMU samples held per sensor before its first sweep.
const PENDING_IMU: usize = 1000;

fn median_max_ms(mut v: Vec<u64>) -> Value {
    if v.is_empty() {
        return json!({"median_ms": null, "max_ms": null});
    }
    v.sort_unstable();
    let n = v.len();
    let median = if n % 2 == 1 {
        v[n / 2] as f64
    } else {
        (v[n / 2 - 1] + v[n / 2]) as f64 / 2.0
    };
    json!({"median_ms": median * 1e-6, "max_ms": v[n - 1] as f64 * 1e-6})
}

/// Copies `src` into `dst` reusing `dst`'s buffers (a derived `clone_from` would allocate
/// new ones for every sweep). Destructured exhaustively: a new field of `Sweep` must be
/// handled here.
fn copy_sweep(dst: &mut Sweep, src: &Sweep) {
    let Sweep {
        index,
        points,
        columns,
        extras,
        timestamp_ns,
        clock,
        device_time_ns,
        first_host_ns,
        last_host_ns,
        packets,
        missing_packets,
        missing_columns,
        frame_id,
        columns_count,
        first_azimuth,
        last_azimuth,
    } = src;
    dst.points.clear();
    dst.points.extend_from_slice(points);
    dst.columns.clear();
    dst.columns.extend_from_slice(columns);
    dst.extras.clear();
    dst.extras.extend_from_slice(extras);
    dst.index = *index;
    dst.timestamp_ns = *timestamp_ns;
    dst.clock = *clock;
    dst.device_time_ns = *device_time_ns;
    dst.first_host_ns = *first_host_ns;
    dst.last_host_ns = *last_host_ns;
    dst.packets = *packets;
    dst.missing_packets = *missing_packets;
    dst.missing_columns = *missing_columns;
    dst.frame_id = *frame_id;
    dst.columns_count = *columns_count;
    dst.first_azimuth = *first_azimuth;
    dst.last_azimuth = *last_azimuth;
}

impl PipelineRunner {
    /// A runner for the resolved flags.
    pub fn new(setup: PipelineSetup) -> Self {
        Self {
            setup,
            sensors: Vec::new(),
            tf_static: None,
            clock_origin: Instant::now(),
            pending_imu: Vec::new(),
            live: None,
        }
    }

    /// The output moved to a new file (`listen --split-every`): its channels, and the static
    /// transforms, are added again there before the next message.
    pub fn new_file(&mut self) {
        self.tf_static = None;
        for sp in self.sensors.iter_mut().flatten() {
            sp.topics = None;
        }
    }

    /// Publishes the outputs to a live view too.
    pub fn set_live(&mut self, live: Option<super::serve::SharedPublisher>) {
        self.live = live;
    }

    /// Sensor `name`'s placement on the vehicle (`--extrinsics`), if given and written to
    /// `/tf_static` (with pipeline outputs).
    pub fn base_from_sensor(&self, name: &str) -> Option<Isometry3<f64>> {
        if !self.setup.outputs {
            return None;
        }
        self.setup
            .extrinsics
            .iter()
            .find(|e| e.name == name)
            .map(|e| e.base_from_sensor)
    }

    /// Whether sweeps are deskewed (any `--deskew` mode but `none`).
    pub fn deskews(&self) -> bool {
        self.setup.config.deskew.mode != DeskewMode::None
    }

    /// Why an explicit `--deskew constant-velocity` would do nothing, if it would: its twist is
    /// zero (no `--pipeline FILE` gave one), so no point moves. Said rather than let pass for
    /// a correction made.
    pub fn idle_deskew(&self, args: &PipelineArgs) -> Option<String> {
        let d = &self.setup.config.deskew;
        (args.deskew.as_deref() == Some("constant-velocity")
            && d.linear_mps == [0.0; 3]
            && d.angular_degps == [0.0; 3])
            .then(|| {
                "--deskew constant-velocity: the twist is zero, so no point would move; give it \
                 as deskew.linear_mps / deskew.angular_degps in a --pipeline FILE.toml, or use \
                 --deskew imu, odometry or poses:FILE"
                    .to_string()
            })
    }

    /// Whether the deskew takes its motion from the odometry (`--deskew odometry`).
    pub fn deskews_with_odometry(&self) -> bool {
        self.setup.config.deskew.mode == DeskewMode::Odometry
    }

    /// Feeds sensor `idx`'s odometry motion (`previous_from_current`, `dt_s` apart) to its
    /// deskew (`--deskew odometry`), before its next sweep is processed.
    pub fn set_relative_motion(
        &mut self,
        idx: usize,
        name: &str,
        previous_from_current: &Isometry3<f64>,
        dt_s: f64,
    ) -> Result<(), SinkError> {
        let sp = Self::sensor(
            &mut self.sensors,
            &self.setup,
            &mut self.pending_imu,
            idx,
            name,
        )
        .map_err(|reason| SinkError::InvalidSensor {
            name: name.to_string(),
            reason,
        })?;
        sp.pipeline.set_relative_motion(previous_from_current, dt_s);
        Ok(())
    }

    /// The constant twist sensor `idx` (named `name`) deskews with (modes
    /// `constant-velocity`, `odometry`).
    pub fn twist(&mut self, idx: usize, name: &str) -> Result<crate::deskew::Twist, SinkError> {
        Self::sensor(
            &mut self.sensors,
            &self.setup,
            &mut self.pending_imu,
            idx,
            name,
        )
        .map(|sp| sp.pipeline.twist())
        .map_err(|reason| SinkError::InvalidSensor {
            name: name.to_string(),
            reason,
        })
    }

    fn sensor<'a>(
        sensors: &'a mut Vec<Option<SensorPipeline>>,
        setup: &PipelineSetup,
        pending_imu: &mut [Vec<HeldImu>],
        idx: usize,
        name: &str,
    ) -> Result<&'a mut SensorPipeline, String> {
        while sensors.len() <= idx {
            sensors.push(None);
        }
        if sensors[idx].is_none() {
            let extr = setup.extrinsics.iter().find(|e| e.name == name);
            let base = extr.map(|e| e.base_from_sensor);
            let mut pipeline =
                Pipeline::new(&setup.config, base.unwrap_or_else(Isometry3::identity))
                    .map_err(|e| e.to_string())?;
            if let Some(p) = &setup.poses {
                pipeline.set_poses(p.clone());
            }
            let mut imu_set = false;
            if let Some(held) = pending_imu.get_mut(idx) {
                for (t, gyro, m) in held.drain(..) {
                    if !imu_set {
                        pipeline.set_imu_to_sensor(&m);
                        imu_set = true;
                    }
                    pipeline.push_imu(t, gyro);
                }
            }
            sensors[idx] = Some(SensorPipeline {
                name: name.to_string(),
                pipeline,
                frame_id: if base.is_some() {
                    "base_link".to_string()
                } else {
                    name.to_string()
                },
                base_from_sensor: base,
                topics: None,
                work: Sweep::default(),
                times: Vec::new(),
                sweeps: 0,
                max: StageTimes::default(),
                totals: SweepStats::default(),
                deskew_skipped: 0,
                last_deskew_error: None,
                imu_set,
            });
        }
        sensors[idx]
            .as_mut()
            .ok_or_else(|| "pipeline state missing".to_string())
    }

    /// Feeds an IMU sample of sensor `idx` (with its metadata's `imu_to_sensor_transform`).
    pub fn push_imu(&mut self, idx: usize, imu_to_sensor: &[f64; 16], s: &ImuSample) {
        let t = i64::try_from(s.sensor_ns).unwrap_or(i64::MAX);
        match self.sensors.get_mut(idx).and_then(Option::as_mut) {
            Some(sp) => {
                if !sp.imu_set {
                    sp.pipeline.set_imu_to_sensor(imu_to_sensor);
                    sp.imu_set = true;
                }
                sp.pipeline.push_imu(t, s.gyro);
            }
            None => {
                while self.pending_imu.len() <= idx {
                    self.pending_imu.push(Vec::new());
                }
                let held = &mut self.pending_imu[idx];
                if held.len() == PENDING_IMU {
                    held.remove(0);
                }
                held.push((t, s.gyro, *imu_to_sensor));
            }
        }
    }

    /// Runs the pipeline on one sweep of sensor `idx` (named `name`) and writes its outputs to
    /// `sink` when there is one. Returns the deskewed sweep, to be written as the sensor's
    /// points.
    pub fn process<W: Write + Seek>(
        &mut self,
        idx: usize,
        name: &str,
        sweep: &Sweep,
        sink: Option<(&mut McapSink<W>, SensorId)>,
    ) -> Result<&Sweep, SinkError> {
        let origin = self.clock_origin;
        let outputs = self.setup.outputs;
        let sp = match Self::sensor(
            &mut self.sensors,
            &self.setup,
            &mut self.pending_imu,
            idx,
            name,
        ) {
            Ok(sp) => sp,
            Err(reason) => {
                return Err(SinkError::InvalidSensor {
                    name: name.to_string(),
                    reason,
                })
            }
        };
        copy_sweep(&mut sp.work, sweep);
        let mut clock = || origin.elapsed().as_nanos() as u64;
        // `--deskew` without `--pipeline`: the later stages' outputs would be thrown away.
        let stats = if outputs {
            sp.pipeline.run(&mut sp.work, &mut clock)
        } else {
            sp.pipeline.run_deskew(&mut sp.work, &mut clock)
        };
        // Points deskewed to the sweep's end pose are stamped with the end's time (on both
        // clocks, so the sensor-clock instant of the stamp stays known: the odometry's IMU).
        let reference_ns = i64::from(stats.reference_ns);
        sp.work.timestamp_ns = sweep.timestamp_ns.saturating_add(reference_ns);
        sp.work.device_time_ns = sweep.device_time_ns.saturating_add(reference_ns);
        sp.sweeps += 1;
        if sp.times.len() < TIMES_KEPT {
            sp.times.push(stats.times);
        }
        let (m, t) = (&mut sp.max, &stats.times);
        m.deskew_ns = m.deskew_ns.max(t.deskew_ns);
        m.filter_ns = m.filter_ns.max(t.filter_ns);
        m.voxel_ns = m.voxel_ns.max(t.voxel_ns);
        m.ground_ns = m.ground_ns.max(t.ground_ns);
        m.cluster_ns = m.cluster_ns.max(t.cluster_ns);
        let t = &mut sp.totals;
        t.input += stats.input;
        t.filtered += stats.filtered;
        t.voxels += stats.voxels;
        t.voxel_skipped += stats.voxel_skipped;
        t.ground += stats.ground;
        t.obstacles += stats.obstacles;
        t.unclustered += stats.unclustered;
        t.clusters += stats.clusters;
        t.filter.range += stats.filter.range;
        t.filter.fov += stats.filter.fov;
        t.filter.crop_box += stats.filter.crop_box;
        if let Some(e) = &stats.deskew_error {
            sp.deskew_skipped += 1;
            sp.last_deskew_error = Some(e.to_string());
        }
        if let (Some(live), true) = (&self.live, outputs) {
            let p = &sp.pipeline;
            let (log_time, stamp) = (sweep.last_host_ns.max(0), sweep.timestamp_ns.max(0));
            let (ground, obstacles) = (p.ground(), p.obstacles());
            live.borrow_mut().pipeline(
                idx,
                &sp.frame_id,
                log_time as u64,
                stamp as u64,
                ground,
                obstacles,
                p.obstacle_clusters(),
                p.clusters(),
            );
        }
        if let Some((sink, id)) = sink {
            let log_time = sweep.last_host_ns.max(0) as u64;
            let stamp = sp.work.timestamp_ns.max(0) as u64;
            if outputs {
                if sp.topics.is_none() {
                    sp.topics = Some(PipelineTopics::add(sink, id, &sp.frame_id)?);
                    if let Some(base) = sp.base_from_sensor {
                        let topic = match self.tf_static {
                            Some(t) => t,
                            None => {
                                let t = scene::add_tf_static(sink)?;
                                self.tf_static = Some(t);
                                t
                            }
                        };
                        let mut buf = Vec::new();
                        scene::encode_transform(
                            sink.format(),
                            &mut buf,
                            stamp,
                            "base_link",
                            name,
                            &base,
                        )?;
                        sink.write_message(topic, log_time, &buf)?;
                    }
                }
                if let Some(topics) = sp.topics.as_mut() {
                    let p = &sp.pipeline;
                    topics.write(
                        sink,
                        log_time,
                        stamp,
                        p.ground(),
                        p.obstacles(),
                        p.obstacle_clusters(),
                        p.clusters(),
                    )?;
                }
            }
        }
        Ok(&sp.work)
    }

    /// The `pipeline` object of the `--json` summary.
    pub fn summary(&self) -> Value {
        let all: Vec<&SensorPipeline> = self.sensors.iter().flatten().collect();
        let times: Vec<StageTimes> = all.iter().flat_map(|s| s.times.iter().copied()).collect();
        let sweeps: u64 = all.iter().map(|s| s.sweeps).sum();
        // Medians over the kept sweeps; maxima over all of them (the total's maximum is that
        // of the kept sweeps: stage maxima need not fall in one sweep).
        let stage = |f: fn(&StageTimes) -> u64| {
            let mut v = median_max_ms(times.iter().map(f).collect());
            let max = all.iter().map(|s| f(&s.max)).max().unwrap_or(0);
            if let Some(o) = v.as_object_mut() {
                if !times.is_empty() {
                    o.insert("max_ms".into(), json!(max as f64 * 1e-6));
                }
            }
            v
        };
        let sum = |f: fn(&SweepStats) -> usize| all.iter().map(|s| f(&s.totals)).sum::<usize>();
        let mut per_sensor = Vec::new();
        for s in &all {
            let t = &s.totals;
            per_sensor.push(json!({
                "name": s.name,
                "frame_id": s.frame_id,
                "sweeps": s.sweeps,
                "points_in": t.input,
                "after_filter": t.filtered,
                "after_voxel": t.voxels,
                "ground": t.ground,
                "obstacles": t.obstacles,
                "unclustered": t.unclustered,
                "clusters": t.clusters,
                "deskew_skipped": s.deskew_skipped,
                "deskew_last_error": s.last_deskew_error,
            }));
        }
        let cfg = &self.setup.config;
        let unused: Vec<&str> = self
            .setup
            .extrinsics
            .iter()
            .map(|e| e.name.as_str())
            .filter(|n| !all.iter().any(|s| s.name == *n))
            .collect();
        for n in &unused {
            tracing::warn!(
                "--extrinsics {n}=…: no sensor of that name (sensor names: {:?})",
                all.iter().map(|s| s.name.as_str()).collect::<Vec<_>>()
            );
        }
        json!({
            "config": self.setup.source,
            "deskew": cfg.deskew.mode.name(),
            "outputs": self.setup.outputs,
            "parameters": {
                "voxel.leaf_m": cfg.voxel_leaf_m,
                "filter.min_range_m": cfg.filter.min_range_m,
                "filter.max_range_m": if cfg.filter.max_range_m.is_finite() { json!(cfg.filter.max_range_m) } else { Value::Null },
                "ground.method": match cfg.ground.method {
                    crate::pipeline::config::GroundMethodName::Grid => "grid",
                    crate::pipeline::config::GroundMethodName::Ransac => "ransac",
                },
                "cluster.tolerance_m": cfg.cluster.tolerance_m,
                "cluster.min_points": cfg.cluster.min_points,
            },
            "sweeps": sweeps,
            "timed_sweeps": times.len(),
            "timings": {
                "deskew": stage(|t| t.deskew_ns),
                "filter": stage(|t| t.filter_ns),
                "voxel": stage(|t| t.voxel_ns),
                "ground": stage(|t| t.ground_ns),
                "cluster": stage(|t| t.cluster_ns),
                "total": median_max_ms(times.iter().map(StageTimes::total_ns).collect()),
            },
            "counts": {
                "points_in": sum(|t| t.input),
                "after_filter": sum(|t| t.filtered),
                "after_voxel": sum(|t| t.voxels),
                "ground": sum(|t| t.ground),
                "obstacles": sum(|t| t.obstacles),
                "unclustered": sum(|t| t.unclustered),
                "clusters": sum(|t| t.clusters),
                "removed_by_range": sum(|t| t.filter.range),
                "removed_by_fov": sum(|t| t.filter.fov),
                "removed_by_crop_box": sum(|t| t.filter.crop_box),
                "voxel_skipped": sum(|t| t.voxel_skipped),
            },
            "deskew_skipped": all.iter().map(|s| s.deskew_skipped).sum::<u64>(),
            "extrinsics_unused": unused,
            "sensors": per_sensor,
        })
    }
}
