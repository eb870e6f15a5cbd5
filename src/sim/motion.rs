//! Sensor motion: a [`Trajectory`] gives `world_from_sensor` at any time and the kinematics an
//! IMU measures (velocity, acceleration, angular velocity; world and body frames).
//!
//! Times are ns on the simulator's clock (the clock of the packets' host timestamps and of
//! [`crate::sensor::velodyne::sim::Truth::time_ns`]); a trajectory starts at its `t0_ns`. Kinds:
//! - [`Motion::Fixed`]: a constant pose (the identity: the static sensor of the encoder tests);
//! - [`Motion::Twist`]: a constant body-frame twist from a start pose (15 m/s forward with
//!   60 °/s yaw is a circle of radius 14.3 m);
//! - [`Motion::Route`]: straight segments and arcs at given speeds ([`Route`]), with curvature
//!   ramps (clothoids) and smooth speed changes so that acceleration and angular velocity are
//!   continuous, carrying the sensor on a mount above the vehicle;
//! - [`Motion::Poses`]: a table of timed poses, interpolated on SE(3) (translation lerp,
//!   rotation slerp); read and written as TUM text (`t x y z qx qy qz qw`, t in seconds).
//!
//! Velocities and accelerations are central differences of the pose over ±1 ms (h²/6 × jerk:
//! ~1e-5 m/s for the twist and the route; piecewise constant for a pose table), so they are
//! consistent with the poses by construction.
//!
//! ```
//! use nalgebra::{Isometry3, Vector3};
//! use ringscan::sim::motion::Trajectory;
//! let t0 = 1_700_000_000_000_000_000;
//! let traj = Trajectory::twist(
//!     t0,
//!     Isometry3::translation(0.0, 0.0, 1.8),
//!     Vector3::new(15.0, 0.0, 0.0),
//!     Vector3::new(0.0, 0.0, 60f64.to_radians()),
//! );
//! // Half a turn (3 s) later: on the far side of the 14.3 m circle, heading back.
//! let p = traj.pose(t0 + 3_000_000_000);
//! let r = 15.0 / 60f64.to_radians();
//! assert!((p.translation.vector - Vector3::new(0.0, 2.0 * r, 1.8)).norm() < 1e-9);
//! let k = traj.kinematics(t0 + 1_000_000_000);
//! assert!((k.velocity_body() - Vector3::new(15.0, 0.0, 0.0)).norm() < 1e-5);
//! ```

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

/// Standard gravity, m/s² (the Ouster IMU's g).
pub const GRAVITY: f64 = 9.80665;

/// Step of the central differences, s.
const FD_STEP_S: f64 = 1e-3;

/// What an IMU rigidly attached to a frame measures, and more, at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Kinematics {
    /// `world_from_frame`.
    pub pose: Isometry3<f64>,
    /// Velocity of the frame's origin, world frame, m/s.
    pub velocity: Vector3<f64>,
    /// Acceleration of the frame's origin, world frame, m/s².
    pub acceleration: Vector3<f64>,
    /// Angular velocity, world frame, rad/s.
    pub angular_velocity: Vector3<f64>,
}

impl Kinematics {
    /// Velocity in the frame's own axes.
    pub fn velocity_body(&self) -> Vector3<f64> {
        self.pose.rotation.inverse() * self.velocity
    }

    /// Acceleration in the frame's own axes (no gravity).
    pub fn acceleration_body(&self) -> Vector3<f64> {
        self.pose.rotation.inverse() * self.acceleration
    }

    /// Angular velocity in the frame's own axes: what a gyro reads, rad/s.
    pub fn angular_velocity_body(&self) -> Vector3<f64> {
        self.pose.rotation.inverse() * self.angular_velocity
    }

    /// Specific force in the frame's own axes (acceleration minus gravity, gravity pointing
    /// −z in the world): what an accelerometer reads, m/s² (+g up at rest).
    pub fn specific_force_body(&self) -> Vector3<f64> {
        self.pose.rotation.inverse() * (self.acceleration + Vector3::new(0.0, 0.0, GRAVITY))
    }
}

