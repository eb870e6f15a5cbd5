//! `ringscan.compat.read_pcap`: velodyne_decoder 3.1.0's `read_pcap` output from ringscan's
//! Velodyne decoder. Its frame splitting (described in ../shared/captures/golden/README.md and
//! velodyne_decoder's `ScanBatcher`): a frame starts at its first packet's azimuth, not at a cut
//! angle, and ends with the packet whose last block wraps past that azimuth after more than
//! half a turn; a packet more than 0.3 s (capture time) after the frame's first one starts the
//! next frame. Its record: 8 float32 per point, `x, y, z, intensity, time, column, ring,
//! return_type` (time in s relative to the frame's stamp, return type 1 strongest, 2 last,
//! 3 both; with an advanced calibration, the HDL-64E's, intensity is the focal correction of
//! the raw one, as velodyne_decoder's `unpackPoint` gives it).

use std::path::PathBuf;
use std::sync::mpsc::{self, SyncSender};

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;

use ringscan::sensor::velodyne::calib::builtin::builtin;
use ringscan::sensor::velodyne::calib::parse_velodyne;
use ringscan::sensor::velodyne::decode::{corrected_intensity, ColumnRate};
use ringscan::sensor::velodyne::model::{BLOCKS, DATA_PACKET_LEN};
use ringscan::sensor::velodyne::wire::DataPacket;
use ringscan::sensor::velodyne::{ReturnMode, VelodyneCalibration, VelodyneDecoder, VelodyneModel};
use ringscan::sensor::DecodeOptions;
use ringscan::source::bag::BagOptions;
use ringscan::time::complete_toh;

use crate::{next_item, to_py_err, Buffer, ErrKind, Inbox, Msg};

/// The longest a frame may last (capture time), velodyne_decoder's constant.
const MAX_FRAME_NS: i64 = 300_000_000;
/// Frames held between the decoding thread and Python.
const QUEUE: usize = 2;

struct Settings {
    path: PathBuf,
    model: Option<VelodyneModel>,
    calib: Option<PathBuf>,
    opts: DecodeOptions,
    /// Cut angle, 0.01°; `None`: at the first packet's azimuth.
    cut: Option<i32>,
    stamp_first: bool,
    /// `min_angle` / `max_angle`, 0.01°; `None`: the full turn.
    window: Option<(u16, u16)>,
    /// `time_range`: packets captured before the start are skipped, the first after the end
    /// stops reading (velodyne_decoder's `iter_pcap`), seconds.
    time_range: (Option<f64>, Option<f64>),
}

/// One frame: its stamp (host, device seconds) and records.
struct Frame {
    host_s: f64,
    device_s: f64,
    data: Vec<f32>,
    n: usize,
}

/// A packet kept for its frame: capture time and bytes.
struct Held {
    host_ns: i64,
    bytes: Box<[u8; DATA_PACKET_LEN]>,
}

fn last_azimuth(p: &Held) -> i32 {
    let o = (BLOCKS - 1) * 100 + 2;
    i32::from(u16::from_le_bytes([p.bytes[o], p.bytes[o + 1]]))
}

/// The packet's own time: its top-of-hour µs completed with the capture time's hour.
fn device_ns(p: &Held) -> i64 {
    let toh = u32::from_le_bytes([p.bytes[1200], p.bytes[1201], p.bytes[1202], p.bytes[1203]]);
    complete_toh(toh, p.host_ns)
}

/// velodyne_decoder's scan batcher.
struct Batcher {
    packets: Vec<Held>,
    initial: i32,
    coverage: i32,
    cut: Option<i32>,
}

impl Batcher {
    /// Adds a packet; returns the finished frame when this packet ends it (the packet is in
    /// it) or starts the next one (the packet is not).
    fn push(&mut self, p: Held) -> Option<Vec<Held>> {
        let az = last_azimuth(&p);
        if self.initial < 0 {
            self.initial = az;
        }
        if let Some(first) = self.packets.first() {
            if p.host_ns - first.host_ns > MAX_FRAME_NS {
                let done = self.restart();
                self.push_fresh(p);
                return Some(done);
            }
        }
        self.packets.push(p);
        let cov = (az - self.initial).rem_euclid(36_000);
        let complete = self.coverage > 18_000 && self.coverage > cov;
        self.coverage = cov;
        complete.then(|| self.restart())
    }

