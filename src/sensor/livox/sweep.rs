//! One Livox sensor's stream: datagrams in (points and IMU, both protocols), sweeps out.
//!
//! A Livox scanner does not spin, so a sweep is an integration period of its point stream:
//! a sweep is cut when a packet's first point is at least the period (default 100 ms,
//! [`LivoxConfig::period_ns`]) after the sweep's first point, or when the device time goes
//! backwards. Where the sensor counts frames — `frame_cnt` steps by one exactly where
//! `udp_cnt` restarts at 0, seen twice — sweeps follow its frames instead (the MID-360
//! protocol says `frame_cnt` means nothing for non-repetitive scanning, so that sensor stays on
//! the period). Loss: SDK2 from `udp_cnt` (+1 per packet, 0 at a frame's start), SDK1 from the
//! device-time gap between consecutive packets (the packet spacing is the model's, or, with
//! no model named, learnt from the stream: the median of the last in-order steps, so a
//! Mid-40 at 1 ms and a Horizon at 0.4 ms are both counted right; until two packets have
//! come, no time gap is counted).
//!
//! A packet a little behind the newest `udp_cnt` (at most [`REORDER_PACKETS`]; SDK1: behind
//! the newest packet's time by at most as many packets) was reordered on the way: it joins
//! the open sweep where its time falls inside it (from the sweep's start to two periods after
//! it; a frame's first packet behind its second starts that frame's sweep instead), else it
//! is dropped as a late one is, and it cuts nothing. A packet of the next `frame_cnt` whose
//! `udp_cnt` is not ahead of the open frame's starts that frame, however short the frames
//! (the next one's 0 may be within the window of the newest). A packet
//! further behind than a reordering explains (more than [`REORDER_PACKETS`] behind the newest
//! `udp_cnt`, or of a frame whose sweep is gone), but at most two periods behind the newest
//! packet's time, came late: it is dropped and counted in [`LivoxStats::late_dropped`] (its
//! gap no longer counted missing, where its frame's numbers are still known: the open frame
//! and the 127 before it; a copy of it is a duplicate), and changes nothing else. Further
//! behind, or with counters and time both jumping, the sensor restarted: one discontinuity. A sweep
//! is also cut when it spans two periods (of 100 ms at least) or holds four times the
//! model's dual-return rate over a period in points (2^22 to 2^26), or as many packets,
//! without the period or the sensor's frame ending it — a timestamp or `frame_cnt` that
//! stands still — counted in [`LivoxStats::forced_cuts`].
//!
//! Once the stream has seen IMU packets, a finished sweep waits for the first IMU sample at or
//! after its last point before it is handed over (on the next datagram, so that a caller that
//! drains [`LivoxStream::drain_imu`] after each push has fed that sample to its deskewer
//! first), and at most until the next sweep is finished. The points and IMU samples come on two
//! ports: live, an IMU packet can reach the host after the point packet that cuts the sweep
//! (two sockets read in any order, in bursts under load), and the sweep's deskew would then
//! hold the angular velocity where a capture read in order interpolates it. Waiting for the
//! covering sample makes the IMU a deskewer sees for a sweep the same in both, at the cost of
//! up to one IMU period (5 ms at 200 Hz) of latency.

use std::collections::VecDeque;

use super::decode::{LivoxDecoder, PacketPoints, Spacing};
use super::frame::{ImuFrame, PointsFrame};
use super::model::{LivoxModel, Protocol, STANDARD_GRAVITY};
use super::wire::{read_imu, LivoxWireError, Record, Sdk1Packet, Sdk2Packet};
use crate::point::Point;
use crate::sensor::{DecodeOptions, ImuSample};
use crate::sweep::ledger::{Count, UdpLedger, LEDGER_NUMBERS};
use crate::sweep::{RecentTimes, SeqStep, SeqWindow, Sweep, REORDER_PACKETS};
use crate::time::ClockSource;

/// Default integration period, ns.
pub const DEFAULT_PERIOD_NS: u64 = 100_000_000;
/// IMU samples held until drained.
pub const MAX_IMU_QUEUE: usize = 4096;
/// A `udp_cnt` jump larger than this is a restart, not loss.
const MAX_COUNTER_GAP: u64 = 4096;
/// Where `udp_cnt` restarts with each frame, a packet of a frame up to this many before the
/// open one (and in time at most two periods late) is late; further back (by `frame_cnt`,
/// mod 256) it is ahead, not behind.
const MAX_FRAMES_BACK: u8 = 127;
/// Fewest and most points a sweep may hold before it is cut (the model's rate sets the cap
/// between them): memory stays bounded whatever the counters and times say.
const MIN_POINT_CAP: f64 = (1u64 << 22) as f64;
const MAX_POINT_CAP: f64 = (1u64 << 26) as f64;
/// SDK1 record spacing a stream may teach, ns: Livox sensors send 100 000 to 480 000
/// points per second; anything outside is a clock step, not a spacing.
const LEARNT_STEP_NS: std::ops::RangeInclusive<i64> = 500..=100_000;

/// How a stream is set up.
#[derive(Clone, Debug)]
pub struct LivoxConfig {
    /// The model (named, or told from the port); `None`: an SDK2 / SDK1 sensor of unknown
    /// model (one line).
    pub model: Option<LivoxModel>,
    /// Protocol when the model is unknown.
    pub protocol: Protocol,
    /// How the model was told.
    pub detection: String,
    /// Range filter.
    pub range: DecodeOptions,
    /// Integration period, ns.
    pub period_ns: u64,
    /// Check the SDK2 CRC-32.
    pub check_crc: bool,
    /// IMU-to-sensor transform overriding the model's published one.
    pub imu_to_sensor: Option<[f64; 16]>,
}

impl LivoxConfig {
    /// Defaults for `model`.
    pub fn new(model: Option<LivoxModel>, protocol: Protocol) -> Self {
        Self {
            model,
            protocol: model.map_or(protocol, LivoxModel::protocol),
            detection: String::new(),
            range: DecodeOptions::default(),
            period_ns: DEFAULT_PERIOD_NS,
            check_crc: true,
            imu_to_sensor: None,
        }
    }
}

