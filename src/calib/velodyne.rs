//! Velodyne calibration: one validated per-laser table, whatever file it came from.
//!
//! Units inside ringscan are always radians and metres. The parsers (`ros_yaml`,
//! `veloview_xml`) convert on load; [`VelodyneCalibration::validate`] rejects anything a
//! decoder could not use safely (non-finite values, impossible angles, duplicate laser ids).

use super::CalibError;

/// Corrections for one laser, in radians and metres.
///
/// Conventions follow velodyne_decoder / the ROS velodyne driver: azimuth used for the point
/// is `block_azimuth - rot_correction`; `vert_correction` is the elevation (+ up).
#[derive(Clone, Debug, PartialEq)]
pub struct LaserCalibration {
    /// Laser id as the packet numbers it (slot order within the firing).
    pub laser_id: u16,
    /// Elevation, radians, + up.
    pub vert_correction: f64,
    /// Rotational correction, radians; the point's azimuth is `azimuth - rot_correction`.
    pub rot_correction: f64,
    /// Far distance correction, metres (HDL-64E).
    pub dist_correction: f64,
    /// Near two-point correction along x, metres (HDL-64E).
    pub dist_correction_x: f64,
    /// Near two-point correction along y, metres (HDL-64E).
    pub dist_correction_y: f64,
    /// Vertical (height) offset of the beam origin, metres.
    pub vert_offset_correction: f64,
    /// Horizontal offset of the beam origin, metres.
    pub horiz_offset_correction: f64,
    /// Focal distance, metres (HDL-64E intensity correction).
    pub focal_distance: f64,
    /// Focal slope (HDL-64E intensity correction), unitless.
    pub focal_slope: f64,
    /// Minimum intensity for the HDL-64E intensity correction.
    pub min_intensity: u8,
    /// Maximum intensity for the HDL-64E intensity correction.
    pub max_intensity: u8,
}

impl LaserCalibration {
    /// A laser with only an elevation and a rotational correction (radians).
    pub fn angles(laser_id: u16, vert_correction: f64, rot_correction: f64) -> Self {
        Self {
            laser_id,
            vert_correction,
            rot_correction,
            dist_correction: 0.0,
            dist_correction_x: 0.0,
            dist_correction_y: 0.0,
            vert_offset_correction: 0.0,
            horiz_offset_correction: 0.0,
            focal_distance: 0.0,
            focal_slope: 0.0,
            min_intensity: 0,
            max_intensity: 255,
        }
    }
}

/// A full per-laser calibration table, indexed by laser id (`lasers[i].laser_id == i`).
#[derive(Clone, Debug, PartialEq)]
pub struct VelodyneCalibration {
    /// One entry per laser, sorted by laser id, ids 0..n without gaps.
    pub lasers: Vec<LaserCalibration>,
    /// Distance unit in metres if the file states one (it wins over the model default).
    pub distance_resolution: Option<f64>,
    /// Whether the table carries HDL-64E style corrections (distance, two-point, offsets).
    pub advanced: bool,
    /// Where it came from: a file name, or `built-in <model> (<source>)`.
    pub source: String,
}

/// Largest magnitude accepted for any distance or offset correction, metres.
pub const MAX_CORRECTION_M: f64 = 10.0;

impl VelodyneCalibration {
    /// Number of lasers.
    pub fn num_lasers(&self) -> usize {
        self.lasers.len()
    }

    /// Checks every invariant the decoder relies on; sorts by laser id.
    pub fn validate(mut self) -> Result<Self, CalibError> {
        let n = self.lasers.len();
        if !matches!(n, 16 | 32 | 64 | 128) {
            return Err(CalibError::Invalid(format!(
                "expected 16, 32, 64 or 128 lasers, found {n}"
            )));
        }
        self.lasers.sort_by_key(|l| l.laser_id);
        for (i, l) in self.lasers.iter().enumerate() {
            if usize::from(l.laser_id) != i {
                return Err(CalibError::Invalid(format!(
                    "laser ids must be 0..{n} without gaps or duplicates; position {i} holds laser_id {}",
                    l.laser_id
                )));
            }
            let half_pi = core::f64::consts::FRAC_PI_2;
            let checks: [(&str, f64, f64); 9] = [
                ("vert_correction", l.vert_correction, half_pi),
                ("rot_correction", l.rot_correction, core::f64::consts::PI),
                ("dist_correction", l.dist_correction, MAX_CORRECTION_M),
                ("dist_correction_x", l.dist_correction_x, MAX_CORRECTION_M),
                ("dist_correction_y", l.dist_correction_y, MAX_CORRECTION_M),
                (
                    "vert_offset_correction",
                    l.vert_offset_correction,
                    MAX_CORRECTION_M,
                ),
                (
                    "horiz_offset_correction",
                    l.horiz_offset_correction,
                    MAX_CORRECTION_M,
                ),
                ("focal_distance", l.focal_distance, 1000.0),
                ("focal_slope", l.focal_slope, 1000.0),
            ];
            for (name, v, limit) in checks {
                if !v.is_finite() || v.abs() > limit {
                    return Err(CalibError::Invalid(format!(
                        "laser {i}: {name} = {v} is outside [-{limit}, {limit}]"
                    )));
                }
            }
            if l.min_intensity > l.max_intensity {
                return Err(CalibError::Invalid(format!(
                    "laser {i}: min_intensity {} > max_intensity {}",
                    l.min_intensity, l.max_intensity
                )));
            }
        }
        if let Some(r) = self.distance_resolution {
            if !(r.is_finite() && r > 0.0 && r <= 0.1) {
                return Err(CalibError::Invalid(format!(
                    "distance_resolution {r} m is outside (0, 0.1]"
                )));
            }
        }
        Ok(self)
    }

    /// Ring of every laser: rank of its elevation, 0 = lowest (ties broken by laser id).
    pub fn rings(&self) -> Vec<u16> {
        let mut order: Vec<usize> = (0..self.lasers.len()).collect();
        order.sort_by(|&a, &b| {
            self.lasers[a]
                .vert_correction
                .total_cmp(&self.lasers[b].vert_correction)
                .then(a.cmp(&b))
        });
        let mut rings = vec![0u16; self.lasers.len()];
        for (rank, &laser) in order.iter().enumerate() {
            rings[laser] = rank as u16;
        }
        rings
    }
}
