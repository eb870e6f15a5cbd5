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
