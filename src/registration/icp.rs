//! Iterative closest point: rigid registration of a source cloud to a target.
//!
//! Three variants ([`IcpMethod`]):
//! - **Point-to-point, closed form**: each iteration pairs every source point with its nearest
//!   target point and solves for the rigid motion in closed form (Arun et al. 1987 / Umeyama
//!   1991: SVD of the weighted cross-covariance, `R = V·diag(1, 1, det(V·Uᵀ))·Uᵀ`, so a
//!   reflection is never returned). Also available alone, with given pairs: [`kabsch`].
//! - **Point-to-point, Gauss–Newton**: the residual `T·p − q` (3 rows per pair) minimised on
//!   SE(3), as KISS-ICP does (Vizzo et al. 2023, Eq. 10-12).
//! - **Point-to-plane, Gauss–Newton**: the residual `nᵀ(T·p − q)` with the target's normal `n`
//!   (Chen & Medioni 1992).
//!
//! [`Icp::align_continuous`] registers a sweep measured while moving (continuous-time ICP,
//! after CT-ICP, Dellenbach et al. 2022): poses at the sweep's first and last points, each
//! point placed by its time along the motion between them, both estimated together.
//!
//! Gauss–Newton updates perturb the current estimate on the left, `T ← exp(δ)·T`, with the
//! twist `δ = (ρ, φ)` (translation first, m; then rotation, rad) and the exact SE(3)
//! exponential ([`se3_exp`]). Robust kernels ([`RobustKernel`]) weight each residual by
//! iteratively reweighted least squares; their scale is stated in metres of residual.
//!
//! Correspondences come from a [`NearestNeighbors`] target: [`IndexedCloud`] (a voxel hash of
//! a fixed cloud, optionally with normals) or the odometry's local map
//! ([`crate::registration::map::VoxelMap`]), both searching the 27 voxels around the query. A pair is kept
//! when the neighbour is closer than `max_correspondence_m`.
//!
//! **Honesty**: too few correspondences, an empty source or a singular system are errors
//! ([`IcpError`]), never a pose; hitting `max_iterations` returns the pose with
//! `converged = false`. The result carries the information matrix `JᵀWJ` of the last
//! iteration, expressed in the *source* frame (see [`IcpResult::information`]), for
//! degeneracy analysis.
//!
//! No I/O, no clock; working buffers are kept in [`Icp`] between calls.

use std::collections::HashMap;

use nalgebra::{Isometry3, Matrix3, Matrix6, Translation3, UnitQuaternion, Vector3, Vector6};

use crate::registration::map::smallest_eigenvector;
use crate::registration::map::voxel_key;
use crate::registration::map::BuildKeyHasher;

/// A registration parameter out of its valid range, found at construction.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RegistrationConfigError {
    /// `name` has the value `value`, which is not `expected`.
    #[error("invalid parameter {name} = {value}: expected {expected}")]
    Invalid {
        /// The parameter, as spelled in its config struct.
        name: &'static str,
        /// The value given (integers converted to `f64`).
        value: f64,
        /// What a valid value is.
        expected: &'static str,
    },
}

impl RegistrationConfigError {
    pub(crate) fn positive(name: &'static str, value: f64) -> Result<(), Self> {
        if value.is_finite() && value > 0.0 {
            Ok(())
        } else {
            Err(Self::Invalid {
                name,
                value,
                expected: "finite and > 0",
            })
        }
    }

    pub(crate) fn non_negative(name: &'static str, value: f64) -> Result<(), Self> {
        if value.is_finite() && value >= 0.0 {
            Ok(())
        } else {
            Err(Self::Invalid {
                name,
                value,
                expected: "finite and >= 0",
            })
        }
    }
}

/// A target point found for a query.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Neighbor {
    /// The target point.
    pub point: Vector3<f64>,
    /// Squared distance to the query, m².
    pub dist_sq: f64,
    /// Unit surface normal at the target point, when the target has one.
    pub normal: Option<Vector3<f64>>,
}

/// A target that answers nearest-neighbour queries.
pub trait NearestNeighbors {
    /// The nearest target point to `query` (target frame), if any is within the search
    /// neighbourhood.
    fn nearest(&self, query: &Vector3<f64>) -> Option<Neighbor>;
}

/// Which residual ICP minimises.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum IcpMethod {
    /// Point-to-point, closed-form (SVD) solve per iteration.
    PointToPoint,
    /// Point-to-point, one Gauss–Newton step on SE(3) per iteration (KISS-ICP's).
    PointToPointGaussNewton,
    /// Point-to-plane, Gauss–Newton; needs target normals (pairs without one are skipped).
    #[default]
    PointToPlane,
}

/// Robust weighting of a residual of length `r` (m).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub enum RobustKernel {
    /// Least squares: weight 1.
    #[default]
    None,
    /// Huber: weight 1 for `r ≤ scale_m`, `scale_m / r` beyond.
    Huber {
        /// Threshold between the quadratic and linear parts, m.
        scale_m: f64,
    },
    /// Geman–McClure, `ρ(r) = ½·k²r² / (k² + r²)`: weight `k⁴ / (k² + r²)²`, `k = scale_m`.
    /// (KISS-ICP's weight `σ² / (σ + r²)²` is this kernel with `k² = σ`.)
    GemanMcClure {
        /// Scale `k`, m: residuals much larger weigh little.
        scale_m: f64,
    },
}

impl RobustKernel {
    /// The IRLS weight of a residual whose squared length is `r_sq` (m²).
    #[inline]
    pub fn weight(&self, r_sq: f64) -> f64 {
        match *self {
            Self::None => 1.0,
            Self::Huber { scale_m } => {
                let r = r_sq.sqrt();
                if r <= scale_m {
                    1.0
                } else {
                    scale_m / r
                }
            }
            Self::GemanMcClure { scale_m } => {
                let k2 = scale_m * scale_m;
                let d = k2 + r_sq;
                k2 * k2 / (d * d)
            }
        }
    }

    fn validate(&self) -> Result<(), RegistrationConfigError> {
        match *self {
            Self::None => Ok(()),
            Self::Huber { scale_m } | Self::GemanMcClure { scale_m } => {
                RegistrationConfigError::positive("kernel.scale_m", scale_m)
            }
        }
    }
}

/// Parameters of [`Icp`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IcpConfig {
    /// The residual minimised.
    pub method: IcpMethod,
    /// Robust weighting.
    pub kernel: RobustKernel,
    /// Pairs farther apart than this are not correspondences, m.
    pub max_correspondence_m: f64,
    /// Iterations at most; reaching it without convergence gives `converged = false`.
    pub max_iterations: usize,
    /// Converged when the norm of an update twist `(ρ m, φ rad)` falls below this.
    pub convergence_update: f64,
    /// Fewer correspondences than this in an iteration is an error (at least 3).
    pub min_correspondences: usize,
}

impl Default for IcpConfig {
    fn default() -> Self {
        Self {
            method: IcpMethod::PointToPlane,
            kernel: RobustKernel::GemanMcClure { scale_m: 0.3 },
            max_correspondence_m: 1.0,
            max_iterations: 50,
            convergence_update: 1e-6,
            min_correspondences: 10,
        }
    }
}

/// A prior on the rotation of the result (an IMU's rotation increment composed onto the
/// previous pose, say), added to the normal equations as the residual
/// `log(R_priorᵀ·R)` with information `information` (rad⁻², rotation axes of the target
/// frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RotationPrior {
    /// The expected rotation of `target_from_source`.
    pub rotation: UnitQuaternion<f64>,
    /// Inverse covariance of the rotation error, rad⁻² (target frame axes).
    pub information: Matrix3<f64>,
}