/// Counters.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LivoxStats {
    /// Point packets decoded.
    pub packets: u64,
    /// IMU packets decoded.
    pub imu_packets: u64,
    /// Datagrams that are not well-formed (including CRC failures).
    pub malformed: u64,
    /// Of those, CRC failures.
    pub crc_failures: u64,
    /// SDK2 packets whose CRC field is 0 (not filled by the sensor): accepted unchecked.
    pub crc_absent: u64,
    /// Packets whose CRC matched.
    pub crc_ok: u64,
    /// Point packets missing (counter or time gaps).
    pub missing: u64,
    /// IMU packets missing (their counter's gaps).
    pub imu_missing: u64,
    /// Restarts of the counter or device time (too large or backwards).
    pub discontinuities: u64,
    /// Point or IMU packets whose counter was seen already (copies): dropped. An SDK2 point
    /// packet's number is looked up in its frame's ledger, so a copy is one however many
    /// packets came since, where it is timed at the newest packet's time or up to two
    /// periods before it (a number seen again at a later time is a restart); an SDK2 IMU
    /// packet's number seen in the last 11, at one of the last 11 IMU packets' times or at
    /// most two periods before the newest's, likewise; SDK1 packets carry no counter: a copy
    /// repeats one of the last 11 packets' times.
    pub duplicates: u64,
    /// Point packets that came too late to join a sweep, dropped: more than
    /// [`REORDER_PACKETS`] behind the newest `udp_cnt` (within two periods of its time); of a
    /// frame already handed over (its last packets came after the next frame's first ones,
    /// and no IMU wait held it) or of one before that; or late by their `udp_cnt` but timed
    /// outside the sweep they would join (before its start or more than two periods after
    /// it: a time that lies, or a packet reordered across the period's cut; SDK1: late by its
    /// time, reordered behind the packet that began the open sweep). Each is counted
    /// here once and not also missing: the gap it left, counted missing when a later packet
    /// came, is taken off `missing` (and off the `missing_packets` of the sweep that counted
    /// it, while that sweep is open or waiting for its IMU samples; one handed over keeps
    /// it), and a copy of it is a duplicate. That takes its frame's
    /// numbers, which the stream holds for the open frame and the 127 before it. A packet of
    /// a frame it holds none of — from before the stream's first packet, or from before the
    /// counters last restarted — and one more than 4096 numbers from its frame's newest are
    /// counted here and `missing` is left as it is: nothing counted missing since is theirs,
    /// but a loss their frame counted before a restart stays counted too, and each copy of
    /// one is counted here again.
    pub late_dropped: u64,
    /// Sweeps cut because they spanned two periods or reached the point cap before the
    /// period or the sensor's frame ended them (a timestamp or `frame_cnt` standing still).
    pub forced_cuts: u64,
    /// IMU samples dropped because nobody drained them.
    pub imu_dropped: u64,
    /// Sweeps emitted.
    pub sweeps: u64,
    /// Points emitted.
    pub points: u64,
    /// Points with a non-zero tag.
    pub tagged_points: u64,
    /// Sweeps handed over without an IMU sample at or after their last point (the IMU
    /// stopped or lags by more than a sweep).
    pub imu_uncovered_sweeps: u64,
    /// Frames of decoded points (`CustomMsg` from a bag, [`super::frame`]) read.
    pub frames: u64,
    /// Points of those frames with a non-finite coordinate: dropped.
    pub frame_points_dropped: u64,
    /// Fewest / most points in a sweep.
    pub min_sweep_points: u64,
    /// Most points in a sweep.
    pub max_sweep_points: u64,
}

/// What the stream knows of its sensor.
#[derive(Clone, Debug, PartialEq)]
pub struct LivoxFacts {
    /// Model, when known.
    pub model: Option<LivoxModel>,
    /// Protocol.
    pub protocol: Protocol,
    /// How the model was told.
    pub detection: String,
    /// Clock of the sweep timestamps.
    pub clock: ClockSource,
    /// Last time type byte (SDK2: 0 none, 1 PTP, 2 GPS; SDK1: 0 none, 1 PTP, 3 PPS+GPS, 4 PPS).
    pub time_type: Option<u8>,
    /// Last point data type.
    pub data_type: Option<u8>,
    /// Integration period, ns.
    pub period_ns: u64,
    /// Whether sweeps follow the sensor's frame counter.
    pub frame_cut: bool,
    /// Laser lines.
    pub lines: u16,
    /// IMU-to-sensor transform in use.
    pub imu_to_sensor: [f64; 16],
    /// SDK1 status code of the last packet.
    pub status_code: Option<u32>,
    /// Points in the last sweep.
    pub last_sweep_points: u64,
}

impl LivoxFacts {
    /// Name of the time type, as the protocol's table words it.
    pub fn time_type_name(&self) -> &'static str {
        match (self.protocol, self.time_type) {
            (_, None) => "",
            (_, Some(0)) => "none (since power-on)",
            (_, Some(1)) => "ptp",
            (Protocol::Sdk2, Some(2)) => "gps",
            (Protocol::Sdk1, Some(3)) => "pps+gps",
            (Protocol::Sdk1, Some(4)) => "pps",
            _ => "unknown",
        }
    }
}

/// One sensor's stream.
#[derive(Debug)]
pub struct LivoxStream {
    cfg: LivoxConfig,
    decoder: LivoxDecoder,
    facts: LivoxFacts,
    stats: LivoxStats,
    sweep: Sweep,
    next_index: u64,
    open: bool,
    /// Device time of the open sweep's last record so far.
    open_end_ns: i64,
    /// A finished sweep waiting for its IMU coverage (the module's doc), and its last record's
    /// device time.
    held: Sweep,
    held_waiting: bool,
    held_end_ns: i64,
    /// SDK2: the first number of the open run whose gap the open sweep counted (the first
    /// its first packet skipped), and the held sweep's: a late packet of the run fills the
    /// gap of the sweep whose numbers it is among. `None` for the held sweep where the run
    /// began since (its numbers are a closed frame's, or forgotten).
    open_gaps_from: Option<u16>,
    held_gaps_from: Option<u16>,
    /// Device time of the newest IMU sample decoded.
    newest_imu_ns: Option<i64>,
    /// First-record time of the last point packet: a later packet earlier than it is a
    /// restart of the device clock (a packet's records may overlap the next one's by a
    /// spacing, depending on how the sensor fills `time_interval`).
    last_packet_ns: Option<i64>,
    /// SDK2 `udp_cnt` of the point packets of the open run (frame) and of the IMU packets.
    udp: UdpLedger,
    imu_udp: SeqWindow,
    /// Time of the SDK2 IMU packet whose number is `imu_udp`'s latest: a number seen again,
    /// at that time or a little before it, is a copy however many times were pushed out of
    /// `imu_recent` since; at a later time, the counter restarted.
    imu_latest_ns: Option<i64>,
    last_frame: Option<u8>,
    /// Sensors that restart `udp_cnt` with their frames: the frames before the open one and
    /// their numbers, newest first, for their packets that come after the next frame's first.
    /// Every frame such a packet may be of is kept ([`MAX_FRAMES_BACK`], a KiB each), so that
    /// one counted missing in its frame is taken off `missing` however far back it is.
    closed: VecDeque<(u8, UdpLedger)>,
    frame_starts: u32,
    sdk1_next_ns: Option<i64>,
    /// SDK1 of no known model: record spacings seen, and the last in-order packet's records.
    sdk1_steps: LearntSpacing,
    sdk1_last_records: usize,
    /// Most points in a sweep.
    max_points: usize,
    /// The times of the last point packets and of the last IMU packets: a copy repeats one
    /// (SDK1 packets carry no counter; an SDK2 counter seen again at a new time restarted).
    recent: RecentTimes,
    imu_recent: RecentTimes,
    imu: VecDeque<ImuSample>,
}

