//! SE(3) exponential, logarithm and geodesic interpolation on `nalgebra::Isometry3<f64>`.
//!
//! A twist `(v, ω)` (linear m/s, angular rad/s, both in the body frame) held for `dt` seconds
//! moves a body by `exp((v, ω)·dt)`: rotation `exp([ω·dt]×)` and translation `V(ω·dt)·v·dt`
//! with `V(φ) = I + (1 − cos θ)/θ² [φ]× + (θ − sin θ)/θ³ [φ]×²`, θ = |φ| (Barfoot, *State
//! Estimation for Robotics*, eq. 7.86 and 7.95). Interpolating two poses along the geodesic
//! `a · exp(s · log(a⁻¹ b))` reproduces a constant-twist motion exactly, where interpolating
//! rotation and translation separately would cut the chord of a turn.

use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};

/// Below this rotation angle (rad) the Taylor series replace the closed forms.
const SMALL_ANGLE: f64 = 1e-6;

fn skew(w: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -w.z, w.y, w.z, 0.0, -w.x, -w.y, w.x, 0.0)
}

/// `V(φ)`: the left Jacobian of SO(3) mapping `ρ` to the translation of `exp((ρ, φ))`.
fn left_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = phi.norm_squared();
    let k = skew(phi);
    let (a, b) = if theta2 < SMALL_ANGLE * SMALL_ANGLE {
        (0.5 - theta2 / 24.0, 1.0 / 6.0 - theta2 / 120.0)
    } else {
        let theta = theta2.sqrt();
        (
            (1.0 - theta.cos()) / theta2,
            (theta - theta.sin()) / (theta2 * theta),
        )
    };
    Matrix3::identity() + k * a + k * k * b
}

/// `V(φ)⁻¹`.
fn left_jacobian_inverse(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = phi.norm_squared();
    let k = skew(phi);
    let c = if theta2 < SMALL_ANGLE * SMALL_ANGLE {
        1.0 / 12.0 + theta2 / 720.0
    } else {
        let theta = theta2.sqrt();
        (1.0 - theta * theta.sin() / (2.0 * (1.0 - theta.cos()))) / theta2
    };
    Matrix3::identity() - k * 0.5 + k * k * c
}

/// `exp((ρ, φ))`: the pose reached from the identity by the body-frame twist `ρ` (translation
/// part, m) and `φ` (rotation vector, rad) applied for unit time.
pub fn exp(rho: &Vector3<f64>, phi: &Vector3<f64>) -> Isometry3<f64> {
    let rotation = UnitQuaternion::from_scaled_axis(*phi);
    let translation = left_jacobian(phi) * rho;
    Isometry3::from_parts(Translation3::from(translation), rotation)
}

/// `log(T) = (ρ, φ)`, the inverse of [`exp`] for rotations below π.
pub fn log(pose: &Isometry3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let phi = pose.rotation.scaled_axis();
    let rho = left_jacobian_inverse(&phi) * pose.translation.vector;
    (rho, phi)
}

/// The pose a fraction `s` of the way from `a` to `b` along the SE(3) geodesic
/// (`s` = 0 gives `a`, 1 gives `b`; values outside extrapolate at the same twist).
pub fn interpolate(a: &Isometry3<f64>, b: &Isometry3<f64>, s: f64) -> Isometry3<f64> {
    let (rho, phi) = log(&(a.inverse() * b));
    a * exp(&(rho * s), &(phi * s))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &Isometry3<f64>, b: &Isometry3<f64>, tol: f64) -> bool {
        (a.translation.vector - b.translation.vector).norm() < tol
            && a.rotation.angle_to(&b.rotation) < tol
    }

    /// A body turning at ω about z while moving forward at v traces a circle of radius v/ω:
    /// after time t it is at (r sin ωt, r (1 − cos ωt)) heading ωt.
    #[test]
    fn exp_of_a_planar_twist_is_a_circular_arc() {
        let (v, w, t) = (15.0, 60f64.to_radians(), 0.1);
        let pose = exp(
            &Vector3::new(v * t, 0.0, 0.0),
            &Vector3::new(0.0, 0.0, w * t),
        );
        let r = v / w;
        let expected = Isometry3::new(
            Vector3::new(r * (w * t).sin(), r * (1.0 - (w * t).cos()), 0.0),
            Vector3::new(0.0, 0.0, w * t),
        );
        assert!(close(&pose, &expected, 1e-12), "{pose:?}");
    }

    #[test]
    fn log_inverts_exp_including_small_angles() {
        for (rho, phi) in [
            (Vector3::new(1.0, -2.0, 0.5), Vector3::new(0.3, -0.2, 1.1)),
            (Vector3::new(0.1, 0.0, 0.0), Vector3::new(0.0, 0.0, 1e-9)),
            (Vector3::new(0.0, 3.0, 0.0), Vector3::zeros()),
        ] {
            let (r2, p2) = log(&exp(&rho, &phi));
            assert!((r2 - rho).norm() < 1e-9, "{rho:?} {r2:?}");
            assert!((p2 - phi).norm() < 1e-12, "{phi:?} {p2:?}");
        }
    }

    #[test]
    fn interpolation_follows_the_arc_not_the_chord() {
        let (v, w) = (15.0, 60f64.to_radians());
        let at = |t: f64| {
            exp(
                &Vector3::new(v * t, 0.0, 0.0),
                &Vector3::new(0.0, 0.0, w * t),
            )
        };
        let a = at(0.0);
        let b = at(1.0);
        let mid = interpolate(&a, &b, 0.5);
        assert!(close(&mid, &at(0.5), 1e-12));
        // Rotation and translation interpolated apart would land on the chord, 0.48 m off.
        let chord = 0.5 * b.translation.vector;
        assert!((chord - at(0.5).translation.vector).norm() > 0.4);
    }
}
