//! The Robosense simulator (`sensor::robosense::sim`) against the decoder, for every model in
//! single and dual return: a moving sensor (15 m/s, 60 °/s yaw) in the urban scene. Each
//! decoded point must lie within 1 cm of the scene point the simulator's ray hit (sensor frame
//! at its firing time, from the lens centre), carry that firing's time within 1 µs, its
//! intensity, return and ring (elevation rank); the stream — angles from the simulated DIFOP,
//! the packets before it held — must hand over every point once, with `t` ≥ 0 from its
//! sweep's first firing.
#![cfg(feature = "sim")]

mod common;

use std::collections::HashMap;

use nalgebra::{Isometry3, Vector3};
use ringscan::sensor::robosense::family::parse_robosense_calibration;
use ringscan::sensor::robosense::m1::{M1Decoder, M1Msop};
use ringscan::sensor::robosense::model::ALL_MODELS;
use ringscan::sensor::robosense::sim::{M1Sim, RobosenseSim, RobosenseTruth, M1_PACKETS_PER_S};
use ringscan::sensor::robosense::{
    Msop, RobosenseAngles, RobosenseConfig, RobosenseDecoder, RobosenseModel, RobosenseStream,
};
use ringscan::sensor::DecodeOptions;
use ringscan::sim::motion::Trajectory;
use ringscan::sim::scenes;

const T0: i64 = 1_714_564_800_000_000_000;

/// Synthetic angles in 0.01° steps (what a DIFOP can carry): interleaved elevations over the
/// model's field, horizontal offsets ±4°.
fn synthetic(model: RobosenseModel) -> RobosenseAngles {
    let n = model.lasers();
    if model == RobosenseModel::Rs16 {
        // The RS-16's DIFOP keeps lasers 0–7 below the horizon, 8–15 above.
        let s: String = (0..16)
            .map(|i| format!("{:.2},0\n", -15.0 + 2.0 * i as f64))
            .collect();
        return parse_robosense_calibration(s.as_bytes()).unwrap().unwrap();
    }
    let (top, span) = match model {
        RobosenseModel::Bpearl => (89.5, 89.0),
        RobosenseModel::Ruby128 => (15.0, 40.0),
        _ => (15.0, 30.0),
    };
    let s: String = (0..n)
        .map(|i| {
            // Alternate halves so that laser order is not elevation order.
            let k = if i % 2 == 0 { i / 2 } else { n / 2 + i / 2 };
            let v = ((top - span * k as f64 / (n - 1) as f64) * 100.0).round() / 100.0;
            let h = [-4.05, 3.61, -1.2, 0.0][i % 4];
            format!("{v:.2},{h}\n")
        })
        .collect();
    parse_robosense_calibration(s.as_bytes()).unwrap().unwrap()
}

fn helios16p() -> RobosenseAngles {
    let s: String = (0..16)
        .map(|i| {
            format!(
                "{:.2},{}\n",
                15.0 - 1.5 * i as f64,
                if i % 2 == 0 { -4.0 } else { 3.6 }
            )
        })
        .collect();
    parse_robosense_calibration(s.as_bytes()).unwrap().unwrap()
}

