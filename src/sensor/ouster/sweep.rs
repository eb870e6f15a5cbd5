//! One Ouster sensor's stream: frames by `frame_id`, column window, missing columns, epochs,
//! IMU samples.
//!
//! Feed it every UDP payload from one sensor with its host receive time; it calls back with
//! each finished sweep (one sensor frame). A sweep is cut when a packet of a newer `frame_id`
//! arrives (half-range signed difference, so the 16-bit — FUSA: 32-bit — counter wraps);
//! one older frame stays open as a reorder window, and packets at most
//! [`RESTART_BEHIND_FRAMES`] frames behind the newest are counted as late and dropped, as are
//! duplicates (packets whose columns all arrived already).
//!
//! A packet further behind is either stale (a datagram delayed or re-sent, alone or in a run a
//! switch buffer flushes, the stream going on with the newest frame after it) or the first of
//! a counter that started over (a reboot the `init_id` does not show, a looped replay, a
//! newest frame a corrupt packet opened far ahead). One of a frame among the last
//! [`RECENT_FRAMES`] emitted, whose valid columns lie within that frame's column times (give
//! or take a frame period) and which comes at most [`STALE_WITHIN_NS`] after the frame's last
//! packet, is stale: late, however long the run (a counter that started over reuses frame
//! ids, not their times: a reboot's clock starts again at its own boot or, PTP, goes on; a
//! loop comes a loop later). Otherwise its frame id cannot tell which; the packets after it
//! can. So it is held, counted
//! late for now, and so are the next ones while each continues from the held frames (at most
//! [`RESTART_BEHIND_FRAMES`] behind the newest held one, at most a second's frames ahead of
//! it). [`RESTART_CONFIRM_PACKETS`] held in a row are a restart: they leave `late`, the open
//! frames are emitted, a discontinuity is counted and the held packets are decoded as the new
//! stream's first. A packet that goes on from the open frames first shows the held ones stale:
//! they stay counted late, once, and nothing else changes (taken for a restart, one stale
//! packet cut the open frame in two and counted the frames back to the newest lost). Bit-for-bit
//! copies of a held packet are late and no evidence. The stream's end or a new epoch leaves the
//! held packets late: so does a restart fewer than [`RESTART_CONFIRM_PACKETS`] packets long.
//!
//! The sweep's timestamp is its earliest column timestamp; `t` of every point is measured from
//! it (points already in the sweep are moved if an earlier column arrives late). A sweep
//! without any valid column has no sensor time: its times are the host's, and so is its clock.
//!
//! Missing columns = columns of the metadata's column window that never arrived with status
//! bit 0 set, plus those of whole frames lost: a frame that opens `d` frames after the newest
//! (`1 < d ≤ fps`, a second's worth) carries the `d − 1` frames before it as missing in its
//! own sweep; a longer step forward is a discontinuity, not a loss (as the other families'
//! one-second gap). A packet whose `init_id` differs from the metadata's (the sensor
//! re-initialised) and whose CRC (if checked) holds starts a new epoch: counted, warned in the
//! summary, the stream goes on.
//! Zone-monitor packets (FW 3.2+) become [`ZoneReport`]s, taken with [`OusterStream::drain_zones`].

use crate::point::{half_to_f32, PointExtra};
use crate::sensor::ouster::calib::ImuProfile;
use crate::sensor::ouster::calib::OusterInfo;
use crate::sensor::ouster::calib::TimestampMode;
use crate::sensor::ouster::decode::OusterDecoder;
use crate::sensor::ouster::model::HeaderKind;
use crate::sensor::ouster::wire::ImuPacketLegacy;
use crate::sensor::ouster::wire::ImuPacketNmea;
use crate::sensor::ouster::wire::LidarPacket;
use crate::sensor::ouster::wire::ZonePacket;
use crate::sensor::ouster::wire::ZoneState;
use crate::sensor::ouster::wire::PACKET_TYPE_ZONE;
use crate::sensor::ouster::wire::ZONE_COUNT;
use crate::sensor::ouster::wire::ZONE_HASH_BYTES;
use crate::sensor::ouster::wire::ZONE_PACKET_BYTES;
use crate::sensor::DecodeError;
use crate::sensor::DecodeOptions;
use crate::sensor::WireError;
use crate::sweep::Sweep;
use crate::time::ClockSource;

/// TAI − UTC since 2017-01-01, seconds (PTP time is TAI).
pub const TAI_MINUS_UTC_S: u64 = 37;
/// Most IMU samples held between two drains.
pub const MAX_IMU_QUEUE: usize = 4096;
/// Most zone reports held between two drains (one per frame: 25 s at 10 Hz).
pub const MAX_ZONE_QUEUE: usize = 256;
/// Standard gravity, m/s² per g (ouster-ros `packet_to_imu_msg`).
const G: f64 = 9.80665;
/// A packet of a frame at most this far behind the newest open one is late (the reorder
/// window every family shares, [`crate::sweep::REORDER_PACKETS`], is well under a frame);
/// further behind, the frame counter started over. Small, because until then every packet of
/// the sensor is dropped as late.
pub const RESTART_BEHIND_FRAMES: i64 = 2;
/// Packets in a row, each continuing from the one before, far behind the newest open frame
/// that make a restart (see the module documentation). A restart goes on for thousands of
/// packets; stale datagrams of a frame not emitted lately (the others are known stale by
/// their times) come one or a few at a time. Four: a stale run of three is still late, and the
/// packets held meanwhile stay within four lidar packets (< 100 kB).
pub const RESTART_CONFIRM_PACKETS: usize = 4;
/// Frames whose id and column times the stream keeps after emitting them, so that a run of
/// stale datagrams of one of them is known for what it is, however long (module
/// documentation). 32: at 20 Hz over 1.5 s, well past [`STALE_WITHIN_NS`]; a fixed table.
pub const RECENT_FRAMES: usize = 32;
/// A datagram of an emitted frame arriving later than this after that frame's last packet
/// (host time) is no stale copy but the sensor's counter going over the same frames again (a
/// capture replayed in a loop): a switch buffer or a re-send delays a datagram by
/// milliseconds, a loop by its length.
pub const STALE_WITHIN_NS: i64 = 1_000_000_000;

