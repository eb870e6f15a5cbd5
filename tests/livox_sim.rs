//! The Livox simulator (`sensor::livox::sim`) against the decoder: a MID-360 and a HAP (SDK2,
//! data types 1, 2 and 3) and an Avia (SDK1, data type 2) moving along the urban route in the urban
//! scene. Every decoded point must lie within its data type's unit of the scene point the
//! simulator's ray hit (sensor frame at its measurement time: 1 mm for type 1 and spherical
//! depth, 1 cm for type 2), carry that measurement's time within 1 µs, its line and its
//! reflectivity; the stream hands over every point once, in sweeps of the integration period.
//! The IMU samples decoded equal the simulated motion (gyro and specific force of the IMU
//! frame at its published position), to the f32 precision the packets carry.
#![cfg(feature = "sim")]

mod common;

use ringscan::sensor::livox::model::LivoxModel;
use ringscan::sensor::livox::sim::{ImuTruth, LivoxSim, LivoxTruth};
use ringscan::sensor::livox::{LivoxConfig, LivoxStream};
use ringscan::sensor::ImuSample;
use ringscan::sim::motion::{Route, Trajectory};
use ringscan::sim::scenes;
use ringscan::sweep::Sweep;

const T0: i64 = 1_714_564_800_000_000_000;

fn simulate(
    model: LivoxModel,
    data_type: u8,
    seconds: f64,
) -> (
    Vec<Sweep>,
    Vec<LivoxTruth>,
    Vec<ImuSample>,
    Vec<ImuTruth>,
    LivoxStream,
) {
    let world = scenes::urban();
    let mut sim = LivoxSim::new(model, T0);
    sim.data_type = data_type;
    sim.trajectory = Trajectory::route(T0, Route::urban());
    let (mut truth, mut imu_truth) = (Vec::new(), Vec::new());
    let packets = sim.run_until(
        &world,
        T0 + (seconds * 1e9) as i64,
        &mut truth,
        &mut imu_truth,
    );
    let mut s = LivoxStream::new(LivoxConfig::new(Some(model), model.protocol()));
    let mut sweeps = Vec::new();
    let mut imu = Vec::new();
    for (host, _port, b) in &packets {
        s.push(*host, b, &mut |sw, _| sweeps.push(sw.clone()));
        imu.extend(s.drain_imu());
    }
    s.finish(&mut |sw, _| sweeps.push(sw.clone()));
    (sweeps, truth, imu, imu_truth, s)
}

fn check_points(model: LivoxModel, data_type: u8, unit_m: f64) {
    let (sweeps, truth, _, _, s) = simulate(model, data_type, 0.35);
    assert_eq!(s.stats().malformed, 0);
    assert_eq!(s.stats().missing, 0);
    let n: usize = sweeps.iter().map(|w| w.points.len()).sum();
    assert!(n > 10_000, "{model:?} type {data_type}: only {n} points");
    assert_eq!(
        n,
        truth.len(),
        "{model:?} type {data_type}: every return once"
    );
    // 0.35 s in 100 ms sweeps: 4 sweeps (the last one partial).
    assert_eq!(sweeps.len(), 4, "{model:?}");
    let mut k = 0;
    let mut worst = 0.0f64;
    for w in &sweeps {
        assert!(w
            .points
            .iter()
            .all(|p| u64::from(p.t) < 100_000_000 + 500_000));
        for p in &w.points {
            let t = &truth[k];
            k += 1;
            for (a, b) in [p.x, p.y, p.z].iter().zip(t.xyz) {
                let e = (f64::from(*a) - b).abs();
                worst = worst.max(e);
                // Half a unit of rounding, plus f32 resolution (and the f32 trig of
                // spherical records) at the point's range.
                let range = t.xyz.iter().map(|c| c * c).sum::<f64>().sqrt();
                assert!(
                    e <= unit_m / 2.0 + 1e-6 * range + 1e-6,
                    "{model:?} type {data_type}: {p:?} vs {t:?}"
                );
            }
            let when = w.device_time_ns + i64::from(p.t);
            assert!(
                (when - t.time_ns).abs() <= 1_000,
                "{model:?}: time {when} vs {}",
                t.time_ns
            );
            assert_eq!(p.ring, t.line);
            assert_eq!(p.intensity, f32::from(t.reflectivity));
        }
    }
    assert!(
        worst <= unit_m,
        "{model:?} type {data_type}: worst {worst} m"
    );
    let (v, _) = ringscan::sensor::SensorStream::summary(&s);
    let mean = v["point_density"]["points_per_sweep_mean"]
        .as_f64()
        .unwrap();
    assert!(mean > 0.0);
}

