//! Criterion benchmark: Robosense decoding next to Velodyne decoding, points per second on one
//! core, real packets held in memory.
//!
//! ```text
//! cargo bench --bench robosense_decode
//! ```
//! Inputs (from `../shared/captures`; the benchmark needs them): the nebula PR #79 RS-Helios-16P
//! capture (750 MSOP packets, single return) repeated 20 times, with `RobosenseHelios16P.csv`;
//! for comparison the nebula VLP-16 and VLS-128 captures with nebula's VLP16.yaml / VLS128.yaml,
//! through the Velodyne decoder. Every payload is loaded before timing; throughput is in
//! elements = points produced (`decoder/*`: the packet view and the decoder into one reused
//! buffer, cleared every 500 packets; `stream/*`: the whole stream — `RobosenseStream` /
//! `VelodyneStream` — sweeps cut and handed to a callback that counts their points).
//! The RS-LiDAR-M1 (`robosense-m1`) has no public capture here: its input is two frames (1260
//! MSOP packets, single return) from the simulator (`sim::M1Sim`, a sensor 1.8 m above the
//! urban scene), made before timing, through `M1Decoder` / `RobosenseStream`.
//! `RINGSCAN_CAPTURES` names the captures folder when it is not `../shared/captures` (a
//! worktree elsewhere).

use std::path::{Path, PathBuf};

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use ringscan::sensor::robosense::family::parse_robosense_calibration;
use ringscan::sensor::robosense::m1::{M1Decoder, M1Msop};
use ringscan::sensor::robosense::sim::M1Sim;
use ringscan::sensor::robosense::{
    Msop, RobosenseAngles, RobosenseConfig, RobosenseDecoder, RobosenseModel, RobosenseStream,
};
use ringscan::sensor::velodyne::calib::parse_velodyne;
use ringscan::sensor::velodyne::wire::DataPacket;
use ringscan::sensor::velodyne::{ReturnMode, VelodyneDecoder, VelodyneModel};
use ringscan::sensor::DecodeOptions;
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

const REPEAT: usize = 20;

fn helios_input(shared: &Path) -> (RobosenseAngles, Vec<(i64, Vec<u8>)>) {
    let pr = shared.join("tier4__nebula__pr79");
    let one = payloads(&first_pcap(
        &pr.join("nebula_tests/data/robosense/helios16P"),
    ));
    let span = one.last().unwrap().0 - one[0].0 + 1_000_000;
    // Repeated: the header clocks repeat too, which the stream counts as a discontinuity once
    // per copy (the decoder does not look at them).
    let mut v = Vec::with_capacity(one.len() * REPEAT);
    for k in 0..REPEAT {
        v.extend(one.iter().map(|(t, p)| (t + k as i64 * span, p.clone())));
    }
    let csv =
        std::fs::read(pr.join("nebula_decoders/calibration/robosense/RobosenseHelios16P.csv"))
            .unwrap();
    (parse_robosense_calibration(&csv).unwrap().unwrap(), v)
}

fn robosense_decoder_pass(
    dec: &RobosenseDecoder,
    packets: &[&[u8]],
    out: &mut Vec<Point>,
) -> usize {
    let mut n = 0;
    out.clear();
    for (i, p) in packets.iter().enumerate() {
        let Ok(p) = Msop::new(p, RobosenseModel::Helios16P) else {
            continue; // the DIFOP
        };
        dec.decode(&p, false, |d| {
            out.push(d.point);
            n += 1;
        });
        if i % 500 == 499 {
            black_box(&*out);
            out.clear();
        }
    }
    n
}

fn robosense_stream_pass(angles: &RobosenseAngles, input: &[(i64, Vec<u8>)]) -> u64 {
    let mut stream = RobosenseStream::new(RobosenseConfig::new(Some(angles.clone())));
    let mut points = 0u64;
    let mut cb = |s: &mut ringscan::sweep::Sweep, _: &_| points += s.points.len() as u64;
    for (t, p) in input {
        stream.push(*t, p, &mut cb).expect("stream");
    }
    stream.finish(&mut cb);
    points
}

fn m1_input() -> Vec<(i64, Vec<u8>)> {
    let scene = ringscan::sim::scenes::named("urban").expect("scene");
    let mut sim = M1Sim::new(1_714_564_800_000_000_000);
    sim.trajectory = ringscan::sim::motion::Trajectory::twist(
        sim.stamp0_ns,
        nalgebra::Isometry3::translation(40.0, 0.0, ringscan::sim::scenes::SENSOR_HEIGHT_M),
        nalgebra::Vector3::zeros(),
        nalgebra::Vector3::zeros(),
    );
    let mut truth = Vec::new();
    (0..1260)
        .map(|_| {
            truth.clear();
            sim.next_packet(&scene, &mut truth)
        })
        .collect()
}

fn m1_decoder_pass(dec: &M1Decoder, packets: &[&[u8]], out: &mut Vec<Point>) -> usize {
    let mut n = 0;
    out.clear();
    for (i, p) in packets.iter().enumerate() {
        let p = M1Msop::new(p).expect("an M1 packet");
        dec.decode(&p, |d| {
            out.push(d.point);
            n += 1;
        });
        if i % 500 == 499 {
            black_box(&*out);
            out.clear();
        }
    }
    n
}

fn m1_stream_pass(input: &[(i64, Vec<u8>)]) -> u64 {
    let mut stream = RobosenseStream::new(RobosenseConfig::new(None));
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
    let shared = std::env::var_os("RINGSCAN_CAPTURES").map_or_else(
        || PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/captures"),
        PathBuf::from,
    );
    assert!(shared.is_dir(), "{} is needed", shared.display());

    let (angles, input) = helios_input(&shared);
    let packets: Vec<&[u8]> = input.iter().map(|(_, p)| p.as_slice()).collect();
    let dec = RobosenseDecoder::new(RobosenseModel::Helios16P, &angles, DecodeOptions::default())
        .unwrap();
    let mut out = Vec::with_capacity(100_000);
    let points = robosense_decoder_pass(&dec, &packets, &mut out) as u64;
    let mut g = c.benchmark_group("decoder");
    g.throughput(Throughput::Elements(points));
    g.bench_function("robosense-helios16p", |b| {
        b.iter(|| black_box(robosense_decoder_pass(&dec, black_box(&packets), &mut out)))
    });
    g.finish();
    let stream_points = robosense_stream_pass(&angles, &input);
    let mut g = c.benchmark_group("stream");
    g.throughput(Throughput::Elements(stream_points));
    g.bench_function("robosense-helios16p", |b| {
        b.iter(|| black_box(robosense_stream_pass(&angles, black_box(&input))))
    });
    g.finish();

    let m1 = m1_input();
    let m1_packets: Vec<&[u8]> = m1.iter().map(|(_, p)| p.as_slice()).collect();
    let m1_dec = M1Decoder::new(DecodeOptions::default());
    let points = m1_decoder_pass(&m1_dec, &m1_packets, &mut out) as u64;
    let mut g = c.benchmark_group("decoder");
    g.throughput(Throughput::Elements(points));
    g.bench_function("robosense-m1", |b| {
        b.iter(|| black_box(m1_decoder_pass(&m1_dec, black_box(&m1_packets), &mut out)))
    });
    g.finish();
    let stream_points = m1_stream_pass(&m1);
    assert_eq!(stream_points, points);
    let mut g = c.benchmark_group("stream");
    g.throughput(Throughput::Elements(stream_points));
    g.bench_function("robosense-m1", |b| {
        b.iter(|| black_box(m1_stream_pass(black_box(&m1))))
    });
    g.finish();

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
