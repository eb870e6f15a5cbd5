//! Livox packets written byte by byte at the offsets of the published protocols (Livox
//! "Communication Protocol — Mid360" §2 for SDK2; Livox-SDK `livox_def.h` / "Livox SDK
//! Communication Protocol" §3 for SDK1), not by ringscan's encoder, decode to the values
//! written into them: every data type, the per-point time rule, the line rule, the tag, the
//! clock, IMU units.

use ringscan::point::Point;
use ringscan::sensor::livox::model::LivoxModel;
use ringscan::sensor::livox::{LivoxConfig, LivoxStream, Protocol};
use ringscan::sensor::{CalibrationPool, FirstDatagram, ImuSample, StreamSettings};
use ringscan::sweep::Sweep;
use ringscan::time::ClockSource;
use std::net::Ipv4Addr;

/// CRC-32 of the protocol's table (poly 0x04C11DB7 reflected, init and xorout all ones),
/// bit by bit, written here independently of the crate's table.
fn crc32_bitwise(bytes: &[u8]) -> u32 {
    let mut c = 0xFFFF_FFFFu32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 == 1 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}

const TS: u64 = 1_700_000_000_123_456_789;

/// An SDK2 packet: the 36-byte header at its documented offsets, then `data`.
fn sdk2(
    data_type: u8,
    time_type: u8,
    dot_num: u16,
    interval_01us: u16,
    udp: u16,
    data: &[u8],
) -> Vec<u8> {
    let mut b = vec![0u8; 36 + data.len()];
    b[0] = 0; // version
    let len = b.len() as u16;
    b[1..3].copy_from_slice(&len.to_le_bytes()); // length
    b[3..5].copy_from_slice(&interval_01us.to_le_bytes()); // time_interval, 0.1 µs
    b[5..7].copy_from_slice(&dot_num.to_le_bytes()); // dot_num
    b[7..9].copy_from_slice(&udp.to_le_bytes()); // udp_cnt
    b[9] = 0; // frame_cnt
    b[10] = data_type;
    b[11] = time_type;
    // 12..24 reserved
    b[28..36].copy_from_slice(&TS.to_le_bytes()); // timestamp
    b[36..].copy_from_slice(data);
    let crc = crc32_bitwise(&b[28..]); // timestamp + data
    b[24..28].copy_from_slice(&crc.to_le_bytes());
    b
}

fn stream(model: Option<LivoxModel>, protocol: Protocol) -> LivoxStream {
    LivoxStream::new(LivoxConfig::new(model, protocol))
}

fn run(s: &mut LivoxStream, packets: &[Vec<u8>]) -> Vec<Sweep> {
    let mut out = Vec::new();
    for (i, p) in packets.iter().enumerate() {
        s.push(1_000 + i as i64, p, &mut |sw, _| out.push(sw.clone()));
    }
    s.finish(&mut |sw, _| out.push(sw.clone()));
    out
}

fn close(p: &Point, xyz: [f32; 3]) {
    for k in 0..3 {
        let v = [p.x, p.y, p.z][k];
        assert!((v - xyz[k]).abs() < 1e-5, "{p:?} vs {xyz:?}");
    }
}

#[test]
fn sdk2_type1_cartesian_mm() {
    let mut d = Vec::new();
    // record 0: x 1234 mm, y −5678 mm, z 910 mm, reflectivity 77, tag 0x15
    d.extend_from_slice(&1234i32.to_le_bytes());
    d.extend_from_slice(&(-5678i32).to_le_bytes());
    d.extend_from_slice(&910i32.to_le_bytes());
    d.extend_from_slice(&[77, 0x15]);
    // record 1: (−1, 2, 3) mm, 255, tag 0
    d.extend_from_slice(&(-1i32).to_le_bytes());
    d.extend_from_slice(&2i32.to_le_bytes());
    d.extend_from_slice(&3i32.to_le_bytes());
    d.extend_from_slice(&[255, 0]);
    // record 2: all zero (no return)
    d.extend_from_slice(&[0u8; 14]);
    // 3 points, last − first = 2.0 µs
    let p = sdk2(1, 1, 3, 20, 0, &d);
    assert_eq!(p.len(), 36 + 3 * 14);
    let mut s = stream(Some(LivoxModel::Mid360), Protocol::Sdk2);
    let sw = run(&mut s, &[p]);
    assert_eq!(sw.len(), 1);
    let pts = &sw[0].points;
    assert_eq!(pts.len(), 2);
    close(&pts[0], [1.234, -5.678, 0.910]);
    close(&pts[1], [-0.001, 0.002, 0.003]);
    assert_eq!((pts[0].intensity, pts[1].intensity), (77.0, 255.0));
    assert_eq!((pts[0].pad, pts[1].pad), (0x15, 0));
    assert_eq!((pts[0].ring, pts[1].ring), (0, 1)); // record i on line i % 4
    assert_eq!((pts[0].t, pts[1].t), (0, 1_000)); // i · 2 µs / (3 − 1)
    assert_eq!(sw[0].device_time_ns, TS as i64);
    assert_eq!(sw[0].timestamp_ns, TS as i64);
    assert_eq!(sw[0].clock, ClockSource::SensorPtp);
    assert_eq!(s.stats().crc_ok, 1);
    assert_eq!(s.facts().time_type_name(), "ptp");
}

