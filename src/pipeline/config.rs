//! The pipeline's parameters: one struct, every parameter named with its unit, validated at
//! load with the offending key named.
//!
//! The built-in `default` pipeline is [`PipelineConfig::default`]. A TOML file (feature
//! `config`, on with the command line) overrides any subset of it:
//!
//! ```toml
//! [deskew]
//! mode = "constant-velocity"      # none | constant-velocity | imu | odometry | poses
//! reference = "start"             # start | end: the sweep's timestamp or its last point
//! linear_mps = [0.0, 0.0, 0.0]    # the constant twist, sensor frame
//! angular_degps = [0.0, 0.0, 0.0]
//! poses_file = "drive.tum"        # with mode = "poses"
//!
//! [filter]
//! min_range_m = 0.5
//! max_range_m = 120.0
//! azimuth_min_deg = -180.0        # both or neither
//! azimuth_max_deg = 180.0
//! elevation_min_deg = -90.0       # both or neither
//! elevation_max_deg = 90.0
//! crop_box_min_m = [-1.0, -1.0, -0.5]   # both or neither, base_link frame
//! crop_box_max_m = [3.5, 1.0, 2.0]
//!
//! [voxel]
//! leaf_m = 0.2
//!
//! [ground]
//! method = "grid"                 # grid | ransac
//! distance_threshold_m = 0.15
//! sectors = 64                    # grid
//! radial_bin_m = 1.0
//! max_range_m = 100.0
//! max_slope_deg = 15.0
//! max_step_m = 0.25
//! sensor_height_m = 1.8           # optional
//! riser_column_deg = 0.25         # riser (kerb face) test: profile width, 0 = off
//! riser_margin_m = 0.01
//! iterations = 100                # ransac
//! seed = 1
//!
//! [cluster]
//! tolerance_m = 0.5
//! min_points = 5
//! max_points = 100000
//! ```
//!
//! Unknown sections and keys, values of the wrong type and values out of range are errors
//! naming the key (`voxel.leaf_m`, …). The core holds only the plain struct and its checks;
//! parsing TOML needs the `config` feature.

use super::cluster::ClusterParams;
#[cfg(feature = "config")]
use super::filter::CropBox;
use super::filter::{FilterConfig, FilterError};
use super::ground::{GroundMethod, PolarGridParams};
use crate::deskew::Reference;

/// Why a configuration was rejected.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// The text is not valid TOML.
    #[error("not valid TOML: {0}")]
    Syntax(String),
    /// A section or key the pipeline does not know.
    #[error("unknown key {key}")]
    UnknownKey {
        /// The dotted key.
        key: String,
    },
    /// A value of the wrong type.
    #[error("{key}: expected {expected}")]
    Type {
        /// The dotted key.
        key: String,
        /// What was expected.
        expected: &'static str,
    },
    /// A value out of range or a missing partner key.
    #[error("{key} = {value}: expected {expected}")]
    Invalid {
        /// The dotted key.
        key: String,
        /// The value as given.
        value: String,
        /// What a valid value is.
        expected: &'static str,
    },
}

impl From<FilterError> for ConfigError {
    fn from(e: FilterError) -> Self {
        match e {
            FilterError::InvalidParameter {
                name,
                value,
                expected,
            } => Self::Invalid {
                key: name.to_string(),
                value: value.to_string(),
                expected,
            },
            other => Self::Invalid {
                key: "filter".into(),
                value: other.to_string(),
                expected: "valid filter parameters",
            },
        }
    }
}

/// Where deskew gets the sensor's motion.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum DeskewMode {
    /// No deskew.
    None,
    /// The constant twist of [`DeskewConfig`].
    #[default]
    ConstantVelocity,
    /// Gyro rotation (Ouster IMU) with the twist's linear velocity.
    Imu,
    /// A constant twist fed by odometry's last relative motion.
    Odometry,
    /// A TUM poses file (its path; read by the caller).
    Poses(String),
}

