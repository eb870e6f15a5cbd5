//! The Robosense family behind ringscan's sensor interface ([`crate::sensor`]).
//!
//! A Robosense sensor is told from its datagrams alone, never from a file name: an MSOP packet
//! is 1248 bytes starting `55 AA 05 0A 5A A5 50 A0` (RS-16 / RS-32 / Bpearl) or `55 AA 05 5A`
//! (Helios, Ruby) with its blocks' marks where the layout puts them; a DIFOP packet is 1248
//! bytes starting `A5 FF 00 5A 11 11 55 55`; an M1 / M1 Plus MSOP packet is 1210 bytes starting
//! `55 AA 5A A5`, its DIFOP 256 bytes with the DIFOP id. Which model of a shared header it is comes from
//! the angle file's laser count or the DIFOP's angle table ([`super::sweep`]), or `--model`.

use std::any::Any;
use std::collections::BTreeMap;
use std::net::Ipv4Addr;
use std::sync::Arc;

use serde_json::{json, Map, Value};

use super::calib::{parse_csv, RobosenseAngles};
use super::m1::{is_m1_difop, M1_MSOP_LEN};
use super::model::{RobosenseModel, PACKET_LEN};
use super::sweep::{RobosenseConfig, RobosenseFacts, RobosenseStream};
use super::wire::{is_difop, msop_shape};
use crate::sensor::{
    summary_str, CalibError, Calibration, CalibrationPool, Claimed, Facts, Family, FirstDatagram,
    OnSweep, PacketCounts, SensorStream, StreamError,
};

/// The Robosense family.
#[derive(Clone, Copy, Debug, Default)]
pub struct Robosense;

const MODEL_IDS: &[&str] = &[
    "rs16",
    "rs32",
    "rsbpearl",
    "rshelios",
    "rshelios16p",
    "rsruby128",
    "rsm1",
];

/// Reads a Robosense angle CSV; `None` for any other text.
pub fn parse_robosense_calibration(bytes: &[u8]) -> Option<Result<RobosenseAngles, CalibError>> {
    let text = core::str::from_utf8(bytes).ok()?;
    parse_csv(text)
}

impl Family for Robosense {
    fn name(&self) -> &'static str {
        "robosense"
    }

    fn models(&self) -> &'static [&'static str] {
        MODEL_IDS
    }

    fn parse_calibration(
        &self,
        bytes: &[u8],
        file_name: &str,
    ) -> Option<Result<Arc<dyn Any + Send + Sync>, CalibError>> {
        parse_robosense_calibration(bytes).map(|r| {
            r.map(|mut a| {
                a.source = file_name.to_string();
                Arc::new(a) as Arc<dyn Any + Send + Sync>
            })
        })
    }

    /// MSOP to 6699, DIFOP to 7788.
    fn describe(&self, s: &Value) -> Vec<String> {
        let st = |k: &str| summary_str(&s[k]);
        let g = |k: &str| s[k].as_u64().unwrap_or(0);
        // What the DIFOP said, or that none was seen.
        let known = |k: &str| match &s[k] {
            Value::Null => "unknown".to_string(),
            Value::String(v) => v.clone(),
            v => v.to_string(),
        };
        let fov = match s["fov_cdeg"]
            .as_array()
            .map(|a| a.iter().filter_map(Value::as_u64).collect::<Vec<_>>())
        {
            Some(v) if v.len() == 2 => {
                format!("{:.2}–{:.2}°", v[0] as f64 / 100.0, v[1] as f64 / 100.0)
            }
            _ => "unknown".to_string(),
        };
        vec![
            format!(
                "  {}, ports {}: Robosense {}, {}; {}",
                crate::sensor::heading(s),
                s["ports"],
                s["model"].as_str().unwrap_or(crate::sensor::UNKNOWN_MODEL),
                st("return_mode"),
                st("detection")
            ),
            format!(
                "    {} MSOP + {} DIFOP packets, {} sweeps, {} points; missing {}, malformed {}, dropped {}, late dropped {}, discontinuities {}, duplicates {}, held {}",
                g("data_packets"),
                g("difop_packets"),
                g("sweeps"),
                g("points"),
                g("missing"),
                g("malformed"),
                g("dropped"),
                g("late_dropped"),
                g("discontinuities"),
                g("duplicates"),
                g("held")
            ),
            format!("    packets per port: {}", s["packets_per_port"]),
            if s["model_id"].as_str() == Some("rsm1") {
                // A MEMS unit: no motor, no angle table; the header's temperature instead.
                format!(
                    "    calibration: {}; DIFOP: frame-rate byte {}, firmware {}, serial {}; temperature {} °C, protocol {}",
                    st("calibration"),
                    known("frame_rate"),
                    known("firmware"),
                    known("serial"),
                    known("temperature_c"),
                    known("protocol")
                )
            } else {
                format!(
                    "    calibration: {}; DIFOP: motor {} rpm, field of view {}, firmware {}, serial {}",
                    st("calibration"),
                    known("motor_rpm"),
                    fov,
                    known("firmware"),
                    known("serial")
                )
            },
            format!("    clock: {} ({})", st("clock"), st("clock_state")),
        ]
    }

    fn default_ports(&self) -> &'static [u16] {
        &[6699, 7788]
    }

    fn calibration_ports(&self, c: &Calibration) -> Vec<u16> {
        if c.get::<RobosenseAngles>().is_some() {
            vec![6699, 7788]
        } else {
            Vec::new()
        }
    }

    fn lidar_sizes(&self, _calibs: &[Calibration]) -> Vec<usize> {
        vec![PACKET_LEN, M1_MSOP_LEN]
    }

    /// An MSOP or DIFOP packet (by its bytes). The first Robosense angle file (bound to this
    /// address, or unbound and unused) serves it; without one the DIFOP's angles do.
    fn claim(&self, d: &FirstDatagram<'_>, pool: &mut CalibrationPool) -> Option<Claimed> {
        let named = match pool.settings.model.as_deref() {
            None => None,
            Some(m) => Some(RobosenseModel::from_id(m)?),
        };
        let shape = msop_shape(d.payload);
        if shape.is_none() && !is_difop(d.payload) && !is_m1_difop(d.payload) {
            return None;
        }
        if let (Some(m), Some(s)) = (named, shape) {
            if m.spec().shape != s {
                return None;
            }
        }
        let fits = |a: &RobosenseAngles| named.is_none_or(|m| m.lasers() == a.lasers());
        let found = pool
            .candidates(self.name(), d.src, true)
            .find(|(_, c)| c.get::<RobosenseAngles>().is_some_and(fits))
            .map(|(i, c)| (i, c.get::<RobosenseAngles>().cloned()));
        let angles = match found {
            Some((i, a)) => {
                pool.mark_used(i);
                a
            }
            None => None,
        };
        let s = &pool.settings;
        let mut cfg = RobosenseConfig::new(angles);
        cfg.model = named;
        cfg.options = s.decode;
        cfg.cut_cdeg = s.cut_angle;
        cfg.keep_columns = s.keep_columns;
        Some(Ok(Box::new(RobosenseStream::new(cfg))))
    }
}

