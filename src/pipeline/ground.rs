//! Ground segmentation: one label per point, `true` for ground.
//!
//! Two methods ([`GroundMethod`]):
//!
//! - **RANSAC** (`Ransac`): the single plane with the most points within
//!   `distance_threshold_m`, from `iterations` random triples drawn by a seeded generator
//!   (SplitMix64), so a run is reproducible; the inliers of the best plane are ground. This is
//!   what Open3D's `segment_plane` does, and it is right only when the ground is one plane: on a
//!   slope change, a ramp or a kerb part of the ground lies outside the plane.
//!
//! - **Polar grid with local planes** (`PolarGrid`), for slopes, ramps and kerbs. The xy plane
//!   around the sensor is cut into sectors (equal angles) and rings (at least `radial_bin_m`
//!   wide, growing with range so bins stay roughly square). In each bin a plane is fitted to
//!   the lowest points: the seeds are the points up to the threshold plus the rise of a
//!   `max_slope_deg` slope across the bin above the mean of the lowest ten (a seed band of the
//!   threshold alone keeps only a strip of a sloped bin, whose fit then lies flat); least
//!   squares `z = a x + b y + c` on them, refitted on the points within a band narrowing to
//!   `distance_threshold_m`. When a bin's points lie along one line (a single scan line
//!   crosses it, common at range with few channels) the line fixes only one direction: a
//!   small ridge term on the slopes makes the fit take the most horizontal plane containing
//!   it instead of a noise-driven one. Walking each
//!   sector outwards, a bin's plane is accepted as ground if it is no steeper than
//!   `max_slope_deg` and continues the last accepted ground of that sector: at the bin's inner
//!   edge it is within `max_step_m` of it, plus the rise a `max_slope_deg` slope allows over
//!   any skipped bins. The first reference is the plane `z = −sensor_height_m` when given. A
//!   point is ground when it lies at most `distance_threshold_m` above its bin's accepted plane
//!   (if the bin's own plane was rejected: above the sector's last accepted plane, extended).
//!   A second layer per bin (a plane fitted to the points up to a step above the first, for
//!   the pavement past a kerb) was tried and dropped: on the simulated scenes it gained under
//!   0.5 % recall and cost up to 0.8 % precision, fitting the low rows of object sides.
//!
//!   Why this design: one plane per small bin follows slope changes (RANSAC's single plane
//!   loses a ramp); seeding from the lowest points keeps object sides out of the fit; the
//!   outward continuity test keeps flat object tops (car roofs, box tops: flat but far above
//!   the ground before them) out. Measured on simulated scenes (`tests/pipeline_sim.rs`,
//!   HDL-32E and OS-1-128): precision ≥ 0.986 and recall ≥ 0.984 on flat ground, a 10 %
//!   slope and a 15 % ramp to a plateau, where RANSAC's recall falls to 0.85–0.89 on the ramp.
//!
//!   **Riser test** (kerb faces). A kerb face lower than the threshold (15 cm against
//!   0.15 m) lies within it of the road's plane, so the planes alone call it ground
//!   (precision 0.95 on the simulated kerb scene). After the planes, the ground points are
//!   cut into radial profiles: azimuth columns `riser_column_deg` wide (about the sensor's
//!   azimuth step, so a column holds one firing direction's points), each sorted by range
//!   in xy. A point is then moved to not-ground when, within 1 m of it along its profile,
//!   the surface rises more steeply than `max_slope_deg` — by more than `riser_margin_m` —
//!   from a point below it (nearer the sensor or at the same range) and some point beyond
//!   it is higher still by the margin, or the same the other way round: it lies part-way up
//!   a rise steeper than ground may be, i.e. on a face. The foot and the top of a step stay
//!   ground (nothing lies below the foot, nothing above the top), and a slope up to
//!   `max_slope_deg` has no rise steep enough. Seen along the profile, a face is steep even
//!   when a single scan line crosses it (along the scan line it looks like a gentle ramp,
//!   which is why tests on xy neighbourhoods, tried before, failed). The margin sits above
//!   the points' height noise: 0.01 m for clean points or ~1 cm of range noise, 0.02 m for
//!   ~2 cm. Measured (`tests/pipeline_sim.rs`, HDL-32E and OS-1-128, clean, 1 cm and 2 cm
//!   of range noise): kerb precision 0.951–0.958 → 0.980–0.987, recall ≥ 0.989; on the
//!   other scenes precision ≥ 0.991 and recall ≥ 0.974 (it also moves the lowest rows of
//!   object sides out of the ground). It misses the faces a ring crosses only where its
//!   neighbours along the profile are far apart (an HDL-32E at 6–16 m: a 15 cm rise over
//!   0.6 m is no steeper than 15°). On a real street sweep (OS-2-128, 0.2 m voxels) it moves
//!   6 % of the ground voxels (HDL-32E: 2.5 %); drawn, they lie along the feet of the
//!   building walls and the kerbs, not on the open road (there is no truth to count them
//!   against). On 0.2 m voxel centroids, as the default pipeline feeds it, a 15 cm face
//!   shares its voxels with the road and pavement beside it and little of it is left to
//!   find: kerb precision per input point 0.951 → 0.953 (HDL-32E), 0.956 → 0.959
//!   (OS-1-128). Cost ~0.6 ms on the OS-2-128 sweep. Off with `riser_column_deg = 0`.
//!
//!   Tried and dropped before it: a face test relabelling a ground point that lies, within
//!   0.3 m in xy, steeply above the lowest point of a 0.1 m grid cell and steeply below the
//!   highest point of another (kerb precision 0.970 on the OS-1-128, 0.952 on the HDL-32E,
//!   where the nearest road and pavement points of a face are ~0.4 m apart in xy).
//!
//! Points with a NaN or infinite coordinate are labelled not ground.

use nalgebra::Vector3;

