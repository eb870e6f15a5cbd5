//! The local map of the odometry: a voxel hash of world points, bounded in points per voxel
//! and in distance from the sensor, plus the voxel subsampling that prepares a sweep for ICP.
//!
//! - **Keys**: a point's voxel is `floor(p / voxel_size_m)` per axis (divided, not multiplied
//!   by the inverse, as KISS-ICP computes it), packed into one `u64`
//!   (three 21-bit fields). Points whose voxel index is beyond ±2²⁰ on an axis (1 048 km at
//!   1 m voxels) are rejected rather than aliased.
//! - **Storage**: every voxel owns one fixed slot of `max_points_per_voxel` points in one flat
//!   array; freed slots are reused, so a warm map allocates nothing per sweep.
//! - **Insertion** (the KISS-ICP rule, Vizzo et al. 2023, Sec. III-D): a point enters its voxel
//!   while the voxel holds fewer than `max_points_per_voxel` points and no point of the voxel
//!   lies closer than `voxel_size_m / √max_points_per_voxel`.
//! - **Bound in space**: [`VoxelMap::remove_far`] drops every voxel whose first point is
//!   `max_distance_m` or more from the sensor.
//! - **Bound in memory**: at most `max_voxels` voxels; a point that would open another is
//!   refused and counted ([`VoxelMap::refused`]). The bound in space alone does not hold
//!   memory: voxels much smaller than the range noise open new voxels with every sweep of a
//!   sensor standing still.
//! - **Nearest neighbour**: the closest stored point among the 27 voxels around the query's
//!   voxel (so a neighbour farther than one voxel size may be missed: correspondence gates
//!   wider than `voxel_size_m` do not widen the search).
//! - **Planes**: each voxel keeps the sums of its points and of their outer products, so the
//!   local plane (normal, spread) of a voxel costs a 3×3 eigen-solve and no pass over points;
//!   degeneracy analysis uses it.
//!
//! No I/O, no clock.

use std::collections::HashMap;
use std::hash::{BuildHasher, Hasher};

use nalgebra::{Isometry3, Matrix3, Vector3};

use crate::registration::icp::NearestNeighbors;
use crate::registration::icp::Neighbor;
use crate::registration::icp::RegistrationConfigError;

/// Half the range of one packed voxel coordinate.
const KEY_HALF: i64 = 1 << 20;
const KEY_MASK: u64 = (1 << 21) - 1;

/// Packs integer voxel coordinates into a key; `None` beyond ±2²⁰.
#[inline]
fn pack(ix: i64, iy: i64, iz: i64) -> Option<u64> {
    let lim = KEY_HALF;
    if ix < -lim || ix >= lim || iy < -lim || iy >= lim || iz < -lim || iz >= lim {
        return None;
    }
    Some(
        (((ix + lim) as u64 & KEY_MASK) << 42)
            | (((iy + lim) as u64 & KEY_MASK) << 21)
            | ((iz + lim) as u64 & KEY_MASK),
    )
}

/// Integer voxel coordinates `floor(p / size)` of a point (a division, as KISS-ICP does);
/// `None` for non-finite or out-of-range points.
#[inline]
fn voxel_coords(p: &Vector3<f64>, size: f64) -> Option<(i64, i64, i64)> {
    let (x, y, z) = (
        (p.x / size).floor(),
        (p.y / size).floor(),
        (p.z / size).floor(),
    );
    // Also rejects NaN: every comparison with NaN is false.
    let lim = KEY_HALF as f64;
    if !(x >= -lim && x < lim && y >= -lim && y < lim && z >= -lim && z < lim) {
        return None;
    }
    Some((x as i64, y as i64, z as i64))
}

/// The voxel key of a point (see the module documentation), `None` when it cannot be keyed.
#[inline]
pub fn voxel_key(p: &Vector3<f64>, voxel_size_m: f64) -> Option<u64> {
    let (x, y, z) = voxel_coords(p, voxel_size_m)?;
    pack(x, y, z)
}

/// A hasher for packed voxel keys: the splitmix64 finaliser of the one `u64` written, so
/// neighbouring voxels land in unrelated buckets. Other inputs are folded byte by byte.
#[derive(Clone, Copy, Debug, Default)]
pub struct KeyHasher(u64);

impl Hasher for KeyHasher {
    #[inline]
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(8) ^ u64::from(b)).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        }
    }

    #[inline]
    fn write_u64(&mut self, k: u64) {
        let mut z = (self.0 ^ k).wrapping_add(0x9e37_79b9_7f4a_7c15);
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        self.0 = z ^ (z >> 31);
    }
}