impl Facts for RobosenseFacts {
    fn family(&self) -> &'static str {
        "robosense"
    }

    fn default_name(&self, addr: Ipv4Addr) -> String {
        let m = self.model.map_or("robosense", RobosenseModel::id);
        if self.serial.is_empty() {
            format!("{m}-{}", addr.octets()[3])
        } else {
            format!("{m}-{}", self.serial)
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
        put("model_detection", self.detection.clone());
        put("return_mode", self.return_mode_words());
        put("clock", self.clock.name().to_string());
        put("clock_state", self.clock_words());
        put("calibration", self.calibration.clone());
        put("serial", self.serial.clone());
        put("firmware", self.firmware.clone());
        put("profile", String::new());
    }

    fn diagnostics(&self, out: &mut Map<String, Value>) {
        out.insert("clock_state".into(), json!(self.clock_words()));
        out.insert("motor_rpm".into(), json!(self.rpm));
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}

impl SensorStream for RobosenseStream {
    fn push(
        &mut self,
        host_ns: i64,
        payload: &[u8],
        on_sweep: &mut OnSweep<'_>,
    ) -> Result<(), StreamError> {
        RobosenseStream::push(self, host_ns, payload, &mut |sw, f| on_sweep(sw, f))
            .map_err(StreamError::Decode)
    }

    fn finish(&mut self, on_sweep: &mut OnSweep<'_>) -> Result<(), StreamError> {
        RobosenseStream::finish(self, &mut |sw, f| on_sweep(sw, f));
        Ok(())
    }

    fn ready(&self) -> bool {
        // The M1 needs nothing beyond its packets.
        self.decoder().is_some() || RobosenseStream::facts(self).model == Some(RobosenseModel::M1)
    }

    fn facts(&self) -> &dyn Facts {
        RobosenseStream::facts(self)
    }

    fn summary(&self) -> (Value, PacketCounts) {
        let (st, f) = (self.stats(), RobosenseStream::facts(self));
        let counts = PacketCounts {
            decoded: st.packets,
            malformed: st.malformed,
            missing: st.missing,
            position: st.difop,
            // A copy is no loss: counted in the sensor's `duplicates` only; a late packet
            // dropped is.
            dropped: st.dropped.saturating_add(st.late_dropped),
        };
        let v = json!({
            "kind": "robosense",
            "model": f.model.map(|m| m.name()),
            "model_id": f.model.map(|m| m.id()),
            "detection": f.detection,
            "return_mode": f.return_mode_words(),
            "calibration": if f.calibration.is_empty() {
                "none yet (no DIFOP with a valid angle table, no angle file): packets held".to_string()
            } else {
                f.calibration.clone()
            },
            "motor_rpm": f.rpm,
            "fov_cdeg": f.fov,
            "serial": f.serial,
            "firmware": f.firmware,
            "protocol": f.protocol,
            "frame_rate": f.frame_rate,
            "temperature_c": f.temperature_c,
            "clock": f.clock.name(),
            "clock_state": f.clock_words(),
            "data_packets": st.packets,
            "difop_packets": st.difop,
            "difop_bad_angles": st.difop_bad_angles,
            "held": self.held(),
            "malformed": st.malformed,
            "missing": st.missing,
            "dropped": st.dropped,
            "late_dropped": st.late_dropped,
            "duplicates": st.duplicates,
            "discontinuities": st.discontinuities,
            "sweeps": st.sweeps,
            "points": st.points,
        });
        (v, counts)
    }

    fn is_lidar_datagram(&self, payload: &[u8]) -> bool {
        msop_shape(payload).is_some()
    }

    fn channels(&self) -> Option<usize> {
        RobosenseStream::facts(self)
            .model
            .map(RobosenseModel::lasers)
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}

#[cfg(test)]
mod tests {
    use super::super::model::ALL_MODELS;
    use super::*;

    #[test]
    fn model_names_are_the_models_ids() {
        let ids: Vec<&str> = ALL_MODELS.iter().map(|m| m.id()).collect();
        assert_eq!(ids, MODEL_IDS);
    }
}
