//! The Livox family behind ringscan's sensor interface ([`crate::sensor`]).
//!
//! A Livox sensor is told from its first datagram: an SDK2 packet (version 0, its length
//! field equal to the datagram's length, a known data type, `dot_num` records filling the
//! data exactly) or an SDK1 packet (version 5, a known data type at its documented length).
//! The destination port names the SDK2 model (MID-360: points to 56301, IMU to 56401; HAP:
//! 57000 / 58000); SDK1 models cannot be told from their packets, so `--model` names them
//! (without it the stream decodes them as one line at 240 k points/s and says so). Livox
//! has no calibration files: the sensor sends Cartesian points.

use std::any::Any;
use std::collections::BTreeMap;
use std::net::Ipv4Addr;
use std::sync::Arc;

use serde_json::{json, Map, Value};

use super::frame::{ImuFrame, PointsFrame};
#[cfg(test)]
use super::model::ALL_MODELS;
use super::model::{LivoxModel, Protocol};
use super::sweep::{LivoxConfig, LivoxFacts, LivoxStream};
use super::wire::{Sdk1Packet, Sdk2Packet};
use crate::sensor::{
    summary_str, CalibError, Calibration, CalibrationPool, Claimed, Facts, Family, FirstDatagram,
    ImuSample, OnSweep, PacketCounts, SensorStream, StreamError,
};

/// The Livox family.
#[derive(Clone, Copy, Debug, Default)]
pub struct Livox;

const MODEL_IDS: &[&str] = &[
    "mid360", "hap", "avia", "horizon", "tele15", "mid40", "mid70",
];

/// The protocol a datagram is a well-formed packet of.
pub fn detect_protocol(payload: &[u8]) -> Option<Protocol> {
    if Sdk2Packet::new(payload).is_ok() {
        Some(Protocol::Sdk2)
    } else if Sdk1Packet::new(payload).is_ok() {
        Some(Protocol::Sdk1)
    } else {
        None
    }
}

/// Builds the stream configuration for a first datagram, or `None` when it is not Livox's.
pub fn config_for(d: &FirstDatagram<'_>, named: Option<LivoxModel>) -> Option<LivoxConfig> {
    if Livox.is_decoded_frame(d.payload) {
        // Points a ROS driver decoded (a bag's CustomMsg): no packet says the model.
        let mut cfg = LivoxConfig::new(named, Protocol::Sdk2);
        cfg.detection = "livox_ros_driver CustomMsg points (decoded by the driver)".to_string();
        return Some(cfg);
    }
    let protocol = detect_protocol(d.payload)?;
    let (model, detection) = match named {
        Some(m) if m.protocol() == protocol => (
            Some(m),
            "named (--model, or a recording's device type)".to_string(),
        ),
        Some(_) => return None,
        None => match protocol {
            Protocol::Sdk2 => match LivoxModel::sdk2_from_port(d.port) {
                Some(m) => (Some(m), format!("SDK2 packet to port {}", d.port)),
                None => (
                    None,
                    format!(
                        "SDK2 packet to port {}: model unknown (name it with --model mid360|hap)",
                        d.port
                    ),
                ),
            },
            Protocol::Sdk1 => (
                None,
                format!(
                    "SDK1 packet to port {}: model unknown (name it with --model avia|horizon|tele15|mid40|mid70)",
                    d.port
                ),
            ),
        },
    };
    let mut cfg = LivoxConfig::new(model, protocol);
    cfg.detection = detection;
    Some(cfg)
}