impl LivoxStream {
    /// A stream.
    pub fn new(cfg: LivoxConfig) -> Self {
        let lines = cfg.model.map_or(1, LivoxModel::lines);
        let imu_to_sensor = cfg
            .imu_to_sensor
            .or_else(|| cfg.model.map(LivoxModel::imu_to_sensor))
            .unwrap_or_else(|| LivoxModel::Hap.imu_to_sensor());
        let facts = LivoxFacts {
            model: cfg.model,
            protocol: cfg.protocol,
            detection: cfg.detection.clone(),
            clock: ClockSource::Host,
            time_type: None,
            data_type: None,
            period_ns: cfg.period_ns,
            frame_cut: false,
            lines,
            imu_to_sensor,
            status_code: None,
            last_sweep_points: 0,
        };
        // Dual returns double the rate; four times that over a period is no sweep a sensor
        // sends, only one its counters or times failed to cut.
        let rate = cfg.model.map_or(480_000.0, |m| f64::from(m.point_rate()));
        let max_points =
            (8.0 * rate * cfg.period_ns as f64 / 1e9).clamp(MIN_POINT_CAP, MAX_POINT_CAP) as usize;
        Self {
            decoder: LivoxDecoder::new(lines, cfg.range),
            cfg,
            facts,
            stats: LivoxStats::default(),
            sweep: Sweep::default(),
            next_index: 0,
            open: false,
            open_end_ns: 0,
            held: Sweep::default(),
            held_waiting: false,
            held_end_ns: 0,
            open_gaps_from: None,
            held_gaps_from: None,
            newest_imu_ns: None,
            imu_latest_ns: None,
            last_packet_ns: None,
            udp: UdpLedger::new(MAX_COUNTER_GAP),
            imu_udp: SeqWindow::new(16, MAX_COUNTER_GAP),
            last_frame: None,
            closed: VecDeque::new(),
            frame_starts: 0,
            sdk1_next_ns: None,
            sdk1_steps: LearntSpacing::default(),
            sdk1_last_records: 0,
            max_points,
            recent: RecentTimes::default(),
            imu_recent: RecentTimes::default(),
            imu: VecDeque::new(),
        }
    }

    /// Facts.
    pub fn facts(&self) -> &LivoxFacts {
        &self.facts
    }

    /// Counters.
    pub fn stats(&self) -> &LivoxStats {
        &self.stats
    }

    /// Configuration.
    pub fn config(&self) -> &LivoxConfig {
        &self.cfg
    }

