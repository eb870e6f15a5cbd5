//! One Hesai sensor's stream: packet checks, clock, loss, health, and sweeps.
//!
//! Feed it every UDP payload from one sensor with its host receive time; it calls back with each
//! finished sweep. No I/O, no clock reads; a packet that is not well-formed (length, marks,
//! CRC, return mode) is counted and skipped.
//!
//! **Sweeps are cut per channel at the cut angle** (default 0°; AT128: 150°, the end of its
//! field of view): each channel's point goes to the sweep of its own corrected azimuth, and a
//! channel moves on to the next sweep when its corrected azimuth passes the cut angle — an
//! azimuth exactly on the cut belongs to the sweep that ends there (nebula's `ScanCutter`). A
//! sweep is emitted once every channel has passed the cut. So a sweep is one clean turn in
//! space, whatever the channels' azimuth offsets (the QT64's reach ±8°): cutting on the block
//! azimuth instead (what the Velodyne stream does) would give every channel its own seam.
//! The sweep's timestamp is the earliest firing of the block group that opened it, so every
//! point's `t` ≥ 0. **The ATX's sweeps are its frames**: one ends when bit 0 of the tail's
//! frame id changes (the SDK's frame split), whatever the azimuths.
//!
//! **Clock.** A packet's time is its tail date + µs ([`super::wire::HesaiPacket::stamp_ns`]);
//! point times add the model's firing offsets. The tail does not say how the sensor's clock is
//! disciplined; the stream calls the clock *synchronised* when the tail time lies within 10 s of
//! the host receive time and *free-running* otherwise (every capture of the shared set: tail
//! clocks of 2017–2020 in 2023–2024 recordings). A synchronised sweep is stamped in the sensor
//! clock (`sensor-ptp`: Hesai's default source), a free-running one in host time.
//!
//! **Loss.** With a UDP sequence number (QT, XT, AT, OT, Pandar64 with its trailer), missing =
//! the sequence gap; without, round(Δ tail time / packet period) − 1. A tail time going
//! backwards or jumping by more than `max_gap_ns` ends the open sweeps (a discontinuity). A
//! packet up to 10 behind (by number, else by time inside a gap counted missing) came late:
//! its points join the open sweep they belong to, else it is dropped (`late_dropped`); one
//! further behind at a time to match (up to 1 024 numbers) is stale, dropped the same way,
//! not a restart. The stream keeps the last [`LEDGER_NUMBERS`] numbers in a [`UdpLedger`], so
//! a stale packet takes its gap off `missing` once, whatever gaps came since, and a copy of
//! it (or of any packet that came) is a duplicate. A sweep longer than `max_sweep_ns` is
//! ended whatever its azimuths or frame bits say (a discontinuity, as in every family).

use std::collections::VecDeque;

use super::calib::HesaiCalibration;
use super::decode::{HesaiDecoder, HesaiOptions, TURN_UDEG};
use super::model::{mode_name, returns_of_mode, HesaiModel};
use super::wire::{CrcPart, FunctionalSafety, HesaiPacket};
use crate::sweep::ledger::{Count, UdpLedger, LEDGER_NUMBERS};
use crate::sweep::{RecentTimes, SeqStep, SeqWindow, Sweep, REORDER_PACKETS};
use crate::time::ClockSource;

/// The tail's UDP sequence number is 32 bits.
const SEQ_MASK: u64 = u32::MAX as u64;

/// Configuration of one stream.
#[derive(Clone, Debug)]
pub struct HesaiConfig {
    /// The model (detected from the first packet when `None`).
    pub model: Option<HesaiModel>,
    /// The angle correction; without one the stream reads the packets (model, clock, loss,
    /// health) but decodes no points.
    pub calibration: Option<HesaiCalibration>,
    /// Its name as shown: the file names of [`Self::calibration_files`] joined by ` + `.
    pub calibration_name: String,
    /// The files it was read from, the angle correction first (an ATX's firetime CSV second);
    /// what `--calib` files a run reports as used.
    pub calibration_files: Vec<String>,
    /// Decoding options.
    pub options: HesaiOptions,
    /// Cut angle, 0.01°; `None` (or 0 for the AT128, whose field of view 0° is outside) = the
    /// model's default (0°, AT128 150°).
    pub cut_cdeg: Option<u32>,
    /// Check CRCs where packets carry them (default on).
    pub check_crc: bool,
    /// A tail-time gap longer than this ends the sweep, ns.
    pub max_gap_ns: i64,
    /// A sweep longer than this is ended, ns (as the Velodyne stream's): a head whose azimuth
    /// stands still, or an ATX whose frame bit never changes, would otherwise grow one sweep
    /// without end. A sweep of more packets than twice this time holds is ended too, for a
    /// tail clock that stands still.
    pub max_sweep_ns: i64,
    /// Only inspecting (`ringscan info`): a sensor without its correction is read without
    /// points. Otherwise [`HesaiStream::missing_calibration`] names it, and a caller that
    /// wants points stops there (a run that writes an empty file and succeeds hides it).
    pub inspect: bool,
}

impl HesaiConfig {
    /// A configuration with ringscan's defaults.
    pub fn new(calibration: Option<HesaiCalibration>, calibration_name: &str) -> Self {
        Self {
            model: None,
            calibration,
            calibration_name: calibration_name.to_string(),
            calibration_files: if calibration_name.is_empty() {
                Vec::new()
            } else {
                vec![calibration_name.to_string()]
            },
            options: HesaiOptions::default(),
            cut_cdeg: None,
            check_crc: true,
            max_gap_ns: 1_000_000_000,
            max_sweep_ns: 1_000_000_000,
            inspect: false,
        }
    }
}

