//! Pandar ATX (UDP protocol 4.7), for which there is neither a shared capture nor a public user
//! manual: the packets and the angle-correction files of this test are written BY HAND, byte by
//! byte, from Hesai's own SDK (HesaiLidar_SDK_2.0, 2.0.11: `libhesai/UdpProtocol/
//! udp_protocol_v4_7.h` for the packet structs and `ATXCorrections`, `libhesai/UdpParser/src/
//! udp4_7_parser.cc` for `LoadCorrectionString` and `ComputeXYZI`), not by ringscan's encoder,
//! and the expected points are computed here in f64 from the SDK's formulas.
//!
//! Checked: the three correction versions the SDK reads (4.1: one azimuth row; 4.2: even / odd
//! azimuth rows chosen by the tail's frame id bit 0; 4.3: the same plus the 70-entry elevation
//! adjustment interpolated over the corrected azimuth, 20°…158° every 2°); every decoded point
//! within 1 mm of the SDK's, in order, with intensity = reflectivity and ring = rank of the
//! channel's elevation (ringscan's convention); the tail time in both date forms of
//! `GetMicroLidarTimeU64`; the UDP sequence number; the packet length of `GetPacketSize` with
//! and without the sequence number and the signature; the frame split of `DecodePacket` on a
//! change of the frame id's bit 0.

use ringscan::point::Point;
use ringscan::sensor::hesai::family::parse_hesai_calibration;
use ringscan::sensor::hesai::{
    HesaiCalibration, HesaiConfig, HesaiDecoder, HesaiModel, HesaiOptions, HesaiPacket, HesaiStream,
};

/// Channels and blocks of every packet here (the header says so; the SDK takes both from it).
const N: usize = 12;
const BLOCKS: usize = 4;

/// Tail time handed to `decode_packet`; with no firing-time table every point has it.
const STAMP: i64 = 777;

fn put16(b: &mut [u8], o: usize, v: u16) {
    b[o..o + 2].copy_from_slice(&v.to_le_bytes());
}

fn put32(b: &mut [u8], o: usize, v: u32) {
    b[o..o + 4].copy_from_slice(&v.to_le_bytes());
}

// ---------------------------------------------------------------------------------------------
// Correction files (`ATXCorrections`, `LoadCorrectionString`)
// ---------------------------------------------------------------------------------------------

/// Azimuth (v1) / even azimuth (v2, v3) of each channel, degrees.
const AZ_DEG: [f64; N] = [
    4.02, 3.66, -3.91, -4.28, 4.04, 0.0, -3.89, -4.25, 0.39, 0.035, 4.39, -1.7,
];
/// Even − odd azimuth, degrees (channel 5 has 0 in both rows: the 158° end of the adjustment).
const ODD_DELTA_DEG: [f64; N] = [
    0.12, 0.31, -0.2, 0.45, 0.07, 0.0, 0.5, -0.33, 0.9, 0.25, -0.6, 0.18,
];
/// Elevation, degrees: distinct and not in channel order.
const EL_DEG: [f64; N] = [
    7.32, -12.5, 6.46, 2.9, -0.35, 5.31, -6.7, 4.45, -14.9, 9.8, 0.6, -3.3,
];

struct Corr {
    minor: u8,
    div: u16,
    /// v1: the azimuth row; v2 / v3: the even row.
    az: Vec<i16>,
    odd: Vec<i16>,
    el: Vec<i16>,
    adj: Vec<i16>,
}

impl Corr {
    fn new(minor: u8, div: u16) -> Self {
        let raw = |d: f64| (d * f64::from(div)).round() as i16;
        let az: Vec<i16> = AZ_DEG.iter().map(|&d| raw(d)).collect();
        let odd = AZ_DEG
            .iter()
            .zip(ODD_DELTA_DEG)
            .map(|(&a, d)| raw(a - d))
            .collect();
        let el = EL_DEG.iter().map(|&d| raw(d)).collect();
        // −100 … +238 units (−0.39° … +0.93° at 256 per degree), not monotonic, last entry
        // non-zero.
        let adj = (0..70i16).map(|i| ((i * 37) % 101 - 50 + i) * 2).collect();
        Corr {
            minor,
            div,
            az,
            odd,
            el,
            adj,
        }
    }

