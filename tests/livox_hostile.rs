//! Hostile Livox datagrams: short, a length field that lies, a dot count that lies, a bad
//! CRC, unknown data types, garbage floods, an IMU flood nobody drains. Each is a counted drop
//! (or a counted gap), never a panic, and memory stays bounded.
#![cfg(feature = "sim")]

use ringscan::sensor::livox::family::detect_protocol;
use ringscan::sensor::livox::model::LivoxModel;
use ringscan::sensor::livox::sim::{encode_sdk2, encode_sdk2_imu, RawPoint, Sdk2Header};
use ringscan::sensor::livox::sweep::MAX_IMU_QUEUE;
use ringscan::sensor::livox::{LivoxConfig, LivoxStream, Protocol};

fn good(udp: u16, ts: u64) -> Vec<u8> {
    let h = Sdk2Header {
        time_interval: 4750,
        udp_cnt: udp,
        data_type: 1,
        time_type: 1,
        timestamp_ns: ts,
        ..Sdk2Header::default()
    };
    let pts: Vec<RawPoint> = (0..96)
        .map(|i| RawPoint {
            v: [1000 + i, 0, 0],
            reflectivity: 1,
            tag: 0,
        })
        .collect();
    encode_sdk2(&h, &pts)
}

fn mid360() -> LivoxStream {
    LivoxStream::new(LivoxConfig::new(Some(LivoxModel::Mid360), Protocol::Sdk2))
}

fn push_all(s: &mut LivoxStream, ps: &[Vec<u8>]) -> usize {
    let mut n = 0;
    for p in ps {
        s.push(0, p, &mut |sw, _| n += sw.points.len());
    }
    s.finish(&mut |sw, _| n += sw.points.len());
    n
}

#[test]
fn short_datagrams_are_malformed() {
    let p = good(0, 1_000_000);
    let mut s = mid360();
    let cut: Vec<Vec<u8>> = (0..p.len()).map(|n| p[..n].to_vec()).collect();
    let n = push_all(&mut s, &cut);
    assert_eq!(n, 0);
    assert_eq!(s.stats().malformed, p.len() as u64);
    assert_eq!(s.stats().packets, 0);
}

#[test]
fn lying_length_field_is_malformed() {
    let mut p = good(0, 1_000_000);
    let l = p.len() as u16 + 14;
    p[1..3].copy_from_slice(&l.to_le_bytes());
    let mut s = mid360();
    push_all(&mut s, &[p]);
    assert_eq!(s.stats().malformed, 1);
}

#[test]
fn lying_dot_count_is_malformed() {
    for dots in [0u16, 95, 97, u16::MAX] {
        let mut p = good(0, 1_000_000);
        p[5..7].copy_from_slice(&dots.to_le_bytes());
        let mut s = mid360();
        assert_eq!(push_all(&mut s, &[p]), 0, "dot_num {dots}");
        assert_eq!(s.stats().malformed, 1);
    }
}

#[test]
fn bad_crc_is_counted_and_dropped() {
    let mut p = good(0, 1_000_000);
    p[40] ^= 0x01; // a data byte
    let mut s = mid360();
    assert_eq!(push_all(&mut s, &[p.clone()]), 0);
    assert_eq!((s.stats().malformed, s.stats().crc_failures), (1, 1));
    // With checks off (`--crc off`) the same bytes decode.
    let mut cfg = LivoxConfig::new(Some(LivoxModel::Mid360), Protocol::Sdk2);
    cfg.check_crc = false;
    let mut s = LivoxStream::new(cfg);
    assert_eq!(push_all(&mut s, &[p]), 96);
    // A zero CRC field is a sensor that does not fill it: accepted, counted apart.
    let mut p = good(0, 1_000_000);
    p[24..28].fill(0);
    let mut s = mid360();
    assert_eq!(push_all(&mut s, &[p]), 96);
    assert_eq!(s.stats().crc_absent, 1);
}

#[test]
fn unknown_data_type_and_version_are_malformed() {
    let mut a = good(0, 1_000_000);
    a[10] = 9;
    let mut b = good(0, 1_000_000);
    b[0] = 1;
    assert!(detect_protocol(&a).is_none() && detect_protocol(&b).is_none());
    let mut s = mid360();
    push_all(&mut s, &[a, b]);
    assert_eq!(s.stats().malformed, 2);
}

#[test]
fn udp_counter_gaps_are_missing_packets() {
    let ps = [
        good(10, 1_000_000),
        good(11, 1_480_000),
        good(15, 3_400_000),
        good(16, 3_880_000),
    ];
    let mut s = mid360();
    let mut missing = 0;
    for p in &ps {
        s.push(0, p, &mut |sw, _| missing += sw.missing_packets);
    }
    s.finish(&mut |sw, _| missing += sw.missing_packets);
    assert_eq!(s.stats().missing, 3);
    assert_eq!(missing, 3);
}

#[test]
fn garbage_never_panics_and_is_never_claimed_as_points() {
    let mut s = mid360();
    let mut x = 0x1234_5678u32;
    let mut n = 0;
    for len in 0..1500usize {
        let mut b = vec![0u8; len];
        for v in b.iter_mut() {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            *v = x as u8;
        }
        if len >= 3 {
            // Make the version and length fields right half the time.
            if len % 2 == 0 {
                b[0] = 0;
                b[1..3].copy_from_slice(&(len as u16).to_le_bytes());
            }
        }
        s.push(0, &b, &mut |sw, _| n += sw.points.len());
    }
    s.finish(&mut |sw, _| n += sw.points.len());
    assert_eq!(
        s.stats().packets + s.stats().imu_packets + s.stats().malformed,
        1500
    );
}

#[test]
fn undrained_imu_is_bounded() {
    let mut s = mid360();
    for i in 0..(MAX_IMU_QUEUE + 100) {
        // Each its own packet (the same `udp_cnt` again would be a copy).
        let h = Sdk2Header {
            time_type: 1,
            timestamp_ns: 5 + i as u64,
            udp_cnt: i as u16,
            ..Sdk2Header::default()
        };
        let p = encode_sdk2_imu(&h, [0.0; 3], [0.0, 0.0, 1.0]);
        s.push(0, &p, &mut |_, _| {});
    }
    assert_eq!(s.stats().imu_dropped, 100);
    assert_eq!(s.drain_imu().count(), MAX_IMU_QUEUE);
}
