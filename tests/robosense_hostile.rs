//! Hostile Robosense input: wrong sizes, broken marks, out-of-range fields, floods before the
//! angles are known, unusable DIFOP tables, random bytes behind valid ids, hostile angle CSVs.
//! Every case is a clear error or a counted drop — never a panic, never unbounded memory.

use ringscan::sensor::robosense::family::parse_robosense_calibration;
use ringscan::sensor::robosense::sweep::MAX_HELD;
use ringscan::sensor::robosense::{Msop, RobosenseConfig, RobosenseModel, RobosenseStream};
use ringscan::sensor::{parse_calibration, CalibError, MAX_CALIB_BYTES};

fn helios_packet(az0: u16) -> Vec<u8> {
    let mut b = vec![0u8; 1248];
    b[..4].copy_from_slice(&[0x55, 0xAA, 0x05, 0x5A]);
    b[20..26].copy_from_slice(&[0, 0, 0x65, 0, 0, 0]);
    for blk in 0..12 {
        let o = 42 + 100 * blk;
        b[o] = 0xFF;
        b[o + 1] = 0xEE;
        let az = (az0 + 20 * blk as u16) % 36_000;
        b[o + 2..o + 4].copy_from_slice(&az.to_be_bytes());
        for s in 0..32 {
            b[o + 4 + 3 * s..o + 6 + 3 * s].copy_from_slice(&400u16.to_be_bytes());
        }
    }
    b
}

fn csv16() -> ringscan::sensor::robosense::RobosenseAngles {
    let s: String = (0..16).map(|i| format!("{},0\n", 15 - 2 * i)).collect();
    parse_robosense_calibration(s.as_bytes()).unwrap().unwrap()
}

fn stream(angles: bool) -> RobosenseStream {
    RobosenseStream::new(RobosenseConfig::new(angles.then(csv16)))
}

fn push(s: &mut RobosenseStream, p: &[u8]) -> usize {
    let mut n = 0;
    s.push(0, p, &mut |sw, _| n += sw.points.len()).unwrap();
    n
}

#[test]
fn wrong_sizes_and_marks_are_counted() {
    let mut s = stream(true);
    let good = helios_packet(100);
    push(&mut s, &good);
    assert_eq!(s.stats().packets, 1);
    for len in [0usize, 1, 42, 1247, 1249, 4000] {
        let mut p = good.clone();
        p.resize(len, 0);
        push(&mut s, &p);
    }
    assert_eq!(s.stats().malformed, 6);
    // A block flag broken in block 7, an azimuth of 360.00°.
    let mut p = good.clone();
    p[42 + 700] = 0x00;
    push(&mut s, &p);
    assert!(Msop::new(&p, RobosenseModel::Helios16P).is_err());
    let mut p = good.clone();
    p[42 + 300 + 2..42 + 300 + 4].copy_from_slice(&36_000u16.to_be_bytes());
    assert!(Msop::new(&p, RobosenseModel::Helios16P).is_err());
    push(&mut s, &p);
    assert_eq!(s.stats().malformed, 8);
    assert_eq!(s.stats().packets, 1);
}

#[test]
fn calendar_out_of_range_is_malformed() {
    let mut b = vec![0u8; 1248];
    b[..8].copy_from_slice(&[0x55, 0xAA, 0x05, 0x0A, 0x5A, 0xA5, 0x50, 0xA0]);
    b[20..30].copy_from_slice(&[24, 13, 40, 25, 61, 61, 0x27, 0x10, 0x27, 0x10]);
    for blk in 0..12 {
        b[42 + 100 * blk] = 0xFF;
        b[43 + 100 * blk] = 0xEE;
    }
    let mut cfg = RobosenseConfig::new(Some({
        let s: String = (0..16).map(|i| format!("{},0\n", -15 + 2 * i)).collect();
        parse_robosense_calibration(s.as_bytes()).unwrap().unwrap()
    }));
    cfg.model = Some(RobosenseModel::Rs16);
    let mut s = RobosenseStream::new(cfg);
    push(&mut s, &b);
    assert_eq!(s.stats().malformed, 1);
    assert_eq!(s.stats().packets, 0);
}

#[test]
fn a_flood_before_the_angles_is_bounded() {
    let mut s = stream(false);
    let p = helios_packet(0);
    for _ in 0..MAX_HELD + 500 {
        push(&mut s, &p);
    }
    assert_eq!(s.held(), MAX_HELD);
    assert_eq!(s.stats().dropped, 500);
    // A DIFOP whose table is unprogrammed (sign bytes FF): counted, packets still held.
    let mut d = vec![0u8; 1248];
    d[..8].copy_from_slice(&[0xA5, 0xFF, 0x00, 0x5A, 0x11, 0x11, 0x55, 0x55]);
    for b in d[468..660].iter_mut() {
        *b = 0xFF;
    }
    push(&mut s, &d);
    assert_eq!(s.stats().difop, 1);
    assert!(s.decoder().is_none());
    assert_eq!(s.held(), MAX_HELD);
    let mut n = 0;
    s.finish(&mut |sw, _| n += sw.points.len());
    assert_eq!(n, 0);
    assert_eq!(s.held(), 0);
    assert_eq!(s.stats().dropped, 500 + MAX_HELD as u64);
}