/// Counters of one stream.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct HesaiStats {
    /// Packets decoded.
    pub packets: u64,
    /// Packets not well-formed (length, marks, return mode), including CRC failures.
    pub malformed: u64,
    /// Packets whose body or tail CRC failed (dropped; also in `malformed`).
    pub crc_failures: u64,
    /// Of those, the packets whose body passed and tail failed.
    pub crc_tail_failures: u64,
    /// Packets whose CRCs were checked and passed.
    pub crc_ok: u64,
    /// Packets missing (sequence or time gaps).
    pub missing: u64,
    /// Discontinuities (time backwards or a gap over `max_gap_ns`).
    pub discontinuities: u64,
    /// Packets seen already (their sequence number, else their time): copies, dropped.
    pub duplicates: u64,
    /// Late packets (reordered on the way) whose points all belong to a sweep already
    /// emitted, or stale ones (more than the reorder window behind, with a time to match):
    /// dropped, and counted as a loss here rather than in `missing`. A late packet whose
    /// points belong to an open sweep joins it instead. A copy of either is a duplicate.
    pub late_dropped: u64,
    /// Packets carrying a cyber-security signature (skipped, not verified).
    pub signed: u64,
    /// Packets whose functional-safety block reports a state other than normal.
    pub safety_not_normal: u64,
    /// Packets whose functional-safety block failed its own CRC: the block is ignored (not
    /// in `safety_not_normal`, not the last state); the points, under their body CRC, are
    /// decoded.
    pub safety_crc_failures: u64,
    /// Sweeps emitted.
    pub sweeps: u64,
    /// Points emitted.
    pub points: u64,
}

/// What the stream learned about its sensor.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HesaiFacts {
    /// The model.
    pub model: Option<HesaiModel>,
    /// How it was chosen.
    pub detection: String,
    /// Protocol version of the pre-header.
    pub protocol: Option<(u8, u8)>,
    /// Last return-mode byte.
    pub return_mode: Option<u8>,
    /// Last distance unit, mm.
    pub dis_unit_mm: Option<u8>,
    /// Last motor speed, rpm.
    pub motor_rpm: Option<u16>,
    /// Correction file name (several joined by ` + `).
    pub calibration: String,
    /// The correction's files, the angle correction first.
    pub calibration_files: Vec<String>,
    /// Tail time of the last packet, ns since the epoch.
    pub last_stamp_ns: Option<i64>,
    /// Whether the tail clock agrees with the host's (see the module docs).
    pub clock_synchronised: Option<bool>,
    /// Clock of the last sweep.
    pub clock: ClockSource,
    /// Last functional-safety block.
    pub safety: Option<FunctionalSafety>,
    /// Last high-temperature shutdown flag.
    pub shutdown_flag: Option<u8>,
    /// Whether the model's packets carry CRCs, and whether they are checked.
    pub crc: CrcState,
}

/// CRC handling of a stream.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum CrcState {
    /// Not known yet.
    #[default]
    Unknown,
    /// The packets carry no CRC.
    Absent,
    /// Checked.
    Checked,
    /// Present but not checked (`--crc off`).
    Unchecked,
    /// Present, of an algorithm no public document gives (ATX): skipped.
    Unpublished,
}

impl CrcState {
    /// Name in summaries.
    pub fn name(self) -> &'static str {
        match self {
            Self::Unknown => "unknown",
            Self::Absent => "absent (no CRC in this model's packets)",
            Self::Checked => "checked (CRC-32/MPEG-2 of body and tail)",
            Self::Unchecked => "present, not checked",
            Self::Unpublished => "present, not checked (its algorithm is not published)",
        }
    }
}

impl HesaiFacts {
    /// Clock state in words.
    pub fn clock_state(&self) -> &'static str {
        match self.clock_synchronised {
            None => "unknown",
            Some(true) => "synchronised (tail time within 10 s of host time; PTP or GPS)",
            Some(false) => "free-running (tail time far from host time: not synchronised)",
        }
    }
}

/// Gaps counted missing kept for a late packet to fill: one is at most [`REORDER_PACKETS`]
/// behind, so it falls in one of the last so many.
const GAPS_KEPT: usize = REORDER_PACKETS as usize + 1;

/// A packet further behind than the reorder window, at a time to match, is stale (held up on
/// the way), not a counter that restarted: up to this many numbers behind.
const STALE_PACKETS: u64 = 1_024;

/// The ATX's time between columns, ns, as the simulator (`sim`) writes them: only the sweep's
/// packet cap uses it.
const ATX_COLUMN_NS: i64 = 72_000;

/// A gap counted missing: the numbers (or tail times) either side of it, what is left of it,
/// and the sweep that counted it.
#[derive(Clone, Copy, Debug)]
struct Gap {
    before: i64,
    after: i64,
    by_seq: bool,
    left: u64,
    sweep: Option<u64>,
}

/// A sweep being filled, with its time base.
#[derive(Debug, Default)]
struct Open {
    sweep: Sweep,
    t0_ns: i64,
    last_packet: u64,
}

impl Open {
    /// Adds `point` at `t` ns after the sweep's start (clamped to the point's field), counting
    /// packet `packet_no` once in the sweep's packets.
    #[inline]
    fn push(&mut self, mut point: crate::point::Point, t: i64, packet_no: u64) {
        point.t = t.clamp(0, i64::from(u32::MAX)) as u32;
        self.sweep.points.push(point);
        if self.last_packet != packet_no {
            self.last_packet = packet_no;
            self.sweep.packets += 1;
        }
    }
}

