//! Criterion benchmark: Livox MID-360 decoding next to Velodyne decoding, points per second on
//! one core, packets held in memory.
//!
//! ```text
//! cargo bench --bench livox_decode
//! ```
//! Inputs: 2 s of simulated MID-360 packets (data type 1, 96 points a packet, the urban scene
//! from a moving sensor: 4 167 packets, every record a return where the ray hits), made before
//! timing by `sensor::livox::sim`; for comparison the nebula VLP-16 capture from
//! `../shared/captures` with nebula's VLP16.yaml through the Velodyne decoder (skipped, with a
//! note, when `../shared` is absent). Throughput is in elements = points produced
//! (`decoder/*`: the packet view and the decoder into one reused buffer, cleared every 500
//! packets; `stream/*`: the whole stream, sweeps cut and handed to a callback).

use std::path::{Path, PathBuf};

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use ringscan::sensor::livox::decode::Spacing;
use ringscan::sensor::livox::model::LivoxModel;
use ringscan::sensor::livox::sim::LivoxSim;
use ringscan::sensor::livox::{LivoxConfig, LivoxDecoder, LivoxStream, Sdk2Packet};
use ringscan::sensor::velodyne::calib::parse_velodyne;
use ringscan::sensor::velodyne::wire::DataPacket;
use ringscan::sensor::velodyne::{ReturnMode, VelodyneDecoder, VelodyneModel};
use ringscan::sensor::DecodeOptions;
use ringscan::sim::motion::{Route, Trajectory};
use ringscan::sim::scenes;
use ringscan::source::pcap::PcapSource;
use ringscan::Point;

const T0: i64 = 1_714_564_800_000_000_000;

fn mid360_input() -> Vec<(i64, Vec<u8>)> {
    let world = scenes::urban();
    let mut sim = LivoxSim::new(LivoxModel::Mid360, T0);
    sim.trajectory = Trajectory::route(T0, Route::urban());
    let mut truth = Vec::new();
    let mut v = Vec::new();
    for _ in 0..4_167 {
        v.push(sim.next_packet(&world, &mut truth));
        truth.clear();
    }
    v
}

fn livox_decoder_pass(dec: &LivoxDecoder, packets: &[&[u8]], out: &mut Vec<Point>) -> usize {
    let mut n = 0;
    out.clear();
    for (i, b) in packets.iter().enumerate() {
        let p = Sdk2Packet::new(b).expect("SDK2 packet");
        let (k, iv) = (p.records(), p.time_interval_ns());
        n += dec
            .decode(
                p.record(),
                k,
                |j| p.record_bytes(j),
                0,
                Spacing::sdk2(k, iv),
                0,
                out,
            )
            .points;
        if i % 500 == 499 {
            black_box(&*out);
            out.clear();
        }
    }
    n
}

fn livox_stream_pass(input: &[(i64, Vec<u8>)]) -> u64 {
    let mut s = LivoxStream::new(LivoxConfig::new(
        Some(LivoxModel::Mid360),
        LivoxModel::Mid360.protocol(),
    ));
    let mut points = 0u64;
    let mut cb = |sw: &mut ringscan::sweep::Sweep, _: &_| points += sw.points.len() as u64;
    for (t, p) in input {
        s.push(*t, p, &mut cb);
    }
    s.finish(&mut cb);
    points
}

fn payloads(pcap: &Path) -> Vec<(i64, Vec<u8>)> {
    let mut src = PcapSource::open(pcap).expect("capture");
    let mut v = Vec::new();
    while let Ok(Some(d)) = src.next_datagram() {
        v.push((d.time_ns, d.payload.to_vec()));
    }
    v
}

fn first_pcap(dir: &Path) -> Option<PathBuf> {
    for e in std::fs::read_dir(dir).ok()?.flatten() {
        if e.path().is_dir() {
            for f in std::fs::read_dir(e.path()).ok()?.flatten() {
                if f.path().extension().is_some_and(|x| x == "pcap") {
                    return Some(f.path());
                }
            }
        }
    }
    None
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

fn bench(c: &mut Criterion) {
    let input = mid360_input();
    let packets: Vec<&[u8]> = input.iter().map(|(_, p)| p.as_slice()).collect();
    let dec = LivoxDecoder::new(4, DecodeOptions::default());
    let mut out = Vec::with_capacity(100_000);
    let points = livox_decoder_pass(&dec, &packets, &mut out) as u64;
    let mut g = c.benchmark_group("decoder");
    g.throughput(Throughput::Elements(points));
    g.bench_function("livox-mid360", |b| {
        b.iter(|| black_box(livox_decoder_pass(&dec, black_box(&packets), &mut out)))
    });
    g.finish();
    let stream_points = livox_stream_pass(&input);
    let mut g = c.benchmark_group("stream");
    g.throughput(Throughput::Elements(stream_points));
    g.bench_function("livox-mid360", |b| {
        b.iter(|| black_box(livox_stream_pass(black_box(&input))))
    });
    g.finish();

    let vel = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/captures/tier4__nebula/src/nebula_velodyne");
    let Some(pcap) =
        first_pcap(&vel.join("nebula_velodyne/test_resources/decoder_ground_truth/vlp16"))
    else {
        eprintln!("../shared/captures absent: the Velodyne comparison is skipped");
        return;
    };
    let one = payloads(&pcap);
    let text = std::fs::read_to_string(vel.join("nebula_velodyne_decoders/calibration/VLP16.yaml"))
        .unwrap();
    let cal = parse_velodyne(&text, "VLP16.yaml").unwrap();
    let packets: Vec<&[u8]> = one
        .iter()
        .map(|(_, p)| p.as_slice())
        .filter(|p| p.len() == 1206)
        .collect();
    let mode = ReturnMode::from_byte(packets[0][1204]).unwrap_or(ReturnMode::Strongest);
    let dec =
        VelodyneDecoder::new(VelodyneModel::Vlp16, mode, &cal, DecodeOptions::default()).unwrap();
    let points = velodyne_decoder_pass(&dec, &packets, &mut out) as u64;
    let mut g = c.benchmark_group("decoder");
    g.throughput(Throughput::Elements(points));
    g.bench_function("velodyne-vlp16", |b| {
        b.iter(|| black_box(velodyne_decoder_pass(&dec, black_box(&packets), &mut out)))
    });
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20).measurement_time(std::time::Duration::from_secs(5));
    targets = bench
}
criterion_main!(benches);
