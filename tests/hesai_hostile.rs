//! Hostile Hesai packets and correction files: each gives a clear error or a counted drop, never
//! a panic. Besides the hand-made cases, every real Hesai packet and correction file of
//! `../shared/captures` is run, as is and after deterministic random mutations, through the
//! very harnesses of the `hesai_packet` and `calib_hesai` fuzz targets (`tools/fuzz/harness.rs`):
//! a short, repeatable fuzz pass inside the test suite (the long runs: tools/fuzz/smoke.sh).
#![cfg(all(feature = "pcap", feature = "mcap", feature = "sim"))]

mod common;
#[path = "../tools/fuzz/harness.rs"]
mod harness;

use ringscan::sensor::hesai::family::parse_hesai_calibration;
use ringscan::sensor::hesai::wire::crc32_mpeg2;
use ringscan::sensor::hesai::{HesaiConfig, HesaiModel, HesaiStream};
use ringscan::sensor::parse_calibration;

const GT: &str = "tier4__nebula/src/nebula_hesai/nebula_hesai/test_resources/decoder_ground_truth";
const CALIB: &str = "tier4__nebula/src/nebula_hesai/nebula_hesai_decoders/calibration";

/// xorshift64*: a fixed, dependency-free random sequence.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

fn mutate(rng: &mut Rng, data: &[u8]) -> Vec<u8> {
    let mut v = data.to_vec();
    match rng.below(4) {
        0 => {
            for _ in 0..1 + rng.below(8) {
                let i = rng.below(v.len());
                if let Some(b) = v.get_mut(i) {
                    *b = rng.next() as u8;
                }
            }
        }
        1 => v.truncate(rng.below(v.len() + 1)),
        2 => {
            let extra = rng.below(40);
            v.extend((0..extra).map(|_| rng.next() as u8));
        }
        _ => {
            // Header / tail fields that steer the decoder.
            for i in [0usize, 1, 2, 3, 6, 7, 9, 10, 11] {
                if rng.below(3) == 0 {
                    if let Some(b) = v.get_mut(i) {
                        *b = rng.next() as u8;
                    }
                }
            }
            let n = v.len();
            for back in 1..40 {
                if rng.below(10) == 0 && back < n {
                    v[n - back] = rng.next() as u8;
                }
            }
        }
    }
    v
}

fn stream_for(model: HesaiModel) -> HesaiStream {
    let mut cfg = HesaiConfig::new(Some(harness::hesai_correction(model)), "test");
    cfg.model = Some(model);
    HesaiStream::new(cfg)
}

fn xt32_packet() -> Vec<u8> {
    // A well-formed XT32 packet: header, 8 blocks, tail in dual (last, strongest) mode.
    let model = HesaiModel::PandarXt32;
    let l = &model.spec().layout;
    let mut b = vec![0u8; l.base_len()];
    b[..12].copy_from_slice(&[0xEE, 0xFF, 6, 1, 0, 0, 32, 8, 0, 4, 2, 1]);
    for blk in 0..8 {
        let o = 12 + blk * l.block_len();
        b[o..o + 2].copy_from_slice(&((blk as u16 / 2) * 18).to_le_bytes());
        for c in 0..32 {
            let u = o + 2 + 4 * c;
            b[u..u + 2].copy_from_slice(&(1000 + c as u16).to_le_bytes());
            b[u + 2] = 50;
        }
    }
    let t = l.tail_start();
    b[t + 10] = 0x39;
    b[t + 13..t + 19].copy_from_slice(&[124, 1, 2, 3, 4, 5]);
    b
}

/// A well-formed Pandar ATX packet written here (HesaiLidar_SDK_2.0 `udp_protocol_v4_7.h`):
/// pre-header 4.7, `lasers` × 2 blocks (azimuth u16 in 1/256°, fine byte, 4-byte units), body
/// CRC, 32-byte tail (frame id at 10, return mode at 24, UTC at 26), UDP sequence (flag bit 0),
/// 12-byte E2E header.
fn atx_packet(lasers: u8) -> Vec<u8> {
    let n = usize::from(lasers);
    let mut b = vec![0xEE, 0xFF, 4, 7, 0, 0, lasers, 2, 1, 4, 1, 0b0000_0001];
    for blk in 0..2u16 {
        b.extend_from_slice(&((60 + blk) * 256).to_le_bytes());
        b.push(0);
        for c in 0..n {
            b.extend_from_slice(&(2_000 + c as u16).to_le_bytes());
            b.extend_from_slice(&[40, 1]);
        }
    }
    b.extend_from_slice(&[0xC0; 4]);
    let mut tail = [0u8; 32];
    tail[24] = 0x37;
    tail[26..32].copy_from_slice(&[124, 1, 2, 3, 4, 5]);
    b.extend_from_slice(&tail);
    b.extend_from_slice(&7u32.to_le_bytes());
    b.extend_from_slice(&[0; 12]);
    b
}