    fn push_fresh(&mut self, p: Held) {
        // A frame's first packet cannot end it: its coverage is 0.
        let az = last_azimuth(&p);
        if self.initial < 0 {
            self.initial = az;
        }
        self.coverage = (az - self.initial).rem_euclid(36_000);
        self.packets.push(p);
    }

    /// Takes the frame; the next starts at the last packet's azimuth (or the cut angle).
    fn restart(&mut self) -> Vec<Held> {
        self.initial = match (self.cut, self.packets.last()) {
            (Some(c), _) => c,
            (None, Some(p)) => last_azimuth(p),
            (None, None) => -1,
        };
        self.coverage = 0;
        std::mem::take(&mut self.packets)
    }
}

/// Decodes one frame into velodyne_decoder's records.
struct FrameDecoder {
    model: VelodyneModel,
    /// Laser index of each ring (the calibration's elevation order).
    laser_of_ring: Vec<usize>,
    calib: VelodyneCalibration,
    opts: DecodeOptions,
    decoders: Vec<(ReturnMode, VelodyneDecoder)>,
    /// Rotation rate of one-column packets (VLS-128 dual), from the packet before, across
    /// frames as velodyne_decoder keeps it.
    column_rate: ColumnRate,
    stamp_first: bool,
    window: Option<(u16, u16)>,
}

impl FrameDecoder {
    fn decoder(&mut self, mode: ReturnMode) -> Result<&VelodyneDecoder, String> {
        if let Some(i) = self.decoders.iter().position(|(m, _)| *m == mode) {
            return Ok(&self.decoders[i].1);
        }
        let d = VelodyneDecoder::new(self.model, mode, &self.calib, self.opts)
            .map_err(|e| e.to_string())?;
        self.decoders.push((mode, d));
        Ok(&self.decoders[self.decoders.len() - 1].1)
    }

    fn frame(&mut self, packets: &[Held]) -> Result<Option<Frame>, String> {
        let (Some(first), Some(last)) = (packets.first(), packets.last()) else {
            return Ok(None);
        };
        let stamp = if self.stamp_first { first } else { last };
        let (stamp_host, stamp_dev) = (stamp.host_ns, device_ns(stamp));
        let mut data: Vec<f32> = Vec::with_capacity(packets.len() * 384 * 8);
        // velodyne_decoder numbers a packet's columns from the last emitted point's + 1.
        let mut next_col: i64 = 0;
        let mut slot_seen: Vec<(usize, u16, usize)> = Vec::new();
        for p in packets {
            // The HDL-64E has no return-mode byte (bytes 1204-1205 are its status cycle):
            // velodyne_decoder takes two blocks of one azimuth as dual return, and so does this.
            let mode = if self.model.is_hdl64() {
                let az = |b: usize| [p.bytes[b * 100 + 2], p.bytes[b * 100 + 3]];
                if az(0) == az(2) {
                    ReturnMode::Dual
                } else {
                    ReturnMode::Strongest
                }
            } else {
                match ReturnMode::from_byte(p.bytes[1204]) {
                    Some(m) => m,
                    None => continue,
                }
            };
            let Ok(packet) = DataPacket::new(&p.bytes[..]) else {
                continue;
            };
            let dt_s = (device_ns(p) - stamp_dev) as f64 * 1e-9;
            let dual = mode.is_dual();
            self.decoder(mode)?;
            let Some(decoder) = self
                .decoders
                .iter()
                .find(|(m, _)| *m == mode)
                .map(|(_, d)| d)
            else {
                continue;
            };
            let base = next_col;
            let start = data.len();
            slot_seen.clear();
            let mut last_col = None;
            let window = self
                .window
                .map(|w| Window::new(w, self.model, mode, &packet));
            let laser_of_ring = &self.laser_of_ring;
            let (model, calib, bytes) = (self.model, &self.calib, &p.bytes[..]);
            let rate = self.column_rate.next(decoder, &packet);
            decoder.decode_with_rate(&packet, 0..BLOCKS, 0, rate, |pt, col| {
                let laser = laser_of_ring
                    .get(usize::from(pt.ring))
                    .copied()
                    .unwrap_or(0);
                if let Some(w) = &window {
                    if !w.keeps(&packet, col, laser, pt.t) {
                        return;
                    }
                }
                let intensity = if calib.advanced {
                    advanced_intensity(model, calib, bytes, dual, col, laser, pt.ret, pt.intensity)
                } else {
                    pt.intensity
                };
                let ret_type = if pt.ret == 0 { 1.0 } else { 2.0 };
                if dual {
                    slot_seen.push((col, pt.ring, data.len()));
                }
                data.extend_from_slice(&[
                    pt.x,
                    pt.y,
                    pt.z,
                    intensity,
                    (dt_s + f64::from(pt.t) * 1e-9) as f32,
                    (base + col as i64) as f32,
                    f32::from(pt.ring),
                    ret_type,
                ]);
                last_col = Some(base + col as i64);
            });
            if dual {
                // One point for a firing whose two returns were equal: "both" (3).
                mark_both(
                    &mut data[start..],
                    &slot_seen,
                    start,
                    &p.bytes[..],
                    &self.laser_of_ring,
                    self.model,
                );
            }
            if let Some(c) = last_col {
                next_col = c + 1;
            }
        }
        let n = data.len() / 8;
        Ok(Some(Frame {
            host_s: stamp_host as f64 * 1e-9,
            device_s: stamp_dev as f64 * 1e-9,
            data,
            n,
        }))
    }
}