#[test]
fn mid360_type1_within_1mm() {
    check_points(LivoxModel::Mid360, 1, 0.001);
}

#[test]
fn mid360_type2_within_1cm() {
    check_points(LivoxModel::Mid360, 2, 0.01);
}

#[test]
fn mid360_spherical_within_1mm() {
    check_points(LivoxModel::Mid360, 3, 0.001);
}

#[test]
fn hap_type1_within_1mm() {
    check_points(LivoxModel::Hap, 1, 0.001);
}

#[test]
fn hap_type2_within_1cm() {
    check_points(LivoxModel::Hap, 2, 0.01);
}

#[test]
fn hap_spherical_within_1mm() {
    check_points(LivoxModel::Hap, 3, 0.001);
}

/// The HAP's published field of view (120° × 25°), six lines, and its point rate: 452 000
/// points/s in the datasheet, 2220 ns a record here (450 450 /s), 96 records a packet.
#[test]
fn hap_point_rate_lines_and_field_of_view() {
    let (sweeps, truth, _, _, s) = simulate(LivoxModel::Hap, 1, 0.35);
    // 0.35 s / (96 × 2220 ns) = 1642.3 packets.
    let packets = s.stats().packets;
    assert!(
        (1641..=1643).contains(&packets),
        "{packets} packets in 0.35 s"
    );
    let mut lines = [0usize; 6];
    for t in &truth {
        let [x, y, z] = t.xyz;
        let az = y.atan2(x).to_degrees();
        let el = z.atan2((x * x + y * y).sqrt()).to_degrees();
        assert!((-60.01..=60.01).contains(&az), "azimuth {az}");
        assert!((-12.51..=12.51).contains(&el), "elevation {el}");
        lines[usize::from(t.line)] += 1;
    }
    assert!(lines.iter().all(|&n| n > truth.len() / 12), "{lines:?}");
    let rate = truth.len() as f64 / 0.35;
    assert!(rate > 100_000.0, "{rate} returns/s");
    assert!(sweeps.iter().all(|w| w.missing_packets == 0));
}

#[test]
fn avia_sdk1_within_1mm() {
    check_points(LivoxModel::Avia, 2, 0.001);
}

#[test]
fn mid360_point_rate_and_field_of_view() {
    let (sweeps, truth, _, _, s) = simulate(LivoxModel::Mid360, 1, 0.35);
    // 200 000 points/s in 96-point packets: 480 µs a packet.
    let packets = s.stats().packets;
    assert!(
        (728..=730).contains(&packets),
        "{packets} packets in 0.35 s"
    );
    for t in &truth {
        let [x, y, z] = t.xyz;
        let el = z.atan2((x * x + y * y).sqrt()).to_degrees();
        assert!((-7.01..=52.01).contains(&el), "elevation {el}");
    }
    assert!(sweeps.iter().all(|w| w.missing_packets == 0));
}

#[test]
fn imu_samples_equal_the_simulated_motion() {
    for model in [LivoxModel::Mid360, LivoxModel::Hap, LivoxModel::Avia] {
        let (_, _, imu, truth, _) = simulate(model, 1, 0.35);
        assert_eq!(imu.len(), truth.len(), "{model:?}");
        assert!(imu.len() >= 70, "{model:?}: 200 Hz");
        for (s, t) in imu.iter().zip(&truth) {
            assert_eq!(s.sensor_ns as i64, t.time_ns);
            for k in 0..3 {
                // The packet carries f32: equal to the f32 of the truth.
                let eg = (s.gyro[k] - t.gyro[k]).abs();
                assert!(
                    eg <= 1e-6 * t.gyro[k].abs() + 1e-7,
                    "{model:?} gyro {s:?} vs {t:?}"
                );
                let ea = (s.accel[k] - t.accel[k]).abs();
                assert!(
                    ea <= 1e-6 * t.accel[k].abs() + 1e-5,
                    "{model:?} accel {s:?} vs {t:?}"
                );
            }
        }
    }
}