#[test]
fn angles_of_the_wrong_count_are_a_clear_error() {
    let s32: String = (0..32).map(|i| format!("{},0\n", 15 - i)).collect();
    let mut cfg = RobosenseConfig::new(Some(
        parse_robosense_calibration(s32.as_bytes())
            .unwrap()
            .unwrap(),
    ));
    cfg.model = Some(RobosenseModel::Helios16P);
    let mut s = RobosenseStream::new(cfg);
    let e = s.push(0, &helios_packet(0), &mut |_, _| {}).unwrap_err();
    assert!(e.to_string().contains("32 lasers"), "{e}");
}

#[test]
fn random_bytes_behind_valid_ids_never_panic() {
    let mut x = 0x9E37_79B9_7F4A_7C15u64;
    let mut rnd = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    let mut s = stream(true);
    let mut n = 0usize;
    for i in 0..3000 {
        let mut p: Vec<u8> = (0..1248).map(|_| rnd() as u8).collect();
        match i % 3 {
            0 => p[..4].copy_from_slice(&[0x55, 0xAA, 0x05, 0x5A]),
            1 => p[..8].copy_from_slice(&[0xA5, 0xFF, 0x00, 0x5A, 0x11, 0x11, 0x55, 0x55]),
            _ => {
                // Valid marks, random everything else (azimuths below 360°).
                p = helios_packet((rnd() % 36_000) as u16);
                for b in 0..12 {
                    let o = 42 + 100 * b;
                    for x in &mut p[o + 4..o + 100] {
                        *x = rnd() as u8;
                    }
                }
                // Any second of the u32 range, any µs of the second: times jump at random.
                p[22..26].copy_from_slice(&(rnd() as u32).to_be_bytes());
                p[26..30].copy_from_slice(&((rnd() % 1_000_000) as u32).to_be_bytes());
            }
        }
        s.push(i as i64, &p, &mut |sw, _| {
            for q in &sw.points {
                assert!(q.x.is_finite() && q.y.is_finite() && q.z.is_finite());
                assert!(q.ring < 16);
            }
            n += sw.points.len();
        })
        .unwrap();
    }
    s.finish(&mut |sw, _| n += sw.points.len());
    let st = s.stats();
    assert_eq!(st.packets + st.malformed + st.difop, 3000, "{st:?}");
    assert!(st.packets >= 1000);
}

#[test]
fn hostile_angle_csvs() {
    let rows = |f: &dyn Fn(usize) -> String, n: usize| -> String { (0..n).map(f).collect() };
    // Not this format: left to the other families (None), or refused with a reason.
    assert!(parse_robosense_calibration(b"\xff\xfe\x00garbage").is_none());
    assert!(parse_robosense_calibration(rows(&|i| format!("{i},0\n"), 129).as_bytes()).is_none());
    assert!(parse_robosense_calibration(rows(&|i| format!("{i},0\n"), 17).as_bytes()).is_none());
    assert!(parse_robosense_calibration(rows(&|_| "NaN,0\n".into(), 16).as_bytes()).is_none());
    assert!(parse_robosense_calibration(rows(&|_| "1,2,3\n".into(), 16).as_bytes()).is_none());
    for bad in ["1e308,0\n", "0,-95\n", "180,0\n"] {
        let t = rows(&|_| bad.to_string(), 16);
        let e = parse_robosense_calibration(t.as_bytes())
            .unwrap()
            .unwrap_err();
        assert!(matches!(e, CalibError::BadValue { .. }), "{e}");
    }
    // Through the shared path: a huge file is refused before parsing.
    let huge = vec![b'1'; MAX_CALIB_BYTES + 1];
    assert!(matches!(
        parse_calibration(&huge, "angle.csv", None),
        Err(CalibError::TooLarge(..))
    ));
    // And a good one is read by this family.
    let good = rows(&|i| format!("{}.25,-{}.5\n", i, i % 4), 32);
    let c = parse_calibration(good.as_bytes(), "angle.csv", None).unwrap();
    assert_eq!(c.family, "robosense");
}