/// Why ICP returned no pose.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum IcpError {
    /// The source cloud holds no point.
    #[error("the source cloud is empty")]
    EmptySource,
    /// Too few pairs were found within the correspondence distance.
    #[error("iteration {iteration}: {found} correspondences, at least {needed} needed")]
    TooFewCorrespondences {
        /// Iteration (from 1) at which it happened.
        iteration: usize,
        /// Pairs found.
        found: usize,
        /// Pairs required (`min_correspondences`).
        needed: usize,
    },
    /// The normal equations (or the cross-covariance) have no unique solution.
    #[error("iteration {iteration}: the system is singular (geometry constrains fewer than 6 degrees of freedom)")]
    Singular {
        /// Iteration (from 1) at which it happened.
        iteration: usize,
    },
}

/// The outcome of a registration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IcpResult {
    /// The estimated motion: `target_point = target_from_source * source_point`.
    pub target_from_source: Isometry3<f64>,
    /// Whether an update fell below `convergence_update` before `max_iterations`.
    pub converged: bool,
    /// Iterations run.
    pub iterations: usize,
    /// Correspondences in the last iteration.
    pub inliers: usize,
    /// Root mean square of the method's residual over those correspondences, m (point
    /// distance for point-to-point, distance to the plane for point-to-plane).
    pub rmse_m: f64,
    /// `JᵀWJ` of the last iteration, in the source frame: the Hessian of the cost for a
    /// right perturbation `T·exp(δ)`, `δ = (tx, ty, tz, rx, ry, rz)` (m, rad) along the
    /// source (sensor) axes. Its small eigenvalues name the directions the data do not
    /// constrain. Robust weights included; the rotation prior is not.
    pub information: Matrix6<f64>,
}

/// What holds a sweep's motion in [`Icp::align_continuous`] where its points do not: both
/// are quadratic penalties added to the normal equations (units of a point's squared
/// residual, m², so an information of `n·I` weighs like `n` points).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SweepPriors {
    /// Where the sweep starts: the previous sweep's end, say.
    pub start: Isometry3<f64>,
    /// Information of the sweep's start pose about `start` (twist `(ρ, φ)` in `start`'s
    /// frame).
    pub start_information: Matrix6<f64>,
    /// The expected motion over the sweep (`log(B⁻¹·E)`, a body twist).
    pub motion: Vector6<f64>,
    /// Information of the motion about `motion`.
    pub motion_information: Matrix6<f64>,
}

/// The outcome of [`Icp::align_continuous`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContinuousResult {
    /// The registration at the sweep's end: `target_from_source` is the end pose `E`.
    pub end: IcpResult,
    /// The pose at the sweep's start, `B`.
    pub start: Isometry3<f64>,
    /// The motion over the sweep, `log(B⁻¹·E)`.
    pub motion: Vector6<f64>,
}

type Matrix12 = nalgebra::SMatrix<f64, 12, 12>;
type Vector12 = nalgebra::SVector<f64, 12>;

/// The skew-symmetric matrix `[v]×` with `[v]×·w = v × w`.
#[inline]
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// The SE(3) exponential of a twist `(ρ, φ)` (translation m, rotation rad).
pub fn se3_exp(xi: &Vector6<f64>) -> Isometry3<f64> {
    let rho = Vector3::new(xi[0], xi[1], xi[2]);
    let phi = Vector3::new(xi[3], xi[4], xi[5]);
    let theta2 = phi.norm_squared();
    let theta = theta2.sqrt();
    let (b, c) = if theta < 1e-5 {
        (0.5 - theta2 / 24.0, 1.0 / 6.0 - theta2 / 120.0)
    } else {
        (
            (1.0 - theta.cos()) / theta2,
            (theta - theta.sin()) / (theta2 * theta),
        )
    };
    let k = skew(&phi);
    let v = Matrix3::identity() + k * b + k * k * c;
    Isometry3::from_parts(
        Translation3::from(v * rho),
        UnitQuaternion::from_scaled_axis(phi),
    )
}

/// The SE(3) logarithm: the twist `(ρ, φ)` with `se3_exp(ξ) = t` (rotation angle in [0, π]).
pub fn se3_log(t: &Isometry3<f64>) -> Vector6<f64> {
    let phi = t.rotation.scaled_axis();
    let theta2 = phi.norm_squared();
    let theta = theta2.sqrt();
    let k = skew(&phi);
    let c = if theta < 1e-5 {
        1.0 / 12.0 + theta2 / 720.0
    } else {
        (1.0 - theta * theta.sin() / (2.0 * (1.0 - theta.cos()))) / theta2
    };
    let v_inv = Matrix3::identity() - k * 0.5 + k * k * c;
    let rho = v_inv * t.translation.vector;
    Vector6::new(rho.x, rho.y, rho.z, phi.x, phi.y, phi.z)
}

/// The adjoint of `t` for twists `(ρ, φ)`: `exp(Ad·δ)·t = t·exp(δ)`.
pub fn adjoint(t: &Isometry3<f64>) -> Matrix6<f64> {
    let r = t.rotation.to_rotation_matrix().into_inner();
    let tr = skew(&t.translation.vector) * r;
    let mut ad = Matrix6::zeros();
    ad.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    ad.fixed_view_mut::<3, 3>(0, 3).copy_from(&tr);
    ad.fixed_view_mut::<3, 3>(3, 3).copy_from(&r);
    ad
}

/// The rigid motion `target_from_source` minimising `Σ wᵢ·|R·sᵢ + t − tᵢ|²` over given
/// pairs, in closed form (SVD of the weighted cross-covariance, reflection excluded).
/// `None` when the slices differ in length, fewer than 3 pairs or a total weight of 0 are
/// given, or the points are collinear (the rotation is then not unique).
pub fn kabsch(
    source: &[Vector3<f64>],
    target: &[Vector3<f64>],
    weights: Option<&[f64]>,
) -> Option<Isometry3<f64>> {
    if source.len() != target.len() || source.len() < 3 {
        return None;
    }
    if weights.is_some_and(|w| w.len() != source.len()) {
        return None;
    }
    let w = |i: usize| weights.map_or(1.0, |w| w[i]);
    let mut sw = 0.0;
    let (mut cs, mut ct) = (Vector3::zeros(), Vector3::zeros());
    for i in 0..source.len() {
        sw += w(i);
        cs += source[i] * w(i);
        ct += target[i] * w(i);
    }
    if sw.is_nan() || sw <= 0.0 {
        return None;
    }
    cs /= sw;
    ct /= sw;
    let mut h = Matrix3::zeros();
    for i in 0..source.len() {
        h += (source[i] - cs) * ((target[i] - ct) * w(i)).transpose();
    }
    rotation_from_cross_covariance(&h).map(|r| {
        let rot = UnitQuaternion::from_matrix(&r);
        Isometry3::from_parts(Translation3::from(ct - rot * cs), rot)
    })
}

/// `R = V·diag(1, 1, d)·Uᵀ`, `d = sign det(V·Uᵀ)`, from `H = Σ (s − s̄)(t − t̄)ᵀ = U·S·Vᵀ`.
fn rotation_from_cross_covariance(h: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    if !h.iter().all(|v| v.is_finite()) {
        return None;
    }
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut s = [
        svd.singular_values[0],
        svd.singular_values[1],
        svd.singular_values[2],
    ];
    s.sort_by(|a, b| b.total_cmp(a));
    // Collinear points (rank ≤ 1): the rotation about their line is free.
    if s[1].is_nan() || s[1] <= 1e-12 * s[0].max(f64::MIN_POSITIVE) {
        return None;
    }
    let v = v_t.transpose();
    let d = (v * u.transpose()).determinant().signum();
    let mut dm = Matrix3::identity();
    // The smallest singular value's column takes the sign (nalgebra sorts them descending).
    let smallest = (0..3)
        .min_by(|&a, &b| svd.singular_values[a].total_cmp(&svd.singular_values[b]))
        .unwrap_or(2);
    dm[(smallest, smallest)] = d;
    Some(v * dm * u.transpose())
}

