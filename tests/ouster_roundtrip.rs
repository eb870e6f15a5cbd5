//! Ouster encode → decode round trips: every profile, every header layout it can carry,
//! H ∈ {16, 32, 64, 128}, one full frame each, on a synthetic calibration.
//!
//! The encoder (`sim::ouster`) writes packets from per-pixel values; the decoder must give
//! back exactly those values (ranges at the field-width limits, RNG15 8 mm steps, NIR8 ×16),
//! the header and column values, a valid CRC-64/XZ for standard headers, and points whose
//! xyz is the lookup table's, whose `t` is the column time and whose ring is the altitude rank.

use ringscan::sensor::ouster::calib::parse;
use ringscan::sensor::ouster::calib::OusterInfo;
use ringscan::sensor::ouster::model::HeaderKind;
use ringscan::sensor::ouster::model::PacketFormat;
use ringscan::sensor::ouster::model::Profile;
use ringscan::sensor::ouster::model::ALL_PROFILES;
use ringscan::sensor::ouster::sim::OusterEncoder;
use ringscan::sensor::ouster::sim::SimColumn;
use ringscan::sensor::ouster::sim::SimHeader;
use ringscan::sensor::ouster::sim::SimPixel;
use ringscan::sensor::ouster::wire::LidarPacket;
use ringscan::sensor::ouster::Extra;
use ringscan::sensor::ouster::OusterDecoder;
use ringscan::sensor::DecodeError;
use ringscan::sensor::WireError;

const W: usize = 512;
const CPP: usize = 16;

/// A small deterministic generator (xorshift64*).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n.max(1)
    }
}

/// A synthetic calibration: parsed from a reduced metadata text (beam angles and a lidar
/// mode, as ouster-sdk's `OS-1-64_sensor_config_reduced.json`), then given the profile, H,
/// ids, firmware and shifts of the case.
fn synthetic_info(profile: Profile, h: usize) -> OusterInfo {
    // Beams from +20° (row 0, top) down to −20°, with a repeating azimuth pattern; two
    // beams share an altitude to exercise the ring tie rule.
    let alt: Vec<f64> = (0..h)
        .map(|u| {
            if u == 1 {
                20.0
            } else {
                20.0 - 40.0 * u as f64 / (h - 1) as f64
            }
        })
        .collect();
    let az: Vec<f64> = (0..h).map(|u| [4.2, 1.4, -1.4, -4.2][u % 4]).collect();
    // The reduced form defaults to 64 beams; the case's H replaces them below.
    let text = serde_json::json!({
        "beam_altitude_angles": (0..64).map(|u| 20.0 - 0.5 * f64::from(u)).collect::<Vec<_>>(),
        "beam_azimuth_angles": vec![0.0; 64],
        "lidar_mode": "512x10",
    })
    .to_string();
    let mut info = parse(&text, "synthetic.json").unwrap_or_else(|e| panic!("{e}"));
    info.format = PacketFormat {
        profile,
        columns_per_packet: CPP,
        pixels_per_column: h,
    };
    info.columns_per_frame = W;
    info.column_window = (0, W - 1);
    info.beam_altitude_angles = alt;
    info.beam_azimuth_angles = az;
    info.pixel_shift_by_row = (0..h).map(|u| [12, 4, -4, -12][u % 4]).collect();
    info.serial = 992_210_000_957;
    info.init_id = 5_431_293;
    info.firmware = "v2.5.2".to_owned();
    info.image_rev = "ousteros-image-prod-aries-v2.5.2+20230101000000".to_owned();
    info
}

/// A pixel value at random within the field widths of the profile, with the limits mixed in.
fn pixel(rng: &mut Rng, profile: Profile, row: usize, col: usize) -> SimPixel {
    let l = profile.layout();
    let mut draw = |f: Option<ringscan::sensor::ouster::model::Field>, limit: bool| -> u32 {
        let Some(f) = f else { return 0 };
        let max = (1u64 << f.width) - 1;
        let raw = match (limit, rng.below(8)) {
            (true, _) | (_, 0) => max,
            (_, 1) => 0,
            _ => rng.below(max + 1),
        };
        (raw as u32) << f.shift
    };
    let limit = (row + col) % 13 == 0;
    SimPixel {
        range_mm: draw(Some(l.range), limit),
        reflectivity: draw(Some(l.reflectivity), limit) as u8,
        signal: draw(l.signal, limit) as u16,
        near_ir: draw(l.near_ir, limit) as u16,
        flags: draw(l.flags, limit) as u8,
        range2_mm: draw(l.range2, limit),
        reflectivity2: draw(l.reflectivity2, limit) as u8,
        signal2: draw(l.signal2, limit) as u16,
        flags2: draw(l.flags2, limit) as u8,
    }
}

