//! Sensor families, and the one small interface through which the rest of ringscan uses them.
//!
//! A family is one folder holding its whole data flow: packet views (`wire`), model facts
//! (`model`), calibration formats (`calib`), decoder (`decode`), sweep rules (`sweep`) and
//! packet encoder (`sim`). What the demultiplexer, the sources, the command line and the sinks
//! need of it is this module's three traits:
//!
//! - [`Family`]: reads the family's calibration files ([`Family::parse_calibration`]) and
//!   decides from a new sensor's first datagram (its bytes and destination port) whether the
//!   sensor is one of its own, building its stream ([`Family::claim`]);
//! - [`SensorStream`]: one sensor's datagrams in ([`SensorStream::push`]), sweeps out, with
//!   counters ([`SensorStream::summary`]) and IMU samples where the sensor has an IMU;
//! - [`Facts`]: what a stream knows of its sensor, in words every sink can write (a default
//!   name, the calibration used, channel metadata, per-sweep diagnostics).
//!
//! [`FAMILIES`] lists them in the order they are asked; adding a family is one folder and one
//! line there. Nothing here performs I/O or reads a clock.

pub mod calib;
pub mod decode;
pub mod hesai;
pub mod livox;
pub mod nmea;
pub mod ouster;
pub mod robosense;
pub mod velodyne;
pub mod wire;

use std::any::Any;
use std::collections::BTreeMap;
use std::net::Ipv4Addr;
use std::sync::Arc;

pub use calib::{CalibError, MAX_CALIB_BYTES};
pub use decode::{DecodeError, DecodeOptions, StreamError};
pub use ouster::sweep::ImuSample;
pub use ouster::sweep::ZoneReport;
pub use wire::WireError;

use crate::sweep::Sweep;

/// The families ringscan decodes, in the order a new sensor is offered to them: a family whose
/// packets can be told only with its calibration (Ouster: size, serial and init_id from the
/// metadata) comes before one that claims by size alone (Velodyne). Hesai, whose sensors also
/// send to port 2368 and whose packets are told by their own marks and sizes, comes before
/// Velodyne too — also because Velodyne's calibration parsers take any text, while Hesai's
/// recognise their CSV by its header line. Robosense (1248-byte packets with their own ids; an
/// angle CSV recognised by its rows of numbers) comes before Velodyne for the same reason, and
/// Livox (its own header: version byte, length field matching the datagram, data type) too.
pub static FAMILIES: &[&dyn Family] = &[
    &ouster::family::Ouster,
    &hesai::family::Hesai,
    &robosense::family::Robosense,
    &livox::family::Livox,
    &velodyne::family::Velodyne,
];

/// The family named `name` (`"velodyne"`, `"ouster"`, `"hesai"`, `"robosense"`, `"livox"`).
pub fn family(name: &str) -> Option<&'static dyn Family> {
    FAMILIES.iter().copied().find(|f| f.name() == name)
}

/// The family one of whose models is called `model` (as `--model` spells it).
pub fn family_of_model(model: &str) -> Option<&'static dyn Family> {
    FAMILIES
        .iter()
        .copied()
        .find(|f| f.models().contains(&model))
}

/// Offers a new sensor's first datagram to every family in [`FAMILIES`] order: the stream of
/// the first that claims it, or `None` when none does (other traffic). With `--model` set, only
/// the family of that model may claim a sensor by size alone.
pub fn claim(d: &FirstDatagram<'_>, pool: &mut CalibrationPool) -> Option<Claimed> {
    FAMILIES.iter().find_map(|f| f.claim(d, pool))
}

/// Whether some family says `payload` is data a driver decoded, not a packet
/// ([`Family::is_decoded_frame`]).
pub fn is_decoded_frame(payload: &[u8]) -> bool {
    FAMILIES.iter().any(|f| f.is_decoded_frame(payload))
}

/// Reads a calibration file with the first family that recognises its format.
pub fn parse_calibration(
    bytes: &[u8],
    file_name: &str,
    addr: Option<Ipv4Addr>,
) -> Result<Calibration, CalibError> {
    calib::check_size(bytes.len())?;
    for f in FAMILIES {
        if let Some(parsed) = f.parse_calibration(bytes, file_name) {
            return Ok(Calibration {
                family: f.name(),
                addr,
                file_name: file_name.to_string(),
                bytes: Arc::from(bytes),
                parsed: parsed?,
            });
        }
    }
    Err(CalibError::UnknownFormat(format!(
        "{file_name}: not a calibration file of any supported sensor"
    )))
}

