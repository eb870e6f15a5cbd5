//! The stream layer on simulated sensors: sweep cuts, loss accounting, model detection,
//! hour roll-over and the GPS clock — each against numbers derived from the simulation's
//! set-up, not from the decoder.

mod common;

use ringscan::sensor::velodyne::calib::builtin::builtin;
use ringscan::sensor::velodyne::sim::encode_position_packet;
use ringscan::sensor::velodyne::sim::VelodyneSim;
use ringscan::sensor::velodyne::ReturnMode;
use ringscan::sensor::velodyne::SensorFacts;
use ringscan::sensor::velodyne::StreamConfig;
use ringscan::sensor::velodyne::VelodyneModel;
use ringscan::sensor::velodyne::VelodyneStream;
use ringscan::sim::scene::Shapes;
use ringscan::sweep::Organized;
use ringscan::sweep::Sweep;
use ringscan::time::ClockSource;

struct Out {
    sweeps: Vec<Sweep>,
    facts: Option<SensorFacts>,
}

fn run(
    sim: &mut VelodyneSim,
    packets: usize,
    cfg: StreamConfig,
    drop: &dyn Fn(usize) -> bool,
    position: Option<&dyn Fn(usize) -> Option<[u8; 512]>>,
) -> (Out, VelodyneStream) {
    let scene = Shapes::room(15.0, 10.0, 1.7, 5.0);
    let mut stream = VelodyneStream::new(cfg);
    let mut out = Out {
        sweeps: Vec::new(),
        facts: None,
    };
    let mut truth = Vec::new();
    for i in 0..packets {
        truth.clear();
        let (host, bytes) = sim.next_packet(&scene, &mut truth);
        if let Some(pos) = position {
            if let Some(pp) = pos(i) {
                stream.push(host, &pp, &mut |_, _| {}).unwrap();
            }
        }
        if drop(i) {
            continue;
        }
        stream
            .push(host, &bytes, &mut |s, f| {
                out.sweeps.push(s.clone());
                out.facts = Some(f.clone());
            })
            .unwrap();
    }
    stream
        .finish(&mut |s, f| {
            out.sweeps.push(s.clone());
            out.facts = Some(f.clone());
        })
        .unwrap();
    (out, stream)
}

fn vlp16_sim() -> VelodyneSim {
    let calib = builtin(VelodyneModel::Vlp16).unwrap();
    let mut sim = VelodyneSim::new(
        VelodyneModel::Vlp16,
        ReturnMode::Strongest,
        calib,
        1_700_000_000_000_000_000,
    );
    sim.azimuth0_deg = 123.4;
    sim
}

#[test]
fn sweeps_are_cut_at_the_cut_angle_and_times_are_relative_to_the_first_firing() {
    let mut sim = vlp16_sim();
    // 2.5 s at 10 Hz: 1884 packets of 1327.104 µs.
    let n = (2.5e9 / sim.period_ns()).floor() as usize;
    let (out, stream) = run(&mut sim, n, StreamConfig::default(), &|_| false, None);
    // The head passes 0° at (360 − 123.4)/3600 s and every 0.1 s after: 25 crossings in
    // 2.5 s, so 26 sweeps (a partial one at each end).
    assert_eq!(out.sweeps.len(), 26);
    assert_eq!(stream.stats().missing, 0);
    assert_eq!(stream.stats().data_packets as usize, n);
    for s in &out.sweeps[1..25] {
        // A full turn: 100 ms, give or take one block (110.592 µs): both ends fall on a block.
        let span = s.span_ns();
        assert!(
            (i64::from(span) - 100_000_000).abs() <= 110_592,
            "sweep {} spans {span} ns",
            s.index
        );
        // Sweeps are cut between blocks; a VLP-16 block holds two firing sequences
        // (110.6 µs, 0.4° at 10 Hz): it starts within one block after the cut.
        assert!(
            s.first_azimuth < 40,
            "sweep {} starts at {}",
            s.index,
            s.first_azimuth
        );
        assert_eq!(s.missing_packets, 0);
        assert_eq!(s.clock, ClockSource::Host);
        // 754 columns … 24 per packet, 37.7 packets per turn.
        assert!(
            (1800..=1812).contains(&s.columns_count),
            "columns {}",
            s.columns_count
        );
        assert!(s.points.iter().all(|p| p.t <= span));
    }
    // Consecutive sweeps start 100 ms apart in device time.
    for w in out.sweeps[1..25].windows(2) {
        let d = w[1].device_time_ns - w[0].device_time_ns;
        assert!((d - 100_000_000).abs() <= 110_592, "{d}"); // both starts fall on a block
    }
}

