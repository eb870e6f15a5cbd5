//! Datagrams → demultiplexer → streams → sink: the [`Session`] that `decode`, `info`,
//! `listen` and the Python package drive, whatever the datagrams come from, with the MCAP
//! output it writes to.

use std::io::Read;
use std::net::Ipv4Addr;
use std::path::Path;
use std::sync::{Arc, Mutex};

use crate::point::Point;
use crate::sensor::DecodeOptions;
use crate::sensor::StreamError;
use crate::sensor::{Calibration, Facts, FirstDatagram, StreamSettings};
use crate::sink::mcap::{
    Behind, Compression, Format, PointFields, SensorId, SensorInfo, SinkOptions, SinkSummary,
    SweepMsg,
};
use crate::sink::{McapSink, SinkError};
use crate::sweep::{Demux, Sweep};
use serde_json::{json, Value};

use super::bag_args::{Input, InputError};
use super::odometry::{OdometryArgs, OdometryRunner};
use super::pipeline::{PipelineArgs, PipelineRunner};
use super::run::RunError;
use super::sensors::{self, load_calibs, Chooser};
use super::FormatArg;

/// Raw datagrams held per sensor until it is registered (for `--raw`), at most this many
/// bytes: as many as a Robosense stream holds while it waits for its DIFOP (4,096 MSOP
/// packets), or two seconds of an OS-2-128's lidar packets. Beyond that they are counted
/// (`raw_dropped`), never dropped unseen.
const RAW_HOLD_BYTES: usize = 16 << 20;
/// Raw datagrams held over all sensors: a capture of many sources that never register (a
/// hostile one) holds no more than this.
const RAW_HOLD_TOTAL_BYTES: usize = 64 << 20;

fn parse_model(m: Option<&str>) -> Result<Option<String>, RunError> {
    match m {
        None => Ok(None),
        Some(s) if crate::sensor::family_of_model(s).is_some() => Ok(Some(s.to_string())),
        Some(s) => {
            // Grouped by family, in `--help`'s order (Velodyne first), not in the order the
            // families are asked to claim a sensor.
            let mut order: Vec<&dyn crate::sensor::Family> =
                ["velodyne", "hesai", "robosense", "livox"]
                    .into_iter()
                    .filter_map(crate::sensor::family)
                    .collect();
            for f in crate::sensor::FAMILIES {
                if !order.iter().any(|g| g.name() == f.name()) {
                    order.push(*f);
                }
            }
            let by_family: Vec<String> = order
                .iter()
                .filter(|f| !f.models().is_empty())
                .map(|f| format!("{}: {}", title_case(f.name()), f.models().join(", ")))
                .collect();
            Err(RunError::Usage(format!(
                "--model {s}: expected one of {}",
                by_family.join("; ")
            )))
        }
    }
}

/// A family's name as prose writes it (`velodyne` → `Velodyne`).
fn title_case(name: &str) -> String {
    let mut t = name.to_string();
    if let Some(c) = t.get_mut(..1) {
        c.make_ascii_uppercase();
    }
    t
}

/// The topic prefix of sensor `idx` named `name` among `n_sensors` counted: none for the
/// first of a single sensor. `ros`: a name ROS 2 takes ([`ros_name`]).
fn topic_prefix(n_sensors: usize, idx: usize, name: &str, ros: bool) -> String {
    if n_sensors <= 1 && idx == 0 {
        String::new()
    } else if ros {
        format!("/{}", ros_name(name))
    } else {
        format!("/{name}")
    }
}

/// A sensor name as a ROS 2 topic token: ROS 2 takes only letters, digits and `_`, and no
/// token that starts with a digit (rmw's full topic name rules), where sensor names hold `-`
/// and `.` (`vlp16-201`): `ros2 bag play` cannot publish such a topic. Other characters become
/// `_`; a leading digit gets `sensor_` before it (a leading `_` would hide the topic).
fn ros_name(name: &str) -> String {
    let token: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    match token.chars().next() {
        Some(c) if !c.is_ascii_digit() => token,
        _ => format!("sensor_{token}"),
    }
}

/// Per-sensor output state.
struct SensorOut {
    addr: Ipv4Addr,
    registered: bool,
    id: Option<SensorId>,
    name: String,
    topic: String,
    calib_file: Option<String>,
    /// Files used beside `calib_file` (the ATX's firetimes), not attached.
    calib_more: Vec<String>,
    raw_hold: Vec<(i64, u16, u16, Vec<u8>)>,
    raw_hold_bytes: usize,
    raw_dropped: u64,
    /// How the sensor was registered in the sink (again in each file with `--split-every`).
    info: Option<SensorInfo>,
}

/// The MCAP output of a run.
pub type Sink = McapSink<std::io::BufWriter<std::fs::File>>;

struct Output {
    sink: Option<Sink>,
    sensors: Vec<SensorOut>,
    n_sensors_hint: usize,
    name: Option<String>,
    raw: bool,
    calibs: Vec<(Option<Ipv4Addr>, String, Vec<u8>)>,
    /// Bytes of `SensorOut::raw_hold` over all sensors (at most [`RAW_HOLD_TOTAL_BYTES`]).
    raw_hold_total: usize,
    error: Option<SinkError>,
    sweeps: u64,
    points: u64,
    imu_samples: u64,
    /// Zone-monitor reports (Ouster FW 3.2+), each a message on `<prefix>/zones`.
    zone_reports: u64,
    pipeline: Option<PipelineRunner>,
    /// `--odometry` (also with `--deskew odometry`).
    odometry: Option<OdometryRunner>,
    /// `--serve`: the live view, also fed by the pipeline.
    live: Option<super::serve::SharedPublisher>,
    /// A copy of every decoded sweep (before the pipeline), for `SweepReader`.
    tap: Option<Vec<(usize, Sweep)>>,
    /// Buffers the tap's consumer gives back, for the next tapped sweeps.
    pool: Option<Arc<BufferPool>>,
    /// Options given that only some families read: (option, those families, where the others
    /// have it).
    family_options: Vec<(&'static str, &'static [&'static str], &'static str)>,
    /// Names of the calibrations that came attached to the input, not from the user.
    from_input: Vec<String>,
    /// `--min-range` / `--max-range` as given, for the warning of a range that kept no point.
    range_given: Option<String>,
}

/// Point and column buffers that the consumer of handed-out sweeps gives back (the Python
/// package, once numpy lets go of an array), reused for the next sweeps: otherwise every sweep
/// lands in memory the allocator has just returned to the kernel, and its page faults cost
/// about a tenth of reading an Ouster capture from Python. At most [`BufferPool::KEEP`] of
/// each are kept, so memory stays bounded whatever the consumer does.
#[derive(Debug, Default)]
pub struct BufferPool {
    points: Mutex<Vec<Vec<Point>>>,
    columns: Mutex<Vec<Vec<u32>>>,
}

impl BufferPool {
    /// Buffers of each kind kept at most (the sweeps a reader has in flight, and one more).
    pub const KEEP: usize = 6;