#[test]
fn sdk2_type2_cartesian_cm() {
    let mut d = Vec::new();
    for (x, y, z, r, t) in [(-150i16, 32_000i16, -7i16, 9u8, 0x04u8), (1, 0, 0, 0, 0)] {
        d.extend_from_slice(&x.to_le_bytes());
        d.extend_from_slice(&y.to_le_bytes());
        d.extend_from_slice(&z.to_le_bytes());
        d.extend_from_slice(&[r, t]);
    }
    let p = sdk2(2, 2, 2, 50, 0, &d);
    let mut s = stream(Some(LivoxModel::Hap), Protocol::Sdk2);
    let sw = run(&mut s, &[p]);
    let pts = &sw[0].points;
    assert_eq!(pts.len(), 2);
    close(&pts[0], [-1.50, 320.0, -0.07]);
    close(&pts[1], [0.01, 0.0, 0.0]);
    assert_eq!((pts[0].intensity, pts[0].pad), (9.0, 0x04));
    assert_eq!(pts[1].t, 5_000);
    assert_eq!(sw[0].clock, ClockSource::SensorGps);
}

#[test]
fn sdk2_type3_spherical() {
    let mut d = Vec::new();
    // (depth mm, theta = zenith 0.01°, phi = azimuth 0.01°)
    for (depth, theta, phi) in [
        (10_000u32, 9_000u16, 9_000u16),
        (2_000, 0, 0),
        (4_000, 4_500, 18_000),
        (0, 9_000, 0),
    ] {
        d.extend_from_slice(&depth.to_le_bytes());
        d.extend_from_slice(&theta.to_le_bytes());
        d.extend_from_slice(&phi.to_le_bytes());
        d.extend_from_slice(&[42, 0x20]);
    }
    let p = sdk2(3, 0, 4, 30, 0, &d);
    assert_eq!(p.len(), 36 + 4 * 10);
    let mut s = stream(Some(LivoxModel::Mid360), Protocol::Sdk2);
    let sw = run(&mut s, &[p]);
    let pts = &sw[0].points;
    assert_eq!(pts.len(), 3, "depth 0 is no return");
    close(&pts[0], [0.0, 10.0, 0.0]);
    close(&pts[1], [0.0, 0.0, 2.0]);
    let h = 4.0 * std::f32::consts::FRAC_1_SQRT_2;
    close(&pts[2], [-h, 0.0, h]);
    assert_eq!(pts[2].ring, 2);
    assert_eq!(pts[2].t, 2_000);
    assert_eq!(pts[0].pad, 0x20);
    // Time type 0: the sensor's clock runs from power-on; the sweep is stamped with the host's.
    assert_eq!(sw[0].clock, ClockSource::Host);
    assert_eq!(sw[0].timestamp_ns, 1_000);
    assert_eq!(sw[0].device_time_ns, TS as i64);
}

#[test]
fn sdk2_dual_echo() {
    let mut d = Vec::new();
    for (v, r, t) in [([100i32, 200, 300], 10u8, 1u8), ([1000, 2000, 3000], 20, 2)] {
        for c in v {
            d.extend_from_slice(&c.to_le_bytes());
        }
        d.extend_from_slice(&[r, t]);
    }
    let p = sdk2(0x11, 1, 1, 0, 0, &d);
    let mut s = stream(Some(LivoxModel::Hap), Protocol::Sdk2);
    let sw = run(&mut s, &[p]);
    let pts = &sw[0].points;
    assert_eq!(pts.len(), 2);
    close(&pts[0], [0.1, 0.2, 0.3]);
    close(&pts[1], [1.0, 2.0, 3.0]);
    assert_eq!((pts[0].ret, pts[1].ret), (0, 1));
    assert_eq!((pts[0].t, pts[1].t), (0, 0));
}

