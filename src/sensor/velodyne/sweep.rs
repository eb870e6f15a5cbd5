//! One Velodyne sensor's stream: model detection, device time, sweeps, loss accounting.
//!
//! Feed it every UDP payload from one sensor (data port and position port alike) with its
//! host receive time; it calls back with each finished sweep. No I/O, no clock reads; buffers
//! are allocated at start-up (and when the model or return mode changes), never per packet.
//!
//! **Model detection** (when the caller does not name the model): the product-id byte
//! (1205) proposes a model, the HDL-64E block layout (`FF EE`, `FF DD`, `FF EE`, …) overrides
//! it, and the packet cadence over the first packets (the smallest difference of their
//! top-of-hour stamps) must match that model's packet period in the packet's return mode
//! within 3 %. If it does not, the model whose period matches is taken instead — two real
//! VLP-16 captures report the HDL-32E id 0x21 but arrive every 1327 µs, the VLP-16's period.
//!
//! **Sweeps** are cut on the firing (block) azimuth: a new sweep starts at the first firing
//! whose azimuth, measured from the cut angle, is smaller than the previous firing's by more
//! than half a turn. A device-time gap of more than `max_gap_ns`, a step backwards (beyond
//! the few packets a reordering network delivers late), or a sweep longer than `max_sweep_ns`
//! also ends the sweep (counted as a discontinuity).

use crate::sensor::nmea::parse_rmc;
use crate::sensor::nmea::Rmc;
use crate::sensor::velodyne::calib::builtin;
use crate::sensor::velodyne::calib::VelodyneCalibration;
use crate::sensor::velodyne::decode::ColumnRate;
use crate::sensor::velodyne::model::ReturnMode;
use crate::sensor::velodyne::model::VelodyneModel;
use crate::sensor::velodyne::model::BLOCKS;
use crate::sensor::velodyne::model::DATA_PACKET_LEN;
use crate::sensor::velodyne::model::POSITION_PACKET_LEN;
use crate::sensor::velodyne::model::SLOTS;
use crate::sensor::velodyne::wire::DataPacket;
use crate::sensor::velodyne::wire::PositionPacket;
use crate::sensor::velodyne::wire::PpsState;
use crate::sensor::velodyne::VelodyneDecoder;
use crate::sensor::DecodeError;
use crate::sensor::DecodeOptions;
use crate::sensor::StreamError;
use crate::sweep::{RecentTimes, Sweep, REORDER_PACKETS};
use crate::time::{complete_toh, toh_delta_us, ClockSource};

/// Packets looked at before the model is decided.
pub const DETECT_PACKETS: usize = 4;

/// Configuration of one stream.
#[derive(Clone, Debug)]
pub struct StreamConfig {
    /// The model, when the user names it (wins over detection).
    pub model: Option<VelodyneModel>,
    /// Calibrations the user gave: the first whose laser count fits the model is used (it
    /// wins over the built-in table).
    pub calibrations: Vec<VelodyneCalibration>,
    /// Range filter.
    pub decode: DecodeOptions,
    /// Cut angle, 0.01° (0..36000).
    pub cut_angle: u16,
    /// A device-time gap longer than this ends the sweep, ns.
    pub max_gap_ns: i64,
    /// A sweep longer than this is ended, ns.
    pub max_sweep_ns: i64,
    /// Keep each point's firing column (for [`crate::sweep::Organized`]).
    pub keep_columns: bool,
    /// Only inspecting: a model without its calibration is read without points
    /// ([`crate::sensor::StreamSettings::inspect`]) instead of being an error.
    pub inspect: bool,
}

impl Default for StreamConfig {
    fn default() -> Self {
        Self {
            model: None,
            calibrations: Vec::new(),
            decode: DecodeOptions::default(),
            cut_angle: 0,
            max_gap_ns: 1_000_000_000,
            max_sweep_ns: 1_000_000_000,
            keep_columns: false,
            inspect: false,
        }
    }
}

/// Gaps counted missing that a late packet may still fill: a packet at most
/// [`REORDER_PACKETS`] late falls in one of the last few.
const GAPS_KEPT: usize = 4;