/// A Unix time stamp whose seconds (bytes 20–25) are beyond what nanoseconds in an i64 hold
/// (found by the fuzz pass: the check allowed up to 2^34 s, whose ns overflow) is no time,
/// not a panic; the largest accepted second still converts.
#[test]
fn unix_seconds_beyond_the_i64_range_are_no_time() {
    use ringscan::sensor::robosense::model::ClockForm;
    let mut p = helios_packet(100);
    // 2^34 − 1 s: 0x03_FFFF_FFFF.
    p[20..26].copy_from_slice(&[0x00, 0x03, 0xFF, 0xFF, 0xFF, 0xFF]);
    let m = Msop::new(&p, RobosenseModel::Helios16P).unwrap();
    assert_eq!(m.stamp_ns(ClockForm::Unix), None);
    // 2^33 − 1 s, 999,999 µs.
    p[20..26].copy_from_slice(&[0x00, 0x01, 0xFF, 0xFF, 0xFF, 0xFF]);
    p[26..30].copy_from_slice(&999_999u32.to_be_bytes());
    let m = Msop::new(&p, RobosenseModel::Helios16P).unwrap();
    assert_eq!(
        m.stamp_ns(ClockForm::Unix),
        Some(((1i64 << 33) - 1) * 1_000_000_000 + 999_999_000)
    );
    let mut s = stream(true);
    let mut p = helios_packet(100);
    p[20..26].copy_from_slice(&[0xFF; 6]);
    push(&mut s, &p);
}

/// A valid M1 packet (1210 bytes, id `55 AA 5A A5`), counter `seq`, time `secs` s, every
/// channel at 4 m straight ahead.
fn m1_packet(seq: u16, secs: u32) -> Vec<u8> {
    let mut b = vec![0u8; 1210];
    b[..4].copy_from_slice(&[0x55, 0xAA, 0x5A, 0xA5]);
    b[4..6].copy_from_slice(&seq.to_be_bytes());
    b[12..16].copy_from_slice(&secs.to_be_bytes());
    for blk in 0..25 {
        for c in 0..5 {
            let o = 32 + 47 * blk + 2 + 9 * c;
            b[o..o + 6].copy_from_slice(&[0x03, 0x20, 0x80, 0x00, 0x80, 0x00]);
        }
    }
    b
}

/// M1: truncated, oversized, wrong-id and spinning-size packets, a µs field out of range, a
/// wrong-size DIFOP and a spinning model's DIFOP on the M1's stream — each a counted drop;
/// the good packets around them still decode (125 points each).
#[test]
fn m1_bad_packets_are_counted_drops() {
    use ringscan::sensor::robosense::m1::M1Msop;
    let mut s = RobosenseStream::new(RobosenseConfig::new(None));
    let good = m1_packet(1, 1_700_000_000);
    assert_eq!(push(&mut s, &good), 0);
    assert_eq!(s.stats().packets, 1);
    assert_eq!(s.facts().model, Some(RobosenseModel::M1));
    let mut bad = 0;
    for len in [0usize, 4, 32, 1209, 1211, 1248, 65_507] {
        let mut p = good.clone();
        p.resize(len, 0);
        assert!(M1Msop::new(&p).is_err());
        push(&mut s, &p);
        bad += 1;
    }
    let mut p = good.clone();
    p[2] = 0x5B; // not the M1's id
    push(&mut s, &p);
    bad += 1;
    let mut p = m1_packet(2, 1_700_000_000);
    p[16..20].copy_from_slice(&1_000_000u32.to_be_bytes()); // a µs field of a whole second
    push(&mut s, &p);
    bad += 1;
    let mut d = vec![0u8; 255];
    d[..8].copy_from_slice(&[0xA5, 0xFF, 0x00, 0x5A, 0x11, 0x11, 0x55, 0x55]);
    push(&mut s, &d);
    bad += 1;
    d.resize(1248, 0); // a spinning model's DIFOP: not this sensor's
    push(&mut s, &d);
    bad += 1;
    assert_eq!(s.stats().malformed, bad, "{:?}", s.stats());
    // The stream goes on: packets 2 and 20 (3–19 missing), then 19 late (a counter a little
    // below the last one is a late packet of the same frame, no longer missing), then the
    // next frame's packet 1, which ends the first frame.
    push(&mut s, &m1_packet(2, 1_700_000_000));
    push(&mut s, &m1_packet(20, 1_700_000_000));
    assert_eq!(push(&mut s, &m1_packet(19, 1_700_000_000)), 0);
    let n = push(&mut s, &m1_packet(1, 1_700_000_000));
    assert_eq!(n, 4 * 125);
    assert_eq!(s.held(), 0);
    assert_eq!((s.stats().packets, s.stats().missing), (5, 16));
}

/// M1 garbage: random bytes behind the M1's id and size (angles, radii, offsets, counters and
/// times at random) never panic, every packet is counted once, memory stays bounded (no
/// packet is held), and every point is finite, within 200 m, on a channel 0..4, return 0 / 1.
#[test]
fn m1_random_bytes_never_panic() {
    let mut x = 0x2545_F491_4F6C_DD1Du64;
    let mut rnd = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    let mut s = RobosenseStream::new(RobosenseConfig::new(None));
    let mut n = 0usize;
    for i in 0..3000 {
        let mut p: Vec<u8> = (0..1210).map(|_| rnd() as u8).collect();
        p[..4].copy_from_slice(&[0x55, 0xAA, 0x5A, 0xA5]);
        if i % 2 == 0 {
            // A plausible time, so that most packets decode.
            p[10..16].copy_from_slice(&[0, 0, 0x65, 0, 0, (i / 2) as u8]);
            p[16..20].copy_from_slice(&((rnd() % 1_000_000) as u32).to_be_bytes());
        }
        s.push(i as i64, &p, &mut |sw, _| {
            for q in &sw.points {
                assert!(q.x.is_finite() && q.y.is_finite() && q.z.is_finite());
                assert!((q.x * q.x + q.y * q.y + q.z * q.z).sqrt() <= 200.01);
                assert!(q.ring < 5 && q.ret <= 1, "{q:?}");
            }
            n += sw.points.len();
        })
        .unwrap();
        assert_eq!(s.held(), 0);
    }
    s.finish(&mut |sw, _| n += sw.points.len());
    let st = s.stats();
    assert_eq!(st.packets + st.malformed, 3000, "{st:?}");
    assert!(st.packets >= 1500, "{st:?}");
    assert!(n > 0 && n as u64 == st.points);
}

