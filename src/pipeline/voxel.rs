//! Voxel-grid downsampling: one output point per occupied voxel.
//!
//! A point `p` falls in voxel `(i, j, k) = floor((p − origin) / leaf)` per axis, computed in
//! `f64` from the `f32` coordinates with the result of the division as written (a
//! multiplication by `1/leaf`, cheaper, whose floor is taken only away from cell boundaries:
//! within 2^-20 of one the division is done), so that a reference computing the same
//! formula, such as Open3D's `voxel_down_sample`, puts every point in the same voxel. The
//! origin is either a fixed point ([`GridOrigin::At`], default the sensor origin: the grid
//! then does not move from sweep to sweep) or, as Open3D does, the cloud's minimum corner
//! less half a leaf ([`GridOrigin::MinBoundMinusHalfLeaf`]).
//!
//! Each voxel index is biased by 2^20 and packed into 21 bits per axis of a `u64` key, so a
//! voxel is a single integer: ±2^20 leaves per axis around the origin (±105 km at a 0.1 m
//! leaf). Points outside that range, and points with a NaN or infinite coordinate, are skipped
//! and counted in [`VoxelStats`]; they never panic.
//!
//! Two ways to group the keys, both linear or near-linear in the points, chosen by
//! [`KeyGrouping`]:
//! - `Hash` (default): an open-addressing table of `u64` keys (multiplicative hash, linear
//!   probing, at most three-quarters full), mapping a key to its voxel slot in order of first
//!   appearance. One pass computes every point's key, a second looks them up (reading each
//!   key's slot a few points ahead, so that cache misses overlap), a third accumulates the
//!   sums; the output follows the input order of each voxel's first point.
//! - `Sort`: `(key, index)` pairs sorted with `sort_unstable`, then one pass over the runs
//!   (small_gicp's approach); the output is in ascending key order.
//!
//! Hash is the default because it measured faster on real sweeps (`tools/bench/pipeline.rs`,
//! one thread, BENCHMARKS.md "Pipeline"): 1.9 against 2.8 ms on a 49 k-point HDL-32E sweep,
//! 5.6 against 7.6 ms on a 120 k-point OS-2-128 frame (0.1 m leaf), and its output keeps scan
//! order.
//!
//! Outputs ([`VoxelGrid::downsample`]):
//! - **centroid**: x, y, z and intensity are the means of the voxel's points (summed in
//!   `f64`); `t`, `ring` and `ret` are those of the voxel's *first point in input order* (the
//!   mean of a ring index is not a ring, and the first point is the one a scan-ordered sweep
//!   met first).
//! - **nearest to centroid** ([`VoxelGrid::downsample_nearest`]): the original point of the
//!   voxel closest to that centroid (ties: the first in input order), all attributes kept.
//!
//! The grid keeps its buffers; once they have grown to a sweep's size, later sweeps of that
//! size allocate nothing (the caller's `out` is cleared and reused too).

use super::{pack_key, positive, GridScale, KeyTable, PipelineError, NO_KEY};
use crate::point::Point;

/// Where voxel `(0, 0, 0)` starts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GridOrigin {
    /// A fixed point, metres, in the frame of the points (default: `[0, 0, 0]`).
    At([f64; 3]),
    /// The minimum corner of the finite points of each call, less half a leaf per axis:
    /// Open3D's `voxel_down_sample` convention (its `voxel_min_bound`).
    MinBoundMinusHalfLeaf,
}

impl Default for GridOrigin {
    fn default() -> Self {
        Self::At([0.0; 3])
    }
}

/// How points are grouped by voxel key. Both give the same voxels; see the module docs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum KeyGrouping {
    /// Open-addressing hash table; output in order of each voxel's first point.
    #[default]
    Hash,
    /// Sort of `(key, index)` pairs; output in ascending key order.
    Sort,
}

/// Parameters of a [`VoxelGrid`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VoxelConfig {
    /// Voxel edge lengths along x, y, z, metres; each finite and > 0.
    pub leaf_size_m: [f64; 3],
    /// Where the grid starts.
    pub origin: GridOrigin,
    /// How keys are grouped.
    pub grouping: KeyGrouping,
}

impl VoxelConfig {
    /// Cubic voxels of `leaf_size_m` metres, grid at the sensor origin, hash grouping.
    pub fn cubic(leaf_size_m: f64) -> Self {
        Self {
            leaf_size_m: [leaf_size_m; 3],
            origin: GridOrigin::default(),
            grouping: KeyGrouping::default(),
        }
    }
}