/// Counters of one stream.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct StreamStats {
    /// Data packets decoded.
    pub data_packets: u64,
    /// Position packets seen.
    pub position_packets: u64,
    /// Packets of another size, or with bad flags / azimuths / layout: counted and skipped.
    pub malformed: u64,
    /// Packets missing (device-time gaps).
    pub missing: u64,
    /// Discontinuities: time going backwards or jumping more than `max_gap_ns`.
    pub discontinuities: u64,
    /// Data packets whose timestamp is one of the last packets' (copies): dropped. A copy
    /// read as a packet would step the time back: a discontinuity cutting the sweep
    /// mid-turn, and its points twice.
    pub duplicates: u64,
    /// Late data packets (a little behind the latest: reordered on the way) whose firings all
    /// belong to a sweep already emitted: dropped, and counted as a loss. A late packet whose
    /// firings fall in the open sweep joins it instead.
    pub late_dropped: u64,
    /// Sweeps emitted.
    pub sweeps: u64,
    /// Points emitted.
    pub points: u64,
    /// Times the return mode changed mid-stream.
    pub mode_changes: u64,
}

/// What the stream learned about its sensor.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SensorFacts {
    /// The model decoded as.
    pub model: Option<VelodyneModel>,
    /// The return mode.
    pub mode: Option<ReturnMode>,
    /// Byte 1205 of the first data packet.
    pub product_id: Option<u8>,
    /// Byte 1204 of the first data packet.
    pub mode_byte: Option<u8>,
    /// How the model was chosen, in words.
    pub detection: String,
    /// The model the packets say, in words, where a `--model` contradicts them.
    pub model_contradicted: Option<String>,
    /// Smallest packet stamp difference seen during detection, µs.
    pub period_us: Option<f64>,
    /// Calibration source.
    pub calibration: String,
    /// Last PPS state reported.
    pub pps: Option<PpsState>,
    /// Last telemetry of the position packets (newer firmware only).
    pub telemetry: Option<crate::sensor::velodyne::wire::Telemetry>,
    /// Last RMC sentence with a valid date.
    pub last_rmc: Option<Rmc>,
    /// Position packets whose NMEA field was empty.
    pub empty_nmea: u64,
    /// Position packets whose NMEA sentence did not parse.
    pub bad_nmea: u64,
    /// Clock of the last sweep.
    pub clock: ClockSource,
}

#[derive(Clone, Copy, Debug)]
struct Prev {
    toh_us: u32,
    /// Azimuth of the last firing, relative to the cut angle.
    rel_az: u16,
}

#[derive(Clone, Copy, Debug)]
struct GpsRef {
    rmc_utc_ns: i64,
    toh_us: u32,
    pps_locked: bool,
    valid: bool,
}

/// A Velodyne stream for one sensor.
#[derive(Debug)]
pub struct VelodyneStream {
    cfg: StreamConfig,
    decoder: Option<VelodyneDecoder>,
    pending: Vec<(i64, Box<[u8; DATA_PACKET_LEN]>)>,
    cur: Sweep,
    prev: Option<Prev>,
    /// Timestamps (µs past the hour) of the last data packets.
    recent: RecentTimes,
    gps: Option<GpsRef>,
    stats: StreamStats,
    facts: SensorFacts,
    next_index: u64,
    /// Host-time minus device-time offset of the current sweep's first packet (for host-clock
    /// timestamps).
    sweep_open: bool,
    /// Top-of-hour stamp and first-firing time of the packet that opened the current sweep:
    /// later packets of the sweep are timed from it by their stamp difference, so a clock that
    /// changes source mid-sweep (the first GPS fix) cannot shift the points' `t`.
    anchor: (u32, i64),
    /// The last gaps counted missing: (stamp before, stamp after, packets not yet come late),
    /// newest first. A late packet must fall in one.
    gaps: [Option<(u32, u32, u64)>; GAPS_KEPT],
    /// Rotation rate of one-column packets (VLS-128 dual), from the packets before.
    column_rate: ColumnRate,
    /// The rate [`Self::column_rate`] gave the packet being decoded.
    packet_rate: Option<f64>,
    /// Inspecting a model whose calibration is missing: packets are counted, not decoded.
    uncalibrated: bool,
}