/// Running sums from which the point-to-point normal equations are assembled (left
/// perturbation, points already transformed):
/// `JᵀWJ = [[Σw·I, −[Σw·p]×], [[Σw·p]×, Σw(|p|²I − ppᵀ)]]`, `JᵀWr = [Σw·r; Σw·p×r]`.
#[derive(Clone, Copy, Default)]
struct PointSums {
    w: f64,
    wp: Vector3<f64>,
    wpp: Matrix3<f64>,
    wr: Vector3<f64>,
    wpxr: Vector3<f64>,
}

impl PointSums {
    #[inline]
    fn add(&mut self, p: &Vector3<f64>, r: &Vector3<f64>, w: f64) {
        self.w += w;
        let wp = p * w;
        self.wp += wp;
        self.wpp += wp * p.transpose();
        self.wr += r * w;
        self.wpxr += wp.cross(r);
    }

    fn system(&self) -> (Matrix6<f64>, Vector6<f64>) {
        let mut h = Matrix6::zeros();
        let sk = skew(&self.wp);
        let trace = self.wpp.trace();
        h.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(Matrix3::identity() * self.w));
        h.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-sk));
        h.fixed_view_mut::<3, 3>(3, 0).copy_from(&sk);
        h.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&(Matrix3::identity() * trace - self.wpp));
        let g = Vector6::new(
            self.wr.x,
            self.wr.y,
            self.wr.z,
            self.wpxr.x,
            self.wpxr.y,
            self.wpxr.z,
        );
        (h, g)
    }
}

/// Rigid registration with reusable buffers. See the module documentation.
#[derive(Clone, Debug)]
pub struct Icp {
    cfg: IcpConfig,
    pairs: Vec<(Vector3<f64>, Vector3<f64>, f64)>,
    motion: Vec<(Matrix3<f64>, Vector3<f64>)>,
}

impl IcpConfig {
    /// `TooFewCorrespondences` when `found` pairs are fewer than `min_correspondences`.
    fn enough_pairs(&self, found: usize, iteration: usize) -> Result<(), IcpError> {
        if found < self.min_correspondences {
            return Err(IcpError::TooFewCorrespondences {
                iteration,
                found,
                needed: self.min_correspondences,
            });
        }
        Ok(())
    }
}

/// Samples of the motion over a sweep in [`Icp::align_continuous`].
const MOTION_STEPS: usize = 256;

impl Icp {
    /// Checks the parameters: correspondence distance > 0, kernel scale > 0, at least one
    /// iteration, a convergence bound ≥ 0 and at least 3 correspondences.
    pub fn new(cfg: IcpConfig) -> Result<Self, RegistrationConfigError> {
        RegistrationConfigError::positive("max_correspondence_m", cfg.max_correspondence_m)?;
        RegistrationConfigError::non_negative("convergence_update", cfg.convergence_update)?;
        cfg.kernel.validate()?;
        if cfg.max_iterations == 0 {
            return Err(RegistrationConfigError::Invalid {
                name: "max_iterations",
                value: 0.0,
                expected: ">= 1",
            });
        }
        if cfg.min_correspondences < 3 {
            return Err(RegistrationConfigError::Invalid {
                name: "min_correspondences",
                value: cfg.min_correspondences as f64,
                expected: ">= 3",
            });
        }
        Ok(Self {
            cfg,
            pairs: Vec::new(),
            motion: Vec::new(),
        })
    }

    /// The parameters.
    pub fn config(&self) -> &IcpConfig {
        &self.cfg
    }

    /// Changes the correspondence gate and the kernel between calls (the odometry's adaptive
    /// threshold); invalid values are rejected and leave the old ones.
    pub fn set_gate(
        &mut self,
        max_correspondence_m: f64,
        kernel: RobustKernel,
    ) -> Result<(), RegistrationConfigError> {
        RegistrationConfigError::positive("max_correspondence_m", max_correspondence_m)?;
        kernel.validate()?;
        self.cfg.max_correspondence_m = max_correspondence_m;
        self.cfg.kernel = kernel;
        Ok(())
    }

    /// Registers `source` (source frame) to `target` starting from `initial`
    /// (`target_from_source`).
    pub fn align(
        &mut self,
        source: &[Vector3<f64>],
        target: &impl NearestNeighbors,
        initial: &Isometry3<f64>,
    ) -> Result<IcpResult, IcpError> {
        self.align_with_prior(source, target, initial, None)
    }

    /// As [`Icp::align`], with an optional rotation prior in the normal equations (the
    /// Gauss–Newton methods only; the closed-form point-to-point method ignores it).
    pub fn align_with_prior(
        &mut self,
        source: &[Vector3<f64>],
        target: &impl NearestNeighbors,
        initial: &Isometry3<f64>,
        prior: Option<&RotationPrior>,
    ) -> Result<IcpResult, IcpError> {
        if source.is_empty() {
            return Err(IcpError::EmptySource);
        }
        let cfg = self.cfg;
        let gate_sq = cfg.max_correspondence_m * cfg.max_correspondence_m;
        let mut t = *initial;
        let mut info_left = Matrix6::zeros();
        let mut converged = false;
        let mut iterations = 0;
        let (mut inliers, mut sse) = (0usize, 0.0f64);
        for it in 1..=cfg.max_iterations {
            iterations = it;
            let r = t.rotation.to_rotation_matrix().into_inner();
            let tr = t.translation.vector;
            inliers = 0;
            sse = 0.0;
            let mut sums = PointSums::default();
            let mut h = Matrix6::zeros();
            let mut g = Vector6::zeros();
            self.pairs.clear();
            for p in source {
                let q = r * p + tr;
                let Some(nb) = target.nearest(&q) else {
                    continue;
                };
                if nb.dist_sq.is_nan() || nb.dist_sq >= gate_sq {
                    continue;
                }
                match cfg.method {
                    IcpMethod::PointToPoint | IcpMethod::PointToPointGaussNewton => {
                        let res = q - nb.point;
                        let w = cfg.kernel.weight(nb.dist_sq);
                        sums.add(&q, &res, w);
                        if cfg.method == IcpMethod::PointToPoint {
                            self.pairs.push((q, nb.point, w));
                        }
                        sse += nb.dist_sq;
                    }
                    IcpMethod::PointToPlane => {
                        let Some(n) = nb.normal else { continue };
                        let e = n.dot(&(q - nb.point));
                        let w = cfg.kernel.weight(e * e);
                        let jr = q.cross(&n);
                        let j = Vector6::new(n.x, n.y, n.z, jr.x, jr.y, jr.z);
                        h += j * (j.transpose() * w);
                        g += j * (w * e);
                        sse += e * e;
                    }
                }
                inliers += 1;
            }
            cfg.enough_pairs(inliers, it)?;
            if cfg.method != IcpMethod::PointToPlane {
                (h, g) = sums.system();
            }
            info_left = h;
            let update = match cfg.method {
                IcpMethod::PointToPoint => {
                    let step = self
                        .closed_form_step()
                        .ok_or(IcpError::Singular { iteration: it })?;
                    let norm = (step.translation.vector.norm_squared()
                        + step.rotation.angle().powi(2))
                    .sqrt();
                    (step, norm)
                }
                _ => {
                    if let Some(pr) = prior {
                        add_rotation_prior(&mut h, &mut g, &t, pr);
                    }
                    let chol = h.cholesky().ok_or(IcpError::Singular { iteration: it })?;
                    let dx = -chol.solve(&g);
                    if !dx.iter().all(|v| v.is_finite()) {
                        return Err(IcpError::Singular { iteration: it });
                    }
                    (se3_exp(&dx), dx.norm())
                }
            };
            t = update.0 * t;
            t.rotation.renormalize_fast();
            if update.1 < cfg.convergence_update {
                converged = true;
                break;
            }
        }
        // The information in the source frame: a left perturbation δₗ = Ad(T)·δᵣ.
        let ad = adjoint(&t);
        let information = ad.transpose() * info_left * ad;
        Ok(IcpResult {
            target_from_source: t,
            converged,
            iterations,
            inliers,
            rmse_m: (sse / inliers.max(1) as f64).sqrt(),
            information,
        })
    }

