//! Euclidean clustering: the connected components of the graph "two points are joined when
//! their distance is ≤ `tolerance_m`" (PCL's `EuclideanClusterExtraction` semantics, and
//! Open3D's `cluster_dbscan` with `min_points = 1`), keeping the components whose size lies in
//! `[min_points, max_points]`.
//!
//! How: the points are binned into cubic cells, on one of two grids, and a union–find over
//! the points joins, for each cell, its own points and those of the cells within reach:
//! - **coarse** (first choice): cells a hair wider than the tolerance (`s = tol·(1 + 1e-8)`).
//!   Points two cells apart on an axis are farther apart than the tolerance, so only cells
//!   within ±1 on every axis can be joined: each column (x, y cell) is compared with itself
//!   and its 4 forward neighbours of the 3×3 column block (each unordered pair once), sliding
//!   a ±1 window in z. Within a cell (at most 64 points) the components come from a
//!   breadth-first search over bit sets of its points that tests each point it reaches only
//!   against those not reached yet (about one test per point in a cell of close points,
//!   where testing every pair cost a union per pair); a cell whose points are one component
//!   is marked so (it stays so), and two such cells are joined by their roots when any pair
//!   of their points is within the tolerance, skipped at once when they are already one
//!   component. Other cells test every pair against their neighbours.
//! - **fine**, when some coarse cell holds more than 64 points (a raw sweep near the sensor):
//!   cells of side `s = tol·(1 − 1e-8) / √3`, so that any two points of one cell are within
//!   the tolerance (the diagonal is `√3·s`) and every cell is one component without a test.
//!   Cells whose coordinates differ by `(a, b, c)` are at least `s·√(Σ max(|·| − 1, 0)²)`
//!   apart, more than the tolerance (≈ √3·s) once an offset reaches 3: cells within ±2 can
//!   be joined, 12 forward neighbour columns of the 5×5 block, a ±2 window in z. Every cell
//!   is one component, so every join goes by roots as above, and pairs within a cell cost
//!   nothing. Two cells of many points first drop the points of one farther than the
//!   tolerance from the other's bounding box, so dense cells that are not joined (two
//!   surfaces a little farther apart than the tolerance) cost a test a point, not a pair.
//!
//! The coarse grid does the work of the pipeline's input (voxel centroids, a few per coarse
//! cell) in about half the time of the fine grid, whose 5×5×5 neighbourhood holds many
//! near-empty cells at that density (BENCHMARKS.md "Pipeline end to end"); with at most 64
//! points a cell, its pair tests stay bounded per point on any input. The fine grid stays
//! linear on dense clouds, where one coarse cell can hold thousands of points.
//!
//! Cells and columns come from one sort, with no hashing: each candidate's cell coordinates,
//! relative to the smallest, are packed x above y above z in as many bits as each axis's
//! extent needs, and the (key, candidate) pairs are sorted by a stable LSD radix sort (digits
//! of up to 12 bits, a pass skipped when its digit never varies). A cell is a run of equal keys,
//! a column a run of equal x, y bits, its cells already in z order, and each cell's points in
//! ascending index order. Walking the columns in (x, y) order, the target column of each
//! offset only moves forward, so one cursor per offset finds every neighbour column without a
//! look-up. A join makes the smaller point position the root, so after the joins one forward
//! pass points every point straight at its root. The result is exact on either grid: the
//! same partition as a brute-force search (tests check this on real sweeps and on random
//! clouds, sparse and dense). All buffers are kept between calls.
//!
//! Distances are computed in `f64` from the `f32` coordinates, so ties at exactly the
//! tolerance are decided as a double-precision reference decides them.
//!
//! Each cluster carries its point indices (ascending), count, centroid, axis-aligned box and a
//! yaw-oriented box: the minimum-area rectangle enclosing the convex hull of its points in the
//! xy plane (Andrew's monotone chain, then rotating calipers: the optimal rectangle has a
//! side on a hull edge), extruded over the cluster's z range. Clusters are ordered by their
//! smallest point index, so the output is deterministic.
//!
//! Points with a NaN or infinite coordinate, and points more than 2^20 fine cells from the
//! origin (about 300 km at a 0.5 m tolerance), belong to no cluster and are counted in
//! [`ClusterStats`].

use super::{positive, GridScale, PipelineError, KEY_BIAS};
use crate::point::Point;

/// Parameters of a [`Clusterer`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClusterParams {
    /// Points closer than or at this distance, metres, are in the same cluster; finite, > 0.
    pub tolerance_m: f64,
    /// Smaller components are dropped; ≥ 1.
    pub min_points: usize,
    /// Larger components are dropped; ≥ `min_points`.
    pub max_points: usize,
}

impl ClusterParams {
    /// Parameters from their values (checked by [`Clusterer::new`]); e.g. `new(0.5, 10,
    /// usize::MAX)`: 0.5 m, at least 10 points, no upper bound.
    pub fn new(tolerance_m: f64, min_points: usize, max_points: usize) -> Self {
        Self {
            tolerance_m,
            min_points,
            max_points,
        }
    }
}

/// A yaw-oriented box: a rectangle in the xy plane rotated by `yaw_rad` about z, over a z
/// range.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OrientedBox {
    /// Centre, metres.
    pub center: [f32; 3],
    /// Length (along the yaw direction, the longer xy side), width, height; metres.
    pub size_m: [f32; 3],
    /// Direction of the length side from the x axis, radians, in `(-π/2, π/2]`.
    pub yaw_rad: f32,
}

/// One cluster. Its point indices are in [`Clusters::points_of`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Cluster {
    /// Number of points.
    pub point_count: usize,
    /// Mean of the points, metres.
    pub centroid: [f32; 3],
    /// Axis-aligned box: minimum corner, metres.
    pub min: [f32; 3],
    /// Axis-aligned box: maximum corner, metres.
    pub max: [f32; 3],
    /// Minimum-area yaw-oriented box.
    pub oriented: OrientedBox,
    /// Offset of this cluster's indices in [`Clusters`]' index buffer.
    start: usize,
}

/// The clusters of one call: reuse it between calls so its buffers stay warm.
#[derive(Clone, Debug, Default)]
pub struct Clusters {
    clusters: Vec<Cluster>,
    indices: Vec<u32>,
}

impl Clusters {
    /// An empty set.
    pub fn new() -> Self {
        Self::default()
    }

    /// The clusters, ordered by their smallest point index.
    pub fn as_slice(&self) -> &[Cluster] {
        &self.clusters
    }

    /// Number of clusters.
    pub fn len(&self) -> usize {
        self.clusters.len()
    }

    /// True when there is no cluster.
    pub fn is_empty(&self) -> bool {
        self.clusters.is_empty()
    }

    /// Indices into the clustered slice of the points of cluster `k` (ascending); empty for
    /// a `k` out of range.
    pub fn points_of(&self, k: usize) -> &[u32] {
        self.clusters
            .get(k)
            .and_then(|c| self.indices.get(c.start..c.start + c.point_count))
            .unwrap_or(&[])
    }

    fn clear(&mut self) {
        self.clusters.clear();
        self.indices.clear();
    }
}

/// What one call did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ClusterStats {
    /// Points considered (not excluded, finite, in range).
    pub candidates: usize,
    /// Connected components found among them.
    pub components: usize,
    /// Components dropped for having fewer than `min_points` points.
    pub too_small: usize,
    /// Components dropped for having more than `max_points` points.
    pub too_large: usize,
    /// Points skipped for a NaN or infinite coordinate or lying too far from the origin.
    pub skipped: usize,
    /// The call used the fine grid (some coarse cell held more than 64 points; see the
    /// module docs).
    pub fine_grid: bool,
}

