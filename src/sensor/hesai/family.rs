//! The Hesai family behind ringscan's sensor interface ([`crate::sensor`]).
//!
//! A Hesai sensor is told from its first datagram alone, never from a file name: the `EE FF`
//! pre-header with a protocol version and laser / block counts that name a model, the Pandar64's
//! 8-byte header, or the Pandar40P's ten `FF EE` blocks in 1262 (or 1266) bytes — Velodyne's
//! data packets, which also start `FF EE` and also go to port 2368, are 1206 bytes. The family
//! is asked before Velodyne, whose calibration parser takes any text: the Hesai CSV is
//! recognised by its header line only.

use std::any::Any;
use std::collections::BTreeMap;
use std::net::Ipv4Addr;
use std::sync::Arc;

use serde_json::{json, Map, Value};

use super::at128::{looks_like_dat, At128Correction};
use super::atx::{looks_like_atx_dat, looks_like_firetimes_csv, AtxCorrection, AtxFiretimes};
use super::calib::{parse_csv, HesaiCalibration};
use super::model::{HesaiModel, ALL_MODELS, SIGNATURE_LEN};
use super::sweep::{return_mode_words, HesaiConfig, HesaiFacts, HesaiStream};
use super::wire::HesaiPacket;
use crate::sensor::{
    summary_str, CalibError, Calibration, CalibrationPool, Claimed, Facts, Family, FirstDatagram,
    OnSweep, PacketCounts, SensorStream, StreamError,
};

/// The Hesai family.
#[derive(Clone, Copy, Debug, Default)]
pub struct Hesai;

const MODEL_IDS: &[&str] = &[
    "pandar40p",
    "pandar64",
    "pandarqt64",
    "pandarqt128",
    "pandarxt16",
    "pandarxt32",
    "pandarxt32m",
    "pandarat128",
    "pandarot128",
    "pandaratx",
];

/// Reads a Hesai correction: the AT128 `.dat` by its `EE FF 01` start, the ATX `.dat` by `EE FF`
/// and a minor version 1–3 after another major, the ATX firetime CSV and the angle CSV by their
/// header lines; `None` for anything else.
pub fn parse_hesai_calibration(bytes: &[u8]) -> Option<Result<HesaiCalibration, CalibError>> {
    if looks_like_atx_dat(bytes) {
        return Some(AtxCorrection::parse(bytes).map(HesaiCalibration::Atx));
    }
    if looks_like_dat(bytes) {
        return Some(At128Correction::parse(bytes).map(HesaiCalibration::At128));
    }
    let text = core::str::from_utf8(bytes).ok()?;
    if looks_like_firetimes_csv(text) {
        return Some(AtxFiretimes::parse_csv(text).map(HesaiCalibration::AtxFiretimes));
    }
    parse_csv(text).map(|r| r.map(HesaiCalibration::Csv))
}

