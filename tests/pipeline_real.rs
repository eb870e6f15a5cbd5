//! The pipeline stages on real sweeps (HDL-32E and OS-2-128 from `../shared/captures`),
//! against naive references written here.

mod pipeline_support;

use pipeline_support::{captures, hdl32_sweep, hdl32_sweeps, os2_128_sweep};

#[test]
fn sweeps_decode() {
    let Some(root) = captures() else { return };
    let h: Vec<usize> = hdl32_sweeps(&root).iter().map(|s| s.len()).collect();
    let o = os2_128_sweep(&root).len();
    eprintln!("HDL-32E sweeps {h:?}; OS-2-128 {o}");
    assert_eq!(hdl32_sweep(&root).len(), h[1]);
}

use std::collections::BTreeMap;

use ringscan::pipeline::cluster::ClusterParams;
use ringscan::pipeline::cluster::Clusterer;
use ringscan::pipeline::cluster::Clusters;
use ringscan::pipeline::ground::GroundMethod;
use ringscan::pipeline::ground::GroundSegmenter;
use ringscan::pipeline::ground::PolarGridParams;
use ringscan::pipeline::voxel::GridOrigin;
use ringscan::pipeline::voxel::KeyGrouping;
use ringscan::pipeline::voxel::VoxelConfig;
use ringscan::pipeline::voxel::VoxelGrid;
use ringscan::Point;

/// Naive voxel reference: a BTreeMap from floor((p − origin) / leaf) (f64) to point indices.
fn voxels_reference(points: &[Point], leaf: [f64; 3], origin: [f64; 3]) -> Vec<Vec<usize>> {
    let mut m: BTreeMap<[i64; 3], Vec<usize>> = BTreeMap::new();
    for (i, p) in points.iter().enumerate() {
        let c = [f64::from(p.x), f64::from(p.y), f64::from(p.z)];
        let k = [0, 1, 2].map(|a| ((c[a] - origin[a]) / leaf[a]).floor() as i64);
        m.entry(k).or_default().push(i);
    }
    m.into_values().collect()
}

fn min_bound(points: &[Point]) -> [f64; 3] {
    let m = |f: fn(&Point) -> f32| {
        points
            .iter()
            .map(|p| f64::from(f(p)))
            .fold(f64::INFINITY, f64::min)
    };
    [m(|p| p.x), m(|p| p.y), m(|p| p.z)]
}

#[test]
fn voxels_hold_the_same_points_as_a_btreemap_reference_on_real_sweeps() {
    let Some(root) = captures() else { return };
    for (name, sweep) in [
        ("HDL-32E", hdl32_sweep(&root)),
        ("OS-2-128", os2_128_sweep(&root)),
    ] {
        let mb = min_bound(&sweep);
        for (leaf, origin) in [
            ([0.1; 3], GridOrigin::At([0.0; 3])),
            ([0.2, 0.2, 0.1], GridOrigin::At([0.05, -0.03, 0.5])),
            ([0.1; 3], GridOrigin::MinBoundMinusHalfLeaf),
            ([0.5; 3], GridOrigin::MinBoundMinusHalfLeaf),
        ] {
            let o = match origin {
                GridOrigin::At(o) => o,
                GridOrigin::MinBoundMinusHalfLeaf => [
                    mb[0] - leaf[0] * 0.5,
                    mb[1] - leaf[1] * 0.5,
                    mb[2] - leaf[2] * 0.5,
                ],
            };
            let reference = voxels_reference(&sweep, leaf, o);
            for grouping in [KeyGrouping::Hash, KeyGrouping::Sort] {
                let mut grid = VoxelGrid::new(VoxelConfig {
                    leaf_size_m: leaf,
                    origin,
                    grouping,
                })
                .unwrap();
                let mut out = Vec::new();
                let stats = grid.downsample(&sweep, &mut out);
                assert_eq!(
                    out.len(),
                    reference.len(),
                    "{name} {leaf:?} {origin:?} {grouping:?}"
                );
                assert_eq!((stats.non_finite, stats.out_of_range), (0, 0));
                // Group the input by the voxel the grid put each point in.
                let mut mine: Vec<Vec<usize>> = vec![Vec::new(); out.len()];
                for (i, &v) in grid.voxel_of_points().iter().enumerate() {
                    mine[v as usize].push(i);
                }
                // Each output point is the mean of its group, with its first point's t and ring.
                for (v, group) in mine.iter().enumerate() {
                    let n = group.len() as f64;
                    let mean = |f: fn(&Point) -> f32| {
                        (group.iter().map(|&i| f64::from(f(&sweep[i]))).sum::<f64>() / n) as f32
                    };
                    let p = out[v];
                    assert_eq!(
                        [p.x, p.y, p.z, p.intensity],
                        [
                            mean(|p| p.x),
                            mean(|p| p.y),
                            mean(|p| p.z),
                            mean(|p| p.intensity)
                        ]
                    );
                    assert_eq!(
                        (p.t, p.ring, p.ret),
                        (sweep[group[0]].t, sweep[group[0]].ring, sweep[group[0]].ret)
                    );
                }
                mine.sort();
                let mut expected = reference.clone();
                expected.sort();
                assert!(
                    mine == expected,
                    "{name} {leaf:?} {origin:?} {grouping:?}: points per voxel differ"
                );
            }
            eprintln!("{name}: {} points, leaf {leaf:?} {origin:?}: {} voxels, same points per voxel as the reference", sweep.len(), reference.len());
        }
    }
}