/// MID-360 driving at 15 m/s while turning at 60 °/s in the urban scene: one 100 ms sweep,
/// deskewed to its start with the IMU samples the stream decoded (gyro, rotated by the
/// model's published IMU-to-lidar transform) and the forward speed, against the truth's world
/// points. As for Ouster (`tests/deskew_truth.rs`): p99 within 2 cm, and over 0.5 m without.
#[test]
fn mid360_imu_deskew_meets_2_cm() {
    use nalgebra::{Isometry3, Point3, Vector3};
    use ringscan::deskew::{Deskewer, ImuTrack, Reference};
    let world = scenes::urban();
    let mut sim = LivoxSim::new(LivoxModel::Mid360, T0);
    sim.trajectory = Trajectory::twist(
        T0,
        Isometry3::translation(40.0, 0.0, scenes::SENSOR_HEIGHT_M),
        Vector3::new(15.0, 0.0, 0.0),
        Vector3::new(0.0, 0.0, 60f64.to_radians()),
    );
    let (mut truth, mut imu_truth) = (Vec::new(), Vec::new());
    let packets = sim.run_until(&world, T0 + 350_000_000, &mut truth, &mut imu_truth);
    let mut s = LivoxStream::new(LivoxConfig::new(
        Some(LivoxModel::Mid360),
        LivoxModel::Mid360.protocol(),
    ));
    let mut sweeps = Vec::new();
    let mut track = ImuTrack::from_imu_to_sensor(&LivoxModel::Mid360.imu_to_sensor());
    for (host, _, b) in &packets {
        s.push(*host, b, &mut |sw, _| sweeps.push(sw.clone()));
        for smp in s.drain_imu() {
            track.push(smp.sensor_ns as i64, smp.gyro);
        }
    }
    let offset = sweeps[0].points.len();
    let sw = &sweeps[1];
    let truth = &truth[offset..offset + sw.points.len()];
    assert!(sw.points.len() > 8_000, "{} points", sw.points.len());
    // The sweep's first point is on the simulator's clock (PTP time type).
    let pose = sim.trajectory.pose(sw.device_time_ns);
    let errors = |pts: &[ringscan::point::Point]| {
        let mut d: Vec<f64> = pts
            .iter()
            .zip(truth)
            .map(|(p, t)| {
                let q = pose * Point3::new(f64::from(p.x), f64::from(p.y), f64::from(p.z));
                (q.coords - Vector3::from(t.world)).norm()
            })
            .collect();
        d.sort_by(f64::total_cmp);
        let at = |f: f64| d[((d.len() - 1) as f64 * f).round() as usize];
        (at(0.5), at(0.99))
    };
    let none = errors(&sw.points);
    let mut pts = sw.points.clone();
    Deskewer::new(Reference::Start)
        .deskew_imu(
            &mut pts,
            sw.device_time_ns,
            &track,
            &Vector3::new(15.0, 0.0, 0.0),
        )
        .unwrap();
    let got = errors(&pts);
    eprintln!(
        "MID-360 IMU: deskewed median {:.2} mm, p99 {:.2} mm; without median {:.1} mm, p99 {:.1} mm",
        got.0 * 1e3,
        got.1 * 1e3,
        none.0 * 1e3,
        none.1 * 1e3
    );
    assert!(got.1 <= 0.02, "p99 {} m", got.1);
    assert!(none.1 > 0.5, "the motion must matter without deskew");
}

/// The sweeps a stream hands over, with the newest IMU sample time drained before each, for
/// the datagrams in the order given (the caller drains the IMU after every push, as `decode`
/// and `listen` do).
fn sweeps_and_imu_seen(packets: &[(i64, u16, Vec<u8>)]) -> (Vec<(Sweep, i64)>, LivoxStream) {
    let mut s = LivoxStream::new(LivoxConfig::new(
        Some(LivoxModel::Mid360),
        LivoxModel::Mid360.protocol(),
    ));
    let mut newest = i64::MIN;
    let mut out = Vec::new();
    for (host, _, b) in packets {
        s.push(*host, b, &mut |sw, _| out.push((sw.clone(), newest)));
        for smp in s.drain_imu() {
            newest = smp.sensor_ns as i64;
        }
    }
    s.finish(&mut |sw, _| out.push((sw.clone(), newest)));
    (out, s)
}