/// An M1 packet of counter `seq` at header time `stamp_ns` (whole µs), return-mode byte `mode`.
fn m1_at(seq: u16, stamp_ns: i64, mode: u8) -> Vec<u8> {
    let mut b = m1_packet(seq, 0);
    b[8] = mode;
    b[10..16].copy_from_slice(&(stamp_ns / 1_000_000_000).to_be_bytes()[2..]);
    b[16..20].copy_from_slice(&((stamp_ns % 1_000_000_000 / 1_000) as u32).to_be_bytes());
    b
}

/// M1 frames of `len` packets, 100 ms apart: (counter, header time) of frame `f`'s packet `q`
/// (counter q + 1).
fn m1_slot(f: i64, q: u16, len: u16) -> (u16, i64) {
    let t = 1_700_000_000_000_000_000 + f * 100_000_000;
    (
        q + 1,
        t + i64::from(q) * 100_000_000 / i64::from(len) / 1_000 * 1_000,
    )
}

/// Pushes M1 packets; (packets, points, missing packets) of each sweep emitted.
fn m1_run(s: &mut RobosenseStream, packets: &[Vec<u8>]) -> Vec<(u32, usize, u64)> {
    let mut out = Vec::new();
    for p in packets {
        s.push(0, p, &mut |sw, _| {
            out.push((sw.packets, sw.points.len(), sw.missing_packets))
        })
        .unwrap();
    }
    out
}

/// M1: a frame's last packet (630) arrives after the next frame's first (counter 1). It is
/// late, of a frame already emitted: dropped and counted once (late, not also missing); the
/// next frame is not cut again by it (the old code counted 628 packets lost, then cut the
/// next frame after its first packet, one more phantom loss).
#[test]
fn m1_a_frames_last_packet_after_the_next_frames_first_is_late() {
    let mut s = RobosenseStream::new(RobosenseConfig::new(None));
    let mut ps = Vec::new();
    // Three whole frames (the frame length is learned), then frame 3 whose 630 comes late.
    for f in 0..3 {
        for q in 0..630 {
            let (c, t) = m1_slot(f, q, 630);
            ps.push(m1_at(c, t, 4));
        }
    }
    for q in 0..629 {
        let (c, t) = m1_slot(3, q, 630);
        ps.push(m1_at(c, t, 4));
    }
    let (c, t) = m1_slot(4, 0, 630);
    ps.push(m1_at(c, t, 4));
    let (c, t) = m1_slot(3, 629, 630);
    ps.push(m1_at(c, t, 4));
    for q in 1..630 {
        let (c, t) = m1_slot(4, q, 630);
        ps.push(m1_at(c, t, 4));
    }
    let (c, t) = m1_slot(5, 0, 630);
    ps.push(m1_at(c, t, 4));
    let sweeps = m1_run(&mut s, &ps);
    let st = s.stats();
    assert_eq!(
        (st.missing, st.late_dropped, st.discontinuities),
        (0, 1, 0),
        "{st:?}"
    );
    // Frame 3 lacks its last packet (missing in it), frame 4 is whole and one sweep.
    assert_eq!(
        sweeps,
        [
            (630, 630 * 125, 0),
            (630, 630 * 125, 0),
            (630, 630 * 125, 0),
            (629, 629 * 125, 1),
            (630, 630 * 125, 0)
        ]
    );
}

