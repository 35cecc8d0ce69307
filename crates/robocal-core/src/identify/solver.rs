//! Iterative linearised least squares (thesis §4.2.1, eq. 4.12–4.21) with Levenberg–Marquardt
//! damping whenever a Gauss–Newton step does not lower the cost.
//!
//! Each step solves min ‖J_s·y − r‖² (+ λ‖y‖²) on the column-scaled Jacobian J_s = J·D⁻¹ (unit
//! columns), then Δρ = D⁻¹·y. The step comes from the normal equations (J_sᵀJ_s + λI)·y = J_sᵀr:
//! JᵀJ and Jᵀr are formed over row blocks in parallel and factored by Cholesky — a tall J of
//! 15,000 × 23 costs n·m² flops there against 2·n·m² for its QR, and the scaled columns keep
//! κ(J_sᵀJ_s) = κ(J_s)² near 1e4, harmless in f64. When a Cholesky pivot falls below 1e-10 (κ(J_s)
//! above ~1e5) the step is taken from the QR of J_s ([J_s; √λ·I] when damped) instead, so an
//! ill-conditioned or rank-deficient problem gets the accuracy of QR and is reported by it. Stops
//! when the scaled step (the change it makes to the model, in metres) is below `step_tol` or the
//! relative cost change below `cost_tol`. An optional Huber loss re-weights whole measurements
//! (iteratively reweighted least squares) and reports the ones it down-weighted.

use faer::Mat;
use faer::linalg::solvers::{DenseSolveCore, Solve, SolveLstsq};

use super::problem::Problem;

/// Settings of `solve`: iteration limit, convergence tests, robust loss.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolverOptions {
    /// Iterations before [`SolveError::IterationLimit`].
    pub max_iterations: usize,
    /// Converged when the largest scaled step component is at most this (m).
    pub step_tol: f64,
    /// …or when an accepted step lowers the cost by less than this fraction.
    pub cost_tol: f64,
    /// …or when the Gauss–Newton step would move the parameters by at most this many of their
    /// own standard deviations (jointly, in the metric of their covariance σ̂²(JᵀJ)⁻¹, with σ̂²
    /// the residual variance of the data themselves). On real data the residual is 10–30 times
    /// the instrument's noise and a flat direction of the cost takes steps that change nothing
    /// anyone could measure: a cost-ratio rule never fires there, this one does.
    pub sigma_tol: f64,
    /// Huber threshold in robust standard deviations per axis; `None` = plain least squares.
    pub huber: Option<f64>,
}

impl Default for SolverOptions {
    fn default() -> Self {
        Self { max_iterations: 100, step_tol: 1e-13, cost_tol: 1e-12, sigma_tol: 1e-3, huber: None }
    }
}

/// Why a fit did not converge.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    /// The cost or a step became non-finite, or no damped step (λ up to 10¹⁰) lowers the cost.
    #[error("diverged at iteration {iteration}: {reason}")]
    Diverged {
        /// The iteration it happened at.
        iteration: usize,
        /// What happened.
        reason: String,
        /// The last accepted iterate (global parameter vector), where the fit stopped.
        last: Vec<f64>,
    },
    /// `max_iterations` reached without meeting a convergence test.
    #[error(
        "no convergence in {iterations} iterations (last scaled step {step_m:.3e} m, relative cost change {cost_change:.3e}; the step still moves {} by {:.2} of its standard deviation): {}",
        moving.first().map_or("no parameter", |m| m.0.as_str()), moving.first().map_or(0.0, |m| m.1), advice(moving)
    )]
    IterationLimit {
        /// The iterations made (`max_iterations`).
        iterations: usize,
        /// The last step: its largest scaled component, m (compared with `step_tol`).
        step_m: f64,
        /// The last step's relative cost decrease (compared with `cost_tol`).
        cost_change: f64,
        /// The free parameters the last Gauss–Newton step moved most, in units of their own
        /// standard deviation (name, |step|/σ), largest first (at most 4).
        moving: Vec<(String, f64)>,
        /// The last iterate (global parameter vector).
        last: Vec<f64>,
    },
}

/// What to try when a fit keeps moving.
fn advice(moving: &[(String, f64)]) -> String {
    let names: Vec<&str> = moving.iter().map(|m| m.0.as_str()).collect();
    if names.is_empty() {
        return "the cost keeps falling without a direction standing out; allow more iterations".into();
    }
    format!(
        "these data barely determine {}: hold them fixed, give a guess of the base and of the TCPs, or measure poses that vary them more",
        names.join(", ")
    )
}