/// What one call did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct VoxelStats {
    /// Occupied voxels = points written.
    pub voxels: usize,
    /// Input points skipped for a NaN or infinite coordinate.
    pub non_finite: usize,
    /// Input points skipped for lying more than 2^20 leaves from the origin on some axis.
    pub out_of_range: usize,
}

/// Marks a skipped point.
const SKIPPED: u32 = u32::MAX;

/// Marks, in the hash grouping's key pass, a point out of the key range (non-finite points
/// are marked [`NO_KEY`]); packed keys use at most 63 bits, so neither is a key.
const OUT_OF_RANGE: u64 = u64::MAX - 1;

/// How many points ahead the hash grouping reads a key's home slot.
const LOOK_AHEAD: usize = 16;

/// The packed voxel key of `p`, or [`NO_KEY`] for a point with a NaN or infinite coordinate,
/// or [`OUT_OF_RANGE`]. Inlined into both key loops (as a closure called from two places it
/// was not). A non-finite coordinate has no index either, so the finiteness test is only
/// made for a point without a key.
#[inline(always)]
fn voxel_key(p: &Point, origin: &[f64; 3], scales: &[GridScale; 3]) -> u64 {
    let ix = scales[0].index(f64::from(p.x) - origin[0]);
    let iy = scales[1].index(f64::from(p.y) - origin[1]);
    let iz = scales[2].index(f64::from(p.z) - origin[2]);
    match (ix, iy, iz) {
        (Some(i), Some(j), Some(k)) => pack_key(i, j, k),
        _ if p.x.is_finite() && p.y.is_finite() && p.z.is_finite() => OUT_OF_RANGE,
        _ => NO_KEY,
    }
}

/// Marks, in the hash grouping's key pass, a point whose key the branch-free pass could not
/// give (see [`fast_voxel_key`]); never left in the keys.
const NEEDS_EXACT: u64 = u64::MAX - 2;

/// The packed voxel key of `p` when every axis is clear of cell boundaries and in range,
/// else [`NEEDS_EXACT`]: without a branch, so the key pass runs without mispredictions and
/// stalls; [`voxel_key`] does the few others.
#[inline(always)]
fn fast_voxel_key(p: &Point, origin: &[f64; 3], scales: &[GridScale; 3]) -> u64 {
    let (i, a) = scales[0].biased_fast(f64::from(p.x) - origin[0]);
    let (j, b) = scales[1].biased_fast(f64::from(p.y) - origin[1]);
    let (k, c) = scales[2].biased_fast(f64::from(p.z) - origin[2]);
    let key = i << 42 | j << 21 | k;
    if a & b & c {
        key
    } else {
        NEEDS_EXACT
    }
}

/// Running sums of one voxel.
#[derive(Clone, Copy, Debug, Default)]
struct Acc {
    sum: [f64; 4],
    count: u32,
    first: u32,
}

/// A reusable voxel-grid downsampler. See the module docs.
#[derive(Debug, Clone)]
pub struct VoxelGrid {
    config: VoxelConfig,
    /// Per input point: its voxel slot, or `SKIPPED`.
    slot_of: Vec<u32>,
    /// Hash grouping: key → voxel slot.
    table: KeyTable,
    /// Hash grouping: the key of each input point (or a skip marker), computed in a pass of
    /// their own.
    keys: Vec<u64>,
    /// Sort grouping: (key, point index).
    pairs: Vec<(u64, u32)>,
    /// Per voxel slot: sums, count, first point.
    acc: Vec<Acc>,
    /// Nearest mode: best squared distance and point per slot.
    best: Vec<(f64, u32)>,
}

impl VoxelGrid {
    /// A grid with validated parameters: every leaf size finite and > 0, a fixed origin
    /// finite.
    pub fn new(config: VoxelConfig) -> Result<Self, PipelineError> {
        positive("leaf_size_m[0]", config.leaf_size_m[0])?;
        positive("leaf_size_m[1]", config.leaf_size_m[1])?;
        positive("leaf_size_m[2]", config.leaf_size_m[2])?;
        if let GridOrigin::At(o) = config.origin {
            for (name, v) in [
                ("origin[0]", o[0]),
                ("origin[1]", o[1]),
                ("origin[2]", o[2]),
            ] {
                if !v.is_finite() {
                    return Err(PipelineError::InvalidParameter {
                        name,
                        value: v,
                        expected: "finite",
                    });
                }
            }
        }
        Ok(Self {
            config,
            slot_of: Vec::new(),
            table: KeyTable::default(),
            keys: Vec::new(),
            pairs: Vec::new(),
            acc: Vec::new(),
            best: Vec::new(),
        })
    }

