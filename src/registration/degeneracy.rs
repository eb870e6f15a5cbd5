//! Degeneracy of a registration: which motions of the sensor the scene does not constrain.
//!
//! After a sweep is registered, the local planes of the map under the sweep's points give the
//! point-to-plane information matrix in the sensor frame,
//! `H = Σ J Jᵀ`, `J = (n, p × n)` (p a sweep point, n the unit normal of the map's plane at
//! its correspondence, both in the sensor frame; twist order tx, ty, tz, rx, ry, rz). A
//! point-to-point information matrix would not do: every pair constrains all three
//! translations, whatever the geometry.
//!
//! Translations (m) and rotations (rad) are put on one scale with a length `L`
//! ([`DegeneracyConfig::rotation_scale_m`], 1 m by default: a rotation δ is weighed as a
//! translation of L·δ), and `H` is divided by the sample count: `Ĥ = S·H·S / N`,
//! `S = diag(1, 1, 1, L⁻¹, L⁻¹, L⁻¹)`. With unit normals the translation block of `Ĥ` has
//! trace 1: an eigenvalue is the share of the constraint the scene puts on that direction.
//! A rotation's eigenvalue grows with the square of the ranges that constrain it, so with
//! L = 1 m a rotation is named degenerate only when the scene holds it far less than it
//! holds a translation (a few far points constrain a yaw); an L near the samples' RMS range
//! weighs a rotation by the displacement it causes there. Eigenvalues below
//! `min_eigenvalue` are **degenerate**; the degenerate subspace is then named along the
//! sensor axes: axis k (x, y, z, roll, pitch, yaw) is degenerate when at least half of its
//! unit twist lies in that subspace (‖P·e_k‖² ≥ ½, P the projector). A long corridor along x
//! gives `x`; an empty flat floor `x`, `y` and `yaw`.
//!
//! Only map voxels with at least `min_voxel_points` points and a planar spread (smallest
//! variance ≤ `max_flatness` × the middle one, middle one ≥ `min_spread_m²`) give a normal:
//! a voxel crossed by one scan line is a line, not a plane. For such a voxel the points of
//! the 27 voxels around it are fitted instead (the next scan lines are there), under the
//! same tests.
//!
//! No I/O, no clock.

use nalgebra::{Isometry3, Matrix6, SymmetricEigen, Vector3, Vector6};

use crate::registration::icp::RegistrationConfigError;
use crate::registration::map::VoxelMap;
use crate::registration::map::VoxelPlane;

/// Parameters of the degeneracy analysis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DegeneracyConfig {
    /// Normalised eigenvalues below this are degenerate (0..1).
    pub min_eigenvalue: f64,
    /// Sweep points sampled at most (evenly spaced through the sweep).
    pub max_samples: usize,
    /// A sample pairs with the map only within this distance, m.
    pub max_correspondence_m: f64,
    /// Map voxels with fewer points give no normal.
    pub min_voxel_points: usize,
    /// Planarity: smallest variance ≤ this × the middle one.
    pub max_flatness: f64,
    /// Spread: the middle standard deviation of the voxel's points is at least this, m.
    pub min_spread_m: f64,
    /// The length `L` that weighs rotations against translations, m.
    pub rotation_scale_m: f64,
}

impl Default for DegeneracyConfig {
    fn default() -> Self {
        Self {
            min_eigenvalue: 0.01,
            max_samples: 1000,
            max_correspondence_m: 1.0,
            min_voxel_points: 5,
            max_flatness: 0.1,
            min_spread_m: 0.05,
            rotation_scale_m: 1.0,
        }
    }
}

impl DegeneracyConfig {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), RegistrationConfigError> {
        RegistrationConfigError::positive("min_eigenvalue", self.min_eigenvalue)?;
        RegistrationConfigError::positive("max_correspondence_m", self.max_correspondence_m)?;
        RegistrationConfigError::positive("max_flatness", self.max_flatness)?;
        RegistrationConfigError::non_negative("min_spread_m", self.min_spread_m)?;
        RegistrationConfigError::positive("rotation_scale_m", self.rotation_scale_m)?;
        if self.max_samples < 6 {
            return Err(RegistrationConfigError::Invalid {
                name: "max_samples",
                value: self.max_samples as f64,
                expected: ">= 6",
            });
        }
        Ok(())
    }
}

