//! One model of the greedy search, fitted on the pooled data (identification and validation
//! sessions together, weighted by the instrument model) and linearised at its solution: the
//! weighted Jacobian J of its free parameters, the weighted residual r, an orthonormal basis Q of
//! J's columns, and the Jacobian columns of any further parameter at that solution.

use faer::Mat;

use super::linalg::{at_v, orthonormal_basis};

use crate::cell::Cell;
use crate::identify::{GlobalParam, Identification, IdentifyError, IdentifyOptions, Problem, identify, prepare};
use crate::kinematics::{Chain, Param, ParameterSet, Rows};

/// A fitted model and its linearisation.
pub struct Stage {
    pub options: IdentifyOptions,
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
                Ok(Stage::assemble(options, problem, x, free, set, Ok(id), j, r, q))
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
                Ok(Stage::assemble(options, p.problem, p.x0, p.free, set, Err(e.to_string()), j, r, q))
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
    ) -> Stage {
        let n = problem.n_obs_rows;
        let c = at_v(q.as_ref(), &r);
        let rss = (0..n)
            .map(|i| {
                let v = r[i] - (0..q.ncols()).map(|k| q[(i, k)] * c[k]).sum::<f64>();
                v * v
            })
            .sum();
        Stage { options, problem, x, free, set, fit, j, r, q, rss }
    }

    pub fn n_rows(&self) -> usize {
        self.problem.n_rows
    }

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
                    let w = if r >= 3 { pr.rotation_weight * o.weight[1] } else { o.weight[0] };
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
    pub fn joint_columns(&self) -> Mat<f64> {
        let dof = self.problem.model.dof();
        self.columns(&(0..dof).map(Param::Theta).collect::<Vec<_>>())
    }

    /// Whether a global parameter is free in this model.
    pub fn is_free(&self, g: usize) -> bool {
        self.free.contains(&g)
    }

    /// Per layout entry: whether the model fits it.
    pub fn free_layout(&self) -> Vec<bool> {
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