/// One sensor family.
pub trait Family: Sync {
    /// Its name, lower case (`"velodyne"`): the `kind` of summaries.
    fn name(&self) -> &'static str;

    /// The model names `--model` accepts for it.
    fn models(&self) -> &'static [&'static str];

    /// Parses `bytes` if they are in one of the family's calibration formats; `None` when they
    /// are not (another family may read them). The value is the family's own table, read back
    /// by its [`Family::claim`].
    fn parse_calibration(
        &self,
        bytes: &[u8],
        file_name: &str,
    ) -> Option<Result<Arc<dyn Any + Send + Sync>, CalibError>>;

    /// The UDP ports its sensors send to by default.
    fn default_ports(&self) -> &'static [u16];

    /// The UDP ports a sensor described by calibration `c` sends to, when the calibration
    /// says (Ouster metadata does); empty otherwise.
    fn calibration_ports(&self, _c: &Calibration) -> Vec<u16> {
        Vec::new()
    }

    /// Payload sizes of the datagrams that start one of its sensors, given the calibrations
    /// (used to count sensors in a capture before decoding it).
    fn lidar_sizes(&self, calibs: &[Calibration]) -> Vec<usize>;

    /// Whether `payload` starts one of its sensors though its length is in no list: a length
    /// the packet's own header gives (the Hesai ATX). Counted like [`Self::lidar_sizes`].
    fn is_header_sized_lidar(&self, _payload: &[u8]) -> bool {
        false
    }

    /// The stream for a new sensor if its first datagram is the family's; `None` leaves the
    /// datagram to the next family. An error is a sensor the family recognised but cannot
    /// decode with what it was given.
    fn claim(&self, datagram: &FirstDatagram<'_>, pool: &mut CalibrationPool) -> Option<Claimed>;

    /// Whether `--port` selects its sensors' packets (they are told by the port they go to);
    /// a family told by its calibration instead (Ouster's metadata) says no.
    fn selected_by_port(&self) -> bool {
        true
    }

    /// Whether `payload` is not a packet but data a ROS driver decoded already, handed on by
    /// a bag source in a layout of the family's own (Livox `CustomMsg` points and IMU samples):
    /// it was never on the wire, so `replay` does not send it.
    fn is_decoded_frame(&self, _payload: &[u8]) -> bool {
        false
    }

    /// The lines `ringscan info` prints for one of its sensors, from the sensor's entry in the
    /// summary ([`SensorStream::summary`]). The family words them because only it knows which
    /// of its facts matter; this default prints what every summary has.
    fn describe(&self, sensor: &serde_json::Value) -> Vec<String> {
        let s = |k: &str| summary_str(&sensor[k]);
        let n = |k: &str| sensor[k].as_u64().unwrap_or(0);
        vec![
            format!(
                "  {}, ports {}: {} {}, {}",
                crate::sensor::heading(sensor),
                sensor["ports"],
                s("kind"),
                s("model"),
                s("return_mode")
            ),
            format!(
                "    {} sweeps, {} points; missing {}, malformed {}",
                n("sweeps"),
                n("points"),
                n("missing"),
                n("malformed")
            ),
            format!("    packets per port: {}", sensor["packets_per_port"]),
            format!(
                "    calibration: {}; clock: {}",
                s("calibration"),
                s("clock")
            ),
        ]
    }
}

/// How `info` names a sensor: `sensor NAME (ADDRESS)`, or `sensor ADDRESS` for one that has
/// no name (a sensor is named when its first sweep is written, so one that decoded nothing
/// has none).
pub fn heading(sensor: &serde_json::Value) -> String {
    let addr = summary_str(&sensor["address"]);
    match sensor["name"].as_str() {
        Some(name) => format!("sensor {name} ({addr})"),
        None => format!("sensor {addr}"),
    }
}

/// A summary field as `info` prints it: its text, or `-` when it has none or an empty one.
pub fn summary_str(v: &serde_json::Value) -> &str {
    v.as_str().filter(|s| !s.is_empty()).unwrap_or("-")
}

/// What [`Family::claim`] returns: a stream, or why the family's sensor cannot be decoded.
pub type Claimed = Result<Box<dyn SensorStream>, StreamError>;

/// A new sensor's first datagram.
#[derive(Clone, Copy, Debug)]
pub struct FirstDatagram<'a> {
    /// Its source address (the sensor).
    pub src: Ipv4Addr,
    /// Its destination port.
    pub port: u16,
    /// The UDP payload.
    pub payload: &'a [u8],
}

