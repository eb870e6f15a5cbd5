//! `ringscan._ringscan`: the native half of the Python package. Thin: every decision (input
//! kinds, sensor detection, calibrations, sweep cutting, summaries, error messages) is the
//! library's and the command line's; this file moves sweeps across threads and into Python.
//!
//! Decoding runs on a thread of its own, which owns the reader (the session is not `Send`), and
//! hands sweeps over a bounded channel: the GIL is released while Python waits, memory stays
//! bounded whatever the capture's size, and Python's work on one sweep overlaps the decoding of
//! the next.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, SyncSender};
use std::sync::{Arc, Mutex, TryLockError};
use std::time::Duration;

use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyRuntimeError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use ringscan::cli::bag_args::BagArgs;
use ringscan::cli::run::{decode_capture, DecodeArgs, RunError, SweepReader};
use ringscan::cli::session::{BufferPool, SessionOptions};
use ringscan::point::{interleave_extended, Point, EXTENDED_STRIDE, POINT_STRIDE};

mod compat;
mod stream;

create_exception!(
    _ringscan,
    RingscanError,
    PyException,
    "Base of every ringscan error."
);
create_exception!(
    _ringscan,
    UsageError,
    RingscanError,
    "Bad options (the command line's exit code 2)."
);
create_exception!(
    _ringscan,
    InputError,
    RingscanError,
    "The capture or bag could not be read."
);
create_exception!(
    _ringscan,
    CalibrationError,
    RingscanError,
    "A calibration file could not be used."
);
create_exception!(
    _ringscan,
    DecodeError,
    RingscanError,
    "A sensor's stream could not be decoded, or the output could not be written."
);

/// Sweeps held between the decoding thread and Python.
const QUEUE: usize = 4;

/// How an error crosses the thread: its class and the command line's message.
#[derive(Clone, Copy, Debug)]
pub(crate) enum ErrKind {
    Usage,
    Input,
    Calib,
    Decode,
}

pub(crate) fn kind_of(e: &RunError) -> ErrKind {
    match e {
        RunError::Usage(_) => ErrKind::Usage,
        RunError::Source { .. } => ErrKind::Input,
        RunError::Calib { .. } => ErrKind::Calib,
        RunError::Kept { err, .. } => kind_of(err),
        _ => ErrKind::Decode,
    }
}

pub(crate) fn to_py_err(kind: ErrKind, msg: String) -> PyErr {
    match kind {
        ErrKind::Usage => UsageError::new_err(msg),
        ErrKind::Input => InputError::new_err(msg),
        ErrKind::Calib => CalibrationError::new_err(msg),
        ErrKind::Decode => DecodeError::new_err(msg),
    }
}

/// A block of memory numpy views without copying (`__array_interface__`): the array keeps
/// this object alive, and nothing in Rust touches the memory once it is handed out.
#[pyclass(module = "ringscan._ringscan", frozen)]
pub struct Buffer {
    data: BufData,
    len: usize,
    typestr: &'static str,
    /// Where the points or columns go back when numpy lets go of them (a reader's sweeps).
    pool: Option<Arc<BufferPool>>,
}

impl Drop for Buffer {
    fn drop(&mut self) {
        let Some(pool) = self.pool.take() else {
            return;
        };
        match std::mem::replace(&mut self.data, BufData::Bytes(Vec::new())) {
            BufData::Points(v) => pool.give_points(v),
            BufData::U32(v) => pool.give_columns(v),
            _ => {}
        }
    }
}

enum BufData {
    Points(Vec<Point>),
    Bytes(Vec<u8>),
    U32(Vec<u32>),
    F32(Vec<f32>),
}

impl Buffer {
    pub(crate) fn points(p: Vec<Point>) -> Self {
        Self {
            len: p.len(),
            data: BufData::Points(p),
            typestr: "|V24",
            pool: None,
        }
    }

    /// The buffer given back to `pool` once numpy has let go of it.
    pub(crate) fn returning_to(mut self, pool: Option<&Arc<BufferPool>>) -> Self {
        self.pool = pool.cloned();
        self
    }

    fn records(bytes: Vec<u8>, stride: usize, typestr: &'static str) -> Self {
        Self {
            len: bytes.len() / stride.max(1),
            data: BufData::Bytes(bytes),
            typestr,
            pool: None,
        }
    }

    pub(crate) fn u32s(v: Vec<u32>) -> Self {
        Self {
            len: v.len(),
            data: BufData::U32(v),
            typestr: "<u4",
            pool: None,
        }
    }

