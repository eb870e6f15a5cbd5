//! The Hesai simulator (`sensor::hesai::sim`) against the decoder, for every model: a moving
//! sensor (15 m/s, 60 °/s yaw) in the urban scene, range noise off. Each decoded point must lie
//! within 1 cm of the scene point the simulator's ray hit (sensor frame at its firing time) and
//! carry that firing's time within 1 µs; the stream must hand over every point once, with
//! `t` ≥ 0 from its sweep's first firing. Single return for every model, dual (last +
//! strongest) for the models that send it. Corrections: a synthetic CSV (elevations spread over
//! the model's field, azimuth offsets up to ±6°), a synthetic AT128 `.dat` and ATX `.dat`
//! (version x.3: per-frame azimuths, elevation adjustment); the real shared files too when
//! `../shared` is present. The ATX's sweeps are its frames.
#![cfg(feature = "sim")]

mod common;

use nalgebra::{Isometry3, Vector3};
use ringscan::sensor::hesai::family::parse_hesai_calibration;
use ringscan::sensor::hesai::model::ALL_MODELS;
use ringscan::sensor::hesai::sim::{HesaiSim, HesaiTruth};
use ringscan::sensor::hesai::{
    HesaiCalibration, HesaiConfig, HesaiDecoder, HesaiModel, HesaiOptions, HesaiPacket, HesaiStream,
};
use ringscan::sim::motion::Trajectory;
use ringscan::sim::scenes;

const T0: i64 = 1_714_564_800_000_000_000;
const CALIB: &str = "tier4__nebula/src/nebula_hesai/nebula_hesai_decoders/calibration";

fn synthetic(model: HesaiModel) -> HesaiCalibration {
    let n = model.channels();
    if model == HesaiModel::PandarAtx {
        // Version x.3, 100 channels in 1/256°: azimuths ±2° (odd frames 0.05° more),
        // elevations 12.5° … −12.5°, an elevation adjustment of ±0.2° along the azimuth.
        let div = 256.0;
        let mut b = vec![0xEE, 0xFF, 4, 3, 0, 0, 100];
        b.extend_from_slice(&256u16.to_le_bytes());
        let mut put = |v: f64| b.extend_from_slice(&((v * div).round() as i16).to_le_bytes());
        for odd in [0.0, 0.05] {
            for c in 0..100 {
                put(((c % 4) as f64 - 2.0) + odd);
            }
        }
        for c in 0..100 {
            put(12.5 - 25.0 * c as f64 / 99.0);
        }
        for i in 0..70 {
            put(0.2 * ((i % 10) as f64 - 5.0) / 5.0);
        }
        b.extend_from_slice(&[0u8; 32]);
        return parse_hesai_calibration(&b).unwrap().unwrap();
    }
    if model == HesaiModel::PandarAt128 {
        let mut b = vec![0u8; 16 + 24 + 1024 + 46080 + 32];
        b[..7].copy_from_slice(&[0xEE, 0xFF, 1, 5, 128, 3, 3]);
        b[15] = 1;
        for m in 0..3usize {
            // Mirror m: encoder (m·120° − 15°) … (m·120° + 105°); output 2·(a − start).
            let s = ((m as i64 * 120 - 15).rem_euclid(360) * 25_600) as u32;
            let e = ((m as i64 * 120 + 105).rem_euclid(360) * 25_600) as u32;
            b[16 + 4 * m..20 + 4 * m].copy_from_slice(&s.to_le_bytes());
            b[28 + 4 * m..32 + 4 * m].copy_from_slice(&e.to_le_bytes());
        }
        for c in 0..128usize {
            let az = ((c % 4) as i32 - 2) * 25_600; // ±2°
            let el = ((12.5 - 25.0 * c as f64 / 127.0) * 25_600.0) as i32;
            b[40 + 4 * c..44 + 4 * c].copy_from_slice(&az.to_le_bytes());
            b[552 + 4 * c..556 + 4 * c].copy_from_slice(&el.to_le_bytes());
        }
        // Azimuth adjustments: a gentle ramp over the encoder angle.
        for c in 0..128usize {
            for i in 0..180usize {
                b[1064 + c * 180 + i] = ((i % 20) as i8 - 10) as u8;
            }
        }
        return parse_hesai_calibration(&b).unwrap().unwrap();
    }
    let mut s = String::from("Laser id,Elevation,Azimuth\n");
    for i in 0..n {
        let el = 15.0 - 40.0 * i as f64 / n as f64;
        let az = [-6.0, -1.042, 0.0, 3.125][i % 4];
        s.push_str(&format!("{},{el:.4},{az}\n", i + 1));
    }
    parse_hesai_calibration(s.as_bytes()).unwrap().unwrap()
}

