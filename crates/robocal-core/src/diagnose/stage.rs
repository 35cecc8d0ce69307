//! One model of the greedy search, fitted on the pooled data (identification and validation
//! sessions together, weighted by the instrument model) and linearised at its solution: the
//! weighted Jacobian J of its free parameters, the weighted residual r, an orthonormal basis Q of
//! J's columns, and the Jacobian columns of any further parameter at that solution.

use faer::Mat;

use super::linalg::{a_b, at_b, at_v, hcat, orthonormal_basis, psd_solve};

use crate::cell::Cell;
use crate::identify::{
    Fit, GlobalParam, Identification, IdentifyError, IdentifyOptions, Problem, Quality, identify, prepare,
};
use crate::kinematics::{Chain, Param, ParameterSet, Rows};

/// A fitted model and its linearisation.
pub struct Stage {
    /// The model's identification options.
    pub options: IdentifyOptions,
    /// The identification problem on the pooled data: observations, rows and global parameters.
    pub problem: Problem,
    /// The linearisation point (global parameters, SI).
    pub x: Vec<f64>,
    /// Global indices of the free parameters (J's columns).
    pub free: Vec<usize>,
    /// The parameter set at `x` (its tool is the problem's first).
    pub set: ParameterSet,
    /// The converged identification, or why the model could not be fitted on the pooled data
    /// (then `x` is the starting point and J, r are linearised there: the score test and the
    /// folds' one-step refits need only that).
    pub fit: Result<Identification, String>,
    /// Weighted Jacobian of the free parameters (measurement rows, then prior rows).
    pub j: Mat<f64>,
    /// Weighted residual target − model.
    pub r: Vec<f64>,
    /// Orthonormal basis of J's column space.
    pub q: Mat<f64>,
    /// Weighted residual sum of squares of the measurement rows, after the model's own linear
    /// step (what no parameter of the model can explain).
    pub rss: f64,
    /// Whether `x` solves the model's least-squares problem: a converged fit, or one linear step
    /// from one (a small effect added). False when the fit was refused and the stage is
    /// linearised at its starting point: its values are that point's and its J (the refused
    /// fit's free parameters) says nothing about their uncertainty.
    pub solved: bool,
}