    /// Registers a sweep whose points were measured while the sensor moved: continuous-time
    /// ICP (after CT-ICP, Dellenbach et al., ICRA 2022). The sweep has two poses, at its
    /// first and last point, and the sensor moves between them with a constant twist: a
    /// source point `(p, a)` measured at the fraction `a` ∈ [0, 1] of the sweep lies at
    /// `B · exp(a·ξ) · p`, `ξ = log(B⁻¹·E)`. Both poses are estimated, `B` from `start` (the
    /// previous sweep's end, say) and `E` from `initial_end` (the prediction): each point moves
    /// with its own share of the correction, instead of the sweep being deskewed with a guessed
    /// motion and registered rigidly. [`SweepPriors`] hold `B` near the previous sweep's end
    /// and `ξ` near an expected motion where the points leave them free.
    ///
    /// Gauss–Newton on left perturbations of `B` and `E` (in the frame of `priors.start`), with the
    /// Jacobian `[(1−a)·J₀ | a·J₀]`, `J₀ = [I | −[y]×]` at the point `y` (the exact one differs
    /// by terms of the order of the sweep's rotation, a few degrees: a direction, not the
    /// residuals, which are exact). `exp(a·ξ)` is interpolated linearly between 256 samples
    /// of the motion (chord error below 1e-7 of the range for a sweep's motion). The
    /// closed-form point-to-point method runs as Gauss–Newton. The rotation prior applies to
    /// `E`. The result's information is the data's on `E` with `B` held, in the source (end)
    /// frame, as [`Icp::align`]'s.
    pub fn align_continuous(
        &mut self,
        source: &[(Vector3<f64>, f64)],
        target: &impl NearestNeighbors,
        initial_start: &Isometry3<f64>,
        initial_end: &Isometry3<f64>,
        priors: &SweepPriors,
        prior: Option<&RotationPrior>,
    ) -> Result<ContinuousResult, IcpError> {
        if source.is_empty() {
            return Err(IcpError::EmptySource);
        }
        let cfg = self.cfg;
        let gate_sq = cfg.max_correspondence_m * cfg.max_correspondence_m;
        // Work in the frame of the prior's start: B and E stay near the origin.
        let start = &priors.start;
        let rf = start.rotation.to_rotation_matrix().into_inner();
        let rft = rf.transpose();
        let tf = start.translation.vector;
        let mut b = start.inverse() * initial_start;
        let mut e = start.inverse() * initial_end;
        let mut info = Matrix6::zeros();
        let mut converged = false;
        let mut iterations = 0;
        let (mut inliers, mut sse) = (0usize, 0.0f64);
        for it in 1..=cfg.max_iterations {
            iterations = it;
            let xi = se3_log(&(b.inverse() * e));
            self.fill_motion_table(&xi);
            let rb = b.rotation.to_rotation_matrix().into_inner();
            let tb = b.translation.vector;
            inliers = 0;
            sse = 0.0;
            let (mut s_bb, mut s_be, mut s_ee) = Default::default();
            let mut h = Matrix12::zeros();
            let mut g = Vector12::zeros();
            for (p, a) in source {
                let a = if a.is_nan() { 0.0 } else { a.clamp(0.0, 1.0) };
                let y = rb * self.moved(p, a) + tb;
                let q = rf * y + tf;
                let Some(nb) = target.nearest(&q) else {
                    continue;
                };
                if nb.dist_sq.is_nan() || nb.dist_sq >= gate_sq {
                    continue;
                }
                match cfg.method {
                    IcpMethod::PointToPoint | IcpMethod::PointToPointGaussNewton => {
                        sse += nb.dist_sq;
                        // The blocks of JᵀWJ are (1−a)², a(1−a) and a² times the rigid one,
                        // those of JᵀWr (1−a) and a times: the rigid sums with scaled weights
                        // and residuals, in start's frame.
                        let w = cfg.kernel.weight(nb.dist_sq);
                        let r = rft * (q - nb.point);
                        let c = 1.0 - a;
                        if c > 1e-9 {
                            PointSums::add(&mut s_bb, &y, &(r / c), w * c * c);
                        }
                        if a > 1e-9 {
                            PointSums::add(&mut s_ee, &y, &(r / a), w * a * a);
                        }
                        PointSums::add(&mut s_be, &y, &Vector3::zeros(), w * a * c);
                    }
                    IcpMethod::PointToPlane => {
                        let Some(n) = nb.normal else { continue };
                        let res = n.dot(&(q - nb.point));
                        sse += res * res;
                        let w = cfg.kernel.weight(res * res);
                        let nf = rft * n;
                        let jr = y.cross(&nf);
                        let j0 = Vector6::new(nf.x, nf.y, nf.z, jr.x, jr.y, jr.z);
                        let mut j = Vector12::zeros();
                        j.fixed_rows_mut::<6>(0).copy_from(&(j0 * (1.0 - a)));
                        j.fixed_rows_mut::<6>(6).copy_from(&(j0 * a));
                        h += j * (j.transpose() * w);
                        g += j * (w * res);
                    }
                }
                inliers += 1;
            }
            cfg.enough_pairs(inliers, it)?;
            if cfg.method != IcpMethod::PointToPlane {
                let (hbb, gb) = s_bb.system();
                let (hee, ge) = s_ee.system();
                let (hbe, _) = s_be.system();
                h.fixed_view_mut::<6, 6>(0, 0).copy_from(&hbb);
                h.fixed_view_mut::<6, 6>(6, 6).copy_from(&hee);
                h.fixed_view_mut::<6, 6>(0, 6).copy_from(&hbe);
                h.fixed_view_mut::<6, 6>(6, 0).copy_from(&hbe);
                g.fixed_rows_mut::<6>(0).copy_from(&gb);
                g.fixed_rows_mut::<6>(6).copy_from(&ge);
            }
            info = h.fixed_view::<6, 6>(6, 6).into_owned();
            // B stays near start; the motion near the expected one.
            let rs = se3_log(&b);
            let mut hbb = h.fixed_view_mut::<6, 6>(0, 0);
            hbb += priors.start_information;
            let mut gb = g.fixed_rows_mut::<6>(0);
            gb += priors.start_information * rs;
            let rv = xi - priors.motion;
            let m = priors.motion_information;
            let mut blk = h.fixed_view_mut::<6, 6>(0, 0);
            blk += m;
            let mut blk = h.fixed_view_mut::<6, 6>(6, 6);
            blk += m;
            let mut blk = h.fixed_view_mut::<6, 6>(0, 6);
            blk -= m;
            let mut blk = h.fixed_view_mut::<6, 6>(6, 0);
            blk -= m.transpose();
            let mv = m * rv;
            let mut gb = g.fixed_rows_mut::<6>(0);
            gb -= mv;
            let mut ge = g.fixed_rows_mut::<6>(6);
            ge += mv;
            if let Some(pr) = prior {
                let mut hee: Matrix6<f64> = h.fixed_view::<6, 6>(6, 6).into_owned();
                let mut gee: Vector6<f64> = g.fixed_rows::<6>(6).into_owned();
                add_rotation_prior_in(&mut hee, &mut gee, &(start * e), pr, &rf);
                h.fixed_view_mut::<6, 6>(6, 6).copy_from(&hee);
                g.fixed_rows_mut::<6>(6).copy_from(&gee);
            }
            let chol = h.cholesky().ok_or(IcpError::Singular { iteration: it })?;
            let dx = -chol.solve(&g);
            if !dx.iter().all(|v| v.is_finite()) {
                return Err(IcpError::Singular { iteration: it });
            }
            b = se3_exp(&dx.fixed_rows::<6>(0).into_owned()) * b;
            e = se3_exp(&dx.fixed_rows::<6>(6).into_owned()) * e;
            b.rotation.renormalize_fast();
            e.rotation.renormalize_fast();
            if dx.norm() < cfg.convergence_update {
                converged = true;
                break;
            }
        }
        // A left perturbation of E in start's frame is, in the source (end) frame,
        // δ = Ad(E)·δᵣ.
        let ad = adjoint(&e);
        Ok(ContinuousResult {
            end: IcpResult {
                target_from_source: start * e,
                converged,
                iterations,
                inliers,
                rmse_m: (sse / inliers.max(1) as f64).sqrt(),
                information: ad.transpose() * info * ad,
            },
            start: start * b,
            motion: se3_log(&(b.inverse() * e)),
        })
    }