    /// The file: EE FF, version (4, minor), 2 reserved, channel count u8, angle division u16,
    /// then the int16 rows of the version, then 32 bytes of SHA-256.
    fn bytes(&self) -> Vec<u8> {
        let mut b = vec![0xEE, 0xFF, 4, self.minor, 0, 0, N as u8];
        b.extend_from_slice(&self.div.to_le_bytes());
        let mut row = |r: &[i16]| {
            for v in r {
                b.extend_from_slice(&v.to_le_bytes());
            }
        };
        match self.minor {
            1 => {
                row(&self.az);
                row(&self.el);
            }
            2 => {
                row(&self.az);
                row(&self.odd);
                row(&self.el);
            }
            _ => {
                row(&self.az);
                row(&self.odd);
                row(&self.el);
                row(&self.adj);
            }
        }
        b.extend((0..32u8).map(|i| i.wrapping_mul(29).wrapping_add(7)));
        let rows = if self.minor == 1 { 2 } else { 3 };
        let extra = if self.minor == 3 { 140 } else { 0 };
        assert_eq!(b.len(), 9 + 2 * N * rows + extra + 32);
        b
    }

    fn calibration(&self) -> HesaiCalibration {
        parse_hesai_calibration(&self.bytes())
            .expect("an ATX correction")
            .expect("a valid ATX correction")
    }

    /// `ATXCorrectionFloat::ElevationAdjust`.
    fn elevation_adjust(&self, mut a: f64) -> f64 {
        const BEG: f64 = 20.0;
        const STEP: f64 = 2.0;
        const END: f64 = BEG + STEP * 69.0;
        while a < 0.0 {
            a += 360.0;
        }
        while a >= 360.0 {
            a -= 360.0;
        }
        if !(BEG..=END).contains(&a) {
            return 0.0;
        }
        let div = f64::from(self.div);
        let i = ((a - BEG) / STEP) as usize;
        if i == 69 {
            return f64::from(self.adj[i]) / div;
        }
        let k = (a - BEG - i as f64 * STEP) / STEP;
        f64::from(self.adj[i]) / div * (1.0 - k) + f64::from(self.adj[i + 1]) / div * k
    }

    /// `ComputeXYZI` with a correction and no firetime file: (azimuth, elevation), degrees.
    fn angles(&self, block_az: u16, frame_id: u8, c: usize, with_adjust: bool) -> (f64, f64) {
        let div = f64::from(self.div);
        let row = if self.minor == 1 || frame_id % 2 == 0 {
            &self.az
        } else {
            &self.odd
        };
        let az = f64::from(block_az) / 256.0 + f64::from(row[c]) / div;
        let mut el = f64::from(self.el[c]) / div;
        if self.minor == 3 && with_adjust {
            el += self.elevation_adjust(az);
        }
        (az, el)
    }
}

// ---------------------------------------------------------------------------------------------
// Packets (`HS_LIDAR_*_ST_V7`, `#pragma pack(1)`, little-endian except the E2E header)
// ---------------------------------------------------------------------------------------------

fn raw_distance(block: usize, c: usize) -> u16 {
    // 500 … ~4600 units, different for every (block, channel); every 7th empty.
    if (c + 2 * block) % 7 == 3 {
        0
    } else {
        (500 + 37 * c + 911 * block) as u16 % 4_000 + 500
    }
}

fn reflectivity(block: usize, c: usize) -> u8 {
    (c * 17 + block * 5 + 3) as u8
}

#[derive(Clone)]
struct Pkt {
    dist_unit: u8,
    flags: u8,
    frame_id: u8,
    az: [u16; BLOCKS],
    utc: [u8; 6],
    us: u32,
    seq: u32,
}

impl Pkt {
    fn new(az: [u16; BLOCKS], frame_id: u8) -> Self {
        Pkt {
            dist_unit: 4,
            flags: 0,
            frame_id,
            az,
            utc: [124, 3, 24, 12, 34, 56],
            us: 250_000,
            seq: 1,
        }
    }
}

