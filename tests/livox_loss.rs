//! Loss accounting on streams built with known losses, late packets, copies and damage: each
//! packet sent is decoded, counted missing, counted late-dropped or counted a copy — once —
//! and the sweeps are cut where the sensor's frames or the period say, never grown without
//! bound.
#![cfg(feature = "sim")]

use ringscan::sensor::livox::model::LivoxModel;
use ringscan::sensor::livox::sim::{
    encode_sdk1_cartesian, encode_sdk2, encode_sdk2_imu, RawPoint, Sdk2Header,
};
use ringscan::sensor::livox::{LivoxConfig, LivoxStats, LivoxStream, Protocol};

const T0: u64 = 1_714_564_800_000_000_000;
/// Time between MID-360-like packets in these streams (96 records 5 µs apart).
const P: u64 = 480_000;

fn points(n: usize) -> Vec<RawPoint> {
    (0..n)
        .map(|i| RawPoint {
            v: [1000 + i as i32, 0, 0],
            reflectivity: 1,
            tag: 0,
        })
        .collect()
}

/// An SDK2 point packet of 96 points.
fn sdk2(udp: u16, frame: u8, ts: u64) -> Vec<u8> {
    sdk2_n(udp, frame, ts, 96)
}

fn sdk2_n(udp: u16, frame: u8, ts: u64, n: usize) -> Vec<u8> {
    let h = Sdk2Header {
        time_interval: 4750,
        udp_cnt: udp,
        frame_cnt: frame,
        data_type: 1,
        time_type: 1,
        timestamp_ns: ts,
    };
    encode_sdk2(&h, &points(n))
}

fn imu(udp: u16, ts: u64) -> Vec<u8> {
    let h = Sdk2Header {
        udp_cnt: udp,
        time_type: 1,
        timestamp_ns: ts,
        ..Sdk2Header::default()
    };
    encode_sdk2_imu(&h, [0.0; 3], [0.0, 0.0, 1.0])
}

/// Flips a data byte: the CRC-32 (timestamp and data) fails, the counters are intact.
fn damage(mut b: Vec<u8>) -> Vec<u8> {
    let k = b.len() - 3;
    b[k] ^= 0x10;
    b
}

/// Per sweep (points, packets, missing packets, first device time, last point's time), and
/// the counters.
type Seen = Vec<(usize, u32, u64, i64, i64)>;

fn run(model: Option<LivoxModel>, protocol: Protocol, packets: &[Vec<u8>]) -> (Seen, LivoxStats) {
    let mut s = LivoxStream::new(LivoxConfig::new(model, protocol));
    let mut out = Vec::new();
    let mut keep = |sw: &mut ringscan::sweep::Sweep, _: &_| {
        let end = sw.points.iter().map(|p| p.t).max().unwrap_or(0);
        out.push((
            sw.points.len(),
            sw.packets,
            sw.missing_packets,
            sw.device_time_ns,
            sw.device_time_ns + i64::from(end),
        ));
    };
    for p in packets {
        s.push(0, p, &mut keep);
    }
    s.finish(&mut keep);
    (out, s.stats().clone())
}

fn mid360(packets: &[Vec<u8>]) -> (Seen, LivoxStats) {
    run(Some(LivoxModel::Mid360), Protocol::Sdk2, packets)
}

fn hap(packets: &[Vec<u8>]) -> (Seen, LivoxStats) {
    run(Some(LivoxModel::Hap), Protocol::Sdk2, packets)
}

/// HAP-like frames of `per` packets 1 ms apart (100: a frame a period), `udp_cnt` from 0 in each: (frame, udp) and
/// the packet.
fn frames(n: usize, per: u16) -> Vec<((u8, u16), Vec<u8>)> {
    (0..n)
        .flat_map(|f| (0..per).map(move |u| (f, u)))
        .enumerate()
        .map(|(k, (f, u))| ((f as u8, u), sdk2(u, f as u8, T0 + k as u64 * 1_000_000)))
        .collect()
}

fn at(fs: &[((u8, u16), Vec<u8>)], frame: u8, udp: u16) -> usize {
    fs.iter().position(|(id, _)| *id == (frame, udp)).unwrap()
}

fn total(seen: &Seen) -> usize {
    seen.iter().map(|s| s.0).sum()
}

