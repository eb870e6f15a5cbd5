//! Once warm, the pipeline stages allocate nothing per sweep: a counting global allocator
//! (test-only; the library itself forbids `unsafe`) watches a second pass over every sweep of
//! the HDL-32E capture (voxel + ground, both methods + clustering + the nearest variant),
//! after a first pass has grown every buffer to its high-water mark.

mod pipeline_support;

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use ringscan::pipeline::cluster::ClusterParams;
use ringscan::pipeline::cluster::Clusterer;
use ringscan::pipeline::cluster::Clusters;
use ringscan::pipeline::ground::GroundMethod;
use ringscan::pipeline::ground::GroundSegmenter;
use ringscan::pipeline::ground::PolarGridParams;
use ringscan::pipeline::voxel::KeyGrouping;
use ringscan::pipeline::voxel::VoxelConfig;
use ringscan::pipeline::voxel::VoxelGrid;

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every call is forwarded unchanged to the system allocator; the counter is the only
// addition.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn no_allocation_per_sweep_once_warm() {
    let Some(root) = pipeline_support::captures() else {
        return;
    };
    let sweeps = pipeline_support::hdl32_sweeps(&root);
    let mut hash = VoxelGrid::new(VoxelConfig::cubic(0.1)).unwrap();
    let mut sort = VoxelGrid::new(VoxelConfig {
        grouping: KeyGrouping::Sort,
        ..VoxelConfig::cubic(0.1)
    })
    .unwrap();
    let mut polar =
        GroundSegmenter::new(GroundMethod::PolarGrid(PolarGridParams::default())).unwrap();
    let mut ransac = GroundSegmenter::new(GroundMethod::Ransac {
        distance_threshold_m: 0.15,
        iterations: 200,
        seed: 3,
    })
    .unwrap();
    let mut clusterer = Clusterer::new(ClusterParams::new(0.5, 10, 5_000)).unwrap();
    let (mut down, mut near, mut labels, mut clusters) =
        (Vec::new(), Vec::new(), Vec::new(), Clusters::new());
    let mut run = |sweep: &[ringscan::Point]| {
        hash.downsample_nearest(sweep, &mut near);
        sort.downsample(sweep, &mut down);
        hash.downsample(sweep, &mut down);
        ransac.segment(&down, &mut labels);
        polar.segment(&down, &mut labels);
        clusterer.cluster_excluding(&down, &labels, &mut clusters);
        clusters.len()
    };
    let start = ALLOCATIONS.load(Ordering::Relaxed);
    for s in &sweeps {
        run(s);
    }
    // The counter works: the first pass grew the buffers.
    assert!(ALLOCATIONS.load(Ordering::Relaxed) > start);
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    let mut found = 0;
    for s in &sweeps {
        found += run(s);
    }
    let allocations = ALLOCATIONS.load(Ordering::Relaxed) - before;
    eprintln!(
        "{} sweeps, {found} clusters in the second pass: {allocations} allocations",
        sweeps.len()
    );
    assert!(found > 0);
    assert_eq!(allocations, 0);
}