use super::{positive, within, PipelineError};
use crate::point::Point;

/// Parameters of the polar-grid method. See the module docs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PolarGridParams {
    /// Angular sectors around the sensor; 4 ..= 4096.
    pub sectors: u32,
    /// Smallest radial extent of a bin, metres; finite, > 0.
    pub radial_bin_m: f64,
    /// Points farther than this in xy, metres, are not ground; finite, > 0.
    pub max_range_m: f64,
    /// A point at most this far above its local ground plane is ground, metres; finite, > 0.
    pub distance_threshold_m: f64,
    /// Steepest slope still ground, degrees; in (0, 90).
    pub max_slope_deg: f64,
    /// Largest height step between neighbouring ground bins (a kerb), metres; finite, ≥ 0.
    pub max_step_m: f64,
    /// Height of the sensor above the ground under it, metres, if known (finite); anchors the
    /// first bins of every sector.
    pub sensor_height_m: Option<f64>,
    /// Azimuth width of the radial profiles of the riser test, degrees (about the sensor's
    /// azimuth resolution); 0 turns the test off; otherwise in [0.01, 10].
    pub riser_column_deg: f64,
    /// Height margin of the riser test, metres (above the points' noise); in [0, 1].
    pub riser_margin_m: f64,
}

impl Default for PolarGridParams {
    /// 64 sectors, 1 m bins, 150 m, 0.15 m above the plane, 15°, 0.25 m steps, no sensor
    /// height; riser test on 0.25° profiles with a 0.01 m margin.
    fn default() -> Self {
        Self {
            sectors: 64,
            radial_bin_m: 1.0,
            max_range_m: 150.0,
            distance_threshold_m: 0.15,
            max_slope_deg: 15.0,
            max_step_m: 0.25,
            sensor_height_m: None,
            riser_column_deg: 0.25,
            riser_margin_m: 0.01,
        }
    }
}

/// How ground is found. See the module docs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GroundMethod {
    /// One plane by RANSAC.
    Ransac {
        /// Inlier distance to the plane, metres; finite, > 0.
        distance_threshold_m: f64,
        /// Random triples tried; ≥ 1.
        iterations: u32,
        /// Seed of the random generator: the same seed gives the same labels.
        seed: u64,
    },
    /// Local planes on a polar grid, grown outwards from the sensor.
    PolarGrid(PolarGridParams),
}

/// What one call found.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GroundStats {
    /// Points labelled ground.
    pub ground: usize,
    /// RANSAC: the best plane `[a, b, c, d]` with `a x + b y + c z + d = 0`, `(a, b, c)` a unit
    /// normal with `c ≥ 0`; `None` for the polar grid or when no plane was found.
    pub plane: Option<[f64; 4]>,
    /// Polar grid: bins whose own plane was accepted as ground.
    pub ground_bins: usize,
    /// Polar grid: points under a bin's plane that the riser test found on a step's face
    /// (not ground, not counted in `ground`).
    pub risers: usize,
}

/// A reusable ground segmenter. See the module docs.
#[derive(Clone, Debug)]
pub struct GroundSegmenter {
    method: GroundMethod,
    /// Finite points as structure-of-arrays (RANSAC) or bin-ordered (polar grid).
    xs: Vec<f32>,
    ys: Vec<f32>,
    zs: Vec<f32>,
    /// Original index of each entry of `xs`/`ys`/`zs`.
    idx: Vec<u32>,
    /// Polar grid: bin of each point, bin starts, ring edges, per-bin planes.
    bin_of: Vec<u32>,
    bin_start: Vec<u32>,
    cursor: Vec<u32>,
    ring_edges: Vec<f64>,
    ring_lut: Vec<u16>,
    /// Per bin: its lowest-points plane and, when its points lie along one line, that line's
    /// direction.
    planes: Vec<Option<Fit>>,
    scratch: Vec<f32>,
    /// Riser test: ground points as (range in xy, z, index), grouped by azimuth column.
    profile: Vec<(f32, f32, u32)>,
    column_of: Vec<u32>,
    /// Riser test: positions (bin order) of the points the planes labelled ground.
    ground_at: Vec<u32>,
    column_start: Vec<u32>,
}

/// Bins of the polar grid at most (rings × sectors): its per-bin state (about 50 bytes) is
/// rewritten at every sweep. The default grid has a few thousand.
pub const MAX_POLAR_BINS: usize = 1 << 20;

