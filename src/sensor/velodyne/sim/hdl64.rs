//! HDL-64E S2 / S3 measurement model for the simulator: which raw distance a laser reports so
//! that its *corrected* point lies on the scene.
//!
//! An HDL-64E calibration corrects each measured distance `m` (raw × resolution) per laser:
//! far distance correction, near "two-point" corrections along the Velodyne x and y axes,
//! horizontal and vertical beam offsets. For one laser at one azimuth the corrected point
//! `P(m)` is therefore not on a ray from the sensor centre. This module writes the correction
//! equations forward (its own f64 implementation; it never calls the decoder), splits the
//! curve `m ↦ P(m)` into the pieces on which it is affine, casts each piece as a ray into the
//! [`Scene`], and reports the smallest `m` whose point lies on a surface, quantised to a raw
//! distance that stays on the same piece. The ground truth of a measurement is the scene point
//! itself; the decoded point differs from it by the quantisation (≤ resolution / 2 along the
//! curve) and by the decoder's azimuth interpolation.
//!
//! The equations are the HDL-64E S3 manual's in velodyne_decoder 3.1.0's convention, which
//! ringscan follows (see `decode::velodyne::advanced_xyz` for the sources and the differences
//! from the ROS driver and VeloView). With α = azimuth − rotational correction, ω = elevation,
//! `dc`, `dcx`, `dcy` the far / near-x / near-y distance corrections, `h`, `v` the horizontal
//! and vertical offsets:
//!
//! ```text
//! near (two-point laser and m < 25.04 m):
//!     xy = (m + dc)·cos ω
//!     corr_x = kx·dc + (1 − kx)·dcx,  kx = (|xy·sin α| − 2.40) / (25.04 − 2.40)
//!     corr_y = ky·dc + (1 − ky)·dcy,  ky = (|xy·cos α| − 1.93) / (25.04 − 1.93)
//!     corr_z = (corr_x + corr_y) / 2
//! far (otherwise): corr_x = corr_y = corr_z = dc
//! x_v = (m + corr_x)·cos ω·sin α − h·cos α     (Velodyne frame: x right, y forward)
//! y_v = (m + corr_y)·cos ω·cos α + h·sin α
//! z_v = (m + corr_z)·sin ω + v
//! P(m) = (y_v, −x_v, z_v)                       (REP 103: x forward, y left, z up)
//! ```
//!
//! `corr_x` is affine in `m` as long as `m + dc` keeps its sign (the `|·|`), so `P` is affine on
//! `[0, −dc)`, `[−dc, 25.04)` and `[25.04, ∞)` (only the last piece for a laser without
//! two-point correction). The near/far switch is a jump (a few mm), so a quantised distance must
//! not cross it: the switch is decided on `raw × resolution` in f32, as velodyne_decoder forms
//! its measured distance, so that the simulator and the reference agree even at raw 12520
//! (25.04 m).

use crate::sensor::velodyne::calib::LaserCalibration;
use crate::sim::scene::Scene;

/// Far calibration point of the two-point correction, metres (HDL-64E S2 manual App. F).
pub const FAR_POINT_M: f64 = 25.04;
/// Near calibration point along the Velodyne x axis, metres.
pub const NEAR_POINT_X_M: f64 = 2.40;
/// Near calibration point along the Velodyne y axis, metres.
pub const NEAR_POINT_Y_M: f64 = 1.93;

/// A simulated HDL-64E measurement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measurement {
    /// Raw distance to write (≥ 1).
    pub raw: u16,
    /// The exact measured distance `m` (metres, before correction) whose corrected point is
    /// [`xyz`](Self::xyz); `raw × resolution_m` is its quantisation.
    pub measured_m: f64,
    /// The ground truth: the corrected point of `measured_m`, REP 103 frame, metres.
    pub xyz: [f64; 3],
    /// Reflectivity to write.
    pub reflectivity: u8,
    /// Label of the surface hit ([`GROUND`](crate::sim::scene::GROUND) or an object id).
    pub label: u32,
}

/// Whether the two-point correction applies to a laser: both near corrections non-zero
/// (velodyne_decoder 3.1.0 `calibration.cpp`). A laser whose near corrections equal the far one
/// gives the same points either way.
pub fn two_point(l: &LaserCalibration) -> bool {
    l.dist_correction_x != 0.0 && l.dist_correction_y != 0.0
}