/// Live, the IMU packets (their own port) can reach the host after point packets sent later.
/// Whether they come in the capture's order or each 3 ms late, every sweep is handed over
/// only once an IMU sample at or after its last point has been drained, and the sweeps are
/// the same; without IMU packets at all nothing waits; when the IMU stops, a sweep waits at
/// most until the next one is finished (counted), and none is lost.
#[test]
fn mid360_sweeps_wait_for_the_imu_samples_that_cover_them() {
    let world = scenes::urban();
    let mut sim = LivoxSim::new(LivoxModel::Mid360, T0);
    sim.trajectory = Trajectory::route(T0, Route::urban());
    let (mut truth, mut imu_truth) = (Vec::new(), Vec::new());
    let packets = sim.run_until(&world, T0 + 450_000_000, &mut truth, &mut imu_truth);
    let imu_port = LivoxModel::Mid360.imu_port().unwrap();
    let mut late = packets.clone();
    for p in late.iter_mut().filter(|p| p.1 == imu_port) {
        p.0 += 3_000_000;
    }
    late.sort_by_key(|p| p.0);
    let (in_order, s1) = sweeps_and_imu_seen(&packets);
    let (delayed, s2) = sweeps_and_imu_seen(&late);
    assert_eq!(in_order.len(), 5);
    assert_eq!(delayed.len(), in_order.len());
    // The last sweep is handed over by `finish`, when the run ends before its IMU sample.
    let last = in_order.len() - 1;
    for (k, ((a, seen_a), (b, seen_b))) in in_order.iter().zip(&delayed).enumerate() {
        let end = a.device_time_ns + a.points.iter().map(|p| i64::from(p.t)).max().unwrap();
        assert!(
            k == last || (*seen_a >= end && *seen_b >= end),
            "sweep {k}: IMU up to {seen_a} / {seen_b}, last point {end}"
        );
        assert_eq!(a.index, b.index);
        assert_eq!(a.points, b.points);
    }
    assert_eq!(s1.stats().imu_uncovered_sweeps, 0);
    assert_eq!(s2.stats().imu_uncovered_sweeps, 0);

    // No IMU: each sweep is handed over by the packet that cuts it.
    let points_only: Vec<_> = packets
        .iter()
        .filter(|p| p.1 != imu_port)
        .cloned()
        .collect();
    let (no_imu, _) = sweeps_and_imu_seen(&points_only);
    assert_eq!(no_imu.len(), 5);
    assert!(no_imu.iter().all(|(_, seen)| *seen == i64::MIN));

    // The IMU stops after 150 ms: sweeps 1.. are handed over uncovered, none lost.
    let stopped: Vec<_> = packets
        .iter()
        .filter(|p| p.1 != imu_port || p.0 < T0 + 150_000_000)
        .cloned()
        .collect();
    let (partial, s3) = sweeps_and_imu_seen(&stopped);
    assert_eq!(partial.len(), 5);
    let n: usize = partial.iter().map(|(w, _)| w.points.len()).sum();
    assert_eq!(n, truth.len());
    // Sweep 4 (the last, open at the end) is handed over by `finish`, not counted.
    assert_eq!(s3.stats().imu_uncovered_sweeps, 3);
}

/// Point packets reordered on the way (one a place late, one three places late): each fills
/// the gap counted when its successor came (SDK2 by `udp_cnt`, SDK1 by time), so nothing is
/// missing, no discontinuity cuts a sweep early, and the sweeps are those of the stream in
/// order. So are those of a run where two point packets came twice (one right behind itself,
/// one three packets late): the copies, by `udp_cnt` or by time, are counted and dropped.
#[test]
fn reordered_packets_are_late_not_lost() {
    let world = scenes::urban();
    for model in [LivoxModel::Mid360, LivoxModel::Avia] {
        let mut sim = LivoxSim::new(model, T0);
        sim.trajectory = Trajectory::route(T0, Route::urban());
        let packets = sim.run_until(&world, T0 + 350_000_000, &mut Vec::new(), &mut Vec::new());
        // The point packets' port (the IMU's packets go to another).
        let mut ports = std::collections::HashMap::new();
        for (_, port, _) in &packets {
            *ports.entry(*port).or_insert(0usize) += 1;
        }
        let point_port = ports.into_iter().max_by_key(|&(_, n)| n).unwrap().0;
        let at: Vec<usize> = (0..packets.len())
            .filter(|&i| packets[i].1 == point_port)
            .collect();
        let packets: Vec<(i64, Vec<u8>)> = packets.into_iter().map(|(h, _, b)| (h, b)).collect();
        let run = |order: &[usize]| {
            let mut s = LivoxStream::new(LivoxConfig::new(Some(model), model.protocol()));
            common::run_stream(&mut s, &packets, order)
        };
        let (in_order, _, _, _) = run(&(0..packets.len()).collect::<Vec<_>>());
        let (reordered, missing, discontinuities, _) = run(&common::reordered(packets.len(), &at));
        assert_eq!((missing, discontinuities), (0, 0), "{model:?}");
        assert_eq!(
            reordered, in_order,
            "{model:?}: (points, packets) per sweep"
        );
        // Two point packets sent twice: the copies are dropped and counted.
        let (copied, missing, discontinuities, copies) =
            run(&common::with_copies(packets.len(), &at));
        assert_eq!((missing, discontinuities, copies), (0, 0, 2), "{model:?}");
        assert_eq!(copied, in_order, "{model:?}: (points, packets) per sweep");
    }
}

