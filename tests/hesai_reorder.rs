//! Hesai streams out of order, with losses and stale, copied or endless packets. The truth of
//! each case is a stream built here with known losses: a late packet whose points belong to
//! an open sweep gives the sweeps of the stream in order; one whose sweep went out already
//! gives the sweeps of the stream without it, and is counted `late_dropped`, not `missing`.
//! Packets come from the simulator (urban scene) or are written with `encode_packet`.
#![cfg(all(feature = "pcap", feature = "mcap", feature = "sim"))]

#[path = "../tools/fuzz/harness.rs"]
mod harness;

use ringscan::sensor::hesai::family::parse_hesai_calibration;
use ringscan::sensor::hesai::model::TailFlags;
use ringscan::sensor::hesai::sim::{encode_packet, BlockData, HesaiSim, TailData};
use ringscan::sensor::hesai::{HesaiCalibration, HesaiConfig, HesaiModel, HesaiStats, HesaiStream};

const T0: i64 = 1_714_564_800_000_000_000;

/// An XT32 correction whose channels all lie on the block azimuth: every channel passes the
/// cut with its block, so which packet is on which side of it is plain.
fn xt32_on_the_block() -> HesaiCalibration {
    let mut s = String::from("Laser id,Elevation,Azimuth\n");
    for i in 0..32 {
        s.push_str(&format!("{},{},0\n", i + 1, 15.0 - i as f64));
    }
    parse_hesai_calibration(s.as_bytes()).unwrap().unwrap()
}

fn sim_packets(model: HesaiModel, calib: &HesaiCalibration, n: usize) -> Vec<(i64, Vec<u8>)> {
    sim_with_returns(model, calib, n).0
}

/// The simulator's packets and how many returns each holds (its truth).
fn sim_with_returns(
    model: HesaiModel,
    calib: &HesaiCalibration,
    n: usize,
) -> (Vec<(i64, Vec<u8>)>, Vec<usize>) {
    let scene = ringscan::sim::scenes::named("urban").unwrap();
    let mut sim = HesaiSim::new(model, calib.clone(), T0);
    (0..n)
        .map(|_| {
            let mut truth = Vec::new();
            let p = sim.next_packet(&scene, &mut truth);
            (p, truth.len())
        })
        .unzip()
}

/// One sweep as compared: device time, packets missing, and its points sorted.
type Seen = (i64, u64, Vec<(u32, u32, u32, u32, u16, u8)>);

fn run(
    model: HesaiModel,
    calib: &HesaiCalibration,
    packets: &[&(i64, Vec<u8>)],
) -> (Vec<Seen>, HesaiStats) {
    let mut cfg = HesaiConfig::new(Some(calib.clone()), "test");
    cfg.model = Some(model);
    let mut s = HesaiStream::new(cfg);
    let mut out = Vec::new();
    let mut on = |sw: &mut ringscan::sweep::Sweep, _: &_| {
        let mut pts: Vec<_> = sw
            .points
            .iter()
            .map(|p| {
                (
                    p.x.to_bits(),
                    p.y.to_bits(),
                    p.z.to_bits(),
                    p.t,
                    p.ring,
                    p.ret,
                )
            })
            .collect();
        pts.sort_unstable();
        out.push((sw.device_time_ns, sw.missing_packets, pts));
    };
    for (host, b) in packets {
        s.push(*host, b, &mut on).unwrap();
    }
    s.finish(&mut on);
    (out, s.stats().clone())
}

/// The index of the first packet during whose push a sweep is emitted (in order): the packet
/// that carries the stream past the cut.
fn first_cut(model: HesaiModel, calib: &HesaiCalibration, packets: &[(i64, Vec<u8>)]) -> usize {
    let mut cfg = HesaiConfig::new(Some(calib.clone()), "test");
    cfg.model = Some(model);
    let mut s = HesaiStream::new(cfg);
    for (i, (host, b)) in packets.iter().enumerate() {
        let mut emitted = false;
        s.push(*host, b, &mut |_, _| emitted = true).unwrap();
        if emitted && i > 20 {
            return i;
        }
    }
    panic!("{model:?}: no cut in {} packets", packets.len());
}

/// `order` of packet indices; `None` marks nothing.
fn pick<'a>(packets: &'a [(i64, Vec<u8>)], order: &[usize]) -> Vec<&'a (i64, Vec<u8>)> {
    order.iter().map(|&i| &packets[i]).collect()
}