    /// Gives a point buffer back.
    pub fn give_points(&self, v: Vec<Point>) {
        Self::give(&self.points, v);
    }

    /// Gives a column buffer back.
    pub fn give_columns(&self, v: Vec<u32>) {
        Self::give(&self.columns, v);
    }

    fn give<T>(pool: &Mutex<Vec<Vec<T>>>, mut v: Vec<T>) {
        if v.capacity() == 0 {
            return;
        }
        v.clear();
        if let Ok(mut p) = pool.lock() {
            if p.len() < Self::KEEP {
                p.push(v);
            }
        }
    }

    fn take<T>(pool: &Mutex<Vec<Vec<T>>>) -> Vec<T> {
        pool.lock()
            .ok()
            .and_then(|mut p| p.pop())
            .unwrap_or_default()
    }
}

impl Output {
    fn sensor(&mut self, idx: usize, addr: Ipv4Addr) -> &mut SensorOut {
        while self.sensors.len() <= idx {
            self.sensors.push(SensorOut {
                addr,
                registered: false,
                id: None,
                name: String::new(),
                topic: String::new(),
                calib_file: None,
                calib_more: Vec::new(),
                raw_hold: Vec::new(),
                raw_hold_bytes: 0,
                raw_dropped: 0,
                info: None,
            });
        }
        &mut self.sensors[idx]
    }

    /// Registers a sensor in the sink once its model is known.
    fn register(
        &mut self,
        idx: usize,
        addr: Ipv4Addr,
        facts: &dyn Facts,
        ports: &[u16],
    ) -> Result<(), SinkError> {
        let mut name = match &self.name {
            Some(n) => n.clone(),
            None => facts.default_name(addr),
        };
        // Two sensors of one model whose addresses end alike: name them by the whole address.
        if self.sensors.iter().any(|s| s.registered && s.name == name) {
            let o = addr.octets();
            name = format!("{name}-{}-{}-{}", o[0], o[1], o[2]);
        }
        // Several files may serve one sensor (the ATX's angle correction and its firetimes);
        // the first is attached.
        let files = facts.calibration_files();
        let first = files.first().copied().unwrap_or_default();
        let more: Vec<String> = files.iter().skip(1).map(|f| f.to_string()).collect();
        let calib = self
            .calibs
            .iter()
            .find(|(a, n, _)| (a.is_none() || *a == Some(addr)) && first == *n)
            .map(|(_, n, b)| (n.clone(), b.clone()));
        let md = sensors::channel_metadata(facts, addr, ports);
        let ros = self
            .sink
            .as_ref()
            .is_some_and(|k| k.format() == crate::sink::mcap::Format::Ros2);
        let topic_prefix = topic_prefix(self.n_sensors_hint, idx, &name, ros);
        let s = self.sensor(idx, addr);
        s.name = name.clone();
        s.topic = format!("{topic_prefix}/points");
        s.calib_file = calib.as_ref().map(|(n, _)| n.clone());
        s.calib_more = more;
        let info = SensorInfo {
            name,
            topic_prefix,
            metadata: md,
            calibration: calib,
        };
        if let Some(sink) = self.sink.as_mut() {
            let id = sink.add_sensor(&info)?;
            let hold = std::mem::take(&mut self.sensors[idx].raw_hold);
            self.raw_hold_total = self
                .raw_hold_total
                .saturating_sub(self.sensors[idx].raw_hold_bytes);
            self.sensors[idx].raw_hold_bytes = 0;
            for (t, port, src_port, payload) in hold {
                sink.write_raw(
                    id,
                    t.max(0) as u64,
                    std::net::SocketAddrV4::new(addr, src_port),
                    port,
                    &payload,
                )?;
            }
            self.sensors[idx].id = Some(id);
        }
        if let Some(live) = &self.live {
            live.borrow_mut()
                .add_sensor(idx, &info.name, &info.topic_prefix);
        }
        self.sensors[idx].registered = true;
        self.sensors[idx].info = Some(info);
        Ok(())
    }

    /// Writes one datagram of sensor `idx` to `/raw` (`--raw`), or holds it until the sensor
    /// is registered (its model known), within [`RAW_HOLD_BYTES`] and
    /// [`RAW_HOLD_TOTAL_BYTES`]; beyond them it is counted in `raw_dropped`.
    fn raw_datagram(
        &mut self,
        idx: usize,
        time: i64,
        src: std::net::SocketAddrV4,
        port: u16,
        payload: &[u8],
    ) -> Result<(), PumpError> {
        let id = self.sensor(idx, *src.ip()).id;
        match (id, self.sink.as_mut()) {
            (Some(id), Some(sink)) => {
                sink.write_raw(id, time.max(0) as u64, src, port, payload)
                    .map_err(PumpError::Sink)?;
            }
            _ => {
                let total = &mut self.raw_hold_total;
                let s = &mut self.sensors[idx];
                if s.raw_hold_bytes + payload.len() <= RAW_HOLD_BYTES
                    && *total + payload.len() <= RAW_HOLD_TOTAL_BYTES
                {
                    s.raw_hold_bytes += payload.len();
                    *total += payload.len();
                    s.raw_hold.push((time, port, src.port(), payload.to_vec()));
                } else {
                    s.raw_dropped += 1;
                }
            }
        }
        Ok(())
    }