/// The CRC-32 covers the timestamp and the data, not the counters: a damaged packet is
/// malformed and a CRC failure, once — not missing too. (Before: each also counted missing,
/// for point and IMU packets alike.)
#[test]
fn a_damaged_packet_is_malformed_not_missing() {
    let mut ps: Vec<Vec<u8>> = (0..40u16)
        .map(|k| sdk2(k, 0, T0 + u64::from(k) * P))
        .collect();
    ps[12] = damage(ps[12].clone());
    ps[30] = damage(ps[30].clone());
    // Sent, lost on the way: 20; damaged right after: 21.
    ps.remove(20);
    ps[20] = damage(ps[20].clone());
    let (seen, st) = mid360(&ps);
    assert_eq!((st.malformed, st.crc_failures), (3, 3));
    assert_eq!((st.missing, st.discontinuities, st.duplicates), (1, 0, 0));
    assert_eq!(st.packets, 36);
    assert_eq!(total(&seen), 36 * 96);
    assert_eq!(seen.iter().map(|s| s.2).sum::<u64>(), 1);

    // A damaged packet's counter never restarts the count, whatever it says.
    let mut ps: Vec<Vec<u8>> = (0..20u16)
        .map(|k| sdk2(k, 0, T0 + u64::from(k) * P))
        .collect();
    ps.insert(10, damage(sdk2(40_000, 9, T0 + 10 * P)));
    let (_, st) = mid360(&ps);
    assert_eq!((st.malformed, st.missing, st.discontinuities), (1, 0, 0));

    // IMU packets likewise.
    let mut ps: Vec<Vec<u8>> = (0..20u16)
        .map(|k| imu(k, T0 + u64::from(k) * 5_000_000))
        .collect();
    ps[7] = damage(ps[7].clone());
    let (_, st) = mid360(&ps);
    assert_eq!((st.malformed, st.crc_failures), (1, 1));
    assert_eq!((st.imu_missing, st.imu_packets), (0, 19));
}

/// SDK1 packets (`datatype` 0: 100 records) 1 ms apart, `drop` not sent.
fn mid40(n: u64, drop: &[u64]) -> Vec<Vec<u8>> {
    (0..n)
        .filter(|k| !drop.contains(k))
        .map(|k| {
            let mut b = vec![0u8; 18 + 100 * 13];
            b[0] = 5; // version
            b[1] = 1; // slot
            b[2] = 1; // id
            b[8] = 1; // PTP time
            b[9] = 0; // Cartesian, 100 records of 13 bytes
            b[10..18].copy_from_slice(&(T0 + k * 1_000_000).to_le_bytes());
            for i in 0..100 {
                let o = 18 + 13 * i;
                b[o..o + 4].copy_from_slice(&(2000 + i as i32).to_le_bytes());
                b[o + 12] = 5;
            }
            b
        })
        .collect()
}

/// SDK1 packets of 96 records (`datatype` 2) `period` apart, `drop` not sent.
fn sdk1_type2(n: u64, period: u64, drop: &[u64]) -> Vec<Vec<u8>> {
    (0..n)
        .filter(|k| !drop.contains(k))
        .map(|k| encode_sdk1_cartesian(1, T0 + k * period, &points(96)))
        .collect()
}

/// SDK1 without `--model`: the packet spacing is the stream's. A Mid-40 (100 records 10 µs
/// apart: a packet a millisecond), a Mid-70 (96 records: 960 µs) and a Horizon (96 records
/// 4.167 µs apart) each count the packets they lost, no more. (Before: with the Horizon's
/// spacing assumed, every Mid-40 and Mid-70 packet counted one missing.)
#[test]
fn sdk1_without_a_model_counts_loss_at_the_stream_s_spacing() {
    let sdk1 = |ps: &[Vec<u8>]| run(None, Protocol::Sdk1, ps);
    let (seen, st) = sdk1(&mid40(300, &[50, 120, 121, 200, 201, 202]));
    assert_eq!((st.missing, st.discontinuities), (6, 0));
    assert_eq!(total(&seen), 294 * 100);
    let (_, st) = sdk1(&sdk1_type2(300, 960_000, &[30, 31, 32, 100]));
    assert_eq!((st.missing, st.discontinuities), (4, 0));
    let (_, st) = sdk1(&sdk1_type2(300, 400_032, &[40, 41]));
    assert_eq!((st.missing, st.discontinuities), (2, 0));
    // A model named still sets the spacing.
    let (_, st) = run(
        Some(LivoxModel::Mid40),
        Protocol::Sdk1,
        &mid40(100, &[10, 60]),
    );
    assert_eq!(st.missing, 2);
}