/// Nanoseconds as velodyne_decoder's float seconds.
fn secs(ns: f64) -> f32 {
    (ns * 1e-9) as f32
}

/// velodyne_decoder's azimuth window (`min_angle` / `max_angle`), tested per point on the
/// azimuth its `PacketDecoder` tests: for the VLP-16, Puck Hi-Res, VLP-32C and HDL-32E the
/// firing's azimuth (its block's azimuth + the packet's mean rotation rate × the firing's
/// delay after the block's first firing, rounded to 0.01°), for the HDL-64E and VLS-128 the
/// azimuth of the block that holds the point. Bounds are inclusive; when `min > max`,
/// velodyne_decoder keeps `max ≤ azimuth ≤ min`, and so does this.
struct Window {
    min: u16,
    max: u16,
    model: VelodyneModel,
    mode: ReturnMode,
    /// 0.01° per s (16/32-beam models).
    rate: f32,
}

impl Window {
    fn new(
        (min, max): (u16, u16),
        model: VelodyneModel,
        mode: ReturnMode,
        p: &DataPacket<'_>,
    ) -> Self {
        // In velodyne_decoder's units and precision: float seconds from its timing table.
        let diff = (i32::from(p.azimuth(BLOCKS - 1)) - i32::from(p.azimuth(0))).rem_euclid(36_000);
        let duration = secs(model.firing(mode, BLOCKS - 1, 0).0) - secs(model.firing(mode, 0, 0).0);
        let rate = if duration > 0.0 {
            diff as f32 / duration
        } else {
            0.0
        };
        Self {
            min,
            max,
            model,
            mode,
            rate,
        }
    }

    fn contains(&self, az: u16) -> bool {
        if self.min <= self.max {
            az >= self.min && az <= self.max
        } else {
            az <= self.min && az >= self.max
        }
    }

