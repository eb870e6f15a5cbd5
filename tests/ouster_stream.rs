//! The Ouster stream on encoded packets: every kind of bad packet is a counted drop (never a
//! panic), frames are cut on `frame_id` across its wrap, a late packet of the previous frame
//! is still taken (one-frame reorder window), older ones are counted, invalid columns are
//! counted as missing, an `init_id` change starts an epoch (a corrupt one is a CRC failure),
//! a frame counter that starts over restarts the stream (one stale packet far behind does
//! not, nor a long run of stale packets of frames emitted lately: they are late), frames lost whole are missing columns, a far-ahead packet costs no genuine frame, IMU packets come out in SI units,
//! the real zone-monitor packet's damaged copies are counted drops and its queue is bounded.
//! Expected numbers come from the packets the test builds, not from the decoder.

use ringscan::sensor::ouster::calib::parse;
use ringscan::sensor::ouster::calib::OusterInfo;
use ringscan::sensor::ouster::model::PacketFormat;
use ringscan::sensor::ouster::model::Profile;
use ringscan::sensor::ouster::sim::encode_imu_legacy;
use ringscan::sensor::ouster::sim::OusterEncoder;
use ringscan::sensor::ouster::sim::SimColumn;
use ringscan::sensor::ouster::sim::SimHeader;
use ringscan::sensor::ouster::sim::SimPixel;
use ringscan::sensor::ouster::sweep::MAX_ZONE_QUEUE;
use ringscan::sensor::ouster::sweep::RESTART_CONFIRM_PACKETS;
use ringscan::sensor::ouster::OusterStream;
use ringscan::sensor::ouster::OusterStreamConfig;
use ringscan::sensor::DecodeOptions;
use ringscan::sweep::Sweep;

const W: usize = 512;
const H: usize = 16;
const CPP: usize = 16;

fn info(profile: Profile) -> OusterInfo {
    let text = serde_json::json!({
        "beam_altitude_angles": (0..64).map(|u| 20.0 - 0.5 * f64::from(u)).collect::<Vec<_>>(),
        "beam_azimuth_angles": vec![0.0; 64],
        "lidar_mode": "512x10",
    })
    .to_string();
    let mut info = parse(&text, "t.json").unwrap();
    info.format = PacketFormat {
        profile,
        columns_per_packet: CPP,
        pixels_per_column: H,
    };
    info.beam_altitude_angles = (0..H).map(|u| 15.0 - 2.0 * u as f64).collect();
    info.beam_azimuth_angles = vec![0.0; H];
    info.pixel_shift_by_row = vec![0; H];
    info.serial = 992_210_000_957;
    info.init_id = 77;
    info.firmware = "v2.5.2".into();
    info.image_rev = "ousteros-image-prod-aries-v2.5.2+20230101000000".into();
    info
}

struct Gen {
    enc: OusterEncoder,
    serial: u64,
}

impl Gen {
    /// Packet `k` (0-based within its frame) of `frame`: columns 16k..16k+15, every pixel at
    /// 5 m (range 5000 mm), column timestamps 1 s + frame · 100 ms + column · 100 ms / W.
    fn packet(&self, frame: u32, k: usize, init_id: u32, invalid_cols: &[usize]) -> Vec<u8> {
        self.packet_at(1_000_000_000, frame, k, init_id, invalid_cols)
    }

    /// [`Self::packet`] with frame 0 at `base_ns` instead of 1 s (another boot of the sensor).
    fn packet_at(
        &self,
        base_ns: u64,
        frame: u32,
        k: usize,
        init_id: u32,
        invalid_cols: &[usize],
    ) -> Vec<u8> {
        let cols: Vec<SimColumn> = (0..CPP)
            .map(|i| {
                let m = k * CPP + i;
                SimColumn {
                    timestamp_ns: base_ns
                        + u64::from(frame) * 100_000_000
                        + (m as u64) * 100_000_000 / W as u64,
                    measurement_id: m as u16,
                    status: if invalid_cols.contains(&m) { 0 } else { 1 },
                    pixels: vec![
                        SimPixel {
                            range_mm: 5000,
                            reflectivity: 50,
                            signal: 9,
                            near_ir: 7,
                            ..SimPixel::default()
                        };
                        H
                    ],
                }
            })
            .collect();
        let h = SimHeader {
            packet_type: 1,
            frame_id: frame,
            init_id,
            serial: self.serial,
            ..SimHeader::default()
        };
        let mut out = Vec::new();
        self.enc.encode(&h, &cols, &mut out).unwrap();
        out
    }
}

fn stream(info: &OusterInfo) -> OusterStream {
    OusterStream::new(OusterStreamConfig {
        info: info.clone(),
        metadata_name: "t.json".into(),
        crc: None,
        decode: DecodeOptions::default(),
        keep_extras: false,
        keep_columns: false,
    })
    .unwrap()
}

fn run(s: &mut OusterStream, packets: &[Vec<u8>]) -> Vec<Sweep> {
    let mut out = Vec::new();
    for p in packets {
        s.push(0, p, &mut |sw, _| out.push(sw.clone()));
    }
    s.finish(&mut |sw, _| out.push(sw.clone()));
    out
}

const PER_FRAME: usize = W / CPP; // 32 packets