fn header_kinds(profile: Profile) -> Vec<HeaderKind> {
    match profile {
        Profile::Legacy => vec![HeaderKind::Legacy],
        _ => vec![HeaderKind::Standard, HeaderKind::Fusa],
    }
}

#[derive(Default)]
struct Tally {
    cases: usize,
    packets: usize,
    points: usize,
}

fn round_trip(profile: Profile, h: usize, kind: HeaderKind, tally: &mut Tally) {
    let what = format!("{profile} H={h} {kind:?}");
    let info = synthetic_info(profile, h);
    let crc = kind == HeaderKind::Standard && profile != Profile::FusaRng15Rfl8Nir8Dual;
    let dec = OusterDecoder::new(&info)
        .unwrap()
        .with_header_kind(kind)
        .with_crc_check(crc);
    assert_eq!(dec.header_kind(), kind, "{what}");
    let enc = OusterEncoder::new(&info).with_header(kind).with_crc(crc);
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15 ^ (h as u64) << 8 ^ profile as u64);
    let legacy = kind == HeaderKind::Legacy;
    let header = SimHeader {
        packet_type: 1,
        frame_id: if kind == HeaderKind::Fusa {
            0x8123_4567
        } else {
            0xFFFE
        },
        init_id: if legacy { 0 } else { info.init_id },
        serial: if legacy { 0 } else { info.serial },
        alert_flags: if legacy { 0 } else { 152 },
        countdown_thermal_shutdown: if legacy { 0 } else { 5 },
        countdown_shot_limiting: if legacy { 0 } else { 200 },
        thermal_shutdown: if legacy { 0 } else { 1 },
        shot_limiting: if legacy { 0 } else { 9 },
    };
    let t0: u64 = 866_100_516_040;
    let valid = |c: usize| c % 7 != 3;
    let columns: Vec<SimColumn> = (0..W)
        .map(|c| SimColumn {
            timestamp_ns: t0 + c as u64 * 195_312,
            measurement_id: c as u16,
            status: if !valid(c) {
                0
            } else if legacy {
                0xFFFF_FFFF
            } else {
                1
            },
            pixels: (0..h).map(|u| pixel(&mut rng, profile, u, c)).collect(),
        })
        .collect();

    let mut frame = dec.new_frame();
    let mut bytes = Vec::new();
    let mut emitted: Vec<(ringscan::Point, Extra, usize, usize)> = Vec::new();
    let sweep_start = t0 + 1_000; // column 0 lies before the sweep start: t clamps to 0
    for chunk in columns.chunks(CPP) {
        enc.encode(&header, chunk, &mut bytes).unwrap();
        assert_eq!(bytes.len(), info.format.packet_bytes(), "{what}");
        let p = dec.packet(&bytes).unwrap_or_else(|e| panic!("{what}: {e}"));
        tally.packets += 1;
        // Header values.
        assert_eq!(p.packet_type(), if legacy { 0 } else { 1 }, "{what}");
        let fid = if kind == HeaderKind::Fusa {
            header.frame_id
        } else {
            header.frame_id & 0xFFFF
        };
        assert_eq!(p.frame_id(), fid, "{what}");
        assert_eq!(p.init_id(), header.init_id, "{what}");
        assert_eq!(p.serial(), header.serial, "{what}");
        assert_eq!(p.alert_flags(), header.alert_flags, "{what}");
        assert_eq!(
            p.countdown_thermal_shutdown(),
            header.countdown_thermal_shutdown,
            "{what}"
        );
        assert_eq!(
            p.countdown_shot_limiting(),
            header.countdown_shot_limiting,
            "{what}"
        );
        assert_eq!(p.thermal_shutdown(), header.thermal_shutdown, "{what}");
        assert_eq!(p.shot_limiting(), header.shot_limiting, "{what}");
        assert_eq!(p.crc_ok(), crc.then_some(true), "{what}");
        // Column headers.
        for (c, col) in chunk.iter().zip(p.columns()) {
            assert_eq!(col.timestamp_ns(), c.timestamp_ns, "{what}");
            assert_eq!(col.measurement_id(), c.measurement_id, "{what}");
            assert_eq!(col.valid(), valid(usize::from(c.measurement_id)), "{what}");
            if legacy {
                assert_eq!(col.status(), c.status, "{what}");
                assert_eq!(col.frame_id() as u32, fid, "{what}");
                assert_eq!(
                    col.encoder_count(),
                    u32::from(c.measurement_id) * 90_112 / W as u32,
                    "{what}"
                );
            }
        }
        dec.decode_packet_into_frame(&p, &mut frame).unwrap();
        dec.decode_with(&p, sweep_start, |pt, x, row, col| {
            emitted.push((pt, x, row, col))
        })
        .unwrap();
    }
    assert_eq!(frame.frame_id, Some(fid_of(&header, kind)), "{what}");
    assert_eq!(frame.packets, W / CPP, "{what}");

    // Every pixel of the frame against the input.
    let l = profile.layout();
    let dual = profile.is_dual();
    let mut expected_points = 0;
    for (c, col) in columns.iter().enumerate() {
        let ok = valid(c);
        assert_eq!(frame.column_valid(c), ok, "{what} column {c}");
        assert_eq!(
            frame.timestamp_ns[c],
            if ok { col.timestamp_ns } else { 0 },
            "{what}"
        );
        for (u, px) in col.pixels.iter().enumerate() {
            let i0 = frame.index(0, u, c).unwrap();
            let want0 = (px.range_mm, px.reflectivity, px.signal, px.flags);
            let got0 = (
                frame.range_mm[i0],
                frame.reflectivity[i0],
                frame.signal[i0],
                frame.flags[i0],
            );
            let zero = (0, 0, 0, 0);
            assert_eq!(got0, if ok { want0 } else { zero }, "{what} ({u}, {c})");
            assert_eq!(
                frame.near_ir[u * W + c],
                if ok { px.near_ir } else { 0 },
                "{what}"
            );
            if ok && px.range_mm > 0 {
                expected_points += 1;
                assert_eq!(frame.xyz[i0], dec.xyz(u, c, px.range_mm).unwrap(), "{what}");
            }
            if dual {
                let i1 = frame.index(1, u, c).unwrap();
                let want1 = (px.range2_mm, px.reflectivity2, px.signal2, px.flags2);
                let got1 = (
                    frame.range_mm[i1],
                    frame.reflectivity[i1],
                    frame.signal[i1],
                    frame.flags[i1],
                );
                assert_eq!(got1, if ok { want1 } else { zero }, "{what} ({u}, {c})");
                if ok && px.range2_mm > 0 {
                    expected_points += 1;
                }
            } else {
                assert!(frame.index(1, u, c).is_none());
            }
            // Fields the profile lacks come back as 0.
            if l.signal.is_none() {
                assert_eq!(px.signal, 0);
            }
        }
    }
    assert_eq!(emitted.len(), expected_points, "{what}");
    assert_eq!(
        frame.points(0) + if dual { frame.points(1) } else { 0 },
        expected_points,
        "{what}"
    );

    // The point stream agrees with the frame and the input.
    let rings = dec.rings();
    let mut last = (0usize, 0usize, 0u8);
    for (k, (pt, x, row, col)) in emitted.iter().enumerate() {
        let px = &columns[*col].pixels[*row];
        let i = frame.index(usize::from(pt.ret), *row, *col).unwrap();
        let want = if pt.ret == 0 {
            Extra {
                range_mm: px.range_mm,
                signal: px.signal,
                near_ir: px.near_ir,
                reflectivity: px.reflectivity,
                flags: px.flags,
                // The encoder writes no zone mask or colour.
                ..Extra::default()
            }
        } else {
            Extra {
                range_mm: px.range2_mm,
                signal: px.signal2,
                near_ir: px.near_ir,
                reflectivity: px.reflectivity2,
                flags: px.flags2,
                ..Extra::default()
            }
        };
        assert_eq!(*x, want, "{what}");
        assert_eq!([pt.x, pt.y, pt.z], frame.xyz[i], "{what}");
        assert_eq!(pt.intensity, f32::from(want.reflectivity), "{what}");
        assert_eq!(pt.ring, rings[*row], "{what}");
        let t = columns[*col].timestamp_ns.saturating_sub(sweep_start);
        assert_eq!(u64::from(pt.t), t, "{what}");
        // Order: column, row, return.
        if k > 0 {
            assert!((*col, *row, pt.ret) > last, "{what}: order");
        }
        last = (*col, *row, pt.ret);
    }
    tally.points += emitted.len();
    tally.cases += 1;
}