impl Family for Livox {
    fn name(&self) -> &'static str {
        "livox"
    }

    fn models(&self) -> &'static [&'static str] {
        MODEL_IDS
    }

    fn parse_calibration(
        &self,
        _bytes: &[u8],
        _file_name: &str,
    ) -> Option<Result<Arc<dyn Any + Send + Sync>, CalibError>> {
        None
    }

    fn is_decoded_frame(&self, payload: &[u8]) -> bool {
        PointsFrame::is_frame(payload) || ImuFrame::is_frame(payload)
    }

    /// MID-360 points / IMU, HAP points / IMU, and the SDK1 data ports Livox-SDK hands the
    /// first four sensors of a host.
    fn describe(&self, s: &Value) -> Vec<String> {
        let st = |k: &str| summary_str(&s[k]);
        let g = |v: &Value| v.as_u64().unwrap_or(0);
        let d = &s["point_density"];
        vec![
            format!(
                "  {}, ports {}: {}, protocol {}, data type {}, {} lines; {}",
                crate::sensor::heading(s),
                s["ports"],
                s["model"].as_str().unwrap_or("Livox, model unknown"),
                st("protocol"),
                s["data_type"],
                s["lines"],
                st("detection")
            ),
            format!(
                "    {} point + {} IMU packets, {} sweeps ({} ms, cut by {}), {} points ({:.0} per sweep, {}–{}); missing {}, malformed {}, discontinuities {}, duplicates {}, late dropped {}, forced cuts {}; IMU missing {}, dropped {}",
                g(&s["data_packets"]),
                g(&s["imu_packets"]),
                g(&s["sweeps"]),
                s["integration_ms"],
                st("sweep_cut"),
                g(&s["points"]),
                d["points_per_sweep_mean"].as_f64().unwrap_or(0.0),
                g(&d["points_per_sweep_min"]),
                g(&d["points_per_sweep_max"]),
                g(&s["missing"]),
                g(&s["malformed"]),
                g(&s["discontinuities"]),
                g(&s["duplicates"]),
                g(&s["late_dropped"]),
                g(&s["forced_cuts"]),
                g(&s["imu_missing"]),
                g(&s["imu_dropped"])
            ),
            format!("    packets per port: {}", s["packets_per_port"]),
            format!(
                "    clock: {} ({}); CRC: {} ok, {} failed, {} without",
                st("clock"),
                st("time_type"),
                g(&s["crc_ok"]),
                g(&s["crc_failures"]),
                g(&s["crc_absent"])
            ),
        ]
    }

    fn default_ports(&self) -> &'static [u16] {
        &[
            56_301, 56_401, 57_000, 58_000, 56_001, 56_002, 56_003, 56_004,
        ]
    }

    fn lidar_sizes(&self, _calibs: &[Calibration]) -> Vec<usize> {
        // SDK1 point packets at their documented lengths; SDK2 lengths vary with dot_num
        // (MID-360: 96 records → 36 + 96 · 14 = 1380 for type 1, 804 for type 2, 996 for 3).
        let mut v = vec![1318, 918, 1362, 978, 786, 1278, 678, 1380, 804, 996];
        v.sort_unstable();
        v.dedup();
        v
    }

    fn claim(&self, d: &FirstDatagram<'_>, pool: &mut CalibrationPool) -> Option<Claimed> {
        let named = match pool.settings.model.as_deref() {
            None => None,
            Some(m) => Some(LivoxModel::from_id(m)?),
        };
        let mut cfg = config_for(d, named)?;
        let s = &pool.settings;
        cfg.range = s.decode;
        if let Some(on) = s.crc {
            cfg.check_crc = on;
        }
        if let Some(p) = s.integration_ns {
            cfg.period_ns = p.max(1);
        }
        cfg.imu_to_sensor = s.imu_to_sensor;
        Some(Ok(Box::new(LivoxStream::new(cfg))))
    }
}

fn protocol_name(p: Protocol) -> &'static str {
    match p {
        Protocol::Sdk1 => "livox-sdk1",
        Protocol::Sdk2 => "livox-sdk2",
    }
}

impl Facts for LivoxFacts {
    fn family(&self) -> &'static str {
        "livox"
    }

    fn default_name(&self, addr: Ipv4Addr) -> String {
        match self.model {
            Some(m) => format!("{}-{}", m.id(), addr.octets()[3]),
            None => format!("livox-{}", addr.octets()[3]),
        }
    }

    fn calibration_name(&self) -> &str {
        "none (Livox sends Cartesian points)"
    }

    fn channel_metadata(&self, md: &mut BTreeMap<String, String>) {
        let mut put = |k: &str, v: String| {
            md.insert(k.to_string(), v);
        };
        put(
            "model",
            self.model.map(|m| m.name().to_string()).unwrap_or_default(),
        );
        put("protocol", protocol_name(self.protocol).to_string());
        put("model_detection", self.detection.clone());
        put("clock", self.clock.name().to_string());
        put("time_type", self.time_type_name().to_string());
        put("lines", self.lines.to_string());
        put("integration_ms", format!("{}", self.period_ns as f64 / 1e6));
        put(
            "sweep_cut",
            if self.frame_cut { "frame_cnt" } else { "time" }.to_string(),
        );
        put(
            "point_pad_byte",
            "Livox tag (confidence / noise flags)".to_string(),
        );
        put("calibration", String::new());
        put("serial", String::new());
        put("firmware", String::new());
        put("profile", String::new());
    }

    fn diagnostics(&self, out: &mut Map<String, Value>) {
        out.insert("time_type".into(), json!(self.time_type_name()));
        out.insert("data_type".into(), json!(self.data_type));
        out.insert("status_code".into(), json!(self.status_code));
        out.insert(
            "sweep_cut".into(),
            json!(if self.frame_cut { "frame_cnt" } else { "time" }),
        );
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}

