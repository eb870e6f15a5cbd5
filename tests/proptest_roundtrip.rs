//! Property tests of the round trips, against independent truth:
//!
//! - **Geometry**: for every Velodyne model × return mode, random scenes, rotation rates, start
//!   azimuths and top-of-hour stamps → `sim::velodyne::VelodyneSim` packets → decoder: every
//!   point lies within 1 cm + range · sin(0.005°) of the scene point the simulator's ray hit
//!   (block azimuths are rounded to 0.01° on the wire), with its ring, return and intensity.
//! - **Wraps**: a start azimuth just below 360° and a top-of-hour counter just below the hour
//!   (3.6e9 µs) through `VelodyneStream`: no discontinuity, no missing packet, every packet
//!   decoded, sweep times strictly increasing and continuous across the hour.
//! - **IPv4 reassembly**: a random payload cut into fragments of a random multiple of 8 bytes,
//!   shuffled (and with a duplicate), gives the original payload back — in the reassembler and
//!   through `PcapSource` reading a capture of the fragments.
//!
//! Case counts keep the file under a minute in a debug build; `PROPTEST_CASES=N` scales them
//! (N per model × mode combination and per property).
#![cfg(all(feature = "sim", feature = "pcap"))]

use std::collections::HashMap;
use std::net::{Ipv4Addr, SocketAddrV4};

use proptest::prelude::*;
use proptest::test_runner::{Config, TestCaseError, TestRunner};

use ringscan::sensor::velodyne::calib::builtin::builtin;
use ringscan::sensor::velodyne::calib::LaserCalibration;
use ringscan::sensor::velodyne::calib::VelodyneCalibration;
use ringscan::sensor::velodyne::decode::ColumnRate;
use ringscan::sensor::velodyne::model::ALL_MODELS;
use ringscan::sensor::velodyne::sim::Truth;
use ringscan::sensor::velodyne::sim::VelodyneSim;
use ringscan::sensor::velodyne::wire::DataPacket;
use ringscan::sensor::velodyne::ReturnMode;
use ringscan::sensor::velodyne::StreamConfig;
use ringscan::sensor::velodyne::VelodyneDecoder;
use ringscan::sensor::velodyne::VelodyneModel;
use ringscan::sensor::velodyne::VelodyneStream;
use ringscan::sensor::DecodeOptions;
use ringscan::sim::net::PcapWriter;
use ringscan::sim::scene::Plane;
use ringscan::sim::scene::Shapes;
use ringscan::sim::scene::Sphere;
use ringscan::source::pcap::PcapSource;
use ringscan::source::reassembly::{FragmentKey, Push, Reassembler, MAX_INTERVALS};
use ringscan::sweep::Sweep;

const MODES: [ReturnMode; 3] = [ReturnMode::Strongest, ReturnMode::Last, ReturnMode::Dual];
const SIN_0005_DEG: f64 = 8.726_646e-5;
const HOUR_US: u32 = 3_600_000_000;