const BLOCK_LEN: usize = 2 + 1 + 4 * N;
const BODY_END: usize = 12 + BLOCKS * BLOCK_LEN;
const TAIL: usize = BODY_END + 4;

/// `HS_LIDAR_HEADER_ST_V7::GetPacketSize`.
fn packet_size(flags: u8) -> usize {
    6 + 6
        + (2 + 1 + 4 * N) * BLOCKS
        + 4
        + 32
        + if flags & 1 != 0 { 4 } else { 0 }
        + 12
        + if flags & 8 != 0 { 32 } else { 0 }
}

fn packet(p: &Pkt) -> Vec<u8> {
    let len = packet_size(p.flags);
    let mut b = vec![0u8; len];
    // HS_LIDAR_PRE_HEADER: delimiter EE FF, version 4.7, status info version, reserved.
    b[..6].copy_from_slice(&[0xEE, 0xFF, 4, 7, 0, 0]);
    // HS_LIDAR_HEADER_ST_V7: laser num, block num, echo count (first block: strongest),
    // distance unit (mm), echo num, status.
    b[6..12].copy_from_slice(&[N as u8, BLOCKS as u8, 2, p.dist_unit, 1, p.flags]);
    for (blk, &az) in p.az.iter().enumerate() {
        let o = 12 + blk * BLOCK_LEN;
        put16(&mut b, o, az);
        // Fine azimuth: the SDK does not use it.
        b[o + 2] = (0x5A + 41 * blk) as u8;
        for c in 0..N {
            let u = o + 3 + 4 * c;
            put16(&mut b, u, raw_distance(blk, c));
            b[u + 2] = reflectivity(blk, c);
            b[u + 3] = (c % 4) as u8; // confidence
        }
    }
    // HS_LIDAR_BODY_CRC_ST_V7: arbitrary (algorithm unpublished).
    b[BODY_END..TAIL].copy_from_slice(&[0xDE, 0xAD, 0xBE, 0xEF]);
    // HS_LIDAR_TAIL_ST_V7 (32): ReservedInfo1 (sts u16, id), reserved 7, frame id, reserved 7,
    // motor speed i16, timestamp u32 (µs), return mode, factory info, UTC (6).
    let t = TAIL;
    b[t..t + 3].copy_from_slice(&[0x34, 0x12, 0x01]);
    b[t + 10] = p.frame_id;
    put16(&mut b, t + 18, 600i16 as u16);
    put32(&mut b, t + 20, p.us);
    b[t + 24] = 0x37;
    b[t + 25] = 0x42;
    b[t + 26..t + 32].copy_from_slice(&p.utc);
    let mut o = t + 32;
    if p.flags & 1 != 0 {
        // HS_LIDAR_TAIL_SEQ_NUM_ST_V7
        put32(&mut b, o, p.seq);
        o += 4;
    }
    // HS_LIDAR_E2E_HEADER_ST_V7 (big-endian): length, counter, data id, CRC.
    let e2e_len = (len - 4 - 32) as u16;
    b[o..o + 2].copy_from_slice(&e2e_len.to_be_bytes());
    b[o + 2..o + 4].copy_from_slice(&(p.seq as u16).to_be_bytes());
    b[o + 4..o + 8].copy_from_slice(&0x0102_0304u32.to_be_bytes());
    b[o + 8..o + 12].copy_from_slice(&0xCAFE_F00Du32.to_be_bytes());
    o += 12;
    if p.flags & 8 != 0 {
        // HS_LIDAR_CYBER_SECURITY_ST_V7
        for (i, v) in b[o..o + 32].iter_mut().enumerate() {
            *v = 0xA5 ^ i as u8;
        }
        o += 32;
    }
    assert_eq!(o, len);
    b
}

// ---------------------------------------------------------------------------------------------
// Expected points
// ---------------------------------------------------------------------------------------------

struct Expected {
    xyz: Vec<[f64; 3]>,
    intensity: Vec<f32>,
    channel: Vec<usize>,
}

fn xyz(d: f64, az_deg: f64, el_deg: f64) -> [f64; 3] {
    let (az, el) = (az_deg.to_radians(), el_deg.to_radians());
    // SDK: x = d cos(el) sin(az), y = d cos(el) cos(az); ringscan (REP 103) = (y, −x, z).
    [
        d * el.cos() * az.cos(),
        -d * el.cos() * az.sin(),
        d * el.sin(),
    ]
}