/// A packet further behind than reordering explains (30 packets, 14 ms), or of a frame two
/// frames back, is late: dropped and counted once in `late_dropped`, its gap no longer
/// missing, the sweeps those of the stream without it. (Before: a counter restart: 29 or 20
/// missing, two discontinuities, a cut.) A sensor that restarts (counters and time go back
/// seconds) is still a discontinuity, one.
#[test]
fn a_packet_far_behind_is_late_not_a_restart() {
    let ps: Vec<Vec<u8>> = (0..300u16)
        .map(|k| sdk2(k, 0, T0 + u64::from(k) * P))
        .collect();
    let mut without = ps.clone();
    let late = without.remove(100);
    let (want, _) = mid360(&without);
    let mut order = without.clone();
    order.insert(130, late);
    let (got, st) = mid360(&order);
    assert_eq!(
        (
            st.late_dropped,
            st.missing,
            st.discontinuities,
            st.duplicates
        ),
        (1, 0, 0, 0)
    );
    let strip = |s: &Seen| s.iter().map(|w| (w.0, w.1, w.3)).collect::<Vec<_>>();
    assert_eq!(strip(&got), strip(&want));

    // HAP frames of 100 packets: frame 0's 31st packet comes during frame 2.
    let fs = frames(5, 100);
    let mut order: Vec<Vec<u8>> = fs.iter().map(|(_, b)| b.clone()).collect();
    let k = at(&fs, 0, 30);
    let late = order.remove(k);
    let (want, _) = hap(&order);
    order.insert(at(&fs, 2, 10), late);
    let (got, st) = hap(&order);
    assert_eq!((st.late_dropped, st.missing, st.discontinuities), (1, 0, 0));
    assert_eq!(strip(&got), strip(&want));

    // Restarted: counters from 0 or 7, device time from power-on.
    for first in [0u16, 7] {
        let mut ps: Vec<Vec<u8>> = (0..150u16)
            .map(|k| sdk2(k, 0, T0 + u64::from(k) * P))
            .collect();
        ps.extend((0..150u16).map(|k| sdk2(first + k, 0, 5_000_000_000 + u64::from(k) * P)));
        let (seen, st) = mid360(&ps);
        assert_eq!(
            (st.discontinuities, st.late_dropped, st.missing),
            (1, 0, 0),
            "from {first}"
        );
        assert_eq!(total(&seen), 300 * 96);
    }
}

/// Packets of the frame just closed that come more than 10 of its packets behind its
/// newest: their gap is un-counted (once), and a copy of one is a copy — counted, never
/// decoded twice — whether the frame's sweep was handed over or is waiting for its IMU
/// samples. (Before: the gap stayed missing, and a copy joined the waiting sweep again.)
#[test]
fn a_closed_frame_s_packets_far_behind_count_once() {
    let fs = frames(5, 100);
    let base: Vec<Vec<u8>> = fs.iter().map(|(_, b)| b.clone()).collect();
    // Frame 1's 21st packet after frame 2's 6th; a copy of frame 1's 51st after frame 2's 9th.
    let mut order = base.clone();
    let late = order.remove(at(&fs, 1, 20));
    order.insert(at(&fs, 2, 5), late);
    order.insert(at(&fs, 2, 8) + 1, base[at(&fs, 1, 50)].clone());
    let (_, st) = hap(&order);
    assert_eq!(
        (
            st.missing,
            st.late_dropped,
            st.duplicates,
            st.discontinuities
        ),
        (0, 1, 1, 0)
    );
    // With IMU samples that stop at the start: frame 1's sweep waits while frame 2 comes,
    // and the late packet joins it; the copy does not.
    let with_imu = |ps: &[Vec<u8>]| {
        let mut v = vec![imu(0, T0)];
        v.extend_from_slice(ps);
        hap(&v)
    };
    let (want, _) = with_imu(&base);
    let (got, st) = with_imu(&order);
    assert_eq!(
        (
            st.missing,
            st.late_dropped,
            st.duplicates,
            st.discontinuities
        ),
        (0, 0, 1, 0)
    );
    assert_eq!(total(&got), total(&want));
    assert_eq!(
        got.iter().map(|s| s.0).collect::<Vec<_>>(),
        want.iter().map(|s| s.0).collect::<Vec<_>>()
    );
}