fn fid_of(h: &SimHeader, kind: HeaderKind) -> u32 {
    if kind == HeaderKind::Fusa {
        h.frame_id
    } else {
        h.frame_id & 0xFFFF
    }
}

#[test]
fn every_profile_header_and_height_round_trips() {
    let mut tally = Tally::default();
    for profile in ALL_PROFILES {
        for h in [16, 32, 64, 128] {
            for kind in header_kinds(profile) {
                round_trip(profile, h, kind, &mut tally);
            }
        }
    }
    println!(
        "round trips: {} cases, {} packets, {} points",
        tally.cases, tally.packets, tally.points
    );
    assert_eq!(tally.cases, 4 * (1 + (ALL_PROFILES.len() - 1) * 2));
}

#[test]
fn rings_are_the_altitude_ranks() {
    let info = synthetic_info(Profile::Rng19Rfl8Sig16Nir16, 16);
    let dec = OusterDecoder::new(&info).unwrap();
    let rings = dec.rings();
    // Row 0 and row 1 share the top altitude: row 1 (lower in the image) gets the lower ring.
    assert_eq!(rings[0], 15);
    assert_eq!(rings[1], 14);
    assert_eq!(rings[15], 0);
    let mut sorted = rings.to_vec();
    sorted.sort_unstable();
    assert_eq!(sorted, (0..16).collect::<Vec<u16>>());
}

