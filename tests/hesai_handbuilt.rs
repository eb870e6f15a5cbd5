//! PandarAT128 and OT128 (Pandar128E4X), for which no real packets are shared: one packet of
//! each is written here BY HAND from the published layouts (Hesai user manuals' "Point cloud
//! data packet"; the field list of nebula's `pandar_at128.hpp` / `pandar_128e3x.hpp`), not by
//! ringscan's encoder, and decoded with the real correction files of `../shared/captures`
//! (`PandarAT128.dat`, `Pandar128E4X.csv`). Every point must lie within 1 mm of the point this
//! test computes itself from the correction formulas (the `.dat` is read here with its own
//! reader). Skips when `../shared` is absent.

mod common;

use ringscan::point::Point;
use ringscan::sensor::hesai::family::parse_hesai_calibration;
use ringscan::sensor::hesai::{HesaiDecoder, HesaiModel, HesaiOptions, HesaiPacket};

const CALIB: &str = "tier4__nebula/src/nebula_hesai/nebula_hesai_decoders/calibration";

use common::crc32_mpeg2_bitwise as crc32_mpeg2;

fn put16(b: &mut [u8], o: usize, v: u16) {
    b[o..o + 2].copy_from_slice(&v.to_le_bytes());
}

fn put32(b: &mut [u8], o: usize, v: u32) {
    b[o..o + 4].copy_from_slice(&v.to_le_bytes());
}

fn raw_distance(block: usize, c: usize) -> u16 {
    // 2 m … 40 m in 4 mm units, different for every (block, channel); every 7th empty.
    if (c + block) % 7 == 3 {
        0
    } else {
        (500 + 37 * c + 911 * block) as u16 % 10_000 + 500
    }
}

fn decode(model: HesaiModel, packet: &[u8], calib_file: &str) -> Vec<Point> {
    let root = common::captures().expect("checked by the caller");
    let bytes = std::fs::read(root.join(CALIB).join(calib_file)).unwrap();
    let calib = parse_hesai_calibration(&bytes)
        .expect("a Hesai correction")
        .unwrap();
    let mut dec = HesaiDecoder::new(model, &calib, HesaiOptions::default()).unwrap();
    let p = HesaiPacket::new(packet, model).unwrap();
    assert!(p.check_crc().is_ok());
    let mut out = Vec::new();
    dec.decode_packet(&p, 0, 0, &mut out).unwrap();
    out
}

fn xyz(d: f64, az_deg: f64, el_deg: f64) -> [f64; 3] {
    let (az, el) = (az_deg.to_radians(), el_deg.to_radians());
    // Hesai azimuth: clockwise from forward; ringscan frame: x forward, y left, z up.
    [
        d * el.cos() * az.cos(),
        -d * el.cos() * az.sin(),
        d * el.sin(),
    ]
}