/// How the sensor moves.
#[derive(Clone, Debug, PartialEq)]
pub enum Motion {
    /// A constant pose.
    Fixed(Isometry3<f64>),
    /// A constant twist in the body frame from a start pose.
    Twist {
        /// Pose at `t0`.
        start: Isometry3<f64>,
        /// Linear velocity, body frame, m/s.
        linear: Vector3<f64>,
        /// Angular velocity, body frame, rad/s.
        angular: Vector3<f64>,
    },
    /// A route of segments.
    Route(Route),
    /// Timed poses, interpolated.
    Poses(PoseTable),
}

/// `world_from_sensor` over time.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    /// Start time, ns (the route's and twist's time origin; a pose table keeps its own times).
    pub t0_ns: i64,
    /// The motion.
    pub motion: Motion,
}

impl Trajectory {
    /// A sensor that never moves (identity: sensor frame = world frame).
    pub fn identity() -> Self {
        Self::fixed(Isometry3::identity())
    }

    /// A sensor that stays at `pose`.
    pub fn fixed(pose: Isometry3<f64>) -> Self {
        Self {
            t0_ns: 0,
            motion: Motion::Fixed(pose),
        }
    }

    /// A constant body-frame twist (`linear` m/s, `angular` rad/s) from `start` at `t0_ns`.
    pub fn twist(
        t0_ns: i64,
        start: Isometry3<f64>,
        linear: Vector3<f64>,
        angular: Vector3<f64>,
    ) -> Self {
        Self {
            t0_ns,
            motion: Motion::Twist {
                start,
                linear,
                angular,
            },
        }
    }

    /// A route driven from `t0_ns`.
    pub fn route(t0_ns: i64, route: Route) -> Self {
        Self {
            t0_ns,
            motion: Motion::Route(route),
        }
    }

    /// Interpolated timed poses (their own absolute times).
    pub fn poses(table: PoseTable) -> Self {
        Self {
            t0_ns: table.first_ns(),
            motion: Motion::Poses(table),
        }
    }

    /// `world_from_sensor` at `t_ns`.
    pub fn pose(&self, t_ns: i64) -> Isometry3<f64> {
        self.pose_s((t_ns - self.t0_ns) as f64 * 1e-9)
    }

    /// `world_from_sensor` at `t_s` seconds after `t0_ns`.
    pub fn pose_s(&self, t_s: f64) -> Isometry3<f64> {
        match &self.motion {
            Motion::Fixed(p) => *p,
            Motion::Twist {
                start,
                linear,
                angular,
            } => start * se3_exp(linear * t_s, angular * t_s),
            Motion::Route(r) => r.pose_s(t_s),
            Motion::Poses(t) => t.pose_s(t_s),
        }
    }

    /// Kinematics of the sensor frame at `t_ns`.
    pub fn kinematics(&self, t_ns: i64) -> Kinematics {
        self.kinematics_of(t_ns, &Isometry3::identity())
    }

    /// Kinematics at `t_ns` of a frame rigidly attached to the sensor (`sensor_from_frame`,
    /// e.g. an IMU's): lever-arm effects included.
    pub fn kinematics_of(&self, t_ns: i64, sensor_from_frame: &Isometry3<f64>) -> Kinematics {
        let t = (t_ns - self.t0_ns) as f64 * 1e-9;
        let h = FD_STEP_S;
        let at = |s: f64| self.pose_s(s) * sensor_from_frame;
        let (a, p, b) = (at(t - h), at(t), at(t + h));
        let (pa, pp, pb) = (
            a.translation.vector,
            p.translation.vector,
            b.translation.vector,
        );
        let dr = b.rotation * a.rotation.inverse();
        Kinematics {
            pose: p,
            velocity: (pb - pa) / (2.0 * h),
            acceleration: (pb - 2.0 * pp + pa) / (h * h),
            angular_velocity: dr.scaled_axis() / (2.0 * h),
        }
    }