/// Builds [`KeyHasher`]s (deterministic: no random state).
#[derive(Clone, Copy, Debug, Default)]
pub struct BuildKeyHasher;

impl BuildHasher for BuildKeyHasher {
    type Hasher = KeyHasher;
    #[inline]
    fn build_hasher(&self) -> KeyHasher {
        KeyHasher(0)
    }
}

/// One bucket of [`VoxelSampler`]'s open-addressing table; `dist < 0` = empty.
#[derive(Clone, Copy, Debug)]
struct Bucket {
    dist: i32,
    key: [i32; 3],
    index: u32,
}

const EMPTY_BUCKET: Bucket = Bucket {
    dist: -1,
    key: [0; 3],
    index: 0,
};

/// KISS-ICP's voxel hash: the coordinates' bits as `u32`, times three primes, XORed.
#[inline]
fn kiss_hash(k: &[i32; 3]) -> usize {
    ((k[0] as u32).wrapping_mul(73_856_093)
        ^ (k[1] as u32).wrapping_mul(19_349_669)
        ^ (k[2] as u32).wrapping_mul(83_492_791)) as usize
}

/// Integer voxel coordinates `floor(p / size)` (a division, as KISS-ICP computes them, so
/// points on a voxel boundary fall on the same side); `None` beyond the `i32` range or NaN.
#[inline]
fn voxel_coords_i32(p: &Vector3<f64>, size: f64) -> Option<[i32; 3]> {
    let (x, y, z) = (
        (p.x / size).floor(),
        (p.y / size).floor(),
        (p.z / size).floor(),
    );
    let lim = 2_147_483_647.0;
    if !(x >= -lim && x <= lim && y >= -lim && y <= lim && z >= -lim && z <= lim) {
        return None;
    }
    Some([x as i32, y as i32, z as i32])
}

/// Keeps the first point of every voxel of a cloud (KISS-ICP's subsampling).
///
/// The kept points come out in the order KISS-ICP's own implementation gives them: it
/// deduplicates in a Robin Hood hash table (linear probing, power-of-two buckets reserved for
/// twice the input size, its three-prime hash) and lists the table's buckets in order. That
/// order decides which points enter a size-limited map voxel and which point of a coarser
/// voxel is "first" in the next subsampling, so matching it lets ringscan's trajectory be
/// compared with KISS-ICP's sweep by sweep. (Checked against `kiss_icp_pybind` 1.3.0 by
/// `tools/odometry_kiss.py`, and against a naive first-point filter in the tests here.)
/// The table is reused between calls.
#[derive(Debug, Default, Clone)]
pub struct VoxelSampler {
    table: Vec<Bucket>,
}

impl VoxelSampler {
    /// An empty sampler.
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends to `out` (cleared first) the first point of every occupied voxel of edge
    /// `voxel_size_m`; points that cannot be keyed (non-finite, beyond the `i32` range) are
    /// dropped. `voxel_size_m` must be finite and > 0 (otherwise nothing is kept).
    pub fn sample(
        &mut self,
        input: &[Vector3<f64>],
        voxel_size_m: f64,
        out: &mut Vec<Vector3<f64>>,
    ) {
        self.sample_by(input, |p| *p, voxel_size_m, out);
    }

    /// As [`VoxelSampler::sample`] for items that carry more than a position (a point with
    /// its time, say): `position` gives the position an item is binned by.
    pub fn sample_by<T: Copy>(
        &mut self,
        input: &[T],
        position: impl Fn(&T) -> Vector3<f64>,
        voxel_size_m: f64,
        out: &mut Vec<T>,
    ) {
        out.clear();
        if input.is_empty() || !(voxel_size_m.is_finite() && voxel_size_m > 0.0) {
            return;
        }
        // tsl::robin_map::reserve(n) with max load factor 0.5: ceil(n / 0.5f) buckets,
        // rounded up to a power of two.
        let buckets = (2 * input.len()).next_power_of_two();
        let mask = buckets - 1;
        self.table.clear();
        self.table.resize(buckets, EMPTY_BUCKET);
        let table = &mut self.table[..];
        'points: for (i, p) in input.iter().enumerate() {
            let Some(key) = voxel_coords_i32(&position(p), voxel_size_m) else {
                continue;
            };
            let mut ib = kiss_hash(&key) & mask;
            let mut dist = 0i32;
            while dist <= table[ib].dist {
                if table[ib].key == key {
                    continue 'points;
                }
                ib = (ib + 1) & mask;
                dist += 1;
            }
            // Robin Hood insertion: take the bucket of any entry closer to its home.
            let mut cur = Bucket {
                dist,
                key,
                index: i as u32,
            };
            loop {
                if table[ib].dist < 0 {
                    table[ib] = cur;
                    break;
                }
                if table[ib].dist < cur.dist {
                    std::mem::swap(&mut cur, &mut table[ib]);
                }
                ib = (ib + 1) & mask;
                cur.dist += 1;
            }
        }
        out.extend(
            table
                .iter()
                .filter(|b| b.dist >= 0)
                .map(|b| input[b.index as usize]),
        );
    }
}

