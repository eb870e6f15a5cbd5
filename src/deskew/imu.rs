//! Gyro samples kept for deskewing: angular velocity in the sensor frame, by time.
//!
//! Ouster IMU samples ([`crate::sensor::ImuSample`]) give the angular velocity in rad/s in the
//! IMU's frame, stamped in the sensor clock (the clock of the lidar columns, so of
//! [`crate::sweep::Sweep::device_time_ns`]). The metadata's `imu_to_sensor_transform`
//! ([`crate::sensor::ouster::calib::OusterInfo::imu_to_sensor`]) maps IMU-frame vectors into the
//! sensor frame; a rigid body has one angular velocity, so only its rotation matters (the
//! lever arm does not change ω).

use std::collections::VecDeque;

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// Default number of samples kept (10 s of Ouster's 100 Hz IMU).
pub const DEFAULT_CAPACITY: usize = 1000;

/// How far past the first or last sample the angular velocity is held constant, ns.
pub const HOLD_NS: i64 = 50_000_000;

/// Angular velocity samples in the sensor frame, oldest first, bounded.
#[derive(Clone, Debug)]
pub struct ImuTrack {
    sensor_from_imu: UnitQuaternion<f64>,
    samples: VecDeque<(i64, Vector3<f64>)>,
    capacity: usize,
}

impl ImuTrack {
    /// A track keeping at most `capacity` samples (at least 2), rotating gyro readings by
    /// `sensor_from_imu`.
    pub fn new(sensor_from_imu: UnitQuaternion<f64>, capacity: usize) -> Self {
        let capacity = capacity.max(2);
        Self {
            sensor_from_imu,
            samples: VecDeque::with_capacity(capacity),
            capacity,
        }
    }