/// Configuration of one Ouster stream.
#[derive(Clone, Debug)]
pub struct OusterStreamConfig {
    /// The sensor's metadata.
    pub info: OusterInfo,
    /// Name of the metadata file (for summaries).
    pub metadata_name: String,
    /// Footer CRC check: `None` = the firmware rule (≥ 2.5, not FUSA), `Some(on)` forces it.
    pub crc: Option<bool>,
    /// Range filter.
    pub decode: DecodeOptions,
    /// Keep range, signal and near-IR per point ([`Sweep::extras`]).
    pub keep_extras: bool,
    /// Keep each point's column (measurement id) in [`Sweep::columns`].
    pub keep_columns: bool,
}

impl OusterStreamConfig {
    /// Size of the IMU packets a sensor with this metadata sends, if any.
    pub fn imu_len_of(info: &OusterInfo) -> Option<usize> {
        match info.imu_profile {
            ImuProfile::Legacy => Some(48),
            ImuProfile::Accel32Gyro32Nmea => {
                Some(crate::sensor::ouster::wire::imu_nmea_packet_bytes(
                    info.imu_measurements_per_packet,
                ))
            }
            ImuProfile::Off => None,
        }
    }
}

/// Counters of one Ouster stream.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct OusterStats {
    /// Lidar packets decoded.
    pub lidar_packets: u64,
    /// IMU packets decoded.
    pub imu_packets: u64,
    /// Packets of no size this sensor sends, or whose headers do not parse.
    pub malformed: u64,
    /// Lidar packets whose footer CRC-64 did not match.
    pub crc_failures: u64,
    /// Packets whose serial number is not the metadata's (and whose CRC, if checked, holds).
    pub wrong_sensor: u64,
    /// Packets of a frame older than the reorder window, and duplicates (every valid column
    /// of the packet already arrived in its open frame). Packets far behind the newest frame
    /// are in it when of a frame emitted lately, in its time, or while held as a possible
    /// restart, and stay when they prove stale.
    pub late: u64,
    /// Times the sensor's `init_id` changed (re-initialisation).
    pub epochs: u64,
    /// Frame counter steps no loss explains: back by more than [`RESTART_BEHIND_FRAMES`] for
    /// [`RESTART_CONFIRM_PACKETS`] packets in a row (the open frames are emitted and the
    /// stream starts anew), or forward by more than a second's frames (not counted as missing).
    pub discontinuities: u64,
    /// Columns of the column window that never arrived, over all sweeps, including those of
    /// whole frames lost.
    pub missing_columns: u64,
    /// Sweeps emitted.
    pub sweeps: u64,
    /// Points emitted.
    pub points: u64,
    /// IMU samples dropped because the queue was not drained.
    pub imu_dropped: u64,
    /// Zone-monitor packets decoded.
    pub zone_packets: u64,
    /// Zone reports dropped because the queue was not drained.
    pub zone_dropped: u64,
}

/// One IMU sample in SI units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuSample {
    /// Sensor timestamp of the accelerometer reading, ns (sensor clock).
    pub sensor_ns: u64,
    /// Host receive time of the packet, ns.
    pub host_ns: i64,
    /// Linear acceleration, m/s², sensor IMU frame.
    pub accel: [f64; 3],
    /// Angular velocity, rad/s.
    pub gyro: [f64; 3],
}

/// One zone-monitor packet: the sensor's verdict on its configured zones for one frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ZoneReport {
    /// Host receive time of the packet, ns.
    pub host_ns: i64,
    /// Timestamp of the zone states, ns (sensor clock).
    pub sensor_ns: u64,
    /// The frame the zones were judged on.
    pub frame_id: u32,
    /// The header's alert flags.
    pub alert_flags: u8,
    /// SHA-256 of the live zone set the states refer to.
    pub zoneset_hash: [u8; ZONE_HASH_BYTES],
    /// The 16 zone slots, live or not, in packet order.
    pub zones: [ZoneState; ZONE_COUNT],
}