#[test]
fn missing_packets_are_counted_in_the_sweep_they_fall_in() {
    let mut sim = vlp16_sim();
    let (out, stream) = run(
        &mut sim,
        400,
        StreamConfig::default(),
        &|i| (200..203).contains(&i) || i == 350,
        None,
    );
    assert_eq!(stream.stats().missing, 4);
    let total: u64 = out.sweeps.iter().map(|s| s.missing_packets).sum();
    assert_eq!(total, 4);
    // Packet 200 is 265 ms in: the third sweep boundary is at 265.7 ms, so the loss straddles
    // it; the three missing packets are booked on the sweep the next received packet opens.
    assert_eq!(
        out.sweeps.iter().filter(|s| s.missing_packets > 0).count(),
        2
    );
}

#[test]
fn a_wrong_product_id_is_overridden_by_the_cadence() {
    let mut sim = vlp16_sim();
    sim.product_id = Some(0x21); // the HDL-32E id, as two real VLP-16 captures send
    let (out, stream) = run(&mut sim, 100, StreamConfig::default(), &|_| false, None);
    let facts = out.facts.unwrap();
    assert_eq!(facts.model, Some(VelodyneModel::Vlp16));
    assert!(facts.detection.contains("1327"), "{}", facts.detection);
    assert_eq!(stream.stats().malformed, 0);
}

#[test]
fn the_hour_roll_over_is_seamless() {
    let mut sim = vlp16_sim();
    sim.toh0_us = 3_600_000_000 - 150_000; // 150 ms before the hour
    let (out, stream) = run(&mut sim, 400, StreamConfig::default(), &|_| false, None);
    assert_eq!(stream.stats().discontinuities, 0);
    assert_eq!(stream.stats().missing, 0);
    for w in out.sweeps[1..out.sweeps.len() - 1].windows(2) {
        let d = w[1].device_time_ns - w[0].device_time_ns;
        assert!((d - 100_000_000).abs() <= 110_592, "{d}"); // both starts fall on a block
    }
}

#[test]
fn gps_time_with_pps_locked_gives_absolute_sensor_timestamps() {
    let mut sim = vlp16_sim();
    sim.toh0_us = 0; // first firing exactly at 12:00:00.000000 UTC
                     // 2024-05-01 12:00:00 UTC = 1714564800 s since the epoch (19844 days · 86400 + 12 h).
    let rmc = "$GPRMC,120000,A,3707.8324,N,12139.2864,W,000.0,144.7,010524,013.8,E,D";
    let cs = rmc[1..].bytes().fold(0u8, |a, c| a ^ c);
    let sentence = format!("{rmc}*{cs:02X}\r\n");
    let pos = move |i: usize| (i == 0).then(|| encode_position_packet(0, 2, &sentence));
    let (out, _) = run(
        &mut sim,
        200,
        StreamConfig::default(),
        &|_| false,
        Some(&pos),
    );
    let s = &out.sweeps[1];
    assert_eq!(s.clock, ClockSource::SensorGps);
    assert_eq!(s.timestamp_ns, s.device_time_ns);
    // Sweep 1 starts at the first firing after 0°: (360 − 123.4)/3600 s after 12:00:00,
    // rounded up to the next block (two firing sequences, 110.592 µs).
    let t0 = 1_714_564_800_000_000_000i64;
    let expected = t0 + 65_722_222; // 236.6° / 3600 °/s
    assert!(
        (0..=110_592).contains(&(s.timestamp_ns - expected)),
        "{} vs {expected}",
        s.timestamp_ns
    );
    // Without PPS lock, the host clock is used.
    let mut sim = vlp16_sim();
    let sentence2 = format!("{rmc}*{cs:02X}\r\n");
    let pos2 = move |i: usize| (i == 0).then(|| encode_position_packet(0, 0, &sentence2));
    let (out, _) = run(
        &mut sim,
        200,
        StreamConfig::default(),
        &|_| false,
        Some(&pos2),
    );
    assert_eq!(out.sweeps[1].clock, ClockSource::Host);
}