impl GroundSegmenter {
    /// A segmenter with validated parameters (see each field's doc for its range).
    pub fn new(method: GroundMethod) -> Result<Self, PipelineError> {
        match method {
            GroundMethod::Ransac {
                distance_threshold_m,
                iterations,
                ..
            } => {
                positive("distance_threshold_m", distance_threshold_m)?;
                if iterations == 0 {
                    return Err(PipelineError::InvalidParameter {
                        name: "iterations",
                        value: 0.0,
                        expected: "≥ 1",
                    });
                }
            }
            GroundMethod::PolarGrid(p) => {
                within("sectors", f64::from(p.sectors), 4.0, 4096.0, "4 ..= 4096")?;
                positive("radial_bin_m", p.radial_bin_m)?;
                positive("max_range_m", p.max_range_m)?;
                positive("distance_threshold_m", p.distance_threshold_m)?;
                within(
                    "max_slope_deg",
                    p.max_slope_deg,
                    f64::MIN_POSITIVE,
                    89.999,
                    "in (0, 90)",
                )?;
                within("max_step_m", p.max_step_m, 0.0, f64::MAX, "finite, ≥ 0")?;
                if let Some(h) = p.sensor_height_m {
                    within("sensor_height_m", h, f64::MIN, f64::MAX, "finite")?;
                }
                if p.riser_column_deg != 0.0 {
                    within(
                        "riser_column_deg",
                        p.riser_column_deg,
                        0.01,
                        10.0,
                        "0 (off) or in [0.01, 10]",
                    )?;
                }
                within("riser_margin_m", p.riser_margin_m, 0.0, 1.0, "in [0, 1]")?;
                if p.max_range_m / p.radial_bin_m > 100_000.0 {
                    return Err(PipelineError::InvalidParameter {
                        name: "radial_bin_m",
                        value: p.radial_bin_m,
                        expected: "≥ max_range_m / 100000",
                    });
                }
            }
        }
        let mut s = Self {
            method,
            xs: Vec::new(),
            ys: Vec::new(),
            zs: Vec::new(),
            idx: Vec::new(),
            bin_of: Vec::new(),
            bin_start: Vec::new(),
            cursor: Vec::new(),
            ring_edges: Vec::new(),
            ring_lut: Vec::new(),
            planes: Vec::new(),
            scratch: Vec::new(),
            profile: Vec::new(),
            column_of: Vec::new(),
            ground_at: Vec::new(),
            column_start: Vec::new(),
        };
        if let GroundMethod::PolarGrid(p) = method {
            s.build_rings(&p);
            // Each bounded alone, sectors and rings still multiply: 4096 sectors of 1 mm
            // rings made 16 M bins, 0.8 GB of planes rewritten at every sweep.
            let bins = (s.ring_edges.len() - 1) * p.sectors as usize;
            if bins > MAX_POLAR_BINS {
                return Err(PipelineError::InvalidParameter {
                    name: "radial_bin_m",
                    value: p.radial_bin_m,
                    expected: "rings × sectors ≤ 2^20: a coarser radial_bin_m or fewer sectors",
                });
            }
        }
        Ok(s)
    }

    /// The method and its parameters.
    pub fn method(&self) -> &GroundMethod {
        &self.method
    }

    /// Labels every point of `points`: `labels` is cleared and gets one entry per point,
    /// `true` for ground.
    pub fn segment(&mut self, points: &[Point], labels: &mut Vec<bool>) -> GroundStats {
        labels.clear();
        labels.resize(points.len(), false);
        let mut stats = match self.method {
            GroundMethod::Ransac {
                distance_threshold_m,
                iterations,
                seed,
            } => self.ransac(points, distance_threshold_m, iterations, seed, labels),
            GroundMethod::PolarGrid(p) => self.polar(points, &p, labels),
        };
        stats.ground = labels.iter().filter(|&&g| g).count();
        stats
    }

    fn load_finite(&mut self, points: &[Point]) {
        self.xs.clear();
        self.ys.clear();
        self.zs.clear();
        self.idx.clear();
        for (i, p) in points.iter().enumerate().take(u32::MAX as usize) {
            if p.x.is_finite() && p.y.is_finite() && p.z.is_finite() {
                self.xs.push(p.x);
                self.ys.push(p.y);
                self.zs.push(p.z);
                self.idx.push(i as u32);
            }
        }
    }

    fn ransac(
        &mut self,
        points: &[Point],
        thr: f64,
        iterations: u32,
        seed: u64,
        labels: &mut [bool],
    ) -> GroundStats {
        self.load_finite(points);
        let n = self.xs.len();
        if n < 3 {
            return GroundStats::default();
        }
        let mut rng = SplitMix64(seed);
        let mut best: Option<([f32; 4], usize)> = None;
        let thr32 = thr as f32;
        for _ in 0..iterations {
            let i = rng.below(n);
            let j = rng.below(n);
            let k = rng.below(n);
            let p = |t: usize| {
                Vector3::new(
                    f64::from(self.xs[t]),
                    f64::from(self.ys[t]),
                    f64::from(self.zs[t]),
                )
            };
            let (a, b, c) = (p(i), p(j), p(k));
            let nrm = (b - a).cross(&(c - a));
            let len = nrm.norm();
            if len.is_nan() || len <= 1e-12 {
                continue;
            }
            let nrm = nrm / len;
            let d = -nrm.dot(&a);
            let plane = [nrm.x as f32, nrm.y as f32, nrm.z as f32, d as f32];
            let count = count_within(&self.xs, &self.ys, &self.zs, plane, thr32);
            if best.is_none_or(|(_, c)| count > c) {
                best = Some((plane, count));
            }
        }
        let Some((plane, _)) = best else {
            return GroundStats::default();
        };
        for t in 0..n {
            let d =
                plane[0] * self.xs[t] + plane[1] * self.ys[t] + plane[2] * self.zs[t] + plane[3];
            if d.abs() <= thr32 {
                labels[self.idx[t] as usize] = true;
            }
        }
        let s = if plane[2] < 0.0 { -1.0 } else { 1.0 };
        GroundStats {
            plane: Some(plane.map(|v| f64::from(v) * s)),
            ..GroundStats::default()
        }
    }

    /// Ring edges: each ring is `max(radial_bin_m, r · 2π / sectors)` wide (square-ish bins);
    /// a lookup table at `radial_bin_m / 8` resolution gives the ring of a range.
    fn build_rings(&mut self, p: &PolarGridParams) {
        self.ring_edges.clear();
        let mut r = 0.0;
        let arc = core::f64::consts::TAU / f64::from(p.sectors);
        self.ring_edges.push(0.0);
        while r < p.max_range_m {
            r += (r * arc).max(p.radial_bin_m);
            self.ring_edges.push(r.min(p.max_range_m));
        }
        let step = p.radial_bin_m / 8.0;
        let cells = (p.max_range_m / step).ceil() as usize + 1;
        self.ring_lut.clear();
        let mut ring = 0usize;
        for c in 0..cells {
            let r = (c as f64 + 0.5) * step;
            while ring + 2 < self.ring_edges.len() && r >= self.ring_edges[ring + 1] {
                ring += 1;
            }
            self.ring_lut.push(ring as u16);
        }
    }

