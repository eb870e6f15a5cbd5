//! Sensor placement and the point filters that run before voxelisation.
//!
//! In order, per point of a (deskewed) sweep, in one pass that copies the survivors from the
//! sweep into the caller's buffer:
//! 1. **range**: keep `min_range_m ≤ |p| ≤ max_range_m` (sensor frame, from the sensor origin);
//! 2. **field of view**: keep azimuths (`atan2(y, x)` in the sensor frame, degrees, counter-
//!    clockwise from x forward) in `[azimuth_min_deg, azimuth_max_deg]` going counter-clockwise
//!    (so `[-45, 45]` is the front quarter and `[135, -135]` the back quarter), and elevations
//!    `atan2(z, √(x² + y²))` in `[elevation_min_deg, elevation_max_deg]` — tested with cross
//!    products and a tangent, no trigonometry per point;
//! 3. **extrinsics**: `p_base = base_from_sensor · p` (REP 105 `base_link`: the vehicle frame);
//! 4. **crop box**: drop points inside the axis-aligned box given in `base_link` (the vehicle's
//!    own body, which a roof-mounted sensor sees).
//!
//! Each removal is counted in [`FilterStats`]. No allocation once the caller's buffer has grown
//! to a sweep's size; no I/O.

use nalgebra::{Isometry3, Translation3, UnitQuaternion};

use crate::point::Point;

/// Why a filter parameter or an extrinsics string was rejected.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum FilterError {
    /// A parameter out of range.
    #[error("invalid parameter {name} = {value}: expected {expected}")]
    InvalidParameter {
        /// The parameter's key (`filter.min_range_m`, …).
        name: &'static str,
        /// Its value.
        value: f64,
        /// What a valid value is.
        expected: &'static str,
    },
    /// An extrinsics string is not `NAME=x,y,z,roll,pitch,yaw`.
    #[error("extrinsics {text:?}: {reason}")]
    Extrinsics {
        /// The text given.
        text: String,
        /// What is wrong.
        reason: String,
    },
}

/// An axis-aligned box, metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CropBox {
    /// Minimum corner (x, y, z).
    pub min_m: [f64; 3],
    /// Maximum corner (x, y, z).
    pub max_m: [f64; 3],
}

/// Parameters of the filters (see the module documentation). `None` disables a filter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FilterConfig {
    /// Nearest range kept, metres (≥ 0).
    pub min_range_m: f64,
    /// Farthest range kept, metres (> `min_range_m`; infinity keeps everything).
    pub max_range_m: f64,
    /// Azimuth window `[from, to]` counter-clockwise, degrees in [-360, 360].
    pub azimuth_deg: Option<[f64; 2]>,
    /// Elevation window `[min, max]`, degrees in [-90, 90], min < max.
    pub elevation_deg: Option<[f64; 2]>,
    /// Points inside this box (in `base_link`) are removed.
    pub crop_box: Option<CropBox>,
}

impl Default for FilterConfig {
    fn default() -> Self {
        Self {
            min_range_m: 0.0,
            max_range_m: f64::INFINITY,
            azimuth_deg: None,
            elevation_deg: None,
            crop_box: None,
        }
    }
}

fn invalid(name: &'static str, value: f64, expected: &'static str) -> FilterError {
    FilterError::InvalidParameter {
        name,
        value,
        expected,
    }
}

impl FilterConfig {
    /// Checks every parameter; the error names the first bad one by its configuration key.
    pub fn validate(&self) -> Result<(), FilterError> {
        if !(self.min_range_m.is_finite() && self.min_range_m >= 0.0) {
            return Err(invalid(
                "filter.min_range_m",
                self.min_range_m,
                "finite and >= 0",
            ));
        }
        if self.max_range_m.is_nan() || self.max_range_m <= self.min_range_m {
            return Err(invalid(
                "filter.max_range_m",
                self.max_range_m,
                "> filter.min_range_m",
            ));
        }
        if let Some([a, b]) = self.azimuth_deg {
            for (name, v) in [("filter.azimuth_min_deg", a), ("filter.azimuth_max_deg", b)] {
                if !(-360.0..=360.0).contains(&v) {
                    return Err(invalid(name, v, "in [-360, 360]"));
                }
            }
        }
        if let Some([lo, hi]) = self.elevation_deg {
            if !(-90.0..=90.0).contains(&lo) {
                return Err(invalid("filter.elevation_min_deg", lo, "in [-90, 90]"));
            }
            if !(-90.0..=90.0).contains(&hi) || hi <= lo {
                return Err(invalid(
                    "filter.elevation_max_deg",
                    hi,
                    "in [-90, 90] and > filter.elevation_min_deg",
                ));
            }
        }
        if let Some(b) = self.crop_box {
            const MIN: [&str; 3] = [
                "filter.crop_box_min_m[0]",
                "filter.crop_box_min_m[1]",
                "filter.crop_box_min_m[2]",
            ];
            const MAX: [&str; 3] = [
                "filter.crop_box_max_m[0]",
                "filter.crop_box_max_m[1]",
                "filter.crop_box_max_m[2]",
            ];
            for i in 0..3 {
                if !b.min_m[i].is_finite() {
                    return Err(invalid(MIN[i], b.min_m[i], "finite"));
                }
                if !b.max_m[i].is_finite() || b.max_m[i] <= b.min_m[i] {
                    return Err(invalid(MAX[i], b.max_m[i], "finite and > the minimum"));
                }
            }
        }
        Ok(())
    }
}

