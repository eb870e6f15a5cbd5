//! `decode`, `info` and `demo`: a capture or bag opened, its sensors counted, its datagrams
//! pumped through a [`Session`] (`session.rs`) and the summary built (printed by `report.rs`);
//! [`SweepReader`], the same sweep by sweep for the Python package.

use std::io::{IsTerminal, Read, Write};
use std::net::Ipv4Addr;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;

use crate::sensor::StreamError;
use crate::sink::mcap::{create_file, SinkSummary};
use crate::sink::SinkError;
use crate::source::pcap::PcapSource;
use crate::source::Datagram;
use serde_json::{json, Value};

use super::bag_args::{self as input, BagArgs, Input, InputError};
use super::report::print_text;
use super::sensors;
use super::session::{
    fields_name, output_json, sink_options_with, BufferPool, ChunkCompression, PumpError,
    ReadSweep, SensorDesc, Session, SessionOptions,
};
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

/// Everything `decode` needs.
#[derive(Debug, Clone)]
pub struct DecodeArgs {
    pub input: PathBuf,
    pub out: Option<PathBuf>,
    /// How datagrams become sweeps and messages, as for `listen`.
    pub session: SessionOptions,
    /// `--fields minimal`: x, y, z, intensity only.
    pub fields_minimal: bool,
    /// `--compression`.
    pub compression: ChunkCompression,
    /// `--threads`: MCAP chunk compression threads.
    pub threads: usize,
    /// `--chunk-size`, bytes.
    pub chunk_size: u64,
    pub strict: bool,
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
    /// `--topic`, `--start`, `--end` (bags).
    pub bag: BagArgs,
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

impl DecodeArgs {
    /// `decode`'s defaults for `input`: no output, every sensor, no range limits, the
    /// calibrations built in.
    pub fn new(input: PathBuf) -> Self {
        Self {
            input,
            out: None,
            session: SessionOptions::default(),
            fields_minimal: false,
            compression: ChunkCompression::default(),
            threads: super::default_threads(),
            chunk_size: crate::sink::mcap::DEFAULT_CHUNK_SIZE,
            strict: false,
            json: false,
            input_bytes: None,
            read_ahead: false,
            serve: Default::default(),
            serve_rate: crate::source::udp::Rate::Max,
            bag: BagArgs::default(),
        }
    }
}

/// The session of a capture or bag and its input, ready to pump: the bag's metadata added and
/// the sensors counted (topic names).
fn start_session(args: &DecodeArgs) -> Result<(Session, Capture), RunError> {
    let (mut session, mut first, mut count) = open_session(args, false)?;
    prescan(&mut first, &mut count);
    let n = count.sensors();
    if args.session.name.is_some() && n > 1 {
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
    let mut options = args.session.clone();
    // A Livox recording names its devices' model, which SDK1 packets do not.
    if options.model.is_none() {
        options.model = first.model_hint().map(str::to_string);
    }
    let mut session = Session::new(&options)?;
    if let Some(b) = first.bag() {
        add_bag_metadata(&mut session, b, &args.session.calib);
    }
    let count = SensorCount::new(session.lidar_sizes(), args.session.port);
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
        args.session.format,
        args.compression,
        args.threads,
        args.chunk_size,
        args.fields_minimal,
    );
    // `--format ros2 --out NAME` (not `.mcap`): a rosbag2 directory around one MCAP file.
    let bag_dir = args
        .out
        .as_deref()
        .filter(|p| args.session.format == FormatArg::Ros2 && crate::sink::rosbag2::is_bag_dir(p));
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
        .chain(args.session.calib.iter().map(|c| {
            let file = c.split_once('=').map_or(c.as_str(), |(_, f)| f);
            ("--calib", Path::new(file))
        }))
        .collect();
    // A bag's output is the MCAP file in its directory (INPUT may be a file there).
    let bag_file = bag_dir.map(|d| crate::sink::rosbag2::file_path(d, 0));
    let outputs: Vec<(&str, &Path)> = (bag_file.as_deref().or(args.out.as_deref()))
        .map(|p| ("--out", p))
        .into_iter()
        .chain(
            args.session
                .odometry
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
    // The live view starts before any output exists: a port it cannot bind leaves nothing.
    session.set_live(super::serve::LivePublisher::start(
        &args.serve,
        Some(args.serve_rate),
    )?);
    let bag_dir_existed = bag_dir.is_some_and(Path::exists);
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
    let sink = match (&out_path, bag_dir.zip(bag_file.as_deref())) {
        (_, Some((dir, file))) => {
            crate::sink::rosbag2::create_dir(dir).map_err(|source| SinkError::Io {
                context: format!("creating the rosbag2 directory {}", dir.display()),
                source,
            })?;
            Some(create_file(file, sink_opts.clone()).inspect_err(|_| discard_bag())?)
        }
        (Some(p), None) => Some(create_file(p, sink_opts.clone())?),
        (None, None) => None,
    };
    session.set_sink(sink);
    // The bag's MCAP is in place once the sink is closed: when its `metadata.yaml` cannot then
    // be written, the file goes too (with the yaml of the start), not left without one.
    let commit_bag = |summary: &Option<SinkSummary>| -> Result<(), SinkError> {
        let (Some(dir), Some(s)) = (bag_dir, summary) else {
            return Ok(());
        };
        let discard_file = |e| {
            if let Some(f) = bag_file.as_deref() {
                let _ = std::fs::remove_file(f);
            }
            e
        };
        let file = crate::sink::rosbag2::BagFile {
            name: crate::sink::rosbag2::file_path(dir, 0)
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            summary: s.clone(),
        };
        crate::sink::rosbag2::write_metadata(dir, &[file])
            .map_err(|source| SinkError::Io {
                context: format!("writing {}/metadata.yaml", dir.display()),
                source,
            })
            .map_err(discard_file)
    };
    let total = match args.input_bytes {
        Some(_) => None,
        None => std::fs::metadata(&args.input)
            .ok()
            .filter(|m| m.is_file())
            .map(|m| m.len()),
    };
    let pumped = pump(&mut src, &mut session, total);
    // A run that found no sensor decoded nothing: an error, as a sensor that cannot be
    // decoded is, rather than a success with an empty output. `info` reports it.
    if pumped.is_ok() && !args.session.inspect {
        if let Some(why) = session.no_sensor_reason(&src) {
            let wrote_nothing = session.chunk_stats().is_some();
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
        let kept = session.totals().0 > 0
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
                sweeps: session.totals().0,
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
            fields_name(args.session.fields_all, args.fields_minimal),
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
        self.session.use_buffer_pool(pool);
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
        session: SessionOptions {
            model: model.map(str::to_string),
            calib: calib.to_vec(),
            inspect: true,
            ..SessionOptions::default()
        },
        json: json_out,
        bag: bag.clone(),
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