/// Parameters of a [`VoxelMap`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VoxelMapConfig {
    /// Edge of a voxel, m.
    pub voxel_size_m: f64,
    /// Points kept per voxel (1..=255).
    pub max_points_per_voxel: usize,
    /// Voxels whose first point is this far from the sensor or farther are dropped, m.
    pub max_distance_m: f64,
    /// Voxels held at most (1..=2³²−1); see [`VoxelMapConfig::voxels_within`].
    pub max_voxels: usize,
}

impl Default for VoxelMapConfig {
    /// KISS-ICP's defaults: 1 m voxels, 20 points per voxel, 100 m; as many voxels as
    /// [`DEFAULT_MAP_BYTES`] holds.
    fn default() -> Self {
        Self {
            voxel_size_m: 1.0,
            max_points_per_voxel: 20,
            max_distance_m: 100.0,
            max_voxels: Self::voxels_within(DEFAULT_MAP_BYTES, 20),
        }
    }
}

/// The memory a map may take by default, bytes. At KISS-ICP's ratio of voxel to range (1/100)
/// a map holds tens of thousands of points (22.8 k after the 7 sweeps of the HDL-32E drive
/// `hdl32_example.pcap`; a flat ground alone fills π·100² voxels): 256 MiB keeps about 220 k
/// voxels of 20 points, 4.4 M points, room for far denser scenes at that ratio.
pub const DEFAULT_MAP_BYTES: usize = 256 << 20;

impl VoxelMapConfig {
    /// The most voxels of `max_points_per_voxel` points whose storage fits in `bytes`.
    pub fn voxels_within(bytes: usize, max_points_per_voxel: usize) -> usize {
        // A voxel's slot of points, moments, normal, length and dirty flag, hash entry with
        // its control byte, and free-list and dirty-list entries; twice that, for vectors and
        // the table grown by doubling.
        let per_voxel = max_points_per_voxel
            .saturating_mul(std::mem::size_of::<Vector3<f64>>())
            .saturating_add(
                std::mem::size_of::<Moments>()
                    + std::mem::size_of::<Option<Vector3<f64>>>()
                    + 2
                    + std::mem::size_of::<(u64, u32)>()
                    + 1
                    + 2 * std::mem::size_of::<u32>(),
            );
        bytes / per_voxel.saturating_mul(2)
    }
}

/// Running sums of a voxel's points (for its plane).
#[derive(Clone, Copy, Debug, Default)]
struct Moments {
    sum: Vector3<f64>,
    /// xx, xy, xz, yy, yz, zz.
    outer: [f64; 6],
}

/// The local plane of a voxel's points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VoxelPlane {
    /// Unit normal (direction of least spread), world frame.
    pub normal: Vector3<f64>,
    /// Variances along the principal axes, ascending, m².
    pub eigenvalues: [f64; 3],
    /// Points in the voxel.
    pub points: usize,
}

/// A bounded voxel hash of world points: see the module documentation.
#[derive(Clone, Debug)]
pub struct VoxelMap {
    cfg: VoxelMapConfig,
    min_spacing_m: f64,
    index: HashMap<u64, u32, BuildKeyHasher>,
    /// Points of slot `s` at `s * max_points_per_voxel ..`.
    points: Vec<Vector3<f64>>,
    lens: Vec<u8>,
    moments: Vec<Moments>,
    free: Vec<u32>,
    live_points: usize,
    refused: u64,
    /// Per slot: the unit normal of its plane when usable (see [`VoxelMap::refresh_normals`]).
    normals: Vec<Option<Vector3<f64>>>,
    /// Slots changed since the last [`VoxelMap::refresh_normals`], and a flag per slot.
    dirty: Vec<u32>,
    is_dirty: Vec<bool>,
}