    fn on_sweep(
        &mut self,
        idx: usize,
        addr: Ipv4Addr,
        sweep: &mut Sweep,
        facts: &dyn Facts,
        ports: &[u16],
    ) {
        if self.error.is_some() {
            return;
        }
        self.sweeps += 1;
        self.points += sweep.points.len() as u64;
        if !self.sensors.get(idx).is_some_and(|s| s.registered) {
            if let Err(e) = self.register(idx, addr, facts, ports) {
                self.error = Some(e);
                return;
            }
        }
        if let Some(tap) = self.tap.as_mut() {
            // A session that only hands its sweeps out (the Python reader) moves their buffers:
            // nothing below would read the sweep.
            let only_tap = self.sink.is_none()
                && self.pipeline.is_none()
                && self.live.is_none()
                && self.odometry.is_none();
            if only_tap {
                let taken = match &self.pool {
                    Some(p) => sweep.take_buffers_with(
                        BufferPool::take(&p.points),
                        BufferPool::take(&p.columns),
                    ),
                    None => sweep.take_buffers(),
                };
                tap.push((idx, taken));
                return;
            }
            tap.push((idx, sweep.clone()));
        }
        let several = !(self.n_sensors_hint <= 1 && idx == 0);
        // `--deskew odometry`: the odometry's last motion deskews this sweep; the twist used is
        // kept to refer the deskewed points to mid-sweep for the odometry.
        let mut odometry_deskew = None;
        if let (Some(p), Some(o)) = (self.pipeline.as_mut(), self.odometry.as_ref()) {
            if p.deskews_with_odometry() {
                let name = &self.sensors[idx].name;
                let fed = match o.last_motion(idx) {
                    Some(m) => p.set_relative_motion(
                        idx,
                        name,
                        &m.previous_from_current,
                        m.dt_ns as f64 * 1e-9,
                    ),
                    None => Ok(()),
                };
                match fed.and_then(|()| p.twist(idx, name)) {
                    Ok(t) => odometry_deskew = Some((t, sweep.timestamp_ns)),
                    Err(e) => {
                        self.error = Some(e);
                        return;
                    }
                }
            }
        }
        let base_from_sensor = self
            .pipeline
            .as_ref()
            .and_then(|p| p.base_from_sensor(&self.sensors[idx].name));
        // The pipeline (when asked for) deskews a copy of the sweep, which is written instead.
        let sweep = match self.pipeline.as_mut() {
            Some(p) => {
                let sink = self.sink.as_mut().zip(self.sensors[idx].id);
                match p.process(idx, &self.sensors[idx].name, sweep, sink) {
                    Ok(s) => s,
                    Err(e) => {
                        self.error = Some(e);
                        return;
                    }
                }
            }
            None => &*sweep,
        };
        if let Some(live) = &self.live {
            live.borrow_mut().sweep(idx, sweep);
        }
        let odometry_diag = match self.odometry.as_mut() {
            Some(o) => {
                let sink = self.sink.as_mut().zip(self.sensors[idx].id);
                match o.process(
                    idx,
                    &self.sensors[idx].name,
                    several,
                    sweep,
                    odometry_deskew,
                    base_from_sensor.as_ref(),
                    self.live.as_ref(),
                    sink,
                ) {
                    Ok(d) => d,
                    Err(e) => {
                        self.error = Some(e);
                        return;
                    }
                }
            }
            None => None,
        };
        let (Some(sink), Some(id)) = (self.sink.as_mut(), self.sensors[idx].id) else {
            return;
        };
        let msg = SweepMsg {
            log_time_ns: sweep.last_host_ns.max(0) as u64,
            timestamp_ns: sweep.timestamp_ns.max(0) as u64,
            points: &sweep.points,
        };
        let written = if sweep.extras.len() == sweep.points.len() && !sweep.extras.is_empty() {
            sink.write_sweep_extended(id, &msg, &sweep.extras)
        } else {
            sink.write_sweep(id, &msg)
        };
        if let Err(e) = written {
            self.error = Some(e);
            return;
        }
        let mut diag = json!({
            "sweep": sweep.index,
            "packets": sweep.packets,
            "missing_packets": sweep.missing_packets,
            "points": sweep.points.len(),
            "columns": sweep.columns_count,
            "span_ns": sweep.span_ns(),
            "clock": sweep.clock.name(),
            "device_time_ns": sweep.device_time_ns,
            "first_azimuth_deg": f64::from(sweep.first_azimuth) / 100.0,
            "frame_id": sweep.frame_id,
            "missing_columns": sweep.missing_columns,
        });
        if let Some(d) = diag.as_object_mut() {
            facts.diagnostics(d);
        }
        if let (Some(d), Some(o)) = (diag.as_object_mut(), odometry_diag) {
            d.insert("odometry".into(), o);
        }
        if let Err(e) = sink.write_diagnostics(id, sweep.last_host_ns.max(0) as u64, &diag) {
            self.error = Some(e);
        }
    }
}

/// Settings of a [`Session`], whatever the datagrams come from. The default is `decode`'s:
/// every sensor, no range limits, the calibrations built in.
#[derive(Debug, Clone, Default)]
pub struct SessionOptions {
    /// `--model`: overrides detection.
    pub model: Option<String>,
    /// `--calib`, as given (`[ADDR=]FILE`).
    pub calib: Vec<String>,
    /// `--name`: frame id and topic prefix of a single sensor.
    pub name: Option<String>,
    /// `--port`: only datagrams sent to this UDP port.
    pub port: Option<u16>,
    /// `--cut-angle`, degrees.
    pub cut_angle_deg: f64,
    /// `--min-range`, metres.
    pub min_range: Option<f32>,
    /// `--max-range`, metres.
    pub max_range: Option<f32>,
    /// `--dual-return-threshold` (Hesai), metres.
    pub dual_return_threshold_m: Option<f32>,
    /// `--fov START:END`, degrees (Hesai).
    pub fov_deg: Option<(f64, f64)>,
    /// `--integration-ms` (Livox).
    pub integration_ms: Option<f64>,
    /// `--fields all`.
    pub fields_all: bool,
    /// `--raw`: every UDP payload to `/raw` as well.
    pub raw: bool,
    /// Packet CRC checks: `None` = where the sensor writes them.
    pub crc: Option<bool>,
    /// `--pipeline`, `--deskew`, `--extrinsics`.
    pub pipeline: PipelineArgs,
    /// Points message layout (the pipeline's outputs need `foxglove`).
    pub format: FormatArg,
    /// `--odometry`, `--trajectory`, `--map-every`.
    pub odometry: OdometryArgs,
    /// Keep each point's firing column in the sweeps (organised images,
    /// [`SweepReader`](super::run::SweepReader)).
    pub keep_columns: bool,
    /// Only inspecting (`info`): [`StreamSettings::inspect`].
    pub inspect: bool,
}

/// A decoded sweep handed out by [`Session::take_sweeps`] (and so by `SweepReader`), with the
/// index of its sensor.
pub struct ReadSweep {
    /// The sensor's index (order of first appearance).
    pub sensor: usize,
    /// The sweep as the stream cut it (no pipeline).
    pub sweep: Sweep,
}

/// What a session knows of a sensor ([`Session::sensor_desc`]).
#[derive(Clone, Debug)]
pub struct SensorDesc {
    /// The name `decode` gives it (its topic prefix when there are several).
    pub name: String,
    /// The sensor family (`velodyne`, `ouster`, ...).
    pub family: &'static str,
    /// Source IPv4 address.
    pub address: Ipv4Addr,
    /// Channels (rows of its organised image), once known.
    pub channels: Option<usize>,
}

/// Datagrams → demultiplexer → streams → sink, independent of where the datagrams come from
/// (a capture for `decode`, sockets for `listen`).
pub struct Session {
    demux: Demux,
    out: Output,
    chooser: std::rc::Rc<std::cell::RefCell<Chooser>>,
    /// `--model`, as given.
    model: Option<String>,
}

/// Why [`Session::push`] or [`Session::finish_streams`] stopped.
pub enum PumpError {
    Source(InputError),
    Stream(usize, StreamError),
    Sink(SinkError),
}

impl Session {
    /// Checks the options, loads the calibrations and sets up the demultiplexer (no output yet:
    /// [`Session::set_sink`]).
    pub fn new(opts: &SessionOptions) -> Result<Self, RunError> {
        let model = parse_model(opts.model.as_deref())?;
        if !(0.0..360.0).contains(&opts.cut_angle_deg) {
            return Err(RunError::Usage(format!(
                "--cut-angle {}: expected [0, 360) degrees",
                opts.cut_angle_deg
            )));
        }
        let decode = DecodeOptions {
            min_range: opts.min_range.unwrap_or(0.0),
            max_range: opts.max_range.unwrap_or(f32::INFINITY),
        };
        if decode.min_range.is_nan() || decode.max_range.is_nan() {
            return Err(RunError::Usage(
                "--min-range / --max-range: expected numbers of metres".into(),
            ));
        }
        if decode.min_range < 0.0 {
            return Err(RunError::Usage(format!(
                "--min-range {}: expected a distance of 0 m or more",
                decode.min_range
            )));
        }
        if decode.min_range > decode.max_range {
            return Err(RunError::Usage(format!(
                "--min-range {} / --max-range {}: empty range",
                decode.min_range, decode.max_range
            )));
        }
        let pipeline = opts
            .pipeline
            .setup()
            .map_err(RunError::Usage)?
            .map(PipelineRunner::new);
        let odometry_deskew = pipeline
            .as_ref()
            .is_some_and(PipelineRunner::deskews_with_odometry);
        let pipeline_deskews = pipeline.as_ref().is_some_and(PipelineRunner::deskews);
        let odometry = opts
            .odometry
            .setup(odometry_deskew, pipeline_deskews)
            .map_err(RunError::Usage)?
            .map(OdometryRunner::new);
        if let Some(why) = pipeline
            .as_ref()
            .and_then(|p| p.idle_deskew(&opts.pipeline))
        {
            return Err(RunError::Usage(why));
        }
        if let Some(t) = opts.dual_return_threshold_m {
            if !(t.is_finite() && t >= 0.0) {
                return Err(RunError::Usage(format!(
                    "--dual-return-threshold {t}: expected metres ≥ 0"
                )));
            }
        }
        if let Some((a, b)) = opts.fov_deg {
            if ![a, b].iter().all(|v| (0.0..=360.0).contains(v)) {
                return Err(RunError::Usage(format!(
                    "--fov {a}:{b}: expected START:END in degrees, each 0 … 360"
                )));
            }
        }
        let calibs = load_calibs(&opts.calib)?;
        let cut = (opts.cut_angle_deg * 100.0).round() as u16 % 36_000;
        let chooser = std::rc::Rc::new(std::cell::RefCell::new(Chooser::new(
            &calibs,
            StreamSettings {
                model,
                decode,
                cut_angle: cut,
                keep_extras: opts.fields_all,
                keep_columns: opts.keep_columns,
                crc: opts.crc,
                dual_return_threshold_m: opts.dual_return_threshold_m,
                fov_cdeg: opts.fov_deg.map(|(a, b)| {
                    (
                        (a.rem_euclid(360.0) * 100.0).round() as u32 % 36_000,
                        (b.rem_euclid(360.0) * 100.0).round() as u32 % 36_000,
                    )
                }),
                integration_ns: opts
                    .integration_ms
                    .filter(|ms| ms.is_finite() && *ms > 0.0)
                    .map(|ms| (ms * 1e6).round() as u64),
                imu_to_sensor: None,
                inspect: opts.inspect,
            },
        )));
        let shared = chooser.clone();
        let config_for = move |d: &FirstDatagram<'_>| shared.borrow_mut().choose(d);
        let demux = Demux::new(Box::new(config_for), opts.port);
        let out = Output {
            sink: None,
            sensors: Vec::new(),
            n_sensors_hint: 1,
            name: opts.name.clone(),
            raw: opts.raw,
            calibs: calibs
                .into_iter()
                .map(|c| (c.addr, c.file_name, c.bytes.to_vec()))
                .collect(),
            raw_hold_total: 0,
            error: None,
            sweeps: 0,
            points: 0,
            imu_samples: 0,
            zone_reports: 0,
            pipeline,
            odometry,
            live: None,
            tap: None,
            pool: None,
            range_given: match (opts.min_range, opts.max_range) {
                (None, None) => None,
                (Some(a), None) => Some(format!("--min-range {a}")),
                (None, Some(b)) => Some(format!("--max-range {b}")),
                (Some(a), Some(b)) => Some(format!("--min-range {a} --max-range {b}")),
            },
            family_options: [
                (
                    opts.fov_deg.is_some(),
                    "--fov",
                    &["hesai"][..],
                    "; other sensors: the pipeline's filter.azimuth_min_deg / azimuth_max_deg",
                ),
                (
                    opts.dual_return_threshold_m.is_some(),
                    "--dual-return-threshold",
                    &["hesai"],
                    "",
                ),
                (
                    opts.integration_ms.is_some(),
                    "--integration-ms",
                    &["livox"],
                    "",
                ),
                (
                    opts.cut_angle_deg != 0.0,
                    "--cut-angle",
                    &["velodyne", "hesai", "robosense"],
                    " (Ouster and Livox sweeps are their frames or integration periods)",
                ),
            ]
            .into_iter()
            .filter(|(given, ..)| *given)
            .map(|(_, o, f, h)| (o, f, h))
            .collect(),
            from_input: Vec::new(),
        };
        Ok(Self {
            demux,
            out,
            chooser,
            model: opts.model.clone(),
        })
    }