impl VelodyneStream {
    /// A new stream.
    pub fn new(cfg: StreamConfig) -> Self {
        Self {
            cfg,
            decoder: None,
            pending: Vec::new(),
            cur: Sweep::default(),
            prev: None,
            recent: RecentTimes::default(),
            gps: None,
            stats: StreamStats::default(),
            facts: SensorFacts::default(),
            next_index: 0,
            sweep_open: false,
            anchor: (0, 0),
            gaps: [None; GAPS_KEPT],
            column_rate: ColumnRate::default(),
            packet_rate: None,
            uncalibrated: false,
        }
    }

    /// Counters so far.
    pub fn stats(&self) -> &StreamStats {
        &self.stats
    }

    /// What is known of the sensor.
    pub fn facts(&self) -> &SensorFacts {
        &self.facts
    }

    /// The decoder, once the model is known.
    pub fn decoder(&self) -> Option<&VelodyneDecoder> {
        self.decoder.as_ref()
    }

    /// Pushes one UDP payload from this sensor. Finished sweeps are handed to `on_sweep` with
    /// what is known of the sensor.
    pub fn push(
        &mut self,
        host_ns: i64,
        payload: &[u8],
        on_sweep: &mut dyn FnMut(&mut Sweep, &SensorFacts),
    ) -> Result<(), StreamError> {
        match payload.len() {
            DATA_PACKET_LEN => self.push_data(host_ns, payload, on_sweep),
            POSITION_PACKET_LEN => {
                self.push_position(payload);
                Ok(())
            }
            _ => {
                self.stats.malformed += 1;
                Ok(())
            }
        }
    }

    /// Ends the stream: decodes packets still held for detection and emits the last sweep.
    pub fn finish(
        &mut self,
        on_sweep: &mut dyn FnMut(&mut Sweep, &SensorFacts),
    ) -> Result<(), StreamError> {
        if self.decoder.is_none() && !self.pending.is_empty() {
            self.detect()?;
            self.replay_pending(on_sweep);
        }
        self.emit(on_sweep);
        Ok(())
    }

    fn push_position(&mut self, payload: &[u8]) {
        let Ok(p) = PositionPacket::new(payload) else {
            self.stats.malformed += 1;
            return;
        };
        self.stats.position_packets += 1;
        let pps = p.pps();
        self.facts.pps = Some(pps);
        if let Some(t) = p.telemetry() {
            self.facts.telemetry = Some(t);
        }
        let nmea = p.nmea();
        if nmea.is_empty() {
            self.facts.empty_nmea += 1;
            return;
        }
        match parse_rmc(nmea) {
            Ok(rmc) => {
                self.facts.last_rmc = Some(rmc);
                self.gps = Some(GpsRef {
                    rmc_utc_ns: rmc.utc_ns,
                    toh_us: p.timestamp_us(),
                    pps_locked: pps == PpsState::Locked,
                    valid: rmc.valid,
                });
            }
            Err(_) => self.facts.bad_nmea += 1,
        }
    }

    fn push_data(
        &mut self,
        host_ns: i64,
        payload: &[u8],
        on_sweep: &mut dyn FnMut(&mut Sweep, &SensorFacts),
    ) -> Result<(), StreamError> {
        let Ok(packet) = DataPacket::new(payload) else {
            self.stats.malformed += 1;
            return Ok(());
        };
        if self.uncalibrated {
            self.stats.data_packets += 1;
            return Ok(());
        }
        if self.decoder.is_none() {
            if self.facts.product_id.is_none() {
                self.facts.product_id = Some(packet.factory_product());
                self.facts.mode_byte = Some(packet.factory_mode());
            }
            // Detection that keeps failing (the caller may go on after the error) must not grow
            // memory: keep the latest DETECT_PACKETS packets, count the older ones as dropped.
            let mut buf = if self.pending.len() >= DETECT_PACKETS {
                self.stats.malformed += 1;
                self.pending.remove(0).1
            } else {
                Box::new([0u8; DATA_PACKET_LEN])
            };
            buf.copy_from_slice(packet.bytes());
            self.pending.push((host_ns, buf));
            if self.pending.len() < DETECT_PACKETS && self.cfg.model.is_none() {
                return Ok(());
            }
            self.detect()?;
            self.replay_pending(on_sweep);
            return Ok(());
        }
        self.decode_packet(host_ns, &packet, on_sweep);
        Ok(())
    }