/// A coarse cell holding more points than this makes the clusterer use the fine grid.
const COARSE_MAX_POINTS: usize = 64;

/// Forward half of the 5×5 column neighbourhood (12 offsets): each unordered pair of
/// columns is visited once. Its first four are the forward half of the 3×3 neighbourhood.
const COLUMN_NEIGHBOURS: [[i64; 2]; 12] = [
    [0, 1],
    [1, -1],
    [1, 0],
    [1, 1],
    [0, 2],
    [1, -2],
    [1, 2],
    [2, -2],
    [2, -1],
    [2, 0],
    [2, 1],
    [2, 2],
];

/// The two cell grids (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Grid {
    /// Cells a little wider than the tolerance: neighbours within ±1 on every axis.
    Coarse,
    /// Cells of tolerance / √3, each within the tolerance across: neighbours within ±2.
    Fine,
}

impl Grid {
    /// Cell side for a tolerance.
    fn side(self, tol: f64) -> f64 {
        match self {
            // Wider by 1e-8: the cell of a coordinate is computed with a rounding error of
            // at most 2^-32 cells (indices stay below 2^20), so points two cells apart on an
            // axis are always farther apart than the tolerance.
            Grid::Coarse => tol * (1.0 + 1e-8),
            // The diagonal, √3 · side, is a hair under the tolerance (the same rounding):
            // any two points of a cell are within it.
            Grid::Fine => tol / 3f64.sqrt() * (1.0 - 1e-8),
        }
    }

    /// How many cells apart on an axis two points can be joined.
    fn reach(self) -> i32 {
        match self {
            Grid::Coarse => 1,
            Grid::Fine => 2,
        }
    }

    /// Forward column offsets within the reach.
    fn column_offsets(self) -> &'static [[i64; 2]] {
        match self {
            Grid::Coarse => &COLUMN_NEIGHBOURS[..4],
            Grid::Fine => &COLUMN_NEIGHBOURS,
        }
    }
}

/// What [`Clusterer::bin`] made.
struct Layout {
    cells: usize,
    columns: usize,
    ybits: u32,
}

/// A reusable Euclidean clusterer. See the module docs.
#[derive(Clone, Debug)]
pub struct Clusterer {
    params: ClusterParams,
    /// Candidate point indices, ascending.
    cand: Vec<u32>,
    /// Cell coordinates of each candidate, biased by `KEY_BIAS`.
    cell_ijk: Vec<[u32; 3]>,
    /// (relative cell key, candidate position), sorted by key; and the radix sort's scratch.
    pairs: Vec<(u64, u32)>,
    scratch: Vec<(u64, u32)>,
    counts: Vec<u32>,
    /// Position of each candidate in the cell-ordered arrays.
    at_of: Vec<u32>,
    /// Per cell: start of its points in the cell-ordered arrays (len = cells + 1).
    cell_start: Vec<u32>,
    /// Per column: start of its cells (len = columns + 1) and its relative (x, y) key.
    col_start: Vec<u32>,
    col_key: Vec<u64>,
    /// Relative z index of each cell (read sequentially by the z windows).
    col_z: Vec<i32>,
    /// Cell-ordered coordinates.
    xyz: Vec<[f32; 3]>,
    /// Union–find parent per point (cell order).
    parent: Vec<u32>,
    /// Per cell: all its points are in one component (they then stay so).
    single: Vec<bool>,
    /// Per root: points in the component, then cluster id.
    comp_size: Vec<u32>,
    comp_cluster: Vec<u32>,
    /// Accepted roots with their smallest point index.
    roots: Vec<(u32, u32)>,
    /// Hull scratch.
    hull: Vec<[f64; 2]>,
    xy: Vec<[f64; 2]>,
}

impl Clusterer {
    /// A clusterer with validated parameters: `tolerance_m` finite and > 0, `min_points` ≥ 1,
    /// `max_points` ≥ `min_points`.
    pub fn new(params: ClusterParams) -> Result<Self, PipelineError> {
        positive("tolerance_m", params.tolerance_m)?;
        if params.min_points == 0 {
            return Err(PipelineError::InvalidParameter {
                name: "min_points",
                value: 0.0,
                expected: "≥ 1",
            });
        }
        if params.max_points < params.min_points {
            return Err(PipelineError::InvalidParameter {
                name: "max_points",
                value: params.max_points as f64,
                expected: "≥ min_points",
            });
        }
        Ok(Self {
            params,
            cand: Vec::new(),
            cell_ijk: Vec::new(),
            pairs: Vec::new(),
            scratch: Vec::new(),
            counts: Vec::new(),
            at_of: Vec::new(),
            cell_start: Vec::new(),
            col_start: Vec::new(),
            col_key: Vec::new(),
            col_z: Vec::new(),
            xyz: Vec::new(),
            parent: Vec::new(),
            single: Vec::new(),
            comp_size: Vec::new(),
            comp_cluster: Vec::new(),
            roots: Vec::new(),
            hull: Vec::new(),
            xy: Vec::new(),
        })
    }

    /// The parameters.
    pub fn params(&self) -> &ClusterParams {
        &self.params
    }

    /// Clusters every point of `points` into `out` (cleared first).
    pub fn cluster(&mut self, points: &[Point], out: &mut Clusters) -> ClusterStats {
        self.run(points, |_| false, out)
    }

    /// Clusters the points whose `exclude` flag is false (a point without a flag, past the
    /// end of `exclude`, is included): pass the ground labels to cluster the non-ground
    /// points. Indices in `out` refer to `points`.
    pub fn cluster_excluding(
        &mut self,
        points: &[Point],
        exclude: &[bool],
        out: &mut Clusters,
    ) -> ClusterStats {
        self.run(points, |i| exclude.get(i).copied().unwrap_or(false), out)
    }