/// A Hesai stream for one sensor.
#[derive(Debug)]
pub struct HesaiStream {
    cfg: HesaiConfig,
    decoder: Option<HesaiDecoder>,
    stats: HesaiStats,
    facts: HesaiFacts,
    /// Per channel: sweep generation and last corrected azimuth (µ°).
    gen: Vec<u64>,
    /// The least and greatest of `gen`, kept with it ([`Self::gens_changed`]): asked for at
    /// every group, they change only at the cut.
    gen_lo: u64,
    gen_hi: u64,
    last_az: Vec<i64>,
    base_gen: u64,
    open: VecDeque<Open>,
    spare: Vec<Sweep>,
    next_index: u64,
    /// The tail's UDP sequence numbers seen lately.
    seq: SeqWindow,
    /// The same numbers' low 16 bits, further back: which came and which were counted missing,
    /// for a stale packet (up to [`STALE_PACKETS`] behind), which the window no longer holds.
    udp: UdpLedger,
    /// The sensor times of the last packets (a copy repeats one).
    recent: RecentTimes,
    prev_stamp: Option<i64>,
    /// Angle-correction CSV: each channel's cut threshold on the block azimuth (cut − its
    /// offset, µ°), the window they span (start, width), and the last block azimuth.
    thresholds: Option<(Vec<i64>, i64, i64)>,
    last_block_udeg: Option<i64>,
    /// Bit 0 of the last packet's frame id (ATX: the sweep ends when it changes).
    last_frame: Option<u8>,
    /// The last gaps counted missing, the newest first.
    gaps: [Option<Gap>; GAPS_KEPT],
    /// Per channel of a late packet's group: the open sweep its point goes to.
    late_idx: Vec<Option<usize>>,
    packet_no: u64,
    cut_udeg: i64,
}

impl HesaiStream {
    /// A new stream.
    pub fn new(cfg: HesaiConfig) -> Self {
        let facts = HesaiFacts {
            calibration: cfg.calibration_name.clone(),
            calibration_files: cfg.calibration_files.clone(),
            ..HesaiFacts::default()
        };
        Self {
            cfg,
            decoder: None,
            stats: HesaiStats::default(),
            facts,
            gen: Vec::new(),
            gen_lo: 0,
            gen_hi: 0,
            last_az: Vec::new(),
            base_gen: 0,
            open: VecDeque::new(),
            spare: Vec::new(),
            next_index: 0,
            seq: SeqWindow::new(32, (1 << 20) - 1),
            udp: UdpLedger::new(u64::from(LEDGER_NUMBERS - 1)),
            recent: RecentTimes::default(),
            prev_stamp: None,
            thresholds: None,
            last_block_udeg: None,
            last_frame: None,
            gaps: [None; GAPS_KEPT],
            late_idx: Vec::new(),
            packet_no: 0,
            cut_udeg: 0,
        }
    }

    /// Counters so far.
    pub fn stats(&self) -> &HesaiStats {
        &self.stats
    }

    /// What is known of the sensor.
    pub fn facts(&self) -> &HesaiFacts {
        &self.facts
    }

    /// The decoder, once the model is known.
    pub fn decoder(&self) -> Option<&HesaiDecoder> {
        self.decoder.as_ref()
    }

    /// The model, once known, when the stream has no correction for it and is not only
    /// inspecting ([`HesaiConfig::inspect`]): its packets give no points.
    pub fn missing_calibration(&self) -> Option<HesaiModel> {
        if self.cfg.inspect || self.cfg.calibration.is_some() {
            return None;
        }
        self.facts.model
    }

    fn ensure_decoder(&mut self, payload: &[u8]) -> Result<(), crate::sensor::DecodeError> {
        if self.facts.model.is_some() {
            return Ok(());
        }
        let (model, how) = match self.cfg.model {
            Some(m) => (m, format!("named by the user ({})", m.id())),
            None => match HesaiModel::detect(payload) {
                Some(m) => (m, detection_words(m, payload)),
                None => return Ok(()),
            },
        };
        // A layout read from each header (ATX) has its correction's channel count.
        let n = match &self.cfg.calibration {
            Some(c) if model.spec().layout.counts_from_header => c.channels(),
            _ => model.channels(),
        };
        self.facts.model = Some(model);
        self.facts.detection = how;
        let layout = &model.spec().layout;
        self.facts.crc = if !layout.body_crc && layout.tail.crc.is_none() {
            CrcState::Absent
        } else if !layout.crc_known {
            CrcState::Unpublished
        } else if self.cfg.check_crc {
            CrcState::Checked
        } else {
            CrcState::Unchecked
        };
        let cut = match self.cfg.cut_cdeg {
            // 0° lies outside the AT128's field of view: its own cut then.
            Some(0) | None => model.spec().default_cut_cdeg,
            Some(c) => c,
        };
        self.cut_udeg = i64::from(cut % 36_000) * 10_000;
        self.gen = vec![0; n];
        self.gens_changed();
        self.last_az = vec![i64::MIN; n];
        let Some(calib) = &self.cfg.calibration else {
            return Ok(());
        };
        let dec = HesaiDecoder::new(model, calib, self.cfg.options)?;
        self.thresholds = dec.azimuth_offsets_udeg().map(|offs| {
            let (lo, hi) = offs
                .iter()
                .fold((i64::MAX, i64::MIN), |(a, b), &o| (a.min(o), b.max(o)));
            let th = offs
                .iter()
                .map(|o| (self.cut_udeg - o).rem_euclid(TURN_UDEG))
                .collect();
            (th, (self.cut_udeg - hi).rem_euclid(TURN_UDEG), hi - lo)
        });
        self.decoder = Some(dec);
        Ok(())
    }