/// The ATX's layout comes from its header: a header whose counts, flags or protocol do not
/// fit the datagram, or a laser count its correction does not have, is counted, not decoded.
#[test]
fn atx_packets_whose_header_lies_are_counted_not_decoded() {
    let good = atx_packet(100);
    let mut s = stream_for(HesaiModel::PandarAtx);
    let mut points = 0;
    let mut on = |sw: &mut ringscan::sweep::Sweep, _: &_| points += sw.points.len();
    s.push(0, &good, &mut on).unwrap();
    assert_eq!(s.stats().packets, 1);
    let with = |i: usize, v: u8| {
        let mut b = good.clone();
        b[i] = v;
        b
    };
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("one byte short", good[..good.len() - 1].to_vec()),
        ("one byte more", [good.clone(), vec![0]].concat()),
        ("no tail", good[..12 + 2 * 403].to_vec()),
        ("99 lasers in the header", with(6, 99)),
        ("no laser", with(6, 0)),
        ("no block", with(7, 0)),
        ("255 blocks", with(7, 255)),
        ("signature flag, no signature", with(11, 0b1001)),
        ("sequence flag off, sequence sent", with(11, 0)),
        ("protocol 4.8", with(3, 8)),
        (
            "a well-formed packet of 99 lasers for a 100-channel correction",
            with_seq(atx_packet(99), 8),
        ),
        ("return mode 0x42", {
            let mut b = good.clone();
            b[12 + 2 * 403 + 4 + 24] = 0x42;
            b
        }),
        ("empty", Vec::new()),
    ];
    for (i, (what, c)) in cases.iter().enumerate() {
        s.push(1_000 * (i as i64 + 1), c, &mut on).unwrap();
        assert_eq!(s.stats().malformed, i as u64 + 1, "{what}");
    }
    assert_eq!(s.stats().packets, 1);
    // The next good packet (sequence number 9; 7 again would be a copy). The 99-laser packet
    // parsed whole under its own header: its number 8 came, so nothing is missing.
    s.push(100_000, &with_seq(good.clone(), 9), &mut on)
        .unwrap();
    s.finish(&mut on);
    assert_eq!(s.stats().packets, 2);
    assert_eq!(s.stats().missing, 0);
    assert_eq!(points, 400, "two good packets of 200 returns");
}

/// An ATX packet of [`atx_packet`] with UDP sequence number `seq` (after the 32-byte tail).
fn with_seq(mut b: Vec<u8>, seq: u32) -> Vec<u8> {
    let n = b.len();
    b[n - 16..n - 12].copy_from_slice(&seq.to_le_bytes());
    b
}

#[test]
fn short_long_and_marked_wrong_packets_are_counted_not_decoded() {
    let good = xt32_packet();
    let mut s = stream_for(HesaiModel::PandarXt32);
    let mut points = 0;
    let mut on = |sw: &mut ringscan::sweep::Sweep, _: &_| points += sw.points.len();
    s.push(0, &good, &mut on).unwrap();
    assert_eq!(s.stats().packets, 1);
    let cases: Vec<Vec<u8>> = vec![
        good[..good.len() - 1].to_vec(),
        [good.clone(), vec![0; 3]].concat(),
        Vec::new(),
        {
            let mut b = good.clone();
            b[6] = 16; // lasers in the header: not the XT32's 32
            b
        },
        {
            let mut b = good.clone();
            b[0] = 0xFF; // pre-header mark
            b
        },
        {
            let mut b = good.clone();
            let t = HesaiModel::PandarXt32.spec().layout.tail_start();
            b[t + 10] = 0x42; // return mode no Hesai sensor sends
            b
        },
    ];
    for (i, c) in cases.iter().enumerate() {
        s.push(1_000 * (i as i64 + 1), c, &mut on).unwrap();
        assert_eq!(s.stats().malformed, i as u64 + 1, "case {i}");
    }
    assert_eq!(s.stats().packets, 1);
}