/// What the stream knows of its sensor, for summaries and MCAP metadata.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OusterFacts {
    /// Product line, e.g. `OS-1-128`.
    pub prod_line: String,
    /// Serial number.
    pub serial: u64,
    /// Firmware ([`crate::sensor::ouster::calib::OusterInfo::firmware_label`]).
    pub firmware: String,
    /// Lidar profile name.
    pub profile: String,
    /// `WxHz`.
    pub mode: String,
    /// Metadata file name.
    pub metadata: String,
    /// Bytes of a lidar packet (the sensor's other packets are IMU packets).
    pub lidar_packet_bytes: usize,
    /// Clock of the sweep timestamps.
    pub clock: ClockSource,
    /// Whether lidar footers are CRC-checked.
    pub crc_checked: bool,
    /// init_id currently decoded.
    pub init_id: u32,
    /// Worst shot-limiting state seen (0 = normal).
    pub shot_limiting: u8,
    /// Worst thermal-shutdown state seen (0 = normal).
    pub thermal_shutdown: u8,
    /// Alert flags (header byte 12) of the last lidar packet.
    pub alert_flags_last: u8,
    /// Every alert flag seen (or-ed).
    pub alert_flags_seen: u8,
    /// Lidar packets with any alert flag set.
    pub alert_packets: u64,
}

#[derive(Debug)]
struct Open {
    frame_id: u32,
    sweep: Sweep,
    seen: Vec<bool>,
    start_ns: u64,
    /// The latest valid column timestamp (0 before one).
    end_ns: u64,
    /// Columns and packets of the whole frames lost just before this one.
    lost_columns: u64,
    lost_packets: u64,
}

/// An emitted frame's id and span of column times, and when its last packet came (host time).
#[derive(Clone, Copy, Debug, Default)]
struct Emitted {
    frame_id: u32,
    first_ns: u64,
    last_ns: u64,
    last_host_ns: i64,
    /// Whether the slot holds a frame (the table starts empty).
    used: bool,
}

/// Lidar packets far behind the newest open frame, held until the packets after them tell a
/// restart from stale datagrams (module documentation).
#[derive(Debug, Default)]
struct Held {
    /// Host time and bytes of each held packet; slots past `len` keep their buffers, so that
    /// holding allocates only the first few times.
    packets: Vec<(i64, Vec<u8>)>,
    len: usize,
    /// The newest frame id among the held packets: the next one must continue from it.
    newest: u32,
}

/// An Ouster stream for one sensor.
#[derive(Debug)]
pub struct OusterStream {
    cfg: OusterStreamConfig,
    decoder: OusterDecoder,
    open: Vec<Open>,
    spare: Vec<Open>,
    held: Held,
    /// The last [`RECENT_FRAMES`] frames emitted, a ring written at `recent_next`.
    recent: [Emitted; RECENT_FRAMES],
    recent_next: usize,
    imu: Vec<ImuSample>,
    zones: Vec<ZoneReport>,
    stats: OusterStats,
    facts: OusterFacts,
    next_index: u64,
    frame_bits: u32,
    /// Column timestamps measured within packets: the time spanned and the columns stepped
    /// over (first to last valid column of each packet), for [`Self::measured_fps`].
    column_span_ns: u64,
    column_steps: u64,
}

impl OusterStream {
    /// A new stream; fails if the metadata cannot make a decoder.
    pub fn new(cfg: OusterStreamConfig) -> Result<Self, DecodeError> {
        let decoder = Self::make_decoder(&cfg, &cfg.info)?;
        Self::with_decoder(cfg, decoder)
    }

    /// A new stream around `decoder`, already made from `cfg.info` (the one a calibration
    /// built when its file was read: the stream then does not compute its XYZ table again);
    /// `cfg.crc` still applies.
    pub fn with_decoder(
        cfg: OusterStreamConfig,
        decoder: OusterDecoder,
    ) -> Result<Self, DecodeError> {
        let decoder = match cfg.crc {
            Some(on) => decoder.with_crc_check(on),
            None => decoder,
        };
        let info = &cfg.info;
        let clock = if info.timestamp_mode == TimestampMode::Ptp1588 {
            ClockSource::SensorPtp
        } else {
            ClockSource::Host
        };
        let facts = OusterFacts {
            prod_line: info.prod_line.clone(),
            serial: info.serial,
            firmware: info.firmware_label(),
            profile: info.format.profile.name().to_string(),
            mode: format!("{}x{}", info.columns_per_frame, info.fps),
            metadata: cfg.metadata_name.clone(),
            lidar_packet_bytes: info.lidar_packet_bytes(),
            clock,
            crc_checked: decoder.crc_check(),
            init_id: info.init_id,
            shot_limiting: 0,
            thermal_shutdown: 0,
            alert_flags_last: 0,
            alert_flags_seen: 0,
            alert_packets: 0,
        };
        let frame_bits = if info.format.profile.header() == HeaderKind::Fusa {
            32
        } else {
            16
        };
        Ok(Self {
            cfg,
            decoder,
            open: Vec::with_capacity(2),
            spare: Vec::with_capacity(2),
            held: Held::default(),
            recent: [Emitted::default(); RECENT_FRAMES],
            recent_next: 0,
            imu: Vec::new(),
            zones: Vec::new(),
            stats: OusterStats::default(),
            facts,
            next_index: 0,
            frame_bits,
            column_span_ns: 0,
            column_steps: 0,
        })
    }

    fn make_decoder(
        cfg: &OusterStreamConfig,
        info: &OusterInfo,
    ) -> Result<OusterDecoder, DecodeError> {
        let mut d = OusterDecoder::new(info)?;
        if let Some(on) = cfg.crc {
            d = d.with_crc_check(on);
        }
        Ok(d)
    }