impl SensorStream for LivoxStream {
    fn push(
        &mut self,
        host_ns: i64,
        payload: &[u8],
        on_sweep: &mut OnSweep<'_>,
    ) -> Result<(), StreamError> {
        LivoxStream::push(self, host_ns, payload, &mut |sw, f| on_sweep(sw, f));
        Ok(())
    }

    fn finish(&mut self, on_sweep: &mut OnSweep<'_>) -> Result<(), StreamError> {
        LivoxStream::finish(self, &mut |sw, f| on_sweep(sw, f));
        Ok(())
    }

    fn ready(&self) -> bool {
        true
    }

    fn facts(&self) -> &dyn Facts {
        LivoxStream::facts(self)
    }

    fn summary(&self) -> (Value, PacketCounts) {
        let (st, f) = (self.stats(), LivoxStream::facts(self));
        let counts = PacketCounts {
            decoded: st.packets + st.imu_packets + st.frames,
            malformed: st.malformed,
            missing: st.missing,
            position: 0,
            // A copy is no loss (the sensor's `duplicates` only); a late packet dropped is.
            dropped: st.late_dropped,
        };
        let mean = if st.sweeps > 0 {
            st.points as f64 / st.sweeps as f64
        } else {
            0.0
        };
        let period_s = f.period_ns as f64 / 1e9;
        let v = json!({
            "kind": "livox",
            "model": f.model.map(|m| m.name()),
            "model_id": f.model.map(|m| m.id()),
            "protocol": protocol_name(f.protocol),
            "detection": f.detection,
            "lines": f.lines,
            "clock": f.clock.name(),
            "time_type": f.time_type_name(),
            "data_type": f.data_type,
            "integration_ms": f.period_ns as f64 / 1e6,
            "sweep_cut": if st.frames > 0 { "message" } else if f.frame_cut { "frame_cnt" } else { "time" },
            "point_density": {
                "points_per_sweep_mean": mean,
                "points_per_sweep_min": st.min_sweep_points,
                "points_per_sweep_max": st.max_sweep_points,
                "points_per_second_mean": if period_s > 0.0 { mean / period_s } else { 0.0 },
            },
            "crc_ok": st.crc_ok,
            "crc_failures": st.crc_failures,
            "crc_absent": st.crc_absent,
            "data_packets": st.packets,
            "custom_msg_frames": st.frames,
            "imu_packets": st.imu_packets,
            "imu_missing": st.imu_missing,
            "imu_dropped": st.imu_dropped,
            "imu_uncovered_sweeps": st.imu_uncovered_sweeps,
            "position_packets": 0,
            "malformed": st.malformed,
            "missing": st.missing,
            "discontinuities": st.discontinuities,
            "duplicates": st.duplicates,
            "late_dropped": st.late_dropped,
            "forced_cuts": st.forced_cuts,
            "sweeps": st.sweeps,
            "points": st.points,
            "tagged_points": st.tagged_points,
        });
        (v, counts)
    }

    fn is_lidar_datagram(&self, payload: &[u8]) -> bool {
        match LivoxStream::facts(self).protocol {
            Protocol::Sdk2 => Sdk2Packet::new(payload).is_ok_and(|p| p.data_type() != 0),
            Protocol::Sdk1 => Sdk1Packet::new(payload).is_ok_and(|p| p.data_type() != 6),
        }
    }

    fn channels(&self) -> Option<usize> {
        Some(usize::from(LivoxStream::facts(self).lines))
    }

    fn drain_imu(&mut self, out: &mut dyn FnMut(&ImuSample, &[f64; 16])) {
        let m = LivoxStream::facts(self).imu_to_sensor;
        for s in LivoxStream::drain_imu(self) {
            out(&s, &m);
        }
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn model_names_are_the_models_ids() {
        let ids: Vec<&str> = ALL_MODELS.iter().map(|m| m.id()).collect();
        assert_eq!(ids, MODEL_IDS);
    }
}
