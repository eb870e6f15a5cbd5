//! What the command line knows per sensor kind: calibration files, which configuration a new
//! source address gets, channel metadata and summary fields.

use std::collections::BTreeMap;
use std::net::Ipv4Addr;
use std::path::Path;

use ringscan::calib::ouster::{parse as parse_ouster, OusterInfo};
use ringscan::calib::{parse_velodyne, VelodyneCalibration, MAX_CALIB_BYTES};
use ringscan::decode::ouster::OusterDecoder;
use ringscan::decode::DecodeOptions;
use ringscan::model::velodyne::{DATA_PACKET_LEN, POSITION_PACKET_LEN};
use ringscan::model::VelodyneModel;
use ringscan::sweep::{Facts, OusterStreamConfig, SensorConfig, SensorStream, StreamConfig};
use ringscan::wire::ouster::LidarPacket;
use serde_json::{json, Value};

use super::run::RunError;

/// A calibration given with `--calib`.
pub enum CalibKind {
    /// A Velodyne laser table.
    Velodyne(VelodyneCalibration),
    /// Ouster sensor metadata.
    Ouster(Box<OusterInfo>),
}

/// One `--calib [ADDR=]FILE`.
pub struct CalibSpec {
    pub addr: Option<Ipv4Addr>,
    pub file_name: String,
    pub bytes: Vec<u8>,
    pub kind: CalibKind,
}

/// Reads and validates every `--calib`: Ouster metadata (JSON) or a Velodyne table (yaml / xml).
pub fn load_calibs(list: &[String]) -> Result<Vec<CalibSpec>, RunError> {
    let mut out = Vec::new();
    for item in list {
        let (addr, path) = match item.split_once('=') {
            Some((a, p)) => match a.parse::<Ipv4Addr>() {
                Ok(ip) => (Some(ip), p),
                Err(_) => {
                    return Err(RunError::Usage(format!(
                        "--calib {item}: `{a}` is not an IPv4 address"
                    )))
                }
            },
            None => (None, item.as_str()),
        };
        let cerr = |msg: String| RunError::Calib {
            path: path.to_string(),
            msg,
        };
        let meta = std::fs::metadata(path).map_err(|e| cerr(e.to_string()))?;
        if meta.len() > MAX_CALIB_BYTES as u64 {
            return Err(cerr(format!(
                "{} bytes; refusing anything over {MAX_CALIB_BYTES} bytes",
                meta.len()
            )));
        }
        let bytes = std::fs::read(path).map_err(|e| cerr(e.to_string()))?;
        let text = std::str::from_utf8(&bytes)
            .map_err(|e| cerr(format!("not UTF-8 text (byte {})", e.valid_up_to())))?;
        let file_name = Path::new(path)
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if text
            .trim_start_matches('\u{feff}')
            .trim_start()
            .starts_with('{')
        {
            out.push(ouster_calib(addr, file_name, bytes).map_err(cerr)?);
            continue;
        }
        let kind =
            CalibKind::Velodyne(parse_velodyne(text, &file_name).map_err(|e| cerr(e.to_string()))?);
        out.push(CalibSpec {
            addr,
            file_name,
            bytes,
            kind,
        });
    }
    Ok(out)
}

/// Ouster metadata JSON (a `--calib` file, or the metadata a bag holds) as a calibration.
pub fn ouster_calib(
    addr: Option<Ipv4Addr>,
    file_name: String,
    bytes: Vec<u8>,
) -> Result<CalibSpec, String> {
    let text = std::str::from_utf8(&bytes)
        .map_err(|e| format!("not UTF-8 text (byte {})", e.valid_up_to()))?;
    let info = parse_ouster(text, &file_name).map_err(|e| e.to_string())?;
    // The decoder's own checks (beam tables, transforms) before anything is written.
    OusterDecoder::new(&info).map_err(|e| e.to_string())?;
    Ok(CalibSpec {
        addr,
        file_name,
        bytes,
        kind: CalibKind::Ouster(Box::new(info)),
    })
}