    fn polar(&mut self, points: &[Point], p: &PolarGridParams, labels: &mut [bool]) -> GroundStats {
        let rings = self.ring_edges.len() - 1;
        let sectors = p.sectors as usize;
        let bins = rings * sectors;
        let step = p.radial_bin_m / 8.0;
        let sector_scale = sectors as f64 / core::f64::consts::TAU;
        let max_r2 = p.max_range_m * p.max_range_m;

        // 1. Bin of every finite point within range; counting sort into bin order.
        let ring_lut = &self.ring_lut;
        let bin = |pt: &Point| {
            let (x, y) = (f64::from(pt.x), f64::from(pt.y));
            let r2 = x * x + y * y;
            if pt.z.is_finite() && r2 <= max_r2 {
                let r = r2.sqrt();
                let ring = ring_lut
                    .get((r / step) as usize)
                    .map_or(rings - 1, |&v| usize::from(v));
                let a = fast_atan2(y, x) + core::f64::consts::PI;
                let sector = ((a * sector_scale) as usize).min(sectors - 1);
                (sector * rings + ring) as u32
            } else {
                u32::MAX
            }
        };
        count_bins(
            bins,
            points.iter().take(u32::MAX as usize).map(bin),
            &mut self.bin_of,
            &mut self.bin_start,
        );
        let total = self.bin_start[bins] as usize;
        for v in [&mut self.xs, &mut self.ys, &mut self.zs] {
            v.clear();
            v.resize(total, 0.0);
        }
        self.idx.clear();
        self.idx.resize(total, 0);
        let cursor = &mut self.cursor;
        cursor.clear();
        cursor.extend_from_slice(&self.bin_start[..bins]);
        for (i, (&b, pt)) in self.bin_of.iter().zip(points).enumerate() {
            if b == u32::MAX {
                continue;
            }
            let at = cursor[b as usize] as usize;
            cursor[b as usize] += 1;
            self.xs[at] = pt.x;
            self.ys[at] = pt.y;
            self.zs[at] = pt.z;
            self.idx[at] = i as u32;
        }

        // 2. A plane per bin from its lowest points.
        self.planes.clear();
        self.planes.resize(bins, None);
        let tan_max = p.max_slope_deg.to_radians().tan();
        for b in 0..bins {
            let (s, e) = (self.bin_start[b] as usize, self.bin_start[b + 1] as usize);
            // The seeds may rise across the bin as much as the steepest ground does.
            let ring = b % rings;
            let extent = (self.ring_edges[ring + 1] - self.ring_edges[ring])
                .max(self.ring_edges[ring + 1] / sector_scale);
            self.planes[b] = fit_lowest(
                &self.xs[s..e],
                &self.ys[s..e],
                &self.zs[s..e],
                p.distance_threshold_m,
                p.distance_threshold_m + extent * tan_max,
                &mut self.scratch,
            );
        }

        // 3. Walk each sector outwards: accept planes that are flat enough and continue the
        //    ground; label the points above their plane by at most the threshold.
        let cos_max = p.max_slope_deg.to_radians().cos();
        let mut stats = GroundStats::default();
        self.ground_at.clear();
        self.ground_at.resize(total, 0);
        let mut grounds = 0;
        for sec in 0..sectors {
            let mid = (sec as f64 + 0.5) / sector_scale - core::f64::consts::PI;
            let (cs, sn) = (mid.cos(), mid.sin());
            // Reference: last accepted plane and the range where it was last accepted.
            let mut reference: Option<([f64; 4], f64)> =
                p.sensor_height_m.map(|h| ([0.0, 0.0, 1.0, h], 0.0));
            for ring in 0..rings {
                let b = sec * rings + ring;
                let r_in = self.ring_edges[ring];
                let r_out = self.ring_edges[ring + 1];
                let (px, py) = (r_in * cs, r_in * sn);
                let mut used = reference.map(|(pl, _)| pl);
                if let Some(pl) = self.planes[b] {
                    // A single scan line's plane is the most horizontal one through it, so
                    // its tilt is the line's own slope: the same test holds for both.
                    let accept = pl[2] >= cos_max
                        && reference.is_none_or(|(rp, r_ref)| {
                            let allowed = p.max_step_m + (r_in - r_ref).max(0.0) * tan_max;
                            (height_at(&pl, px, py) - height_at(&rp, px, py)).abs() <= allowed
                        });
                    if accept {
                        used = Some(pl);
                        reference = Some((pl, r_out));
                        stats.ground_bins += 1;
                    }
                }
                let Some(pl) = used else { continue };
                let (s, e) = (self.bin_start[b] as usize, self.bin_start[b + 1] as usize);
                let thr = p.distance_threshold_m;
                let dist = |pl: &[f64; 4], x: f64, y: f64, z: f64| {
                    pl[0] * x + pl[1] * y + pl[2] * z + pl[3]
                };
                for t in s..e {
                    let (x, y, z) = (
                        f64::from(self.xs[t]),
                        f64::from(self.ys[t]),
                        f64::from(self.zs[t]),
                    );
                    // Each point is in one bin and every label starts false: a plain store,
                    // no branch on the data; the ground ones listed for the riser test the
                    // same way.
                    let ground = dist(&pl, x, y, z) <= thr;
                    labels[self.idx[t] as usize] = ground;
                    self.ground_at[grounds] = t as u32;
                    grounds += usize::from(ground);
                }
            }
        }
        self.ground_at.truncate(grounds);
        if p.riser_column_deg > 0.0 {
            stats.risers = self.risers(p, labels);
        }
        stats
    }