/// M1: a stray packet with a corrupt counter (0xFFFF), and a switch from dual return (1260
/// packets a frame) to single (630), add no loss: every frame is whole. The old code kept
/// the largest counter ever seen and added it minus each frame's last at every frame end
/// (64 905 and 630 phantom packets a frame). A frame whose last packets are really lost
/// still counts them, once the frame length is known.
#[test]
fn m1_a_corrupt_counter_or_a_mode_change_adds_no_phantom_loss() {
    let mut s = RobosenseStream::new(RobosenseConfig::new(None));
    let mut ps = Vec::new();
    for f in 0..3 {
        for q in 0..1260 {
            let (c, t) = m1_slot(f, q, 1260);
            ps.push(m1_at(c, t, 5));
            if f == 1 && q == 100 {
                // Between two packets, a time of its own.
                ps.push(m1_at(0xFFFF, t + 20_000, 5));
            }
        }
    }
    for f in 3..8 {
        // Frame 6 loses its last 5 packets.
        let n = if f == 6 { 625 } else { 630 };
        for q in 0..n {
            let (c, t) = m1_slot(f, q, 630);
            ps.push(m1_at(c, t, 4));
        }
    }
    let (c, t) = m1_slot(8, 0, 630);
    ps.push(m1_at(c, t, 4));
    let sweeps = m1_run(&mut s, &ps);
    let st = s.stats();
    assert_eq!(
        (st.missing, st.discontinuities, st.duplicates),
        (5, 0, 0),
        "{st:?}"
    );
    let packets: Vec<u32> = sweeps.iter().map(|w| w.0).collect();
    assert_eq!(packets, [1260, 1261, 1260, 630, 630, 630, 625, 630]);
    let missing: Vec<u64> = sweeps.iter().map(|w| w.2).collect();
    assert_eq!(missing, [0, 0, 0, 0, 0, 0, 5, 0]);
}

/// M1: a copy of a packet older than the latest (counters 1, 2, 3, 5, then 2 again, same
/// bytes, then 6 … 20) is a copy: dropped, its points not added twice, and the real loss (4)
/// still counted. The old code took it for a late packet, un-counting 4's loss.
#[test]
fn m1_a_copy_of_an_older_packet_is_a_copy() {
    let p = |q: u16| {
        let (c, t) = m1_slot(0, q, 630);
        m1_at(c, t, 4)
    };
    let (c, t) = m1_slot(1, 0, 630);
    let next_frame = m1_at(c, t, 4);
    let run = |order: &[u16]| {
        let mut s = RobosenseStream::new(RobosenseConfig::new(None));
        let mut ps: Vec<Vec<u8>> = order.iter().map(|&q| p(q)).collect();
        ps.extend((5..20).map(p));
        ps.push(next_frame.clone());
        let sweeps = m1_run(&mut s, &ps);
        let st = s.stats();
        (sweeps, st.missing, st.duplicates, st.late_dropped)
    };
    assert_eq!(run(&[0, 1, 2, 4, 1]), (vec![(19, 19 * 125, 1)], 1, 1, 0));
    // A packet that really came late (4, after 5) fills its gap, in the sweep that counted
    // it; its copy is a copy.
    assert_eq!(run(&[0, 1, 2, 4, 3, 3]), (vec![(20, 20 * 125, 0)], 0, 1, 0));
}

/// M1 frames 0 and 1 whole and frame 2's first packet (which ends frame 1), `len` packets a
/// frame, return mode `mode`.
fn m1_two_frames(len: u16, mode: u8) -> Vec<Vec<u8>> {
    let mut ps = Vec::new();
    for f in 0..2 {
        for q in 0..len {
            let (c, t) = m1_slot(f, q, len);
            ps.push(m1_at(c, t, mode));
        }
    }
    let (c, t) = m1_slot(2, 0, len);
    ps.push(m1_at(c, t, mode));
    ps
}

/// (missing, late_dropped, duplicates, discontinuities).
type M1Counts = (u64, u64, u64, u64);

/// Sweeps (packets, points, missing) and the stream's counts.
fn m1_tally(ps: &[Vec<u8>]) -> (Vec<(u32, usize, u64)>, M1Counts) {
    let mut s = RobosenseStream::new(RobosenseConfig::new(None));
    let sweeps = m1_run(&mut s, ps);
    let st = s.stats();
    let c = (
        st.missing,
        st.late_dropped,
        st.duplicates,
        st.discontinuities,
    );
    (sweeps, c)
}

/// M1, single (630 packets a frame) and dual return (1260): one packet of the open frame
/// (frame 1's 101st) arriving 15 or 40 packets late, beyond the 10-number window, is counted
/// once: it joins its frame's sweep (its time is inside it), no longer missing, the sweeps as
/// if it had come in order. The old code took it for a discontinuity (more than 10 packet
/// periods behind in time) or, in dual return within that time, dropped it into
/// `late_dropped` and left it counted missing too. Frame 1's first packet 15 late is before
/// its sweep's start: dropped, counted once (`late_dropped`, not missing).
#[test]
fn m1_a_packet_far_late_in_its_own_frame_is_counted_once() {
    for (len, mode) in [(630usize, 4u8), (1260, 5)] {
        let base = m1_two_frames(len as u16, mode);
        let (in_order, c) = m1_tally(&base);
        assert_eq!(c, (0, 0, 0, 0));
        for late in [15usize, 40] {
            let mut ps = base.clone();
            let p = ps.remove(len + 100);
            ps.insert(len + 100 + late, p);
            assert_eq!(
                m1_tally(&ps),
                (in_order.clone(), (0, 0, 0, 0)),
                "{len} {late}"
            );
        }
        let mut ps = base.clone();
        let p = ps.remove(len);
        ps.insert(len + 15, p);
        let (sweeps, c) = m1_tally(&ps);
        assert_eq!(c, (0, 1, 0, 0), "{len}");
        let packets: Vec<u32> = sweeps.iter().map(|w| w.0).collect();
        assert_eq!(packets, [len as u32, len as u32 - 1], "{len}");
    }
}

