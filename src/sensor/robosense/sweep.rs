//! One Robosense sensor's stream: model, DIFOP, held packets, clock, loss and sweeps.
//!
//! Feed it every UDP payload from one sensor (MSOP and DIFOP alike) with its host receive
//! time; it calls back with each finished sweep. No I/O, no clock reads; a packet that is not
//! well-formed is counted and skipped.
//!
//! **Angles.** A calibration given by the caller (the angle CSV) wins; otherwise the first
//! DIFOP packet whose angle table is valid supplies them. MSOP packets that arrive before the
//! angles are known are held — at most [`MAX_HELD`] of them (a DIFOP comes about once a
//! second; that is over two seconds of the densest model), the oldest dropped and counted
//! beyond — and decoded, in order, once they are. The return mode is the DIFOP's (single until
//! one says dual), the motor speed too (600 rpm until one says).
//!
//! **Sweeps** are cut on the block azimuth: a block whose azimuth passes the cut angle (default
//! 0°) opens a new sweep (RoboSense's SDK and nebula cut the same way). The sweep's timestamp is
//! its first firing, so every `t` ≥ 0. The M1 does not spin: its sweeps are its frames (the
//! packet counter restarting at 1, 10 Hz), never waiting for a DIFOP; see `decode_m1`.
//!
//! **Clock.** The header time (Unix or calendar form, [`super::model::ClockForm`]) is the
//! packet's first firing. The stream calls the clock *synchronised* when it lies within 10 s of
//! the host receive time (the sensor follows PTP or GPS) and stamps sweeps in it; otherwise in
//! host time, the sensor's own time kept as `device_time_ns`.
//!
//! **Loss.** Missing packets = round(Δ header time / packet period) − 1; a header time going
//! backwards or jumping by more than `max_gap_ns` ends the open sweep (a discontinuity), and
//! so does a sweep spanning more than `max_sweep_ns` (a motor that stalls never reaches the
//! cut). A packet behind the latest came late: it fills the gap it was counted missing in, if
//! one was, and joins the open sweep with its firings from the sweep's start on; one with none
//! there belonged to a sweep already emitted and is dropped (`late_dropped`, a loss). Which
//! places came and which were counted missing is kept in a [`UdpLedger`] of the packets'
//! places in time (header time over the packet period), so this holds up to a turn (and at
//! most [`LEDGER_NUMBERS`] packets) behind, and a copy of a packet that came is a duplicate
//! however late; further back, or before the stream's first packet by more than 10, the
//! clock went back (a discontinuity).

use std::collections::VecDeque;

use super::calib::RobosenseAngles;
use super::decode::RobosenseDecoder;
use super::m1::{is_m1_difop, M1Decoder, M1Difop, M1Msop, M1_BLOCKS, M1_FRAME_NS};
use super::model::{RobosenseModel, Shape};
use super::wire::{is_difop, msop_shape, Difop, Msop};
use crate::sensor::{DecodeError, DecodeOptions};
use crate::sweep::ledger::{Count, UdpLedger, LEDGER_NUMBERS};
use crate::sweep::{RecentTimes, Sweep, REORDER_PACKETS};
use crate::time::ClockSource;

/// MSOP packets held while waiting for the angles.
pub const MAX_HELD: usize = 4096;

/// M1: a packet counter at most this far below the last one is a late packet, not a new frame
/// (rs_driver's window).
pub const M1_REORDER: u16 = 10;
/// M1: a header time at most this far behind the latest is a late packet (10 packets).
const M1_REORDER_NS: i64 = 10 * M1_FRAME_NS / 630;
/// M1: a sweep whose frame never ends (the counter does not restart) is cut at 1.5 frames.
pub const M1_MAX_SWEEP_NS: i64 = M1_FRAME_NS * 3 / 2;
/// M1: the largest packet counter a frame can have (1260 packets in dual return). A counter
/// of 0 or beyond is corrupt, and must not stand for a frame's length or a loss.
pub const M1_MAX_COUNTER: u16 = 2 * super::m1::M1_PACKETS_PER_FRAME;

/// Configuration of one stream.
#[derive(Clone, Debug)]
pub struct RobosenseConfig {
    /// The model (else told from the packets).
    pub model: Option<RobosenseModel>,
    /// Angles from a file (win over the DIFOP's).
    pub angles: Option<RobosenseAngles>,
    /// Range filter.
    pub options: DecodeOptions,
    /// Cut angle, 0.01°.
    pub cut_cdeg: u16,
    /// A header-time gap longer than this ends the sweep, ns.
    pub max_gap_ns: i64,
    /// A sweep spanning longer than this is cut (a discontinuity), ns: the azimuth of a
    /// stalled motor never reaches the cut, and its sweep would grow without end.
    pub max_sweep_ns: i64,
    /// Keep each point's firing column.
    pub keep_columns: bool,
}

impl RobosenseConfig {
    /// Defaults: model and angles from the packets, cut at 0°.
    pub fn new(angles: Option<RobosenseAngles>) -> Self {
        Self {
            model: None,
            angles,
            options: DecodeOptions::default(),
            cut_cdeg: 0,
            max_gap_ns: 1_000_000_000,
            max_sweep_ns: 1_000_000_000,
            keep_columns: false,
        }
    }
}