    fn replay_pending(&mut self, on_sweep: &mut dyn FnMut(&mut Sweep, &SensorFacts)) {
        let pending = core::mem::take(&mut self.pending);
        if self.uncalibrated {
            self.stats.data_packets += pending.len() as u64;
            return;
        }
        for (host, bytes) in &pending {
            if let Ok(p) = DataPacket::new(&bytes[..]) {
                self.decode_packet(*host, &p, on_sweep);
            }
        }
    }

    fn detect(&mut self) -> Result<(), StreamError> {
        let Some((_, first)) = self.pending.first() else {
            return Ok(());
        };
        let Ok(p) = DataPacket::new(&first[..]) else {
            return Ok(());
        };
        let hdl64 = p.looks_like_hdl64();
        let mode = if hdl64 {
            if p.looks_dual() {
                ReturnMode::Dual
            } else {
                ReturnMode::Strongest
            }
        } else {
            ReturnMode::from_byte(p.factory_mode()).unwrap_or(if p.looks_dual() {
                ReturnMode::Dual
            } else {
                ReturnMode::Strongest
            })
        };
        let mut period: Option<f64> = None;
        for w in self.pending.windows(2) {
            let (a, b) = (&w[0].1, &w[1].1);
            let ta = u32::from_le_bytes([a[1200], a[1201], a[1202], a[1203]]);
            let tb = u32::from_le_bytes([b[1200], b[1201], b[1202], b[1203]]);
            let d = toh_delta_us(ta, tb) as f64;
            if d > 0.0 {
                period = Some(period.map_or(d, |p: f64| p.min(d)));
            }
        }
        self.facts.period_us = period;
        let id_model = if hdl64 {
            None
        } else {
            VelodyneModel::from_product_id(p.factory_product())
        };
        let (model, how) = if let Some(m) = self.cfg.model {
            // The user's model wins, but a contradiction the packets show is told: decoding a
            // VLP-16 as an HDL-32E gives wrong points without any other sign.
            let seen = choose_model(id_model, hdl64, mode, period)
                .filter(|(seen, _)| *seen != m)
                .map(|(seen, why)| format!("{}: {why}", seen.name()));
            let how = match &seen {
                Some(s) => format!("named by the user ({}), though the packets say {s}", m.id()),
                None => format!("named by the user ({})", m.id()),
            };
            self.facts.model_contradicted = seen;
            (m, how)
        } else {
            choose_model(id_model, hdl64, mode, period).ok_or(StreamError::UnknownModel {
                product_id: p.factory_product(),
                period_us: period,
            })?
        };
        self.facts.detection = how;
        self.build_decoder(model, mode)
    }

    fn build_decoder(&mut self, model: VelodyneModel, mode: ReturnMode) -> Result<(), StreamError> {
        let calib = match self
            .cfg
            .calibrations
            .iter()
            .find(|c| c.num_lasers() == model.lasers())
        {
            Some(c) => c.clone(),
            None => match self.cfg.calibrations.first() {
                Some(c) => {
                    return Err(StreamError::Decode(DecodeError::LaserCount {
                        model: model.name(),
                        expected: model.lasers(),
                        found: c.num_lasers(),
                    }))
                }
                None => match builtin::builtin(model) {
                    Some(c) => c,
                    None if self.cfg.inspect => {
                        // Read on without points: the packets still tell the model, return
                        // mode, clock and loss.
                        self.facts.calibration = format!(
                            "none (the {} has no built-in calibration: give its file with \
                             --calib; no points decoded)",
                            model.name()
                        );
                        self.facts.model = Some(model);
                        self.facts.mode = Some(mode);
                        self.uncalibrated = true;
                        return Ok(());
                    }
                    None => return Err(StreamError::NeedsCalibration(model.name(), "")),
                },
            },
        };
        self.facts.calibration = calib.source.clone();
        let dec = VelodyneDecoder::new(model, mode, &calib, self.cfg.decode)?;
        self.facts.model = Some(model);
        self.facts.mode = Some(mode);
        self.decoder = Some(dec);
        self.column_rate.reset();
        Ok(())
    }