fn real(model: HesaiModel) -> Option<(HesaiCalibration, &'static str)> {
    let file = match model {
        HesaiModel::Pandar40P => "Pandar40P.csv",
        HesaiModel::Pandar64 => "Pandar64.csv",
        HesaiModel::PandarQt64 => "PandarQT64.csv",
        HesaiModel::PandarQt128 => "PandarQT128.csv",
        HesaiModel::PandarXt16 => "PandarXT16.csv",
        HesaiModel::PandarXt32 => "PandarXT32.csv",
        HesaiModel::PandarXt32m => "PandarXT32M.csv",
        HesaiModel::PandarAt128 => "PandarAT128.dat",
        HesaiModel::PandarOt128 => "Pandar128E4X.csv",
        // No ATX correction is shared.
        HesaiModel::PandarAtx => return None,
    };
    let root = common::captures()?;
    let b = std::fs::read(root.join(CALIB).join(file)).ok()?;
    Some((parse_hesai_calibration(&b)?.ok()?, file))
}

#[derive(Default, Debug)]
struct Figures {
    points: usize,
    max_xyz_m: f64,
    max_t_ns: i64,
    sweeps: u64,
}

fn run(model: HesaiModel, calib: HesaiCalibration, mode: u8) -> Figures {
    let scene = scenes::named("urban").unwrap();
    let mut sim = HesaiSim::new(model, calib.clone(), T0);
    sim.return_mode = mode;
    sim.trajectory = Trajectory::twist(
        T0,
        Isometry3::translation(40.0, 0.0, scenes::SENSOR_HEIGHT_M),
        Vector3::new(15.0, 0.0, 0.0),
        Vector3::new(0.0, 0.0, 60f64.to_radians()),
    );
    let mut dec = HesaiDecoder::new(model, &calib, HesaiOptions::default()).unwrap();
    let mut cfg = HesaiConfig::new(Some(calib), "sim");
    cfg.model = Some(model);
    let mut stream = HesaiStream::new(cfg);
    let mut fig = Figures::default();
    let mut streamed = 0usize;
    let mut sweep_azimuths = Vec::new();
    // Every block azimuth sent, in 0.01° from the layouts' units (AT128: 1/25 600°, ATX:
    // 1/256°, the rest 0.01°): a sweep's first and last azimuth must be among them.
    let mut block_cdeg = std::collections::HashSet::new();
    let mut on_sweep = |sw: &mut ringscan::sweep::Sweep, _: &_| {
        streamed += sw.points.len();
        sweep_azimuths.push((sw.first_azimuth, sw.last_azimuth));
        for p in &sw.points {
            assert!(i64::from(p.t) < 200_000_000, "t {} ns", p.t);
        }
    };
    // A little over one sweep (AT128: one mirror field and more).
    let packets = (120_000_000 / sim.period_ns()) as usize;
    let mut total_truth = 0usize;
    for _ in 0..packets {
        let mut truth: Vec<HesaiTruth> = Vec::new();
        let (host, bytes) = sim.next_packet(&scene, &mut truth);
        total_truth += truth.len();
        let p = HesaiPacket::new(&bytes, model).unwrap();
        assert_eq!(HesaiModel::detect(&bytes), Some(model));
        let stamp = p.stamp_ns().unwrap();
        for b in 0..p.layout().blocks {
            let raw = u64::from(p.azimuth(b));
            block_cdeg.insert(match model {
                HesaiModel::PandarAt128 => raw / 256 % 36_000,
                HesaiModel::PandarAtx => raw * 100 / 256 % 36_000,
                _ => raw % 36_000,
            });
        }
        let t0 = stamp - 1_000_000;
        let mut pts = Vec::new();
        dec.decode_packet(&p, stamp, t0, &mut pts).unwrap();
        assert_eq!(
            pts.len(),
            truth.len(),
            "{model:?} packet {}",
            sim.packet_index
        );
        for (pt, tr) in pts.iter().zip(&truth) {
            let d = [
                f64::from(pt.x) - tr.xyz[0],
                f64::from(pt.y) - tr.xyz[1],
                f64::from(pt.z) - tr.xyz[2],
            ];
            let e = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            fig.max_xyz_m = fig.max_xyz_m.max(e);
            let dt = (t0 + i64::from(pt.t) - tr.time_ns).abs();
            fig.max_t_ns = fig.max_t_ns.max(dt);
            assert_eq!(pt.ret, tr.ret, "{model:?}");
            assert_eq!(pt.intensity, f32::from(tr.reflectivity));
            assert_eq!(pt.ring, dec.ring(tr.channel));
        }
        fig.points += pts.len();
        stream.push(host, &bytes, &mut on_sweep).unwrap();
    }
    stream.finish(&mut on_sweep);
    assert_eq!(
        streamed, total_truth,
        "{model:?}: every point handed over once"
    );
    assert_eq!(stream.stats().missing, 0);
    assert_eq!(stream.stats().malformed, 0);
    for (first, last) in sweep_azimuths {
        assert!(
            block_cdeg.contains(&u64::from(first)) && block_cdeg.contains(&u64::from(last)),
            "{model:?}: sweep azimuths {first}, {last} (0.01°) are no block's"
        );
    }
    fig.sweeps = stream.stats().sweeps;
    fig
}