/// Where a sensor sits on the vehicle: `base_link ← sensor`.
#[derive(Clone, Debug, PartialEq)]
pub struct Extrinsics {
    /// Sensor name the transform belongs to (its frame id).
    pub name: String,
    /// Maps sensor-frame points into `base_link`.
    pub base_from_sensor: Isometry3<f64>,
}

impl Extrinsics {
    /// Parses `NAME=x,y,z,roll,pitch,yaw`: metres, then degrees, the rotation applied as
    /// roll about x, then pitch about y, then yaw about z, all fixed axes (REP 103:
    /// `R = Rz(yaw)·Ry(pitch)·Rx(roll)`).
    pub fn parse(text: &str) -> Result<Self, FilterError> {
        let err = |reason: &str| FilterError::Extrinsics {
            text: text.to_string(),
            reason: reason.to_string(),
        };
        let (name, values) = text
            .split_once('=')
            .ok_or_else(|| err("expected NAME=x,y,z,roll,pitch,yaw"))?;
        let name = name.trim();
        if name.is_empty() {
            return Err(err("the sensor name is empty"));
        }
        let mut v = [0f64; 6];
        let mut n = 0;
        for part in values.split(',') {
            if n == 6 {
                return Err(err("more than 6 values"));
            }
            let x: f64 = part
                .trim()
                .parse()
                .map_err(|_| err(&format!("value {} ({part:?}) is not a number", n + 1)))?;
            if !x.is_finite() {
                return Err(err(&format!("value {} is not finite", n + 1)));
            }
            v[n] = x;
            n += 1;
        }
        if n != 6 {
            return Err(err(&format!(
                "expected 6 values x,y,z (m),roll,pitch,yaw (deg), found {n}"
            )));
        }
        Ok(Self {
            name: name.to_string(),
            base_from_sensor: Isometry3::from_parts(
                Translation3::new(v[0], v[1], v[2]),
                UnitQuaternion::from_euler_angles(
                    v[3].to_radians(),
                    v[4].to_radians(),
                    v[5].to_radians(),
                ),
            ),
        })
    }
}

/// What one call of [`Filter::apply`] removed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FilterStats {
    /// Points in.
    pub input: usize,
    /// Removed by the range filter (or for a non-finite coordinate).
    pub range: usize,
    /// Removed by the field-of-view filter.
    pub fov: usize,
    /// Removed by the crop box.
    pub crop_box: usize,
}

/// The filters with their validated parameters and precomputed constants.
#[derive(Clone, Debug)]
pub struct Filter {
    config: FilterConfig,
    min2: f32,
    max2: f32,
    /// Unit directions of the azimuth window's ends and whether it spans more than 180°.
    azimuth: Option<([f32; 2], [f32; 2], bool)>,
    /// tan of the elevation limits.
    elevation: Option<(f32, f32)>,
}

impl Filter {
    /// Validates `config` and prepares the constants.
    pub fn new(config: FilterConfig) -> Result<Self, FilterError> {
        config.validate()?;
        let azimuth = config.azimuth_deg.map(|[a, b]| {
            let (a, b) = (a.to_radians(), b.to_radians());
            let width = (b - a).rem_euclid(std::f64::consts::TAU);
            (
                [a.cos() as f32, a.sin() as f32],
                [b.cos() as f32, b.sin() as f32],
                width > std::f64::consts::PI,
            )
        });
        let elevation = config
            .elevation_deg
            .map(|[lo, hi]| (lo.to_radians().tan() as f32, hi.to_radians().tan() as f32));
        Ok(Self {
            config,
            min2: (config.min_range_m * config.min_range_m) as f32,
            max2: if config.max_range_m.is_finite() {
                (config.max_range_m * config.max_range_m) as f32
            } else {
                f32::INFINITY
            },
            azimuth,
            elevation,
        })
    }

