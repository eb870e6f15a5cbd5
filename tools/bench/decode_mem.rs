//! ringscan's decoder on packets held in memory (the in-memory half of tools/bench_velodyne.sh).
//!
//! ```text
//! cargo run --release --example bench_decode_mem -- CAPTURE --model hdl32e --calib FILE [--repeat 3]
//! ```
//! Loads every UDP payload of CAPTURE (with its pcap time) into memory first (not timed), then
//! times, single-threaded, each `--repeat` times (the best run is reported, every run listed):
//!
//! * `ringscan_decoder_in_memory`: `DataPacket::new` + `VelodyneDecoder::decode` over every
//!   1206-byte payload, appending to one reused `Vec<Point>` that is cleared at each rotation
//!   (the packet whose block-0 azimuth completes a turn, the grouping tools/bench/vd_bench.py
//!   gives velodyne_decoder's `ScanDecoder`);
//! * `ringscan_stream_in_memory`: the full `VelodyneStream` path (every payload, data and
//!   position, pushed with its host time: layout checks, device time, loss accounting, sweep
//!   cutting, the sweep's point buffer).
//!
//! Prints one JSON object per line.

use std::path::Path;
use std::time::Instant;

use ringscan::sensor::velodyne::calib::builtin::builtin;
use ringscan::sensor::velodyne::calib::parse_velodyne;
use ringscan::sensor::velodyne::calib::VelodyneCalibration;
use ringscan::sensor::velodyne::wire::DataPacket;
use ringscan::sensor::velodyne::ReturnMode;
use ringscan::sensor::velodyne::StreamConfig;
use ringscan::sensor::velodyne::VelodyneDecoder;
use ringscan::sensor::velodyne::VelodyneModel;
use ringscan::sensor::velodyne::VelodyneStream;
use ringscan::sensor::DecodeOptions;
use ringscan::source::pcap::PcapSource;
use ringscan::Point;

const DATA_LEN: usize = 1206;

fn arg(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn die(msg: String) -> ! {
    eprintln!("bench_decode_mem: {msg}");
    std::process::exit(2)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first().filter(|a| !a.starts_with("--")).cloned() else {
        die("usage: bench_decode_mem CAPTURE --model M [--calib FILE] [--repeat N]".into())
    };
    let model_id = arg(&args, "--model").unwrap_or_else(|| "hdl32e".into());
    let model = VelodyneModel::from_id(&model_id)
        .unwrap_or_else(|| die(format!("unknown model {model_id}")));
    let repeat: usize = arg(&args, "--repeat")
        .and_then(|r| r.parse().ok())
        .unwrap_or(3)
        .max(1);
    let calib: VelodyneCalibration = match arg(&args, "--calib") {
        Some(f) => {
            let text = std::fs::read_to_string(&f).unwrap_or_else(|e| die(format!("{f}: {e}")));
            let name = Path::new(&f)
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            parse_velodyne(&text, &name).unwrap_or_else(|e| die(format!("{f}: {e}")))
        }
        None => builtin(model).unwrap_or_else(|| die(format!("{model_id} needs --calib"))),
    };

    // Load: all payloads back to back, with (host time, offset, length).
    let t0 = Instant::now();
    let mut src =
        PcapSource::open(Path::new(&path)).unwrap_or_else(|e| die(format!("{path}: {e}")));
    let mut bytes: Vec<u8> = Vec::new();
    let mut all: Vec<(i64, usize, usize)> = Vec::new();
    let mut data: Vec<usize> = Vec::new(); // offsets of the 1206-byte payloads
    while let Some(d) = src
        .next_datagram()
        .unwrap_or_else(|e| die(format!("{path}: {e}")))
    {
        let off = bytes.len();
        bytes.extend_from_slice(d.payload);
        if d.payload.len() == DATA_LEN {
            data.push(off);
        }
        all.push((d.time_ns, off, d.payload.len()));
    }
    let load_s = t0.elapsed().as_secs_f64();
    let Some(&first) = data.first() else {
        die(format!("{path}: no 1206-byte payloads"))
    };
    let mode = ReturnMode::from_byte(bytes[first + 1204]).unwrap_or(ReturnMode::Strongest);
    let decoder = VelodyneDecoder::new(model, mode, &calib, DecodeOptions::default())
        .unwrap_or_else(|e| die(format!("decoder: {e}")));

    // Rotation boundaries, as vd_bench.py groups packets: after the packet whose block-0
    // azimuth has covered a full turn since the group's first packet.
    let mut ends_rotation = vec![false; data.len()];
    {
        let (mut covered, mut prev) = (0u32, None::<u32>);
        for (i, &off) in data.iter().enumerate() {
            let az = u32::from(u16::from_le_bytes([bytes[off + 2], bytes[off + 3]]));
            if let Some(p) = prev {
                covered += (az + 36_000 - p) % 36_000;
            }
            prev = Some(az);
            if covered >= 36_000 - 1 {
                ends_rotation[i] = true;
                covered = 0;
                prev = None;
            }
        }
    }

    // 1. The decoder alone.
    let mut runs = Vec::new();
    let mut points = 0u64;
    let mut out: Vec<Point> = Vec::with_capacity(100_000);
    for _ in 0..repeat {
        points = 0;
        out.clear();
        let t = Instant::now();
        for (i, &off) in data.iter().enumerate() {
            let p = DataPacket::new(&bytes[off..off + DATA_LEN])
                .unwrap_or_else(|e| die(format!("packet: {e}")));
            let n = decoder.decode(&p, 0, &mut out);
            points += n.points as u64;
            if ends_rotation[i] {
                std::hint::black_box(&out);
                out.clear();
            }
        }
        std::hint::black_box(&out);
        runs.push(t.elapsed().as_secs_f64());
    }
    report(
        "ringscan_decoder_in_memory",
        points,
        data.len(),
        &runs,
        load_s,
    );

    // 2. The full stream path.
    let mut runs = Vec::new();
    let mut points = 0u64;
    let mut sweeps = 0u64;
    for _ in 0..repeat {
        let cfg = StreamConfig {
            model: Some(model),
            calibrations: vec![calib.clone()],
            ..StreamConfig::default()
        };
        let mut stream = VelodyneStream::new(cfg);
        points = 0;
        sweeps = 0;
        let t = Instant::now();
        let mut on_sweep =
            |s: &mut ringscan::sweep::Sweep, _: &ringscan::sensor::velodyne::SensorFacts| {
                points += s.points.len() as u64;
                sweeps += 1;
            };
        for &(time, off, len) in &all {
            stream
                .push(time, &bytes[off..off + len], &mut on_sweep)
                .unwrap_or_else(|e| die(format!("stream: {e}")));
        }
        stream
            .finish(&mut on_sweep)
            .unwrap_or_else(|e| die(format!("stream: {e}")));
        runs.push(t.elapsed().as_secs_f64());
    }
    report(
        "ringscan_stream_in_memory",
        points,
        data.len(),
        &runs,
        load_s,
    );
    eprintln!("bench_decode_mem: {sweeps} sweeps in the stream path");
}

fn report(what: &str, points: u64, packets: usize, runs: &[f64], load_s: f64) {
    let best = runs.iter().copied().fold(f64::INFINITY, f64::min);
    let runs_s: Vec<String> = runs.iter().map(|r| format!("{r:.6}")).collect();
    println!(
        "{{\"what\": \"{what}\", \"points\": {points}, \"packets\": {packets}, \"wall_s\": {best:.6}, \"runs_s\": [{}], \"points_per_s\": {:.1}, \"load_s\": {load_s:.6}}}",
        runs_s.join(", "),
        points as f64 / best
    );
}