/// Settings shared by every new sensor.
#[derive(Clone)]
pub struct Common {
    pub model: Option<VelodyneModel>,
    pub decode: DecodeOptions,
    pub cut_angle: u16,
    /// `--fields all`: keep range, signal and near-IR per point (Ouster).
    pub keep_extras: bool,
    /// `--crc`: `None` = the firmware rule.
    pub crc: Option<bool>,
}

/// Chooses the configuration of a new source address from its first datagram.
pub struct Chooser {
    velodyne: Vec<(Option<Ipv4Addr>, VelodyneCalibration)>,
    ouster: Vec<(Option<Ipv4Addr>, String, OusterInfo, OusterDecoder)>,
    used: Vec<bool>,
    common: Common,
}

impl Chooser {
    pub fn new(calibs: &[CalibSpec], common: Common) -> Self {
        let mut velodyne = Vec::new();
        let mut ouster = Vec::new();
        for c in calibs {
            match &c.kind {
                CalibKind::Velodyne(v) => velodyne.push((c.addr, v.clone())),
                CalibKind::Ouster(info) => {
                    if let Ok(d) = OusterDecoder::new(info) {
                        ouster.push((c.addr, c.file_name.clone(), (**info).clone(), d));
                    }
                }
            }
        }
        let used = vec![false; ouster.len()];
        Self {
            velodyne,
            ouster,
            used,
            common,
        }
    }

    /// Adds a calibration after the start (Ouster metadata fetched from a sensor); it serves
    /// sensors first seen from now on.
    pub fn add(&mut self, c: &CalibSpec) {
        match &c.kind {
            CalibKind::Velodyne(v) => self.velodyne.push((c.addr, v.clone())),
            CalibKind::Ouster(info) => {
                if let Ok(d) = OusterDecoder::new(info) {
                    self.ouster
                        .push((c.addr, c.file_name.clone(), (**info).clone(), d));
                    self.used.push(false);
                }
            }
        }
    }

    /// Payload sizes that start a sensor's main stream (Velodyne data, each Ouster lidar size).
    pub fn lidar_sizes(&self) -> Vec<usize> {
        let mut v = vec![DATA_PACKET_LEN];
        v.extend(
            self.ouster
                .iter()
                .map(|(_, _, i, _)| i.lidar_packet_bytes()),
        );
        v
    }

    /// The configuration for a new sensor at `src` whose first datagram is `payload` to `port`.
    ///
    /// Ouster metadata is matched first: a lidar packet of the metadata's size whose serial and
    /// init_id fit (profile-based packets), or whose destination port is the metadata's lidar
    /// port (LEGACY packets carry no serial); an IMU-only sensor (lidar port 0) by its IMU
    /// packet size and port. Each metadata file serves one sensor, unless bound to an address.
    /// Velodyne-sized datagrams (1206 / 512 bytes) get a Velodyne stream.
    pub fn choose(&mut self, src: Ipv4Addr, port: u16, payload: &[u8]) -> Option<SensorConfig> {
        for (i, (addr, name, info, dec)) in self.ouster.iter().enumerate() {
            if addr.is_some_and(|a| a != src) || (addr.is_none() && self.used[i]) {
                continue;
            }
            let lidar = payload.len() == info.lidar_packet_bytes() && info.udp_port_lidar != 0 && {
                match LidarPacket::with_header(payload, &info.format, dec.header_kind()) {
                    Ok(p) => {
                        if info.format.profile.header()
                            == ringscan::model::ouster::HeaderKind::Legacy
                        {
                            port == info.udp_port_lidar
                        } else {
                            dec.check_sensor(&p).is_ok()
                                && (info.serial == 0 || p.serial() == info.serial)
                        }
                    }
                    Err(_) => false,
                }
            };
            let imu_only = info.udp_port_lidar == 0
                && info.udp_port_imu == port
                && OusterStreamConfig::imu_len_of(info) == Some(payload.len());
            if lidar || imu_only {
                self.used[i] = true;
                return Some(SensorConfig::Ouster(Box::new(OusterStreamConfig {
                    info: info.clone(),
                    metadata_name: name.clone(),
                    crc: self.common.crc,
                    decode: self.common.decode,
                    keep_extras: self.common.keep_extras,
                    keep_columns: false,
                })));
            }
        }
        if matches!(payload.len(), DATA_PACKET_LEN | POSITION_PACKET_LEN) {
            return Some(SensorConfig::Velodyne(StreamConfig {
                model: self.common.model,
                calibrations: self
                    .velodyne
                    .iter()
                    .filter(|(a, _)| a.is_none() || *a == Some(src))
                    .map(|(_, c)| c.clone())
                    .collect(),
                decode: self.common.decode,
                cut_angle: self.common.cut_angle,
                ..StreamConfig::default()
            }));
        }
        None
    }
}