/// A frame's first packets lost: the next one's `udp_cnt` says how many, and the frame still
/// starts a sweep of its own. Reordered behind the second, the first is late. (Before: a
/// discontinuity and nothing missing.)
#[test]
fn a_frame_s_first_packets_lost_are_missing() {
    let fs = frames(5, 100);
    let base: Vec<Vec<u8>> = fs.iter().map(|(_, b)| b.clone()).collect();
    let (want, _) = hap(&base);
    let lost = [at(&fs, 2, 0), at(&fs, 3, 0), at(&fs, 3, 1)];
    let order: Vec<Vec<u8>> = (0..base.len())
        .filter(|k| !lost.contains(k))
        .map(|k| base[k].clone())
        .collect();
    let (got, st) = hap(&order);
    assert_eq!((st.missing, st.discontinuities), (3, 0));
    assert_eq!(got.len(), want.len());
    assert_eq!(got.iter().map(|s| s.2).collect::<Vec<_>>(), [0, 0, 1, 2, 0]);
    // The first behind the second.
    let mut order = base.clone();
    order.swap(at(&fs, 3, 0), at(&fs, 3, 1));
    let (got, st) = hap(&order);
    assert_eq!((st.missing, st.discontinuities, st.late_dropped), (0, 0, 0));
    assert_eq!(total(&got), total(&want));
}

/// A sweep never grows without bound: a timestamp that stands still (the period never ends)
/// is cut at the point cap (2^22 points for a MID-360 on 100 ms), a `frame_cnt` that stands
/// still at two periods; each cut counted. (Before: one sweep of everything.)
#[test]
fn a_sweep_is_cut_when_its_counters_or_time_stand_still() {
    let mut s = LivoxStream::new(LivoxConfig::new(Some(LivoxModel::Mid360), Protocol::Sdk2));
    let mut sizes = Vec::new();
    for k in 0..45_000u32 {
        s.push(0, &sdk2(k as u16, 0, T0), &mut |sw, _| {
            sizes.push(sw.points.len())
        });
    }
    s.finish(&mut |sw, _| sizes.push(sw.points.len()));
    assert_eq!(sizes.len(), 2, "{sizes:?}");
    assert!(
        sizes[0] >= 1 << 22 && sizes[0] < (1 << 22) + 96,
        "{sizes:?}"
    );
    assert_eq!(sizes.iter().sum::<usize>(), 45_000 * 96);
    assert_eq!(s.stats().forced_cuts, 1);

    // Packets of no points, the same time: cut at as many packets.
    let mut s = LivoxStream::new(LivoxConfig::new(Some(LivoxModel::Mid360), Protocol::Sdk2));
    let mut packets = Vec::new();
    let empty = sdk2_n(0, 0, T0, 0);
    for k in 0..((1u32 << 22) + 10) {
        let mut b = empty.clone();
        b[7..9].copy_from_slice(&(k as u16).to_le_bytes());
        s.push(0, &b, &mut |sw, _| packets.push(sw.packets));
    }
    s.finish(&mut |sw, _| packets.push(sw.packets));
    assert_eq!(packets, [1 << 22, 10]);

    // HAP: frames 0–2 of 100 packets 1 ms apart, then frame 3 never ends (1 s).
    let mut ps: Vec<Vec<u8>> = frames(3, 100).into_iter().map(|(_, b)| b).collect();
    ps.extend((0..1000u64).map(|k| sdk2(k as u16, 3, T0 + (300 + k) * 1_000_000)));
    let (seen, st) = hap(&ps);
    assert_eq!(st.forced_cuts, 4, "{seen:?}");
    assert!(seen.iter().all(|s| s.4 - s.3 < 200_000_000), "{seen:?}");
    assert_eq!(total(&seen), 1300 * 96);
}