#[test]
fn sdk2_imu_in_si_units() {
    let mut d = Vec::new();
    for v in [0.1f32, -0.2, 0.3, 0.01, -0.02, 1.0] {
        d.extend_from_slice(&v.to_le_bytes());
    }
    let p = sdk2(0, 1, 1, 0, 0, &d);
    let mut pool = CalibrationPool::new(Vec::new(), StreamSettings::default());
    let first = FirstDatagram {
        src: Ipv4Addr::new(192, 168, 1, 12),
        port: 56_401,
        payload: &p,
    };
    let mut st = ringscan::sensor::claim(&first, &mut pool)
        .expect("claimed")
        .expect("stream");
    assert_eq!(st.facts().family(), "livox");
    st.push(5, &p, &mut |_, _| {}).unwrap();
    let mut got: Vec<(ImuSample, [f64; 16])> = Vec::new();
    st.drain_imu(&mut |s, m| got.push((*s, *m)));
    assert_eq!(got.len(), 1);
    let (s, m) = got[0];
    assert_eq!(s.sensor_ns, TS);
    let g = [0.1f32, -0.2, 0.3].map(f64::from);
    assert_eq!(s.gyro, g);
    let a = [0.01f32, -0.02, 1.0].map(|v| f64::from(v) * 9.806_65);
    assert_eq!(s.accel, a);
    // MID-360: IMU at (11.0, 23.29, −44.12) mm in the point-cloud frame, axes aligned.
    assert_eq!([m[3], m[7], m[11]], [11.0, 23.29, -44.12]);
    assert_eq!([m[0], m[5], m[10], m[15]], [1.0; 4]);
}

#[test]
fn ports_name_the_sdk2_model_and_lines_follow() {
    let mut d = Vec::new();
    for i in 0..8i32 {
        for c in [1000 + i, 0, 0] {
            d.extend_from_slice(&c.to_le_bytes());
        }
        d.extend_from_slice(&[1, 0]);
    }
    let p = sdk2(1, 1, 8, 70, 0, &d);
    for (port, model, lines) in [
        (56_301u16, Some("mid360"), 4u16),
        (57_000, Some("hap"), 6),
        (40_000, None, 1),
    ] {
        let mut pool = CalibrationPool::new(Vec::new(), StreamSettings::default());
        let first = FirstDatagram {
            src: Ipv4Addr::new(10, 0, 0, 2),
            port,
            payload: &p,
        };
        let mut st = ringscan::sensor::claim(&first, &mut pool).unwrap().unwrap();
        let mut rings = Vec::new();
        st.push(0, &p, &mut |_, _| {}).unwrap();
        st.finish(&mut |sw, _| rings.extend(sw.points.iter().map(|q| q.ring)))
            .unwrap();
        let want: Vec<u16> = (0..8).map(|i| i % lines).collect();
        assert_eq!(rings, want, "port {port}");
        let (v, _) = st.summary();
        assert_eq!(v["model_id"].as_str(), model, "port {port}");
    }
}

/// An SDK1 packet: version 5, slot, id, reserved, status u32, timestamp type, data type,
/// timestamp 8 bytes, then `data`.
fn sdk1(data_type: u8, ts_type: u8, ts: [u8; 8], data: &[u8]) -> Vec<u8> {
    let mut b = vec![0u8; 18 + data.len()];
    b[0] = 5;
    b[1] = 1; // slot
    b[2] = 1; // id
    b[4..8].copy_from_slice(&0x0000_0200u32.to_le_bytes()); // status: PPS ok
    b[8] = ts_type;
    b[9] = data_type;
    b[10..18].copy_from_slice(&ts);
    b[18..].copy_from_slice(data);
    b
}

fn sdk1_run(model: LivoxModel, p: Vec<u8>) -> (Vec<Sweep>, LivoxStream) {
    let mut s = stream(Some(model), Protocol::Sdk1);
    let sw = run(&mut s, &[p]);
    (sw, s)
}