    /// The riser test (see the module docs): relabels as not ground the ground points that
    /// lie on a step's face in their radial profile. Returns how many.
    fn risers(&mut self, p: &PolarGridParams, labels: &mut [bool]) -> usize {
        let columns = (360.0 / p.riser_column_deg).ceil() as usize;
        let scale = columns as f64 / core::f64::consts::TAU;
        // Counting sort of the ground points (listed by the labelling, in bin order) into
        // azimuth columns.
        let (xs, ys, zs, idx) = (&self.xs, &self.ys, &self.zs, &self.idx);
        let column = |&t: &u32| {
            let (x, y) = (f64::from(xs[t as usize]), f64::from(ys[t as usize]));
            let a = fast_atan2(y, x) + core::f64::consts::PI;
            ((a * scale) as usize).min(columns - 1) as u32
        };
        count_bins(
            columns,
            self.ground_at.iter().map(column),
            &mut self.column_of,
            &mut self.column_start,
        );
        let total = self.column_start[columns] as usize;
        self.profile.clear();
        self.profile.resize(total, (0.0, 0.0, 0));
        self.cursor.clear();
        self.cursor.extend_from_slice(&self.column_start[..columns]);
        for (&c, &t) in self.column_of.iter().zip(&self.ground_at) {
            let at = self.cursor[c as usize] as usize;
            self.cursor[c as usize] += 1;
            let (x, y) = (f64::from(xs[t as usize]), f64::from(ys[t as usize]));
            let r = (x.powi(2) + y.powi(2)).sqrt();
            self.profile[at] = (r as f32, zs[t as usize], idx[t as usize]);
        }
        // Each column's profile by range; a point on a rise steeper than the steepest ground
        // (by the margin) from a point below it, with a point higher still beyond it (or the
        // same the other way round), lies on the face of a step.
        let tan_max = p.max_slope_deg.to_radians().tan() as f32;
        let m = p.riser_margin_m as f32;
        let mut relabelled = 0;
        for c in 0..columns {
            let col =
                &mut self.profile[self.column_start[c] as usize..self.column_start[c + 1] as usize];
            if col.len() < 2 {
                continue;
            }
            col.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
            let col = &*col;
            let mut lo = 0;
            let mut hi = 0;
            for (k, &(r, z, i)) in col.iter().enumerate() {
                while col[lo].0 < r - RISER_SPAN_M {
                    lo += 1;
                }
                while hi < col.len() && col[hi].0 <= r + RISER_SPAN_M {
                    hi += 1;
                }
                // At most RISER_NEIGHBOURS on each side: a sensor's column holds one point per
                // ring within the span, and a hostile cloud stays linear.
                let (from, to) = (
                    lo.max(k.saturating_sub(RISER_NEIGHBOURS)),
                    hi.min(k + 1 + RISER_NEIGHBOURS),
                );
                // Without a branch per neighbour (on flat ground, whether a neighbour lies
                // a margin above or below is noise, which branches mispredict). The point
                // itself needs no skipping: it is neither `m ≥ 0` above nor below itself.
                let (mut lower, mut higher, mut steep_below, mut steep_above) =
                    (false, false, false, false);
                for &(rq, zq, _) in &col[from..to] {
                    let (before, beyond) = (rq <= r, rq >= r);
                    let (below, above) = (before & (zq < z - m), beyond & (zq > z + m));
                    lower |= below;
                    steep_below |= below & (z - zq > tan_max * (r - rq) + m);
                    higher |= above;
                    steep_above |= above & (zq - z > tan_max * (rq - r) + m);
                }
                if (steep_below && higher) || (steep_above && lower) {
                    labels[i as usize] = false;
                    relabelled += 1;
                }
            }
        }
        relabelled
    }
}

/// The first half of a counting sort: `of[i]` is item `i`'s bin (`u32::MAX`: none) and
/// `start[b]` where bin `b` begins in bin order (`start[bins]`: the items binned).
fn count_bins(
    bins: usize,
    items: impl Iterator<Item = u32>,
    of: &mut Vec<u32>,
    start: &mut Vec<u32>,
) {
    of.clear();
    start.clear();
    start.resize(bins + 1, 0);
    for b in items {
        of.push(b);
        if b != u32::MAX {
            start[b as usize + 1] += 1;
        }
    }
    for b in 0..bins {
        start[b + 1] += start[b];
    }
}

/// How far along its radial profile the riser test looks from a point, metres.
const RISER_SPAN_M: f32 = 1.0;

/// The most neighbours on each side the riser test looks at (the nearest in range).
const RISER_NEIGHBOURS: usize = 64;

/// Height `z` of the plane `a x + b y + c z + d = 0` (`c > 0`) above `(x, y)`.
fn height_at(pl: &[f64; 4], x: f64, y: f64) -> f64 {
    -(pl[0] * x + pl[1] * y + pl[3]) / pl[2]
}

/// Points of the SoA arrays within `thr` of the plane (vectorises).
fn count_within(xs: &[f32], ys: &[f32], zs: &[f32], pl: [f32; 4], thr: f32) -> usize {
    let mut n = 0usize;
    for ((&x, &y), &z) in xs.iter().zip(ys).zip(zs) {
        let d = pl[0] * x + pl[1] * y + pl[2] * z + pl[3];
        n += usize::from(d.abs() <= thr);
    }
    n
}

/// A fitted plane `a x + b y + c z + d = 0` (unit normal, `c > 0`).
type Fit = [f64; 4];

/// Seeds = points below the mean of the lowest `LOWEST` points plus `thr`; plane by
/// principal components; refitted twice on the points within `thr`.
fn fit_lowest(
    xs: &[f32],
    ys: &[f32],
    zs: &[f32],
    thr: f64,
    seed_margin: f64,
    scratch: &mut Vec<f32>,
) -> Option<Fit> {
    const LOWEST: usize = 10;
    if xs.len() < 3 {
        return None;
    }
    scratch.clear();
    scratch.extend_from_slice(zs);
    let k = LOWEST.min(scratch.len());
    scratch.select_nth_unstable_by(k - 1, f32::total_cmp);
    let low = scratch[..k].iter().map(|&z| f64::from(z)).sum::<f64>() / k as f64;
    let seed_top = low + seed_margin;
    let mut f = fit(xs, ys, zs, |_, _, z| z <= seed_top)?;
    // Refits with a band narrowing from the seed margin to the threshold.
    for band in [0.5 * (seed_margin + thr), thr, thr] {
        let pl = f;
        f = fit(xs, ys, zs, |x, y, z| {
            (pl[0] * x + pl[1] * y + pl[2] * z + pl[3]).abs() <= band
        })
        .unwrap_or(f);
    }
    Some(f)
}