#[test]
fn frames_are_cut_on_frame_id_across_the_wrap() {
    let info = info(Profile::Rng19Rfl8Sig16Nir16);
    let g = Gen {
        enc: OusterEncoder::new(&info),
        serial: info.serial,
    };
    let mut packets = Vec::new();
    for frame in [65_534u32, 65_535, 0, 1] {
        for k in 0..PER_FRAME {
            packets.push(g.packet(frame, k, 77, &[]));
        }
    }
    let mut s = stream(&info);
    let sweeps = run(&mut s, &packets);
    assert_eq!(sweeps.len(), 4);
    assert_eq!(
        sweeps.iter().map(|s| s.frame_id).collect::<Vec<_>>(),
        [65_534, 65_535, 0, 1]
    );
    for sw in &sweeps {
        assert_eq!(sw.points.len(), W * H);
        assert_eq!(sw.missing_columns, 0);
        // t from the frame's first column: the last column is (W−1)/W · 100 ms later.
        assert_eq!(
            sw.span_ns(),
            ((W as u64 - 1) * 100_000_000 / W as u64) as u32
        );
    }
    assert_eq!(s.stats().late, 0);
}

#[test]
fn bad_packets_are_counted_drops() {
    let info = info(Profile::Rng19Rfl8Sig16Nir16); // FW 2.5.2: CRC checked
    let g = Gen {
        enc: OusterEncoder::new(&info),
        serial: info.serial,
    };
    let mut packets = Vec::new();
    for k in 0..PER_FRAME {
        let mut p = g.packet(10, k, 77, &[]);
        match k {
            3 => p.truncate(p.len() - 1), // wrong size: malformed
            5 => p[100] ^= 0x40,          // flipped bit: CRC failure
            7 => {
                p = Gen {
                    enc: OusterEncoder::new(&info),
                    serial: 1234,
                }
                .packet(10, k, 77, &[])
            } // other sensor
            _ => {}
        }
        packets.push(p);
    }
    packets.push(vec![0u8; 3]); // garbage
    let mut s = stream(&info);
    let sweeps = run(&mut s, &packets);
    let st = s.stats().clone();
    assert_eq!(st.malformed, 2, "{st:?}");
    assert_eq!(st.crc_failures, 1, "{st:?}");
    assert_eq!(st.wrong_sensor, 1, "{st:?}");
    assert_eq!(sweeps.len(), 1);
    // Three packets of 16 columns lost.
    assert_eq!(sweeps[0].missing_columns, 48);
    assert_eq!(sweeps[0].missing_packets, 3);
    assert_eq!(sweeps[0].points.len(), (W - 48) * H);
}

#[test]
fn invalid_columns_are_missing_and_give_no_points() {
    let info = info(Profile::Rng15Rfl8Nir8);
    let g = Gen {
        enc: OusterEncoder::new(&info),
        serial: info.serial,
    };
    let invalid = [0usize, 17, 18, 511];
    let packets: Vec<_> = (0..PER_FRAME)
        .map(|k| g.packet(3, k, 77, &invalid))
        .collect();
    let mut s = stream(&info);
    let sweeps = run(&mut s, &packets);
    assert_eq!(sweeps[0].missing_columns, invalid.len() as u64);
    assert_eq!(sweeps[0].points.len(), (W - invalid.len()) * H);
    // The sweep starts at column 1 (column 0 is invalid).
    assert_eq!(
        sweeps[0].device_time_ns,
        1_000_000_000 + 3 * 100_000_000 + 100_000_000 / W as i64
    );
}

#[test]
fn a_late_packet_of_the_previous_frame_is_kept_older_ones_are_counted() {
    let info = info(Profile::Rng19Rfl8Sig16Nir16Dual);
    let g = Gen {
        enc: OusterEncoder::new(&info),
        serial: info.serial,
    };
    let mut packets = Vec::new();
    for k in 0..PER_FRAME {
        if k != 4 {
            packets.push(g.packet(20, k, 77, &[]));
        }
    }
    for k in 0..PER_FRAME {
        packets.push(g.packet(21, k, 77, &[]));
        if k == 2 {
            packets.push(g.packet(20, 4, 77, &[])); // late by two packets: within the window
        }
    }
    packets.push(g.packet(22, 0, 77, &[]));
    packets.push(g.packet(20, 9, 77, &[])); // frame 20 is closed by now: late
    let mut s = stream(&info);
    let sweeps = run(&mut s, &packets);
    assert_eq!(
        sweeps.iter().map(|s| s.frame_id).collect::<Vec<_>>(),
        [20, 21, 22]
    );
    assert_eq!(
        sweeps[0].missing_columns, 0,
        "the late packet completed frame 20"
    );
    assert_eq!(sweeps[0].points.len(), W * H); // second returns absent (range 0): one point per pixel
    assert_eq!(s.stats().late, 1);
}

#[test]
fn an_init_id_change_is_a_new_epoch_not_a_dropped_sensor() {
    let info = info(Profile::Rng19Rfl8Sig16Nir16);
    let g = Gen {
        enc: OusterEncoder::new(&info),
        serial: info.serial,
    };
    let mut packets: Vec<_> = (0..PER_FRAME).map(|k| g.packet(1, k, 77, &[])).collect();
    packets.extend((0..PER_FRAME).map(|k| g.packet(0, k, 78, &[])));
    let mut s = stream(&info);
    let sweeps = run(&mut s, &packets);
    assert_eq!(s.stats().epochs, 1);
    assert_eq!(s.stats().wrong_sensor, 0);
    assert_eq!(sweeps.len(), 2);
    assert!(sweeps.iter().all(|s| s.points.len() == W * H));
    assert_eq!(s.facts().init_id, 78);
}

