//! Packets built by hand from the Robosense protocol documentation (user manuals' MSOP / DIFOP
//! tables; RoboSense's SDK packet structs), byte offsets written out here — not by the
//! project's encoder — decode to the values written into them, for every layout:
//!
//! - V1 header (RS-16, RS-32, Bpearl): id `55 AA 05 0A 5A A5 50 A0`, calendar time at 20–29
//!   (year − 2000, month, day, hour, minute, second, ms u16 BE, µs u16 BE), 12 blocks of 100
//!   bytes from byte 42: `FF EE`, azimuth u16 BE (0.01°), 32 × (distance u16 BE, intensity);
//! - Helios header (Helios, Helios-16P): id `55 AA 05 5A`, Unix time at 20–29 (u48 s, u32 µs,
//!   BE), the same blocks, distance unit 2.5 mm;
//! - Ruby header: id `55 AA 05 5A`, Unix time at 10–19, 3 blocks of 388 bytes from byte 80:
//!   `FE`, return id, azimuth, 128 slots;
//! - DIFOP: id `A5 FF 00 5A 11 11 55 55`, rpm at 8, return mode at 300, angles from 468
//!   (sign byte, u16 BE 0.01°), RS-16 pitches at 1165 (u24 BE 0.0001°).
//!
//! Expected points are worked out here from the manual's formulas:
//! `x = d·cos v·cos h + RX·cos h0`, `y = −d·cos v·sin h − RX·sin h0`, `z = d·sin v + RZ`,
//! `h0 = A + ⌊step · t_fire / t_span⌋`, `h = h0 + horizontal`.

use ringscan::point::Point;
use ringscan::sensor::robosense::family::parse_robosense_calibration;
use ringscan::sensor::robosense::{
    Difop, Msop, RobosenseAngles, RobosenseConfig, RobosenseDecoder, RobosenseModel,
    RobosenseStream,
};
use ringscan::sensor::DecodeOptions;

fn put16(b: &mut [u8], o: usize, v: u16) {
    b[o] = (v >> 8) as u8;
    b[o + 1] = v as u8;
}

/// Angles: laser i at vertical `v(i)`, horizontal `h(i)`, through the CSV text.
fn angles(n: usize, v: impl Fn(usize) -> f64, h: impl Fn(usize) -> f64) -> RobosenseAngles {
    let s: String = (0..n).map(|i| format!("{},{}\n", v(i), h(i))).collect();
    parse_robosense_calibration(s.as_bytes()).unwrap().unwrap()
}

/// A V1 / Helios packet: 12 blocks, block b azimuth `az0 + 20·b`.
fn packet42(v1: bool, az0: u16) -> Vec<u8> {
    let mut b = vec![0u8; 1248];
    if v1 {
        b[..8].copy_from_slice(&[0x55, 0xAA, 0x05, 0x0A, 0x5A, 0xA5, 0x50, 0xA0]);
        // 2024-03-01 12:34:56.789012.
        b[20..30].copy_from_slice(&[24, 3, 1, 12, 34, 56, 0x03, 0x15, 0x00, 0x0C]);
    } else {
        b[..4].copy_from_slice(&[0x55, 0xAA, 0x05, 0x5A]);
        b[4..6].copy_from_slice(&[0x00, 0x01]);
        // 1_709_296_496 s = 0x65E1CB70; 789_012 µs = 0x000C0A14.
        b[20..30].copy_from_slice(&[0, 0, 0x65, 0xE1, 0xCB, 0x70, 0x00, 0x0C, 0x0A, 0x14]);
    }
    for blk in 0..12 {
        let o = 42 + 100 * blk;
        b[o] = 0xFF;
        b[o + 1] = 0xEE;
        put16(&mut b, o + 2, (az0 + 20 * blk as u16) % 36_000);
    }
    b
}

fn slot42(b: &mut [u8], blk: usize, slot: usize, raw: u16, intensity: u8) {
    let o = 42 + 100 * blk + 4 + 3 * slot;
    put16(b, o, raw);
    b[o + 2] = intensity;
}