/// M1: a copy of a packet that came 15 or 40 packets late in its own frame is a duplicate
/// (right after it, and again 30 packets on), not late again: counted once, the sweeps as
/// in order. The old code counted each copy in `late_dropped` (or cut a discontinuity).
#[test]
fn m1_a_copy_of_a_far_late_packet_is_a_duplicate() {
    for (len, mode) in [(630usize, 4u8), (1260, 5)] {
        let base = m1_two_frames(len as u16, mode);
        let (in_order, _) = m1_tally(&base);
        for late in [15usize, 40] {
            let mut ps = base.clone();
            let p = ps.remove(len + 100);
            let at = len + 100 + late;
            ps.insert(at, p.clone());
            ps.insert(at + 1, p.clone());
            ps.insert(at + 31, p);
            assert_eq!(
                m1_tally(&ps),
                (in_order.clone(), (0, 0, 2, 0)),
                "{len} {late}"
            );
        }
    }
}

/// A Helios-16P packet (the angles of `csv16`) at `t_us` µs after a base time, first block
/// at `az0`, 0.20° a block.
fn helios_at(az0: u16, t_us: i64) -> Vec<u8> {
    let mut b = helios_packet(az0);
    let t = 0x6500_0000i64 * 1_000_000 + t_us;
    b[20..26].copy_from_slice(&(t / 1_000_000).to_be_bytes()[2..]);
    b[26..30].copy_from_slice(&((t % 1_000_000) as u32).to_be_bytes());
    b
}

/// The Helios-16P's packet period, µs, and the packets of a head turning at 600 rpm: packet
/// `k` at `k` periods, 12 blocks of 0.20° (2.4° a packet; 150 packets a turn, 100 ms).
fn helios_turning(k: i64) -> Vec<u8> {
    let period_us = RobosenseModel::Helios16P.spec().packet_period_ns(false) / 1_000.0;
    helios_at(
        ((k * 240).rem_euclid(36_000)) as u16,
        (k as f64 * period_us).round() as i64,
    )
}

/// Pushes spinning packets; (packets, points, missing packets, first `t`, last `t`) of each
/// sweep emitted, `finish` included.
fn spin_run(s: &mut RobosenseStream, packets: &[Vec<u8>]) -> Vec<(u32, usize, u64, u32, u32)> {
    let mut out = Vec::new();
    let mut on = |sw: &mut ringscan::sweep::Sweep, _: &_| {
        let t = sw.points.iter().map(|p| p.t);
        out.push((
            sw.packets,
            sw.points.len(),
            sw.missing_packets,
            t.clone().min().unwrap_or(0),
            t.max().unwrap_or(0),
        ))
    };
    for p in packets {
        s.push(0, p, &mut on).unwrap();
    }
    s.finish(&mut on);
    out
}

fn helios_stream() -> RobosenseStream {
    let mut cfg = RobosenseConfig::new(Some(csv16()));
    cfg.model = Some(RobosenseModel::Helios16P);
    RobosenseStream::new(cfg)
}

/// A motor that stalls (the azimuth stands still while the header time goes on, 3 s of
/// packets) never reaches the cut: its sweep is still cut once it spans more than
/// `max_sweep_ns` (1 s), each cut a discontinuity, and every point is handed over once. The
/// old code held one sweep for the whole stream (unbounded memory).
#[test]
fn a_stalled_motor_still_cuts_its_sweeps() {
    let period_us = RobosenseModel::Helios16P.spec().packet_period_ns(false) / 1_000.0;
    let n = (3e6 / period_us) as i64;
    let ps: Vec<Vec<u8>> = (0..n)
        .map(|k| helios_at(9_000, (k as f64 * period_us).round() as i64))
        .collect();
    let mut s = helios_stream();
    let sweeps = spin_run(&mut s, &ps);
    assert!(sweeps.len() >= 3, "{}", sweeps.len());
    for w in &sweeps {
        assert!(w.4 <= 1_000_000_000 + 1_000_000, "{w:?}");
    }
    let st = s.stats();
    assert_eq!(st.discontinuities as usize, sweeps.len() - 1, "{st:?}");
    assert_eq!(st.missing, 0);
    // A packet a cut splits counts in both sweeps; its points go to one or the other.
    let one = spin_run(&mut helios_stream(), &ps[..1])[0].1;
    assert!(one > 0);
    assert_eq!(sweeps.iter().map(|w| w.1).sum::<usize>(), n as usize * one);
    assert_eq!(sweeps.iter().map(|w| w.1 as u64).sum::<u64>(), st.points);
}

