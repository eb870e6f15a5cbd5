//! Criterion benchmark of the Velodyne decode path on real packets held in memory.
//!
//! ```text
//! cargo bench --bench decode
//! ```
//! Inputs: the HDL-32E Monterey capture and the VLP-16 `velodyne_example.pcap` from
//! `../shared/captures` with the calibrations the goldens use, when that folder is there; else
//! the simulated VLP-16 fixture `fixtures/demo-vlp16.pcap` with the built-in calibration.
//! Every payload is loaded before timing. Throughput is in elements = points produced.
//!
//! * `decoder/<input>`: `DataPacket::new` + `VelodyneDecoder::decode` over every data packet,
//!   into one reused `Vec<Point>`, cleared at every rotation (as a sweep buffer is);
//! * `stream/<input>`: the full `VelodyneStream` path (data and position packets with their
//!   host times; sweeps cut and handed to a callback that counts their points).

use std::path::{Path, PathBuf};

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use ringscan::sensor::velodyne::calib::builtin::builtin;
use ringscan::sensor::velodyne::calib::parse_velodyne;
use ringscan::sensor::velodyne::calib::VelodyneCalibration;
use ringscan::sensor::velodyne::wire::DataPacket;
use ringscan::sensor::velodyne::ReturnMode;
use ringscan::sensor::velodyne::SensorFacts;
use ringscan::sensor::velodyne::StreamConfig;
use ringscan::sensor::velodyne::VelodyneDecoder;
use ringscan::sensor::velodyne::VelodyneModel;
use ringscan::sensor::velodyne::VelodyneStream;
use ringscan::sensor::DecodeOptions;
use ringscan::source::pcap::PcapSource;
use ringscan::sweep::Sweep;
use ringscan::Point;

struct Input {
    name: &'static str,
    model: VelodyneModel,
    calib: VelodyneCalibration,
    /// Every UDP payload with its host time.
    datagrams: Vec<(i64, Vec<u8>)>,
}

fn load(
    name: &'static str,
    pcap: &Path,
    model: VelodyneModel,
    calib: Option<&Path>,
) -> Option<Input> {
    let mut src = PcapSource::open(pcap).ok()?;
    let mut datagrams = Vec::new();
    while let Ok(Some(d)) = src.next_datagram() {
        datagrams.push((d.time_ns, d.payload.to_vec()));
    }
    let calib = match calib {
        Some(f) => {
            let text = std::fs::read_to_string(f).ok()?;
            let file = f.file_name()?.to_string_lossy().into_owned();
            parse_velodyne(&text, &file).ok()?
        }
        None => builtin(model)?,
    };
    Some(Input {
        name,
        model,
        calib,
        datagrams,
    })
}

fn inputs() -> Vec<Input> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let shared = root.join("../shared/captures");
    let params = shared.join("ros-drivers__velodyne/velodyne_pointcloud/params");
    let mut v = Vec::new();
    if shared.is_dir() {
        v.extend(load(
            "hdl32e-monterey",
            &shared.join("Kitware__VeloView/Testing/Data/monterey-first-100-packets.pcap"),
            VelodyneModel::Hdl32e,
            Some(&params.join("32db.yaml")),
        ));
        v.extend(load(
            "vlp16-example",
            &shared.join("jerry73204__rust-lidar-utils/test_files/velodyne_example.pcap"),
            VelodyneModel::Vlp16,
            Some(&params.join("VLP16db.yaml")),
        ));
    }
    if v.is_empty() {
        v.extend(load(
            "vlp16-demo-fixture",
            &root.join("fixtures/demo-vlp16.pcap"),
            VelodyneModel::Vlp16,
            None,
        ));
    }
    assert!(!v.is_empty(), "no capture to benchmark");
    v
}

/// For each packet: whether it completes a rotation (its block-0 azimuth has covered a full turn
/// since the first packet of the rotation), the grouping of tools/bench/decode_mem.rs.
fn rotation_ends(packets: &[&[u8]]) -> Vec<bool> {
    let (mut covered, mut prev) = (0u32, None::<u32>);
    packets
        .iter()
        .map(|p| {
            let az = u32::from(u16::from_le_bytes([p[2], p[3]]));
            if let Some(q) = prev {
                covered += (az + 36_000 - q) % 36_000;
            }
            prev = Some(az);
            let end = covered >= 36_000 - 1;
            if end {
                covered = 0;
                prev = None;
            }
            end
        })
        .collect()
}

fn decoder_pass(
    dec: &VelodyneDecoder,
    packets: &[&[u8]],
    ends: &[bool],
    out: &mut Vec<Point>,
) -> usize {
    let mut n = 0;
    out.clear();
    for (p, &end) in packets.iter().zip(ends) {
        let p = DataPacket::new(p).expect("1206 bytes");
        n += dec.decode(&p, 0, out).points;
        if end {
            black_box(&*out);
            out.clear();
        }
    }
    n
}

fn stream_pass(input: &Input) -> u64 {
    let cfg = StreamConfig {
        model: Some(input.model),
        calibrations: vec![input.calib.clone()],
        ..StreamConfig::default()
    };
    let mut stream = VelodyneStream::new(cfg);
    let mut points = 0u64;
    let mut cb = |s: &mut Sweep, _: &SensorFacts| points += s.points.len() as u64;
    for (t, p) in &input.datagrams {
        stream.push(*t, p, &mut cb).expect("stream");
    }
    stream.finish(&mut cb).expect("stream");
    points
}

fn bench(c: &mut Criterion) {
    for input in inputs() {
        let packets: Vec<&[u8]> = input
            .datagrams
            .iter()
            .map(|(_, p)| p.as_slice())
            .filter(|p| p.len() == 1206)
            .collect();
        let mode = ReturnMode::from_byte(packets[0][1204]).unwrap_or(ReturnMode::Strongest);
        let dec = VelodyneDecoder::new(input.model, mode, &input.calib, DecodeOptions::default())
            .expect("decoder");
        let ends = rotation_ends(&packets);
        let mut out = Vec::with_capacity(100_000);
        let points = decoder_pass(&dec, &packets, &ends, &mut out) as u64;

        let mut g = c.benchmark_group("decoder");
        g.throughput(Throughput::Elements(points));
        g.bench_function(input.name, |b| {
            b.iter(|| black_box(decoder_pass(&dec, black_box(&packets), &ends, &mut out)))
        });
        g.finish();

        let stream_points = stream_pass(&input);
        let mut g = c.benchmark_group("stream");
        g.throughput(Throughput::Elements(stream_points));
        g.bench_function(input.name, |b| {
            b.iter(|| black_box(stream_pass(black_box(&input))))
        });
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