#[test]
fn rng15_ranges_are_8_mm_steps_and_nir8_is_times_16() {
    let info = synthetic_info(Profile::Rng15Rfl8Nir8, 16);
    let dec = OusterDecoder::new(&info).unwrap();
    let enc = OusterEncoder::new(&info);
    let mut cols: Vec<SimColumn> = (0..CPP)
        .map(|c| SimColumn {
            timestamp_ns: 1,
            measurement_id: c as u16,
            status: 1,
            pixels: vec![SimPixel::default(); 16],
        })
        .collect();
    cols[0].pixels[0].range_mm = 12_345; // → 12_344
    cols[0].pixels[1].range_mm = (1 << 18) - 1; // 2^15 − 1 steps of 8 mm → 262_136
    cols[0].pixels[2].near_ir = 4_095; // → 4_080 (255 × 16)
    let mut b = Vec::new();
    enc.encode(
        &SimHeader {
            init_id: info.init_id,
            serial: info.serial,
            ..SimHeader::default()
        },
        &cols,
        &mut b,
    )
    .unwrap();
    let p = dec.packet(&b).unwrap();
    let mut frame = dec.new_frame();
    dec.decode_packet_into_frame(&p, &mut frame).unwrap();
    assert_eq!(frame.range_mm[0], 12_344);
    assert_eq!(frame.range_mm[W], 262_136);
    assert_eq!(frame.near_ir[2 * W], 4_080);
}

#[test]
fn rng19_range_limit_is_2_pow_19_minus_1() {
    let info = synthetic_info(Profile::Rng19Rfl8Sig16Nir16Dual, 32);
    let dec = OusterDecoder::new(&info).unwrap();
    let enc = OusterEncoder::new(&info);
    let mut cols: Vec<SimColumn> = (0..CPP)
        .map(|c| SimColumn {
            timestamp_ns: 5,
            measurement_id: (W - CPP + c) as u16,
            status: 1,
            pixels: vec![SimPixel::default(); 32],
        })
        .collect();
    cols[15].pixels[31].range_mm = (1 << 19) - 1;
    cols[15].pixels[31].range2_mm = (1 << 19) - 1;
    cols[15].pixels[31].signal2 = u16::MAX;
    let mut b = Vec::new();
    enc.encode(
        &SimHeader {
            init_id: info.init_id,
            serial: info.serial,
            ..SimHeader::default()
        },
        &cols,
        &mut b,
    )
    .unwrap();
    let p = dec.packet(&b).unwrap();
    let mut got = Vec::new();
    dec.decode_with(&p, 0, |pt, x, row, col| got.push((pt.ret, x, row, col)))
        .unwrap();
    assert_eq!(got.len(), 2);
    assert_eq!(got[0].1.range_mm, 524_287);
    assert_eq!(got[1].1.range_mm, 524_287);
    assert_eq!(got[1].1.signal, u16::MAX);
    assert_eq!((got[0].2, got[0].3), (31, W - 1));
}