#[test]
fn legacy_imu_packets_come_out_in_si_units() {
    let info = info(Profile::Rng19Rfl8Sig16Nir16);
    let mut s = stream(&info);
    let imu = encode_imu_legacy(5, 6, 7, [0.0, 0.0, 1.0], [90.0, 0.0, -180.0]);
    s.push(0, &imu, &mut |_, _| {});
    let samples: Vec<_> = s.drain_imu().collect();
    assert_eq!(samples.len(), 1);
    assert_eq!(samples[0].sensor_ns, 6);
    assert!((samples[0].accel[2] - 9.80665).abs() < 1e-9);
    assert!((samples[0].gyro[0] - std::f64::consts::FRAC_PI_2).abs() < 1e-6);
    assert!((samples[0].gyro[2] + std::f64::consts::PI).abs() < 1e-6);
    assert_eq!(s.stats().imu_packets, 1);
}

/// `--fields all` on real data: with extras kept, the sums of range, signal and near-IR over
/// the points of the dual-return OS-0-32 capture equal ouster-sdk's golden sums (range and
/// signal of both returns; near-IR is per pixel, so the golden's first-return sum counts it
/// once per first-return point and the second-return points repeat their pixel's value).
#[test]
fn extras_of_a_real_capture_sum_to_the_goldens() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/captures");
    if !root.join("golden").is_dir() {
        eprintln!("SKIP: {} is absent", root.display());
        return;
    }
    let dir = root.join("ouster-lidar__ouster-sdk/tests/pcaps");
    let meta = std::fs::read_to_string(dir.join("OS-0-32-U1_v2.2.0_1024x10.json")).unwrap();
    let info = parse(&meta, "OS-0-32-U1_v2.2.0_1024x10.json").unwrap();
    let mut s = OusterStream::new(OusterStreamConfig {
        info,
        metadata_name: "m".into(),
        crc: None,
        decode: DecodeOptions::default(),
        keep_extras: true,
        keep_columns: false,
    })
    .unwrap();
    let mut src =
        ringscan::source::pcap::PcapSource::open(&dir.join("OS-0-32-U1_v2.2.0_1024x10.pcap"))
            .unwrap();
    let mut sweeps = Vec::new();
    while let Some(d) = src.next_datagram().unwrap() {
        s.push(d.time_ns, d.payload, &mut |sw, _| sweeps.push(sw.clone()));
    }
    s.finish(&mut |sw, _| sweeps.push(sw.clone()));
    assert_eq!(sweeps.len(), 1);
    let sw = &sweeps[0];
    assert_eq!(sw.extras.len(), sw.points.len());
    let golden: serde_json::Value = serde_json::from_slice(
        &std::fs::read(root.join(
            "golden/ouster-lidar__ouster-sdk/tests/pcaps/OS-0-32-U1_v2.2.0_1024x10.golden.json",
        ))
        .unwrap(),
    )
    .unwrap();
    let r = &golden["sensors"][0]["frames"][0]["returns"];
    let g = |i: usize, k: &str| r[i]["sum"][k].as_f64().unwrap() as u64;
    let sum = |ret: u8, f: &dyn Fn(&ringscan::point::PointExtra) -> u64| -> u64 {
        sw.points
            .iter()
            .zip(&sw.extras)
            .filter(|(p, _)| p.ret == ret)
            .map(|(_, e)| f(e))
            .sum()
    };
    assert_eq!(sum(0, &|e| u64::from(e.range_mm)), g(0, "range_mm"));
    assert_eq!(sum(1, &|e| u64::from(e.range_mm)), g(1, "range2_mm"));
    assert_eq!(sum(0, &|e| u64::from(e.signal)), g(0, "signal"));
    assert_eq!(sum(1, &|e| u64::from(e.signal)), g(1, "signal2"));
    assert_eq!(sum(0, &|e| u64::from(e.near_ir)), g(0, "nir"));
}

/// The real zone-monitor packet (FW 3.2, `imu_zm_no_lidar.pcap`) and its metadata, if present.
fn real_zone_packet() -> Option<(OusterInfo, Vec<u8>)> {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/captures");
    if !root.join("golden").is_dir() {
        eprintln!("SKIP: {} is absent", root.display());
        return None;
    }
    let dir = root.join("ouster-lidar__ouster-sdk/tests/pcaps");
    let meta = std::fs::read_to_string(dir.join("imu_zm_no_lidar_0.json")).unwrap();
    let info = parse(&meta, "imu_zm_no_lidar_0.json").unwrap();
    let mut src =
        ringscan::source::pcap::PcapSource::open(&dir.join("imu_zm_no_lidar.pcap")).unwrap();
    let mut zm = None;
    while let Some(d) = src.next_datagram().unwrap() {
        if d.dst.port() == 7514 {
            zm = Some(d.payload.to_vec());
        }
    }
    Some((info, zm.expect("the capture's zone-monitor packet")))
}

