//! The Ouster family behind ringscan's sensor interface ([`crate::sensor`]).

use std::any::Any;
use std::collections::BTreeMap;
use std::net::Ipv4Addr;
use std::sync::Arc;

use serde_json::{json, Map, Value};

use super::calib::{parse, OusterInfo};
use super::decode::OusterDecoder;
use super::model::HeaderKind;
use super::sweep::{OusterFacts, OusterStream, OusterStreamConfig};
use super::wire::{
    shot_limiting_name, thermal_shutdown_name, LidarPacket, ZonePacket, PACKET_TYPE_ZONE,
};
use crate::sensor::{
    summary_str, CalibError, Calibration, CalibrationPool, Claimed, Facts, Family, FirstDatagram,
    ImuSample, OnSweep, PacketCounts, SensorStream, StreamError, ZoneReport,
};

/// The Ouster family.
#[derive(Clone, Copy, Debug, Default)]
pub struct Ouster;

/// A sensor's metadata with the decoder it makes (built once, when the file is read: the
/// decoder checks the beam tables and transforms, and tells packets of this sensor apart).
#[derive(Debug)]
pub struct OusterCalibration {
    /// The metadata.
    pub info: OusterInfo,
    /// Its decoder.
    pub decoder: OusterDecoder,
}

impl OusterCalibration {
    /// Reads a metadata JSON text and builds its decoder.
    pub fn parse(text: &str, file_name: &str) -> Result<Self, CalibError> {
        let info = parse(text, file_name)?;
        let decoder = OusterDecoder::new(&info).map_err(|e| CalibError::Invalid(e.to_string()))?;
        Ok(Self { info, decoder })
    }

    /// Whether a sensor whose first datagram is `d` is the one this metadata describes: a
    /// lidar packet of the metadata's size whose serial and init_id fit (profile-based
    /// packets), or whose destination port is the metadata's lidar port (LEGACY packets carry
    /// no serial; a file `bound` to the sender's address needs no port: the user named the
    /// sensor, and its packets may come through a port offset); an IMU-only sensor (lidar port
    /// 0) by its IMU packet size and port.
    pub fn fits(&self, d: &FirstDatagram<'_>, bound: bool) -> bool {
        let info = &self.info;
        let lidar = d.payload.len() == info.lidar_packet_bytes()
            && info.udp_port_lidar != 0
            && match LidarPacket::with_header(d.payload, &info.format, self.decoder.header_kind()) {
                Ok(p) => {
                    if info.format.profile.header() == HeaderKind::Legacy {
                        bound || d.port == info.udp_port_lidar
                    } else {
                        self.decoder.check_sensor(&p).is_ok()
                            && (info.serial == 0 || p.serial() == info.serial)
                    }
                }
                Err(_) => false,
            };
        let imu_only = info.udp_port_lidar == 0
            && info.udp_port_imu == d.port
            && OusterStreamConfig::imu_len_of(info) == Some(d.payload.len());
        // A zone-monitor packet names its sensor by serial, as profile-based lidar packets do.
        let zone = info.serial != 0
            && ZonePacket::new(d.payload, info.format.profile.header())
                .is_ok_and(|p| p.packet_type() == PACKET_TYPE_ZONE && p.serial() == info.serial);
        lidar || imu_only || zone
    }
}

