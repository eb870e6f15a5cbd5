//! The PandarAT128's angle correction (`.dat`) in both published layouts.
//!
//! * Version 1.3, which no shared file uses: a file is written here BY HAND, byte offsets
//!   spelled out from the layout the AT128 readers share (HesaiLidar_SDK_2.0 ≤ 2.0.7
//!   `udp4_3_parser.cc`, the AT128 ROS driver, nebula's `HesaiCorrection` case 3): 16-byte header,
//!   u16 start / end frames, i16 channel azimuths / elevations, two 36 000-entry i8 grids (one
//!   entry per 0.01° of encoder azimuth, shared by all channels), SHA-256. The angles are compared
//!   with values worked out below from the formulas, in 1/25600°.
//! * Version 1.5: the four shared `PandarAT128.dat*` files parse, and identical files parse to
//!   identical corrections.
//! * Files whose sizes lie, unknown versions, impossible values: a clear error.

mod common;

use ringscan::sensor::hesai::at128::{AdjustGrid, At128Correction};
use ringscan::sensor::hesai::family::parse_hesai_calibration;
use ringscan::sensor::hesai::{HesaiCalibration, HesaiDecoder, HesaiModel, HesaiOptions};

const CALIB: &str = "tier4__nebula/src/nebula_hesai/nebula_hesai_decoders/calibration";

// Offsets of a 1.3 file with 3 mirrors and 128 channels.
const START: usize = 16; // u16 × 3
const END: usize = 22; // u16 × 3
const AZ: usize = 28; // i16 × 128
const EL: usize = 284; // i16 × 128
const AZ_ADJ: usize = 540; // i8 × 36 000
const EL_ADJ: usize = 36_540; // i8 × 36 000
const SHA: usize = 72_540; // 32 bytes
const LEN: usize = 72_572;

/// A 1.3 file: fields 30°–150°, 150°–270°, 270°–30° of encoder azimuth; channel k's azimuth
/// (k % 7 − 3) × 0.5°, elevation 12.7° − k × 0.2°; channel 5 overridden to 1.5° / −12.34°;
/// grid entries 5 000 (50.00°) = (+7, −3) and 1 000 (10.00°) = (−20, +11), every other 0.
fn v13(res: u8) -> Vec<u8> {
    let mut b = vec![0u8; LEN];
    b[0..4].copy_from_slice(&[0xEE, 0xFF, 0x01, 0x03]);
    b[4] = 128; // channels
    b[5] = 3; // mirrors
    b[6] = 3; // frames
    b[15] = res;
    let put16 = |b: &mut Vec<u8>, o: usize, v: i32| {
        b[o..o + 2].copy_from_slice(&(v as u16).to_le_bytes());
    };
    for (m, (s, e)) in [(3_000, 15_000), (15_000, 27_000), (27_000, 3_000)]
        .into_iter()
        .enumerate()
    {
        put16(&mut b, START + 2 * m, s);
        put16(&mut b, END + 2 * m, e);
    }
    for k in 0..128i32 {
        put16(&mut b, AZ + 2 * k as usize, (k % 7 - 3) * 50);
        put16(&mut b, EL + 2 * k as usize, 1_270 - 20 * k);
    }
    put16(&mut b, AZ + 2 * 5, 150);
    put16(&mut b, EL + 2 * 5, -1_234);
    b[AZ_ADJ + 5_000] = 7;
    b[EL_ADJ + 5_000] = (-3i8) as u8;
    b[AZ_ADJ + 1_000] = (-20i8) as u8;
    b[EL_ADJ + 1_000] = 11;
    for (i, x) in b[SHA..].iter_mut().enumerate() {
        *x = i as u8; // not checked
    }
    b
}

/// Encoder azimuth in 1/25600° from the packet's 0.01° word and fine byte.
fn enc(cdeg: i64, fine: i64) -> i64 {
    cdeg * 256 + fine
}

