//! Criterion benchmark: Hesai decoding next to Velodyne decoding, points per second on one
//! core, real packets held in memory.
//!
//! ```text
//! cargo bench --bench hesai_decode
//! ```
//! Inputs (from `../shared/captures`; the benchmark needs them): the nebula PandarXT32 capture
//! (2 000 packets, dual return) repeated 10 times, with `PandarXT32.csv`; for comparison the
//! nebula VLP-16 and VLS-128 captures with nebula's VLP16.yaml / VLS128.yaml, through the
//! Velodyne decoder. The AT128, of which no real capture exists, on 0.5 s of the simulator's
//! packets (urban scene, single return) with the real `PandarAT128.dat`; the ATX likewise, with
//! a correction written in the benchmark (no ATX file is shared). Every payload is loaded before timing; throughput is in elements = points
//! produced (`decoder/*`: the packet view and the decoder into one reused buffer, cleared every
//! 500 packets; `stream/*`: the whole stream — `HesaiStream` / `VelodyneStream` — sweeps cut
//! and handed to a callback that counts their points).

use std::path::{Path, PathBuf};

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use ringscan::sensor::hesai::family::parse_hesai_calibration;
use ringscan::sensor::hesai::sim::HesaiSim;
use ringscan::sensor::hesai::{
    HesaiCalibration, HesaiConfig, HesaiDecoder, HesaiModel, HesaiOptions, HesaiPacket, HesaiStream,
};
use ringscan::sensor::velodyne::calib::parse_velodyne;
use ringscan::sensor::velodyne::wire::DataPacket;
use ringscan::sensor::velodyne::{ReturnMode, VelodyneDecoder, VelodyneModel};
use ringscan::sensor::DecodeOptions;
use ringscan::sim::motion::Trajectory;
use ringscan::sim::scenes;
use ringscan::source::pcap::PcapSource;
use ringscan::Point;

fn payloads(pcap: &Path) -> Vec<(i64, Vec<u8>)> {
    let mut src = PcapSource::open(pcap).expect("capture");
    let mut v = Vec::new();
    while let Ok(Some(d)) = src.next_datagram() {
        v.push((d.time_ns, d.payload.to_vec()));
    }
    v
}

fn first_pcap(dir: &Path) -> PathBuf {
    for e in std::fs::read_dir(dir).expect("folder").flatten() {
        if e.path().is_dir() {
            for f in std::fs::read_dir(e.path()).unwrap().flatten() {
                if f.path().extension().is_some_and(|x| x == "pcap") {
                    return f.path();
                }
            }
        }
    }
    panic!("no pcap under {}", dir.display())
}

const REPEAT: usize = 10;

fn hesai_input(shared: &Path) -> (HesaiCalibration, Vec<(i64, Vec<u8>)>) {
    let gt = shared
        .join("tier4__nebula/src/nebula_hesai/nebula_hesai/test_resources/decoder_ground_truth");
    let one = payloads(&first_pcap(&gt.join("xt32")));
    let span = one.last().unwrap().0 - one[0].0 + 200_000;
    // Repeated: the tail clocks repeat too, which the stream counts as a discontinuity once per
    // copy (the decoder does not look at them).
    let mut v = Vec::with_capacity(one.len() * REPEAT);
    for k in 0..REPEAT {
        v.extend(one.iter().map(|(t, p)| (t + k as i64 * span, p.clone())));
    }
    let csv =
        std::fs::read(shared.join(
            "tier4__nebula/src/nebula_hesai/nebula_hesai_decoders/calibration/PandarXT32.csv",
        ))
        .unwrap();
    (parse_hesai_calibration(&csv).unwrap().unwrap(), v)
}

fn at128_input(shared: &Path) -> (HesaiCalibration, Vec<(i64, Vec<u8>)>) {
    let dat =
        std::fs::read(shared.join(
            "tier4__nebula/src/nebula_hesai/nebula_hesai_decoders/calibration/PandarAT128.dat",
        ))
        .unwrap();
    let calib = parse_hesai_calibration(&dat).unwrap().unwrap();
    simulated(HesaiModel::PandarAt128, calib)
}