    /// Absolute device time of a packet stamp: completed from the GPS time when there is one,
    /// else from the host receive time.
    fn device_time(&self, toh_us: u32, host_ns: i64) -> (i64, ClockSource) {
        match self.gps {
            Some(g) if g.valid => {
                let est = g.rmc_utc_ns + toh_delta_us(g.toh_us, toh_us) * 1_000;
                let clock = if g.pps_locked {
                    ClockSource::SensorGps
                } else {
                    ClockSource::Host
                };
                (complete_toh(toh_us, est), clock)
            }
            _ => (complete_toh(toh_us, host_ns), ClockSource::Host),
        }
    }

    fn decode_packet(
        &mut self,
        host_ns: i64,
        p: &DataPacket<'_>,
        on_sweep: &mut dyn FnMut(&mut Sweep, &SensorFacts),
    ) {
        let Some(dec) = self.decoder.as_ref() else {
            return;
        };
        let model = dec.model();
        // A return-mode change (factory byte) rebuilds the decoder.
        if !model.is_hdl64() {
            if let Some(m) = ReturnMode::from_byte(p.factory_mode()) {
                if m != dec.mode() {
                    self.emit(on_sweep);
                    self.stats.mode_changes += 1;
                    if self.build_decoder(model, m).is_err() {
                        self.stats.malformed += 1;
                        return;
                    }
                }
            }
        }
        let Some(dec) = self.decoder.as_ref() else {
            return;
        };
        if dec.check_layout(p).is_err() {
            self.stats.malformed += 1;
            return;
        }
        let mode = dec.mode();
        let bpf = dec.blocks_per_firing().max(1);
        let used = dec.blocks_used().clamp(1, BLOCKS);
        let block_t: [u32; BLOCKS] = core::array::from_fn(|b| dec.block_time_ns(b));
        let toh = p.timestamp_us();
        let (stamp_ns, clock) = self.device_time(toh, host_ns);
        // A new sweep takes the packet's time from the current clock; a sweep already open
        // goes on from the time of the packet that opened it (see `anchor`).
        let fresh_first_firing_ns = stamp_ns.saturating_add(model.stamp_to_first_firing_ns());
        let period_ns = model.packet_period_ns(mode);

        // Copies, loss and discontinuities. Two packets of one sensor never share a timestamp.
        if self.recent.contains(i64::from(toh)) {
            self.stats.duplicates += 1;
            return;
        }
        if let Some(prev) = self.prev {
            let d_us = toh_delta_us(prev.toh_us, toh);
            let d_ns = d_us * 1_000;
            // Late: a little behind the latest, and inside a gap counted missing (a clock
            // that stepped back fills none, and stays a discontinuity).
            let within = d_ns < 0
                && period_ns > 0.0
                && d_ns as f64 >= -f64::from(REORDER_PACKETS) * period_ns;
            if within && self.fill_gap(toh) {
                self.push_late(toh, host_ns, p, clock);
                return;
            }
            if d_ns <= 0 || d_ns > self.cfg.max_gap_ns {
                self.stats.discontinuities += 1;
                self.emit(on_sweep);
                self.prev = None;
                // A clock that restarted (or a capture replayed again) may repeat times.
                self.recent.clear();
                self.gaps = [None; GAPS_KEPT];
                self.column_rate.reset();
            } else if period_ns > 0.0 {
                let missing = ((d_ns as f64 / period_ns).round() as i64 - 1).max(0) as u64;
                if missing > 0 {
                    self.stats.missing += missing;
                    if self.sweep_open {
                        self.cur.missing_packets += missing;
                    }
                    self.gaps.rotate_right(1);
                    self.gaps[0] = Some((prev.toh_us, toh, missing));
                }
            }
        }
        self.recent.push(i64::from(toh));
        self.packet_rate = match self.decoder.as_ref() {
            Some(d) => self.column_rate.next(d, p),
            None => None,
        };
        let mut first_firing_ns = if self.sweep_open {
            self.anchored_first_firing(toh)
        } else {
            fresh_first_firing_ns
        };
        let cut = self.cfg.cut_angle;
        let rel = |az: u16| -> u16 {
            ((u32::from(az) + 36_000 - u32::from(cut) % 36_000) % 36_000) as u16
        };
        let mut last_rel = self.prev.map(|p| p.rel_az);
        let mut seg_start = 0usize;
        let mut g = 0usize;
        while g < used {
            let r = rel(p.azimuth(g));
            let wrapped = matches!(last_rel, Some(l) if u32::from(l) > u32::from(r) + 18_000);
            let too_long = self.sweep_open
                && first_firing_ns
                    .saturating_add(i64::from(block_t[g]))
                    .saturating_sub(self.cur.device_time_ns)
                    > self.cfg.max_sweep_ns;
            // Blocks of this packet before `g` may open the sweep themselves (a wrap inside the
            // stream's first packet, or the first after a discontinuity).
            if (wrapped || too_long) && (self.sweep_open || g > seg_start) {
                if !wrapped {
                    // No turn ended it: a stalled motor or a clock that ran on.
                    self.stats.discontinuities += 1;
                }
                if g > seg_start {
                    self.add_segment_at(toh, host_ns, p, seg_start..g, first_firing_ns, clock);
                }
                self.emit(on_sweep);
                first_firing_ns = fresh_first_firing_ns;
                seg_start = g;
            }
            last_rel = Some(r);
            g += bpf;
        }
        if seg_start < used {
            self.add_segment_at(toh, host_ns, p, seg_start..used, first_firing_ns, clock);
        }
        self.cur.last_azimuth = p.azimuth(used - 1);
        self.stats.data_packets += 1;
        self.prev = Some(Prev {
            toh_us: toh,
            rel_az: last_rel.unwrap_or(0),
        });
    }