impl VoxelMap {
    /// A new empty map; rejects a voxel size or distance that is not finite and > 0, a
    /// point count outside 1..=255 and a voxel count outside 1..=2³²−1 (slots are `u32`).
    pub fn new(cfg: VoxelMapConfig) -> Result<Self, RegistrationConfigError> {
        RegistrationConfigError::positive("voxel_size_m", cfg.voxel_size_m)?;
        RegistrationConfigError::positive("max_distance_m", cfg.max_distance_m)?;
        if cfg.max_points_per_voxel == 0 || cfg.max_points_per_voxel > 255 {
            return Err(RegistrationConfigError::Invalid {
                name: "max_points_per_voxel",
                value: cfg.max_points_per_voxel as f64,
                expected: "1..=255",
            });
        }
        if cfg.max_voxels == 0 || u32::try_from(cfg.max_voxels).is_err() {
            return Err(RegistrationConfigError::Invalid {
                name: "max_voxels",
                value: cfg.max_voxels as f64,
                expected: "1..=4294967295",
            });
        }
        // As KISS-ICP computes it: sqrt(v² / n).
        let spacing =
            (cfg.voxel_size_m * cfg.voxel_size_m / cfg.max_points_per_voxel as f64).sqrt();
        Ok(Self {
            cfg,
            min_spacing_m: spacing,
            index: HashMap::with_hasher(BuildKeyHasher),
            points: Vec::new(),
            lens: Vec::new(),
            moments: Vec::new(),
            free: Vec::new(),
            live_points: 0,
            refused: 0,
            normals: Vec::new(),
            dirty: Vec::new(),
            is_dirty: Vec::new(),
        })
    }

    /// The parameters.
    pub fn config(&self) -> &VoxelMapConfig {
        &self.cfg
    }

    /// Removes every point, keeping the buffers.
    pub fn clear(&mut self) {
        self.index.clear();
        self.points.clear();
        self.lens.clear();
        self.moments.clear();
        self.free.clear();
        self.live_points = 0;
        self.normals.clear();
        self.dirty.clear();
        self.is_dirty.clear();
    }

    /// Whether the map holds no point.
    pub fn is_empty(&self) -> bool {
        self.index.is_empty()
    }

    /// Points held.
    pub fn len(&self) -> usize {
        self.live_points
    }

    /// Occupied voxels.
    pub fn voxels(&self) -> usize {
        self.index.len()
    }

    /// Points refused since the map was made because it held `max_voxels` voxels.
    pub fn refused(&self) -> u64 {
        self.refused
    }