/// Counters of one stream.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RobosenseStats {
    /// MSOP packets decoded.
    pub packets: u64,
    /// DIFOP packets read.
    pub difop: u64,
    /// Packets not well-formed (or of no known shape). The header-time gap such a packet
    /// leaves is also counted in `missing` (its place is not read from a packet that failed
    /// its checks), so a sum of both counts it twice.
    pub malformed: u64,
    /// DIFOP packets whose angle table could not be used.
    pub difop_bad_angles: u64,
    /// Packets missing (header-time gaps).
    pub missing: u64,
    /// Held packets dropped (the hold was full).
    pub dropped: u64,
    /// Discontinuities.
    pub discontinuities: u64,
    /// MSOP packets seen already (a header time that came, its place in time among those
    /// kept; M1: its counter in its frame's, or the frame before's): copies, dropped.
    pub duplicates: u64,
    /// Late MSOP packets (reordered on the way) whose firings all belong to a sweep already
    /// emitted: dropped, and counted as a loss (a packet counted missing before it came
    /// moves from `missing` to here: a spinning model's up to a turn behind, by its place in
    /// time; an M1 packet of the open frame however far behind, as its frame's counters are
    /// all kept, one of the frame before by its counters too; a copy of any is a duplicate).
    /// A late packet with firings in the open sweep joins it instead, no longer missing; an
    /// M1 packet of the open frame timed before its sweep's start (the frame's first packets
    /// come after a later one) is dropped here, and no longer missing in that sweep's
    /// `missing_packets` either.
    pub late_dropped: u64,
    /// Sweeps emitted.
    pub sweeps: u64,
    /// Points emitted.
    pub points: u64,
}

/// What the stream learned about its sensor.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RobosenseFacts {
    /// The model.
    pub model: Option<RobosenseModel>,
    /// How it was chosen.
    pub detection: String,
    /// Where the angles came from (file name, `DIFOP`), empty while unknown.
    pub calibration: String,
    /// DIFOP: motor speed, rpm.
    pub rpm: Option<u16>,
    /// DIFOP: return-mode byte.
    pub return_mode: Option<u8>,
    /// DIFOP: field of view (start, end), 0.01°.
    pub fov: Option<(u16, u16)>,
    /// DIFOP: serial number.
    pub serial: String,
    /// DIFOP: firmware versions.
    pub firmware: String,
    /// Helios / Ruby / M1 header: protocol version.
    pub protocol: Option<u16>,
    /// M1 DIFOP: frame-rate byte.
    pub frame_rate: Option<u8>,
    /// M1 header: temperature, °C.
    pub temperature_c: Option<i16>,
    /// Whether the header clock agrees with the host's.
    pub clock_synchronised: Option<bool>,
    /// Clock of the last sweep.
    pub clock: ClockSource,
}

impl RobosenseFacts {
    /// Return mode in words.
    pub fn return_mode_words(&self) -> String {
        match (self.model, self.return_mode) {
            (Some(m), Some(r)) => format!("{} ({r:#04x})", m.mode_name(r)),
            _ => "single (no DIFOP seen)".to_string(),
        }
    }

    /// Clock form and state in words.
    pub fn clock_words(&self) -> String {
        let form = match self.model.map(|m| m.spec().clock) {
            Some(super::model::ClockForm::Unix) => "header Unix time (s + µs)",
            Some(super::model::ClockForm::Calendar) => "header calendar time (Y-M-D h:m:s ms µs)",
            None => "unknown",
        };
        let state = match self.clock_synchronised {
            None => "unknown",
            Some(true) => "synchronised (within 10 s of host time)",
            Some(false) => "free-running (far from host time)",
        };
        format!("{form}, {state}")
    }
}

/// A Robosense stream.
#[derive(Debug)]
pub struct RobosenseStream {
    cfg: RobosenseConfig,
    decoder: Option<RobosenseDecoder>,
    stats: RobosenseStats,
    facts: RobosenseFacts,
    held: VecDeque<(i64, Vec<u8>)>,
    open: Option<(Sweep, i64)>,
    spare: Option<Sweep>,
    next_index: u64,
    last_block_az: Option<u16>,
    prev_stamp: Option<i64>,
    /// Header times of the last MSOP packets (copies share one).
    recent: RecentTimes,
    dual: bool,
    /// The last DIFOP, while the model is unknown (a DIFOP that came before any MSOP).
    last_difop: Option<Vec<u8>>,
    /// Spinning models: the packets' places in time (header time over the packet period,
    /// from the latest's), which came and which were counted missing, as the M1's counters
    /// are kept: a late packet fills its gap, a copy is a copy, however far behind.
    spin_udp: UdpLedger,
    /// Spinning: this packet's place, and the place of the packet that opened the open
    /// sweep (gaps counted after it were counted in that sweep).
    spin_slot: u16,
    spin_sweep_slot: u16,
    /// M1: the decoder (no angles needed) and the packet counters of the open frame: all of
    /// them, as a packet of it may come later than the 10-number window reaches.
    m1: Option<M1Decoder>,
    m1_udp: UdpLedger,
    /// M1: the counters of the frame before (none after a discontinuity), for its late
    /// packets; swapped with the open frame's, so neither is allocated again.
    m1_prev_udp: UdpLedger,
    /// M1: the largest counter of the open frame, and of the frame before.
    m1_frame_max: u16,
    m1_last_frame_max: u16,
    /// M1: the frame length learned (two frames in a row ending on the same counter) and the
    /// return mode it holds for.
    m1_frame_len: Option<u16>,
    m1_mode: Option<u8>,
    /// M1: whether the open sweep began inside the open frame (a frame spanning more than
    /// [`M1_MAX_SWEEP_NS`]), so that the frame's losses were not all counted in it.
    m1_sweep_cut_in_frame: bool,
}