fn check(label: &str, fig: &Figures) {
    println!(
        "{label:<34} {:>8} points, {:>2} sweeps, max |Δxyz| {:.2e} m, max |Δt| {} ns",
        fig.points, fig.sweeps, fig.max_xyz_m, fig.max_t_ns
    );
    assert!(fig.points > 1_000, "{label}: only {} points", fig.points);
    assert!(fig.max_xyz_m <= 0.01, "{label}: {} m", fig.max_xyz_m);
    assert!(fig.max_t_ns <= 1_000, "{label}: {} ns", fig.max_t_ns);
    // 0.12 s: one turn and a bit (AT128: one mirror field and a bit), so at most 3 sweeps.
    assert!(
        (2..=3).contains(&fig.sweeps),
        "{label}: {} sweeps",
        fig.sweeps
    );
}

#[test]
fn every_model_decodes_back_to_the_truth() {
    for model in ALL_MODELS {
        let fig = run(model, synthetic(model), 0x37);
        check(&format!("{} synthetic, strongest", model.name()), &fig);
        if let Some((calib, file)) = real(model) {
            let fig = run(model, calib, 0x37);
            check(&format!("{} {file}, strongest", model.name()), &fig);
        }
    }
}

#[test]
fn dual_return_models_decode_back_to_the_truth() {
    for model in [
        HesaiModel::Pandar40P,
        HesaiModel::Pandar64,
        HesaiModel::PandarQt64,
        HesaiModel::PandarQt128,
        HesaiModel::PandarXt32,
        HesaiModel::PandarOt128,
        HesaiModel::PandarAtx,
    ] {
        let fig = run(model, synthetic(model), 0x39);
        check(&format!("{} synthetic, last+strongest", model.name()), &fig);
    }
}

/// Packets lost for most of a turn, or for more than one, within the stream's gap limit (1 s):
/// the azimuth step across the loss can be three quarters of a turn or more, which alone reads
/// as blocks out of order; the time between the packets tells the turn. Every sweep still
/// ends at the cut, so none holds more than one turn (a missed cut gave one of 1.8 turns), and
/// every point decoded is handed over once.
#[test]
fn a_loss_of_most_of_a_turn_or_more_still_cuts_every_turn() {
    let scene = scenes::named("urban").unwrap();
    for model in [
        HesaiModel::PandarXt32,
        HesaiModel::Pandar64,
        HesaiModel::PandarQt128,
    ] {
        // (azimuth where the loss starts, turns lost): 600 rpm, a turn is 100 ms.
        for (from_deg, turns) in [(9.0, 0.81), (200.0, 0.9), (100.0, 1.3), (350.0, 0.76)] {
            let mut sim = HesaiSim::new(model, synthetic(model), T0);
            let period = sim.period_ns();
            let turn_ns: i64 = 100_000_000;
            let lost_from = T0 + turn_ns + (from_deg / 360.0 * turn_ns as f64) as i64;
            let lost_to = lost_from + (turns * turn_ns as f64) as i64;
            let packets: Vec<common::SimPacket> = (0..4 * turn_ns / period)
                .map(|k| {
                    let mut truth = Vec::new();
                    let (host, bytes) = sim.next_packet(&scene, &mut truth);
                    (T0 + k * period, host, bytes, truth.len())
                })
                .collect();
            let mut cfg = HesaiConfig::new(Some(synthetic(model)), "sim");
            cfg.model = Some(model);
            // One turn, and the spread of the channels' azimuth offsets (±6°: 3.3 ms) that
            // cuts each channel at its own time.
            common::check_a_loss(
                &mut HesaiStream::new(cfg),
                &packets,
                lost_from..lost_to,
                turn_ns * 11 / 10,
                &format!("{model:?}, {turns} turn lost from {from_deg}°"),
            );
        }
    }
}