    /// Poses from `from_ns` to `to_ns` (inclusive) every `step_ns`, for a TUM file of the
    /// true trajectory.
    pub fn sample(&self, from_ns: i64, to_ns: i64, step_ns: i64) -> PoseTable {
        let step = step_ns.max(1);
        let mut poses = Vec::new();
        let mut t = from_ns;
        while t <= to_ns {
            poses.push((t, self.pose(t)));
            t += step;
        }
        PoseTable { poses }
    }
}

/// exp of a twist (ρ, φ): rotation exp(φ), translation V(φ)·ρ.
fn se3_exp(rho: Vector3<f64>, phi: Vector3<f64>) -> Isometry3<f64> {
    let th = phi.norm();
    let k = phi.cross_matrix();
    let (a, b) = if th < 1e-6 {
        (0.5 - th * th / 24.0, 1.0 / 6.0 - th * th / 120.0)
    } else {
        (
            (1.0 - th.cos()) / (th * th),
            (th - th.sin()) / (th * th * th),
        )
    };
    let v = nalgebra::Matrix3::identity() + k * a + k * k * b;
    Isometry3::from_parts(
        Translation3::from(v * rho),
        UnitQuaternion::from_scaled_axis(phi),
    )
}

/// Timed poses, sorted by time; interpolated on SE(3) between neighbours, held before the
/// first and after the last.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PoseTable {
    /// (time ns, `world_from_sensor`), strictly increasing times.
    pub poses: Vec<(i64, Isometry3<f64>)>,
}

impl PoseTable {
    /// A table from poses, sorted by time (later duplicates of a time dropped).
    pub fn new(mut poses: Vec<(i64, Isometry3<f64>)>) -> Self {
        poses.sort_by_key(|p| p.0);
        poses.dedup_by_key(|p| p.0);
        Self { poses }
    }

    /// Time of the first pose (0 when empty).
    pub fn first_ns(&self) -> i64 {
        self.poses.first().map_or(0, |p| p.0)
    }

    /// The interpolated pose at `t_ns` (identity when empty).
    pub fn pose(&self, t_ns: i64) -> Isometry3<f64> {
        self.pose_s((t_ns - self.first_ns()) as f64 * 1e-9)
    }

    fn pose_s(&self, t_s: f64) -> Isometry3<f64> {
        let Some(&(t0, first)) = self.poses.first() else {
            return Isometry3::identity();
        };
        let rel = |t: i64| (t - t0) as f64 * 1e-9;
        let i = self.poses.partition_point(|p| rel(p.0) <= t_s);
        if i == 0 {
            return first;
        }
        if i == self.poses.len() {
            return self.poses[i - 1].1;
        }
        let (ta, a) = self.poses[i - 1];
        let (tb, b) = self.poses[i];
        let u = (t_s - rel(ta)) / (rel(tb) - rel(ta));
        let tr = a.translation.vector.lerp(&b.translation.vector, u);
        let rot = a.rotation.slerp(&b.rotation, u);
        Isometry3::from_parts(Translation3::from(tr), rot)
    }

    /// Parses TUM text with the parser `--deskew poses:FILE` uses
    /// ([`crate::deskew::PoseTable::from_tum`]: 8 values a line, times read exactly to the ns,
    /// at least two poses strictly increasing in time, unit quaternions); one format, one set
    /// of rules for every TUM file ringscan reads.
    pub fn parse_tum(text: &str) -> Result<Self, crate::deskew::PosesError> {
        let table = crate::deskew::PoseTable::from_tum(text)?;
        Ok(Self::new(table.entries().collect()))
    }

    /// Writes TUM text (times with 9 decimals, qw ≥ 0).
    pub fn to_tum(&self) -> String {
        let mut s = String::with_capacity(self.poses.len() * 100);
        for (t, p) in &self.poses {
            let q = p.rotation.quaternion();
            let k = if q.w < 0.0 { -1.0 } else { 1.0 };
            let tr = p.translation.vector;
            s.push_str(&format!(
                "{}.{:09} {:.9} {:.9} {:.9} {:.12} {:.12} {:.12} {:.12}\n",
                t.div_euclid(1_000_000_000),
                t.rem_euclid(1_000_000_000),
                tr.x,
                tr.y,
                tr.z,
                k * q.i,
                k * q.j,
                k * q.k,
                k * q.w
            ));
        }
        s
    }
}