    pub(crate) fn f32s(v: Vec<f32>) -> Self {
        Self {
            len: v.len(),
            data: BufData::F32(v),
            typestr: "<f4",
            pool: None,
        }
    }

    fn address(&self) -> usize {
        match &self.data {
            BufData::Points(v) => v.as_ptr() as usize,
            BufData::Bytes(v) => v.as_ptr() as usize,
            BufData::U32(v) => v.as_ptr() as usize,
            BufData::F32(v) => v.as_ptr() as usize,
        }
    }
}

#[pymethods]
impl Buffer {
    /// The numpy array interface (version 3): one-dimensional, `len` records.
    #[getter]
    fn __array_interface__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("version", 3)?;
        d.set_item("shape", (self.len,))?;
        d.set_item("typestr", self.typestr)?;
        // An empty vector's pointer is dangling but non-null and never read: numpy accepts it.
        d.set_item("data", (self.address(), false))?;
        Ok(d)
    }

    fn __len__(&self) -> usize {
        self.len
    }
}

/// One decoded sweep as the native module hands it out; `ringscan.Sweep` wraps it.
#[pyclass(module = "ringscan._ringscan", frozen, get_all)]
pub struct RawSweep {
    index: u64,
    timestamp_ns: i64,
    clock: &'static str,
    device_time_ns: i64,
    first_host_ns: i64,
    last_host_ns: i64,
    packets: u32,
    missing_packets: u64,
    missing_columns: u64,
    frame_id: u32,
    columns_count: u32,
    first_azimuth_cdeg: u16,
    sensor: String,
    sensor_index: usize,
    family: &'static str,
    address: String,
    channels: Option<usize>,
    /// `Point` records (24 bytes), or `Point` + `PointExtra` records (48 bytes) with extras.
    points: Py<Buffer>,
    /// Whether `points` holds the extended records.
    extended: bool,
    /// Each point's firing column, when kept (organised sensors), else `None`.
    columns: Option<Py<Buffer>>,
}

/// What a decoding thread sends: items, then its end (with the summary) or its error.
pub(crate) enum Msg<T> {
    Item(T),
    End(String),
    Error(ErrKind, String),
}

/// A sweep and its sensor, from the reader's thread.
type SweepMsg = Box<(
    ringscan::cli::session::ReadSweep,
    Option<ringscan::cli::session::SensorDesc>,
)>;

/// The receiving end of a thread's channel, shared by the Python threads that hold its
/// object. `recv` waits with the GIL released but holds the lock, and must re-take the GIL
/// before it lets go of it: so no other caller may wait for the lock while holding the GIL
/// (both would hang). A second `next()` is refused, and `close()` only sets a flag when the
/// lock is busy; the waiting `recv` sees it within its 100 ms poll.
pub(crate) struct Inbox<T> {
    rx: Mutex<Option<Receiver<T>>>,
    closed: AtomicBool,
    /// Set when Ctrl-C interrupts a wait: a listener's sockets stop with its consumer.
    stop_on_interrupt: Option<Arc<AtomicBool>>,
}

/// What [`Inbox::recv`] got.
pub(crate) enum Recv<T> {
    Msg(T),
    /// The inbox was closed, or had already ended.
    Finished,
    /// Every sender is gone (the thread ended); the inbox is now finished.
    Disconnected,
}

impl<T: Send> Inbox<T> {
    pub(crate) fn new(rx: Receiver<T>) -> Self {
        Self {
            rx: Mutex::new(Some(rx)),
            closed: AtomicBool::new(false),
            stop_on_interrupt: None,
        }
    }

    pub(crate) fn stopping_on_interrupt(mut self, stop: Arc<AtomicBool>) -> Self {
        self.stop_on_interrupt = Some(stop);
        self
    }