/// Whether a raw distance is on the near piece of the two-point correction: `raw × resolution_m
/// < 25.04 m`, evaluated in f32 as velodyne_decoder evaluates it.
pub fn is_near(l: &LaserCalibration, raw: u16, resolution_m: f64) -> bool {
    two_point(l) && f32::from(raw) * (resolution_m as f32) < FAR_POINT_M as f32
}

/// The corrected point (REP 103, metres) of a measured distance `m` on the given piece of the
/// correction (`near`: the two-point formula; else the far correction only). `azimuth_rad` is the
/// firing azimuth minus the laser's rotational correction, radians (Velodyne convention:
/// clockwise seen from above, 0 = forward).
pub fn corrected_point(l: &LaserCalibration, azimuth_rad: f64, m: f64, near: bool) -> [f64; 3] {
    let (sw, cw) = l.vert_correction.sin_cos();
    let (sa, ca) = azimuth_rad.sin_cos();
    let dc = l.dist_correction;
    let (corr_x, corr_y, corr_z) = if near {
        let xy = (m + dc) * cw;
        let kx = ((xy * sa).abs() - NEAR_POINT_X_M) / (FAR_POINT_M - NEAR_POINT_X_M);
        let ky = ((xy * ca).abs() - NEAR_POINT_Y_M) / (FAR_POINT_M - NEAR_POINT_Y_M);
        let cx = kx * dc + (1.0 - kx) * l.dist_correction_x;
        let cy = ky * dc + (1.0 - ky) * l.dist_correction_y;
        (cx, cy, 0.5 * (cx + cy))
    } else {
        (dc, dc, dc)
    };
    let h = l.horiz_offset_correction;
    let x_v = (m + corr_x) * cw * sa - h * ca;
    let y_v = (m + corr_y) * cw * ca + h * sa;
    let z_v = (m + corr_z) * sw + l.vert_offset_correction;
    [y_v, -x_v, z_v]
}

/// The point a decoder following these equations gives for a raw distance.
pub fn decoded_point(
    l: &LaserCalibration,
    azimuth_rad: f64,
    raw: u16,
    resolution_m: f64,
) -> [f64; 3] {
    corrected_point(
        l,
        azimuth_rad,
        f64::from(raw) * resolution_m,
        is_near(l, raw, resolution_m),
    )
}

/// Pieces `[lo, hi)` of measured distance on which the corrected point is affine, in order,
/// with whether each is on the near (two-point) side.
fn pieces(l: &LaserCalibration, max_m: f64) -> Vec<(f64, f64, bool)> {
    if !two_point(l) {
        return vec![(0.0, max_m, false)];
    }
    let far = FAR_POINT_M.min(max_m);
    let kink = -l.dist_correction;
    let mut out = Vec::with_capacity(3);
    if kink > 0.0 && kink < far {
        out.push((0.0, kink, true));
        out.push((kink, far, true));
    } else {
        out.push((0.0, far, true));
    }
    if far < max_m {
        out.push((far, max_m, false));
    }
    out
}

/// The smallest measured distance whose corrected point lies on the scene, quantised to a raw
/// distance on the same piece; `None` when the laser sees nothing within the raw range.
pub fn measure(
    l: &LaserCalibration,
    azimuth_rad: f64,
    resolution_m: f64,
    scene: &dyn Scene,
) -> Option<Measurement> {
    let max_m = 65_535.0 * resolution_m;
    for (lo, hi, near) in pieces(l, max_m) {
        let a = corrected_point(l, azimuth_rad, lo, near);
        let b = corrected_point(l, azimuth_rad, hi, near);
        let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if len <= 0.0 {
            continue;
        }
        let unit = [d[0] / len, d[1] / len, d[2] / len];
        let Some(hit) = scene.cast(a, unit) else {
            continue;
        };
        if hit.range >= len {
            continue;
        }
        let m = lo + (hi - lo) * hit.range / len;
        let xyz = [
            a[0] + hit.range * unit[0],
            a[1] + hit.range * unit[1],
            a[2] + hit.range * unit[2],
        ];
        let Some(raw) = quantise(l, m, resolution_m, near) else {
            continue;
        };
        return Some(Measurement {
            raw,
            measured_m: m,
            xyz,
            reflectivity: hit.reflectivity,
            label: hit.label,
        });
    }
    None
}