const STAMP: i64 = 1_709_296_496_789_012_000;

fn decode_all(
    model: RobosenseModel,
    a: &RobosenseAngles,
    p: &[u8],
    dual: bool,
) -> Vec<(Point, i64, usize, usize)> {
    let dec = RobosenseDecoder::new(model, a, DecodeOptions::default()).unwrap();
    let m = Msop::new(p, model).unwrap();
    let mut v = Vec::new();
    dec.decode(&m, dual, |d| {
        v.push((d.point, d.offset_ns, d.block, d.slot))
    });
    v
}

fn expect(d: f64, v_deg: f64, h_cdeg: i32, h0_cdeg: i32, rx: f64, rz: f64) -> [f64; 3] {
    let (v, h, h0) = (
        v_deg.to_radians(),
        (f64::from(h_cdeg) / 100.0).to_radians(),
        (f64::from(h0_cdeg) / 100.0).to_radians(),
    );
    [
        d * v.cos() * h.cos() + rx * h0.cos(),
        -d * v.cos() * h.sin() - rx * h0.sin(),
        d * v.sin() + rz,
    ]
}

fn close(p: &Point, e: [f64; 3]) {
    let err = ((f64::from(p.x) - e[0]).powi(2)
        + (f64::from(p.y) - e[1]).powi(2)
        + (f64::from(p.z) - e[2]).powi(2))
    .sqrt();
    assert!(err < 1e-4, "{p:?} vs {e:?}");
}

#[test]
fn rs32_single_calendar_clock() {
    let a = angles(32, |i| -25.0 + i as f64, |i| if i == 5 { 1.5 } else { 0.0 });
    let mut p = packet42(true, 9000);
    slot42(&mut p, 0, 0, 2000, 77); // 10 m
    slot42(&mut p, 1, 5, 1000, 12); // 5 m
    let m = Msop::new(&p, RobosenseModel::Rs32).unwrap();
    assert_eq!(
        m.stamp_ns(ringscan::sensor::robosense::model::ClockForm::Calendar),
        Some(STAMP)
    );
    let pts = decode_all(RobosenseModel::Rs32, &a, &p, false);
    assert_eq!(pts.len(), 2);
    let rx = 0.03997;
    // Block 0 slot 0: fires at 0 µs; h0 = 9000.
    close(&pts[0].0, expect(10.0, -25.0, 9000, 9000, rx, 0.0));
    assert_eq!(pts[0].0.intensity, 77.0);
    assert_eq!(pts[0].0.ring, 0);
    assert_eq!(pts[0].1, 0);
    // Block 1 slot 5: fires 14.40 µs into the block (RS-32 table), the block 55.52 µs in;
    // h0 = 9020 + ⌊20 · 14.40 / 55.52⌋ = 9025; h = 9025 + 150.
    close(&pts[1].0, expect(5.0, -20.0, 9175, 9025, rx, 0.0));
    assert_eq!(pts[1].1, 55_520 + 14_400);
    assert_eq!(pts[1].0.ring, 5);
}

#[test]
fn rs16_single_and_dual() {
    let a = angles(16, |i| -15.0 + 2.0 * i as f64, |_| 0.0);
    let mut p = packet42(true, 100);
    // Slot 17 = laser 1, its second firing: 58.30 µs into the block; the step spans two
    // firings of 55.5 µs: h0 = 120 + ⌊20 · 58.30 / 111⌋ = 130.
    slot42(&mut p, 1, 17, 400, 9); // 2 m
    let pts = decode_all(RobosenseModel::Rs16, &a, &p, false);
    assert_eq!(pts.len(), 1);
    close(&pts[0].0, expect(2.0, -13.0, 130, 130, 0.03825, 0.0));
    assert_eq!(pts[0].1, 111_000 + 58_300);
    assert_eq!(pts[0].0.ring, 1);
    // Dual: slots 0–15 first return, 16–31 second return of the same firing.
    let mut p = packet42(true, 100);
    slot42(&mut p, 2, 3, 1000, 50);
    slot42(&mut p, 2, 19, 1400, 20);
    slot42(&mut p, 3, 4, 800, 50);
    slot42(&mut p, 3, 20, 800, 50); // same as the first: one point
    let pts = decode_all(RobosenseModel::Rs16, &a, &p, true);
    assert_eq!(pts.len(), 3);
    assert_eq!((pts[0].0.ret, pts[1].0.ret, pts[2].0.ret), (0, 1, 0));
    assert_eq!(pts[0].1, 2 * 55_500 + 8_400);
    assert_eq!(pts[1].1, pts[0].1);
    // h0 = 140 + ⌊20 · 8.40 / 55.5⌋ = 143.
    close(&pts[1].0, expect(7.0, -9.0, 143, 143, 0.03825, 0.0));
}

