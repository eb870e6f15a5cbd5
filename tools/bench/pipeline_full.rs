//! Criterion benchmark of the whole pipeline on one real sweep: deskew → filter → voxel →
//! ground → cluster, as `ringscan decode --pipeline default` runs it.
//!
//! ```text
//! cargo bench --bench pipeline_full
//! ```
//! Inputs (from `../shared/captures`; the bench says so and does nothing when absent):
//! * `os2-128`: the one complete frame of `OS-2-128-U1_v2.3.0_1024x10.pcap` (128 × 1024,
//!   119 682 points), decoded by `OusterStream` with its metadata;
//! * `hdl32e`: the 6th sweep of the HDL-32E Monterey capture (`32db.yaml`).
//!
//! Each iteration copies the decoded sweep into the pipeline's input (the copy the CLI makes,
//! ~3 MB) and runs [`Pipeline::run`] with the default configuration and a constant-velocity
//! deskew at 15 m/s and 60 °/s (so deskew does real work). After criterion, the per-stage
//! median and maximum over 200 runs (after a first, reported on its own: it grows the
//! pipeline's buffers) are printed, from the stage times the pipeline reports
//! with an `Instant` clock (for the default configuration and with `voxel.leaf_m` 0.25 and 0.3),
//! and the process's CPU time per run over the same 200 runs (user +
//! system from `/proc/self/stat`, Linux): on a shared machine wall time includes waiting for a
//! core, CPU time does not.

use std::path::{Path, PathBuf};
use std::time::Instant;

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use nalgebra::{Isometry3, Vector3};
use ringscan::deskew::Twist;
use ringscan::pipeline::config::PipelineConfig;
use ringscan::pipeline::run::Pipeline;
use ringscan::pipeline::run::StageTimes;
use ringscan::sensor::ouster::OusterStream;
use ringscan::sensor::ouster::OusterStreamConfig;
use ringscan::sensor::velodyne::calib::parse_velodyne;
use ringscan::sensor::velodyne::StreamConfig;
use ringscan::sensor::velodyne::VelodyneModel;
use ringscan::sensor::velodyne::VelodyneStream;
use ringscan::sensor::DecodeOptions;
use ringscan::source::pcap::PcapSource;
use ringscan::sweep::Sweep;

fn captures() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/captures");
    p.is_dir().then_some(p)
}

fn os2_sweep(root: &Path) -> Option<Sweep> {
    let dir = root.join("ouster-lidar__ouster-sdk/tests/pcaps");
    let text = std::fs::read_to_string(dir.join("OS-2-128-U1_v2.3.0_1024x10.json")).ok()?;
    let info =
        ringscan::sensor::ouster::calib::parse(&text, "OS-2-128-U1_v2.3.0_1024x10.json").ok()?;
    let mut stream = OusterStream::new(OusterStreamConfig {
        info,
        metadata_name: "OS-2-128-U1_v2.3.0_1024x10.json".into(),
        crc: None,
        decode: DecodeOptions::default(),
        keep_extras: false,
        keep_columns: false,
    })
    .ok()?;
    let mut src = PcapSource::open(&dir.join("OS-2-128-U1_v2.3.0_1024x10.pcap")).ok()?;
    let mut best: Option<Sweep> = None;
    let mut keep = |s: &mut Sweep, _: &_| {
        if best
            .as_ref()
            .is_none_or(|b| s.points.len() > b.points.len())
        {
            best = Some(s.clone());
        }
    };
    while let Ok(Some(d)) = src.next_datagram() {
        stream.push(d.time_ns, d.payload, &mut keep);
    }
    stream.finish(&mut keep);
    best
}

fn hdl32_sweep(root: &Path) -> Option<Sweep> {
    let text = std::fs::read_to_string(
        root.join("ros-drivers__velodyne/velodyne_pointcloud/params/32db.yaml"),
    )
    .ok()?;
    let calib = parse_velodyne(&text, "32db.yaml").ok()?;
    let mut stream = VelodyneStream::new(StreamConfig {
        model: Some(VelodyneModel::Hdl32e),
        calibrations: vec![calib],
        ..StreamConfig::default()
    });
    let mut src = PcapSource::open(
        &root.join("Kitware__VeloView/Testing/Data/monterey-first-100-packets.pcap"),
    )
    .ok()?;
    let mut sweeps = Vec::new();
    while let Ok(Some(d)) = src.next_datagram() {
        let _ = stream.push(d.time_ns, d.payload, &mut |s: &mut Sweep, _: &_| {
            sweeps.push(s.clone())
        });
    }
    sweeps.into_iter().nth(5)
}

fn pipeline() -> Pipeline {
    pipeline_with(&PipelineConfig::default())
}

