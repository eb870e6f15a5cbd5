//! Simulated scenes → packets → decoder, checked against the scene's geometry.
//!
//! The simulator fires each laser at its datasheet time and azimuth and casts it into a known
//! room; the decoder must put every point back on the surface it hit: within 1 cm + range ·
//! sin(0.005°) (block azimuths are rounded to 0.01° on the wire, so the decoder's interpolated
//! azimuth can be off by half a step), with the right ring, return, time and intensity.

use ringscan::sensor::velodyne::calib::builtin::builtin;
use ringscan::sensor::velodyne::calib::LaserCalibration;
use ringscan::sensor::velodyne::calib::VelodyneCalibration;
use ringscan::sensor::velodyne::decode::ColumnRate;
use ringscan::sensor::velodyne::model::ALL_MODELS;
use ringscan::sensor::velodyne::sim::Truth;
use ringscan::sensor::velodyne::sim::VelodyneSim;
use ringscan::sensor::velodyne::wire::DataPacket;
use ringscan::sensor::velodyne::ReturnMode;
use ringscan::sensor::velodyne::VelodyneDecoder;
use ringscan::sensor::velodyne::VelodyneModel;
use ringscan::sensor::velodyne::{StreamConfig, VelodyneStream};
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
    // One-column packets (VLS-128 dual) take the rotation rate from the packet before: the
    // first packet is decoded only for that.
    let mut rate = ColumnRate::default();
    let warm_up = usize::from(dec.needs_rate());
    for i in 0..packets + warm_up {
        let mut truth: Vec<Truth> = Vec::new();
        let (_, bytes) = sim.next_packet(&scene, &mut truth);
        let p = DataPacket::new(&bytes).unwrap();
        dec.check_layout(&p).unwrap();
        let r = rate.next(&dec, &p);
        if i < warm_up {
            continue;
        }
        let mut pts = Vec::new();
        let n = dec.decode_with_rate(&p, 0..12, 0, r, |pt, _| pts.push(pt));
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
            // 40 packets, or as many as hold 40 of three columns (VLS-128 dual: one a packet).
            let packets = (120 / model.columns_per_packet(mode).max(1)).max(40);
            let (n, _) = roundtrip(model, mode, packets);
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

/// The stream (what `decode` and `listen` run) hands one-column packets (VLS-128 dual) the
/// rotation rate of the packet before, as the decoder checked above against the truth: the
/// same points, bit for bit, as packet-by-packet decoding with `ColumnRate`. Without the
/// rate, every point but those of each packet's first firing group would move.
#[test]
fn vls128_dual_stream_rotates_each_column_by_the_rate_of_the_packet_before() {
    let (model, mode) = (VelodyneModel::Vls128, ReturnMode::Dual);
    let calib = calibration(model);
    let scene = Shapes::room(12.0, 9.0, 1.8, 4.0);
    let mut sim = VelodyneSim::new(model, mode, calib.clone(), 1_700_000_000_000_000_000);
    let dec = VelodyneDecoder::new(model, mode, &calib, DecodeOptions::default()).unwrap();
    let mut stream = VelodyneStream::new(StreamConfig {
        model: Some(model),
        calibrations: vec![calib.clone()],
        ..StreamConfig::default()
    });
    let (mut from_stream, mut direct) = (Vec::new(), Vec::new());
    let mut rate = ColumnRate::default();
    let key = |p: &ringscan::point::Point| (p.x.to_bits(), p.y.to_bits(), p.z.to_bits(), p.ret);
    // A turn and a half: sweeps are cut inside the run.
    for _ in 0..2_800 {
        let mut truth = Vec::new();
        let (host, bytes) = sim.next_packet(&scene, &mut truth);
        let p = DataPacket::new(&bytes).unwrap();
        let r = rate.next(&dec, &p);
        dec.decode_with_rate(&p, 0..12, 0, r, |pt, _| direct.push(key(&pt)));
        stream
            .push(host, &bytes, &mut |s, _| {
                from_stream.extend(s.points.iter().map(key))
            })
            .unwrap();
    }
    stream
        .finish(&mut |s, _| from_stream.extend(s.points.iter().map(key)))
        .unwrap();
    assert_eq!(stream.stats().sweeps, 2, "{:?}", stream.stats());
    assert!(direct.len() > 300_000, "{}", direct.len());
    from_stream.sort_unstable();
    direct.sort_unstable();
    assert!(
        from_stream == direct,
        "the stream's points are not the decoder's"
    );
}