#[test]
fn bpearl_lens_height() {
    let a = angles(32, |i| 2.8 * i as f64, |_| 0.0);
    let mut p = packet42(true, 18_000);
    slot42(&mut p, 11, 8, 600, 1); // 3 m, laser 8 at 22.4°; last block: nominal step 20
    let pts = decode_all(RobosenseModel::Bpearl, &a, &p, false);
    assert_eq!(pts.len(), 1);
    // Slot 8 fires at 25.68 µs: h0 = 18220 + ⌊20 · 25.68 / 55.52⌋ = 18229.
    close(
        &pts[0].0,
        expect(3.0, 22.4, 18_229, 18_229, 0.01473, 0.09427),
    );
    assert_eq!(pts[0].1, 11 * 55_520 + 25_680);
}

#[test]
fn helios_unix_clock_and_dual_pairs() {
    let a = angles(
        32,
        |i| 15.0 - i as f64,
        |i| if i % 2 == 0 { -0.5 } else { 0.5 },
    );
    let mut p = packet42(false, 35_980); // wraps through 0 at block 1
    slot42(&mut p, 0, 31, 4000, 200); // 10 m
    let m = Msop::new(&p, RobosenseModel::Helios).unwrap();
    assert_eq!(
        m.stamp_ns(ringscan::sensor::robosense::model::ClockForm::Unix),
        Some(STAMP)
    );
    assert_eq!(m.protocol_version(), Some(1));
    let pts = decode_all(RobosenseModel::Helios, &a, &p, false);
    // Step 36000 → 0 is 20; slot 31 fires at 53.63 µs: h0 = 35980 + ⌊20 · 53.63 / 55.56⌋ = 35999.
    close(
        &pts[0].0,
        expect(10.0, -16.0, 35_999 + 50, 35_999, 0.03498, 0.0),
    );
    assert_eq!(pts[0].1, 53_630);
    assert_eq!(pts[0].0.ring, 0);
    // Dual: blocks 2k, 2k + 1 are the two returns of one firing (same azimuth).
    let mut p = packet42(false, 1000);
    for blk in 0..12 {
        put16(&mut p, 42 + 100 * blk + 2, 1000 + 20 * (blk as u16 / 2));
    }
    slot42(&mut p, 2, 0, 2000, 5);
    slot42(&mut p, 3, 0, 2600, 4);
    let pts = decode_all(RobosenseModel::Helios, &a, &p, true);
    assert_eq!(pts.len(), 2);
    assert_eq!((pts[0].0.ret, pts[1].0.ret), (0, 1));
    assert_eq!((pts[0].1, pts[1].1), (55_560, 55_560));
    close(&pts[1].0, expect(6.5, 15.0, 1020 - 50, 1020, 0.03498, 0.0));
}