    /// A packet a little behind the latest, inside a gap counted missing, was reordered on the
    /// way: it fills that gap, and the stream goes on from the latest packet. Its firings timed
    /// inside the open sweep join it, after the points that came before it (a sweep keeps
    /// the order of arrival, as the ROS driver's does; with columns kept, its columns follow
    /// the sweep's last). Firings of a sweep already emitted are lost: a packet with none in
    /// the open sweep is counted in `late_dropped`.
    fn push_late(&mut self, toh: u32, host_ns: i64, p: &DataPacket<'_>, clock: ClockSource) {
        self.recent.push(i64::from(toh));
        self.stats.missing = self.stats.missing.saturating_sub(1);
        let Some(dec) = self.decoder.as_ref().filter(|_| self.sweep_open) else {
            self.stats.late_dropped += 1;
            return;
        };
        let (bpf, used) = (
            dec.blocks_per_firing().max(1),
            dec.blocks_used().clamp(1, BLOCKS),
        );
        let first_firing_ns = self.anchored_first_firing(toh);
        let first = (0..used).step_by(bpf).find(|&g| {
            first_firing_ns.saturating_add(i64::from(dec.block_time_ns(g)))
                >= self.cur.device_time_ns
        });
        let Some(first) = first else {
            self.stats.late_dropped += 1;
            return;
        };
        self.cur.missing_packets = self.cur.missing_packets.saturating_sub(1);
        self.add_segment(host_ns, p, first..used, first_firing_ns, clock);
        self.stats.data_packets += 1;
    }

    /// The first firing of a packet stamped `toh` in the open sweep, timed from the packet
    /// that opened it (`anchor`).
    fn anchored_first_firing(&self, toh: u32) -> i64 {
        let (toh0, ff0) = self.anchor;
        ff0.saturating_add(toh_delta_us(toh0, toh).saturating_mul(1_000))
    }

    /// Whether a packet stamped `toh` falls inside one of the last gaps counted missing,
    /// which then counts one packet fewer.
    fn fill_gap(&mut self, toh: u32) -> bool {
        let inside = self
            .gaps
            .iter_mut()
            .flatten()
            .find(|(before, after, left)| {
                *left > 0 && toh_delta_us(*before, toh) > 0 && toh_delta_us(toh, *after) > 0
            });
        match inside {
            Some((_, _, left)) => {
                *left -= 1;
                true
            }
            None => false,
        }
    }