fn expected(corr: &Corr, p: &Pkt, with_adjust: bool) -> Expected {
    let mut e = Expected {
        xyz: Vec::new(),
        intensity: Vec::new(),
        channel: Vec::new(),
    };
    for (blk, &az) in p.az.iter().enumerate() {
        for c in 0..N {
            let raw = raw_distance(blk, c);
            if raw == 0 {
                continue;
            }
            let d = f64::from(raw) * f64::from(p.dist_unit) / 1000.0;
            let (a, el) = corr.angles(az, p.frame_id, c, with_adjust);
            e.xyz.push(xyz(d, a, el));
            e.intensity.push(f32::from(reflectivity(blk, c)));
            e.channel.push(c);
        }
    }
    e
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

/// Ring = rank of the channel's elevation, 0 = lowest (ringscan's convention).
fn elevation_rank(c: usize) -> u16 {
    EL_DEG.iter().filter(|&&e| e < EL_DEG[c]).count() as u16
}

fn decode(calib: &HesaiCalibration, bytes: &[u8]) -> Vec<Point> {
    let p = HesaiPacket::new(bytes, HesaiModel::PandarAtx).expect("a valid ATX packet");
    let mut dec = HesaiDecoder::new(HesaiModel::PandarAtx, calib, HesaiOptions::default()).unwrap();
    let mut out = Vec::new();
    let n = dec.decode_packet(&p, STAMP, 0, &mut out).unwrap();
    assert_eq!(n, out.len());
    out
}

/// Decodes `p` and checks every point against the SDK's; returns (points, max error).
fn check(corr: &Corr, calib: &HesaiCalibration, p: &Pkt) -> (Vec<Point>, f64) {
    let got = decode(calib, &packet(p));
    let e = expected(corr, p, true);
    let err = max_error(&got, &e.xyz);
    assert!(
        err < 1e-3,
        "v{} frame {}: max error {err} m",
        corr.minor,
        p.frame_id
    );
    for (i, pt) in got.iter().enumerate() {
        assert_eq!(pt.intensity, e.intensity[i], "point {i}");
        assert_eq!(pt.ring, elevation_rank(e.channel[i]), "point {i}");
        assert_eq!(i64::from(pt.t), STAMP, "point {i}");
        assert_eq!(pt.ret, 0, "point {i}");
    }
    (got, err)
}

/// Block azimuths (u16 / 256 = degrees; the fine azimuth byte is not used by the SDK).
/// Middle of the field: the v3 adjustment is interpolated (61.25°, 66.40625°, 75.5°, ≈89.9°).
const MID: [u16; BLOCKS] = [15_680, 17_000, 19_328, 23_015];
/// Edges of the adjustment: 10° (every channel below 20°: no adjustment), 158° (channel 5
/// exactly at the last entry, the others past it), 156.5° (channels either side of 158°),
/// 19.75° (channels either side of 20°).
const EDGE: [u16; BLOCKS] = [2_560, 40_448, 40_064, 5_056];

fn run_version(minor: u8, div: u16, dist_unit: u8) {
    let corr = Corr::new(minor, div);
    let calib = corr.calibration();
    let mut by_parity: [Vec<Vec<Point>>; 2] = [Vec::new(), Vec::new()];
    for (parity, frame_ids) in [[0u8, 2], [1, 3]].iter().enumerate() {
        let (mut points, mut err) = (0, 0.0f64);
        for &fid in frame_ids {
            for az in [MID, EDGE] {
                let mut p = Pkt::new(az, fid);
                p.dist_unit = dist_unit;
                let (got, e) = check(&corr, &calib, &p);
                points += got.len();
                err = err.max(e);
                if fid < 2 {
                    by_parity[parity].push(got);
                }
            }
        }
        let name = ["even", "odd"][parity];
        println!("ATX v{minor} ({name} frame ids): {points} points, max |Δxyz| {err:.3e} m");
    }
    // The same body with an even and an odd frame id.
    for (even, odd) in by_parity[0].iter().zip(&by_parity[1]) {
        if minor == 1 {
            assert_eq!(even, odd, "v1 has one azimuth row");
        } else {
            assert_ne!(even, odd, "v{minor}: even and odd rows must differ");
        }
    }
    if minor >= 2 {
        // An odd frame decoded as if even (and vice versa) is far off: the row is the odd one.
        let mut odd = Pkt::new(MID, 1);
        odd.dist_unit = dist_unit;
        let mut even_u = odd.clone();
        even_u.frame_id = 0;
        let got = decode(&calib, &packet(&odd));
        let wrong = max_error(&got, &expected(&corr, &even_u, true).xyz);
        assert!(
            wrong > 5e-3,
            "v{minor}: odd frame decoded with the even row? {wrong}"
        );
    }
    if minor == 3 {
        // The elevation adjustment matters in the middle of the field …
        let p = Pkt::new(MID, 0);
        let got = decode(&calib, &packet(&p));
        let without = max_error(&got, &expected(&corr, &p, false).xyz);
        assert!(without > 0.05, "v3 adjustment not applied? {without}");
        // … and the 158° end uses the last entry (channel 5, block 1 of EDGE).
        assert_ne!(corr.adj[69], 0);
        assert_eq!(corr.angles(EDGE[1], 0, 5, true).0, 158.0);
        assert_eq!(
            corr.elevation_adjust(158.0),
            f64::from(corr.adj[69]) / f64::from(div)
        );
    }
}

#[test]
fn atx_v1_correction() {
    run_version(1, 100, 4);
}

#[test]
fn atx_v2_correction() {
    run_version(2, 100, 2);
}

#[test]
fn atx_v3_correction() {
    run_version(3, 256, 4);
}

#[test]
fn atx_bad_corrections_rejected() {
    let good = Corr::new(3, 256).bytes();
    // Minor version 4: "min_version is wrong!".
    let mut b = good.clone();
    b[3] = 4;
    assert!(!matches!(parse_hesai_calibration(&b), Some(Ok(_))));
    // One byte short of 9 + 3·2·N + 140 + 32: "correction string length is too short".
    let b = &good[..good.len() - 1];
    assert!(!matches!(parse_hesai_calibration(b), Some(Ok(_))));
    // Angle division 0.
    let mut b = good.clone();
    b[7] = 0;
    b[8] = 0;
    assert!(!matches!(parse_hesai_calibration(&b), Some(Ok(_))));
    // More than ATX_MAX_CHANNEL_NUM (200) channels.
    let mut b = good;
    b[6] = 201;
    assert!(!matches!(parse_hesai_calibration(&b), Some(Ok(_))));
}

/// Days from 1970-01-01 to y-m-d (proleptic Gregorian; H. Hinnant's `days_from_civil`).
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

#[test]
fn atx_tail_time_seq_and_length() {
    // UTC form (byte 0 ≠ 0): year − 1900, month, day, h, min, s (mktime with tm_mday = day + 1,
    // minus one day: the date as written), + µs.
    let mut p = Pkt::new(MID, 0);
    p.utc = [124, 3, 24, 12, 34, 56];
    p.us = 250_000;
    let b = packet(&p);
    let h = HesaiPacket::new(&b, HesaiModel::PandarAtx).unwrap();
    let secs = days_from_civil(2024, 3, 24) * 86_400 + 12 * 3600 + 34 * 60 + 56;
    assert_eq!(secs, 1_711_283_696);
    assert_eq!(h.stamp_ns(), Some(secs * 1_000_000_000 + 250_000_000));
    assert_eq!(h.frame_id(), Some(0));
    assert_eq!(h.return_mode(), 0x37);
    assert_eq!(h.layout().channels, N);
    assert_eq!(h.layout().blocks, BLOCKS);
    assert_eq!(HesaiModel::detect(&b), Some(HesaiModel::PandarAtx));

    // Unix form (byte 0 = 0): seconds as a big-endian u32 in bytes 2..6, + µs.
    let secs: u32 = 1_700_000_123;
    let mut p = Pkt::new(MID, 7);
    p.utc = [0, 0, 0, 0, 0, 0];
    p.utc[2..6].copy_from_slice(&secs.to_be_bytes());
    p.us = 999_999;
    let b = packet(&p);
    let h = HesaiPacket::new(&b, HesaiModel::PandarAtx).unwrap();
    assert_eq!(
        h.stamp_ns(),
        Some(i64::from(secs) * 1_000_000_000 + 999_999_000)
    );
    assert_eq!(h.frame_id(), Some(7));
    println!(
        "ATX tail time: UTC form {:?} ns, Unix form {:?} ns",
        HesaiPacket::new(&packet(&Pkt::new(MID, 0)), HesaiModel::PandarAtx)
            .unwrap()
            .stamp_ns(),
        h.stamp_ns()
    );

    // Lengths per GetPacketSize: sequence number (bit 0) +4, signature (bit 3) +32; the
    // other status bits (IMU, functional safety, confidence) add nothing.
    let corr = Corr::new(3, 256);
    let calib = corr.calibration();
    let reference = decode(&calib, &packet(&Pkt::new(MID, 0)));
    for flags in [0x00u8, 0x01, 0x08, 0x09, 0x02, 0x04, 0x10, 0x1F] {
        let mut p = Pkt::new(MID, 0);
        p.flags = flags;
        p.seq = 0x0012_3456 + u32::from(flags);
        let b = packet(&p);
        assert_eq!(b.len(), packet_size(flags));
        let h = HesaiPacket::new(&b, HesaiModel::PandarAtx)
            .unwrap_or_else(|e| panic!("flags {flags:#04x}, {} bytes: {e:?}", b.len()));
        assert_eq!(HesaiModel::detect(&b), Some(HesaiModel::PandarAtx));
        assert_eq!(
            h.udp_seq(),
            (flags & 1 != 0).then_some(p.seq),
            "flags {flags:#04x}"
        );
        assert_eq!(h.has_signature(), flags & 8 != 0, "flags {flags:#04x}");
        assert_eq!(
            h.stamp_ns(),
            Some(1_711_283_696 * 1_000_000_000 + 250_000_000)
        );
        assert_eq!(decode(&calib, &b), reference, "flags {flags:#04x}");
        let longer = [b.clone(), vec![0]].concat();
        assert!(
            HesaiPacket::new(&longer, HesaiModel::PandarAtx).is_err(),
            "flags {flags:#04x}: {} bytes accepted",
            longer.len()
        );
        assert!(
            HesaiPacket::new(&b[..b.len() - 1], HesaiModel::PandarAtx).is_err(),
            "flags {flags:#04x}: {} bytes accepted",
            b.len() - 1
        );
        println!(
            "ATX status {flags:#04x}: {} bytes, seq {:?}, signed {}",
            b.len(),
            h.udp_seq(),
            h.has_signature()
        );
    }
}

/// Pushes packets with these frame ids; returns the packets and points of every sweep.
fn stream(frame_ids: &[u8]) -> (Vec<(u32, usize)>, u64, u64, u64) {
    let corr = Corr::new(3, 256);
    let mut cfg = HesaiConfig::new(Some(corr.calibration()), "atx.dat");
    cfg.model = Some(HesaiModel::PandarAtx);
    let mut s = HesaiStream::new(cfg);
    let mut sweeps = Vec::new();
    let mut cb = |sw: &mut ringscan::sweep::Sweep, _: &ringscan::sensor::hesai::HesaiFacts| {
        sweeps.push((sw.packets, sw.points.len()))
    };
    let secs: u32 = 1_700_000_000;
    for (i, &fid) in frame_ids.iter().enumerate() {
        let mut p = Pkt::new(MID, fid);
        p.flags = 0x01;
        p.seq = 100 + i as u32;
        p.utc = [0, 0, 0, 0, 0, 0];
        p.utc[2..6].copy_from_slice(&secs.to_be_bytes());
        p.us = 100_000 + 500 * i as u32;
        let host_ns = i64::from(secs) * 1_000_000_000 + i64::from(p.us) * 1000 + 1_000_000;
        s.push(host_ns, &packet(&p), &mut cb).unwrap();
    }
    s.finish(&mut cb);
    let st = s.stats();
    (sweeps, st.packets, st.malformed, st.sweeps)
}

#[test]
fn atx_frame_split_on_frame_id_bit0() {
    let per_packet = (0..BLOCKS)
        .flat_map(|b| (0..N).map(move |c| raw_distance(b, c)))
        .filter(|&r| r != 0)
        .count();

    // 0 0 0 | 1 1 1 | 2 2: a new frame at every change of bit 0.
    let (sweeps, packets, malformed, n) = stream(&[0, 0, 0, 1, 1, 1, 2, 2]);
    println!("ATX frame split 0,0,0,1,1,1,2,2: sweeps (packets, points) {sweeps:?}");
    assert_eq!((packets, malformed, n), (8, 0, 3));
    assert_eq!(
        sweeps,
        vec![
            (3, 3 * per_packet),
            (3, 3 * per_packet),
            (2, 2 * per_packet)
        ]
    );

    // 1 1 3 3 | 0: the SDK splits on frame_id % 2 only (1 → 3 keeps the frame).
    let (sweeps, packets, malformed, n) = stream(&[1, 1, 3, 3, 0]);
    println!("ATX frame split 1,1,3,3,0: sweeps (packets, points) {sweeps:?}");
    assert_eq!((packets, malformed, n), (5, 0, 2));
    assert_eq!(sweeps, vec![(4, 4 * per_packet), (1, per_packet)]);
}

/// The firetime CSV (`LoadFiretimesFile`, type 2: the header line skipped, then `index,even,odd`
/// with a 1-based index, in any order), which `ComputeXYZI` applies before the correction:
/// `raw_azimuth += (even frame ? even[ch] : −odd[ch]) × |motor speed| × 1e-9 / 8`, the
/// elevation adjustment then read at the shifted azimuth. (Added by the main author after the
/// rest of this file; the formula is the SDK's, evaluated here in f64.)
#[test]
fn atx_firetimes_csv() {
    let corr = Corr::new(3, 256);
    let even: Vec<f64> = (0..N).map(|c| 4_960.0 + 3_900.0 * c as f64).collect();
    let odd: Vec<f64> = (0..N).map(|c| 7_560.0 + 520.0 * c as f64).collect();
    let mut csv = String::from("Channel,Even_fire time(ns),Odd_fire time(ns)\n");
    for c in (0..N).rev() {
        csv.push_str(&format!("{},{},{}\n", c + 1, even[c], odd[c]));
    }
    let Some(Ok(HesaiCalibration::Atx(angles))) = parse_hesai_calibration(&corr.bytes()) else {
        panic!("the angle correction")
    };
    let Some(Ok(HesaiCalibration::AtxFiretimes(fire))) = parse_hesai_calibration(csv.as_bytes())
    else {
        panic!("the firetime CSV")
    };
    let calib = HesaiCalibration::Atx(angles.with_firetimes(fire).unwrap());
    // The tail's motor speed written by `packet`.
    let speed = 600.0;
    let div = f64::from(corr.div);
    for fid in [0u8, 1] {
        let p = Pkt::new(MID, fid);
        let got = decode(&calib, &packet(&p));
        let mut exp = Vec::new();
        for (blk, &az) in p.az.iter().enumerate() {
            for c in 0..N {
                let raw = raw_distance(blk, c);
                if raw == 0 {
                    continue;
                }
                let shift = if fid % 2 == 0 { even[c] } else { -odd[c] } * speed * 1e-9 / 8.0;
                let row = if fid % 2 == 0 { &corr.az } else { &corr.odd };
                let a = f64::from(az) / 256.0 + shift + f64::from(row[c]) / div;
                let el = f64::from(corr.el[c]) / div + corr.elevation_adjust(a);
                exp.push(xyz(f64::from(raw) * 0.004, a, el));
            }
        }
        let err = max_error(&got, &exp);
        // Without the firetimes the points are off by up to ~1 mm at these ranges.
        let without = max_error(&got, &expected(&corr, &p, true).xyz);
        println!(
            "ATX firetimes (frame id {fid}): {} points, max |Δxyz| {err:.3e} m; {without:.3e} m \
             from the points without them",
            got.len()
        );
        assert!(err < 5e-5, "{err}");
        assert!(without > 2e-4, "firetimes not applied? {without}");
    }
}