#[test]
fn crc_sensor_and_frame_checks() {
    let info = synthetic_info(Profile::Rng19Rfl8Sig16Nir16, 64);
    let dec = OusterDecoder::new(&info).unwrap();
    assert!(dec.crc_check(), "FW 2.5.2 standard header: CRC checked");
    let enc = OusterEncoder::new(&info);
    let cols: Vec<SimColumn> = (0..CPP)
        .map(|c| SimColumn {
            timestamp_ns: 7,
            measurement_id: c as u16,
            status: 1,
            pixels: vec![
                SimPixel {
                    range_mm: 1000,
                    ..SimPixel::default()
                };
                64
            ],
        })
        .collect();
    let hdr = SimHeader {
        frame_id: 10,
        init_id: info.init_id,
        serial: info.serial,
        ..SimHeader::default()
    };
    let mut b = Vec::new();
    enc.encode(&hdr, &cols, &mut b).unwrap();
    assert!(dec.packet(&b).is_ok());

    // One flipped bit: the CRC catches it (and only when checking).
    let mut bad = b.clone();
    bad[100] ^= 0x04;
    assert!(matches!(
        dec.packet(&bad),
        Err(DecodeError::Wire(WireError::Crc { .. }))
    ));
    assert!(dec.clone().with_crc_check(false).packet(&bad).is_ok());
    assert_eq!(
        LidarPacket::new(&bad, &info.format).unwrap().crc_ok(),
        Some(false)
    );

    // Another sensor's packet (serial differs): refused; serial 0 in the packet passes.
    for (serial, ok) in [(info.serial + 1, false), (0, true)] {
        let mut other = Vec::new();
        enc.encode(&SimHeader { serial, ..hdr }, &cols, &mut other)
            .unwrap();
        assert_eq!(dec.packet(&other).is_ok(), ok, "serial {serial}");
    }

    // A packet of another frame is refused by a frame being filled.
    let mut frame = dec.new_frame();
    dec.decode_packet_into_frame(&dec.packet(&b).unwrap(), &mut frame)
        .unwrap();
    let mut next = Vec::new();
    enc.encode(
        &SimHeader {
            frame_id: 11,
            ..hdr
        },
        &cols,
        &mut next,
    )
    .unwrap();
    assert_eq!(
        dec.decode_packet_into_frame(&dec.packet(&next).unwrap(), &mut frame),
        Err(DecodeError::FrameId {
            expected: 10,
            found: 11
        })
    );
    frame.clear();
    assert!(dec
        .decode_packet_into_frame(&dec.packet(&next).unwrap(), &mut frame)
        .is_ok());
    assert_eq!(frame.frame_id, Some(11));

    // A packet of another format is refused by the decoder.
    let legacy = PacketFormat {
        profile: Profile::Legacy,
        columns_per_packet: CPP,
        pixels_per_column: 64,
    };
    let lb = vec![0u8; legacy.packet_bytes()];
    let lp = LidarPacket::new(&lb, &legacy).unwrap();
    assert!(matches!(
        dec.decode_with(&lp, 0, |_, _, _, _| {}),
        Err(DecodeError::Format { .. })
    ));
    // Wrong lengths never get a view.
    assert!(dec.packet(&b[..b.len() - 1]).is_err());
}

#[test]
fn random_bytes_never_panic() {
    // Any bytes of the right length: a view, the sensor and CRC checks, both decode paths;
    // errors are fine, panics are not. Measurement ids ≥ W and all-ones statuses included.
    let mut rng = Rng(0xDEAD_BEEF_CAFE_F00D);
    for profile in ALL_PROFILES {
        for h in [16, 128] {
            let info = synthetic_info(profile, h);
            let dec = OusterDecoder::new(&info).unwrap().with_crc_check(false);
            let mut frame = dec.new_frame();
            for _ in 0..20 {
                let b: Vec<u8> = (0..info.format.packet_bytes())
                    .map(|_| rng.next() as u8)
                    .collect();
                let p = LidarPacket::new(&b, &info.format).unwrap();
                let _ = dec.check_sensor(&p);
                let _ = p.crc_ok();
                let mut n = 0;
                dec.decode_with(&p, rng.next(), |_, _, row, col| {
                    assert!(row < h && col < W);
                    n += 1;
                })
                .unwrap();
                frame.clear();
                let d = dec.decode_packet_into_frame(&p, &mut frame).unwrap();
                assert_eq!(d.points, n);
                assert!(n <= CPP * h * 2);
            }
        }
    }
}