    /// Every point held, in no particular order.
    pub fn points(&self) -> impl Iterator<Item = &Vector3<f64>> + '_ {
        let m = self.cfg.max_points_per_voxel;
        self.index.values().flat_map(move |&s| {
            let s = s as usize;
            &self.points[s * m..s * m + usize::from(self.lens[s])]
        })
    }

    /// Adds world points under the insertion rule of the module documentation.
    pub fn add_points(&mut self, world_points: impl IntoIterator<Item = Vector3<f64>>) {
        let m = self.cfg.max_points_per_voxel;
        for p in world_points {
            let Some((x, y, z)) = voxel_coords(&p, self.cfg.voxel_size_m) else {
                continue;
            };
            let Some(key) = pack(x, y, z) else { continue };
            let slot = match self.index.get(&key) {
                Some(&s) => {
                    let s = s as usize;
                    let len = usize::from(self.lens[s]);
                    if len >= m {
                        continue;
                    }
                    let near = self.points[s * m..s * m + len]
                        .iter()
                        .any(|q| (q - p).norm() < self.min_spacing_m);
                    if near {
                        continue;
                    }
                    s
                }
                None if self.index.len() >= self.cfg.max_voxels => {
                    self.refused += 1;
                    continue;
                }
                None => {
                    let s = match self.free.pop() {
                        Some(s) => s as usize,
                        None => {
                            let s = self.lens.len();
                            self.lens.push(0);
                            self.moments.push(Moments::default());
                            self.normals.push(None);
                            self.is_dirty.push(false);
                            self.points.resize((s + 1) * m, Vector3::zeros());
                            s
                        }
                    };
                    self.lens[s] = 0;
                    self.moments[s] = Moments::default();
                    self.index.insert(key, s as u32);
                    s
                }
            };
            let len = usize::from(self.lens[slot]);
            self.points[slot * m + len] = p;
            self.lens[slot] += 1;
            if !self.is_dirty[slot] {
                self.is_dirty[slot] = true;
                self.dirty.push(slot as u32);
            }
            let mo = &mut self.moments[slot];
            mo.sum += p;
            mo.outer[0] += p.x * p.x;
            mo.outer[1] += p.x * p.y;
            mo.outer[2] += p.x * p.z;
            mo.outer[3] += p.y * p.y;
            mo.outer[4] += p.y * p.z;
            mo.outer[5] += p.z * p.z;
            self.live_points += 1;
        }
    }

    /// Drops every voxel whose first point is `max_distance_m` or more from `origin`.
    pub fn remove_far(&mut self, origin: &Vector3<f64>) {
        let m = self.cfg.max_points_per_voxel;
        let max_sq = self.cfg.max_distance_m * self.cfg.max_distance_m;
        let (points, lens, free, live) = (
            &self.points,
            &mut self.lens,
            &mut self.free,
            &mut self.live_points,
        );
        self.index.retain(|_, &mut s| {
            let su = s as usize;
            if (points[su * m] - origin).norm_squared() >= max_sq {
                *live -= usize::from(lens[su]);
                lens[su] = 0;
                free.push(s);
                false
            } else {
                true
            }
        });
    }

    /// Adds a sweep's points given in the sensor frame at `world_from_sensor`, then drops the
    /// voxels beyond `max_distance_m` of the sensor.
    pub fn update(&mut self, sensor_points: &[Vector3<f64>], world_from_sensor: &Isometry3<f64>) {
        let r = world_from_sensor.rotation.to_rotation_matrix();
        let t = world_from_sensor.translation.vector;
        if self.index.len().saturating_add(sensor_points.len()) > self.cfg.max_voxels {
            // The sweep may fill the map: the voxels left behind make room for it first. Below
            // the bound, KISS-ICP's order (add, then drop), which ringscan's trajectories
            // follow sweep by sweep, stands.
            self.remove_far(&t);
        }
        self.add_points(sensor_points.iter().map(|p| r * p + t));
        self.remove_far(&t);
    }

    /// The closest stored point to `query` among the 27 voxels around it, with its squared
    /// distance and its voxel slot (for [`VoxelMap::slot_plane`]).
    #[inline]
    pub fn nearest_in_slot(&self, query: &Vector3<f64>) -> Option<(Vector3<f64>, f64, u32)> {
        let (x, y, z) = voxel_coords(query, self.cfg.voxel_size_m)?;
        let m = self.cfg.max_points_per_voxel;
        let mut best: Option<(Vector3<f64>, f64, u32)> = None;
        let mut best_d = f64::INFINITY;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(key) = pack(x + dx, y + dy, z + dz) else {
                        continue;
                    };
                    let Some(&s) = self.index.get(&key) else {
                        continue;
                    };
                    let su = s as usize;
                    for q in &self.points[su * m..su * m + usize::from(self.lens[su])] {
                        let d = (q - query).norm_squared();
                        if d < best_d {
                            best_d = d;
                            best = Some((*q, d, s));
                        }
                    }
                }
            }
        }
        best
    }

    /// Recomputes the normal of every voxel changed since the last call: kept when the voxel
    /// holds at least `min_points` points, its middle standard deviation is at least
    /// `min_spread_m` and its smallest variance at most `max_flatness` times the middle one.
    pub fn refresh_normals(&mut self, min_points: usize, max_flatness: f64, min_spread_m: f64) {
        let spread_sq = min_spread_m * min_spread_m;
        for &s in &self.dirty {
            let su = s as usize;
            self.is_dirty[su] = false;
            let n = usize::from(self.lens[su]);
            self.normals[su] = plane_of(&self.moments[su], n)
                .filter(|p| {
                    let [l0, l1, _] = p.eigenvalues;
                    p.points >= min_points && l1 >= spread_sq && l0 <= max_flatness * l1
                })
                .map(|p| p.normal);
        }
        self.dirty.clear();
    }

    /// A view of the map whose neighbours carry their voxel's normal (for point-to-plane
    /// ICP), as of the last [`VoxelMap::refresh_normals`].
    pub fn with_normals(&self) -> PlanarView<'_> {
        PlanarView(self)
    }

    /// The plane of the points of a voxel slot (from [`VoxelMap::nearest_in_slot`]); `None`
    /// for fewer than 3 points or a freed slot.
    pub fn slot_plane(&self, slot: u32) -> Option<VoxelPlane> {
        let s = slot as usize;
        let n = usize::from(*self.lens.get(s)?);
        plane_of(&self.moments[s], n)
    }

    /// The plane of all the points in the 27 voxels around `query`'s voxel; `None` for fewer
    /// than 3 points.
    pub fn neighbourhood_plane(&self, query: &Vector3<f64>) -> Option<VoxelPlane> {
        let (x, y, z) = voxel_coords(query, self.cfg.voxel_size_m)?;
        let mut total = Moments::default();
        let mut n = 0usize;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(key) = pack(x + dx, y + dy, z + dz) else {
                        continue;
                    };
                    let Some(&s) = self.index.get(&key) else {
                        continue;
                    };
                    let mo = &self.moments[s as usize];
                    total.sum += mo.sum;
                    for (t, o) in total.outer.iter_mut().zip(mo.outer) {
                        *t += o;
                    }
                    n += usize::from(self.lens[s as usize]);
                }
            }
        }
        plane_of(&total, n)
    }
}

