//! The rest of the Python API on top of the same code as the command line: the streaming
//! [`Decoder`] (datagrams a caller receives itself), [`Listener`] (live sensors, `listen`'s
//! sockets and bounded queues), the pipeline stages and the odometry on arrays (configured by
//! the CLI's TOML keys and flags, so their checks and messages), and [`McapWriter`] (the
//! CLI's MCAP sink and schemas).

use std::net::{Ipv4Addr, SocketAddrV4};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex, PoisonError};

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};

use ringscan::cli::listen::{listen_run, parse_sensor, ListenArgs, ListenHooks, TappedSweep};
use ringscan::cli::odometry::{MethodArg, OdometryArgs};
use ringscan::cli::run::DecodeArgs;
use ringscan::cli::session::{Session, SessionOptions};
use ringscan::deskew::{Deskewer, Twist};
use ringscan::pipeline::cluster::{Clusterer, Clusters};
use ringscan::pipeline::config::PipelineConfig;
use ringscan::pipeline::ground::GroundSegmenter;
use ringscan::pipeline::voxel::{VoxelConfig, VoxelGrid};
use ringscan::point::Point;
use ringscan::registration::odometry::Odometry as CoreOdometry;
use ringscan::sink::mcap::{create_file, SensorId, SensorInfo, SweepMsg};

use crate::{decode_args, kind_of, raw_sweep, to_py_err, Buffer, ErrKind, Inbox, RawSweep, Recv};

/// Points from bytes of 24-byte records (any alignment).
fn points_of(bytes: &[u8]) -> PyResult<Vec<Point>> {
    if bytes.len() % 24 != 0 {
        return Err(to_py_err(
            ErrKind::Usage,
            format!("{} bytes: not whole 24-byte point records", bytes.len()),
        ));
    }
    Ok(bytemuck::pod_collect_to_vec::<u8, Point>(bytes))
}

fn pipeline_config(toml: &str) -> PyResult<PipelineConfig> {
    PipelineConfig::from_toml(toml).map_err(|e| to_py_err(ErrKind::Usage, format!("pipeline: {e}")))
}

/// Datagrams pushed by the caller, decoded as `decode` decodes a capture.
#[pyclass(module = "ringscan._ringscan", unsendable)]
pub struct Decoder {
    session: Session,
}

#[pymethods]
impl Decoder {
    #[new]
    #[pyo3(signature = (model=None, calib=vec![], port=None, cut_angle=0.0, min_range=None, max_range=None, fields_all=false, keep_columns=true))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        model: Option<String>,
        calib: Vec<String>,
        port: Option<u16>,
        cut_angle: f64,
        min_range: Option<f32>,
        max_range: Option<f32>,
        fields_all: bool,
        keep_columns: bool,
    ) -> PyResult<Self> {
        let mut args = decode_args(
            PathBuf::from("datagrams"),
            model,
            calib,
            Vec::new(),
            None,
            None,
            port,
            cut_angle,
            min_range,
            max_range,
            fields_all,
            None,
            None,
            None,
            None,
        );
        args.session.keep_columns = keep_columns;
        let mut session =
            Session::new(&args.session).map_err(|e| to_py_err(kind_of(&e), e.to_string()))?;
        session.enable_tap();
        Ok(Self { session })
    }

    /// Feeds one UDP payload from `src` ("IP:PORT") to `port`, received at `time_ns`; returns
    /// the sweeps it completed.
    #[pyo3(signature = (payload, src, port, time_ns=0))]
    fn push(
        &mut self,
        py: Python<'_>,
        payload: &[u8],
        src: &str,
        port: u16,
        time_ns: i64,
    ) -> PyResult<Vec<RawSweep>> {
        let src: SocketAddrV4 = src.parse().map_err(|_| {
            to_py_err(
                ErrKind::Usage,
                format!("src {src:?}: expected \"IPv4:PORT\""),
            )
        })?;
        if let Err(e) = self.session.push(time_ns, src, port, payload) {
            let e = self.session.run_error(e, "datagrams");
            return Err(to_py_err(kind_of(&e), e.to_string()));
        }
        self.drain(py)
    }

    /// Ends every stream: their last sweeps.
    fn finish(&mut self, py: Python<'_>) -> PyResult<Vec<RawSweep>> {
        if let Err(e) = self.session.finish_streams() {
            let e = self.session.run_error(e, "datagrams");
            return Err(to_py_err(kind_of(&e), e.to_string()));
        }
        self.drain(py)
    }

    /// The summary's shared fields (sweeps, points, packets, sensors), a JSON string.
    fn summary(&self) -> String {
        serde_json::Value::Object(self.session.summary().0).to_string()
    }
}