    /// Waits for the next message with the GIL released, waking up to let Ctrl-C through.
    /// The receiver moves into the wait and back (it is `Send`, not `Sync`).
    pub(crate) fn recv(&self, py: Python<'_>, what: &str) -> PyResult<Recv<T>> {
        let mut guard = match self.rx.try_lock() {
            Ok(g) => g,
            // Only a panic inside `recv` poisons it, and the slot is still consistent.
            Err(TryLockError::Poisoned(p)) => p.into_inner(),
            Err(TryLockError::WouldBlock) => {
                return Err(PyRuntimeError::new_err(format!(
                    "{what}: next() is already waiting on another thread; iterate it from one thread at a time"
                )))
            }
        };
        loop {
            if self.closed.load(Ordering::Acquire) {
                *guard = None;
            }
            let Some(rx) = guard.take() else {
                return Ok(Recv::Finished);
            };
            let (rx, got) = py.allow_threads(move || {
                let got = rx.recv_timeout(Duration::from_millis(100));
                (rx, got)
            });
            match got {
                Ok(m) if !self.closed.load(Ordering::Acquire) => {
                    *guard = Some(rx);
                    return Ok(Recv::Msg(m));
                }
                Ok(_) => return Ok(Recv::Finished),
                Err(RecvTimeoutError::Timeout) => {
                    *guard = Some(rx);
                    if let Err(e) = py.check_signals() {
                        if let Some(stop) = &self.stop_on_interrupt {
                            stop.store(true, Ordering::Relaxed);
                        }
                        return Err(e);
                    }
                }
                Err(RecvTimeoutError::Disconnected) => return Ok(Recv::Disconnected),
            }
        }
    }

    /// Ends the inbox without waiting: dropping the receiver tells the thread to stop.
    pub(crate) fn close(&self) {
        self.closed.store(true, Ordering::Release);
        match self.rx.try_lock() {
            Ok(mut g) => *g = None,
            Err(TryLockError::Poisoned(p)) => *p.into_inner() = None,
            // A `recv` in progress drops it at its next poll.
            Err(TryLockError::WouldBlock) => {}
        }
    }
}

/// The next item from a decoding thread: `None` at its end (the summary kept in `summary`)
/// or once closed, its error raised; the channel is closed after either.
pub(crate) fn next_item<T: Send>(
    py: Python<'_>,
    inbox: &Inbox<Msg<T>>,
    summary: Option<&Mutex<Option<String>>>,
) -> PyResult<Option<T>> {
    match inbox.recv(py, "the reader")? {
        Recv::Msg(Msg::Item(t)) => Ok(Some(t)),
        Recv::Msg(Msg::End(s)) => {
            inbox.close();
            if let Some(Ok(mut slot)) = summary.map(Mutex::lock) {
                *slot = Some(s);
            }
            Ok(None)
        }
        Recv::Msg(Msg::Error(kind, msg)) => {
            inbox.close();
            Err(to_py_err(kind, msg))
        }
        Recv::Finished => Ok(None),
        Recv::Disconnected => Err(PyRuntimeError::new_err(
            "the decoding thread stopped without an answer (a bug: please report it)",
        )),
    }
}

pub(crate) fn raw_sweep(
    py: Python<'_>,
    rs: ringscan::cli::session::ReadSweep,
    desc: Option<ringscan::cli::session::SensorDesc>,
    pool: Option<&Arc<BufferPool>>,
) -> PyResult<RawSweep> {
    let mut sw = rs.sweep;
    let extended = !sw.extras.is_empty() && sw.extras.len() == sw.points.len();
    let points = if extended {
        let mut bytes = Vec::new();
        interleave_extended(&sw.points, &sw.extras, &mut bytes);
        Buffer::records(bytes, EXTENDED_STRIDE, "|V48")
    } else {
        debug_assert_eq!(POINT_STRIDE, 24);
        Buffer::points(std::mem::take(&mut sw.points)).returning_to(pool)
    };
    let n = points.len;
    let columns = if sw.columns.len() == n && n > 0 {
        Some(Py::new(
            py,
            Buffer::u32s(std::mem::take(&mut sw.columns)).returning_to(pool),
        )?)
    } else {
        None
    };
    let desc = desc.unwrap_or(ringscan::cli::session::SensorDesc {
        name: String::new(),
        family: "",
        address: std::net::Ipv4Addr::UNSPECIFIED,
        channels: None,
    });
    Ok(RawSweep {
        index: sw.index,
        timestamp_ns: sw.timestamp_ns,
        clock: sw.clock.name(),
        device_time_ns: sw.device_time_ns,
        first_host_ns: sw.first_host_ns,
        last_host_ns: sw.last_host_ns,
        packets: sw.packets,
        missing_packets: sw.missing_packets,
        missing_columns: sw.missing_columns,
        frame_id: sw.frame_id,
        columns_count: sw.columns_count,
        first_azimuth_cdeg: sw.first_azimuth,
        sensor: desc.name,
        sensor_index: rs.sensor,
        family: desc.family,
        address: desc.address.to_string(),
        channels: desc.channels,
        points: Py::new(py, points)?,
        extended,
        columns,
    })
}