/// The plane of `n` points from their moments; `None` for fewer than 3.
fn plane_of(mo: &Moments, n: usize) -> Option<VoxelPlane> {
    if n < 3 {
        return None;
    }
    let nf = n as f64;
    let mean = mo.sum / nf;
    let o = &mo.outer;
    let cov = Matrix3::new(
        o[0] / nf - mean.x * mean.x,
        o[1] / nf - mean.x * mean.y,
        o[2] / nf - mean.x * mean.z,
        o[1] / nf - mean.x * mean.y,
        o[3] / nf - mean.y * mean.y,
        o[4] / nf - mean.y * mean.z,
        o[2] / nf - mean.x * mean.z,
        o[4] / nf - mean.y * mean.z,
        o[5] / nf - mean.z * mean.z,
    );
    let (normal, eigenvalues) = smallest_eigenvector(&cov)?;
    Some(VoxelPlane {
        normal,
        eigenvalues,
        points: n,
    })
}

/// The unit eigenvector of the smallest eigenvalue of a symmetric 3×3 matrix, and the
/// eigenvalues ascending. `None` if the matrix is not finite.
pub fn smallest_eigenvector(m: &Matrix3<f64>) -> Option<(Vector3<f64>, [f64; 3])> {
    if !m.iter().all(|v| v.is_finite()) {
        return None;
    }
    let eig = nalgebra::SymmetricEigen::new(*m);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    let v = eig.eigenvectors.column(order[0]).into_owned();
    let norm = v.norm();
    if norm.is_nan() || norm <= 0.0 {
        return None;
    }
    Some((
        v / norm,
        [
            eig.eigenvalues[order[0]],
            eig.eigenvalues[order[1]],
            eig.eigenvalues[order[2]],
        ],
    ))
}

/// A [`VoxelMap`] answering with normals: see [`VoxelMap::with_normals`].
#[derive(Clone, Copy, Debug)]
pub struct PlanarView<'a>(&'a VoxelMap);

impl NearestNeighbors for PlanarView<'_> {
    #[inline]
    fn nearest(&self, query: &Vector3<f64>) -> Option<Neighbor> {
        self.0
            .nearest_in_slot(query)
            .map(|(point, dist_sq, slot)| Neighbor {
                point,
                dist_sq,
                normal: self.0.normals.get(slot as usize).copied().flatten(),
            })
    }
}