impl Family for Ouster {
    fn name(&self) -> &'static str {
        "ouster"
    }

    fn models(&self) -> &'static [&'static str] {
        &[]
    }

    /// The sensor's metadata: a JSON object (every form: flat, FW 1.12/1.13, nested).
    fn parse_calibration(
        &self,
        bytes: &[u8],
        file_name: &str,
    ) -> Option<Result<Arc<dyn Any + Send + Sync>, CalibError>> {
        let text = match core::str::from_utf8(bytes) {
            Ok(t) => t,
            Err(_) => return None,
        };
        if !text
            .trim_start_matches('\u{feff}')
            .trim_start()
            .starts_with('{')
        {
            return None;
        }
        Some(
            OusterCalibration::parse(text, file_name)
                .map(|c| Arc::new(c) as Arc<dyn Any + Send + Sync>),
        )
    }

    /// Lidar packets to 7502, IMU packets to 7503 (ouster-sdk's defaults).
    fn default_ports(&self) -> &'static [u16] {
        &[7502, 7503]
    }

    fn calibration_ports(&self, c: &Calibration) -> Vec<u16> {
        c.get::<OusterCalibration>()
            .map(|o| {
                [
                    o.info.udp_port_lidar,
                    o.info.udp_port_imu,
                    o.info.udp_port_zm,
                ]
            })
            .into_iter()
            .flatten()
            .filter(|&p| p != 0)
            .collect()
    }

    fn lidar_sizes(&self, calibs: &[Calibration]) -> Vec<usize> {
        calibs
            .iter()
            .filter_map(|c| c.get::<OusterCalibration>())
            .map(|c| c.info.lidar_packet_bytes())
            .collect()
    }

    /// Ouster packets cannot be decoded, nor told apart, without the sensor's metadata: a
    /// sensor is claimed by the first metadata that [fits](OusterCalibration::fits) its first
    /// datagram. Each file serves one sensor, unless bound to an address.
    fn claim(&self, d: &FirstDatagram<'_>, pool: &mut CalibrationPool) -> Option<Claimed> {
        let (idx, cal, name) = pool
            .candidates(self.name(), d.src, true)
            .find_map(|(i, c)| {
                let oc = c.get::<OusterCalibration>()?;
                oc.fits(d, c.addr == Some(d.src)).then(|| {
                    (
                        i,
                        (oc.info.clone(), oc.decoder.clone()),
                        c.file_name.clone(),
                    )
                })
            })?;
        pool.mark_used(idx);
        let s = &pool.settings;
        let (cal, decoder) = cal;
        let cfg = OusterStreamConfig {
            info: cal,
            metadata_name: name,
            crc: s.crc,
            decode: s.decode,
            keep_extras: s.keep_extras,
            keep_columns: s.keep_columns,
        };
        Some(
            OusterStream::with_decoder(cfg, decoder)
                .map(|s| Box::new(s) as Box<dyn SensorStream>)
                .map_err(StreamError::Decode),
        )
    }

    fn selected_by_port(&self) -> bool {
        false
    }

    fn describe(&self, s: &Value) -> Vec<String> {
        let st = |k: &str| summary_str(&s[k]);
        let g = |v: &Value| v.as_u64().unwrap_or(0);
        let mut out = Vec::with_capacity(4);
        // A reduced metadata file (the legacy sensor_config form) has no model, serial or
        // firmware: those are left out rather than printed as gaps and a serial 0.
        let text = |k: &str| s[k].as_str().filter(|t| !t.is_empty());
        let serial = match &s["serial"] {
            Value::Number(n) if n.as_u64() != Some(0) => Some(format!("sn {n}")),
            Value::String(t) if !t.is_empty() && t != "0" => Some(format!("sn {t}")),
            _ => None,
        };
        let mut what: Vec<String> = Vec::with_capacity(5);
        match text("model") {
            Some(m) => what.push(m.to_string()),
            None if serial.is_none() => {
                what.push("Ouster (model and serial not in the metadata)".to_string())
            }
            None => what.push("Ouster".to_string()),
        }
        what.extend(serial);
        what.extend(
            ["firmware", "profile", "lidar_mode"]
                .into_iter()
                .filter_map(text)
                .map(str::to_string),
        );
        out.push(format!(
            "  {}, ports {}: {}, window [{}, {}]",
            crate::sensor::heading(s),
            s["ports"],
            what.join(" "),
            s["column_window"][0],
            s["column_window"][1]
        ));
        out.push(format!(
            "    {} lidar + {} IMU{} packets, {} sweeps, {} points; missing columns {}, malformed {}, CRC failures {}, late {}, other sensor {}, epochs {}, discontinuities {}",
            g(&s["lidar_packets"]),
            g(&s["imu_packets"]),
            match s["zone_packets"].as_u64() {
                Some(n) if n > 0 => format!(" + {n} zone-monitor"),
                _ => String::new(),
            },
            g(&s["sweeps"]),
            g(&s["points"]),
            g(&s["missing_columns"]),
            g(&s["malformed"]),
            g(&s["crc_failures"]),
            g(&s["late"]),
            g(&s["wrong_sensor"]),
            g(&s["epochs"]),
            g(&s["discontinuities"])
        ));
        out.push(format!("    packets per port: {}", s["packets_per_port"]));
        out.push(format!(
            "    metadata: {}; timestamps: {}; clock: {}; CRC checked: {}; shot limiting: {}; thermal: {}",
            st("calibration"),
            st("timestamp_mode"),
            st("clock"),
            s["crc_checked"],
            st("shot_limiting"),
            st("thermal_shutdown")
        ));
        out
    }
}