impl DeskewMode {
    /// The name used in configuration and on the command line.
    pub fn name(&self) -> &'static str {
        match self {
            Self::None => "none",
            Self::ConstantVelocity => "constant-velocity",
            Self::Imu => "imu",
            Self::Odometry => "odometry",
            Self::Poses(_) => "poses",
        }
    }
}

/// `[deskew]`.
#[derive(Clone, Debug, PartialEq)]
pub struct DeskewConfig {
    /// `deskew.mode`.
    pub mode: DeskewMode,
    /// `deskew.reference`.
    pub reference: Reference,
    /// `deskew.linear_mps`: sensor-frame linear velocity, m/s.
    pub linear_mps: [f64; 3],
    /// `deskew.angular_degps`: sensor-frame angular velocity, °/s.
    pub angular_degps: [f64; 3],
}

impl Default for DeskewConfig {
    /// Constant velocity at rest (the identity until odometry or a twist is given).
    fn default() -> Self {
        Self {
            mode: DeskewMode::ConstantVelocity,
            reference: Reference::Start,
            linear_mps: [0.0; 3],
            angular_degps: [0.0; 3],
        }
    }
}

/// `[ground] method`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum GroundMethodName {
    /// Local planes on a polar grid.
    #[default]
    Grid,
    /// One plane by RANSAC.
    Ransac,
}

/// `[ground]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GroundConfig {
    /// `ground.method`.
    pub method: GroundMethodName,
    /// `ground.distance_threshold_m`: a point this close above its ground plane is ground.
    pub distance_threshold_m: f64,
    /// `ground.sectors` (grid).
    pub sectors: u32,
    /// `ground.radial_bin_m` (grid).
    pub radial_bin_m: f64,
    /// `ground.max_range_m` (grid): farther points are not ground.
    pub max_range_m: f64,
    /// `ground.max_slope_deg` (grid).
    pub max_slope_deg: f64,
    /// `ground.max_step_m` (grid): the highest kerb.
    pub max_step_m: f64,
    /// `ground.sensor_height_m` (grid): height of the points' origin above the ground.
    pub sensor_height_m: Option<f64>,
    /// `ground.riser_column_deg` (grid): azimuth width of the riser test's profiles; 0 = off.
    pub riser_column_deg: f64,
    /// `ground.riser_margin_m` (grid): height margin of the riser test.
    pub riser_margin_m: f64,
    /// `ground.iterations` (ransac).
    pub iterations: u32,
    /// `ground.seed` (ransac).
    pub seed: u64,
}

impl Default for GroundConfig {
    fn default() -> Self {
        Self {
            method: GroundMethodName::Grid,
            distance_threshold_m: 0.15,
            sectors: 64,
            radial_bin_m: 1.0,
            max_range_m: 100.0,
            max_slope_deg: 15.0,
            max_step_m: 0.25,
            sensor_height_m: None,
            riser_column_deg: 0.25,
            riser_margin_m: 0.01,
            iterations: 100,
            seed: 1,
        }
    }
}

impl GroundConfig {
    /// The segmenter's method and parameters.
    pub fn method(&self) -> GroundMethod {
        match self.method {
            GroundMethodName::Grid => GroundMethod::PolarGrid(PolarGridParams {
                sectors: self.sectors,
                radial_bin_m: self.radial_bin_m,
                max_range_m: self.max_range_m,
                distance_threshold_m: self.distance_threshold_m,
                max_slope_deg: self.max_slope_deg,
                max_step_m: self.max_step_m,
                sensor_height_m: self.sensor_height_m,
                riser_column_deg: self.riser_column_deg,
                riser_margin_m: self.riser_margin_m,
            }),
            GroundMethodName::Ransac => GroundMethod::Ransac {
                distance_threshold_m: self.distance_threshold_m,
                iterations: self.iterations,
                seed: self.seed,
            },
        }
    }
}