impl RobosenseStream {
    /// A new stream.
    pub fn new(cfg: RobosenseConfig) -> Self {
        let mut facts = RobosenseFacts::default();
        if let Some(a) = &cfg.angles {
            facts.calibration = a.source.clone();
        }
        Self {
            cfg,
            decoder: None,
            stats: RobosenseStats::default(),
            facts,
            held: VecDeque::new(),
            open: None,
            spare: None,
            next_index: 0,
            last_block_az: None,
            prev_stamp: None,
            recent: RecentTimes::default(),
            dual: false,
            last_difop: None,
            spin_udp: UdpLedger::new(u64::from(LEDGER_NUMBERS - 1)),
            spin_slot: 0,
            spin_sweep_slot: 0,
            m1: None,
            m1_udp: UdpLedger::new(u64::from(M1_MAX_COUNTER)),
            m1_prev_udp: UdpLedger::new(u64::from(M1_MAX_COUNTER)),
            m1_frame_max: 0,
            m1_last_frame_max: 0,
            m1_frame_len: None,
            m1_mode: None,
            m1_sweep_cut_in_frame: false,
        }
    }

    /// Counters.
    pub fn stats(&self) -> &RobosenseStats {
        &self.stats
    }

    /// Facts.
    pub fn facts(&self) -> &RobosenseFacts {
        &self.facts
    }

    /// The decoder, once model and angles are known.
    pub fn decoder(&self) -> Option<&RobosenseDecoder> {
        self.decoder.as_ref()
    }

    /// Packets held, waiting for the angles.
    pub fn held(&self) -> usize {
        self.held.len()
    }

    /// Tells the model from an MSOP packet's shape and, where the shape is shared, from the
    /// angles: the Helios header serves the Helios (32 lasers) and the Helios-16P (16), the
    /// V1 header the RS-16 (16), RS-32 and Bpearl (32; the Bpearl's lasers look up to 90°).
    fn tell_model(&mut self, shape: Shape, difop_angles: Option<&[(f64, f64)]>) {
        if self.facts.model.is_some() {
            return;
        }
        if let Some(m) = self.cfg.model {
            if m.spec().shape == shape {
                self.facts.model = Some(m);
                self.facts.detection = format!("named by the user ({})", m.id());
            }
            return;
        }
        let file_lasers = self.cfg.angles.as_ref().map(RobosenseAngles::lasers);
        let (m, how) = match shape {
            Shape::Mems => (
                RobosenseModel::M1,
                "1210-byte MSOP, id 55 AA 5A A5 (M1 / M1 Plus)".to_string(),
            ),
            Shape::Ruby => (RobosenseModel::Ruby128, "80-byte header, FE blocks".to_string()),
            Shape::Helios => match (file_lasers, difop_angles) {
                (Some(16), _) => (RobosenseModel::Helios16P, "Helios header; 16-laser angle file".into()),
                (Some(_), _) => (RobosenseModel::Helios, "Helios header; 32-laser angle file".into()),
                (None, Some(a)) if helios16p_difop(a) => (
                    RobosenseModel::Helios16P,
                    "Helios header; DIFOP lists 16 lasers (its entries 16–31 are not a 32-laser fan)".into(),
                ),
                (None, Some(_)) => (RobosenseModel::Helios, "Helios header; DIFOP lists 32 lasers".into()),
                (None, None) => return,
            },
            Shape::V1 => match (file_lasers, difop_angles) {
                (Some(16), _) => (RobosenseModel::Rs16, "V1 header; 16-laser angle file".into()),
                (Some(_), _) => (RobosenseModel::Rs32, "V1 header; 32-laser angle file".into()),
                (None, Some(a)) if a.len() == 16 => (RobosenseModel::Rs16, "V1 header; RS-16 DIFOP pitch table".into()),
                (None, Some(a)) if a.iter().any(|&(v, _)| v > 30.0) => {
                    (RobosenseModel::Bpearl, "V1 header; DIFOP angles up to 90° (Bpearl)".into())
                }
                (None, Some(_)) => (RobosenseModel::Rs32, "V1 header; DIFOP angles within ±25° (RS-32)".into()),
                (None, None) => return,
            },
        };
        self.facts.model = Some(m);
        self.facts.detection = how;
    }

    fn build_decoder(&mut self, angles: &RobosenseAngles) -> Result<(), DecodeError> {
        let Some(m) = self.facts.model else {
            return Ok(());
        };
        let mut dec = RobosenseDecoder::new(m, angles, self.cfg.options)?;
        if let Some(r) = self.facts.rpm {
            dec.set_rpm(r);
        }
        // A DIFOP seen before the model was known set the return mode.
        if let Some(mode) = self.facts.return_mode {
            self.dual = m.is_dual(mode);
        }
        self.facts.calibration = angles.source.clone();
        self.decoder = Some(dec);
        Ok(())
    }