    /// A track for an Ouster sensor from its `imu_to_sensor_transform` (row-major 4×4, the
    /// translation is not needed). The 3×3 block is re-orthonormalised.
    pub fn from_imu_to_sensor(imu_to_sensor: &[f64; 16]) -> Self {
        let m = Matrix3::new(
            imu_to_sensor[0],
            imu_to_sensor[1],
            imu_to_sensor[2],
            imu_to_sensor[4],
            imu_to_sensor[5],
            imu_to_sensor[6],
            imu_to_sensor[8],
            imu_to_sensor[9],
            imu_to_sensor[10],
        );
        let rotation = if m.iter().all(|v| v.is_finite()) && m.determinant() > 0.5 {
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&m))
        } else {
            UnitQuaternion::identity()
        };
        Self::new(rotation, DEFAULT_CAPACITY)
    }

    /// Adds a gyro reading (rad/s, IMU frame) taken at `t_ns` (sensor clock). Readings older
    /// than the newest kept one are ignored; the oldest is dropped when the track is full.
    /// Returns whether the sample was kept.
    pub fn push(&mut self, t_ns: i64, gyro_radps: [f64; 3]) -> bool {
        let w = Vector3::from(gyro_radps);
        if !w.iter().all(|v| v.is_finite()) || self.samples.back().is_some_and(|&(t, _)| t_ns <= t)
        {
            return false;
        }
        if self.samples.len() == self.capacity {
            self.samples.pop_front();
        }
        self.samples.push_back((t_ns, self.sensor_from_imu * w));
        true
    }

    /// Samples kept.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// Whether no sample is kept.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Angular velocity in the sensor frame at `t_ns`, rad/s: linear between the samples
    /// around it, held up to [`HOLD_NS`] beyond the first and last; `None` farther out. Two
    /// samples more than 2 × [`HOLD_NS`] apart are a gap (samples lost, the gyro stopped):
    /// each is held up to [`HOLD_NS`] into it, and a line across the rest would be invented.
    /// Times may lie anywhere in `i64` (a corrupt stamp): differences are unsigned.
    pub fn angular_velocity_at(&self, t_ns: i64) -> Option<Vector3<f64>> {
        let hold = HOLD_NS.unsigned_abs();
        let (&(t0, w0), &(t1, w1)) = (self.samples.front()?, self.samples.back()?);
        if t_ns <= t0 {
            return (t0.abs_diff(t_ns) <= hold).then_some(w0);
        }
        if t_ns >= t1 {
            return (t_ns.abs_diff(t1) <= hold).then_some(w1);
        }
        let hi = self.samples.partition_point(|&(t, _)| t <= t_ns);
        let (ta, wa) = self.samples[hi - 1];
        let (tb, wb) = self.samples[hi];
        let (after_a, span) = (t_ns.abs_diff(ta), tb.abs_diff(ta));
        if span > 2 * hold {
            return match (after_a <= hold, tb.abs_diff(t_ns) <= hold) {
                (true, _) => Some(wa),
                (_, true) => Some(wb),
                _ => None,
            };
        }
        let s = after_a as f64 / span as f64;
        Some(wa + (wb - wa) * s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Stamps at either end of `i64` (a corrupt column time: Ouster's u64 stamps beyond 2^63)
    /// are far from every sample, not a panic (debug) or a wrapped difference that passed for
    /// near (release).
    #[test]
    fn times_at_the_ends_of_i64_are_far_from_every_sample() {
        let mut track = ImuTrack::new(UnitQuaternion::identity(), 10);
        assert!(track.push(1_000_000_000, [0.0, 0.0, 1.0]));
        assert_eq!(track.angular_velocity_at(i64::MIN), None);
        assert_eq!(track.angular_velocity_at(i64::MAX), None);
        let mut wide = ImuTrack::new(UnitQuaternion::identity(), 10);
        assert!(wide.push(i64::MIN, [0.0, 0.0, 1.0]));
        assert!(wide.push(i64::MAX, [0.0, 0.0, 2.0]));
        assert_eq!(wide.angular_velocity_at(0), None);
    }

    /// A gap in the samples (more than twice the hold) is no reading: each side is held for
    /// [`HOLD_NS`] into it, and between them there is none. Before, a 10 s gap gave a rate
    /// interpolated across it, and the IMU rotation prior integrated it.
    #[test]
    fn a_gap_between_samples_is_not_bridged() {
        let mut track = ImuTrack::new(UnitQuaternion::identity(), 10);
        assert!(track.push(0, [0.0, 0.0, 0.0]));
        assert!(track.push(10_000_000_000, [0.0, 0.0, 1.0]));
        assert_eq!(track.angular_velocity_at(5_000_000_000), None);
        assert_eq!(track.angular_velocity_at(HOLD_NS), Some(Vector3::zeros()));
        assert_eq!(
            track.angular_velocity_at(10_000_000_000 - HOLD_NS),
            Some(Vector3::new(0.0, 0.0, 1.0))
        );
        // Samples 2 × the hold apart are still interpolated.
        let mut close = ImuTrack::new(UnitQuaternion::identity(), 10);
        assert!(close.push(0, [0.0, 0.0, 0.0]));
        assert!(close.push(2 * HOLD_NS, [0.0, 0.0, 1.0]));
        let w = close.angular_velocity_at(HOLD_NS / 2).unwrap();
        assert!((w.z - 0.25).abs() < 1e-12, "{w}");
    }

    #[test]
    fn readings_are_rotated_into_the_sensor_frame_and_interpolated() {
        // An IMU mounted rotated 90° about z: its x axis is the sensor's y axis.
        let m = [
            0.0, -1.0, 0.0, 6.0, //
            1.0, 0.0, 0.0, -11.0, //
            0.0, 0.0, 1.0, 7.0, //
            0.0, 0.0, 0.0, 1.0,
        ];
        let mut track = ImuTrack::from_imu_to_sensor(&m);
        assert!(track.push(1_000, [1.0, 0.0, 0.0]));
        assert!(track.push(3_000, [3.0, 0.0, 0.0]));
        assert!(!track.push(2_000, [9.0, 0.0, 0.0]), "out of order");
        let w = track.angular_velocity_at(2_000).unwrap();
        assert!((w - Vector3::new(0.0, 2.0, 0.0)).norm() < 1e-12, "{w:?}");
        let held = track.angular_velocity_at(0).unwrap();
        assert!(
            (held - Vector3::new(0.0, 1.0, 0.0)).norm() < 1e-12,
            "{held:?}"
        );
        assert!(track.angular_velocity_at(3_000 + HOLD_NS + 1).is_none());
    }

    #[test]
    fn the_track_stays_bounded() {
        let mut track = ImuTrack::new(UnitQuaternion::identity(), 4);
        for i in 0..10 {
            track.push(i, [i as f64, 0.0, 0.0]);
        }
        assert_eq!(track.len(), 4);
        assert_eq!(track.angular_velocity_at(6).map(|w| w.x), Some(6.0));
    }
}