    /// Pushes one UDP payload. Finished sweeps go to `on_sweep`. An error means the stream
    /// cannot decode at all (the correction does not fit the model).
    pub fn push(
        &mut self,
        host_ns: i64,
        payload: &[u8],
        on_sweep: &mut dyn FnMut(&mut Sweep, &HesaiFacts),
    ) -> Result<(), crate::sensor::DecodeError> {
        self.ensure_decoder(payload)?;
        let Some(model) = self.facts.model else {
            self.stats.malformed += 1;
            return Ok(());
        };
        let Ok(p) = HesaiPacket::new(payload, model) else {
            self.stats.malformed += 1;
            return Ok(());
        };
        if self.facts.crc == CrcState::Checked {
            match p.check_crc() {
                Ok(()) => self.stats.crc_ok += 1,
                Err((part, _)) => {
                    if part == CrcPart::Tail {
                        self.stats.crc_tail_failures += 1;
                    }
                    self.stats.crc_failures += 1;
                    self.stats.malformed += 1;
                    // Only the body failed: the tail tells which packet came corrupt, so its
                    // number is not also counted missing (its points are lost, counted above).
                    // The tail failed: its number is taken only where it is the very next one
                    // (a corrupt number landing exactly there is a chance in 2^32); any other
                    // leaves its gap counted missing too, as which packet it was is unknown.
                    let seq = match part {
                        CrcPart::Body => p.checked_udp_seq(),
                        CrcPart::Tail => p.udp_seq().filter(|&s| {
                            self.seq
                                .latest()
                                .is_some_and(|l| u64::from(s) == l.wrapping_add(1) & SEQ_MASK)
                        }),
                    };
                    if let Some(s) = seq {
                        self.number_seen(s);
                    }
                    return Ok(());
                }
            }
        }
        let mode = p.return_mode();
        let Some(n) = returns_of_mode(mode) else {
            self.stats.malformed += 1;
            // Its CRCs (where checked) passed: the number is the packet's, not also missing.
            if let Some(s) = p.udp_seq() {
                self.number_seen(s);
            }
            return Ok(());
        };
        if p.has_signature() {
            self.stats.signed += 1;
        }
        // A health report that fails its own CRC is not believed (neither counted as not
        // normal nor kept as the last state); the points are still good, their body CRC says.
        if let Some(fs) = p.functional_safety() {
            if p.check_safety_crc().is_err() {
                self.stats.safety_crc_failures += 1;
            } else {
                if fs.lidar_state != 1 {
                    self.stats.safety_not_normal += 1;
                }
                self.facts.safety = Some(fs);
            }
        }
        self.facts.shutdown_flag = p.shutdown_flag();
        self.facts.protocol = p.protocol();
        self.facts.return_mode = Some(mode);
        self.facts.dis_unit_mm = Some(p.dis_unit_mm());
        self.facts.motor_rpm = Some(p.motor_rpm());
        // A tail without a valid date gives no sensor time: the host's stands in, and is no
        // evidence of a synchronised clock. Host times can lie anywhere in i64 (a corrupt
        // capture), so every difference with them saturates.
        let (stamp, synced) = match p.stamp_ns() {
            Some(t) => (t, t.abs_diff(host_ns) < 10_000_000_000),
            None => (host_ns, false),
        };
        self.facts.clock_synchronised = Some(synced);
        self.facts.last_stamp_ns = Some(stamp);

        // ATX: a packet whose laser count is not its correction's cannot be decoded with it:
        // malformed. It parsed whole by its own header (a corrupt count would not fit the
        // datagram's length), so its number tells which packet it was: not also missing.
        if self
            .decoder
            .as_ref()
            .is_some_and(|d| p.layout().channels != d.channels())
        {
            self.stats.malformed += 1;
            if let Some(s) = p.udp_seq() {
                self.number_seen(s);
            }
            return Ok(());
        }

        // Loss and discontinuities.
        let blocks = p.layout().blocks;
        let period_ns = (blocks / n) as i64 * i64::from(model.spec().block_period_ns);
        let step = self.prev_stamp.map(|prev| stamp.saturating_sub(prev));
        // A packet a little behind the latest (by its sequence number where it has one, else
        // by its time) was reordered on the way: it fills a gap already counted as missing,
        // and the stream goes on from the latest packet, not from it. A copy is a packet whose
        // sensor time is one of the last packets' (and its number too, where it has one).
        let sensor_time = p.stamp_ns().is_some();
        let time_seen = sensor_time && self.recent.contains(stamp);
        let udp_seq = p.udp_seq();
        let behind = match (udp_seq, self.seq.latest()) {
            (Some(s), Some(l)) => l.wrapping_sub(u64::from(s)) & SEQ_MASK,
            _ => 0,
        };
        // Its sensor time behind the latest by about as much as its number is: an old packet
        // of this very stream, not a counter or a clock that started again.
        let from_the_past = sensor_time
            && behind <= STALE_PACKETS
            && step.is_some_and(|d| {
                d < 0 && d.unsigned_abs() <= (behind + 1) * 2 * period_ns.max(1) as u64
            });
        let mut seq = udp_seq.map(|s| self.seq.step_within(u64::from(s)));
        let mut stale = false;
        match (seq, udp_seq) {
            (Some(SeqStep::Jump), Some(s)) => {
                if from_the_past {
                    stale = true;
                } else {
                    self.restart_numbers(s);
                }
            }
            // A number seen already is a copy, unless its sensor time says the counter
            // restarted or stands still: a time neither among the last packets' nor an old
            // one of this stream. Without a sensor time nothing says so.
            (Some(SeqStep::Duplicate), Some(s)) if sensor_time && !time_seen && !from_the_past => {
                self.restart_numbers(s);
                seq = Some(SeqStep::Jump);
            }
            (Some(step), Some(s)) => self.ledger_take(s, step),
            _ => {}
        }
        let copy = match seq {
            Some(s) => s == SeqStep::Duplicate,
            None => time_seen,
        };
        if copy {
            self.stats.duplicates += 1;
            return Ok(());
        }
        if let (true, Some(s)) = (stale, udp_seq) {
            // Beyond the reorder window its sweep is long gone: dropped, and not also missing.
            // The window no longer holds its number, the ledger does: a copy of a packet that
            // came (stale or not) is a copy, not a second stale packet.
            match self.udp.peek(s as u16) {
                Count::Seen { .. } => {
                    self.stats.duplicates += 1;
                    return Ok(());
                }
                Count::Lost { .. } => {
                    self.udp.take(s as u16);
                    if self.fill_gap(i64::from(s), true).is_none() {
                        // Counted missing, though the gap is no longer kept.
                        self.stats.missing = self.stats.missing.saturating_sub(1);
                    }
                }
                // From before the ledger's numbers (a restart, or a gap wider than it keeps):
                // a gap still kept may hold it, and the ledger keeps it from now on.
                _ => {
                    self.udp.take_before(s as u16);
                    self.fill_gap(i64::from(s), true);
                }
            }
            self.stats.late_dropped += 1;
            return Ok(());
        }
        // A late packet: `Some(the sweep that counted its gap)`.
        let late = match (seq, udp_seq) {
            (Some(SeqStep::Late), Some(s)) => {
                Some(self.fill_gap(i64::from(s), true).unwrap_or_else(|| {
                    // The window counted its number lost, though the gap is no longer kept.
                    self.stats.missing = self.stats.missing.saturating_sub(1);
                    None
                }))
            }
            (Some(SeqStep::Stray), _) => Some(None),
            (Some(_), _) => None,
            // Without a number: a little behind, and inside a gap counted missing (a clock
            // that stepped back fills none, and stays a discontinuity).
            (None, _) => step
                .filter(|&d| d < 0 && d >= -i64::from(REORDER_PACKETS) * period_ns)
                .and_then(|_| self.fill_gap(stamp, false)),
        };
        if let Some(counted_by) = late {
            if sensor_time {
                self.recent.push(stamp);
            }
            self.push_late(&p, stamp, n, counted_by);
            return Ok(());
        }
        let discontinuity = step.is_some_and(|d| d < 0 || d > self.cfg.max_gap_ns);
        match (seq, udp_seq) {
            (Some(SeqStep::Next { lost }), Some(s)) if lost > 0 => {
                let before = i64::from(s).wrapping_sub(lost as i64 + 1);
                self.add_missing(lost, before, i64::from(s), true);
            }
            (Some(_), _) => {}
            (None, _) => {
                if let (Some(d), Some(prev), false) = (step, self.prev_stamp, discontinuity) {
                    if period_ns > 0 {
                        let m = (d as f64 / period_ns as f64).round() as i64 - 1;
                        if m > 0 {
                            self.add_missing(m as u64, prev, stamp, false);
                        }
                    }
                }
            }
        }
        self.prev_stamp = Some(stamp);
        if discontinuity {
            self.stats.discontinuities += 1;
            // A clock that restarted (or a capture replayed again) may repeat times.
            self.recent.clear();
            for g in &mut self.gaps {
                if g.is_some_and(|g| !g.by_seq) {
                    *g = None;
                }
            }
            self.emit_all(on_sweep);
            self.last_az.iter_mut().for_each(|a| *a = i64::MIN);
            self.last_block_udeg = None;
        }
        if sensor_time {
            self.recent.push(stamp);
        }

        // A late packet never gets here: it neither ends a frame nor starts one.
        let frame = p.frame_id().map(|f| f & 1);
        if let (Some(f), Some(last)) = (frame, self.last_frame) {
            if f != last {
                self.emit_all(on_sweep);
            }
        }
        self.last_frame = frame;

        self.packet_no += 1;
        self.stats.packets += 1;
        let Some(mut dec) = self.decoder.take() else {
            return Ok(());
        };
        dec.prepare(n, p.tail_flags());
        let nc = dec.channels();
        // How far the head turned since the last packet (its motor speed from the tail, else
        // the usual 600 rpm), for a step the azimuths alone cannot tell.
        let rpm = crate::sweep::motor_rpm_or_nominal(Some(p.motor_rpm()));
        let turned_udeg = step
            .filter(|_| !discontinuity)
            .map(|d| crate::sweep::rotation_in(d, rpm, TURN_UDEG));
        // A sweep holding more packets than twice `max_sweep_ns` does ends too: for a tail
        // clock that stands still.
        // The ATX gives no block period (its firing times come with its correction): its
        // nominal column period then.
        let cap_period = match period_ns {
            0 => (blocks / n) as i64 * ATX_COLUMN_NS,
            p => p,
        };
        let max_packets = (self.cfg.max_sweep_ns / cap_period.max(1)).saturating_mul(2) as u64;
        let mut g = 0;
        while g < blocks {
            let block_az = p.azimuth(g);
            let az_cdeg = dec.block_azimuth_cdeg(block_az);
            let azimuths = dec.block_azimuths(block_az);
            let group_t0 = stamp.saturating_add(dec.group_earliest_ns(g));
            // A sweep too long is ended whatever the azimuths say (a head standing still, a
            // frame bit that never changes), and the next starts as after a discontinuity.
            if self.open.front().is_some_and(|o| {
                group_t0.saturating_sub(o.t0_ns) > self.cfg.max_sweep_ns
                    || u64::from(o.sweep.packets) > max_packets
            }) {
                self.stats.discontinuities += 1;
                self.emit_all(on_sweep);
                self.last_az.iter_mut().for_each(|a| *a = i64::MIN);
                self.last_block_udeg = None;
            }
            // Per-channel cut. The first group after a start or a discontinuity may straddle
            // the cut: its channels already past it (within a quarter turn) open the next
            // sweep (nebula's `initialize_state`).
            // The ATX's sweeps are its frames (cut above): no azimuth cut.
            let by_azimuth = frame.is_none();
            if by_azimuth && self.last_az.first() == Some(&i64::MIN) {
                let q = TURN_UDEG / 4;
                let rel = |az: i64| (az - self.cut_udeg).rem_euclid(TURN_UDEG);
                let azs: Vec<i64> = (0..nc).filter_map(|c| azimuths.channel_udeg(c)).collect();
                let straddles =
                    azs.iter().any(|&a| rel(a) < q) && azs.iter().any(|&a| rel(a) >= TURN_UDEG - q);
                for c in 0..nc {
                    let after = azimuths
                        .channel_udeg(c)
                        .is_some_and(|a| rel(a) < TURN_UDEG / 2);
                    self.gen[c] = self.base_gen + u64::from(straddles && after);
                }
                self.gens_changed();
            }
            if !by_azimuth {
            } else if let Some((th, w_start, w_width)) = &self.thresholds {
                // Angle-correction CSV: channel c's azimuth is the block azimuth + a constant,
                // so it passes the cut exactly when the block azimuth passes cut − offset(c);
                // the channels are looked at only when the block's step reaches that window.
                let cur = i64::from(block_az % 36_000) * 10_000;
                match self.last_block_udeg {
                    None => self.last_block_udeg = Some(cur),
                    Some(last) => {
                        let span = (cur - last).rem_euclid(TURN_UDEG);
                        // A step back (blocks of one packet out of azimuth order) is not a
                        // turn forward, and progress stays where it was. Across packets the
                        // time between them tells a step back from packets lost.
                        let turned = (g == 0).then_some(turned_udeg).flatten();
                        match crate::sweep::azimuth_step(span, TURN_UDEG, turned) {
                            crate::sweep::Step::Back => {}
                            crate::sweep::Step::Forward { full_turn } => {
                                let hits = full_turn
                                    || (w_start - last).rem_euclid(TURN_UDEG) < span
                                    || (last - w_start).rem_euclid(TURN_UDEG) <= *w_width;
                                if hits {
                                    // Each channel past its cut once, however many turns
                                    // went by unseen: no empty sweeps for lost ones.
                                    for (g_c, &t) in self.gen.iter_mut().zip(th) {
                                        if full_turn || (t - last).rem_euclid(TURN_UDEG) < span {
                                            *g_c += 1;
                                        }
                                    }
                                    self.gens_changed();
                                }
                                self.last_block_udeg = Some(cur);
                            }
                        }
                    }
                }
                if let Some(first) = self.last_az.first_mut() {
                    // Only the first channel's marks "past the first group" in this mode.
                    *first = 0;
                }
            } else {
                for c in 0..nc {
                    let Some(az) = azimuths.channel_udeg(c) else {
                        continue;
                    };
                    let last = self.last_az[c];
                    if last != i64::MIN {
                        let span = (az - last).rem_euclid(TURN_UDEG);
                        let to_cut = (self.cut_udeg - last).rem_euclid(TURN_UDEG);
                        // A step back (less than a quarter turn: blocks of one packet out of
                        // azimuth order) is not a turn forward past the cut, and the
                        // channel's progress stays where it was (no second crossing).
                        if span >= TURN_UDEG / 4 * 3 {
                            continue;
                        }
                        if to_cut < span {
                            self.gen[c] += 1;
                        }
                    }
                    self.last_az[c] = az;
                }
                self.gens_changed();
            }
            // Keep at most two sweeps open: a channel two sweeps ahead closes the oldest.
            let (lo, hi) = (self.gen_lo, self.gen_hi);
            while hi >= self.base_gen + 2 {
                self.emit_front(on_sweep);
            }
            let clock = if synced {
                ClockSource::SensorPtp
            } else {
                ClockSource::Host
            };
            let host_t0 = host_ns.saturating_add(group_t0.saturating_sub(stamp));
            let packet_no = self.packet_no;
            // Open the sweeps this group's channels need (up to the greatest generation's).
            let idx = hi.saturating_sub(self.base_gen) as usize;
            while self.open.len() <= idx {
                let mut sw = self.spare.pop().unwrap_or_default();
                sw.clear();
                sw.index = self.next_index;
                self.next_index += 1;
                sw.timestamp_ns = if synced { group_t0 } else { host_t0 };
                sw.clock = clock;
                sw.device_time_ns = group_t0;
                sw.first_host_ns = host_ns;
                sw.first_azimuth = az_cdeg;
                self.open.push_back(Open {
                    sweep: sw,
                    t0_ns: group_t0,
                    last_packet: 0,
                });
            }
            let (gens, base, open) = (&self.gen, self.base_gen, &mut self.open);
            if lo == hi {
                // Every channel in one sweep (all but the groups at the cut): straight in.
                if let Some(o) = open.get_mut(lo.saturating_sub(base) as usize) {
                    let before = o.sweep.points.len();
                    let t_base = stamp.saturating_sub(o.t0_ns);
                    let pts = &mut o.sweep.points;
                    dec.decode_group(&p, g, n, |d| {
                        let t = t_base.saturating_add(i64::from(d.firing_ns));
                        let mut pt = d.point;
                        pt.t = t.clamp(0, i64::from(u32::MAX)) as u32;
                        pts.push(pt);
                    });
                    if o.sweep.points.len() > before && o.last_packet != packet_no {
                        o.last_packet = packet_no;
                        o.sweep.packets += 1;
                    }
                }
            } else {
                dec.decode_group(&p, g, n, |d| {
                    let idx = (gens[d.channel].saturating_sub(base)) as usize;
                    if let Some(o) = open.get_mut(idx) {
                        let t = stamp
                            .saturating_add(i64::from(d.firing_ns))
                            .saturating_sub(o.t0_ns);
                        o.push(d.point, t, packet_no);
                    }
                });
            }
            for o in self.open.iter_mut() {
                o.sweep.last_host_ns = host_ns;
                o.sweep.last_azimuth = az_cdeg;
                o.sweep.columns_count += 1;
            }
            // Every channel past the cut: the oldest sweep is complete.
            while lo > self.base_gen && !self.open.is_empty() {
                self.emit_front(on_sweep);
            }
            if lo > self.base_gen && self.open.is_empty() {
                self.base_gen = lo;
            }
            g += n;
        }
        self.decoder = Some(dec);
        Ok(())
    }