/// `[cluster]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClusterConfig {
    /// `cluster.tolerance_m`: points this close are in one cluster.
    pub tolerance_m: f64,
    /// `cluster.min_points`: smaller clusters are dropped.
    pub min_points: usize,
    /// `cluster.max_points`: larger clusters are dropped.
    pub max_points: usize,
}

impl ClusterConfig {
    /// The clusterer's parameters.
    pub fn params(&self) -> ClusterParams {
        ClusterParams::new(self.tolerance_m, self.min_points, self.max_points)
    }
}

impl Default for ClusterConfig {
    fn default() -> Self {
        Self {
            tolerance_m: 0.5,
            min_points: 5,
            max_points: 100_000,
        }
    }
}

/// Every parameter of the pipeline.
#[derive(Clone, Debug, PartialEq)]
pub struct PipelineConfig {
    /// `[deskew]`.
    pub deskew: DeskewConfig,
    /// `[filter]`.
    pub filter: FilterConfig,
    /// `voxel.leaf_m`: voxel edge, metres.
    pub voxel_leaf_m: f64,
    /// `[ground]`.
    pub ground: GroundConfig,
    /// `[cluster]`.
    pub cluster: ClusterConfig,
}

impl Default for PipelineConfig {
    /// The `default` pipeline: constant-velocity deskew at rest, points from 0.5 to 120 m,
    /// 0.2 m voxels, polar-grid ground, 0.5 m clusters of 5 to 100 000 voxels.
    fn default() -> Self {
        Self {
            deskew: DeskewConfig::default(),
            filter: FilterConfig {
                min_range_m: 0.5,
                max_range_m: 120.0,
                ..FilterConfig::default()
            },
            voxel_leaf_m: 0.2,
            ground: GroundConfig::default(),
            cluster: ClusterConfig::default(),
        }
    }
}

fn invalid(key: &str, value: impl ToString, expected: &'static str) -> ConfigError {
    ConfigError::Invalid {
        key: key.to_string(),
        value: value.to_string(),
        expected,
    }
}

fn positive(key: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(invalid(key, v, "finite and > 0"))
    }
}

