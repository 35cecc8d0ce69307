//! Numerical inverse kinematics for any parameter set, compliance included.
//!
//! The deflection c_j·τ_j(q) depends on the configuration, so the joint-space Jacobian is
//! J_q = J_θ · (I + diag(c)·∂τ/∂q), with ∂τ/∂q exact ([`GravityModel::torques_and_jacobian`]).
//! Newton's method on the 6-D pose error (position, world rotation vector) then converges
//! quadratically from a nominal seed a few millimetres away.

use nalgebra::{DMatrix, DVector, Matrix6, Vector6};

use super::chain::{Chain, JointState};
use super::frame::{Frame, rotation_vector};
use super::gravity::GravityModel;
use super::ik_analytic::{IkError, Singularity};
use super::model::MAX_JOINTS;

/// Stopping rules of the numerical solver.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IkOptions {
    /// Converged when the position error is at most this (m)…
    pub tol_position: f64,
    /// …and the rotation error at most this (rad).
    pub tol_rotation: f64,
    /// Most steps before giving up with [`IkError::NotConverged`].
    pub max_iterations: usize,
    /// Largest joint step per iteration (rad); larger Newton steps are scaled down.
    pub max_step: f64,
}

impl Default for IkOptions {
    fn default() -> Self {
        // Well inside the 1 nm / 1 µrad contract, well above double-precision noise at 1 m.
        // Easy targets converge in 2–4 iterations; the budget is for proving a target out of reach,
        // where the damping has to grow until no step lowers the error.
        Self { tol_position: 1e-11, tol_rotation: 1e-10, max_iterations: 100, max_step: 0.2 }
    }
}

/// A converged numerical solution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IkSolution {
    /// Joint readings, rad; entries beyond `dof` are zero.
    pub q: [f64; MAX_JOINTS],
    /// Number of joints: the entries of `q` in use.
    pub dof: usize,
    /// Newton/Levenberg–Marquardt steps taken.
    pub iterations: usize,
    /// Final position error, m.
    pub residual_position: f64,
    /// Final rotation error, rad.
    pub residual_rotation: f64,
}

impl IkSolution {
    /// The solution's joints, rad: the first `dof` entries of `q`.
    pub fn joints(&self) -> &[f64] {
        &self.q[..self.dof]
    }
}

/// Length that weighs rotation errors against position errors in the merit function
/// (1 mrad ≙ 0.1 mm). Pure Newton steps do not depend on it; damped steps and the
/// "closest reachable" verdict do.
const ROTATION_WEIGHT_M: f64 = 0.1;

/// Solve `chain`'s FK(q) = `target` from `seed`. `gravity` gives τ(q) for the compliance terms.
///
/// Newton steps while they lower the merit ‖e_p‖² + (L·‖e_r‖)²; Levenberg–Marquardt damping when a
/// step would raise it (the cached Jacobian is reused, no extra forward kinematics). If the damping
/// grows without any step lowering the merit, the solver is at a local minimum of the pose error:
/// the target is out of reach from this seed, and the error says how close it got.
pub fn solve(
    chain: &Chain,
    gravity: &GravityModel,
    target: &Frame,
    seed: &[f64],
    opts: &IkOptions,
) -> Result<IkSolution, IkError> {
    solve_in(chain, gravity, target, seed, &JointState::new(&[]), opts)
}