impl NearestNeighbors for VoxelMap {
    #[inline]
    fn nearest(&self, query: &Vector3<f64>) -> Option<Neighbor> {
        self.nearest_in_slot(query)
            .map(|(point, dist_sq, _)| Neighbor {
                point,
                dist_sq,
                normal: None,
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f64, y: f64, z: f64) -> Vector3<f64> {
        Vector3::new(x, y, z)
    }

    #[test]
    fn keys_pack_floor_of_each_axis() {
        // floor(-0.5) = -1, floor(0.5) = 0, floor(1.5) = 1.
        let k = voxel_key(&v(-0.5, 0.5, 1.5), 1.0).unwrap();
        assert_eq!(k, pack(-1, 0, 1).unwrap());
        assert_ne!(k, pack(0, 0, 1).unwrap());
        assert!(voxel_key(&v(f64::NAN, 0.0, 0.0), 1.0).is_none());
        assert!(voxel_key(&v(2e6, 0.0, 0.0), 1.0).is_none());
        assert!(voxel_key(&v(-1048576.0, 0.0, 0.0), 1.0).is_some());
    }

    #[test]
    fn sampler_keeps_the_first_point_of_every_voxel() {
        let pts = [
            v(0.1, 0.1, 0.1),
            v(0.2, 0.2, 0.2),
            v(1.1, 0.0, 0.0),
            v(0.9, 0.9, 0.9),
        ];
        let mut out = Vec::new();
        VoxelSampler::new().sample(&pts, 1.0, &mut out);
        out.sort_by(|a, b| a.x.total_cmp(&b.x));
        assert_eq!(out, vec![pts[0], pts[2]]);
        // Against a naive filter (a BTreeMap of voxels, first point wins) on a scatter dense
        // enough to collide in the table.
        let mut s = 777u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64) * 40.0 - 20.0
        };
        let pts: Vec<_> = (0..20_000).map(|_| v(rnd(), rnd(), rnd() * 0.2)).collect();
        let mut naive = std::collections::BTreeMap::new();
        for p in &pts {
            let k = [
                (p.x / 0.7).floor() as i64,
                (p.y / 0.7).floor() as i64,
                (p.z / 0.7).floor() as i64,
            ];
            naive.entry(k).or_insert(*p);
        }
        let mut sampler = VoxelSampler::new();
        sampler.sample(&pts, 0.7, &mut out);
        assert_eq!(out.len(), naive.len());
        let mut got: Vec<_> = out.iter().map(|p| (p.x, p.y, p.z)).collect();
        let mut want: Vec<_> = naive.values().map(|p| (p.x, p.y, p.z)).collect();
        got.sort_by(|a, b| a.partial_cmp(b).unwrap());
        want.sort_by(|a, b| a.partial_cmp(b).unwrap());
        assert_eq!(got, want);
    }

    #[test]
    fn sampler_lists_voxels_in_robin_hood_table_order() {
        // Hand-worked: 3 points → 8 buckets (2·3 rounded up); the voxels (0,0,0), (1,0,0) and
        // (2,0,0) hash to 0, 73856093 and 147712186, i.e. buckets 0, 5 and 2 (mod 8).
        let pts = [v(0.5, 0.5, 0.5), v(1.5, 0.5, 0.5), v(2.5, 0.5, 0.5)];
        let mut out = Vec::new();
        VoxelSampler::new().sample(&pts, 1.0, &mut out);
        assert_eq!(out, vec![pts[0], pts[2], pts[1]]);
        // A collision: (0,0,0) and (8,0,0) both hash to bucket 0 of 8 (8·73856093 ≡ 0), so
        // the second probes on to bucket 1; (0,0,1) hashes to 83492791 ≡ 7. Order: 0, 1, 7.
        let pts = [v(0.5, 0.5, 0.5), v(8.5, 0.5, 0.5), v(0.5, 0.5, 1.5)];
        VoxelSampler::new().sample(&pts, 1.0, &mut out);
        assert_eq!(out, vec![pts[0], pts[1], pts[2]]);
    }

    #[test]
    fn map_insertion_rule_and_bounds() {
        let mut map = VoxelMap::new(VoxelMapConfig {
            voxel_size_m: 1.0,
            max_points_per_voxel: 4,
            max_distance_m: 10.0,
            ..VoxelMapConfig::default()
        })
        .unwrap();
        // Spacing = 1 / √4 = 0.5 m: the second point (0.3 m away) is refused.
        map.add_points([v(0.1, 0.1, 0.1), v(0.4, 0.1, 0.1), v(0.9, 0.1, 0.1)]);
        assert_eq!(map.len(), 2);
        map.add_points([v(0.1, 0.9, 0.1), v(0.9, 0.9, 0.9), v(0.1, 0.1, 0.9)]);
        assert_eq!(map.len(), 4); // full at 4
        assert_eq!(map.voxels(), 1);
        map.add_points([v(20.5, 0.0, 0.0)]);
        assert_eq!((map.len(), map.voxels()), (5, 2));
        map.remove_far(&v(0.0, 0.0, 0.0));
        assert_eq!((map.len(), map.voxels()), (4, 1));
        // The freed slot is reused.
        map.add_points([v(-3.5, 0.0, 0.0)]);
        assert_eq!(map.lens.len(), 2);
    }