impl Stage {
    /// Fit `options` on `cell` and linearise at the solution; when the model cannot be fitted
    /// (it diverges, or its conditioning is refused — a model without β on a robot whose
    /// parallel axes are tilted has its least-squares solution at infinity), linearise at the
    /// starting point instead and say why.
    pub fn fit(cell: &Cell, options: IdentifyOptions) -> Result<Stage, IdentifyError> {
        match identify(cell, &options) {
            Ok(id) => {
                let (j, r) = id.linearised();
                // J has full column rank (identifiability kept only independent parameters): a
                // thin QR is the basis, at half the cost of an SVD of the tall matrix.
                let q = j.qr().compute_thin_Q();
                let (problem, x, free, set) = (id.problem.clone(), id.x.clone(), id.free.clone(), id.set.clone());
                Ok(Stage::assemble(options, problem, x, free, set, Ok(id), j, r, q, true))
            }
            Err(
                e @ (IdentifyError::Solve(_)
                | IdentifyError::IllConditioned { .. }
                | IdentifyError::RankDeficient { .. }),
            ) => {
                let p = prepare(cell, &options)?;
                let mut j = Mat::<f64>::zeros(p.problem.n_rows, p.free.len());
                let mut r = vec![0.0; p.problem.n_rows];
                p.problem.linearise(&p.x0, &p.free, &mut j, &mut r);
                let q = orthonormal_basis(j.as_ref(), 1e-12);
                let mut set = ParameterSet::nominal(cell.model.clone(), p.problem.tools[0].tool.clone(), p.base);
                set.layout = p.problem.layout.clone();
                set.nominal = p.problem.layout.nominal_values(&cell.model, &p.problem.tools[0].tool, &p.base);
                set.values = p.problem.layout_values(&p.x0, 0);
                Ok(Stage::assemble(options, p.problem, p.x0, p.free, set, Err(e.to_string()), j, r, q, false))
            }
            Err(e) => Err(e),
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn assemble(
        options: IdentifyOptions,
        problem: Problem,
        x: Vec<f64>,
        free: Vec<usize>,
        set: ParameterSet,
        fit: Result<Identification, String>,
        j: Mat<f64>,
        r: Vec<f64>,
        q: Mat<f64>,
        solved: bool,
    ) -> Stage {
        let n = problem.n_obs_rows;
        let c = at_v(q.as_ref(), &r);
        let rss = (0..n)
            .map(|i| {
                let v = r[i] - (0..q.ncols()).map(|k| q[(i, k)] * c[k]).sum::<f64>();
                v * v
            })
            .sum();
        Stage { options, problem, x, free, set, fit, j, r, q, rss, solved }
    }

    /// This stage's parameter set extended by `params`, with the values of `x` (the extended
    /// `problem`'s vector) wherever the problem carries the parameter.
    fn extended_set(&self, problem: &Problem, params: &[Param], x: &[f64]) -> ParameterSet {
        let mut set = self.set.clone();
        set.extend(params);
        for (i, p) in problem.layout.params().iter().enumerate() {
            if let Some(gl) = problem.robot_index(*p) {
                set.values[i] = x[gl];
            }
        }
        set
    }

    /// The model plus a candidate, as one Gauss–Newton step from this stage's solution on the
    /// pooled data: J gains the candidate's columns (`cols`, weighted, from
    /// [`Stage::columns`] or [`Stage::global_columns`]) and a table's regularisation rows,
    /// the residual becomes the pooled least-squares residual of the extended linear model, Q
    /// is extended by the candidate's unabsorbed directions.
    ///
    /// The step is checked against the nonlinear model: when the residual the extended model
    /// really gives at the new point differs from the linear prediction by more than 1 % of the
    /// weighted RSS (a large effect — a missing compliance turns joints by a degree), the
    /// extended model is refitted in full from there instead. Small effects (tables of tenths
    /// of a milliradian) stay linear: their second-order terms are nanometres, and a full refit
    /// of a model with hundreds of knots costs seconds.
    pub fn extend(
        &self,
        cell: &Cell,
        options: IdentifyOptions,
        params: &[Param],
        frees: &[usize],
        cols: &Mat<f64>,
        eta: f64,
    ) -> Result<Stage, IdentifyError> {
        let (mut problem, remap) = self.problem.extended(params);
        let m_new = cols.ncols();
        // Global indices of the new columns.
        let new_globals: Vec<usize> = if frees.is_empty() {
            params.iter().map(|p| problem.robot_index(*p).expect("just added")).collect()
        } else {
            frees.iter().map(|&g| remap[g]).collect()
        };
        // A table's regularisation rows.
        let tables: Vec<(i16, usize, f64)> = params
            .iter()
            .zip(&new_globals)
            .enumerate()
            .filter_map(|(c, (p, &g))| match p {
                Param::Joint(_, crate::kinematics::JointTerm::Map { knot, .. }) => {
                    Some((*knot, g, (0..self.n_obs_rows()).map(|r| cols[(r, c)].powi(2)).sum::<f64>()))
                }
                _ => None,
            })
            .collect();
        let new_priors = if tables.is_empty() { Vec::new() } else { crate::identify::table_priors(&tables, eta) };
        let old_rows = self.n_rows();
        problem.add_priors(new_priors.clone());
        let n = problem.n_rows;
        let p_old = self.p();
        let w = p_old + m_new;
        let a = Mat::<f64>::from_fn(n, w, |r, c| {
            if r < old_rows {
                if c < p_old { self.j[(r, c)] } else { cols[(r, c - p_old)] }
            } else {
                let pr = &new_priors[r - old_rows];
                let g = if c < p_old { usize::MAX } else { new_globals[c - p_old] };
                pr.terms.iter().filter(|(tg, _)| *tg == g).map(|(_, v)| *v).sum()
            }
        });
        let mut r0 = self.r.clone();
        r0.resize(n, 0.0);
        // The pooled least-squares step of the extended linear model.
        let g = at_b(a.as_ref(), a.as_ref());
        // A column with no effect (a payload where nothing carries its torque to the TCP: no
        // compliance free: each held) keeps the scale 1: floored at the smallest positive number, its
        // square underflowed to 0 and the scaled Gram matrix read 0/0 (a panic in the
        // eigendecomposition on a FANUC sweeps twin).
        let scale: Vec<f64> = (0..w).map(|c| if g[(c, c)] > 0.0 { g[(c, c)].sqrt() } else { 1.0 }).collect();
        let gs = Mat::<f64>::from_fn(w, w, |i, k| g[(i, k)] / (scale[i] * scale[k]));
        let b: Vec<f64> = at_v(a.as_ref(), &r0).iter().zip(&scale).map(|(v, s)| v / s).collect();
        let delta: Vec<f64> = psd_solve(&gs, &b, 1e-13).iter().zip(&scale).map(|(v, s)| v / s).collect();
        let mut r = r0.clone();
        for (i, ri) in r.iter_mut().enumerate() {
            *ri -= (0..w).map(|c| a[(i, c)] * delta[c]).sum::<f64>();
        }
        let mut free: Vec<usize> = self.free.iter().map(|&g| remap[g]).collect();
        free.extend(&new_globals);
        let mut x = vec![0.0; problem.n_params()];
        for (g_old, &g_new) in remap.iter().enumerate() {
            x[g_new] = self.x[g_old];
        }
        for (c, &gl) in free.iter().enumerate() {
            x[gl] += delta[c];
        }
        // The nonlinear check.
        let mut actual = vec![0.0; n];
        problem.residual(&x, &mut actual);
        let rss_lin: f64 = r.iter().map(|v| v * v).sum();
        let rss_true: f64 = actual.iter().map(|v| v * v).sum();
        if (rss_true - rss_lin).abs() > 0.01 * rss_lin {
            let mut o = options;
            o.start = Some(self.extended_set(&problem, params, &x));
            return Stage::fit(cell, o);
        }
        // Q: the old basis (padded with the new prior rows) and the candidate's new directions.
        let qpad = Mat::<f64>::from_fn(n, self.q.ncols(), |r, c| if r < old_rows { self.q[(r, c)] } else { 0.0 });
        let an = Mat::<f64>::from_fn(n, m_new, |r, c| a[(r, p_old + c)]);
        let proj = a_b(qpad.as_ref(), at_b(qpad.as_ref(), an.as_ref()).as_ref());
        let rest = Mat::<f64>::from_fn(n, m_new, |r, c| an[(r, c)] - proj[(r, c)]);
        let qn = orthonormal_basis(rest.as_ref(), 1e-10);
        let q = hcat(&qpad, &qn);
        let set = self.extended_set(&problem, params, &x);
        let rss = r[..problem.n_obs_rows].iter().map(|v| v * v).sum();
        Ok(Stage {
            options,
            problem,
            x,
            free,
            set,
            fit: Err("extended by one linear step".into()),
            j: a,
            r,
            q,
            rss,
            solved: self.solved,
        })
    }

    /// Standard deviations of free global parameters at the data's own scale, as an
    /// identification reports them ([`crate::identify::Quality::make_robust`]): the larger of
    /// σ̂²(JᵀJ)⁻¹, σ̂² the weighted residual per degree of freedom, and the cluster-robust σ with
    /// the readings grouped by stop; `None` for a fixed parameter, one the data do not
    /// determine (a non-finite σ), and every parameter of a stage that is not [`Stage::solved`].
    ///
    /// Why not (JᵀJ)⁻¹ alone: J is weighted by the instrument model, so that is the σ the
    /// instrument alone would leave. On real data the residual is 10–30× the instrument's and the
    /// readings of one stop (several reflectors) share the stop's error; on a tracker twin with
    /// 0.35 mm of pose-to-pose error, a backlash printed 0.0152 ± 0.00006° was 0.012° in truth.
    pub(crate) fn stds_of(&self, globals: &[usize]) -> Vec<Option<f64>> {
        if !self.solved {
            return vec![None; globals.len()];
        }
        let pr = &self.problem;
        let cost: f64 = self.r.iter().map(|v| v * v).sum();
        let fit = Fit {
            x: self.x.clone(),
            iterations: 0,
            residual: self.r.clone(),
            jacobian: self.j.clone(),
            weights: vec![1.0; pr.obs.len()],
            cost,
        };
        let rows: Vec<(usize, usize)> = pr.obs.iter().map(|o| (o.row, o.rows)).collect();
        let dof = pr.model.dof();
        let (pose_of_obs, n_poses) = crate::cell::poses::group_poses(pr.obs.iter().map(|o| &o.state.q[..dof]));
        let mut quality = Quality::of(&fit, pr.obs.len(), &rows);
        quality.make_robust(&fit, &rows, &pose_of_obs, n_poses);
        globals
            .iter()
            .map(|g| self.free.iter().position(|f| f == g).map(|c| quality.std[c]).filter(|s| s.is_finite()))
            .collect()
    }

    /// Rows of J and r: the measurement rows, then the prior rows.
    pub fn n_rows(&self) -> usize {
        self.problem.n_rows
    }

    /// Measurement rows (3 per position, 6 per pose).
    pub fn n_obs_rows(&self) -> usize {
        self.problem.n_obs_rows
    }

    /// Free parameters of the model.
    pub fn p(&self) -> usize {
        self.j.ncols()
    }

    /// The weighted Jacobian columns of further model parameters (or of parameters the model
    /// already has, e.g. θ_j) at the solution: n_rows × params, zero on the prior rows.
    pub fn columns(&self, params: &[Param]) -> Mat<f64> {
        let pr = &self.problem;
        let mut layout = pr.layout.clone();
        let idx = layout.extend(params);
        let chains: Vec<Chain> = (0..pr.tools.len())
            .map(|t| {
                let mut v = pr.layout_values(&self.x, t);
                v.resize(layout.len(), 0.0);
                Chain::new(&pr.model, &layout, &v)
            })
            .collect();
        let m = params.len();
        let mut out = Mat::<f64>::zeros(pr.n_rows, m);
        let mut buf = vec![0.0; 6 * m.max(1)];
        for o in &pr.obs {
            let rows = if o.rows == 6 { Rows::Pose } else { Rows::Position };
            chains[o.tool].jacobian_columns_into(&o.state, &layout, rows, idx.iter().copied().zip(0..m), &mut buf, 6);
            for c in 0..m {
                for r in 0..o.rows {
                    let w = if r >= 3 { pr.rotation_weight * o.weight[r] } else { o.weight[r] };
                    out[(o.row + r, c)] = buf[c * 6 + r] * w;
                }
            }
        }
        out
    }

    /// The weighted Jacobian columns of global parameters the model holds fixed (a base or a TCP
    /// the candidate would free).
    pub fn global_columns(&self, globals: &[usize]) -> Mat<f64> {
        let pr = &self.problem;
        let mut j = Mat::<f64>::zeros(pr.n_rows, globals.len());
        let mut r = vec![0.0; pr.n_rows];
        pr.linearise(&self.x, globals, &mut j, &mut r);
        for k in pr.n_obs_rows..pr.n_rows {
            for c in 0..globals.len() {
                j[(k, c)] = 0.0;
            }
        }
        j
    }

    /// ∂(TCP)/∂θ_j of every joint, weighted (n_rows × dof): a joint-angle term's column is this
    /// column times its basis function, row by row.
    pub(crate) fn joint_columns(&self) -> Mat<f64> {
        let dof = self.problem.model.dof();
        self.columns(&(0..dof).map(Param::Theta).collect::<Vec<_>>())
    }

    /// Whether a global parameter is free in this model.
    pub(crate) fn is_free(&self, g: usize) -> bool {
        self.free.contains(&g)
    }

    /// Per layout entry: whether the model fits it.
    pub(crate) fn free_layout(&self) -> Vec<bool> {
        let pr = &self.problem;
        let mut free = vec![false; pr.layout.len()];
        for &g in &self.free {
            if let GlobalParam::Robot(i) = pr.params[g] {
                free[i] = true;
            }
        }
        free
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::simulate::{SimulateOptions, simulate};

    /// A stage whose fit is refused is linearised at its start, with the refused fit's free
    /// parameters: its values are the start's and its J says nothing of their uncertainty, so it
    /// reports no σ. The same model fitted reports one for every free parameter. (A refused refit
    /// of a diagnosis's accepted effect once printed the start's value with a σ 200 times the
    /// converged fit's: `compliance_cubic j2 -1.127e-6 ± 2.943e-5 deg/(N·m)³`, against
    /// −1.52e-6 ± 1.50e-7 from the fit, issue 24.)
    #[test]
    fn a_refused_fit_reports_no_standard_deviation() {
        let sim = simulate(&SimulateOptions { seed: 3, ..Default::default() }).unwrap();
        let fitted = Stage::fit(&sim.cell, IdentifyOptions::default()).unwrap();
        assert!(fitted.fit.is_ok() && fitted.solved);
        assert!(fitted.stds_of(&fitted.free).iter().all(|s| s.is_some_and(|v| v > 0.0)));
        let refused =
            Stage::fit(&sim.cell, IdentifyOptions { kappa_limit: 2.0, ..IdentifyOptions::default() }).unwrap();
        let why = refused.fit.as_ref().expect_err("refused at κ 2");
        assert!(why.contains("ill-conditioned"), "{why}");
        assert!(!refused.solved);
        assert_eq!(refused.free, fitted.free);
        assert!(refused.stds_of(&refused.free).iter().all(|s| s.is_none()));
    }
}
