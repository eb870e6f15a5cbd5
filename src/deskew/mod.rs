//! Deskew: every point of a sweep moved to the sensor pose at one reference time.
//!
//! A spinning sensor measures each point from where it was at that point's firing time `t`
//! (ns after the sweep's timestamp). When the sensor moves, a sweep drawn in one frame smears:
//! at 15 m/s a 100 ms sweep ends 1.5 m from where it began. Deskewing maps each point
//! `p` seen at `t` into the frame of the reference time `r` (the sweep's timestamp or its end):
//! `p_r = ref_from_sensor(t) · p`, with `ref_from_sensor(t) = start_from_sensor(r)⁻¹ ·
//! start_from_sensor(t)`.
//!
//! The motion `start_from_sensor(t)` comes from one of three sources:
//! - a constant body-frame [`Twist`] (given, or from the last relative motion odometry
//!   estimated: [`Twist::from_relative_motion`]): `exp(ξ·t)`, exact for a constant twist;
//! - the gyro ([`ImuTrack`]): rotation integrated from the angular velocity, translation from a
//!   constant linear velocity;
//! - a [`PoseTable`] of `world_from_sensor` poses, interpolated on SE(3).
//!
//! The motion is evaluated at [`TABLE_STEPS`] + 1 times spread over the sweep; each point then
//! takes the pose linearly interpolated between its two neighbours (the rotation changes by
//! ≤ 0.03° between steps at 60 °/s over 100 ms, so the interpolation error is below 1 µm at
//! 100 m). Points are moved in place; the table is allocated once, at construction: nothing is
//! allocated per sweep. No I/O, no clock.

pub mod imu;
pub mod poses;
pub mod se3;

use nalgebra::{Isometry3, Vector3};

use crate::point::Point;

pub use imu::ImuTrack;
pub use poses::{PoseTable, PosesError};

/// Number of intervals of the per-sweep motion table.
pub const TABLE_STEPS: usize = 256;

/// Which sensor pose the deskewed points are expressed in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Reference {
    /// The pose at the sweep's timestamp (its first firing, `t` = 0).
    #[default]
    Start,
    /// The pose at the sweep's last point.
    End,
}

/// A rigid-body velocity in the sensor (body) frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Twist {
    /// Linear velocity, m/s (x forward, y left, z up).
    pub linear_mps: Vector3<f64>,
    /// Angular velocity, rad/s, about the sensor's axes.
    pub angular_radps: Vector3<f64>,
}

impl Twist {
    /// No motion.
    pub fn zero() -> Self {
        Self::default()
    }

    /// The constant twist that moves the sensor by `prev_from_curr` (the pose of the current
    /// sweep in the previous sweep's frame, as odometry estimates it) in `dt_s` seconds.
    /// `None` when `dt_s` is not a positive finite number.
    pub fn from_relative_motion(prev_from_curr: &Isometry3<f64>, dt_s: f64) -> Option<Self> {
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return None;
        }
        let (rho, phi) = se3::log(prev_from_curr);
        Some(Self {
            linear_mps: rho / dt_s,
            angular_radps: phi / dt_s,
        })
    }

    /// `start_from_sensor` after `dt_s` seconds at this twist.
    pub fn integrate(&self, dt_s: f64) -> Isometry3<f64> {
        se3::exp(&(self.linear_mps * dt_s), &(self.angular_radps * dt_s))
    }
}

/// Why a sweep could not be deskewed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DeskewError {
    /// No gyro sample near this time.
    #[error("no IMU sample within 50 ms of {t_ns} ns (sensor clock); {samples} samples kept")]
    NoImu {
        /// The time (sensor clock), ns.
        t_ns: i64,
        /// Samples in the track.
        samples: usize,
    },
    /// The poses do not cover the sweep.
    #[error("poses: {0}")]
    Poses(#[from] PosesError),
}

/// A 3×4 affine transform in f32, row-major: `[r00 r01 r02 tx r10 … tz]`.
type Affine = [f32; 12];

fn affine_of(pose: &Isometry3<f64>) -> Affine {
    let m = pose.to_homogeneous();
    let mut a = [0f32; 12];
    for r in 0..3 {
        for c in 0..4 {
            a[r * 4 + c] = m[(r, c)] as f32;
        }
    }
    a
}

/// Deskews sweeps in place. Holds the motion table (see the module documentation).
#[derive(Clone, Debug)]
pub struct Deskewer {
    reference: Reference,
    /// `start_from_sensor` at step k (f64, before the reference is applied).
    poses: Vec<Isometry3<f64>>,
    /// `ref_from_sensor` at step k.
    table: Vec<Affine>,
}

