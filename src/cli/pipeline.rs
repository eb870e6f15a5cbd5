//! `--pipeline`, `--deskew`, `--extrinsics`: the perception pipeline run on every decoded sweep,
//! its MCAP outputs and its `--json` figures. The algorithms live in `ringscan::pipeline` and
//! `ringscan::deskew`; this file reads files, owns the clock and writes.

use std::io::{Seek, Write};
use std::time::Instant;

use nalgebra::Isometry3;
use ringscan::deskew::PoseTable;
use ringscan::pipeline::config::{DeskewMode, PipelineConfig};
use ringscan::pipeline::filter::Extrinsics;
use ringscan::pipeline::run::{Pipeline, StageTimes, SweepStats};
use ringscan::sink::scene::{self, PipelineTopics};
use ringscan::sink::{McapSink, SensorId, SinkError, TopicId};
use ringscan::sweep::{ImuSample, Sweep};
use serde_json::{json, Value};

/// The pipeline flags of `decode`.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct PipelineArgs {
    /// Perception pipeline run on every sweep: `none`, `default`, or a TOML file of
    /// parameters (see `ringscan::pipeline::config`). Writes `ground`, `obstacles` and
    /// `clusters` per sensor.
    #[arg(long, value_name = "none|default|FILE.toml")]
    pub pipeline: Option<String>,
    /// Motion correction of every sweep: `none`, `constant-velocity` (the twist of the
    /// pipeline configuration), `imu` (Ouster gyro), `poses:FILE` (TUM poses), `odometry`.
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
        if config.deskew.mode == DeskewMode::Odometry {
            return Err(
                "--deskew odometry: needs odometry, which this build does not run yet; \
                 use constant-velocity (with deskew.linear_mps / angular_degps), imu or poses:FILE"
                    .to_string(),
            );
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

impl PipelineRunner {
    /// A runner for the resolved flags.
    pub fn new(setup: PipelineSetup) -> Self {
        Self {
            setup,
            sensors: Vec::new(),
            tf_static: None,
            clock_origin: Instant::now(),
            pending_imu: Vec::new(),
        }
    }

    /// Whether pipeline outputs are written (not only deskew).
    pub fn outputs(&self) -> bool {
        self.setup.outputs
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
        sp.work.clone_from(sweep);
        let mut clock = || origin.elapsed().as_nanos() as u64;
        let stats = sp.pipeline.run(&mut sp.work, &mut clock);
        sp.times.push(stats.times);
        let t = &mut sp.totals;
        t.input += stats.input;
        t.filtered += stats.filtered;
        t.voxels += stats.voxels;
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
        if let Some((sink, id)) = sink {
            let log_time = sweep.last_host_ns.max(0) as u64;
            let stamp = sweep.timestamp_ns.max(0) as u64;
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
                        scene::encode_frame_transform(&mut buf, stamp, "base_link", name, &base);
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
        let stage = |f: fn(&StageTimes) -> u64| median_max_ms(times.iter().map(f).collect());
        let sum = |f: fn(&SweepStats) -> usize| all.iter().map(|s| f(&s.totals)).sum::<usize>();
        let mut per_sensor = Vec::new();
        for s in &all {
            let t = &s.totals;
            per_sensor.push(json!({
                "name": s.name,
                "frame_id": s.frame_id,
                "sweeps": s.times.len(),
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
        json!({
            "config": self.setup.source,
            "deskew": cfg.deskew.mode.name(),
            "outputs": self.setup.outputs,
            "parameters": {
                "voxel.leaf_m": cfg.voxel_leaf_m,
                "filter.min_range_m": cfg.filter.min_range_m,
                "filter.max_range_m": if cfg.filter.max_range_m.is_finite() { json!(cfg.filter.max_range_m) } else { Value::Null },
                "ground.method": match cfg.ground.method {
                    ringscan::pipeline::config::GroundMethodName::Grid => "grid",
                    ringscan::pipeline::config::GroundMethodName::Ransac => "ransac",
                },
                "cluster.tolerance_m": cfg.cluster.tolerance_m,
                "cluster.min_points": cfg.cluster.min_points,
            },
            "sweeps": times.len(),
            "timings": {
                "deskew": stage(|t| t.deskew_ns),
                "filter": stage(|t| t.filter_ns),
                "voxel": stage(|t| t.voxel_ns),
                "ground": stage(|t| t.ground_ns),
                "cluster": stage(|t| t.cluster_ns),
                "total": stage(StageTimes::total_ns),
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
            },
            "deskew_skipped": all.iter().map(|s| s.deskew_skipped).sum::<u64>(),
            "sensors": per_sensor,
        })
    }
}