/// A piece of a [`Route`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Segment {
    /// Straight ahead.
    Straight {
        /// Length, m.
        length: f64,
        /// Speed, m/s.
        speed: f64,
    },
    /// A circular arc.
    Arc {
        /// Radius, m.
        radius: f64,
        /// Turn, radians (positive: left, counter-clockwise seen from above).
        angle: f64,
        /// Speed, m/s.
        speed: f64,
    },
}

impl Segment {
    fn length(&self) -> f64 {
        match *self {
            Segment::Straight { length, .. } => length,
            Segment::Arc { radius, angle, .. } => radius * angle.abs(),
        }
    }

    fn speed(&self) -> f64 {
        match *self {
            Segment::Straight { speed, .. } | Segment::Arc { speed, .. } => speed.max(0.1),
        }
    }

    fn curvature(&self) -> f64 {
        match *self {
            Segment::Straight { .. } => 0.0,
            Segment::Arc { radius, angle, .. } => angle.signum() / radius,
        }
    }
}

/// Sampling step of a route's tables, m.
const ROUTE_DS: f64 = 0.05;

/// A planar route: a vehicle drives segments on the plane z = `start.z`, yaw following the
/// path, carrying the sensor at `mount` (`vehicle_from_sensor`).
///
/// Curvature changes linearly over [`Route::curvature_ramp_m`] centred on each joint (a
/// clothoid: the yaw rate has no step), speed changes with a half-cosine over up to
/// [`Route::speed_ramp_m`] inside the longer of the two segments at a joint (the acceleration
/// has no step inside a segment). After the last segment the vehicle goes on straight at the
/// last speed.
#[derive(Clone, Debug, PartialEq)]
pub struct Route {
    /// Start (x, y, yaw rad) and height of the vehicle.
    pub start: [f64; 4],
    /// The segments.
    pub segments: Vec<Segment>,
    /// `vehicle_from_sensor`.
    pub mount: Isometry3<f64>,
    /// Length of the curvature ramps, m.
    pub curvature_ramp_m: f64,
    /// Longest speed ramp, m.
    pub speed_ramp_m: f64,
    /// Cumulated arc length at each segment's start, and the total.
    joints: Vec<f64>,
    /// Per table step: (s, x, y, yaw, t).
    table: Vec<[f64; 5]>,
}

impl Route {
    /// A route from `start` = (x, y, yaw rad, z) of the vehicle, sensor at `mount`.
    pub fn new(start: [f64; 4], segments: Vec<Segment>, mount: Isometry3<f64>) -> Self {
        let mut r = Self {
            start,
            segments,
            mount,
            curvature_ramp_m: 4.0,
            speed_ramp_m: 40.0,
            joints: Vec::new(),
            table: Vec::new(),
        };
        r.build();
        r
    }

    /// The urban drive of [`super::scenes::urban`]: counter-clockwise once around the block
    /// from (20, 0) heading +x, corners of radius 10 m at 9 m/s, straights at 12–20 m/s, then
    /// on along the first street to (80, 0) at up to 20 m/s; sensor 1.8 m above the road;
    /// ≈ 543 m in ≈ 43 s.
    pub fn urban() -> Self {
        let q = std::f64::consts::FRAC_PI_2;
        let arc = Segment::Arc {
            radius: 10.0,
            angle: q,
            speed: 9.0,
        };
        let st = |length: f64, speed: f64| Segment::Straight { length, speed };
        Self::new(
            [20.0, 0.0, 0.0, 0.0],
            vec![
                st(120.0, 20.0),
                arc,
                st(80.0, 14.0),
                arc,
                st(130.0, 20.0),
                arc,
                st(80.0, 14.0),
                arc,
                st(70.0, 20.0),
            ],
            Isometry3::translation(0.0, 0.0, super::scenes::SENSOR_HEIGHT_M),
        )
    }