/// A packet late by its `udp_cnt` (within the reorder window) joins the open sweep only where
/// its time falls inside it (0 ..= two periods after the sweep's start); a time that lies (5 s
/// ahead or behind), or one from before the sweep (reordered across the period's cut), puts
/// it in `late_dropped`, not in `missing` too, and the sweeps are those of the stream without
/// it. (Before: it joined the open sweep at t = u32::MAX or t = 0.) Likewise a packet of the
/// frame just closed, into its frame's sweep waiting for IMU samples. A frame's first packet
/// behind its second belongs to the sweep its second began: that sweep starts at it.
#[test]
fn a_late_packet_timed_outside_the_open_sweep_is_dropped() {
    let ps: Vec<Vec<u8>> = (0..300u16)
        .map(|k| sdk2(k, 0, T0 + u64::from(k) * P))
        .collect();
    let strip = |s: &Seen| s.iter().map(|w| (w.0, w.1, w.3, w.4)).collect::<Vec<_>>();
    // Packet 100 after 101, timed 5 s off; packet 208 after 209, which began the second sweep.
    for (k, ts) in [
        (100, T0 + 100 * P + 5_000_000_000),
        (100, T0 + 100 * P - 5_000_000_000),
        (208, T0 + 208 * P),
    ] {
        let mut without = ps.clone();
        without.remove(k);
        let (want, _) = mid360(&without);
        let mut order = ps.clone();
        order[k] = sdk2(k as u16, 0, ts);
        order.swap(k, k + 1);
        let (got, st) = mid360(&order);
        assert_eq!(
            (
                st.late_dropped,
                st.missing,
                st.packets,
                st.duplicates,
                st.discontinuities
            ),
            (1, 0, 299, 0, 0),
            "packet {k} at {ts}"
        );
        assert_eq!(strip(&got), strip(&want), "packet {k} at {ts}");
    }
    // Timed inside the open sweep, though not where its number says: it joins.
    let mut order = ps.clone();
    order[100] = sdk2(100, 0, T0 + 100 * P - 1_000_000);
    order.swap(100, 101);
    let (got, st) = mid360(&order);
    assert_eq!((st.late_dropped, st.missing, st.packets), (0, 0, 300));
    assert_eq!(total(&got), 300 * 96);
    // A frame's first packet behind its second, which began the frame's sweep: the sweep is
    // its frame's, and starts at it (its points were at t = 0, the sweep at the second).
    let fs = frames(5, 100);
    let base: Vec<Vec<u8>> = fs.iter().map(|(_, b)| b.clone()).collect();
    let (want, _) = hap(&base);
    let mut order = base.clone();
    order.swap(at(&fs, 3, 0), at(&fs, 3, 1));
    let (got, st) = hap(&order);
    assert_eq!((st.late_dropped, st.missing, st.packets), (0, 0, 500));
    assert_eq!(strip(&got), strip(&want));

    // HAP frames, the IMU stopped at the start: frame 1's sweep waits while frame 2 comes.
    // Frame 1's 96th packet after frame 2's 3rd, timed in frame 0 (before its sweep began).
    let mut base: Vec<Vec<u8>> = vec![imu(0, T0)];
    base.extend(fs.iter().map(|(_, b)| b.clone()));
    let k = 1 + at(&fs, 1, 95);
    let mut without = base.clone();
    without.remove(k);
    let (want, _) = hap(&without);
    let mut order = without.clone();
    let ts = T0 + 50_000_000;
    order.insert(at(&fs, 2, 3), sdk2(95, 1, ts));
    let (got, st) = hap(&order);
    assert_eq!(
        (st.late_dropped, st.missing, st.packets, st.duplicates),
        (1, 0, 499, 0)
    );
    assert_eq!(strip(&got), strip(&want));
}