/// A calibration file, read and checked.
#[derive(Clone)]
pub struct Calibration {
    /// The family that read it.
    pub family: &'static str,
    /// The sensor it is bound to (`--calib ADDR=FILE`), or any.
    pub addr: Option<Ipv4Addr>,
    /// File name, as summaries and MCAP channel metadata name it.
    pub file_name: String,
    /// The file's bytes (attached to MCAP output).
    pub bytes: Arc<[u8]>,
    /// The family's parsed table.
    pub parsed: Arc<dyn Any + Send + Sync>,
}

impl core::fmt::Debug for Calibration {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Calibration")
            .field("family", &self.family)
            .field("addr", &self.addr)
            .field("file_name", &self.file_name)
            .finish()
    }
}

impl Calibration {
    /// The family's table, if it is of type `T`.
    pub fn get<T: 'static>(&self) -> Option<&T> {
        self.parsed.downcast_ref::<T>()
    }
}

/// Settings every new stream gets, whatever its family.
#[derive(Clone, Debug, Default)]
pub struct StreamSettings {
    /// `--model`: the model named by the user (wins over detection), as its family spells it.
    pub model: Option<String>,
    /// Range filter.
    pub decode: DecodeOptions,
    /// Sweep cut angle, 0.01° (0..36000), for spinning sensors that cut by azimuth.
    pub cut_angle: u16,
    /// Keep the extra per-point fields the family has (`--fields all`).
    pub keep_extras: bool,
    /// Keep each point's firing column (for [`crate::sweep::Organized`]).
    pub keep_columns: bool,
    /// Packet checksum checks: `None` = the family's rule, `Some(on)` forces them.
    pub crc: Option<bool>,
    /// Multi-return sensors that send each return in a block of its own (Hesai): drop a return
    /// that is not its firing's last when within this distance (m) of another (nebula's
    /// `dual_return_distance_threshold`). `None`: only identical returns are merged.
    pub dual_return_threshold_m: Option<f32>,
    /// Keep only points whose corrected azimuth lies in (start, end), 0.01°, clockwise
    /// (Hesai; `--fov`).
    pub fov_cdeg: Option<(u32, u32)>,
    /// Integration period of sensors that do not spin (Livox), ns: a sweep per period.
    /// `None`: the family's default (100 ms).
    pub integration_ns: Option<u64>,
    /// IMU-to-sensor transform (row-major 4 × 4, mm) overriding the one the family
    /// publishes per model (Livox).
    pub imu_to_sensor: Option<[f64; 16]>,
    /// Only inspecting the input (`ringscan info`): a sensor whose points need a calibration
    /// it was not given (VLS-128, a Hesai sensor without its angle correction) is still read — model, return mode, clock, loss — instead of
    /// stopping the run.
    pub inspect: bool,
}

/// How a sensor summary names a model no data packet told (every datagram it sent went
/// elsewhere, e.g. to another port than `--port`, or it sent only position packets).
pub const UNKNOWN_MODEL: &str = "model unknown (no data packet decoded)";

/// The calibrations given for a run, and which of them already serve a sensor: a file not
/// bound to an address serves the first sensor it fits (a family may let one file serve
/// several, as Velodyne's tables do).
#[derive(Clone, Debug, Default)]
pub struct CalibrationPool {
    calibs: Vec<Calibration>,
    used: Vec<bool>,
    /// Settings for every new stream.
    pub settings: StreamSettings,
}

impl CalibrationPool {
    /// A pool of `calibs` with `settings`.
    pub fn new(calibs: Vec<Calibration>, settings: StreamSettings) -> Self {
        let used = vec![false; calibs.len()];
        Self {
            calibs,
            used,
            settings,
        }
    }

    /// Adds a calibration after the start (metadata fetched from a live sensor); it serves
    /// sensors first seen from now on.
    pub fn add(&mut self, c: Calibration) {
        self.calibs.push(c);
        self.used.push(false);
    }

    /// Every calibration.
    pub fn all(&self) -> &[Calibration] {
        &self.calibs
    }

    /// The calibrations of `family` that may serve a sensor at `src`, with their index: bound
    /// to that address, or unbound and (when `unused`) not yet serving a sensor.
    pub fn candidates<'a>(
        &'a self,
        family: &'a str,
        src: Ipv4Addr,
        unused: bool,
    ) -> impl Iterator<Item = (usize, &'a Calibration)> + 'a {
        self.calibs.iter().enumerate().filter(move |(i, c)| {
            c.family == family
                && match c.addr {
                    Some(a) => a == src,
                    None => !(unused && self.used[*i]),
                }
        })
    }

    /// Marks calibration `idx` as serving a sensor.
    pub fn mark_used(&mut self, idx: usize) {
        if let Some(u) = self.used.get_mut(idx) {
            *u = true;
        }
    }
}