/// XT32, the cut at packet c: c−3 held up until after c+2 (its sweep went out at c), c+1
/// lost, c+5 held up until after c+8 (its sweep still open). The sweeps are those of the
/// stream without c−3 and c+1: the sweep after the cut keeps the one packet it lost (c+1),
/// not c−3's points nor a count lowered by it. Before, c−3's points went into that sweep and
/// its missing count fell to 0.
#[test]
fn late_packets_join_their_own_sweep_or_are_dropped_and_counted() {
    let model = HesaiModel::PandarXt32;
    let calib = xt32_on_the_block();
    let packets = sim_packets(model, &calib, 700);
    let c = first_cut(model, &calib, &packets);
    let n = packets.len();
    let mut order: Vec<usize> = (0..n).filter(|&i| i != c - 3 && i != c + 1).collect();
    // c−3 after c+2; c+5 after c+8.
    let at = order.iter().position(|&i| i == c + 2).unwrap();
    order.insert(at + 1, c - 3);
    order.retain(|&i| i != c + 5);
    let at = order.iter().position(|&i| i == c + 8).unwrap();
    order.insert(at + 1, c + 5);
    let (got, st) = run(model, &calib, &pick(&packets, &order));

    let truth: Vec<usize> = (0..n).filter(|&i| i != c - 3 && i != c + 1).collect();
    let (want, ref_st) = run(model, &calib, &pick(&packets, &truth));
    assert_eq!(ref_st.missing, 2);
    assert_eq!(got.len(), want.len());
    for (i, (g, w)) in got.iter().zip(&want).enumerate() {
        assert_eq!((g.0, g.1), (w.0, w.1), "sweep {i}: time, missing");
        assert!(
            g.2 == w.2,
            "sweep {i}: {} points, {} wanted",
            g.2.len(),
            w.2.len()
        );
    }
    // c−3 counted late, not missing; c+1 missing; c+5 found.
    assert_eq!((st.missing, st.late_dropped), (1, 1));
    assert_eq!(st.packets, n as u64 - 2);
    assert_eq!(st.discontinuities, 0);
}

/// A packet held up past its sweep's cut neither drives the cut nor ends a frame, on the two
/// models whose cut is not the plain block azimuth's: the AT128 (per-channel azimuths, cut at
/// 150°: A, B past the cut, C late from before it, D) and the ATX (its frames: the last
/// packet of a frame coming after the first of the next). The truth is the stream without the
/// late packet. Before, the AT128 gave a sweep of two packets {B, C}, and the ATX split a
/// frame in three.
#[test]
fn a_late_packet_neither_cuts_nor_ends_a_frame() {
    for model in [HesaiModel::PandarAt128, HesaiModel::PandarAtx] {
        let calib = harness::hesai_correction(model);
        let count = if model == HesaiModel::PandarAtx {
            1_600
        } else {
            900
        };
        let packets = sim_packets(model, &calib, count);
        let c = first_cut(model, &calib, &packets);
        let n = packets.len();
        let mut order: Vec<usize> = (0..n).filter(|&i| i != c - 1).collect();
        let at = order.iter().position(|&i| i == c).unwrap();
        order.insert(at + 1, c - 1);
        let (got, st) = run(model, &calib, &pick(&packets, &order));
        let truth: Vec<usize> = (0..n).filter(|&i| i != c - 1).collect();
        let (want, _) = run(model, &calib, &pick(&packets, &truth));
        assert_eq!(got.len(), want.len(), "{model:?}: sweeps");
        for (i, (g, w)) in got.iter().zip(&want).enumerate() {
            assert_eq!((g.0, g.1), (w.0, w.1), "{model:?} sweep {i}: time, missing");
            assert!(g.2 == w.2, "{model:?} sweep {i}: points");
        }
        assert_eq!(
            (st.missing, st.late_dropped, st.discontinuities),
            (0, 1, 0),
            "{model:?}"
        );
    }
}

/// XT32 packets 100 … 115, then 102 again from 13 packets back (it had not come: held up on
/// the way), then 116 on: beyond the reorder window, but its time is as far behind as its
/// number, so it is stale, not a restart. Truth: the stream without it, the packet counted
/// late, not missing. Before: a cut mid-turn, a discontinuity, and 13 packets missing that
/// all came.
#[test]
fn a_stale_packet_is_dropped_not_taken_for_a_restart() {
    let model = HesaiModel::PandarXt32;
    let calib = xt32_on_the_block();
    let packets = sim_packets(model, &calib, 150);
    let mut order: Vec<usize> = (0..150).filter(|&i| i != 102).collect();
    let at = order.iter().position(|&i| i == 115).unwrap();
    order.insert(at + 1, 102);
    let (got, st) = run(model, &calib, &pick(&packets, &order));
    let truth: Vec<usize> = (0..150).filter(|&i| i != 102).collect();
    let (want, _) = run(model, &calib, &pick(&packets, &truth));
    assert_eq!(got.len(), want.len(), "sweeps");
    for (i, (g, w)) in got.iter().zip(&want).enumerate() {
        assert_eq!((g.0, g.1), (w.0, w.1), "sweep {i}: time, missing");
        assert!(g.2 == w.2, "sweep {i}: points");
    }
    assert_eq!((st.missing, st.late_dropped, st.discontinuities), (0, 1, 0));
}