/// A converged fit.
#[derive(Clone, Debug)]
pub struct Fit {
    /// Global parameter vector.
    pub x: Vec<f64>,
    /// Iterations made.
    pub iterations: usize,
    /// Final (weighted) residual and Jacobian of the free parameters, unscaled (SI).
    pub residual: Vec<f64>,
    /// (rows of the stacked system) × (free parameters, in the order of `solve`'s `free`).
    pub jacobian: Mat<f64>,
    /// Robust weight of each observation (1 = full weight).
    pub weights: Vec<f64>,
    /// Σ r² of the final weighted residual, robust weights included.
    pub cost: f64,
}

/// Fit the free parameters `free` (global indices) from `x0`.
///
/// Levenberg–Marquardt on the column-scaled normal equations: a Gauss–Newton step (λ = 0) while
/// it lowers the cost as predicted, damping (λ) raised when a step fails or achieves less than a
/// quarter of its predicted decrease and lowered when it achieves most of it (Nielsen's rule),
/// so the method stays globally convergent and ends with Gauss–Newton's fast steps.
///
/// Converged when any of: the scaled step is below `step_tol`; an accepted step lowers the cost
/// by less than `cost_tol` of it; or the undamped Gauss–Newton step would move the parameters
/// by less than `sigma_tol` of their standard deviations (the Newton decrement bᵀA⁻¹b, which is
/// the cost decrease it predicts, against σ̂² = cost/(n − m)).
pub fn solve(problem: &Problem, free: &[usize], x0: &[f64], opts: &SolverOptions) -> Result<Fit, SolveError> {
    let n = problem.n_rows;
    let m = free.len();
    let mut x = x0.to_vec();
    let mut jac = Mat::<f64>::zeros(n, m);
    let mut res = vec![0.0; n];
    let mut trial_res = vec![0.0; n];
    // Work space reused by every iteration: the weighted right side and row weights.
    let mut rhs = vec![0.0; n];
    let mut row_w = vec![1.0; n];
    let mut weights = vec![1.0; problem.obs.len()];
    let mut lambda = 0.0f64;
    let mut last_step = f64::INFINITY;
    let mut last_change = f64::INFINITY;
    let mut moving: Vec<(String, f64)> = Vec::new();
    let dof = (problem.n_obs_rows.saturating_sub(m)).max(1) as f64;

    for iteration in 1..=opts.max_iterations {
        problem.linearise(&x, free, &mut jac, &mut res);
        if let Some(k) = opts.huber {
            weights = huber_weights(problem, &res, k);
        }
        let cost = weighted_cost(problem, &res, &weights);
        if !cost.is_finite() {
            return Err(SolveError::Diverged { iteration, reason: "the cost is not finite".into(), last: x });
        }
        for o in 0..problem.obs.len() {
            let ob = &problem.obs[o];
            let w = weights[o].sqrt();
            for r in ob.row..ob.row + ob.rows {
                row_w[r] = w;
                rhs[r] = res[r] * w;
            }
        }
        rhs[problem.n_obs_rows..n].copy_from_slice(&res[problem.n_obs_rows..n]);
        // The step from the normal equations of the column-scaled system (see the module notes),
        // or, when they are too ill-conditioned to trust, from a QR of the scaled Jacobian.
        let robust = opts.huber.is_some();
        let (gram, grad) = normal_equations(&jac, &rhs, robust.then_some(&row_w[..]));
        let scale: Vec<f64> = (0..m).map(|c| if gram[(c, c)] > 0.0 { gram[(c, c)].sqrt() } else { 1.0 }).collect();
        let a = Mat::<f64>::from_fn(m, m, |i, k| gram[(i, k)] / (scale[i] * scale[k]));
        let b: Vec<f64> = (0..m).map(|c| grad[c] / scale[c]).collect();
        let mut scaled_qr: Option<Mat<f64>> = None;
        let mut step_for = |lambda: f64| -> Vec<f64> {
            match spd_solve(&a, &b, lambda) {
                Some(y) => y,
                None => {
                    let js = scaled_qr
                        .get_or_insert_with(|| Mat::<f64>::from_fn(n, m, |r, c| jac[(r, c)] * row_w[r] / scale[c]));
                    if lambda == 0.0 { lstsq(js, &rhs) } else { damped_lstsq(js, &rhs, lambda) }
                }
            }
        };
        // The undamped step, and how far it would move the parameters in units of their σ.
        let gn = step_for(0.0);
        let sigma2 = cost / dof;
        let decrement = gn.iter().zip(&b).map(|(y, g)| y * g).sum::<f64>().max(0.0);
        let settled = gn.iter().all(|v| v.is_finite()) && sigma2 > 0.0 && decrement <= opts.sigma_tol.powi(2) * sigma2;
        moving = moving_parameters(problem, free, &a, &gn, sigma2);
        // Try steps until one lowers the cost.
        let mut accepted = false;
        loop {
            let y = if lambda == 0.0 { gn.clone() } else { step_for(lambda) };
            if y.iter().any(|v| !v.is_finite()) {
                return Err(SolveError::Diverged {
                    iteration,
                    reason: "the least-squares step is not finite".into(),
                    last: x,
                });
            }
            let mut xt = x.clone();
            for c in 0..m {
                xt[free[c]] += y[c] / scale[c];
            }
            problem.residual(&xt, &mut trial_res);
            let trial = weighted_cost(problem, &trial_res, &weights);
            let step = y.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            // The decrease the linear model predicts for this step: 2yᵀb − yᵀAy.
            let ay: Vec<f64> = (0..m).map(|i| (0..m).map(|k| a[(i, k)] * y[k]).sum()).collect();
            let predicted = 2.0 * y.iter().zip(&b).map(|(p, q)| p * q).sum::<f64>()
                - y.iter().zip(&ay).map(|(p, q)| p * q).sum::<f64>();
            if trial.is_finite() && trial <= cost {
                accepted = true;
                x = xt;
                last_step = step;
                last_change = if cost > 0.0 { (cost - trial) / cost } else { 0.0 };
                let gain = if predicted > 0.0 { (cost - trial) / predicted } else { 1.0 };
                lambda = if gain > 0.25 {
                    let l = lambda * (1.0f64 / 3.0).max(1.0 - (2.0 * gain - 1.0).powi(3));
                    if l > 1e-9 { l } else { 0.0 }
                } else {
                    (lambda * 2.0).max(1e-6)
                };
                break;
            }
            // No decrease: a step this small means we are at the minimum already.
            if step <= opts.step_tol || settled {
                last_step = step;
                last_change = 0.0;
                break;
            }
            lambda = if lambda == 0.0 { 1e-6 } else { lambda * 10.0 };
            if lambda > 1e10 {
                return Err(SolveError::Diverged {
                    iteration,
                    reason: format!("no damped step lowers the cost (λ = {lambda:.1e}, cost {cost:.3e} m²)"),
                    last: x,
                });
            }
        }
        if settled || last_step <= opts.step_tol || last_change <= opts.cost_tol {
            // The quality report needs J and the residual at the solution. When the last step was
            // negligible (≤ 1e-9 on unit-scaled columns) this iteration's J is that Jacobian to
            // ~1e-9 relative and the trial residual is the residual there: no re-linearisation.
            if accepted && last_step > REUSE_JACOBIAN_STEP {
                problem.linearise(&x, free, &mut jac, &mut res);
            } else if accepted {
                res.copy_from_slice(&trial_res);
            }
            if let Some(k) = opts.huber {
                weights = huber_weights(problem, &res, k);
            }
            for o in 0..problem.obs.len() {
                let ob = &problem.obs[o];
                let w = weights[o].sqrt();
                for r in ob.row..ob.row + ob.rows {
                    res[r] *= w;
                    for c in 0..m {
                        jac[(r, c)] *= w;
                    }
                }
            }
            let cost = res.iter().map(|v| v * v).sum();
            return Ok(Fit { x, iterations: iteration, residual: res, jacobian: jac, weights, cost });
        }
    }
    Err(SolveError::IterationLimit {
        iterations: opts.max_iterations,
        step_m: last_step,
        cost_change: last_change,
        moving,
        last: x,
    })
}