impl Deskewer {
    /// A deskewer expressing points in the `reference` pose.
    pub fn new(reference: Reference) -> Self {
        Self {
            reference,
            poses: vec![Isometry3::identity(); TABLE_STEPS + 1],
            table: vec![[0.0; 12]; TABLE_STEPS + 1],
        }
    }

    /// The reference pose.
    pub fn reference(&self) -> Reference {
        self.reference
    }

    /// Constant velocity: `start_from_sensor(t) = exp(ξ·t)`.
    pub fn deskew_constant_velocity(&mut self, points: &mut [Point], twist: &Twist) {
        let span_ns = span_ns(points);
        if span_ns == 0 {
            return;
        }
        let dt_s = span_ns as f64 * 1e-9 / TABLE_STEPS as f64;
        for (k, pose) in self.poses.iter_mut().enumerate() {
            *pose = twist.integrate(k as f64 * dt_s);
        }
        self.apply(points, span_ns);
    }

    /// IMU: rotation integrated from the gyro over the sweep, translation at `linear_mps`
    /// (body frame). `sweep_start_ns` is the sweep's first firing in the IMU's clock
    /// ([`crate::sweep::Sweep::device_time_ns`] for Ouster).
    pub fn deskew_imu(
        &mut self,
        points: &mut [Point],
        sweep_start_ns: i64,
        imu: &ImuTrack,
        linear_mps: &Vector3<f64>,
    ) -> Result<(), DeskewError> {
        let span_ns = span_ns(points);
        if span_ns == 0 {
            return Ok(());
        }
        let dt_ns = span_ns as f64 / TABLE_STEPS as f64;
        let dt_s = dt_ns * 1e-9;
        self.poses[0] = Isometry3::identity();
        for k in 0..TABLE_STEPS {
            // Midpoint rule: the step's rotation uses ω at its middle (exact for constant ω).
            let t_mid = sweep_start_ns.saturating_add(((k as f64 + 0.5) * dt_ns) as i64);
            let w = imu.angular_velocity_at(t_mid).ok_or(DeskewError::NoImu {
                t_ns: t_mid,
                samples: imu.len(),
            })?;
            let step = se3::exp(&(linear_mps * dt_s), &(w * dt_s));
            self.poses[k + 1] = self.poses[k] * step;
        }
        self.apply(points, span_ns);
        Ok(())
    }

    /// Poses: `start_from_sensor(t) = world_from_sensor(t0)⁻¹ · world_from_sensor(t0 + t)`,
    /// `t0` = `sweep_start_ns` in the table's clock.
    pub fn deskew_poses(
        &mut self,
        points: &mut [Point],
        sweep_start_ns: i64,
        table: &PoseTable,
    ) -> Result<(), DeskewError> {
        let span_ns = span_ns(points);
        if span_ns == 0 {
            return Ok(());
        }
        let start_inv = table.world_from_sensor(sweep_start_ns)?.inverse();
        let dt_ns = span_ns as f64 / TABLE_STEPS as f64;
        for (k, pose) in self.poses.iter_mut().enumerate() {
            let t = sweep_start_ns.saturating_add((k as f64 * dt_ns).round() as i64);
            *pose = start_inv * table.world_from_sensor(t)?;
        }
        self.apply(points, span_ns);
        Ok(())
    }

    /// Builds `ref_from_sensor` per step from `self.poses` and moves the points.
    fn apply(&mut self, points: &mut [Point], span_ns: u32) {
        let reference_inv = match self.reference {
            Reference::Start => self.poses[0].inverse(),
            Reference::End => self.poses[TABLE_STEPS].inverse(),
        };
        for (a, pose) in self.table.iter_mut().zip(&self.poses) {
            *a = affine_of(&(reference_inv * pose));
        }
        let steps_per_ns = TABLE_STEPS as f32 / span_ns as f32;
        let table = &self.table[..];
        for p in points.iter_mut() {
            let u = p.t as f32 * steps_per_ns;
            let k = (u as usize).min(TABLE_STEPS - 1);
            let f = u - k as f32;
            let (a, b) = (&table[k], &table[k + 1]);
            let mut m = [0f32; 12];
            for i in 0..12 {
                m[i] = a[i] + (b[i] - a[i]) * f;
            }
            let (x, y, z) = (p.x, p.y, p.z);
            p.x = m[0] * x + m[1] * y + m[2] * z + m[3];
            p.y = m[4] * x + m[5] * y + m[6] * z + m[7];
            p.z = m[8] * x + m[9] * y + m[10] * z + m[11];
        }
    }
}