    /// The parameters.
    pub fn config(&self) -> &VoxelConfig {
        &self.config
    }

    /// One point per occupied voxel, the voxel's centroid (x, y, z, intensity means; `t`,
    /// `ring`, `ret` of its first point in input order), written to `out` (cleared first).
    pub fn downsample(&mut self, points: &[Point], out: &mut Vec<Point>) -> VoxelStats {
        let stats = self.group(points);
        out.clear();
        out.reserve(self.acc.len());
        for a in &self.acc {
            let n = f64::from(a.count);
            let mut p = points.get(a.first as usize).copied().unwrap_or_default();
            p.x = (a.sum[0] / n) as f32;
            p.y = (a.sum[1] / n) as f32;
            p.z = (a.sum[2] / n) as f32;
            p.intensity = (a.sum[3] / n) as f32;
            out.push(p);
        }
        stats
    }

    /// One point per occupied voxel: the input point closest to the voxel's centroid (ties:
    /// the first in input order), every attribute kept. Written to `out` (cleared first).
    pub fn downsample_nearest(&mut self, points: &[Point], out: &mut Vec<Point>) -> VoxelStats {
        let stats = self.group(points);
        self.best.clear();
        self.best.resize(self.acc.len(), (f64::INFINITY, SKIPPED));
        for (i, (&slot, p)) in self.slot_of.iter().zip(points).enumerate() {
            let (Some(a), Some(b)) = (
                self.acc.get(slot as usize),
                self.best.get_mut(slot as usize),
            ) else {
                continue;
            };
            let n = f64::from(a.count);
            let dx = f64::from(p.x) - a.sum[0] / n;
            let dy = f64::from(p.y) - a.sum[1] / n;
            let dz = f64::from(p.z) - a.sum[2] / n;
            let d2 = dx * dx + dy * dy + dz * dz;
            if d2 < b.0 {
                *b = (d2, i as u32);
            }
        }
        out.clear();
        out.reserve(self.best.len());
        out.extend(
            self.best
                .iter()
                .filter_map(|&(_, i)| points.get(i as usize)),
        );
        stats
    }

    /// For each point of the last call's input, the index in `out` of the point that stands
    /// for its voxel, or `u32::MAX` for a skipped point: to carry labels computed on the
    /// downsampled cloud back to the sweep.
    pub fn voxel_of_points(&self) -> &[u32] {
        &self.slot_of
    }