    /// Why no sensor was found in `src`, if none was: nothing was read (a bag's `--topic`
    /// that names none of its packet topics is told), or what was read fitted no sensor
    /// family (or not the `--model` given).
    pub fn no_sensor_reason<R: Read>(&self, src: &Input<R>) -> Option<String> {
        // Sensors were recognised, but every data packet of theirs went to another port (what
        // did reach them, a Velodyne's position packets, gives no point).
        let st = self.demux.stats();
        if let (Some(want), Some(first)) = (self.demux.data_port(), st.other_port_first) {
            if self
                .demux
                .sensors()
                .all(|(_, s, _)| s.summary().1.decoded == 0)
            {
                return Some(format!(
                    "{} data packets, none of them to --port {want} (the first went to port \
                     {first})",
                    st.other_port
                ));
            }
        }
        if self.demux.sensors().next().is_some() {
            return None;
        }
        let ignored = self.demux.stats().ignored;
        let missed = src.bag().and_then(|b| b.topics_missed());
        let points = src
            .bag()
            .filter(|b| b.stats().packet_messages == 0)
            .map(|b| b.point_cloud_topics())
            .unwrap_or_default();
        Some(match (ignored, missed, &self.model) {
            (0, Some((given, known)), _) => {
                format!(
                    "--topic {} is none of the bag's packet topics ({})",
                    given.join(" --topic "),
                    if known.is_empty() {
                        "it has none".to_string()
                    } else {
                        known.join(", ")
                    }
                )
            }
            (0, None, _) if !points.is_empty() => format!(
                "the bag holds decoded point clouds ({}), not packets (an MCAP that ringscan \
                 writes with --raw keeps the packets too, and decodes again)",
                points.join(", ")
            ),
            (0, None, _) => {
                // What the input's own counters tell of why (records skipped, a cut).
                let c = src.capture_json();
                let n = |k: &str| c[k].as_u64().unwrap_or(0);
                let skipped: Vec<String> = [
                    ("malformed (headers that contradict the record, or longer than the snaplen)", n("malformed_records")),
                    ("truncated by the capture's snaplen", n("truncated_records")),
                    ("not IPv4 UDP", n("non_udp")),
                ]
                .iter()
                .filter(|(_, k)| *k > 0)
                .map(|(what, k)| format!("{k} {what}"))
                .collect();
                let records = n("records");
                if !skipped.is_empty() {
                    format!(
                        "no datagram was read: of the {records} records, {}",
                        skipped.join(", ")
                    )
                } else if let (0, Some(at)) = (records, c["truncated_tail_offset"].as_u64()) {
                    format!("no datagram was read: the capture ends at byte {at}, inside its first record")
                } else {
                    "no datagram was read (an empty capture, or none selected by --topic, \
                     --start, --end)"
                        .to_string()
                }
            }
            (n, _, Some(m)) => format!("{n} datagrams, none of them a packet of --model {m}"),
            (n, _, None) => match self.unused_calibrations().as_slice() {
                // The input brought its sensor's metadata (a bag's metadata topic), but no
                // lidar packet that would start the sensor came.
                [] if !self.out.from_input.is_empty() => format!(
                    "{n} datagrams that no sensor family recognised; the input's own \
                     calibration ({}) was read, but none of its sensor's lidar packets came \
                     (an Ouster sensor starts on them{})",
                    self.out.from_input.join(", "),
                    if src.bag().is_some_and(|b| !b.topics_given().is_empty()) {
                        ": does --topic select only its IMU packets?"
                    } else {
                        ""
                    }
                ),
                [] => format!(
                    "{n} datagrams that no sensor family recognised (Ouster packets need their \
                     metadata: --calib META.json; the others are known by their size and layout)"
                ),
                given => format!(
                    "{n} datagrams that no sensor family recognised; {} {} given, but no \
                     packet fits {} (an Ouster metadata file names its packets' size and \
                     ports: another sensor's, or another lidar mode's?)",
                    given.join(", "),
                    if given.len() == 1 { "was" } else { "were" },
                    if given.len() == 1 { "it" } else { "them" },
                ),
            },
        })
    }

