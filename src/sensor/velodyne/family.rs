//! The Velodyne family behind ringscan's sensor interface ([`crate::sensor`]).

use std::any::Any;
use std::collections::BTreeMap;
use std::net::Ipv4Addr;
use std::sync::Arc;

use serde_json::{json, Map, Value};

use super::calib::{parse_velodyne_bytes, VelodyneCalibration};
use super::model::{VelodyneModel, ALL_MODELS, DATA_PACKET_LEN, POSITION_PACKET_LEN};
use super::sweep::{SensorFacts, StreamConfig, VelodyneStream};
use crate::sensor::{
    summary_str, CalibError, Calibration, CalibrationPool, Claimed, Facts, Family, FirstDatagram,
    OnSweep, PacketCounts, SensorStream, StreamError,
};

/// The Velodyne family.
#[derive(Clone, Copy, Debug, Default)]
pub struct Velodyne;

const MODEL_IDS: &[&str] = &[
    "vlp16",
    "puck-hires",
    "hdl32e",
    "vlp32c",
    "hdl64e-s2",
    "hdl64e-s3",
    "vls128",
];

impl Family for Velodyne {
    fn name(&self) -> &'static str {
        "velodyne"
    }

    fn models(&self) -> &'static [&'static str] {
        MODEL_IDS
    }

    /// A ROS yaml, a VeloView xml or an HDL-64E db.xml: any text that is not a JSON object
    /// (Ouster's metadata) is offered to the Velodyne parsers, whose errors then say what is
    /// wrong with it.
    fn parse_calibration(
        &self,
        bytes: &[u8],
        file_name: &str,
    ) -> Option<Result<Arc<dyn Any + Send + Sync>, CalibError>> {
        let text = String::from_utf8_lossy(bytes);
        if text
            .trim_start_matches('\u{feff}')
            .trim_start()
            .starts_with('{')
        {
            return None;
        }
        Some(
            parse_velodyne_bytes(bytes, file_name)
                .map(|c| Arc::new(c) as Arc<dyn Any + Send + Sync>),
        )
    }

    /// Data packets to 2368, position packets to 8308.
    fn default_ports(&self) -> &'static [u16] {
        &[2368, 8308]
    }

    fn lidar_sizes(&self, _calibs: &[Calibration]) -> Vec<usize> {
        vec![DATA_PACKET_LEN]
    }

    /// Datagrams of the data (1206 B) or position (512 B) packet size. The model is detected
    /// later, by the stream, from the product id and the packet cadence; every Velodyne table
    /// given (bound to this address or to none) is offered to it, the first whose laser count
    /// fits the model wins.
    fn claim(&self, d: &FirstDatagram<'_>, pool: &mut CalibrationPool) -> Option<Claimed> {
        if !matches!(d.payload.len(), DATA_PACKET_LEN | POSITION_PACKET_LEN) {
            return None;
        }
        let s = &pool.settings;
        let model = match s.model.as_deref() {
            None => None,
            // Another family's model: not a Velodyne, whatever the size says.
            Some(m) => Some(VelodyneModel::from_id(m)?),
        };
        let calibrations = pool
            .candidates(self.name(), d.src, false)
            .filter_map(|(_, c)| c.get::<VelodyneCalibration>().cloned())
            .collect();
        let cfg = StreamConfig {
            model,
            calibrations,
            decode: s.decode,
            cut_angle: s.cut_angle,
            keep_columns: s.keep_columns,
            inspect: s.inspect,
            ..StreamConfig::default()
        };
        Some(Ok(Box::new(VelodyneStream::new(cfg))))
    }

    fn describe(&self, s: &Value) -> Vec<String> {
        let st = |k: &str| summary_str(&s[k]);
        let g = |v: &Value| v.as_u64().unwrap_or(0);
        let mut out = Vec::with_capacity(4);
        // What is known of the model, its return mode and how it was told, without the gaps
        // of a sensor whose packets were not decoded.
        let what: Vec<&str> = [
            s["model"].as_str().or(Some(crate::sensor::UNKNOWN_MODEL)),
            s["return_mode"].as_str(),
        ]
        .into_iter()
        .flatten()
        .collect();
        out.push(format!(
            "  {}, ports {}: {}{}",
            crate::sensor::heading(s),
            s["ports"],
            what.join(" "),
            s["detection"]
                .as_str()
                .filter(|d| !d.is_empty())
                .map(|d| format!(", {d}"))
                .unwrap_or_default()
        ));
        out.push(format!(
            "    {} data + {} position packets, {} sweeps, {} points; missing {}, malformed {}, discontinuities {}, duplicates {}, late dropped {}",
            g(&s["data_packets"]),
            g(&s["position_packets"]),
            g(&s["sweeps"]),
            g(&s["points"]),
            g(&s["missing"]),
            g(&s["malformed"]),
            g(&s["discontinuities"]),
            g(&s["duplicates"]),
            g(&s["late_dropped"])
        ));
        out.push(format!("    packets per port: {}", s["packets_per_port"]));
        out.push(format!(
            "    calibration: {}; clock: {}; PPS: {}; GPS: {}",
            st("calibration"),
            st("clock"),
            s["pps"].as_str().unwrap_or("no position packets"),
            if s["gps"].is_null() {
                "no NMEA time".to_string()
            } else {
                format!("RMC valid={}", s["gps"]["valid"])
            }
        ));
        out
    }
}