    /// Whether the point of firing column `col` (in the packet), laser `laser` and firing
    /// time `t_ns` (after the packet's first firing) is inside the window.
    fn keeps(&self, p: &DataPacket<'_>, col: usize, laser: usize, t_ns: u32) -> bool {
        // The block that holds the point; in dual return, the first of its pair.
        let block = if self.mode.is_dual() {
            let (last, strongest, _) = dual_pair(self.model, col, laser);
            last.min(strongest)
        } else {
            single_slot(self.model, col, laser).0
        };
        if block >= BLOCKS {
            return false;
        }
        let block_az = p.azimuth(block);
        let az = match self.model {
            VelodyneModel::Hdl64eS2 | VelodyneModel::Hdl64eS3 | VelodyneModel::Vls128 => block_az,
            _ => {
                let dt = secs(f64::from(t_ns)) - secs(self.model.firing(self.mode, block, 0).0);
                let a = f32::from(block_az) + self.rate * dt;
                ((a + 36_000.0).round() as i64).rem_euclid(36_000) as u16
            }
        };
        self.contains(az)
    }
}

/// The blocks holding the last and the strongest return of laser `laser` in firing column
/// `col` of a dual-return packet, and the laser's slot in them (velodyne_decoder 3.1.0's
/// pairing, from the manuals' dual-return layouts): VLP-16 / 32-laser models, blocks `2k`
/// (last) and `2k + 1` (strongest); HDL-64E, the strongest in block `4c + bank` and the last two
/// blocks later (upper, lower, upper, lower); VLS-128, one column a packet, bank `b`'s last in
/// block `2b` and its strongest in `2b + 1`.
fn dual_pair(model: VelodyneModel, col: usize, laser: usize) -> (usize, usize, usize) {
    match model {
        VelodyneModel::Hdl64eS2 | VelodyneModel::Hdl64eS3 => {
            let strongest = 4 * col + laser / 32;
            (strongest + 2, strongest, laser % 32)
        }
        VelodyneModel::Vls128 => (2 * (laser / 32), 2 * (laser / 32) + 1, laser % 32),
        _ => {
            let lasers = model.lasers().max(1);
            let firings = (32 / lasers).max(1);
            let (pair, seq) = (col / firings, col % firings);
            (2 * pair, 2 * pair + 1, seq * lasers + laser)
        }
    }
}

/// The block and slot of laser `laser`'s measurement in firing column `col` of a
/// single-return packet: VLP-16 two firings a block, 32-laser models one, HDL-64E an upper and
/// a lower block a column, VLS-128 four banks a column.
fn single_slot(model: VelodyneModel, col: usize, laser: usize) -> (usize, usize) {
    match model {
        VelodyneModel::Hdl64eS2 | VelodyneModel::Hdl64eS3 => (2 * col + laser / 32, laser % 32),
        VelodyneModel::Vls128 => (4 * col + laser / 32, laser % 32),
        _ => {
            let lasers = model.lasers().max(1);
            let firings = (32 / lasers).max(1);
            (col / firings, (col % firings) * lasers + laser)
        }
    }
}

/// velodyne_decoder's intensity with an advanced calibration (the HDL-64E's): the focal
/// formula on the point's raw reflectivity and raw distance ([`corrected_intensity`]), read
/// from the block and slot that hold the point (`ret` 0: the strongest or only return).
#[allow(clippy::too_many_arguments)]
fn advanced_intensity(
    model: VelodyneModel,
    calib: &VelodyneCalibration,
    bytes: &[u8],
    dual: bool,
    col: usize,
    laser: usize,
    ret: u8,
    raw_intensity: f32,
) -> f32 {
    let (block, slot) = if dual {
        let (last, strongest, slot) = dual_pair(model, col, laser);
        (if ret == 0 { strongest } else { last }, slot)
    } else {
        single_slot(model, col, laser)
    };
    let o = block * 100 + 4 + slot * 3;
    match (bytes.get(o..o + 2), calib.lasers.get(laser)) {
        (Some(d), Some(l)) => {
            corrected_intensity(l, raw_intensity as u8, u16::from_le_bytes([d[0], d[1]]))
        }
        _ => raw_intensity,
    }
}