    /// A packet counted malformed whose sequence number can be trusted: the window takes it,
    /// so its gap is not also counted missing.
    fn number_seen(&mut self, seq: u32) {
        // A packet that is not decoded never restarts the count: a number out of reach leaves
        // the window as it was (a restart would make the next good packet count the distance
        // back to it as lost).
        let step = self.seq.step_within(u64::from(seq));
        self.ledger_take(seq, step);
        match step {
            SeqStep::Next { lost } if lost > 0 => {
                let before = i64::from(seq).wrapping_sub(lost as i64 + 1);
                self.add_missing(lost, before, i64::from(seq), true);
            }
            // Counted malformed instead, in the stream and in its sweep.
            SeqStep::Late => match self.fill_gap(i64::from(seq), true) {
                Some(sweep) => self.uncount_in_sweep(sweep),
                None => self.stats.missing = self.stats.missing.saturating_sub(1),
            },
            _ => {}
        }
    }

    /// Starts the numbers again from `s` (the counter restarted): window, ledger and gaps.
    fn restart_numbers(&mut self, s: u32) {
        self.seq.restart(u64::from(s));
        self.udp.restart(s as u16);
        self.gaps = [None; GAPS_KEPT];
    }

    /// Keeps number `s` in the ledger as the window took it (`step`): the window tells a step
    /// ahead on the whole 32-bit counter, the ledger's 16 bits only up to what it holds, so a
    /// step over that (or a multiple of 2^16 that its bits hide) starts it again at `s`.
    fn ledger_take(&mut self, s: u32, step: SeqStep) {
        match step {
            SeqStep::Next { lost } if lost >= u64::from(LEDGER_NUMBERS - 1) => {
                self.udp.restart(s as u16)
            }
            SeqStep::Next { .. } | SeqStep::Late | SeqStep::Stray => {
                self.udp.take(s as u16);
            }
            SeqStep::Duplicate | SeqStep::Jump => {}
        }
    }

