//! Point-cloud stages applied to a sweep after decoding (and deskewing): voxel downsampling,
//! ground segmentation, Euclidean clustering.
//!
//! Every stage is a reusable object built from validated parameters
//! ([`voxel::VoxelGrid::new`], [`ground::GroundSegmenter::new`],
//! [`cluster::Clusterer::new`]): a bad value is rejected once, at construction, with a
//! [`PipelineError`] naming the parameter. Stages read flat `&[Point]` slices and write into
//! caller-owned buffers; they keep their working buffers between calls, so once warm a sweep
//! is processed without allocating. Nothing here performs I/O or reads a clock.
//!
//! A typical sweep: `VoxelGrid::downsample` → `GroundSegmenter::segment` (one label per
//! point) → `Clusterer::cluster_excluding` (the non-ground points) → boxes per cluster.
//!
//! Registration and odometry, which keep state from sweep to sweep, are the layer beside this
//! one: [`crate::registration`].

pub mod cluster;
pub mod config;
pub mod filter;
pub mod ground;
pub mod run;
pub mod voxel;

/// A stage parameter out of its valid range, found when the stage is built.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum PipelineError {
    /// `name` has the value `value`, which is not `expected`.
    #[error("invalid parameter {name} = {value}: expected {expected}")]
    InvalidParameter {
        /// The parameter, as spelled in its parameter struct (`leaf_size_m`, `min_points`, …).
        name: &'static str,
        /// The value given (integers converted to `f64`).
        value: f64,
        /// What a valid value is, e.g. `"finite and > 0"`.
        expected: &'static str,
    },
}

/// Checks that a parameter is finite and strictly positive.
pub(crate) fn positive(name: &'static str, value: f64) -> Result<(), PipelineError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(PipelineError::InvalidParameter {
            name,
            value,
            expected: "finite and > 0",
        })
    }
}

/// Checks that a parameter lies in `[lo, hi]` (and is not NaN).
pub(crate) fn within(
    name: &'static str,
    value: f64,
    lo: f64,
    hi: f64,
    expected: &'static str,
) -> Result<(), PipelineError> {
    if value >= lo && value <= hi {
        Ok(())
    } else {
        Err(PipelineError::InvalidParameter {
            name,
            value,
            expected,
        })
    }
}

/// A reusable open-addressing map from a packed 63-bit integer key (a voxel or cell) to a
/// dense id `0, 1, 2, …` in order of first insertion. Multiplicative (Fibonacci) hashing,
/// linear probing, at most three-quarters full (doubling then), so a lookup touches a few
/// neighbouring slots on average.
#[derive(Debug, Clone, Default)]
pub(crate) struct KeyTable {
    slots: Vec<(u64, u32)>,
    /// The entries while the table grows.
    moved: Vec<(u64, u32)>,
    shift: u32,
    len: u32,
}

/// Marks an empty [`KeyTable`] slot; packed keys use at most 63 bits, so never a key.
pub(crate) const NO_KEY: u64 = u64::MAX;

impl KeyTable {
    /// Empties the table for at most `max_keys` keys, keeping its size (the largest a call
    /// has needed: a sweep has far fewer voxels than points, and a table sized for those
    /// stays in cache) unless that is more than `max_keys` can ever fill: then it is cut to
    /// the size `max_keys` would grow it to (the memory stays reserved, so growing back does
    /// not allocate), and one huge call does not make every later reset clear a huge table.
    pub(crate) fn reset(&mut self, max_keys: usize) {
        let fits = (max_keys.max(12) * 4 / 3 + 1).next_power_of_two();
        if self.slots.len() > fits {
            self.slots.truncate(fits);
            self.shift = 64 - fits.trailing_zeros();
        }
        self.slots.fill((NO_KEY, 0));
        self.len = 0;
    }

    fn home(&self, key: u64) -> usize {
        home(key, self.shift)
    }

    /// Reads the home slot of `key` and discards it: called with a key that will be inserted a
    /// little later, it brings that slot into cache while other work goes on (the read is
    /// kept by `black_box`; nothing waits for its value, so several such misses overlap).
    /// Safe code has no prefetch instruction; this is its stand-in, and an imperfect one: a
    /// load that misses holds its place in the reorder buffer until it completes, so once
    /// the buffer fills the core waits on it (`perf` puts ~8 % of the OS-2-128 pipeline on
    /// this read; reading 6 keys ahead instead of 16 was no faster, BENCHMARKS.md).
    #[inline]
    pub(crate) fn warm(&self, key: u64) {
        if let Some(e) = self.slots.get(self.home(key)) {
            std::hint::black_box(e.0);
        }
    }