/// Spinning: the last packet before the cut arrives after the first one past it. Its firings
/// belong to the sweep already emitted: dropped (`late_dropped`), not added to the new sweep
/// at time 0; the gap it left moves from `missing` to `late_dropped`, and stays missing in
/// the sweep that lost it. The new sweep is what it is in order.
#[test]
fn a_late_packet_of_the_sweep_before_is_dropped() {
    // Packet 150 crosses 0° (its block 0 at 360.00° − 0 = 0.00°): the cut.
    let order: Vec<i64> = (0..300).collect();
    let mut late = order.clone();
    late.swap(148, 149);
    late.swap(149, 150); // …, 147, 149, 150, 148, 151, …
    let all = |o: &[i64]| o.iter().map(|&k| helios_turning(k)).collect::<Vec<_>>();
    let mut s = helios_stream();
    let in_order = spin_run(&mut s, &all(&order));
    assert_eq!(in_order.len(), 2);
    let mut s = helios_stream();
    let got = spin_run(&mut s, &all(&late));
    // The new sweep is what it is in order (the old code added the late packet to it, its
    // times clamped to 0).
    assert_eq!(got[1], in_order[1]);
    let st = s.stats();
    assert_eq!(
        (st.missing, st.late_dropped, st.discontinuities),
        (0, 1, 0),
        "{st:?}"
    );
    let per_packet = in_order[0].1 / in_order[0].0 as usize;
    assert_eq!(got[0].0, in_order[0].0 - 1);
    assert_eq!(got[0].1, in_order[0].1 - per_packet);
    assert_eq!(got[0].2, 1, "the sweep that lost it");
}

/// Spinning: a packet from before the stream's first (late, but inside no gap counted) does
/// not un-count a real loss elsewhere: 2, 3, 5 (4 lost), then 1. The old code un-counted 4.
#[test]
fn a_late_packet_fills_only_a_gap_counted() {
    let ps: Vec<Vec<u8>> = [2, 3, 5, 1, 6].iter().map(|&k| helios_turning(k)).collect();
    let mut s = helios_stream();
    let sweeps = spin_run(&mut s, &ps);
    let st = s.stats();
    assert_eq!(
        (st.missing, st.late_dropped, st.discontinuities),
        (1, 1, 0),
        "{st:?}"
    );
    assert_eq!(sweeps.len(), 1);
    assert_eq!((sweeps[0].0, sweeps[0].2), (4, 1));
}

/// Every datagram pushed is counted once: decoded, malformed, a DIFOP, dropped from the hold,
/// a copy or late and dropped.
fn counted_once(s: &RobosenseStream, pushed: usize) {
    let st = s.stats();
    let c = st.packets + st.malformed + st.difop + st.dropped + st.duplicates + st.late_dropped;
    assert_eq!(c, pushed as u64, "{st:?}");
}

/// M1, single and dual return: frame 1's first packet arriving 15 packets late, before its
/// sweep's start, is dropped into `late_dropped` and so is no longer missing, in the stream
/// nor in its sweep: the sweeps' `missing_packets` add up to the stream's `missing` (0). The
/// old code left it missing in the sweep (1) while the stream counted it late: twice.
#[test]
fn m1_a_late_dropped_first_packet_is_not_missing_in_its_sweep() {
    for (len, mode) in [(630usize, 4u8), (1260, 5)] {
        let mut ps = m1_two_frames(len as u16, mode);
        let p = ps.remove(len);
        ps.insert(len + 15, p);
        let mut s = RobosenseStream::new(RobosenseConfig::new(None));
        let mut sweeps = m1_run(&mut s, &ps);
        s.finish(&mut |sw, _| sweeps.push((sw.packets, sw.points.len(), sw.missing_packets)));
        let st = s.stats();
        assert_eq!(
            (st.missing, st.late_dropped, st.duplicates),
            (0, 1, 0),
            "{len}"
        );
        let per_sweep: Vec<(u32, u64)> = sweeps.iter().map(|w| (w.0, w.2)).collect();
        assert_eq!(
            per_sweep,
            [(len as u32, 0), (len as u32 - 1, 0), (1, 0)],
            "{len}"
        );
        assert_eq!(sweeps.iter().map(|w| w.2).sum::<u64>(), st.missing);
        counted_once(&s, ps.len());
    }
}