#[test]
fn zone_monitor_packets_are_checked_and_bad_ones_counted() {
    let Some((info, zm)) = real_zone_packet() else {
        return;
    };
    assert_eq!(info.udp_port_zm, 7514);
    let zones = |s: &mut OusterStream| s.drain_zones().collect::<Vec<_>>();

    // The real packet: its footer CRC-64 checks (FW 3.2), one report.
    let mut s = stream(&info);
    run(&mut s, std::slice::from_ref(&zm));
    let got = zones(&mut s);
    assert_eq!(got.len(), 1);
    assert_eq!((got[0].frame_id, got[0].host_ns), (30_002, 0));
    assert_eq!(got[0].zones.iter().filter(|z| z.live).count(), 4);
    assert_eq!((s.stats().zone_packets, s.stats().malformed), (1, 0));
    assert_eq!(s.stats().crc_failures, 0);

    // One bit flipped in a zone record: a CRC failure, no report.
    let mut bad = zm.clone();
    bad[100] ^= 0x10;
    let mut s = stream(&info);
    run(&mut s, &[bad.clone()]);
    assert!(zones(&mut s).is_empty());
    assert_eq!((s.stats().zone_packets, s.stats().crc_failures), (0, 1));
    // … taken as it is with the CRC check forced off.
    let mut s = OusterStream::new(OusterStreamConfig {
        info: info.clone(),
        metadata_name: "m".into(),
        crc: Some(false),
        decode: DecodeOptions::default(),
        keep_extras: false,
        keep_columns: false,
    })
    .unwrap();
    run(&mut s, &[bad]);
    assert_eq!(zones(&mut s).len(), 1);

    // Cut short, one byte long, another packet type, another sensor's serial.
    let mut s = stream(&info);
    let mut other_type = zm.clone();
    other_type[0] = 1;
    let mut other_sensor = zm.clone();
    other_sensor[7] ^= 1;
    let mut long = zm.clone();
    long.push(0);
    run(
        &mut s,
        &[zm[..679].to_vec(), long, other_type, other_sensor],
    );
    assert!(zones(&mut s).is_empty());
    assert_eq!(s.stats().malformed, 3);
    assert_eq!(s.stats().wrong_sensor, 1);

    // A consumer that never drains: the queue stays bounded, the rest counted.
    let mut s = stream(&info);
    let flood = vec![zm; MAX_ZONE_QUEUE + 44];
    run(&mut s, &flood);
    assert_eq!(s.stats().zone_packets, (MAX_ZONE_QUEUE + 44) as u64);
    assert_eq!(s.stats().zone_dropped, 44);
    assert_eq!(zones(&mut s).len(), MAX_ZONE_QUEUE);
}

/// Pushes `packets` with host times `host[i]`, then finishes.
fn run_at(s: &mut OusterStream, packets: &[(i64, Vec<u8>)]) -> Vec<Sweep> {
    let mut out = Vec::new();
    for (host, p) in packets {
        s.push(*host, p, &mut |sw, _| out.push(sw.clone()));
    }
    s.finish(&mut |sw, _| out.push(sw.clone()));
    out
}

fn frames_of(g: &Gen, frames: &[u32], init_id: u32) -> Vec<Vec<u8>> {
    frames
        .iter()
        .flat_map(|&f| (0..PER_FRAME).map(move |k| g.packet(f, k, init_id, &[])))
        .collect()
}

/// A sensor that reboots without a new init_id (LEGACY packets carry none) counts its frames
/// from 0 again: the stream starts anew there (one discontinuity), instead of dropping every
/// packet as late until the counter passes the old frames again. FUSA's 32-bit counter alike.
#[test]
fn a_frame_counter_that_starts_over_is_a_restart_not_late_packets() {
    for (profile, before) in [
        (Profile::Legacy, 5_000u32),
        (Profile::Rng19Rfl8Sig16Nir16, 20_000),
        (Profile::FusaRng15Rfl8Nir8Dual, 1_000_000_000),
    ] {
        let mut info = info(profile);
        if profile == Profile::Legacy {
            info.init_id = 0;
        }
        let g = Gen {
            enc: OusterEncoder::new(&info),
            serial: info.serial,
        };
        let frames = [before, before + 1, before + 2, 0, 1, 2];
        let mut s = stream(&info);
        let sweeps = run(&mut s, &frames_of(&g, &frames, 77));
        let st = s.stats();
        assert_eq!(
            sweeps.iter().map(|s| s.frame_id).collect::<Vec<_>>(),
            frames,
            "{profile:?} {st:?}"
        );
        assert!(
            sweeps.iter().all(|s| s.points.len() == W * H),
            "{profile:?}"
        );
        assert_eq!((st.late, st.discontinuities), (0, 1), "{profile:?}");
        assert_eq!((st.missing_columns, st.epochs), (0, 0), "{profile:?}");
    }
}