/// The largest time offset of the points, ns.
fn span_ns(points: &[Point]) -> u32 {
    points.iter().map(|p| p.t).max().unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(x: f32, y: f32, z: f32, t: u32) -> Point {
        Point {
            x,
            y,
            z,
            t,
            ..Point::default()
        }
    }

    /// Straight motion at 10 m/s: a point 20 m ahead seen 50 ms in was seen from 0.5 m
    /// further along, so in the start frame it lies at 20.5 m; in the end frame (100 ms) at
    /// 20.5 − 1.0 = 19.5 m.
    #[test]
    fn straight_motion_shifts_points_by_velocity_times_time() {
        let twist = Twist {
            linear_mps: Vector3::new(10.0, 0.0, 0.0),
            angular_radps: Vector3::zeros(),
        };
        let mut pts = [
            point(20.0, 0.0, 0.0, 50_000_000),
            point(0.0, 5.0, 1.0, 100_000_000),
        ];
        Deskewer::new(Reference::Start).deskew_constant_velocity(&mut pts, &twist);
        assert!((pts[0].x - 20.5).abs() < 1e-5, "{:?}", pts[0]);
        assert!((pts[1].x - 1.0).abs() < 1e-5 && (pts[1].y - 5.0).abs() < 1e-6);
        let mut pts = [
            point(20.0, 0.0, 0.0, 50_000_000),
            point(0.0, 0.0, 0.0, 100_000_000),
        ];
        Deskewer::new(Reference::End).deskew_constant_velocity(&mut pts, &twist);
        assert!((pts[0].x - 19.5).abs() < 1e-5, "{:?}", pts[0]);
        assert!(
            pts[1].x.abs() < 1e-5,
            "the last point is in the end frame already"
        );
    }

    /// Pure yaw at 60 °/s: a point seen straight ahead (10, 0) at t = 90 ms was seen by a
    /// sensor turned 5.4° left, so in the start frame it is at 10·(cos 5.4°, sin 5.4°).
    #[test]
    fn yaw_rotates_points_by_the_angle_turned() {
        let twist = Twist {
            linear_mps: Vector3::zeros(),
            angular_radps: Vector3::new(0.0, 0.0, 60f64.to_radians()),
        };
        let mut pts = [
            point(10.0, 0.0, 0.0, 90_000_000),
            point(0.0, 0.0, 0.0, 100_000_000),
        ];
        Deskewer::new(Reference::Start).deskew_constant_velocity(&mut pts, &twist);
        let a = 5.4f64.to_radians();
        assert!(
            (f64::from(pts[0].x) - 10.0 * a.cos()).abs() < 1e-5,
            "{:?}",
            pts[0]
        );
        assert!(
            (f64::from(pts[0].y) - 10.0 * a.sin()).abs() < 1e-5,
            "{:?}",
            pts[0]
        );
    }

    /// Driving a 15 m/s, 60 °/s arc: the start-frame position of a point seen at t from the
    /// sensor pose (r sin ωt, r(1 − cos ωt)) heading ωt, r = v/ω, written out by hand.
    #[test]
    fn arc_motion_matches_the_closed_form_pose() {
        let (v, w) = (15.0f64, 60f64.to_radians());
        let twist = Twist {
            linear_mps: Vector3::new(v, 0.0, 0.0),
            angular_radps: Vector3::new(0.0, 0.0, w),
        };
        let r = v / w;
        let mut pts = Vec::new();
        let mut expected = Vec::new();
        for i in 0..=100u32 {
            let t_ns = i * 1_000_000 + 333; // not on a table step
            let t = f64::from(t_ns) * 1e-9;
            let (px, py, pz) = (
                30.0 * (i as f64 * 0.3).cos(),
                30.0 * (i as f64 * 0.3).sin(),
                -1.5,
            );
            let th = w * t;
            let (sx, sy) = (r * th.sin(), r * (1.0 - th.cos()));
            expected.push((
                sx + th.cos() * px - th.sin() * py,
                sy + th.sin() * px + th.cos() * py,
                pz,
            ));
            pts.push(point(px as f32, py as f32, pz as f32, t_ns));
        }
        Deskewer::new(Reference::Start).deskew_constant_velocity(&mut pts, &twist);
        for (p, e) in pts.iter().zip(&expected) {
            let d = ((f64::from(p.x) - e.0).powi(2)
                + (f64::from(p.y) - e.1).powi(2)
                + (f64::from(p.z) - e.2).powi(2))
            .sqrt();
            assert!(d < 1e-4, "{p:?} vs {e:?}: {d} m");
        }
    }

    #[test]
    fn zero_motion_is_the_identity_and_fields_other_than_xyz_are_kept() {
        let pts0: Vec<Point> = (0..50)
            .map(|i| Point {
                x: i as f32,
                y: -(i as f32),
                z: 0.5,
                intensity: 7.0,
                t: i * 2_000_000,
                ring: (i % 16) as u16,
                ret: (i % 2) as u8,
                pad: 0,
            })
            .collect();
        let mut pts = pts0.clone();
        Deskewer::new(Reference::End).deskew_constant_velocity(&mut pts, &Twist::zero());
        assert_eq!(pts, pts0);
    }

    #[test]
    fn imu_with_constant_rate_matches_constant_velocity() {
        let (v, w) = (15.0f64, 60f64.to_radians());
        let mut track = ImuTrack::new(nalgebra::UnitQuaternion::identity(), 100);
        let t0 = 1_000_000_000_000i64;
        for k in -2..15 {
            track.push(t0 + k * 10_000_000, [0.0, 0.0, w]);
        }
        let make = || -> Vec<Point> {
            (0..1000u32)
                .map(|i| point(20.0, (i as f32) * 0.01, 0.0, i * 100_000))
                .collect()
        };
        let (mut a, mut b) = (make(), make());
        let twist = Twist {
            linear_mps: Vector3::new(v, 0.0, 0.0),
            angular_radps: Vector3::new(0.0, 0.0, w),
        };
        let mut d = Deskewer::new(Reference::Start);
        d.deskew_constant_velocity(&mut a, &twist);
        d.deskew_imu(&mut b, t0, &track, &Vector3::new(v, 0.0, 0.0))
            .unwrap();
        for (p, q) in a.iter().zip(&b) {
            assert!(
                (p.x - q.x).abs() < 1e-4 && (p.y - q.y).abs() < 1e-4,
                "{p:?} {q:?}"
            );
        }
        // A sweep far from any sample is an error, not a guess.
        let mut c = make();
        assert!(matches!(
            d.deskew_imu(&mut c, 0, &track, &Vector3::zeros()),
            Err(DeskewError::NoImu { .. })
        ));
    }

    #[test]
    fn poses_table_on_the_arc_matches_constant_velocity() {
        let (v, w) = (15.0f64, 60f64.to_radians());
        let twist = Twist {
            linear_mps: Vector3::new(v, 0.0, 0.0),
            angular_radps: Vector3::new(0.0, 0.0, w),
        };
        // world_from_sensor sampled every 50 ms from 1 s before to 1 s after t0.
        let t0 = 5_000_000_000i64;
        let entries = (-20..=20)
            .map(|k| {
                let t = t0 + k * 50_000_000;
                (t, twist.integrate((t - t0) as f64 * 1e-9))
            })
            .collect();
        let table = PoseTable::new(entries).unwrap();
        let make = || -> Vec<Point> {
            (0..1000u32)
                .map(|i| point(-15.0, 3.0 + (i as f32) * 0.01, 2.0, i * 100_000))
                .collect()
        };
        let (mut a, mut b) = (make(), make());
        let mut d = Deskewer::new(Reference::End);
        d.deskew_constant_velocity(&mut a, &twist);
        d.deskew_poses(&mut b, t0 + 7, &table).unwrap();
        for (p, q) in a.iter().zip(&b) {
            assert!(
                (p.x - q.x).abs() < 1e-4 && (p.y - q.y).abs() < 1e-4,
                "{p:?} {q:?}"
            );
        }
        let mut c = make();
        assert!(d.deskew_poses(&mut c, t0 + 990_000_000, &table).is_err());
    }

    #[test]
    fn twist_from_relative_motion_reproduces_the_motion() {
        let twist = Twist {
            linear_mps: Vector3::new(12.0, 0.5, 0.0),
            angular_radps: Vector3::new(0.0, 0.1, 0.8),
        };
        let delta = twist.integrate(0.1);
        let back = Twist::from_relative_motion(&delta, 0.1).unwrap();
        assert!((back.linear_mps - twist.linear_mps).norm() < 1e-9);
        assert!((back.angular_radps - twist.angular_radps).norm() < 1e-9);
        assert!(Twist::from_relative_motion(&delta, 0.0).is_none());
    }
}