#[test]
fn crc_failures_are_dropped_and_counted() {
    let model = HesaiModel::PandarQt128;
    let (b, t) = qt128_with_crcs(0);
    let mut s = stream_for(model);
    let mut on = |_: &mut ringscan::sweep::Sweep, _: &_| {};
    s.push(0, &b, &mut on).unwrap();
    assert_eq!((s.stats().crc_ok, s.stats().crc_failures), (1, 0));
    let mut bad_body = b.clone();
    bad_body[20] ^= 1;
    s.push(1, &bad_body, &mut on).unwrap();
    let mut bad_tail = b.clone();
    bad_tail[t + 25] ^= 0x80;
    s.push(2, &bad_tail, &mut on).unwrap();
    assert_eq!(s.stats().crc_failures, 2);
    assert_eq!(s.stats().crc_tail_failures, 1);
    assert_eq!(s.stats().malformed, 2);
    assert_eq!(s.stats().packets, 1);
    // With the signature appended: still one packet, and counted as signed (on a stream of
    // its own: the same sequence number again would be a copy).
    let signed = [b.clone(), vec![0xAB; 32]].concat();
    let mut s = stream_for(model);
    s.push(3, &signed, &mut on).unwrap();
    assert_eq!(s.stats().signed, 1);
    assert_eq!(s.stats().packets, 1);
}

/// Packets 1, 2, 3 with packet 2 corrupt. Its body alone failing: the tail CRC vouches for its
/// sequence number, so it is malformed and not also missing (it was both). Its tail failing:
/// its number is taken only where it is the very next one (2 after 1); a number the corruption
/// changed (3) says nothing of which packet it was, and the gap it leaves is counted missing
/// too. A return mode no sensor sends under good CRCs: malformed, its number taken (it was
/// counted missing as well).
#[test]
fn a_corrupt_body_under_a_good_tail_is_not_also_missing() {
    let model = HesaiModel::PandarQt128;
    for (corrupt, missing) in [
        ("body", 0),
        ("tail", 0),
        ("tail's number", 1),
        ("return mode", 0),
    ] {
        let mut s = stream_for(model);
        let mut on = |_: &mut ringscan::sweep::Sweep, _: &_| {};
        for seq in 1..=3u32 {
            let (mut b, t) = qt128_with_crcs(seq);
            // 0.1 ms apart (µs field of the tail's date + time).
            b[t + 21..t + 25].copy_from_slice(&(seq * 100).to_le_bytes());
            let tail = crc32_mpeg2(&b[t..t + 30]);
            b[t + 30..t + 34].copy_from_slice(&tail.to_le_bytes());
            if seq == 2 {
                match corrupt {
                    "body" => b[20] ^= 1,
                    "tail" => b[t + 12] ^= 1,
                    "tail's number" => b[t + 26] ^= 1,
                    _ => {
                        b[t + 12] = 0x42;
                        let tail = crc32_mpeg2(&b[t..t + 30]);
                        b[t + 30..t + 34].copy_from_slice(&tail.to_le_bytes());
                    }
                }
            }
            s.push(i64::from(seq) * 100_000, &b, &mut on).unwrap();
        }
        let st = s.stats();
        let crc_failures = u64::from(corrupt != "return mode");
        assert_eq!(
            (st.packets, st.crc_failures, st.malformed),
            (2, crc_failures, 1),
            "{corrupt}"
        );
        assert_eq!(st.missing, missing, "{corrupt}");
    }
}

/// A packet of an unknown return mode (malformed, good CRCs) whose number is far behind the
/// latest does not restart the count: the next good packet counts no loss. It restarted the
/// window at its number, and the next packet counted the 500 numbers back to it as missing.
#[test]
fn a_malformed_packet_far_behind_does_not_restart_the_count() {
    let mut s = stream_for(HesaiModel::PandarQt128);
    let mut on = |_: &mut ringscan::sweep::Sweep, _: &_| {};
    for (k, seq) in [1000u32, 1001, 500, 1002].into_iter().enumerate() {
        let (mut b, t) = qt128_with_crcs(seq);
        b[t + 21..t + 25].copy_from_slice(&(k as u32 * 100).to_le_bytes());
        if seq == 500 {
            b[t + 12] = 0x42;
        }
        let tail = crc32_mpeg2(&b[t..t + 30]);
        b[t + 30..t + 34].copy_from_slice(&tail.to_le_bytes());
        s.push(k as i64 * 100_000, &b, &mut on).unwrap();
    }
    let st = s.stats();
    assert_eq!((st.packets, st.malformed, st.missing), (3, 1, 0), "{st:?}");
}