#[test]
fn organized_image_has_one_cell_per_ring_and_column() {
    let mut sim = vlp16_sim();
    let cfg = StreamConfig {
        keep_columns: true,
        ..StreamConfig::default()
    };
    let (out, _) = run(&mut sim, 120, cfg, &|_| false, None);
    let s = &out.sweeps[1];
    let img = Organized::from_sweep(s, 16).unwrap();
    assert_eq!(img.rows, 16);
    assert_eq!(img.layers, 1);
    assert_eq!(img.cols as u32, s.columns_count);
    // The room is closed: every beam returns, so every cell is valid.
    assert_eq!(img.valid.iter().filter(|v| **v).count(), s.points.len());
    assert_eq!(s.points.len(), 16 * img.cols);
    // Within a column, rings go up in elevation: z/range increases with the row.
    let col = img.cols / 2;
    let elev = |r: usize| {
        let p = img.get(0, r, col).unwrap();
        (p.z / (p.x * p.x + p.y * p.y).sqrt()).atan()
    };
    for r in 1..16 {
        assert!(elev(r) > elev(r - 1));
    }
}

#[test]
fn a_gps_fix_arriving_mid_sweep_does_not_shift_point_times() {
    // The host clock (2023-11-14) is months away from the GPS time (2024-05-01 12:00): the
    // first sweep opens on the host clock and the fix arrives in its 10th packet. Every point
    // of every sweep must stay within its sweep's own span (at 10 Hz, < 0.1 s plus a packet).
    // Before the fix, the packets after the fix were timed by the GPS clock: sweep 0 was cut
    // there as "too long" and sweep 1 began mid-turn (and, live, `t` could jump).
    let mut sim = vlp16_sim();
    let rmc = "$GPRMC,120000,A,3707.8324,N,12139.2864,W,000.0,144.7,010524,013.8,E,D";
    let cs = rmc[1..].bytes().fold(0u8, |a, c| a ^ c);
    let sentence = format!("{rmc}*{cs:02X}\r\n");
    let pos = move |i: usize| (i == 10).then(|| encode_position_packet(0, 2, &sentence));
    let (out, _) = run(
        &mut sim,
        300,
        StreamConfig::default(),
        &|_| false,
        Some(&pos),
    );
    assert!(out.sweeps.len() >= 3);
    assert_eq!(out.sweeps[0].clock, ClockSource::Host);
    assert_eq!(out.sweeps[1].clock, ClockSource::SensorGps);
    // Sweep 0 runs from the start azimuth (123.4°) to the wrap: 236.6° at 3600 °/s = 65.72 ms
    // (to within a packet); it is not cut where the clock changed source. Sweep 1 is a whole
    // turn on the GPS clock.
    let first = out.sweeps[0].span_ns() as i64;
    assert!(
        (first - 65_722_222).abs() < 1_400_000,
        "sweep 0 spans {first} ns"
    );
    assert!(
        out.sweeps[1].span_ns() > 99_000_000,
        "sweep 1 spans {}",
        out.sweeps[1].span_ns()
    );
    let bound = 100_000_000 + 1_400_000;
    for s in &out.sweeps {
        let max_t = s.points.iter().map(|p| p.t).max().unwrap_or(0);
        assert!(max_t <= bound, "sweep {}: t up to {max_t} ns", s.index);
        assert!(
            max_t <= s.span_ns(),
            "sweep {}: t {max_t} > span {}",
            s.index,
            s.span_ns()
        );
    }
}

/// A packet sent twice (a switch or a capture tool repeating itself), once right behind itself
/// and once three packets later: the copies share a timestamp with a packet just seen, so they
/// are dropped and counted, and the sweeps are those of the run without them. (Before, each
/// copy stepped the time back: a discontinuity that cut the sweep mid-turn, and its points
/// twice.)
/// The next `n` packets of `sim` as (host time, payload).
fn sim_packets(sim: &mut VelodyneSim, scene: &Shapes, n: usize) -> Vec<(i64, Vec<u8>)> {
    (0..n)
        .map(|_| {
            let (host, bytes) = sim.next_packet(scene, &mut Vec::new());
            (host, bytes.to_vec())
        })
        .collect()
}