/// 0.5 s of the simulated Pandar ATX (urban scene, single return) with a correction written
/// here (version 4.3, 100 channels: per-frame azimuths and the elevation adjustment, the
/// decoder's most expensive ATX form).
fn atx_input() -> (HesaiCalibration, Vec<(i64, Vec<u8>)>) {
    let mut b = vec![0xEE, 0xFF, 4, 3, 0, 0, 100];
    b.extend_from_slice(&256u16.to_le_bytes());
    let mut put = |v: f64| b.extend_from_slice(&((v * 256.0).round() as i16).to_le_bytes());
    for odd in [0.0, 0.05] {
        for c in 0..100 {
            put((c % 4) as f64 - 2.0 + odd);
        }
    }
    for c in 0..100 {
        put(12.5 - 25.0 * c as f64 / 99.0);
    }
    for i in 0..70 {
        put(0.04 * ((i % 10) as f64 - 5.0));
    }
    b.extend_from_slice(&[0; 32]);
    let calib = parse_hesai_calibration(&b).unwrap().unwrap();
    simulated(HesaiModel::PandarAtx, calib)
}

fn simulated(
    model: HesaiModel,
    calib: HesaiCalibration,
) -> (HesaiCalibration, Vec<(i64, Vec<u8>)>) {
    let t0 = 1_714_564_800_000_000_000;
    let mut sim = HesaiSim::new(model, calib.clone(), t0);
    sim.trajectory = Trajectory::fixed(nalgebra::Isometry3::translation(
        40.0,
        0.0,
        scenes::SENSOR_HEIGHT_M,
    ));
    let scene = scenes::named("urban").unwrap();
    let n = (500_000_000 / sim.period_ns()) as usize;
    let mut truth = Vec::new();
    let v = (0..n)
        .map(|_| {
            truth.clear();
            sim.next_packet(&scene, &mut truth)
        })
        .collect();
    (calib, v)
}

fn hesai_decoder_pass(
    model: HesaiModel,
    dec: &mut HesaiDecoder,
    packets: &[&[u8]],
    out: &mut Vec<Point>,
) -> usize {
    let mut n = 0;
    out.clear();
    for (i, p) in packets.iter().enumerate() {
        let p = HesaiPacket::new(p, model).expect("packet of the model");
        n += dec.decode_packet(&p, 0, 0, out).unwrap_or(0);
        if i % 500 == 499 {
            black_box(&*out);
            out.clear();
        }
    }
    n
}

fn hesai_stream_pass(calib: &HesaiCalibration, input: &[(i64, Vec<u8>)]) -> u64 {
    let mut stream = HesaiStream::new(HesaiConfig::new(Some(calib.clone()), "bench"));
    let mut points = 0u64;
    let mut cb = |s: &mut ringscan::sweep::Sweep, _: &_| points += s.points.len() as u64;
    for (t, p) in input {
        stream.push(*t, p, &mut cb).expect("stream");
    }
    stream.finish(&mut cb);
    points
}

fn velodyne_decoder_pass(dec: &VelodyneDecoder, packets: &[&[u8]], out: &mut Vec<Point>) -> usize {
    let mut n = 0;
    out.clear();
    for (i, p) in packets.iter().enumerate() {
        let p = DataPacket::new(p).expect("1206 bytes");
        n += dec.decode(&p, 0, out).points;
        if i % 500 == 499 {
            black_box(&*out);
            out.clear();
        }
    }
    n
}