    /// Pushes one UDP payload; finished sweeps go to `on_sweep`. An error means the angles do
    /// not fit the model.
    pub fn push(
        &mut self,
        host_ns: i64,
        payload: &[u8],
        on_sweep: &mut dyn FnMut(&mut Sweep, &RobosenseFacts),
    ) -> Result<(), DecodeError> {
        if is_difop(payload) {
            return self.push_difop(payload, on_sweep);
        }
        if is_m1_difop(payload) {
            self.push_m1_difop(payload);
            return Ok(());
        }
        let Some(shape) = msop_shape(payload) else {
            self.stats.malformed += 1;
            return Ok(());
        };
        self.tell_model(shape, None);
        if shape == Shape::Mems {
            // Self-contained points: nothing to wait for, no angle table to build.
            if self.facts.model == Some(RobosenseModel::M1) {
                self.decode_m1(host_ns, payload, on_sweep);
            } else {
                self.stats.malformed += 1;
            }
            return Ok(());
        }
        if self.facts.model.is_some() && self.decoder.is_none() {
            if let Some(a) = self.cfg.angles.clone() {
                self.build_decoder(&a)?;
            }
        }
        if self.decoder.is_none() {
            if self.facts.model.is_some_and(|m| m.spec().shape != shape) {
                self.stats.malformed += 1;
                return Ok(());
            }
            if self.held.len() >= MAX_HELD {
                self.held.pop_front();
                self.stats.dropped += 1;
            }
            self.held.push_back((host_ns, payload.to_vec()));
            if let Some(d) = self.last_difop.take() {
                // Read again now that a packet can tell the model (which may also decode the
                // packets held). It was counted a DIFOP when it came: the second reading
                // counts it for good, as a DIFOP or malformed.
                let r = self.push_difop(&d, on_sweep);
                self.stats.difop = self.stats.difop.saturating_sub(1);
                return r;
            }
            return Ok(());
        }
        self.decode_msop(host_ns, payload, on_sweep);
        Ok(())
    }

    fn push_difop(
        &mut self,
        payload: &[u8],
        on_sweep: &mut dyn FnMut(&mut Sweep, &RobosenseFacts),
    ) -> Result<(), DecodeError> {
        let Ok(d) = Difop::new(payload) else {
            self.stats.malformed += 1;
            return Ok(());
        };
        if self.facts.model == Some(RobosenseModel::M1) {
            // A spinning model's DIFOP on an M1's stream: not this sensor's.
            self.stats.malformed += 1;
            return Ok(());
        }
        self.stats.difop += 1;
        self.facts.rpm = Some(d.rpm());
        self.facts.fov = Some(d.fov());
        d.write_serial(&mut self.facts.serial);
        d.write_firmware(&mut self.facts.firmware);
        self.facts.return_mode = Some(d.return_mode());
        if let Some(dec) = &mut self.decoder {
            dec.set_rpm(d.rpm());
        }
        // The model of a shared header is told from the DIFOP's angles.
        if self.facts.model.is_none() {
            if let Some((_, p)) = self.held.front() {
                if let Some(shape) = msop_shape(p) {
                    let probe = match shape {
                        Shape::Helios => Some(RobosenseModel::Helios),
                        Shape::V1 => Some(RobosenseModel::Rs32),
                        Shape::Ruby | Shape::Mems => None,
                    };
                    let a = probe.map(|m| d.angles(m));
                    let a16 = d.angles(RobosenseModel::Rs16).ok();
                    match (shape, a) {
                        (Shape::V1, Some(Ok(a)))
                            if a.iter().all(|&(v, h)| v == 0.0 && h == 0.0) =>
                        {
                            self.tell_model(shape, a16.as_deref())
                        }
                        (_, Some(Ok(a))) => self.tell_model(shape, Some(&a)),
                        _ => self.tell_model(shape, None),
                    }
                }
            }
        }
        match self.facts.model {
            Some(m) => self.dual = m.is_dual(d.return_mode()),
            None => self.last_difop = Some(payload.to_vec()),
        }
        if self.decoder.is_none() {
            if let Some(m) = self.facts.model {
                match d.angles(m) {
                    Ok(lasers) => {
                        let a = RobosenseAngles {
                            source: "DIFOP".into(),
                            lasers,
                        };
                        self.build_decoder(&a)?;
                    }
                    Err(_) => self.stats.difop_bad_angles += 1,
                }
            }
            if self.decoder.is_some() {
                let held: Vec<_> = self.held.drain(..).collect();
                for (h, p) in held {
                    self.decode_msop(h, &p, on_sweep);
                }
            }
        }
        Ok(())
    }