#[test]
fn copies_are_dropped_and_counted() {
    let mut sim = vlp16_sim();
    let scene = Shapes::room(15.0, 10.0, 1.7, 5.0);
    let packets = sim_packets(&mut sim, &scene, 400);
    let run = |order: &[usize]| {
        common::run_stream(
            &mut VelodyneStream::new(StreamConfig::default()),
            &packets,
            order,
        )
    };
    let all: Vec<usize> = (0..packets.len()).collect();
    let (in_order, ..) = run(&all);
    let (copied, missing, discontinuities, copies) = run(&common::with_copies(all.len(), &all));
    assert_eq!((missing, discontinuities, copies), (0, 0, 2));
    assert_eq!(copied, in_order, "(points, packets) per sweep");
}

/// Each sweep's points in a canonical order (a late packet's points join after the others),
/// with the sweep's packet and missing counts.
type SweepSet = (Vec<[i64; 5]>, u32, u64);

/// Pushes `packets[k]` for each `k` of `order`; returns each sweep as a [`SweepSet`] and the
/// stream's counters.
fn sweep_sets(
    packets: &[(i64, Vec<u8>)],
    order: &[usize],
) -> (Vec<SweepSet>, ringscan::sensor::velodyne::StreamStats) {
    let mut stream = VelodyneStream::new(StreamConfig::default());
    let mut out = Vec::new();
    let mut on = |s: &mut Sweep, _: &SensorFacts| {
        let mut pts: Vec<[i64; 5]> = s
            .points
            .iter()
            .map(|p| {
                let mm = |v: f32| (f64::from(v) * 1e6).round() as i64;
                [i64::from(p.t), i64::from(p.ring), mm(p.x), mm(p.y), mm(p.z)]
            })
            .collect();
        pts.sort_unstable();
        out.push((pts, s.packets, s.missing_packets));
    };
    for &k in order {
        stream.push(packets[k].0, &packets[k].1, &mut on).unwrap();
    }
    stream.finish(&mut on).unwrap();
    (out, stream.stats().clone())
}

/// A packet reordered on the way (one a place late, one three places late, inside a sweep)
/// joins its sweep: the same points at the same times as in order, no loss, no cut. Before,
/// each was a discontinuity that cut its sweep in two. A packet late past its sweep's cut is
/// as good as lost: its sweep holds what the run without it holds, and it is counted in
/// `late_dropped` (a loss), not in `missing`.
#[test]
fn reordered_packets_join_their_sweep_or_are_counted_late() {
    let mut sim = vlp16_sim();
    let scene = Shapes::room(15.0, 10.0, 1.7, 5.0);
    let packets = sim_packets(&mut sim, &scene, 400);
    let all: Vec<usize> = (0..packets.len()).collect();
    let (in_order, st) = sweep_sets(&packets, &all);
    assert_eq!((st.missing, st.discontinuities), (0, 0));
    assert!(in_order.len() >= 4, "{} sweeps", in_order.len());
    // The packets that cut a sweep: those whose push emitted one.
    let mut cuts = Vec::new();
    let mut stream = VelodyneStream::new(StreamConfig::default());
    for (k, (host, bytes)) in packets.iter().enumerate() {
        let mut emitted = false;
        stream
            .push(*host, bytes, &mut |_, _| emitted = true)
            .unwrap();
        if emitted {
            cuts.push(k);
        }
    }

    // Late inside a sweep (a VLP-16 turn is 75 packets): a packet a place late and one three
    // places late, well inside their sweeps.
    let mut order = all.clone();
    order.swap(cuts[0] + 20, cuts[0] + 21);
    let late = order.remove(cuts[1] + 30);
    order.insert(cuts[1] + 33, late);
    let (reordered, st) = sweep_sets(&packets, &order);
    assert_eq!((st.missing, st.discontinuities, st.late_dropped), (0, 0, 0));
    assert_eq!(reordered.len(), in_order.len());
    for (i, (a, b)) in reordered.iter().zip(&in_order).enumerate() {
        assert!(a == b, "sweep {i}: points, packets or missing differ");
    }

    // Late past the cut: the last packet wholly in a sweep comes after the packet that cut it.
    let k = cuts[1];
    let mut order = all.clone();
    order.swap(k - 1, k);
    let (late, st) = sweep_sets(&packets, &order);
    let without: Vec<usize> = all.iter().copied().filter(|&i| i != k - 1).collect();
    let (lost, lost_st) = sweep_sets(&packets, &without);
    assert_eq!(lost_st.missing, 1);
    assert_eq!((st.missing, st.discontinuities, st.late_dropped), (0, 0, 1));
    assert_eq!(late.len(), lost.len());
    for (i, (a, b)) in late.iter().zip(&lost).enumerate() {
        assert!(
            a.0 == b.0 && a.1 == b.1,
            "sweep {i}: points or packets differ"
        );
    }

    // A packet behind the latest that fills no gap counted missing is no late one: after a
    // silence of 1.5 s (a discontinuity, which counts no loss) the first two packets swapped.
    // Read as late, it un-counted the loss counted before the silence (missing 0). It is a
    // discontinuity, as before late packets were read: the real loss stays counted, and the
    // packet after it counts the one it stepped back over (missing 2).
    let mut after: Vec<(i64, Vec<u8>)> = packets[..200].to_vec();
    for _ in 0..1_130 {
        sim.next_packet(&scene, &mut Vec::new());
    }
    after.extend(sim_packets(&mut sim, &scene, 50));
    let mut order: Vec<usize> = (0..after.len()).collect();
    order.remove(150); // one loss before the silence, counted
    order.swap(199, 200); // the first two after it (positions moved by the removal)
    let (_, st) = sweep_sets(&after, &order);
    assert_eq!((st.missing, st.discontinuities, st.late_dropped), (2, 2, 0));
}

