//! `ringscan listen`: sensors on the network → the same [`Session`] as `decode` → MCAP.
//!
//! Threads: the main thread runs a single-threaded tokio runtime with one receive task per
//! port, the signal handlers, the status line and the Ouster metadata fetches; one decode
//! thread owns the [`Session`] (demultiplexer, streams, MCAP sink). Between them a bounded
//! queue with a byte budget: the receive side never waits for the decode thread or the disk;
//! what does not fit is dropped and counted.

use std::collections::{BTreeSet, HashMap};
use std::io::{IsTerminal, Write};
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::sensor::livox::model::ALL_MODELS;
use crate::sensor::livox::LivoxModel;
use crate::sensor::ouster::family::OusterCalibration;
use crate::sensor::ouster::OusterStream;
use crate::sensor::{Calibration, FAMILIES};
use crate::sink::mcap::{Behind, SinkOptions, SinkSummary};
use crate::sink::rosbag2::BagFile;
use crate::sink::{McapSink, SinkError};
use crate::source::udp::{self, BoundSocket, Queue, ReceiveStats, Received, SocketOptions};
use serde_json::{json, Value};

use super::run::RunError;
use super::sensors::load_calibs;
use super::session::{
    fields_name, output_json, sink_options_with, ChunkCompression, ReadSweep, SensorDesc, Session,
    SessionOptions, Sink,
};
use super::FormatArg;

/// The Ouster HTTP API path of the sensor metadata.
pub const METADATA_PATH: &str = "/api/v1/sensor/metadata";
/// Datagrams the queue between the receive tasks and the decode thread holds at most.
pub const QUEUE_DATAGRAMS: usize = 65_536;
/// Payload bytes the queue holds at most (memory stays bounded under a flood).
pub const QUEUE_BYTES: usize = 128 << 20;
/// Time between two metadata requests to one sensor.
const FETCH_RETRY: Duration = Duration::from_secs(5);
/// Payload bytes held, over all sensors, while their metadata is fetched (the oldest go first
/// beyond it: 16 MiB is about 2.5 s of an OS-2-128 at 2048 × 10).
pub const HOLD_BYTES: usize = 16 << 20;

/// When `--split-every` starts a new file.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Split {
    /// Every so many seconds.
    Seconds(f64),
    /// Once the file holds so many bytes.
    Bytes(u64),
}

/// Parses `--split-every`: `S`, `Ss` (seconds) or `NMB` / `NM` (megabytes, 10^6 bytes).
pub fn parse_split(s: &str) -> Result<Split, String> {
    let t = s.trim();
    let lower = t.to_ascii_lowercase();
    let num = |x: &str| {
        x.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v > 0.0)
            .ok_or_else(|| format!("`{s}`: expected seconds (`60`, `60s`) or megabytes (`500MB`)"))
    };
    if let Some(m) = lower.strip_suffix("mb").or_else(|| lower.strip_suffix('m')) {
        return Ok(Split::Bytes((num(m)? * 1e6) as u64));
    }
    let secs = lower.strip_suffix('s').unwrap_or(&lower);
    Ok(Split::Seconds(num(secs)?))
}

/// Parses `--sensor IP[:PORT]`.
pub fn parse_sensor(s: &str) -> Result<(Ipv4Addr, Option<u16>), String> {
    if let Ok(a) = s.parse::<SocketAddrV4>() {
        return Ok((*a.ip(), Some(a.port())));
    }
    s.parse::<Ipv4Addr>()
        .map(|ip| (ip, None))
        .map_err(|_| format!("`{s}`: expected IPv4[:PORT]"))
}

/// Everything `listen` needs.
#[derive(Debug, Clone)]
pub struct ListenArgs {
    pub sensors: Vec<(Ipv4Addr, Option<u16>)>,
    pub out: Option<PathBuf>,
    pub split_every: Option<Split>,
    /// How datagrams become sweeps and messages, as for `decode`.
    pub session: SessionOptions,
    /// `--fields minimal`.
    pub fields_minimal: bool,
    /// `--threads`: MCAP chunk compression threads.
    pub threads: usize,
    /// `--chunk-size`, bytes.
    pub chunk_size: u64,
    pub multicast: Option<Ipv4Addr>,
    pub interface: Ipv4Addr,
    /// Port of the sensors' HTTP API (Ouster metadata).
    pub api_port: u16,
    pub recv_buffer: usize,
    /// Stop by itself after this long (one past the clock's range: never).
    pub duration: Option<Duration>,
    pub strict: bool,
    pub json: bool,
    /// `--serve`: the live view.
    pub serve: super::serve::ServeArgs,
    /// `--hesai-ptc[=PORT]`: fetch the angle correction of every `--sensor` without a bound
    /// `--calib` over Hesai's TCP control protocol at this port before listening.
    pub hesai_ptc: Option<u16>,
    /// What a caller embedding `listen` adds (the Python package).
    pub hooks: ListenHooks,
}

/// A decoded sweep handed to an embedding caller, with its sensor.
pub type TappedSweep = (ReadSweep, Option<SensorDesc>);

/// What a caller embedding `listen` adds (the Python package): a stop flag instead of the
/// process's signals, and every decoded sweep through a bounded channel; a sweep that finds
/// the channel full is dropped and counted (`receive.sweeps_dropped`), as the receive queue
/// drops datagrams, so a slow consumer never holds up the sockets.
#[derive(Debug, Clone, Default)]
pub struct ListenHooks {
    /// Set it to stop listening (checked every 100 ms); SIGINT, SIGTERM and SIGHUP are then left to
    /// the caller.
    pub stop: Option<Arc<AtomicBool>>,
    /// Where decoded sweeps go.
    pub sweeps: Option<SyncSender<TappedSweep>>,
    /// Sweeps dropped because the channel was full.
    pub sweeps_dropped: Arc<AtomicU64>,
}

/// What `listen` ends with.
pub struct ListenOutcome {
    /// The `--json` summary.
    pub json: Value,
    /// Packets lost (missing, dropped or malformed).
    pub lost: u64,
    /// The output files and their summaries.
    pub files: Vec<(PathBuf, SinkSummary)>,
}

/// From the decode thread to the main thread.
enum Event {
    /// Fetch this sensor's metadata.
    Fetch(Ipv4Addr),
    /// The decode thread stopped on an error.
    Failed,
}

/// From the main thread to the decode thread.
enum Control {
    /// Metadata fetched from a sensor: (address, file name, bytes).
    Metadata(Ipv4Addr, String, Vec<u8>),
}

/// Counters the decode thread publishes for the status line.
#[derive(Default)]
struct Live {
    sweeps: AtomicU64,
    points: AtomicU64,
}

/// The output files of a run.
struct Files {
    base: PathBuf,
    split: Option<Split>,
    opts: SinkOptions,
    index: usize,
    current: PathBuf,
    opened: Instant,
    closed: Vec<(PathBuf, SinkSummary)>,
    /// `--format ros2` into a rosbag2 directory: `base` is the directory.
    bag_dir: bool,
    /// The rosbag2 directory was made by this run (removed again if it records nothing).
    made_dir: bool,
    /// Syncs closed rosbag2 files and rewrites `metadata.yaml` off the decode thread.
    checkpoints: Option<Checkpoints>,
    /// The first file is written as this temporary file until a sensor is recognised, then
    /// renamed to its path: a run that receives nothing of a sensor (a wrong port, a sensor
    /// switched off) leaves no empty file, and a file already at the path as it was.
    pending: Option<PathBuf>,
}

/// In a rosbag2 directory without `--split-every`, the file is closed and a new one started
/// this often, and `metadata.yaml` rewritten: it lists only complete files (an MCAP file is
/// readable by every reader only once its footer is written), so a recording killed outright
/// keeps all but its last seconds in a bag that opens.
const BAG_CHECKPOINT: Split = Split::Seconds(10.0);

impl Files {
    fn path_for(base: &Path, split: Option<Split>, index: usize) -> PathBuf {
        if split.is_none() {
            return base.to_path_buf();
        }
        let stem = base
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let ext = base
            .extension()
            .map(|e| format!(".{}", e.to_string_lossy()))
            .unwrap_or_default();
        base.with_file_name(format!("{stem}_{index:04}{ext}"))
    }