    /// Payload sizes that start a sensor's main stream.
    pub fn lidar_sizes(&self) -> Vec<usize> {
        self.chooser.borrow().lidar_sizes()
    }

    /// How many sensors are expected (one: topics without a sensor prefix). Sensors already
    /// registered without an output (a [`SweepReader`](super::run::SweepReader) counts while
    /// it decodes) take the topics the count gives; with an output, topics are written once
    /// and stay.
    pub fn set_sensor_hint(&mut self, n: usize) {
        self.out.n_sensors_hint = n;
        if self.out.sink.is_none() {
            for (idx, s) in self.out.sensors.iter_mut().enumerate() {
                if let Some(info) = s.info.as_mut() {
                    info.topic_prefix = topic_prefix(n, idx, &s.name, false);
                    s.topic = format!("{}/points", info.topic_prefix);
                }
            }
        }
    }

    /// Where sweeps go from now on (`None`: decode and count only).
    pub fn set_sink(&mut self, sink: Option<Sink>) {
        self.out.sink = sink;
    }

    /// Whether a `--calib` file of `family` may still serve a sensor at `addr` (bound to it,
    /// or unbound and serving no sensor yet): its first lidar packet will start it.
    pub fn calibration_pending(&self, family: &str, addr: Ipv4Addr) -> bool {
        self.chooser.borrow().pending(family, addr)
    }

    /// Lets go of the datagrams the demultiplexer holds for `addr` (the caller holds them too
    /// and pushes them again).
    pub fn forget_early(&mut self, addr: Ipv4Addr) {
        self.demux.forget_early(addr);
    }

    /// Adds a calibration (e.g. Ouster metadata fetched from the sensor) for sensors not yet
    /// seen; it is attached to the output like a `--calib` file.
    pub fn add_calib(&mut self, spec: Calibration) {
        self.chooser.borrow_mut().add(&spec);
        self.out.from_input.retain(|n| n != &spec.file_name);
        self.out
            .calibs
            .push((spec.addr, spec.file_name, spec.bytes.to_vec()));
    }

    /// Closes the current output and continues into `next` (`--split-every`): every sensor
    /// already known is registered again in the new file. Returns the closed file's summary.
    /// If the current output cannot be finished, the session is left without one and `next`
    /// is dropped unused (nothing goes to a file after a failed one).
    pub fn rotate(&mut self, next: Sink) -> Result<Option<SinkSummary>, SinkError> {
        let closed = match self.out.sink.take() {
            Some(s) => Some(s.finish()?),
            None => None,
        };
        let sink = self.out.sink.insert(next);
        for s in self.out.sensors.iter_mut() {
            s.id = match &s.info {
                Some(info) => Some(sink.add_sensor(info)?),
                None => None,
            };
        }
        if let Some(p) = self.out.pipeline.as_mut() {
            p.new_file();
        }
        if let Some(o) = self.out.odometry.as_mut() {
            o.new_file();
        }
        Ok(closed)
    }

    /// Publishes the sweeps (and pipeline outputs) to a live view from now on (`--serve`).
    pub fn set_live(&mut self, live: Option<super::serve::LivePublisher>) {
        let live = live.map(|l| std::rc::Rc::new(std::cell::RefCell::new(l)));
        if let Some(p) = self.out.pipeline.as_mut() {
            p.set_live(live.clone());
        }
        self.out.live = live;
    }

