//! Built-in calibrations: the manufacturer's published laser tables, for sensors whose units all
//! share one design (VLP-16 / Puck LITE, Puck Hi-Res, HDL-32E, VLP-32C). The HDL-64E and VLS-128
//! are calibrated per unit and have no built-in table: give their own db.xml / yaml.
//!
//! Each laser has an elevation (`vert_correction`), for the VLP-32C an azimuth offset
//! (`rot_correction`), and the vertical offset of its beam origin (`vert_offset_correction`):
//! the lasers do not start on the sensor axis but pass through a focal point in front of it, so
//! a beam of elevation ω appears to leave the axis at height `f·tan(−ω)` for a focal distance
//! `f` (up to 2 cm on the VLP-32C). A decoder adds it to `z` (`z = d·sin ω + vert_offset`, as
//! velodyne_decoder since its PR #518 and the VLP-16 manual's "apply the vertical correction").
//! The tables are therefore not [`advanced`](VelodyneCalibration::advanced): they carry no
//! distance or HDL-64E style corrections. `distance_resolution` is `None`: the model default
//! applies (2 mm; 4 mm for the VLP-32C).
//!
//! Sources, per table:
//! - **VLP-16 / Puck LITE** — VLP-16 User Manual (63-9243) Table 9-1 "Vertical Angle" and
//!   "Vertical Correction (mm)" columns (lasers 7–15 read from the manual; 0–6 are the mirror
//!   values of the same antisymmetric table, e.g. laser 0 at −15° → 11.2 mm). The tabulated
//!   corrections agree with `41.91 mm · tan(−ω)` (focal distance of the VLP-16 optical drawing
//!   86-0101, as in velodyne_decoder) to within the table's 0.05 mm rounding (unit test below).
//! - **Puck Hi-Res** — the same Table 9-1, Puck Hi-Res columns. The manual prints elevations to
//!   two decimals (0.67°); the three-decimal values (0.667°, multiples of 4/3° offset from ±10°)
//!   are those of Velodyne's VeloView calibration file and ros-drivers `VLP16_hires_db.yaml`.
//!   The Hi-Res corrections are the tabulated ones; they do not follow `41.91 mm · tan(−ω)`
//!   (up to 0.4 mm apart), so the table wins.
//! - **HDL-32E** — elevations of the HDL-32E User's Manual "Laser Firing Sequence" table, equal
//!   to Velodyne's VeloView `HDL-32.xml` (−30.67° … +10.67°, rotational corrections 0). Vertical
//!   offsets as tabulated in the HDL-32E envelope drawing 86-0106 Rev B, taken from
//!   velodyne_decoder `calib_db.cpp` (the drawing itself was not available here); they are
//!   within 0.08 mm of `28.83 mm · tan(−ω)`.
//! - **VLP-32C** — elevation and azimuth offset δ per laser from the VLP-32C User Manual
//!   (63-9325) Table 9-2 (checked here for lasers 14–31, and the elevation ↔ laser id pairing of
//!   Table 9-6 for all 32); identical to Velodyne's VeloView `VLP-32c.xml` and ros-drivers
//!   `VeloView-VLP-32C.yaml`. The manual's δ is added to the azimuth; ringscan subtracts
//!   `rot_correction`, so `rot_correction = −δ` (laser 14: δ = +4.2° → −4.2°, as VeloView). The
//!   manual tabulates no vertical offsets; they are `42.4 mm · tan(−ω)` with velodyne_decoder's
//!   VLP-32C focal distance.

use crate::sensor::velodyne::calib::LaserCalibration;
use crate::sensor::velodyne::calib::VelodyneCalibration;
use crate::sensor::velodyne::model::VelodyneModel;

/// VLP-16 / Puck LITE: (elevation °, vertical correction mm), by laser id.
const VLP16: [(f64, f64); 16] = [
    (-15.0, 11.2),
    (1.0, -0.7),
    (-13.0, 9.7),
    (3.0, -2.2),
    (-11.0, 8.1),
    (5.0, -3.7),
    (-9.0, 6.6),
    (7.0, -5.1),
    (-7.0, 5.1),
    (9.0, -6.6),
    (-5.0, 3.7),
    (11.0, -8.1),
    (-3.0, 2.2),
    (13.0, -9.7),
    (-1.0, 0.7),
    (15.0, -11.2),
];