/// Rewrites an SDK2 packet's `udp_cnt` and `frame_cnt` (header bytes 7–9, outside the CRC).
fn set_counters(b: &mut [u8], udp: u16, frame: u8) {
    b[7..9].copy_from_slice(&udp.to_le_bytes());
    b[9] = frame;
}

/// A simulated MID-360 run of `ns` with its point packets' and IMU packets' `udp_cnt` given by
/// `point_cnt(k)` and `imu_cnt(k)` for the k-th of each; `(host, is_imu, payload)`.
fn mid360_with_counters(
    ns: i64,
    point_cnt: impl Fn(usize) -> (u16, u8),
    imu_cnt: impl Fn(usize) -> u16,
    model: LivoxModel,
) -> Vec<(i64, bool, Vec<u8>)> {
    let world = scenes::urban();
    let mut sim = LivoxSim::new(model, T0);
    sim.trajectory = Trajectory::route(T0, Route::urban());
    let imu_port = model.imu_port().unwrap();
    let (mut kp, mut ki) = (0, 0);
    sim.run_until(&world, T0 + ns, &mut Vec::new(), &mut Vec::new())
        .into_iter()
        .map(|(host, port, mut b)| {
            let imu = port == imu_port;
            if imu {
                set_counters(&mut b, imu_cnt(ki), 0);
                ki += 1;
            } else {
                let (u, f) = point_cnt(kp);
                set_counters(&mut b, u, f);
                kp += 1;
            }
            (host, imu, b)
        })
        .collect()
}

/// `udp_cnt` wraps from 65535 to 0 (the MID-360 counts on across its frames): a packet lost
/// just before the wrap is as lost as any other, for the point and the IMU counters. (The wrap
/// read as a frame start, which counts no loss: 0 and 0 before.)
#[test]
fn a_loss_at_the_counter_wrap_is_counted() {
    // 0.12 s: 250 point packets wrapping at the 100th, 24 IMU packets wrapping at the 10th.
    let packets = mid360_with_counters(
        120_000_000,
        |k| ((k as u16).wrapping_add(65_436), 0),
        |k| (k as u16).wrapping_add(65_526),
        LivoxModel::Mid360,
    );
    let udp = |b: &[u8]| u16::from_le_bytes([b[7], b[8]]);
    let mut s = LivoxStream::new(LivoxConfig::new(
        Some(LivoxModel::Mid360),
        LivoxModel::Mid360.protocol(),
    ));
    let (mut points, mut sent) = (0usize, 0usize);
    for (host, _, b) in &packets {
        // Lost: the last point packet and the last IMU packet before the wrap.
        if udp(b) == 65_535 {
            continue;
        }
        sent += 1;
        s.push(*host, b, &mut |sw, _| points += sw.points.len());
    }
    s.finish(&mut |sw, _| points += sw.points.len());
    assert_eq!(sent + 2, packets.len());
    let st = s.stats();
    assert_eq!((st.missing, st.imu_missing), (1, 1));
    assert_eq!((st.discontinuities, st.duplicates), (0, 0));
    assert!(points > 0);
}