#[test]
fn sdk1_cartesian_types_0_2_4_7() {
    // (data type, records, returns per record, bytes per return, tag?)
    for (dt, n, k, tagged) in [
        (0u8, 100usize, 1usize, false),
        (2, 96, 1, true),
        (4, 48, 2, true),
        (7, 30, 3, true),
    ] {
        let mut d = Vec::new();
        for i in 0..n {
            for j in 0..k {
                let base = (i * 10 + j) as i32;
                for c in [base + 1, -(base + 2), base + 3] {
                    d.extend_from_slice(&c.to_le_bytes());
                }
                d.push(j as u8 + 7);
                if tagged {
                    d.push(0x10);
                }
            }
        }
        let p = sdk1(dt, 1, 5_000_000u64.to_le_bytes(), &d);
        let (sw, s) = sdk1_run(LivoxModel::Avia, p);
        let pts = &sw[0].points;
        assert_eq!(pts.len(), n * k, "type {dt}");
        for (idx, q) in pts.iter().enumerate() {
            let (i, j) = (idx / k, idx % k);
            let base = (i * 10 + j) as f32;
            close(
                q,
                [
                    (base + 1.0) / 1000.0,
                    -(base + 2.0) / 1000.0,
                    (base + 3.0) / 1000.0,
                ],
            );
            assert_eq!(q.ret as usize, j);
            assert_eq!(q.intensity, (j + 7) as f32);
            assert_eq!(q.pad, if tagged { 0x10 } else { 0 });
            assert_eq!(q.ring as usize, i % 6);
            assert_eq!(q.t as usize, i * 4_167, "Avia: 4167 ns a record");
        }
        assert_eq!(s.facts().status_code, Some(0x200));
        assert_eq!(sw[0].clock, ClockSource::SensorPtp);
    }
}

#[test]
fn sdk1_spherical_types_1_3_5_8() {
    for (dt, n, k) in [(1u8, 100usize, 1usize), (3, 96, 1), (5, 48, 2), (8, 30, 3)] {
        let mut d = Vec::new();
        for _ in 0..n {
            if k == 1 {
                d.extend_from_slice(&3_000u32.to_le_bytes()); // depth mm
                d.extend_from_slice(&9_000u16.to_le_bytes()); // theta
                d.extend_from_slice(&27_000u16.to_le_bytes()); // phi: −y
                d.push(5);
                if dt == 3 {
                    d.push(0x01);
                }
            } else {
                d.extend_from_slice(&0u16.to_le_bytes()); // theta: up
                d.extend_from_slice(&0u16.to_le_bytes()); // phi
                for j in 0..k {
                    d.extend_from_slice(&(1_000u32 * (j as u32 + 1)).to_le_bytes());
                    d.extend_from_slice(&[j as u8, 0x02]);
                }
            }
        }
        let p = sdk1(dt, 0, 0u64.to_le_bytes(), &d);
        let (sw, _) = sdk1_run(LivoxModel::Mid70, p);
        let pts = &sw[0].points;
        assert_eq!(pts.len(), n * k, "type {dt}");
        for (idx, q) in pts.iter().enumerate() {
            if k == 1 {
                close(q, [0.0, -3.0, 0.0]);
                assert_eq!(q.pad, if dt == 3 { 1 } else { 0 });
            } else {
                let j = idx % k;
                close(q, [0.0, 0.0, (j + 1) as f32]);
                assert_eq!((q.ret as usize, q.pad), (j, 2));
            }
            assert_eq!(q.ring, 0, "Mid-70: one line");
            assert_eq!(q.t as usize, (idx / k) * 10_000, "Mid-70: 10 µs a record");
        }
    }
}

#[test]
fn sdk1_imu_and_utc_timestamp() {
    let mut d = Vec::new();
    for v in [0.5f32, 0.0, -0.5, 0.0, 0.0, -1.0] {
        d.extend_from_slice(&v.to_le_bytes());
    }
    // Type 3 (PPS + GPS): year − 2000, month, day, hour, then µs within the hour (u32).
    let mut ts = [24u8, 5, 17, 13, 0, 0, 0, 0];
    ts[4..8].copy_from_slice(&1_234_567u32.to_le_bytes());
    let p = sdk1(6, 3, ts, &d);
    assert_eq!(p.len(), 42);
    let mut s = stream(Some(LivoxModel::Horizon), Protocol::Sdk1);
    run(&mut s, &[p]);
    let got: Vec<ImuSample> = s.drain_imu().collect();
    assert_eq!(got.len(), 1);
    // 2024-05-17 13:00:00 UTC = 1 715 950 800 s.
    assert_eq!(got[0].sensor_ns, 1_715_950_800_000_000_000 + 1_234_567_000);
    assert_eq!(got[0].gyro, [0.5, 0.0, -0.5]);
    assert_eq!(got[0].accel, [0.0, 0.0, -9.806_65]);
    assert_eq!(s.stats().imu_packets, 1);
}
