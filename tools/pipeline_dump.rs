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

#[path = "../tests/pipeline_support/mod.rs"]
mod pipeline_support;

use std::io::Write;
use std::path::Path;

use ringscan::pipeline::cluster::{ClusterParams, Clusterer, Clusters};
use ringscan::pipeline::voxel::{GridOrigin, VoxelConfig, VoxelGrid};
use ringscan::Point;

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
    let out_dir = std::env::args().nth(1).ok_or("usage: pipeline_dump OUT_DIR")?;
    let out_dir = Path::new(&out_dir);
    std::fs::create_dir_all(out_dir)?;
    let root = pipeline_support::captures().ok_or("../shared/captures is absent")?;
    for (name, sweep) in [
        ("os2_128", pipeline_support::os2_128_sweep(&root)),
        ("hdl32", pipeline_support::hdl32_sweep(&root)),
    ] {
        write_xyz(&out_dir.join(format!("{name}.xyz.f32")), &sweep)?;
        let mut counts = Vec::new();
        let mut down = Vec::new();
        for leaf in [0.05, 0.1, 0.2, 0.5] {
            let mut grid = VoxelGrid::new(VoxelConfig {
                origin: GridOrigin::MinBoundMinusHalfLeaf,
                ..VoxelConfig::cubic(leaf)
            })?;
            counts.push(format!("\"{leaf}\": {}", grid.downsample(&sweep, &mut down).voxels));
        }
        VoxelGrid::new(VoxelConfig::cubic(0.1))?.downsample(&sweep, &mut down);
        write_xyz(&out_dir.join(format!("{name}.down.xyz.f32")), &down)?;
        let mut clusters = Clusters::new();
        Clusterer::new(ClusterParams::new(0.5, 1, usize::MAX))?.cluster(&down, &mut clusters);
        write_labels(&out_dir.join(format!("{name}.down.labels.i32")), down.len(), &clusters)?;
        let all = clusters.len();
        Clusterer::new(ClusterParams::new(0.5, 10, 2000))?.cluster(&down, &mut clusters);
        write_labels(&out_dir.join(format!("{name}.down.labels10.i32")), down.len(), &clusters)?;
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
        eprintln!("{name}: {} points, {} voxelised, {all} clusters", sweep.len(), down.len());
    }
    Ok(())
}