    /// The metadata.
    pub fn info(&self) -> &OusterInfo {
        &self.cfg.info
    }

    /// The decoder.
    pub fn decoder(&self) -> &OusterDecoder {
        &self.decoder
    }

    /// Counters.
    pub fn stats(&self) -> &OusterStats {
        &self.stats
    }

    /// The frame rate the packets' own column timestamps show, at the metadata's columns per
    /// frame; `None` before a packet with two valid columns. LEGACY packets carry no serial,
    /// so another unit's metadata (or the same unit's in another mode) is accepted by size:
    /// a rate far from the metadata's is how such a mix-up shows.
    pub fn measured_fps(&self) -> Option<f64> {
        if self.column_steps == 0 || self.column_span_ns == 0 {
            return None;
        }
        let column_ns = self.column_span_ns as f64 / self.column_steps as f64;
        Some(1e9 / (column_ns * self.cfg.info.columns_per_frame.max(1) as f64))
    }

    /// Why the frame rate the packets show contradicts the metadata's, when it does by more
    /// than a fifth (a mode of another rate, at least 2×, is far beyond that; the sensor's
    /// own jitter is well within).
    pub fn rate_mismatch(&self) -> Option<String> {
        let measured = self.measured_fps()?;
        let fps = f64::from(self.cfg.info.fps);
        if fps <= 0.0 || (measured / fps - 1.0).abs() <= 0.2 {
            return None;
        }
        Some(format!(
            "the packets' column timestamps give {measured:.1} frames/s, the metadata's lidar \
             mode {} says {fps}: it may be another unit's, or of another mode (its beam angles \
             and column times are then wrong)",
            self.facts.mode
        ))
    }

    /// What is known of the sensor.
    pub fn facts(&self) -> &OusterFacts {
        &self.facts
    }

    /// Whether a payload of this size is one this sensor sends (lidar, IMU or zone monitor).
    pub fn accepts_len(&self, len: usize) -> bool {
        len == self.cfg.info.lidar_packet_bytes()
            || Some(len) == self.imu_len()
            || len == ZONE_PACKET_BYTES
    }

    fn imu_len(&self) -> Option<usize> {
        OusterStreamConfig::imu_len_of(&self.cfg.info)
    }

