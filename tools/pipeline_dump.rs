//! Dumps real sweeps and ringscan's pipeline results on them for `tools/pipeline_open3d.py`
//! (Open3D side-by-side checks and timing).
//!
//! ```text
//! cargo run --release --example pipeline_dump -- OUT_DIR
//! ```
//! For each sweep (`os2_128`: the complete OS-2-128 frame; `hdl32`: the second HDL-32E sweep
//! of the Monterey capture; both decoded by ringscan from `../shared/captures`), writes:
//! - `NAME.xyz.f32`: the sweep, x y z per point (little-endian f32);
//! - `NAME.down.xyz.f32`: the sweep voxelised at 0.1 m (centroids, grid at the origin);
//! - `NAME.down.labels.i32`: per voxelised point, ringscan's cluster (tolerance 0.5 m, sizes
//!   [1, ∞)), clusters numbered by their smallest point index;
//! - `NAME.down.labels10.i32`: the same with sizes [10, 2000], −1 for dropped points;
//! - `NAME.json`: point counts, and ringscan's voxel counts with Open3D's grid origin (min
//!   bound − leaf/2) for leaves 0.05, 0.1, 0.2, 0.5 m.
//!
//! With `--time N` it only times ringscan's voxel (0.1 m) + ground (RANSAC 0.15 m, 200
//! iterations; or the polar grid) + clustering (0.5 m, ≥ 10 points) on each sweep, one thread,
//! buffers warm, and prints the median of N runs per stage in the format of
//! `tools/pipeline_open3d.py`, so the two can be run back to back on the same CPU.

#[path = "../tests/pipeline_support/mod.rs"]
mod pipeline_support;

use std::io::Write;
use std::path::Path;

use std::time::Instant;

use ringscan::pipeline::cluster::ClusterParams;
use ringscan::pipeline::cluster::Clusterer;
use ringscan::pipeline::cluster::Clusters;
use ringscan::pipeline::ground::GroundMethod;
use ringscan::pipeline::ground::GroundSegmenter;
use ringscan::pipeline::ground::PolarGridParams;
use ringscan::pipeline::voxel::GridOrigin;
use ringscan::pipeline::voxel::VoxelConfig;
use ringscan::pipeline::voxel::VoxelGrid;
use ringscan::Point;

fn median_ms(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN) * 1e3
}

/// Times voxel + ground + cluster on one sweep, `repeat` runs after one warm-up run.
fn time(name: &str, sweep: &[Point], repeat: usize) -> Result<(), Box<dyn std::error::Error>> {
    let ransac = GroundMethod::Ransac {
        distance_threshold_m: 0.15,
        iterations: 200,
        seed: 1,
    };
    let polar = GroundMethod::PolarGrid(PolarGridParams::default());
    for (label, method) in [("RANSAC", ransac), ("polar grid", polar)] {
        let mut grid = VoxelGrid::new(VoxelConfig::cubic(0.1))?;
        let mut seg = GroundSegmenter::new(method)?;
        let mut cl = Clusterer::new(ClusterParams::new(0.5, 10, usize::MAX))?;
        let (mut down, mut labels, mut clusters) = (Vec::new(), Vec::new(), Clusters::new());
        let (mut tv, mut tg, mut tc, mut tt) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for run in 0..=repeat {
            let t0 = Instant::now();
            grid.downsample(sweep, &mut down);
            let t1 = Instant::now();
            seg.segment(&down, &mut labels);
            let t2 = Instant::now();
            cl.cluster_excluding(&down, &labels, &mut clusters);
            let t3 = Instant::now();
            if run > 0 {
                tv.push((t1 - t0).as_secs_f64());
                tg.push((t2 - t1).as_secs_f64());
                tc.push((t3 - t2).as_secs_f64());
                tt.push((t3 - t0).as_secs_f64());
            }
        }
        let ground = labels.iter().filter(|&&g| g).count();
        println!(
            "ringscan {name}, one thread, median of {repeat}: voxel {:.2} ms ({} points), {label} {:.2} ms ({ground} ground), cluster {:.2} ms ({} clusters), total {:.2} ms",
            median_ms(&mut tv),
            down.len(),
            median_ms(&mut tg),
            median_ms(&mut tc),
            clusters.len(),
            median_ms(&mut tt)
        );
    }
    Ok(())
}

fn write_xyz(path: &Path, points: &[Point]) -> std::io::Result<()> {
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    for p in points {
        for v in [p.x, p.y, p.z] {
            out.write_all(&v.to_le_bytes())?;
        }
    }
    out.flush()
}

fn write_labels(path: &Path, n: usize, clusters: &Clusters) -> std::io::Result<()> {
    let mut labels = vec![-1i32; n];
    for k in 0..clusters.len() {
        for &i in clusters.points_of(k) {
            labels[i as usize] = k as i32;
        }
    }
    let bytes: Vec<u8> = labels.iter().flat_map(|l| l.to_le_bytes()).collect();
    std::fs::write(path, bytes)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let root = pipeline_support::captures().ok_or("../shared/captures is absent")?;
    let sweeps = [
        ("os2_128", pipeline_support::os2_128_sweep(&root)),
        ("hdl32", pipeline_support::hdl32_sweep(&root)),
    ];
    if args.first().map(String::as_str) == Some("--time") {
        let repeat: usize = args.get(1).ok_or("--time N")?.parse()?;
        for (name, sweep) in &sweeps {
            time(name, sweep, repeat.max(1))?;
        }
        return Ok(());
    }
    let out_dir = args
        .first()
        .ok_or("usage: pipeline_dump OUT_DIR | --time N")?;
    let out_dir = Path::new(out_dir);
    std::fs::create_dir_all(out_dir)?;
    for (name, sweep) in sweeps {
        write_xyz(&out_dir.join(format!("{name}.xyz.f32")), &sweep)?;
        let mut counts = Vec::new();
        let mut down = Vec::new();
        for leaf in [0.05, 0.1, 0.2, 0.5] {
            let mut grid = VoxelGrid::new(VoxelConfig {
                origin: GridOrigin::MinBoundMinusHalfLeaf,
                ..VoxelConfig::cubic(leaf)
            })?;
            counts.push(format!(
                "\"{leaf}\": {}",
                grid.downsample(&sweep, &mut down).voxels
            ));
        }
        VoxelGrid::new(VoxelConfig::cubic(0.1))?.downsample(&sweep, &mut down);
        write_xyz(&out_dir.join(format!("{name}.down.xyz.f32")), &down)?;
        let mut clusters = Clusters::new();
        Clusterer::new(ClusterParams::new(0.5, 1, usize::MAX))?.cluster(&down, &mut clusters);
        write_labels(
            &out_dir.join(format!("{name}.down.labels.i32")),
            down.len(),
            &clusters,
        )?;
        let all = clusters.len();
        Clusterer::new(ClusterParams::new(0.5, 10, 2000))?.cluster(&down, &mut clusters);
        write_labels(
            &out_dir.join(format!("{name}.down.labels10.i32")),
            down.len(),
            &clusters,
        )?;
        std::fs::write(
            out_dir.join(format!("{name}.json")),
            format!(
                "{{\"points\": {}, \"down_points\": {}, \"clusters\": {all}, \"clusters10\": {}, \"voxel_counts_open3d_origin\": {{{}}}}}\n",
                sweep.len(),
                down.len(),
                clusters.len(),
                counts.join(", ")
            ),
        )?;
        eprintln!(
            "{name}: {} points, {} voxelised, {all} clusters",
            sweep.len(),
            down.len()
        );
    }
    Ok(())
}