    /// Counts `m` packets missing between `before` and `after` (numbers, or tail times), in the
    /// newest open sweep, and keeps the gap for a late packet to fill.
    fn add_missing(&mut self, m: u64, before: i64, after: i64, by_seq: bool) {
        self.stats.missing += m;
        let sweep = self.open.back_mut().map(|o| {
            o.sweep.missing_packets += m;
            o.sweep.index
        });
        self.gaps.rotate_right(1);
        self.gaps[0] = Some(Gap {
            before,
            after,
            by_seq,
            left: m,
            sweep,
        });
    }

    /// Whether `key` (a number, or a tail time) falls in a gap counted missing: then one
    /// fewer is missing in the stream, and `Some(the sweep that counted it)`. That sweep's
    /// count is the caller's: it goes down only for a packet whose points it gets.
    fn fill_gap(&mut self, key: i64, by_seq: bool) -> Option<Option<u64>> {
        let inside = |g: &Gap| {
            if by_seq {
                let (k, b, a) = (key as u32, g.before as u32, g.after as u32);
                k.wrapping_sub(b) > 0 && k.wrapping_sub(b) < a.wrapping_sub(b)
            } else {
                g.before < key && key < g.after
            }
        };
        let g = self
            .gaps
            .iter_mut()
            .flatten()
            .find(|g| g.by_seq == by_seq && g.left > 0 && inside(g))?;
        g.left -= 1;
        let sweep = g.sweep;
        self.stats.missing = self.stats.missing.saturating_sub(1);
        Some(sweep)
    }