    /// Flushes the odometry's trajectory files (`--trajectory`).
    pub fn finish_odometry(&mut self) -> Result<(), RunError> {
        match self.out.odometry.as_mut() {
            Some(o) => o.finish().map_err(RunError::Live),
            None => Ok(()),
        }
    }

    /// Drops the output unwritten: its temporary file is removed.
    pub fn abort_sink(&mut self) {
        if let Some(s) = self.out.sink.take() {
            s.abort();
        }
    }

    /// Closes the output, if any (and lets the live view's clients drain).
    pub fn close_sink(&mut self) -> Result<Option<SinkSummary>, SinkError> {
        if let Some(live) = &self.out.live {
            live.borrow_mut().close();
        }
        match self.out.sink.take() {
            Some(s) => Ok(Some(s.finish()?)),
            None => Ok(None),
        }
    }

    /// Writes a diagnostics object for sensor `idx` (e.g. `listen`'s periodic health), if it
    /// is registered in an output.
    pub fn write_diagnostics(
        &mut self,
        idx: usize,
        log_time_ns: u64,
        json: &Value,
    ) -> Result<(), SinkError> {
        let id = self.out.sensors.get(idx).and_then(|s| s.id);
        match (self.out.sink.as_mut(), id) {
            (Some(sink), Some(id)) => sink.write_diagnostics(id, log_time_ns, json),
            _ => Ok(()),
        }
    }

    /// The output's chunk counters so far, if there is an output.
    pub fn chunk_stats(&self) -> Option<crate::sink::mcap::WriterStats> {
        self.out.sink.as_ref().map(|s| s.chunk_stats())
    }

    /// Sweeps and points so far.
    pub fn totals(&self) -> (u64, u64) {
        (self.out.sweeps, self.out.points)
    }

    /// Takes the buffers of the sweeps it hands out from `pool`, where their consumer gives
    /// them back (see [`BufferPool`]).
    pub fn use_buffer_pool(&mut self, pool: Arc<BufferPool>) {
        self.out.pool = Some(pool);
    }

    /// The demultiplexer (per-sensor streams and counters).
    pub fn demux(&self) -> &Demux {
        &self.demux
    }

    /// Keeps a copy of every decoded sweep (before the pipeline) for [`Session::take_sweeps`].
    pub fn enable_tap(&mut self) {
        self.out.tap.get_or_insert_with(Vec::new);
    }

    /// The sweeps decoded since the last call (with [`Session::enable_tap`]), oldest first.
    pub fn take_sweeps(&mut self) -> impl Iterator<Item = ReadSweep> + '_ {
        self.out
            .tap
            .iter_mut()
            .flat_map(|t| t.drain(..))
            .map(|(sensor, sweep)| ReadSweep { sensor, sweep })
    }

    /// The sensor of index `idx`, once seen.
    pub fn sensor_desc(&self, idx: usize) -> Option<SensorDesc> {
        let (address, stream) = self.demux.stream(idx)?;
        let name = self
            .out
            .sensors
            .get(idx)
            .map(|s| s.name.clone())
            .filter(|n| !n.is_empty())
            .unwrap_or_else(|| stream.facts().default_name(address));
        Some(SensorDesc {
            name,
            family: stream.facts().family(),
            address,
            channels: stream.channels(),
        })
    }

    /// A calibration attached to the input (a bag ringscan wrote carries the files it decoded
    /// with): used as [`Self::add_calib`] does, but not reported when no sensor takes it, as
    /// the user did not give it.
    pub fn add_attached_calib(&mut self, spec: Calibration) {
        let name = spec.file_name.clone();
        self.add_calib(spec);
        self.out.from_input.push(name);
    }

    /// The `--calib` files no sensor took, by name (not the input's own attachments).
    fn unused_calibrations(&self) -> Vec<&str> {
        let out = &self.out;
        let used: std::collections::BTreeSet<&str> = out
            .sensors
            .iter()
            .flat_map(|s| s.calib_file.iter().chain(&s.calib_more))
            .map(String::as_str)
            .collect();
        out.calibs
            .iter()
            .map(|(_, n, _)| n.as_str())
            .filter(|n| !used.contains(n) && !out.from_input.iter().any(|a| a == n))
            .collect()
    }

    /// The error a [`PumpError`] means for the user.
    pub fn run_error(&self, e: PumpError, path: &str) -> RunError {
        match e {
            PumpError::Source(err) => RunError::Source {
                path: path.to_string(),
                err,
            },
            PumpError::Stream(idx, err) => {
                let unused = self.unused_calibrations();
                // An option the model cannot honour (`--min-range` beyond its range) is no
                // matter of calibration, whichever file the stream was building with.
                let options_only = matches!(
                    err,
                    crate::sensor::StreamError::Decode(crate::sensor::DecodeError::Option(_))
                );
                let note = if unused.is_empty() || options_only {
                    String::new()
                } else {
                    format!(
                        " ({} given, but it fits none of the sensors found: family, model, \
                         laser count, serial or address)",
                        unused.join(", ")
                    )
                };
                RunError::Stream {
                    addr: self
                        .demux
                        .stream(idx)
                        .map(|(a, _)| a)
                        .unwrap_or(Ipv4Addr::UNSPECIFIED),
                    err,
                    note,
                }
            }
            PumpError::Sink(e) => RunError::Sink(e),
        }
    }