    /// Fills `slot_of` and `acc` (one slot per voxel, in output order).
    fn group(&mut self, points: &[Point]) -> VoxelStats {
        let [lx, ly, lz] = self.config.leaf_size_m;
        let origin = match self.config.origin {
            GridOrigin::At(o) => o,
            GridOrigin::MinBoundMinusHalfLeaf => {
                let mut min = [f64::INFINITY; 3];
                for p in points {
                    if p.x.is_finite() && p.y.is_finite() && p.z.is_finite() {
                        min[0] = min[0].min(f64::from(p.x));
                        min[1] = min[1].min(f64::from(p.y));
                        min[2] = min[2].min(f64::from(p.z));
                    }
                }
                [min[0] - lx * 0.5, min[1] - ly * 0.5, min[2] - lz * 0.5]
            }
        };
        let mut stats = VoxelStats::default();
        self.slot_of.clear();
        self.acc.clear();
        // Points past u32 indices cannot be addressed by the slot buffers; a sweep never has
        // 4 billion points, so any beyond are counted as out of range.
        let kept = points.len().min(SKIPPED as usize);
        stats.out_of_range += points.len() - kept;
        let points = &points[..kept];
        // `floor((p − origin) / leaf)`, the division's result at a multiplication's cost.
        let scales = [GridScale::new(lx), GridScale::new(ly), GridScale::new(lz)];
        let key_of = |p: &Point| voxel_key(p, &origin, &scales);
        match self.config.grouping {
            KeyGrouping::Hash => {
                // Three passes. The keys first: a tight loop of arithmetic and conversions with
                // no table access in it. Then the table: a new voxel's slot is a cache miss
                // (the table is larger than L2 on a 128 × 1024 sweep, and the slots are
                // spread by the hash), so the home slot of the key `LOOK_AHEAD` points on is
                // read ahead, and the misses of several points overlap instead of queueing.
                // (Measured on the OS-2-128 sweep, BENCHMARKS.md "Pipeline end to end":
                // one pass with the look-ups in it took ~20 % longer.)
                self.keys.clear();
                self.keys
                    .extend(points.iter().map(|p| fast_voxel_key(p, &origin, &scales)));
                for (k, p) in self.keys.iter_mut().zip(points) {
                    if *k == NEEDS_EXACT {
                        *k = key_of(p);
                    }
                }
                self.table.reset(points.len());
                for (i, &key) in self.keys.iter().enumerate() {
                    if let Some(&ahead) = self.keys.get(i + LOOK_AHEAD) {
                        self.table.warm(ahead);
                    }
                    if key == NO_KEY || key == OUT_OF_RANGE {
                        if key == OUT_OF_RANGE {
                            stats.out_of_range += 1;
                        } else {
                            stats.non_finite += 1;
                        }
                        self.slot_of.push(SKIPPED);
                        continue;
                    }
                    // Every point looks its key up, also when it repeats the last one's: a
                    // repeat finds its slot in cache, and a test for it mispredicted (it was
                    // 5-11 % of this stage on the real sweeps, BENCHMARKS.md).
                    let (slot, new) = self.table.insert(key);
                    if new {
                        self.acc.push(Acc {
                            first: i as u32,
                            ..Acc::default()
                        });
                    }
                    self.slot_of.push(slot);
                }
                // The sums in a pass of their own: a voxel met again after other voxels has
                // its sums out of cache, and here their addresses are known ahead (`slot_of`
                // is read in order), so those misses overlap instead of each waiting for the
                // table look-up that found its slot.
                for (p, &slot) in points.iter().zip(&self.slot_of) {
                    if let Some(a) = self.acc.get_mut(slot as usize) {
                        a.sum[0] += f64::from(p.x);
                        a.sum[1] += f64::from(p.y);
                        a.sum[2] += f64::from(p.z);
                        a.sum[3] += f64::from(p.intensity);
                        a.count += 1;
                    }
                }
            }
            KeyGrouping::Sort => {
                self.pairs.clear();
                self.slot_of.resize(points.len(), SKIPPED);
                for (i, p) in points.iter().enumerate() {
                    match key_of(p) {
                        OUT_OF_RANGE => stats.out_of_range += 1,
                        NO_KEY => stats.non_finite += 1,
                        k => self.pairs.push((k, i as u32)),
                    }
                }
                self.pairs.sort_unstable();
                let mut prev = NO_KEY;
                for &(key, i) in &self.pairs {
                    if key != prev {
                        prev = key;
                        self.acc.push(Acc {
                            first: i,
                            ..Acc::default()
                        });
                    }
                    let slot = self.acc.len() - 1;
                    self.slot_of[i as usize] = slot as u32;
                    let p = &points[i as usize];
                    let a = &mut self.acc[slot];
                    a.sum[0] += f64::from(p.x);
                    a.sum[1] += f64::from(p.y);
                    a.sum[2] += f64::from(p.z);
                    a.sum[3] += f64::from(p.intensity);
                    a.count += 1;
                }
            }
        }
        stats.voxels = self.acc.len();
        stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    fn pt(x: f32, y: f32, z: f32, intensity: f32, t: u32, ring: u16) -> Point {
        Point {
            x,
            y,
            z,
            intensity,
            t,
            ring,
            ret: 0,
            pad: 0,
        }
    }

    /// Deterministic pseudo-random points in a box, with a few NaN and far-away points.
    fn cloud(n: usize, seed: u64) -> Vec<Point> {
        let mut s = seed;
        let mut r = move || {
            s = s
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((s >> 40) as f32) / (1u64 << 24) as f32
        };
        let mut v: Vec<Point> = (0..n)
            .map(|i| {
                pt(
                    r() * 8.0 - 4.0,
                    r() * 6.0 - 3.0,
                    r() * 2.0 - 1.0,
                    r() * 255.0,
                    i as u32,
                    i as u16 % 32,
                )
            })
            .collect();
        v.push(pt(f32::NAN, 0.0, 0.0, 0.0, 0, 0));
        v.push(pt(0.0, f32::INFINITY, 0.0, 0.0, 0, 0));
        v.push(pt(1.0e9, 0.0, 0.0, 0.0, 0, 0));
        v
    }

    /// The naive reference: a BTreeMap from floor((p - origin) / leaf) to the point indices.
    fn reference(
        points: &[Point],
        leaf: [f64; 3],
        origin: [f64; 3],
    ) -> BTreeMap<[i64; 3], Vec<usize>> {
        let mut m: BTreeMap<[i64; 3], Vec<usize>> = BTreeMap::new();
        for (i, p) in points.iter().enumerate() {
            let c = [f64::from(p.x), f64::from(p.y), f64::from(p.z)];
            if c.iter().any(|v| !v.is_finite()) {
                continue;
            }
            let k = [0, 1, 2].map(|a| ((c[a] - origin[a]) / leaf[a]).floor());
            if k.iter().any(|v| v.abs() >= (1 << 20) as f64) {
                continue;
            }
            m.entry(k.map(|v| v as i64)).or_default().push(i);
        }
        m
    }

    fn check_against_reference(points: &[Point], config: VoxelConfig, origin: [f64; 3]) {
        let mut grid = VoxelGrid::new(config).unwrap();
        let reference = reference(points, config.leaf_size_m, origin);
        let mut out = Vec::new();
        let stats = grid.downsample(points, &mut out);
        assert_eq!(stats.voxels, reference.len());
        assert_eq!(out.len(), reference.len());
        assert_eq!((stats.non_finite, stats.out_of_range), (2, 1));
        // Expected centroids (f64 means rounded to f32) with the first point's t and ring.
        let mut expected: Vec<Point> = reference
            .values()
            .map(|ix| {
                let n = ix.len() as f64;
                let m = |f: fn(&Point) -> f32| {
                    (ix.iter().map(|&i| f64::from(f(&points[i]))).sum::<f64>() / n) as f32
                };
                let first = points[ix[0]];
                pt(
                    m(|p| p.x),
                    m(|p| p.y),
                    m(|p| p.z),
                    m(|p| p.intensity),
                    first.t,
                    first.ring,
                )
            })
            .collect();
        let key = |p: &Point| (p.t, p.ring);
        expected.sort_by_key(key);
        out.sort_by_key(key);
        assert_eq!(out, expected);

        // Nearest: an input point of each voxel, the closest to the centroid.
        let mut near = Vec::new();
        grid.downsample_nearest(points, &mut near);
        let mut expected_near: Vec<Point> = reference
            .values()
            .map(|ix| {
                let n = ix.len() as f64;
                let c = [
                    ix.iter().map(|&i| f64::from(points[i].x)).sum::<f64>() / n,
                    ix.iter().map(|&i| f64::from(points[i].y)).sum::<f64>() / n,
                    ix.iter().map(|&i| f64::from(points[i].z)).sum::<f64>() / n,
                ];
                let d = |i: usize| {
                    let p = points[i];
                    (f64::from(p.x) - c[0]).powi(2)
                        + (f64::from(p.y) - c[1]).powi(2)
                        + (f64::from(p.z) - c[2]).powi(2)
                };
                let best = ix
                    .iter()
                    .copied()
                    .fold(ix[0], |b, i| if d(i) < d(b) { i } else { b });
                points[best]
            })
            .collect();
        expected_near.sort_by_key(key);
        near.sort_by_key(key);
        assert_eq!(near, expected_near);
    }

    #[test]
    fn same_voxels_as_a_btreemap_reference_both_groupings() {
        let points = cloud(20_000, 7);
        for grouping in [KeyGrouping::Hash, KeyGrouping::Sort] {
            for (leaf, origin) in [
                ([0.1; 3], [0.0; 3]),
                ([0.3, 0.2, 0.05], [0.0; 3]),
                ([0.25; 3], [0.11, -0.07, 0.3]),
            ] {
                let config = VoxelConfig {
                    leaf_size_m: leaf,
                    origin: GridOrigin::At(origin),
                    grouping,
                };
                check_against_reference(&points, config, origin);
            }
        }
    }

    #[test]
    fn open3d_origin_is_the_min_bound_less_half_a_leaf() {
        let points = cloud(5_000, 11);
        let finite = || {
            points
                .iter()
                .filter(|p| p.x.is_finite() && p.y.is_finite() && p.z.is_finite())
        };
        let min = |f: fn(&Point) -> f32| {
            finite()
                .map(|p| f64::from(f(p)))
                .fold(f64::INFINITY, f64::min)
        };
        let leaf = [0.2, 0.2, 0.2];
        let origin = [min(|p| p.x) - 0.1, min(|p| p.y) - 0.1, min(|p| p.z) - 0.1];
        let config = VoxelConfig {
            leaf_size_m: leaf,
            origin: GridOrigin::MinBoundMinusHalfLeaf,
            grouping: KeyGrouping::Hash,
        };
        check_against_reference(&points, config, origin);
    }

    #[test]
    fn two_points_in_one_voxel_average_and_keep_the_first_points_attributes() {
        let points = [
            pt(0.01, 0.02, 0.03, 10.0, 500, 3),
            pt(0.05, 0.06, 0.07, 30.0, 100, 9),
            pt(0.15, 0.0, 0.0, 1.0, 7, 1),
        ];
        let mut grid = VoxelGrid::new(VoxelConfig::cubic(0.1)).unwrap();
        let mut out = vec![Point::default(); 9]; // cleared by the call
        grid.downsample(&points, &mut out);
        assert_eq!(out.len(), 2);
        assert!(
            (out[0].x - 0.03).abs() < 1e-7
                && (out[0].y - 0.04).abs() < 1e-7
                && (out[0].z - 0.05).abs() < 1e-7
        );
        assert_eq!((out[0].intensity, out[0].t, out[0].ring), (20.0, 500, 3));
        assert_eq!(out[1], points[2]);
        // Nearest: both are 0.0346 m from the centroid; the first in input order wins.
        grid.downsample_nearest(&points, &mut out);
        assert_eq!(out, vec![points[0], points[2]]);
    }

    #[test]
    fn negative_coordinates_floor_not_truncate() {
        // -0.05 is in voxel -1, 0.05 in voxel 0: two voxels, not one.
        let points = [
            pt(-0.05, 0.0, 0.0, 0.0, 0, 0),
            pt(0.05, 0.0, 0.0, 0.0, 1, 0),
        ];
        let mut grid = VoxelGrid::new(VoxelConfig::cubic(0.1)).unwrap();
        let mut out = Vec::new();
        assert_eq!(grid.downsample(&points, &mut out).voxels, 2);
    }

    #[test]
    fn invalid_parameters_are_named() {
        for (leaf, name) in [
            ([0.0, 0.1, 0.1], "leaf_size_m[0]"),
            ([0.1, -1.0, 0.1], "leaf_size_m[1]"),
            ([0.1, 0.1, f64::NAN], "leaf_size_m[2]"),
            ([f64::INFINITY, 0.1, 0.1], "leaf_size_m[0]"),
        ] {
            let mut c = VoxelConfig::cubic(0.1);
            c.leaf_size_m = leaf;
            match VoxelGrid::new(c) {
                Err(PipelineError::InvalidParameter { name: n, .. }) => assert_eq!(n, name),
                other => panic!("{leaf:?}: {other:?}"),
            }
        }
        let mut c = VoxelConfig::cubic(0.1);
        c.origin = GridOrigin::At([0.0, f64::NAN, 0.0]);
        assert!(matches!(
            VoxelGrid::new(c),
            Err(PipelineError::InvalidParameter {
                name: "origin[1]",
                ..
            })
        ));
    }

    #[test]
    fn empty_input_gives_empty_output() {
        let mut grid = VoxelGrid::new(VoxelConfig::cubic(0.1)).unwrap();
        let mut out = vec![Point::default()];
        assert_eq!(grid.downsample(&[], &mut out), VoxelStats::default());
        assert!(out.is_empty());
        let mut c = VoxelConfig::cubic(0.1);
        c.origin = GridOrigin::MinBoundMinusHalfLeaf;
        let mut grid = VoxelGrid::new(c).unwrap();
        assert_eq!(
            grid.downsample(&[pt(f32::NAN, 0.0, 0.0, 0.0, 0, 0)], &mut out)
                .non_finite,
            1
        );
        assert!(out.is_empty());
    }
}