impl Decoder {
    fn drain(&mut self, py: Python<'_>) -> PyResult<Vec<RawSweep>> {
        let sweeps: Vec<_> = self.session.take_sweeps().collect();
        sweeps
            .into_iter()
            .map(|rs| {
                let desc = self.session.sensor_desc(rs.sensor);
                raw_sweep(py, rs, desc, None)
            })
            .collect()
    }
}

/// How a listener's thread ended: the summary (JSON), or the error (no kind: it panicked).
type Outcome = Result<String, (Option<ErrKind>, String)>;

/// The largest `queue`: a sync channel allocates all its slots up front, so a huge bound is
/// memory taken at once (or an abort), not a limit.
const MAX_QUEUE: usize = 1 << 16;

/// A seam for the tests, compiled into debug builds only (the test suite's; a wheel is a
/// release build): with this variable set the listening thread panics at its start, as a bug
/// in it would, so the tests can see that such an end raises instead of looking like a stop.
#[cfg(debug_assertions)]
const TEST_LISTEN_PANIC: &str = "RINGSCAN_TEST_LISTEN_PANIC";

/// `listen` on a thread of its own, its sweeps through a bounded channel.
#[pyclass(module = "ringscan._ringscan")]
pub struct Listener {
    inbox: Inbox<TappedSweep>,
    stop: Arc<AtomicBool>,
    done: Arc<Mutex<Option<Outcome>>>,
    /// Whether the thread's error reached Python: it is raised once, by `next()` or `stop()`.
    raised: AtomicBool,
    /// Locked only without the GIL: `finish` holds it while it joins.
    thread: Mutex<Option<std::thread::JoinHandle<()>>>,
}

