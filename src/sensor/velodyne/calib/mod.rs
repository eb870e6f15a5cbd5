//! Velodyne calibration: one validated per-laser table, whatever file it came from.
//!
//! Units inside ringscan are always radians and metres. The parsers (`ros_yaml`,
//! `veloview_xml`) convert on load; [`VelodyneCalibration::validate`] rejects anything a
//! decoder could not use safely (non-finite values, impossible angles, duplicate laser ids).
//!
//! # Velodyne conventions shared by every source
//!
//! - **Units**: radians and metres inside ringscan. ROS yaml is already in radians and metres
//!   (including `focal_distance`, see [`ros_yaml`]); VeloView xml / db.xml is in degrees and
//!   centimetres and is converted on load ([`veloview_xml`]).
//! - **Two-point distance correction** (HDL-64E): the ROS and velodyne_decoder decoders apply
//!   the near/far interpolation only to lasers whose `two_pt_correction_available` is true. The
//!   parsers fold that flag into the values: a laser without two-point correction gets
//!   `dist_correction_x = dist_correction_y = dist_correction`, for which the interpolation
//!   `(dc - dcx)·(xx - 2.40)/(25.04 - 2.40) + dcx` is exactly `dc`. A decoder can therefore apply
//!   the two-point formula to every laser of an [`VelodyneCalibration::advanced`] table and get
//!   what the references get, with no extra flag.
//! - **`advanced`** is true when any laser has a non-zero distance correction (`dist_correction`,
//!   `dist_correction_x`, `dist_correction_y`) or offset (`vert_offset_correction`,
//!   `horiz_offset_correction`) — the HDL-64E model. Built-in tables are not advanced: their only
//!   extra is a pure vertical beam-origin offset, applied as `z += vert_offset_correction`
//!   ([`builtin`]).
//! - **Intensity limits** default to `min_intensity = 0`, `max_intensity = 255` when a file does
//!   not state them (ROS `calibration.cc`, and db.xml files without `minIntensity_` /
//!   `maxIntensity_`).

pub mod builtin;
pub mod ros_yaml;
pub mod veloview_xml;

use crate::sensor::calib::{check_size, CalibError};

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
                    // 1e300 in full is 301 digits: large values in exponent form.
                    let shown = if v.abs() < 1e6 {
                        format!("{v}")
                    } else {
                        format!("{v:e}")
                    };
                    return Err(CalibError::Invalid(format!(
                        "laser {i}: {name} = {shown} is outside [-{limit}, {limit}]"
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

/// Whether any laser carries a distance or offset correction (the HDL-64E model).
pub(crate) fn has_advanced_corrections(lasers: &[LaserCalibration]) -> bool {
    lasers.iter().any(|l| {
        [
            l.dist_correction,
            l.dist_correction_x,
            l.dist_correction_y,
            l.vert_offset_correction,
            l.horiz_offset_correction,
        ]
        .iter()
        .any(|&v| v != 0.0)
    })
}

/// Parses a Velodyne calibration text of either format: VeloView xml / db.xml when the first
/// non-blank character is `<`, ROS yaml otherwise. `source_name` (usually the file name) is kept
/// in [`VelodyneCalibration::source`].
pub fn parse_velodyne(text: &str, source_name: &str) -> Result<VelodyneCalibration, CalibError> {
    check_size(text.len())?;
    let body = text.strip_prefix('\u{feff}').unwrap_or(text);
    if body.trim_start().starts_with('<') {
        veloview_xml::parse(text, source_name)
    } else {
        ros_yaml::parse(text, source_name)
    }
}

/// Like [`parse_velodyne`], for the raw bytes of a file: refuses oversized input before looking
/// at it and reports text that is not UTF-8 with the line and column of the first bad byte.
pub fn parse_velodyne_bytes(
    bytes: &[u8],
    source_name: &str,
) -> Result<VelodyneCalibration, CalibError> {
    check_size(bytes.len())?;
    match core::str::from_utf8(bytes) {
        Ok(text) => parse_velodyne(text, source_name),
        Err(e) => {
            let good = &bytes[..e.valid_up_to()];
            let line = 1 + good.iter().filter(|&&b| b == b'\n').count();
            let line_start = good.iter().rposition(|&b| b == b'\n').map_or(0, |p| p + 1);
            // Column in characters of the valid prefix of this line, 1-based.
            let column = 1 + String::from_utf8_lossy(&good[line_start..]).chars().count();
            Err(CalibError::Syntax {
                format: "text",
                line,
                column,
                message: format!("not UTF-8 text (bad byte at offset {})", e.valid_up_to()),
            })
        }
    }
}
