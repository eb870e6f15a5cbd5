//! What writing MCAP costs, without the decoding: per-chunk compression cost (for a projection
//! to more cores), the sink on 1..N compression threads, and what each point field costs.
//!
//! ```text
//! ringscan decode CAPTURE … --compression none --out sweeps.mcap     # the sweeps, once
//! cargo run --release --example bench_mcap_threads -- sweeps.mcap [--threads 1,2] [--rounds 5]
//!     [--compressions zstd:-3,zstd:1,lz4,none] [--chunk-sizes 1,2,4,8,16] [--only chunks,sink,fields,crate]
//! ```
//!
//! The `/points` messages (`foxglove.PointCloud`) of the input are read into memory once, as
//! `Point` records with their log times and timestamps. Then, each setting timed `--rounds` times
//! (median kept), everything in memory (no file system):
//!
//! * `chunks`: the sweeps written by `McapSink` with `--compression none`, its chunks read back,
//!   and each chunk's records compressed alone on one thread with each compression (as a worker
//!   does): time per chunk (median, mean), MB/s and ratio. The mean time per chunk × chunks is
//!   the compression CPU a file costs; divided by N threads it is the wall a pool of N needs if
//!   nothing else limits it (the projection in docs/mcap-threads-figures.md). Per chunk size
//!   (`--chunk-sizes`, MiB) at the first compression.
//! * `sink`: `McapSink::write_sweep` of every sweep into a `Vec`, per compression and per
//!   `--threads` value: wall, CPU of the process (user + system), real-time factor of the
//!   writing alone, ratio.
//! * `fields`: the records without one field at a time (and the minimal x, y, z, intensity),
//!   in 4 MiB chunks compressed with the first compression on one thread: size and time, and
//!   the difference to the whole record: what the field costs.
//! * `crate`: the same messages written with the `mcap` crate's `Writer` (the sink before it
//!   wrote its own records), zstd's NbWorkers 0 and 2, for comparison.

use std::collections::BTreeMap;
use std::io::Cursor;
use std::time::Instant;

use ringscan::point::Point;
use ringscan::sink::mcap::{Compression, McapSink, SensorInfo, SinkOptions, SweepMsg};