/// HAP-like frames of 20 packets (20 ms): a packet three or four frames back, up to two
/// periods late, is counted once — `late_dropped`, its gap no longer missing — and a loss
/// of its frame that no packet fills stays missing. (Before: dropped, and still missing.)
#[test]
fn a_packet_three_or_more_frames_back_is_counted_once() {
    let fs = frames(8, 20);
    let base: Vec<Vec<u8>> = fs.iter().map(|(_, b)| b.clone()).collect();
    // Frame 0 loses its 12th packet for good; its 11th comes during frame 3, frame 1's 8th
    // during frame 5.
    let mut order = base.clone();
    let late_0 = order[at(&fs, 0, 10)].clone();
    let late_1 = order[at(&fs, 1, 7)].clone();
    order.insert(at(&fs, 5, 4), late_1);
    order.insert(at(&fs, 3, 4), late_0);
    for k in [at(&fs, 1, 7), at(&fs, 0, 11), at(&fs, 0, 10)] {
        order.remove(k);
    }
    let (seen, st) = hap(&order);
    assert_eq!(
        (
            st.late_dropped,
            st.missing,
            st.duplicates,
            st.discontinuities
        ),
        (2, 1, 0, 0)
    );
    assert_eq!(st.packets + st.late_dropped, order.len() as u64);
    assert_eq!(total(&seen), (8 * 20 - 3) * 96);
}

/// A copy of a packet already counted late (more than 10 behind, with the time it had) is a
/// duplicate, never late again and never un-counting another loss: from before the run's
/// first number, from before a closed frame's first number, three frames back. (Before:
/// each copy was counted in `late_dropped` again.)
#[test]
fn a_copy_of_a_stale_packet_is_a_duplicate() {
    // The stream starts at 482: 480 comes after 520, and again twice.
    let ps: Vec<Vec<u8>> = (480..800u16)
        .map(|k| sdk2(k, 0, T0 + u64::from(k) * P))
        .collect();
    let mut order = ps[2..].to_vec();
    order.insert(38, ps[0].clone());
    order.insert(39, ps[0].clone());
    order.insert(90, ps[0].clone());
    let (seen, st) = mid360(&order);
    assert_eq!(
        (
            st.late_dropped,
            st.duplicates,
            st.missing,
            st.discontinuities
        ),
        (1, 2, 0, 0)
    );
    assert_eq!(total(&seen), 318 * 96);

    // HAP frames of 20 packets, the first frame seen from its 6th: its 3rd comes during
    // frame 1 (its frame closed), its 8th three frames late, each with a copy later; frame
    // 0 lost its 10th for good.
    let fs = frames(8, 20);
    let base: Vec<Vec<u8>> = fs.iter().map(|(_, b)| b.clone()).collect();
    let (third, eighth) = (base[at(&fs, 0, 2)].clone(), base[at(&fs, 0, 7)].clone());
    let mut order = base.clone();
    order.insert(at(&fs, 4, 15), eighth.clone());
    order.insert(at(&fs, 3, 10), eighth.clone());
    order.insert(at(&fs, 3, 4), eighth);
    order.insert(at(&fs, 1, 19), third.clone());
    order.insert(at(&fs, 1, 5), third);
    order.remove(at(&fs, 0, 9));
    order.remove(at(&fs, 0, 7));
    order.drain(..5);
    let (_, st) = hap(&order);
    assert_eq!(
        (
            st.late_dropped,
            st.duplicates,
            st.missing,
            st.discontinuities
        ),
        (2, 3, 1, 0)
    );
}

/// HAP-like frames of at most 11 packets, the stream seen from the middle of its first
/// frame: the next frame's first packet (`udp_cnt` 0, at most 10 behind the newest, before
/// any number the stream holds) starts that frame. Every packet is decoded, none missing,
/// and after the second frame start the sweeps are the frames. (Before: the next frame's
/// first packets were taken for reordered ones of the open frame, and the first its ledger
/// had seen started the frame with those before it counted missing: 2 for 5-packet frames.)
#[test]
fn a_frame_shorter_than_the_reorder_window_starts_the_next_frame() {
    for (per, skip) in [(5u16, 2usize), (3, 1), (11, 2), (11, 1)] {
        let fs = frames(6, per);
        let order: Vec<Vec<u8>> = fs[skip..].iter().map(|(_, b)| b.clone()).collect();
        let (seen, st) = hap(&order);
        let pushed = order.len() as u64;
        assert_eq!(
            (
                st.missing,
                st.late_dropped,
                st.duplicates,
                st.discontinuities,
                st.packets
            ),
            (0, 0, 0, 0, pushed),
            "frames of {per}, from {skip}"
        );
        // Frames 0 and 1 in one sweep (the frame cut is taken at the second frame start),
        // then one sweep a frame, each from its first packet (1 ms apart).
        let per_ = usize::from(per);
        let mut want = vec![(
            (2 * per_ - skip) * 96,
            (2 * per_ - skip) as u32,
            0u64,
            (T0 + skip as u64 * 1_000_000) as i64,
        )];
        for f in 2..6 {
            want.push((
                per_ * 96,
                u32::from(per),
                0,
                (T0 + (f * per_) as u64 * 1_000_000) as i64,
            ));
        }
        let got: Vec<_> = seen.iter().map(|w| (w.0, w.1, w.2, w.3)).collect();
        assert_eq!(got, want, "frames of {per}, from {skip}");
    }
}