    /// Samples `exp(k/N·ξ)`, k = 0..=N, for [`Icp::moved`].
    fn fill_motion_table(&mut self, xi: &Vector6<f64>) {
        self.motion.clear();
        self.motion.extend((0..=MOTION_STEPS).map(|k| {
            let m = se3_exp(&(xi * (k as f64 / MOTION_STEPS as f64)));
            (
                m.rotation.to_rotation_matrix().into_inner(),
                m.translation.vector,
            )
        }));
    }

    /// `exp(a·ξ)·p` from the table of [`Icp::fill_motion_table`], `a` ∈ [0, 1].
    #[inline]
    fn moved(&self, p: &Vector3<f64>, a: f64) -> Vector3<f64> {
        let x = a * MOTION_STEPS as f64;
        let k = (x as usize).min(MOTION_STEPS - 1);
        let f = x - k as f64;
        let (r0, t0) = &self.motion[k];
        let (r1, t1) = &self.motion[k + 1];
        (r0 * p + t0) * (1.0 - f) + (r1 * p + t1) * f
    }

    /// Moves timed points `(p, a)` of a sweep into the frame of its end, `exp(ξ)`, with the
    /// motion `ξ` over the sweep (the deskew that matches [`Icp::align_continuous`]).
    pub fn deskew_to_end(
        &mut self,
        points: &[(Vector3<f64>, f64)],
        xi: &Vector6<f64>,
        out: &mut Vec<Vector3<f64>>,
    ) {
        self.fill_motion_table(xi);
        let end_inv = se3_exp(xi).inverse();
        let r = end_inv.rotation.to_rotation_matrix().into_inner();
        let t = end_inv.translation.vector;
        out.clear();
        out.extend(points.iter().map(|(p, a)| {
            let a = if a.is_nan() { 0.0 } else { a.clamp(0.0, 1.0) };
            r * self.moved(p, a) + t
        }));
    }

    /// The weighted closed-form motion taking the paired (already transformed) source points
    /// onto their targets.
    fn closed_form_step(&self) -> Option<Isometry3<f64>> {
        let mut sw = 0.0;
        let (mut cs, mut ct) = (Vector3::zeros(), Vector3::zeros());
        for (s, t, w) in &self.pairs {
            sw += w;
            cs += s * *w;
            ct += t * *w;
        }
        if sw.is_nan() || sw <= 0.0 {
            return None;
        }
        cs /= sw;
        ct /= sw;
        let mut h = Matrix3::zeros();
        for (s, t, w) in &self.pairs {
            h += (s - cs) * ((t - ct) * *w).transpose();
        }
        let r = rotation_from_cross_covariance(&h)?;
        let rot = UnitQuaternion::from_matrix(&r);
        Some(Isometry3::from_parts(
            Translation3::from(ct - rot * cs),
            rot,
        ))
    }
}

/// Adds `log(R_priorᵀ·R)` with its information to the normal equations of a left
/// perturbation: `R ← exp(φ)·R` changes the residual by `R_priorᵀ·φ` to first order.
fn add_rotation_prior(
    h: &mut Matrix6<f64>,
    g: &mut Vector6<f64>,
    t: &Isometry3<f64>,
    prior: &RotationPrior,
) {
    add_rotation_prior_in(h, g, t, prior, &Matrix3::identity());
}

/// As [`add_rotation_prior`] for a perturbation `φ` expressed in a frame rotated by `frame`
/// from the target's: `R ← exp(frame·φ)·R`.
fn add_rotation_prior_in(
    h: &mut Matrix6<f64>,
    g: &mut Vector6<f64>,
    t: &Isometry3<f64>,
    prior: &RotationPrior,
    frame: &Matrix3<f64>,
) {
    let e0 = (prior.rotation.inverse() * t.rotation).scaled_axis();
    let a = prior.rotation.inverse().to_rotation_matrix().into_inner() * frame;
    let at_l = a.transpose() * prior.information;
    let hr = at_l * a;
    let gr = at_l * e0;
    let mut blk = h.fixed_view_mut::<3, 3>(3, 3);
    blk += hr;
    let mut gb = g.fixed_view_mut::<3, 1>(3, 0);
    gb += gr;
}

/// A fixed target cloud in a voxel hash, with optional normals (for point-to-plane).
#[derive(Clone, Debug)]
pub struct IndexedCloud {
    voxel_size_m: f64,
    points: Vec<Vector3<f64>>,
    normals: Vec<Option<Vector3<f64>>>,
    /// Indices into `points`, grouped by voxel.
    order: Vec<u32>,
    cells: HashMap<u64, (u32, u32), BuildKeyHasher>,
}

impl IndexedCloud {
    /// Indexes `points` in voxels of edge `voxel_size_m` (the nearest-neighbour search covers
    /// the 27 voxels around a query). Non-finite points are kept but never found.
    pub fn new(
        points: Vec<Vector3<f64>>,
        voxel_size_m: f64,
    ) -> Result<Self, RegistrationConfigError> {
        RegistrationConfigError::positive("voxel_size_m", voxel_size_m)?;
        let mut keyed: Vec<(u64, u32)> = points
            .iter()
            .enumerate()
            .filter_map(|(i, p)| voxel_key(p, voxel_size_m).map(|k| (k, i as u32)))
            .collect();
        keyed.sort_unstable();
        let mut cells = HashMap::with_capacity_and_hasher(keyed.len(), BuildKeyHasher);
        let mut start = 0usize;
        while start < keyed.len() {
            let key = keyed[start].0;
            let mut end = start + 1;
            while end < keyed.len() && keyed[end].0 == key {
                end += 1;
            }
            cells.insert(key, (start as u32, (end - start) as u32));
            start = end;
        }
        let n = points.len();
        Ok(Self {
            voxel_size_m,
            points,
            normals: vec![None; n],
            order: keyed.into_iter().map(|(_, i)| i).collect(),
            cells,
        })
    }

    /// The points.
    pub fn points(&self) -> &[Vector3<f64>] {
        &self.points
    }

    /// The normals (after [`IndexedCloud::estimate_normals`]), `None` where the
    /// neighbourhood is not planar.
    pub fn normals(&self) -> &[Option<Vector3<f64>>] {
        &self.normals
    }

    fn for_each_near(&self, q: &Vector3<f64>, mut f: impl FnMut(u32)) {
        let inv = 1.0 / self.voxel_size_m;
        let base = [
            (q.x * inv).floor(),
            (q.y * inv).floor(),
            (q.z * inv).floor(),
        ];
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let c = Vector3::new(
                        (base[0] + f64::from(dx) + 0.5) * self.voxel_size_m,
                        (base[1] + f64::from(dy) + 0.5) * self.voxel_size_m,
                        (base[2] + f64::from(dz) + 0.5) * self.voxel_size_m,
                    );
                    let Some(key) = voxel_key(&c, self.voxel_size_m) else {
                        continue;
                    };
                    if let Some(&(s, n)) = self.cells.get(&key) {
                        for &i in &self.order[s as usize..(s + n) as usize] {
                            f(i);
                        }
                    }
                }
            }
        }
    }

    /// Estimates a normal at every point from its neighbours within `voxel_size_m`
    /// (principal component analysis): kept when at least `min_neighbors` points are found
    /// and the smallest variance is below `max_flatness` (0..1) times the middle one.
    pub fn estimate_normals(&mut self, min_neighbors: usize, max_flatness: f64) {
        let r2 = self.voxel_size_m * self.voxel_size_m;
        let mut normals = vec![None; self.points.len()];
        for (i, p) in self.points.iter().enumerate() {
            let (mut n, mut sum, mut outer) = (0usize, Vector3::zeros(), Matrix3::zeros());
            self.for_each_near(p, |j| {
                let q = self.points[j as usize];
                if (q - p).norm_squared() <= r2 {
                    n += 1;
                    let d = q - p; // centred on p for precision
                    sum += d;
                    outer += d * d.transpose();
                }
            });
            if n < min_neighbors.max(3) {
                continue;
            }
            let mean = sum / n as f64;
            let cov = outer / n as f64 - mean * mean.transpose();
            if let Some((normal, ev)) = smallest_eigenvector(&cov) {
                if ev[0] <= max_flatness * ev[1] && ev[1] > 0.0 {
                    normals[i] = Some(normal);
                }
            }
        }
        self.normals = normals;
    }
}