/// A packet two frames behind is still late (the counter did not start over); three behind is
/// a restart.
#[test]
fn two_frames_behind_is_late_three_is_a_restart() {
    let info = info(Profile::Rng19Rfl8Sig16Nir16);
    let g = Gen {
        enc: OusterEncoder::new(&info),
        serial: info.serial,
    };
    let mut packets = frames_of(&g, &[10, 11, 12], 77);
    packets.push(g.packet(10, 3, 77, &[])); // two behind 12, frame 10 emitted: late
    let mut s = stream(&info);
    let sweeps = run(&mut s, &packets);
    assert_eq!(sweeps.len(), 3);
    assert_eq!((s.stats().late, s.stats().discontinuities), (1, 0));

    // Three behind, and the stream goes on from there: a restart at frame 9, whose first
    // packets (held until the stream showed it) are decoded too.
    let mut packets = frames_of(&g, &[10, 11, 12], 77);
    packets.extend((3..PER_FRAME).map(|k| g.packet(9, k, 77, &[])));
    let mut s = stream(&info);
    let sweeps = run(&mut s, &packets);
    assert_eq!(
        sweeps.iter().map(|s| s.frame_id).collect::<Vec<_>>(),
        [10, 11, 12, 9]
    );
    assert_eq!(sweeps[3].points.len(), (PER_FRAME - 3) * CPP * H);
    assert_eq!((s.stats().late, s.stats().discontinuities), (0, 1));
    assert_eq!(s.stats().lidar_packets, packets.len() as u64);

    // A restart is RESTART_CONFIRM_PACKETS packets in a row; the stream ending one short of
    // that leaves them late (nothing showed a restart).
    for (run_len, restart) in [
        (1, false),
        (RESTART_CONFIRM_PACKETS - 1, false),
        (RESTART_CONFIRM_PACKETS, true),
    ] {
        let mut packets = frames_of(&g, &[10, 11, 12], 77);
        packets.extend((3..3 + run_len).map(|k| g.packet(9, k, 77, &[])));
        let mut s = stream(&info);
        let sweeps = run(&mut s, &packets);
        let st = s.stats();
        let frames: &[u32] = if restart {
            &[10, 11, 12, 9]
        } else {
            &[10, 11, 12]
        };
        assert_eq!(
            sweeps.iter().map(|s| s.frame_id).collect::<Vec<_>>(),
            frames,
            "{run_len} {st:?}"
        );
        let late = if restart { 0 } else { run_len as u64 };
        assert_eq!(
            (st.late, st.discontinuities),
            (late, u64::from(restart)),
            "{run_len}"
        );
        assert_eq!(
            st.lidar_packets + st.late,
            packets.len() as u64,
            "{run_len}"
        );
    }
}

/// The sweeps of `packets` and the stream's counters.
fn sweeps_and_stats(
    info: &OusterInfo,
    packets: &[Vec<u8>],
) -> (Vec<Sweep>, ringscan::sensor::ouster::OusterStats) {
    let mut s = stream(info);
    let sweeps = run(&mut s, packets);
    (sweeps, s.stats().clone())
}

/// Whether two runs gave the same sweeps: frames, points, loss and time.
fn assert_same_sweeps(got: &[Sweep], want: &[Sweep], what: &str) {
    assert_eq!(
        got.iter().map(|s| s.frame_id).collect::<Vec<_>>(),
        want.iter().map(|s| s.frame_id).collect::<Vec<_>>(),
        "{what}"
    );
    for (g, w) in got.iter().zip(want) {
        assert!(
            g.points == w.points,
            "{what}: points of frame {}",
            g.frame_id
        );
        assert_eq!(
            (g.missing_columns, g.missing_packets, g.packets),
            (w.missing_columns, w.missing_packets, w.packets),
            "{what}: frame {}",
            g.frame_id
        );
        assert_eq!(
            (g.device_time_ns, g.timestamp_ns),
            (w.device_time_ns, w.timestamp_ns),
            "{what}"
        );
    }
}

/// One packet 3 or 100 frames late (delayed, re-sent) in the middle of frame 12, the stream
/// going on with frame 12 right after it: counted late once, and the sweeps are those of the
/// stream without it (it was a restart: frame 12 cut in two, a discontinuity, and the frames
/// from it back to 12 counted lost). 100 behind frame 12 is across the wrap of the counter:
/// 16 bits for LEGACY and RNG19, 32 for FUSA.
#[test]
fn one_packet_far_late_is_late_not_a_restart() {
    for profile in [
        Profile::Legacy,
        Profile::Rng19Rfl8Sig16Nir16,
        Profile::FusaRng15Rfl8Nir8Dual,
    ] {
        let mut info = info(profile);
        if profile == Profile::Legacy {
            info.init_id = 0;
        }
        let g = Gen {
            enc: OusterEncoder::new(&info),
            serial: info.serial,
        };
        let bits = if profile == Profile::FusaRng15Rfl8Nir8Dual {
            32
        } else {
            16
        };
        let clean = frames_of(&g, &[10, 11, 12, 13], 77);
        let (want, want_st) = sweeps_and_stats(&info, &clean);
        assert_eq!((want.len(), want_st.late), (4, 0), "{profile:?}");
        for lag in [3u64, 100] {
            let stale = ((12 + (1u64 << bits) - lag) % (1u64 << bits)) as u32;
            let mut packets = clean.clone();
            // After packet 5 of frame 12 (frames 10 and 11 take 64 packets).
            packets.insert(2 * PER_FRAME + 6, g.packet(stale, 7, 77, &[]));
            let (got, st) = sweeps_and_stats(&info, &packets);
            let what = format!("{profile:?}, {lag} late (frame {stale})");
            assert_same_sweeps(&got, &want, &what);
            assert_eq!(
                (st.late, st.discontinuities, st.missing_columns),
                (1, 0, 0),
                "{what}: {st:?}"
            );
            assert_eq!(
                (st.lidar_packets, st.sweeps, st.points),
                (want_st.lidar_packets, want_st.sweeps, want_st.points),
                "{what}"
            );
        }
    }
}