#[test]
fn helios16p_difop_angles_hold_and_release() {
    // DIFOP by hand: 16 lasers 15° … −15° in 2° steps (entries 0–15), entries 16–31 another
    // fan below; laser 3's entry written as 00 03 7A (+8.90°); horizontal entries from 564.
    let mut d = vec![0u8; 1248];
    d[..8].copy_from_slice(&[0xA5, 0xFF, 0x00, 0x5A, 0x11, 0x11, 0x55, 0x55]);
    d[8..10].copy_from_slice(&[0x02, 0x58]); // 600 rpm
    d[292..298].copy_from_slice(&[0x24, 0x10, 0xBA, 0xC9, 0xD5, 0x0B]);
    d[300] = 0x04; // strongest
    for i in 0..32usize {
        let v: i32 = if i == 3 {
            890
        } else if i < 16 {
            1500 - 200 * i as i32
        } else {
            -1600 - 100 * i as i32
        };
        let o = 468 + 3 * i;
        d[o] = u8::from(v < 0);
        put16(&mut d, o + 1, v.unsigned_abs() as u16);
        let h: i32 = if i % 2 == 0 { -405 } else { 361 };
        let o = 564 + 3 * i;
        d[o] = u8::from(h < 0);
        put16(&mut d, o + 1, h.unsigned_abs() as u16);
    }
    let df = Difop::new(&d).unwrap();
    assert_eq!(df.rpm(), 600);
    assert_eq!(df.serial(), "2410bac9d50b");
    let ang = df.angles(RobosenseModel::Helios16P).unwrap();
    assert_eq!(ang[3], (8.90, 3.61));
    assert_eq!(ang[0], (15.0, -4.05));

    let mut p = packet42(false, 5000);
    slot42(&mut p, 4, 3, 4000, 33); // laser 3, 10 m
    let mut s = RobosenseStream::new(RobosenseConfig::new(None));
    let mut pts = Vec::new();
    // MSOP before the DIFOP: held.
    s.push(0, &p, &mut |sw, _| pts.extend_from_slice(&sw.points))
        .unwrap();
    assert_eq!(s.held(), 1);
    assert!(s.decoder().is_none());
    s.push(1, &d, &mut |sw, _| pts.extend_from_slice(&sw.points))
        .unwrap();
    assert_eq!(s.held(), 0);
    assert_eq!(s.facts().model, Some(RobosenseModel::Helios16P));
    s.finish(&mut |sw, _| pts.extend_from_slice(&sw.points));
    assert_eq!(pts.len(), 1);
    // Slot 3 fires 9.45 µs into block 4; the Helios-16P's step spans 111.12 µs:
    // h0 = 5080 + ⌊20 · 9.45 / 111.12⌋ = 5081; h = 5081 + 361.
    close(&pts[0], expect(10.0, 8.90, 5081 + 361, 5081, 0.03498, 0.0));
    assert_eq!(pts[0].t, (4 * 55_560 + 9_450) as u32);
}

#[test]
fn helios16p_dual_slot_halves() {
    let a = angles(16, |i| 15.0 - 2.0 * i as f64, |_| 0.0);
    let mut p = packet42(false, 0);
    slot42(&mut p, 0, 2, 2000, 1);
    slot42(&mut p, 0, 18, 2400, 2);
    let pts = decode_all(RobosenseModel::Helios16P, &a, &p, true);
    assert_eq!(pts.len(), 2);
    assert_eq!((pts[0].0.ret, pts[1].0.ret), (0, 1));
    // Dual: both returns at laser 2's firing, 6.30 µs; step spans one block (55.56 µs):
    // h0 = 0 + ⌊20 · 6.30 / 55.56⌋ = 2.
    assert_eq!((pts[0].1, pts[1].1), (6_300, 6_300));
    close(&pts[1].0, expect(6.0, 11.0, 2, 2, 0.03498, 0.0));
}