/// Sets return type 3 on the points of a dual packet whose firing had equal last and
/// strongest distances (the decoder then gives one point, the strongest's, as
/// velodyne_decoder does).
fn mark_both(
    records: &mut [f32],
    seen: &[(usize, u16, usize)],
    start: usize,
    bytes: &[u8],
    laser_of_ring: &[usize],
    model: VelodyneModel,
) {
    for &(col, ring, at) in seen {
        let Some(&laser) = laser_of_ring.get(usize::from(ring)) else {
            continue;
        };
        let (last_block, strongest_block, slot) = dual_pair(model, col, laser);
        let at_block = |b: usize| {
            let o = b * 100 + 4 + slot * 3;
            bytes.get(o..o + 2)
        };
        let (last, strongest) = (at_block(last_block), at_block(strongest_block));
        if last.is_some() && last == strongest {
            if let Some(v) = records.get_mut(at - start + 7) {
                *v = 3.0;
            }
        }
    }
}

fn run(s: &Settings, tx: &SyncSender<Msg<Frame>>) -> Result<(), (ErrKind, String)> {
    let path_s = s.path.display().to_string();
    let input = ringscan::source::input::open(&s.path, BagOptions::default())
        .map_err(|e| (ErrKind::Input, format!("{path_s}: {e}")))?;
    if input.bag().is_some() {
        return Err((
            ErrKind::Usage,
            format!("{path_s}: read_pcap reads pcap captures; open bags with ringscan.open"),
        ));
    }
    let mut input = input;
    let calib = match &s.calib {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .map_err(|e| (ErrKind::Calib, format!("calibration {}: {e}", p.display())))?;
            Some(
                parse_velodyne(&text, &p.display().to_string())
                    .map_err(|e| (ErrKind::Calib, format!("calibration {}: {e}", p.display())))?,
            )
        }
        None => None,
    };
    let mut batcher = Batcher {
        packets: Vec::new(),
        initial: s.cut.unwrap_or(-1),
        coverage: 0,
        cut: s.cut,
    };
    let mut dec: Option<FrameDecoder> = None;
    let mut emit = |packets: Vec<Held>, first: &[u8]| -> Result<bool, (ErrKind, String)> {
        if dec.is_none() {
            let model = match s.model.or_else(|| VelodyneModel::from_product_id(first[1205])) {
                Some(m) => m,
                None => {
                    return Err((
                        ErrKind::Usage,
                        format!(
                            "{path_s}: the packets' product byte 0x{:02x} names no model: set config.model",
                            first[1205]
                        ),
                    ))
                }
            };
            let calib = match calib.clone().or_else(|| builtin(model)) {
                Some(c) => c,
                None => {
                    return Err((
                        ErrKind::Calib,
                        format!(
                            "the {} has no built-in calibration: set config.calibration",
                            model.name()
                        ),
                    ))
                }
            };
            let rings = calib.rings();
            let mut laser_of_ring = vec![0; rings.len()];
            for (laser, &ring) in rings.iter().enumerate() {
                if let Some(slot) = laser_of_ring.get_mut(usize::from(ring)) {
                    *slot = laser;
                }
            }
            dec = Some(FrameDecoder {
                model,
                laser_of_ring,
                calib,
                opts: s.opts,
                decoders: Vec::new(),
                column_rate: ColumnRate::default(),
                stamp_first: s.stamp_first,
                window: s.window,
            });
        }
        let Some(d) = dec.as_mut() else {
            return Ok(true);
        };
        match d.frame(&packets).map_err(|e| (ErrKind::Decode, e))? {
            Some(frame) => Ok(tx.send(Msg::Item(frame)).is_ok()),
            None => Ok(true),
        }
    };
    loop {
        let d = match input.next_datagram() {
            Ok(Some(d)) => d,
            Ok(None) => break,
            Err(e) => return Err((ErrKind::Input, format!("{path_s}: {e}"))),
        };
        let t = d.time_ns as f64 * 1e-9;
        if s.time_range.0.is_some_and(|t0| t < t0) {
            continue;
        }
        if s.time_range.1.is_some_and(|t1| t > t1) {
            break;
        }
        let Ok(bytes) = <[u8; DATA_PACKET_LEN]>::try_from(d.payload) else {
            continue;
        };
        let held = Held {
            host_ns: d.time_ns,
            bytes: Box::new(bytes),
        };
        if let Some(frame) = batcher.push(held) {
            if !emit(frame, &bytes)? {
                return Ok(());
            }
        }
    }
    let rest = std::mem::take(&mut batcher.packets);
    if let Some(first) = rest.first() {
        let first = *first.bytes;
        if !emit(rest, &first)? {
            return Ok(());
        }
    }
    let _ = tx.send(Msg::End(String::new()));
    Ok(())
}