    /// Feeds one datagram (`time` = host receive time, ns).
    pub fn push(
        &mut self,
        time: i64,
        src: std::net::SocketAddrV4,
        port: u16,
        payload: &[u8],
    ) -> Result<(), PumpError> {
        let (demux, out) = (&mut self.demux, &mut self.out);
        let addr = *src.ip();
        let routed = demux.push_from(time, src, port, payload, &mut |idx, sweep, facts| {
            out.on_sweep(idx, addr, sweep, facts, &[port]);
        });
        // Datagrams the sensor sent before the one that started it went to it first.
        let (idx, own) = match (routed, demux.replayed().0) {
            (Ok(Some(idx)), _) => (idx, true),
            (Ok(None), Some(idx)) => (idx, false),
            (Ok(None), None) => return Ok(()),
            (Err((idx, e)), _) => return Err(PumpError::Stream(idx, e)),
        };
        if let Some(e) = out.error.take() {
            return Err(PumpError::Sink(e));
        }
        let registered = out.sensors.get(idx).is_some_and(|s| s.registered);
        if !registered {
            if let Some((_, stream)) = demux.stream(idx) {
                if stream.ready() {
                    let ports: Vec<u16> = demux
                        .sensors()
                        .nth(idx)
                        .map(|(_, _, p)| p.to_vec())
                        .unwrap_or_default();
                    out.register(idx, addr, stream.facts(), &ports)
                        .map_err(PumpError::Sink)?;
                }
            }
        }
        if let Some(stream) = demux.stream_mut(idx) {
            let id = out.sensors.get(idx).and_then(|x| x.id);
            let mut failed = None;
            stream.drain_imu(&mut |smp, imu_to_sensor| {
                out.imu_samples += 1;
                if let Some(p) = out.pipeline.as_mut() {
                    p.push_imu(idx, imu_to_sensor, smp);
                }
                if let Some(o) = out.odometry.as_mut() {
                    o.push_imu(idx, imu_to_sensor, smp);
                }
                if let (Some(sink), Some(id), None) = (out.sink.as_mut(), id, &failed) {
                    let msg = json!({
                        "timestamp_ns": smp.sensor_ns,
                        "linear_acceleration": smp.accel,
                        "angular_velocity": smp.gyro,
                    });
                    if let Err(e) = sink.write_imu(id, smp.host_ns.max(0) as u64, &msg) {
                        failed = Some(e);
                    }
                }
            });
            if let Some(e) = failed {
                return Err(PumpError::Sink(e));
            }
            stream.drain_zones(&mut |z| {
                out.zone_reports += 1;
                if let (Some(sink), Some(id), None) = (out.sink.as_mut(), id, &failed) {
                    let msg = zone_report_json(z);
                    if let Err(e) = sink.write_zones(id, z.host_ns.max(0) as u64, &msg) {
                        failed = Some(e);
                    }
                }
            });
            if let Some(e) = failed {
                return Err(PumpError::Sink(e));
            }
        }
        if out.raw && out.sink.is_some() {
            for e in demux.replayed().1 {
                let from = std::net::SocketAddrV4::new(addr, e.src_port);
                out.raw_datagram(idx, e.host_ns, from, e.dst_port, e.payload)?;
            }
            if own {
                out.raw_datagram(idx, time, src, port, payload)?;
            }
        }
        Ok(())
    }

    /// Ends every stream: their last sweeps, and raw packets still held.
    pub fn finish_streams(&mut self) -> Result<(), PumpError> {
        let (demux, out) = (&mut self.demux, &mut self.out);
        let addrs: Vec<Ipv4Addr> = demux.sensors().map(|(a, _, _)| a).collect();
        let ports: Vec<Vec<u16>> = demux.sensors().map(|(_, _, p)| p.to_vec()).collect();
        let r = demux.finish(&mut |idx, sweep, facts| {
            let addr = addrs.get(idx).copied().unwrap_or(Ipv4Addr::UNSPECIFIED);
            out.on_sweep(
                idx,
                addr,
                sweep,
                facts,
                ports.get(idx).map(|p| p.as_slice()).unwrap_or(&[]),
            );
        });
        if let Err((idx, e)) = r {
            return Err(PumpError::Stream(idx, e));
        }
        if let Some(e) = out.error.take() {
            return Err(PumpError::Sink(e));
        }
        // Sensors whose raw packets are still held (model never known): write them anyway.
        if out.raw {
            for idx in 0..out.sensors.len() {
                if !out.sensors[idx].registered && !out.sensors[idx].raw_hold.is_empty() {
                    let addr = out.sensors[idx].addr;
                    if let Some((_, stream)) = demux.stream(idx) {
                        out.register(
                            idx,
                            addr,
                            stream.facts(),
                            ports.get(idx).map(|p| p.as_slice()).unwrap_or(&[]),
                        )
                        .map_err(PumpError::Sink)?;
                    }
                }
            }
        }
        Ok(())
    }

    /// The summary fields every command shares (`sweeps`, `points`, `imu_samples`,
    /// `zone_reports`, `packets`,
    /// `sensors`), and the number of packets lost (dropped, malformed or missing).
    pub fn summary(&self) -> (serde_json::Map<String, Value>, u64) {
        let (demux, out) = (&self.demux, &self.out);
        let dstats = demux.stats().clone();
        let mut sensors = Vec::new();
        let (mut decoded, mut malformed, mut missing, mut position) = (0u64, 0u64, 0u64, 0u64);
        let mut sensor_dropped = 0u64;
        for (idx, (addr, stream, ports)) in demux.sensors().enumerate() {
            let (mut v, c) = stream.summary();
            decoded += c.decoded;
            malformed += c.malformed;
            missing += c.missing;
            position += c.position;
            sensor_dropped += c.dropped;
            let so = out.sensors.get(idx);
            if let Some(o) = v.as_object_mut() {
                o.insert("name".into(), json!(so.map(|s| s.name.clone())));
                o.insert("address".into(), json!(addr.to_string()));
                o.insert("ports".into(), json!(ports));
                let per_port: serde_json::Map<String, Value> = ports
                    .iter()
                    .zip(demux.port_packets(idx))
                    .map(|(p, n)| (p.to_string(), json!(n)))
                    .collect();
                o.insert("packets_per_port".into(), Value::Object(per_port));
                o.insert(
                    "calibration_file".into(),
                    json!(so.and_then(|s| s.calib_file.clone())),
                );
                o.insert("topic".into(), json!(so.map(|s| s.topic.clone())));
                o.insert("raw_dropped".into(), json!(so.map(|s| s.raw_dropped)));
            }
            sensors.push(v);
        }
        let dropped = dstats.other_port + dstats.dropped_sensor_limit + sensor_dropped;
        let mut m = serde_json::Map::new();
        m.insert("sweeps".into(), json!(out.sweeps));
        m.insert("points".into(), json!(out.points));
        m.insert("imu_samples".into(), json!(out.imu_samples));
        m.insert("zone_reports".into(), json!(out.zone_reports));
        // A calibration no sensor took (another model's file, another sensor's metadata)
        // would otherwise pass unnoticed: the sensor decodes without it, or not at all.
        m.insert(
            "unused_calibrations".into(),
            json!(self.unused_calibrations()),
        );
        // An option of one family on a run that found sensors, none of them that family's,
        // did nothing: say so rather than let it pass for applied.
        let kinds: std::collections::BTreeSet<&str> =
            sensors.iter().filter_map(|s| s["kind"].as_str()).collect();
        let mut unused_options: Vec<String> = out
            .family_options
            .iter()
            .filter(|(_, families, _)| {
                !kinds.is_empty() && !families.iter().any(|f| kinds.contains(f))
            })
            .map(|(option, families, hint)| {
                let names: Vec<String> = families.iter().map(|f| title_case(f)).collect();
                format!(
                    "{option} applies to {} sensors only, and none was found{hint}",
                    names.join(", ")
                )
            })
            .collect();
        // `--port` selects the packets of sensors told by their data port; on a run of only
        // sensors told by their calibration it selected nothing.
        if let Some(p) = demux.data_port() {
            let by_port = |k: &&str| crate::sensor::family(k).is_none_or(|f| f.selected_by_port());
            if !kinds.is_empty() && !kinds.iter().any(by_port) {
                let names: Vec<String> = kinds.iter().map(|k| title_case(k)).collect();
                unused_options.push(format!(
                    "--port {p} selects nothing on {} sensors: they are told by their \
                     calibration (its ports), and all their packets were decoded",
                    names.join(", ")
                ));
            }
        }
        m.insert("unused_options".into(), json!(unused_options));
        // A range that kept no point of the packets decoded (beyond the sensor's reach, or
        // a typo) gives an empty output that would otherwise pass for a quiet scene.
        let warnings: Vec<String> = out
            .range_given
            .as_ref()
            .filter(|_| decoded > 0 && out.points == 0)
            .map(|r| format!("{r}: no point of the {decoded} packets decoded is in that range"))
            .into_iter()
            .collect();
        m.insert("warnings".into(), json!(warnings));
        m.insert(
            "packets".into(),
            json!({
                "decoded": decoded,
                "dropped": dropped,
                "malformed": malformed,
                "missing": missing,
                "position": position,
                "ignored": dstats.ignored,
                "early": dstats.early,
                "other_port": dstats.other_port,
            }),
        );
        m.insert("sensors".into(), Value::Array(sensors));
        if let Some(p) = out.pipeline.as_ref() {
            m.insert("pipeline".into(), p.summary());
        }
        if let Some(o) = out.odometry.as_ref() {
            m.insert("odometry".into(), o.summary());
        }
        if let Some(live) = &out.live {
            m.insert("serve".into(), live.borrow().summary());
        }
        (m, dropped + malformed + missing)
    }
}