#[test]
fn v13_built_by_hand_gives_the_hand_computed_angles() {
    let c = At128Correction::parse(&v13(1)).unwrap();
    assert_eq!(c.version, (1, 3));
    assert_eq!(c.grid, AdjustGrid::Shared001Deg);
    assert_eq!(c.channels(), 128);
    // Fields in 1/25600°: 30° = 768 000, 150° = 3 840 000, 270° = 6 912 000.
    assert_eq!(c.start_frame, vec![768_000, 3_840_000, 6_912_000]);
    assert_eq!(c.end_frame, vec![3_840_000, 6_912_000, 768_000]);

    // Channel 5 at encoder 50.00° + 128/25600° (mirror 0, grid entry 5 000 = +0.07° / −0.03°):
    // azimuth = 2 × (1 280 128 − 768 000) − 150·256 + 7·256 = 1 024 256 − 38 400 + 1 792
    //         = 987 648 (38.58°); elevation = −1 234·256 − 3·256 = −316 672 (−12.37°).
    assert_eq!(c.angles(5, enc(5_000, 128)), Some((987_648, -316_672)));
    // The grid is shared: channel 0 (azimuth −1.5°, elevation 12.7°) at the same encoder angle:
    // 1 024 256 + 150·256 + 7·256 = 1 064 448; 1 270·256 − 3·256 = 324 352.
    assert_eq!(c.angles(0, enc(5_000, 128)), Some((1_064_448, 324_352)));
    // No interpolation: one fine step short of 50.00° reads entry 4 999 (0): channel 5 at
    // 49.99° + 255: 2 × (4 999·256 + 255 − 768 000) − 38 400 = 2 × 511 999 − 38 400 = 985 598.
    assert_eq!(c.angles(5, enc(4_999, 255)), Some((985_598, -315_904)));
    // Mirror 2's field wraps: encoder 10.00° (256 000 units) lies in 270°–30°; entry 1 000 =
    // −0.20° / +0.11°. Channel 9 (azimuth (9 % 7 − 3) × 0.5° = −0.5°, elevation 12.7 − 1.8 = 10.9°):
    // 2 × (256 000 − 6 912 000) + 50·256 − 20·256 = −13 312 000 + 7 680 = −13 304 320,
    // + 2 turns (18 432 000) = 5 127 680 (200.30°); elevation (1 090 + 11)·256 = 281 856.
    assert_eq!(c.angles(9, enc(1_000, 0)), Some((5_127_680, 281_856)));

    // Resolution 2: every file value doubles (the encoder angle does not).
    let c2 = At128Correction::parse(&{
        let mut b = v13(2);
        // Fields halved so that they stay 30° / 150° / 270° after × 2.
        for (m, (s, e)) in [(1_500, 7_500), (7_500, 13_500), (13_500, 1_500)]
            .into_iter()
            .enumerate()
        {
            b[START + 2 * m..START + 2 * m + 2].copy_from_slice(&(s as u16).to_le_bytes());
            b[END + 2 * m..END + 2 * m + 2].copy_from_slice(&(e as u16).to_le_bytes());
        }
        b
    })
    .unwrap();
    assert_eq!(c2.start_frame, c.start_frame);
    // Channel 5: 1 024 256 − 2·38 400 + 2·1 792 = 951 040; −2·316 672 = −633 344.
    assert_eq!(c2.angles(5, enc(5_000, 128)), Some((951_040, -633_344)));

    // Outside every field: a file whose fields leave 150°–270° uncovered.
    let mut b = v13(1);
    b[START + 2..START + 4].copy_from_slice(&27_000u16.to_le_bytes());
    let c3 = At128Correction::parse(&b).unwrap();
    assert_eq!(c3.angles(5, enc(20_000, 0)), None);

    // Through the family's reader and the decoder: channel azimuths follow the same formula.
    let calib = parse_hesai_calibration(&v13(1)).unwrap().unwrap();
    assert!(matches!(&calib, HesaiCalibration::At128(a) if a.version == (1, 3)));
    let dec = HesaiDecoder::new(HesaiModel::PandarAt128, &calib, HesaiOptions::default()).unwrap();
    // 987 648 / 25 600° = 38.58° = 38 580 000 µ°.
    assert_eq!(
        dec.channel_azimuth_udeg(enc(5_000, 128) as u32, 5),
        Some(38_580_000)
    );
}