    /// Total length of the segments, m.
    pub fn length(&self) -> f64 {
        self.joints.last().copied().unwrap_or(0.0)
    }

    /// Time to drive the segments, s.
    pub fn duration_s(&self) -> f64 {
        let l = self.length();
        self.time_at(l)
    }

    fn build(&mut self) {
        let mut s = 0.0;
        self.joints = vec![0.0];
        for seg in &self.segments {
            s += seg.length();
            self.joints.push(s);
        }
        let n = (s / ROUTE_DS).ceil() as usize + 1;
        let mut table = Vec::with_capacity(n + 1);
        let (mut x, mut y, mut yaw, mut t) = (self.start[0], self.start[1], self.start[2], 0.0);
        let mut s = 0.0;
        table.push([s, x, y, yaw, t]);
        for _ in 0..n {
            let (nx, ny, nyaw) = self.advance(s, x, y, yaw, ROUTE_DS);
            t += simpson(|u| 1.0 / self.speed(u), s, s + ROUTE_DS);
            s += ROUTE_DS;
            (x, y, yaw) = (nx, ny, nyaw);
            table.push([s, x, y, yaw, t]);
        }
        self.table = table;
    }

    /// Curvature at arc length `s`, 1/m.
    pub fn curvature(&self, s: f64) -> f64 {
        let k = |i: usize| {
            self.segments
                .get(i.min(self.segments.len().saturating_sub(1)))
                .map_or(0.0, |g| g.curvature())
        };
        let i = self.segment_at(s);
        let mut c = k(i);
        if s > self.length() {
            return 0.0;
        }
        // Ramps centred on the joints, at most half of each adjacent segment.
        for j in [i, i + 1] {
            if j == 0 || j >= self.segments.len() {
                continue;
            }
            let sj = self.joints[j];
            let half = (0.5 * self.curvature_ramp_m)
                .min(0.5 * self.segments[j - 1].length())
                .min(0.5 * self.segments[j].length());
            if half > 0.0 && (s - sj).abs() < half {
                let u = (s - (sj - half)) / (2.0 * half);
                c = k(j - 1) + (k(j) - k(j - 1)) * u;
            }
        }
        c
    }

    /// Speed at arc length `s`, m/s.
    pub fn speed(&self, s: f64) -> f64 {
        let v = |i: usize| {
            self.segments
                .get(i.min(self.segments.len().saturating_sub(1)))
                .map_or(1.0, |g| g.speed())
        };
        let i = self.segment_at(s);
        for j in [i, i + 1] {
            if j == 0 || j >= self.segments.len() {
                continue;
            }
            let sj = self.joints[j];
            let (a, b) = (&self.segments[j - 1], &self.segments[j]);
            let (la, lb) = (a.length(), b.length());
            let straight = |g: &Segment| matches!(g, Segment::Straight { .. });
            // In a straight rather than an arc (the yaw rate stays v/R), else the longer.
            let in_a = match (straight(a), straight(b)) {
                (true, false) => true,
                (false, true) => false,
                _ => la >= lb,
            };
            let (lo, hi) = if in_a {
                (sj - self.speed_ramp_m.min(0.5 * la), sj)
            } else {
                (sj, sj + self.speed_ramp_m.min(0.5 * lb))
            };
            if s >= lo && s < hi && hi > lo {
                let u = (s - lo) / (hi - lo);
                let w = 0.5 * (1.0 - (std::f64::consts::PI * u).cos());
                return v(j - 1) + (v(j) - v(j - 1)) * w;
            }
        }
        v(i)
    }

    fn segment_at(&self, s: f64) -> usize {
        self.joints
            .partition_point(|&j| j <= s)
            .saturating_sub(1)
            .min(self.segments.len().saturating_sub(1))
    }