impl Facts for OusterFacts {
    fn family(&self) -> &'static str {
        "ouster"
    }

    fn default_name(&self, addr: Ipv4Addr) -> String {
        let model = if self.prod_line.is_empty() {
            "ouster".to_string()
        } else {
            self.prod_line.to_ascii_lowercase()
        };
        if self.serial != 0 {
            format!("{model}-{}", self.serial)
        } else {
            format!("{model}-{}", addr.octets()[3])
        }
    }

    fn calibration_name(&self) -> &str {
        &self.metadata
    }

    fn channel_metadata(&self, md: &mut BTreeMap<String, String>) {
        let mut put = |k: &str, v: String| {
            md.insert(k.to_string(), v);
        };
        put("model", self.prod_line.clone());
        put("serial", self.serial.to_string());
        put("firmware", self.firmware.clone());
        put("profile", self.profile.clone());
        put("lidar_mode", self.mode.clone());
        put("init_id", self.init_id.to_string());
        put("clock", self.clock.name().to_string());
        put("calibration", self.metadata.clone());
        put("lidar_packet_bytes", self.lidar_packet_bytes.to_string());
        put("crc_checked", self.crc_checked.to_string());
    }

    fn diagnostics(&self, out: &mut Map<String, Value>) {
        out.insert(
            "shot_limiting".into(),
            json!(shot_limiting_name(self.shot_limiting)),
        );
        out.insert(
            "thermal_shutdown".into(),
            json!(thermal_shutdown_name(self.thermal_shutdown)),
        );
        out.insert("init_id".into(), json!(self.init_id));
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}

impl SensorStream for OusterStream {
    fn push(
        &mut self,
        host_ns: i64,
        payload: &[u8],
        on_sweep: &mut OnSweep<'_>,
    ) -> Result<(), StreamError> {
        OusterStream::push(self, host_ns, payload, &mut |sw, f| on_sweep(sw, f));
        Ok(())
    }

    fn finish(&mut self, on_sweep: &mut OnSweep<'_>) -> Result<(), StreamError> {
        OusterStream::finish(self, &mut |sw, f| on_sweep(sw, f));
        Ok(())
    }

    fn ready(&self) -> bool {
        true
    }

    fn facts(&self) -> &dyn Facts {
        OusterStream::facts(self)
    }

    fn summary(&self) -> (Value, PacketCounts) {
        let (st, f, info) = (self.stats(), OusterStream::facts(self), self.info());
        let counts = PacketCounts {
            decoded: st.lidar_packets + st.imu_packets + st.zone_packets,
            malformed: st.malformed + st.crc_failures,
            missing: st
                .missing_columns
                .div_ceil(info.format.columns_per_packet.max(1) as u64),
            position: 0,
            dropped: st.wrong_sensor + st.late + st.imu_dropped + st.zone_dropped,
        };
        let v = json!({
            "kind": "ouster",
            "model": f.prod_line,
            "serial": f.serial,
            "firmware": f.firmware,
            "build_rev": info.firmware,
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
            "shot_limiting": shot_limiting_name(f.shot_limiting),
            "thermal_shutdown": thermal_shutdown_name(f.thermal_shutdown),
            "lidar_packets": st.lidar_packets,
            "imu_packets": st.imu_packets,
            "zone_packets": st.zone_packets,
            "malformed": st.malformed,
            "crc_failures": st.crc_failures,
            "wrong_sensor": st.wrong_sensor,
            "late": st.late,
            "epochs": st.epochs,
            "discontinuities": st.discontinuities,
            "missing_columns": st.missing_columns,
            "missing": counts.missing,
            "sweeps": st.sweeps,
            "points": st.points,
            "imu_dropped": st.imu_dropped,
            "zone_dropped": st.zone_dropped,
            "measured_fps": self.measured_fps(),
            "warnings": self.rate_mismatch().into_iter().collect::<Vec<_>>(),
            "alert_flags": {
                "last": f.alert_flags_last,
                "seen": f.alert_flags_seen,
                "packets": f.alert_packets,
            },
        });
        (v, counts)
    }

    fn is_lidar_datagram(&self, _payload: &[u8]) -> bool {
        // An Ouster sensor is told by its metadata, not by a port: `--port` does not filter it.
        false
    }

    fn channels(&self) -> Option<usize> {
        Some(self.info().format.pixels_per_column)
    }

    fn drain_zones(&mut self, out: &mut dyn FnMut(&ZoneReport)) {
        for z in OusterStream::drain_zones(self) {
            out(&z);
        }
    }

    fn drain_imu(&mut self, out: &mut dyn FnMut(&ImuSample, &[f64; 16])) {
        let imu_to_sensor = self.info().imu_to_sensor;
        for s in OusterStream::drain_imu(self) {
            out(&s, &imu_to_sensor);
        }
    }

    fn epochs(&self) -> u64 {
        self.stats().epochs
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}