/// A QT128 packet (protocol 3.2) with UDP sequence number `seq` and both CRCs right; the
/// tail's start.
fn qt128_with_crcs(seq: u32) -> (Vec<u8>, usize) {
    let model = HesaiModel::PandarQt128;
    let l = &model.spec().layout;
    let mut b = vec![0u8; l.base_len()];
    b[..12].copy_from_slice(&[0xEE, 0xFF, 3, 2, 0, 0, 128, 2, 0, 4, 1, 0x05]);
    for blk in 0..2 {
        let o = 12 + blk * l.block_len();
        for c in 0..128 {
            let u = o + 2 + 4 * c;
            b[u..u + 2].copy_from_slice(&500u16.to_le_bytes());
        }
    }
    let t = l.tail_start();
    b[t + 12] = 0x37;
    b[t + 15..t + 21].copy_from_slice(&[124, 1, 2, 3, 4, 5]);
    let body = crc32_mpeg2(&b[l.body_start()..l.body_end()]);
    b[l.body_end()..l.body_end() + 4].copy_from_slice(&body.to_le_bytes());
    // The sequence number (tail offset 26, under the tail CRC).
    b[t + 26..t + 30].copy_from_slice(&seq.to_le_bytes());
    let tail = crc32_mpeg2(&b[t..t + 30]);
    b[t + 30..t + 34].copy_from_slice(&tail.to_le_bytes());
    (b, t)
}

#[test]
fn hesai_csv_goes_to_hesai_and_its_errors_say_what_is_wrong() {
    let mut csv = String::from("Laser id,Elevation,Azimuth\n");
    for i in 1..=32 {
        csv.push_str(&format!("{i},{},0.1\n", 15 - i));
    }
    let c = parse_calibration(csv.as_bytes(), "x.csv", None).unwrap();
    assert_eq!(c.family, "hesai");
    for (bad, word) in [
        (csv.replace("\n7,8,0.1", "\n7,NaN,0.1"), "Elevation"),
        (csv.replace("\n7,8,0.1", "\n7,8,1e9"), "Azimuth"),
        (csv.replace("\n7,8,0.1", "\n9,8,0.1"), "Laser id"),
        (csv.replace("\n32,-17,0.1\n", "\n"), "31 channels"),
        (csv.replace("\n7,8,0.1", "\n7,8"), "row"),
    ] {
        let e = parse_calibration(bad.as_bytes(), "x.csv", None).unwrap_err();
        assert!(e.to_string().contains(word), "{e}");
    }
    // A Velodyne yaml is still Velodyne's.
    let yaml =
        "lasers:\n- {laser_id: 0, rot_correction: 0.0, vert_correction: 0.1}\nnum_lasers: 1\n";
    match parse_calibration(yaml.as_bytes(), "v.yaml", None) {
        Ok(c) => assert_eq!(c.family, "velodyne"),
        Err(e) => assert!(!e.to_string().contains("Hesai"), "{e}"),
    }
    // AT128 .dat: truncated and wrong versions are refused with the reason.
    let e = parse_calibration(&[0xEE, 0xFF, 1, 5, 128, 3, 3, 0], "a.dat", None).unwrap_err();
    assert!(e.to_string().contains("AT128"), "{e}");
}

/// Packets of every model from the simulator (tail time `T0`).
fn sim_packets(model: HesaiModel, n: usize) -> Vec<Vec<u8>> {
    const T0: i64 = 1_714_564_800_000_000_000;
    let scene = ringscan::sim::scenes::named("urban").unwrap();
    let mut sim =
        ringscan::sensor::hesai::sim::HesaiSim::new(model, harness::hesai_correction(model), T0);
    (0..n)
        .map(|_| sim.next_packet(&scene, &mut Vec::new()).1)
        .collect()
}