    fn run(
        &mut self,
        points: &[Point],
        excluded: impl Fn(usize) -> bool,
        out: &mut Clusters,
    ) -> ClusterStats {
        out.clear();
        let mut stats = ClusterStats::default();
        let tol = self.params.tolerance_m;
        let tol2 = tol * tol;
        let n = points.len().min(u32::MAX as usize - 1);
        stats.skipped += points.len() - n;

        // 1. Candidates: not excluded, finite and within 2^20 fine cells of the origin on
        //    every axis (then within range of the coarse grid too), with their coarse cells.
        let fine = GridScale::new(Grid::Fine.side(tol));
        let coarse = GridScale::new(Grid::Coarse.side(tol));
        let (skipped, mut range) = self.select(points, n, excluded, fine, coarse);
        stats.skipped += skipped;
        stats.candidates = self.cand.len();

        // 2–4. Cells, then the joins: on the coarse grid unless one of its cells holds more
        //      than `COARSE_MAX_POINTS` points, on the fine grid then.
        let mut grid = Grid::Coarse;
        let mut bits = self.sort_cells(range);
        if self.a_cell_holds_more_than(COARSE_MAX_POINTS) {
            grid = Grid::Fine;
            range = self.cells_on(points, fine);
            bits = self.sort_cells(range);
        }
        let layout = self.build_cells(points, bits);
        self.join(grid, &layout, tol2);
        stats.fine_grid = grid == Grid::Fine;
        let nc = self.cand.len();

        // 5. Component sizes, accepted components ordered by their smallest point index.
        self.comp_size.clear();
        self.comp_size.resize(nc, 0);
        self.comp_cluster.clear();
        self.comp_cluster.resize(nc, u32::MAX);
        self.roots.clear();
        for &r in &self.parent {
            self.comp_size[r as usize] += 1;
        }
        for (c, &r) in self.parent.iter().enumerate() {
            if r as usize != c {
                continue;
            }
            stats.components += 1;
            let size = self.comp_size[c] as usize;
            if size < self.params.min_points {
                stats.too_small += 1;
            } else if size > self.params.max_points {
                stats.too_large += 1;
            } else {
                self.roots.push((u32::MAX, c as u32));
            }
        }
        // Smallest point index per accepted root: candidates are ascending, so the first
        // candidate met in each component is its smallest.
        for (&i, &at) in self.cand.iter().zip(&self.at_of) {
            let r = self.parent[at as usize];
            if self.comp_cluster[r as usize] == u32::MAX {
                self.comp_cluster[r as usize] = i;
            }
        }
        for e in &mut self.roots {
            e.0 = self.comp_cluster[e.1 as usize];
        }
        self.roots.sort_unstable();
        self.comp_cluster.iter_mut().for_each(|v| *v = u32::MAX);
        let mut start = 0usize;
        for (k, &(_, r)) in self.roots.iter().enumerate() {
            self.comp_cluster[r as usize] = k as u32;
            let count = self.comp_size[r as usize] as usize;
            out.clusters.push(Cluster {
                point_count: count,
                start,
                ..Cluster::default()
            });
            start += count;
        }

        // 6. Indices per cluster (ascending) and the sums for the centroids and boxes.
        out.indices.resize(start, 0);
        // `comp_size` becomes each cluster's fill cursor.
        for (k, c) in out.clusters.iter().enumerate() {
            self.comp_size[k] = c.start as u32;
        }
        for (&i, &at) in self.cand.iter().zip(&self.at_of) {
            let r = self.parent[at as usize];
            let k = self.comp_cluster[r as usize];
            if k != u32::MAX {
                let slot = self.comp_size[k as usize] as usize;
                self.comp_size[k as usize] += 1;
                out.indices[slot] = i;
            }
        }
        for c in &mut out.clusters {
            let idx = &out.indices[c.start..c.start + c.point_count];
            describe(points, idx, c, &mut self.xy, &mut self.hull);
        }
        stats
    }

    /// Fills `cand` with the points to cluster (not `excluded`, within range of the `fine`
    /// grid) and `cell_ijk` with their cells on the `coarse` grid, biased by
    /// `KEY_BIAS`; returns the points skipped and the smallest and largest biased cells.
    fn select(
        &mut self,
        points: &[Point],
        n: usize,
        excluded: impl Fn(usize) -> bool,
        fine: GridScale,
        coarse: GridScale,
    ) -> (usize, ([u32; 3], [u32; 3])) {
        // Coordinates below this in magnitude are within 2^20 − 1 fine cells of the origin:
        // their range check needs no division.
        let near = (KEY_BIAS - 1) as f64 * fine.side * (1.0 - 1e-9);
        let mut skipped = 0;
        let (mut lo, mut hi) = ([u32::MAX; 3], [0u32; 3]);
        self.cand.clear();
        self.cell_ijk.clear();
        for (i, p) in points.iter().enumerate().take(n) {
            if excluded(i) {
                continue;
            }
            let v = [f64::from(p.x), f64::from(p.y), f64::from(p.z)];
            let (a, fa) = coarse.biased_fast(v[0]);
            let (b, fb) = coarse.biased_fast(v[1]);
            let (c, fc) = coarse.biased_fast(v[2]);
            let ijk = if fa & fb & fc && v[0].abs().max(v[1].abs()).max(v[2].abs()) < near {
                [a as u32, b as u32, c as u32]
            } else if v.iter().all(|&v| fine.index(v).is_some()) {
                // In range of the coarse grid too: its cells are larger.
                v.map(|v| (coarse.index(v).unwrap_or(0) + KEY_BIAS) as u32)
            } else {
                skipped += 1;
                continue;
            };
            for k in 0..3 {
                lo[k] = lo[k].min(ijk[k]);
                hi[k] = hi[k].max(ijk[k]);
            }
            self.cand.push(i as u32);
            self.cell_ijk.push(ijk);
        }
        (skipped, (lo, hi))
    }

    /// `cell_ijk` of the candidates on the grid of `scale` (biased by `KEY_BIAS`); returns
    /// the smallest and largest.
    fn cells_on(&mut self, points: &[Point], scale: GridScale) -> ([u32; 3], [u32; 3]) {
        let (mut lo, mut hi) = ([u32::MAX; 3], [0u32; 3]);
        self.cell_ijk.clear();
        for &i in &self.cand {
            let p = &points[i as usize];
            // In range: checked on this (the fine) grid by `select`.
            let ijk =
                [p.x, p.y, p.z].map(|v| (scale.index(f64::from(v)).unwrap_or(0) + KEY_BIAS) as u32);
            for k in 0..3 {
                lo[k] = lo[k].min(ijk[k]);
                hi[k] = hi[k].max(ijk[k]);
            }
            self.cell_ijk.push(ijk);
        }
        (lo, hi)
    }

    /// Sorts the candidates by their cell (`cell_ijk`, within `lo..=hi`) into `pairs`;
    /// returns the bits of the y and z fields of the keys.
    fn sort_cells(&mut self, (lo, hi): ([u32; 3], [u32; 3])) -> (u32, u32) {
        // Keys relative to the smallest cell coordinates, each axis in as many bits as its
        // extent needs (at most 21: biased indices lie in [0, 2^21)), x above y above z, so
        // that key order is (x, y, z) order: a cell is a run of equal keys, a column (x, y) a
        // run of equal `key >> zbits`, already sorted by z. A stable LSD radix sort of (key,
        // candidate position) keeps each cell's candidates ascending.
        // Bits of the largest relative index, 0 for one value or none.
        let bits = |k: usize| 32 - hi[k].saturating_sub(lo[k]).leading_zeros();
        let (ybits, zbits) = (bits(1), bits(2));
        let total = bits(0) + ybits + zbits;
        self.pairs.clear();
        self.pairs
            .extend(self.cell_ijk.iter().enumerate().map(|(pos, ijk)| {
                let rel = |k: usize| u64::from(ijk[k] - lo[k]);
                ((rel(0) << ybits | rel(1)) << zbits | rel(2), pos as u32)
            }));
        radix_sort(&mut self.pairs, &mut self.scratch, total, &mut self.counts);
        (ybits, zbits)
    }

    /// True when more than `k` sorted candidates share a cell.
    fn a_cell_holds_more_than(&self, k: usize) -> bool {
        self.pairs
            .windows(k + 1)
            .any(|w| w.first().map(|e| e.0) == w.last().map(|e| e.0))
    }

