//! The candidate pool for DETMAX (§4.2.5): every measurement of the chosen sessions as its
//! Jacobian block on the identifiable parameters, built once and selected from many times.

use super::prepare::{Prepared, prepare};
use super::problem::{GlobalParam, Problem};
use super::{IdentifyError, IdentifyOptions, detmax, observability};
use crate::cell::Cell;
use crate::kinematics::Param;

/// The candidate pool for DETMAX: every measurement of the chosen sessions, as its Jacobian
/// block on the identifiable parameters at the starting point (SI units, as the thesis computes
/// O1). Build once, select many times (the study draws thousands of sets from one pool).
pub struct DetmaxPool {
    blocks: Vec<detmax::Block>,
    members: Vec<(String, usize)>,
    m: usize,
    /// The pool's problem, starting point and free parameters, for workspace Jacobians.
    problem: Problem,
    x0: Vec<f64>,
    free: Vec<usize>,
}

impl DetmaxPool {
    /// The pool of `cell` under `opts`: every measurement of the chosen sessions (the options'
    /// `subset` ignored), as its block on the parameters free at the starting point. Refused for the
    /// reasons an identification's preparation is.
    pub fn new(cell: &Cell, opts: &IdentifyOptions) -> Result<DetmaxPool, IdentifyError> {
        let mut pool_opts = opts.clone();
        pool_opts.selection.subset.clear();
        let Prepared { problem, x0, free, .. } = prepare(cell, &pool_opts)?;
        let chains = problem.chains(&x0);
        let blocks = problem
            .obs
            .iter()
            .map(|o| detmax::Block { rows: o.rows, data: problem.block(&chains, o, &free) })
            .collect();
        let members = problem.obs.iter().map(|o| (problem.session_names[o.session].clone(), o.index)).collect();
        Ok(DetmaxPool { blocks, members, m: free.len(), problem, x0, free })
    }

    /// A workspace for [`Self::select_prediction`]: `count` configurations drawn uniformly within
    /// the joint limits (ChaCha8, `seed`), carrying the pool's first tool, as position blocks on
    /// the pool's parameters at its starting point (unweighted, metres: the prediction's units).
    pub fn uniform_workspace(&self, count: usize, seed: u64) -> Result<detmax::Workspace, IdentifyError> {
        use crate::kinematics::{GravityModel, JointState, Rows};
        use rand::{Rng, SeedableRng};
        let p = &self.problem;
        let chain = &p.chains(&self.x0)[0];
        let tool = &p.tools[0].tool;
        let gravity = GravityModel::new(&p.model, tool);
        let moments = p.layout.params().iter().any(|p| matches!(p, Param::ToolMoment(_)));
        // Layout column of each free parameter on tool 0's chain (another tool's: none).
        let cols: Vec<Option<usize>> = self
            .free
            .iter()
            .map(|&g| match p.params[g] {
                GlobalParam::Robot(i) => Some(i),
                GlobalParam::Tool { tool: 0, k } => p.layout.index_of(Param::Tool(k)),
                GlobalParam::Tool { .. } => None,
            })
            .collect();
        let dof = p.model.dof();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut buf = vec![0.0; 3 * p.layout.len()];
        let mut q = vec![0.0; dof];
        let blocks: Vec<detmax::Block> = (0..count)
            .map(|_| {
                for (j, l) in p.model.links.iter().enumerate() {
                    q[j] = rng.random_range(l.limits[0]..=l.limits[1]);
                }
                let (tau, per_kg, per_kgm) = gravity.torques_and_payload_slopes(&q, &tool.com, moments);
                let mut s = JointState::with_torques(&q, &tau[..dof]);
                s.temperature_c = crate::kinematics::params::REFERENCE_TEMPERATURE_C;
                s.tau_per_kg = per_kg;
                s.tau_per_kgm = per_kgm;
                chain.jacobian_into(&s, &p.layout, Rows::Position, &mut buf, 3);
                let mut data = vec![0.0; 3 * cols.len()];
                for (c, col) in cols.iter().enumerate() {
                    if let Some(i) = col {
                        for r in 0..3 {
                            data[r * cols.len() + c] = buf[i * 3 + r];
                        }
                    }
                }
                detmax::Block::new(3, data)
            })
            .collect();
        detmax::Workspace::new(&blocks, self.m).map_err(|e| IdentifyError::option(format!("DETMAX workspace: {e}")))
    }