fn run(model: RobosenseModel, dual: bool) -> (usize, f64, i64) {
    let angles = if model == RobosenseModel::Helios16P {
        helios16p()
    } else {
        synthetic(model)
    };
    let scene = scenes::named("urban").unwrap();
    let mut sim = RobosenseSim::new(model, angles.clone(), T0);
    sim.dual = dual;
    sim.trajectory = Trajectory::twist(
        T0,
        Isometry3::translation(40.0, 0.0, scenes::SENSOR_HEIGHT_M),
        Vector3::new(15.0, 0.0, 0.0),
        Vector3::new(0.0, 0.0, 60f64.to_radians()),
    );
    let dec = RobosenseDecoder::new(model, &angles, DecodeOptions::default()).unwrap();
    let mut cfg = RobosenseConfig::new(None);
    cfg.model = Some(model);
    let mut stream = RobosenseStream::new(cfg);
    let ring_of = |l: usize| {
        angles
            .lasers
            .iter()
            .filter(|&&(v, _)| v < angles.lasers[l].0)
            .count() as u16
    };
    let (mut n, mut max_xyz, mut max_t) = (0usize, 0f64, 0i64);
    let mut expected_times = Vec::new();
    let mut streamed = Vec::new();
    let mut on_sweep = |sw: &mut ringscan::sweep::Sweep, _: &_| {
        for p in &sw.points {
            streamed.push(sw.device_time_ns + i64::from(p.t));
        }
    };
    let packets = (150_000_000.0 / model.spec().packet_period_ns(dual)) as usize;
    for k in 0..packets {
        // The DIFOP after a few packets: those before it are held.
        if k == 5 {
            stream.push(0, &sim.difop(), &mut on_sweep).unwrap();
        }
        let mut truth: Vec<RobosenseTruth> = Vec::new();
        let stamp = sim.stamp_of(sim.packet_index);
        let (host, bytes) = sim.next_packet(&scene, &mut truth);
        let by_key: HashMap<(usize, usize), RobosenseTruth> =
            truth.iter().map(|t| ((t.block, t.slot), *t)).collect();
        assert_eq!(by_key.len(), truth.len());
        let m = Msop::new(&bytes, model).unwrap();
        let mut seen = 0;
        dec.decode(&m, dual, |d| {
            let t = by_key.get(&(d.block, d.slot)).unwrap_or_else(|| {
                panic!(
                    "{model:?} packet {k}: no truth for block {} slot {}",
                    d.block, d.slot
                )
            });
            seen += 1;
            let p = d.point;
            let e = ((f64::from(p.x) - t.xyz[0]).powi(2)
                + (f64::from(p.y) - t.xyz[1]).powi(2)
                + (f64::from(p.z) - t.xyz[2]).powi(2))
            .sqrt();
            assert!(
                e < 0.01,
                "{model:?} dual {dual} packet {k} block {} slot {}: {e} m",
                d.block,
                d.slot
            );
            let dt = (stamp + d.offset_ns - t.time_ns).abs();
            assert!(dt < 1_000, "{model:?}: time off by {dt} ns");
            assert_eq!(p.intensity, f32::from(t.intensity));
            assert_eq!(p.ret, t.ret, "{model:?} block {} slot {}", d.block, d.slot);
            assert_eq!(p.ring, ring_of(model.laser_of_slot(d.slot)));
            max_xyz = max_xyz.max(e);
            max_t = max_t.max(dt);
            expected_times.push(t.time_ns);
        });
        assert_eq!(
            seen,
            truth.len(),
            "{model:?} packet {k}: every return decoded once"
        );
        n += seen;
        stream.push(host, &bytes, &mut on_sweep).unwrap();
    }
    stream.finish(&mut on_sweep);
    assert_eq!(stream.stats().dropped, 0);
    assert_eq!(stream.facts().calibration, "DIFOP");
    assert_eq!(
        streamed.len(),
        expected_times.len(),
        "{model:?}: the stream hands every point once"
    );
    for (a, b) in streamed.iter().zip(&expected_times) {
        assert!((a - b).abs() < 1_000, "{model:?}: stream time {a} vs {b}");
    }
    assert!(stream.stats().sweeps >= 1);
    assert_eq!(stream.stats().missing, 0);
    (n, max_xyz, max_t)
}

#[test]
fn every_model_single_and_dual_within_1cm_and_1us() {
    // The M1 has its own simulator and test (`m1_within_1cm_and_1us`).
    for m in ALL_MODELS.into_iter().filter(|&m| m != RobosenseModel::M1) {
        for dual in [false, true] {
            let (n, e, t) = run(m, dual);
            println!(
                "{:>14} dual {dual:5}: {n:7} points, max xyz {:.2} mm, max time {t} ns",
                m.name(),
                e * 1e3
            );
            assert!(n > 1000, "{m:?}: only {n} points");
        }
    }
}