    /// From the sorted candidates: `xyz` (cell order), `at_of`, `cell_start`, the columns
    /// and `col_z`.
    fn build_cells(&mut self, points: &[Point], (ybits, zbits): (u32, u32)) -> Layout {
        // Cells in key order (columns in (x, y) order, z ascending within a column), the
        // candidates grouped by cell, the columns.
        let nc = self.cand.len();
        self.at_of.clear();
        self.at_of.resize(nc, 0);
        self.xyz.clear();
        self.cell_start.clear();
        self.col_start.clear();
        self.col_key.clear();
        self.col_z.clear();
        let zmask = (1u64 << zbits) - 1;
        let mut last: Option<u64> = None;
        for (at, &(key, pos)) in self.pairs.iter().enumerate() {
            if last != Some(key) {
                let column = key >> zbits;
                if last.map(|k| k >> zbits) != Some(column) {
                    self.col_start.push(self.cell_start.len() as u32);
                    self.col_key.push(column);
                }
                self.cell_start.push(at as u32);
                self.col_z.push((key & zmask) as i32);
                last = Some(key);
            }
            self.at_of[pos as usize] = at as u32;
            let p = &points[self.cand[pos as usize] as usize];
            self.xyz.push([p.x, p.y, p.z]);
        }
        let cells = self.cell_start.len();
        self.cell_start.push(nc as u32);
        self.col_start.push(cells as u32);
        Layout {
            cells,
            columns: self.col_key.len(),
            ybits,
        }
    }

    /// Union–find over the points (in cell order): within each cell, then between each cell
    /// and the cells within `grid.reach()` of it on every axis, found by column: a column is
    /// compared with itself and its forward neighbours (each unordered pair once), sliding a
    /// window in z. Neighbour columns are found by one cursor per offset: walking the
    /// columns in (x, y) order, each offset's target only grows.
    fn join(&mut self, grid: Grid, layout: &Layout, tol2: f64) {
        let nc = self.cand.len();
        self.parent.clear();
        self.parent.extend(0..nc as u32);
        self.single.clear();
        for c in 0..layout.cells {
            let (s, e) = (self.cell_start[c] as usize, self.cell_start[c + 1] as usize);
            match grid {
                // Within the tolerance of each other: all one component.
                Grid::Fine => {
                    for a in s + 1..e {
                        self.parent[a] = s as u32;
                    }
                    self.single.push(true);
                }
                // At most `COARSE_MAX_POINTS` (64) points: components by a search over
                // bit sets of the cell's points.
                Grid::Coarse => {
                    let single = match self.xyz.get(s..e) {
                        Some(xyz) if xyz.len() <= 64 => {
                            components_in_cell(xyz, tol2, &mut self.parent[s..e], s as u32)
                        }
                        _ => self.components_by_pairs(s, e, tol2),
                    };
                    self.single.push(single);
                }
            }
        }
        let reach = grid.reach();
        let offsets = grid.column_offsets();
        let ylim = 1u64 << layout.ybits;
        let mut cursors = [0usize; 12];
        for col in 0..layout.columns {
            let own = self.col_start[col] as usize..self.col_start[col + 1] as usize;
            for a in own.clone() {
                let za = self.col_z[a];
                for b in a + 1..own.end {
                    if self.col_z[b] - za > reach {
                        break;
                    }
                    self.link(a, b, tol2);
                }
            }
            let key = self.col_key[col];
            let (cx, cy) = (key >> layout.ybits, key & (ylim - 1));
            for (cursor, &[di, dj]) in cursors.iter_mut().zip(offsets) {
                let ty = cy as i64 + dj;
                if ty < 0 || ty >= ylim as i64 {
                    continue;
                }
                let target = (cx + di as u64) << layout.ybits | ty as u64;
                while *cursor < layout.columns && self.col_key[*cursor] < target {
                    *cursor += 1;
                }
                if *cursor == layout.columns || self.col_key[*cursor] != target {
                    continue;
                }
                let other = *cursor;
                let theirs = self.col_start[other] as usize..self.col_start[other + 1] as usize;
                // Both columns are sorted by z: slide a window of cells within the reach.
                let mut lo = theirs.start;
                for a in own.clone() {
                    let za = self.col_z[a];
                    while lo < theirs.end && self.col_z[lo] < za - reach {
                        lo += 1;
                    }
                    for b in lo..theirs.end {
                        if self.col_z[b] > za + reach {
                            break;
                        }
                        self.link(a, b, tol2);
                    }
                }
            }
        }
        // A join makes the smaller id the root and path halving only shortens paths, so
        // parent[p] ≤ p: one forward pass points every point at its root.
        for p in 0..nc {
            let q = self.parent[p] as usize;
            self.parent[p] = self.parent[q];
        }
    }

    /// The components among points `s..e` (one cell), by testing every pair; true when
    /// they are one. What [`components_in_cell`] does for more than 64 points, which a
    /// coarse cell never holds.
    fn components_by_pairs(&mut self, s: usize, e: usize, tol2: f64) -> bool {
        for a in s..e {
            for b in a + 1..e {
                if dist2(&self.xyz[a], &self.xyz[b]) <= tol2 {
                    union(&mut self.parent, a as u32, b as u32);
                }
            }
        }
        let r = find(&mut self.parent, s as u32);
        (s + 1..e).all(|a| find(&mut self.parent, a as u32) == r)
    }

    /// Joins the components of cells `a` and `b` where a point of one is within the
    /// tolerance of a point of the other.
    #[inline]
    fn link(&mut self, a: usize, b: usize, tol2: f64) {
        let (sa, ea) = (self.cell_start[a] as usize, self.cell_start[a + 1] as usize);
        let (sb, eb) = (self.cell_start[b] as usize, self.cell_start[b + 1] as usize);
        if self.single[a] && self.single[b] {
            // One component each: skipped when it is the same one, else one pair within
            // the tolerance joins them.
            let ra = find(&mut self.parent, sa as u32);
            let rb = find(&mut self.parent, sb as u32);
            if ra != rb && any_within(&self.xyz[sa..ea], &self.xyz[sb..eb], tol2) {
                let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
                self.parent[hi as usize] = lo;
            }
            return;
        }
        // A coarse cell of several components (at most `COARSE_MAX_POINTS` points): every
        // pair.
        for p in sa..ea {
            for q in sb..eb {
                if dist2(&self.xyz[p], &self.xyz[q]) <= tol2 {
                    union(&mut self.parent, p as u32, q as u32);
                }
            }
        }
    }
}

/// Stable LSD radix sort of `pairs` by their key's low `bits` bits, in as few passes as
/// digits of at most 12 bits allow (the bits shared evenly: 24 bits, a sweep's usual key, go
/// in two passes of 12 rather than three of 11; a 4096-entry count table still sits in L1);
/// a pass whose digit is the same for every key is skipped. `scratch` and `counts` are
/// reused.
fn radix_sort(
    pairs: &mut Vec<(u64, u32)>,
    scratch: &mut Vec<(u64, u32)>,
    bits: u32,
    counts: &mut Vec<u32>,
) {
    const MAX_DIGIT: u32 = 12;
    let passes = bits.div_ceil(MAX_DIGIT).max(1);
    let digit = bits.div_ceil(passes).max(1);
    let n = pairs.len();
    scratch.clear();
    scratch.resize(n, (0, 0));
    let mut shift = 0;
    while shift < bits {
        let mask = (1u64 << digit) - 1;
        counts.clear();
        counts.resize(1 << digit, 0);
        for &(k, _) in pairs.iter() {
            counts[((k >> shift) & mask) as usize] += 1;
        }
        if counts.iter().any(|&c| c as usize == n) {
            shift += digit;
            continue;
        }
        let mut sum = 0;
        for c in counts.iter_mut() {
            let here = *c;
            *c = sum;
            sum += here;
        }
        for &e in pairs.iter() {
            let d = ((e.0 >> shift) & mask) as usize;
            scratch[counts[d] as usize] = e;
            counts[d] += 1;
        }
        std::mem::swap(pairs, scratch);
        shift += digit;
    }
}