/// A head standing still (every block at azimuth 0) and an ATX whose frame bit never
/// changes give no cut: a sweep ends anyway after `max_sweep_ns` (1 s), and after twice as
/// many packets as that holds when the tail clock stands still too. Every point goes out
/// once, each sweep spans at most 1 s. Before: one sweep for the whole stream.
#[test]
fn a_sweep_without_a_cut_ends_after_max_sweep_ns() {
    for model in [HesaiModel::PandarXt32, HesaiModel::PandarAtx] {
        let calib = harness::hesai_correction(model);
        let channels = calib.channels();
        let blocks = if model == HesaiModel::PandarAtx { 2 } else { 8 };
        let period = if model == HesaiModel::PandarAtx {
            144_000
        } else {
            8 * i64::from(model.spec().block_period_ns)
        };
        let packet = |i: i64, stamp: i64| {
            let block = BlockData {
                azimuth: if model == HesaiModel::PandarAtx {
                    60 * 256
                } else {
                    0
                },
                units: vec![(1_000, 50); channels],
            };
            let tail = TailData {
                return_mode: 0x37,
                motor_rpm: 600,
                stamp_ns: stamp,
                udp_seq: i as u32,
                dis_unit_mm: 4,
                flags: TailFlags::default(),
                signature: false,
                frame_id: 0,
            };
            encode_packet(model, &vec![block; blocks], &tail)
        };
        for frozen_clock in [false, true] {
            let n = if frozen_clock {
                // Twice 1 s's packets, twice over, and some.
                4 * 1_000_000_000 / period + 10
            } else {
                2_500_000_000 / period
            };
            let mut cfg = HesaiConfig::new(Some(calib.clone()), "test");
            cfg.model = Some(model);
            let mut s = HesaiStream::new(cfg);
            let sweeps = std::cell::Cell::new(0);
            let (mut points, mut longest) = (0usize, 0u32);
            let mut on = |sw: &mut ringscan::sweep::Sweep, _: &_| {
                sweeps.set(sweeps.get() + 1);
                points += sw.points.len();
                longest = longest.max(sw.points.iter().map(|p| p.t).max().unwrap_or(0));
                assert!(
                    sw.packets as i64 <= 2 * 1_000_000_000 / period + 1,
                    "{model:?}: {} packets in one sweep",
                    sw.packets
                );
            };
            for i in 0..n {
                let stamp = if frozen_clock { T0 } else { T0 + i * period };
                s.push(stamp, &packet(i, stamp), &mut on).unwrap();
            }
            let before_finish = sweeps.get();
            s.finish(&mut on);
            let what = format!("{model:?}, clock frozen {frozen_clock}");
            assert!(before_finish >= 2, "{what}: {before_finish} sweeps cut");
            assert_eq!(points as i64, n * (blocks * channels) as i64, "{what}");
            // Cut between groups: the last group fires within a packet period of the limit.
            assert!(
                i64::from(longest) <= 1_000_000_000 + period,
                "{what}: t up to {longest} ns"
            );
            assert_eq!(s.stats().missing, 0, "{what}");
            // Each cut for length is a discontinuity, as in every family: 2.5 s of packets
            // cut at 1 s and 2 s; a frozen clock's twice 2 s's packets and some, cut after 2 s's
            // packets twice.
            assert_eq!(s.stats().discontinuities, 2, "{what}");
        }
    }
}

/// XT32 packets whose tail has no valid date (month 0: their time is the host's) with one
/// copy: the number repeats and nothing says the counter restarted, so it is a copy,
/// dropped and counted once. Before, it was taken for a restart and its points added twice.
#[test]
fn a_copy_without_a_sensor_time_is_still_a_copy() {
    let model = HesaiModel::PandarXt32;
    let calib = xt32_on_the_block();
    let l = &model.spec().layout;
    let month = l.tail_start() + l.tail.date + 1;
    let (mut packets, returns) = sim_with_returns(model, &calib, 10);
    for (_, b) in &mut packets {
        b[month] = 0;
    }
    let mut cfg = HesaiConfig::new(Some(calib.clone()), "test");
    cfg.model = Some(model);
    cfg.check_crc = false;
    let mut s = HesaiStream::new(cfg);
    let mut points = 0;
    let mut on = |sw: &mut ringscan::sweep::Sweep, _: &_| points += sw.points.len();
    let order = [0, 1, 2, 3, 4, 3, 5, 6, 7, 8, 9];
    for (k, &i) in order.iter().enumerate() {
        // Host times 0.5 ms apart, the copy's too.
        s.push(T0 + k as i64 * 500_000, &packets[i].1, &mut on)
            .unwrap();
    }
    s.finish(&mut on);
    let st = s.stats();
    assert_eq!((st.packets, st.duplicates, st.missing), (10, 1, 0));
    assert_eq!(points, returns.iter().sum::<usize>());
}