#[test]
fn ruby128_single_and_ab_dual() {
    let a = angles(128, |i| 15.0 - 0.2 * i as f64, |_| 0.0);
    let mut p = vec![0u8; 1248];
    p[..4].copy_from_slice(&[0x55, 0xAA, 0x05, 0x5A]);
    // Unix time at 10–19.
    p[10..20].copy_from_slice(&[0, 0, 0x65, 0xE1, 0xCB, 0x70, 0x00, 0x0C, 0x0A, 0x14]);
    for blk in 0..3 {
        let o = 80 + 388 * blk;
        p[o] = 0xFE;
        put16(&mut p, o + 2, 20_000 + 20 * blk as u16);
    }
    // Block 2 slot 70 (laser 70): fires ((70 mod 64) div 4) · 3.236 = 3.236 µs in; last block:
    // nominal step round(36000 · 10 · 55.55 µs) = 20; h0 = 20040 + ⌊20 · 3.236 / 55.55⌋ = 20041.
    let o = 80 + 388 * 2 + 4 + 3 * 70;
    put16(&mut p, o, 3000); // 15 m
    p[o + 2] = 99;
    let m = Msop::new(&p, RobosenseModel::Ruby128).unwrap();
    assert_eq!(
        m.stamp_ns(ringscan::sensor::robosense::model::ClockForm::Unix),
        Some(STAMP)
    );
    let pts = decode_all(RobosenseModel::Ruby128, &a, &p, false);
    assert_eq!(pts.len(), 1);
    close(
        &pts[0].0,
        expect(15.0, 15.0 - 14.0, 20_041, 20_041, 0.03615, 0.0),
    );
    assert_eq!(pts[0].1, 2 * 55_550 + 3_236);
    assert_eq!(pts[0].0.ring, 127 - 70);
    // Dual A A B: blocks 0 and 1 share an azimuth (one firing's two returns).
    put16(&mut p, 80 + 2, 20_000);
    put16(&mut p, 80 + 388 + 2, 20_000);
    p[80 + 388 + 1] = 1;
    let o0 = 80 + 4 + 3 * 5;
    let o1 = 80 + 388 + 4 + 3 * 5;
    put16(&mut p, o0, 1000);
    put16(&mut p, o1, 1300);
    let pts = decode_all(RobosenseModel::Ruby128, &a, &p, true);
    assert_eq!(pts.len(), 3);
    assert_eq!((pts[0].0.ret, pts[1].0.ret, pts[2].0.ret), (0, 1, 0));
    assert_eq!(pts[2].1, 55_550 + 3_236);
}

#[test]
fn rs16_difop_pitch_table() {
    let mut d = vec![0u8; 1248];
    d[..8].copy_from_slice(&[0xA5, 0xFF, 0x00, 0x5A, 0x11, 0x11, 0x55, 0x55]);
    // Laser 0: 150000 (15.0000°, pointing down: lower eight), laser 9: 30000 (3.0000°, up).
    d[1165..1168].copy_from_slice(&[0x02, 0x49, 0xF0]);
    d[1165 + 27..1165 + 30].copy_from_slice(&[0x00, 0x75, 0x30]);
    let a = Difop::new(&d)
        .unwrap()
        .angles(RobosenseModel::Rs16)
        .unwrap();
    assert_eq!(a[0], (-15.0, 0.0));
    assert_eq!(a[9], (3.0, 0.0));
}