/// A copy of the newest packet that comes after more than 11 other packets (here frame 0's
/// last 15, reordered after frame 1's 6th and dropped late: the copy's time has left the
/// 11 kept) is a duplicate: the ledger has its number and its time is the newest's. (Before:
/// a counter restart, one discontinuity, the copy decoded twice and the closed frames'
/// numbers forgotten.) A sensor whose counter goes back to numbers it sent and goes on from
/// there, its time going on, still restarted: one discontinuity, every packet decoded.
#[test]
fn a_copy_of_the_newest_packet_is_a_duplicate_however_many_came_since() {
    let fs = frames(3, 100);
    let base: Vec<Vec<u8>> = fs.iter().map(|(_, b)| b.clone()).collect();
    let (first, last) = (at(&fs, 0, 85), at(&fs, 0, 99));
    let without: Vec<Vec<u8>> = base
        .iter()
        .enumerate()
        .filter(|(k, _)| !(first..=last).contains(k))
        .map(|(_, b)| b.clone())
        .collect();
    let (want, _) = hap(&without);
    let mut order = without.clone();
    let newest = order
        .iter()
        .position(|b| *b == base[at(&fs, 1, 5)])
        .unwrap();
    order.splice(newest + 1..newest + 1, base[first..=last].iter().cloned());
    order.insert(newest + 16, base[at(&fs, 1, 5)].clone());
    let (got, st) = hap(&order);
    assert_eq!(
        (
            st.duplicates,
            st.discontinuities,
            st.late_dropped,
            st.missing,
            st.packets
        ),
        (1, 0, 15, 0, 285)
    );
    assert_eq!(
        st.packets + st.duplicates + st.late_dropped,
        order.len() as u64
    );
    let strip = |s: &Seen| s.iter().map(|w| (w.0, w.1, w.2, w.3)).collect::<Vec<_>>();
    assert_eq!(strip(&got), strip(&want));

    // Restarted at 140, 10 numbers back, the time going on.
    let mut ps: Vec<Vec<u8>> = (0..150u16)
        .map(|k| sdk2(k, 0, T0 + u64::from(k) * P))
        .collect();
    ps.extend((0..150u16).map(|k| sdk2(140 + k, 0, T0 + u64::from(150 + k) * P)));
    let (seen, st) = mid360(&ps);
    assert_eq!(
        (
            st.discontinuities,
            st.duplicates,
            st.late_dropped,
            st.missing,
            st.packets
        ),
        (1, 0, 0, 0, 300)
    );
    assert_eq!(total(&seen), 300 * 96);
}

/// SDK1 (Mid-40: 100 records 10 µs apart, 1 ms a packet): a packet reordered behind the one
/// that began the next sweep (packet 99 after 100, the period's cut between them) is timed
/// before that sweep: dropped, counted once in `late_dropped`, not missing, the sweeps those
/// of the stream without it; one reordered inside the open sweep joins it. (Before: its
/// points went into the open sweep at t = 0.)
#[test]
fn an_sdk1_late_packet_timed_outside_the_open_sweep_is_dropped() {
    let mid40_ = |ps: &[Vec<u8>]| run(Some(LivoxModel::Mid40), Protocol::Sdk1, ps);
    let strip = |s: &Seen| s.iter().map(|w| (w.0, w.1, w.3, w.4)).collect::<Vec<_>>();
    let ps = mid40(300, &[]);
    let (want, _) = mid40_(&mid40(300, &[99]));
    let mut order = ps.clone();
    order.swap(99, 100);
    let (got, st) = mid40_(&order);
    assert_eq!(
        (
            st.late_dropped,
            st.missing,
            st.packets,
            st.duplicates,
            st.discontinuities
        ),
        (1, 0, 299, 0, 0)
    );
    assert_eq!(st.packets + st.late_dropped, order.len() as u64);
    assert_eq!(strip(&got), strip(&want));
    assert!(got.iter().all(|w| w.2 == 0), "{got:?}");

    // Packet 150 after 151, inside the sweep begun at 100: it joins.
    let mut order = ps.clone();
    order.swap(150, 151);
    let (got, st) = mid40_(&order);
    assert_eq!((st.late_dropped, st.missing, st.packets), (0, 0, 300));
    let (want, _) = mid40_(&ps);
    assert_eq!(strip(&got), strip(&want));
}