    fn decode_msop(
        &mut self,
        host_ns: i64,
        payload: &[u8],
        on_sweep: &mut dyn FnMut(&mut Sweep, &RobosenseFacts),
    ) {
        let (Some(model), Some(dec)) = (self.facts.model, self.decoder.take()) else {
            return;
        };
        let Ok(p) = Msop::new(payload, model) else {
            self.stats.malformed += 1;
            self.decoder = Some(dec);
            return;
        };
        let spec = model.spec();
        let Some(stamp) = p.stamp_ns(spec.clock) else {
            self.stats.malformed += 1;
            self.decoder = Some(dec);
            return;
        };
        self.facts.protocol = p.protocol_version();
        // Host times can lie anywhere in i64 (a corrupt capture): differences with them
        // saturate.
        let synced = stamp.abs_diff(host_ns) < 10_000_000_000;
        self.facts.clock_synchronised = Some(synced);
        let dual = self.dual;
        let period = spec.packet_period_ns(dual);
        let mut discontinuity = false;
        // Time since the last packet, for an azimuth step the azimuths alone cannot tell.
        let mut since_last = None;
        // A packet older than the latest was reordered on the way: it opens no sweep, and
        // the stream goes on from the latest.
        let mut late = false;
        // It fills a gap counted missing.
        let mut fills = false;
        let mut slot = self.spin_udp.latest().unwrap_or(0);
        if let Some(prev) = self.prev_stamp {
            let d = stamp.saturating_sub(prev);
            let turn_ns = 60e9 / crate::sweep::motor_rpm_or_nominal(self.facts.rpm);
            // The rotor tells a copy or a late packet from a clock that stepped back: the
            // azimuth of a packet `behind` places in time lies as far behind the latest's, one
            // of a clock gone back continues on from the latest. Tolerance: three packets'
            // turn and a twentieth of the way back (the motor's speed varies).
            let blocks = spec.shape.blocks();
            let rotor_agrees = |behind: f64| match self.last_block_az {
                Some(latest_az) if blocks > 0 && period > 0.0 => {
                    let step = 36_000.0 * period / turn_ns;
                    let expected = f64::from(latest_az) - behind * step;
                    let off = (f64::from(p.azimuth(blocks - 1)) - expected).rem_euclid(36_000.0);
                    off.min(36_000.0 - off) <= 3.0 * step + 0.05 * behind * step
                }
                _ => true,
            };
            let places_behind = if period > 0.0 {
                (-(d as f64) / period).round().max(0.0)
            } else {
                0.0
            };
            // Two packets of one sensor never share a header time: a copy, where the rotor
            // agrees.
            if self.recent.contains(stamp) && rotor_agrees(places_behind) {
                self.stats.duplicates += 1;
                self.decoder = Some(dec);
                return;
            }
            if d < 0 && period > 0.0 {
                // Its place, in whole packets behind the latest (at least one: it is older).
                let behind = places_behind.max(1.0);
                // More than a turn behind, beyond what the ledger keeps, or a rotor that went
                // on: the clock went back, not a packet late.
                let rotor_agrees = rotor_agrees(behind);
                let count =
                    if behind < f64::from(LEDGER_NUMBERS) && -(d as f64) <= turn_ns && rotor_agrees
                    {
                        slot = slot.wrapping_sub(behind as u16);
                        self.spin_udp.peek(slot)
                    } else {
                        Count::Far
                    };
                match count {
                    Count::Seen { .. } => {
                        self.stats.duplicates += 1;
                        self.decoder = Some(dec);
                        return;
                    }
                    Count::Lost { .. } => (late, fills) = (true, true),
                    // Just before the stream's first: late, with no gap counted to fill.
                    Count::Stray => late = true,
                    Count::Next { .. } | Count::Far => discontinuity = true,
                }
            } else if d < 0 || d > self.cfg.max_gap_ns {
                discontinuity = true;
            } else if period > 0.0 {
                since_last = Some(d);
                let steps = (d as f64 / period).round() as i64;
                let m = steps - 1;
                if m > 0 {
                    self.stats.missing += m as u64;
                    if let Some((sw, _)) = &mut self.open {
                        sw.missing_packets += m as u64;
                    }
                }
                // A step of less than half a period (a clock's jitter) keeps the place.
                if steps >= i64::from(LEDGER_NUMBERS) {
                    slot = slot.wrapping_add(steps as u16);
                    self.spin_udp.restart(slot);
                } else if steps > 0 {
                    slot = slot.wrapping_add(steps as u16);
                    self.spin_udp.take(slot);
                }
            }
        }
        if discontinuity || self.prev_stamp.is_none() {
            slot = 0;
            self.spin_udp.restart(slot);
        } else if late {
            self.spin_udp.take(slot);
        }
        self.spin_slot = slot;
        if !late {
            self.prev_stamp = Some(stamp);
        }
        if discontinuity {
            self.stats.discontinuities += 1;
            // A clock that restarted (or a capture replayed again) may repeat times.
            self.recent.clear();
            self.emit(on_sweep);
            self.last_block_az = None;
        }
        self.recent.push(stamp);
        let clock = if synced {
            ClockSource::SensorPtp
        } else {
            ClockSource::Host
        };
        let mut roles = [(0usize, None); 12];
        dec.roles(&p, dual, &mut roles);
        let blocks = spec.shape.blocks();
        let period_ns = super::model::us_to_ns(spec.firing_period_us(dual));
        let block_time = |b: usize| stamp.saturating_add(roles[b].0 as i64 * period_ns);
        if late {
            // Only a gap really counted is un-counted (not one before the stream's first
            // packet or a discontinuity), and in the sweep that counted it.
            if fills {
                self.stats.missing = self.stats.missing.saturating_sub(1);
            }
            // Firings before the open sweep's start belong to a sweep already emitted: their
            // time in this one would be negative (clamped to its start).
            let open = self
                .open
                .as_mut()
                .filter(|(_, t0)| (0..blocks).any(|b| block_time(b) >= *t0));
            let Some((sw, _)) = open else {
                self.stats.late_dropped += 1;
                self.decoder = Some(dec);
                return;
            };
            // The open sweep counted the gaps found after the packet that opened it (that
            // packet's own went to the sweep before).
            let latest = self.spin_udp.latest().unwrap_or(0);
            if fills && latest.wrapping_sub(slot) < latest.wrapping_sub(self.spin_sweep_slot) {
                sw.missing_packets = sw.missing_packets.saturating_sub(1);
            }
        }
        self.stats.packets += 1;
        // The blocks at which a new sweep starts.
        let cut = i32::from(self.cfg.cut_cdeg % 36_000);
        let mut starts = [false; 12];
        let mut last = self.last_block_az;
        // The motor speed a DIFOP gave (else the usual 600 rpm).
        let rpm = crate::sweep::motor_rpm_or_nominal(self.facts.rpm);
        // The start of the sweep open when a block comes, to cut one grown too long; a start
        // in this packet opens a new one, short.
        let mut open_t0 = self.open.as_ref().map(|(_, t0)| *t0);
        let mut too_long = false;
        for (b, s) in starts.iter_mut().enumerate().take(blocks).filter(|_| !late) {
            let az = p.azimuth(b);
            if let Some(l) = last {
                let span = i64::from((i32::from(az) - i32::from(l)).rem_euclid(36_000));
                let to_cut = i64::from((cut - i32::from(l)).rem_euclid(36_000));
                // Crossing forward (a step back within a quarter turn is not a turn); across
                // packets, the time between them tells a step back from packets lost, and
                // a whole turn lost passed the cut whatever the azimuths.
                let turned = since_last
                    .filter(|_| b == 0)
                    .map(|d| crate::sweep::rotation_in(d, rpm, 36_000));
                *s = match crate::sweep::azimuth_step(span, 36_000, turned) {
                    crate::sweep::Step::Back => false,
                    crate::sweep::Step::Forward { full_turn } => {
                        full_turn || (span > 0 && to_cut > 0 && to_cut <= span)
                    }
                };
            }
            if !*s
                && open_t0
                    .is_some_and(|t0| block_time(b).saturating_sub(t0) > self.cfg.max_sweep_ns)
            {
                *s = true;
                too_long = true;
            }
            if *s {
                open_t0 = None;
            }
            last = Some(az);
        }
        if too_long {
            self.stats.discontinuities += 1;
        }
        if !late {
            self.last_block_az = last;
        }
        let keep_columns = self.cfg.keep_columns;
        let mut cur_block = usize::MAX;
        let mut counted = false;
        let mut col_base = 0u32;
        dec.decode(&p, dual, |d| {
            if d.block != cur_block {
                // Blocks without points still open sweeps: walk every block up to this one.
                let from = if cur_block == usize::MAX {
                    0
                } else {
                    cur_block + 1
                };
                for b in from..=d.block {
                    self.block_begins(
                        b,
                        p.azimuth(b),
                        &roles,
                        &starts,
                        stamp,
                        host_ns,
                        period_ns,
                        clock,
                        on_sweep,
                    );
                    if starts[b] {
                        counted = false;
                    }
                }
                cur_block = d.block;
            }
            if let Some((sw, t0)) = &mut self.open {
                if late && block_time(d.block) < *t0 {
                    return;
                }
                if !counted {
                    sw.packets += 1;
                    counted = true;
                    col_base = sw.columns_count;
                }
                let mut pt = d.point;
                pt.t = stamp
                    .saturating_add(d.offset_ns)
                    .saturating_sub(*t0)
                    .clamp(0, i64::from(u32::MAX)) as u32;
                sw.points.push(pt);
                if keep_columns {
                    sw.columns.push(col_base + d.firing as u32);
                }
            }
        });
        let from = if cur_block == usize::MAX {
            0
        } else {
            cur_block + 1
        };
        for b in from..blocks {
            self.block_begins(
                b,
                p.azimuth(b),
                &roles,
                &starts,
                stamp,
                host_ns,
                period_ns,
                clock,
                on_sweep,
            );
        }
        if let Some((sw, _)) = &mut self.open {
            sw.last_host_ns = host_ns;
            if !late {
                sw.last_azimuth = p.azimuth(blocks - 1);
            }
            sw.columns_count += spec.firings(dual) as u32;
        }
        self.decoder = Some(dec);
    }