/// RS-LiDAR-M1 / M1 Plus MSOP, built byte by byte from the layout in RoboSense's SDK
/// (`decoder_RSM1.hpp`: `RSM1MsopHeader`, `RSM1Block`, `RSM1Channel`) and the M1 Plus
/// datasheet's MSOP table: 1210 bytes; id `55 AA 5A A5`; packet counter u16 BE at 4; protocol
/// version at 6; return mode at 8; Unix time at 10–19 (u48 s, u32 µs, BE); lidar type at 30;
/// temperature at 31 (°C + 80); 25 blocks of 47 bytes from byte 32, each a time offset (µs), a
/// return byte and 5 channels of 9 bytes: radius u16 BE (5 mm), elevation and azimuth u16 BE
/// (0.01°, 32768 = 0°), intensity, attribute, elongation. Point: `x = r·cos el·cos az`,
/// `y = r·cos el·sin az`, `z = r·sin el`; time = packet time + block offset; ring = channel.
fn m1_packet() -> Vec<u8> {
    let mut b = vec![0u8; 1210];
    b[..4].copy_from_slice(&[0x55, 0xAA, 0x5A, 0xA5]);
    b[4..6].copy_from_slice(&[0x01, 0x2C]); // packet 300 of the frame
    b[6..8].copy_from_slice(&[0x00, 0x01]);
    b[8] = 0x04; // strongest
                 // 1_709_296_496 s = 0x65E1CB70; 789_012 µs = 0x000C0A14.
    b[10..20].copy_from_slice(&[0, 0, 0x65, 0xE1, 0xCB, 0x70, 0x00, 0x0C, 0x0A, 0x14]);
    b[30] = 0x10;
    b[31] = 0x78; // 120 − 80 = 40 °C
                  // Block 0 (byte 32), channel 0 (byte 34): 10 m (2000 = 0x07D0), elevation +5.00°
                  // (33268 = 0x81F4), azimuth −30.00° (29768 = 0x7448), intensity 77.
    b[32] = 0;
    b[34..43].copy_from_slice(&[0x07, 0xD0, 0x81, 0xF4, 0x74, 0x48, 77, 0, 0]);
    // Block 7 (byte 32 + 7·47 = 361): 42 µs after the packet time, return byte 1; channel 3
    // (byte 361 + 2 + 27 = 390): 3 m (600 = 0x0258), elevation −10.00° (31768 = 0x7C18),
    // azimuth +59.90° (38758 = 0x9766), intensity 200.
    b[361] = 42;
    b[362] = 1;
    b[390..399].copy_from_slice(&[0x02, 0x58, 0x7C, 0x18, 0x97, 0x66, 200, 0, 0]);
    // Block 10 (byte 502), channel 1: angles but radius 0 — no return.
    b[502 + 2 + 9 + 2..502 + 2 + 9 + 6].copy_from_slice(&[0x81, 0xF4, 0x74, 0x48]);
    // Block 24 (byte 1160), channel 4 (byte 1198, the last 9 bytes before the 3 reserved):
    // 0.15 m (30 = 0x001E), under the M1's 0.2 m minimum — no point.
    b[1160] = 144;
    b[1198..1207].copy_from_slice(&[0x00, 0x1E, 0x7B, 0x1E, 0x97, 0x70, 9, 0, 0]);
    b
}

fn spherical(r: f64, el_deg: f64, az_deg: f64) -> [f64; 3] {
    let (el, az) = (el_deg.to_radians(), az_deg.to_radians());
    [
        r * el.cos() * az.cos(),
        r * el.cos() * az.sin(),
        r * el.sin(),
    ]
}

#[test]
fn m1_msop_decodes_to_the_values_written() {
    use ringscan::sensor::robosense::m1::{M1Decoder, M1Msop};
    let b = m1_packet();
    let m = M1Msop::new(&b).unwrap();
    assert_eq!(m.seq(), 300);
    assert_eq!(m.protocol_version(), 1);
    assert_eq!(m.return_mode(), 4);
    assert_eq!(m.lidar_type(), 0x10);
    assert_eq!(m.temperature_c(), 40);
    assert_eq!(m.stamp_ns(), Some(STAMP));
    let mut pts = Vec::new();
    M1Decoder::new(DecodeOptions::default()).decode(&m, |d| pts.push(d));
    assert_eq!(
        pts.len(),
        2,
        "no return and under-range points are not points"
    );
    let (a, c) = (pts[0], pts[1]);
    assert_eq!((a.block, a.channel, a.offset_ns), (0, 0, 0));
    close(&a.point, spherical(10.0, 5.0, -30.0));
    // −30° azimuth is to the right: y < 0 (REP 103, y left).
    assert!(a.point.y < -4.0);
    assert_eq!((a.point.intensity, a.point.ring, a.point.ret), (77.0, 0, 0));
    assert_eq!((c.block, c.channel, c.offset_ns), (7, 3, 42_000));
    close(&c.point, spherical(3.0, -10.0, 59.9));
    assert_eq!(
        (c.point.intensity, c.point.ring, c.point.ret),
        (200.0, 3, 1)
    );
    // The caller's range filter applies within the M1's own.
    let mut n = 0;
    M1Decoder::new(DecodeOptions {
        min_range: 5.0,
        max_range: f32::INFINITY,
    })
    .decode(&m, |_| n += 1);
    assert_eq!(n, 1);
}