    /// Position and yaw `d` metres on from (x, y, yaw) at arc length `s` (3-point Gauss on
    /// the heading, the heading by the trapezoid on the curvature: exact for a linear ramp).
    fn advance(&self, s: f64, x: f64, y: f64, yaw: f64, d: f64) -> (f64, f64, f64) {
        let k0 = self.curvature(s);
        let heading = |u: f64| yaw + 0.5 * (k0 + self.curvature(s + u)) * u;
        let g = (0.6f64).sqrt();
        let mut cx = 0.0;
        let mut cy = 0.0;
        for (w, p) in [(5.0 / 9.0, -g), (8.0 / 9.0, 0.0), (5.0 / 9.0, g)] {
            let u = 0.5 * d * (1.0 + p);
            let h = heading(u);
            cx += w * h.cos();
            cy += w * h.sin();
        }
        (x + 0.5 * d * cx, y + 0.5 * d * cy, heading(d))
    }

    fn time_at(&self, s: f64) -> f64 {
        let i = ((s / ROUTE_DS).floor().max(0.0) as usize).min(self.table.len() - 1);
        let e = self.table[i];
        e[4] + simpson(|u| 1.0 / self.speed(u), e[0], s)
    }

    /// Arc length reached at `t_s`.
    fn s_at(&self, t_s: f64) -> f64 {
        let last = self.table[self.table.len() - 1];
        if t_s >= last[4] {
            return last[0] + (t_s - last[4]) * self.speed(last[0]);
        }
        if t_s <= 0.0 {
            return t_s * self.speed(0.0);
        }
        let i = self
            .table
            .partition_point(|e| e[4] <= t_s)
            .saturating_sub(1);
        let e = self.table[i];
        let mut s = e[0] + (t_s - e[4]) * self.speed(e[0]);
        for _ in 0..4 {
            let f = e[4] + simpson(|u| 1.0 / self.speed(u), e[0], s) - t_s;
            if f.abs() < 1e-14 {
                break;
            }
            s -= f * self.speed(s);
        }
        s
    }

    fn pose_s(&self, t_s: f64) -> Isometry3<f64> {
        let s = self.s_at(t_s);
        let (x, y, yaw) = if s <= 0.0 {
            let (x0, y0, a) = (self.start[0], self.start[1], self.start[2]);
            (x0 + s * a.cos(), y0 + s * a.sin(), a)
        } else {
            let last = self.table[self.table.len() - 1];
            if s >= last[0] {
                let d = s - last[0];
                (
                    last[1] + d * last[3].cos(),
                    last[2] + d * last[3].sin(),
                    last[3],
                )
            } else {
                let i = ((s / ROUTE_DS).floor() as usize).min(self.table.len() - 1);
                let e = self.table[i];
                self.advance(e[0], e[1], e[2], e[3], s - e[0])
            }
        };
        let vehicle = Isometry3::from_parts(
            Translation3::new(x, y, self.start[3]),
            UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
        );
        vehicle * self.mount
    }
}

fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64) -> f64 {
    (b - a) / 6.0 * (f(a) + 4.0 * f(0.5 * (a + b)) + f(b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn twist_kinematics_match_the_closed_form() {
        let start = Isometry3::from_parts(
            Translation3::new(1.0, 2.0, 1.8),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.3),
        );
        let v = Vector3::new(15.0, 0.0, 0.0);
        let w = Vector3::new(0.0, 0.0, 60f64.to_radians());
        let tr = Trajectory::twist(1_000, start, v, w);
        for k in 0..50 {
            let t = 1_000 + k * 123_456_789;
            let kin = tr.kinematics(t);
            let r = kin.pose.rotation;
            // Constant body twist: v_w = R v, ω_w = R ω, a_w = R (ω × v).
            assert!((kin.velocity - r * v).norm() < 1e-5);
            assert!((kin.angular_velocity - r * w).norm() < 1e-9);
            assert!((kin.acceleration - r * w.cross(&v)).norm() < 1e-4);
            // Accelerometer: centripetal 15 · 1.047 = 15.7 m/s² to the left, +g up.
            let f = kin.specific_force_body();
            assert!((f - Vector3::new(0.0, 15.0 * w.z, GRAVITY)).norm() < 1e-4);
            // Circle of radius v/ω around the start's left.
            let c = start * nalgebra::Point3::new(0.0, v.x / w.z, 0.0);
            let d = (kin.pose.translation.vector - c.coords).xy().norm();
            assert!((d - v.x / w.z).abs() < 1e-9);
        }
    }

    #[test]
    fn lever_arm_adds_centripetal_acceleration() {
        let w = Vector3::new(0.0, 0.0, 2.0);
        let tr = Trajectory::twist(0, Isometry3::identity(), Vector3::zeros(), w);
        let imu = Isometry3::translation(0.5, 0.0, 0.0);
        let k = tr.kinematics_of(0, &imu);
        // Spinning in place: a point 0.5 m out accelerates ω²r = 2 m/s² inwards.
        assert!((k.acceleration - Vector3::new(-2.0, 0.0, 0.0)).norm() < 1e-5);
        assert!((k.velocity - Vector3::new(0.0, 1.0, 0.0)).norm() < 1e-5);
    }

    #[test]
    fn urban_route_loops_once_and_respects_its_speeds() {
        let r = Route::urban();
        assert!((r.length() - (480.0 + 20.0 * std::f64::consts::PI)).abs() < 1e-9);
        let tr = Trajectory::route(0, r.clone());
        let end = tr.pose_s(r.duration_s());
        let start = tr.pose_s(0.0);
        // Symmetric corners: once around the block (to the integration error), then 60 m on.
        let d = end.translation.vector - start.translation.vector;
        assert!((d - Vector3::new(60.0, 0.0, 0.0)).norm() < 1e-3, "{d:?}");
        assert!(end.rotation.angle_to(&start.rotation) < 1e-6);
        let mut max_v: f64 = 0.0;
        let mut max_yaw_rate: f64 = 0.0;
        let n = (r.duration_s() * 100.0) as i64;
        let mut prev: Option<Kinematics> = None;
        for k in 0..n {
            let kin = tr.kinematics(k * 10_000_000);
            max_v = max_v.max(kin.velocity.norm());
            max_yaw_rate = max_yaw_rate.max(kin.angular_velocity.z.abs());
            // The sensor stays 1.8 m up; the body velocity is forward only.
            assert!((kin.pose.translation.z - 1.8).abs() < 1e-12);
            let vb = kin.velocity_body();
            assert!(vb.y.abs() < 1e-3 && vb.z.abs() < 1e-9, "{vb:?}");
            // Smooth: acceleration changes by less than 1 m/s² per 10 ms.
            if let Some(p) = prev {
                assert!((kin.acceleration - p.acceleration).norm() < 1.0);
            }
            prev = Some(kin);
        }
        assert!((max_v - 20.0).abs() < 1e-3);
        assert!((max_yaw_rate - 0.9).abs() < 0.02, "{max_yaw_rate}");
    }

    #[test]
    fn tum_round_trips_and_interpolates() {
        let a = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 1.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.0),
        );
        let b = Isometry3::from_parts(
            Translation3::new(2.0, 4.0, 1.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 1.0),
        );
        let t0 = 1_714_564_800_123_456_789;
        let table = PoseTable::new(vec![(t0 + 1_000_000_000, b), (t0, a)]);
        let text = table.to_tum();
        assert!(text.starts_with("1714564800.123456789 0.000000000"));
        let back = PoseTable::parse_tum(&format!("# t x y z qx qy qz qw\n\n{text}")).unwrap();
        assert_eq!(back.poses.len(), 2);
        assert_eq!(back.poses[0].0, t0);
        let tr = Trajectory::poses(back);
        let mid = tr.pose(t0 + 500_000_000);
        assert!((mid.translation.vector - Vector3::new(1.0, 2.0, 1.0)).norm() < 1e-9);
        assert!((mid.rotation.euler_angles().2 - 0.5).abs() < 1e-9);
        assert_eq!(tr.pose(t0 - 5), a);
        assert!(PoseTable::parse_tum("1 2 3").is_err());
        assert!(PoseTable::parse_tum("1.x 0 0 0 0 0 0 1").is_err());
        assert!(PoseTable::parse_tum("1 0 0 0 0 0 0 0").is_err());
    }
}