/// The default name of a sensor: `<model>-<serial, else the last octet of its address>`.
pub fn default_name(facts: Facts<'_>, addr: Ipv4Addr) -> String {
    match facts {
        Facts::Velodyne(f) => match f.model {
            Some(m) => format!("{}-{}", m.id(), addr.octets()[3]),
            None => format!("velodyne-{}", addr.octets()[3]),
        },
        Facts::Ouster(f) => {
            let model = if f.prod_line.is_empty() {
                "ouster".to_string()
            } else {
                f.prod_line.to_ascii_lowercase()
            };
            if f.serial != 0 {
                format!("{model}-{}", f.serial)
            } else {
                format!("{model}-{}", addr.octets()[3])
            }
        }
    }
}

/// The calibration file a sensor uses, by the name its stream reports.
pub fn calibration_name(facts: Facts<'_>) -> String {
    match facts {
        Facts::Velodyne(f) => f.calibration.clone(),
        Facts::Ouster(f) => f.metadata.clone(),
    }
}

/// MCAP channel metadata of a sensor.
pub fn channel_metadata(
    facts: Facts<'_>,
    addr: Ipv4Addr,
    ports: &[u16],
) -> BTreeMap<String, String> {
    let mut md = BTreeMap::new();
    let mut put = |k: &str, v: String| {
        md.insert(k.to_string(), v);
    };
    put("source_address", addr.to_string());
    put(
        "ports",
        ports
            .iter()
            .map(|p| p.to_string())
            .collect::<Vec<_>>()
            .join(","),
    );
    put("driver", format!("ringscan {}", env!("CARGO_PKG_VERSION")));
    match facts {
        Facts::Velodyne(f) => {
            put(
                "model",
                f.model.map(|m| m.name().to_string()).unwrap_or_default(),
            );
            put(
                "return_mode",
                f.mode.map(|m| m.name().to_string()).unwrap_or_default(),
            );
            put(
                "product_id",
                f.product_id
                    .map(|p| format!("{p:#04x}"))
                    .unwrap_or_default(),
            );
            put("model_detection", f.detection.clone());
            put("clock", f.clock.name().to_string());
            put("calibration", f.calibration.clone());
            put("serial", String::new());
            put("firmware", String::new());
            put("profile", String::new());
        }
        Facts::Ouster(f) => {
            put("model", f.prod_line.clone());
            put("serial", f.serial.to_string());
            put("firmware", f.firmware.clone());
            put("profile", f.profile.clone());
            put("lidar_mode", f.mode.clone());
            put("init_id", f.init_id.to_string());
            put("clock", f.clock.name().to_string());
            put("calibration", f.metadata.clone());
            put("crc_checked", f.crc_checked.to_string());
        }
    }
    md
}

/// Fields of the per-sweep diagnostics that depend on the sensor kind.
pub fn diagnostics_extra(facts: Facts<'_>) -> Value {
    match facts {
        Facts::Velodyne(f) => json!({ "pps": f.pps.map(|p| p.name()) }),
        Facts::Ouster(f) => json!({
            "shot_limiting": ringscan::wire::ouster::shot_limiting_name(f.shot_limiting),
            "thermal_shutdown": ringscan::wire::ouster::thermal_shutdown_name(f.thermal_shutdown),
            "init_id": f.init_id,
        }),
    }
}

/// Packet counts of one sensor, for the run's totals.
#[derive(Default)]
pub struct Counts {
    pub decoded: u64,
    pub malformed: u64,
    pub missing: u64,
    pub position: u64,
    pub dropped: u64,
}