/// A capture time at either end of `i64` (an MCAP log time of 2^64 − 1 read as i64::MAX, a
/// pcapng interface whose negative `if_tsoffset` saturates to i64::MIN): every model's stream
/// decodes on without overflowing its time arithmetic, and does not call such a host clock
/// synchronised with the tail's. (Debug builds check overflow: the old code panicked here.)
#[test]
fn host_times_at_the_ends_of_i64_do_not_overflow() {
    use ringscan::sensor::hesai::model::ALL_MODELS;
    for model in ALL_MODELS {
        let packets = sim_packets(model, 40);
        for host in [i64::MAX, i64::MIN, i64::MAX - 1_000] {
            let mut stream = stream_for(model);
            let mut points = 0usize;
            let mut on_sweep = |sw: &mut ringscan::sweep::Sweep, _: &_| points += sw.points.len();
            for p in &packets {
                stream.push(host, p, &mut on_sweep).unwrap();
            }
            stream.finish(&mut on_sweep);
            assert_eq!(stream.stats().packets, 40, "{model:?} at host time {host}");
            assert!(points > 0, "{model:?} at host time {host}");
            assert_eq!(
                stream.facts().clock_synchronised,
                Some(false),
                "{model:?} at host time {host}"
            );
        }
    }
}

/// `decode_packet` is public: times at the ends of `i64` saturate (a point's `t` then clamps)
/// instead of overflowing. (Debug builds check overflow: the old code panicked here.)
#[test]
fn decode_packet_times_at_the_ends_of_i64_do_not_overflow() {
    use ringscan::sensor::hesai::{HesaiDecoder, HesaiOptions, HesaiPacket};
    let model = HesaiModel::PandarXt32;
    let b = xt32_packet();
    let p = HesaiPacket::new(&b, model).unwrap();
    let mut dec = HesaiDecoder::new(
        model,
        &harness::hesai_correction(model),
        HesaiOptions::default(),
    )
    .unwrap();
    for (stamp, t0, t) in [(i64::MAX, i64::MIN, u32::MAX), (i64::MIN, i64::MAX, 0)] {
        let mut out = Vec::new();
        let n = dec.decode_packet(&p, stamp, t0, &mut out).unwrap();
        assert!(n > 0);
        assert!(out.iter().all(|pt| pt.t == t), "stamp {stamp}, t0 {t0}");
    }
}

/// A tail whose date is no date (a zero month or day): its time is the host's, which is no
/// evidence of a synchronised sensor clock, so the clock is reported free-running. Which byte
/// holds the date is found by trying every tail byte, not taken from the layout the decoder
/// uses.
#[test]
fn a_tail_without_a_valid_date_is_not_a_synchronised_clock() {
    use ringscan::sensor::hesai::model::ALL_MODELS;
    use ringscan::sensor::hesai::HesaiPacket;
    let mut tried = Vec::new();
    for model in ALL_MODELS {
        let packets = sim_packets(model, 2);
        let good = &packets[0];
        let Ok(p) = HesaiPacket::new(good, model) else {
            panic!("{model:?}: the simulator's packet is refused");
        };
        let host = p.stamp_ns().expect("the simulator writes a valid date");
        // The last 64 bytes hold every model's tail.
        let dateless = (good.len().saturating_sub(64)..good.len()).find_map(|i| {
            let mut b = good.clone();
            b[i] = 0;
            HesaiPacket::new(&b, model)
                .is_ok_and(|p| p.stamp_ns().is_none())
                .then_some(b)
        });
        let Some(bad) = dateless else {
            // AT128: its tail time is Unix seconds, valid whatever its bytes.
            continue;
        };
        let mut cfg = HesaiConfig::new(Some(harness::hesai_correction(model)), "test");
        cfg.model = Some(model);
        cfg.check_crc = false;
        let mut stream = HesaiStream::new(cfg);
        stream.push(host, &bad, &mut |_, _| {}).unwrap();
        assert_eq!(stream.stats().packets, 1, "{model:?}");
        assert_eq!(
            stream.facts().clock_synchronised,
            Some(false),
            "{model:?}: a dateless tail called synchronised"
        );
        tried.push(model);
    }
    assert!(tried.len() >= 8, "only {tried:?} have a date to break");
}