/// Packet counts of one sensor, in the terms every family shares (the run's totals).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PacketCounts {
    /// Packets decoded.
    pub decoded: u64,
    /// Packets that are not well-formed (including failed checksums): counted and skipped.
    pub malformed: u64,
    /// Packets missing (sequence or device-time gaps).
    pub missing: u64,
    /// Auxiliary packets (Velodyne position packets).
    pub position: u64,
    /// Packets dropped for another reason (another sensor's, too late, queue full).
    pub dropped: u64,
}

/// What a stream knows of its sensor, in terms every sink can write.
pub trait Facts {
    /// The family's name.
    fn family(&self) -> &'static str;

    /// The sensor's default name: `<model>-<serial, else the last octet of its address>`.
    fn default_name(&self, addr: Ipv4Addr) -> String;

    /// The calibration in use, as shown: its file name, or the built-in table's name; several
    /// files serving one sensor are joined by ` + `, the main one first.
    fn calibration_name(&self) -> &str;

    /// The files the calibration was read from, the main one first (Hesai ATX: its angle
    /// correction and its firetimes); by default the one [`Self::calibration_name`] names.
    fn calibration_files(&self) -> Vec<&str> {
        match self.calibration_name() {
            "" => Vec::new(),
            n => vec![n],
        }
    }

    /// Adds the family's channel metadata (model, serial, firmware, profile, clock, …).
    fn channel_metadata(&self, md: &mut BTreeMap<String, String>);

    /// Adds the family's fields to a sweep's diagnostics (clock health, alerts).
    fn diagnostics(&self, out: &mut serde_json::Map<String, serde_json::Value>);

    /// The family's own facts type, for callers that need what only that family has.
    fn as_any(&self) -> &dyn Any;
}

/// Called with each finished sweep and the facts of its sensor. The sweep is lent mutably so
/// that a consumer that keeps it can move its buffers out ([`Sweep::take_buffers`]) instead of
/// copying them: a stream reads nothing of a sweep after handing it out, and clears it before
/// reusing it.
pub type OnSweep<'a> = dyn FnMut(&mut Sweep, &dyn Facts) + 'a;

/// One sensor's stream: its datagrams in, sweeps out.
pub trait SensorStream: Send + core::fmt::Debug {
    /// Pushes one UDP payload from this sensor (host receive time in ns); finished sweeps go
    /// to `on_sweep`. A malformed datagram is counted, not an error; an error means the stream
    /// cannot decode at all (its model cannot be told, a calibration does not fit).
    fn push(
        &mut self,
        host_ns: i64,
        payload: &[u8],
        on_sweep: &mut OnSweep<'_>,
    ) -> Result<(), StreamError>;

    /// Emits the sweeps still open, at the end of the input.
    fn finish(&mut self, on_sweep: &mut OnSweep<'_>) -> Result<(), StreamError>;

    /// Whether the stream knows how to decode (Velodyne: once its model is detected).
    fn ready(&self) -> bool;

    /// What is known of the sensor.
    fn facts(&self) -> &dyn Facts;

    /// The sensor's summary (`info` and `--json`): family-specific fields with `kind` = the
    /// family's name, and the counts of the run's totals.
    fn summary(&self) -> (serde_json::Value, PacketCounts);

    /// Whether `payload` is one of the sensor's main (point) datagrams: `--port` filters those.
    fn is_lidar_datagram(&self, payload: &[u8]) -> bool;

    /// Rows of an organised image of its sweeps (the channel count), once known.
    fn channels(&self) -> Option<usize>;

    /// Hands the IMU samples decoded since the last call to `out`, with the IMU-to-sensor
    /// transform (row-major 4 × 4, mm); sensors without an IMU have none.
    fn drain_imu(&mut self, _out: &mut dyn FnMut(&ImuSample, &[f64; 16])) {}

    /// Hands the zone-monitor reports decoded since the last call to `out` (sensors that
    /// judge zones themselves: Ouster FW 3.2+); others have none.
    fn drain_zones(&mut self, _out: &mut dyn FnMut(&ZoneReport)) {}

    /// Times the sensor re-initialised (a new configuration epoch), so that a live source can
    /// read its calibration again.
    fn epochs(&self) -> u64 {
        0
    }

    /// The family's own stream type, for callers that need what only that family has.
    fn as_any(&self) -> &dyn Any;
}