impl Family for Hesai {
    fn name(&self) -> &'static str {
        "hesai"
    }

    fn models(&self) -> &'static [&'static str] {
        MODEL_IDS
    }

    fn parse_calibration(
        &self,
        bytes: &[u8],
        _file_name: &str,
    ) -> Option<Result<Arc<dyn Any + Send + Sync>, CalibError>> {
        parse_hesai_calibration(bytes).map(|r| r.map(|c| Arc::new(c) as Arc<dyn Any + Send + Sync>))
    }

    /// Point-cloud packets to 2368 (the PTC control port 9347 is TCP).
    fn default_ports(&self) -> &'static [u16] {
        &[2368]
    }

    fn lidar_sizes(&self, _calibs: &[Calibration]) -> Vec<usize> {
        let mut v = Vec::new();
        // The ATX's lengths follow its header's counts: not a fixed list.
        for m in ALL_MODELS
            .into_iter()
            .filter(|m| !m.spec().layout.counts_from_header)
        {
            let l = &m.spec().layout;
            v.push(l.base_len());
            if l.trailing_udp_seq {
                v.push(l.base_len() + 4);
            }
            if l.signature {
                v.push(l.base_len() + SIGNATURE_LEN);
            }
        }
        v.sort_unstable();
        v.dedup();
        v
    }

    /// The ATX: its length follows its header's laser and block counts.
    fn is_header_sized_lidar(&self, payload: &[u8]) -> bool {
        HesaiModel::detect(payload) == Some(HesaiModel::PandarAtx)
    }

    /// A datagram whose bytes name a Hesai model ([`HesaiModel::detect`]), or that fits the
    /// model named with `--model`. The first Hesai correction with the model's channel count
    /// (bound to this address, or unbound and unused) serves it; without one the stream reads
    /// the packets but decodes no points.
    fn claim(&self, d: &FirstDatagram<'_>, pool: &mut CalibrationPool) -> Option<Claimed> {
        let named = match pool.settings.model.as_deref() {
            None => None,
            Some(m) => Some(HesaiModel::from_id(m)?),
        };
        let first = named.map(|m| (m, HesaiPacket::new(d.payload, m)));
        let (model, packet) = match first {
            Some((m, Ok(p))) => (m, Some(p)),
            Some((_, Err(_))) => return None,
            None => {
                let m = HesaiModel::detect(d.payload)?;
                (m, HesaiPacket::new(d.payload, m).ok())
            }
        };
        // The laser count its packets carry: the ATX's header gives its own.
        let lasers = packet.map_or(model.channels(), |p| p.layout().channels);
        let fits = |c: &HesaiCalibration| match c {
            HesaiCalibration::At128(_) => model == HesaiModel::PandarAt128,
            HesaiCalibration::Atx(a) => model == HesaiModel::PandarAtx && a.channels() == lasers,
            // Joins the ATX's angle correction below.
            HesaiCalibration::AtxFiretimes(_) => false,
            HesaiCalibration::Csv(_) => {
                c.channels() == model.channels()
                    && !matches!(model, HesaiModel::PandarAt128 | HesaiModel::PandarAtx)
            }
        };
        let found = pool
            .candidates(self.name(), d.src, true)
            .find(|(_, c)| c.get::<HesaiCalibration>().is_some_and(fits))
            .map(|(i, c)| (i, c.clone()));
        let (mut calibration, mut files) = match found {
            Some((i, c)) => {
                pool.mark_used(i);
                (
                    c.get::<HesaiCalibration>().cloned(),
                    vec![c.file_name.clone()],
                )
            }
            None => (None, Vec::new()),
        };
        // An ATX angle correction takes a firetime CSV of its channel count along.
        if let Some(HesaiCalibration::Atx(a)) = &calibration {
            let firetimes = pool
                .candidates(self.name(), d.src, true)
                .find(|(_, c)| {
                    matches!(c.get::<HesaiCalibration>(),
                        Some(HesaiCalibration::AtxFiretimes(f)) if f.channels() == a.channels())
                })
                .and_then(|(i, c)| match c.get::<HesaiCalibration>() {
                    Some(HesaiCalibration::AtxFiretimes(f)) => {
                        Some((i, f.clone(), c.file_name.clone()))
                    }
                    _ => None,
                });
            if let Some((i, f, file)) = firetimes {
                if let Ok(joined) = a.clone().with_firetimes(f) {
                    pool.mark_used(i);
                    calibration = Some(HesaiCalibration::Atx(joined));
                    files.push(file);
                }
            }
        }
        let s = &pool.settings;
        let mut cfg = HesaiConfig::new(calibration, &files.join(" + "));
        cfg.calibration_files = files;
        cfg.model = named;
        cfg.options.range = s.decode;
        cfg.cut_cdeg = Some(u32::from(s.cut_angle));
        if let Some(on) = s.crc {
            cfg.check_crc = on;
        }
        if let Some(t) = s.dual_return_threshold_m {
            cfg.options.dual_return_threshold_m = t;
        }
        cfg.options.fov_cdeg = s.fov_cdeg;
        cfg.inspect = s.inspect;
        Some(Ok(Box::new(HesaiStream::new(cfg))))
    }

    fn describe(&self, s: &Value) -> Vec<String> {
        let st = |k: &str| summary_str(&s[k]);
        let g = |v: &Value| v.as_u64().unwrap_or(0);
        let mut out = Vec::with_capacity(4);
        out.push(format!(
            "  {}, ports {}: Hesai {}, protocol {}, {}; {}",
            crate::sensor::heading(s),
            s["ports"],
            s["model"].as_str().unwrap_or(crate::sensor::UNKNOWN_MODEL),
            match (&s["model"], s["protocol"].as_str()) {
                (Value::Null, _) => "-",
                (_, p) => p.unwrap_or("none (no pre-header)"),
            },
            st("return_mode"),
            st("detection")
        ));
        out.push(format!(
            "    {} packets, {} sweeps, {} points; missing {}, malformed {} (CRC failures {}), discontinuities {}, duplicates {}, late dropped {}, signed {}",
            g(&s["data_packets"]),
            g(&s["sweeps"]),
            g(&s["points"]),
            g(&s["missing"]),
            g(&s["malformed"]),
            g(&s["crc_failures"]),
            g(&s["discontinuities"]),
            g(&s["duplicates"]),
            g(&s["late_dropped"]),
            g(&s["signed_packets"])
        ));
        out.push(format!("    packets per port: {}", s["packets_per_port"]));
        out.push(format!(
            "    calibration: {}; clock: {} ({}); CRC: {}; functional safety: {}",
            st("calibration"),
            st("clock_state"),
            st("clock"),
            st("crc"),
            match (
                s["functional_safety"].is_null(),
                g(&s["safety_crc_failures"])
            ) {
                (true, 0) => "none in these packets".to_string(),
                (true, n) => format!("all {n} blocks failed their CRC (ignored)"),
                (false, 0) => format!("{} (CRC ok)", s["functional_safety"]),
                (false, n) => format!(
                    "{}; {n} blocks failed their CRC (ignored)",
                    s["functional_safety"]
                ),
            }
        ));
        out
    }
}