impl NearestNeighbors for IndexedCloud {
    fn nearest(&self, query: &Vector3<f64>) -> Option<Neighbor> {
        let mut best: Option<(u32, f64)> = None;
        self.for_each_near(query, |i| {
            let d = (self.points[i as usize] - query).norm_squared();
            if best.is_none_or(|(_, b)| d < b) {
                best = Some((i, d));
            }
        });
        best.map(|(i, d)| Neighbor {
            point: self.points[i as usize],
            dist_sq: d,
            normal: self.normals[i as usize],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
        fn range(&mut self, a: f64, b: f64) -> f64 {
            a + (b - a) * self.next()
        }
    }

    fn iso(t: [f64; 3], axis: [f64; 3], angle_deg: f64) -> Isometry3<f64> {
        let ax = Vector3::new(axis[0], axis[1], axis[2]).normalize();
        Isometry3::from_parts(
            Translation3::new(t[0], t[1], t[2]),
            UnitQuaternion::from_scaled_axis(ax * angle_deg.to_radians()),
        )
    }

    fn pose_error(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
        let d = a.inverse() * b;
        (d.translation.vector.norm(), d.rotation.angle())
    }

    /// A room 10 × 8 × 3 m with a box and a slanted panel, sampled on a 0.2 m grid: planes
    /// in every direction, so all six degrees of freedom are constrained.
    fn room() -> Vec<Vector3<f64>> {
        let mut pts = Vec::new();
        let step = 0.2;
        let grid = |a0: f64, a1: f64, b0: f64, b1: f64, f: &mut dyn FnMut(f64, f64)| {
            let (na, nb) = (((a1 - a0) / step) as i32, ((b1 - b0) / step) as i32);
            for i in 0..=na {
                for j in 0..=nb {
                    f(a0 + f64::from(i) * step, b0 + f64::from(j) * step);
                }
            }
        };
        grid(-5.0, 5.0, -4.0, 4.0, &mut |x, y| {
            pts.push(Vector3::new(x, y, 0.0))
        });
        grid(-4.0, 4.0, 0.1, 3.0, &mut |y, z| {
            pts.push(Vector3::new(5.0, y, z))
        });
        grid(-5.0, 5.0, 0.1, 3.0, &mut |x, z| {
            pts.push(Vector3::new(x, 4.0, z))
        });
        grid(-5.0, 5.0, 0.1, 3.0, &mut |x, z| {
            pts.push(Vector3::new(x, -4.0, z))
        });
        // Box 1 × 1 × 1 at (1.5, 1.0).
        grid(1.0, 2.0, 0.5, 1.5, &mut |x, y| {
            pts.push(Vector3::new(x, y, 1.0))
        });
        grid(0.5, 1.5, 0.1, 1.0, &mut |y, z| {
            pts.push(Vector3::new(1.0, y, z))
        });
        grid(1.0, 2.0, 0.1, 1.0, &mut |x, z| {
            pts.push(Vector3::new(x, 0.5, z))
        });
        // A panel tilted 30° about x, at x ∈ [-3, -1].
        grid(-3.0, -1.0, 0.0, 1.5, &mut |x, s| {
            pts.push(Vector3::new(x, -2.0 + s * 0.866, 0.2 + s * 0.5))
        });
        pts
    }

    /// Random points on curved surfaces (a sphere and a wavy terrain): no sliding direction.
    fn blob(n: usize, seed: u64) -> Vec<Vector3<f64>> {
        let mut rng = Lcg(seed);
        let mut pts = Vec::new();
        for _ in 0..n / 2 {
            let (u, v) = (rng.range(0.0, std::f64::consts::TAU), rng.range(-1.0, 1.0));
            let s = (1.0 - v * v).sqrt();
            pts.push(Vector3::new(
                1.5 * s * u.cos() + 2.0,
                1.5 * s * u.sin(),
                1.5 * v + 1.0,
            ));
        }
        for _ in 0..n / 2 {
            let (x, y) = (rng.range(-4.0, 4.0), rng.range(-4.0, 4.0));
            pts.push(Vector3::new(x, y, 0.3 * (x * 1.3).sin() * (y * 0.9).cos()));
        }
        pts
    }

    fn transformed(pts: &[Vector3<f64>], t: &Isometry3<f64>) -> Vec<Vector3<f64>> {
        pts.iter()
            .map(|p| t * nalgebra::Point3::from(*p))
            .map(|p| p.coords)
            .collect()
    }

    #[test]
    fn se3_exp_and_log_are_inverse() {
        for xi in [
            Vector6::new(0.1, -0.2, 0.3, 0.0, 0.0, 0.0),
            Vector6::new(1.0, 2.0, -3.0, 0.3, -0.2, 0.9),
            Vector6::new(0.0, 0.0, 1.0, 0.0, 0.0, 3.0),
            Vector6::new(0.5, 0.0, 0.0, 1e-7, 0.0, -2e-7),
        ] {
            let back = se3_log(&se3_exp(&xi));
            assert!((back - xi).norm() < 1e-12, "{xi} -> {back}");
        }
        // exp of a pure rotation about z applied to a translation twist: the screw motion
        // (hand-derived: a quarter turn with ρ = (π/2, 0, 0) ends at (1, 1, 0)).
        let t = se3_exp(&Vector6::new(
            std::f64::consts::FRAC_PI_2,
            0.0,
            0.0,
            0.0,
            0.0,
            std::f64::consts::FRAC_PI_2,
        ));
        assert!((t.translation.vector - Vector3::new(1.0, 1.0, 0.0)).norm() < 1e-12);
    }

    #[test]
    fn adjoint_moves_a_right_perturbation_to_the_left() {
        let t = iso([1.0, -2.0, 0.5], [0.3, 1.0, -0.2], 40.0);
        let d = Vector6::new(0.01, 0.02, -0.03, 0.02, -0.01, 0.015);
        let left = se3_exp(&(adjoint(&t) * d)) * t;
        let right = t * se3_exp(&d);
        let (et, er) = pose_error(&left, &right);
        assert!(et < 1e-12 && er < 1e-12);
    }

    #[test]
    fn kabsch_recovers_large_rotations_exactly() {
        let mut rng = Lcg(7);
        let src: Vec<_> = (0..50)
            .map(|_| {
                Vector3::new(
                    rng.range(-5.0, 5.0),
                    rng.range(-5.0, 5.0),
                    rng.range(-2.0, 2.0),
                )
            })
            .collect();
        for t in [
            iso([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 90.0),
            iso([3.0, -1.0, 0.5], [1.0, 1.0, 0.0], 135.0),
            iso([-10.0, 20.0, 1.0], [0.2, -0.5, 1.0], 179.9),
            iso([1.0, 2.0, 3.0], [1.0, 0.0, 0.0], 180.0),
            iso([0.1, 0.0, 0.0], [0.0, 1.0, 0.0], -60.0),
        ] {
            let dst = transformed(&src, &t);
            let got = kabsch(&src, &dst, None).unwrap();
            let (et, er) = pose_error(&got, &t);
            assert!(et < 1e-9 && er < 1e-9, "{t:?}: {et} m {er} rad");
        }
    }

    #[test]
    fn kabsch_never_returns_a_reflection() {
        // Coplanar points: the cross-covariance has rank 2 and the unconstrained SVD solution
        // can be a reflection; the determinant correction must give the rotation.
        let src: Vec<_> = (0..20)
            .map(|i| Vector3::new(f64::from(i % 5), f64::from(i / 5) * 0.7, 0.0))
            .collect();
        let t = iso([0.5, -0.5, 2.0], [1.0, -2.0, 0.5], 120.0);
        let dst = transformed(&src, &t);
        let got = kabsch(&src, &dst, None).unwrap();
        let r = got.rotation.to_rotation_matrix().into_inner();
        assert!((r.determinant() - 1.0).abs() < 1e-12);
        let (et, er) = pose_error(&got, &t);
        assert!(et < 1e-9 && er < 1e-9, "{et} {er}");
        // Mirror image: the best rotation is not the reflection.
        let mirrored: Vec<_> = dst.iter().map(|p| Vector3::new(p.x, p.y, -p.z)).collect();
        let m = kabsch(&src, &mirrored, None).unwrap();
        assert!((m.rotation.to_rotation_matrix().into_inner().determinant() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn kabsch_refuses_collinear_or_too_few_points() {
        let line: Vec<_> = (0..10)
            .map(|i| Vector3::new(f64::from(i), 0.0, 0.0))
            .collect();
        assert!(kabsch(&line, &line, None).is_none());
        assert!(kabsch(&line[..2], &line[..2], None).is_none());
        assert!(kabsch(&line[..3], &line[..4], None).is_none());
        assert!(kabsch(&line[..3], &line[..3], Some(&[0.0, 0.0, 0.0])).is_none());
    }

    fn exact_cfg(method: IcpMethod) -> IcpConfig {
        IcpConfig {
            method,
            kernel: RobustKernel::None,
            max_correspondence_m: 1.0,
            max_iterations: 200,
            convergence_update: 1e-10,
            min_correspondences: 10,
        }
    }

    #[test]
    fn point_to_point_recovers_known_transforms_on_exact_data() {
        let target_pts = blob(3000, 3);
        let target = IndexedCloud::new(target_pts.clone(), 0.5).unwrap();
        for method in [IcpMethod::PointToPoint, IcpMethod::PointToPointGaussNewton] {
            let mut icp = Icp::new(exact_cfg(method)).unwrap();
            for truth in [
                iso([0.05, -0.03, 0.02], [0.0, 0.0, 1.0], 2.0),
                iso([-0.1, 0.05, 0.0], [1.0, 0.5, 0.2], 3.0),
                iso([0.0, 0.0, 0.08], [0.0, 1.0, 0.0], -2.5),
            ] {
                // The source is the target seen from `truth`: target = truth · source.
                let source = transformed(&target_pts, &truth.inverse());
                let res = icp.align(&source, &target, &Isometry3::identity()).unwrap();
                let (et, er) = pose_error(&res.target_from_source, &truth);
                assert!(res.converged, "{method:?} {truth:?}");
                assert!(et < 1e-6 && er < 1e-6, "{method:?}: {et} m, {er} rad");
                assert!(res.rmse_m < 1e-6);
                assert_eq!(res.inliers, source.len());
            }
        }
    }

    #[test]
    fn point_to_plane_recovers_known_transforms_on_exact_data() {
        let target_pts = room();
        let mut target = IndexedCloud::new(target_pts.clone(), 0.5).unwrap();
        target.estimate_normals(6, 0.05);
        for kernel in [
            RobustKernel::None,
            RobustKernel::GemanMcClure { scale_m: 0.2 },
            RobustKernel::Huber { scale_m: 0.1 },
        ] {
            let mut icp = Icp::new(IcpConfig {
                kernel,
                ..exact_cfg(IcpMethod::PointToPlane)
            })
            .unwrap();
            for truth in [
                iso([0.2, -0.1, 0.05], [0.0, 0.0, 1.0], 4.0),
                iso([-0.15, 0.2, -0.05], [0.3, -0.2, 1.0], -6.0),
                iso([0.0, 0.25, 0.1], [1.0, 0.0, 0.2], 2.0),
            ] {
                let source = transformed(&target_pts, &truth.inverse());
                let res = icp.align(&source, &target, &Isometry3::identity()).unwrap();
                let (et, er) = pose_error(&res.target_from_source, &truth);
                assert!(res.converged);
                assert!(et < 1e-6 && er < 1e-6, "{kernel:?}: {et} m, {er} rad");
                assert!(res.iterations < 50);
            }
        }
    }

    #[test]
    fn continuous_time_recovers_the_motion_within_a_sweep_on_exact_data() {
        // A sweep measured while moving: the point seen at the fraction a of the sweep lies at
        // start·exp(a·ξ)·p. Registered rigidly the sweep is smeared; continuous-time ICP must
        // recover the end pose from a prediction that is off.
        let mut rng = Lcg(5);
        for (method, world, cell) in [
            (IcpMethod::PointToPointGaussNewton, blob(4000, 9), 0.5),
            (IcpMethod::PointToPlane, room(), 0.5),
        ] {
            let mut target = IndexedCloud::new(world.clone(), cell).unwrap();
            target.estimate_normals(6, 0.05);
            let mut icp = Icp::new(exact_cfg(method)).unwrap();
            let start = iso([0.3, -0.2, 0.1], [0.1, 0.2, 1.0], 20.0);
            let xi = Vector6::new(0.4, 0.1, -0.02, 0.005, -0.01, 0.1);
            let end = start * se3_exp(&xi);
            let source: Vec<(Vector3<f64>, f64)> = world
                .iter()
                .map(|w| {
                    let a = rng.next();
                    let pose = start * se3_exp(&(xi * a));
                    ((pose.inverse() * nalgebra::Point3::from(*w)).coords, a)
                })
                .collect();
            let initial = start * se3_exp(&(xi * 0.7));
            // The start given is off too, and the priors (weak) pull towards the wrong values.
            let start_guess = start * se3_exp(&Vector6::new(0.02, -0.01, 0.0, 0.0, 0.001, -0.002));
            let priors = SweepPriors {
                start: start_guess,
                start_information: Matrix6::identity() * 1e-6,
                motion: xi * 0.7,
                motion_information: Matrix6::identity() * 1e-6,
            };
            let ct = icp
                .align_continuous(&source, &target, &start_guess, &initial, &priors, None)
                .unwrap();
            let res = ct.end;
            let (et, er) = pose_error(&res.target_from_source, &end);
            assert!(res.converged, "{method:?}");
            let (bt, br) = pose_error(&ct.start, &start);
            assert!(bt < 1e-6 && br < 1e-6, "{method:?}: start {bt} m, {br} rad");
            // The motion table's chord error bounds it (a few 1e-7 here), not the solver.
            assert!(et < 1e-6 && er < 1e-6, "{method:?}: {et} m, {er} rad");
            // Deskewed with the motion found, the sweep is the world seen from the end pose.
            let mut out = Vec::new();
            icp.deskew_to_end(&source, &ct.motion, &mut out);
            let worst = out
                .iter()
                .zip(&world)
                .map(|(p, w)| ((end * nalgebra::Point3::from(*p)).coords - w).norm())
                .fold(0.0, f64::max);
            assert!(worst < 1e-6, "{method:?}: deskewed {worst} m off");
            // Rigid ICP on the smeared sweep cannot do as well.
            let smeared: Vec<_> = source.iter().map(|p| p.0).collect();
            let rigid = icp.align(&smeared, &target, &initial).unwrap();
            assert!(pose_error(&rigid.target_from_source, &end).0 > 1e-3);
        }
    }

    #[test]
    fn information_is_expressed_in_the_source_frame() {
        // Point-to-point, no kernel, at the exact solution every source point p is paired
        // (w = 1), so JᵀJ = Σ [I, −[p]×]ᵀ[I, −[p]×] with p in the source frame.
        let target_pts = blob(2000, 11);
        let target = IndexedCloud::new(target_pts.clone(), 0.5).unwrap();
        let truth = iso([3.0, -2.0, 1.0], [0.2, 0.1, 1.0], 3.0);
        let source = transformed(&target_pts, &truth.inverse());
        let mut icp = Icp::new(exact_cfg(IcpMethod::PointToPointGaussNewton)).unwrap();
        let res = icp.align(&source, &target, &truth).unwrap();
        let mut naive = Matrix6::zeros();
        for p in &source {
            let mut j = nalgebra::Matrix3x6::zeros();
            j.fixed_view_mut::<3, 3>(0, 0)
                .copy_from(&Matrix3::identity());
            j.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-skew(p)));
            naive += j.transpose() * j;
        }
        let rel = (res.information - naive).norm() / naive.norm();
        assert!(rel < 1e-9, "relative difference {rel}");
    }

    #[test]
    fn continuous_time_reports_failures_and_survives_hostile_input() {
        let target = IndexedCloud::new(room(), 0.5).unwrap();
        let mut icp = Icp::new(exact_cfg(IcpMethod::PointToPointGaussNewton)).unwrap();
        let id = Isometry3::identity();
        let priors = SweepPriors {
            start: id,
            start_information: Matrix6::identity(),
            motion: Vector6::zeros(),
            motion_information: Matrix6::identity(),
        };
        assert_eq!(
            icp.align_continuous(&[], &target, &id, &id, &priors, None),
            Err(IcpError::EmptySource)
        );
        // Far from the target: no pair, an error, not a pose.
        let far: Vec<_> = room()
            .iter()
            .map(|p| (p + Vector3::new(100.0, 0.0, 0.0), 0.5))
            .collect();
        assert!(matches!(
            icp.align_continuous(&far, &target, &id, &id, &priors, None),
            Err(IcpError::TooFewCorrespondences { found: 0, .. })
        ));
        // Non-finite points and fractions (NaN, ±inf, outside [0, 1]) among good ones: the
        // fractions are clamped (NaN as 0), the bad points find no pair; a pose or an error,
        // never a panic, and a pose is finite.
        let mut mixed: Vec<(Vector3<f64>, f64)> = room().iter().map(|p| (*p, 0.5)).collect();
        for (i, a) in [f64::NAN, f64::INFINITY, -3.0, 7.0, f64::NEG_INFINITY]
            .into_iter()
            .enumerate()
        {
            mixed[i * 7].1 = a;
            mixed.push((Vector3::new(f64::NAN, 1.0, 1.0), a));
            mixed.push((Vector3::new(f64::INFINITY, 0.0, 0.0), 0.5));
        }
        match icp.align_continuous(&mixed, &target, &id, &id, &priors, None) {
            Ok(r) => {
                assert!(r
                    .end
                    .target_from_source
                    .translation
                    .vector
                    .iter()
                    .all(|v| v.is_finite()));
                assert!(r.motion.iter().all(|v| v.is_finite()));
            }
            Err(e) => assert!(!matches!(e, IcpError::EmptySource), "{e}"),
        }
        let mut out = Vec::new();
        icp.deskew_to_end(
            &mixed,
            &Vector6::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.1),
            &mut out,
        );
        assert_eq!(out.len(), mixed.len());
    }

    #[test]
    fn too_few_correspondences_is_an_error_not_a_pose() {
        let target = IndexedCloud::new(room(), 0.5).unwrap();
        let far: Vec<_> = room()
            .iter()
            .map(|p| p + Vector3::new(100.0, 0.0, 0.0))
            .collect();
        let mut icp = Icp::new(exact_cfg(IcpMethod::PointToPointGaussNewton)).unwrap();
        let err = icp
            .align(&far, &target, &Isometry3::identity())
            .unwrap_err();
        assert!(matches!(
            err,
            IcpError::TooFewCorrespondences {
                iteration: 1,
                found: 0,
                needed: 10
            }
        ));
        assert_eq!(
            icp.align(&[], &target, &Isometry3::identity()),
            Err(IcpError::EmptySource)
        );
        // Point-to-plane without normals has no usable pair.
        let mut p2l = Icp::new(exact_cfg(IcpMethod::PointToPlane)).unwrap();
        assert!(matches!(
            p2l.align(&room(), &target, &Isometry3::identity()),
            Err(IcpError::TooFewCorrespondences { found: 0, .. })
        ));
    }

    #[test]
    fn hitting_max_iterations_is_reported() {
        let target_pts = blob(4000, 5);
        let target = IndexedCloud::new(target_pts.clone(), 0.5).unwrap();
        let truth = iso([0.1, 0.05, 0.0], [0.0, 0.0, 1.0], 3.0);
        let source = transformed(&target_pts, &truth.inverse());
        let mut icp = Icp::new(IcpConfig {
            max_iterations: 2,
            ..exact_cfg(IcpMethod::PointToPoint)
        })
        .unwrap();
        let res = icp.align(&source, &target, &Isometry3::identity()).unwrap();
        assert!(!res.converged);
        assert_eq!(res.iterations, 2);
    }

    #[test]
    fn singular_geometry_is_an_error() {
        // Points on one line: the rotation about the line is unobservable.
        let line: Vec<_> = (0..100)
            .map(|i| Vector3::new(f64::from(i) * 0.05, 0.0, 0.0))
            .collect();
        let target = IndexedCloud::new(line.clone(), 0.5).unwrap();
        let mut icp = Icp::new(exact_cfg(IcpMethod::PointToPointGaussNewton)).unwrap();
        assert!(matches!(
            icp.align(&line, &target, &Isometry3::identity()),
            Err(IcpError::Singular { iteration: 1 })
        ));
        let mut svd = Icp::new(exact_cfg(IcpMethod::PointToPoint)).unwrap();
        assert!(matches!(
            svd.align(&line, &target, &Isometry3::identity()),
            Err(IcpError::Singular { iteration: 1 })
        ));
    }

    #[test]
    fn rotation_prior_pulls_the_rotation() {
        let target_pts = room();
        let mut target = IndexedCloud::new(target_pts.clone(), 0.5).unwrap();
        target.estimate_normals(6, 0.05);
        let truth = iso([0.1, -0.1, 0.0], [0.0, 0.0, 1.0], 3.0);
        let source = transformed(&target_pts, &truth.inverse());
        let mut icp = Icp::new(exact_cfg(IcpMethod::PointToPlane)).unwrap();
        // A prior that agrees with the data changes nothing.
        let agree = RotationPrior {
            rotation: truth.rotation,
            information: Matrix3::identity() * 1e4,
        };
        let res = icp
            .align_with_prior(&source, &target, &Isometry3::identity(), Some(&agree))
            .unwrap();
        let (et, er) = pose_error(&res.target_from_source, &truth);
        assert!(et < 1e-6 && er < 1e-6);
        // An overwhelming prior 1° away wins over the data.
        let off = UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.0, 1f64.to_radians()))
            * truth.rotation;
        let strong = RotationPrior {
            rotation: off,
            information: Matrix3::identity() * 1e14,
        };
        let res = icp
            .align_with_prior(&source, &target, &Isometry3::identity(), Some(&strong))
            .unwrap();
        assert!(res.target_from_source.rotation.angle_to(&off) < 1e-5);
    }

    #[test]
    fn bad_config_is_rejected() {
        let d = IcpConfig::default();
        assert!(Icp::new(IcpConfig {
            max_correspondence_m: 0.0,
            ..d
        })
        .is_err());
        assert!(Icp::new(IcpConfig {
            max_iterations: 0,
            ..d
        })
        .is_err());
        assert!(Icp::new(IcpConfig {
            min_correspondences: 2,
            ..d
        })
        .is_err());
        assert!(Icp::new(IcpConfig {
            convergence_update: f64::NAN,
            ..d
        })
        .is_err());
        assert!(Icp::new(IcpConfig {
            kernel: RobustKernel::Huber { scale_m: -1.0 },
            ..d
        })
        .is_err());
    }
}