    /// Creates the file at its path (not a temporary one: a recording killed outright keeps
    /// the chunks written so far).
    fn create(&self, path: &Path) -> Result<Sink, SinkError> {
        let f = std::fs::File::create(path).map_err(|source| SinkError::Io {
            context: format!("creating {}", path.display()),
            source,
        })?;
        McapSink::new(std::io::BufWriter::new(f), self.opts.clone())
    }

    /// Moves the first file to its path, now that it records a sensor (the open file is
    /// renamed under the writer, which goes on writing to it).
    fn promote(&mut self) -> Result<(), SinkError> {
        let Some(temp) = self.pending.take() else {
            return Ok(());
        };
        std::fs::rename(&temp, &self.current).map_err(|source| SinkError::Io {
            context: format!("renaming {} to {}", temp.display(), self.current.display()),
            source,
        })?;
        // Its split or checkpoint period starts with the recording.
        self.opened = Instant::now();
        Ok(())
    }

    /// Removes what a run that recorded no sensor made: the first file's temporary file and,
    /// for a rosbag2, the empty `metadata.yaml` (and the directory, if this run made it).
    fn discard(&mut self) {
        if let Some(temp) = self.pending.take() {
            let _ = std::fs::remove_file(temp);
            if self.bag_dir {
                let _ = std::fs::remove_file(self.base.join("metadata.yaml"));
                if self.made_dir {
                    let _ = std::fs::remove_dir(&self.base);
                }
            }
        }
    }

    /// The file `index` of the run.
    fn path(&self, index: usize) -> PathBuf {
        if self.bag_dir {
            crate::sink::rosbag2::file_path(&self.base, index)
        } else {
            Self::path_for(&self.base, self.split, index)
        }
    }

    /// The rosbag2 files closed so far (and `last`), as `metadata.yaml` lists them.
    fn bag_files(&self, last: Option<(&Path, &SinkSummary)>) -> Vec<BagFile> {
        self.closed
            .iter()
            .map(|(p, s)| (p.as_path(), s))
            .chain(last)
            .map(|(p, s)| crate::sink::rosbag2::BagFile {
                name: p
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default(),
                summary: s.clone(),
            })
            .collect()
    }

    /// A rosbag2 file was closed: it is synced, then `metadata.yaml` rewritten to name it, on
    /// the checkpoint thread. An error of an earlier checkpoint is returned here.
    fn checkpoint(&mut self, closed: &Path) -> Result<(), SinkError> {
        if !self.bag_dir {
            return Ok(());
        }
        let files = self.bag_files(None);
        let base = self.base.clone();
        let c = self
            .checkpoints
            .get_or_insert_with(|| Checkpoints::start(base));
        c.send(closed.to_path_buf(), files)
    }

    /// The last rosbag2 file was finished (`last`): waits for the checkpoints under way, syncs
    /// it, and writes the final `metadata.yaml`.
    /// A checkpoint that failed is reported, after the final yaml was still attempted: it
    /// names the files that were finished.
    fn write_final_metadata(&mut self, last: (&Path, &SinkSummary)) -> Result<(), SinkError> {
        let earlier = self.checkpoints.take().map_or(Ok(()), Checkpoints::finish);
        if !self.bag_dir {
            return earlier;
        }
        let files = self.bag_files(Some(last));
        let fin = sync_file(last.0).and_then(|()| write_bag_metadata(&self.base, &files));
        earlier.and(fin)
    }

    fn due(&self) -> bool {
        if self.pending.is_some() {
            return false;
        }
        let split = match (self.split, self.bag_dir) {
            (None, true) => Some(BAG_CHECKPOINT),
            (s, _) => s,
        };
        match split {
            None => false,
            Some(Split::Seconds(s)) => self.opened.elapsed().as_secs_f64() >= s,
            Some(Split::Bytes(b)) => std::fs::metadata(&self.current).is_ok_and(|m| m.len() >= b),
        }
    }
}

/// The thread that makes closed rosbag2 files durable and names them in `metadata.yaml`, in
/// the order they were closed. A file is synced before the yaml that names it is written: a
/// power loss must not leave a yaml naming a file cut short (a recording killed outright loses
/// nothing written). Syncing seconds of points can take longer than the receive queue lasts,
/// so the decode thread only hands the work over.
struct Checkpoints {
    base: PathBuf,
    jobs: Option<std::sync::mpsc::Sender<(PathBuf, Vec<BagFile>)>>,
    thread: Option<std::thread::JoinHandle<Result<(), SinkError>>>,
}

impl Checkpoints {
    fn start(base: PathBuf) -> Self {
        let (tx, rx) = std::sync::mpsc::channel::<(PathBuf, Vec<BagFile>)>();
        let thread = std::thread::Builder::new()
            .name("ringscan-checkpoint".into())
            .spawn({
                let base = base.clone();
                move || {
                    for (closed, files) in rx {
                        sync_file(&closed)?;
                        write_bag_metadata(&base, &files)?;
                    }
                    Ok(())
                }
            });
        match thread {
            Ok(t) => Self {
                base,
                jobs: Some(tx),
                thread: Some(t),
            },
            // No thread: each checkpoint is done on the caller's (as it was before).
            Err(e) => {
                tracing::warn!("no checkpoint thread ({e}): files are synced on the decode thread");
                Self {
                    base,
                    jobs: None,
                    thread: None,
                }
            }
        }
    }

    fn send(&mut self, closed: PathBuf, files: Vec<BagFile>) -> Result<(), SinkError> {
        let Some(jobs) = &self.jobs else {
            sync_file(&closed)?;
            return write_bag_metadata(&self.base, &files);
        };
        if jobs.send((closed, files)).is_ok() {
            return Ok(());
        }
        // The thread stopped on an error: that error.
        self.jobs = None;
        match self.thread.take().map(std::thread::JoinHandle::join) {
            Some(Ok(r)) => r,
            _ => Err(checkpoint_thread_lost()),
        }
    }

    /// Waits for every checkpoint handed over.
    fn finish(mut self) -> Result<(), SinkError> {
        self.jobs = None;
        match self.thread.take().map(std::thread::JoinHandle::join) {
            None | Some(Ok(Ok(()))) => Ok(()),
            Some(Ok(Err(e))) => Err(e),
            Some(Err(_)) => Err(checkpoint_thread_lost()),
        }
    }
}