/// The six motions of the sensor frame, named.
pub const AXIS_NAMES: [&str; 6] = ["x", "y", "z", "roll", "pitch", "yaw"];

/// The degeneracy of one registered sweep.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Degeneracy {
    /// The point-to-plane information matrix `H` (sensor frame, twist tx ty tz rx ry rz; m, rad).
    pub information: Matrix6<f64>,
    /// Eigenvalues of the normalised matrix `Ĥ`, ascending.
    pub eigenvalues: [f64; 6],
    /// The matching unit eigenvectors (columns), rotation rows scaled by `L` (see the module
    /// documentation).
    pub eigenvectors: Matrix6<f64>,
    /// Largest over smallest eigenvalue of `Ĥ` (infinite when the smallest is 0).
    pub condition_number: f64,
    /// The length `L` used to scale rotations, m.
    pub scale_m: f64,
    /// Samples that found a planar correspondence.
    pub samples: usize,
    /// Per sensor axis (x, y, z, roll, pitch, yaw): the share of its unit twist lying in the
    /// degenerate subspace (0..1).
    pub axis_share: [f64; 6],
}

impl Degeneracy {
    /// Whether any direction is degenerate.
    pub fn is_degenerate(&self, cfg: &DegeneracyConfig) -> bool {
        self.eigenvalues[0] < cfg.min_eigenvalue
    }

    /// The sensor axes named degenerate (share ≥ ½), in the order x, y, z, roll, pitch, yaw.
    pub fn degenerate_axes(&self) -> impl Iterator<Item = &'static str> + '_ {
        AXIS_NAMES
            .iter()
            .zip(self.axis_share)
            .filter(|(_, s)| *s >= 0.5)
            .map(|(n, _)| *n)
    }

    /// The degenerate axes as one string, e.g. `"x,y,yaw"` (empty when none).
    pub fn degenerate_names(&self) -> String {
        self.degenerate_axes().collect::<Vec<_>>().join(",")
    }
}