/// Puck Hi-Res: (elevation °, vertical correction mm), by laser id.
const PUCK_HI_RES: [(f64, f64); 16] = [
    (-10.0, 7.4),
    (0.667, -0.9),
    (-8.667, 6.5),
    (2.0, -1.8),
    (-7.333, 5.5),
    (3.333, -2.7),
    (-6.0, 4.6),
    (4.667, -3.7),
    (-4.667, 3.7),
    (6.0, -4.6),
    (-3.333, 2.7),
    (7.333, -5.5),
    (-2.0, 1.8),
    (8.667, -6.5),
    (-0.667, 0.9),
    (10.0, -7.4),
];

/// HDL-32E: (elevation °, vertical offset mm), by laser id.
const HDL32E: [(f64, f64); 32] = [
    (-30.67, 17.17),
    (-9.33, 4.76),
    (-29.33, 16.27),
    (-8.0, 4.07),
    (-28.0, 15.4),
    (-6.67, 3.38),
    (-26.67, 14.54),
    (-5.33, 2.7),
    (-25.33, 13.71),
    (-4.0, 2.02),
    (-24.0, 12.89),
    (-2.67, 1.35),
    (-22.67, 12.09),
    (-1.33, 0.67),
    (-21.33, 11.31),
    (0.0, 0.0),
    (-20.0, 10.54),
    (1.33, -0.67),
    (-18.67, 9.78),
    (2.67, -1.35),
    (-17.33, 9.04),
    (4.0, -2.02),
    (-16.0, 8.3),
    (5.33, -2.7),
    (-14.67, 7.58),
    (6.67, -3.38),
    (-13.33, 6.86),
    (8.0, -4.07),
    (-12.0, 6.15),
    (9.33, -4.76),
    (-10.67, 5.45),
    (10.67, -5.45),
];

/// VLP-32C: (elevation °, manual azimuth offset δ °), by laser id.
const VLP32C: [(f64, f64); 32] = [
    (-25.0, 1.4),
    (-1.0, -4.2),
    (-1.667, 1.4),
    (-15.639, -1.4),
    (-11.31, 1.4),
    (0.0, -1.4),
    (-0.667, 4.2),
    (-8.843, -1.4),
    (-7.254, 1.4),
    (0.333, -4.2),
    (-0.333, 1.4),
    (-6.148, -1.4),
    (-5.333, 4.2),
    (1.333, -1.4),
    (0.667, 4.2),
    (-4.0, -1.4),
    (-4.667, 1.4),
    (1.667, -4.2),
    (1.0, 1.4),
    (-3.667, -4.2),
    (-3.333, 4.2),
    (3.333, -1.4),
    (2.333, 1.4),
    (-2.667, -1.4),
    (-3.0, 1.4),
    (7.0, -1.4),
    (4.667, 1.4),
    (-2.333, -4.2),
    (-2.0, 4.2),
    (15.0, -1.4),
    (10.333, 1.4),
    (-1.333, -1.4),
];

/// VLP-32C focal distance, metres (velodyne_decoder `calib_db.cpp`).
pub const VLP32C_FOCAL_DISTANCE_M: f64 = 42.4e-3;

/// The built-in table of a model, or `None` for the HDL-64E and VLS-128 (always per unit).
pub fn builtin(model: VelodyneModel) -> Option<VelodyneCalibration> {
    let (lasers, source): (Vec<LaserCalibration>, &str) = match model {
        VelodyneModel::Vlp16 => (
            tabulated(&VLP16),
            "built-in VLP-16 (VLP-16 manual 63-9243 Table 9-1: elevations, vertical corrections)",
        ),
        VelodyneModel::PuckHiRes => (
            tabulated(&PUCK_HI_RES),
            "built-in Puck Hi-Res (VLP-16 manual 63-9243 Table 9-1, Puck Hi-Res columns)",
        ),
        VelodyneModel::Hdl32e => (
            tabulated(&HDL32E),
            "built-in HDL-32E (HDL-32E manual elevations; vertical offsets of drawing 86-0106 Rev B)",
        ),
        VelodyneModel::Vlp32c => (
            VLP32C
                .iter()
                .enumerate()
                .map(|(id, &(elevation, delta))| {
                    let mut l =
                        LaserCalibration::angles(id as u16, elevation.to_radians(), (-delta).to_radians());
                    l.vert_offset_correction = VLP32C_FOCAL_DISTANCE_M * (-l.vert_correction).tan();
                    l
                })
                .collect(),
            "built-in VLP-32C (VLP-32C manual 63-9325 Table 9-2; vertical offset 42.4 mm·tan(-elevation))",
        ),
        VelodyneModel::Hdl64eS2 | VelodyneModel::Hdl64eS3 | VelodyneModel::Vls128 => return None,
    };
    VelodyneCalibration {
        lasers,
        distance_resolution: None,
        advanced: false,
        source: source.into(),
    }
    .validate()
    .ok()
}