    /// An M1 DIFOP: device facts only (the M1 needs no angle table).
    fn push_m1_difop(&mut self, payload: &[u8]) {
        let Ok(d) = M1Difop::new(payload) else {
            self.stats.malformed += 1;
            return;
        };
        if self.facts.model.is_some_and(|m| m != RobosenseModel::M1) {
            self.stats.malformed += 1;
            return;
        }
        self.stats.difop += 1;
        self.facts.frame_rate = Some(d.frame_rate());
        self.facts.serial = d.serial();
        self.facts.firmware = d.firmware();
    }

    /// An M1 MSOP packet into the open sweep. Sweeps follow the sensor's frames: the packet
    /// counter restarts at 1 with each frame (rs_driver splits the same way), so a counter
    /// more than [`M1_REORDER`] below the last one opens a new sweep; a counter a little
    /// below it is a packet that came late, kept in the open sweep (one whose counter was seen
    /// already at the same time is a copy, dropped). A packet older than the latest whose
    /// counter the open frame counted lost, however far below, is late too (up to half a frame
    /// before the sweep's start; a copy of it is a copy). Any other packet older than the
    /// latest is late from the frame before, emitted already: dropped (`late_dropped`), within
    /// 10 packets in time or, where the frame before's counters had or counted lost its
    /// counter, however far behind within that frame (a copy of a packet it had is a copy).
    /// Should the counter stop restarting, a sweep is also cut once it spans
    /// [`M1_MAX_SWEEP_NS`]. Loss: the counter's gaps within a frame, its first packets, and its
    /// last ones once the frame length is learned (two frames in a row ending on the same
    /// counter, in one return mode).
    fn decode_m1(
        &mut self,
        host_ns: i64,
        payload: &[u8],
        on_sweep: &mut dyn FnMut(&mut Sweep, &RobosenseFacts),
    ) {
        let Ok(p) = M1Msop::new(payload) else {
            self.stats.malformed += 1;
            return;
        };
        let Some(stamp) = p.stamp_ns() else {
            self.stats.malformed += 1;
            return;
        };
        let dec = *self
            .m1
            .get_or_insert_with(|| M1Decoder::new(self.cfg.options));
        self.facts.protocol = Some(p.protocol_version());
        self.facts.return_mode = Some(p.return_mode());
        self.facts.temperature_c = Some(p.temperature_c());
        if self.facts.calibration.is_empty() || self.cfg.angles.is_some() {
            self.facts.calibration = "none needed (M1 points carry their angles)".into();
        }
        let synced = stamp.abs_diff(host_ns) < 10_000_000_000;
        self.facts.clock_synchronised = Some(synced);
        let clock = if synced {
            ClockSource::SensorPtp
        } else {
            ClockSource::Host
        };
        let seq = p.seq();
        let mode = p.return_mode();
        if self.m1_mode.replace(mode).is_some_and(|m| m != mode) {
            // Dual return sends twice the packets a frame: the length learned no longer holds,
            // nor does the last frame's for learning it again.
            self.m1_frame_len = None;
            self.m1_last_frame_max = 0;
        }
        let d = self.prev_stamp.map(|prev| stamp.saturating_sub(prev));
        let t0 = self.open.as_ref().map(|(_, t0)| *t0);
        // Counter gaps before this packet (in the open frame, or the new frame's first
        // packets lost), and whether it fills a gap of the open sweep counted before.
        let mut missing = 0u64;
        let mut fills = false;
        let mut cut = false;
        let valid_seq = (1..=M1_MAX_COUNTER).contains(&seq);
        let count = valid_seq.then(|| self.m1_udp.peek(seq));
        // Behind the latest in time, with a counter the open frame counted lost or had, and no
        // earlier than its first packets can be (the frame before's are a whole frame back):
        // a packet of the open frame, however late, not a clock going back.
        let of_open_frame = d.is_some_and(|d| d < 0)
            && matches!(count, Some(Count::Lost { .. } | Count::Seen { .. }))
            && t0.is_some_and(|t0| stamp >= t0.saturating_sub(M1_FRAME_NS / 2));
        // Likewise a packet of the frame before, however far behind its last: timed before
        // the open sweep, no earlier than a frame can last, its counter had or counted lost
        // there (and neither in the open frame).
        let of_prev_frame = valid_seq
            && !of_open_frame
            && d.is_some_and(|d| d < 0)
            && !matches!(count, Some(Count::Lost { .. } | Count::Seen { .. }))
            && matches!(
                self.m1_prev_udp.peek(seq),
                Count::Lost { .. } | Count::Seen { .. }
            )
            && t0.is_some_and(|t0| stamp < t0 && stamp >= t0.saturating_sub(M1_MAX_SWEEP_NS));
        if d.is_some_and(|d| {
            d > self.cfg.max_gap_ns || (d < -M1_REORDER_NS && !of_open_frame && !of_prev_frame)
        }) {
            self.stats.discontinuities += 1;
            cut = true;
            self.recent.clear();
            self.m1_udp.reset();
            self.m1_prev_udp.reset();
            self.m1_frame_max = 0;
            self.m1_last_frame_max = 0;
            self.m1_sweep_cut_in_frame = false;
            self.prev_stamp = None;
        }
        let late_in_time = !cut && d.is_some_and(|d| d < 0);
        // Where the open frame's counters say it is the frame's: the last 10 numbers as
        // before the ledger, and further back for a packet late in time too.
        let in_open = count.filter(|c| {
            !cut && match *c {
                Count::Lost { behind } | Count::Seen { behind } => {
                    behind <= REORDER_PACKETS || of_open_frame
                }
                Count::Stray => true,
                Count::Next { .. } | Count::Far => false,
            }
        });
        if !valid_seq {
            // A corrupt counter: its place in the frame is unknown, so it moves no counter
            // state and counts no loss; the points are whole (the decoder checks them).
            if late_in_time && t0.is_some_and(|t0| stamp < t0) {
                self.stats.late_dropped += 1;
                return;
            }
        } else if let Some(c) = in_open {
            if matches!(c, Count::Seen { .. }) && (self.recent.contains(stamp) || of_open_frame) {
                self.stats.duplicates += 1;
                return;
            }
            self.m1_udp.take(seq);
            // A counter seen already at a new time (a counter that stands still) has no gap
            // to fill.
            let filled = matches!(c, Count::Lost { .. });
            if t0.is_some_and(|t0| stamp < t0) {
                // Before the open sweep's start (the frame's first packets came after a later
                // one): its times there would be negative. Its loss was counted in the open
                // sweep too, unless a cut inside the frame emitted the sweep that counted it.
                self.drop_late(filled);
                if filled && !self.m1_sweep_cut_in_frame {
                    if let Some((sw, _)) = &mut self.open {
                        sw.missing_packets = sw.missing_packets.saturating_sub(1);
                    }
                }
                self.recent.push(stamp);
                return;
            }
            fills = filled;
        } else if late_in_time {
            // Older than the latest packet, whatever its counter says: a packet of the frame
            // before (its last ones may come after the next frame's first), emitted already.
            // One its counters had came already, however far behind: a copy.
            let counted = match self.m1_prev_udp.peek(seq) {
                Count::Seen { .. } => {
                    self.stats.duplicates += 1;
                    return;
                }
                c @ (Count::Lost { .. } | Count::Stray) => {
                    self.m1_prev_udp.take(seq);
                    matches!(c, Count::Lost { .. })
                }
                Count::Next { .. } | Count::Far => false,
            };
            self.drop_late(counted);
            self.recent.push(stamp);
            return;
        } else if self
            .m1_udp
            .latest()
            .is_some_and(|l| seq.saturating_add(M1_REORDER) < l)
        {
            // The counter restarted: a new frame. Its last packets lost are known only from
            // the frame length learned; taking the frame's counters past its last one counts
            // them and keeps them there for a late one to fill.
            cut = true;
            let frame_max = self.m1_frame_max;
            if frame_max == self.m1_last_frame_max {
                self.m1_frame_len = Some(frame_max);
            }
            self.m1_last_frame_max = frame_max;
            if let Some(len) = self.m1_frame_len.filter(|&len| len > frame_max) {
                if let Count::Next { lost } = self.m1_udp.take(len.saturating_add(1)) {
                    self.stats.missing += lost;
                    if let Some((sw, _)) = &mut self.open {
                        sw.missing_packets += lost;
                    }
                }
            }
            std::mem::swap(&mut self.m1_udp, &mut self.m1_prev_udp);
            // The frame's first packets lost are counted, and filled should they come late.
            self.m1_udp.start_lost_before(seq);
            missing = u64::from(seq.saturating_sub(1));
            self.m1_frame_max = seq;
            self.m1_sweep_cut_in_frame = false;
        } else {
            if let Count::Next { lost } = self.m1_udp.take(seq) {
                missing = lost;
            }
            self.m1_frame_max = self.m1_frame_max.max(seq);
        }
        self.recent.push(stamp);
        // The latest header time seen: a late packet does not move it back.
        self.prev_stamp = Some(self.prev_stamp.map_or(stamp, |prev| prev.max(stamp)));
        if let Some(t0) = t0 {
            if !cut && stamp.saturating_sub(t0) >= M1_MAX_SWEEP_NS {
                cut = true;
                self.m1_sweep_cut_in_frame = true;
            }
        }
        if cut {
            self.emit(on_sweep);
        }
        self.stats.missing += missing;
        if fills {
            self.stats.missing = self.stats.missing.saturating_sub(1);
        }
        self.stats.packets += 1;
        if self.open.is_none() {
            let mut sw = self.spare.take().unwrap_or_default();
            sw.clear();
            sw.index = self.next_index;
            self.next_index += 1;
            sw.device_time_ns = stamp;
            sw.timestamp_ns = if clock == ClockSource::Host {
                host_ns
            } else {
                stamp
            };
            sw.clock = clock;
            sw.first_host_ns = host_ns;
            self.open = Some((sw, stamp));
        }
        let keep_columns = self.cfg.keep_columns;
        if let Some((sw, t0)) = &mut self.open {
            // Counter gaps before this packet (the new frame's first packets: in the new one).
            sw.missing_packets += missing;
            if fills {
                sw.missing_packets = sw.missing_packets.saturating_sub(1);
            }
            sw.packets += 1;
            sw.last_host_ns = host_ns;
            let col_base = sw.columns_count;
            let t0 = *t0;
            dec.decode(&p, |d| {
                let mut pt = d.point;
                pt.t = stamp
                    .saturating_add(d.offset_ns)
                    .saturating_sub(t0)
                    .clamp(0, i64::from(u32::MAX)) as u32;
                sw.points.push(pt);
                if keep_columns {
                    sw.columns.push(col_base + d.block as u32);
                }
            });
            sw.columns_count += M1_BLOCKS as u32;
        }
    }