/// Analyses a registered sweep: `sensor_points` (sensor frame) at `world_from_sensor` in
/// `map`. `None` when fewer than 6 samples find a planar correspondence (nothing to say).
pub fn analyse(
    cfg: &DegeneracyConfig,
    map: &VoxelMap,
    sensor_points: &[Vector3<f64>],
    world_from_sensor: &Isometry3<f64>,
) -> Option<Degeneracy> {
    if sensor_points.is_empty() {
        return None;
    }
    let rot = world_from_sensor.rotation.to_rotation_matrix().into_inner();
    let rot_t = rot.transpose();
    let tr = world_from_sensor.translation.vector;
    let stride = sensor_points.len().div_ceil(cfg.max_samples).max(1);
    let gate_sq = cfg.max_correspondence_m * cfg.max_correspondence_m;
    let min_spread_sq = cfg.min_spread_m * cfg.min_spread_m;
    let mut h = Matrix6::zeros();
    let mut n = 0usize;
    for p in sensor_points.iter().step_by(stride) {
        let q = rot * p + tr;
        let Some((_, d2, slot)) = map.nearest_in_slot(&q) else {
            continue;
        };
        if d2 >= gate_sq {
            continue;
        }
        let usable = |p: &VoxelPlane| {
            let [l0, l1, _] = p.eigenvalues;
            p.points >= cfg.min_voxel_points && l1 >= min_spread_sq && l0 <= cfg.max_flatness * l1
        };
        // The voxel's own plane, else the plane of the 27 voxels around it (a voxel crossed
        // by a single scan line is a line; its neighbours hold the next lines).
        let plane = match map.slot_plane(slot).filter(usable) {
            Some(p) => p,
            None => match map.neighbourhood_plane(&q).filter(usable) {
                Some(p) => p,
                None => continue,
            },
        };
        let ns = rot_t * plane.normal;
        let pn = p.cross(&ns);
        let j = Vector6::new(ns.x, ns.y, ns.z, pn.x, pn.y, pn.z);
        h += j * j.transpose();
        n += 1;
    }
    if n < 6 {
        return None;
    }
    let scale_m = cfg.rotation_scale_m;
    let mut s = Matrix6::identity();
    for k in 3..6 {
        s[(k, k)] = 1.0 / scale_m;
    }
    let hn = s * h * s / n as f64;
    let eig = SymmetricEigen::new(hn);
    let mut order = [0usize, 1, 2, 3, 4, 5];
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    let mut eigenvalues = [0.0; 6];
    let mut eigenvectors = Matrix6::zeros();
    for (i, &k) in order.iter().enumerate() {
        eigenvalues[i] = eig.eigenvalues[k].max(0.0);
        eigenvectors.set_column(i, &eig.eigenvectors.column(k));
    }
    let mut projector = Matrix6::zeros();
    for (i, &ev) in eigenvalues.iter().enumerate() {
        if ev < cfg.min_eigenvalue {
            let v = eigenvectors.column(i);
            projector += v * v.transpose();
        }
    }
    let mut axis_share = [0.0; 6];
    for (k, share) in axis_share.iter_mut().enumerate() {
        // ‖P·e_k‖² = P_kk for a projector.
        *share = projector[(k, k)];
    }
    let condition_number = if eigenvalues[0] > 0.0 {
        eigenvalues[5] / eigenvalues[0]
    } else {
        f64::INFINITY
    };
    Some(Degeneracy {
        information: h,
        eigenvalues,
        eigenvectors,
        condition_number,
        scale_m,
        samples: n,
        axis_share,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::registration::map::VoxelMapConfig;
    use nalgebra::{Translation3, UnitQuaternion};

    fn map_of(points: &[Vector3<f64>]) -> VoxelMap {
        let mut m = VoxelMap::new(VoxelMapConfig {
            voxel_size_m: 1.0,
            max_points_per_voxel: 20,
            max_distance_m: 200.0,
            ..VoxelMapConfig::default()
        })
        .unwrap();
        m.add_points(points.iter().copied());
        m
    }

    fn grid(
        a0: f64,
        a1: f64,
        b0: f64,
        b1: f64,
        step: f64,
        f: impl Fn(f64, f64) -> Vector3<f64>,
    ) -> Vec<Vector3<f64>> {
        let mut out = Vec::new();
        let (na, nb) = (((a1 - a0) / step) as i32, ((b1 - b0) / step) as i32);
        for i in 0..=na {
            for j in 0..=nb {
                out.push(f(a0 + f64::from(i) * step, b0 + f64::from(j) * step));
            }
        }
        out
    }

    fn analyse_world(world: &[Vector3<f64>], pose: &Isometry3<f64>) -> Degeneracy {
        let map = map_of(world);
        let inv = pose.inverse();
        let sensor: Vec<_> = world
            .iter()
            .map(|p| (inv * nalgebra::Point3::from(*p)).coords)
            .collect();
        analyse(&DegeneracyConfig::default(), &map, &sensor, pose).unwrap()
    }

    #[test]
    fn flat_floor_leaves_x_y_and_yaw_free() {
        let floor = grid(-30.0, 30.0, -30.0, 30.0, 0.25, |x, y| {
            Vector3::new(x, y, 0.0)
        });
        let pose = Isometry3::from_parts(
            Translation3::new(2.0, -1.0, 1.8),
            UnitQuaternion::identity(),
        );
        let d = analyse_world(&floor, &pose);
        assert!(d.is_degenerate(&DegeneracyConfig::default()));
        assert_eq!(d.degenerate_names(), "x,y,yaw");
    }

    #[test]
    fn a_floor_seen_as_scan_lines_is_still_named() {
        // A VLP-16's floor rings from 1.8 m: circles of radius 1.8 / tan(15°, 13°, 11°, 9°, 7°),
        // 0.2° apart: a 1 m voxel holds one arc (a line); its neighbourhood holds the next.
        let mut floor = Vec::new();
        for deg in [15.0f64, 13.0, 11.0, 9.0, 7.0] {
            let r = 1.8 / deg.to_radians().tan();
            for k in 0..1800 {
                let a = f64::from(k) * 0.2f64.to_radians();
                floor.push(Vector3::new(r * a.cos(), r * a.sin(), 0.0));
            }
        }
        let pose =
            Isometry3::from_parts(Translation3::new(0.0, 0.0, 1.8), UnitQuaternion::identity());
        let d = analyse_world(&floor, &pose);
        assert_eq!(d.degenerate_names(), "x,y,yaw");
        // The voxels alone are lines: without the neighbourhood there would be no sample.
        let map = map_of(&floor);
        let (_, _, slot) = map.nearest_in_slot(&floor[0]).unwrap();
        let own = map.slot_plane(slot).unwrap();
        assert!(own.eigenvalues[1] < 0.05 * 0.05, "{:?}", own.eigenvalues);
    }

    #[test]
    fn corridor_leaves_its_axis_free_in_the_sensor_frame() {
        // A corridor along world x, 3 m wide, 2.5 m high, 80 m long (no end walls in range).
        let mut world = grid(-40.0, 40.0, -1.5, 1.5, 0.2, |x, y| Vector3::new(x, y, 0.0));
        world.extend(grid(-40.0, 40.0, -1.5, 1.5, 0.2, |x, y| {
            Vector3::new(x, y, 2.5)
        }));
        world.extend(grid(-40.0, 40.0, 0.0, 2.5, 0.2, |x, z| {
            Vector3::new(x, -1.5, z)
        }));
        world.extend(grid(-40.0, 40.0, 0.0, 2.5, 0.2, |x, z| {
            Vector3::new(x, 1.5, z)
        }));
        // Sensor aligned with the corridor: the free axis is x.
        let aligned =
            Isometry3::from_parts(Translation3::new(0.0, 0.3, 1.2), UnitQuaternion::identity());
        let d = analyse_world(&world, &aligned);
        assert_eq!(d.degenerate_names(), "x");
        // Sensor yawed by 90°: the corridor runs along the sensor's y.
        let yawed = Isometry3::from_parts(
            Translation3::new(0.0, 0.3, 1.2),
            UnitQuaternion::from_scaled_axis(Vector3::z() * std::f64::consts::FRAC_PI_2),
        );
        let d = analyse_world(&world, &yawed);
        assert_eq!(d.degenerate_names(), "y");
    }

    #[test]
    fn a_box_room_is_not_degenerate() {
        let mut world = grid(-10.0, 10.0, -8.0, 8.0, 0.25, |x, y| Vector3::new(x, y, 0.0));
        world.extend(grid(-8.0, 8.0, 0.0, 3.0, 0.25, |y, z| {
            Vector3::new(10.0, y, z)
        }));
        world.extend(grid(-8.0, 8.0, 0.0, 3.0, 0.25, |y, z| {
            Vector3::new(-10.0, y, z)
        }));
        world.extend(grid(-10.0, 10.0, 0.0, 3.0, 0.25, |x, z| {
            Vector3::new(x, 8.0, z)
        }));
        world.extend(grid(-10.0, 10.0, 0.0, 3.0, 0.25, |x, z| {
            Vector3::new(x, -8.0, z)
        }));
        let pose =
            Isometry3::from_parts(Translation3::new(1.0, 2.0, 1.5), UnitQuaternion::identity());
        let d = analyse_world(&world, &pose);
        assert!(
            !d.is_degenerate(&DegeneracyConfig::default()),
            "{:?}",
            d.eigenvalues
        );
        assert_eq!(d.degenerate_names(), "");
        assert!(d.condition_number.is_finite());
    }
}