impl Facts for HesaiFacts {
    fn family(&self) -> &'static str {
        "hesai"
    }

    fn default_name(&self, addr: Ipv4Addr) -> String {
        match self.model {
            Some(m) => format!("{}-{}", m.id(), addr.octets()[3]),
            None => format!("hesai-{}", addr.octets()[3]),
        }
    }

    fn calibration_name(&self) -> &str {
        &self.calibration
    }

    fn calibration_files(&self) -> Vec<&str> {
        self.calibration_files.iter().map(String::as_str).collect()
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
            "protocol",
            self.protocol
                .map(|(a, b)| format!("{a}.{b}"))
                .unwrap_or_default(),
        );
        put(
            "return_mode",
            self.return_mode.map(return_mode_words).unwrap_or_default(),
        );
        put("model_detection", self.detection.clone());
        put("clock", self.clock.name().to_string());
        put("clock_state", self.clock_state().to_string());
        put("crc", self.crc.name().to_string());
        put("calibration", self.calibration.clone());
        put("serial", String::new());
        put("firmware", String::new());
        put("profile", String::new());
    }

    fn diagnostics(&self, out: &mut Map<String, Value>) {
        out.insert("clock_state".into(), json!(self.clock_state()));
        out.insert("motor_rpm".into(), json!(self.motor_rpm));
        out.insert("functional_safety".into(), safety_json(self));
        out.insert("shutdown_flag".into(), json!(self.shutdown_flag));
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}

fn safety_json(f: &HesaiFacts) -> Value {
    match f.safety {
        None => Value::Null,
        Some(s) => json!({
            "lidar_state": s.lidar_state,
            "fault_code_type": s.fault_code_type,
            "fault_code": s.fault_code,
            "total_fault_codes": s.total_fault_codes,
            "rolling_counter": s.rolling_counter,
        }),
    }
}

impl SensorStream for HesaiStream {
    fn push(
        &mut self,
        host_ns: i64,
        payload: &[u8],
        on_sweep: &mut OnSweep<'_>,
    ) -> Result<(), StreamError> {
        HesaiStream::push(self, host_ns, payload, &mut |sw, f| on_sweep(sw, f))
            .map_err(StreamError::Decode)?;
        match self.missing_calibration() {
            Some(m) => Err(StreamError::NeedsCalibration(
                m.name(),
                " (the sensor serves its angle correction: `ringscan hesai-calib --sensor IP --out \
                 FILE`, or `listen --hesai-ptc`)",
            )),
            None => Ok(()),
        }
    }

    fn finish(&mut self, on_sweep: &mut OnSweep<'_>) -> Result<(), StreamError> {
        HesaiStream::finish(self, &mut |sw, f| on_sweep(sw, f));
        Ok(())
    }

    fn ready(&self) -> bool {
        self.decoder().is_some()
    }

    fn facts(&self) -> &dyn Facts {
        HesaiStream::facts(self)
    }

    fn summary(&self) -> (Value, PacketCounts) {
        let (st, f) = (self.stats(), HesaiStream::facts(self));
        let counts = PacketCounts {
            decoded: st.packets,
            malformed: st.malformed,
            missing: st.missing,
            position: 0,
            // A copy is no loss (the sensor's `duplicates` only); a late packet dropped is.
            dropped: st.late_dropped,
        };
        let v = json!({
            "kind": "hesai",
            "model": f.model.map(|m| m.name()),
            "model_id": f.model.map(|m| m.id()),
            "protocol": f.protocol.map(|(a, b)| format!("{a}.{b}")),
            "return_mode": f.return_mode.map(return_mode_words),
            "detection": f.detection,
            "calibration": if f.calibration.is_empty() {
                "none (give the angle-correction file with --calib: no points decoded)".to_string()
            } else {
                f.calibration.clone()
            },
            "dis_unit_mm": f.dis_unit_mm,
            "motor_rpm": f.motor_rpm,
            "clock": f.clock.name(),
            "clock_state": f.clock_state(),
            "crc": f.crc.name(),
            "crc_ok": st.crc_ok,
            "crc_failures": st.crc_failures,
            "crc_tail_failures": st.crc_tail_failures,
            "signed_packets": st.signed,
            "functional_safety": safety_json(f),
            "safety_not_normal": st.safety_not_normal,
            "safety_crc_failures": st.safety_crc_failures,
            "data_packets": st.packets,
            "position_packets": 0,
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
        match HesaiStream::facts(self).model {
            Some(m) => m.accepts(payload),
            None => HesaiModel::detect(payload).is_some(),
        }
    }

    fn channels(&self) -> Option<usize> {
        // The ATX's count is its correction's (= its packets' laser count).
        self.decoder()
            .map(|d| d.channels())
            .or_else(|| HesaiStream::facts(self).model.map(HesaiModel::channels))
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

    #[test]
    fn velodyne_yaml_is_not_hesai() {
        assert!(parse_hesai_calibration(b"lasers:\n - {laser_id: 0}\n").is_none());
        assert!(parse_hesai_calibration(b"{\"beam_intrinsics\": {}}").is_none());
    }
}