    /// [`Self::add_segment`], remembering the packet that opens a sweep as its time anchor.
    fn add_segment_at(
        &mut self,
        toh: u32,
        host_ns: i64,
        p: &DataPacket<'_>,
        blocks: core::ops::Range<usize>,
        first_firing_ns: i64,
        clock: ClockSource,
    ) {
        let was_open = self.sweep_open;
        self.add_segment(host_ns, p, blocks, first_firing_ns, clock);
        if !was_open && self.sweep_open {
            self.anchor = (toh, first_firing_ns);
        }
    }

    fn add_segment(
        &mut self,
        host_ns: i64,
        p: &DataPacket<'_>,
        blocks: core::ops::Range<usize>,
        first_firing_ns: i64,
        clock: ClockSource,
    ) {
        let Some(dec) = self.decoder.as_ref() else {
            return;
        };
        let seg_t0 = i64::from(dec.block_time_ns(blocks.start));
        if !self.sweep_open {
            self.cur.clear();
            self.cur.index = self.next_index;
            self.cur.device_time_ns = first_firing_ns.saturating_add(seg_t0);
            self.cur.clock = clock;
            self.cur.timestamp_ns = match clock {
                ClockSource::Host => host_ns.saturating_add(seg_t0),
                _ => self.cur.device_time_ns,
            };
            self.cur.first_host_ns = host_ns;
            self.cur.first_azimuth = p.azimuth(blocks.start);
            self.sweep_open = true;
            self.facts.clock = clock;
        }
        let t_base = first_firing_ns.saturating_sub(self.cur.device_time_ns);
        let col_base = self.cur.columns_count;
        let before = self.cur.points.len();
        if self.cfg.keep_columns {
            let first_col = dec.block_column(blocks.start) as u32;
            let (points, columns) = (&mut self.cur.points, &mut self.cur.columns);
            dec.decode_with_rate(p, blocks.clone(), t_base, self.packet_rate, |pt, col| {
                points.push(pt);
                columns.push(col_base + col as u32 - first_col);
            });
        } else {
            let points = &mut self.cur.points;
            points.reserve(blocks.len() * SLOTS);
            dec.decode_with_rate(p, blocks.clone(), t_base, self.packet_rate, |pt, _| {
                points.push(pt)
            });
        }
        let cols = dec.block_column(blocks.end - 1) + 1 - dec.block_column(blocks.start);
        // VLP-16: each block holds two firing columns.
        let per_block_extra =
            if matches!(dec.model(), VelodyneModel::Vlp16 | VelodyneModel::PuckHiRes)
                && !dec.mode().is_dual()
            {
                1
            } else {
                0
            };
        self.cur.columns_count += (cols + per_block_extra) as u32;
        self.stats.points += (self.cur.points.len() - before) as u64;
        self.cur.packets += 1;
        self.cur.last_host_ns = host_ns;
    }

    fn emit(&mut self, on_sweep: &mut dyn FnMut(&mut Sweep, &SensorFacts)) {
        if !self.sweep_open {
            return;
        }
        self.sweep_open = false;
        if self.cur.packets > 0 {
            self.stats.sweeps += 1;
            self.next_index += 1;
            on_sweep(&mut self.cur, &self.facts);
        }
    }
}