#[test]
fn real_packets_and_files_mutated_through_the_fuzz_harnesses() {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let mut runs = 0usize;
    // Always: the synthetic packets.
    let mut seeds: Vec<Vec<u8>> = vec![xt32_packet(), atx_packet(100), atx_packet(7)];
    // An ATX correction (version 4.3, 3 channels) written here.
    let mut atx_dat = vec![0xEE, 0xFF, 4, 3, 0, 0, 3, 0, 1];
    atx_dat.extend((0..9 + 70).flat_map(|i: i16| (i * 37 - 200).to_le_bytes()));
    atx_dat.extend_from_slice(&[0; 32]);
    assert!(parse_hesai_calibration(&atx_dat).is_some_and(|r| r.is_ok()));
    let mut files: Vec<Vec<u8>> = vec![atx_dat];
    if let Some(root) = common::captures() {
        for entry in walk(&root.join(GT)) {
            if entry.extension().is_some_and(|e| e == "pcap") {
                for (_, _, p) in common::datagrams(&entry).into_iter().take(3) {
                    seeds.push(p);
                }
            }
        }
        for entry in walk(&root.join(CALIB)) {
            let b = std::fs::read(&entry).unwrap();
            assert!(
                parse_hesai_calibration(&b).is_some_and(|r| r.is_ok()),
                "{} is not read as a Hesai correction",
                entry.display()
            );
            files.push(b);
        }
    }
    for seed in &seeds {
        for sel in 0..10u8 {
            harness::hesai_packet(&[&[sel][..], seed].concat());
            runs += 1;
        }
        for _ in 0..300 {
            let m = mutate(&mut rng, seed);
            let sel = rng.next() as u8;
            harness::hesai_packet(&[&[sel][..], &m].concat());
            runs += 1;
        }
    }
    for f in &files {
        harness::calib_hesai(f);
        for _ in 0..200 {
            harness::calib_hesai(&mutate(&mut rng, f));
            runs += 1;
        }
    }
    println!(
        "{runs} harness runs on {} packets and {} files",
        seeds.len(),
        files.len()
    );
}

fn walk(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    let Ok(rd) = std::fs::read_dir(dir) else {
        return out;
    };
    for e in rd.flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out.sort();
    out
}

/// The functional-safety block (17 bytes after the QT128's body CRC: version, state,
/// code counts, fault code u16, 8 reserved, CRC u32 LE "from the Lidar State field to the
/// Reserved field", QT128 manual) is believed only when its own CRC checks. The real QT128
/// capture: every block checks (1,800 packets) and says state 0, "Init" (bits 7–5), which is
/// not normal; a block changed to state 2 ("report fault") without its CRC is ignored and
/// counted, the points decode as before; the same change with the CRC recomputed (by the
/// bit-by-bit CRC above) is believed.
#[test]
fn functional_safety_blocks_are_believed_only_under_their_own_crc() {
    let Some(root) = common::captures() else {
        return;
    };
    let model = HesaiModel::PandarQt128;
    let pcap = root
        .join(GT)
        .join("qt128/1730273789074637152/1730273789074637152_0.pcap");
    let packets: Vec<(i64, Vec<u8>)> = common::datagrams(&pcap)
        .into_iter()
        .map(|(t, _, p)| (t, p))
        .filter(|(_, p)| p.len() == 1127)
        .collect();
    assert_eq!(packets.len(), 1800);
    // Header 12 + 2 blocks of (2 + 128 × 4) + body CRC 4.
    let fs = 12 + 2 * (2 + 128 * 4) + 4;
    let state = |p: &[u8]| p[fs + 1] >> 5;
    for (_, p) in &packets {
        let stored = u32::from_le_bytes(p[fs + 13..fs + 17].try_into().unwrap());
        assert_eq!(common::crc32_mpeg2_bitwise(&p[fs + 1..fs + 13]), stored);
    }
    let not_normal = packets.iter().filter(|(_, p)| state(p) != 1).count() as u64;
    assert_eq!(not_normal, 1800, "the capture's blocks all say Init");
    let run = |packets: &[(i64, Vec<u8>)]| {
        let mut s = stream_for(model);
        let mut points = Vec::new();
        let mut on = |sw: &mut ringscan::sweep::Sweep, _: &_| {
            points.extend(sw.points.iter().map(|p| (p.x, p.y, p.z, p.t)))
        };
        for (t, p) in packets {
            s.push(*t, p, &mut on).unwrap();
        }
        s.finish(&mut on);
        (s.stats().clone(), s.facts().safety, points)
    };
    let (st, safety, points) = run(&packets);
    assert_eq!(
        (st.safety_crc_failures, st.safety_not_normal),
        (0, not_normal),
        "{st:?}"
    );
    assert_eq!(safety.map(|s| s.lidar_state), Some(0));

    // Every tenth block says "report fault" (2), its CRC left as it was: 180 ignored.
    let fault = |p: &mut Vec<u8>| p[fs + 1] = (p[fs + 1] & 0x1F) | (2 << 5);
    let mut lying = packets.clone();
    for (_, p) in lying.iter_mut().step_by(10) {
        fault(p);
    }
    let (st2, safety2, points2) = run(&lying);
    assert_eq!(
        (st2.safety_crc_failures, st2.safety_not_normal),
        (180, not_normal - 180),
        "{st2:?}"
    );
    assert_eq!((st2.packets, st2.malformed), (st.packets, st.malformed));
    assert_eq!(safety2.map(|s| s.lidar_state), Some(0));
    assert_eq!(points2, points);

    // The same faults under a CRC that checks: believed, the last of them the last state.
    let mut faulted = lying;
    for (_, p) in faulted.iter_mut().step_by(10) {
        let crc = common::crc32_mpeg2_bitwise(&p[fs + 1..fs + 13]);
        p[fs + 13..fs + 17].copy_from_slice(&crc.to_le_bytes());
    }
    faulted.truncate(1791);
    let (st3, safety3, _) = run(&faulted);
    assert_eq!(
        (st3.safety_crc_failures, st3.safety_not_normal),
        (0, 1791),
        "{st3:?}"
    );
    assert_eq!(safety3.map(|s| s.lidar_state), Some(2));
}