/// [`solve`] under given conditions: the approach directions and temperature of `conditions`
/// apply to every iterate (its joints and torques are ignored).
pub(crate) fn solve_in(
    chain: &Chain,
    gravity: &GravityModel,
    target: &Frame,
    seed: &[f64],
    conditions: &JointState,
    opts: &IkOptions,
) -> Result<IkSolution, IkError> {
    let n = chain.dof();
    if target.t.iter().chain(target.r.iter()).any(|v| !v.is_finite()) {
        return Err(IkError::InvalidTarget("non-finite pose".into()));
    }
    if seed.len() < n || seed[..n].iter().any(|v| !v.is_finite()) {
        return Err(IkError::InvalidTarget("seed must have one finite value per joint".into()));
    }
    let mut q = [0.0; MAX_JOINTS];
    q[..n].copy_from_slice(&seed[..n]);
    let compliant = chain.uses_torques();

    // The last accepted point: joints, error, merit, Jacobian.
    let mut best_q = q;
    let mut best = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
    let mut best_e = Vector6::zeros();
    let mut best_j = [[0.0; 6]; MAX_JOINTS];
    let mut lambda = 0.0f64;
    let mut iterations = 0;
    loop {
        // Evaluate the pose error and the joint Jacobian at q.
        let (tau, dtau) = if compliant {
            gravity.torques_and_jacobian(&q[..n])
        } else {
            ([0.0; MAX_JOINTS], [[0.0; MAX_JOINTS]; MAX_JOINTS])
        };
        let state = JointState { q, tau, ..*conditions };
        let trace = chain.trace_scaled(&chain.joint_angles(&state), chain.length_scale(&state));
        let dp = target.t - trace.tcp.t;
        let dr = rotation_vector(&(target.r * trace.tcp.r.transpose()));
        let (ep, er) = (dp.norm(), dr.norm());
        let merit = ep * ep + (ROTATION_WEIGHT_M * er).powi(2);
        if ep <= opts.tol_position && er <= opts.tol_rotation {
            return Ok(IkSolution { q, dof: n, iterations, residual_position: ep, residual_rotation: er });
        }
        if merit < best.2 {
            best_q = q;
            best = (ep, er, merit);
            best_e = Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z);
            let jt = chain.joint_jacobian(&trace);
            // J_q[:, k] = Σ_i J_θ[:, i]·∂θ_i/∂q_k
            let d = chain.angle_jacobian(&state, &dtau);
            for k in 0..n {
                best_j[k] = [0.0; 6];
                for i in 0..n {
                    let w = d[i][k];
                    if w != 0.0 {
                        for r in 0..6 {
                            best_j[k][r] += jt[i][r] * w;
                        }
                    }
                }
            }
            lambda *= 0.1;
        } else {
            // The step raised the merit: back to the last accepted point, more damping.
            lambda = if lambda == 0.0 { 1e-6 } else { lambda * 10.0 };
            if lambda > 1e6 {
                return Err(IkError::Unreachable(format!(
                    "the closest pose this model reaches from the seed is {:.4} mm and {:.2} µrad away",
                    best.0 * 1e3,
                    best.1 * 1e6
                )));
            }
        }
        if iterations == opts.max_iterations {
            break;
        }
        iterations += 1;
        let step = damped_step(&best_j, n, &best_e, lambda).ok_or(IkError::Singular(Singularity::Jacobian))?;
        let biggest = step.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let scale = if biggest > opts.max_step { opts.max_step / biggest } else { 1.0 };
        for k in 0..n {
            q[k] = best_q[k] + step[k] * scale;
        }
    }
    Err(IkError::NotConverged { iterations, residual_mm: best.0 * 1e3, residual_urad: best.1 * 1e6 })
}

/// The step Δq: Newton (J·Δq = e) when undamped and square, otherwise the weighted
/// Levenberg–Marquardt normal equations (JᵀWJ + λ·diag(JᵀWJ) + λ·I)Δq = JᵀW·e, W weighing rotation
/// rows by L².
fn damped_step(jq: &[[f64; 6]; MAX_JOINTS], n: usize, e: &Vector6<f64>, lambda: f64) -> Option<[f64; MAX_JOINTS]> {
    let mut out = [0.0; MAX_JOINTS];
    if n == 6 && lambda == 0.0 {
        let j = Matrix6::from_fn(|r, k| jq[k][r]);
        let lu = j.lu();
        // A numerically singular square system: fall through to the damped form.
        if lu.determinant().abs() > 1e-14 {
            let x = lu.solve(e)?;
            out[..6].copy_from_slice(x.as_slice());
            return Some(out);
        }
    }
    let w = [1.0, 1.0, 1.0, ROTATION_WEIGHT_M.powi(2), ROTATION_WEIGHT_M.powi(2), ROTATION_WEIGHT_M.powi(2)];
    let mut a = DMatrix::<f64>::zeros(n, n);
    let mut b = DVector::<f64>::zeros(n);
    for i in 0..n {
        for k in 0..n {
            a[(i, k)] = (0..6).map(|r| jq[i][r] * w[r] * jq[k][r]).sum();
        }
        b[i] = (0..6).map(|r| jq[i][r] * w[r] * e[r]).sum();
    }
    let floor = 1e-12 * (0..n).map(|i| a[(i, i)]).fold(0.0, f64::max);
    for i in 0..n {
        a[(i, i)] += lambda * a[(i, i)] + lambda.max(1e-12) * floor.max(1e-18);
    }
    let x = a.cholesky()?.solve(&b);
    out[..n].copy_from_slice(x.as_slice());
    Some(out)
}