/// A return `extra_m` metres (of measured distance) behind `first`, as from a surface behind it
/// (the last return of a dual-return firing), reflectivity a third of the first's.
pub fn behind(
    l: &LaserCalibration,
    azimuth_rad: f64,
    resolution_m: f64,
    first: &Measurement,
    extra_m: f64,
) -> Option<Measurement> {
    let m = first.measured_m + extra_m;
    let raw = (m / resolution_m).round();
    if !(1.0..=65_535.0).contains(&raw) {
        return None;
    }
    let raw = raw as u16;
    let near = is_near(l, raw, resolution_m);
    let raw = quantise(l, m, resolution_m, near)?;
    Some(Measurement {
        raw,
        measured_m: m,
        xyz: corrected_point(l, azimuth_rad, m, near),
        reflectivity: first.reflectivity / 3,
        label: first.label,
    })
}

/// The raw distance nearest to `m` whose piece (near / far) is `near`.
fn quantise(l: &LaserCalibration, m: f64, resolution_m: f64, near: bool) -> Option<u16> {
    let r = (m / resolution_m).round();
    [r, r - 1.0, r + 1.0]
        .into_iter()
        .filter(|c| (1.0..=65_535.0).contains(c))
        .map(|c| c as u16)
        .find(|&c| is_near(l, c, resolution_m) == near)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::scene::Shapes;

    fn laser() -> LaserCalibration {
        // Laser 0 of ros-drivers `64e_s2.1-sztaki.yaml`.
        let mut l = LaserCalibration::angles(0, -0.15304134919741974, -0.1248942899601548);
        l.dist_correction = 1.5195264;
        l.dist_correction_x = 1.5500304;
        l.dist_correction_y = 1.5231381;
        l.vert_offset_correction = 0.19548199;
        l.horiz_offset_correction = 0.025999999;
        l
    }

    #[test]
    fn the_curve_is_affine_on_each_piece() {
        let l = laser();
        let az = 2.2795;
        for (lo, hi, near) in pieces(&l, 131.07) {
            let a = corrected_point(&l, az, lo, near);
            let b = corrected_point(&l, az, hi, near);
            for k in 1..10 {
                let t = f64::from(k) / 10.0;
                let p = corrected_point(&l, az, lo + t * (hi - lo), near);
                for i in 0..3 {
                    assert!((p[i] - (a[i] + t * (b[i] - a[i]))).abs() < 1e-9);
                }
            }
        }
    }

    #[test]
    fn measurements_land_on_the_scene_and_decode_within_quantisation() {
        let l = laser();
        let scene = Shapes::room(12.0, 9.0, 1.8, 4.0);
        let mut near = 0;
        for k in 0..3600 {
            let az = f64::from(k) * 0.1_f64.to_radians();
            let m = measure(&l, az, 0.002, &scene).unwrap();
            // On a surface of the room (walls at ±12 / ±9, floor −1.8) or a sphere.
            let p = m.xyz;
            let on_plane = [
                (p[0].abs() - 12.0).abs(),
                (p[1].abs() - 9.0).abs(),
                (p[2] + 1.8).abs(),
            ]
            .into_iter()
            .any(|e| e < 1e-9);
            let on_sphere = [([4.0, 1.0, 0.0], 0.8), ([-3.0, -2.5, -0.5], 0.5)]
                .into_iter()
                .any(|(c, r)| {
                    let d: f64 = (0..3).map(|i| (p[i] - c[i]) * (p[i] - c[i])).sum();
                    (d.sqrt() - r).abs() < 1e-9
                });
            assert!(on_plane || on_sphere, "{p:?}");
            let q = decoded_point(&l, az, m.raw, 0.002);
            let e: f64 = (0..3)
                .map(|i| (p[i] - q[i]) * (p[i] - q[i]))
                .sum::<f64>()
                .sqrt();
            assert!(e <= 0.0011, "quantisation error {e}");
            near += usize::from(is_near(&l, m.raw, 0.002));
        }
        assert!(near > 1000, "the near piece is exercised ({near})");
    }

    #[test]
    fn quantisation_never_crosses_the_far_point() {
        let l = laser();
        // 25.0399 m rounds to raw 12520 (25.04 m, far piece): the near piece keeps 12519.
        assert_eq!(quantise(&l, 25.0399, 0.002, true), Some(12519));
        assert_eq!(quantise(&l, 25.0399, 0.002, false), Some(12520));
        assert!(!is_near(&l, 12520, 0.002));
        assert!(is_near(&l, 12519, 0.002));
    }
}