    /// M1: a late packet of a sweep already emitted, dropped; `counted` if it was counted
    /// missing (it moves to `late_dropped`).
    fn drop_late(&mut self, counted: bool) {
        if counted {
            self.stats.missing = self.stats.missing.saturating_sub(1);
        }
        self.stats.late_dropped += 1;
    }

    #[allow(clippy::too_many_arguments)]
    fn block_begins(
        &mut self,
        b: usize,
        az: u16,
        roles: &[(usize, Option<u8>); 12],
        starts: &[bool; 12],
        stamp: i64,
        host_ns: i64,
        period_ns: i64,
        clock: ClockSource,
        on_sweep: &mut dyn FnMut(&mut Sweep, &RobosenseFacts),
    ) {
        if starts[b] {
            self.emit(on_sweep);
        }
        if self.open.is_none() {
            let t0 = stamp.saturating_add(roles[b].0 as i64 * period_ns);
            let mut sw = self.spare.take().unwrap_or_default();
            sw.clear();
            sw.index = self.next_index;
            self.next_index += 1;
            sw.device_time_ns = t0;
            sw.timestamp_ns = if clock == ClockSource::Host {
                host_ns.saturating_add(t0.saturating_sub(stamp))
            } else {
                t0
            };
            sw.clock = clock;
            sw.first_host_ns = host_ns;
            sw.last_host_ns = host_ns;
            sw.first_azimuth = az;
            self.open = Some((sw, t0));
            self.spin_sweep_slot = self.spin_slot;
        }
    }