/// A sensor that counts frames (the HAP: `udp_cnt` restarts at 0 and `frame_cnt` steps by one
/// with each): the last packet of a frame, reordered behind the next frame's first, is late.
/// While its frame's sweep waits for its IMU samples it joins it, and the sweeps are those of
/// the run in order; without IMU packets that sweep was handed over already, and the packet is
/// dropped and counted, however late it comes. Either way nothing is missing and nothing is a
/// discontinuity. (Before: 468 missing, 2 discontinuities, and the frame's tail cut into a
/// sweep of its own.)
#[test]
fn a_frame_s_last_packet_behind_the_next_frame_is_late() {
    const PER_FRAME: usize = 470;
    let packets = mid360_with_counters(
        560_000_000,
        |k| ((k % PER_FRAME) as u16, (k / PER_FRAME) as u8),
        |k| k as u16,
        LivoxModel::Hap,
    );
    let point_at: Vec<usize> = (0..packets.len()).filter(|&i| !packets[i].1).collect();
    // Frame 3's first point packet and frame 2's last: sweeps follow frames by then.
    let (last2, first3) = (point_at[3 * PER_FRAME - 1], point_at[3 * PER_FRAME]);
    let stripped: Vec<(i64, Vec<u8>)> = packets.iter().map(|(h, _, b)| (*h, b.clone())).collect();
    let run = |order: &[usize]| {
        let mut s = LivoxStream::new(LivoxConfig::new(
            Some(LivoxModel::Hap),
            LivoxModel::Hap.protocol(),
        ));
        let r = common::run_stream(&mut s, &stripped, order);
        assert!(s.facts().frame_cut);
        (r, s.stats().late_dropped)
    };
    let swap = |order: &mut Vec<usize>| {
        let (i, j) = (
            order.iter().position(|&k| k == last2).unwrap(),
            order.iter().position(|&k| k == first3).unwrap(),
        );
        order.swap(i, j);
    };
    // With the IMU: the frame's sweep is still held.
    let all: Vec<usize> = (0..packets.len()).collect();
    let ((in_order, ..), _) = run(&all);
    assert_eq!(in_order.len(), 6, "{in_order:?}");
    let mut order = all.clone();
    swap(&mut order);
    let ((late, missing, discontinuities, _), dropped) = run(&order);
    assert_eq!((missing, discontinuities, dropped), (0, 0, 0));
    assert_eq!(late, in_order);

    // Without: dropped, counted.
    let points_only: Vec<usize> = point_at.clone();
    let ((in_order, ..), _) = run(&points_only);
    let mut order = points_only;
    swap(&mut order);
    let ((late, missing, discontinuities, _), dropped) = run(&order);
    assert_eq!((missing, discontinuities, dropped), (0, 0, 1));
    assert_eq!(late.len(), in_order.len());
    let lost_points = in_order[2].0 - late[2].0;
    assert!(lost_points > 0 && lost_points <= 96, "{lost_points}");
    assert_eq!(
        (late[2].1, in_order[2].1),
        (PER_FRAME as u32 - 1, PER_FRAME as u32)
    );
    assert_eq!(late[3..], in_order[3..]);

    // A packet of frame 2 twenty packets into frame 3 is still its frame's: dropped and
    // counted. (Counted against frame 3's `udp_cnt`, it read as 444 packets lost.)
    let k = point_at[3 * PER_FRAME - 5];
    let mut order: Vec<usize> = point_at.iter().copied().filter(|&i| i != k).collect();
    let at = order
        .iter()
        .position(|&i| i == point_at[3 * PER_FRAME + 20])
        .unwrap();
    order.insert(at + 1, k);
    let ((very_late, missing, discontinuities, _), dropped) = run(&order);
    assert_eq!((missing, discontinuities, dropped), (0, 0, 1));
    assert_eq!(very_late.len(), in_order.len());
    assert_eq!(very_late[3..], in_order[3..]);
}

/// A `udp_cnt` that stands still (0, or any one value) repeats numbers, not packets: a copy is
/// a packet whose time is seen again too, so every point and IMU packet is decoded, and the
/// points are those of the run with counting numbers. (Counting numbers alone, every packet
/// after the first was a copy.)
#[test]
fn a_counter_that_stands_still_is_no_copy() {
    let counting = mid360_with_counters(
        120_000_000,
        |k| (k as u16, 0),
        |k| k as u16,
        LivoxModel::Mid360,
    );
    let points = |packets: &[(i64, bool, Vec<u8>)]| {
        let mut s = LivoxStream::new(LivoxConfig::new(
            Some(LivoxModel::Mid360),
            LivoxModel::Mid360.protocol(),
        ));
        let mut n = 0usize;
        for (host, _, b) in packets {
            s.push(*host, b, &mut |sw, _| n += sw.points.len());
        }
        s.finish(&mut |sw, _| n += sw.points.len());
        (n, s.stats().clone())
    };
    let (want, _) = points(&counting);
    for value in [0u16, 7] {
        let standing =
            mid360_with_counters(120_000_000, |_| (value, 0), |_| value, LivoxModel::Mid360);
        let (got, st) = points(&standing);
        assert_eq!(st.duplicates, 0, "udp_cnt {value}");
        assert_eq!(got, want, "udp_cnt {value}");
        assert_eq!(
            st.packets + st.imu_packets,
            standing.len() as u64,
            "udp_cnt {value}"
        );
    }
}