    /// The parameters.
    pub fn config(&self) -> &FilterConfig {
        &self.config
    }

    fn in_fov(&self, p: &Point) -> bool {
        if let Some((a, b, wide)) = self.azimuth {
            // p is counter-clockwise of a: cross(a, p) ≥ 0; clockwise of b: cross(p, b) ≥ 0.
            let after_a = a[0] * p.y - a[1] * p.x >= 0.0;
            let before_b = p.x * b[1] - p.y * b[0] >= 0.0;
            let inside = if wide {
                after_a || before_b
            } else {
                after_a && before_b
            };
            if !inside {
                return false;
            }
        }
        if let Some((lo, hi)) = self.elevation {
            let r = (p.x * p.x + p.y * p.y).sqrt();
            if p.z < r * lo || p.z > r * hi {
                return false;
            }
        }
        true
    }

    /// Writes the points of `src` that pass the filters, moved into `base_link` with
    /// `base_from_sensor`, to `dst` (cleared first; order kept).
    pub fn apply(
        &self,
        src: &[Point],
        dst: &mut Vec<Point>,
        base_from_sensor: &Isometry3<f64>,
    ) -> FilterStats {
        let mut stats = FilterStats {
            input: src.len(),
            ..FilterStats::default()
        };
        dst.clear();
        dst.reserve(src.len());
        let m = base_from_sensor.to_homogeneous();
        let identity = *base_from_sensor == Isometry3::identity();
        let a: [f32; 12] = std::array::from_fn(|i| m[(i / 4, i % 4)] as f32);
        let crop = self
            .config
            .crop_box
            .map(|b| (b.min_m.map(|v| v as f32), b.max_m.map(|v| v as f32)));
        for &p in src {
            let mut p = p;
            let r2 = p.x * p.x + p.y * p.y + p.z * p.z;
            // NaN fails both comparisons: non-finite points go with the range filter.
            if !(r2 >= self.min2 && r2 <= self.max2) {
                stats.range += 1;
                continue;
            }
            if !self.in_fov(&p) {
                stats.fov += 1;
                continue;
            }
            if !identity {
                let (x, y, z) = (p.x, p.y, p.z);
                p.x = a[0] * x + a[1] * y + a[2] * z + a[3];
                p.y = a[4] * x + a[5] * y + a[6] * z + a[7];
                p.z = a[8] * x + a[9] * y + a[10] * z + a[11];
            }
            if let Some((lo, hi)) = crop {
                if p.x >= lo[0]
                    && p.x <= hi[0]
                    && p.y >= lo[1]
                    && p.y <= hi[1]
                    && p.z >= lo[2]
                    && p.z <= hi[2]
                {
                    stats.crop_box += 1;
                    continue;
                }
            }
            dst.push(p);
        }
        stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(x: f32, y: f32, z: f32) -> Point {
        Point {
            x,
            y,
            z,
            ..Point::default()
        }
    }

    /// Reference: the same decisions with atan2 and the Euclidean norm.
    fn reference(cfg: &FilterConfig, p: &Point) -> bool {
        let (x, y, z) = (f64::from(p.x), f64::from(p.y), f64::from(p.z));
        let r = (x * x + y * y + z * z).sqrt();
        if r < cfg.min_range_m || r > cfg.max_range_m {
            return false;
        }
        if let Some([a, b]) = cfg.azimuth_deg {
            let az = y.atan2(x).to_degrees();
            let width = (b - a).rem_euclid(360.0);
            if (az - a).rem_euclid(360.0) > width {
                return false;
            }
        }
        if let Some([lo, hi]) = cfg.elevation_deg {
            let el = z.atan2((x * x + y * y).sqrt()).to_degrees();
            if el < lo || el > hi {
                return false;
            }
        }
        true
    }

    #[test]
    fn range_and_field_of_view_match_a_trigonometric_reference() {
        let mut pts = Vec::new();
        for i in 0..72 {
            for j in 0..9 {
                let az = (f64::from(i) * 5.0 + 2.5).to_radians();
                let el = (f64::from(j) * 10.0 - 42.5).to_radians();
                for r in [0.3, 1.0, 20.0, 150.0] {
                    pts.push(at(
                        (r * el.cos() * az.cos()) as f32,
                        (r * el.cos() * az.sin()) as f32,
                        (r * el.sin()) as f32,
                    ));
                }
            }
        }
        for cfg in [
            FilterConfig {
                min_range_m: 0.5,
                max_range_m: 100.0,
                ..FilterConfig::default()
            },
            FilterConfig {
                azimuth_deg: Some([-45.0, 45.0]),
                ..FilterConfig::default()
            },
            FilterConfig {
                azimuth_deg: Some([135.0, -135.0]),
                elevation_deg: Some([-15.0, 10.0]),
                ..FilterConfig::default()
            },
            FilterConfig {
                azimuth_deg: Some([-120.0, 170.0]), // 290° wide
                ..FilterConfig::default()
            },
        ] {
            let filter = Filter::new(cfg).unwrap();
            let mut kept = Vec::new();
            let stats = filter.apply(&pts, &mut kept, &Isometry3::identity());
            let expected: Vec<Point> = pts.iter().filter(|p| reference(&cfg, p)).copied().collect();
            assert_eq!(kept, expected, "{cfg:?}");
            assert!(!expected.is_empty() && expected.len() < pts.len());
            assert_eq!(stats.input - stats.range - stats.fov, expected.len());
        }
    }

    #[test]
    fn extrinsics_move_points_into_base_link_then_the_crop_box_applies() {
        // Sensor 1.2 m ahead of base_link, 1.8 m up, turned 90° left (yaw): its x axis is the
        // vehicle's y axis. A point 5 m ahead of the sensor is at (1.2, 5, 1.8) in base_link.
        let e = Extrinsics::parse("os1=1.2,0,1.8,0,0,90").unwrap();
        assert_eq!(e.name, "os1");
        let cfg = FilterConfig {
            crop_box: Some(CropBox {
                min_m: [-1.0, -1.0, 0.0],
                max_m: [3.0, 1.0, 2.0],
            }),
            ..FilterConfig::default()
        };
        let filter = Filter::new(cfg).unwrap();
        // The second point, 0.5 m to the sensor's right and 0.2 m below it, lands on the
        // vehicle's roof at (1.7, 0, 1.6).
        let mut pts = vec![at(9.0, 9.0, 9.0)];
        let stats = filter.apply(
            &[at(5.0, 0.0, 0.0), at(0.0, -0.5, -0.2)],
            &mut pts,
            &e.base_from_sensor,
        );
        assert_eq!(stats.crop_box, 1);
        assert_eq!(pts.len(), 1);
        assert!((pts[0].x - 1.2).abs() < 1e-6 && (pts[0].y - 5.0).abs() < 1e-6);
        assert!((pts[0].z - 1.8).abs() < 1e-6);
    }

    #[test]
    fn extrinsics_roll_pitch_yaw_compose_as_rz_ry_rx() {
        // roll 90°: y → z; then yaw 90°: x → y. The sensor's y axis ends on base z.
        let e = Extrinsics::parse("a=0,0,0,90,0,90").unwrap();
        let v = e.base_from_sensor * nalgebra::Point3::new(0.0, 1.0, 0.0);
        assert!(
            (v - nalgebra::Point3::new(0.0, 0.0, 1.0)).norm() < 1e-12,
            "{v:?}"
        );
        let v = e.base_from_sensor * nalgebra::Point3::new(1.0, 0.0, 0.0);
        assert!(
            (v - nalgebra::Point3::new(0.0, 1.0, 0.0)).norm() < 1e-12,
            "{v:?}"
        );
        for bad in [
            "a",
            "=1,2,3,4,5,6",
            "a=1,2,3",
            "a=1,2,3,4,5,6,7",
            "a=1,2,x,4,5,6",
            "a=1,2,inf,4,5,6",
        ] {
            assert!(Extrinsics::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn invalid_parameters_are_named() {
        let name = |cfg: FilterConfig| match Filter::new(cfg) {
            Err(FilterError::InvalidParameter { name, .. }) => name,
            other => panic!("{other:?}"),
        };
        let d = FilterConfig::default();
        assert_eq!(
            name(FilterConfig {
                min_range_m: -1.0,
                ..d
            }),
            "filter.min_range_m"
        );
        assert_eq!(
            name(FilterConfig {
                max_range_m: f64::NAN,
                ..d
            }),
            "filter.max_range_m"
        );
        assert_eq!(
            name(FilterConfig {
                elevation_deg: Some([10.0, 5.0]),
                ..d
            }),
            "filter.elevation_max_deg"
        );
        assert_eq!(
            name(FilterConfig {
                crop_box: Some(CropBox {
                    min_m: [0.0; 3],
                    max_m: [1.0, 0.0, 1.0]
                }),
                ..d
            }),
            "filter.crop_box_max_m[1]"
        );
        // Non-finite points are dropped as out of range, not passed on.
        let f = Filter::new(d).unwrap();
        let mut out = Vec::new();
        let pts = [at(f32::NAN, 0.0, 0.0), at(1.0, 0.0, 0.0)];
        assert_eq!(f.apply(&pts, &mut out, &Isometry3::identity()).range, 1);
        assert_eq!(out, [pts[1]]);
    }
}