/// The M1 through the family interface, from its bytes alone: claimed by size and id (no
/// DIFOP, no angle file), decoded at once; the frame ends where the packet counter restarts;
/// a gap in the counter is counted; the 256-byte DIFOP (id, frame rate at 9, firmware at
/// 28–37, serial at 38–43) fills the device facts.
#[test]
fn m1_through_the_family_interface() {
    use ringscan::sensor::{claim, CalibrationPool, FirstDatagram, StreamSettings};
    let p300 = m1_packet();
    let mut pool = CalibrationPool::new(Vec::new(), StreamSettings::default());
    let first = FirstDatagram {
        src: std::net::Ipv4Addr::new(192, 168, 1, 200),
        port: 6699,
        payload: &p300,
    };
    let mut s = claim(&first, &mut pool).expect("claimed").expect("stream");
    assert!(s.is_lidar_datagram(&p300));
    let mut sweeps: Vec<(i64, Vec<Point>, u64)> = Vec::new();
    let mut on = |sw: &mut ringscan::sweep::Sweep, _: &dyn ringscan::sensor::Facts| {
        sweeps.push((sw.device_time_ns, sw.points.clone(), sw.missing_packets))
    };
    s.push(STAMP, &p300, &mut on).unwrap();
    assert!(s.ready());
    // Packet 302 (301 lost), 317 µs later; then packet 2 of the next frame (1 lost, and
    // 303–630 of this one: the largest counter seen is 302, so those are not known lost).
    let mut p302 = p300.clone();
    p302[4..6].copy_from_slice(&[0x01, 0x2E]);
    p302[16..20].copy_from_slice(&[0x00, 0x0C, 0x0B, 0x51]); // 789_329 µs
    s.push(STAMP, &p302, &mut on).unwrap();
    let mut p2 = p300.clone();
    p2[4..6].copy_from_slice(&[0x00, 0x02]);
    p2[16..20].copy_from_slice(&[0x00, 0x0D, 0x0B, 0x00]); // 854_784 µs
    s.push(STAMP, &p2, &mut on).unwrap();
    let mut difop = vec![0u8; 256];
    difop[..8].copy_from_slice(&[0xA5, 0xFF, 0x00, 0x5A, 0x11, 0x11, 0x55, 0x55]);
    difop[9] = 10;
    difop[28..38].copy_from_slice(&[1, 2, 3, 4, 5, 6, 7, 8, 9, 10]);
    difop[38..44].copy_from_slice(&[0xAB, 0xCD, 0xEF, 0x01, 0x23, 0x45]);
    s.push(STAMP, &difop, &mut on).unwrap();
    s.finish(&mut on).unwrap();
    assert_eq!(sweeps.len(), 2);
    assert_eq!(sweeps[0].0, STAMP);
    assert_eq!(sweeps[0].1.len(), 4);
    assert_eq!(sweeps[0].2, 1);
    // Second packet's block 7 point: 317 µs + 42 µs after the sweep's start.
    assert_eq!(sweeps[0].1[3].t, 359_000);
    assert_eq!(sweeps[1].0, STAMP + 65_772_000);
    assert_eq!(sweeps[1].2, 1);
    let (v, counts) = s.summary();
    assert_eq!(v["model"], "RS-LiDAR-M1");
    assert_eq!(v["model_id"], "rsm1");
    assert_eq!(v["serial"], "abcdef012345");
    assert_eq!(v["firmware"], "0102030405/060708090a");
    assert_eq!(v["frame_rate"], 10);
    assert_eq!(v["temperature_c"], 40);
    assert_eq!(v["return_mode"], "strongest (0x04)");
    assert_eq!(v["held"], 0);
    assert_eq!(
        (counts.decoded, counts.missing, counts.malformed),
        (3, 2, 0)
    );
    let lines = ringscan::sensor::family("robosense").unwrap().describe(&v);
    assert!(lines[0].contains("Robosense RS-LiDAR-M1"), "{lines:?}");
    assert!(
        lines[3].contains("serial abcdef012345") && lines[3].contains("40 °C"),
        "{lines:?}"
    );
}