impl Drop for Checkpoints {
    /// A run that ends on an error still leaves the checkpoints handed over done.
    fn drop(&mut self) {
        self.jobs = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn checkpoint_thread_lost() -> SinkError {
    SinkError::Io {
        context: "the rosbag2 checkpoint thread".into(),
        source: std::io::Error::other("it stopped without a result"),
    }
}

/// Writes a file's data to the disk (`fsync`).
fn sync_file(path: &Path) -> Result<(), SinkError> {
    std::fs::OpenOptions::new()
        .append(true)
        .open(path)
        .and_then(|f| f.sync_all())
        .map_err(|source| SinkError::Io {
            context: format!("syncing {}", path.display()),
            source,
        })
}

/// Rewrites `base/metadata.yaml` for `files`, and syncs the directory (its new names).
fn write_bag_metadata(base: &Path, files: &[BagFile]) -> Result<(), SinkError> {
    crate::sink::rosbag2::write_metadata(base, files).map_err(|source| SinkError::Io {
        context: format!("writing {}/metadata.yaml", base.display()),
        source,
    })?;
    crate::sink::mcap::sync_parent_dir(&base.join("metadata.yaml"));
    Ok(())
}

/// The MCAP settings of `listen`: the default compression on `--threads` threads, which the
/// decode thread never waits for (a chunk they cannot take in time is written uncompressed).
fn listen_sink_options(args: &ListenArgs) -> SinkOptions {
    SinkOptions {
        behind: Behind::WriteUncompressed,
        ..sink_options_with(
            args.session.format,
            ChunkCompression::default(),
            args.threads,
            args.chunk_size,
            args.fields_minimal,
        )
    }
}

/// The folder of the angle corrections fetched over PTC, removed with its files when the run
/// ends (they are copies of what the sensor holds; the output attaches them).
struct FetchedCorrections(Option<PathBuf>);

impl FetchedCorrections {
    /// The run's folder, made on first use. Made new, private (0700) and under a name no one
    /// can claim first: a folder of a predictable name that another user had made, holding a
    /// symbolic link where a file is written, would have had the run write through the link,
    /// and the guard would have removed that user's folder.
    fn dir(&mut self) -> std::io::Result<PathBuf> {
        use std::os::unix::fs::DirBuilderExt;
        if let Some(d) = &self.0 {
            return Ok(d.clone());
        }
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        let mut last = None;
        for attempt in 0u32..16 {
            let d = std::env::temp_dir().join(format!(
                "ringscan-hesai-ptc-{}-{:08x}",
                std::process::id(),
                nanos.wrapping_add(attempt.wrapping_mul(0x9e37_79b9))
            ));
            match std::fs::DirBuilder::new().mode(0o700).create(&d) {
                Ok(()) => {
                    self.0 = Some(d.clone());
                    return Ok(d);
                }
                Err(e) => last = Some(e),
            }
        }
        Err(last.unwrap_or_else(|| std::io::Error::other("no folder name left")))
    }
}

impl Drop for FetchedCorrections {
    fn drop(&mut self) {
        let Some(d) = &self.0 else {
            return;
        };
        if let Err(e) = std::fs::remove_dir_all(d) {
            if e.kind() != std::io::ErrorKind::NotFound {
                tracing::warn!("{}: {e}", d.display());
            }
        }
    }
}

/// `args` with the angle correction of every `--sensor` that has no `--calib ADDR=FILE` of its
/// own, fetched over Hesai's PTC at `port` and bound to its address (written to a folder of
/// the run in the temporary folder, so that the run reads and attaches it like any `--calib`
/// file; the folder goes when the returned guard is dropped). A sensor that does not answer is
/// left as it was (it may not be a Hesai).
fn with_hesai_corrections(args: &ListenArgs, port: u16) -> (ListenArgs, FetchedCorrections) {
    let mut out = args.clone();
    let mut guard = FetchedCorrections(None);
    let mut seen = BTreeSet::new();
    for (ip, _) in &args.sensors {
        let bound = args
            .session
            .calib
            .iter()
            .any(|c| c.split_once('=').is_some_and(|(a, _)| a == ip.to_string()));
        if bound || !seen.insert(*ip) {
            continue;
        }
        let addr = std::net::SocketAddr::new((*ip).into(), port);
        match super::ptc::fetch_angle_correction(addr, Duration::from_secs(2)) {
            Ok(bytes) => {
                let ext = if bytes.starts_with(&[0xEE, 0xFF]) {
                    "dat"
                } else {
                    "csv"
                };
                let dir = match guard.dir() {
                    Ok(d) => d,
                    Err(e) => {
                        tracing::warn!("--hesai-ptc: a private temporary folder: {e}");
                        continue;
                    }
                };
                let path = dir.join(format!("hesai-ptc-{ip}.{ext}"));
                match std::fs::write(&path, &bytes) {
                    Ok(()) => {
                        tracing::info!(
                            "{ip}: angle correction fetched over PTC ({} bytes)",
                            bytes.len()
                        );
                        out.session.calib.push(format!("{ip}={}", path.display()));
                    }
                    Err(e) => tracing::warn!("{}: {e}", path.display()),
                }
                if crate::sensor::hesai::atx::looks_like_atx_dat(&bytes) {
                    with_atx_firetimes(&mut out, &dir, *ip, addr);
                }
            }
            Err(e) => tracing::warn!("--hesai-ptc: {e}"),
        }
    }
    (out, guard)
}

/// An ATX's firetime correction, fetched over PTC beside its angle correction and written as
/// the CSV the run joins to it; without it (an older firmware, an error) the ATX is decoded
/// without the firetime shift, which is said.
fn with_atx_firetimes(out: &mut ListenArgs, dir: &Path, ip: Ipv4Addr, addr: SocketAddr) {
    match super::ptc::fetch_atx_firetimes(addr, Duration::from_secs(2)) {
        Ok(f) => {
            let path = dir.join(format!("hesai-ptc-{ip}-firetimes.csv"));
            match std::fs::write(&path, f.to_csv()) {
                Ok(()) => {
                    tracing::info!(
                        "{ip}: firetime correction fetched over PTC ({} channels)",
                        f.channels()
                    );
                    out.session.calib.push(format!("{ip}={}", path.display()));
                }
                Err(e) => tracing::warn!("{}: {e}", path.display()),
            }
        }
        Err(e) => tracing::warn!(
            "--hesai-ptc: {e}; the ATX at {ip} is decoded without its firetime correction"
        ),
    }
}

/// Parses fetched Ouster metadata into a calibration bound to `addr`.
fn metadata_spec(addr: Ipv4Addr, name: String, bytes: Vec<u8>) -> Result<Calibration, String> {
    let c = super::sensors::calibration(&bytes, &name, Some(addr))?;
    if c.get::<OusterCalibration>().is_none() {
        return Err("not Ouster metadata".into());
    }
    Ok(c)
}

/// An output error with the file's path and every cause (down to the OS error, e.g. "No space
/// left on device").
fn file_error(path: &Path, e: &SinkError) -> RunError {
    let mut msg = format!("{}: {e}", path.display());
    let mut cause = std::error::Error::source(e);
    while let Some(c) = cause {
        let s = c.to_string();
        if !msg.contains(&s) {
            msg.push_str(": ");
            msg.push_str(&s);
        }
        cause = c.source();
    }
    RunError::Live(msg)
}

/// What the decode thread hands back.
struct DecodeResult {
    summary: serde_json::Map<String, Value>,
    lost: u64,
    files: Vec<(PathBuf, SinkSummary)>,
    held: Held,
}

/// Datagrams of Ouster sensors whose metadata is being fetched, decoded once it arrives, so a
/// recording's first frames are not lost to the request's round trip.
#[derive(Default)]
struct Held {
    by_addr: HashMap<Ipv4Addr, std::collections::VecDeque<Received>>,
    bytes: usize,
    /// Datagrams held, ever.
    held: u64,
    /// Pushed again once the metadata came (each was counted `ignored` when it arrived).
    replayed: u64,
    /// Of those, routed to a sensor this time.
    decoded: u64,
    /// Let go to stay within [`HOLD_BYTES`].
    evicted: u64,
    /// Let go when a `--calib` file started their sensor (the demultiplexer holds a sensor's
    /// datagrams of the last second itself, and routed them).
    recognised: u64,
}

impl Held {
    fn hold(&mut self, r: Received) {
        let addr = *r.src.ip();
        self.bytes += r.payload.len();
        self.held += 1;
        self.by_addr.entry(addr).or_default().push_back(r);
        while self.bytes > HOLD_BYTES {
            // The oldest datagram of the sensor holding most.
            let Some(q) = self.by_addr.values_mut().max_by_key(|q| q.len()) else {
                break;
            };
            match q.pop_front() {
                Some(old) => {
                    self.bytes -= old.payload.len();
                    self.evicted += 1;
                }
                None => break,
            }
        }
    }

    fn take(&mut self, addr: Ipv4Addr) -> std::collections::VecDeque<Received> {
        let q = self.by_addr.remove(&addr).unwrap_or_default();
        self.bytes -= q.iter().map(|r| r.payload.len()).sum::<usize>();
        q
    }

    fn json(&self) -> Value {
        json!({
            "held": self.held,
            "decoded": self.decoded,
            "replayed": self.replayed,
            "evicted": self.evicted,
            "recognised": self.recognised,
            "left": self.by_addr.values().map(|q| q.len() as u64).sum::<u64>(),
        })
    }
}

struct DecodeThread {
    session: Session,
    files: Option<Files>,
    sensors: Vec<Ipv4Addr>,
    events: tokio::sync::mpsc::UnboundedSender<Event>,
    ctl: Receiver<Control>,
    stats: Arc<ReceiveStats>,
    live: Arc<Live>,
    /// Last metadata request per address.
    asked: HashMap<Ipv4Addr, Instant>,
    /// Ouster `init_id` epochs seen per sensor index.
    epochs: Vec<u64>,
    /// When the last health diagnostics were written.
    last_health: Instant,
    /// Datagrams waiting for their sensor's metadata.
    held: Held,
    /// Where decoded sweeps go, and the count of those dropped ([`ListenHooks`]).
    tap: Option<(SyncSender<TappedSweep>, Arc<AtomicU64>)>,
}

impl DecodeThread {
    /// Hands the sweeps decoded so far to the embedding caller, if any.
    fn forward_sweeps(&mut self) {
        let Some((tx, dropped)) = &self.tap else {
            return;
        };
        let sweeps: Vec<ReadSweep> = self.session.take_sweeps().collect();
        for rs in sweeps {
            let desc = self.session.sensor_desc(rs.sensor);
            match tx.try_send((rs, desc)) {
                Ok(()) => {}
                Err(TrySendError::Full(_)) => {
                    dropped.fetch_add(1, Ordering::Relaxed);
                }
                // The caller is gone: it stops the run through its flag.
                Err(TrySendError::Disconnected(_)) => {}
            }
        }
    }

    fn run(mut self, rx: Receiver<Received>) -> Result<DecodeResult, RunError> {
        let mut last_check = Instant::now();
        loop {
            match rx.recv_timeout(Duration::from_millis(100)) {
                Ok(r) => {
                    self.stats
                        .queued_bytes
                        .fetch_sub(r.payload.len(), Ordering::Relaxed);
                    let ignored = self.session.demux().stats().ignored;
                    if let Err(e) = self.session.push(r.time_ns, r.src, r.port, &r.payload) {
                        let err = self.session.run_error(e, "listen");
                        self.close_on_error();
                        return Err(self.with_path(err));
                    }
                    if let Err(e) = self.promote() {
                        self.close_on_error();
                        return Err(self.with_path(RunError::Sink(e)));
                    }
                    if self.session.demux().stats().ignored > ignored {
                        self.unclaimed(r);
                    } else if self.held.by_addr.contains_key(r.src.ip()) {
                        // Started by a `--calib` file: the demultiplexer routed its held
                        // datagrams (those of the last second) to it.
                        let n = self.held.take(*r.src.ip()).len() as u64;
                        self.held.recognised += n;
                    }
                    self.forward_sweeps();
                    let (sweeps, points) = self.session.totals();
                    self.live.sweeps.store(sweeps, Ordering::Relaxed);
                    self.live.points.store(points, Ordering::Relaxed);
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break,
            }
            if last_check.elapsed() >= Duration::from_millis(100) {
                last_check = Instant::now();
                if let Err(e) = self.housekeeping() {
                    self.close_on_error();
                    return Err(self.with_path(e));
                }
                self.forward_sweeps();
            }
        }
        match self.finish() {
            Ok(r) => Ok(r),
            Err((e, path)) => Err(match (e, path) {
                (RunError::Sink(e), Some(p)) => file_error(&p, &e),
                (e, _) => e,
            }),
        }
    }

    /// The first file goes to its path once a sensor is recognised ([`Files::pending`]).
    fn promote(&mut self) -> Result<(), SinkError> {
        match self.files.as_mut() {
            Some(f) if f.pending.is_some() && self.session.demux().sensors().next().is_some() => {
                f.promote()
            }
            _ => Ok(()),
        }
    }

    /// After an error: the output is finalised if it records a sensor (what came before the
    /// error), else removed. A rosbag2's `metadata.yaml` then names the file finalised, as
    /// at a normal end (else the bag opened without it). The run's error is the one
    /// reported: one in closing is only logged.
    fn close_on_error(&mut self) {
        match self.files.as_mut() {
            Some(f) if f.pending.is_some() => {
                self.session.abort_sink();
                f.discard();
            }
            _ => {
                let last = self.session.close_sink();
                let Some(f) = self.files.as_mut() else {
                    return;
                };
                let current = f.current.clone();
                let named = match &last {
                    Ok(Some(s)) => f.write_final_metadata((&current, s)),
                    // Not finished: the yaml keeps the files before it.
                    _ => f.checkpoints.take().map_or(Ok(()), Checkpoints::finish),
                };
                if let Err(e) = last.map(|_| ()).and(named) {
                    tracing::warn!("closing {} after the error: {e}", current.display());
                }
            }
        }
    }

    /// Output errors name the file.
    fn with_path(&self, e: RunError) -> RunError {
        match (e, &self.files) {
            (RunError::Sink(e), Some(f)) => RunError::Live(format!("{}: {e}", f.current.display())),
            (e, _) => e,
        }
    }

    /// A datagram from a sensor address that no family claimed: a sensor whose calibration
    /// is not known yet (an Ouster sensor without its metadata); ask the sensor for it, and
    /// hold the datagram until it comes. A sensor a `--calib` file may still start (its IMU
    /// packet came before its first lidar packet) is not asked.
    fn unclaimed(&mut self, r: Received) {
        let addr = *r.src.ip();
        if !self.sensors.contains(&addr) {
            return;
        }
        self.held.hold(r);
        if self.session.calibration_pending("ouster", addr) {
            return;
        }
        if self
            .asked
            .get(&addr)
            .is_some_and(|t| t.elapsed() < FETCH_RETRY)
        {
            return;
        }
        self.asked.insert(addr, Instant::now());
        let _ = self.events.send(Event::Fetch(addr));
    }

    /// Once a second, per sensor: its counters and health (Velodyne PPS and GPS; Ouster alert
    /// flags, shot limiting, thermal shutdown, init_id) and the receive side's, to
    /// `/diagnostics` with `"health": true`.
    fn write_health(&mut self) -> Result<(), RunError> {
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
        let receive = json!({
            "datagrams": self.stats.datagrams.load(Ordering::Relaxed),
            "queue_dropped": self.stats.queue_dropped.load(Ordering::Relaxed),
            "other_source": self.stats.other_source.load(Ordering::Relaxed),
            "queued_bytes": self.stats.queued_bytes.load(Ordering::Relaxed),
        });
        // The current file's chunks, and those written uncompressed because the compression
        // threads were behind.
        let mcap = self
            .session
            .chunk_stats()
            .map(|c| json!({"chunks": c.chunks, "chunks_uncompressed": c.chunks_uncompressed}));
        let mut msgs = Vec::new();
        for (idx, (_, stream, _)) in self.session.demux().sensors().enumerate() {
            let (mut v, _) = stream.summary();
            if let Some(o) = v.as_object_mut() {
                o.insert("health".into(), json!(true));
                o.insert("receive".into(), receive.clone());
                if let Some(m) = &mcap {
                    o.insert("mcap".into(), m.clone());
                }
            }
            msgs.push((idx, v));
        }
        for (idx, v) in msgs {
            self.session.write_diagnostics(idx, now, &v)?;
        }
        Ok(())
    }

    fn housekeeping(&mut self) -> Result<(), RunError> {
        if self.last_health.elapsed() >= Duration::from_secs(1) {
            self.last_health = Instant::now();
            self.write_health()?;
        }
        while let Ok(c) = self.ctl.try_recv() {
            match c {
                Control::Metadata(addr, name, bytes) => self.on_metadata(addr, name, bytes)?,
            }
        }
        self.promote()?;
        // A sensor re-initialised (Ouster: a new init_id): read its calibration again.
        let mut refetch = Vec::new();
        for (idx, (addr, stream, _)) in self.session.demux().sensors().enumerate() {
            let e = stream.epochs();
            if self.epochs.len() <= idx {
                self.epochs.resize(idx + 1, 0);
            }
            if e > self.epochs[idx] {
                self.epochs[idx] = e;
                tracing::info!("sensor {addr}: re-initialised; reading its metadata again");
                refetch.push(addr);
            }
        }
        for addr in refetch {
            self.asked.insert(addr, Instant::now());
            let _ = self.events.send(Event::Fetch(addr));
        }
        let due = self.files.as_ref().is_some_and(Files::due);
        if due {
            self.rotate()?;
        }
        Ok(())
    }

    fn on_metadata(
        &mut self,
        addr: Ipv4Addr,
        name: String,
        bytes: Vec<u8>,
    ) -> Result<(), RunError> {
        let spec = match metadata_spec(addr, name.clone(), bytes) {
            Ok(s) => s,
            Err(e) => {
                tracing::warn!("sensor {addr}: metadata from its HTTP API not usable: {e}");
                return Ok(());
            }
        };
        // A sensor already decoding: compare what changed.
        let existing = self
            .session
            .demux()
            .sensors()
            .find(|(a, _, _)| *a == addr)
            .and_then(|(_, s, _)| {
                s.as_any()
                    .downcast_ref::<OusterStream>()
                    .map(|o| o.info().clone())
            });
        match (existing, spec.get::<OusterCalibration>().map(|c| &c.info)) {
            (Some(old), Some(new)) => {
                let same = old.format == new.format
                    && old.columns_per_frame == new.columns_per_frame
                    && old.serial == new.serial;
                if same {
                    tracing::info!("sensor {addr}: metadata re-read; lidar format unchanged");
                } else {
                    tracing::warn!(
                        "sensor {addr}: its lidar configuration changed (mode or profile); its packets are counted as malformed until ringscan restarts"
                    );
                }
            }
            _ => {
                tracing::info!("sensor {addr}: metadata read from http://{addr}{METADATA_PATH}");
                self.session.add_calib(spec);
            }
        }
        // What arrived while the metadata was on its way (the demultiplexer's own copies of
        // the last second's go: these are pushed again).
        self.session.forget_early(addr);
        let held = self.held.take(addr);
        if !held.is_empty() {
            tracing::info!(
                "sensor {addr}: decoding {} datagrams held for its metadata",
                held.len()
            );
        }
        for r in held {
            let ignored = self.session.demux().stats().ignored;
            if let Err(e) = self.session.push(r.time_ns, r.src, r.port, &r.payload) {
                return Err(self.session.run_error(e, "listen"));
            }
            self.held.replayed += 1;
            if self.session.demux().stats().ignored == ignored {
                self.held.decoded += 1;
            }
        }
        Ok(())
    }

    fn rotate(&mut self) -> Result<(), RunError> {
        let Some(files) = self.files.as_mut() else {
            return Ok(());
        };
        let next_path = files.path(files.index + 1);
        let next = files.create(&next_path)?;
        let closed = match self.session.rotate(next) {
            Ok(c) => c,
            Err(e) => {
                // The current file could not be finished: the error names it, and the next
                // one, never used, goes.
                let _ = std::fs::remove_file(&next_path);
                return Err(e.into());
            }
        };
        let prev = std::mem::replace(&mut files.current, next_path);
        files.index += 1;
        files.opened = Instant::now();
        if let Some(s) = closed {
            tracing::info!("closed {}", prev.display());
            files.closed.push((prev.clone(), s));
            files.checkpoint(&prev)?;
        }
        Ok(())
    }

    fn finish(mut self) -> Result<DecodeResult, (RunError, Option<PathBuf>)> {
        let path = self.files.as_ref().map(|f| f.current.clone());
        if let Err(e) = self.session.finish_streams() {
            let err = self.session.run_error(e, "listen");
            self.close_on_error();
            return Err((err, path));
        }
        self.forward_sweeps();
        if let Err(e) = self.session.finish_odometry() {
            self.close_on_error();
            return Err((e, path));
        }
        // No sensor was recognised: nothing is written (the summary says what came).
        if let Some(f) = self.files.as_mut().filter(|f| f.pending.is_some()) {
            self.session.abort_sink();
            f.discard();
            self.files = None;
        }
        let last = self
            .session
            .close_sink()
            .map_err(|e| (RunError::Sink(e), path.clone()))?;
        let mut files = Vec::new();
        if let Some(mut f) = self.files.take() {
            if let Some(s) = &last {
                let current = f.current.clone();
                f.write_final_metadata((&current, s))
                    .map_err(|e| (RunError::Sink(e), path))?;
            }
            files = f.closed;
            if let Some(s) = last {
                files.push((f.current, s));
            }
        }
        let (mut summary, lost) = self.session.summary();
        // Datagrams held and pushed again were counted `ignored` on arrival.
        if let Some(p) = summary.get_mut("packets").and_then(Value::as_object_mut) {
            let i = p.get("ignored").and_then(Value::as_u64).unwrap_or(0);
            p.insert(
                "ignored".into(),
                json!(i.saturating_sub(self.held.replayed)),
            );
        }
        Ok(DecodeResult {
            summary,
            lost,
            files,
            held: std::mem::take(&mut self.held),
        })
    }
}

/// The ports to listen on: a `--sensor`'s own, else those its calibrations name, else every
/// family's defaults.
fn ports_for(args: &ListenArgs, calibs: &[Calibration]) -> BTreeSet<u16> {
    let mut ports = BTreeSet::new();
    for (ip, port) in &args.sensors {
        if let Some(p) = port {
            ports.insert(*p);
            continue;
        }
        let named: Vec<u16> = calibs
            .iter()
            .filter(|c| c.addr.is_none() || c.addr == Some(*ip))
            .flat_map(|c| {
                FAMILIES
                    .iter()
                    .filter(|f| f.name() == c.family)
                    .flat_map(|f| f.calibration_ports(c))
            })
            .collect();
        if named.is_empty() {
            ports.extend(FAMILIES.iter().flat_map(|f| f.default_ports()));
        } else {
            ports.extend(named);
        }
    }
    ports
}

/// A thread that writes the status lines it is given to stderr, and its handle; `None` if it
/// cannot start (the run goes on without a status line). Write errors are ignored: a terminal
/// that went away (SIGHUP) fails with EIO, and `eprint!` would panic on it.
fn status_writer() -> Option<(SyncSender<String>, std::thread::JoinHandle<()>)> {
    let (tx, rx) = std::sync::mpsc::sync_channel::<String>(1);
    let handle = std::thread::Builder::new()
        .name("ringscan-status".into())
        .spawn(move || {
            for line in rx {
                let mut err = std::io::stderr().lock();
                let _ = err.write_all(line.as_bytes());
                let _ = err.flush();
            }
        })
        .ok()?;
    Some((tx, handle))
}

/// After SIGHUP the terminal is gone and every write to it fails (EIO), so the standard
/// output and error that were the terminal (`tty`: as found when the run started; by the
/// time the signal comes the kernel has already cut the terminal off, and `isatty` fails on
/// it) are pointed at /dev/null: the run finishes its file and its summary goes nowhere,
/// instead of a print failing or panicking half-way.
fn detach_from_terminal(tty: (bool, bool)) {
    let Ok(null) = std::fs::OpenOptions::new().write(true).open("/dev/null") else {
        return;
    };
    if tty.0 {
        let _ = nix::unistd::dup2_stdout(&null);
    }
    if tty.1 {
        let _ = nix::unistd::dup2_stderr(&null);
    }
}

fn status_line(
    live: &Live,
    stats: &ReceiveStats,
    kernel: u64,
    prev: &mut (Instant, u64, u64, u64),
) -> String {
    let (t0, sw0, pt0, dg0) = *prev;
    let dt = t0.elapsed().as_secs_f64().max(1e-3);
    let sw = live.sweeps.load(Ordering::Relaxed);
    let pt = live.points.load(Ordering::Relaxed);
    let dg = stats.datagrams.load(Ordering::Relaxed);
    *prev = (Instant::now(), sw, pt, dg);
    format!(
        "\r{:6.1} sweeps/s · {:9.0} points/s · {:7.0} packets/s · lost: queue {} kernel {} · other sources {}   ",
        (sw - sw0) as f64 / dt,
        (pt - pt0) as f64 / dt,
        (dg - dg0) as f64 / dt,
        stats.queue_dropped.load(Ordering::Relaxed),
        kernel,
        stats.other_source.load(Ordering::Relaxed),
    )
}

fn kernel_drops(sockets: &[BoundSocket]) -> u64 {
    sockets.iter().filter_map(BoundSocket::kernel_drops).sum()
}

/// Why a run recognised no sensor, if it did not (from its summary): nothing came, or what
/// came was from other addresses, or its sensor's metadata never came, or it was of no sensor
/// ringscan decodes. Like `decode` finding no sensor, this is a failure, not an empty success.
fn no_sensor_reason(summary: &Value, args: &ListenArgs) -> Option<String> {
    if summary["sensors"].as_array().is_some_and(|s| !s.is_empty()) {
        return None;
    }
    let g = |v: &Value| v.as_u64().unwrap_or(0);
    let r = &summary["receive"];
    let ports: Vec<String> = r["sockets"]
        .as_array()
        .map(|a| a.iter().map(|s| g(&s["port"]).to_string()).collect())
        .unwrap_or_default();
    let ports = format!(
        "UDP port{} {}",
        if ports.len() == 1 { "" } else { "s" },
        ports.join(", ")
    );
    let mut addrs: Vec<String> = args.sensors.iter().map(|(ip, _)| ip.to_string()).collect();
    addrs.dedup();
    let addrs = addrs.join(", ");
    let secs = summary["elapsed_s"].as_f64().unwrap_or(0.0);
    let (datagrams, other) = (g(&r["datagrams"]), g(&r["other_source"]));
    let held = g(&r["held_for_metadata"]["held"]);
    Some(if datagrams == 0 && other > 0 {
        format!(
            "in {secs:.1} s, no datagram came from {addrs} to {ports}; {other} came from other \
             addresses (--sensor names the sensor's own)"
        )
    } else if datagrams == 0 {
        format!("in {secs:.1} s, no datagram came to {ports}")
    } else if held > 0 {
        format!(
            "{datagrams} datagrams came from {addrs}; {held} were held for their Ouster \
             metadata, which did not come from http://ADDR:{}{METADATA_PATH} (give it with \
             --calib)",
            args.api_port
        )
    } else {
        format!(
            "{datagrams} datagrams came from {addrs} to {ports}, none of them a packet of a \
             sensor ringscan decodes"
        )
    })
}

/// `ringscan listen` (`configure`: `--configure`, Livox).
pub fn listen_command(
    args: &ListenArgs,
    configure: Option<&super::livox_ctl::ConfigureArgs>,
) -> Result<ExitCode, RunError> {
    let ListenOutcome {
        json: json_out,
        lost,
        files,
    } = listen_run_with(args, configure)?;
    if let Some(why) = no_sensor_reason(&json_out, args) {
        return Err(RunError::NoSensor {
            path: "listen".into(),
            why,
            wrote_nothing: args.out.is_some(),
        });
    }
    if args.json {
        outln!("{json_out}");
    } else {
        let g = |v: &Value| v.as_u64().unwrap_or(0);
        let p = &json_out["packets"];
        let r = &json_out["receive"];
        outln!(
            "listened {:.1} s ({}): {} datagrams, {} sweeps, {} points; packets decoded {}, dropped {} (queue {}, kernel {}), malformed {}, missing {}, ignored {}, from other sources {}",
            json_out["elapsed_s"].as_f64().unwrap_or(0.0),
            json_out["stop"].as_str().unwrap_or(""),
            g(&r["datagrams"]),
            g(&json_out["sweeps"]),
            g(&json_out["points"]),
            g(&p["decoded"]),
            g(&p["dropped"]),
            g(&r["queue_dropped"]),
            g(&r["kernel_dropped"]),
            g(&p["malformed"]),
            g(&p["missing"]),
            g(&p["ignored"]),
            g(&r["other_source"]),
        );
        super::report::print_warnings(&json_out);
        for (path, s) in &files {
            // The topics' counts as `decode` prints them (JSON).
            outln!(
                "  wrote {}: {}",
                path.display(),
                serde_json::json!(s.messages)
            );
        }
    }
    if args.strict && lost > 0 {
        return Err(RunError::Reported(format!(
            "--strict: {lost} packets missing, dropped or malformed"
        )));
    }
    Ok(ExitCode::SUCCESS)
}

/// Listens until a signal, `--duration` or the hooks' stop flag; the summary.
pub fn listen_run(args: &ListenArgs) -> Result<ListenOutcome, RunError> {
    listen_run_with(args, None)
}

/// The Livox model `--configure` starts: `--model` if given (an error if it is not a Livox
/// model), else `None` (SDK2 discovery says which).
fn configure_model(args: &ListenArgs) -> Result<Option<LivoxModel>, RunError> {
    match args.session.model.as_deref() {
        None => Ok(None),
        Some(m) => LivoxModel::from_id(m).map(Some).ok_or_else(|| {
            let ids: Vec<&str> = ALL_MODELS.iter().map(|m| m.id()).collect();
            RunError::Usage(format!(
                "--configure starts Livox sensors only; --model {m} is not one ({})",
                ids.join(", ")
            ))
        }),
    }
}

/// [`listen_run`], first configuring a Livox sensor to stream when `configure` is given
/// (after the sockets are bound, so its first datagrams are not lost), and keeping it
/// streaming (the SDK1 heartbeat) until the end.
pub fn listen_run_with(
    args: &ListenArgs,
    configure: Option<&super::livox_ctl::ConfigureArgs>,
) -> Result<ListenOutcome, RunError> {
    let configure_model = match configure {
        Some(_) => configure_model(args)?,
        None => None,
    };
    if args.sensors.is_empty() {
        return Err(RunError::Usage(
            "listen: give at least one --sensor IP[:PORT]".into(),
        ));
    }
    if let Some(g) = args.multicast.filter(|g| !g.is_multicast()) {
        return Err(RunError::Usage(format!(
            "--multicast {g}: not a multicast group (224.0.0.0 … 239.255.255.255); a sensor \
             sending to this host's address needs no --multicast"
        )));
    }
    if args.split_every.is_some() && args.out.is_none() {
        return Err(RunError::Usage("--split-every needs --out".into()));
    }
    // The first file is written beside its path and renamed into place ([`Files::pending`]),
    // so a path that is not a regular file is refused as `decode` refuses it (renaming over
    // a device would replace it). A link to a file records into the file.
    let resolved;
    let args = match &args.out {
        Some(out) => {
            let bag_dir =
                args.session.format == FormatArg::Ros2 && crate::sink::rosbag2::is_bag_dir(out);
            if bag_dir || args.split_every.is_some() {
                super::run::out_dir_exists(out)?;
                args
            } else {
                resolved = ListenArgs {
                    out: Some(super::run::output_file_path(out, "MCAP")?),
                    ..args.clone()
                };
                &resolved
            }
        }
        None => args,
    };
    let started = Instant::now();
    // The fetched files live as long as this run (`_fetched` is dropped on every return).
    let (fetched, _fetched);
    let args = match args.hesai_ptc {
        None => args,
        Some(port) => {
            (fetched, _fetched) = with_hesai_corrections(args, port);
            &fetched
        }
    };
    // Options and calibrations are checked here, before any socket is opened.
    Session::new(&args.session)?;
    let calibs = load_calibs(&args.session.calib)?;
    let ports = ports_for(args, &calibs);
    let mut addrs: Vec<Ipv4Addr> = args.sensors.iter().map(|(ip, _)| *ip).collect();
    addrs.dedup();
    let n_sensors = {
        let mut a = addrs.clone();
        a.sort();
        a.dedup();
        a.len()
    };

    // Sockets.
    let mut sockets = Vec::new();
    for &port in &ports {
        let s = udp::bind(&SocketOptions {
            port,
            multicast: args.multicast,
            interface: args.interface,
            recv_buffer: args.recv_buffer,
        })
        .map_err(|e| RunError::Live(e.to_string()))?;
        // Linux reports twice the usable size; the kernel's cap is net.core.rmem_max.
        if s.granted_recv_buffer < s.requested_recv_buffer {
            tracing::warn!(
                "UDP port {port}: receive buffer {} bytes granted of {} asked (net.core.rmem_max = {}); raise it with `sysctl -w net.core.rmem_max={}`",
                s.granted_recv_buffer,
                s.requested_recv_buffer,
                udp::rmem_max().map_or("?".into(), |v| v.to_string()),
                s.requested_recv_buffer
            );
        } else {
            tracing::info!(
                "UDP port {port}: receive buffer {} bytes",
                s.granted_recv_buffer
            );
        }
        sockets.push(s);
    }
    let kernel_base: Vec<u64> = sockets
        .iter()
        .map(|s| s.kernel_drops().unwrap_or(0))
        .collect();

    // The live view (bound before the sockets report ready) and the decode thread.
    let live_view = super::serve::LivePublisher::start(&args.serve, None)?;
    let live_stats = live_view.as_ref().map(|l| l.stats());
    let stats = Arc::new(ReceiveStats::default());
    let live = Arc::new(Live::default());
    let (tx, rx) = std::sync::mpsc::sync_channel::<Received>(QUEUE_DATAGRAMS);
    let (ev_tx, mut ev_rx) = tokio::sync::mpsc::unbounded_channel::<Event>();
    let (ctl_tx, ctl_rx) = std::sync::mpsc::channel::<Control>();
    let (ready_tx, ready_rx) = std::sync::mpsc::channel::<Result<(), RunError>>();
    let decode = {
        let opts = args.session.clone();
        let out = args.out.clone();
        let split = args.split_every;
        let sink_opts = listen_sink_options(args);
        let stats = stats.clone();
        let live = live.clone();
        let sensors = addrs.clone();
        // The thread holds the only sender: when it ends for any reason, a panic included,
        // the main loop's `ev_rx.recv()` sees the channel closed and stops the run (a copy
        // kept here would leave it receiving, at 0 points/s, until a signal).
        let ev = ev_tx;
        let hooks_sweeps = args.hooks.sweeps.clone();
        let hooks_dropped = args.hooks.sweeps_dropped.clone();
        std::thread::Builder::new()
            .name("ringscan-decode".into())
            .spawn(move || -> Result<DecodeResult, RunError> {
                let setup = (|| -> Result<(Session, Option<Files>), RunError> {
                    let mut session = Session::new(&opts)?;
                    if hooks_sweeps.is_some() {
                        session.enable_tap();
                    }
                    session.set_sensor_hint(n_sensors);
                    session.set_live(live_view);
                    let files = match out {
                        Some(base) => {
                            let base_existed = base.exists();
                            let bag_dir = opts.format == FormatArg::Ros2
                                && crate::sink::rosbag2::is_bag_dir(&base);
                            let mut files = Files {
                                base,
                                split,
                                opts: sink_opts,
                                index: 0,
                                current: PathBuf::new(),
                                opened: Instant::now(),
                                closed: Vec::new(),
                                bag_dir,
                                made_dir: bag_dir && !base_existed,
                                checkpoints: None,
                                pending: None,
                            };
                            let current = files.path(0);
                            files.current = current.clone();
                            if bag_dir {
                                if files.base.join("metadata.yaml").exists() {
                                    return Err(RunError::Usage(format!(
                                        "--out {}: already holds a rosbag2 (metadata.yaml); \
                                         choose another --out",
                                        files.base.display()
                                    )));
                                }
                                // The directory and its first (empty) metadata.yaml.
                                crate::sink::rosbag2::create_dir(&files.base).map_err(
                                    |source| {
                                        file_error(
                                            &files.base,
                                            &SinkError::Io {
                                                context: "creating the rosbag2 directory".into(),
                                                source,
                                            },
                                        )
                                    },
                                )?;
                            }
                            let temp = crate::sink::mcap::temp_path(&current);
                            let sink = files.create(&temp).map_err(|e| {
                                files.pending = Some(temp.clone());
                                files.discard();
                                file_error(&current, &e)
                            })?;
                            files.pending = Some(temp);
                            session.set_sink(Some(sink));
                            Some(files)
                        }
                        None => None,
                    };
                    Ok((session, files))
                })();
                let (session, files) = match setup {
                    Ok(x) => {
                        let _ = ready_tx.send(Ok(()));
                        x
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                        return Err(RunError::Live("decode thread setup failed".into()));
                    }
                };
                let t = DecodeThread {
                    session,
                    files,
                    sensors,
                    events: ev.clone(),
                    ctl: ctl_rx,
                    stats,
                    live,
                    asked: HashMap::new(),
                    epochs: Vec::new(),
                    last_health: Instant::now(),
                    held: Held::default(),
                    tap: hooks_sweeps.map(|tx| (tx, hooks_dropped)),
                };
                let r = t.run(rx);
                if r.is_err() {
                    let _ = ev.send(Event::Failed);
                }
                r
            })
            .map_err(|e| RunError::Live(format!("starting the decode thread: {e}")))?
    };
    match ready_rx.recv() {
        Ok(Ok(())) => {}
        Ok(Err(e)) => {
            let _ = decode.join();
            return Err(e);
        }
        Err(_) => return Err(RunError::Live("the decode thread did not start".into())),
    }

    let configured = match configure {
        None => None,
        Some(c) => {
            let device = addrs.first().copied().unwrap_or(Ipv4Addr::LOCALHOST);
            match super::livox_ctl::configure(c, configure_model, device, args.interface, &ports) {
                Ok(x) => Some(x),
                Err(e) => {
                    drop(tx);
                    let _ = decode.join();
                    return Err(e);
                }
            }
        }
    };

    tracing::info!(
        "listening on UDP ports {:?} for {:?}",
        ports.iter().collect::<Vec<_>>(),
        addrs
    );

    // The receive side.
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| RunError::Live(format!("starting the runtime: {e}")))?;
    let sources = Arc::new(addrs.clone());
    let terminal = std::io::stderr().is_terminal();
    // The status line is written by a thread of its own: the runtime's one thread also reads
    // every socket, and a terminal that stops taking output (Ctrl-S, a slow SSH link) would
    // stop it in the write while the kernel drops datagrams. A line the writer has not taken
    // by the next second is skipped.
    let status = terminal.then(status_writer).flatten();
    let tty = (std::io::stdout().is_terminal(), terminal);
    let reason = rt.block_on(async {
        let mut tasks = Vec::new();
        for s in &sockets {
            let sock = match s.socket.try_clone() {
                Ok(x) => x,
                Err(e) => return Err(RunError::Live(format!("UDP port {}: {e}", s.port))),
            };
            let q = Queue {
                tx: tx.clone(),
                byte_budget: QUEUE_BYTES,
                stats: stats.clone(),
            };
            tasks.push(tokio::spawn(udp::receive(sock, s.port, sources.clone(), q)));
        }
        drop(tx);
        // An embedding caller stops the run with its flag and keeps the process's signals.
        let stop = args.hooks.stop.clone();
        let mut sigterm = match &stop {
            Some(_) => None,
            None => match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
                Ok(s) => Some(s),
                Err(e) => return Err(RunError::Live(format!("installing the SIGTERM handler: {e}"))),
            },
        };
        // A closed SSH session ends a recording like SIGTERM: by default it killed the process
        // with the MCAP unfinished.
        let mut sighup = match &stop {
            Some(_) => None,
            None => match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::hangup()) {
                Ok(s) => Some(s),
                Err(e) => return Err(RunError::Live(format!("installing the SIGHUP handler: {e}"))),
            },
        };
        let mut stop_tick = tokio::time::interval(Duration::from_millis(100));
        // The CLI bounds --duration, the library's callers (Python) need not: `Instant + d`
        // panicked past the clock's range, which is no deadline anyway.
        let deadline = args.duration.and_then(|d| tokio::time::Instant::now().checked_add(d));
        let mut tick = tokio::time::interval(Duration::from_secs(1));
        let mut prev = (Instant::now(), 0, 0, 0);
        let api_port = args.api_port;
        let reason = loop {
            tokio::select! {
                _ = tokio::signal::ctrl_c(), if stop.is_none() => break "SIGINT",
                _ = async { match sigterm.as_mut() { Some(s) => { s.recv().await; } None => std::future::pending().await } } => break "SIGTERM",
                _ = async { match sighup.as_mut() { Some(s) => { s.recv().await; } None => std::future::pending().await } } => {
                    detach_from_terminal(tty);
                    break "SIGHUP";
                }
                _ = stop_tick.tick(), if stop.is_some() => {
                    if stop.as_ref().is_some_and(|s| s.load(Ordering::Relaxed)) {
                        break "stopped by the caller";
                    }
                }
                _ = async { match deadline { Some(d) => tokio::time::sleep_until(d).await, None => std::future::pending().await } } => break "duration reached",
                ev = ev_rx.recv() => match ev {
                    Some(Event::Fetch(addr)) => {
                        let ctl = ctl_tx.clone();
                        tokio::spawn(async move {
                            let at = SocketAddr::V4(SocketAddrV4::new(addr, api_port));
                            match udp::http_get(at, METADATA_PATH, Duration::from_secs(5)).await {
                                Ok(body) => {
                                    let _ = ctl.send(Control::Metadata(addr, format!("metadata-{addr}.json"), body));
                                }
                                Err(e) => tracing::warn!("sensor {addr}: {e}"),
                            }
                        });
                    }
                    Some(Event::Failed) | None => break "decode thread stopped",
                },
                _ = tick.tick() => {
                    if let Some((status, _)) = &status {
                        let serve = live_stats.as_deref().map(super::serve::status).unwrap_or_default();
                        let line = format!("{}{serve}", status_line(&live, &stats, kernel_drops(&sockets), &mut prev));
                        let _ = status.try_send(line);
                    }
                }
            }
        };
        for t in &tasks {
            t.abort();
        }
        for t in tasks {
            let _ = t.await;
        }
        Ok(reason)
    });
    drop(rt);
    // The last status line is out before the newline that ends it (and the summary after).
    if let Some((tx, writer)) = status {
        drop(tx);
        let _ = writer.join();
        let _ = writeln!(std::io::stderr());
    }
    let control = configured.map(super::livox_ctl::Configured::finish);
    // With the runtime gone, no sender of datagrams is left: the decode thread finishes its
    // file and ends. Wait for it even when the loop failed, so the process never exits with
    // the file half finished.
    let joined = decode.join();
    let reason = reason?;
    tracing::info!("stopping: {reason}");
    let result = match joined {
        Ok(r) => r?,
        Err(_) => return Err(RunError::Live("the decode thread panicked".into())),
    };
    let elapsed = started.elapsed().as_secs_f64();