/// The tail's µs field is the fraction of its date's second; one of a second or more is a
/// corrupt tail, no sensor time (it moved the packet by up to 71 minutes): the host's time
/// stands in and is no evidence of a synchronised clock. Which bytes hold the µs is found by
/// their value, not taken from the layout the decoder uses.
#[test]
fn a_tail_microsecond_field_of_a_second_or_more_is_no_sensor_time() {
    use ringscan::sensor::hesai::model::ALL_MODELS;
    use ringscan::sensor::hesai::HesaiPacket;
    let mut tried = Vec::new();
    for model in ALL_MODELS {
        let packets = sim_packets(model, 40);
        // The packet whose µs is largest: its four bytes are the least likely elsewhere.
        let (good, stamp, us) = packets
            .iter()
            .filter_map(|b| {
                let s = HesaiPacket::new(b, model).ok()?.stamp_ns()?;
                Some((b, s, (s.rem_euclid(1_000_000_000) / 1_000) as u32))
            })
            .max_by_key(|&(_, _, us)| us)
            .expect("the simulator writes valid times");
        assert!(us > 0x100, "{model:?}: µs {us}");
        let at: Vec<usize> = (good.len().saturating_sub(128)..good.len() - 3)
            .filter(|&i| good[i..i + 4] == us.to_le_bytes())
            .collect();
        let [i] = at[..] else {
            panic!("{model:?}: µs {us} found at {at:?}");
        };
        for bad_us in [1_000_000u32, u32::MAX] {
            let mut bad = good.clone();
            bad[i..i + 4].copy_from_slice(&bad_us.to_le_bytes());
            let p = HesaiPacket::new(&bad, model).unwrap();
            assert_eq!(p.stamp_ns(), None, "{model:?}: µs {bad_us}");
            let mut cfg = HesaiConfig::new(Some(harness::hesai_correction(model)), "test");
            cfg.model = Some(model);
            cfg.check_crc = false;
            let mut stream = HesaiStream::new(cfg);
            stream.push(stamp, &bad, &mut |_, _| {}).unwrap();
            assert_eq!(stream.stats().packets, 1, "{model:?}");
            assert_eq!(
                stream.facts().clock_synchronised,
                Some(false),
                "{model:?}: µs {bad_us} called a synchronised clock"
            );
        }
        tried.push(model);
    }
    assert_eq!(tried.len(), ALL_MODELS.len());
}