impl Facts for SensorFacts {
    fn family(&self) -> &'static str {
        "velodyne"
    }

    fn default_name(&self, addr: Ipv4Addr) -> String {
        match self.model {
            Some(m) => format!("{}-{}", m.id(), addr.octets()[3]),
            None => format!("velodyne-{}", addr.octets()[3]),
        }
    }

    fn calibration_name(&self) -> &str {
        &self.calibration
    }

    fn channel_metadata(&self, md: &mut BTreeMap<String, String>) {
        let mut put = |k: &str, v: String| {
            md.insert(k.to_string(), v);
        };
        put(
            "model",
            self.model.map(|m| m.name().to_string()).unwrap_or_default(),
        );
        put(
            "return_mode",
            self.mode.map(|m| m.name().to_string()).unwrap_or_default(),
        );
        put(
            "product_id",
            self.product_id
                .map(|p| format!("{p:#04x}"))
                .unwrap_or_default(),
        );
        put("model_detection", self.detection.clone());
        put("clock", self.clock.name().to_string());
        put("calibration", self.calibration.clone());
        put("serial", String::new());
        put("firmware", String::new());
        put("profile", String::new());
    }

    fn diagnostics(&self, out: &mut Map<String, Value>) {
        out.insert("pps".into(), json!(self.pps.map(|p| p.name())));
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}

impl SensorStream for VelodyneStream {
    fn push(
        &mut self,
        host_ns: i64,
        payload: &[u8],
        on_sweep: &mut OnSweep<'_>,
    ) -> Result<(), StreamError> {
        VelodyneStream::push(self, host_ns, payload, &mut |sw, f| on_sweep(sw, f))
    }

    fn finish(&mut self, on_sweep: &mut OnSweep<'_>) -> Result<(), StreamError> {
        VelodyneStream::finish(self, &mut |sw, f| on_sweep(sw, f))
    }

    fn ready(&self) -> bool {
        self.decoder().is_some()
    }

    fn facts(&self) -> &dyn Facts {
        VelodyneStream::facts(self)
    }

    fn summary(&self) -> (Value, PacketCounts) {
        let (st, f) = (self.stats(), VelodyneStream::facts(self));
        let counts = PacketCounts {
            decoded: st.data_packets,
            malformed: st.malformed,
            missing: st.missing,
            position: st.position_packets,
            // A copy is no loss (the sensor's `duplicates` only); a late packet dropped is.
            dropped: st.late_dropped,
        };
        let v = json!({
            "kind": "velodyne",
            "model": f.model.map(|m| m.name()),
            "model_id": f.model.map(|m| m.id()),
            "return_mode": f.mode.map(|m| m.name()),
            "product_id": f.product_id.map(|p| format!("{p:#04x}")),
            "detection": f.detection,
            "model_contradicted": f.model_contradicted,
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
            "duplicates": st.duplicates,
            "late_dropped": st.late_dropped,
            "sweeps": st.sweeps,
            "points": st.points,
        });
        (v, counts)
    }

    fn is_lidar_datagram(&self, payload: &[u8]) -> bool {
        payload.len() == DATA_PACKET_LEN
    }

    fn channels(&self) -> Option<usize> {
        VelodyneStream::facts(self).model.map(|m| m.lasers())
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// Model names `--model` accepts, each a [`VelodyneModel::id`].
pub fn model_ids() -> impl Iterator<Item = &'static str> {
    ALL_MODELS.into_iter().map(VelodyneModel::id)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn model_names_are_the_models_ids() {
        assert_eq!(model_ids().collect::<Vec<_>>(), MODEL_IDS);
    }
}