/// IMU packets 5 ms apart: 0–9, 20 (10–19 lost), then 10–19 late, then 21; the late ones
/// push 20's time out of the 11 kept. A copy of 20 (now second newest) and a copy of 21
/// after them are copies: every packet counted once, nothing missing. (Before: the copy of
/// 20 restarted the counter, counted an IMU packet, and 22 after it counted 21 missing.) A
/// counter that goes back to numbers it sent, its time going on, still restarted.
#[test]
fn an_imu_copy_is_a_duplicate_once_its_time_is_pushed_out() {
    let t = |k: u64| T0 + k * 5_000_000;
    let mut ps: Vec<Vec<u8>> = (0..10u16).map(|k| imu(k, t(u64::from(k)))).collect();
    ps.push(imu(20, t(20)));
    ps.extend((10..20u16).map(|k| imu(k, t(u64::from(k)))));
    ps.push(imu(21, t(21)));
    // Point packets between do not change it.
    ps.extend((0..30u16).map(|k| sdk2(k, 0, t(21) + u64::from(k) * P)));
    ps.push(imu(20, t(20)));
    ps.push(imu(21, t(21)));
    ps.push(imu(22, t(22)));
    let (_, st) = mid360(&ps);
    assert_eq!(
        (st.imu_packets, st.duplicates, st.imu_missing, st.packets),
        (23, 2, 0, 30)
    );
    assert_eq!(st.imu_packets + st.duplicates + st.packets, ps.len() as u64);

    // Back 5 numbers at 50, the time going on: a restart, every packet an IMU packet.
    let mut ps: Vec<Vec<u8>> = (0..50u16).map(|k| imu(k, t(u64::from(k)))).collect();
    ps.extend((0..50u16).map(|k| imu(45 + k, t(50 + u64::from(k)))));
    let (_, st) = mid360(&ps);
    assert_eq!((st.imu_packets, st.duplicates, st.imu_missing), (100, 0, 0));
}

/// A late packet dropped (timed before the sweep it would join) is taken off the count of
/// the sweep that counted it missing, as off the stream's: the sweeps' `missing_packets`
/// sum to the stream's `missing`. Packet 208 after 209, which began the second sweep (its
/// gap that sweep's); packet 207 after 209, with an IMU stopped at the start so that the
/// first sweep (whose 208 counted 207 missing) waits; packet 150 more than 10 behind (30
/// late, within two periods). (Before: each sweep kept its 1.)
#[test]
fn a_dropped_late_packet_is_off_its_sweep_s_missing_too() {
    let ps: Vec<Vec<u8>> = (0..300u16)
        .map(|k| sdk2(k, 0, T0 + u64::from(k) * P))
        .collect();
    for (k, by, with_imu) in [(208, 1, false), (207, 2, true), (150, 30, false)] {
        let mut order = if with_imu {
            vec![imu(0, T0)]
        } else {
            Vec::new()
        };
        let mut rest = ps.clone();
        let late = rest.remove(k);
        rest.insert(k + by, late);
        order.extend(rest);
        let (seen, st) = mid360(&order);
        assert_eq!(
            (st.late_dropped, st.missing, st.packets, st.discontinuities),
            (1, 0, 299, 0),
            "packet {k}"
        );
        assert_eq!(
            seen.iter().map(|s| s.2).sum::<u64>(),
            st.missing,
            "packet {k}: {seen:?}"
        );
    }
}