/// The summary object of one sensor (merged with name, address, ports and topic by the caller).
pub fn sensor_summary(stream: &SensorStream) -> (Value, Counts) {
    match stream {
        SensorStream::Velodyne(s) => {
            let (st, f) = (s.stats(), s.facts());
            let counts = Counts {
                decoded: st.data_packets,
                malformed: st.malformed,
                missing: st.missing,
                position: st.position_packets,
                dropped: 0,
            };
            let v = json!({
                "kind": "velodyne",
                "model": f.model.map(|m| m.name()),
                "model_id": f.model.map(|m| m.id()),
                "return_mode": f.mode.map(|m| m.name()),
                "product_id": f.product_id.map(|p| format!("{p:#04x}")),
                "detection": f.detection,
                "packet_period_us": f.period_us,
                "calibration": f.calibration,
                "clock": f.clock.name(),
                "pps": f.pps.map(|p| p.name()),
                "telemetry": f.telemetry.map(|t| json!({
                    "temp_top_c": t.temp_top_c,
                    "temp_bottom_c": t.temp_bottom_c,
                    "temp_at_adc_calibration_c": t.temp_at_adc_calibration_c,
                    "temp_change_since_adc_calibration": t.temp_change_since_adc_calibration,
                    "seconds_since_adc_calibration": t.seconds_since_adc_calibration,
                    "adc_calibration_reason": t.adc_calibration_reason,
                    "adc_calibration_flags": t.adc_calibration_flags,
                    "thermal_shutdown": t.thermal_shutdown,
                    "temp_at_shutdown_c": t.temp_at_shutdown_c,
                    "temp_at_power_up_c": t.temp_at_power_up_c,
                })),
                "gps": f.last_rmc.map(|r| json!({"utc_ns": r.utc_ns, "valid": r.valid, "lat_deg": r.lat_deg, "lon_deg": r.lon_deg})),
                "nmea_empty": f.empty_nmea,
                "nmea_bad": f.bad_nmea,
                "data_packets": st.data_packets,
                "position_packets": st.position_packets,
                "malformed": st.malformed,
                "missing": st.missing,
                "discontinuities": st.discontinuities,
                "sweeps": st.sweeps,
                "points": st.points,
            });
            (v, counts)
        }
        SensorStream::Ouster(s) => {
            let (st, f, info) = (s.stats(), s.facts(), s.info());
            let counts = Counts {
                decoded: st.lidar_packets + st.imu_packets,
                malformed: st.malformed + st.crc_failures,
                missing: st
                    .missing_columns
                    .div_ceil(info.format.columns_per_packet.max(1) as u64),
                position: 0,
                dropped: st.wrong_sensor + st.late + st.imu_dropped,
            };
            let v = json!({
                "kind": "ouster",
                "model": f.prod_line,
                "serial": f.serial,
                "firmware": f.firmware,
                "profile": f.profile,
                "lidar_mode": f.mode,
                "columns_per_frame": info.columns_per_frame,
                "pixels_per_column": info.format.pixels_per_column,
                "column_window": [info.column_window.0, info.column_window.1],
                "timestamp_mode": format!("{:?}", info.timestamp_mode),
                "init_id": f.init_id,
                "calibration": f.metadata,
                "clock": f.clock.name(),
                "crc_checked": f.crc_checked,
                "shot_limiting": ringscan::wire::ouster::shot_limiting_name(f.shot_limiting),
                "thermal_shutdown": ringscan::wire::ouster::thermal_shutdown_name(f.thermal_shutdown),
                "lidar_packets": st.lidar_packets,
                "imu_packets": st.imu_packets,
                "malformed": st.malformed,
                "crc_failures": st.crc_failures,
                "wrong_sensor": st.wrong_sensor,
                "late": st.late,
                "epochs": st.epochs,
                "missing_columns": st.missing_columns,
                "missing": counts.missing,
                "sweeps": st.sweeps,
                "points": st.points,
                "imu_dropped": st.imu_dropped,
            });
            (v, counts)
        }
    }
}