/// Picks the model from the product id, the HDL-64E layout and the packet cadence.
fn choose_model(
    id_model: Option<VelodyneModel>,
    hdl64: bool,
    mode: ReturnMode,
    period_us: Option<f64>,
) -> Option<(VelodyneModel, String)> {
    use VelodyneModel::*;
    let candidates: &[VelodyneModel] = if hdl64 {
        &[Hdl64eS2, Hdl64eS3]
    } else {
        &[Vlp16, Hdl32e, Vlp32c, Vls128]
    };
    let fits = |m: VelodyneModel, d: f64| {
        let p = m.packet_period_ns(mode) / 1_000.0;
        // The VLS-128's firing sequence depends on its firmware: 3 × 53.3 = 160 µs per packet
        // (manual Rev 3, FW 5.1.7.1), 173.3 µs (Rev 4, FW ≥ 5.2.3.0; VeloView, velodyne_decoder),
        // and 165–166 µs on nebula's real capture.
        let slack = if m == VelodyneModel::Vls128 {
            p * (173.3 / 160.0 - 1.0) * 1.03
        } else {
            0.0
        };
        d >= p * 0.97 && d <= p * 1.03 + slack
    };
    match period_us {
        Some(d) => {
            if let Some(m) = id_model {
                if fits(m, d) {
                    return Some((
                        m,
                        format!(
                            "product id {:#04x} ({}), confirmed by the {d:.0} µs packet period",
                            m.product_id().unwrap_or(0),
                            m.name()
                        ),
                    ));
                }
            }
            if let Some(&m) = candidates.iter().find(|&&m| fits(m, d)) {
                let why = match id_model {
                    Some(idm) => format!(
                        "packet period {d:.0} µs fits the {} in {mode} mode, not the {} its product id {:#04x} names",
                        m.name(),
                        idm.name(),
                        idm.product_id().unwrap_or(0)
                    ),
                    None if hdl64 => format!("HDL-64E block layout, packet period {d:.0} µs fits the {}", m.name()),
                    None => format!("unknown product id; packet period {d:.0} µs fits the {}", m.name()),
                };
                return Some((m, why));
            }
            id_model.map(|m| (m, format!("product id {:#04x} ({}); packet period {d:.0} µs fits no model (packet loss?)", m.product_id().unwrap_or(0), m.name())))
        }
        None => {
            if hdl64 {
                Some((
                    Hdl64eS2,
                    "HDL-64E block layout; one packet only, S2 assumed".to_string(),
                ))
            } else {
                id_model.map(|m| {
                    (
                        m,
                        format!(
                            "product id {:#04x} ({}), not checked against the cadence (told from the first packet alone)",
                            m.product_id().unwrap_or(0),
                            m.name()
                        ),
                    )
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_vls128_firmware_cadence_is_confirmed() {
        for period in [159.9, 165.8, 173.3] {
            let (m, why) = choose_model(
                Some(VelodyneModel::Vls128),
                false,
                ReturnMode::Strongest,
                Some(period),
            )
            .unwrap();
            assert_eq!(m, VelodyneModel::Vls128);
            assert!(why.contains("confirmed"), "{period}: {why}");
        }
        // Dual return: one sequence a packet, a third of each.
        for period in [53.3, 55.3, 57.8] {
            let (m, why) = choose_model(
                Some(VelodyneModel::Vls128),
                false,
                ReturnMode::Dual,
                Some(period),
            )
            .unwrap();
            assert_eq!(m, VelodyneModel::Vls128);
            assert!(why.contains("confirmed"), "dual {period}: {why}");
        }
    }

    #[test]
    fn cadence_overrides_a_wrong_product_id() {
        // 0x21 says HDL-32E but packets come every 1327 µs: a VLP-16.
        let (m, _) = choose_model(
            Some(VelodyneModel::Hdl32e),
            false,
            ReturnMode::Strongest,
            Some(1327.0),
        )
        .unwrap();
        assert_eq!(m, VelodyneModel::Vlp16);
        let (m, _) = choose_model(
            Some(VelodyneModel::Hdl32e),
            false,
            ReturnMode::Strongest,
            Some(553.0),
        )
        .unwrap();
        assert_eq!(m, VelodyneModel::Hdl32e);
        // VLP-16 dual and VLP-32C single share 663.5 µs; the id and the mode settle it.
        let (m, _) = choose_model(
            Some(VelodyneModel::Vlp16),
            false,
            ReturnMode::Dual,
            Some(664.0),
        )
        .unwrap();
        assert_eq!(m, VelodyneModel::Vlp16);
        let (m, _) = choose_model(
            Some(VelodyneModel::Vlp32c),
            false,
            ReturnMode::Strongest,
            Some(664.0),
        )
        .unwrap();
        assert_eq!(m, VelodyneModel::Vlp32c);
        let (m, _) = choose_model(None, true, ReturnMode::Strongest, Some(345.6)).unwrap();
        assert_eq!(m, VelodyneModel::Hdl64eS3);
        assert!(choose_model(None, false, ReturnMode::Strongest, Some(1000.0)).is_none());
    }
}