/// Least-squares plane `z = a x + b y + c` of the selected points, in one pass over running
/// sums, with a ridge term `n·RIDGE_M2` on `a` and `b`: when the points lie along one line (a
/// single scan line crossing the bin) the slope across the line is not determined by the data,
/// and the ridge makes it zero — the most horizontal plane containing the line — instead of
/// whatever the noise says; elsewhere it changes slopes by under 1 %. `None` if fewer than
/// three points.
fn fit(xs: &[f32], ys: &[f32], zs: &[f32], keep: impl Fn(f64, f64, f64) -> bool) -> Option<Fit> {
    let (mut n, mut sx, mut sy, mut sz) = (0f64, 0f64, 0f64, 0f64);
    let (mut sxx, mut sxy, mut syy, mut sxz, mut syz) = (0f64, 0f64, 0f64, 0f64, 0f64);
    // Sums relative to the first point keep the cancellation small far from the sensor.
    let (ox, oy, oz) = match (xs.first(), ys.first(), zs.first()) {
        (Some(&x), Some(&y), Some(&z)) => (f64::from(x), f64::from(y), f64::from(z)),
        _ => return None,
    };
    // Without a branch: a point left out adds zeros (the sums are the same to the bit), and
    // whether a point is kept is data, which a branch would mispredict on mixed bins.
    for ((&x, &y), &z) in xs.iter().zip(ys).zip(zs) {
        let (x, y, z) = (f64::from(x), f64::from(y), f64::from(z));
        let w = if keep(x, y, z) { 1.0 } else { 0.0 };
        let (x, y, z) = ((x - ox) * w, (y - oy) * w, (z - oz) * w);
        n += w;
        sx += x;
        sy += y;
        sz += z;
        sxx += x * x;
        sxy += x * y;
        syy += y * y;
        sxz += x * z;
        syz += y * z;
    }
    if n < 3.0 {
        return None;
    }
    let (mx, my, mz) = (sx / n, sy / n, sz / n);
    let cxx = sxx / n - mx * mx;
    let cxy = sxy / n - mx * my;
    let cyy = syy / n - my * my;
    let cxz = sxz / n - mx * mz;
    let cyz = syz / n - my * mz;
    // (C + ridge) [a b]ᵀ = [cxz cyz]ᵀ.
    let (p, q, r) = (cxx + RIDGE_M2, cxy, cyy + RIDGE_M2);
    let det = p * r - q * q;
    if det.is_nan() || det <= 0.0 {
        return None;
    }
    let a = (r * cxz - q * cyz) / det;
    let b = (p * cyz - q * cxz) / det;
    let norm = (a * a + b * b + 1.0).sqrt();
    // a x + b y − z + c' = 0 through the mean, as a unit normal with c > 0.
    let (mx, my, mz) = (mx + ox, my + oy, mz + oz);
    let nrm = [-a / norm, -b / norm, 1.0 / norm];
    let d = -(nrm[0] * mx + nrm[1] * my + nrm[2] * mz);
    Some([nrm[0], nrm[1], nrm[2], d])
}

/// Ridge on the slopes of [`fit`], m² per point.
const RIDGE_M2: f64 = 0.02 * 0.02;

/// SplitMix64 (Steele, Lea, Flood 2014): a small, seedable, reproducible generator.
struct SplitMix64(u64);

impl SplitMix64 {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `0..n` (`n > 0`), by the multiply-shift method.
    fn below(&mut self, n: usize) -> usize {
        ((u128::from(self.next()) * n as u128) >> 64) as usize
    }
}