/// A Pandar40P (no sequence number) loses packet 5, then its tail clock steps back 1 ms at
/// packet 15 (less than 10 packet periods): no gap counted lies there, so it is no late
/// packet filling one but a discontinuity, and packet 5 stays missing. Before, the step back
/// was taken for a late packet and un-counted packet 5's loss.
#[test]
fn a_clock_stepping_back_fills_no_gap() {
    let model = HesaiModel::Pandar40P;
    let calib = harness::hesai_correction(model);
    let mut packets = sim_packets(model, &calib, 30);
    let l = &model.spec().layout;
    let us = l.tail_start() + l.tail.timestamp_us;
    // Without the optional trailing sequence number: loss is told by time alone.
    for (_, b) in packets.iter_mut() {
        b.truncate(l.base_len());
    }
    for (_, b) in packets.iter_mut().skip(15) {
        let t = u32::from_le_bytes(b[us..us + 4].try_into().unwrap());
        b[us..us + 4].copy_from_slice(&(t - 1_000).to_le_bytes());
    }
    let order: Vec<usize> = (0..30).filter(|&i| i != 5).collect();
    let (_, st) = run(model, &calib, &pick(&packets, &order));
    assert_eq!((st.missing, st.discontinuities, st.late_dropped), (1, 1, 0));
}

/// XT32 packet 300 held up until after 330, or after 500, then a copy of it, and a copy of
/// packet 325 (which came in order) 60 packets after it; in the second stream every tenth
/// packet from 310 to 490 is lost too, so more gaps came after 300's than the stream keeps.
/// Each datagram is counted once: the stale 300 in `late_dropped`, its gap off `missing`,
/// the copies in `duplicates`; `missing` is the packets never sent (none, or the 19 lost);
/// and the stream with the copies gives the sweeps and counters of the stream without them
/// but for `duplicates`. Before, each copy was a second `late_dropped`, and 300's gap stayed
/// counted missing where no longer kept (20 missing).
#[test]
fn a_copy_of_a_stale_packet_is_a_duplicate() {
    let model = HesaiModel::PandarXt32;
    let calib = xt32_on_the_block();
    let packets = sim_packets(model, &calib, 700);
    for (late, lossy) in [(30, false), (200, true)] {
        let lost: Vec<usize> = if lossy {
            (310..500).step_by(10).collect()
        } else {
            Vec::new()
        };
        let sent: Vec<usize> = (0..700)
            .filter(|i| *i != 300 && !lost.contains(i))
            .collect();
        let mut without_copies = sent.clone();
        let at = without_copies
            .iter()
            .position(|&i| i == 300 + late)
            .unwrap();
        without_copies.insert(at + 1, 300);
        let mut with_copies = without_copies.clone();
        with_copies.insert(at + 2, 300);
        let at = with_copies.iter().position(|&i| i == 385).unwrap();
        with_copies.insert(at + 1, 325);
        let what = format!("{late} late, {} lost", lost.len());

        let (got, st) = run(model, &calib, &pick(&packets, &with_copies));
        assert_eq!(
            (st.packets, st.late_dropped, st.duplicates, st.missing),
            (sent.len() as u64, 1, 2, lost.len() as u64),
            "{what}"
        );
        assert_eq!(st.discontinuities, 0, "{what}");
        assert_eq!(
            st.packets + st.late_dropped + st.duplicates + st.malformed,
            with_copies.len() as u64,
            "{what}: every datagram counted once"
        );
        let (want, ref_st) = run(model, &calib, &pick(&packets, &without_copies));
        assert_eq!(
            HesaiStats {
                duplicates: ref_st.duplicates + 2,
                ..ref_st
            },
            st,
            "{what}: the copies change nothing but `duplicates`"
        );
        assert_eq!(got.len(), want.len(), "{what}: sweeps");
        for (i, (g, w)) in got.iter().zip(&want).enumerate() {
            assert_eq!((g.0, g.1), (w.0, w.1), "{what}, sweep {i}: time, missing");
            assert!(g.2 == w.2, "{what}, sweep {i}: points");
        }
    }
}