impl PipelineConfig {
    /// Checks every value; the error names the first bad key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let d = &self.deskew;
        for (i, v) in d.linear_mps.iter().enumerate() {
            if !v.is_finite() || v.abs() > 1000.0 {
                return Err(invalid(
                    &format!("deskew.linear_mps[{i}]"),
                    v,
                    "finite, |v| <= 1000",
                ));
            }
        }
        for (i, v) in d.angular_degps.iter().enumerate() {
            if !v.is_finite() || v.abs() > 3600.0 {
                return Err(invalid(
                    &format!("deskew.angular_degps[{i}]"),
                    v,
                    "finite, |v| <= 3600",
                ));
            }
        }
        if let DeskewMode::Poses(path) = &d.mode {
            if path.is_empty() {
                return Err(invalid("deskew.poses_file", "\"\"", "a file name"));
            }
        }
        self.filter.validate()?;
        positive("voxel.leaf_m", self.voxel_leaf_m)?;
        // The grid keys ±2^20 leaves around the origin: a leaf so small that this does not
        // reach the farthest point the filter keeps would drop every point beyond it.
        let reach = self.voxel_leaf_m * f64::from(1u32 << 20);
        if self.filter.max_range_m.is_finite() && reach < self.filter.max_range_m {
            return Err(invalid(
                "voxel.leaf_m",
                self.voxel_leaf_m,
                ">= filter.max_range_m / 2^20 (the grid reaches ±2^20 leaves around the origin)",
            ));
        }
        let g = &self.ground;
        positive("ground.distance_threshold_m", g.distance_threshold_m)?;
        if !(4..=4096).contains(&g.sectors) {
            return Err(invalid("ground.sectors", g.sectors, "4 ..= 4096"));
        }
        positive("ground.radial_bin_m", g.radial_bin_m)?;
        positive("ground.max_range_m", g.max_range_m)?;
        if g.max_range_m / g.radial_bin_m > 100_000.0 {
            return Err(invalid(
                "ground.radial_bin_m",
                g.radial_bin_m,
                ">= ground.max_range_m / 100000",
            ));
        }
        if !(g.max_slope_deg > 0.0 && g.max_slope_deg < 90.0) {
            return Err(invalid(
                "ground.max_slope_deg",
                g.max_slope_deg,
                "in (0, 90)",
            ));
        }
        if !(g.max_step_m.is_finite() && g.max_step_m >= 0.0) {
            return Err(invalid(
                "ground.max_step_m",
                g.max_step_m,
                "finite and >= 0",
            ));
        }
        if let Some(h) = g.sensor_height_m {
            if !h.is_finite() || h.abs() > 100.0 {
                return Err(invalid("ground.sensor_height_m", h, "finite, |h| <= 100"));
            }
        }
        if g.riser_column_deg != 0.0 && !(0.01..=10.0).contains(&g.riser_column_deg) {
            return Err(invalid(
                "ground.riser_column_deg",
                g.riser_column_deg,
                "0 (off) or in [0.01, 10]",
            ));
        }
        if !(g.riser_margin_m.is_finite() && (0.0..=1.0).contains(&g.riser_margin_m)) {
            return Err(invalid(
                "ground.riser_margin_m",
                g.riser_margin_m,
                "in [0, 1]",
            ));
        }
        if g.iterations == 0 || g.iterations > 1_000_000 {
            return Err(invalid("ground.iterations", g.iterations, "1 ..= 1000000"));
        }
        // What only the segmenter can tell (its grid's rings × sectors), refused here too:
        // before decoding starts, as a bad value, not at the first sensor.
        if let Err(super::PipelineError::InvalidParameter {
            name,
            value,
            expected,
        }) = super::ground::GroundSegmenter::new(g.method())
        {
            return Err(invalid(&format!("ground.{name}"), value, expected));
        }
        let c = &self.cluster;
        positive("cluster.tolerance_m", c.tolerance_m)?;
        if c.min_points == 0 {
            return Err(invalid("cluster.min_points", c.min_points, ">= 1"));
        }
        if c.max_points < c.min_points {
            return Err(invalid(
                "cluster.max_points",
                c.max_points,
                ">= cluster.min_points",
            ));
        }
        Ok(())
    }
}

#[cfg(feature = "config")]
mod toml_load {
    use super::*;
    use toml::{Table, Value};

    fn float(key: &str, v: &Value) -> Result<f64, ConfigError> {
        match v {
            Value::Float(f) => Ok(*f),
            Value::Integer(i) => Ok(*i as f64),
            _ => Err(ConfigError::Type {
                key: key.into(),
                expected: "a number",
            }),
        }
    }

    fn uint(key: &str, v: &Value, max: u64) -> Result<u64, ConfigError> {
        match v {
            Value::Integer(i) if *i >= 0 && (*i as u64) <= max => Ok(*i as u64),
            Value::Integer(i) => Err(invalid(key, i, "a non-negative integer in range")),
            _ => Err(ConfigError::Type {
                key: key.into(),
                expected: "an integer",
            }),
        }
    }

