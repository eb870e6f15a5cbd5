//! What the MCAP chunk compression costs: the sweeps of a capture written with each compression
//! the `mcap` crate offers (the crate ringscan's sink uses), timing the writing only.
//!
//! ```text
//! cargo run --release --example bench_mcap_compression -- CAPTURE --model hdl32e --calib FILE
//! ```
//! The capture is decoded first (ringscan `VelodyneStream`, not timed) and every sweep's point
//! bytes are kept in memory; then, for each setting, one MCAP file with one message per sweep
//! (the bare point bytes, 24 bytes per point, no protobuf wrapper) is written to
//! `$TMPDIR/bench_mcap_compression.mcap`, finished (not fsynced) and deleted. Prints, per setting,
//! the time, the point bytes per second, the real-time factor of the writing alone (capture
//! duration / time) and the compression ratio. Add the decode time (tools/bench/decode_mem.rs) to
//! estimate a `ringscan decode --out` with that setting.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

use ringscan::sensor::velodyne::calib::builtin::builtin;
use ringscan::sensor::velodyne::calib::parse_velodyne;
use ringscan::sensor::velodyne::SensorFacts;
use ringscan::sensor::velodyne::StreamConfig;
use ringscan::sensor::velodyne::VelodyneModel;
use ringscan::sensor::velodyne::VelodyneStream;
use ringscan::source::pcap::PcapSource;
use ringscan::sweep::Sweep;

fn arg(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args
        .first()
        .cloned()
        .expect("usage: bench_mcap_compression CAPTURE --model M [--calib FILE]");
    let model = VelodyneModel::from_id(&arg(&args, "--model").unwrap_or_else(|| "hdl32e".into()))
        .expect("model");
    let calib = match arg(&args, "--calib") {
        Some(f) => {
            let name = Path::new(&f)
                .file_name()
                .unwrap()
                .to_string_lossy()
                .into_owned();
            parse_velodyne(&std::fs::read_to_string(&f).expect("calibration"), &name)
                .expect("calibration")
        }
        None => builtin(model).expect("built-in calibration"),
    };
    let mut src = PcapSource::open(Path::new(&path)).expect("capture");
    let cfg = StreamConfig {
        model: Some(model),
        calibrations: vec![calib],
        ..StreamConfig::default()
    };
    let mut stream = VelodyneStream::new(cfg);
    let mut sweeps: Vec<(u64, Vec<u8>)> = Vec::new();
    let mut cb = |s: &mut Sweep, _: &SensorFacts| {
        sweeps.push((
            s.last_host_ns.max(0) as u64,
            ringscan::point::as_bytes(&s.points).to_vec(),
        ))
    };
    let (mut first, mut last) = (None, 0i64);
    while let Some(d) = src.next_datagram().expect("capture") {
        first.get_or_insert(d.time_ns);
        last = d.time_ns;
        stream.push(d.time_ns, d.payload, &mut cb).expect("stream");
    }
    stream.finish(&mut cb).expect("stream");
    let duration = (last - first.unwrap_or(last)) as f64 * 1e-9;
    let total: usize = sweeps.iter().map(|(_, s)| s.len()).sum();
    println!(
        "{} sweeps, {:.1} MB of points, {duration:.2} s of capture",
        sweeps.len(),
        total as f64 / 1e6
    );
    println!("| compression | threads | time (s) | MB/s of points | real-time factor (writing only) | ratio |");
    println!("|---|---:|---:|---:|---:|---:|");
    let out = std::env::temp_dir().join("bench_mcap_compression.mcap");
    // (name, compression, level (0 = the library default; a negative zstd level is passed as
    // its two's complement, which the mcap crate hands to zstd as an i32), threads)
    let neg = |l: i32| l as u32;
    let settings: Vec<(&str, Option<mcap::Compression>, u32, u32)> = vec![
        ("none", None, 0, 0),
        ("lz4", Some(mcap::Compression::Lz4), 0, 0),
        ("zstd -5 (fast)", Some(mcap::Compression::Zstd), neg(-5), 0),
        ("zstd -3 (fast)", Some(mcap::Compression::Zstd), neg(-3), 0),
        ("zstd -2 (fast)", Some(mcap::Compression::Zstd), neg(-2), 0),
        ("zstd -1 (fast)", Some(mcap::Compression::Zstd), neg(-1), 0),
        ("zstd 1", Some(mcap::Compression::Zstd), 1, 0),
        ("zstd 3 (mcap default)", Some(mcap::Compression::Zstd), 0, 0),
        ("zstd -5 (fast)", Some(mcap::Compression::Zstd), neg(-5), 2),
        ("zstd -3 (fast)", Some(mcap::Compression::Zstd), neg(-3), 2),
        ("zstd -1 (fast)", Some(mcap::Compression::Zstd), neg(-1), 2),
        ("zstd 1", Some(mcap::Compression::Zstd), 1, 2),
        ("zstd 3 (mcap default)", Some(mcap::Compression::Zstd), 0, 2),
    ];
    for (name, comp, level, threads) in settings {
        let t = Instant::now();
        let f = std::io::BufWriter::with_capacity(
            1 << 20,
            std::fs::File::create(&out).expect("output"),
        );
        let mut w = mcap::WriteOptions::new()
            .compression(comp)
            .compression_level(level)
            .compression_threads(threads)
            .chunk_size(Some(4 << 20))
            .create(f)
            .expect("mcap");
        let schema = w.add_schema("points", "raw", b"").expect("mcap");
        let ch = w
            .add_channel(schema, "/points", "raw", &BTreeMap::new())
            .expect("mcap");
        for (i, (t_ns, bytes)) in sweeps.iter().enumerate() {
            let h = mcap::records::MessageHeader {
                channel_id: ch,
                sequence: i as u32,
                log_time: *t_ns,
                publish_time: *t_ns,
            };
            w.write_to_known_channel(&h, bytes).expect("mcap");
        }
        w.finish().expect("mcap");
        drop(w);
        let e = t.elapsed().as_secs_f64();
        let size = std::fs::metadata(&out).map(|m| m.len()).unwrap_or(1);
        println!(
            "| {name} | {threads} | {e:.3} | {:.0} | {:.1}× | {:.2} |",
            total as f64 / e / 1e6,
            duration / e,
            total as f64 / size as f64
        );
        let _ = std::fs::remove_file(&out);
    }
}