/// The connected components of the tolerance graph on one cell's points (at most 64, as
/// bits of a `u64`): from the lowest point not yet reached, a breadth-first search that
/// tests each point it takes from the frontier against the points not reached yet only, so
/// a cell whose points are mostly within the tolerance of each other costs about one test
/// per point rather than one per pair. Every point's parent becomes its component's lowest
/// point (`base` + its position), the root a union–find expects; true when there is one
/// component.
fn components_in_cell(xyz: &[[f32; 3]], tol2: f64, parent: &mut [u32], base: u32) -> bool {
    let n = xyz.len().min(64).min(parent.len());
    let mut unreached = if n == 64 { u64::MAX } else { (1u64 << n) - 1 };
    let mut components = 0;
    while unreached != 0 {
        let first = unreached.trailing_zeros();
        unreached &= unreached - 1;
        let mut frontier = 1u64 << first;
        let mut members = frontier;
        while frontier != 0 {
            let i = frontier.trailing_zeros() as usize;
            frontier &= frontier - 1;
            let (mut rest, mut found) = (unreached, 0u64);
            while rest != 0 {
                let j = rest.trailing_zeros() as usize;
                rest &= rest - 1;
                found |= u64::from(dist2(&xyz[i], &xyz[j]) <= tol2) << j;
            }
            unreached &= !found;
            frontier |= found;
            members |= found;
        }
        while members != 0 {
            parent[members.trailing_zeros() as usize] = base + first;
            members &= members - 1;
        }
        components += 1;
    }
    components <= 1
}

/// Root of `x` with path halving.
#[inline]
fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let g = parent[parent[x as usize] as usize];
        parent[x as usize] = g;
        x = g;
    }
    x
}

/// Point pairs of two cells above which [`any_within`] first drops the points of one cell
/// too far from the other's bounding box (below, the box costs more than it saves).
const BOX_FILTER_PAIRS: usize = 4096;

/// True when some point of `a` is within `sqrt(tol2)` of some point of `b`.
#[inline]
fn any_within(a: &[[f32; 3]], b: &[[f32; 3]], tol2: f64) -> bool {
    if a.len().saturating_mul(b.len()) <= BOX_FILTER_PAIRS {
        return a.iter().any(|p| b.iter().any(|q| dist2(p, q) <= tol2));
    }
    // Two dense fine cells that are not joined cost every pair: two surfaces a little farther
    // apart than the tolerance, each cell of them thousands of points, made billions of tests
    // a sweep. A point farther than the tolerance from `b`'s bounding box is farther from all
    // of `b`, so such cells cost one test a point.
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for q in b {
        for k in 0..3 {
            lo[k] = lo[k].min(f64::from(q[k]));
            hi[k] = hi[k].max(f64::from(q[k]));
        }
    }
    let near_box = |p: &&[f32; 3]| {
        let d2: f64 = (0..3)
            .map(|k| {
                let v = f64::from(p[k]);
                let d = (lo[k] - v).max(v - hi[k]).max(0.0);
                d * d
            })
            .sum();
        d2 <= tol2
    };
    a.iter()
        .filter(near_box)
        .any(|p| b.iter().any(|q| dist2(p, q) <= tol2))
}

/// Squared distance, computed in `f64` from the `f32` coordinates.
#[inline]
fn dist2(p: &[f32; 3], q: &[f32; 3]) -> f64 {
    let dx = f64::from(q[0]) - f64::from(p[0]);
    let dy = f64::from(q[1]) - f64::from(p[1]);
    let dz = f64::from(q[2]) - f64::from(p[2]);
    dx * dx + dy * dy + dz * dz
}

/// Joins the components of `a` and `b`; the smaller root becomes the root.
#[inline]
fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
        parent[hi as usize] = lo;
    }
}

/// Fills a cluster's centroid, axis-aligned and oriented boxes from its points.
fn describe(
    points: &[Point],
    idx: &[u32],
    c: &mut Cluster,
    xy: &mut Vec<[f64; 2]>,
    hull: &mut Vec<[f64; 2]>,
) {
    let mut sum = [0f64; 3];
    let mut min = [f32::INFINITY; 3];
    let mut max = [f32::NEG_INFINITY; 3];
    xy.clear();
    for &i in idx {
        let Some(p) = points.get(i as usize) else {
            continue;
        };
        for (k, v) in [p.x, p.y, p.z].into_iter().enumerate() {
            sum[k] += f64::from(v);
            min[k] = min[k].min(v);
            max[k] = max[k].max(v);
        }
        xy.push([f64::from(p.x), f64::from(p.y)]);
    }
    let n = idx.len().max(1) as f64;
    c.centroid = [
        (sum[0] / n) as f32,
        (sum[1] / n) as f32,
        (sum[2] / n) as f32,
    ];
    c.min = min;
    c.max = max;
    drop_interior(xy);
    convex_hull(xy, hull);
    let (center, length, width, yaw) = min_area_rectangle(hull);
    c.oriented = OrientedBox {
        center: [
            center[0] as f32,
            center[1] as f32,
            ((f64::from(min[2]) + f64::from(max[2])) * 0.5) as f32,
        ],
        size_m: [length as f32, width as f32, max[2] - min[2]],
        yaw_rad: yaw as f32,
    };
}