/// Decoding options shared by `Reader` and `info` (the command line's flags).
#[allow(clippy::too_many_arguments)]
pub(crate) fn decode_args(
    path: PathBuf,
    model: Option<String>,
    calib: Vec<String>,
    topics: Vec<String>,
    start: Option<f64>,
    end: Option<f64>,
    port: Option<u16>,
    cut_angle_deg: f64,
    min_range: Option<f32>,
    max_range: Option<f32>,
    fields_all: bool,
    crc: Option<bool>,
    dual_return_threshold_m: Option<f32>,
    fov_deg: Option<(f64, f64)>,
    integration_ms: Option<f64>,
) -> DecodeArgs {
    DecodeArgs {
        session: SessionOptions {
            model,
            calib,
            port,
            cut_angle_deg,
            min_range,
            max_range,
            fields_all,
            crc,
            dual_return_threshold_m,
            fov_deg,
            integration_ms,
            ..SessionOptions::default()
        },
        bag: BagArgs { topics, start, end },
        // One thread: a fleet runs one decoding thread per task.
        threads: 1,
        ..DecodeArgs::new(path)
    }
}

/// A capture or bag being decoded on a thread of its own.
#[pyclass(module = "ringscan._ringscan")]
pub struct Reader {
    inbox: Inbox<Msg<SweepMsg>>,
    summary: Mutex<Option<String>>,
    /// Where the sweeps' arrays go back for the decoding thread to reuse.
    pool: Arc<BufferPool>,
}

fn spawn_reader(args: DecodeArgs, pool: Arc<BufferPool>) -> PyResult<Receiver<Msg<SweepMsg>>> {
    let (tx, rx) = mpsc::sync_channel::<Msg<SweepMsg>>(QUEUE);
    std::thread::Builder::new()
        .name("ringscan-read".into())
        .spawn(move || read_thread(&args, pool, &tx))
        .map_err(|e| PyRuntimeError::new_err(format!("starting the decoding thread: {e}")))?;
    Ok(rx)
}

fn read_thread(args: &DecodeArgs, pool: Arc<BufferPool>, tx: &SyncSender<Msg<SweepMsg>>) {
    let mut reader = match SweepReader::open(args) {
        Ok(r) => r,
        Err(e) => {
            let _ = tx.send(Msg::Error(kind_of(&e), e.to_string()));
            return;
        }
    };
    reader.use_buffer_pool(pool);
    loop {
        let msg = match reader.next_sweep() {
            Ok(Some(rs)) => {
                let desc = reader.sensor(rs.sensor);
                Msg::Item(Box::new((rs, desc)))
            }
            Ok(None) => {
                let _ = tx.send(Msg::End(reader.summary().json.to_string()));
                return;
            }
            Err(e) => Msg::Error(kind_of(&e), e.to_string()),
        };
        let stop = matches!(msg, Msg::Error(..));
        // A closed channel: the Python side is gone; stop decoding.
        if tx.send(msg).is_err() || stop {
            return;
        }
    }
}

#[pymethods]
impl Reader {
    #[new]
    #[pyo3(signature = (path, model=None, calib=vec![], topics=vec![], start=None, end=None, port=None, cut_angle=0.0, min_range=None, max_range=None, fields_all=false, crc=None, dual_return_threshold=None, fov=None, integration_ms=None, keep_columns=true, read_ahead=false))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        path: PathBuf,
        model: Option<String>,
        calib: Vec<String>,
        topics: Vec<String>,
        start: Option<f64>,
        end: Option<f64>,
        port: Option<u16>,
        cut_angle: f64,
        min_range: Option<f32>,
        max_range: Option<f32>,
        fields_all: bool,
        crc: Option<bool>,
        dual_return_threshold: Option<f32>,
        fov: Option<(f64, f64)>,
        integration_ms: Option<f64>,
        keep_columns: bool,
        read_ahead: bool,
    ) -> PyResult<Self> {
        let mut args = decode_args(
            path,
            model,
            calib,
            topics,
            start,
            end,
            port,
            cut_angle,
            min_range,
            max_range,
            fields_all,
            crc,
            dual_return_threshold,
            fov,
            integration_ms,
        );
        args.session.keep_columns = keep_columns;
        args.read_ahead = read_ahead;
        let pool = Arc::new(BufferPool::default());
        Ok(Self {
            inbox: Inbox::new(spawn_reader(args, Arc::clone(&pool))?),
            summary: Mutex::new(None),
            pool,
        })
    }

    /// The next sweep, or `None` at the end; raises the decoding error, if any.
    fn next(&self, py: Python<'_>) -> PyResult<Option<RawSweep>> {
        match next_item(py, &self.inbox, Some(&self.summary))? {
            Some(b) => {
                let (rs, desc) = *b;
                Ok(Some(raw_sweep(py, rs, desc, Some(&self.pool))?))
            }
            None => Ok(None),
        }
    }

    /// The `--json` summary (a JSON string) once the reader reached the end, else `None`.
    fn summary(&self) -> Option<String> {
        self.summary.lock().ok().and_then(|s| s.clone())
    }

    /// Stops decoding (the thread ends at its next sweep); a `next()` waiting on another
    /// thread returns `None` within 100 ms.
    fn close(&self) {
        self.inbox.close();
    }
}