/// The `output` object of a summary.
pub fn output_json(
    s: &SinkSummary,
    path: Option<&Path>,
    opts: &SinkOptions,
    fields: &str,
) -> Value {
    json!({
        "path": path.map(|p| p.display().to_string()),
        "format": if opts.format == Format::Ros2 { "ros2" } else { "foxglove" },
        // Velodyne points have no extra fields: `--fields all` writes the default ones.
        "fields": fields,
        "topics": s.messages,
        "attachments": s.attachments.iter().map(|a| json!({"name": a.name, "media_type": a.media_type, "size": a.size})).collect::<Vec<_>>(),
        "chunks": s.chunks,
        "chunks_uncompressed": s.chunks_uncompressed,
        "raw_dropped": s.raw_dropped,
        "threads": opts.threads,
    })
}

/// The name of `--fields` in summaries.
pub fn fields_name(all: bool, minimal: bool) -> &'static str {
    match (all, minimal) {
        (true, _) => "all",
        (false, true) => "minimal",
        (false, false) => "default",
    }
}

/// The sink options of `--format`, `--compression`, `--threads`, `--chunk-size` and `--fields
/// minimal`; the
/// compression threads are waited for when behind (`decode`; `listen` sets
/// [`Behind::WriteUncompressed`]).
pub fn sink_options_with(
    format: FormatArg,
    compression: ChunkCompression,
    threads: usize,
    chunk_size: u64,
    fields_minimal: bool,
) -> SinkOptions {
    SinkOptions {
        format: if format == FormatArg::Ros2 {
            Format::Ros2
        } else {
            Format::Foxglove
        },
        compression: compression.kind,
        zstd_level: compression.zstd_level,
        threads,
        chunk_size,
        behind: Behind::Wait,
        fields: if fields_minimal {
            PointFields::Minimal
        } else {
            PointFields::Default
        },
    }
}

/// `--compression`: how MCAP chunks are compressed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ChunkCompression {
    /// zstd, lz4 or none.
    pub kind: Compression,
    /// The zstd level (ignored otherwise).
    pub zstd_level: i32,
}

impl Default for ChunkCompression {
    fn default() -> Self {
        Self {
            kind: Compression::Zstd,
            zstd_level: crate::sink::mcap::DEFAULT_ZSTD_LEVEL,
        }
    }
}

impl std::str::FromStr for ChunkCompression {
    type Err = String;

    /// `zstd`, `zstd:LEVEL`, `lz4` or `none`.
    fn from_str(s: &str) -> Result<Self, String> {
        let levels = crate::sink::mcap::ZSTD_LEVELS;
        match s {
            "zstd" => Ok(Self::default()),
            "lz4" => Ok(Self {
                kind: Compression::Lz4,
                ..Self::default()
            }),
            "none" => Ok(Self {
                kind: Compression::None,
                ..Self::default()
            }),
            _ => {
                let level = s
                    .strip_prefix("zstd:")
                    .and_then(|l| l.parse::<i32>().ok())
                    .filter(|l| levels.contains(l) && *l != 0)
                    .ok_or_else(|| {
                        format!(
                            "{s:?}: expected zstd, zstd:LEVEL (LEVEL {} … {}, not 0; negative levels are zstd's fast modes), lz4 or none",
                            levels.start(),
                            levels.end()
                        )
                    })?;
                Ok(Self {
                    kind: Compression::Zstd,
                    zstd_level: level,
                })
            }
        }
    }
}

/// A zone-monitor report as the `/zones` message (`ringscan.ZoneStates`).
fn zone_report_json(z: &crate::sensor::ZoneReport) -> Value {
    use std::fmt::Write as _;
    let mut hash = String::with_capacity(2 * z.zoneset_hash.len());
    for b in z.zoneset_hash {
        let _ = write!(hash, "{b:02x}");
    }
    let zones: Vec<Value> = z
        .zones
        .iter()
        .map(|s| {
            json!({
                "live": s.live,
                "id": s.id,
                "error_flags": s.error_flags,
                "trigger_type": s.trigger_type,
                "trigger_status": s.trigger_status,
                "triggered_frames": s.triggered_frames,
                "count": s.count,
                "occlusion_count": s.occlusion_count,
                "invalid_count": s.invalid_count,
                "max_count": s.max_count,
                "min_range_mm": s.min_range_mm,
                "max_range_mm": s.max_range_mm,
                "mean_range_mm": s.mean_range_mm,
            })
        })
        .collect();
    json!({
        "timestamp_ns": z.sensor_ns,
        "frame_id": z.frame_id,
        "alert_flags": z.alert_flags,
        "live_zoneset_hash": hash,
        "zones": zones,
    })
}