/// A few stale packets in a row (fewer than a restart takes), and one stale packet the
/// network repeated more often than that: each counted late once, the sweeps unchanged.
#[test]
fn a_short_stale_run_and_a_repeated_stale_packet_are_late() {
    for profile in [Profile::Legacy, Profile::FusaRng15Rfl8Nir8Dual] {
        let mut info = info(profile);
        if profile == Profile::Legacy {
            info.init_id = 0;
        }
        let g = Gen {
            enc: OusterEncoder::new(&info),
            serial: info.serial,
        };
        let clean = frames_of(&g, &[10, 11, 12, 13], 77);
        let (want, _) = sweeps_and_stats(&info, &clean);
        let run_of = (0..RESTART_CONFIRM_PACKETS - 1).map(|k| g.packet(5, k, 77, &[]));
        let copies = std::iter::repeat_n(g.packet(5, 9, 77, &[]), 2 * RESTART_CONFIRM_PACKETS);
        for (what, stale) in [
            ("a short run", run_of.collect::<Vec<_>>()),
            ("copies", copies.collect()),
        ] {
            let mut packets = clean.clone();
            let at = 2 * PER_FRAME + 6;
            let n = stale.len() as u64;
            packets.splice(at..at, stale);
            let (got, st) = sweeps_and_stats(&info, &packets);
            let what = format!("{profile:?}, {what}");
            assert_same_sweeps(&got, &want, &what);
            assert_eq!(
                (st.late, st.discontinuities, st.missing_columns),
                (n, 0, 0),
                "{what}: {st:?}"
            );
        }
    }
}

/// A long stale run: 4, 8 or 64 packets in a row of frames the stream emitted 3 to 5 frames
/// before (a switch buffer flushing datagrams the sensor sent then), in the middle of frame
/// 15: each counted late once, the sweeps those of the stream without them. Copies of packets
/// that arrived, and packets delayed there from frames 11 and 12 (the stream without them at
/// all is the truth: their columns missing once, in their frames). They continue from one
/// another as a restart's would: their frame ids are of frames emitted and their column times
/// those frames' (it was a restart: frame 15 cut in two, a discontinuity, the held packets
/// emitted as sweeps of their own).
#[test]
fn a_long_stale_run_of_emitted_frames_is_late_not_a_restart() {
    for profile in [
        Profile::Legacy,
        Profile::Rng19Rfl8Sig16Nir16,
        Profile::FusaRng15Rfl8Nir8Dual,
    ] {
        let mut info = info(profile);
        if profile == Profile::Legacy {
            info.init_id = 0;
        }
        let g = Gen {
            enc: OusterEncoder::new(&info),
            serial: info.serial,
        };
        let clean = frames_of(&g, &[10, 11, 12, 13, 14, 15, 16], 77);
        // After packet 5 of frame 15 (frames 10 to 14 take 160 packets).
        let at = 5 * PER_FRAME + 6;
        for n in [4usize, 8, 64] {
            assert!(n >= RESTART_CONFIRM_PACKETS);
            // Copies: packets 0.. of frames 11 and 12, already decoded.
            let stale: Vec<Vec<u8>> = frames_of(&g, &[11, 12], 77).into_iter().take(n).collect();
            let (want, want_st) = sweeps_and_stats(&info, &clean);
            let mut packets = clean.clone();
            packets.splice(at..at, stale.clone());
            let mut s = stream(&info);
            let got = run(&mut s, &packets);
            let st = s.stats().clone();
            let what = format!("{profile:?}, {n} copies");
            assert_same_sweeps(&got, &want, &what);
            assert_eq!(
                (st.late, st.discontinuities, st.missing_columns),
                (n as u64, 0, 0),
                "{what}: {st:?}"
            );
            assert_eq!(
                (st.lidar_packets, st.sweeps, st.points),
                (want_st.lidar_packets, want_st.sweeps, want_st.points),
                "{what}"
            );
            assert_eq!(st.lidar_packets + st.late, packets.len() as u64, "{what}");

            // Delayed: the first n of packets 1.. of frames 11 and 12 (62 for 64: each frame
            // keeps its packet 0, so both were emitted) taken out of their place.
            let delayed: Vec<usize> = [PER_FRAME, 2 * PER_FRAME]
                .iter()
                .flat_map(|&f| f + 1..f + PER_FRAME)
                .take(n)
                .collect();
            let moved: Vec<Vec<u8>> = delayed.iter().map(|&i| clean[i].clone()).collect();
            let without: Vec<Vec<u8>> = (0..clean.len())
                .filter(|i| !delayed.contains(i))
                .map(|i| clean[i].clone())
                .collect();
            let (want, want_st) = sweeps_and_stats(&info, &without);
            let mut packets = without.clone();
            let at = at - moved.len();
            packets.splice(at..at, moved.clone());
            let mut s = stream(&info);
            let got = run(&mut s, &packets);
            let st = s.stats().clone();
            let what = format!("{profile:?}, {} delayed", moved.len());
            assert_same_sweeps(&got, &want, &what);
            assert_eq!(
                (st.late, st.discontinuities),
                (moved.len() as u64, 0),
                "{what}: {st:?}"
            );
            assert_eq!(st.missing_columns, want_st.missing_columns, "{what}");
            assert_eq!(
                st.missing_columns,
                (moved.len() * CPP) as u64,
                "{what}: the delayed columns are missing once, no frame is"
            );
            assert_eq!(st.lidar_packets + st.late, packets.len() as u64, "{what}");
        }
    }
}