    fn string<'a>(key: &str, v: &'a Value) -> Result<&'a str, ConfigError> {
        v.as_str().ok_or_else(|| ConfigError::Type {
            key: key.into(),
            expected: "a string",
        })
    }

    fn vec3(key: &str, v: &Value) -> Result<[f64; 3], ConfigError> {
        let not = || ConfigError::Type {
            key: key.into(),
            expected: "an array of 3 numbers",
        };
        let a = v.as_array().ok_or_else(not)?;
        if a.len() != 3 {
            return Err(not());
        }
        let mut out = [0.0; 3];
        for (i, x) in a.iter().enumerate() {
            out[i] = float(&format!("{key}[{i}]"), x)?;
        }
        Ok(out)
    }

    fn section<'a>(root: &'a Table, name: &str) -> Result<Option<&'a Table>, ConfigError> {
        match root.get(name) {
            None => Ok(None),
            Some(Value::Table(t)) => Ok(Some(t)),
            Some(_) => Err(ConfigError::Type {
                key: name.into(),
                expected: "a table",
            }),
        }
    }

    /// Both keys or neither.
    fn pair<T>(
        a: Option<T>,
        b: Option<T>,
        key_a: &str,
        key_b: &str,
    ) -> Result<Option<[T; 2]>, ConfigError> {
        match (a, b) {
            (Some(a), Some(b)) => Ok(Some([a, b])),
            (None, None) => Ok(None),
            (Some(_), None) => Err(invalid(key_b, "(missing)", "given together with its pair")),
            (None, Some(_)) => Err(invalid(key_a, "(missing)", "given together with its pair")),
        }
    }

    impl PipelineConfig {
        /// The default pipeline with the values of a TOML text applied over it, validated.
        pub fn from_toml(text: &str) -> Result<Self, ConfigError> {
            let root: Table = text
                .parse()
                .map_err(|e: toml::de::Error| ConfigError::Syntax(e.to_string()))?;
            let mut cfg = Self::default();
            for name in root.keys() {
                if !["deskew", "filter", "voxel", "ground", "cluster"].contains(&name.as_str()) {
                    return Err(ConfigError::UnknownKey { key: name.clone() });
                }
            }
            if let Some(t) = section(&root, "deskew")? {
                let mut poses_file = None;
                let mut mode = None;
                for (k, v) in t {
                    let key = format!("deskew.{k}");
                    match k.as_str() {
                        "mode" => mode = Some(string(&key, v)?.to_string()),
                        "reference" => {
                            cfg.deskew.reference = match string(&key, v)? {
                                "start" => Reference::Start,
                                "end" => Reference::End,
                                s => return Err(invalid(&key, s, "\"start\" or \"end\"")),
                            }
                        }
                        "linear_mps" => cfg.deskew.linear_mps = vec3(&key, v)?,
                        "angular_degps" => cfg.deskew.angular_degps = vec3(&key, v)?,
                        "poses_file" => poses_file = Some(string(&key, v)?.to_string()),
                        _ => return Err(ConfigError::UnknownKey { key }),
                    }
                }
                if let Some(m) = mode {
                    cfg.deskew.mode = match m.as_str() {
                        "none" => DeskewMode::None,
                        "constant-velocity" => DeskewMode::ConstantVelocity,
                        "imu" => DeskewMode::Imu,
                        "odometry" => DeskewMode::Odometry,
                        "poses" => DeskewMode::Poses(poses_file.clone().ok_or_else(|| {
                            invalid(
                                "deskew.poses_file",
                                "(missing)",
                                "a file with mode = \"poses\"",
                            )
                        })?),
                        _ => {
                            return Err(invalid(
                                "deskew.mode",
                                m,
                                "none, constant-velocity, imu, odometry or poses",
                            ))
                        }
                    };
                }
                if poses_file.is_some() && !matches!(cfg.deskew.mode, DeskewMode::Poses(_)) {
                    return Err(invalid(
                        "deskew.poses_file",
                        poses_file.unwrap_or_default(),
                        "only with mode = \"poses\"",
                    ));
                }
            }
            if let Some(t) = section(&root, "filter")? {
                let f = &mut cfg.filter;
                let (mut az, mut el, mut cb) = ([None, None], [None, None], [None, None]);
                for (k, v) in t {
                    let key = format!("filter.{k}");
                    match k.as_str() {
                        "min_range_m" => f.min_range_m = float(&key, v)?,
                        "max_range_m" => f.max_range_m = float(&key, v)?,
                        "azimuth_min_deg" => az[0] = Some(float(&key, v)?),
                        "azimuth_max_deg" => az[1] = Some(float(&key, v)?),
                        "elevation_min_deg" => el[0] = Some(float(&key, v)?),
                        "elevation_max_deg" => el[1] = Some(float(&key, v)?),
                        "crop_box_min_m" => cb[0] = Some(vec3(&key, v)?),
                        "crop_box_max_m" => cb[1] = Some(vec3(&key, v)?),
                        _ => return Err(ConfigError::UnknownKey { key }),
                    }
                }
                f.azimuth_deg = pair(
                    az[0],
                    az[1],
                    "filter.azimuth_min_deg",
                    "filter.azimuth_max_deg",
                )?;
                f.elevation_deg = pair(
                    el[0],
                    el[1],
                    "filter.elevation_min_deg",
                    "filter.elevation_max_deg",
                )?;
                f.crop_box = pair(
                    cb[0],
                    cb[1],
                    "filter.crop_box_min_m",
                    "filter.crop_box_max_m",
                )?
                .map(|[min_m, max_m]| CropBox { min_m, max_m });
            }
            if let Some(t) = section(&root, "voxel")? {
                for (k, v) in t {
                    let key = format!("voxel.{k}");
                    match k.as_str() {
                        "leaf_m" => cfg.voxel_leaf_m = float(&key, v)?,
                        _ => return Err(ConfigError::UnknownKey { key }),
                    }
                }
            }
            if let Some(t) = section(&root, "ground")? {
                let g = &mut cfg.ground;
                for (k, v) in t {
                    let key = format!("ground.{k}");
                    match k.as_str() {
                        "method" => {
                            g.method = match string(&key, v)? {
                                "grid" => GroundMethodName::Grid,
                                "ransac" => GroundMethodName::Ransac,
                                s => return Err(invalid(&key, s, "\"grid\" or \"ransac\"")),
                            }
                        }
                        "distance_threshold_m" => g.distance_threshold_m = float(&key, v)?,
                        "sectors" => g.sectors = uint(&key, v, u64::from(u32::MAX))? as u32,
                        "radial_bin_m" => g.radial_bin_m = float(&key, v)?,
                        "max_range_m" => g.max_range_m = float(&key, v)?,
                        "max_slope_deg" => g.max_slope_deg = float(&key, v)?,
                        "max_step_m" => g.max_step_m = float(&key, v)?,
                        "sensor_height_m" => g.sensor_height_m = Some(float(&key, v)?),
                        "riser_column_deg" => g.riser_column_deg = float(&key, v)?,
                        "riser_margin_m" => g.riser_margin_m = float(&key, v)?,
                        "iterations" => g.iterations = uint(&key, v, u64::from(u32::MAX))? as u32,
                        "seed" => g.seed = uint(&key, v, i64::MAX as u64)?,
                        _ => return Err(ConfigError::UnknownKey { key }),
                    }
                }
            }
            if let Some(t) = section(&root, "cluster")? {
                let c = &mut cfg.cluster;
                for (k, v) in t {
                    let key = format!("cluster.{k}");
                    match k.as_str() {
                        "tolerance_m" => c.tolerance_m = float(&key, v)?,
                        "min_points" => c.min_points = uint(&key, v, u32::MAX.into())? as usize,
                        "max_points" => c.max_points = uint(&key, v, u32::MAX.into())? as usize,
                        _ => return Err(ConfigError::UnknownKey { key }),
                    }
                }
            }
            cfg.validate()?;
            Ok(cfg)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_pipeline_is_valid() {
        PipelineConfig::default().validate().unwrap();
    }

    #[cfg(feature = "config")]
    #[test]
    fn a_full_file_loads_every_key() {
        let text = r#"
[deskew]
mode = "poses"
poses_file = "drive.tum"
reference = "end"
linear_mps = [15, 0, 0]
angular_degps = [0.0, 0.0, 60.0]
[filter]
min_range_m = 1
max_range_m = 80.5
azimuth_min_deg = -90
azimuth_max_deg = 90
elevation_min_deg = -30
elevation_max_deg = 10
crop_box_min_m = [-1, -1, -0.5]
crop_box_max_m = [3.5, 1, 2]
[voxel]
leaf_m = 0.1
[ground]
method = "ransac"
distance_threshold_m = 0.2
sectors = 32
radial_bin_m = 2.0
max_range_m = 50
max_slope_deg = 10
max_step_m = 0.3
sensor_height_m = 1.9
riser_column_deg = 0.5
riser_margin_m = 0.02
iterations = 200
seed = 7
[cluster]
tolerance_m = 0.7
min_points = 3
max_points = 5000
"#;
        let c = PipelineConfig::from_toml(text).unwrap();
        assert_eq!(c.deskew.mode, DeskewMode::Poses("drive.tum".into()));
        assert_eq!(c.deskew.reference, Reference::End);
        assert_eq!(c.deskew.linear_mps, [15.0, 0.0, 0.0]);
        assert_eq!(c.deskew.angular_degps, [0.0, 0.0, 60.0]);
        assert_eq!((c.filter.min_range_m, c.filter.max_range_m), (1.0, 80.5));
        assert_eq!(c.filter.azimuth_deg, Some([-90.0, 90.0]));
        assert_eq!(c.filter.elevation_deg, Some([-30.0, 10.0]));
        assert_eq!(
            c.filter.crop_box,
            Some(CropBox {
                min_m: [-1.0, -1.0, -0.5],
                max_m: [3.5, 1.0, 2.0]
            })
        );
        assert_eq!(c.voxel_leaf_m, 0.1);
        let g = c.ground;
        assert_eq!(g.method, GroundMethodName::Ransac);
        assert_eq!(
            (
                g.distance_threshold_m,
                g.sectors,
                g.radial_bin_m,
                g.max_range_m
            ),
            (0.2, 32, 2.0, 50.0)
        );
        assert_eq!(
            (
                g.max_slope_deg,
                g.max_step_m,
                g.sensor_height_m,
                g.iterations,
                g.seed
            ),
            (10.0, 0.3, Some(1.9), 200, 7)
        );
        assert_eq!((g.riser_column_deg, g.riser_margin_m), (0.5, 0.02));
        assert_eq!(
            (
                c.cluster.tolerance_m,
                c.cluster.min_points,
                c.cluster.max_points
            ),
            (0.7, 3, 5000)
        );
        // An empty file is the default pipeline.
        assert_eq!(
            PipelineConfig::from_toml("").unwrap(),
            PipelineConfig::default()
        );
    }

    /// Every key: a wrong value is rejected and the error names that key.
    #[cfg(feature = "config")]
    #[test]
    fn every_bad_value_is_rejected_with_its_key() {
        let cases: &[(&str, &str)] = &[
            ("[voxel]\nleaf_m = 0", "voxel.leaf_m"),
            ("[voxel]\nleaf_m = -0.1", "voxel.leaf_m"),
            ("[voxel]\nleaf_m = \"big\"", "voxel.leaf_m"),
            ("[voxel]\nleaf = 0.2", "voxel.leaf"),
            ("[voxels]\nleaf_m = 0.2", "voxels"),
            ("voxel = 3", "voxel"),
            ("[deskew]\nmode = \"gps\"", "deskew.mode"),
            ("[deskew]\nmode = \"poses\"", "deskew.poses_file"),
            ("[deskew]\nposes_file = \"a.tum\"", "deskew.poses_file"),
            ("[deskew]\nreference = \"middle\"", "deskew.reference"),
            ("[deskew]\nlinear_mps = [1, 2]", "deskew.linear_mps"),
            ("[deskew]\nlinear_mps = [1, 2, 1e9]", "deskew.linear_mps[2]"),
            (
                "[deskew]\nangular_degps = [0, nan, 0]",
                "deskew.angular_degps[1]",
            ),
            ("[deskew]\nspeed = 3", "deskew.speed"),
            ("[filter]\nmin_range_m = -1", "filter.min_range_m"),
            ("[filter]\nmax_range_m = 0.1", "filter.max_range_m"),
            (
                "[filter]\nazimuth_min_deg = -400\nazimuth_max_deg = 0",
                "filter.azimuth_min_deg",
            ),
            (
                "[filter]\nazimuth_min_deg = 0\nazimuth_max_deg = 400",
                "filter.azimuth_max_deg",
            ),
            ("[filter]\nazimuth_min_deg = 0", "filter.azimuth_max_deg"),
            (
                "[filter]\nelevation_max_deg = 0",
                "filter.elevation_min_deg",
            ),
            (
                "[filter]\nelevation_min_deg = -95\nelevation_max_deg = 0",
                "filter.elevation_min_deg",
            ),
            (
                "[filter]\nelevation_min_deg = 5\nelevation_max_deg = 0",
                "filter.elevation_max_deg",
            ),
            (
                "[filter]\ncrop_box_min_m = [0, 0, 0]",
                "filter.crop_box_max_m",
            ),
            (
                "[filter]\ncrop_box_min_m = [0, 0, 0]\ncrop_box_max_m = [1, 1, 0]",
                "filter.crop_box_max_m[2]",
            ),
            (
                "[filter]\ncrop_box_min_m = [0, \"a\", 0]",
                "filter.crop_box_min_m[1]",
            ),
            ("[filter]\nrange_m = 3", "filter.range_m"),
            ("[ground]\nmethod = \"patchwork\"", "ground.method"),
            (
                "[ground]\ndistance_threshold_m = 0",
                "ground.distance_threshold_m",
            ),
            ("[ground]\nsectors = 2", "ground.sectors"),
            ("[ground]\nsectors = -5", "ground.sectors"),
            ("[ground]\nsectors = 1.5", "ground.sectors"),
            ("[ground]\nradial_bin_m = 0", "ground.radial_bin_m"),
            ("[ground]\nradial_bin_m = 0.00001", "ground.radial_bin_m"),
            (
                "[ground]\nsectors = 4096\nradial_bin_m = 0.001",
                "ground.radial_bin_m",
            ),
            ("[ground]\nmax_range_m = inf", "ground.max_range_m"),
            ("[ground]\nmax_slope_deg = 90", "ground.max_slope_deg"),
            ("[ground]\nmax_step_m = -0.1", "ground.max_step_m"),
            ("[ground]\nsensor_height_m = inf", "ground.sensor_height_m"),
            (
                "[ground]\nriser_column_deg = 0.001",
                "ground.riser_column_deg",
            ),
            ("[ground]\nriser_column_deg = -1", "ground.riser_column_deg"),
            ("[ground]\nriser_margin_m = nan", "ground.riser_margin_m"),
            ("[ground]\niterations = 0", "ground.iterations"),
            ("[ground]\nseed = -1", "ground.seed"),
            ("[ground]\nplane = 1", "ground.plane"),
            ("[cluster]\ntolerance_m = 0", "cluster.tolerance_m"),
            ("[cluster]\nmin_points = 0", "cluster.min_points"),
            (
                "[cluster]\nmin_points = 10\nmax_points = 5",
                "cluster.max_points",
            ),
            ("[cluster]\nradius_m = 1", "cluster.radius_m"),
        ];
        for (text, key) in cases {
            let e = PipelineConfig::from_toml(text).unwrap_err();
            let named = match &e {
                ConfigError::UnknownKey { key } => key.clone(),
                ConfigError::Type { key, .. } => key.clone(),
                ConfigError::Invalid { key, .. } => key.clone(),
                ConfigError::Syntax(s) => s.clone(),
            };
            assert_eq!(&named, key, "{text:?}: {e}");
            assert!(e.to_string().contains(key), "{e}");
        }
        assert!(matches!(
            PipelineConfig::from_toml("[voxel\nleaf_m = 1"),
            Err(ConfigError::Syntax(_))
        ));
    }
}
