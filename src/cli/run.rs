//! `decode`, `info` and `demo`: capture → demultiplexer → streams → sink, and the summary.

use std::io::{IsTerminal, Read, Write};
use std::net::Ipv4Addr;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use crate::point::Point;
use crate::sensor::DecodeOptions;
use crate::sensor::StreamError;
use crate::sensor::{Calibration, Facts, FirstDatagram, StreamSettings};
use crate::sink::mcap::{
    create_file, Behind, Compression, Format, PointFields, SensorId, SensorInfo, SinkOptions,
    SinkSummary, SweepMsg,
};
use crate::sink::{McapSink, SinkError};
use crate::source::pcap::PcapSource;
use crate::source::Datagram;
use crate::sweep::{Demux, Sweep};
use serde_json::{json, Value};

use super::bag_args::{self as input, BagArgs, Input, InputError};
use super::odometry::{OdometryArgs, OdometryRunner};
use super::pipeline::{PipelineArgs, PipelineRunner};
use super::sensors::{self, load_calibs, Chooser};
use super::FormatArg;

/// The example capture `ringscan demo` decodes: a simulated VLP-16 made by
/// `cargo run --release --example simulate -- --model vlp16 --seconds 1 --out fixtures/demo-vlp16.pcap`.
const DEMO_PCAP: &[u8] = include_bytes!("../../fixtures/demo-vlp16.pcap");

/// Datagrams read ahead to count the sensors (for topic names) before decoding...
const PRESCAN_DATAGRAMS: usize = 4_000;
/// ... or input bytes, whichever comes first: 4,000 datagrams are 5 MB of Velodyne or Hesai
/// packets but up to 100 MB of Ouster ones, read twice (about half of a 200 MB capture).
/// 8 MiB still hold a third of a second of the largest Ouster mode, by which every sensor
/// of a recording has spoken.
const PRESCAN_BYTES: u64 = 8 << 20;
/// Raw datagrams held per sensor until it is registered (for `--raw`), at most this many
/// bytes: as many as a Robosense stream holds while it waits for its DIFOP (4,096 MSOP
/// packets), or two seconds of an OS-2-128's lidar packets. Beyond that they are counted
/// (`raw_dropped`), never dropped unseen.
const RAW_HOLD_BYTES: usize = 16 << 20;
/// Raw datagrams held over all sensors: a capture of many sources that never register (a
/// hostile one) holds no more than this.
const RAW_HOLD_TOTAL_BYTES: usize = 64 << 20;

/// Everything `decode` needs.
#[derive(Debug, Clone)]
pub struct DecodeArgs {
    pub input: PathBuf,
    pub out: Option<PathBuf>,
    pub model: Option<String>,
    pub calib: Vec<String>,
    pub name: Option<String>,
    pub port: Option<u16>,
    pub cut_angle_deg: f64,
    pub min_range: Option<f32>,
    pub max_range: Option<f32>,
    /// `--dual-return-threshold` (Hesai).
    pub dual_return_threshold_m: Option<f32>,
    /// `--fov START:END`, degrees (Hesai).
    pub fov_deg: Option<(f64, f64)>,
    /// `--integration-ms` (Livox).
    pub integration_ms: Option<f64>,
    pub fields_all: bool,
    /// `--fields minimal`: x, y, z, intensity only.
    pub fields_minimal: bool,
    /// `--compression`.
    pub compression: ChunkCompression,
    /// `--threads`: MCAP chunk compression threads.
    pub threads: usize,
    /// `--chunk-size`, bytes.
    pub chunk_size: u64,
    pub format: FormatArg,
    pub raw: bool,
    pub strict: bool,
    /// Ouster CRC check: `None` = the firmware rule.
    pub crc: Option<bool>,
    pub json: bool,
    /// Decode these bytes instead of reading `input` (the demo).
    pub input_bytes: Option<&'static [u8]>,
    /// Read a capture on a thread of its own, ahead of the decoding ([`input::open_with`]):
    /// for callers whose decoding thread has a spare core beside it (the Python package).
    pub read_ahead: bool,
    /// `--serve`: the live view.
    pub serve: super::serve::ServeArgs,
    /// `--serve-rate`: publishing speed of the live view.
    pub serve_rate: crate::source::udp::Rate,
    /// `--pipeline`, `--deskew`, `--extrinsics`.
    pub pipeline: PipelineArgs,
    /// `--odometry`, `--trajectory`, `--map-every`.
    pub odometry: OdometryArgs,
    /// `--topic`, `--start`, `--end` (bags).
    pub bag: BagArgs,
    /// Keep each point's firing column in the sweeps ([`SweepReader`]'s organised images).
    pub keep_columns: bool,
    /// `info`: read a sensor that lacks a calibration without points instead of failing
    /// ([`StreamSettings::inspect`]).
    pub inspect: bool,
}