fn pipeline_with(cfg: &PipelineConfig) -> Pipeline {
    let mut p = Pipeline::new(cfg, Isometry3::identity()).unwrap();
    p.set_twist(Twist {
        linear_mps: Vector3::new(15.0, 0.0, 0.0),
        angular_radps: Vector3::new(0.0, 0.0, 60f64.to_radians()),
    });
    p
}

/// User + system CPU time of this process, ns (`/proc/self/stat` fields 14 and 15, in clock
/// ticks of 10 ms); `None` off Linux.
fn cpu_ns() -> Option<u64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let rest = stat.rsplit_once(')')?.1;
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = f.get(11)?.parse::<u64>().ok()? + f.get(12)?.parse::<u64>().ok()?;
    Some(ticks * 10_000_000)
}

fn stage_report(name: &str, sweep: &Sweep, cfg: &PipelineConfig) {
    let mut p = pipeline_with(cfg);
    let mut work = sweep.clone();
    let origin = Instant::now();
    let mut clock = || origin.elapsed().as_nanos() as u64;
    let mut times: Vec<StageTimes> = Vec::new();
    // The first sweep grows every buffer (allocations, page faults): reported on its own,
    // and the median and max below are over the 200 sweeps after it.
    work.points.copy_from_slice(&sweep.points);
    let first = p.run(&mut work, &mut clock).times.total_ns() as f64 * 1e-6;
    let mut last = None;
    let cpu0 = cpu_ns();
    let wall0 = Instant::now();
    for _ in 0..200 {
        work.points.copy_from_slice(&sweep.points);
        let s = p.run(&mut work, &mut clock);
        times.push(s.times);
        last = Some(s);
    }
    let ms = |f: fn(&StageTimes) -> u64| {
        let mut v: Vec<u64> = times.iter().map(f).collect();
        v.sort_unstable();
        (v[v.len() / 2] as f64 * 1e-6, v[v.len() - 1] as f64 * 1e-6)
    };
    let wall = wall0.elapsed().as_nanos() as f64 / 200.0 * 1e-6;
    let cpu = match (cpu0, cpu_ns()) {
        (Some(a), Some(b)) => format!("{:.3} ms", (b - a) as f64 / 200.0 * 1e-6),
        _ => "n/a".to_string(),
    };
    let s = last.unwrap();
    eprintln!("{name}: per run (copy + pipeline) wall {wall:.3} ms, CPU {cpu} (200 runs)");
    eprintln!(
        "{name}: {} points → {} after filter → {} voxels → {} ground, {} obstacles in {} clusters ({} unclustered)",
        s.input, s.filtered, s.voxels, s.ground, s.obstacles, s.clusters, s.unclustered
    );
    for (stage, f) in [
        (
            "deskew",
            (|t: &StageTimes| t.deskew_ns) as fn(&StageTimes) -> u64,
        ),
        ("filter", |t| t.filter_ns),
        ("voxel", |t| t.voxel_ns),
        ("ground", |t| t.ground_ns),
        ("cluster", |t| t.cluster_ns),
        ("total", StageTimes::total_ns),
    ] {
        let (med, max) = ms(f);
        eprintln!("  {stage:8} median {med:7.3} ms   max {max:7.3} ms");
    }
    eprintln!("  (the first sweep, before the 200: {first:.3} ms, its buffers growing)");
}

fn bench(c: &mut Criterion) {
    let Some(root) = captures() else {
        eprintln!("pipeline_full: ../shared/captures is absent: nothing to measure");
        return;
    };
    let inputs: Vec<(&str, Sweep)> = [
        ("os2-128", os2_sweep(&root)),
        ("hdl32e", hdl32_sweep(&root)),
    ]
    .into_iter()
    .filter_map(|(n, s)| s.map(|s| (n, s)))
    .collect();
    let mut g = c.benchmark_group("pipeline_full");
    for (name, sweep) in &inputs {
        g.throughput(Throughput::Elements(sweep.points.len() as u64));
        let mut p = pipeline();
        let mut work = sweep.clone();
        g.bench_function(*name, |b| {
            b.iter(|| {
                work.points.copy_from_slice(&sweep.points);
                black_box(p.run(&mut work, &mut || 0));
            })
        });
    }
    g.finish();
    for (name, sweep) in &inputs {
        stage_report(name, sweep, &PipelineConfig::default());
    }
    // The same with coarser voxels: what the leaf size costs.
    for leaf in [0.25, 0.3] {
        let coarse = PipelineConfig {
            voxel_leaf_m: leaf,
            ..PipelineConfig::default()
        };
        for (name, sweep) in &inputs {
            stage_report(name, sweep, &coarse);
        }
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30);
    targets = bench
}
criterion_main!(benches);