    /// `n` measurements minimising the mean prediction variance over `workspace` (see
    /// [`detmax::detmax_prediction`]) from a random start drawn with `seed`: the subset and a
    /// description for the quality report.
    pub fn select_prediction(
        &self,
        n: usize,
        seed: u64,
        workspace: &detmax::Workspace,
    ) -> Result<(Vec<(String, usize)>, serde_json::Value), IdentifyError> {
        let o = detmax::DetmaxOptions { seed, ..detmax::DetmaxOptions::new(n) };
        let d = detmax::detmax_prediction(&self.blocks, self.m, workspace, &o)
            .map_err(|e| IdentifyError::option(format!("DETMAX: {e}")))?;
        let subset = d.selected.iter().map(|&i| self.members[i].clone()).collect();
        let info = serde_json::json!({
            "method": "detmax", "n": n, "criterion": "prediction", "seed": seed, "pool": self.blocks.len(),
            "workspace_rows": workspace.rows(),
            "prediction_rms_initial": d.index_initial, "prediction_rms_final": d.index_final,
            "exchanges": d.exchanges, "polish": o.polish, "polish_exchanges": d.polish_exchanges,
            "converged": d.converged,
        });
        Ok((subset, info))
    }

    /// The candidates' Jacobian blocks, in pool order, with their (session, index).
    pub fn blocks(&self) -> (&[detmax::Block], &[(String, usize)]) {
        (&self.blocks, &self.members)
    }

    /// Candidates in the pool.
    pub fn len(&self) -> usize {
        self.blocks.len()
    }

    /// Whether the pool has no candidate.
    pub fn is_empty(&self) -> bool {
        self.blocks.is_empty()
    }

    /// `n` measurements maximising `index` from a random start drawn with `seed`: the subset
    /// (session, index) and a description for the quality report.
    pub fn select(
        &self,
        n: usize,
        index: observability::Index,
        seed: u64,
    ) -> Result<(Vec<(String, usize)>, serde_json::Value), IdentifyError> {
        self.select_with(&detmax::DetmaxOptions { index, seed, ..detmax::DetmaxOptions::new(n) })
    }

    /// As [`Self::select`] with every DETMAX option (e.g. `polish: false`, the thesis's DETMAX
    /// alone, whose random starts end in different local optima).
    pub(crate) fn select_with(
        &self,
        o: &detmax::DetmaxOptions,
    ) -> Result<(Vec<(String, usize)>, serde_json::Value), IdentifyError> {
        let (n, index, seed) = (o.n, o.index, o.seed);
        let d = detmax::detmax(&self.blocks, self.m, o).map_err(|e| IdentifyError::option(format!("DETMAX: {e}")))?;
        let subset = d.selected.iter().map(|&i| self.members[i].clone()).collect();
        let info = serde_json::json!({
            "method": "detmax", "n": n, "index": index.name(), "seed": seed, "pool": self.blocks.len(),
            "index_initial": d.index_initial, "index_final": d.index_final, "exchanges": d.exchanges,
            "polish": o.polish, "polish_exchanges": d.polish_exchanges, "converged": d.converged,
        });
        Ok((subset, info))
    }
}

/// DETMAX selection of `n` measurements from the chosen sessions (the pool), maximising `index`
/// on the Jacobian blocks of the identifiable parameters at the starting point. Returns the
/// subset (session, index) and a description for the quality report.
pub fn select_detmax(
    cell: &Cell,
    opts: &IdentifyOptions,
    n: usize,
    index: observability::Index,
    seed: u64,
) -> Result<(Vec<(String, usize)>, serde_json::Value), IdentifyError> {
    DetmaxPool::new(cell, opts)?.select(n, index, seed)
}