/// Why a run failed.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// Bad command-line usage (exit code 2).
    #[error("{0}")]
    Usage(String),
    /// The capture or bag could not be read.
    #[error("{}", with_path(path, err))]
    Source { path: String, err: InputError },
    /// A calibration file could not be used.
    #[error("calibration {path}: {msg}")]
    Calib { path: String, msg: String },
    /// A sensor's stream could not be decoded; `note` names the calibration files no sensor
    /// took (the one meant for it may be among them).
    #[error("sensor {addr}: {err}{note}")]
    Stream {
        addr: Ipv4Addr,
        err: StreamError,
        note: String,
    },
    /// Writing the output failed.
    #[error("{0}")]
    Sink(#[from] SinkError),
    /// The live listener could not go on (sockets, threads, the output file), with context.
    #[error("{0}")]
    Live(String),
    /// The run finished and printed its summary, which shows it failed: `--strict` and
    /// something was lost, or a replay that sent nothing.
    #[error("{0}")]
    Reported(String),
    /// A file could not be read or written (`render`'s MCAP and PNG), with its path.
    #[error("{0}")]
    File(String),
    /// A run that failed after decoding sweeps: they were written to `out` (a valid file).
    #[error("{err}; {out} was written with the {sweeps} sweeps decoded before")]
    Kept {
        err: Box<RunError>,
        out: String,
        sweeps: u64,
    },
    /// `decode` found no sensor in its input: nothing was decoded, and nothing written.
    #[error("{path}: no sensor found: {why}{}", if *.wrote_nothing { "; nothing written" } else { "" })]
    NoSensor {
        path: String,
        why: String,
        /// An output was asked for (and not written).
        wrote_nothing: bool,
    },
}

impl RunError {
    /// The failure as `--json` prints it on stdout (a script reads it as it reads a summary):
    /// the message, the exit code, what failed and, for a run that kept a partial output, the
    /// file and its sweeps.
    pub fn json(&self, exit_code: u8) -> Value {
        let (kind, inner) = match self {
            RunError::Kept { err, .. } => (err.kind(), err.as_ref()),
            e => (e.kind(), e),
        };
        let mut m = serde_json::Map::new();
        m.insert("error".into(), json!(self.to_string()));
        m.insert("kind".into(), json!(kind));
        m.insert("exit_code".into(), json!(exit_code));
        if let RunError::NoSensor { why, .. } = inner {
            m.insert("no_sensor".into(), json!(why));
        }
        if let RunError::Kept { out, sweeps, .. } = self {
            m.insert("output".into(), json!({"path": out, "sweeps": sweeps}));
        }
        Value::Object(m)
    }

    /// What failed, in one word (`kind` of [`RunError::json`]).
    fn kind(&self) -> &'static str {
        match self {
            RunError::Usage(_) => "usage",
            RunError::Source { .. } => "input",
            RunError::Calib { .. } => "calibration",
            RunError::Stream { .. } => "sensor",
            RunError::Sink(_) => "output",
            RunError::Live(_) => "live",
            RunError::Reported(_) => "reported",
            RunError::File(_) => "file",
            RunError::Kept { err, .. } => err.kind(),
            RunError::NoSensor { .. } => "no_sensor",
        }
    }
}