/// A motor that stalls (every block at one azimuth, the clock going on: 3 s of VLP-16
/// packets) gives no azimuth cut: sweeps end after `max_sweep_ns` (1 s), each forced cut
/// counted as a discontinuity as the stream's documentation says, and every point is handed
/// over once.
#[test]
fn a_stalled_motor_still_cuts_its_sweeps() {
    let mut sim = vlp16_sim();
    let scene = Shapes::room(15.0, 10.0, 1.7, 5.0);
    let mut packets = sim_packets(&mut sim, &scene, 2300); // 1.327 ms each: 3.05 s
    for (_, bytes) in &mut packets {
        // The 12 blocks' azimuths (bytes 2..4 of each 100-byte block) held at 90°.
        for b in 0..12 {
            bytes[b * 100 + 2..b * 100 + 4].copy_from_slice(&9000u16.to_le_bytes());
        }
    }
    // The points of the packets, from a stream that never ends a sweep for its length.
    let mut unbounded = VelodyneStream::new(StreamConfig {
        max_sweep_ns: i64::MAX,
        ..StreamConfig::default()
    });
    let mut expected = 0usize;
    for (host, bytes) in &packets {
        unbounded
            .push(*host, bytes, &mut |s, _| expected += s.points.len())
            .unwrap();
    }
    unbounded
        .finish(&mut |s, _| expected += s.points.len())
        .unwrap();
    let mut stream = VelodyneStream::new(StreamConfig::default());
    let mut sweeps: Vec<Sweep> = Vec::new();
    let mut points = 0usize;
    for (host, bytes) in packets {
        stream
            .push(host, &bytes, &mut |s, _| sweeps.push(s.clone()))
            .unwrap();
    }
    stream.finish(&mut |s, _| sweeps.push(s.clone())).unwrap();
    for s in &sweeps {
        points += s.points.len();
        let span = s.points.iter().map(|p| p.t).max().unwrap_or(0);
        // The length is checked per block: its firings may run on by up to one block.
        assert!(span <= 1_000_000_000 + 110_000, "a sweep of {span} ns");
    }
    // 3.05 s in sweeps of at most 1 s: three forced cuts, four sweeps.
    assert_eq!(
        sweeps.len(),
        4,
        "{:?}",
        sweeps.iter().map(|s| s.points.len()).collect::<Vec<_>>()
    );
    assert_eq!(stream.stats().discontinuities, 3);
    assert_eq!(points, expected);
    assert!(points > 0);
    assert_eq!(stream.stats().missing, 0);
}
