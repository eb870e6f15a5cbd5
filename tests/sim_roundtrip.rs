//! Simulated scenes → packets → decoder, checked against the scene's geometry.
//!
//! The simulator fires each laser at its datasheet time and azimuth and casts it into a known
//! room; the decoder must put every point back on the surface it hit: within 1 cm + range ·
//! sin(0.005°) (block azimuths are rounded to 0.01° on the wire, so the decoder's interpolated
//! azimuth can be off by half a step), with the right ring, return, time and intensity.

use ringscan::sensor::velodyne::calib::builtin::builtin;
use ringscan::sensor::velodyne::calib::LaserCalibration;
use ringscan::sensor::velodyne::calib::VelodyneCalibration;
use ringscan::sensor::velodyne::model::ALL_MODELS;
use ringscan::sensor::velodyne::sim::Truth;
use ringscan::sensor::velodyne::sim::VelodyneSim;
use ringscan::sensor::velodyne::wire::DataPacket;
use ringscan::sensor::velodyne::ReturnMode;
use ringscan::sensor::velodyne::VelodyneDecoder;
use ringscan::sensor::velodyne::VelodyneModel;
use ringscan::sensor::DecodeOptions;
use ringscan::sim::scene::Shapes;
use std::collections::HashMap;

const SIN_0005_DEG: f64 = 8.726_646e-5;

/// An angles-only table for models without a built-in one (HDL-64E, VLS-128): evenly spread
/// elevations from −24.9° to +2°, interleaved so ring ≠ laser id.
fn spread(n: usize) -> VelodyneCalibration {
    let lasers = (0..n)
        .map(|i| {
            let k = if i % 2 == 0 { i / 2 } else { n / 2 + i / 2 };
            let deg = -24.9 + 26.9 * k as f64 / (n - 1) as f64;
            LaserCalibration::angles(
                i as u16,
                deg.to_radians(),
                ((i % 4) as f64 - 1.5).to_radians() * 0.5,
            )
        })
        .collect();
    VelodyneCalibration {
        lasers,
        distance_resolution: None,
        advanced: false,
        source: "test spread".into(),
    }
    .validate()
    .unwrap()
}

fn calibration(model: VelodyneModel) -> VelodyneCalibration {
    builtin(model).unwrap_or_else(|| spread(model.lasers()))
}

fn roundtrip(model: VelodyneModel, mode: ReturnMode, packets: usize) -> (usize, f64) {
    let calib = calibration(model);
    let scene = Shapes::room(12.0, 9.0, 1.8, 4.0);
    let mut sim = VelodyneSim::new(model, mode, calib.clone(), 1_700_000_000_000_000_000);
    sim.azimuth0_deg = 123.4;
    sim.toh0_us = 3_599_990_000; // crosses the hour
    let dec = VelodyneDecoder::new(model, mode, &calib, DecodeOptions::default()).unwrap();
    let rings = calib.rings();
    let mut checked = 0usize;
    let mut worst_excess = f64::NEG_INFINITY;
    for _ in 0..packets {
        let mut truth: Vec<Truth> = Vec::new();
        let (_, bytes) = sim.next_packet(&scene, &mut truth);
        let p = DataPacket::new(&bytes).unwrap();
        dec.check_layout(&p).unwrap();
        let mut pts = Vec::new();
        let n = dec.decode(&p, 0, &mut pts);
        assert_eq!(
            n.points,
            truth.len(),
            "{model} {mode}: every measurement decodes to one point"
        );
        // Key by (firing time, ring, return): unique per measurement.
        let by_key: HashMap<(u32, u16, u8), &Truth> = truth
            .iter()
            .map(|t| ((t.t_ns.round() as u32, rings[t.laser], t.ret), t))
            .collect();
        for pt in &pts {
            let t = by_key
                .get(&(pt.t, pt.ring, pt.ret))
                .unwrap_or_else(|| panic!("{model} {mode}: no truth for point {pt:?}"));
            let d = ((f64::from(pt.x) - t.xyz[0]).powi(2)
                + (f64::from(pt.y) - t.xyz[1]).powi(2)
                + (f64::from(pt.z) - t.xyz[2]).powi(2))
            .sqrt();
            let allowed = 0.01 + t.range * SIN_0005_DEG;
            assert!(
                d <= allowed,
                "{model} {mode}: point off by {d} m (allowed {allowed}) at range {}",
                t.range
            );
            assert_eq!(pt.intensity, f32::from(t.reflectivity));
            worst_excess = worst_excess.max(d - allowed);
            checked += 1;
        }
    }
    (checked, worst_excess)
}

#[test]
fn every_model_and_return_mode_round_trips_through_the_scene() {
    for model in ALL_MODELS {
        if model.is_hdl64() {
            continue; // HDL-64E corrections: tests/hdl64e.rs
        }
        for mode in [ReturnMode::Strongest, ReturnMode::Last, ReturnMode::Dual] {
            if !model.supports(mode) {
                continue;
            }
            let (n, _) = roundtrip(model, mode, 40);
            assert!(n > 40 * 200, "{model} {mode}: only {n} points checked");
        }
    }
}

#[test]
fn hdl64e_angles_only_round_trips() {
    for model in [VelodyneModel::Hdl64eS2, VelodyneModel::Hdl64eS3] {
        for mode in [ReturnMode::Strongest, ReturnMode::Dual] {
            let (n, _) = roundtrip(model, mode, 40);
            assert!(n > 40 * 200, "{model} {mode}: only {n} points checked");
        }
    }
}