    /// IMU samples decoded since the last call.
    pub fn drain_imu(&mut self) -> impl Iterator<Item = ImuSample> + '_ {
        self.imu.drain(..)
    }

    /// Pushes one datagram; finished sweeps go to `on_sweep`. Malformed datagrams are counted.
    pub fn push(
        &mut self,
        host_ns: i64,
        payload: &[u8],
        on_sweep: &mut dyn FnMut(&mut Sweep, &LivoxFacts),
    ) {
        if self.held_waiting && self.covered(self.held_end_ns) {
            self.release(on_sweep);
        }
        if PointsFrame::is_frame(payload) {
            match PointsFrame::new(payload) {
                Some(f) => self.push_frame(host_ns, f, on_sweep),
                None => self.stats.malformed += 1,
            }
            return;
        }
        if ImuFrame::is_frame(payload) {
            match ImuFrame::new(payload) {
                Some(f) => self.push_imu_frame(host_ns, f),
                None => self.stats.malformed += 1,
            }
            return;
        }
        let r = match self.cfg.protocol {
            Protocol::Sdk2 => self.push_sdk2(host_ns, payload, on_sweep),
            Protocol::Sdk1 => self.push_sdk1(host_ns, payload, on_sweep),
        };
        if let Err(e) = r {
            self.stats.malformed += 1;
            if matches!(e, LivoxWireError::Crc { .. }) {
                self.stats.crc_failures += 1;
            }
        }
    }

    /// A frame of points decoded already: one sweep of its own (a sweep still open is finished
    /// first), `ring` = line, `t` = `offset_time`, intensity = reflectivity, the tag kept; the
    /// range filter applies, as to packets.
    fn push_frame(
        &mut self,
        host_ns: i64,
        f: PointsFrame<'_>,
        on_sweep: &mut dyn FnMut(&mut Sweep, &LivoxFacts),
    ) {
        let ts = i64::try_from(f.timebase_ns()).unwrap_or(i64::MAX);
        self.emit(on_sweep);
        self.begin(host_ns, ts, 0);
        let r = self.cfg.range;
        let (min2, max2) = (r.min_range * r.min_range, r.max_range * r.max_range);
        let mut last = ts;
        let mut lines = self.facts.lines;
        for p in f.points() {
            let [x, y, z] = p.xyz;
            if !(x.is_finite() && y.is_finite() && z.is_finite()) {
                self.stats.frame_points_dropped += 1;
                continue;
            }
            let d2 = x * x + y * y + z * z;
            if d2 == 0.0 || d2 < min2 || d2 > max2 {
                continue;
            }
            last = last.max(ts.saturating_add(i64::from(p.offset_time_ns)));
            lines = lines.max(u16::from(p.line) + 1);
            self.sweep.points.push(Point {
                x,
                y,
                z,
                intensity: f32::from(p.reflectivity),
                t: p.offset_time_ns,
                ring: u16::from(p.line),
                ret: 0,
                pad: p.tag,
            });
        }
        self.facts.lines = lines;
        self.stats.frames += 1;
        self.open_end_ns = last;
        self.sweep.packets = self.sweep.packets.saturating_add(1);
        self.sweep.last_host_ns = host_ns;
        self.last_packet_ns = Some(ts);
        self.emit(on_sweep);
    }

    /// Emits the sweep waiting for its IMU samples, if any, and the open sweep.
    pub fn finish(&mut self, on_sweep: &mut dyn FnMut(&mut Sweep, &LivoxFacts)) {
        self.emit(on_sweep);
        self.release(on_sweep);
    }

    fn queue_imu(&mut self, s: ImuSample) {
        // The latest, not the largest: after a device clock restart, older times count again.
        self.newest_imu_ns = i64::try_from(s.sensor_ns).ok();
        if self.imu.len() < MAX_IMU_QUEUE {
            self.imu.push_back(s);
        } else {
            self.stats.imu_dropped += 1;
        }
    }

    fn clock_of(protocol: Protocol, time_type: u8) -> ClockSource {
        match (protocol, time_type) {
            (_, 1) => ClockSource::SensorPtp,
            (Protocol::Sdk2, 2) | (Protocol::Sdk1, 3) => ClockSource::SensorGps,
            _ => ClockSource::Host,
        }
    }

    fn push_sdk2(
        &mut self,
        host_ns: i64,
        payload: &[u8],
        on_sweep: &mut dyn FnMut(&mut Sweep, &LivoxFacts),
    ) -> Result<(), LivoxWireError> {
        let p = Sdk2Packet::new(payload)?;
        // The CRC covers the timestamp and the data, not the counters before them: a packet
        // that fails it is dropped, but its counters still say it came (and what it skipped),
        // so the next packet does not count it missing too.
        let mut damaged = None;
        if self.cfg.check_crc {
            let stored = p.stored_crc();
            if stored == 0 {
                self.stats.crc_absent += 1;
            } else {
                let computed = p.computed_crc();
                if stored == computed {
                    self.stats.crc_ok += 1;
                } else {
                    damaged = Some(LivoxWireError::Crc { stored, computed });
                }
            }
        }
        let ts = i64::try_from(p.timestamp_ns()).unwrap_or(i64::MAX);
        if damaged.is_none() {
            self.facts.time_type = Some(p.time_type());
            self.facts.clock = Self::clock_of(Protocol::Sdk2, p.time_type());
        }
        if p.record() == Record::Imu {
            return self.push_sdk2_imu(&p, ts, host_ns, damaged);
        }
        let trusted = damaged.is_none();
        if trusted {
            self.facts.data_type = Some(p.data_type());
        }
        let (udp, frame) = (p.udp_cnt(), p.frame_cnt());
        let period = i64::try_from(self.cfg.period_ns).unwrap_or(i64::MAX);
        // A sensor that restarts counts from 0, seconds back; one on PTP goes on ahead: a
        // packet at most two periods behind the newest was held up on the way.
        let behind_in_time = trusted
            && self
                .last_packet_ns
                .is_some_and(|l| ts < l && l.saturating_sub(ts) <= period.saturating_mul(2));
        let next_frame = self.last_frame.map(|f| f.wrapping_add(1)) == Some(frame);
        // Where `udp_cnt` restarts with each frame, a packet of an older frame is numbered in
        // its own frame: however late, counted against the open frame it would read as loss.
        if self.frame_starts > 0 {
            let frames_back = self.last_frame.map_or(0, |f| f.wrapping_sub(frame));
            if (1..=MAX_FRAMES_BACK).contains(&frames_back) && (behind_in_time || !trusted) {
                if let Some(k) = self.closed.iter().position(|(f, _)| *f == frame) {
                    return self.push_closed_frame(k, &p, host_ns, ts, damaged);
                }
                // A frame the stream holds no numbers of (before its first packet, or before
                // the counters last restarted): nothing it counted missing is known to be
                // this packet's.
                return match damaged {
                    Some(e) => Err(e),
                    None => {
                        self.stats.late_dropped += 1;
                        Ok(())
                    }
                };
            }
        }
        let count = self.udp.peek(udp);
        let reorder = REORDER_PACKETS;
        let arrival = match count {
            // The next frame's number, not ahead of the open frame's: `udp_cnt` restarted with
            // the frame, its first packets lost where the number is not 0. No packet of the
            // open frame carries the next frame's number, so this holds before the stream has
            // seen a frame start too: a frame of at most 11 packets puts the next one's 0
            // within the reorder window of its newest, where, from before the numbers the
            // stream holds (it began mid-frame), it read as a stray of the open frame.
            _ if next_frame && udp < LEDGER_NUMBERS && !matches!(count, Count::Next { .. }) => {
                Arrival::FrameStart
            }
            Count::Next { lost } => Arrival::Next { lost },
            Count::Lost { behind } if behind <= reorder => Arrival::Late { filled: true },
            Count::Stray => Arrival::Late { filled: false },
            Count::Seen { behind }
                if behind <= reorder && (!trusted || self.recent.contains(ts)) =>
            {
                Arrival::Copy
            }
            // The newest packet's time, or up to two periods before it, however many packets
            // came since (only the last 11 times are kept, and late packets and a closed
            // frame's push them out): a copy. A restart's time goes on, or back by seconds.
            Count::Seen { .. } if behind_in_time || self.last_packet_ns == Some(ts) || !trusted => {
                Arrival::Copy
            }
            Count::Lost { .. } if behind_in_time || !trusted => Arrival::Stale { filled: true },
            Count::Far if behind_in_time => Arrival::Stale { filled: false },
            // A damaged packet's counters never restart the count: the next good one decides.
            _ if !trusted => Arrival::Copy,
            _ => Arrival::Restart,
        };
        let mut lost = 0;
        // A packet a little behind the latest was reordered on the way: it fills the gap its
        // successor counted (`Some(whether it did)`), cuts nothing, and the stream goes on from
        // the latest.
        let mut late = None;
        let mut frame_start = false;
        match arrival {
            Arrival::Copy => {
                return match damaged {
                    Some(e) => Err(e),
                    None => {
                        self.stats.duplicates += 1;
                        Ok(())
                    }
                };
            }
            Arrival::Stale { filled } => {
                if filled {
                    self.udp.take(udp);
                    self.unmiss_sdk2(udp);
                } else {
                    // From before the run's first number: kept, so that a copy is a copy.
                    self.udp.take_before(udp);
                }
                return match damaged {
                    Some(e) => Err(e),
                    None => {
                        self.stats.late_dropped += 1;
                        Ok(())
                    }
                };
            }
            Arrival::Late { filled } => {
                late = Some(filled);
                self.udp.take(udp);
                // It came: off `missing` whether it joins the open sweep or is dropped (in
                // its own sweep's count too, a damaged one as well).
                if filled {
                    self.unmiss_sdk2(udp);
                }
            }
            Arrival::Next { lost: l } => {
                self.udp.take(udp);
                self.stats.missing += l;
                lost = l;
            }
            Arrival::FrameStart => {
                frame_start = true;
                lost = u64::from(udp);
                self.stats.missing += lost;
                self.frame_starts = self.frame_starts.saturating_add(1);
                // The open frame's numbers join the closed ones'; the oldest are forgotten
                // (their ledger is the new open frame's).
                let oldest = if self.closed.len() >= usize::from(MAX_FRAMES_BACK) {
                    self.closed.pop_back().map(|(_, numbers)| numbers)
                } else {
                    None
                };
                let mut numbers = oldest.unwrap_or_else(|| UdpLedger::new(MAX_COUNTER_GAP));
                std::mem::swap(&mut numbers, &mut self.udp);
                if let Some(f) = self.last_frame {
                    self.closed.push_front((f, numbers));
                }
                self.udp.start_lost_before(udp);
            }
            Arrival::Restart => {
                self.udp.restart(udp);
                self.closed.clear();
                // A restart at 0 without a frame step: a sensor whose `frame_cnt` means
                // nothing may restart `udp_cnt` with its frames; nothing is known lost.
                if udp != 0 {
                    self.stats.discontinuities += 1;
                }
            }
        }
        self.recent.push(ts);
        if late.is_none() {
            self.last_frame = Some(frame);
        }
        if self.frame_starts >= 2 {
            self.facts.frame_cut = true;
        }
        if let Some(e) = damaged {
            if self.open {
                self.sweep.missing_packets += lost;
            }
            return Err(e);
        }
        if late.is_some() {
            let its_frame = self.facts.frame_cut && self.sweep.frame_id == u32::from(frame);
            if self.open && its_frame && p.records() > 0 {
                self.start_earlier(ts);
            }
            if !(self.open && self.join_late(false, &p, host_ns, ts)) {
                self.stats.late_dropped += 1;
            }
            return Ok(());
        }
        let interval = p.time_interval_ns();
        let cut = if self.facts.frame_cut {
            frame_start || (self.open && self.sweep.frame_id != u32::from(frame))
        } else {
            self.time_cut(ts)
        };
        // A restart already counted is one discontinuity, not two.
        let backwards = self.last_packet_ns.is_some_and(|l| ts < l);
        if backwards && !(arrival == Arrival::Restart && udp != 0) {
            self.stats.discontinuities += 1;
        }
        let forced = !(cut || backwards) && self.overfull(ts);
        if forced {
            self.stats.forced_cuts += 1;
        }
        if cut || backwards || forced {
            self.emit(on_sweep);
        }
        let fresh = !self.open;
        self.begin(host_ns, ts, u32::from(frame));
        let new_run = matches!(arrival, Arrival::FrameStart | Arrival::Restart);
        if new_run {
            self.held_gaps_from = None;
        }
        if fresh || new_run {
            self.open_gaps_from = Some(udp.wrapping_sub(u16::try_from(lost).unwrap_or(u16::MAX)));
        }
        self.sweep.missing_packets += lost;
        decode_sdk2(&self.decoder, &p, ts, None, &mut self.sweep);
        self.after_packet(
            host_ns,
            ts,
            ts.saturating_add(i64::try_from(interval).unwrap_or(i64::MAX)),
        );
        Ok(())
    }

    /// A frame's first packet reordered behind a later one, which began its sweep: the sweep
    /// is its frame's, so it starts at this packet instead, its points' times moved on by as
    /// much. Only while the sweep holds no more packets than a reorder spans (every point is
    /// moved), and never to span more than a sweep may.
    fn start_earlier(&mut self, ts: i64) {
        let Ok(by) = u32::try_from(self.sweep.device_time_ns.saturating_sub(ts)) else {
            return;
        };
        if by == 0
            || self.sweep.packets > u32::from(REORDER_PACKETS)
            || self.open_end_ns.saturating_sub(ts) > self.max_span_ns()
        {
            return;
        }
        for p in &mut self.sweep.points {
            p.t = p.t.saturating_add(by);
        }
        self.sweep.device_time_ns = ts;
        if self.sweep.clock != ClockSource::Host {
            self.sweep.timestamp_ns = ts;
        }
    }

    /// A late SDK2 point packet into the open sweep (`into_held`: the sweep waiting for its
    /// IMU samples), which must be begun, as [`Self::join_decoded`] tells.
    fn join_late(&mut self, into_held: bool, p: &Sdk2Packet<'_>, host_ns: i64, ts: i64) -> bool {
        let end = ts.saturating_add(i64::try_from(p.time_interval_ns()).unwrap_or(i64::MAX));
        self.join_decoded(into_held, host_ns, end, |decoder, max_t_ns, sweep| {
            decode_sdk2(decoder, p, ts, Some(max_t_ns), sweep)
        })
    }

    /// A late point packet, its last record timed `end_ns`, into the open or the held sweep
    /// (`into_held`): `decode` appends its records timed inside the sweep (`0 ..=` the longest
    /// a sweep may span after its start, the bound it is given), and if there are any the
    /// packet joins (the gap it fills the caller has taken off, joined or not).
    /// A packet with no such record — its time lies, or it belongs to a sweep already
    /// finished — joins nothing: `false`, the caller counts it dropped. Late, it moves no cut
    /// and leaves the stream's newest packet as it was.
    fn join_decoded(
        &mut self,
        into_held: bool,
        host_ns: i64,
        end_ns: i64,
        decode: impl FnOnce(&LivoxDecoder, i64, &mut Sweep) -> PacketPoints,
    ) -> bool {
        let max_t_ns = self.max_span_ns();
        let (sweep, sweep_end_ns) = if into_held {
            (&mut self.held, &mut self.held_end_ns)
        } else {
            (&mut self.sweep, &mut self.open_end_ns)
        };
        if decode(&self.decoder, max_t_ns, sweep).in_window == 0 {
            return false;
        }
        sweep.packets = sweep.packets.saturating_add(1);
        sweep.columns_count = sweep.columns_count.saturating_add(1);
        sweep.last_host_ns = sweep.last_host_ns.max(host_ns);
        *sweep_end_ns = (*sweep_end_ns).max(end_ns);
        self.stats.packets += 1;
        true
    }

    /// An SDK2 IMU packet. A damaged one (`damaged`: its CRC failed) is numbered, so the next
    /// does not count it missing, and then dropped; its counter never restarts the window,
    /// as its time (under the CRC) cannot tell a copy from a restart.
    fn push_sdk2_imu(
        &mut self,
        p: &Sdk2Packet<'_>,
        ts: i64,
        host_ns: i64,
        damaged: Option<LivoxWireError>,
    ) -> Result<(), LivoxWireError> {
        let udp = u64::from(p.udp_cnt());
        let trusted = damaged.is_none();
        let step = if trusted {
            self.imu_udp.step(udp)
        } else {
            self.imu_udp.step_within(udp)
        };
        // Only the last 11 times are kept, and late packets push them out: a number seen
        // again at the newest packet's time, or up to two periods before it, is a copy too.
        let period = i64::try_from(self.cfg.period_ns).unwrap_or(i64::MAX);
        let not_after_newest = self
            .imu_latest_ns
            .is_some_and(|l| ts <= l && l.saturating_sub(ts) <= period.saturating_mul(2));
        match step {
            SeqStep::Duplicate if !trusted => {}
            SeqStep::Duplicate if self.imu_recent.contains(ts) || not_after_newest => {
                self.stats.duplicates += 1;
                return Ok(());
            }
            // The number again at a new time: the counter restarted or stands still.
            SeqStep::Duplicate => {
                self.imu_udp.restart(udp);
                self.imu_latest_ns = Some(ts);
            }
            SeqStep::Next { lost } => {
                self.stats.imu_missing += lost;
                if trusted {
                    self.imu_latest_ns = Some(ts);
                }
            }
            SeqStep::Late => self.stats.imu_missing = self.stats.imu_missing.saturating_sub(1),
            // A restart (the counter may restart at 0 with each frame): no loss known.
            SeqStep::Jump if trusted => self.imu_latest_ns = Some(ts),
            SeqStep::Jump | SeqStep::Stray => {}
        }
        if let Some(e) = damaged {
            return Err(e);
        }
        self.imu_recent.push(ts);
        self.stats.imu_packets += 1;
        for i in 0..p.records() {
            self.push_imu_record(p.record_bytes(i), ts, host_ns);
        }
        Ok(())
    }

    /// A point packet of a frame before the open one (`k`: 0 the newest closed): its frame's
    /// last packets came after the next frame's first. It is late, never a cut; its number
    /// fills its frame's gap (once: a copy is a copy, however far behind) or tells the frame's
    /// tail lost. Where sweeps follow the frames, its points join its frame's sweep while that
    /// waits for its IMU samples; on the period, a packet of the frame just closed joins the
    /// open sweep as any late packet's do (in either, where its time falls inside the sweep);
    /// else it is dropped (counted). A damaged one (`damaged`) only does the counting.
    fn push_closed_frame(
        &mut self,
        k: usize,
        p: &Sdk2Packet<'_>,
        host_ns: i64,
        ts: i64,
        damaged: Option<LivoxWireError>,
    ) -> Result<(), LivoxWireError> {
        let Some((frame, ledger)) = self.closed.get_mut(k) else {
            return match damaged {
                Some(e) => Err(e),
                None => {
                    self.stats.late_dropped += 1;
                    Ok(())
                }
            };
        };
        let frame = u32::from(*frame);
        let udp = p.udp_cnt();
        let (filled, lost) = match ledger.peek(udp) {
            Count::Lost { .. } => (true, 0),
            Count::Next { lost } => (false, lost),
            Count::Stray => (false, 0),
            Count::Seen { .. } => {
                return match damaged {
                    Some(e) => Err(e),
                    None => {
                        self.stats.duplicates += 1;
                        Ok(())
                    }
                };
            }
            // Far ahead of the frame's numbers or before them: nothing to tell of its loss.
            // Kept where the ledger reaches it, so that a copy is a copy.
            Count::Far => {
                ledger.take_before(udp);
                return match damaged {
                    Some(e) => Err(e),
                    None => {
                        self.stats.late_dropped += 1;
                        Ok(())
                    }
                };
            }
        };
        ledger.take(udp);
        self.recent.push(ts);
        self.stats.missing += lost;
        if filled {
            self.stats.missing = self.stats.missing.saturating_sub(1);
        }
        let into_held = self.facts.frame_cut;
        let sweep = if k == 0 && !into_held && self.open {
            &mut self.sweep
        } else if k == 0 && into_held && self.held_waiting && self.held.frame_id == frame {
            &mut self.held
        } else {
            return match damaged {
                Some(e) => Err(e),
                None => {
                    self.stats.late_dropped += 1;
                    Ok(())
                }
            };
        };
        // The gap it fills is taken off the sweep it would join, joined or not.
        sweep.missing_packets += lost;
        if filled {
            sweep.missing_packets = sweep.missing_packets.saturating_sub(1);
        }
        if let Some(e) = damaged {
            return Err(e);
        }
        if !self.join_late(into_held, p, host_ns, ts) {
            self.stats.late_dropped += 1;
        }
        Ok(())
    }

    fn push_sdk1(
        &mut self,
        host_ns: i64,
        payload: &[u8],
        on_sweep: &mut dyn FnMut(&mut Sweep, &LivoxFacts),
    ) -> Result<(), LivoxWireError> {
        let p = Sdk1Packet::new(payload)?;
        let Some(ts) = p.timestamp_ns() else {
            return Err(LivoxWireError::DataType {
                what: "Livox SDK1 UTC timestamp",
                found: p.timestamp_type(),
            });
        };
        let ts = i64::try_from(ts).unwrap_or(i64::MAX);
        self.facts.time_type = Some(p.timestamp_type());
        self.facts.clock = Self::clock_of(Protocol::Sdk1, p.timestamp_type());
        self.facts.status_code = Some(p.status_code());
        if p.record() == Record::Imu {
            self.stats.imu_packets += 1;
            self.push_imu_record(p.record_bytes(0), ts, host_ns);
            return Ok(());
        }
        self.facts.data_type = Some(p.data_type());
        // Without a counter, a copy shows by its time: two packets of one sensor never share
        // a first point's time.
        if self.recent.contains(ts) {
            self.stats.duplicates += 1;
            return Ok(());
        }
        // The model's spacing, else the stream's; before it is learnt, the Horizon's (the
        // shortest) bounds the reorder window, and no time gap counts.
        let known = match self.cfg.model {
            Some(m) => Some(m.sdk1_point_interval_ns() as i64),
            None => self.sdk1_steps.median(),
        };
        let step = known.unwrap_or(4_167);
        let n = p.records();
        let mut lost = 0;
        // A packet a little older than the latest was reordered on the way (these packets
        // carry no counter: by time).
        let period = step * n as i64;
        let late = self
            .last_packet_ns
            .is_some_and(|l| ts < l && ts >= l.saturating_sub(i64::from(REORDER_PACKETS) * period));
        let spacing = Spacing::step(u64::try_from(step).unwrap_or(0));
        let last = ts.saturating_add(step.saturating_mul(n.saturating_sub(1) as i64));
        if late {
            // It came: off `missing` whether it joins the open sweep or is dropped. Only its
            // records timed inside the sweep join it, as an SDK2 packet late by its counter
            // does: one reordered behind the packet that began the sweep is timed before it
            // (its points went in clamped to t = 0).
            self.unmiss();
            self.recent.push(ts);
            let joined = self.open
                && self.join_decoded(false, host_ns, last, |decoder, max_t_ns, sweep| {
                    decoder.decode_within(
                        p.record(),
                        n,
                        |i| p.record_bytes(i),
                        ts,
                        spacing,
                        sweep.device_time_ns,
                        max_t_ns,
                        &mut sweep.points,
                    )
                });
            if !joined {
                self.stats.late_dropped += 1;
            }
            return Ok(());
        }
        if let Some(next) = self.sdk1_next_ns {
            let gap = ts - next;
            if gap < 0 {
                if ts < next - period {
                    self.stats.discontinuities += 1;
                }
            } else if period > 0 && known.is_some() {
                let l = ((gap as f64) / (period as f64)).round() as u64;
                if l < MAX_COUNTER_GAP {
                    self.stats.missing += l;
                    lost = l;
                } else {
                    self.stats.discontinuities += 1;
                }
            }
        }
        // Where the next packet is due is not known before the spacing is.
        self.sdk1_next_ns = known.map(|step| ts.saturating_add(step * n as i64));
        let backwards = self.last_packet_ns.is_some_and(|l| ts < l);
        if backwards {
            // A clock that restarted (or a capture replayed again) may repeat times.
            self.recent.clear();
        }
        if self.cfg.model.is_none() {
            // Consecutive packets are a packet's records apart; over a loss, a multiple of
            // that, which the median outvotes.
            if let Some(prev) = self.last_packet_ns.filter(|&l| ts > l) {
                let per = (ts - prev) / self.sdk1_last_records.max(1) as i64;
                if LEARNT_STEP_NS.contains(&per) {
                    self.sdk1_steps.push(per);
                }
            }
            self.sdk1_last_records = n;
        }
        self.recent.push(ts);
        let cut = self.time_cut(ts) || backwards;
        let forced = !cut && self.overfull(ts);
        if forced {
            self.stats.forced_cuts += 1;
        }
        if cut || forced {
            self.emit(on_sweep);
        }
        self.begin(host_ns, ts, 0);
        self.sweep.missing_packets += lost;
        let start = self.sweep.device_time_ns;
        self.decoder.decode(
            p.record(),
            n,
            |i| p.record_bytes(i),
            ts,
            spacing,
            start,
            &mut self.sweep.points,
        );
        self.after_packet(host_ns, ts, last);
        Ok(())
    }

    /// A sample of the driver's IMU topic (a bag's `sensor_msgs/Imu`): counted and queued as
    /// an IMU packet's sample is, so sweeps of `CustomMsg` frames wait for it as packets' do.
    fn push_imu_frame(&mut self, host_ns: i64, f: ImuFrame<'_>) {
        self.stats.imu_packets += 1;
        let (g, a) = (f.gyro(), f.accel());
        if g.iter().chain(a.iter()).all(|v| v.is_finite()) {
            self.queue_imu(ImuSample {
                sensor_ns: f.time_ns(),
                host_ns,
                accel: a,
                gyro: g,
            });
        }
    }

    fn push_imu_record(&mut self, rec: &[u8], ts: i64, host_ns: i64) {
        let raw = read_imu(rec);
        let g = raw.gyro.map(f64::from);
        let a = raw.acc.map(|v| f64::from(v) * STANDARD_GRAVITY);
        if g.iter().chain(a.iter()).all(|v| v.is_finite()) {
            self.queue_imu(ImuSample {
                sensor_ns: ts.max(0) as u64,
                host_ns,
                accel: a,
                gyro: g,
            });
        }
    }

    /// Whether the open sweep is as long as a sweep may be: two periods (two of the default
    /// at least, so a frame-cut sensor on a shorter period keeps its frames whole), or the
    /// point cap, or as many packets (those with no points grow nothing else).
    fn overfull(&self, ts: i64) -> bool {
        self.open
            && (ts.saturating_sub(self.sweep.device_time_ns) >= self.max_span_ns()
                || self.sweep.points.len() >= self.max_points
                || self.sweep.packets as usize >= self.max_points)
    }

    /// The longest a sweep may span, ns: two periods, of the default at least.
    fn max_span_ns(&self) -> i64 {
        let span = self.cfg.period_ns.max(DEFAULT_PERIOD_NS).saturating_mul(2);
        i64::try_from(span).unwrap_or(i64::MAX)
    }

    fn time_cut(&self, ts: i64) -> bool {
        self.open
            && ts.saturating_sub(self.sweep.device_time_ns)
                >= i64::try_from(self.cfg.period_ns).unwrap_or(i64::MAX)
    }

    fn begin(&mut self, host_ns: i64, ts: i64, frame: u32) {
        if self.open {
            return;
        }
        self.open = true;
        self.sweep.clear();
        self.sweep.index = self.next_index;
        self.sweep.device_time_ns = ts;
        self.sweep.clock = self.facts.clock;
        self.sweep.timestamp_ns = match self.facts.clock {
            ClockSource::Host => host_ns,
            _ => ts,
        };
        self.sweep.first_host_ns = host_ns;
        self.sweep.frame_id = frame;
        self.open_end_ns = ts;
    }

    /// Whether IMU samples reach `end_ns` (or none has been seen: nothing to wait for).
    fn covered(&self, end_ns: i64) -> bool {
        self.stats.imu_packets == 0 || self.newest_imu_ns.is_some_and(|t| t >= end_ns)
    }

    /// A late packet came: one fewer missing (in the open sweep too, if it counted it).
    fn unmiss(&mut self) {
        self.stats.missing = self.stats.missing.saturating_sub(1);
        if self.open {
            self.sweep.missing_packets = self.sweep.missing_packets.saturating_sub(1);
        }
    }

    /// A late SDK2 packet of the open run came, number `udp` counted lost: one fewer missing,
    /// in the sweep that counted it too where that is still open or held (the open sweep
    /// counted the run's numbers from `open_gaps_from` on, the held one those from
    /// `held_gaps_from`); a sweep handed over keeps its count.
    fn unmiss_sdk2(&mut self, udp: u16) {
        self.stats.missing = self.stats.missing.saturating_sub(1);
        let Some(latest) = self.udp.latest() else {
            return;
        };
        let among =
            |from: Option<u16>| from.is_some_and(|f| udp.wrapping_sub(f) <= latest.wrapping_sub(f));
        let sweep = if self.open && among(self.open_gaps_from) {
            &mut self.sweep
        } else if self.held_waiting && among(self.held_gaps_from) {
            &mut self.held
        } else {
            return;
        };
        sweep.missing_packets = sweep.missing_packets.saturating_sub(1);
    }

    fn after_packet(&mut self, host_ns: i64, first_ns: i64, last_ns: i64) {
        self.open_end_ns = self.open_end_ns.max(last_ns);
        self.stats.packets += 1;
        self.sweep.packets = self.sweep.packets.saturating_add(1);
        self.sweep.columns_count = self.sweep.columns_count.saturating_add(1);
        self.sweep.last_host_ns = host_ns;
        self.last_packet_ns = Some(first_ns);
    }

    /// Finishes the open sweep: handed over now when its IMU samples are in, else held (the
    /// module's doc); a sweep still held from before goes first, covered or not.
    fn emit(&mut self, on_sweep: &mut dyn FnMut(&mut Sweep, &LivoxFacts)) {
        if !self.open {
            return;
        }
        self.open = false;
        if self.held_waiting {
            self.stats.imu_uncovered_sweeps += 1;
            self.release(on_sweep);
        }
        self.held_gaps_from = self.open_gaps_from.take();
        // The buffers trade places: no allocation per sweep.
        std::mem::swap(&mut self.sweep, &mut self.held);
        self.held_waiting = true;
        self.held_end_ns = self.open_end_ns;
        self.next_index += 1;
        if self.covered(self.held_end_ns) {
            self.release(on_sweep);
        }
    }

    /// Hands over the held sweep, if any.
    fn release(&mut self, on_sweep: &mut dyn FnMut(&mut Sweep, &LivoxFacts)) {
        if !self.held_waiting {
            return;
        }
        self.held_waiting = false;
        let n = self.held.points.len() as u64;
        self.stats.sweeps += 1;
        self.stats.points += n;
        self.stats.tagged_points += self.held.points.iter().filter(|p| p.pad != 0).count() as u64;
        self.stats.min_sweep_points = if self.stats.sweeps == 1 {
            n
        } else {
            self.stats.min_sweep_points.min(n)
        };
        self.stats.max_sweep_points = self.stats.max_sweep_points.max(n);
        self.facts.last_sweep_points = n;
        on_sweep(&mut self.held, &self.facts);
    }
}