fn max_error(got: &[Point], expected: &[[f64; 3]]) -> f64 {
    assert_eq!(got.len(), expected.len());
    got.iter()
        .zip(expected)
        .map(|(p, e)| {
            let d = [
                f64::from(p.x) - e[0],
                f64::from(p.y) - e[1],
                f64::from(p.z) - e[2],
            ];
            (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
        })
        .fold(0.0, f64::max)
}

#[test]
fn ot128_packet_by_hand() {
    let Some(root) = common::captures() else {
        return;
    };
    // Pandar128E4X.csv: "Laser id,Elevation,Azimuth", one row per channel.
    let text = std::fs::read_to_string(root.join(CALIB).join("Pandar128E4X.csv")).unwrap();
    let rows: Vec<(f64, f64)> = text
        .lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.trim().parse().unwrap()).collect();
            (v[1], v[2])
        })
        .collect();
    assert_eq!(rows.len(), 128);

    // Header (12): EE FF, protocol 1.4, 2 reserved, 128 lasers, 2 blocks, reserved,
    // distance unit 4 mm, 1 return, flags (UDP sequence, functional safety).
    // Body: 2 × (azimuth u16 + 128 × (distance u16, reflectivity u8)), CRC-32/MPEG-2.
    // Functional safety (17). Tail (56): reserved 9, azimuth state u16, operational state,
    // return mode, motor speed u16, date (6), µs u32, factory, UDP sequence u32, IMU (22),
    // tail CRC u32.
    let block_len = 2 + 128 * 3;
    let body_end = 12 + 2 * block_len;
    let fs = body_end + 4;
    let tail = fs + 17;
    let mut b = vec![0u8; tail + 56];
    b[..12].copy_from_slice(&[0xEE, 0xFF, 1, 4, 0, 0, 128, 2, 0, 4, 1, 0b0000_0101]);
    let block_az = [12_345u16, 12_355];
    let mut expected = Vec::new();
    for (blk, &az) in block_az.iter().enumerate() {
        let o = 12 + blk * block_len;
        put16(&mut b, o, az);
        for c in 0..128 {
            let raw = raw_distance(blk, c);
            put16(&mut b, o + 2 + 3 * c, raw);
            b[o + 2 + 3 * c + 2] = (c * 2) as u8;
        }
    }
    let crc = crc32_mpeg2(&b[12..body_end]);
    put32(&mut b, body_end, crc);
    b[fs] = 1; // functional-safety version
    b[fs + 1] = 1 << 5; // lidar state: normal
    b[tail + 11] = 1; // operational state: standard
    b[tail + 12] = 0x37; // strongest
    put16(&mut b, tail + 13, 600);
    b[tail + 15..tail + 21].copy_from_slice(&[124, 3, 24, 12, 0, 0]);
    put32(&mut b, tail + 21, 250_000);
    put32(&mut b, tail + 26, 7);
    let crc = crc32_mpeg2(&b[tail..tail + 52]);
    put32(&mut b, tail + 52, crc);
    assert_eq!(b.len(), 861);

    // Single return: points in block order, then channel order.
    for (blk, &az) in block_az.iter().enumerate() {
        for (c, &(el, az_off)) in rows.iter().enumerate() {
            let raw = raw_distance(blk, c);
            if raw == 0 {
                continue;
            }
            expected.push(xyz(
                f64::from(raw) * 0.004,
                f64::from(az) / 100.0 + az_off,
                el,
            ));
        }
    }
    let got = decode(HesaiModel::PandarOt128, &b, "Pandar128E4X.csv");
    let err = max_error(&got, &expected);
    println!("OT128: {} points, max |Δxyz| {err:.3e} m", got.len());
    assert!(err < 1e-3, "{err}");
    // Signed packets (32 more bytes) decode the same.
    let signed = [b.clone(), vec![0x5A; 32]].concat();
    assert_eq!(
        decode(HesaiModel::PandarOt128, &signed, "Pandar128E4X.csv"),
        got
    );
}

/// The AT128 `.dat` (version 1.5), read here with its own reader.
struct Dat {
    start: Vec<i64>,
    end: Vec<i64>,
    az: Vec<i64>,
    el: Vec<i64>,
    az_adj: Vec<i64>,
    el_adj: Vec<i64>,
}

fn read_dat(b: &[u8]) -> Dat {
    assert_eq!(&b[..4], &[0xEE, 0xFF, 1, 5]);
    let (n, m, res) = (usize::from(b[4]), usize::from(b[5]), i64::from(b[15]));
    let rd_u32 = |o: usize| i64::from(u32::from_le_bytes(b[o..o + 4].try_into().unwrap()));
    let rd_i32 = |o: usize| i64::from(i32::from_le_bytes(b[o..o + 4].try_into().unwrap()));
    let mut o = 16;
    let start = (0..m).map(|i| rd_u32(o + 4 * i) * res).collect();
    o += 4 * m;
    let end = (0..m).map(|i| rd_u32(o + 4 * i) * res).collect();
    o += 4 * m;
    let az = (0..n).map(|i| rd_i32(o + 4 * i) * res).collect();
    o += 4 * n;
    let el = (0..n).map(|i| rd_i32(o + 4 * i) * res).collect();
    o += 4 * n;
    let az_adj = b[o..o + 180 * n]
        .iter()
        .map(|&v| i64::from(v as i8) * res)
        .collect();
    o += 180 * n;
    let el_adj = b[o..o + 180 * n]
        .iter()
        .map(|&v| i64::from(v as i8) * res)
        .collect();
    Dat {
        start,
        end,
        az,
        el,
        az_adj,
        el_adj,
    }
}