/// A frame counter that starts over on frames the stream emitted is still a restart: a reboot
/// (its clock 40 s ahead of the first boot's for the same frame ids; coming at once, so that
/// only the column times tell) and a capture replayed in a loop (the same packets, after a
/// 2 s pause: their frames' last packets more than `STALE_WITHIN_NS` before) are told from
/// stale datagrams by their times.
#[test]
fn a_counter_over_emitted_frames_again_is_still_a_restart() {
    let info = info(Profile::Rng19Rfl8Sig16Nir16);
    let g = Gen {
        enc: OusterEncoder::new(&info),
        serial: info.serial,
    };
    let first: Vec<Vec<u8>> = frames_of(&g, &[0, 1, 2, 3, 4, 5], 77);
    // 1 ms of host time per packet: 0.19 s for the six frames.
    let host = |i: usize| i as i64 * 1_000_000;
    for (what, pause_ns, again) in [
        (
            "a reboot",
            0,
            [0u32, 1, 2]
                .iter()
                .flat_map(|&f| (0..PER_FRAME).map(move |k| (f, k)))
                .map(|(f, k)| g.packet_at(41_000_000_000, f, k, 77, &[]))
                .collect::<Vec<_>>(),
        ),
        ("a loop", 2_000_000_000, frames_of(&g, &[0, 1, 2], 77)),
    ] {
        let mut packets: Vec<(i64, Vec<u8>)> = first
            .iter()
            .enumerate()
            .map(|(i, p)| (host(i), p.clone()))
            .collect();
        let after = host(first.len()) + pause_ns;
        packets.extend(
            again
                .into_iter()
                .enumerate()
                .map(|(i, p)| (after + host(i), p)),
        );
        let mut s = stream(&info);
        let sweeps = run_at(&mut s, &packets);
        let st = s.stats();
        assert_eq!(
            sweeps.iter().map(|s| s.frame_id).collect::<Vec<_>>(),
            [0, 1, 2, 3, 4, 5, 0, 1, 2],
            "{what} {st:?}"
        );
        assert!(sweeps.iter().all(|s| s.points.len() == W * H), "{what}");
        assert_eq!((st.late, st.discontinuities), (0, 1), "{what}");
        assert_eq!(st.lidar_packets, packets.len() as u64, "{what}");
    }
}

/// One packet far ahead (corrupt, spoofed) in the middle of frame 11: the frame it opens is
/// emitted on its own, frame 11 is not cut, and the frames after it decode (where they were
/// dropped as late for 30 000 frames, FUSA's for ever).
#[test]
fn one_packet_far_ahead_costs_no_genuine_frame() {
    for (profile, jump) in [
        (Profile::Rng19Rfl8Sig16Nir16, 30_000u32),
        (Profile::FusaRng15Rfl8Nir8Dual, 1_000_000_000),
    ] {
        let info = info(profile);
        let g = Gen {
            enc: OusterEncoder::new(&info),
            serial: info.serial,
        };
        let mut packets = Vec::new();
        for (f, k) in (10..14u32).flat_map(|f| (0..PER_FRAME).map(move |k| (f, k))) {
            packets.push(g.packet(f, k, 77, &[]));
            if (f, k) == (11, 5) {
                packets.push(g.packet(11 + jump, 9, 77, &[]));
            }
        }
        let mut s = stream(&info);
        let sweeps = run(&mut s, &packets);
        let st = s.stats();
        assert_eq!(
            sweeps.iter().map(|s| s.frame_id).collect::<Vec<_>>(),
            [10, 11, 11 + jump, 12, 13],
            "{profile:?} {st:?}"
        );
        for (i, sw) in sweeps.iter().enumerate() {
            let (points, missing) = if i == 2 {
                (CPP * H, W - CPP)
            } else {
                (W * H, 0)
            };
            // Second returns are absent (range 0): one point per pixel, dual or not.
            assert_eq!(sw.points.len(), points, "{profile:?} sweep {i}");
            assert_eq!(sw.missing_columns, missing as u64, "{profile:?} sweep {i}");
        }
        // The step forward (not a loss of 30 000 frames) and the step back.
        assert_eq!((st.late, st.discontinuities), (0, 2), "{profile:?}");
        assert_eq!(st.missing_columns, (W - CPP) as u64, "{profile:?}");
    }
}

/// Frames lost whole: the sweep after them carries their columns (of the column window) as
/// missing; a step of more than a second's frames (10 here) is a discontinuity, no loss.
#[test]
fn frames_lost_whole_are_missing_columns_of_the_next_sweep() {
    for window in [(0usize, W - 1), (100, 299), (500, 9)] {
        let mut info = info(Profile::Rng19Rfl8Sig16Nir16);
        info.column_window = window;
        let in_window = info.columns_in_window() as u64;
        assert_eq!(info.fps, 10);
        let g = Gen {
            enc: OusterEncoder::new(&info),
            serial: info.serial,
        };
        // Out of the window the sensor sends columns invalid (status 0).
        let out: Vec<usize> = (0..W).filter(|&c| !info.is_column_in_window(c)).collect();
        let frames = [5u32, 7, 8, 12, 22, 33];
        let packets: Vec<_> = frames
            .iter()
            .flat_map(|&f| (0..PER_FRAME).map(move |k| (f, k)))
            .map(|(f, k)| g.packet(f, k, 77, &out))
            .collect();
        let mut s = stream(&info);
        let sweeps = run(&mut s, &packets);
        assert_eq!(
            sweeps.iter().map(|s| s.frame_id).collect::<Vec<_>>(),
            frames
        );
        // Frame 6 lost before 7, 9–11 before 12, 13–21 before 22; 33 is 11 frames on.
        let lost = [0u64, 1, 0, 3, 9, 0];
        for (sw, n) in sweeps.iter().zip(lost) {
            assert_eq!(
                sw.missing_columns,
                n * in_window,
                "{window:?} {}",
                sw.frame_id
            );
            assert_eq!(
                sw.missing_packets,
                n * in_window.div_ceil(CPP as u64),
                "{window:?} {}",
                sw.frame_id
            );
            assert_eq!(sw.points.len(), in_window as usize * H);
        }
        let st = s.stats();
        assert_eq!(st.missing_columns, 13 * in_window, "{window:?}");
        assert_eq!((st.discontinuities, st.late), (1, 0), "{window:?}");
    }
}