/// Packets reordered on the way (one a place late, one three places late): each fills the gap
/// counted when its successor came, so nothing is missing, the stream goes on (no
/// discontinuity, which closed the open sweeps mid-turn), and the sweeps are those of the
/// stream in order. By UDP sequence number (XT32, QT128) and by tail time (Pandar40P, Pandar64).
/// So are those of a run where two packets came twice, one right behind itself and one three
/// packets late: the copies are counted and dropped (they were decoded again before).
#[test]
fn reordered_packets_are_late_not_lost() {
    let scene = scenes::named("urban").unwrap();
    for model in [
        HesaiModel::PandarXt32,
        HesaiModel::PandarQt128,
        HesaiModel::Pandar40P,
        HesaiModel::Pandar64,
    ] {
        let mut sim = HesaiSim::new(model, synthetic(model), T0);
        let n = (300_000_000 / sim.period_ns()) as usize;
        let packets: Vec<(i64, Vec<u8>)> = (0..n)
            .map(|_| sim.next_packet(&scene, &mut Vec::new()))
            .collect();
        let run = |order: &[usize]| {
            let mut cfg = HesaiConfig::new(Some(synthetic(model)), "sim");
            cfg.model = Some(model);
            common::run_stream(&mut HesaiStream::new(cfg), &packets, order)
        };
        // Away from the cuts (a turn is n / 3 packets).
        let all: Vec<usize> = (0..n).collect();
        let (in_order, _, _, _) = run(&all);
        let (reordered, missing, discontinuities, _) = run(&common::reordered(n, &all));
        assert_eq!((missing, discontinuities), (0, 0), "{model:?}");
        assert_eq!(
            reordered, in_order,
            "{model:?}: (points, packets) per sweep"
        );
        // Two packets sent twice: the copies are dropped and counted, not added again.
        let (copied, missing, discontinuities, copies) = run(&common::with_copies(n, &all));
        assert_eq!((missing, discontinuities, copies), (0, 0, 2), "{model:?}");
        assert_eq!(copied, in_order, "{model:?}: (points, packets) per sweep");
    }
}

/// A sequence number that stands still (a sensor that leaves the field at one value) repeats
/// numbers, not packets: a copy is a packet whose tail time is seen again too, so nothing is
/// dropped and the sweeps are those of the run with counting numbers. (Counting numbers alone,
/// every packet after the first was a copy.)
#[test]
fn a_sequence_number_that_stands_still_is_no_copy() {
    let scene = scenes::named("urban").unwrap();
    let model = HesaiModel::PandarXt32;
    let mut sim = HesaiSim::new(model, synthetic(model), T0);
    let n = (300_000_000 / sim.period_ns()) as usize;
    let packets: Vec<(i64, Vec<u8>)> = (0..n)
        .map(|_| sim.next_packet(&scene, &mut Vec::new()))
        .collect();
    // XT32 tail: the sequence number at offset 24 (no CRC over it).
    let at = model.spec().layout.tail_start() + 24;
    let stuck: Vec<(i64, Vec<u8>)> = packets
        .iter()
        .map(|(h, b)| {
            let mut b = b.clone();
            b[at..at + 4].copy_from_slice(&7u32.to_le_bytes());
            (*h, b)
        })
        .collect();
    let run = |packets: &[(i64, Vec<u8>)]| {
        let mut cfg = HesaiConfig::new(Some(synthetic(model)), "sim");
        cfg.model = Some(model);
        common::run_stream(
            &mut HesaiStream::new(cfg),
            packets,
            &(0..n).collect::<Vec<_>>(),
        )
    };
    let (counting, ..) = run(&packets);
    let (standing, missing, discontinuities, copies) = run(&stuck);
    assert_eq!((missing, discontinuities, copies), (0, 0, 0));
    assert_eq!(standing, counting);
}
