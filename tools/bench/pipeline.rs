//! Criterion benchmark of the pipeline stages (voxel, ground, cluster) on real sweeps, one
//! thread, buffers warm (each stage object and output buffer is reused across iterations, as
//! in a sweep loop).
//!
//! ```text
//! cargo bench --bench pipeline
//! ```
//! Inputs (from `../shared/captures`, decoded by ringscan before timing): the complete
//! OS-2-128 frame (119 682 points) and the second HDL-32E sweep of the Monterey capture
//! (49 426 points); the same sweeps `tools/pipeline_open3d.sh` times Open3D on. Parameters
//! are those of the Open3D reference run: leaf 0.1 m, plane threshold 0.15 m, 200 RANSAC
//! iterations, cluster tolerance 0.5 m, at least 10 points.
//!
//! * `voxel/<sweep>/{hash,sort,nearest}`: centroid downsampling by hash or sort grouping,
//!   and the nearest-to-centroid variant (hash);
//! * `ground/<sweep>/{ransac,polar}` on the voxelised sweep;
//! * `cluster/<sweep>` on the voxelised points the polar grid calls not ground;
//! * `pipeline/<sweep>/{ransac,polar}`: voxel + ground + cluster from the raw sweep, the
//!   figure compared with Open3D's `voxel_down_sample` + `segment_plane` + `cluster_dbscan`.

#[path = "../../tests/pipeline_support/mod.rs"]
mod pipeline_support;

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use ringscan::pipeline::cluster::ClusterParams;
use ringscan::pipeline::cluster::Clusterer;
use ringscan::pipeline::cluster::Clusters;
use ringscan::pipeline::ground::GroundMethod;
use ringscan::pipeline::ground::GroundSegmenter;
use ringscan::pipeline::ground::PolarGridParams;
use ringscan::pipeline::voxel::KeyGrouping;
use ringscan::pipeline::voxel::VoxelConfig;
use ringscan::pipeline::voxel::VoxelGrid;
use ringscan::Point;

const LEAF_M: f64 = 0.1;
const RANSAC: GroundMethod = GroundMethod::Ransac {
    distance_threshold_m: 0.15,
    iterations: 200,
    seed: 1,
};
const CLUSTER: ClusterParams = ClusterParams {
    tolerance_m: 0.5,
    min_points: 10,
    max_points: usize::MAX,
};

fn sweeps() -> Vec<(&'static str, Vec<Point>)> {
    let Some(root) = pipeline_support::captures() else {
        return Vec::new();
    };
    vec![
        ("os2_128", pipeline_support::os2_128_sweep(&root)),
        ("hdl32", pipeline_support::hdl32_sweep(&root)),
    ]
}

fn voxel(c: &mut Criterion, name: &str, raw: &[Point]) {
    let mut g = c.benchmark_group(format!("voxel/{name}"));
    g.throughput(Throughput::Elements(raw.len() as u64));
    let mut out = Vec::new();
    for (label, grouping) in [("hash", KeyGrouping::Hash), ("sort", KeyGrouping::Sort)] {
        let mut grid = VoxelGrid::new(VoxelConfig {
            grouping,
            ..VoxelConfig::cubic(LEAF_M)
        })
        .unwrap();
        g.bench_function(label, |b| {
            b.iter(|| grid.downsample(black_box(raw), &mut out))
        });
    }
    let mut grid = VoxelGrid::new(VoxelConfig::cubic(LEAF_M)).unwrap();
    g.bench_function("nearest", |b| {
        b.iter(|| grid.downsample_nearest(black_box(raw), &mut out))
    });
    g.finish();
}

fn stages(c: &mut Criterion, name: &str, raw: &[Point]) {
    let mut grid = VoxelGrid::new(VoxelConfig::cubic(LEAF_M)).unwrap();
    let mut down = Vec::new();
    grid.downsample(raw, &mut down);
    let mut labels = Vec::new();

    let mut g = c.benchmark_group(format!("ground/{name}"));
    g.throughput(Throughput::Elements(down.len() as u64));
    let polar = GroundMethod::PolarGrid(PolarGridParams::default());
    for (label, method) in [("ransac", RANSAC), ("polar", polar)] {
        let mut seg = GroundSegmenter::new(method).unwrap();
        g.bench_function(label, |b| {
            b.iter(|| seg.segment(black_box(&down), &mut labels))
        });
    }
    g.finish();

    GroundSegmenter::new(polar)
        .unwrap()
        .segment(&down, &mut labels);
    let mut g = c.benchmark_group(format!("cluster/{name}"));
    g.throughput(Throughput::Elements(down.len() as u64));
    let mut cl = Clusterer::new(CLUSTER).unwrap();
    let mut clusters = Clusters::new();
    g.bench_function("non_ground", |b| {
        b.iter(|| cl.cluster_excluding(black_box(&down), &labels, &mut clusters))
    });
    g.finish();

    let mut g = c.benchmark_group(format!("pipeline/{name}"));
    g.throughput(Throughput::Elements(raw.len() as u64));
    for (label, method) in [("ransac", RANSAC), ("polar", polar)] {
        let mut seg = GroundSegmenter::new(method).unwrap();
        g.bench_function(label, |b| {
            b.iter(|| {
                grid.downsample(black_box(raw), &mut down);
                seg.segment(&down, &mut labels);
                cl.cluster_excluding(&down, &labels, &mut clusters);
                clusters.len()
            })
        });
    }
    g.finish();
}

fn benches(c: &mut Criterion) {
    for (name, raw) in sweeps() {
        voxel(c, name, &raw);
        stages(c, name, &raw);
    }
}

criterion_group! {
    name = pipeline;
    config = Criterion::default().sample_size(20).warm_up_time(std::time::Duration::from_millis(500)).measurement_time(std::time::Duration::from_secs(2));
    targets = benches
}
criterion_main!(pipeline);