/// The free parameters a Gauss–Newton step `y` (scaled columns) moves most in units of their
/// standard deviation √(σ̂²·(A⁻¹)_cc), largest first, at most four.
fn moving_parameters(problem: &Problem, free: &[usize], a: &Mat<f64>, y: &[f64], sigma2: f64) -> Vec<(String, f64)> {
    let m = free.len();
    if m == 0 || sigma2.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) || y.iter().any(|v| !v.is_finite()) {
        return Vec::new();
    }
    let Ok(llt) = a.llt(faer::Side::Lower) else { return Vec::new() };
    let inv = llt.inverse();
    let mut z: Vec<(usize, f64)> =
        (0..m).map(|c| (c, y[c].abs() / (sigma2 * inv[(c, c)].max(f64::MIN_POSITIVE)).sqrt())).collect();
    z.sort_by(|p, q| q.1.total_cmp(&p.1));
    z.into_iter().take(4).map(|(c, v)| (problem.name(free[c]), v)).collect()
}

/// Largest final step (unit-scaled columns) after which the last linearisation is reused.
const REUSE_JACOBIAN_STEP: f64 = 1e-9;

/// The robustly weighted cost of the measurement rows plus the prior rows (regularisation and
/// anchors, never down-weighted).
fn weighted_cost(problem: &Problem, res: &[f64], weights: &[f64]) -> f64 {
    problem
        .obs
        .iter()
        .zip(weights)
        .map(|(o, w)| w * res[o.row..o.row + o.rows].iter().map(|v| v * v).sum::<f64>())
        .sum::<f64>()
        + res[problem.n_obs_rows..problem.n_rows].iter().map(|v| v * v).sum::<f64>()
}