#[pymethods]
impl Listener {
    #[new]
    #[pyo3(signature = (sensors, model=None, calib=vec![], duration=None, multicast=None, interface="0.0.0.0", recv_buffer=None, api_port=80, queue=16, out=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        sensors: Vec<String>,
        model: Option<String>,
        calib: Vec<String>,
        duration: Option<f64>,
        multicast: Option<&str>,
        interface: &str,
        recv_buffer: Option<usize>,
        api_port: u16,
        queue: usize,
        out: Option<PathBuf>,
    ) -> PyResult<Self> {
        let sensors = sensors
            .iter()
            .map(|s| parse_sensor(s).map_err(|e| to_py_err(ErrKind::Usage, format!("sensor {e}"))))
            .collect::<PyResult<Vec<_>>>()?;
        let ip = |s: &str, what: &str| -> PyResult<Ipv4Addr> {
            s.parse().map_err(|_| {
                to_py_err(
                    ErrKind::Usage,
                    format!("{what} {s:?}: expected an IPv4 address"),
                )
            })
        };
        let duration = match duration {
            None => None,
            Some(d) => Some(
                // NaN, infinities and values past `Duration`'s range are refused here.
                std::time::Duration::try_from_secs_f64(d)
                    .ok()
                    .filter(|d| !d.is_zero())
                    .ok_or_else(|| {
                        to_py_err(
                            ErrKind::Usage,
                            format!("duration {d}: expected a positive number of seconds"),
                        )
                    })?,
            ),
        };
        if queue > MAX_QUEUE {
            return Err(to_py_err(
                ErrKind::Usage,
                format!("queue {queue}: expected at most {MAX_QUEUE} sweeps"),
            ));
        }
        let d = DecodeArgs {
            session: SessionOptions {
                model,
                calib,
                keep_columns: true,
                ..SessionOptions::default()
            },
            ..DecodeArgs::new(PathBuf::from("udp"))
        };
        let (tx, rx) = mpsc::sync_channel::<TappedSweep>(queue.max(1));
        let stop = Arc::new(AtomicBool::new(false));
        let args = ListenArgs {
            sensors,
            out,
            split_every: None,
            session: d.session,
            fields_minimal: false,
            threads: 1,
            chunk_size: d.chunk_size,
            multicast: multicast.map(|m| ip(m, "multicast")).transpose()?,
            interface: ip(interface, "interface")?,
            api_port,
            recv_buffer: recv_buffer.unwrap_or(ringscan::source::udp::DEFAULT_RECV_BUFFER),
            duration,
            strict: false,
            json: true,
            serve: Default::default(),
            hesai_ptc: None,
            hooks: ListenHooks {
                stop: Some(stop.clone()),
                sweeps: Some(tx),
                sweeps_dropped: Default::default(),
            },
        };
        let done = Arc::new(Mutex::new(None));
        let done_t = done.clone();
        let thread = std::thread::Builder::new()
            .name("ringscan-listen".into())
            .spawn(move || {
                #[cfg(debug_assertions)]
                if std::env::var_os(TEST_LISTEN_PANIC).is_some() {
                    panic!("{TEST_LISTEN_PANIC} is set");
                }
                let r = listen_run(&args)
                    .map(|o| o.json.to_string())
                    .map_err(|e| (Some(kind_of(&e)), e.to_string()));
                *done_t.lock().unwrap_or_else(PoisonError::into_inner) = Some(r);
                // `args` holds the first sender: dropped after `done` is set, so a receiver
                // that sees the channel disconnected finds the outcome (or a panic).
            })
            .map_err(|e| PyRuntimeError::new_err(format!("starting the listener: {e}")))?;
        Ok(Self {
            inbox: Inbox::new(rx).stopping_on_interrupt(stop.clone()),
            stop,
            done,
            raised: AtomicBool::new(false),
            thread: Mutex::new(Some(thread)),
        })
    }

    /// The next sweep, or `None` once listening stopped (then `summary()`); raises the
    /// listening thread's error.
    fn next(&self, py: Python<'_>) -> PyResult<Option<RawSweep>> {
        match self.inbox.recv(py, "the listener")? {
            Recv::Msg((rs, desc)) => Ok(Some(raw_sweep(py, rs, desc, None)?)),
            Recv::Disconnected | Recv::Finished => {
                self.finish(py)?;
                Ok(None)
            }
        }
    }

    /// Stops listening and waits for the thread to end, the MCAP file (if any) finished;
    /// raises the thread's error unless `next()` did. Sweeps still queued stay for `next()`.
    fn stop(&self, py: Python<'_>) -> PyResult<()> {
        self.stop.store(true, Ordering::Relaxed);
        self.finish(py)
    }

    /// The `listen --json` summary (a JSON string) once stopped, else `None`.
    fn summary(&self) -> Option<String> {
        match self.done.lock().ok()?.as_ref()? {
            Ok(s) => Some(s.clone()),
            Err(_) => None,
        }
    }
}