    /// The id of `key`, inserting it with the next id if absent; `true` if it was inserted.
    /// The table doubles (and rehashes) when it becomes three-quarters full, so any number of
    /// keys fits; `max_keys` in [`KeyTable::reset`] only bounds how large a table is kept.
    #[inline]
    pub(crate) fn insert(&mut self, key: u64) -> (u32, bool) {
        if (self.len as usize + 1) * 4 > self.slots.len() * 3 {
            self.grow();
        }
        let mask = self.slots.len() - 1;
        let mut h = self.home(key);
        loop {
            let Some(e) = self.slots.get_mut(h) else {
                return (u32::MAX, false); // unreachable: h ≤ mask
            };
            if e.0 == key {
                return (e.1, false);
            }
            if e.0 == NO_KEY {
                *e = (key, self.len);
                self.len += 1;
                return (self.len - 1, true);
            }
            h = (h + 1) & mask;
        }
    }

    #[cold]
    fn grow(&mut self) {
        // The entries go through `moved` (kept), and `slots` grows within its capacity when a
        // reset cut it: once warm, growing allocates nothing.
        self.moved.clear();
        self.moved
            .extend(self.slots.iter().copied().filter(|e| e.0 != NO_KEY));
        let cap = (self.slots.len() * 2).max(16);
        self.slots.clear();
        self.slots.resize(cap, (NO_KEY, 0));
        self.shift = 64 - cap.trailing_zeros();
        let mask = cap - 1;
        for &(key, id) in &self.moved {
            let mut h = home(key, self.shift);
            while self.slots[h].0 != NO_KEY {
                h = (h + 1) & mask;
            }
            self.slots[h] = (key, id);
        }
    }
}

/// The home slot of `key` in a table of `2^(64 − shift)` slots (Fibonacci hashing).
#[inline]
fn home(key: u64, shift: u32) -> usize {
    (key.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> shift) as usize
}

/// Half the index range of a packed key per axis: indices in `[-KEY_BIAS, KEY_BIAS)` fit.
pub(crate) const KEY_BIAS: i64 = 1 << 20;

/// Packs three grid indices, each in `[-KEY_BIAS, KEY_BIAS)`, into 21 bits each of a `u64`.
#[inline]
pub(crate) fn pack_key(i: i64, j: i64, k: i64) -> u64 {
    let b = |v: i64| ((v + KEY_BIAS) as u64) & 0x1F_FFFF;
    b(i) << 42 | b(j) << 21 | b(k)
}

/// The grid index `floor(v)` of a scaled coordinate if it fits a packed key. (Written with a
/// truncating cast: `f64::floor` is a library call on baseline x86-64, without SSE4.1.)
#[inline]
pub(crate) fn grid_index(scaled: f64) -> Option<i64> {
    let lim = KEY_BIAS as f64;
    if scaled >= -lim && scaled < lim {
        let t = scaled as i64; // truncates toward zero; exact for |scaled| < 2^20
        Some(if (t as f64) > scaled { t - 1 } else { t })
    } else {
        None // also NaN
    }
}

/// `floor(v / side)` for many `v` and one cell side, as [`grid_index`] of the quotient, at the
/// cost of a multiplication: the key passes of the voxel grid and the clusterer, three per
/// point, are a tenth of the pipeline's time on a 128 × 1024 sweep (BENCHMARKS.md "Pipeline
/// end to end").
///
/// The result is the division's, bit for bit, so a reference that divides (Open3D) puts every
/// point in the same cell: `q = v · (1/side)` differs from the rounded quotient `v / side` by
/// at most `|q| · 2^-51` (two roundings of 2^-53 each, and `1/side` rounded), under 2^-31 for
/// the `|q| < 2^20` a key holds; their floors can differ only when an integer lies between
/// them, so when `q` is within 2^-20 (far more than 2^-31) of an integer, or out of the key
/// range (or NaN), the division is done after all. That is about one coordinate in 500 000.
#[derive(Debug, Clone, Copy)]
pub(crate) struct GridScale {
    side: f64,
    /// `1/side` when it is a normal number (its rounding then bounded as above), else NaN:
    /// every call divides.
    inv: f64,
}

impl GridScale {
    /// For cells of `side` (finite, > 0; any other value only makes every call divide).
    pub(crate) fn new(side: f64) -> Self {
        let inv = 1.0 / side;
        GridScale {
            side,
            inv: if inv.is_normal() && inv > 0.0 {
                inv
            } else {
                f64::NAN
            },
        }
    }

    /// 1.5 · 2^52: `(q + ROUND) − ROUND` is `q` rounded to the nearest integer (|q| < 2^51),
    /// in two additions instead of a round trip through an integer register.
    const ROUND: f64 = 6_755_399_441_055_744.0;
    /// Closer than this to an integer, `q`'s floor may not be the division's.
    const NEAR: f64 = 1.0 / (1u64 << 20) as f64;