/// Huber weights per observation on its residual norm per axis, against a robust scale (MAD of
/// all residual components).
fn huber_weights(problem: &Problem, res: &[f64], k: f64) -> Vec<f64> {
    let mut abs: Vec<f64> = res.iter().map(|v| v.abs()).collect();
    abs.sort_by(f64::total_cmp);
    let sigma = 1.4826 * abs[abs.len() / 2];
    problem
        .obs
        .iter()
        .map(|o| {
            let a = (res[o.row..o.row + o.rows].iter().map(|v| v * v).sum::<f64>() / o.rows as f64).sqrt();
            if sigma <= 0.0 || a <= k * sigma { 1.0 } else { k * sigma / a }
        })
        .collect()
}

/// Least squares by Householder QR. Without column pivoting: the columns are already scaled to
/// unit norm and every dependent parameter was removed by the identifiability step, and faer's
/// pivoted QR spends most of its time re-computing column norms (it was a third of a 75-pose
/// identification). A singular R gives a non-finite step, which the caller reports as divergence;
/// conditioning itself is judged by the quality report (κ on the singular values).
fn lstsq(a: &Mat<f64>, b: &[f64]) -> Vec<f64> {
    let mut rhs = Mat::<f64>::zeros(b.len(), 1);
    for (i, v) in b.iter().enumerate() {
        rhs[(i, 0)] = *v;
    }
    let x = a.qr().solve_lstsq(&rhs);
    (0..a.ncols()).map(|i| x[(i, 0)]).collect()
}

fn damped_lstsq(a: &Mat<f64>, b: &[f64], lambda: f64) -> Vec<f64> {
    let (n, m) = (a.nrows(), a.ncols());
    let mut aug = Mat::<f64>::zeros(n + m, m);
    for c in 0..m {
        for r in 0..n {
            aug[(r, c)] = a[(r, c)];
        }
        aug[(n + c, c)] = lambda.sqrt();
    }
    let mut rhs = vec![0.0; n + m];
    rhs[..n].copy_from_slice(b);
    lstsq(&aug, &rhs)
}

/// Smallest pivot, relative to the unit diagonal of the scaled normal matrix, below which the
/// normal equations are not trusted and the QR of J_s (κ(J_s), not its square) takes over. The
/// pivots bound κ(A) = κ(J_s)² from below only; above them, an identification accepts κ(J_s) ≤ its
/// `kappa_limit` (1,000 by default: κ(A) ≤ 1e6, ten digits of the step left). And the solution is
/// where Jᵀr = 0, formed directly each iteration: a less exact step slows the convergence, it does
/// not move the point converged to.
const NORMAL_PIVOT_MIN: f64 = 1e-10;

/// JᵀWJ and Jᵀ·√W·b (W = diag(w²) when robust weights `w` are given; `b` = √W·r, the weighted
/// right side, so the second is JᵀWr), summed over row blocks in
/// parallel: for a tall J (15,000 × 23 at 5,000 poses) forming them is about n·m² flops, a QR of J
/// twice that and sequential.
fn normal_equations(jac: &Mat<f64>, rhs: &[f64], w: Option<&[f64]>) -> (Mat<f64>, Vec<f64>) {
    let (n, m) = (jac.nrows(), jac.ncols());
    let block = |start: usize, len: usize| -> (Mat<f64>, Vec<f64>) {
        let jb = jac.as_ref().subrows(start, len);
        let weighted;
        let jw = match w {
            None => jb,
            Some(w) => {
                weighted = Mat::<f64>::from_fn(len, m, |r, c| jb[(r, c)] * w[start + r]);
                weighted.as_ref()
            }
        };
        let g = jw.transpose() * jw;
        let rb = faer::MatRef::from_column_major_slice(&rhs[start..start + len], len, 1);
        let grad = jw.transpose() * rb;
        (g, (0..m).map(|c| grad[(c, 0)]).collect())
    };
    if n < NORMAL_PAR_MIN_ROWS || rayon::current_num_threads() < 2 {
        return block(0, n);
    }
    let half = n / 2;
    let ((g1, r1), (g2, r2)) = rayon::join(|| block(0, half), || block(half, n - half));
    (g1 + g2, r1.iter().zip(&r2).map(|(a, b)| a + b).collect())
}