/// The M1 simulator against the M1 decoder and stream: a moving sensor (15 m/s, 60 °/s yaw) in
/// the urban scene, 0.35 s (three frames and a half). Every decoded point within 1 cm of the
/// scene point the ray hit (sensor frame at its firing time), its time within 1 µs, intensity
/// and channel exact; the stream, with the DIFOP only after 100 packets (the M1 must not wait
/// for it), hands every point over once, in sweeps that are the sensor's frames (630 packets
/// each, cut where the counter restarts), with nothing missing.
#[test]
fn m1_within_1cm_and_1us() {
    let scene = scenes::named("urban").unwrap();
    let mut sim = M1Sim::new(T0);
    sim.trajectory = Trajectory::twist(
        T0,
        Isometry3::translation(40.0, 0.0, scenes::SENSOR_HEIGHT_M),
        Vector3::new(15.0, 0.0, 0.0),
        Vector3::new(0.0, 0.0, 60f64.to_radians()),
    );
    let dec = M1Decoder::new(DecodeOptions::default());
    let mut stream = RobosenseStream::new(RobosenseConfig::new(None));
    let mut sweeps: Vec<(i64, usize, u32)> = Vec::new();
    let mut streamed = Vec::new();
    let mut on_sweep = |sw: &mut ringscan::sweep::Sweep,
                        f: &ringscan::sensor::robosense::RobosenseFacts| {
        assert_eq!(f.model, Some(RobosenseModel::M1));
        for p in &sw.points {
            streamed.push((sw.device_time_ns + i64::from(p.t), p.ring));
        }
        sweeps.push((sw.device_time_ns, sw.points.len(), sw.packets));
    };
    let packets = M1_PACKETS_PER_S as usize * 35 / 100;
    let (mut n, mut max_xyz, mut max_t) = (0usize, 0f64, 0i64);
    let mut expected = Vec::new();
    for k in 0..packets {
        if k == 100 {
            stream.push(0, &sim.difop(), &mut on_sweep).unwrap();
        }
        let mut truth: Vec<RobosenseTruth> = Vec::new();
        let stamp = sim.stamp_of(sim.packet_index);
        let (host, bytes) = sim.next_packet(&scene, &mut truth);
        let by_key: HashMap<(usize, usize), RobosenseTruth> =
            truth.iter().map(|t| ((t.block, t.slot), *t)).collect();
        let m = M1Msop::new(&bytes).unwrap();
        assert_eq!(m.seq() as usize, k % 630 + 1);
        assert_eq!(m.stamp_ns(), Some(stamp));
        let mut seen = 0;
        dec.decode(&m, |d| {
            let t = by_key
                .get(&(d.block, d.channel))
                .unwrap_or_else(|| panic!("packet {k}: no truth for {} {}", d.block, d.channel));
            seen += 1;
            let p = d.point;
            let e = ((f64::from(p.x) - t.xyz[0]).powi(2)
                + (f64::from(p.y) - t.xyz[1]).powi(2)
                + (f64::from(p.z) - t.xyz[2]).powi(2))
            .sqrt();
            assert!(
                e < 0.01,
                "packet {k} block {} channel {}: {e} m",
                d.block,
                d.channel
            );
            let dt = (stamp + d.offset_ns - t.time_ns).abs();
            assert!(dt < 1_000, "time off by {dt} ns");
            assert_eq!(p.intensity, f32::from(t.intensity));
            assert_eq!((p.ring, p.ret), (d.channel as u16, 0));
            max_xyz = max_xyz.max(e);
            max_t = max_t.max(dt);
            expected.push((t.time_ns, d.channel as u16));
        });
        assert_eq!(seen, truth.len(), "packet {k}: every return decoded once");
        n += seen;
        stream.push(host, &bytes, &mut on_sweep).unwrap();
        if k < 100 {
            assert_eq!(stream.held(), 0, "an M1 packet never waits for a DIFOP");
        }
    }
    stream.finish(&mut on_sweep);
    println!(
        "RS-LiDAR-M1: {n} points in {packets} packets, max xyz {:.3} mm, max time {max_t} ns",
        max_xyz * 1e3
    );
    assert!(n > packets * 125 / 2, "only {n} points");
    let st = stream.stats();
    assert_eq!(
        (st.packets as usize, st.missing, st.dropped, st.malformed),
        (packets, 0, 0, 0)
    );
    assert_eq!(st.difop, 1);
    assert_eq!(stream.facts().serial, "314253647586");
    assert_eq!(
        streamed.len(),
        expected.len(),
        "the stream hands every point once"
    );
    for (a, b) in streamed.iter().zip(&expected) {
        assert!(
            (a.0 - b.0).abs() < 1_000 && a.1 == b.1,
            "stream {a:?} vs {b:?}"
        );
    }
    // Frames of 630 packets, each starting at its first packet's time (100 ms apart); the last
    // one is the half frame the capture ends in.
    assert_eq!(sweeps.len(), 4);
    for (i, &(t0, _, pk)) in sweeps.iter().enumerate() {
        assert_eq!(t0, T0 + i as i64 * 100_000_000);
        assert_eq!(pk as usize, if i < 3 { 630 } else { packets - 3 * 630 });
    }
}