#[test]
fn shared_dat_files_are_version_1_5_and_parse() {
    let Some(root) = common::captures() else {
        return;
    };
    let dir = root.join(CALIB);
    let mut parsed = Vec::new();
    for name in [
        "PandarAT128.dat",
        "PandarAT128.dat_or",
        "PandarAT128.dat.2209",
        "PandarAT128.dat.2303",
    ] {
        let bytes = std::fs::read(dir.join(name)).unwrap();
        assert_eq!(&bytes[..4], &[0xEE, 0xFF, 1, 5], "{name}");
        let c = At128Correction::parse(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!((c.version, c.grid), ((1, 5), AdjustGrid::PerChannel2Deg));
        assert_eq!((c.channels(), c.start_frame.len()), (128, 3), "{name}");
        eprintln!(
            "{name}: version 1.5, resolution {}, {} bytes",
            bytes[15],
            bytes.len()
        );
        parsed.push(c);
    }
    // NEBULA.md: .dat.2303 is .dat, .dat.2209 is .dat_or; the two pairs differ.
    assert_eq!(parsed[0], parsed[3]);
    assert_eq!(parsed[1], parsed[2]);
    assert_ne!(parsed[0], parsed[1]);
}

fn refused(bytes: &[u8], needle: &str) {
    match At128Correction::parse(bytes) {
        Ok(_) => panic!("accepted a file that should be refused ({needle})"),
        Err(e) => {
            let m = e.to_string();
            assert!(
                m.contains("AT128 angle correction") && m.contains(needle),
                "{m:?} lacks {needle:?}"
            );
        }
    }
}

#[test]
fn dat_files_whose_sizes_lie_are_refused_by_name() {
    let good = v13(1);
    // One byte short / long: the expected size is named.
    refused(&good[..LEN - 1], "is 72572 bytes, found 72571");
    let mut long = good.clone();
    long.push(0);
    refused(&long, "found 72573");
    // A header claiming 4 mirrors: 4 more bytes of fields expected.
    let mut b = good.clone();
    b[5] = 4;
    b[6] = 4;
    refused(&b, "is 72576 bytes");
    // Mirrors and frames disagree (nebula and the SDK would read the file differently).
    let mut b = good.clone();
    b[6] = 2;
    refused(&b, "2 frames for 3 mirrors");
    // A 1.5-sized file labelled 1.3, and a 1.3 file labelled 1.5.
    let mut b = vec![0u8; 16 + 24 + 1024 + 46_080 + 32];
    b[..7].copy_from_slice(&[0xEE, 0xFF, 1, 3, 128, 3, 3]);
    b[15] = 1;
    refused(
        &b,
        "version 1.3 with 128 channels and 3 mirrors is 72572 bytes, found 47176",
    );
    let mut b = good.clone();
    b[3] = 5;
    refused(&b, "is 47176 bytes, found 72572");
    // The SDK's 1.6–1.9 (fields declared, byte order unpublished) and unknown versions.
    let mut b = good.clone();
    b[3] = 7;
    refused(&b, "byte order is unknown");
    b[3] = 4;
    refused(&b, "version 1.4 is not supported");
    // 64 channels; resolution 0; a field start beyond one turn (65 535 × 0.01° × 256).
    let mut b = good.clone();
    b[4] = 64;
    refused(&b, "64 channels");
    let mut b = good.clone();
    b[15] = 0;
    refused(&b, "resolution 0");
    let mut b = good.clone();
    b[START..START + 2].copy_from_slice(&u16::MAX.to_le_bytes());
    refused(&b, "outside one turn");
    // A channel elevation of 327.67° (i16 max).
    let mut b = good;
    b[EL..EL + 2].copy_from_slice(&i16::MAX.to_le_bytes());
    refused(&b, "channel 0");
    // Too short for a header at all.
    refused(&[0xEE, 0xFF, 1, 3, 128], "16-byte header");
}