fn cross(o: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

/// Removes points that cannot be hull vertices, in one pass (Akl–Toussaint): those strictly
/// inside the polygon of the extreme points in eight directions (x, y and the diagonals),
/// which are on the hull and in counter-clockwise order along it. On a cluster's points most
/// are inside, so the hull's sort handles a few instead of all (`describe` took a quarter of
/// the clustering stage before). The hull of what is left is the hull of all.
fn drop_interior(pts: &mut Vec<[f64; 2]>) {
    if pts.len() < 16 {
        return;
    }
    // Support points in the directions −90°, −45°, 0°, 45°, 90°, 135°, 180°, 225°.
    let key = |p: [f64; 2]| {
        [
            -p[1],
            p[0] - p[1],
            p[0],
            p[0] + p[1],
            p[1],
            p[1] - p[0],
            -p[0],
            -p[0] - p[1],
        ]
    };
    let mut best = [pts[0]; 8];
    let mut top = key(pts[0]);
    for &p in pts.iter() {
        let k = key(p);
        for d in 0..8 {
            if k[d] > top[d] {
                top[d] = k[d];
                best[d] = p;
            }
        }
    }
    // Each edge as its start and direction, `cross(a, b, q)` without recomputing `b − a`;
    // fewer than eight distinct edges are padded by repeating one, which tests it twice.
    let mut edges = [([0.0; 2], [0.0; 2]); 8];
    let mut n = 0;
    for d in 0..8 {
        let (a, b) = (best[d], best[(d + 1) % 8]);
        if a != b {
            edges[n] = (a, [b[0] - a[0], b[1] - a[1]]);
            n += 1;
        }
    }
    if n < 3 {
        return;
    }
    for k in n..8 {
        edges[k] = edges[0];
    }
    // All eight tests, and the compaction, without a branch.
    let mut kept = 0;
    for r in 0..pts.len() {
        let q = pts[r];
        let inside = edges.iter().fold(true, |inside, &(a, u)| {
            inside & (u[0] * (q[1] - a[1]) - u[1] * (q[0] - a[0]) > 0.0)
        });
        pts[kept] = q;
        kept += usize::from(!inside);
    }
    pts.truncate(kept);
}

/// Convex hull of `pts` (sorted in place), counter-clockwise, no collinear points: Andrew's
/// monotone chain.
fn convex_hull(pts: &mut [[f64; 2]], hull: &mut Vec<[f64; 2]>) {
    hull.clear();
    pts.sort_unstable_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    if pts.len() < 3 {
        hull.extend_from_slice(pts);
        hull.dedup();
        return;
    }
    for &p in pts.iter() {
        while hull.len() >= 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0 {
            hull.pop();
        }
        hull.push(p);
    }
    let lower = hull.len() + 1;
    for &p in pts.iter().rev().skip(1) {
        while hull.len() >= lower && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0 {
            hull.pop();
        }
        hull.push(p);
    }
    hull.pop(); // the first point again
}

/// Minimum-area enclosing rectangle of a convex polygon (counter-clockwise): centre, length
/// (longer side), width, yaw of the length side in (-π/2, π/2]. Rotating calipers: for each
/// hull edge, the rectangle with a side on that edge; the extreme points along the edge, along
/// its normal and against the edge advance monotonically as the edges turn.
fn min_area_rectangle(hull: &[[f64; 2]]) -> ([f64; 2], f64, f64, f64) {
    match hull.len() {
        0 => return ([0.0; 2], 0.0, 0.0, 0.0),
        1 => return (hull[0], 0.0, 0.0, 0.0),
        _ => {}
    }
    let h = hull.len();
    let dot = |a: [f64; 2], b: [f64; 2]| a[0] * b[0] + a[1] * b[1];
    let after = |k: usize| if k + 1 == h { 0 } else { k + 1 };
    // Moves caliper `k` forward while `f` does not decrease (at most once round).
    fn advance(hull: &[[f64; 2]], k: &mut usize, f: impl Fn([f64; 2]) -> f64) {
        for _ in 0..hull.len() {
            let next = if *k + 1 == hull.len() { 0 } else { *k + 1 };
            if f(hull[next]) >= f(hull[*k]) {
                *k = next;
            } else {
                break;
            }
        }
    }
    // Area, centre, length, width, direction of the length side.
    let mut best = (f64::INFINITY, [0.0; 2], 0.0, 0.0, [1.0, 0.0]);
    let (mut far_u, mut far_v, mut near_u) = (1usize, 1usize, 0usize);
    for i in 0..h {
        let a = hull[i];
        let b = hull[after(i)];
        let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
        if len == 0.0 {
            continue;
        }
        let u = [(b[0] - a[0]) / len, (b[1] - a[1]) / len];
        let v = [-u[1], u[0]]; // inward normal of a counter-clockwise polygon
        advance(hull, &mut far_u, |p| dot(p, u));
        advance(hull, &mut far_v, |p| dot(p, v));
        if i == 0 {
            near_u = far_u; // from the far end, -u·p rises to the near end
        }
        advance(hull, &mut near_u, |p| -dot(p, u));
        let (umax, umin) = (dot(hull[far_u], u), dot(hull[near_u], u));
        let (vmin, vmax) = (dot(a, v), dot(hull[far_v], v));
        let (du, dv) = (umax - umin, vmax - vmin);
        let area = du * dv;
        if area < best.0 {
            let cu = (umax + umin) * 0.5;
            let cv = (vmax + vmin) * 0.5;
            let center = [cu * u[0] + cv * v[0], cu * u[1] + cv * v[1]];
            let (length, width, dir) = if du >= dv { (du, dv, u) } else { (dv, du, v) };
            best = (area, center, length, width, dir);
        }
    }
    let (_, center, length, width, dir) = best;
    let mut yaw = dir[1].atan2(dir[0]);
    if yaw <= -core::f64::consts::FRAC_PI_2 {
        yaw += core::f64::consts::PI;
    } else if yaw > core::f64::consts::FRAC_PI_2 {
        yaw -= core::f64::consts::PI;
    }
    (center, length, width, yaw)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pt(x: f32, y: f32, z: f32) -> Point {
        Point {
            x,
            y,
            z,
            ..Point::default()
        }
    }

    /// Blobs of points around random centres plus scattered points: many components of many
    /// sizes, with gaps near the tolerance.
    fn cloud(n: usize, seed: u64) -> Vec<Point> {
        let mut s = seed;
        let mut r = move || {
            s = s
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((s >> 40) as f32) / (1u64 << 24) as f32
        };
        let mut v = Vec::with_capacity(n);
        while v.len() < n {
            let c = [r() * 40.0 - 20.0, r() * 40.0 - 20.0, r() * 3.0];
            let size = (r() * r() * 200.0) as usize + 1;
            let spread = r() * 1.5;
            for _ in 0..size.min(n - v.len()) {
                v.push(pt(
                    c[0] + (r() - 0.5) * spread,
                    c[1] + (r() - 0.5) * spread,
                    c[2] + (r() - 0.5) * spread,
                ));
            }
        }
        v
    }

    /// O(n²) reference: breadth-first search over "distance ≤ tolerance" (f64), components
    /// with a size in [min, max], each as ascending indices, ordered by smallest index.
    fn reference(
        points: &[Point],
        keep: &[bool],
        tol: f64,
        min: usize,
        max: usize,
    ) -> Vec<Vec<u32>> {
        let n = points.len();
        let mut seen = vec![false; n];
        let mut out = Vec::new();
        let d2 = |a: &Point, b: &Point| {
            let dx = f64::from(a.x) - f64::from(b.x);
            let dy = f64::from(a.y) - f64::from(b.y);
            let dz = f64::from(a.z) - f64::from(b.z);
            dx * dx + dy * dy + dz * dz
        };
        for s in 0..n {
            if seen[s] || !keep[s] {
                continue;
            }
            seen[s] = true;
            let mut comp = vec![s as u32];
            let mut q = 0;
            while q < comp.len() {
                let a = comp[q] as usize;
                q += 1;
                for b in 0..n {
                    if !seen[b] && keep[b] && d2(&points[a], &points[b]) <= tol * tol {
                        seen[b] = true;
                        comp.push(b as u32);
                    }
                }
            }
            comp.sort_unstable();
            if comp.len() >= min && comp.len() <= max {
                out.push(comp);
            }
        }
        out
    }

    fn partition(c: &Clusters) -> Vec<Vec<u32>> {
        (0..c.len()).map(|k| c.points_of(k).to_vec()).collect()
    }

    #[test]
    fn same_partition_as_an_o_n2_reference() {
        let points = cloud(3_000, 5);
        let exclude: Vec<bool> = (0..points.len()).map(|i| i % 7 == 3).collect();
        let keep: Vec<bool> = exclude.iter().map(|e| !e).collect();
        let mut out = Clusters::new();
        for (tol, min, max) in [
            (0.3, 1, usize::MAX),
            (0.5, 5, 150),
            (0.12, 2, 40),
            (1.0, 1, 10_000),
        ] {
            let mut c = Clusterer::new(ClusterParams::new(tol, min, max)).unwrap();
            let stats = c.cluster_excluding(&points, &exclude, &mut out);
            let expected = reference(&points, &keep, tol, min, max);
            assert_eq!(partition(&out), expected, "tolerance {tol}");
            assert_eq!(
                stats.components - stats.too_small - stats.too_large,
                expected.len()
            );
            assert_eq!(stats.candidates, keep.iter().filter(|&&k| k).count());
            for (k, cl) in out.as_slice().iter().enumerate() {
                assert_eq!(cl.point_count, expected[k].len());
            }
        }
    }

    /// A point of a random cloud: on a lattice of step `tol / 2` (so pairs exactly at the
    /// tolerance and duplicates are common), around one of a few centres that may lie far
    /// apart (up to ~1e5 tolerances: every bit width of the radix keys), or non-finite.
    fn lattice_point() -> impl proptest::strategy::Strategy<Value = (u8, [i16; 3])> {
        use proptest::prelude::*;
        (0u8..6, prop::array::uniform3(-8i16..8))
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(200))]
        #[test]
        fn random_clouds_partition_as_the_o_n2_reference(
            raw in proptest::collection::vec(lattice_point(), 0..300),
            tol in proptest::sample::select(vec![0.05, 0.3, 0.5, 1.7]),
            min in 1usize..4,
            spread in proptest::sample::select(vec![1.0f64, 50.0, 3.0e4]),
            copies in proptest::sample::select(vec![1usize, 1, 70]),
        ) {
            let centres = [
                [0.0, 0.0, 0.0],
                [spread, -spread, 0.5],
                [-spread, spread * 0.5, -spread],
                [1.0, 2.0, spread],
                [f64::NAN, 0.0, 0.0],
            ];
            // Each point `copies` times: 70 copies fill coarse cells past 64 points, so both
            // grids are checked.
            let take = if copies > 1 { 20 } else { raw.len() };
            let points: Vec<Point> = raw
                .iter()
                .take(take)
                .flat_map(|r| std::iter::repeat_n(r, copies))
                .map(|&(c, [a, b, d])| {
                    let centre = centres[usize::from(c) % centres.len()];
                    let step = tol / 2.0 * if c == 5 { 0.93 } else { 1.0 };
                    pt(
                        (centre[0] * tol + f64::from(a) * step) as f32,
                        (centre[1] * tol + f64::from(b) * step) as f32,
                        (centre[2] * tol + f64::from(d) * step) as f32,
                    )
                })
                .collect();
            let keep: Vec<bool> = points
                .iter()
                .map(|p| p.x.is_finite() && p.y.is_finite() && p.z.is_finite())
                .collect();
            let mut out = Clusters::new();
            let mut c = Clusterer::new(ClusterParams::new(tol, min, 120)).unwrap();
            // Twice with one clusterer: reused buffers give the same answer.
            for _ in 0..2 {
                let stats = c.cluster(&points, &mut out);
                proptest::prop_assert_eq!(partition(&out), reference(&points, &keep, tol, min, 120));
                proptest::prop_assert_eq!(stats.skipped, keep.iter().filter(|k| !**k).count());
            }
        }
    }

    #[test]
    fn a_coarse_cell_of_two_components_and_a_dense_cloud_on_the_fine_grid() {
        // Tolerance 0.5: p0 and p1 share the coarse cell (0, 0, 0) but lie 0.69 m apart;
        // p2 (cell (0, 0, 1)) is 0.40 m from p1 and 0.98 m from p0; p3 (cell (0, 0, −1)) is
        // 0.35 m from p0 and 0.92 m from p1. Components {p0, p3} and {p1, p2}.
        let split = [
            pt(0.05, 0.05, 0.05),
            pt(0.45, 0.45, 0.45),
            pt(0.45, 0.45, 0.85),
            pt(0.05, 0.05, -0.3),
        ];
        let mut c = Clusterer::new(ClusterParams::new(0.5, 1, 100)).unwrap();
        let mut out = Clusters::new();
        let stats = c.cluster(&split, &mut out);
        assert!(!stats.fine_grid);
        assert_eq!(partition(&out), vec![vec![0, 3], vec![1, 2]]);
        // The same with 80 points packed in a 4 cm box beside p0 (one coarse cell over 64
        // points): the fine grid, the same components, the box joined to p0's.
        let mut dense = split.to_vec();
        for k in 0..80 {
            let f = |v: u32| (v % 4) as f32 * 0.01;
            dense.push(pt(0.1 + f(k), 0.1 + f(k / 4), 0.1 + f(k / 16)));
        }
        let stats = c.cluster(&dense, &mut out);
        assert!(stats.fine_grid);
        let keep = vec![true; dense.len()];
        let expected = reference(&dense, &keep, 0.5, 1, 100);
        assert_eq!(partition(&out), expected);
        assert_eq!(expected.len(), 2);
        assert_eq!(expected[1], vec![1, 2]);
    }

    /// Two dense slabs (hundreds of points a fine cell) farther apart than the tolerance, and
    /// nearer than it: the cell pairs between them go through the bounding-box filter of
    /// `any_within` (every pair of points, before), with the reference's components.
    #[test]
    fn dense_slabs_apart_and_together_partition_as_the_reference() {
        for gap in [0.7f32, 0.45] {
            let mut points = Vec::new();
            for z in [0.0, gap] {
                for i in 0..50 {
                    for j in 0..50 {
                        points.push(pt(i as f32 * 0.02, j as f32 * 0.02, z));
                    }
                }
            }
            let mut c = Clusterer::new(ClusterParams::new(0.5, 1, usize::MAX)).unwrap();
            let mut out = Clusters::new();
            let stats = c.cluster(&points, &mut out);
            assert!(stats.fine_grid);
            let keep = vec![true; points.len()];
            let expected = reference(&points, &keep, 0.5, 1, usize::MAX);
            assert_eq!(expected.len(), if gap > 0.5 { 2 } else { 1 });
            assert_eq!(partition(&out), expected, "gap {gap}");
        }
    }

    #[test]
    fn pairs_exactly_at_the_tolerance_are_joined() {
        // Points 0.5 m apart along x (exact in binary), and one 0.5 + 1e-6 m away.
        let points = [
            pt(0.0, 0.0, 0.0),
            pt(0.5, 0.0, 0.0),
            pt(1.000_001, 0.0, 0.0),
        ];
        let mut c = Clusterer::new(ClusterParams::new(0.5, 1, 10)).unwrap();
        let mut out = Clusters::new();
        c.cluster(&points, &mut out);
        assert_eq!(partition(&out), vec![vec![0, 1], vec![2]]);
    }

    #[test]
    fn boxes_of_a_rotated_rectangle() {
        // A 4 m × 2 m × 1.5 m block of points, yawed by 30°, centred at (10, -3, 0.75).
        let yaw = 30f64.to_radians();
        let (c, s) = (yaw.cos(), yaw.sin());
        let mut points = Vec::new();
        for i in 0..=40 {
            for j in 0..=20 {
                for k in 0..=6 {
                    let (u, v) = (i as f64 * 0.1 - 2.0, j as f64 * 0.1 - 1.0);
                    points.push(pt(
                        (10.0 + c * u - s * v) as f32,
                        (-3.0 + s * u + c * v) as f32,
                        k as f32 * 0.25,
                    ));
                }
            }
        }
        let mut cl = Clusterer::new(ClusterParams::new(0.3, 1, usize::MAX)).unwrap();
        let mut out = Clusters::new();
        cl.cluster(&points, &mut out);
        assert_eq!(out.len(), 1);
        let b = out.as_slice()[0];
        assert_eq!(b.point_count, points.len());
        let close = |a: f32, e: f64, tol: f64| (f64::from(a) - e).abs() < tol;
        assert!(
            close(b.centroid[0], 10.0, 1e-4)
                && close(b.centroid[1], -3.0, 1e-4)
                && close(b.centroid[2], 0.75, 1e-4)
        );
        let o = b.oriented;
        assert!(close(o.yaw_rad, yaw, 1e-5), "{o:?}");
        assert!(
            close(o.size_m[0], 4.0, 1e-4)
                && close(o.size_m[1], 2.0, 1e-4)
                && close(o.size_m[2], 1.5, 1e-6),
            "{o:?}"
        );
        assert!(
            close(o.center[0], 10.0, 1e-4)
                && close(o.center[1], -3.0, 1e-4)
                && close(o.center[2], 0.75, 1e-6)
        );
        // Axis-aligned box: half extents 2·cos30 + 1·sin30 along x, 2·sin30 + 1·cos30 along y.
        let hx = 2.0 * c + s;
        let hy = 2.0 * s + c;
        assert!(close(b.min[0], 10.0 - hx, 1e-4) && close(b.max[0], 10.0 + hx, 1e-4));
        assert!(close(b.min[1], -3.0 - hy, 1e-4) && close(b.max[1], -3.0 + hy, 1e-4));
    }

    /// The hull after `drop_interior` is the hull of all the points: random clouds, points
    /// on a lattice (ties for every extreme, collinear runs), a segment, one repeated point.
    #[test]
    fn dropping_interior_points_keeps_the_hull() {
        let mut s = 99u64;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 33) as f64 / (1u64 << 31) as f64
        };
        let mut clouds: Vec<Vec<[f64; 2]>> = Vec::new();
        for n in [16, 17, 40, 200, 3000] {
            clouds.push(
                (0..n)
                    .map(|_| [next() * 10.0 - 5.0, next() * 3.0])
                    .collect(),
            );
            clouds.push(
                (0..n)
                    .map(|_| [(next() * 6.0).floor() * 0.2, (next() * 4.0).floor() * 0.2])
                    .collect(),
            );
            clouds.push(
                (0..n)
                    .map(|_| {
                        let t = next();
                        [t, 2.0 * t]
                    })
                    .collect(),
            );
            clouds.push(vec![[1.5, -2.0]; n]);
            // A rotated thin rectangle, like a wall.
            clouds.push(
                (0..n)
                    .map(|_| {
                        let (u, v) = (next() * 8.0, next() * 0.3);
                        [0.8 * u - 0.6 * v + 3.0, 0.6 * u + 0.8 * v - 1.0]
                    })
                    .collect(),
            );
        }
        let (mut a, mut b) = (Vec::new(), Vec::new());
        for (k, cloud) in clouds.iter().enumerate() {
            let mut all = cloud.clone();
            convex_hull(&mut all, &mut a);
            let mut kept = cloud.clone();
            drop_interior(&mut kept);
            convex_hull(&mut kept, &mut b);
            assert_eq!(
                a,
                b,
                "cloud {k} ({} points, {} kept)",
                cloud.len(),
                kept.len()
            );
            if cloud.len() >= 200 && k % 5 == 0 {
                assert!(
                    kept.len() < cloud.len() / 2,
                    "cloud {k}: {} of {} kept",
                    kept.len(),
                    cloud.len()
                );
            }
        }
    }

    #[test]
    fn minimum_area_rectangle_on_hand_made_hulls() {
        let mut hull = Vec::new();
        // A unit square rotated 45° (a diamond): the optimal box is the square itself.
        let mut pts = vec![
            [1.0, 0.0],
            [0.0, 1.0],
            [-1.0, 0.0],
            [0.0, -1.0],
            [0.0, 0.0],
            [0.5, 0.2],
        ];
        convex_hull(&mut pts, &mut hull);
        assert_eq!(hull.len(), 4);
        let (c, l, w, yaw) = min_area_rectangle(&hull);
        let r2 = 2f64.sqrt();
        assert!(
            (l - r2).abs() < 1e-12
                && (w - r2).abs() < 1e-12
                && c[0].abs() < 1e-12
                && c[1].abs() < 1e-12
        );
        assert!((yaw.abs() - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
        // Collinear points: a segment of length 5 along (3, 4).
        let mut pts = vec![[0.0, 0.0], [3.0, 4.0], [1.5, 2.0]];
        convex_hull(&mut pts, &mut hull);
        let (_, l, w, yaw) = min_area_rectangle(&hull);
        assert!(
            (l - 5.0).abs() < 1e-12 && w.abs() < 1e-12 && (yaw - 4f64.atan2(3.0)).abs() < 1e-12
        );
        // One point and none.
        let mut pts = vec![[2.0, 1.0], [2.0, 1.0]];
        convex_hull(&mut pts, &mut hull);
        assert_eq!(min_area_rectangle(&hull), ([2.0, 1.0], 0.0, 0.0, 0.0));
        assert_eq!(min_area_rectangle(&[]), ([0.0, 0.0], 0.0, 0.0, 0.0));
    }

    /// Points near the edge of the range, 2^20 fine cells from the origin, are candidates
    /// exactly when the division puts them inside it (the other coordinates off cell
    /// boundaries, so that the fast path decides).
    #[test]
    fn the_range_edge_is_the_divisions() {
        let tol = 0.5;
        let side = Grid::Fine.side(tol);
        let mut c = Clusterer::new(ClusterParams::new(tol, 1, 5)).unwrap();
        let mut out = Clusters::new();
        let (mut inside, mut outside) = (0, 0);
        for edge in [KEY_BIAS as f64 * side, -(KEY_BIAS as f64) * side] {
            let e = edge as f32;
            for step in -40i32..=40 {
                let v = f32::from_bits((e.to_bits() as i32 + step) as u32);
                let expected_in = crate::pipeline::grid_index(f64::from(v) / side).is_some();
                for p in [pt(v, 0.3, 0.7), pt(1.1, v, 2.2), pt(0.6, -3.3, v)] {
                    let stats = c.cluster(&[p], &mut out);
                    assert_eq!(stats.skipped == 0, expected_in, "{v} on an axis");
                    assert_eq!(out.len(), usize::from(expected_in));
                }
                if expected_in {
                    inside += 1;
                } else {
                    outside += 1;
                }
            }
        }
        assert!(inside > 20 && outside > 20, "{inside} {outside}");
    }

    #[test]
    fn non_finite_points_are_skipped_and_invalid_parameters_named() {
        let points = [
            pt(f32::NAN, 0.0, 0.0),
            pt(0.0, 0.0, 0.0),
            pt(0.1, 0.0, 0.0),
            pt(1e30, 0.0, 0.0),
        ];
        let mut c = Clusterer::new(ClusterParams::new(0.2, 1, 5)).unwrap();
        let mut out = Clusters::new();
        let stats = c.cluster(&points, &mut out);
        assert_eq!(partition(&out), vec![vec![1, 2]]);
        assert_eq!(stats.skipped, 2);
        assert!(out.points_of(7).is_empty());
        for (p, name) in [
            (ClusterParams::new(0.0, 1, 5), "tolerance_m"),
            (ClusterParams::new(f64::NAN, 1, 5), "tolerance_m"),
            (ClusterParams::new(0.5, 0, 5), "min_points"),
            (ClusterParams::new(0.5, 6, 5), "max_points"),
        ] {
            assert!(
                matches!(Clusterer::new(p), Err(PipelineError::InvalidParameter { name: n, .. }) if n == name),
                "{p:?}"
            );
        }
    }
}