/// A capture time at either end of `i64` (an MCAP log time of 2^64 − 1 read as i64::MAX, a
/// pcapng interface whose negative `if_tsoffset` saturates to i64::MIN): every model's stream
/// (the DIFOP first, then a sweep and more of packets) decodes on without overflowing its time
/// arithmetic, and does not call such a host clock synchronised with the header's. (Debug
/// builds check overflow: the old code panicked here.)
#[test]
fn host_times_at_the_ends_of_i64_do_not_overflow() {
    let scene = scenes::named("urban").unwrap();
    for model in ALL_MODELS {
        let mut packets = Vec::new();
        if model == RobosenseModel::M1 {
            let mut sim = M1Sim::new(T0);
            for _ in 0..700 {
                packets.push(sim.next_packet(&scene, &mut Vec::new()).1);
            }
        } else {
            let mut sim = RobosenseSim::new(model, synthetic(model), T0);
            packets.push(sim.difop());
            let n = (150_000_000.0 / model.spec().packet_period_ns(false)) as usize;
            for _ in 0..n {
                packets.push(sim.next_packet(&scene, &mut Vec::new()).1);
            }
        }
        for host in [i64::MAX, i64::MIN, i64::MAX - 1_000] {
            let mut cfg = RobosenseConfig::new(None);
            cfg.model = Some(model);
            let mut stream = RobosenseStream::new(cfg);
            let mut points = 0usize;
            let mut on_sweep = |sw: &mut ringscan::sweep::Sweep, _: &_| points += sw.points.len();
            for p in &packets {
                stream.push(host, p, &mut on_sweep).unwrap();
            }
            stream.finish(&mut on_sweep);
            assert_eq!(stream.stats().malformed, 0, "{model:?} at host time {host}");
            assert!(points > 0, "{model:?} at host time {host}");
            assert_eq!(
                stream.facts().clock_synchronised,
                Some(false),
                "{model:?} at host time {host}"
            );
        }
    }
}