fn arg(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn die(msg: String) -> ! {
    eprintln!("bench_mcap_threads: {msg}");
    std::process::exit(2)
}

struct Sweep {
    log_ns: u64,
    stamp_ns: u64,
    points: Vec<Point>,
}

#[derive(Clone, Copy)]
struct Comp {
    kind: Compression,
    level: i32,
}

impl Comp {
    fn parse(s: &str) -> Self {
        match s {
            "none" => Comp {
                kind: Compression::None,
                level: 0,
            },
            "lz4" => Comp {
                kind: Compression::Lz4,
                level: 0,
            },
            _ => Comp {
                kind: Compression::Zstd,
                level: s
                    .strip_prefix("zstd:")
                    .and_then(|l| l.parse().ok())
                    .unwrap_or_else(|| die(format!("compression {s}: zstd:LEVEL, lz4 or none"))),
            },
        }
    }
    fn name(&self) -> String {
        match self.kind {
            Compression::None => "none".into(),
            Compression::Lz4 => "lz4".into(),
            _ => format!("zstd:{}", self.level),
        }
    }
    /// Compresses as the sink's workers do (one zstd frame / one lz4 frame per chunk).
    fn compress(&self, src: &[u8], z: &mut Option<zstd::bulk::Compressor<'static>>) -> usize {
        match self.kind {
            Compression::None => src.len(),
            Compression::Lz4 => {
                use std::io::Write as _;
                let mut e = lz4::EncoderBuilder::new()
                    .level(0)
                    .block_checksum(lz4::liblz4::BlockChecksum::NoBlockChecksum)
                    .build(Vec::with_capacity(src.len()))
                    .expect("lz4");
                e.write_all(src).expect("lz4");
                let (o, r) = e.finish();
                r.expect("lz4");
                o.len()
            }
            _ => {
                let c =
                    z.get_or_insert_with(|| zstd::bulk::Compressor::new(self.level).expect("zstd"));
                let mut out = Vec::with_capacity(zstd::zstd_safe::compress_bound(src.len()));
                c.compress_to_buffer(src, &mut out).expect("zstd");
                out.len()
            }
        }
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// User + system CPU seconds of this process so far.
fn cpu_s() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    // Fields after the command name (which may hold spaces) : utime is the 14th field overall.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|x| x.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(11) + ticks(12)) / 100.0
}

fn read_sweeps(path: &str) -> Vec<Sweep> {
    use prost::Message as _;
    let bytes = std::fs::read(path).unwrap_or_else(|e| die(format!("{path}: {e}")));
    let mut out = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap_or_else(|e| die(format!("{path}: {e}"))) {
        let m = m.unwrap_or_else(|e| die(format!("{path}: {e}")));
        if !m.channel.topic.ends_with("/points") {
            continue;
        }
        let pc = ringscan::sink::read::PointCloud::decode(&m.data[..])
            .unwrap_or_else(|e| die(format!("{path}: {e}")));
        if pc.point_stride != 24 {
            die(format!(
                "{path}: records of {} bytes; write the input with the default --fields",
                pc.point_stride
            ));
        }
        let stamp = pc
            .timestamp
            .map_or(0, |t| t.seconds as u64 * 1_000_000_000 + t.nanos as u64);
        out.push(Sweep {
            log_ns: m.log_time,
            stamp_ns: stamp,
            points: pc
                .data
                .chunks_exact(24)
                .map(bytemuck::pod_read_unaligned::<Point>)
                .collect(),
        });
    }
    out
}

/// Writes every sweep with `opts` into memory; returns the chunks written.
fn write_sink(sweeps: &[Sweep], opts: SinkOptions) -> usize {
    let mut sink = McapSink::new(Cursor::new(Vec::with_capacity(1 << 30)), opts).expect("sink");
    let id = sink
        .add_sensor(&SensorInfo {
            name: "bench".into(),
            ..SensorInfo::default()
        })
        .expect("sensor");
    for s in sweeps {
        sink.write_sweep(
            id,
            &SweepMsg {
                log_time_ns: s.log_ns,
                timestamp_ns: s.stamp_ns,
                points: &s.points,
            },
        )
        .expect("sweep");
    }
    sink.finish().expect("finish").chunks
}

/// The uncompressed records of every chunk of a file written with `--compression none`.
fn chunks_of(sweeps: &[Sweep], chunk_size: u64) -> Vec<Vec<u8>> {
    let shared = std::rc::Rc::new(std::cell::RefCell::new(Cursor::new(Vec::new())));
    struct W(std::rc::Rc<std::cell::RefCell<Cursor<Vec<u8>>>>);
    impl std::io::Write for W {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            self.0.borrow_mut().write(b)
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }
    impl std::io::Seek for W {
        fn seek(&mut self, p: std::io::SeekFrom) -> std::io::Result<u64> {
            self.0.borrow_mut().seek(p)
        }
    }
    let mut sink = McapSink::new(
        W(shared.clone()),
        SinkOptions {
            compression: Compression::None,
            chunk_size,
            ..SinkOptions::default()
        },
    )
    .expect("sink");
    let id = sink
        .add_sensor(&SensorInfo {
            name: "bench".into(),
            ..SensorInfo::default()
        })
        .expect("sensor");
    for s in sweeps {
        let msg = SweepMsg {
            log_time_ns: s.log_ns,
            timestamp_ns: s.stamp_ns,
            points: &s.points,
        };
        sink.write_sweep(id, &msg).expect("sweep");
    }
    sink.finish().expect("finish");
    let bytes = shared.borrow().get_ref().clone();
    let mut out = Vec::new();
    for r in mcap::read::LinearReader::new(&bytes).expect("read") {
        if let Ok(mcap::records::Record::Chunk { data, .. }) = r {
            out.push(data.into_owned());
        }
    }
    out
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first().filter(|a| !a.starts_with("--")).cloned() else {
        die("usage: bench_mcap_threads SWEEPS.mcap [--threads 1,2] [--rounds 5] [--compressions …] [--chunk-sizes 1,4] [--only …]".into())
    };
    let list = |name: &str, default: &str| -> Vec<String> {
        arg(&args, name)
            .unwrap_or_else(|| default.into())
            .split(',')
            .filter(|s| !s.is_empty())
            .map(str::to_string)
            .collect()
    };
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let threads: Vec<usize> = list("--threads", &format!("1,{cores}"))
        .iter()
        .map(|t| t.parse().unwrap_or_else(|_| die(format!("--threads {t}"))))
        .collect();
    let rounds: usize = arg(&args, "--rounds")
        .and_then(|r| r.parse().ok())
        .unwrap_or(5)
        .max(1);
    let comps: Vec<Comp> = list("--compressions", "zstd:-3,zstd:-1,zstd:1,lz4,none")
        .iter()
        .map(|c| Comp::parse(c))
        .collect();
    let chunk_sizes: Vec<u64> = list("--chunk-sizes", "1,2,4,8,16")
        .iter()
        .map(|c| {
            c.parse::<u64>()
                .unwrap_or_else(|_| die(format!("--chunk-sizes {c}")))
                << 20
        })
        .collect();
    let only = list("--only", "chunks,sink,fields,crate");
    let first = comps[0];

    let sweeps = read_sweeps(&path);
    let points: usize = sweeps.iter().map(|s| s.points.len()).sum();
    let point_bytes = points * 24;
    let duration = match (sweeps.first(), sweeps.last()) {
        (Some(a), Some(b)) => (b.log_ns - a.log_ns) as f64 * 1e-9,
        _ => 0.0,
    };
    println!(
        "input {path}: {} sweeps, {points} points ({:.1} MB of 24-byte records), {duration:.2} s; {cores} CPUs; load average {}",
        sweeps.len(),
        point_bytes as f64 / 1e6,
        std::fs::read_to_string("/proc/loadavg").unwrap_or_default().trim()
    );

    if only.iter().any(|o| o == "chunks") {
        println!("\n### Per-chunk compression cost, one thread (median of {rounds} rounds)\n");
        println!("| compression | chunk MiB | chunks | ms per chunk, median | ms per chunk, mean | MB/s (uncompressed) | CPU s per file | ratio |");
        println!("|---|---:|---:|---:|---:|---:|---:|---:|");
        let mut rows: Vec<(Comp, u64)> = comps.iter().map(|c| (*c, 4u64 << 20)).collect();
        rows.extend(
            chunk_sizes
                .iter()
                .filter(|&&s| s != 4 << 20)
                .map(|&s| (first, s)),
        );
        let mut cache: BTreeMap<u64, Vec<Vec<u8>>> = BTreeMap::new();
        for (comp, size) in rows {
            let chunks = cache
                .entry(size)
                .or_insert_with(|| chunks_of(&sweeps, size));
            let total: usize = chunks.iter().map(Vec::len).sum();
            let mut per_chunk: Vec<Vec<f64>> = vec![Vec::new(); chunks.len()];
            let mut out_bytes = 0usize;
            let mut z = None;
            for _ in 0..rounds {
                out_bytes = 0;
                for (i, c) in chunks.iter().enumerate() {
                    let t = Instant::now();
                    out_bytes += comp.compress(c, &mut z);
                    per_chunk[i].push(t.elapsed().as_secs_f64());
                }
            }
            let times: Vec<f64> = per_chunk.into_iter().map(median).collect();
            let sum: f64 = times.iter().sum();
            println!(
                "| {} | {} | {} | {:.2} | {:.2} | {:.0} | {:.3} | {:.2} |",
                comp.name(),
                size >> 20,
                chunks.len(),
                median(times.clone()) * 1e3,
                sum / times.len().max(1) as f64 * 1e3,
                total as f64 / sum / 1e6,
                sum,
                total as f64 / out_bytes.max(1) as f64
            );
        }
    }

    if only.iter().any(|o| o == "sink") {
        println!("\n### McapSink::write_sweep into memory, by compression threads (median of {rounds} rounds, rounds interleaved)\n");
        println!("| compression | threads | wall s, median | CPU s, median | MB/s of points | real-time factor (writing only) | chunks |");
        println!("|---|---:|---:|---:|---:|---:|---:|");
        for comp in &comps {
            let mut res: BTreeMap<usize, (Vec<f64>, Vec<f64>, usize)> = BTreeMap::new();
            for _ in 0..rounds {
                for &t in &threads {
                    let opts = SinkOptions {
                        compression: comp.kind,
                        zstd_level: if comp.kind == Compression::Zstd {
                            comp.level
                        } else {
                            -3
                        },
                        threads: t,
                        ..SinkOptions::default()
                    };
                    let (c0, t0) = (cpu_s(), Instant::now());
                    let chunks = write_sink(&sweeps, opts);
                    let wall = t0.elapsed().as_secs_f64();
                    let e = res.entry(t).or_default();
                    e.0.push(wall);
                    e.1.push(cpu_s() - c0);
                    e.2 = chunks;
                }
            }
            for (t, (walls, cpus, chunks)) in res {
                let wall = median(walls);
                println!(
                    "| {} | {t} | {wall:.3} | {:.2} | {:.0} | {:.1}× | {chunks} |",
                    comp.name(),
                    median(cpus),
                    point_bytes as f64 / wall / 1e6,
                    duration / wall
                );
            }
        }
    }

    if only.iter().any(|o| o == "fields") {
        println!("\n### What each point field costs ({}, 4 MiB chunks, one thread, median of {rounds} rounds)\n", first.name());
        println!("| record | bytes per point | compressed MB | compress s | ratio | saves vs the whole record: MB, s |");
        println!("|---|---:|---:|---:|---:|---|");
        // (name, byte ranges [from, to) of the 24-byte record kept)
        let layouts: Vec<(&str, Vec<(usize, usize)>)> = vec![
            ("whole (default)", vec![(0, 24)]),
            ("without x", vec![(4, 24)]),
            ("without y", vec![(0, 4), (8, 24)]),
            ("without z", vec![(0, 8), (12, 24)]),
            ("without intensity", vec![(0, 12), (16, 24)]),
            ("without t", vec![(0, 16), (20, 24)]),
            ("without ring", vec![(0, 20), (22, 24)]),
            ("without return and padding", vec![(0, 22)]),
            ("minimal (x, y, z, intensity)", vec![(0, 16)]),
        ];
        let mut base: Option<(f64, f64)> = None;
        for (name, keep) in layouts {
            let stride: usize = keep.iter().map(|(a, b)| b - a).sum();
            let mut chunks: Vec<Vec<u8>> = vec![Vec::new()];
            for s in &sweeps {
                let c = chunks.last_mut().expect("one chunk");
                for p in &s.points {
                    let b = bytemuck::bytes_of(p);
                    for &(from, to) in &keep {
                        c.extend_from_slice(&b[from..to]);
                    }
                }
                if c.len() >= 4 << 20 {
                    chunks.push(Vec::new());
                }
            }
            let mut times = Vec::new();
            let mut out = 0usize;
            let mut z = None;
            for _ in 0..rounds {
                out = 0;
                let t = Instant::now();
                for c in &chunks {
                    out += first.compress(c, &mut z);
                }
                times.push(t.elapsed().as_secs_f64());
            }
            let secs = median(times);
            let mb = out as f64 / 1e6;
            let total: usize = chunks.iter().map(Vec::len).sum();
            let saves = match base {
                None => {
                    base = Some((mb, secs));
                    "—".to_string()
                }
                Some((bm, bs)) => format!(
                    "{:.1} MB ({:.0} %), {:.3} s ({:.0} %)",
                    bm - mb,
                    100.0 * (bm - mb) / bm,
                    bs - secs,
                    100.0 * (bs - secs) / bs
                ),
            };
            println!(
                "| {name} | {stride} | {mb:.1} | {secs:.3} | {:.2} | {saves} |",
                total as f64 / out.max(1) as f64
            );
        }
    }

    if only.iter().any(|o| o == "crate") {
        println!("\n### The mcap crate's Writer (the sink before), same point bytes as raw messages, 4 MiB chunks (median of {rounds} rounds)\n");
        println!("| compression | zstd NbWorkers | wall s | CPU s |");
        println!("|---|---:|---:|---:|");
        for comp in comps.iter().filter(|c| c.kind == Compression::Zstd) {
            for workers in [0u32, 2] {
                let mut walls = Vec::new();
                let mut cpus = Vec::new();
                for _ in 0..rounds {
                    let (c0, t0) = (cpu_s(), Instant::now());
                    let mut w = mcap::WriteOptions::new()
                        .compression(Some(mcap::Compression::Zstd))
                        .compression_level(comp.level as u32)
                        .compression_threads(workers)
                        .chunk_size(Some(4 << 20))
                        .create(Cursor::new(Vec::with_capacity(1 << 30)))
                        .expect("mcap");
                    let schema = w.add_schema("points", "raw", b"").expect("mcap");
                    let ch = w
                        .add_channel(schema, "/points", "raw", &BTreeMap::new())
                        .expect("mcap");
                    for (i, s) in sweeps.iter().enumerate() {
                        let h = mcap::records::MessageHeader {
                            channel_id: ch,
                            sequence: i as u32,
                            log_time: s.log_ns,
                            publish_time: s.log_ns,
                        };
                        w.write_to_known_channel(&h, ringscan::point::as_bytes(&s.points))
                            .expect("mcap");
                    }
                    w.finish().expect("mcap");
                    drop(w);
                    walls.push(t0.elapsed().as_secs_f64());
                    cpus.push(cpu_s() - c0);
                }
                println!(
                    "| {} | {workers} | {:.3} | {:.2} |",
                    comp.name(),
                    median(walls),
                    median(cpus)
                );
            }
        }
    }
}