    /// `grid_index(v / side)`.
    #[inline(always)]
    pub(crate) fn index(self, v: f64) -> Option<i64> {
        let q = v * self.inv;
        let lim = KEY_BIAS as f64;
        if q > -lim && q < lim {
            let r = (q + Self::ROUND) - Self::ROUND;
            let d = q - r; // exact, in [−0.5, 0.5]
            if d.abs() > Self::NEAR {
                let floor = if d < 0.0 { r - 1.0 } else { r };
                return Some(floor as i64); // an integer: exact
            }
        }
        grid_index(v / self.side)
    }

    /// [`GridScale::index`]'s fast path without a branch: the index biased by `KEY_BIAS` in
    /// the low 21 bits, as [`pack_key`] packs it, and whether that is the division's result.
    /// When the flag is false (near a cell boundary, out of range, NaN), the bits mean
    /// nothing and [`GridScale::index`] must be asked.
    #[inline(always)]
    pub(crate) fn biased_fast(self, v: f64) -> (u64, bool) {
        // 2^52 + KEY_BIAS: adding it to an integer in [−2^20, 2^20) gives a double in
        // [2^52, 2^53) whose low mantissa bits are that integer + KEY_BIAS.
        const TO_BITS: f64 = 4_503_599_627_370_496.0 + KEY_BIAS as f64;
        let q = v * self.inv;
        let r = (q + Self::ROUND) - Self::ROUND;
        let d = q - r;
        let floor = r - if d < 0.0 { 1.0 } else { 0.0 };
        let ok = d.abs() > Self::NEAR && q.abs() < KEY_BIAS as f64;
        ((floor + TO_BITS).to_bits() & 0x1F_FFFF, ok)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `GridScale::index` against the division on values at, next to and between cell
    /// boundaries, for sides that are not exact binary fractions (0.1, 0.3, tol/√3, ...),
    /// out of range and non-finite values.
    #[test]
    fn grid_scale_matches_the_division() {
        let mut sides = vec![
            0.1,
            0.25,
            0.3,
            0.5 / 3f64.sqrt() * (1.0 - 1e-8),
            0.5 * (1.0 + 1e-8),
        ];
        sides.extend([0.07, 1.0 / 3.0, 2.0, 1e-3, 123.456, 1e-300, 1e300, 5e-324]);
        let mut rng = 0x2545_F491_4F6C_DD1Du64;
        let mut next = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            rng
        };
        let mut checked = 0u64;
        for &side in &sides {
            let g = GridScale::new(side);
            let mut values = vec![0.0, -0.0, f64::NAN, f64::INFINITY, f64::NEG_INFINITY];
            for _ in 0..20_000 {
                let r = next();
                // A cell boundary k·side (k up to ±2^20 and a little past), then 0–3 ulps
                // either side of it, or a random point within a cell.
                let k = (r % (1 << 22)) as i64 - (1 << 21);
                let k = if r & (1 << 40) != 0 { k / 4096 } else { k };
                let at = k as f64 * side;
                let ulps = (r >> 48) % 4;
                let v = match (r >> 52) % 3 {
                    0 => f64::from_bits(at.to_bits().wrapping_add(ulps)),
                    1 => f64::from_bits(at.to_bits().wrapping_sub(ulps)),
                    _ => at + side * ((r >> 20) % 1000) as f64 / 1000.0,
                };
                values.push(v);
                values.push(f64::from(v as f32));
            }
            for v in values {
                let exact = grid_index(v / side);
                assert_eq!(g.index(v), exact, "v {v:e}, side {side:e}");
                let (bits, ok) = g.biased_fast(v);
                if ok {
                    let k = exact.map(|k| pack_key(0, 0, k) & 0x1F_FFFF);
                    assert_eq!(Some(bits), k, "fast path: v {v:e}, side {side:e}");
                }
                checked += 1;
            }
        }
        assert!(checked > 500_000);
    }

    #[test]
    fn key_table_grows_and_keeps_every_id() {
        let mut t = KeyTable::default();
        let key = |i: u64| pack_key(i as i64 % 1000 - 500, i as i64 / 1000, -(i as i64 % 7));
        for round in 0..2 {
            t.reset(50_000);
            for i in 0..50_000u64 {
                assert_eq!(t.insert(key(i)), (i as u32, true), "round {round}, key {i}");
            }
            // After the doublings every key is still found with its id.
            for i in (0..50_000u64).rev() {
                assert_eq!(t.insert(key(i)), (i as u32, false));
            }
            assert!(t.slots.len() * 3 >= 50_000 * 4, "{}", t.slots.len());
        }
        // A small call after a large one clears a small table, and it still works.
        t.reset(100);
        assert!(t.slots.len() <= 256, "{}", t.slots.len());
        for i in 0..100u64 {
            assert_eq!(t.insert(key(i)), (i as u32, true));
        }
        for i in 0..100u64 {
            assert_eq!(t.insert(key(i)), (i as u32, false));
        }
    }
}