    /// Takes the IMU samples decoded since the last call.
    pub fn drain_imu(&mut self) -> std::vec::Drain<'_, ImuSample> {
        self.imu.drain(..)
    }

    /// Takes the zone reports decoded since the last call.
    pub fn drain_zones(&mut self) -> std::vec::Drain<'_, ZoneReport> {
        self.zones.drain(..)
    }

    /// Pushes one UDP payload from this sensor; finished sweeps go to `on_sweep`.
    pub fn push(
        &mut self,
        host_ns: i64,
        payload: &[u8],
        on_sweep: &mut dyn FnMut(&mut Sweep, &OusterFacts),
    ) {
        if payload.len() == self.cfg.info.lidar_packet_bytes() {
            self.push_lidar(host_ns, payload, on_sweep);
        } else if Some(payload.len()) == self.imu_len() {
            self.push_imu(host_ns, payload);
        } else if payload.len() == ZONE_PACKET_BYTES {
            self.push_zone(host_ns, payload);
        } else {
            self.stats.malformed += 1;
        }
    }

    fn push_zone(&mut self, host_ns: i64, payload: &[u8]) {
        let Ok(p) = ZonePacket::new(payload, self.cfg.info.format.profile.header()) else {
            self.stats.malformed += 1;
            return;
        };
        if p.packet_type() != PACKET_TYPE_ZONE {
            self.stats.malformed += 1;
            return;
        }
        let expected = self.cfg.info.serial;
        if expected != 0 && p.serial() != expected {
            self.stats.wrong_sensor += 1;
            return;
        }
        let crc = self
            .cfg
            .crc
            .unwrap_or_else(|| self.cfg.info.zone_packets_have_crc());
        if crc && p.crc() != p.computed_crc() {
            self.stats.crc_failures += 1;
            return;
        }
        self.stats.zone_packets += 1;
        if self.zones.len() >= MAX_ZONE_QUEUE {
            self.stats.zone_dropped += 1;
            return;
        }
        let mut zones = [ZoneState::default(); ZONE_COUNT];
        for (i, z) in zones.iter_mut().enumerate() {
            *z = p.zone(i).unwrap_or_default();
        }
        self.zones.push(ZoneReport {
            host_ns,
            sensor_ns: p.timestamp_ns(),
            frame_id: p.frame_id(),
            alert_flags: p.alert_flags(),
            zoneset_hash: p.zoneset_hash(),
            zones,
        });
    }

    /// Emits the sweeps still open. Packets held as a possible restart stay counted late:
    /// nothing after them showed one.
    pub fn finish(&mut self, on_sweep: &mut dyn FnMut(&mut Sweep, &OusterFacts)) {
        self.held.len = 0;
        self.open.sort_by_key(|o| o.sweep.index);
        while !self.open.is_empty() {
            let o = self.open.remove(0);
            self.emit(o, on_sweep);
        }
    }

    fn push_imu(&mut self, host_ns: i64, payload: &[u8]) {
        let push = |s: ImuSample, stats: &mut OusterStats, q: &mut Vec<ImuSample>| {
            if q.len() < MAX_IMU_QUEUE {
                q.push(s);
            } else {
                stats.imu_dropped += 1;
            }
        };
        match self.cfg.info.imu_profile {
            ImuProfile::Legacy => match ImuPacketLegacy::new(payload) {
                Ok(p) => {
                    let a = p.accel_g();
                    let g = p.gyro_dps();
                    let s = ImuSample {
                        sensor_ns: p.accel_ts_ns(),
                        host_ns,
                        accel: a.map(|v| f64::from(v) * G),
                        gyro: g.map(|v| f64::from(v).to_radians()),
                    };
                    self.stats.imu_packets += 1;
                    push(s, &mut self.stats, &mut self.imu);
                }
                Err(_) => self.stats.malformed += 1,
            },
            ImuProfile::Accel32Gyro32Nmea => {
                match ImuPacketNmea::new(payload, self.cfg.info.imu_measurements_per_packet) {
                    Ok(p) => {
                        self.stats.imu_packets += 1;
                        for m in p.measurements().filter(|m| m.valid()) {
                            let s = ImuSample {
                                sensor_ns: m.timestamp_ns,
                                host_ns,
                                accel: m.accel.map(f64::from),
                                gyro: m.gyro.map(f64::from),
                            };
                            push(s, &mut self.stats, &mut self.imu);
                        }
                    }
                    Err(_) => self.stats.malformed += 1,
                }
            }
            ImuProfile::Off => self.stats.malformed += 1,
        }
    }

    /// Signed difference `b − a` of two frame ids on the sensor's counter width.
    fn frame_diff(&self, a: u32, b: u32) -> i64 {
        let m = 1i64 << self.frame_bits;
        let d = (i64::from(b) - i64::from(a)).rem_euclid(m);
        if d >= m / 2 {
            d - m
        } else {
            d
        }
    }

    fn push_lidar(
        &mut self,
        host_ns: i64,
        payload: &[u8],
        on_sweep: &mut dyn FnMut(&mut Sweep, &OusterFacts),
    ) {
        let packet = match self.decoder.packet(payload) {
            Ok(p) => p,
            Err(DecodeError::SensorId {
                found_init_id,
                found_serial,
                expected_serial,
                ..
            }) => {
                // The footer first: a bit flipped in the header must pass neither for another
                // sensor nor for a re-initialisation (two epochs, the open frames cut short).
                if self.decoder.crc_check() {
                    let d = &self.decoder;
                    match LidarPacket::with_header(payload, d.format(), d.header_kind()) {
                        Ok(p) if p.check_crc().is_ok() => {}
                        Ok(_) => {
                            self.stats.crc_failures += 1;
                            return;
                        }
                        Err(_) => {
                            self.stats.malformed += 1;
                            return;
                        }
                    }
                }
                if expected_serial != 0 && found_serial != 0 && found_serial != expected_serial {
                    self.stats.wrong_sensor += 1;
                    return;
                }
                // Same sensor, new init_id: a new epoch. The XYZ table stays: it does not
                // depend on the init_id, and a sender alternating ids must not rebuild it.
                self.finish(on_sweep);
                self.decoder.set_init_id(found_init_id);
                self.cfg.info.init_id = found_init_id;
                self.facts.init_id = found_init_id;
                self.stats.epochs += 1;
                match self.decoder.packet(payload) {
                    Ok(p) => p,
                    Err(_) => {
                        self.stats.malformed += 1;
                        return;
                    }
                }
            }
            Err(DecodeError::Wire(WireError::Crc { .. })) => {
                self.stats.crc_failures += 1;
                return;
            }
            Err(_) => {
                self.stats.malformed += 1;
                return;
            }
        };
        self.facts.shot_limiting = self.facts.shot_limiting.max(packet.shot_limiting());
        self.facts.thermal_shutdown = self.facts.thermal_shutdown.max(packet.thermal_shutdown());
        let alerts = packet.alert_flags();
        self.facts.alert_flags_last = alerts;
        self.facts.alert_flags_seen |= alerts;
        self.facts.alert_packets += u64::from(alerts != 0);
        let fid = packet.frame_id();
        let far_behind = !self.open.iter().any(|o| o.frame_id == fid)
            && self
                .newest_open()
                .is_some_and(|n| self.frame_diff(n, fid) < -RESTART_BEHIND_FRAMES);
        if far_behind && self.was_emitted(host_ns, &packet) {
            // Stale, whatever comes next: no evidence of a restart, nor against one held.
            self.stats.late += 1;
            return;
        }
        if far_behind {
            self.hold(host_ns, payload, fid, on_sweep);
            return;
        }
        // The stream goes on from its open frames: what was held was stale, and stays late.
        self.held.len = 0;
        self.place(host_ns, &packet, on_sweep);
    }

    /// The newest open frame's id.
    fn newest_open(&self) -> Option<u32> {
        self.open.iter().map(|o| o.frame_id).reduce(
            |a, b| {
                if self.frame_diff(a, b) > 0 {
                    b
                } else {
                    a
                }
            },
        )
    }

    /// Whether the packet is of a frame emitted lately, in time too: its valid columns lie
    /// within that frame's column times give or take a frame period, and it came at most
    /// [`STALE_WITHIN_NS`] after the frame's last packet. A sensor that started over reuses
    /// frame ids, not their times: a reboot's clock starts again from its own boot (seconds
    /// apart at least) or, PTP, goes on forward; a looped replay has the times but comes a
    /// loop later. A packet without a valid column shows no time: it is not known stale.
    fn was_emitted(&self, host_ns: i64, packet: &LidarPacket<'_>) -> bool {
        let w = self.cfg.info.columns_per_frame;
        let mut span = None::<(u64, u64)>;
        for c in packet
            .columns()
            .filter(|c| c.valid() && usize::from(c.measurement_id()) < w)
        {
            let t = c.timestamp_ns();
            span = Some(span.map_or((t, t), |(lo, hi)| (lo.min(t), hi.max(t))));
        }
        let Some((lo, hi)) = span else {
            return false;
        };
        let period_ns = 1_000_000_000 / u64::from(self.cfg.info.fps.max(1));
        let fid = packet.frame_id();
        self.recent.iter().any(|e| {
            e.used
                && e.frame_id == fid
                && lo >= e.first_ns.saturating_sub(period_ns)
                && hi <= e.last_ns.saturating_add(period_ns)
                && host_ns.saturating_sub(e.last_host_ns) <= STALE_WITHIN_NS
        })
    }

    /// Holds a packet far behind the newest open frame (module documentation); the
    /// [`RESTART_CONFIRM_PACKETS`]th in a row restarts the stream.
    fn hold(
        &mut self,
        host_ns: i64,
        payload: &[u8],
        fid: u32,
        on_sweep: &mut dyn FnMut(&mut Sweep, &OusterFacts),
    ) {
        let held = &self.held;
        let step = self.frame_diff(held.newest, fid);
        let continues = held.len > 0
            && step >= -RESTART_BEHIND_FRAMES
            && step <= i64::from(self.cfg.info.fps.max(1));
        // Late until the packets after it tell: a restart takes it out of `late` to decode it.
        self.stats.late += 1;
        if continues {
            // A datagram the network repeated says nothing of what the sensor's counter did.
            if held
                .packets
                .iter()
                .take(held.len)
                .any(|(_, p)| p.as_slice() == payload)
            {
                return;
            }
            if step > 0 {
                self.held.newest = fid;
            }
        } else {
            // A fresh start: what was held before did not go on, so it was stale.
            self.held.len = 0;
            self.held.newest = fid;
        }
        let held = &mut self.held;
        match held.packets.get_mut(held.len) {
            Some((host, bytes)) => {
                *host = host_ns;
                bytes.clear();
                bytes.extend_from_slice(payload);
            }
            None => held.packets.push((host_ns, payload.to_vec())),
        }
        held.len += 1;
        if held.len >= RESTART_CONFIRM_PACKETS {
            self.restart(on_sweep);
        }
    }

    /// The held packets were the first of a counter that started over: waiting for it to pass
    /// the newest frame again would drop every packet for up to 2^15 frames (FUSA: ever).
    fn restart(&mut self, on_sweep: &mut dyn FnMut(&mut Sweep, &OusterFacts)) {
        let held = std::mem::take(&mut self.held.packets);
        let n = std::mem::take(&mut self.held.len);
        self.stats.late = self.stats.late.saturating_sub(n as u64);
        self.stats.discontinuities += 1;
        self.finish(on_sweep);
        for (host_ns, bytes) in held.iter().take(n) {
            // The decoder accepted these bytes when they came (a new epoch since would have
            // let go of them): this cannot fail, but a failure must not lose their count.
            match self.decoder.packet(bytes) {
                Ok(p) => self.place(*host_ns, &p, on_sweep),
                Err(_) => self.stats.malformed += 1,
            }
        }
        self.held.packets = held;
    }

    /// Puts an accepted lidar packet of an open frame, or of one it opens, into its sweep.
    fn place(
        &mut self,
        host_ns: i64,
        packet: &LidarPacket<'_>,
        on_sweep: &mut dyn FnMut(&mut Sweep, &OusterFacts),
    ) {
        let fid = packet.frame_id();
        // Find or open the frame's sweep.
        let idx = match self.open.iter().position(|o| o.frame_id == fid) {
            Some(i) => i,
            None => {
                let mut lost_frames = 0u64;
                if let Some(n) = self.newest_open() {
                    let d = self.frame_diff(n, fid);
                    if d < 0 {
                        // Older than the newest frame and not open: late. (Far behind, it
                        // was held instead, by `hold`; a restart starts with nothing open.)
                        self.stats.late += 1;
                        return;
                    } else if d > i64::from(self.cfg.info.fps.max(1)) {
                        // Not counted as frames lost: one corrupt or spoofed packet would
                        // add up to 2^15 frames of them. The genuine packets that follow,
                        // far behind it, then start the stream anew.
                        self.stats.discontinuities += 1;
                    } else {
                        lost_frames = (d - 1) as u64;
                    }
                }
                if self.open.len() == 2 {
                    // Reorder window of one frame: the older open frame is done.
                    let oldest =
                        if self.frame_diff(self.open[0].frame_id, self.open[1].frame_id) > 0 {
                            0
                        } else {
                            1
                        };
                    let o = self.open.remove(oldest);
                    self.emit(o, on_sweep);
                }
                let mut o = self.spare.pop().unwrap_or_else(|| Open {
                    frame_id: 0,
                    sweep: Sweep::default(),
                    seen: Vec::new(),
                    start_ns: 0,
                    end_ns: 0,
                    lost_columns: 0,
                    lost_packets: 0,
                });
                o.frame_id = fid;
                o.sweep.clear();
                o.sweep.index = self.next_index;
                self.next_index += 1;
                o.sweep.frame_id = fid;
                o.seen.clear();
                o.seen.resize(self.cfg.info.columns_per_frame, false);
                o.start_ns = u64::MAX;
                o.end_ns = 0;
                // The host's times until a valid column gives the sensor's: a recycled sweep
                // must not keep those of the frame it held before.
                o.sweep.device_time_ns = host_ns;
                o.sweep.first_host_ns = host_ns;
                o.sweep.last_host_ns = host_ns;
                let info = &self.cfg.info;
                let window = info.columns_in_window() as u64;
                let cpp = info.format.columns_per_packet.max(1) as u64;
                o.lost_columns = lost_frames.saturating_mul(window);
                o.lost_packets = lost_frames.saturating_mul(window.div_ceil(cpp));
                self.open.push(o);
                self.open.len() - 1
            }
        };
        let w = self.cfg.info.columns_per_frame;
        // A packet whose valid columns all arrived already (a duplicate datagram, a sender
        // repeating itself) is dropped and counted as late: appended again, it would grow the
        // open frame without bound.
        {
            let seen = &self.open[idx].seen;
            let mut valid = packet
                .columns()
                .filter(|c| c.valid() && usize::from(c.measurement_id()) < w)
                .peekable();
            if valid.peek().is_some()
                && valid.all(|c| seen.get(usize::from(c.measurement_id())) == Some(&true))
            {
                self.stats.late += 1;
                return;
            }
        }
        // The earliest and latest valid columns of this packet.
        let mut first_ts = None::<u64>;
        let mut last_ts = None::<u64>;
        for c in packet
            .columns()
            .filter(|c| c.valid() && usize::from(c.measurement_id()) < w)
        {
            let t = c.timestamp_ns();
            first_ts = Some(first_ts.map_or(t, |f| f.min(t)));
            last_ts = Some(last_ts.map_or(t, |l| l.max(t)));
        }
        // The time between the packet's first and last valid columns, per column stepped: a
        // packet whose columns go back in time or span more than a second (a clock jump) says
        // nothing of the rate.
        let mut span = None::<((u16, u64), (u16, u64))>;
        for c in packet.columns().filter(|c| c.valid()) {
            let here = (c.measurement_id(), c.timestamp_ns());
            span = Some(span.map_or((here, here), |(first, _)| (first, here)));
        }
        if let Some(((m0, t0), (m1, t1))) = span {
            if m1 > m0 && t1 > t0 && t1 - t0 < 1_000_000_000 {
                // Saturating: a hostile stream of one-second spans must not wrap (or panic).
                self.column_span_ns = self.column_span_ns.saturating_add(t1 - t0);
                self.column_steps = self.column_steps.saturating_add(u64::from(m1 - m0));
            }
        }
        let opts = self.cfg.decode;
        let (keep_extras, keep_columns) = (self.cfg.keep_extras, self.cfg.keep_columns);
        let o = &mut self.open[idx];
        if let Some(ts) = last_ts {
            o.end_ns = o.end_ns.max(ts);
        }
        if let Some(ts) = first_ts {
            // Column timestamps are u64 on the wire: one beyond i64 saturates.
            let device_ns = i64::try_from(ts).unwrap_or(i64::MAX);
            if o.start_ns == u64::MAX {
                o.start_ns = ts;
                o.sweep.device_time_ns = device_ns;
                o.sweep.first_host_ns = host_ns;
            } else if ts < o.start_ns {
                let shift = (o.start_ns - ts).min(u64::from(u32::MAX)) as u32;
                for p in &mut o.sweep.points {
                    p.t = p.t.saturating_add(shift);
                }
                o.start_ns = ts;
                o.sweep.device_time_ns = device_ns;
                o.sweep.first_host_ns = o.sweep.first_host_ns.min(host_ns);
            }
        }
        let start = if o.start_ns == u64::MAX {
            0
        } else {
            o.start_ns
        };
        let before = o.sweep.points.len();
        let (points, extras, columns) = (
            &mut o.sweep.points,
            &mut o.sweep.extras,
            &mut o.sweep.columns,
        );
        let result = if opts == DecodeOptions::default() && !keep_extras {
            // Every point is kept: the decoder's own append loop (measured 2× faster).
            if keep_columns {
                self.decoder.decode_columns(packet, start, points, columns)
            } else {
                self.decoder.decode(packet, start, points)
            }
        } else {
            self.decoder
                .decode_with(packet, start, |pt, ex, _row, col| {
                    let r = ex.range_mm as f32 * 1e-3;
                    if !(r >= opts.min_range && r <= opts.max_range) {
                        return;
                    }
                    points.push(pt);
                    if keep_extras {
                        let [red, green, blue] = ex.rgb.map(half_to_f32);
                        extras.push(PointExtra {
                            range_mm: ex.range_mm,
                            signal: ex.signal,
                            near_ir: ex.near_ir,
                            zones: ex.zones,
                            pad: 0,
                            red,
                            green,
                            blue,
                        });
                    }
                    if keep_columns {
                        columns.push(col as u32);
                    }
                })
        };
        // Columns that were valid but had no return still arrived.
        for c in packet.columns() {
            let m = usize::from(c.measurement_id());
            if c.valid() && m < w {
                if let Some(s) = o.seen.get_mut(m) {
                    *s = true;
                }
            }
        }
        if result.is_err() {
            self.stats.malformed += 1;
            return;
        }
        o.sweep.packets += 1;
        o.sweep.last_host_ns = host_ns;
        self.stats.points += (o.sweep.points.len() - before) as u64;
        self.stats.lidar_packets += 1;
    }

    fn emit(&mut self, mut o: Open, on_sweep: &mut dyn FnMut(&mut Sweep, &OusterFacts)) {
        let info = &self.cfg.info;
        let in_window = (0..info.columns_per_frame).filter(|&c| info.is_column_in_window(c));
        let received = in_window
            .clone()
            .filter(|&c| o.seen.get(c).copied().unwrap_or(false))
            .count();
        let expected = info.columns_in_window();
        let in_frame = expected.saturating_sub(received) as u64;
        let cpp = info.format.columns_per_packet.max(1) as u64;
        let missing = in_frame.saturating_add(o.lost_columns);
        o.sweep.missing_columns = missing;
        o.sweep.missing_packets = in_frame.div_ceil(cpp).saturating_add(o.lost_packets);
        o.sweep.columns_count = received as u32;
        // Without a valid column the sweep has no sensor time (see `push_lidar`).
        o.sweep.clock = if o.start_ns == u64::MAX {
            ClockSource::Host
        } else {
            self.facts.clock
        };
        o.sweep.timestamp_ns = match o.sweep.clock {
            ClockSource::SensorPtp => o
                .sweep
                .device_time_ns
                .saturating_sub((TAI_MINUS_UTC_S * 1_000_000_000) as i64),
            _ => o.sweep.first_host_ns,
        };
        if o.sweep.packets > 0 && o.start_ns != u64::MAX {
            if let Some(slot) = self.recent.get_mut(self.recent_next) {
                *slot = Emitted {
                    frame_id: o.frame_id,
                    first_ns: o.start_ns,
                    last_ns: o.end_ns,
                    last_host_ns: o.sweep.last_host_ns,
                    used: true,
                };
            }
            self.recent_next = (self.recent_next + 1) % RECENT_FRAMES;
        }
        if o.sweep.packets > 0 {
            self.stats.sweeps += 1;
            self.stats.missing_columns += missing;
            on_sweep(&mut o.sweep, &self.facts);
        }
        self.spare.push(o);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::ouster::model::PacketFormat;
    use crate::sensor::ouster::model::Profile;
    use crate::sensor::ouster::sim::{OusterEncoder, SimColumn, SimHeader, SimPixel};

    #[test]
    fn tai_offset_is_37_seconds() {
        assert_eq!(super::TAI_MINUS_UTC_S, 37);
    }

    /// A new init_id changes what the decoder accepts, not the XYZ table: a sender
    /// alternating ids must not cost a new table (4 MiB at 128 × 1024) per packet.
    #[test]
    fn a_new_init_id_keeps_the_xyz_table() {
        let text = serde_json::json!({
            "beam_altitude_angles": (0..16).map(|u| 15.0 - 2.0 * f64::from(u)).collect::<Vec<_>>(),
            "beam_azimuth_angles": vec![0.0; 16],
            "lidar_mode": "512x10",
            "data_format": {
                "pixels_per_column": 16,
                "columns_per_packet": 16,
                "columns_per_frame": 512,
            },
        })
        .to_string();
        let mut info = crate::sensor::ouster::calib::parse(&text, "t.json").unwrap();
        info.format = PacketFormat {
            profile: Profile::Rng19Rfl8Sig16Nir16,
            columns_per_packet: 16,
            pixels_per_column: 16,
        };
        info.pixel_shift_by_row = vec![0; 16];
        info.serial = 992_210_000_957;
        info.init_id = 77;
        info.firmware = "v2.5.2".into();
        let enc = OusterEncoder::new(&info);
        let mut s = OusterStream::new(OusterStreamConfig {
            info: info.clone(),
            metadata_name: "t.json".into(),
            crc: None,
            decode: DecodeOptions::default(),
            keep_extras: false,
            keep_columns: false,
        })
        .unwrap();
        let before = s.decoder().clone();
        let cols: Vec<SimColumn> = (0..16)
            .map(|m| SimColumn {
                timestamp_ns: 1_000 + m,
                measurement_id: m as u16,
                status: 1,
                pixels: vec![
                    SimPixel {
                        range_mm: 5000,
                        ..SimPixel::default()
                    };
                    16
                ],
            })
            .collect();
        for (frame, init_id) in [(1, 78), (2, 79), (3, 78)] {
            let h = SimHeader {
                frame_id: frame,
                init_id,
                serial: info.serial,
                ..SimHeader::default()
            };
            let mut p = Vec::new();
            enc.encode(&h, &cols, &mut p).unwrap();
            s.push(0, &p, &mut |_, _| {});
        }
        assert_eq!((s.stats().epochs, s.stats().lidar_packets), (3, 3));
        assert_eq!(s.decoder().init_id(), 78);
        assert!(s.decoder().crc_check());
        assert!(s.decoder().shares_table_with(&before));
    }
}