impl Listener {
    /// Waits for the listening thread to end, then raises its error (once). The GIL is
    /// released for the whole wait, lock included: a second caller waits for the first's join.
    fn finish(&self, py: Python<'_>) -> PyResult<()> {
        py.allow_threads(|| {
            let mut handle = self.thread.lock().unwrap_or_else(PoisonError::into_inner);
            if let Some(h) = handle.take() {
                let panic = h.join().err();
                let mut done = self.done.lock().unwrap_or_else(PoisonError::into_inner);
                if done.is_none() {
                    let why = panic
                        .as_ref()
                        .and_then(|p| {
                            p.downcast_ref::<&str>()
                                .map(|s| s.to_string())
                                .or_else(|| p.downcast_ref::<String>().cloned())
                        })
                        .unwrap_or_default();
                    *done = Some(Err((
                        None,
                        format!(
                            "the listening thread stopped without a result ({why}): a bug, please report it"
                        ),
                    )));
                }
            }
        });
        let done = self.done.lock().unwrap_or_else(PoisonError::into_inner);
        match done.as_ref() {
            Some(Err((kind, msg))) if !self.raised.swap(true, Ordering::AcqRel) => {
                Err(match kind {
                    Some(k) => to_py_err(*k, msg.clone()),
                    None => PyRuntimeError::new_err(msg.clone()),
                })
            }
            _ => Ok(()),
        }
    }
}

impl Drop for Listener {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// `[voxel]` of the pipeline: one point per voxel (the centroid).
#[pyfunction]
fn voxel_downsample(py: Python<'_>, points: &[u8], toml: &str) -> PyResult<Py<Buffer>> {
    let pts = points_of(points)?;
    let cfg = pipeline_config(toml)?;
    let mut grid = VoxelGrid::new(VoxelConfig::cubic(cfg.voxel_leaf_m))
        .map_err(|e| to_py_err(ErrKind::Usage, format!("voxel: {e}")))?;
    let out = py.allow_threads(move || {
        let mut out = Vec::new();
        grid.downsample(&pts, &mut out);
        out
    });
    Py::new(py, Buffer::points(out))
}

/// `[ground]` of the pipeline: whether each point is ground (one byte per point).
#[pyfunction]
fn segment_ground(py: Python<'_>, points: &[u8], toml: &str) -> PyResult<Py<PyBytes>> {
    let pts = points_of(points)?;
    let cfg = pipeline_config(toml)?;
    let mut seg = GroundSegmenter::new(cfg.ground.method())
        .map_err(|e| to_py_err(ErrKind::Usage, format!("ground: {e}")))?;
    let labels = py.allow_threads(move || {
        let mut labels = Vec::new();
        seg.segment(&pts, &mut labels);
        labels.into_iter().map(u8::from).collect::<Vec<u8>>()
    });
    Ok(PyBytes::new(py, &labels).unbind())
}

/// `[cluster]` of the pipeline: each point's cluster (u32, `u32::MAX` for none) and each
/// cluster's point count, centroid, min and max.
#[pyfunction]
#[allow(clippy::type_complexity)]
fn cluster(
    py: Python<'_>,
    points: &[u8],
    toml: &str,
) -> PyResult<(Py<Buffer>, Vec<(usize, [f32; 3], [f32; 3], [f32; 3])>)> {
    let pts = points_of(points)?;
    let cfg = pipeline_config(toml)?;
    let mut clusterer = Clusterer::new(cfg.cluster.params())
        .map_err(|e| to_py_err(ErrKind::Usage, format!("cluster: {e}")))?;
    let (labels, list) = py.allow_threads(move || {
        let mut out = Clusters::new();
        clusterer.cluster(&pts, &mut out);
        let mut labels = vec![u32::MAX; pts.len()];
        for k in 0..out.len() {
            for &i in out.points_of(k) {
                if let Some(l) = labels.get_mut(i as usize) {
                    *l = k as u32;
                }
            }
        }
        let list = out
            .as_slice()
            .iter()
            .map(|c| (c.point_count, c.centroid, c.min, c.max))
            .collect::<Vec<_>>();
        (labels, list)
    });
    Ok((Py::new(py, Buffer::u32s(labels))?, list))
}

/// `[deskew]` of the pipeline, constant velocity: the points moved to the sweep's start (or
/// end) pose.
#[pyfunction]
fn deskew(py: Python<'_>, points: &[u8], toml: &str) -> PyResult<Py<Buffer>> {
    let mut pts = points_of(points)?;
    let cfg = pipeline_config(toml)?;
    let d = &cfg.deskew;
    let twist = Twist {
        linear_mps: d.linear_mps.into(),
        angular_radps: d.angular_degps.map(f64::to_radians).into(),
    };
    let reference = d.reference;
    let pts = py.allow_threads(move || {
        Deskewer::new(reference).deskew_constant_velocity(&mut pts, &twist);
        pts
    });
    Py::new(py, Buffer::points(pts))
}

/// The LiDAR odometry, configured as `decode --odometry`'s flags.
#[pyclass(module = "ringscan._ringscan", unsendable)]
pub struct Odometry {
    inner: CoreOdometry,
}

#[pymethods]
impl Odometry {
    #[new]
    #[pyo3(signature = (method="point-to-plane", voxel=None, max_range=100.0))]
    fn new(method: &str, voxel: Option<f64>, max_range: f64) -> PyResult<Self> {
        use clap::ValueEnum;
        let m = MethodArg::from_str(method, true).map_err(|_| {
            to_py_err(
                ErrKind::Usage,
                format!(
                    "method {method:?}: expected point-to-plane, point-to-point or continuous-time"
                ),
            )
        })?;
        let args = OdometryArgs {
            odometry: true,
            odometry_method: m,
            odometry_voxel: voxel,
            odometry_max_range: max_range,
            ..OdometryArgs::default()
        };
        let setup = args
            .setup(false, false)
            .map_err(|e| to_py_err(ErrKind::Usage, e))?
            .ok_or_else(|| to_py_err(ErrKind::Usage, "odometry: not configured".into()))?;
        let inner = CoreOdometry::new(*setup.config())
            .map_err(|e| to_py_err(ErrKind::Usage, format!("--odometry: {e}")))?;
        Ok(Self { inner })
    }