/// `ringscan info --json` on a capture or bag, as a JSON string.
#[pyfunction]
#[pyo3(signature = (path, model=None, calib=vec![], topics=vec![], start=None, end=None))]
fn info(
    py: Python<'_>,
    path: PathBuf,
    model: Option<String>,
    calib: Vec<String>,
    topics: Vec<String>,
    start: Option<f64>,
    end: Option<f64>,
) -> PyResult<String> {
    let mut args = decode_args(
        path, model, calib, topics, start, end, None, 0.0, None, None, false, None, None, None,
        None,
    );
    // As `ringscan info`: a sensor without the calibration its points need is still read.
    args.session.inspect = true;
    run_decode(py, &args)
}

/// `ringscan decode --json` of a capture or bag into an MCAP file `out` (or no file), as a
/// JSON string: the fleet's per-capture output. Takes `Reader`'s decoding options, so an MCAP
/// holds the points a `Reader` with the same options gives.
#[pyfunction]
#[pyo3(signature = (path, out=None, model=None, calib=vec![], topics=vec![], threads=1, start=None, end=None, port=None, cut_angle=0.0, min_range=None, max_range=None, fields_all=false, crc=None, dual_return_threshold=None, fov=None, integration_ms=None, read_ahead=false))]
#[allow(clippy::too_many_arguments)]
fn decode(
    py: Python<'_>,
    path: PathBuf,
    out: Option<PathBuf>,
    model: Option<String>,
    calib: Vec<String>,
    topics: Vec<String>,
    threads: usize,
    start: Option<f64>,
    end: Option<f64>,
    port: Option<u16>,
    cut_angle: f64,
    min_range: Option<f32>,
    max_range: Option<f32>,
    fields_all: bool,
    crc: Option<bool>,
    dual_return_threshold: Option<f32>,
    fov: Option<(f64, f64)>,
    integration_ms: Option<f64>,
    read_ahead: bool,
) -> PyResult<String> {
    let mut args = decode_args(
        path,
        model,
        calib,
        topics,
        start,
        end,
        port,
        cut_angle,
        min_range,
        max_range,
        fields_all,
        crc,
        dual_return_threshold,
        fov,
        integration_ms,
    );
    args.out = out;
    args.threads = threads.max(1);
    args.read_ahead = read_ahead;
    run_decode(py, &args)
}

/// A whole decode without the GIL; its summary as a JSON string.
fn run_decode(py: Python<'_>, args: &DecodeArgs) -> PyResult<String> {
    py.allow_threads(|| decode_capture(args).map_err(|e| (kind_of(&e), e.to_string())))
        .map(|s| s.json.to_string())
        .map_err(|(k, m)| to_py_err(k, m))
}

/// Runs the command line with `argv` (program name first); returns its exit code.
#[pyfunction]
fn cli_main(py: Python<'_>, argv: Vec<String>) -> u8 {
    py.allow_threads(|| ringscan::cli::run(argv))
}

/// The library's version.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

#[pymodule]
fn _ringscan(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("RingscanError", py.get_type::<RingscanError>())?;
    m.add("UsageError", py.get_type::<UsageError>())?;
    m.add("InputError", py.get_type::<InputError>())?;
    m.add("CalibrationError", py.get_type::<CalibrationError>())?;
    m.add("DecodeError", py.get_type::<DecodeError>())?;
    m.add_class::<Buffer>()?;
    m.add_class::<RawSweep>()?;
    m.add_class::<Reader>()?;
    m.add_function(wrap_pyfunction!(info, m)?)?;
    m.add_function(wrap_pyfunction!(cli_main, m)?)?;
    m.add_function(wrap_pyfunction!(decode, m)?)?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    compat::register(m)?;
    stream::register(m)?;
    Ok(())
}