    /// One packet fewer missing in sweep `index`, if still open (one emitted already did go
    /// out without it).
    fn uncount_in_sweep(&mut self, index: Option<u64>) {
        if let Some(o) = self.open.iter_mut().find(|o| Some(o.sweep.index) == index) {
            o.sweep.missing_packets = o.sweep.missing_packets.saturating_sub(1);
        }
    }

    /// A packet reordered on the way (behind the latest) neither moves the cut nor ends a
    /// frame: the stream goes on from the latest packet. Each of its points joins the open
    /// sweep it belongs to, after the points so far (arrival order, as the Velodyne stream
    /// keeps): by its channel's azimuth against that channel's progress past the cut, or
    /// (ATX) by its frame bit, and the sweep that counted its gap (`counted_by`) counts one
    /// fewer. A packet with no point for an open sweep is dropped and counted in
    /// `late_dropped`.
    fn push_late(&mut self, p: &HesaiPacket<'_>, stamp: i64, n: usize, counted_by: Option<u64>) {
        let Some(mut dec) = self.decoder.take() else {
            // Without a correction no sweep is ever open: read, with nothing to place.
            self.stats.packets += 1;
            return;
        };
        dec.prepare(n, p.tail_flags());
        let nc = dec.channels();
        let frame = p.frame_id().map(|f| f & 1);
        self.packet_no += 1;
        let packet_no = self.packet_no;
        let mut idx = std::mem::take(&mut self.late_idx);
        let mut placed = false;
        let mut g = 0;
        while g < p.layout().blocks {
            let block_az = p.azimuth(g);
            idx.clear();
            if frame.is_some() {
                let open = frame == self.last_frame && !self.open.is_empty();
                idx.resize(nc, open.then_some(0));
            } else {
                let azimuths = dec.block_azimuths(block_az);
                let block_udeg = i64::from(block_az % 36_000) * 10_000;
                for c in 0..nc {
                    let gen = self.late_gen(c, block_udeg, azimuths.channel_udeg(c));
                    let i = gen.checked_sub(self.base_gen).map(|i| i as usize);
                    idx.push(i.filter(|&i| i < self.open.len()));
                }
            }
            let open = &mut self.open;
            let max_sweep_ns = self.cfg.max_sweep_ns;
            dec.decode_group(p, g, n, |d| {
                let Some(o) = idx
                    .get(d.channel)
                    .copied()
                    .flatten()
                    .and_then(|i| open.get_mut(i))
                else {
                    return;
                };
                let t = stamp
                    .saturating_add(i64::from(d.firing_ns))
                    .saturating_sub(o.t0_ns);
                // Late by its number, but timed outside the sweep its azimuth names (a tail
                // time that lies): no place in it.
                if !(0..=max_sweep_ns).contains(&t) {
                    return;
                }
                placed = true;
                o.push(d.point, t, packet_no);
            });
            g += n;
        }
        self.late_idx = idx;
        self.decoder = Some(dec);
        if placed {
            self.stats.packets += 1;
            self.uncount_in_sweep(counted_by);
        } else {
            self.stats.late_dropped += 1;
        }
    }