/// Packets lost for most of a turn, or for more than one, within the stream's gap limit (1 s):
/// the azimuth step across the loss can be three quarters of a turn or more, which alone reads
/// as a block out of order; the time between the packets tells the turn. Every sweep still
/// ends at the cut, so none holds more than one turn (a missed cut gave one of 1.8 turns), and
/// every point decoded is handed over once.
#[test]
fn a_loss_of_most_of_a_turn_or_more_still_cuts_every_turn() {
    let scene = scenes::named("urban").unwrap();
    let turn_ns: i64 = 100_000_000; // 600 rpm
    for model in [
        RobosenseModel::Rs32,
        RobosenseModel::Helios,
        RobosenseModel::Ruby128,
    ] {
        for (from_deg, turns) in [(9.0, 0.81), (350.0, 0.8), (100.0, 1.3), (200.0, 0.76)] {
            let mut sim = RobosenseSim::new(model, synthetic(model), T0);
            let lost_from = T0 + turn_ns + (from_deg / 360.0 * turn_ns as f64) as i64;
            let lost_to = lost_from + (turns * turn_ns as f64) as i64;
            let mut cfg = RobosenseConfig::new(None);
            cfg.model = Some(model);
            let mut stream = RobosenseStream::new(cfg);
            stream.push(0, &sim.difop(), &mut |_, _| {}).unwrap();
            let n = (4.0 * turn_ns as f64 / model.spec().packet_period_ns(false)) as usize;
            let packets: Vec<common::SimPacket> = (0..n)
                .map(|_| {
                    let t = sim.stamp_of(sim.packet_index);
                    let mut truth = Vec::new();
                    let (host, bytes) = sim.next_packet(&scene, &mut truth);
                    (t, host, bytes, truth.len())
                })
                .collect();
            common::check_a_loss(
                &mut stream,
                &packets,
                lost_from..lost_to,
                turn_ns * 11 / 10,
                &format!("{model:?}, {turns} turn lost from {from_deg}°"),
            );
        }
    }
}

/// Packets reordered on the way (one a place late, one three places late): each fills the gap
/// counted when its successor came (by header time: these packets carry no counter), so
/// nothing is missing, the stream goes on (no discontinuity, which closed the open sweep
/// mid-turn), and the sweeps are those of the stream in order. So are those of a run where two
/// packets came twice (one right behind itself, one three packets late): the copies, which
/// share a header time with their packet, are counted and dropped.
#[test]
fn reordered_packets_are_late_not_lost() {
    let scene = scenes::named("urban").unwrap();
    for model in [
        RobosenseModel::Rs32,
        RobosenseModel::Helios,
        RobosenseModel::Ruby128,
    ] {
        let mut sim = RobosenseSim::new(model, synthetic(model), T0);
        let difop = sim.difop();
        let n = (300_000_000.0 / model.spec().packet_period_ns(false)) as usize;
        let packets: Vec<(i64, Vec<u8>)> = (0..n)
            .map(|_| sim.next_packet(&scene, &mut Vec::new()))
            .collect();
        let run = |order: &[usize]| {
            let mut cfg = RobosenseConfig::new(None);
            cfg.model = Some(model);
            // The DIFOP first (the angles), then the packets in `order`.
            let mut stream = RobosenseStream::new(cfg);
            stream.push(0, &difop, &mut |_, _| {}).unwrap();
            common::run_stream(&mut stream, &packets, order)
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

/// A DIFOP that comes before any MSOP, with no model named, is kept and read again when the
/// first MSOP tells the model: counted once (found by the `family_stream` fuzz target: it
/// was counted at each reading).
#[test]
fn a_difop_before_the_first_packet_is_counted_once() {
    let scene = scenes::named("urban").unwrap();
    let model = RobosenseModel::Helios;
    let mut sim = RobosenseSim::new(model, synthetic(model), T0);
    let difop = sim.difop();
    let (host, msop) = sim.next_packet(&scene, &mut Vec::new());
    let mut stream = RobosenseStream::new(RobosenseConfig::new(None));
    stream.push(0, &difop, &mut |_, _| {}).unwrap();
    stream.push(host, &msop, &mut |_, _| {}).unwrap();
    stream.finish(&mut |_, _| {});
    let st = stream.stats();
    assert_eq!((st.difop, st.malformed, st.packets), (1, 0, 1), "{st:?}");
}