fn cases(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn runner(cases: u32) -> TestRunner {
    TestRunner::new(Config {
        cases,
        failure_persistence: None,
        ..Config::default()
    })
}

/// An angles-only table for models without a built-in one (HDL-64E, VLS-128): evenly spread
/// elevations from −24.9° to +2°, interleaved so ring ≠ laser id, small rotational corrections.
fn spread(n: usize) -> VelodyneCalibration {
    let lasers = (0..n)
        .map(|i| {
            let k = if i % 2 == 0 { i / 2 } else { n / 2 + i / 2 };
            let deg = -24.9 + 26.9 * k as f64 / (n - 1) as f64;
            LaserCalibration::angles(
                i as u16,
                deg.to_radians(),
                ((i % 4) as f64 - 1.5).to_radians() * 0.5,
            )
        })
        .collect();
    VelodyneCalibration {
        lasers,
        distance_resolution: None,
        advanced: false,
        source: "proptest spread".into(),
    }
    .validate()
    .unwrap()
}

fn calibration(model: VelodyneModel) -> VelodyneCalibration {
    builtin(model).unwrap_or_else(|| spread(model.lasers()))
}

fn combinations() -> Vec<(VelodyneModel, ReturnMode)> {
    ALL_MODELS
        .into_iter()
        .flat_map(|m| MODES.into_iter().map(move |r| (m, r)))
        .collect()
}

/// A random scene around the sensor: a box (walls, floor, ceiling at random distances and
/// tilts) and two spheres.
#[derive(Clone, Debug)]
struct SceneParams {
    half_x: f64,
    half_y: f64,
    floor: f64,
    ceiling: f64,
    tilt: f64,
    spheres: [(f64, f64, f64, f64); 2],
    reflectivity: u8,
}

impl SceneParams {
    fn shapes(&self) -> Shapes {
        let r = self.reflectivity;
        let (s, c) = self.tilt.sin_cos();
        let p = |normal: [f64; 3], d: f64, refl: u8| Plane {
            normal,
            d,
            reflectivity: refl,
        };
        Shapes {
            planes: vec![
                p([c, s, 0.0], self.half_x, r),
                p([-c, -s, 0.0], self.half_x, r.wrapping_add(40)),
                p([-s, c, 0.0], self.half_y, r.wrapping_add(80)),
                p([s, -c, 0.0], self.half_y, r.wrapping_add(120)),
                p([0.0, 0.0, -1.0], self.floor, r.wrapping_add(160)),
                p([0.0, 0.0, 1.0], self.ceiling, r.wrapping_add(200)),
            ],
            spheres: self
                .spheres
                .iter()
                .map(|&(x, y, z, radius)| Sphere {
                    center: [x, y, z],
                    radius,
                    reflectivity: 255,
                })
                .collect(),
            max_range: 200.0,
        }
    }
}

fn scene_params() -> impl Strategy<Value = SceneParams> {
    let sphere = (-20.0..20.0f64, -20.0..20.0f64, -2.0..3.0f64, 0.2..2.0f64);
    (
        3.0..60.0f64,
        3.0..60.0f64,
        0.5..3.0f64,
        0.5..10.0f64,
        -0.8..0.8f64,
        [sphere.clone(), sphere],
        any::<u8>(),
    )
        .prop_map(
            |(half_x, half_y, floor, ceiling, tilt, spheres, reflectivity)| SceneParams {
                half_x,
                half_y,
                floor,
                ceiling,
                tilt,
                spheres,
                reflectivity,
            },
        )
}

/// Simulator set-up: rotation rate (300–1200 rpm), start azimuth, top-of-hour stamp.
#[derive(Clone, Debug)]
struct Motion {
    deg_per_s: f64,
    azimuth0_deg: f64,
    toh0_us: u32,
}

fn motion() -> impl Strategy<Value = Motion> {
    (1_800.0..7_200.0f64, 0.0..360.0f64, 0..HOUR_US).prop_map(
        |(deg_per_s, azimuth0_deg, toh0_us)| Motion {
            deg_per_s,
            azimuth0_deg,
            toh0_us,
        },
    )
}

fn sim_for(model: VelodyneModel, mode: ReturnMode, m: &Motion) -> VelodyneSim {
    let mut sim = VelodyneSim::new(model, mode, calibration(model), 1_700_000_000_000_000_000);
    sim.deg_per_s = m.deg_per_s;
    sim.azimuth0_deg = m.azimuth0_deg;
    sim.toh0_us = m.toh0_us;
    sim
}

/// Decodes `packets` simulated packets and checks every point against the ray it came from.
/// Returns the number of points checked.
fn geometry_roundtrip(
    model: VelodyneModel,
    mode: ReturnMode,
    scene: &SceneParams,
    m: &Motion,
    packets: usize,
) -> Result<usize, TestCaseError> {
    let mut sim = sim_for(model, mode, m);
    let calib = sim.calib.clone();
    let rings = calib.rings();
    let shapes = scene.shapes();
    let dec = VelodyneDecoder::new(model, mode, &calib, DecodeOptions::default())
        .map_err(|e| TestCaseError::fail(e.to_string()))?;
    let mut checked = 0;
    let mut truth: Vec<Truth> = Vec::new();
    let mut points = Vec::new();
    // A packet of one firing column (VLS-128 dual) takes its rotation rate from the packet
    // before: one more packet first, decoded only for that.
    let mut rate = ColumnRate::default();
    if dec.needs_rate() {
        let (_, bytes) = sim.next_packet(&shapes, &mut truth);
        let p = DataPacket::new(&bytes).map_err(|e| TestCaseError::fail(e.to_string()))?;
        rate.next(&dec, &p);
    }
    for _ in 0..packets {
        truth.clear();
        points.clear();
        let (_, bytes) = sim.next_packet(&shapes, &mut truth);
        let p = DataPacket::new(&bytes).map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert!(dec.check_layout(&p).is_ok());
        let r = rate.next(&dec, &p);
        let n = dec.decode_with_rate(&p, 0..12, 0, r, |pt, _| points.push(pt));
        prop_assert_eq!(n.points, truth.len(), "one point per measurement");
        let by_key: HashMap<(u32, u16, u8), &Truth> = truth
            .iter()
            .map(|t| ((t.t_ns.round() as u32, rings[t.laser], t.ret), t))
            .collect();
        prop_assert_eq!(by_key.len(), truth.len(), "truth keys are unique");
        for pt in &points {
            let t = by_key.get(&(pt.t, pt.ring, pt.ret));
            prop_assert!(t.is_some(), "no truth for {:?}", pt);
            let t = t.unwrap();
            let d = ((f64::from(pt.x) - t.xyz[0]).powi(2)
                + (f64::from(pt.y) - t.xyz[1]).powi(2)
                + (f64::from(pt.z) - t.xyz[2]).powi(2))
            .sqrt();
            let allowed = 0.01 + t.range * SIN_0005_DEG;
            prop_assert!(
                d <= allowed,
                "point off by {} m (allowed {}) at range {}: {:?} vs {:?}",
                d,
                allowed,
                t.range,
                pt,
                t
            );
            prop_assert_eq!(pt.intensity, f32::from(t.reflectivity));
            checked += 1;
        }
    }
    Ok(checked)
}

#[test]
fn every_model_and_mode_round_trips_random_scenes() {
    let n = cases(24);
    for (model, mode) in combinations() {
        let total = std::cell::Cell::new(0usize);
        let mut runner = runner(n);
        runner
            .run(
                &(scene_params(), motion(), 1usize..4),
                |(scene, m, packets)| {
                    let checked = geometry_roundtrip(model, mode, &scene, &m, packets)?;
                    total.set(total.get() + checked);
                    Ok(())
                },
            )
            .unwrap_or_else(|e| panic!("{model} {mode}: {e}"));
        let total = total.get();
        // Walls all around within 60 m: most rays hit something.
        assert!(
            total >= n as usize * 100,
            "{model} {mode}: only {total} points checked"
        );
    }
}

/// Packets through a stream that names the model; returns the sweeps and the stream.
fn stream_run(sim: &mut VelodyneSim, packets: usize) -> (Vec<Sweep>, VelodyneStream) {
    let scene = Shapes::room(15.0, 10.0, 1.7, 5.0);
    let mut stream = VelodyneStream::new(StreamConfig {
        model: Some(sim.model),
        calibrations: vec![sim.calib.clone()],
        ..StreamConfig::default()
    });
    let mut sweeps = Vec::new();
    let mut truth = Vec::new();
    for _ in 0..packets {
        truth.clear();
        let (host, bytes) = sim.next_packet(&scene, &mut truth);
        stream
            .push(host, &bytes, &mut |s, _| sweeps.push(s.clone()))
            .expect("the stream accepts simulated packets");
    }
    stream
        .finish(&mut |s, _| sweeps.push(s.clone()))
        .expect("the stream finishes");
    (sweeps, stream)
}

#[test]
fn azimuth_and_top_of_hour_wraps_are_seamless() {
    let n = cases(12);
    for (model, mode) in combinations() {
        let period_us = model.packet_period_ns(mode) / 1_000.0;
        // 60–120 packets; the hour rolls over after 1 to 50 of them; the head starts within
        // 0.1° below 360° (and still reports below 36000 after rounding), so it passes 0° in
        // the first packet.
        let strategy = (
            60usize..120,
            1u32..50,
            359.9..359.99f64,
            3_000.0..7_200.0f64,
        );
        let mut runner = runner(n);
        runner
            .run(&strategy, |(packets, before_hour, az0, deg_per_s)| {
                let m = Motion {
                    deg_per_s,
                    azimuth0_deg: az0,
                    toh0_us: HOUR_US - (f64::from(before_hour) * period_us) as u32,
                };
                let mut sim = sim_for(model, mode, &m);
                let (sweeps, stream) = stream_run(&mut sim, packets);
                let st = stream.stats();
                prop_assert_eq!(st.discontinuities, 0, "{:?}", st);
                prop_assert_eq!(st.missing, 0, "{:?}", st);
                prop_assert_eq!(st.data_packets, packets as u64, "{:?}", st);
                prop_assert_eq!(st.malformed, 0, "{:?}", st);
                prop_assert_eq!(st.mode_changes, 0, "{:?}", st);
                prop_assert!(!sweeps.is_empty());
                // Every sweep after the first starts on the first firing past the cut angle
                // (0°): within one firing group's rotation of it (+ 0.01° of rounding).
                let group_ns = model.packet_period_ns(mode) * model.blocks_per_firing(mode) as f64
                    / model.blocks_used(mode) as f64;
                let max_start = (group_ns * 1e-9 * deg_per_s * 100.0).ceil() as u16 + 1;
                for s in &sweeps[1..] {
                    prop_assert!(
                        s.first_azimuth <= max_start,
                        "sweep {} starts at {} × 0.01°, past {}",
                        s.index,
                        s.first_azimuth,
                        max_start
                    );
                }
                let span_ns = packets as f64 * model.packet_period_ns(mode);
                for w in sweeps.windows(2) {
                    let (a, b) = (&w[0], &w[1]);
                    prop_assert_eq!(b.index, a.index + 1);
                    prop_assert!(
                        b.device_time_ns > a.device_time_ns,
                        "sweep {} starts at {} ns, before sweep {} at {} ns",
                        b.index,
                        b.device_time_ns,
                        a.index,
                        a.device_time_ns
                    );
                    prop_assert!(b.timestamp_ns > a.timestamp_ns);
                    // No hour jump: consecutive sweeps are at most a turn (≤ 0.2 s) apart.
                    prop_assert!(
                        (b.device_time_ns - a.device_time_ns) as f64 <= span_ns.max(2e8),
                        "gap of {} ns",
                        b.device_time_ns - a.device_time_ns
                    );
                }
                // Device time runs with the simulator's clock across the hour: the last sweep
                // starts within the run.
                let first = sweeps.first().map(|s| s.device_time_ns).unwrap_or(0);
                let last = sweeps.last().map(|s| s.device_time_ns).unwrap_or(0);
                prop_assert!(
                    ((last - first) as f64) < span_ns,
                    "sweeps span {} ns in a run of {} ns",
                    last - first,
                    span_ns
                );
                let points: u64 = sweeps.iter().map(|s| s.points.len() as u64).sum();
                prop_assert_eq!(points, st.points);
                for s in &sweeps {
                    let span = s.span_ns();
                    prop_assert!(s.points.iter().all(|p| p.t <= span));
                    prop_assert_eq!(s.missing_packets, 0);
                }
                Ok(())
            })
            .unwrap_or_else(|e| panic!("{model} {mode}: {e}"));
    }
}

// ----- IPv4 reassembly ---------------------------------------------------------------------------

/// Fragments of `payload` (the IP payload), `frag` bytes each (a multiple of 8), as
/// (offset, more-fragments, bytes), in order.
fn cut(payload: &[u8], frag: usize) -> Vec<(usize, bool, Vec<u8>)> {
    payload
        .chunks(frag)
        .enumerate()
        .map(|(i, c)| (i * frag, (i + 1) * frag < payload.len(), c.to_vec()))
        .collect()
}

/// An IP payload of `min_len` bytes or more, a fragment size (a multiple of 8 up to 1480), and
/// a shuffled order of its fragments in which one fragment (not the last to arrive) is sent
/// twice. At most [`MAX_INTERVALS`] fragments: beyond that a set may hold more disjoint ranges
/// than the reassembler keeps, and it is dropped by design (hostile tiny fragments).
fn fragments_case(min_len: usize) -> impl Strategy<Value = (Vec<u8>, usize, Vec<usize>)> {
    (
        prop::collection::vec(any::<u8>(), min_len..20_000),
        1usize..=185,
    )
        .prop_flat_map(|(payload, units)| {
            let min_units = payload.len().div_ceil(8 * MAX_INTERVALS);
            let frag = units.max(min_units) * 8;
            let n = payload.len().div_ceil(frag);
            let order = Just((0..n).collect::<Vec<usize>>()).prop_shuffle();
            (Just(payload), Just(frag), order, any::<usize>())
        })
        .prop_map(|(payload, frag, mut order, dup)| {
            // The copy arrives just before the last fragment and is not that one, so the set
            // completes exactly once, with the last fragment.
            if order.len() > 1 {
                let last = order.len() - 1;
                let copy = order[dup % last];
                order.insert(last, copy);
            }
            (payload, frag, order)
        })
}

#[test]
fn reassembly_in_any_order_gives_the_payload() {
    let key = FragmentKey {
        src: Ipv4Addr::new(192, 168, 1, 10),
        dst: Ipv4Addr::new(192, 168, 1, 77),
        protocol: 17,
        id: 4242,
    };
    runner(cases(512))
        .run(&fragments_case(1), |(payload, frag, order)| {
            let frags = cut(&payload, frag);
            let mut r = Reassembler::default();
            let mut completed = None;
            for (i, &k) in order.iter().enumerate() {
                let (offset, more, bytes) = &frags[k];
                let got = r.push(1_000 + i as i64, key, *offset, *more, bytes);
                if i + 1 < order.len() {
                    prop_assert_eq!(got, Push::Pending, "fragment {} of {}", i, order.len());
                } else {
                    completed = Some(got);
                }
            }
            prop_assert_eq!(completed, Some(Push::Complete { len: payload.len() }));
            prop_assert_eq!(r.completed(), &payload[..]);
            prop_assert_eq!(r.pending_sets(), 0);
            prop_assert_eq!(r.pending_bytes(), 0);
            Ok(())
        })
        .unwrap();
}

/// An Ethernet + IPv4 frame holding one fragment of an IP payload.
fn fragment_frame(
    src: Ipv4Addr,
    dst: Ipv4Addr,
    id: u16,
    offset: usize,
    more: bool,
    bytes: &[u8],
) -> Vec<u8> {
    let mut f = vec![
        0x01, 0x00, 0x5e, 0, 0, 1, 0x60, 0x76, 0x88, 0, 0, 2, 0x08, 0x00,
    ];
    let total = (20 + bytes.len()) as u16;
    let flags_offset = (u16::from(more) << 13) | (offset / 8) as u16;
    let mut ip = [0u8; 20];
    ip[0] = 0x45;
    ip[2..4].copy_from_slice(&total.to_be_bytes());
    ip[4..6].copy_from_slice(&id.to_be_bytes());
    ip[6..8].copy_from_slice(&flags_offset.to_be_bytes());
    ip[8] = 64;
    ip[9] = 17;
    ip[12..16].copy_from_slice(&src.octets());
    ip[16..20].copy_from_slice(&dst.octets());
    let mut sum: u32 = ip
        .chunks_exact(2)
        .map(|w| u32::from(u16::from_be_bytes([w[0], w[1]])))
        .sum();
    while sum > 0xFFFF {
        sum = (sum & 0xFFFF) + (sum >> 16);
    }
    ip[10..12].copy_from_slice(&(!(sum as u16)).to_be_bytes());
    f.extend_from_slice(&ip);
    f.extend_from_slice(bytes);
    f
}

#[test]
fn fragmented_udp_in_a_capture_reads_back_in_any_order() {
    runner(cases(256))
        .run(&fragments_case(9), |(mut ip_payload, frag, order)| {
            let (src, dst) = (
                SocketAddrV4::new(Ipv4Addr::new(10, 5, 0, 2), 7502),
                SocketAddrV4::new(Ipv4Addr::new(10, 5, 0, 1), 7503),
            );
            // The IP payload that gets fragmented: a UDP header, then the data.
            let udp_len = ip_payload.len() as u16;
            ip_payload[0..2].copy_from_slice(&src.port().to_be_bytes());
            ip_payload[2..4].copy_from_slice(&dst.port().to_be_bytes());
            ip_payload[4..6].copy_from_slice(&udp_len.to_be_bytes());
            ip_payload[6..8].copy_from_slice(&[0, 0]);
            let data = ip_payload[8..].to_vec();
            let frags = cut(&ip_payload, frag);
            let mut w = PcapWriter::new(Vec::new()).unwrap();
            for (i, &k) in order.iter().enumerate() {
                let (offset, more, bytes) = &frags[k];
                let frame = fragment_frame(*src.ip(), *dst.ip(), 99, *offset, *more, bytes);
                w.write(1_700_000_000_000_000_000 + i as i64 * 1_000, &frame)
                    .unwrap();
            }
            let file = w.into_inner().unwrap();
            let mut source = PcapSource::new(&file[..]).unwrap();
            let mut got = Vec::new();
            while let Some(d) = source.next_datagram().unwrap() {
                got.push((d.src, d.dst, d.payload.to_vec()));
            }
            // Every fragment is used once; whether the duplicate lands before or after the set
            // completes, exactly one datagram comes out.
            prop_assert_eq!(got.len(), 1, "{:?}", source.stats());
            prop_assert_eq!(got[0].0, src);
            prop_assert_eq!(got[0].1, dst);
            prop_assert_eq!(&got[0].2, &data);
            // A single "fragment" (offset 0, no more fragments) is a plain datagram.
            prop_assert_eq!(source.stats().reassembled, u64::from(frags.len() > 1));
            Ok(())
        })
        .unwrap();
}

/// Found by the wrap property above (fixed in 8664547): the head starts at 359.90°, the second
/// firing of the first packet is at 0.23°, and a new sweep must start there — the first firing
/// whose azimuth is smaller than the previous one's by more than half a turn — even in the
/// stream's first packet, before any sweep is open.
#[test]
fn a_wrap_inside_the_first_packet_starts_a_new_sweep() {
    for mode in [ReturnMode::Strongest, ReturnMode::Dual] {
        let m = Motion {
            deg_per_s: 3_000.0,
            azimuth0_deg: 359.9,
            toh0_us: 1_000_000,
        };
        let mut sim = sim_for(VelodyneModel::Vlp16, mode, &m);
        // 60 packets at 3000°/s: 239°, no second wrap.
        let (sweeps, _) = stream_run(&mut sim, 60);
        assert_eq!(sweeps.len(), 2, "{mode}: sweeps cut at 0°");
        assert_eq!(sweeps[0].first_azimuth, 35_990, "{mode}");
        assert_eq!(
            sweeps[1].first_azimuth, 23,
            "{mode}: 359.9° + 3000°/s × 110.592 µs"
        );
    }
}