/// How a point packet's counters place it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Arrival {
    /// Seen already: dropped.
    Copy,
    /// Further behind than reordering explains, within two periods: dropped, its gap (if
    /// `filled`) no longer missing.
    Stale { filled: bool },
    /// Reordered on the way: joins the open sweep, its gap (if `filled`) no longer missing.
    Late { filled: bool },
    /// In order, `lost` skipped.
    Next { lost: u64 },
    /// A frame's first packet come, its number's worth before it lost.
    FrameStart,
    /// The counter restarted.
    Restart,
}

/// The last record spacings of an SDK1 stream of no known model, ns.
#[derive(Clone, Copy, Debug, Default)]
struct LearntSpacing {
    steps: [i64; 15],
    len: usize,
    next: usize,
}

impl LearntSpacing {
    fn push(&mut self, step: i64) {
        self.steps[self.next] = step;
        self.next = (self.next + 1) % self.steps.len();
        self.len = (self.len + 1).min(self.steps.len());
    }

    /// The median (the lower of two): a loss's longer step is outvoted while fewer than half
    /// the steps kept span one.
    fn median(&self) -> Option<i64> {
        if self.len == 0 {
            return None;
        }
        let mut s = self.steps;
        let s = &mut s[..self.len];
        s.sort_unstable();
        Some(s[(self.len - 1) / 2])
    }
}

/// Decodes an SDK2 point packet first timed `ts` into `sweep` (point times from its start;
/// with `max_t_ns`, only the records timed `0..=max_t_ns` after it).
fn decode_sdk2(
    decoder: &LivoxDecoder,
    p: &Sdk2Packet<'_>,
    ts: i64,
    max_t_ns: Option<i64>,
    sweep: &mut Sweep,
) -> PacketPoints {
    let (n, interval) = (p.records(), p.time_interval_ns());
    let (kind, rec, spacing) = (
        p.record(),
        |i| p.record_bytes(i),
        Spacing::sdk2(n, interval),
    );
    match max_t_ns {
        None => decoder.decode(
            kind,
            n,
            rec,
            ts,
            spacing,
            sweep.device_time_ns,
            &mut sweep.points,
        ),
        Some(max) => decoder.decode_within(
            kind,
            n,
            rec,
            ts,
            spacing,
            sweep.device_time_ns,
            max,
            &mut sweep.points,
        ),
    }
}