/// `path: err`, without the path twice where the error names it first (the bag readers'
/// errors do).
fn with_path(path: &str, err: &InputError) -> String {
    let e = err.to_string();
    if e.starts_with(&format!("{path}: ")) {
        e
    } else {
        format!("{path}: {e}")
    }
}

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
/// first of a single sensor.
fn topic_prefix(n_sensors: usize, idx: usize, name: &str) -> String {
    if n_sensors <= 1 && idx == 0 {
        String::new()
    } else {
        format!("/{name}")
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
    /// A copy of every decoded sweep (before the pipeline), for [`SweepReader`].
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
        let topic_prefix = topic_prefix(self.n_sensors_hint, idx, &name);
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

/// Summary of a decode run, the `--json` object.
pub struct Summary {
    pub json: Value,
    pub lost: u64,
}

/// Counts the sensors of an input from its first datagrams (at most [`PRESCAN_DATAGRAMS`],
/// within its first [`PRESCAN_BYTES`]): the sources of datagrams of a main-stream size (and
/// port, if given). The count decides the topic names.
struct SensorCount {
    sizes: Vec<usize>,
    port: Option<u16>,
    addrs: Vec<Ipv4Addr>,
    seen: usize,
}

impl SensorCount {
    fn new(sizes: Vec<usize>, port: Option<u16>) -> Self {
        Self {
            sizes,
            port,
            addrs: Vec::new(),
            seen: 0,
        }
    }

    /// Whether the next datagram, read from input offset `bytes`, is still counted.
    fn counts_next(&self, bytes: u64) -> bool {
        self.seen < PRESCAN_DATAGRAMS && bytes <= PRESCAN_BYTES
    }

    fn see(&mut self, d: &Datagram<'_>) {
        self.seen += 1;
        if (self.sizes.contains(&d.payload.len())
            || crate::sensor::FAMILIES
                .iter()
                .any(|f| f.is_header_sized_lidar(d.payload)))
            && self.port.is_none_or(|p| p == d.dst.port())
            && !self.addrs.contains(d.src.ip())
        {
            self.addrs.push(*d.src.ip());
        }
    }

    fn sensors(&self) -> usize {
        self.addrs.len()
    }
}

/// Counts the sensors of `src` by reading its first datagrams; an error ends the count (the
/// decoding, reading the input again, meets it where it is).
fn prescan<R: Read>(src: &mut Input<R>, count: &mut SensorCount) {
    while count.counts_next(src.bytes()) {
        match src.next_datagram() {
            Ok(Some(d)) => count.see(&d),
            Ok(None) | Err(_) => break,
        }
    }
}

/// Settings of a [`Session`], whatever the datagrams come from.
#[derive(Debug, Clone)]
pub struct SessionOptions {
    pub model: Option<String>,
    pub calib: Vec<String>,
    pub name: Option<String>,
    pub port: Option<u16>,
    pub cut_angle_deg: f64,
    pub min_range: Option<f32>,
    pub max_range: Option<f32>,
    pub dual_return_threshold_m: Option<f32>,
    pub fov_deg: Option<(f64, f64)>,
    /// `--integration-ms` (Livox).
    pub integration_ms: Option<f64>,
    pub fields_all: bool,
    pub raw: bool,
    pub crc: Option<bool>,
    /// `--pipeline`, `--deskew`, `--extrinsics`.
    pub pipeline: PipelineArgs,
    /// Points message layout (the pipeline's outputs need `foxglove`).
    pub format: FormatArg,
    /// `--odometry`, `--trajectory`, `--map-every`.
    pub odometry: OdometryArgs,
    /// Keep each point's firing column in the sweeps (organised images, [`SweepReader`]).
    pub keep_columns: bool,
    /// Only inspecting (`info`): [`StreamSettings::inspect`].
    pub inspect: bool,
}

impl DecodeArgs {
    /// `decode`'s defaults for `input`: no output, every sensor, no range limits, the
    /// calibrations built in.
    pub fn new(input: PathBuf) -> Self {
        Self {
            input,
            out: None,
            model: None,
            calib: Vec::new(),
            name: None,
            port: None,
            cut_angle_deg: 0.0,
            min_range: None,
            max_range: None,
            dual_return_threshold_m: None,
            fov_deg: None,
            integration_ms: None,
            fields_all: false,
            fields_minimal: false,
            compression: ChunkCompression::default(),
            threads: super::default_threads(),
            chunk_size: crate::sink::mcap::DEFAULT_CHUNK_SIZE,
            format: FormatArg::Foxglove,
            raw: false,
            strict: false,
            crc: None,
            json: false,
            input_bytes: None,
            read_ahead: false,
            pipeline: PipelineArgs::default(),
            odometry: OdometryArgs::default(),
            serve: Default::default(),
            serve_rate: crate::source::udp::Rate::Max,
            bag: BagArgs::default(),
            keep_columns: false,
            inspect: false,
        }
    }

    /// The options of the [`Session`] this run uses.
    pub fn session_options(&self) -> SessionOptions {
        SessionOptions {
            model: self.model.clone(),
            calib: self.calib.clone(),
            name: self.name.clone(),
            port: self.port,
            cut_angle_deg: self.cut_angle_deg,
            min_range: self.min_range,
            max_range: self.max_range,
            dual_return_threshold_m: self.dual_return_threshold_m,
            fov_deg: self.fov_deg,
            integration_ms: self.integration_ms,
            fields_all: self.fields_all,
            raw: self.raw,
            crc: self.crc,
            pipeline: self.pipeline.clone(),
            format: self.format,
            odometry: self.odometry.clone(),
            keep_columns: self.keep_columns,
            inspect: self.inspect,
        }
    }
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
    /// registered without an output (a [`SweepReader`] counts while it decodes) take the
    /// topics the count gives; with an output, topics are written once and stay.
    pub fn set_sensor_hint(&mut self, n: usize) {
        self.out.n_sensors_hint = n;
        if self.out.sink.is_none() {
            for (idx, s) in self.out.sensors.iter_mut().enumerate() {
                if let Some(info) = s.info.as_mut() {
                    info.topic_prefix = topic_prefix(n, idx, &s.name);
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
    pub fn rotate(&mut self, next: Sink) -> Result<Option<SinkSummary>, SinkError> {
        let old = self.out.sink.replace(next);
        let closed = match old {
            Some(s) => Some(s.finish()?),
            None => None,
        };
        let sink = self.out.sink.as_mut().ok_or_else(|| SinkError::Io {
            context: "rotating the output".into(),
            source: std::io::Error::other("no output"),
        })?;
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

/// The session of a capture or bag and its input, ready to pump: the bag's metadata added and
/// the sensors counted (topic names).
fn start_session(args: &DecodeArgs) -> Result<(Session, Capture), RunError> {
    let (mut session, mut first, mut count) = open_session(args, false)?;
    prescan(&mut first, &mut count);
    let n = count.sensors();
    if args.name.is_some() && n > 1 {
        return Err(RunError::Usage(format!(
            "--name: the capture holds {n} sensors; names are given per sensor automatically"
        )));
    }
    session.set_sensor_hint(n);
    // The topics are named before anything is written: the input is read again from the
    // start.
    drop(first);
    Ok((session, open_input(args, args.read_ahead)?))
}

/// An opened input, as the decoding reads it.
type Capture = Input<Box<dyn Read>>;

fn open_input(args: &DecodeArgs, read_ahead: bool) -> Result<Capture, RunError> {
    match args.input_bytes {
        Some(b) => Ok(Input::Pcap(Box::new(
            PcapSource::new(Box::new(b) as Box<dyn Read>).map_err(|err| RunError::Source {
                path: args.input.display().to_string(),
                err: err.into(),
            })?,
        ))),
        None => input::open_with(&args.input, &args.bag, read_ahead),
    }
}

/// The input opened (read ahead if `read_ahead` and the options ask for it), its session (the
/// bag's metadata added), and a sensor count not yet started.
fn open_session(
    args: &DecodeArgs,
    read_ahead: bool,
) -> Result<(Session, Capture, SensorCount), RunError> {
    let first = open_input(args, read_ahead && args.read_ahead)?;
    let mut options = args.session_options();
    // A Livox recording names its devices' model, which SDK1 packets do not.
    if options.model.is_none() {
        options.model = first.model_hint().map(str::to_string);
    }
    let mut session = Session::new(&options)?;
    if let Some(b) = first.bag() {
        add_bag_metadata(&mut session, b, &args.calib);
    }
    let count = SensorCount::new(session.lidar_sizes(), args.port);
    Ok((session, first, count))
}

/// The `--json` summary of a finished run, and the packets lost.
fn summary_json(
    session: &Session,
    src: &Input<Box<dyn Read>>,
    path: &str,
    output: Value,
    elapsed_s: f64,
) -> Summary {
    let (mut m, lost) = session.summary();
    if let Some(why) = session.no_sensor_reason(src) {
        m.insert("no_sensor".into(), json!(why));
    }
    // A `--topic` the bag does not have, beside ones it has, selected nothing (a typo).
    if let Some(b) = src.bag() {
        let unknown = b.topics_unknown();
        if !unknown.is_empty() {
            if let Some(Value::Array(u)) = m.get_mut("unused_options") {
                u.push(json!(format!(
                    "--topic {}: the bag has no such topic (the other --topic values were read)",
                    unknown.join(" --topic ")
                )));
            }
        }
    }
    m.insert("input".into(), json!(path));
    m.insert("capture".into(), src.capture_json());
    m.insert("output".into(), output);
    m.insert("elapsed_s".into(), json!(elapsed_s));
    Summary {
        json: Value::Object(m),
        lost,
    }
}

/// Runs a decode: the library entry of `ringscan decode` (and of `info` with no output).
pub fn decode_capture(args: &DecodeArgs) -> Result<Summary, RunError> {
    let started = Instant::now();
    let path_s = args.input.display().to_string();
    let sink_opts = sink_options_with(
        args.format,
        args.compression,
        args.threads,
        args.chunk_size,
        args.fields_minimal,
    );
    // `--format ros2 --out NAME` (not `.mcap`): a rosbag2 directory around one MCAP file.
    let bag_dir = args
        .out
        .as_deref()
        .filter(|p| args.format == FormatArg::Ros2 && crate::sink::rosbag2::is_bag_dir(p));
    let out_path = match (&args.out, bag_dir) {
        // `demo` has no output-less run to advise.
        (Some(p), None) => Some(output_file_path(
            p,
            if args.input_bytes.is_some() {
                "demo's MCAP"
            } else {
                "MCAP"
            },
        )?),
        _ => None,
    };
    // A bag is never overwritten: refused as the other unusable --out paths are, before
    // anything is decoded.
    if let Some(dir) = bag_dir.filter(|d| d.join("metadata.yaml").exists()) {
        return Err(RunError::Usage(format!(
            "--out {}: already holds a rosbag2 (metadata.yaml); choose another --out",
            dir.display()
        )));
    }
    if let Some(dir) = bag_dir.filter(|d| d.exists() && !d.is_dir()) {
        return Err(RunError::Usage(format!(
            "--out {}: --format ros2 writes a rosbag2 directory there, and it is a file (a name \
             ending in .mcap writes one MCAP file instead)",
            dir.display()
        )));
    }
    if let Some(dir) = bag_dir {
        out_dir_exists(dir)?;
    }
    // An output over a file this run reads would destroy it (the rename replaces it at the
    // end, or the trajectory is written over it as the run goes): refused before anything.
    let inputs: Vec<(&str, &Path)> = std::iter::once(("INPUT", args.input.as_path()))
        .chain(args.calib.iter().map(|c| {
            let file = c.split_once('=').map_or(c.as_str(), |(_, f)| f);
            ("--calib", Path::new(file))
        }))
        .collect();
    let outputs: Vec<(&str, &Path)> = (args.out.as_deref().filter(|_| bag_dir.is_none()))
        .map(|p| ("--out", p))
        .into_iter()
        .chain(
            args.odometry
                .trajectory
                .as_deref()
                .map(|p| ("--trajectory", p)),
        )
        .collect();
    for (i, (what, out)) in outputs.iter().enumerate() {
        let clash = |(other, path): &(&str, &Path), why: &str| {
            (same_file(out, path) || *out == *path).then(|| {
                RunError::Usage(format!(
                    "{what} {}: the same file as {other} {}; {why}",
                    out.display(),
                    path.display()
                ))
            })
        };
        let read = inputs
            .iter()
            .find_map(|x| clash(x, "writing it would destroy what is read"));
        let written = outputs[..i]
            .iter()
            .find_map(|x| clash(x, "one would overwrite the other"));
        if let Some(e) = read.or(written) {
            return Err(e);
        }
    }
    let (mut session, mut src) = start_session(args)?;
    let bag_dir_existed = bag_dir.is_some_and(Path::exists);
    let sink = match (&out_path, bag_dir) {
        (_, Some(dir)) => {
            crate::sink::rosbag2::create_dir(dir).map_err(|source| SinkError::Io {
                context: format!("creating the rosbag2 directory {}", dir.display()),
                source,
            })?;
            Some(create_file(
                &crate::sink::rosbag2::file_path(dir, 0),
                sink_opts.clone(),
            )?)
        }
        (Some(p), None) => Some(create_file(p, sink_opts.clone())?),
        (None, None) => None,
    };
    session.set_sink(sink);
    let commit_bag = |summary: &Option<SinkSummary>| -> Result<(), SinkError> {
        let (Some(dir), Some(s)) = (bag_dir, summary) else {
            return Ok(());
        };
        let file = crate::sink::rosbag2::BagFile {
            name: crate::sink::rosbag2::file_path(dir, 0)
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            summary: s.clone(),
        };
        crate::sink::rosbag2::write_metadata(dir, &[file]).map_err(|source| SinkError::Io {
            context: format!("writing {}/metadata.yaml", dir.display()),
            source,
        })
    };
    session.set_live(super::serve::LivePublisher::start(
        &args.serve,
        Some(args.serve_rate),
    )?);
    let total = match args.input_bytes {
        Some(_) => None,
        None => std::fs::metadata(&args.input)
            .ok()
            .filter(|m| m.is_file())
            .map(|m| m.len()),
    };
    // On an error, the output is finalised (a valid MCAP) if it holds a sweep: what was
    // decoded before the damage. An output without one is not written, so a run that could
    // not decode leaves no empty file, and leaves a file already at the path as it was.
    // A bag whose MCAP could not be finished loses the empty `metadata.yaml` written at its
    // start (and the directory, if this run made it), so the failed run leaves nothing that
    // looks like a bag and stops the next run into the same --out.
    let discard_bag = || {
        if let Some(dir) = bag_dir {
            let _ = std::fs::remove_file(dir.join("metadata.yaml"));
            if !bag_dir_existed {
                let _ = std::fs::remove_dir(dir);
            }
        }
    };
    let pumped = pump(&mut src, &mut session, total);
    // A run that found no sensor decoded nothing: an error, as a sensor that cannot be
    // decoded is, rather than a success with an empty output. `info` reports it.
    if pumped.is_ok() && !args.inspect {
        if let Some(why) = session.no_sensor_reason(&src) {
            let wrote_nothing = session.out.sink.is_some();
            session.abort_sink();
            discard_bag();
            return Err(RunError::NoSensor {
                path: path_s,
                why,
                wrote_nothing,
            });
        }
    }
    if let Err(e) = pumped {
        let kept = session.out.sweeps > 0
            && match session.close_sink() {
                Ok(s) => commit_bag(&s).is_ok(),
                Err(_) => false,
            };
        if !kept {
            session.abort_sink();
            discard_bag();
        }
        let err = naming_output(
            session.run_error(e, &path_s),
            out_path.as_deref().or(bag_dir),
        );
        return Err(match (&args.out, kept) {
            // The user is told that a file was written after all, and what it holds.
            (Some(out), true) => RunError::Kept {
                err: Box::new(err),
                out: out.display().to_string(),
                sweeps: session.out.sweeps,
            },
            _ => err,
        });
    }
    let sink_summary = match session
        .close_sink()
        .and_then(|s| commit_bag(&s).map(|()| s))
    {
        Ok(s) => s,
        Err(e) => {
            discard_bag();
            return Err(naming_output(e.into(), out_path.as_deref().or(bag_dir)));
        }
    };
    session.finish_odometry()?;
    let output = match &sink_summary {
        Some(s) => output_json(
            s,
            args.out.as_deref(),
            &sink_opts,
            fields_name(args.fields_all, args.fields_minimal),
        ),
        None => Value::Null,
    };
    Ok(summary_json(
        &session,
        &src,
        &path_s,
        output,
        started.elapsed().as_secs_f64(),
    ))
}

/// An output error that names the file it failed on: the sink's own errors say what it was
/// doing (`writing an MCAP chunk`), not where, and a disk that filled up should say which file.
fn naming_output(e: RunError, out: Option<&Path>) -> RunError {
    match (e, out) {
        (RunError::Sink(SinkError::Io { context, source }), Some(out))
            if !context.contains(&*out.to_string_lossy()) =>
        {
            RunError::Sink(SinkError::Io {
                context: format!("{}: {context}", out.display()),
                source,
            })
        }
        (e, _) => e,
    }
}

/// A decoded sweep handed out by [`SweepReader`], with the index of its sensor.
pub struct ReadSweep {
    /// The sensor's index (order of first appearance).
    pub sensor: usize,
    /// The sweep as the stream cut it (no pipeline).
    pub sweep: Sweep,
}

/// What a [`SweepReader`] knows of a sensor.
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

/// A capture or bag read sweep by sweep: the same session as `decode` (sensor detection,
/// calibrations, the bag's metadata), without an output; the Python package's `open`.
pub struct SweepReader {
    src: Input<Box<dyn Read>>,
    /// The sensors counted while the first datagrams are decoded (`decode` counts them
    /// before, reading them twice: it names its topics before writing; here they are only
    /// the summary's, named again once the count is known).
    count: Option<SensorCount>,
    session: Session,
    path: String,
    queue: std::collections::VecDeque<ReadSweep>,
    finished: bool,
    started: Instant,
}

impl SweepReader {
    /// Opens `args.input` (or `args.input_bytes`) with `args`' decoding options; `out`, the
    /// pipeline and odometry options are not used.
    pub fn open(args: &DecodeArgs) -> Result<Self, RunError> {
        let (mut session, src, count) = open_session(args, true)?;
        session.enable_tap();
        Ok(Self {
            src,
            count: Some(count),
            session,
            path: args.input.display().to_string(),
            queue: std::collections::VecDeque::new(),
            finished: false,
            started: Instant::now(),
        })
    }

    /// Takes the buffers of the sweeps it hands out from `pool`, where their consumer gives
    /// them back (see [`BufferPool`]).
    pub fn use_buffer_pool(&mut self, pool: Arc<BufferPool>) {
        self.session.out.pool = Some(pool);
    }

    /// The next sweep of any sensor, in the order the streams finish them; `None` at the end.
    pub fn next_sweep(&mut self) -> Result<Option<ReadSweep>, RunError> {
        loop {
            if let Some(s) = self.queue.pop_front() {
                return Ok(Some(s));
            }
            if self.finished {
                return Ok(None);
            }
            let counting = self
                .count
                .as_ref()
                .is_some_and(|c| c.counts_next(self.src.bytes()));
            let next = self.src.next_datagram();
            match (&next, self.count.as_mut()) {
                (Ok(Some(d)), Some(c)) if counting => c.see(d),
                (_, Some(c)) => {
                    self.session.set_sensor_hint(c.sensors());
                    self.count = None;
                }
                _ => {}
            }
            let pumped = match next {
                Ok(Some(d)) => self.session.push(d.time_ns, d.src, d.dst.port(), d.payload),
                Ok(None) => {
                    self.finished = true;
                    self.session.finish_streams()
                }
                Err(e) => Err(PumpError::Source(e)),
            };
            if let Err(e) = pumped {
                self.finished = true;
                return Err(self.session.run_error(e, &self.path));
            }
            self.queue.extend(self.session.take_sweeps());
        }
    }

    /// The sensor of index `idx`, once seen.
    pub fn sensor(&self, idx: usize) -> Option<SensorDesc> {
        self.session.sensor_desc(idx)
    }

    /// The `--json` summary so far (complete once [`Self::next_sweep`] returned `None`).
    pub fn summary(&self) -> Summary {
        summary_json(
            &self.session,
            &self.src,
            &self.path,
            Value::Null,
            self.started.elapsed().as_secs_f64(),
        )
    }
}

/// A bag's Ouster metadata configures its sensor unless `--calib` binds a file to that
/// sensor's address; an unbound `--calib` metadata that fits the sensor is matched first.
/// Without any `--calib`, the calibration files attached to a bag's MCAP (as ringscan attaches
/// the files it decoded with) serve its sensors, each matched as an unbound `--calib` file is.
fn add_bag_metadata(session: &mut Session, bag: &crate::source::bag::BagSource, calib: &[String]) {
    if calib.is_empty() {
        for (name, bytes) in bag.attachments() {
            match sensors::calibration(bytes, name, None) {
                Ok(spec) => {
                    tracing::info!("{name}: the calibration attached to the bag is used");
                    session.add_attached_calib(spec);
                }
                Err(e) => tracing::debug!("attachment {name}: not a calibration: {e}"),
            }
        }
    }
    for s in bag.sensors() {
        let Some(text) = &s.metadata else { continue };
        let bound = calib.iter().any(|c| {
            c.split_once('=')
                .and_then(|(a, _)| a.parse::<Ipv4Addr>().ok())
                == Some(s.address)
        });
        if bound {
            continue;
        }
        let ns = s.namespace.trim_matches('/').replace('/', "_");
        let name = if ns.is_empty() {
            "metadata.json".to_string()
        } else {
            format!("{ns}.metadata.json")
        };
        // The bag's own, as its attachments are: not the user's to be told of when a file
        // attached beside it served instead.
        match sensors::calibration(text.as_bytes(), &name, Some(s.address)) {
            Ok(spec) => session.add_attached_calib(spec),
            Err(e) => tracing::warn!("{}: the bag's metadata is not used: {e}", s.namespace),
        }
    }
}

fn pump<R: Read>(
    src: &mut Input<R>,
    session: &mut Session,
    total_bytes: Option<u64>,
) -> Result<(), PumpError> {
    let progress = total_bytes.is_some() && std::io::stderr().is_terminal();
    let mut last_progress = Instant::now();
    loop {
        let d = match src.next_datagram() {
            Ok(Some(d)) => d,
            Ok(None) => break,
            Err(e) => return Err(PumpError::Source(e)),
        };
        session.push(d.time_ns, d.src, d.dst.port(), d.payload)?;
        if progress && last_progress.elapsed().as_millis() >= 500 {
            last_progress = Instant::now();
            let done = src.bytes();
            let total = total_bytes.unwrap_or(1).max(1);
            let (sweeps, points) = session.totals();
            eprint!(
                "\r{:5.1} % · {} sweeps · {} points",
                100.0 * done as f64 / total as f64,
                sweeps,
                points
            );
            let _ = std::io::stderr().flush();
        }
    }
    session.finish_streams()?;
    if progress {
        eprintln!();
    }
    Ok(())
}

/// `ringscan decode`.
pub fn decode_command(args: &DecodeArgs) -> Result<ExitCode, RunError> {
    let s = decode_capture(args)?;
    if args.json {
        outln!("{}", s.json);
    } else {
        print_text(&s.json);
    }
    if args.strict && s.lost > 0 {
        return Err(RunError::Reported(format!(
            "--strict: {} packets missing, dropped or malformed",
            s.lost
        )));
    }
    // An input cut short lost its tail, which no packet counter sees.
    if let Some(at) = s.json["capture"]["truncated_tail_offset"]
        .as_u64()
        .filter(|_| args.strict)
    {
        return Err(RunError::Reported(format!(
            "--strict: the input is cut short at byte {at} (its last record is incomplete)"
        )));
    }
    Ok(ExitCode::SUCCESS)
}

/// The file `decode --out` writes: `path`, or the regular file a symbolic link names. The
/// output is written beside it and renamed over it at the end, so a path that is not a regular
/// file is refused before anything is decoded: renaming over a device (`/dev/null`) or a
/// directory would replace it.
pub(crate) fn output_file_path(path: &Path, kind: &str) -> Result<PathBuf, RunError> {
    let refuse = |what: &str| {
        RunError::Usage(format!(
            "--out {}: {what} (ringscan writes the {kind} beside it and renames it into place); \
             give a file path{}",
            path.display(),
            if kind == "MCAP" {
                ", or leave out --out to decode without writing"
            } else {
                ""
            }
        ))
    };
    let meta = match std::fs::symlink_metadata(path) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            // Said now, not as a failure to create the temporary file beside it.
            out_dir_exists(path)?;
            return Ok(path.to_path_buf());
        }
        Err(e) => return Err(refuse(&format!("cannot be inspected ({e})"))),
    };
    let ft = meta.file_type();
    if ft.is_file() {
        Ok(path.to_path_buf())
    } else if ft.is_symlink() {
        match std::fs::metadata(path) {
            Ok(t) if t.is_file() => std::fs::canonicalize(path)
                .map_err(|e| refuse(&format!("a symbolic link that cannot be resolved ({e})"))),
            Ok(_) => Err(refuse("a symbolic link to something that is not a file")),
            Err(_) => Err(refuse("a symbolic link to nothing")),
        }
    } else if ft.is_dir() {
        Err(refuse("a directory, not a file"))
    } else {
        Err(refuse("a device, pipe or socket, not a file"))
    }
}

/// Whether `a` and `b` name one existing file (through links, `.` and `..` alike).
pub(crate) fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// Refuses an `--out` whose directory does not exist (bad usage, named before any work)
/// rather than failing on the first file created there.
pub(crate) fn out_dir_exists(path: &Path) -> Result<(), RunError> {
    match path.parent().filter(|d| !d.as_os_str().is_empty()) {
        Some(d) if !d.is_dir() => Err(RunError::Usage(format!(
            "--out {}: its directory {} does not exist; create it first",
            path.display(),
            d.display()
        ))),
        _ => Ok(()),
    }
}

/// `ringscan info`.
pub fn info_command(
    input: &Path,
    model: Option<&str>,
    calib: &[String],
    bag: &BagArgs,
    json_out: bool,
) -> Result<ExitCode, RunError> {
    let args = DecodeArgs {
        model: model.map(str::to_string),
        calib: calib.to_vec(),
        json: json_out,
        bag: bag.clone(),
        inspect: true,
        ..DecodeArgs::new(input.to_path_buf())
    };
    let s = decode_capture(&args)?;
    if json_out {
        outln!("{}", s.json);
    } else {
        print_text(&s.json);
    }
    Ok(ExitCode::SUCCESS)
}

/// `ringscan demo`.
pub fn demo_command(out: &Path, json_out: bool) -> Result<ExitCode, RunError> {
    let args = DecodeArgs {
        out: Some(out.to_path_buf()),
        json: json_out,
        input_bytes: Some(DEMO_PCAP),
        ..DecodeArgs::new(PathBuf::from("fixtures/demo-vlp16.pcap (built in)"))
    };
    let s = decode_capture(&args)?;
    if json_out {
        outln!("{}", s.json);
    } else {
        print_text(&s.json);
        outln!(
            "Open {} in Foxglove (https://app.foxglove.dev) to see the point clouds.",
            out.display()
        );
    }
    Ok(ExitCode::SUCCESS)
}

fn print_text(j: &Value) {
    let g = |v: &Value| v.as_u64().unwrap_or(0);
    let c = &j["capture"];
    outln!("{}", j["input"].as_str().unwrap_or(""));
    outln!(
        "  capture: {} records, {} UDP datagrams ({} reassembled from fragments), {:.3} s{}",
        g(&c["records"]),
        g(&c["datagrams"]),
        g(&c["reassembled"]),
        c["duration_s"].as_f64().unwrap_or(0.0),
        match c["truncated_tail_offset"].as_u64() {
            Some(o) => format!(", last record truncated at byte {o}"),
            None => String::new(),
        }
    );
    if let Some(b) = c["bag"].as_object() {
        outln!(
            "  bag ({}): {} messages, {} with packets; unknown types {}, malformed {}, other topics {}, outside the time window {}",
            b["kind"].as_str().unwrap_or(""),
            g(&b["messages"]),
            g(&b["packet_messages"]),
            g(&b["unknown_type"]),
            g(&b["malformed"]),
            g(&b["unselected"]),
            g(&b["outside_time"])
        );
        for s in b["sensors"].as_array().into_iter().flatten() {
            outln!(
                "    {} ({}) as {}, ports {}/{}: {}{}",
                s["namespace"].as_str().unwrap_or(""),
                s["family"].as_str().unwrap_or(""),
                s["address"].as_str().unwrap_or(""),
                s["data_port"],
                s["aux_port"],
                s["topics"],
                if s["metadata_in_bag"] == true {
                    ", metadata in the bag"
                } else {
                    ""
                }
            );
        }
    }
    for s in j["sensors"].as_array().into_iter().flatten() {
        let kind = s["kind"].as_str().unwrap_or("");
        let Some(family) = crate::sensor::family(kind) else {
            outln!("  sensor of an unknown kind {kind:?}: {s}");
            continue;
        };
        if s["ports"].as_array().is_some_and(|p| p.is_empty()) {
            // Recognised, but every datagram of its went to another port than --port.
            outln!(
                "  {}: {kind}, no datagram decoded (none to --port)",
                crate::sensor::heading(s)
            );
            continue;
        }
        for line in family.describe(s) {
            outln!("{line}");
        }
    }
    if let Some(why) = j["no_sensor"].as_str() {
        outln!("  no sensor found: {why}");
    }
    let p = &j["packets"];
    print_warnings(j);
    outln!(
        "  total: {} sweeps, {} points; packets decoded {}, dropped {}, malformed {}, missing {}, ignored {}",
        g(&j["sweeps"]),
        g(&j["points"]),
        g(&p["decoded"]),
        g(&p["dropped"]),
        g(&p["malformed"]),
        g(&p["missing"]),
        g(&p["ignored"])
    );
    if let Some(n) = p["other_port"].as_u64().filter(|&n| n > 0) {
        outln!("  {n} data packets went to other ports than --port: dropped, not decoded");
    }
    if let Some(o) = j["output"].as_object() {
        outln!(
            "  wrote {} ({}): {}",
            o["path"].as_str().unwrap_or(""),
            o["format"].as_str().unwrap_or(""),
            o["topics"]
        );
        let held_over: u64 = j["sensors"].as_array().map_or(0, |a| {
            a.iter().filter_map(|s| s["raw_dropped"].as_u64()).sum()
        });
        let not_written = o["raw_dropped"].as_u64().unwrap_or(0) + held_over;
        if let Some(n) = Some(not_written).filter(|&n| n > 0) {
            outln!(
                "  {n} raw packets not written (output.raw_dropped: no ROS 2 packet message \
                 of their family holds them, --format foxglove keeps them on /raw; \
                 sensors[].raw_dropped: more than 16 MiB arrived before the sensor was known)"
            );
        }
    }
    outln!("  {:.3} s", j["elapsed_s"].as_f64().unwrap_or(0.0));
}

/// The text summary's warnings (`decode`, `info`, `listen`): calibrations and options no
/// sensor used, sweeps left unskewed.
pub(crate) fn print_warnings(j: &Value) {
    for name in j["unused_calibrations"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(Value::as_str)
    {
        outln!(
            "  warning: calibration {name} was used by no sensor: it fits none of the sensors \
             found (family, model, laser count, serial or address)"
        );
    }
    for w in (j["warnings"].as_array().into_iter().flatten()).filter_map(Value::as_str) {
        outln!("  warning: {w}");
    }
    for w in j["unused_options"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(Value::as_str)
    {
        outln!("  warning: {w}");
    }
    let names: Vec<&str> = (j["sensors"].as_array().into_iter().flatten())
        .filter_map(|s| s["name"].as_str())
        .collect();
    for n in (j["pipeline"]["extrinsics_unused"]
        .as_array()
        .into_iter()
        .flatten())
    .filter_map(Value::as_str)
    {
        outln!(
            "  warning: --extrinsics {n}=…: no sensor of that name (sensor names: {}); not applied",
            names.join(", ")
        );
    }
    // What a family found wrong with a sensor's data or its calibration.
    for s in j["sensors"].as_array().into_iter().flatten() {
        for w in (s["warnings"].as_array().into_iter().flatten()).filter_map(Value::as_str) {
            outln!("  warning: {}: {w}", crate::sensor::heading(s));
        }
    }
    // A --model the packets contradict (a family that can tell says so in its summary).
    for s in j["sensors"].as_array().into_iter().flatten() {
        if let Some(seen) = s["model_contradicted"].as_str() {
            outln!(
                "  warning: sensor {}: --model {}, though the packets say {seen}; its points are \
                 likely wrong",
                s["address"].as_str().unwrap_or(""),
                s["model_id"].as_str().unwrap_or("")
            );
        }
    }
    if let Some(n) = j["pipeline"]["deskew_skipped"].as_u64().filter(|&n| n > 0) {
        let why = j["pipeline"]["sensors"]
            .as_array()
            .into_iter()
            .flatten()
            .find_map(|s| s["deskew_last_error"].as_str())
            .unwrap_or("");
        outln!("  warning: deskew skipped on {n} sweeps (kept as measured): {why}");
    }
    if let Some(n) = j["pipeline"]["counts"]["voxel_skipped"]
        .as_u64()
        .filter(|&n| n > 0)
    {
        let leaf = j["pipeline"]["parameters"]["voxel.leaf_m"]
            .as_f64()
            .unwrap_or(0.0);
        outln!(
            "  warning: the voxel grid left out {n} points beyond ±2^20 leaves of {leaf} m ({:.1} m) from the origin; raise voxel.leaf_m",
            leaf * f64::from(1u32 << 20)
        );
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