#[test]
fn at128_packet_by_hand() {
    let Some(root) = common::captures() else {
        return;
    };
    let dat = read_dat(&std::fs::read(root.join(CALIB).join("PandarAT128.dat")).unwrap());
    // Encoder azimuths in 1/25600°: 30° and 30.1° into mirror 0's field.
    let enc: [i64; 2] = [
        dat.start[0] + 30 * 25_600,
        dat.start[0] + 30 * 25_600 + 2_560,
    ];
    assert!(enc[1] < dat.end[0]);

    // Header (12): EE FF, protocol 4.3, 2 reserved, 128 lasers, 2 blocks, reserved, distance
    // unit 4 mm, 1 return, flags. Body: 2 × (azimuth u16 in 0.01°, fine azimuth u8 in 1/256 of
    // that, 128 × (distance u16, reflectivity, confidence)), CRC-32/MPEG-2. Tail (40): reserved
    // 6, shutdown flag, reserved 11, motor speed u16, µs u32, return mode, factory, date (a zero
    // byte then the Unix seconds, 40-bit big-endian), UDP sequence u32, tail CRC u32.
    let block_len = 3 + 128 * 4;
    let body_end = 12 + 2 * block_len;
    let tail = body_end + 4;
    let mut b = vec![0u8; tail + 40];
    b[..12].copy_from_slice(&[0xEE, 0xFF, 4, 3, 0, 0, 128, 2, 0, 4, 1, 0b0000_0001]);
    for (blk, &a) in enc.iter().enumerate() {
        let o = 12 + blk * block_len;
        put16(&mut b, o, (a >> 8) as u16);
        b[o + 2] = (a & 0xFF) as u8;
        for c in 0..128 {
            put16(&mut b, o + 3 + 4 * c, raw_distance(blk, c));
            b[o + 3 + 4 * c + 2] = 100;
            b[o + 3 + 4 * c + 3] = 1;
        }
    }
    let crc = crc32_mpeg2(&b[12..body_end]);
    put32(&mut b, body_end, crc);
    put16(&mut b, tail + 18, 200);
    put32(&mut b, tail + 20, 123_456);
    b[tail + 24] = 0x37;
    let secs: u64 = 1_679_653_308;
    for i in 0..5 {
        b[tail + 27 + i] = (secs >> (8 * (4 - i))) as u8;
    }
    put32(&mut b, tail + 32, 42);
    let crc = crc32_mpeg2(&b[tail..tail + 36]);
    put32(&mut b, tail + 36, crc);
    assert_eq!(b.len() + 32, 1118);

    // The correction formulas: adjustments interpolated every 2° of encoder azimuth, rounded to
    // 0.01°; azimuth = 2 (a − start) − azimuth[ch] + 256 adj; elevation = elevation[ch] + 256 adj.
    let adj = |row: &[i64], a: i64| -> i64 {
        let step = 2 * 25_600;
        let i = (a / step) as usize;
        let k = (a - i as i64 * step) as f64 / step as f64;
        ((1.0 - k) * row[i] as f64 + k * row[i + 1] as f64).round() as i64
    };
    let mut expected = Vec::new();
    for (blk, &a) in enc.iter().enumerate() {
        for c in 0..128 {
            let raw = raw_distance(blk, c);
            if raw == 0 {
                continue;
            }
            let row = c * 180..c * 180 + 180;
            let az = 2 * (a - dat.start[0]) - dat.az[c] + 256 * adj(&dat.az_adj[row.clone()], a);
            let el = dat.el[c] + 256 * adj(&dat.el_adj[row], a);
            expected.push(xyz(
                f64::from(raw) * 0.004,
                az as f64 / 25_600.0,
                el as f64 / 25_600.0,
            ));
        }
    }
    let got = decode(HesaiModel::PandarAt128, &b, "PandarAT128.dat");
    let err = max_error(&got, &expected);
    println!("AT128: {} points, max |Δxyz| {err:.3e} m", got.len());
    assert!(err < 1e-3, "{err}");
    let p = HesaiPacket::new(&b, HesaiModel::PandarAt128).unwrap();
    assert_eq!(p.stamp_ns(), Some(1_679_653_308_123_456_000));
    assert_eq!(p.udp_seq(), Some(42));
    let _ = dat.end;
}