    #[test]
    fn the_map_holds_at_most_max_voxels() {
        let mut map = VoxelMap::new(VoxelMapConfig {
            voxel_size_m: 1.0,
            max_points_per_voxel: 4,
            max_distance_m: 10.0,
            max_voxels: 10,
        })
        .unwrap();
        // 1000 points, each in a voxel of its own: 10 kept, the rest refused and counted.
        map.add_points((0..1000).map(|i| v(f64::from(i % 10) + 0.5, f64::from(i / 10), 0.5)));
        assert_eq!((map.voxels(), map.len(), map.refused()), (10, 10, 990));
        // Its memory: the slots of 10 voxels.
        assert_eq!(map.lens.len(), 10);
        assert!(map.points.len() <= 10 * 4);
        // A full map still takes points into the voxels it holds.
        map.add_points([v(0.9, 0.9, 0.9)]);
        assert_eq!((map.voxels(), map.len(), map.refused()), (10, 11, 990));
        // A sweep that would not fit: the voxels it left behind make room for it first.
        let far = Isometry3::translation(100.0, 0.0, 0.0);
        map.update(&[v(0.5, 0.5, 0.5), v(1.5, 0.5, 0.5)], &far);
        assert_eq!((map.voxels(), map.len(), map.refused()), (2, 2, 990));
        assert_eq!(map.lens.len(), 10);
    }

    #[test]
    fn nearest_matches_brute_force_within_one_voxel() {
        let mut map = VoxelMap::new(VoxelMapConfig {
            voxel_size_m: 0.5,
            max_points_per_voxel: 20,
            max_distance_m: 100.0,
            ..VoxelMapConfig::default()
        })
        .unwrap();
        // A deterministic scatter.
        let mut s = 12345u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64) * 4.0 - 2.0
        };
        let pts: Vec<_> = (0..3000).map(|_| v(rnd(), rnd(), rnd())).collect();
        map.add_points(pts.iter().copied());
        let stored: Vec<_> = map.points().copied().collect();
        for _ in 0..200 {
            let q = v(rnd(), rnd(), rnd());
            let brute = stored
                .iter()
                .map(|p| (p - q).norm_squared())
                .fold(f64::INFINITY, f64::min);
            let got = map.nearest(&q).unwrap();
            if brute.sqrt() < 0.5 {
                // Within one voxel size the 27-voxel search is exact.
                assert_eq!(got.dist_sq, brute);
            } else {
                assert!(got.dist_sq >= brute);
            }
        }
    }

    #[test]
    fn voxel_plane_of_a_tilted_plane() {
        let mut map = VoxelMap::new(VoxelMapConfig {
            voxel_size_m: 10.0,
            max_points_per_voxel: 255,
            max_distance_m: 100.0,
            ..VoxelMapConfig::default()
        })
        .unwrap();
        let n = v(1.0, 2.0, 3.0).normalize();
        let a = n.cross(&v(1.0, 0.0, 0.0)).normalize();
        let b = n.cross(&a);
        let c = v(5.0, 5.0, 5.0);
        // Spacing 10 / √255 = 0.63 m < 0.7 m: every point is kept.
        for i in 0..6 {
            for j in 0..6 {
                map.add_points([c + a * (i as f64 * 0.7 - 1.75) + b * (j as f64 * 0.7 - 1.75)]);
            }
        }
        let (_, _, slot) = map.nearest_in_slot(&c).unwrap();
        let plane = map.slot_plane(slot).unwrap();
        assert_eq!(plane.points, 36);
        assert!(plane.normal.dot(&n).abs() > 1.0 - 1e-9);
        assert!(plane.eigenvalues[0].abs() < 1e-9);
    }

    #[test]
    fn bad_config_is_rejected() {
        let bad = |c: VoxelMapConfig| VoxelMap::new(c).is_err();
        let d = VoxelMapConfig::default();
        assert!(bad(VoxelMapConfig {
            voxel_size_m: 0.0,
            ..d
        }));
        assert!(bad(VoxelMapConfig {
            voxel_size_m: f64::NAN,
            ..d
        }));
        assert!(bad(VoxelMapConfig {
            max_points_per_voxel: 0,
            ..d
        }));
        assert!(bad(VoxelMapConfig {
            max_points_per_voxel: 256,
            ..d
        }));
        assert!(bad(VoxelMapConfig {
            max_distance_m: -1.0,
            ..d
        }));
        for max_voxels in [0, usize::MAX] {
            assert!(bad(VoxelMapConfig { max_voxels, ..d }));
        }
    }
}