/// `atan2(y, x)` within 1.2e-5 rad (Abramowitz & Stegun 4.4.49: a degree-9 odd polynomial on
/// [−1, 1], |error| ≤ 1e-5 there, 1.15e-5 measured over every octant): a sector index needs far
/// less (a sector spans ≥ 1.5e-3 rad at the 4096-sector limit), and libm's `atan2` was a
/// third of the stage's binning (`perf`: 3.6 % of the whole pipeline on a 128 × 1024 sweep).
/// NaN in, NaN out; (0, 0) gives 0.
#[inline]
fn fast_atan2(y: f64, x: f64) -> f64 {
    use core::f64::consts::{FRAC_PI_2, PI};
    let (ax, ay) = (x.abs(), y.abs());
    let (num, den) = if ay > ax { (ax, ay) } else { (ay, ax) };
    if den == 0.0 {
        return if x.is_sign_negative() {
            PI.copysign(y)
        } else {
            0.0f64.copysign(y)
        };
    }
    let z = num / den;
    let z2 = z * z;
    let mut a = z
        * (0.999_866_0
            + z2 * (-0.330_299_5 + z2 * (0.180_141_0 + z2 * (-0.085_133_0 + z2 * 0.020_835_1))));
    if ay > ax {
        a = FRAC_PI_2 - a;
    }
    if x < 0.0 {
        a = PI - a;
    }
    a.copysign(y)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_atan2_is_within_1_2e_5_rad_of_atan2() {
        let mut worst = 0f64;
        for k in 0..200_000 {
            let t = k as f64 / 200_000.0 * core::f64::consts::TAU - core::f64::consts::PI;
            for r in [1e-3, 1.0, 137.5] {
                let (y, x) = (r * t.sin(), r * t.cos());
                worst = worst.max((fast_atan2(y, x) - y.atan2(x)).abs());
            }
        }
        for (y, x) in [
            (0.0, 1.0),
            (0.0, -1.0),
            (1.0, 0.0),
            (-1.0, 0.0),
            (2.0, 2.0),
            (-3.0, -3.0),
        ] {
            worst = worst.max((fast_atan2(y, x) - f64::atan2(y, x)).abs());
        }
        assert!(worst <= 1.2e-5, "worst error {worst} rad");
        assert_eq!(fast_atan2(0.0, 0.0), 0.0);
        assert!(fast_atan2(f64::NAN, 1.0).is_nan());
    }

    fn pt(x: f64, y: f64, z: f64) -> Point {
        Point {
            x: x as f32,
            y: y as f32,
            z: z as f32,
            ..Point::default()
        }
    }

    /// A sensor-like pattern over a ground height field `h(x, y)` (metres, sensor at the
    /// origin `sensor_h` above `h(0, 0)`): rings at the ranges where beams 2°…25° below the
    /// horizon meet flat ground, 720 azimuths each; plus the four walls of a box (2 × 2 × 1.5 m,
    /// centred 8 m ahead, standing on the ground). Returns the points and the truth.
    fn scene(h: impl Fn(f64, f64) -> f64, sensor_h: f64) -> (Vec<Point>, Vec<bool>) {
        let (mut pts, mut truth) = (Vec::new(), Vec::new());
        for beam in 2..=25 {
            let r = sensor_h / (f64::from(beam)).to_radians().tan();
            for a in 0..720 {
                let az = f64::from(a) * 0.5f64.to_radians();
                let (x, y) = (r * az.cos(), r * az.sin());
                if (x - 8.0).abs() <= 1.0 && y.abs() <= 1.0 {
                    continue; // under the box
                }
                pts.push(pt(x, y, h(x, y) - sensor_h));
                truth.push(true);
            }
        }
        for i in 0..=20 {
            for k in 0..=15 {
                let (s, z) = (f64::from(i) * 0.1 - 1.0, f64::from(k) * 0.1);
                for (x, y) in [(7.0, s), (9.0, s), (8.0 + s, -1.0), (8.0 + s, 1.0)] {
                    pts.push(pt(x, y, h(8.0, 0.0) - sensor_h + z));
                    truth.push(k as f64 * 0.1 < 0.0); // never ground
                }
            }
        }
        (pts, truth)
    }

    /// (precision, recall) of `labels` against `truth`.
    fn score(labels: &[bool], truth: &[bool]) -> (f64, f64) {
        let tp = labels.iter().zip(truth).filter(|(l, t)| **l && **t).count() as f64;
        let fp = labels
            .iter()
            .zip(truth)
            .filter(|(l, t)| **l && !**t)
            .count() as f64;
        let fneg = labels
            .iter()
            .zip(truth)
            .filter(|(l, t)| !**l && **t)
            .count() as f64;
        (tp / (tp + fp), tp / (tp + fneg))
    }

    const RANSAC: GroundMethod = GroundMethod::Ransac {
        distance_threshold_m: 0.15,
        iterations: 200,
        seed: 42,
    };

    #[test]
    fn flat_ground_with_a_box_both_methods() {
        let (pts, truth) = scene(|_, _| 0.0, 1.8);
        let mut labels = Vec::new();
        for m in [RANSAC, GroundMethod::PolarGrid(PolarGridParams::default())] {
            let mut g = GroundSegmenter::new(m).unwrap();
            let stats = g.segment(&pts, &mut labels);
            let (p, r) = score(&labels, &truth);
            // The box's two lowest rows (0 and 0.1 m) are within the 0.15 m threshold.
            assert!(p > 0.98 && r > 0.999, "{m:?}: precision {p}, recall {r}");
            assert_eq!(stats.ground, labels.iter().filter(|&&l| l).count());
        }
    }

    #[test]
    fn ransac_is_reproducible_and_finds_the_plane() {
        let (pts, _) = scene(|_, _| 0.0, 1.8);
        let mut g = GroundSegmenter::new(RANSAC).unwrap();
        let (mut a, mut b) = (Vec::new(), Vec::new());
        let sa = g.segment(&pts, &mut a);
        let sb = g.segment(&pts, &mut b);
        assert_eq!(a, b);
        assert_eq!(sa, sb);
        let pl = sa.plane.unwrap();
        assert!(pl[2] > 0.999 && (pl[3] - 1.8).abs() < 0.15, "{pl:?}");
    }

    #[test]
    fn polar_grid_follows_a_ten_percent_slope_where_ransac_cannot() {
        // Ground rising at 10 % along x beyond x = 5 m (a ramp), flat before.
        let h = |x: f64, _y: f64| if x > 5.0 { 0.1 * (x - 5.0) } else { 0.0 };
        let (pts, truth) = scene(h, 1.8);
        let mut labels = Vec::new();
        let mut g =
            GroundSegmenter::new(GroundMethod::PolarGrid(PolarGridParams::default())).unwrap();
        g.segment(&pts, &mut labels);
        let (p, r) = score(&labels, &truth);
        assert!(
            p > 0.98 && r > 0.97,
            "polar grid: precision {p}, recall {r}"
        );
        // One plane cannot hold both the flat part and the ramp.
        GroundSegmenter::new(RANSAC)
            .unwrap()
            .segment(&pts, &mut labels);
        let (rp, rr) = score(&labels, &truth);
        eprintln!("10 % ramp: polar grid precision {p:.4} recall {r:.4}; RANSAC {rp:.4} {rr:.4}");
        assert!(rr < 0.9, "RANSAC: precision {rp}, recall {rr}");
    }

    #[test]
    fn invalid_parameters_are_named() {
        let bad = |m: GroundMethod, name: &str| match GroundSegmenter::new(m) {
            Err(PipelineError::InvalidParameter { name: n, .. }) => assert_eq!(n, name),
            other => panic!("{m:?}: {other:?}"),
        };
        bad(
            GroundMethod::Ransac {
                distance_threshold_m: 0.0,
                iterations: 10,
                seed: 0,
            },
            "distance_threshold_m",
        );
        bad(
            GroundMethod::Ransac {
                distance_threshold_m: 0.1,
                iterations: 0,
                seed: 0,
            },
            "iterations",
        );
        let d = PolarGridParams::default();
        bad(
            GroundMethod::PolarGrid(PolarGridParams { sectors: 2, ..d }),
            "sectors",
        );
        // Within each bound alone, 16 M bins together (0.8 GB rewritten per sweep).
        let fine = PolarGridParams {
            sectors: 4096,
            radial_bin_m: 0.001,
            max_range_m: 100.0,
            ..d
        };
        bad(GroundMethod::PolarGrid(fine), "radial_bin_m");
        assert!(
            GroundSegmenter::new(GroundMethod::PolarGrid(PolarGridParams {
                radial_bin_m: 1.0,
                ..fine
            }))
            .is_ok()
        );
        bad(
            GroundMethod::PolarGrid(PolarGridParams {
                radial_bin_m: f64::NAN,
                ..d
            }),
            "radial_bin_m",
        );
        bad(
            GroundMethod::PolarGrid(PolarGridParams {
                max_slope_deg: 90.0,
                ..d
            }),
            "max_slope_deg",
        );
        bad(
            GroundMethod::PolarGrid(PolarGridParams {
                max_step_m: -0.1,
                ..d
            }),
            "max_step_m",
        );
        bad(
            GroundMethod::PolarGrid(PolarGridParams {
                sensor_height_m: Some(f64::INFINITY),
                ..d
            }),
            "sensor_height_m",
        );
        bad(
            GroundMethod::PolarGrid(PolarGridParams {
                max_range_m: 1e9,
                ..d
            }),
            "radial_bin_m",
        );
        bad(
            GroundMethod::PolarGrid(PolarGridParams {
                riser_column_deg: 0.001,
                ..d
            }),
            "riser_column_deg",
        );
        bad(
            GroundMethod::PolarGrid(PolarGridParams {
                riser_margin_m: f64::NAN,
                ..d
            }),
            "riser_margin_m",
        );
    }

    /// One radial profile straight ahead, the sensor 1.8 m up: road (z = 0) to 6 m, a 15 cm
    /// kerb face at 6 m hit at 3, 7 and 12 cm, pavement (z = 0.15) beyond. By the definition
    /// (ground slopes ≤ 15°) the face points are not ground, the road and pavement are; a
    /// 10 % ramp in the same profile keeps every point. With the test off, the face is ground
    /// (it lies within the 0.15 m threshold).
    #[test]
    fn riser_test_on_a_hand_made_kerb_and_ramp() {
        let at = |r: f32, z: f32| Point {
            x: r,
            y: 0.0,
            z: z - 1.8,
            ..Point::default()
        };
        let mut kerb: Vec<Point> = (0..20).map(|k| at(3.0 + 0.15 * k as f32, 0.0)).collect();
        let face = kerb.len();
        kerb.extend([at(6.0, 0.03), at(6.0, 0.07), at(6.0, 0.12)]);
        kerb.extend((0..20).map(|k| at(6.1 + 0.15 * k as f32, 0.15)));
        let ramp: Vec<Point> = (0..60)
            .map(|k| {
                let r = 3.0 + 0.1 * k as f32;
                at(r, 0.1 * (r - 3.0))
            })
            .collect();
        let params = PolarGridParams {
            sensor_height_m: Some(1.8),
            ..PolarGridParams::default()
        };
        let mut labels = Vec::new();
        let mut g = GroundSegmenter::new(GroundMethod::PolarGrid(params)).unwrap();
        let stats = g.segment(&kerb, &mut labels);
        for (i, &l) in labels.iter().enumerate() {
            assert_eq!(
                l,
                !(face..face + 3).contains(&i),
                "kerb point {i}: {:?}",
                kerb[i]
            );
        }
        assert_eq!((stats.risers, stats.ground), (3, kerb.len() - 3));
        let stats = g.segment(&ramp, &mut labels);
        assert!(labels.iter().all(|&l| l), "{labels:?}");
        assert_eq!(stats.risers, 0);
        let mut off = GroundSegmenter::new(GroundMethod::PolarGrid(PolarGridParams {
            riser_column_deg: 0.0,
            ..params
        }))
        .unwrap();
        assert_eq!(off.segment(&kerb, &mut labels).ground, kerb.len());
        // 200 000 points along one ray within a metre (no sensor makes that): each looks at
        // 64 neighbours a side, not at all the others; flat, so all ground.
        let dense: Vec<Point> = (0..200_000)
            .map(|k| at(5.0 + 1e-5 * k as f32, 0.0))
            .collect();
        let stats = g.segment(&dense, &mut labels);
        assert_eq!((stats.ground, stats.risers), (dense.len(), 0));
    }

    #[test]
    fn no_points_and_non_finite_points() {
        let mut labels = vec![true; 3];
        for m in [RANSAC, GroundMethod::PolarGrid(PolarGridParams::default())] {
            let mut g = GroundSegmenter::new(m).unwrap();
            assert_eq!(g.segment(&[], &mut labels).ground, 0);
            assert!(labels.is_empty());
            let pts = [
                pt(f64::NAN, 0.0, 0.0),
                pt(1.0, 0.0, -1.0),
                pt(0.0, 1.0, f64::INFINITY),
            ];
            g.segment(&pts, &mut labels);
            assert_eq!(labels.len(), 3);
            assert!(!labels[0] && !labels[2]);
        }
    }
}
