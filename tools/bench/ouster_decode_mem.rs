//! ringscan's Ouster decoder on packets held in memory (the in-memory half of
//! tools/bench_ouster.sh).
//!
//! ```text
//! cargo run --release --example bench_ouster_decode_mem -- CAPTURE --calib META.json [--repeat 3]
//! ```
//! Loads every UDP payload of CAPTURE (with its pcap time) into memory first (not timed), then
//! times, single-threaded, each `--repeat` times (the best run is reported, every run listed):
//!
//! * `ringscan_ouster_decoder_in_memory`: `OusterDecoder::packet` (length and sensor checks) +
//!   `OusterDecoder::decode` of every lidar payload into one reused `Vec<Point>`, cleared at
//!   each new `frame_id` (points with range > 0, xyz from the table);
//! * `ringscan_ouster_frame_in_memory`: `OusterDecoder::decode_packet_into_frame` into one
//!   reused organised `OusterFrame` (every pixel's range, reflectivity, signal, near-IR, flags
//!   and xyz, as ouster-sdk's `LidarFrame` + `XYZLut`), cleared per frame;
//! * `ringscan_ouster_stream_in_memory`: the full `OusterStream` path of `ringscan decode`
//!   (every payload, lidar and IMU, pushed with its host time: checks, frame cutting, missing
//!   columns, the sweep's point buffer).
//!
//! Pixels = frames × H × W. Prints one JSON object per line.

use std::path::Path;
use std::time::Instant;

use ringscan::sensor::ouster::calib::parse;
use ringscan::sensor::ouster::OusterDecoder;
use ringscan::sensor::ouster::OusterStream;
use ringscan::sensor::ouster::OusterStreamConfig;
use ringscan::sensor::DecodeOptions;
use ringscan::source::pcap::PcapSource;
use ringscan::Point;

fn arg(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn die(msg: String) -> ! {
    eprintln!("bench_ouster_decode_mem: {msg}");
    std::process::exit(2)
}

struct Run {
    name: &'static str,
    frames: u64,
    points: u64,
    secs: f64,
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first().filter(|a| !a.starts_with("--")).cloned() else {
        die(
            "usage: bench_ouster_decode_mem CAPTURE --calib META.json [--repeat N] [--only NAME]"
                .into(),
        )
    };
    let meta = arg(&args, "--calib").unwrap_or_else(|| die("--calib META.json is needed".into()));
    let repeat: usize = arg(&args, "--repeat")
        .and_then(|r| r.parse().ok())
        .unwrap_or(3)
        .max(1);
    let only = arg(&args, "--only");
    let text = std::fs::read_to_string(&meta).unwrap_or_else(|e| die(format!("{meta}: {e}")));
    let info = parse(&text, &meta).unwrap_or_else(|e| die(format!("{meta}: {e}")));
    let lidar_len = info.lidar_packet_bytes();
    let (h, w) = (info.pixels_per_column(), info.columns_per_frame);

    // Load: all payloads back to back, with (host time, offset, length).
    let t0 = Instant::now();
    let mut src =
        PcapSource::open(Path::new(&path)).unwrap_or_else(|e| die(format!("{path}: {e}")));
    let mut bytes: Vec<u8> = Vec::new();
    let mut all: Vec<(i64, usize, usize)> = Vec::new();
    while let Some(d) = src
        .next_datagram()
        .unwrap_or_else(|e| die(format!("{path}: {e}")))
    {
        all.push((d.time_ns, bytes.len(), d.payload.len()));
        bytes.extend_from_slice(d.payload);
    }
    let lidar: Vec<&[u8]> = all
        .iter()
        .filter(|&&(_, _, n)| n == lidar_len)
        .map(|&(_, o, n)| &bytes[o..o + n])
        .collect();
    eprintln!(
        "loaded {} payloads ({} lidar, {:.1} MB) in {:.2} s",
        all.len(),
        lidar.len(),
        bytes.len() as f64 / 1e6,
        t0.elapsed().as_secs_f64()
    );
    let decoder = OusterDecoder::new(&info).unwrap_or_else(|e| die(format!("{meta}: {e}")));
    let wanted = |n: &str| only.as_deref().is_none_or(|o| n.contains(o));

    let mut runs: Vec<Run> = Vec::new();
    for _ in 0..repeat {
        if wanted("ringscan_ouster_decoder_in_memory") {
            let mut out: Vec<Point> = Vec::with_capacity(h * w * decoder.returns());
            let (mut frames, mut points, mut fid) = (0u64, 0u64, None);
            let t = Instant::now();
            for p in &lidar {
                let Ok(view) = decoder.packet(p) else {
                    continue;
                };
                if fid != Some(view.frame_id()) {
                    fid = Some(view.frame_id());
                    frames += 1;
                    points += out.len() as u64;
                    out.clear();
                }
                let start = view.column(0).map_or(0, |c| c.timestamp_ns());
                let _ = decoder.decode(&view, start, &mut out);
            }
            points += out.len() as u64;
            runs.push(Run {
                name: "ringscan_ouster_decoder_in_memory",
                frames,
                points,
                secs: t.elapsed().as_secs_f64(),
            });
        }
        if wanted("ringscan_ouster_frame_in_memory") {
            let mut frame = decoder.new_frame();
            let (mut frames, mut points) = (0u64, 0u64);
            let t = Instant::now();
            for p in &lidar {
                let Ok(view) = decoder.packet(p) else {
                    continue;
                };
                if frame.frame_id.is_some_and(|f| f != view.frame_id()) {
                    points += (0..frame.returns)
                        .map(|r| frame.points(r) as u64)
                        .sum::<u64>();
                    frames += 1;
                    frame.clear();
                }
                let _ = decoder.decode_packet_into_frame(&view, &mut frame);
            }
            if frame.frame_id.is_some() {
                points += (0..frame.returns)
                    .map(|r| frame.points(r) as u64)
                    .sum::<u64>();
                frames += 1;
            }
            runs.push(Run {
                name: "ringscan_ouster_frame_in_memory",
                frames,
                points,
                secs: t.elapsed().as_secs_f64(),
            });
        }
        if wanted("ringscan_ouster_stream_in_memory") {
            let cfg = OusterStreamConfig {
                info: info.clone(),
                metadata_name: meta.clone(),
                crc: None,
                decode: DecodeOptions::default(),
                keep_extras: false,
                keep_columns: false,
            };
            let mut stream = OusterStream::new(cfg).unwrap_or_else(|e| die(format!("{e}")));
            let (mut frames, mut points) = (0u64, 0u64);
            let mut on = |s: &mut ringscan::sweep::Sweep,
                          _: &ringscan::sensor::ouster::OusterFacts| {
                frames += 1;
                points += s.points.len() as u64;
            };
            let t = Instant::now();
            for &(time, o, n) in &all {
                stream.push(time, &bytes[o..o + n], &mut on);
                let _ = stream.drain_imu().count();
            }
            stream.finish(&mut on);
            runs.push(Run {
                name: "ringscan_ouster_stream_in_memory",
                frames,
                points,
                secs: t.elapsed().as_secs_f64(),
            });
        }
    }
    for r in &runs {
        let pixels = r.frames * (h * w) as u64;
        println!(
            "{{\"what\":\"{}\",\"frames\":{},\"pixels\":{},\"points\":{},\"elapsed_s\":{:.6},\"pixels_per_s\":{:.0}}}",
            r.name,
            r.frames,
            pixels,
            r.points,
            r.secs,
            pixels as f64 / r.secs
        );
    }
}