/// M1: a copy of one of the frame before's packets, 15 or 40 counters behind that frame's
/// last, arriving once the next frame has begun, is a duplicate (it came already), in single
/// and dual return; a packet of it that really came late there is late (dropped, no longer
/// missing). The old code counted the copy in `late_dropped` (dual return, within 10 packet
/// periods in time) or cut a discontinuity (further back in time), and the late packet a
/// discontinuity too, with a frame's worth of phantom loss after it.
#[test]
fn m1_a_copy_from_the_frame_before_far_back_is_a_duplicate() {
    for (len, mode) in [(630usize, 4u8), (1260, 5)] {
        let base = m1_two_frames(len as u16, mode);
        let (in_order, _) = m1_tally(&base);
        for back in [15usize, 40] {
            // A copy of frame 1's packet `len − back`, after frame 2's first packet.
            let mut ps = base.clone();
            ps.push(base[2 * len - 1 - back].clone());
            let (_, s_in_order) = m1_tally(&ps[..ps.len() - 1]);
            assert_eq!(s_in_order, (0, 0, 0, 0));
            let (sweeps, c) = m1_tally(&ps);
            assert_eq!(
                (sweeps, c),
                (in_order.clone(), (0, 0, 1, 0)),
                "{len} {back}"
            );
            let mut s = RobosenseStream::new(RobosenseConfig::new(None));
            m1_run(&mut s, &ps);
            counted_once(&s, ps.len());
            // That packet came only then: late, of a frame emitted, counted once.
            let mut ps = base.clone();
            let p = ps.remove(2 * len - 1 - back);
            ps.push(p);
            let mut s = RobosenseStream::new(RobosenseConfig::new(None));
            let sweeps = m1_run(&mut s, &ps);
            let st = s.stats();
            assert_eq!(
                (
                    st.missing,
                    st.late_dropped,
                    st.duplicates,
                    st.discontinuities
                ),
                (0, 1, 0, 0),
                "{len} {back}"
            );
            assert_eq!(sweeps[1].0, len as u32 - 1, "{len} {back}");
            counted_once(&s, ps.len());
        }
    }
}

/// Spinning (Helios-16P, 150 packets a turn): a packet 15 or 40 packets late, beyond the
/// 10-packet window, is counted once, as the M1's: in its open sweep it joins it (the sweeps
/// as in order, nothing missing); of the sweep before, emitted, it is dropped into
/// `late_dropped` (no longer missing in the stream; the sweep that lost it says so); a copy
/// of a packet that came, 15 or 40 packets on, is a duplicate. The old code took each for
/// the clock going back: a discontinuity, the sweep cut there, and the packets between it
/// and the latest counted missing again.
#[test]
fn a_spinning_packet_far_late_is_counted_once() {
    let all = |o: &[i64]| o.iter().map(|&k| helios_turning(k)).collect::<Vec<_>>();
    let order: Vec<i64> = (0..300).collect();
    let in_order = spin_run(&mut helios_stream(), &all(&order));
    assert_eq!(in_order.len(), 2);
    let counts = |s: &RobosenseStream| {
        let st = s.stats();
        (
            st.missing,
            st.late_dropped,
            st.duplicates,
            st.discontinuities,
        )
    };
    for late in [15usize, 40] {
        // Packet 60 of sweep 0, late within it.
        let mut o = order.clone();
        let k = o.remove(60);
        o.insert(60 + late, k);
        let mut s = helios_stream();
        let got = spin_run(&mut s, &all(&o));
        assert_eq!((counts(&s), &got), ((0, 0, 0, 0), &in_order), "{late}");
        counted_once(&s, o.len());
        // Packet 140 of sweep 0, come after sweep 1 began (the cut at packet 150).
        let mut o = order.clone();
        let k = o.remove(140);
        o.insert(140 + late, k);
        let mut s = helios_stream();
        let got = spin_run(&mut s, &all(&o));
        assert_eq!(counts(&s), (0, 1, 0, 0), "{late}");
        assert_eq!(got[1], in_order[1], "{late}");
        assert_eq!((got[0].0, got[0].2), (in_order[0].0 - 1, 1), "{late}");
        counted_once(&s, o.len());
        // A copy of packet 60, `late` packets after it.
        let mut o = order.clone();
        o.insert(61 + late, 60);
        let mut s = helios_stream();
        let got = spin_run(&mut s, &all(&o));
        assert_eq!((counts(&s), &got), ((0, 0, 1, 0), &in_order), "{late}");
        counted_once(&s, o.len());
    }
}

/// A spinning model whose header clock steps back by less than a turn (5, 40 and 140
/// packets) while the rotor turns on: the packets after the step land on places in time that
/// came already, but their azimuths continue from the latest packet's, where a late packet's
/// or a copy's lie as far behind as their time. The rotor tells them apart: one
/// discontinuity, every packet decoded, none a duplicate or late. Taking them by their time
/// alone dropped up to a turn of data as copies.
#[test]
fn a_spinning_clock_stepping_back_is_a_discontinuity_not_copies() {
    let period_us = RobosenseModel::Helios16P.spec().packet_period_ns(false) / 1_000.0;
    for back in [5i64, 40, 140] {
        let packets: Vec<Vec<u8>> = (0..300i64)
            .map(|k| {
                let t = if k < 100 { k } else { k - back };
                helios_at(
                    ((k * 240).rem_euclid(36_000)) as u16,
                    (t as f64 * period_us).round() as i64,
                )
            })
            .collect();
        let mut s = helios_stream();
        let sweeps = spin_run(&mut s, &packets);
        let st = s.stats();
        assert_eq!(
            (
                st.discontinuities,
                st.duplicates,
                st.late_dropped,
                st.packets
            ),
            (1, 0, 0, 300),
            "{back}: {st:?}"
        );
        assert_eq!(
            sweeps.iter().map(|s| u64::from(s.0)).sum::<u64>(),
            300,
            "{back}"
        );
        counted_once(&s, packets.len());
    }
}