    // Summary.
    let socket_json: Vec<Value> = sockets
        .iter()
        .zip(&kernel_base)
        .map(|(s, base)| {
            json!({
                "port": s.port,
                "recv_buffer_requested": s.requested_recv_buffer,
                "recv_buffer_granted": s.granted_recv_buffer,
                "kernel_drops": s.kernel_drops().map(|d| d.saturating_sub(*base)),
            })
        })
        .collect();
    let kernel: u64 = sockets
        .iter()
        .zip(&kernel_base)
        .filter_map(|(s, b)| s.kernel_drops().map(|d| d.saturating_sub(*b)))
        .sum();
    let queue_dropped = stats.queue_dropped.load(Ordering::Relaxed);
    let mut m = result.summary;
    if let Some(p) = m.get_mut("packets").and_then(Value::as_object_mut) {
        let d = p.get("dropped").and_then(Value::as_u64).unwrap_or(0);
        p.insert("dropped".into(), json!(d + queue_dropped + kernel));
    }
    m.insert("input".into(), json!("udp"));
    m.insert("stop".into(), json!(reason));
    m.insert(
        "receive".into(),
        json!({
            "datagrams": stats.datagrams.load(Ordering::Relaxed),
            "bytes": stats.bytes.load(Ordering::Relaxed),
            "other_source": stats.other_source.load(Ordering::Relaxed),
            "queue_dropped": queue_dropped,
            "sweeps_dropped": args.hooks.sweeps_dropped.load(Ordering::Relaxed),
            "queue_peak_bytes": stats.queued_bytes_peak.load(Ordering::Relaxed),
            "kernel_dropped": kernel,
            "errors": stats.errors.load(Ordering::Relaxed),
            "held_for_metadata": result.held.json(),
            "sockets": socket_json,
        }),
    );
    let sink_opts = listen_sink_options(args);
    let fields = fields_name(args.session.fields_all, args.fields_minimal);
    m.insert(
        "output".into(),
        match result.files.last() {
            Some((p, s)) => output_json(s, Some(p), &sink_opts, fields),
            None => Value::Null,
        },
    );
    m.insert(
        "files".into(),
        Value::Array(
            result
                .files
                .iter()
                .map(|(p, s)| output_json(s, Some(p), &sink_opts, fields))
                .collect(),
        ),
    );
    m.insert("elapsed_s".into(), json!(elapsed));
    if let Some(c) = control {
        m.insert("livox_control".into(), c);
    }
    let lost = result.lost + queue_dropped + kernel;
    Ok(ListenOutcome {
        json: Value::Object(m),
        lost,
        files: result.files,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_every_in_seconds_or_megabytes() {
        assert_eq!(parse_split("60"), Ok(Split::Seconds(60.0)));
        assert_eq!(parse_split("0.5s"), Ok(Split::Seconds(0.5)));
        assert_eq!(parse_split("500MB"), Ok(Split::Bytes(500_000_000)));
        assert_eq!(parse_split("2m"), Ok(Split::Bytes(2_000_000)));
        for bad in ["", "0", "-1", "abc", "nanMB", "infs"] {
            assert!(parse_split(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn sensor_with_or_without_port() {
        assert_eq!(
            parse_sensor("192.168.1.201"),
            Ok((Ipv4Addr::new(192, 168, 1, 201), None))
        );
        assert_eq!(
            parse_sensor("10.0.0.2:7502"),
            Ok((Ipv4Addr::new(10, 0, 0, 2), Some(7502)))
        );
        assert!(parse_sensor("10.0.0.2:99999").is_err());
        assert!(parse_sensor("sensor.local").is_err());
    }

    #[test]
    fn split_file_names() {
        let b = Path::new("/x/drive.mcap");
        assert_eq!(Files::path_for(b, None, 3), PathBuf::from("/x/drive.mcap"));
        assert_eq!(
            Files::path_for(b, Some(Split::Seconds(1.0)), 12),
            PathBuf::from("/x/drive_0012.mcap")
        );
    }

    #[test]
    fn held_datagrams_stay_within_their_budget_and_keep_their_order() {
        let mut h = Held::default();
        let (a, b) = (Ipv4Addr::new(10, 0, 0, 1), Ipv4Addr::new(10, 0, 0, 2));
        let dgram = |addr: Ipv4Addr, k: u32| Received {
            time_ns: i64::from(k),
            src: SocketAddrV4::new(addr, 7502),
            port: 7502,
            payload: vec![0; 8192],
        };
        // 20 MiB from `a` (2560 datagrams), then 100 from `b`.
        for k in 0..2560 {
            h.hold(dgram(a, k));
        }
        for k in 0..100 {
            h.hold(dgram(b, k));
        }
        let cap = HOLD_BYTES / 8192;
        assert!(h.bytes <= HOLD_BYTES);
        assert_eq!(h.held, 2660);
        // Only the sensor holding most gave way: its oldest datagrams.
        assert_eq!(h.evicted, 2660 - cap as u64);
        let qb = h.take(b);
        assert_eq!(qb.len(), 100);
        let qa = h.take(a);
        assert_eq!(qa.len(), cap - 100);
        assert!(qa
            .iter()
            .zip(qa.iter().skip(1))
            .all(|(x, y)| x.time_ns + 1 == y.time_ns));
        assert_eq!(qa.back().map(|r| r.time_ns), Some(2559));
        assert_eq!(h.bytes, 0);
        assert_eq!(h.json()["left"], 0);
    }
}