/// Frames of a Velodyne pcap, velodyne_decoder's way.
#[pyclass(module = "ringscan._ringscan")]
pub struct CompatReader {
    inbox: Inbox<Msg<Frame>>,
}

#[pymethods]
impl CompatReader {
    #[new]
    #[pyo3(signature = (path, model=None, calibration=None, min_range=0.1, max_range=200.0, cut_angle=None, timestamp_first_packet=false, time_range=(None, None), min_angle=0.0, max_angle=360.0))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        path: PathBuf,
        model: Option<String>,
        calibration: Option<PathBuf>,
        min_range: f32,
        max_range: f32,
        cut_angle: Option<f64>,
        timestamp_first_packet: bool,
        time_range: (Option<f64>, Option<f64>),
        min_angle: f64,
        max_angle: f64,
    ) -> PyResult<Self> {
        if !(min_angle.is_finite() && max_angle.is_finite()) {
            return Err(to_py_err(
                ErrKind::Usage,
                format!("min_angle {min_angle} / max_angle {max_angle}: expected degrees"),
            ));
        }
        // velodyne_decoder: each angle taken modulo 360° to 0.01°; equal bounds mean the full turn.
        let to_cdeg = |a: f64| ((a % 360.0 + 360.0) % 360.0 * 100.0).round() as u16;
        let (lo, hi) = (to_cdeg(min_angle), to_cdeg(max_angle));
        let window = (lo != hi).then_some((lo, hi));
        let model = match model.as_deref() {
            None => None,
            Some(m) => Some(VelodyneModel::from_id(m).ok_or_else(|| {
                to_py_err(ErrKind::Usage, format!("model {m:?}: not a Velodyne model"))
            })?),
        };
        if !(min_range >= 0.0 && min_range <= max_range) {
            return Err(to_py_err(
                ErrKind::Usage,
                format!("min_range {min_range} / max_range {max_range}: empty range"),
            ));
        }
        let cut = match cut_angle {
            Some(a) if a.is_finite() && a >= 0.0 => Some((a * 100.0).round() as i32 % 36_000),
            Some(a) if a.is_finite() => None,
            Some(a) => {
                return Err(to_py_err(
                    ErrKind::Usage,
                    format!("cut_angle {a}: expected degrees"),
                ))
            }
            None => None,
        };
        let s = Settings {
            path,
            model,
            calib: calibration,
            opts: DecodeOptions {
                min_range,
                max_range,
            },
            cut,
            stamp_first: timestamp_first_packet,
            window,
            time_range,
        };
        let (tx, rx) = mpsc::sync_channel::<Msg<Frame>>(QUEUE);
        std::thread::Builder::new()
            .name("ringscan-compat".into())
            .spawn(move || {
                if let Err((k, m)) = run(&s, &tx) {
                    let _ = tx.send(Msg::Error(k, m));
                }
            })
            .map_err(|e| PyRuntimeError::new_err(format!("starting the decoding thread: {e}")))?;
        Ok(Self {
            inbox: Inbox::new(rx),
        })
    }

    /// `(host_s, device_s, Buffer of n x 8 float32, n)`, or `None` at the end.
    #[allow(clippy::type_complexity)]
    fn next(&self, py: Python<'_>) -> PyResult<Option<(f64, f64, Py<Buffer>, usize)>> {
        match next_item(py, &self.inbox, None)? {
            Some(f) => Ok(Some((
                f.host_s,
                f.device_s,
                Py::new(py, Buffer::f32s(f.data))?,
                f.n,
            ))),
            None => Ok(None),
        }
    }

    fn close(&self) {
        self.inbox.close();
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<CompatReader>()
}