    /// The sweep generation a late point of channel `c` belongs to: the channel's own, or the
    /// one before where the cut lies between the late azimuth and the channel's latest.
    /// `block_udeg` serves where each channel's cut is a threshold on the block azimuth.
    fn late_gen(&self, c: usize, block_udeg: i64, channel_udeg: Option<i64>) -> u64 {
        let gen = self.gen.get(c).copied().unwrap_or(self.base_gen);
        let (az, last, cut) = match &self.thresholds {
            Some((th, ..)) => (Some(block_udeg), self.last_block_udeg, th.get(c).copied()),
            None => (
                channel_udeg,
                self.last_az.get(c).copied().filter(|&a| a != i64::MIN),
                Some(self.cut_udeg),
            ),
        };
        let (Some(az), Some(last), Some(cut)) = (az, last, cut) else {
            return gen;
        };
        // A late packet is a few degrees behind; half a turn "behind" is ahead, not across.
        let back = (last - az).rem_euclid(TURN_UDEG);
        let crossed = back < TURN_UDEG / 2 && (cut - az).rem_euclid(TURN_UDEG) < back;
        gen.saturating_sub(u64::from(crossed))
    }

    fn emit_front(&mut self, on_sweep: &mut dyn FnMut(&mut Sweep, &HesaiFacts)) {
        if let Some(mut o) = self.open.pop_front() {
            if !o.sweep.points.is_empty() || o.sweep.packets > 0 {
                self.stats.sweeps += 1;
                self.stats.points += o.sweep.points.len() as u64;
                self.facts.clock = o.sweep.clock;
                on_sweep(&mut o.sweep, &self.facts);
            }
            self.spare.push(o.sweep);
        }
        self.base_gen += 1;
    }

    fn emit_all(&mut self, on_sweep: &mut dyn FnMut(&mut Sweep, &HesaiFacts)) {
        while !self.open.is_empty() {
            self.emit_front(on_sweep);
        }
        let top = self
            .gen
            .iter()
            .copied()
            .max()
            .unwrap_or(0)
            .max(self.base_gen);
        self.gen.iter_mut().for_each(|g| *g = top);
        self.gens_changed();
        self.base_gen = top;
    }

    /// Recomputes [`Self::gen_lo`] and [`Self::gen_hi`] after `gen` changed.
    fn gens_changed(&mut self) {
        (self.gen_lo, self.gen_hi) = self
            .gen
            .iter()
            .fold((u64::MAX, 0), |(a, b), &g| (a.min(g), b.max(g)));
        if self.gen.is_empty() {
            self.gen_lo = 0;
        }
    }

    /// Emits the sweeps still open, at the end of the input.
    pub fn finish(&mut self, on_sweep: &mut dyn FnMut(&mut Sweep, &HesaiFacts)) {
        self.emit_all(on_sweep);
    }
}

fn detection_words(m: HesaiModel, payload: &[u8]) -> String {
    match payload {
        [0xEE, 0xFF, major, minor, ..] if m.spec().protocol_major.is_some() => format!(
            "pre-header EE FF, protocol {major}.{minor}, {} lasers × {} blocks, {} bytes",
            m.channels(),
            m.spec().layout.blocks,
            payload.len()
        ),
        [0xEE, 0xFF, ..] => format!(
            "header EE FF, {} lasers × {} blocks, {} bytes",
            m.channels(),
            m.spec().layout.blocks,
            payload.len()
        ),
        _ => format!(
            "{} blocks starting FF EE, {} bytes (Velodyne's are 1206)",
            m.spec().layout.blocks,
            payload.len()
        ),
    }
}

/// Name of a return-mode byte, with the byte.
pub fn return_mode_words(mode: u8) -> String {
    format!("{} ({mode:#04x})", mode_name(mode))
}