fn velodyne_stream_pass(
    model: VelodyneModel,
    cal: &ringscan::sensor::velodyne::VelodyneCalibration,
    input: &[(i64, Vec<u8>)],
) -> u64 {
    let cfg = ringscan::sensor::velodyne::StreamConfig {
        model: Some(model),
        calibrations: vec![cal.clone()],
        ..Default::default()
    };
    let mut stream = ringscan::sensor::velodyne::VelodyneStream::new(cfg);
    let mut points = 0u64;
    let mut cb = |s: &mut ringscan::sweep::Sweep, _: &_| points += s.points.len() as u64;
    for (t, p) in input {
        stream.push(*t, p, &mut cb).expect("stream");
    }
    stream.finish(&mut cb).expect("stream");
    points
}

fn bench(c: &mut Criterion) {
    let shared = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/captures");
    assert!(shared.is_dir(), "{} is needed", shared.display());

    let mut out = Vec::with_capacity(100_000);
    // Hesai XT32 (real packets) and AT128 (simulated).
    for (name, model, (calib, input)) in [
        ("hesai-xt32", HesaiModel::PandarXt32, hesai_input(&shared)),
        ("hesai-at128", HesaiModel::PandarAt128, at128_input(&shared)),
        ("hesai-atx", HesaiModel::PandarAtx, atx_input()),
    ] {
        let packets: Vec<&[u8]> = input.iter().map(|(_, p)| p.as_slice()).collect();
        let mut dec = HesaiDecoder::new(model, &calib, HesaiOptions::default()).unwrap();
        let points = hesai_decoder_pass(model, &mut dec, &packets, &mut out) as u64;
        let mut g = c.benchmark_group("decoder");
        g.throughput(Throughput::Elements(points));
        g.bench_function(name, |b| {
            b.iter(|| {
                black_box(hesai_decoder_pass(
                    model,
                    &mut dec,
                    black_box(&packets),
                    &mut out,
                ))
            })
        });
        g.finish();
        let stream_points = hesai_stream_pass(&calib, &input);
        let mut g = c.benchmark_group("stream");
        g.throughput(Throughput::Elements(stream_points));
        g.bench_function(name, |b| {
            b.iter(|| black_box(hesai_stream_pass(&calib, black_box(&input))))
        });
        g.finish();
    }

    // Velodyne, same harness.
    let vel = shared.join("tier4__nebula/src/nebula_velodyne");
    for (name, dir, yaml, model) in [
        (
            "velodyne-vlp16",
            "vlp16",
            "VLP16.yaml",
            VelodyneModel::Vlp16,
        ),
        (
            "velodyne-vls128",
            "vls128",
            "VLS128.yaml",
            VelodyneModel::Vls128,
        ),
    ] {
        let one = payloads(&first_pcap(
            &vel.join("nebula_velodyne/test_resources/decoder_ground_truth")
                .join(dir),
        ));
        let text =
            std::fs::read_to_string(vel.join("nebula_velodyne_decoders/calibration").join(yaml))
                .unwrap();
        let cal = parse_velodyne(&text, yaml).unwrap();
        let packets: Vec<&[u8]> = one
            .iter()
            .map(|(_, p)| p.as_slice())
            .filter(|p| p.len() == 1206)
            .collect();
        let mode = ReturnMode::from_byte(packets[0][1204]).unwrap_or(ReturnMode::Strongest);
        let dec = VelodyneDecoder::new(model, mode, &cal, DecodeOptions::default()).unwrap();
        let points = velodyne_decoder_pass(&dec, &packets, &mut out) as u64;
        let mut g = c.benchmark_group("decoder");
        g.throughput(Throughput::Elements(points));
        g.bench_function(name, |b| {
            b.iter(|| black_box(velodyne_decoder_pass(&dec, black_box(&packets), &mut out)))
        });
        g.finish();
        let stream_points = velodyne_stream_pass(model, &cal, &one);
        let mut g = c.benchmark_group("stream");
        g.throughput(Throughput::Elements(stream_points));
        g.bench_function(name, |b| {
            b.iter(|| black_box(velodyne_stream_pass(model, &cal, black_box(&one))))
        });
        g.finish();
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20).measurement_time(std::time::Duration::from_secs(5));
    targets = bench
}
criterion_main!(benches);