/// A bit flipped in a packet's init_id (CRC checked: FW 2.5) is a CRC failure, not two
/// epochs cutting the frame in three; one flipped in its serial is not another sensor.
#[test]
fn a_corrupt_init_id_is_a_crc_failure_not_an_epoch() {
    let info = info(Profile::Rng19Rfl8Sig16Nir16);
    let g = Gen {
        enc: OusterEncoder::new(&info),
        serial: info.serial,
    };
    let mut packets = frames_of(&g, &[1], 77);
    packets[10][4] ^= 0x01; // init_id, bytes 4..7
    packets[20][8] ^= 0x10; // serial, bytes 7..12
    let mut s = stream(&info);
    let sweeps = run(&mut s, &packets);
    let st = s.stats();
    assert_eq!(
        (st.epochs, st.crc_failures, st.wrong_sensor),
        (0, 2, 0),
        "{st:?}"
    );
    assert_eq!(sweeps.len(), 1);
    assert_eq!(sweeps[0].missing_columns, 2 * CPP as u64);
    assert_eq!(s.facts().init_id, 77);
    // A genuine new init_id (its CRC holds) is still an epoch.
    let mut packets = frames_of(&g, &[1], 77);
    packets.extend(frames_of(&g, &[0], 78));
    let mut s = stream(&info);
    assert_eq!(run(&mut s, &packets).len(), 2);
    assert_eq!((s.stats().epochs, s.facts().init_id), (1, 78));
}

/// PTP column timestamps beyond i64 (2^63 ns): saturated, not an overflow (a panic in a debug
/// build) when the TAI offset is taken off.
#[test]
fn ptp_timestamps_beyond_i64_saturate() {
    let mut info = info(Profile::Rng19Rfl8Sig16Nir16);
    info.timestamp_mode = ringscan::sensor::ouster::calib::TimestampMode::Ptp1588;
    let enc = OusterEncoder::new(&info);
    let cols: Vec<SimColumn> = (0..CPP)
        .map(|m| SimColumn {
            timestamp_ns: 0x8000_0000_0000_0000 + m as u64,
            measurement_id: m as u16,
            status: 1,
            pixels: vec![
                SimPixel {
                    range_mm: 5000,
                    ..SimPixel::default()
                };
                H
            ],
        })
        .collect();
    let h = SimHeader {
        frame_id: 3,
        init_id: 77,
        serial: info.serial,
        ..SimHeader::default()
    };
    let mut p = Vec::new();
    enc.encode(&h, &cols, &mut p).unwrap();
    let mut s = stream(&info);
    let sweeps = run(&mut s, &[p]);
    assert_eq!(sweeps.len(), 1);
    assert_eq!(sweeps[0].points.len(), CPP * H);
    assert_eq!(sweeps[0].device_time_ns, i64::MAX);
    assert_eq!(sweeps[0].timestamp_ns, i64::MAX - 37_000_000_000);
}

/// A frame none of whose columns is valid has no sensor time: its sweep's times are the host
/// times of its packets (clock: host), not those of the frame its recycled buffer held.
#[test]
fn a_sweep_without_valid_columns_has_its_own_host_times() {
    let mut info = info(Profile::Rng19Rfl8Sig16Nir16);
    info.timestamp_mode = ringscan::sensor::ouster::calib::TimestampMode::Ptp1588;
    let g = Gen {
        enc: OusterEncoder::new(&info),
        serial: info.serial,
    };
    let all: Vec<usize> = (0..W).collect();
    let mut packets = Vec::new();
    for f in 1..=4u32 {
        for k in 0..PER_FRAME {
            let host = 1_700_000_000_000_000_000 + i64::from(f) * 100_000_000 + k as i64 * 1000;
            let invalid: &[usize] = if f == 3 { &all } else { &[] };
            packets.push((host, g.packet(f, k, 77, invalid)));
        }
    }
    let mut s = stream(&info);
    let sweeps = run_at(&mut s, &packets);
    assert_eq!(sweeps.len(), 4);
    let sw = &sweeps[2];
    assert_eq!((sw.frame_id, sw.points.len()), (3, 0));
    let first = 1_700_000_000_000_000_000 + 3 * 100_000_000;
    assert_eq!(sw.first_host_ns, first);
    assert_eq!(sw.timestamp_ns, first);
    assert_eq!(sw.device_time_ns, first);
    assert_eq!(sw.last_host_ns, first + (PER_FRAME as i64 - 1) * 1000);
    assert_eq!(sw.clock, ringscan::time::ClockSource::Host);
    assert_eq!(sw.missing_columns, W as u64);
    // The others keep the sensor's PTP time (TAI − 37 s).
    let f4 = &sweeps[3];
    assert_eq!(f4.clock, ringscan::time::ClockSource::SensorPtp);
    assert_eq!(f4.device_time_ns, 1_000_000_000 + 4 * 100_000_000);
    assert_eq!(f4.timestamp_ns, f4.device_time_ns - 37_000_000_000);
}