    /// Registers one sweep's points (24-byte records, `t` in ns since `stamp_ns`): a dict
    /// with the pose (`world_from_sensor`, 16 floats row-major), status, ICP figures.
    fn register<'py>(
        &mut self,
        py: Python<'py>,
        points: &[u8],
        stamp_ns: i64,
    ) -> PyResult<Bound<'py, PyDict>> {
        let pts = points_of(points)?;
        let inner = &mut self.inner;
        let step = py.allow_threads(move || inner.register_points(&pts, stamp_ns));
        let m = step.world_from_sensor.to_homogeneous();
        let rows: Vec<f64> = (0..4)
            .flat_map(|r| (0..4).map(move |c| (r, c)))
            .map(|(r, c)| m[(r, c)])
            .collect();
        let d = PyDict::new(py);
        d.set_item("stamp_ns", step.stamp_ns)?;
        d.set_item("index", step.index)?;
        d.set_item("world_from_sensor", rows)?;
        d.set_item("status", format!("{:?}", step.status))?;
        d.set_item("points", step.points)?;
        d.set_item("source_points", step.source_points)?;
        d.set_item("keyframe", step.keyframe)?;
        d.set_item("map_points", step.map_points)?;
        d.set_item("threshold_m", step.threshold_m)?;
        Ok(d)
    }

    /// Forgets the map and the trajectory.
    fn reset(&mut self) {
        self.inner.reset();
    }
}

/// MCAP files with the command line's schemas and channels.
#[pyclass(module = "ringscan._ringscan", unsendable)]
pub struct McapWriter {
    sink: Option<ringscan::cli::session::Sink>,
    sensors: Vec<SensorId>,
    path: PathBuf,
}