/// Lasers from (elevation °, vertical offset mm) rows, no rotational correction.
fn tabulated(rows: &[(f64, f64)]) -> Vec<LaserCalibration> {
    rows.iter()
        .enumerate()
        .map(|(id, &(elevation, offset_mm))| {
            let mut l = LaserCalibration::angles(id as u16, elevation.to_radians(), 0.0);
            l.vert_offset_correction = offset_mm * 1e-3;
            l
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::velodyne::model::ALL_MODELS;

    #[test]
    fn every_fixed_design_model_has_a_valid_table() {
        for m in ALL_MODELS {
            match builtin(m) {
                Some(c) => {
                    assert_eq!(c.num_lasers(), m.lasers(), "{m}");
                    assert!(!c.advanced);
                    assert_eq!(c.distance_resolution, None);
                    assert!(c.source.starts_with("built-in "), "{}", c.source);
                }
                None => assert!(
                    matches!(
                        m,
                        VelodyneModel::Hdl64eS2 | VelodyneModel::Hdl64eS3 | VelodyneModel::Vls128
                    ),
                    "{m}"
                ),
            }
        }
    }

    #[test]
    fn vlp16_ring_order_interleaves_low_and_high_lasers() {
        // Elevations −15, 1, −13, 3, …: laser 0 is the lowest (ring 0), laser 1 at +1° is ring 8,
        // laser 15 at +15° is the highest (ring 15); ring = (elevation + 15) / 2.
        let c = builtin(VelodyneModel::Vlp16).unwrap();
        let rings = c.rings();
        for (id, &(elevation, _)) in VLP16.iter().enumerate() {
            assert_eq!(f64::from(rings[id]), (elevation + 15.0) / 2.0, "laser {id}");
        }
        assert_eq!(&rings[..4], &[0, 8, 1, 9]);
    }

    #[test]
    fn vlp16_corrections_follow_the_focal_distance() {
        // Laser 0: 41.91 mm · tan(15°) = 41.91 · 0.267949 = 11.230 mm; the manual prints 11.2.
        let c = builtin(VelodyneModel::Vlp16).unwrap();
        assert!((c.lasers[0].vert_offset_correction - 0.0112).abs() < 1e-12);
        assert!((41.91e-3 * 15f64.to_radians().tan() - 0.011230).abs() < 1e-6);
        for l in &c.lasers {
            let formula = 41.91e-3 * (-l.vert_correction).tan();
            assert!(
                (l.vert_offset_correction - formula).abs() <= 0.05e-3,
                "laser {}",
                l.laser_id
            );
        }
    }

    #[test]
    fn hdl32e_offsets_are_close_to_the_focal_formula() {
        let c = builtin(VelodyneModel::Hdl32e).unwrap();
        for l in &c.lasers {
            let formula = 28.83e-3 * (-l.vert_correction).tan();
            assert!(
                (l.vert_offset_correction - formula).abs() <= 0.08e-3,
                "laser {}",
                l.laser_id
            );
        }
        // Laser 15 fires horizontally: no offset; lasers 0 and 31 are lowest and highest.
        assert_eq!(c.lasers[15].vert_offset_correction, 0.0);
        let rings = c.rings();
        assert_eq!((rings[0], rings[31]), (0, 31));
    }

    #[test]
    fn vlp32c_uses_the_manual_offsets_with_ringscan_sign() {
        let c = builtin(VelodyneModel::Vlp32c).unwrap();
        // Manual Table 9-2: laser 14 at 0.667°, δ = +4.2° → rot_correction = −4.2°.
        assert!((c.lasers[14].rot_correction - (-4.2f64).to_radians()).abs() < 1e-15);
        assert!((c.lasers[29].vert_correction - 15f64.to_radians()).abs() < 1e-15);
        // Laser 0 at −25°: 42.4 mm · tan(25°) = 42.4 · 0.466308 = 19.771 mm.
        assert!((c.lasers[0].vert_offset_correction - 0.019771).abs() < 1e-6);
        // Manual Table 9-6 lists ids from the highest elevation down.
        let top_down = [
            29, 30, 25, 26, 21, 22, 17, 13, 18, 14, 9, 5, 10, 6, 1, 31, 2, 28, 27, 23, 24, 20, 19,
            15, 16, 12, 11, 8, 7, 4, 3, 0,
        ];
        let rings = c.rings();
        for (k, &id) in top_down.iter().enumerate() {
            assert_eq!(usize::from(rings[id]), 31 - k, "laser {id}");
        }
    }
}