/// Brute-force connected components of "distance ≤ tol" (f64): every pair with |Δx| ≤ tol is
/// measured (the points are walked in x order, so pairs farther apart in x are never looked
/// at; nothing else is pruned). Components in [min, max], as ascending index lists, sorted.
fn components_reference(
    points: &[Point],
    keep: &[bool],
    tol: f64,
    min: usize,
    max: usize,
) -> Vec<Vec<u32>> {
    let mut by_x: Vec<usize> = (0..points.len()).filter(|&i| keep[i]).collect();
    by_x.sort_by(|&a, &b| points[a].x.total_cmp(&points[b].x));
    let xs: Vec<f64> = by_x.iter().map(|&i| f64::from(points[i].x)).collect();
    let mut seen = vec![false; by_x.len()];
    let mut out = Vec::new();
    let d2 = |a: &Point, b: &Point| {
        let dx = f64::from(a.x) - f64::from(b.x);
        let dy = f64::from(a.y) - f64::from(b.y);
        let dz = f64::from(a.z) - f64::from(b.z);
        dx * dx + dy * dy + dz * dz
    };
    for s in 0..by_x.len() {
        if seen[s] {
            continue;
        }
        seen[s] = true;
        let mut comp = vec![s];
        let mut q = 0;
        while q < comp.len() {
            let a = comp[q];
            q += 1;
            let lo = xs.partition_point(|&x| x < xs[a] - tol);
            for b in lo..by_x.len() {
                if xs[b] > xs[a] + tol {
                    break;
                }
                if !seen[b] && d2(&points[by_x[a]], &points[by_x[b]]) <= tol * tol {
                    seen[b] = true;
                    comp.push(b);
                }
            }
        }
        let mut c: Vec<u32> = comp.iter().map(|&k| by_x[k] as u32).collect();
        c.sort_unstable();
        if c.len() >= min && c.len() <= max {
            out.push(c);
        }
    }
    out.sort();
    out
}

fn partition(c: &Clusters) -> Vec<Vec<u32>> {
    let mut v: Vec<Vec<u32>> = (0..c.len()).map(|k| c.points_of(k).to_vec()).collect();
    v.sort();
    v
}

#[test]
fn clusters_are_the_connected_components_on_voxelised_real_sweeps() {
    let Some(root) = captures() else { return };
    for (name, sweep) in [
        ("HDL-32E", hdl32_sweep(&root)),
        ("OS-2-128", os2_128_sweep(&root)),
    ] {
        let mut down = Vec::new();
        VoxelGrid::new(VoxelConfig::cubic(0.1))
            .unwrap()
            .downsample(&sweep, &mut down);
        let mut ground = Vec::new();
        GroundSegmenter::new(GroundMethod::PolarGrid(PolarGridParams::default()))
            .unwrap()
            .segment(&down, &mut ground);
        let all = vec![false; down.len()];
        for (what, exclude) in [("all points", &all), ("non-ground", &ground)] {
            let keep: Vec<bool> = exclude.iter().map(|e| !e).collect();
            for (tol, min, max) in [
                (0.5, 1, usize::MAX),
                (0.5, 10, 2_000),
                (0.25, 3, usize::MAX),
            ] {
                let mut c = Clusterer::new(ClusterParams::new(tol, min, max)).unwrap();
                let mut out = Clusters::new();
                c.cluster_excluding(&down, exclude, &mut out);
                let expected = components_reference(&down, &keep, tol, min, max);
                assert!(
                    partition(&out) == expected,
                    "{name} {what} tol {tol} [{min}, {max}]: partitions differ ({} vs {} clusters)",
                    out.len(),
                    expected.len()
                );
                eprintln!("{name} voxelised 0.1 m ({} points), {what}, tolerance {tol} m, size [{min}, {max}]: {} clusters, same partition as the brute-force reference", down.len(), out.len());
            }
        }
    }
}