    fn emit(&mut self, on_sweep: &mut dyn FnMut(&mut Sweep, &RobosenseFacts)) {
        if let Some((mut sw, _)) = self.open.take() {
            if !sw.points.is_empty() || sw.packets > 0 {
                self.stats.sweeps += 1;
                self.stats.points += sw.points.len() as u64;
                self.facts.clock = sw.clock;
                on_sweep(&mut sw, &self.facts);
            }
            self.spare = Some(sw);
        }
    }

    /// Emits the open sweep and decodes nothing more of the held packets (they never got
    /// their angles: counted as dropped).
    pub fn finish(&mut self, on_sweep: &mut dyn FnMut(&mut Sweep, &RobosenseFacts)) {
        self.stats.dropped += self.held.len() as u64;
        self.held.clear();
        self.emit(on_sweep);
    }
}

/// Whether a Helios DIFOP's 32 angle entries describe a Helios-16P: its 16 lasers are entries
/// 0–15, a fan falling monotonically, and the unused entries 16–31 all lie more than 1° below
/// that fan (the shared capture's: −9.94° … −53.7° under a fan down to −8.01°). A heuristic:
/// an angle file or `--model` settles it where it fails.
fn helios16p_difop(a: &[(f64, f64)]) -> bool {
    a.len() >= 32
        && a[..16].windows(2).all(|w| w[0].0 > w[1].0)
        && a[16..32].iter().all(|&(v, _)| v < a[15].0 - 1.0)
}