/// Rows below which the normal equations are formed on one thread.
const NORMAL_PAR_MIN_ROWS: usize = 1500;

/// Solve (A + λI)·y = b for the symmetric positive definite scaled normal matrix A by Cholesky;
/// `None` when a pivot falls below [`NORMAL_PIVOT_MIN`] (or A is not positive definite).
fn spd_solve(a: &Mat<f64>, b: &[f64], lambda: f64) -> Option<Vec<f64>> {
    let m = a.nrows();
    let damped = Mat::<f64>::from_fn(m, m, |i, k| a[(i, k)] + if i == k { lambda } else { 0.0 });
    let llt = damped.llt(faer::Side::Lower).ok()?;
    let l = llt.L();
    if (0..m).any(|i| {
        let p = l[(i, i)] * l[(i, i)];
        p.is_nan() || p < NORMAL_PIVOT_MIN * (1.0 + lambda)
    }) {
        return None;
    }
    let rhs = Mat::<f64>::from_fn(m, 1, |i, _| b[i]);
    let y = llt.solve(&rhs);
    Some((0..m).map(|i| y[(i, 0)]).collect())
}

/// Rows below which [`r_factor`] factors on one thread.
const TSQR_PAR_MIN_ROWS: usize = 1500;

/// The m×m upper-triangular R of a tall J = Q·R (n ≥ m), by a QR of each half of the rows on its
/// own thread and a QR of the two stacked R's (the "tall-skinny QR"). J and R share their column
/// inner products (JᵀJ = RᵀR): singular values, right singular vectors, column norms and any
/// Gram–Schmidt or least squares among the columns, at m×m instead of n×m.
pub fn r_factor(j: faer::MatRef<'_, f64>) -> Mat<f64> {
    let (n, m) = (j.nrows(), j.ncols());
    let upper = |a: faer::MatRef<'_, f64>| {
        let qr = a.qr();
        let r = qr.thin_R();
        Mat::<f64>::from_fn(r.nrows(), m, |i, k| if i <= k { r[(i, k)] } else { 0.0 })
    };
    if n < TSQR_PAR_MIN_ROWS || n < 4 * m || rayon::current_num_threads() < 2 {
        return upper(j);
    }
    let half = n / 2;
    let (r1, r2) = rayon::join(|| upper(j.subrows(0, half)), || upper(j.subrows(half, n - half)));
    let stacked = Mat::<f64>::from_fn(2 * m, m, |i, k| if i < m { r1[(i, k)] } else { r2[(i - m, k)] });
    upper(stacked.as_ref())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cell::fixtures::{irb120_cell, measurement, random_configurations, session};
    use crate::cell::{Cell, Observation, Purpose};
    use crate::identify::problem::{GlobalParam, MeasurementSelection};
    use crate::kinematics::model::irb120;
    use crate::kinematics::thesis::trical_tool;
    use crate::kinematics::{JointState, Param, ParamLayout, ParameterSet};
    use nalgebra::{DMatrix, DVector, Vector3};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    /// The nominal base of the problems (m, rad): z_0 parallel to Z_W.
    const BASE: [f64; 6] = [0.160, -0.256, -0.221, 1.6, 0.0, 0.0];

    /// Positions measured with the TriCal at `n` random configurations, on a robot whose base and
    /// tool translations are off the nominal ones by `base_shift` and `tool_shift` (m), plus
    /// Gaussian noise of `sigma` (m) per axis.
    fn cell(n: usize, base_shift: [f64; 3], tool_shift: [f64; 3], sigma: f64) -> Cell {
        let mut base = BASE;
        let mut tool = trical_tool();
        for k in 0..3 {
            base[k] += base_shift[k];
            tool.tcp[k] += tool_shift[k];
        }
        let chain = ParameterSet::nominal(irb120(), tool, base).nominal_chain();
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let noise = Normal::new(0.0, sigma.max(f64::MIN_POSITIVE)).unwrap();
        let ms = random_configurations(n, 10)
            .into_iter()
            .map(|q| {
                let e = if sigma > 0.0 {
                    Vector3::new(noise.sample(&mut rng), noise.sample(&mut rng), noise.sample(&mut rng))
                } else {
                    Vector3::zeros()
                };
                let p = chain.fk(&JointState::new(&q)).t + e;
                measurement(q, Observation::Position(p))
            })
            .collect();
        irb120_cell(vec![session("points", Purpose::Identification, trical_tool(), ms)])
    }

    fn problem(cell: &Cell) -> Problem {
        Problem::new(cell, ParamLayout::full(&cell.model), BASE, &MeasurementSelection::default(), 1.0).unwrap()
    }

    /// The base and tool translations: the TCP position is affine in them (p = t_base + R_base·(…
    /// + R_flange·t_tool)), so the problem in these six parameters is linear.
    fn translations(p: &Problem) -> Vec<usize> {
        let base = (0..3).map(|k| p.robot_index(Param::Base(k)).unwrap());
        let tool = (0..3).map(|k| p.params.iter().position(|g| *g == GlobalParam::Tool { tool: 0, k }).unwrap());
        base.chain(tool).collect()
    }

    /// Exact data: the translations come back to rounding. Noisy data: the fit is the linear
    /// least-squares solution x₀ + (JᵀJ)⁻¹Jᵀr₀ computed apart (nalgebra, normal equations).
    #[test]
    fn recovers_a_linear_problem() {
        let (db, dt) = ([0.002, -0.001, 0.003], [0.0005, 0.001, -0.0015]);
        let p = problem(&cell(20, db, dt, 0.0));
        let free = translations(&p);
        let fit = solve(&p, &free, &p.nominal, &SolverOptions::default()).unwrap();
        let want: Vec<f64> = db.iter().chain(&dt).copied().collect();
        for (c, &g) in free.iter().enumerate() {
            let d = fit.x[g] - p.nominal[g];
            assert!((d - want[c]).abs() < 1e-12, "{}: {d} vs {}", p.name(g), want[c]);
        }
        assert!(fit.cost < 1e-24, "cost {}", fit.cost);
        assert!(fit.iterations <= 3, "{} iterations for a linear problem", fit.iterations);
        assert_eq!(fit.weights, vec![1.0; 20]);
        assert_eq!((fit.jacobian.nrows(), fit.jacobian.ncols(), fit.residual.len()), (60, 6, 60));

        let p = problem(&cell(20, db, dt, 50e-6));
        let fit = solve(&p, &free, &p.nominal, &SolverOptions::default()).unwrap();
        let mut jac = Mat::<f64>::zeros(p.n_rows, free.len());
        let mut r0 = vec![0.0; p.n_rows];
        p.linearise(&p.nominal, &free, &mut jac, &mut r0);
        let j = DMatrix::from_fn(p.n_rows, free.len(), |r, c| jac[(r, c)]);
        let dx = (j.transpose() * &j).try_inverse().unwrap() * j.transpose() * DVector::from_vec(r0);
        for (c, &g) in free.iter().enumerate() {
            let d = fit.x[g] - p.nominal[g];
            assert!((d - dx[c]).abs() < 1e-12, "{}: {d} vs {}", p.name(g), dx[c]);
        }
        // The final residual and Jacobian are those at the solution.
        let mut r = vec![0.0; p.n_rows];
        p.residual(&fit.x, &mut r);
        assert!(r.iter().zip(&fit.residual).all(|(a, b)| (a - b).abs() < 1e-15));
        assert!((fit.cost - r.iter().map(|v| v * v).sum::<f64>()).abs() < 1e-18);
    }

    /// A tall random matrix of columns over six orders of magnitude: the R of the two-block
    /// factorisation has RᵀR = JᵀJ (the inner products every caller relies on), is upper
    /// triangular, and has J's singular values (computed apart by nalgebra on J itself).
    #[test]
    fn r_factor_keeps_the_inner_products() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let normal = Normal::new(0.0, 1.0).unwrap();
        let (n, m) = (4001, 9);
        let j = Mat::<f64>::from_fn(n, m, |_, c| normal.sample(&mut rng) * 10f64.powi(c as i32 - 4));
        let r = r_factor(j.as_ref());
        assert_eq!((r.nrows(), r.ncols()), (m, m));
        let (jtj, rtr) = (j.transpose() * &j, r.transpose() * &r);
        for a in 0..m {
            for b in 0..m {
                let scale = (jtj[(a, a)] * jtj[(b, b)]).sqrt();
                assert!((jtj[(a, b)] - rtr[(a, b)]).abs() <= 1e-13 * scale, "({a}, {b})");
                if a > b {
                    assert_eq!(r[(a, b)], 0.0);
                }
            }
        }
        let sv_j = DMatrix::from_fn(n, m, |a, b| j[(a, b)]).singular_values();
        let sv_r = DMatrix::from_fn(m, m, |a, b| r[(a, b)]).singular_values();
        let (mut x, mut y) = (sv_j.as_slice().to_vec(), sv_r.as_slice().to_vec());
        x.sort_by(f64::total_cmp);
        y.sort_by(f64::total_cmp);
        // Backward-stable factorisations: each singular value to ε·σ_max, whatever its size.
        assert!(x.iter().zip(&y).all(|(a, b)| (a - b).abs() <= 1e-13 * x[m - 1]), "{x:?} vs {y:?}");
    }

    /// The step from the scaled normal equations (Cholesky, two threads forming JᵀWJ) equals the
    /// step from the QR of the scaled, weighted Jacobian, damped or not; a dependent column is
    /// refused (no Cholesky step) so that the QR path reports it.
    #[test]
    fn normal_equations_step_matches_the_qr_step() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let normal = Normal::new(0.0, 1.0).unwrap();
        let (n, m) = (3000, 8);
        let jac = Mat::<f64>::from_fn(n, m, |_, c| normal.sample(&mut rng) * 10f64.powi(c as i32 - 3));
        let rhs: Vec<f64> = (0..n).map(|_| normal.sample(&mut rng) * 1e-5).collect();
        let w: Vec<f64> = (0..n).map(|r| if r % 97 == 0 { 0.3 } else { 1.0 }).collect();
        let wr: Vec<f64> = (0..n).map(|r| rhs[r] * w[r]).collect();
        let (gram, grad) = normal_equations(&jac, &wr, Some(&w));
        let scale: Vec<f64> = (0..m).map(|c| gram[(c, c)].sqrt()).collect();
        let a = Mat::<f64>::from_fn(m, m, |i, k| gram[(i, k)] / (scale[i] * scale[k]));
        let b: Vec<f64> = (0..m).map(|c| grad[c] / scale[c]).collect();
        let js = Mat::<f64>::from_fn(n, m, |r, c| jac[(r, c)] * w[r] / scale[c]);
        for lambda in [0.0, 1e-3, 10.0] {
            let y = spd_solve(&a, &b, lambda).expect("well conditioned");
            let z = if lambda == 0.0 { lstsq(&js, &wr) } else { damped_lstsq(&js, &wr, lambda) };
            let big = z.iter().fold(0.0f64, |s, v| s.max(v.abs()));
            assert!(y.iter().zip(&z).all(|(p, q)| (p - q).abs() <= 1e-10 * big), "λ {lambda}: {y:?} vs {z:?}");
        }
        let twice = Mat::<f64>::from_fn(n, 2, |r, _| jac[(r, 0)]);
        let (g2, r2) = normal_equations(&twice, &rhs, None);
        let s2 = g2[(0, 0)].sqrt();
        let a2 = Mat::<f64>::from_fn(2, 2, |i, k| g2[(i, k)] / (s2 * s2));
        assert!(spd_solve(&a2, &[r2[0] / s2, r2[1] / s2], 0.0).is_none());
    }

    /// Two parameters with one effect (base z and d1 both move the arm along Z_W when z_0 is
    /// parallel to it): the unpivoted QR meets a zero pivot, the step is not finite, and the
    /// solver reports divergence at the first iteration instead of returning numbers.
    #[test]
    fn rank_deficient_problem_is_reported() {
        let p = problem(&cell(20, [0.0, 0.0, 0.003], [0.0; 3], 0.0));
        let free = vec![p.robot_index(Param::Base(2)).unwrap(), p.robot_index(Param::D(0)).unwrap()];
        let mut jac = Mat::<f64>::zeros(p.n_rows, 2);
        let mut r = vec![0.0; p.n_rows];
        p.linearise(&p.nominal, &free, &mut jac, &mut r);
        assert!((0..p.n_rows).all(|row| jac[(row, 0)] == jac[(row, 1)]), "one column twice");
        let outcome = solve(&p, &free, &p.nominal, &SolverOptions::default());
        match outcome {
            Err(SolveError::Diverged { iteration: 1, reason, .. }) => {
                assert!(reason.contains("step is not finite"), "{reason}")
            }
            other => panic!("{other:?}"),
        }
    }

    /// Non-finite data: an error at the first iteration, not a number.
    #[test]
    fn non_finite_data_diverge() {
        let mut c = cell(10, [0.0; 3], [0.0; 3], 0.0);
        c.sessions[0].measurements[4].observation = Observation::Position(Vector3::new(f64::NAN, 0.0, 0.0));
        let p = problem(&c);
        let free = translations(&p);
        match solve(&p, &free, &p.nominal, &SolverOptions::default()) {
            Err(SolveError::Diverged { iteration: 1, reason, .. }) => {
                assert!(reason.contains("cost is not finite"), "{reason}")
            }
            other => panic!("{other:?}"),
        }
    }

    /// A nonlinear problem (the base rotation free, started 0.1 rad off) cut at one iteration
    /// is an error that says how far it got.
    #[test]
    fn iteration_limit_is_an_error() {
        let p = problem(&cell(10, [0.0; 3], [0.0; 3], 0.0));
        let free: Vec<usize> = (0..6).map(|k| p.robot_index(Param::Base(k)).unwrap()).collect();
        let mut x0 = p.nominal.clone();
        x0[free[3]] += 0.1;
        let opts = SolverOptions { max_iterations: 1, ..Default::default() };
        match solve(&p, &free, &x0, &opts) {
            Err(SolveError::IterationLimit { iterations: 1, step_m, moving, .. }) => {
                assert!(step_m > 1e-6);
                // The rotation started 0.1 rad off is what still moves: by more than its σ, a
                // thousand times the converged threshold (`sigma_tol` 1e-3).
                assert!(moving[0].0.starts_with("base_") && moving[0].1 > 1.0, "{moving:?}");
            }
            other => panic!("{other:?}"),
        }
        // Given the iterations, it converges to the true base.
        let fit = solve(&p, &free, &x0, &SolverOptions::default()).unwrap();
        assert!(free.iter().all(|&g| (fit.x[g] - p.nominal[g]).abs() < 1e-10));
    }

    /// The stopping rule's promise, checked apart: at the returned solution of a nonlinear fit on
    /// noisy data, the Gauss–Newton step (normal equations by nalgebra, from a central-difference
    /// Jacobian) would move the parameters by less than `sigma_tol` of their standard deviation,
    /// jointly: δᵀ(JᵀJ)δ ≤ sigma_tol²·σ̂² with σ̂² = RSS/(n − m).
    #[test]
    fn stops_when_the_step_is_far_below_sigma() {
        let p = problem(&cell(40, [0.001, 0.0, -0.002], [0.0; 3], 0.2e-3));
        let mut free: Vec<usize> = (0..6).map(|k| p.robot_index(Param::Base(k)).unwrap()).collect();
        free.extend((1..5).map(|j| p.robot_index(Param::Theta(j)).unwrap()));
        let mut x0 = p.nominal.clone();
        x0[free[3]] += 0.02;
        let opts = SolverOptions::default();
        let fit = solve(&p, &free, &x0, &opts).unwrap();
        let n = p.n_rows;
        let res = |x: &[f64]| {
            let mut r = vec![0.0; n];
            p.residual(x, &mut r);
            DVector::from_vec(r)
        };
        let r = res(&fit.x);
        let mut j = DMatrix::<f64>::zeros(n, free.len());
        for (c, &g) in free.iter().enumerate() {
            let h = 1e-7;
            let (mut xp, mut xm) = (fit.x.clone(), fit.x.clone());
            xp[g] += h;
            xm[g] -= h;
            let d = (res(&xp) - res(&xm)) / (2.0 * h);
            for i in 0..n {
                j[(i, c)] = -d[i];
            }
        }
        let a = j.transpose() * &j;
        let g = j.transpose() * &r;
        let step = a.clone().cholesky().unwrap().solve(&g);
        let decrement = (step.transpose() * &a * &step)[(0, 0)];
        let sigma2 = r.norm_squared() / (n - free.len()) as f64;
        assert!(decrement <= opts.sigma_tol.powi(2) * sigma2, "δᵀAδ = {decrement:e} against σ̂² = {sigma2:e}");
        assert!(fit.iterations < 20, "{} iterations", fit.iterations);
    }

    /// Huber weights: a gross outlier among 10 µm noise is down-weighted, the others keep full
    /// weight, and the fit stays where the clean data put it.
    #[test]
    fn huber_down_weights_an_outlier() {
        let mut c = cell(30, [0.0; 3], [0.0; 3], 10e-6);
        let clean = problem(&c);
        let free = translations(&clean);
        let reference = solve(&clean, &free, &clean.nominal, &SolverOptions::default()).unwrap();
        if let Observation::Position(p) = &mut c.sessions[0].measurements[7].observation {
            p.x += 0.005;
        }
        let p = problem(&c);
        let opts = SolverOptions { huber: Some(2.0), ..Default::default() };
        let fit = solve(&p, &free, &p.nominal, &opts).unwrap();
        assert!(fit.weights[7] < 0.01, "outlier weight {}", fit.weights[7]);
        assert!(fit.weights.iter().enumerate().filter(|&(i, _)| i != 7).all(|(_, w)| *w > 0.5), "{:?}", fit.weights);
        let plain = solve(&p, &free, &p.nominal, &SolverOptions::default()).unwrap();
        let shift = |f: &Fit| free.iter().map(|&g| (f.x[g] - reference.x[g]).abs()).fold(0.0, f64::max);
        assert!(shift(&fit) < 5e-6 && shift(&plain) > 5e-5, "robust {} m, plain {} m", shift(&fit), shift(&plain));
    }
}