#[pymethods]
impl McapWriter {
    #[new]
    #[pyo3(signature = (path, format="foxglove", compression="zstd", threads=1))]
    fn new(path: PathBuf, format: &str, compression: &str, threads: usize) -> PyResult<Self> {
        let fmt = match format {
            "foxglove" => ringscan::cli::FormatArg::Foxglove,
            "ros2" => ringscan::cli::FormatArg::Ros2,
            f => {
                return Err(to_py_err(
                    ErrKind::Usage,
                    format!("format {f:?}: expected 'foxglove' or 'ros2'"),
                ))
            }
        };
        let comp = compression
            .parse()
            .map_err(|e: String| to_py_err(ErrKind::Usage, format!("compression {e}")))?;
        let d = DecodeArgs::new(path.clone());
        let opts = ringscan::cli::session::sink_options_with(
            fmt,
            comp,
            threads.max(1),
            d.chunk_size,
            false,
        );
        let sink =
            create_file(&path, opts).map_err(|e| to_py_err(ErrKind::Decode, e.to_string()))?;
        Ok(Self {
            sink: Some(sink),
            sensors: Vec::new(),
            path,
        })
    }

    /// Adds a sensor (topics `<topic_prefix>/points`, ...); returns its handle.
    #[pyo3(signature = (name, topic_prefix="", metadata=None))]
    fn add_sensor(
        &mut self,
        name: &str,
        topic_prefix: &str,
        metadata: Option<std::collections::BTreeMap<String, String>>,
    ) -> PyResult<usize> {
        let sink = self.open()?;
        let id = sink
            .add_sensor(&SensorInfo {
                name: name.to_string(),
                topic_prefix: topic_prefix.to_string(),
                metadata: metadata.unwrap_or_default(),
                calibration: None,
            })
            .map_err(|e| to_py_err(ErrKind::Usage, e.to_string()))?;
        self.sensors.push(id);
        Ok(self.sensors.len() - 1)
    }

    /// Writes one sweep (24-byte point records) of sensor `sensor`.
    #[pyo3(signature = (sensor, points, timestamp_ns, log_time_ns=None))]
    fn write_sweep(
        &mut self,
        py: Python<'_>,
        sensor: usize,
        points: &[u8],
        timestamp_ns: u64,
        log_time_ns: Option<u64>,
    ) -> PyResult<()> {
        let pts = points_of(points)?;
        let id = *self
            .sensors
            .get(sensor)
            .ok_or_else(|| to_py_err(ErrKind::Usage, format!("sensor {sensor}: not added")))?;
        let sink = self.open()?;
        py.allow_threads(move || {
            sink.write_sweep(
                id,
                &SweepMsg {
                    log_time_ns: log_time_ns.unwrap_or(timestamp_ns),
                    timestamp_ns,
                    points: &pts,
                },
            )
        })
        .map_err(|e| to_py_err(ErrKind::Decode, e.to_string()))
    }

    /// Finishes the file; returns the messages per topic as a JSON string.
    fn close(&mut self, py: Python<'_>) -> PyResult<String> {
        match self.sink.take() {
            Some(s) => {
                let summary = py
                    .allow_threads(move || s.finish())
                    .map_err(|e| to_py_err(ErrKind::Decode, e.to_string()))?;
                Ok(serde_json::json!({"path": self.path.display().to_string(), "topics": summary.messages}).to_string())
            }
            None => Ok("{}".into()),
        }
    }
}

impl McapWriter {
    fn open(&mut self) -> PyResult<&mut ringscan::cli::session::Sink> {
        self.sink
            .as_mut()
            .ok_or_else(|| to_py_err(ErrKind::Usage, "the MCAP writer is closed".into()))
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Decoder>()?;
    m.add_class::<Listener>()?;
    m.add_class::<Odometry>()?;
    m.add_class::<McapWriter>()?;
    m.add_function(wrap_pyfunction!(voxel_downsample, m)?)?;
    m.add_function(wrap_pyfunction!(segment_ground, m)?)?;
    m.add_function(wrap_pyfunction!(cluster, m)?)?;
    m.add_function(wrap_pyfunction!(deskew, m)?)?;
    #[cfg(debug_assertions)]
    m.add("_test_listen_panic", TEST_LISTEN_PANIC)?;
    Ok(())
}
