//! The identification problem: which measurements, which parameters, and the stacked residual and
//! Jacobian (eq. 4.12–4.15) of a parameter vector.
//!
//! Parameters form one global vector: the robot's (geometry, β, compliance, effect terms, base —
//! the [`ParamLayout`] without its tool entries) followed by six per tool block (x, y, z, a, b,
//! c of T_T^6). A tool block is one physical target ([`tool_blocks`]): the sessions that name
//! the same `target`; else a session whose TCP is identified, alone (three reflectors with the
//! same zero guess are three points on the flange, not one); else the sessions with the same
//! declared tool. Every measurement is evaluated with the chain of its own block.
//!
//! Rows per measurement: 3 for a ball or a position, 6 for a full pose — the rotation rows are the
//! world rotation vector of R_meas·R_modelᵀ times a length (`rotation_weight`, m/rad) so position
//! and orientation residuals share one unit. A TriCal measurement with indicator readings has its
//! target moved from the ball centre by the trilaterated offset, turned into {W} with the model's
//! tool orientation.

use faer::Mat;
use nalgebra::Vector3;
use rayon::prelude::*;

use crate::cell::{Cell, Measurement, Observation, Purpose, Session};
use crate::kinematics::frame::rotation_vector;
use crate::kinematics::params::REFERENCE_TEMPERATURE_C;
use crate::kinematics::{
    Chain, Frame, GravityModel, JointState, MAX_JOINTS, Param, ParamLayout, RobotModel, Rows, Tool,
};
use crate::metrology::TriCal;

/// One parameter of the global vector.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GlobalParam {
    /// A robot parameter: index into the problem's [`ParamLayout`].
    Robot(usize),
    /// Component k of tool t's T_T^6.
    Tool {
        /// The tool block: index into [`Problem::tools`].
        tool: usize,
        /// The component: 0–2 x, y, z (m), 3–5 a, b, c (rad, ZY'X'').
        k: usize,
    },
}

/// A distinct tool and the sessions that used it.
#[derive(Clone, Debug, PartialEq)]
pub struct ToolBlock {
    /// The tool as its first session declares it (TCP guess or value, payload).
    pub tool: Tool,
    /// Names of the sessions measured with it.
    pub sessions: Vec<String>,
    /// Its TCP is only a guess and should be identified.
    pub identify_tcp: bool,
    /// Whether any of its measurements is a full pose.
    pub has_orientation: bool,
}

/// What a measurement is compared with.
#[derive(Clone, Debug)]
enum Target {
    Point(Vector3<f64>),
    /// A ball centre corrected by the TriCal's trilaterated offset (tool frame).
    Ball {
        centre: Vector3<f64>,
        offset: Vector3<f64>,
    },
    Pose(Frame),
}

/// One measurement prepared for the solver.
#[derive(Clone, Debug)]
pub struct Obs {
    /// Index of the session in the cell and of the measurement in it.
    pub session: usize,
    /// Index of the measurement in its session (0-based).
    pub index: usize,
    /// Its tool block: index into [`Problem::tools`].
    pub tool: usize,
    /// The joint readings (rad), holding torques (N·m), approach directions and temperature.
    pub state: JointState,
    target: Target,
    /// First row in the stacked residual.
    pub row: usize,
    /// Its rows: 3 for a ball or a position, 6 for a full pose.
    pub rows: usize,
    /// Row multipliers (1/σ in a common unit) of the position rows (X, Y, Z of {W}) and of the
    /// rotation rows: 1 unless the caller weights the problem by an instrument model
    /// ([`Problem::set_weights`]).
    pub weight: [f64; 6],
    /// (sin, cos) of the joint readings, computed once ([`Chain::joint_sincos`]).
    q_sc: [(f64, f64); MAX_JOINTS],
}

impl Obs {
    /// The TCP pose of `chain` at this measurement's state, from the readings' (sin, cos) cached
    /// here: what the fit's residual is computed from.
    pub(crate) fn fk(&self, chain: &Chain) -> Frame {
        chain.fk_cached(&self.state, &self.q_sc)
    }

    /// Whether it measured a ball of the artefact (its position is the ball's, not the TCP's
    /// path).
    pub(crate) fn is_ball(&self) -> bool {
        matches!(self.target, Target::Ball { .. })
    }

    /// The measured TCP position in {W} (m): the point, the ball centre, or the pose's origin.
    pub(crate) fn measured_position(&self) -> Vector3<f64> {
        match &self.target {
            Target::Point(p) => *p,
            Target::Ball { centre, .. } => *centre,
            Target::Pose(f) => f.t,
        }
    }
}

/// A linear pseudo-observation Σ coef·x ≈ target on global parameters: the regularisation rows
/// of a correction table (smoothness, zero mean, target 0) or an anchor of a parameter to a
/// value. Appended after the measurement rows.
#[derive(Clone, Debug, PartialEq)]
pub struct Prior {
    /// (global index, coefficient) pairs.
    pub terms: Vec<(usize, f64)>,
    /// The value Σ coef·x is drawn to: the row's residual is `target` − Σ coef·x (the coefficients
    /// carry its weight).
    pub target: f64,
}

/// Which measurements enter the problem.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeasurementSelection {
    /// Session names; empty = every identification session.
    pub sessions: Vec<String>,
    /// A subset of measurements as (session name, index); empty = all of the chosen sessions.
    pub subset: Vec<(String, usize)>,
    /// Measurements left out (session name, 0-based index in the session): outliers.
    pub exclude: Vec<(String, usize)>,
}

impl MeasurementSelection {
    /// The selected measurements as (session index, measurement index), in selection order.
    pub fn picks(&self, cell: &Cell) -> Result<Vec<(usize, usize)>, ProblemError> {
        // Sessions.
        let chosen: Vec<usize> = if self.sessions.is_empty() {
            (0..cell.sessions.len()).filter(|&i| cell.sessions[i].purpose == Purpose::Identification).collect()
        } else {
            self.sessions
                .iter()
                .map(|n| {
                    cell.sessions
                        .iter()
                        .position(|s| &s.name == n)
                        .ok_or_else(|| ProblemError::UnknownSession(n.clone()))
                })
                .collect::<Result<_, _>>()?
        };
        // Measurements.
        let mut picks: Vec<(usize, usize)> = Vec::new();
        if self.subset.is_empty() {
            for &s in &chosen {
                picks.extend((0..cell.sessions[s].measurements.len()).map(|i| (s, i)));
            }
        } else {
            for (name, i) in &self.subset {
                let s = cell
                    .sessions
                    .iter()
                    .position(|s| &s.name == name)
                    .ok_or_else(|| ProblemError::UnknownSession(name.clone()))?;
                if *i >= cell.sessions[s].measurements.len() {
                    return Err(ProblemError::UnknownMeasurement { session: name.clone(), index: *i });
                }
                picks.push((s, *i));
            }
        }
        for (name, i) in &self.exclude {
            let s = cell
                .sessions
                .iter()
                .position(|s| &s.name == name)
                .ok_or_else(|| ProblemError::UnknownSession(name.clone()))?;
            if *i >= cell.sessions[s].measurements.len() {
                return Err(ProblemError::UnknownMeasurement { session: name.clone(), index: *i });
            }
            picks.retain(|&p| p != (s, *i));
        }
        if picks.is_empty() {
            return Err(ProblemError::Empty);
        }
        Ok(picks)
    }
}

/// Why the selected measurements cannot form a problem.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProblemError {
    /// No session of that name.
    #[error("no session named '{0}' in the cell")]
    UnknownSession(String),
    /// A measurement index beyond its session.
    #[error("measurement {index} of session '{session}' does not exist")]
    UnknownMeasurement {
        /// The session's name.
        session: String,
        /// The measurement's index (0-based).
        index: usize,
    },
    /// The selection leaves no measurement.
    #[error("no measurements to identify from")]
    Empty,
    /// A ball measurement in a cell without an artefact.
    #[error("a ball measurement needs the cell's artefact")]
    NoArtefact,
}

/// The tool blocks of the picked measurements (in order of first appearance) and, per session of
/// the cell, its block (`usize::MAX` when none of its measurements is picked). One block per
/// physical target: sessions naming the same `target` share one; a session whose TCP is identified
/// and that names no target has its own; the other sessions share a block when their declared
/// tools are equal (their TCPs are fixed: sharing changes nothing but the names).
pub fn tool_blocks(cell: &Cell, picks: &[(usize, usize)]) -> (Vec<ToolBlock>, Vec<usize>) {
    #[derive(PartialEq)]
    enum Key<'a> {
        Target(&'a str),
        Own(usize),
        Tool(&'a Tool),
    }
    let key = |s: usize| {
        let sess = &cell.sessions[s];
        match (&sess.target, sess.identify_tcp) {
            (Some(t), _) => Key::Target(t),
            (None, true) => Key::Own(s),
            (None, false) => Key::Tool(&sess.tool),
        }
    };
    let mut tools: Vec<ToolBlock> = Vec::new();
    let mut keys: Vec<Key> = Vec::new();
    let mut session_tool = vec![usize::MAX; cell.sessions.len()];
    for &(s, _) in picks {
        if session_tool[s] != usize::MAX {
            continue;
        }
        let sess: &Session = &cell.sessions[s];
        let k = key(s);
        let t = match keys.iter().position(|x| *x == k) {
            Some(t) => t,
            None => {
                keys.push(k);
                tools.push(ToolBlock {
                    tool: sess.tool.clone(),
                    sessions: Vec::new(),
                    identify_tcp: false,
                    has_orientation: false,
                });
                tools.len() - 1
            }
        };
        tools[t].sessions.push(sess.name.clone());
        tools[t].identify_tcp |= sess.identify_tcp;
        tools[t].has_orientation |=
            picks.iter().any(|&(ps, i)| ps == s && matches!(sess.measurements[i].observation, Observation::Pose(_)));
        session_tool[s] = t;
    }
    (tools, session_tool)
}

/// The identification problem of a cell.
#[derive(Clone, Debug)]
pub struct Problem {
    /// The robot model.
    pub model: RobotModel,
    /// The robot parameter layout (the full layout plus any effect terms); its tool entries are not
    /// global parameters: each tool block has its own six.
    pub layout: ParamLayout,
    /// The tool blocks, in order of first appearance; the first is the parameter set's tool.
    pub tools: Vec<ToolBlock>,
    /// The global parameter vector's entries: the layout's robot parameters in order, then six per
    /// tool block.
    pub params: Vec<GlobalParam>,
    /// Nominal value of every global parameter (SI).
    pub nominal: Vec<f64>,
    /// The measurements, in selection order.
    pub obs: Vec<Obs>,
    /// Rows of the stacked system: the measurement rows, then one per prior.
    pub n_rows: usize,
    /// Rows of the measurements alone.
    pub n_obs_rows: usize,
    /// Linear pseudo-observations, their rows after the measurement rows.
    pub priors: Vec<Prior>,
    /// m per rad for rotation residual rows.
    pub rotation_weight: f64,
    /// Session names, in cell order.
    pub session_names: Vec<String>,
}

/// Fill every observation's ∂τ/∂h (`JointState::tau_per_kgm`), for a payload's first-moment
/// error (`tool_moment_*`) that `extended` adds: the torques are linear in the last link's first
/// moment, so the slope per kilogram-metre along each flange axis is exact
/// ([`GravityModel::torques_and_payload_slopes`]).
fn fill_moment_torques(model: &RobotModel, tools: &[ToolBlock], obs: &mut [Obs]) {
    let models: Vec<GravityModel> = tools.iter().map(|b| GravityModel::new(model, &b.tool)).collect();
    let dof = model.dof();
    obs.par_iter_mut().with_min_len(PAR_MIN_OBS).for_each(|o| {
        let tool = &tools[o.tool].tool;
        let (_, _, per_kgm) = models[o.tool].torques_and_payload_slopes(&o.state.q[..dof], &tool.com, true);
        o.state.tau_per_kgm = per_kgm;
    });
}

impl Problem {
    /// Build the problem of `cell` with the robot parameter layout `layout` (the full layout plus any
    /// effect terms). Base nominal = `base`.
    pub fn new(
        cell: &Cell,
        layout: ParamLayout,
        base: [f64; 6],
        selection: &MeasurementSelection,
        rotation_weight: f64,
    ) -> Result<Problem, ProblemError> {
        let model = cell.model.clone();
        let picks = selection.picks(cell)?;
        let (tools, session_tool) = tool_blocks(cell, &picks);
        // Global parameters.
        let mut params = Vec::new();
        let mut nominal = Vec::new();
        let robot_nominal = layout.nominal_values(&model, &tools[0].tool, &base);
        for (i, p) in layout.params().iter().enumerate() {
            if !matches!(p, Param::Tool(_)) {
                params.push(GlobalParam::Robot(i));
                nominal.push(robot_nominal[i]);
            }
        }
        for (t, b) in tools.iter().enumerate() {
            for k in 0..6 {
                params.push(GlobalParam::Tool { tool: t, k });
                nominal.push(b.tool.tcp[k]);
            }
        }
        // Observations.
        let gravity: Vec<GravityModel> = tools.iter().map(|b| GravityModel::new(&model, &b.tool)).collect();
        // ∂τ/∂m of each tool, for a payload-error parameter (in the model or a candidate of the
        // diagnosis), and ∂τ/∂h for its first moment where the layout has it: the torques are
        // linear in the payload's mass and first moment, so the slopes are exact, not
        // finite-difference approximations. In parallel: the longest part of building a large
        // problem.
        let moments = layout.params().iter().any(|p| matches!(p, Param::ToolMoment(_)));
        let trical = TriCal::default();
        let torques: Vec<_> = picks
            .par_iter()
            .with_min_len(PAR_MIN_OBS)
            .map(|&(s, i)| {
                let q = &cell.sessions[s].measurements[i].q;
                let t = session_tool[s];
                gravity[t].torques_and_payload_slopes(q, &tools[t].tool.com, moments)
            })
            .collect();
        // Each measurement's place in the run, as the drift terms' basis, where the model has
        // them: zero (the run's mean, no drift) otherwise and when the measurements share no run.
        let drifts = layout.params().iter().any(|p| matches!(p, Param::Drift(..)));
        let run = drifts
            .then(|| super::run::run_positions(cell, &picks))
            .flatten()
            .and_then(|(_, at)| super::run::drift_basis(&at));
        let mut obs = Vec::with_capacity(picks.len());
        let mut row = 0;
        for (n, ((s, i), (tau, per_kg, per_kgm))) in picks.into_iter().zip(torques).enumerate() {
            let m: &Measurement = &cell.sessions[s].measurements[i];
            let t = session_tool[s];
            let mut state = JointState::with_torques(&m.q, &tau[..model.dof()]);
            if let Some(a) = &m.approach {
                for (j, &v) in a.iter().enumerate() {
                    state.approach[j] = v as f64;
                }
            }
            state.temperature_c = m.temperature_c.unwrap_or(REFERENCE_TEMPERATURE_C);
            state.tau_per_kg = per_kg;
            state.tau_per_kgm = per_kgm;
            if let Some(run) = &run {
                state.run = run[n];
            }
            let target = match (&m.observation, &m.indicators) {
                (Observation::Ball(k), ind) => {
                    let centre =
                        cell.artefact.as_ref().and_then(|a| a.triangle.ball(*k)).ok_or(ProblemError::NoArtefact)?;
                    match ind.and_then(|d| trical.offset(d).ok()) {
                        Some(offset) => Target::Ball { centre, offset },
                        None => Target::Point(centre),
                    }
                }
                (Observation::Position(p), _) => Target::Point(*p),
                (Observation::Pose(f), _) => Target::Pose(*f),
            };
            let rows = if matches!(target, Target::Pose(_)) { 6 } else { 3 };
            let mut q_sc = [(0.0, 1.0); MAX_JOINTS];
            for (sc, q) in q_sc.iter_mut().zip(&m.q) {
                *sc = q.sin_cos();
            }
            obs.push(Obs { session: s, index: i, tool: t, state, target, row, rows, weight: [1.0; 6], q_sc });
            row += rows;
        }
        Ok(Problem {
            model,
            layout,
            tools,
            params,
            nominal,
            obs,
            n_rows: row,
            n_obs_rows: row,
            priors: Vec::new(),
            rotation_weight,
            session_names: cell.sessions.iter().map(|s| s.name.clone()).collect(),
        })
    }

    /// Length of the global parameter vector.
    pub(crate) fn n_params(&self) -> usize {
        self.params.len()
    }

    /// The same problem with further robot parameters (effect terms) in its layout: the global
    /// vector gains them after the robot's other parameters (before the tools), and every
    /// existing global index moves accordingly. Returns the problem and, per old global index,
    /// its new one. Observations, weights and priors are kept (priors re-indexed).
    pub fn extended(&self, extra: &[Param]) -> (Problem, Vec<usize>) {
        let mut layout = self.layout.clone();
        layout.extend(extra);
        let base: [f64; 6] = {
            let mut b = [0.0; 6];
            for (g, p) in self.params.iter().enumerate() {
                if let GlobalParam::Robot(i) = *p
                    && let Param::Base(k) = self.layout.params()[i]
                {
                    b[k] = self.nominal[g];
                }
            }
            b
        };
        let robot_nominal = layout.nominal_values(&self.model, &self.tools[0].tool, &base);
        let mut params = Vec::new();
        let mut nominal = Vec::new();
        for (i, p) in layout.params().iter().enumerate() {
            if !matches!(p, Param::Tool(_)) {
                params.push(GlobalParam::Robot(i));
                nominal.push(robot_nominal[i]);
            }
        }
        for (t, b) in self.tools.iter().enumerate() {
            for k in 0..6 {
                params.push(GlobalParam::Tool { tool: t, k });
                nominal.push(b.tool.tcp[k]);
            }
        }
        // Old robot entries keep their layout index (the layout only grew at its end).
        let remap: Vec<usize> = self
            .params
            .iter()
            .map(|p| params.iter().position(|q| q == p).expect("every old parameter is still there"))
            .collect();
        let priors = self
            .priors
            .iter()
            .map(|p| Prior { terms: p.terms.iter().map(|&(g, c)| (remap[g], c)).collect(), target: p.target })
            .collect();
        let mut pr = Problem { layout, params, nominal, priors, ..self.clone() };
        pr.n_rows = pr.n_obs_rows + pr.priors.len();
        let had_moments = self.layout.params().iter().any(|p| matches!(p, Param::ToolMoment(_)));
        if !had_moments && extra.iter().any(|p| matches!(p, Param::ToolMoment(_))) {
            fill_moment_torques(&pr.model, &pr.tools, &mut pr.obs);
        }
        (pr, remap)
    }

    /// Weight every observation: `weight(obs)` gives the multipliers of its position rows and
    /// rotation rows (1/σ of each, in one common unit so the rows are comparable).
    pub fn set_weights(&mut self, mut weight: impl FnMut(&Obs) -> [f64; 6]) {
        for o in &mut self.obs {
            o.weight = weight(o);
        }
    }

    /// Append prior rows (Σ coef·x ≈ 0 on global parameters).
    pub(crate) fn add_priors(&mut self, priors: Vec<Prior>) {
        self.n_rows += priors.len();
        self.priors.extend(priors);
    }

    fn write_priors(&self, x: &[f64], out: &mut [f64]) {
        for (k, p) in self.priors.iter().enumerate() {
            out[self.n_obs_rows + k] = p.target - p.terms.iter().map(|&(g, c)| c * x[g]).sum::<f64>();
        }
    }

    /// Global index of a robot parameter, if present.
    pub(crate) fn robot_index(&self, p: Param) -> Option<usize> {
        let li = self.layout.index_of(p)?;
        self.params.iter().position(|g| *g == GlobalParam::Robot(li))
    }

    /// Human name of a global parameter: the layout name, or `tool_x` for the first tool and
    /// `tool2_x`, `tool3_x` … for the others.
    pub fn name(&self, g: usize) -> String {
        match self.params[g] {
            GlobalParam::Robot(i) => self.layout.params()[i].to_string(),
            GlobalParam::Tool { tool, k } => {
                let c = crate::kinematics::params::POSE_COMPONENTS[k];
                if tool == 0 { format!("tool_{c}") } else { format!("tool{}_{c}", tool + 1) }
            }
        }
    }

    /// The layout-ordered robot values with tool `t`'s block in the tool slots.
    pub(crate) fn layout_values(&self, x: &[f64], t: usize) -> Vec<f64> {
        let mut v = vec![0.0; self.layout.len()];
        for (g, p) in self.params.iter().enumerate() {
            match *p {
                GlobalParam::Robot(i) => v[i] = x[g],
                GlobalParam::Tool { tool, k } if tool == t => {
                    let i = self.layout.index_of(Param::Tool(k)).expect("the layout has tool entries");
                    v[i] = x[g];
                }
                _ => {}
            }
        }
        v
    }

    /// One chain per tool at `x`.
    pub fn chains(&self, x: &[f64]) -> Vec<Chain> {
        (0..self.tools.len()).map(|t| Chain::new(&self.model, &self.layout, &self.layout_values(x, t))).collect()
    }

    /// Residual (target − model) of every row at `x`.
    pub fn residual(&self, x: &[f64], out: &mut [f64]) {
        let chains = self.chains(x);
        let (obs_out, _) = out.split_at_mut(self.n_obs_rows);
        par_rows(&self.obs, obs_out, &|part, first, out: &mut [f64]| {
            for o in part {
                let f = chains[o.tool].fk_cached(&o.state, &o.q_sc);
                self.write_residual(o, &f, &mut out[o.row - first..o.row - first + o.rows]);
            }
        });
        self.write_priors(x, out);
    }

    /// The unweighted error target − model of an observation at the chain of its tool: position
    /// (m) and, for a pose, the world rotation vector of R_target·R_modelᵀ (rad).
    pub fn error(&self, o: &Obs, f: &Frame) -> (Vector3<f64>, Option<Vector3<f64>>) {
        let target = match &o.target {
            Target::Point(p) => *p,
            Target::Ball { centre, offset } => centre - f.r * offset,
            Target::Pose(p) => p.t,
        };
        let rot = match &o.target {
            Target::Pose(p) => Some(rotation_vector(&(p.r * f.r.transpose()))),
            _ => None,
        };
        (target - f.t, rot)
    }

    /// The observed position of an observation (its target before any TriCal offset), {W}, m.
    pub fn target_position(&self, o: &Obs) -> Vector3<f64> {
        match &o.target {
            Target::Point(p) => *p,
            Target::Ball { centre, .. } => *centre,
            Target::Pose(p) => p.t,
        }
    }

    fn write_residual(&self, o: &Obs, f: &Frame, out: &mut [f64]) {
        let (d, rot) = self.error(o, f);
        for k in 0..3 {
            out[k] = d[k] * o.weight[k];
        }
        if let Some(w) = rot {
            for k in 0..3 {
                out[3 + k] = w[k] * self.rotation_weight * o.weight[3 + k];
            }
        }
    }

    /// Jacobian of every parameter (column g = global index g) and the residual at `x`: what the
    /// identifiability sweep and the priors judge.
    pub(crate) fn linearise_all(&self, x: &[f64]) -> (Mat<f64>, Vec<f64>) {
        let all: Vec<usize> = (0..self.n_params()).collect();
        let mut jac = Mat::<f64>::zeros(self.n_rows, all.len());
        let mut res = vec![0.0; self.n_rows];
        self.linearise(x, &all, &mut jac, &mut res);
        (jac, res)
    }

    /// Residual and Jacobian of the free parameters (`free[c]` = global index of column c) at `x`.
    /// ∂(residual)/∂ρ = −∂(model)/∂ρ; we return J = ∂(model)/∂ρ so that Δρ solves J·Δρ ≈ r.
    pub fn linearise(&self, x: &[f64], free: &[usize], jac: &mut Mat<f64>, res: &mut [f64]) {
        let chains = self.chains(x);
        let m = self.layout.len();
        // Column of each layout entry for each tool.
        let mut col_of = vec![vec![None; m]; self.tools.len()];
        for (c, &g) in free.iter().enumerate() {
            match self.params[g] {
                GlobalParam::Robot(i) => {
                    for t in 0..self.tools.len() {
                        col_of[t][i] = Some(c);
                    }
                }
                GlobalParam::Tool { tool, k } => {
                    let i = self.layout.index_of(Param::Tool(k)).expect("tool entries");
                    col_of[tool][i] = Some(c);
                }
            }
        }
        // Per tool, the (layout entry, output column) pairs to compute: the free ones only.
        let wanted: Vec<Vec<(usize, usize)>> = col_of
            .iter()
            .map(|cols| cols.iter().enumerate().filter_map(|(i, c)| c.map(|c| (i, c))).collect())
            .collect();
        // The measurement rows, in parallel over contiguous parts of the observations: each part
        // writes its own rows of J and r.
        let (obs_jac, _) = jac.as_mut().split_at_row_mut(self.n_obs_rows);
        let (obs_res, _) = res.split_at_mut(self.n_obs_rows);
        let parts = JacRows { jac: obs_jac, res: obs_res };
        par_rows(&self.obs, parts, &|part, first, mut rows_out: JacRows| {
            let mut buf = vec![0.0; 6 * free.len().max(1)];
            for o in part {
                let rows = if o.rows == 6 { Rows::Pose } else { Rows::Position };
                let f = chains[o.tool].jacobian_columns_cached(
                    &o.state,
                    &o.q_sc,
                    &self.layout,
                    rows,
                    wanted[o.tool].iter().copied(),
                    &mut buf,
                    6,
                );
                let at = o.row - first;
                self.write_residual(o, &f, &mut rows_out.res[at..at + o.rows]);
                for &(_, c) in &wanted[o.tool] {
                    for r in 0..o.rows {
                        let w = if r >= 3 { self.rotation_weight * o.weight[r] } else { o.weight[r] };
                        rows_out.jac[(at + r, c)] = buf[c * 6 + r] * w;
                    }
                }
            }
        });
        if !self.priors.is_empty() {
            self.write_priors(x, res);
            let col: std::collections::HashMap<usize, usize> = free.iter().enumerate().map(|(c, &g)| (g, c)).collect();
            for (k, p) in self.priors.iter().enumerate() {
                let r = self.n_obs_rows + k;
                for c in 0..free.len() {
                    jac[(r, c)] = 0.0;
                }
                for &(g, coef) in &p.terms {
                    if let Some(&c) = col.get(&g) {
                        jac[(r, c)] += coef;
                    }
                }
            }
        }
    }

    /// The Jacobian block of one observation (rows × free), e.g. for DETMAX pools.
    pub fn block(&self, chains: &[Chain], o: &Obs, free: &[usize]) -> Vec<f64> {
        let m = self.layout.len();
        let mut buf = vec![0.0; 6 * m];
        let rows = if o.rows == 6 { Rows::Pose } else { Rows::Position };
        chains[o.tool].jacobian_into(&o.state, &self.layout, rows, &mut buf, 6);
        let mut out = vec![0.0; o.rows * free.len()];
        for (c, &g) in free.iter().enumerate() {
            let i = match self.params[g] {
                GlobalParam::Robot(i) => Some(i),
                GlobalParam::Tool { tool, k } if tool == o.tool => self.layout.index_of(Param::Tool(k)),
                _ => None,
            };
            if let Some(i) = i {
                for r in 0..o.rows {
                    let w = if r >= 3 { self.rotation_weight * o.weight[r] } else { o.weight[r] };
                    out[r * free.len() + c] = buf[i * 6 + r] * w;
                }
            }
        }
        out
    }
}

/// Observations per part below which the work is not split further across threads (handing a
/// part to another thread costs a few microseconds; one observation's FK and Jacobian about half
/// of one).
pub(crate) const PAR_MIN_OBS: usize = 256;

/// The rows of the stacked system that a part of the observations writes: a row range of J and r.
struct JacRows<'a> {
    jac: faer::MatMut<'a, f64>,
    res: &'a mut [f64],
}

/// Output that splits at a row (counted from its first row) into two independent parts.
trait SplitRows: Send + Sized {
    fn split(self, row: usize) -> (Self, Self);
}

impl SplitRows for &mut [f64] {
    fn split(self, row: usize) -> (Self, Self) {
        self.split_at_mut(row)
    }
}

impl SplitRows for JacRows<'_> {
    fn split(self, row: usize) -> (Self, Self) {
        let (j1, j2) = self.jac.split_at_row_mut(row);
        let (r1, r2) = self.res.split_at_mut(row);
        (JacRows { jac: j1, res: r1 }, JacRows { jac: j2, res: r2 })
    }
}

/// Run `f(part, first_row, out)` on contiguous parts of `obs` in parallel, each part with the
/// rows of `out` it owns (`out` starts at `obs[0].row`; the observations' rows are contiguous and
/// in order). Small problems run on the calling thread.
fn par_rows<O: SplitRows>(obs: &[Obs], out: O, f: &(dyn Fn(&[Obs], usize, O) + Sync)) {
    if obs.len() < 2 * PAR_MIN_OBS || rayon::current_num_threads() < 2 {
        f(obs, obs.first().map_or(0, |o| o.row), out);
        return;
    }
    let mid = obs.len() / 2;
    let (a, b) = out.split(obs[mid].row - obs[0].row);
    rayon::join(|| par_rows(&obs[..mid], a, f), || par_rows(&obs[mid..], b, f));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cell::fixtures::{irb120_cell, measurement, random_configurations, session};
    use crate::kinematics::ParameterSet;
    use crate::kinematics::frame::rot_zyx;
    use crate::kinematics::model::irb120;
    use crate::kinematics::thesis::trical_tool;

    /// T_0^W of the problems below (m, rad): the thesis cell's base, roughly.
    const BASE: [f64; 6] = [0.160, -0.256, -0.221, 1.6, 0.009, -0.024];
    const ROTATION_WEIGHT: f64 = 0.5;

    /// A tracker nest on the TriCal body: another tool than the TriCal's ball.
    fn nest() -> Tool {
        Tool { tcp: [0.0, 0.060, 0.080, 0.0, 0.0, 0.0], ..trical_tool() }
    }

    /// The nominal TCP frame of `tool` at q, computed apart from the problem.
    fn nominal_fk(tool: &Tool, q: &[f64]) -> Frame {
        ParameterSet::nominal(irb120(), tool.clone(), BASE).nominal_chain().fk(&JointState::new(q))
    }

    /// Four sessions: three balls with the TriCal, three positions with the TriCal again (a second
    /// session with the same tool), two full poses with the nest (targets off the nominal model by
    /// a few mm and mrad), and a validation session.
    fn cell() -> Cell {
        let q = random_configurations(12, 7);
        let balls = (0..3).map(|i| measurement(q[i].clone(), Observation::Ball(i + 1))).collect();
        let points = (3..6)
            .map(|i| {
                let p = nominal_fk(&trical_tool(), &q[i]).t + Vector3::new(0.001, -0.002, 0.0005);
                measurement(q[i].clone(), Observation::Position(p))
            })
            .collect();
        let poses = (6..8)
            .map(|i| {
                let f = nominal_fk(&nest(), &q[i]);
                let off = Frame::new(rot_zyx(0.002, -0.001, 0.003), Vector3::new(0.002, 0.001, -0.001));
                measurement(q[i].clone(), Observation::Pose(f.compose(&off)))
            })
            .collect();
        let check = (8..12).map(|i| measurement(q[i].clone(), Observation::Ball(1))).collect();
        irb120_cell(vec![
            session("balls", Purpose::Identification, trical_tool(), balls),
            session("points", Purpose::Identification, trical_tool(), points),
            session("poses", Purpose::Identification, nest(), poses),
            session("check", Purpose::Validation, trical_tool(), check),
        ])
    }

    fn problem(cell: &Cell, selection: &MeasurementSelection) -> Result<Problem, ProblemError> {
        Problem::new(cell, ParamLayout::full(&cell.model), BASE, selection, ROTATION_WEIGHT)
    }

    fn residual(p: &Problem, x: &[f64]) -> Vec<f64> {
        let mut r = vec![0.0; p.n_rows];
        p.residual(x, &mut r);
        r
    }

    /// In a model with drift terms, each measurement's place in its run becomes the drift basis of
    /// its state: from the sequence numbers two sessions share (a plate's reflectors), centred
    /// over the problem's measurements; two sessions with neither times nor sequence numbers share
    /// no run, and every state keeps the run's mean (zero), where a drift term moves nothing.
    #[test]
    fn each_measurements_place_in_its_run_is_its_drift_basis() {
        let q = random_configurations(40, 3);
        let seq = |first: usize, with: bool| -> Vec<Measurement> {
            (0..20)
                .map(|i| {
                    let mut m = measurement(q[first + i].clone(), Observation::Position(Vector3::new(0.4, 0.1, 0.5)));
                    m.sequence = with.then_some(10 * i as u64);
                    m
                })
                .collect()
        };
        for with in [true, false] {
            // The same stops read by two reflectors when numbered; two separate runs otherwise.
            let second = if with { 0 } else { 20 };
            let cell = irb120_cell(vec![
                session("r1", Purpose::Identification, trical_tool(), seq(0, with)),
                session("r2", Purpose::Identification, nest(), seq(second, with)),
            ]);
            let mut layout = ParamLayout::full(&cell.model);
            layout.extend(&crate::identify::drift_terms());
            let p = Problem::new(&cell, layout, BASE, &MeasurementSelection::default(), ROTATION_WEIGHT).unwrap();
            let expected = crate::identify::run::drift_basis(&(0..20).map(|i| 10.0 * i as f64).collect::<Vec<_>>());
            for o in &p.obs {
                let want = if with { expected.as_ref().unwrap()[o.index] } else { [0.0; 3] };
                let off = o.state.run.iter().zip(want).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
                assert!(off < 1e-15, "{} [{}]: {:?} against {want:?}", o.session, o.index, o.state.run);
            }
        }
    }

    /// A problem large enough to be split across threads (1,200 measurements, mixed position and
    /// pose rows, two tools) linearises to exactly what each observation's block computes on its
    /// own through the uncached kinematics, and its residual is the same in both passes.
    #[test]
    fn parallel_linearisation_matches_each_observation() {
        let q = random_configurations(1200, 5);
        let points =
            (0..700).map(|i| measurement(q[i].clone(), Observation::Position(Vector3::new(0.4, 0.1, 0.5)))).collect();
        let poses =
            (700..1200).map(|i| measurement(q[i].clone(), Observation::Pose(nominal_fk(&nest(), &q[i])))).collect();
        let cell = irb120_cell(vec![
            session("points", Purpose::Identification, trical_tool(), points),
            session("poses", Purpose::Identification, nest(), poses),
        ]);
        let p = problem(&cell, &MeasurementSelection::default()).unwrap();
        assert!(p.obs.len() >= 2 * PAR_MIN_OBS);
        let free: Vec<usize> = (0..p.n_params()).collect();
        let mut x = p.nominal.clone();
        for (k, v) in x.iter_mut().enumerate() {
            *v += 1e-4 * ((k % 7) as f64 - 3.0);
        }
        let mut jac = Mat::<f64>::zeros(p.n_rows, free.len());
        let mut res = vec![0.0; p.n_rows];
        p.linearise(&x, &free, &mut jac, &mut res);
        let chains = p.chains(&x);
        for o in &p.obs {
            let b = p.block(&chains, o, &free);
            for r in 0..o.rows {
                for c in 0..free.len() {
                    let (got, want) = (jac[(o.row + r, c)], b[r * free.len() + c]);
                    assert!((got - want).abs() <= 1e-12 * (1.0 + want.abs()), "obs {} row {r} col {c}", o.index);
                }
            }
            let f = chains[o.tool].fk(&o.state);
            let mut want = [0.0; 6];
            p.write_residual(o, &f, &mut want[..o.rows]);
            for r in 0..o.rows {
                assert!((res[o.row + r] - want[r]).abs() < 1e-14);
            }
        }
        assert_eq!(residual(&p, &x), res);
    }

    /// Rows: 3 per ball or position, 6 per pose, stacked in selection order; the validation
    /// session only when named. One parameter block per distinct tool, shared by the sessions
    /// that used it.
    #[test]
    fn rows_and_tool_blocks() {
        let cell = cell();
        let p = problem(&cell, &MeasurementSelection::default()).unwrap();
        assert_eq!(p.obs.len(), 8);
        assert_eq!(p.n_rows, 3 * 3 + 3 * 3 + 2 * 6);
        let rows: Vec<(usize, usize)> = p.obs.iter().map(|o| (o.row, o.rows)).collect();
        let want: Vec<(usize, usize)> = (0..6).map(|i| (3 * i, 3)).chain([(18, 6), (24, 6)]).collect();
        assert_eq!(rows, want);
        assert_eq!(p.tools.len(), 2);
        assert_eq!(p.tools[0].sessions, ["balls", "points"]);
        assert_eq!(p.tools[1].sessions, ["poses"]);
        assert_eq!((p.tools[0].has_orientation, p.tools[1].has_orientation), (false, true));
        assert_eq!(p.obs.iter().map(|o| o.tool).collect::<Vec<_>>(), [0, 0, 0, 0, 0, 0, 1, 1]);
        // The robot's parameters without the layout's tool entries, then six per tool.
        let robot = p.layout.len() - 6;
        assert_eq!(p.n_params(), robot + 12);
        assert_eq!(p.params[robot + 7], GlobalParam::Tool { tool: 1, k: 1 });
        assert_eq!((p.name(robot), p.name(robot + 11)), ("tool_x".to_string(), "tool2_c".to_string()));
        assert_eq!(&p.nominal[robot + 6..robot + 12], &nest().tcp);
        assert_eq!(p.nominal[p.robot_index(Param::Base(3)).unwrap()], BASE[3]);

        // The validation session, named, alone.
        let only = MeasurementSelection { sessions: vec!["check".into()], ..Default::default() };
        let p = problem(&cell, &only).unwrap();
        assert_eq!((p.obs.len(), p.n_rows, p.tools.len()), (4, 12, 1));
        // A subset, in its own order.
        let subset =
            MeasurementSelection { subset: vec![("poses".into(), 1), ("balls".into(), 2)], ..Default::default() };
        let p = problem(&cell, &subset).unwrap();
        assert_eq!(p.obs.iter().map(|o| (o.session, o.index, o.row)).collect::<Vec<_>>(), [(2, 1, 0), (0, 2, 6)]);
        assert_eq!(p.tools[0].tool, nest());
    }

    /// One TCP per physical target: sessions whose TCP is identified get one each even with equal
    /// (zero) guesses; sessions naming one target share it; declared equal tools share as before.
    /// An excluded measurement is not in the problem, an unknown one is an error.
    #[test]
    fn tool_blocks_are_physical_targets() {
        let q = random_configurations(6, 3);
        let point = |i: usize| measurement(q[i].clone(), Observation::Position(Vector3::new(0.5, 0.1, 0.3)));
        let reflector = |name: &str, i: usize| {
            let mut s = session(name, Purpose::Identification, Tool::flange(), vec![point(i), point(i + 1)]);
            s.identify_tcp = true;
            s
        };
        let mut cell = irb120_cell(vec![
            reflector("r1", 0),
            reflector("r2", 2),
            reflector("r3", 4),
            session("declared-a", Purpose::Identification, nest(), vec![point(0)]),
            session("declared-b", Purpose::Identification, nest(), vec![point(1)]),
        ]);
        let blocks = |cell: &Cell| {
            let p = problem(cell, &MeasurementSelection::default()).unwrap();
            p.tools.iter().map(|b| (b.sessions.join("+"), b.identify_tcp)).collect::<Vec<_>>()
        };
        let own = |s: &str| (s.to_string(), true);
        assert_eq!(blocks(&cell), [own("r1"), own("r2"), own("r3"), ("declared-a+declared-b".into(), false)]);
        cell.sessions[0].target = Some("nest-1".into());
        cell.sessions[2].target = Some("nest-1".into());
        assert_eq!(blocks(&cell), [own("r1+r3"), own("r2"), ("declared-a+declared-b".into(), false)]);
        cell.sessions[4].target = Some("nest-2".into());
        assert_eq!(blocks(&cell)[2..], [("declared-a".into(), false), ("declared-b".into(), false)]);

        let sel = MeasurementSelection { exclude: vec![("r2".into(), 1)], ..Default::default() };
        let p = problem(&cell, &sel).unwrap();
        assert_eq!(p.obs.len(), 7);
        assert!(!p.obs.iter().any(|o| o.session == 1 && o.index == 1));
        let sel = MeasurementSelection { exclude: vec![("r2".into(), 2)], ..Default::default() };
        assert_eq!(
            problem(&cell, &sel).unwrap_err(),
            ProblemError::UnknownMeasurement { session: "r2".into(), index: 2 }
        );
    }

    #[test]
    fn selection_errors() {
        let cell = cell();
        let sel = |sessions: &[&str], subset: &[(&str, usize)]| MeasurementSelection {
            sessions: sessions.iter().map(|s| s.to_string()).collect(),
            subset: subset.iter().map(|(s, i)| (s.to_string(), *i)).collect(),
            exclude: Vec::new(),
        };
        assert_eq!(problem(&cell, &sel(&["nope"], &[])).unwrap_err(), ProblemError::UnknownSession("nope".into()));
        assert_eq!(
            problem(&cell, &sel(&[], &[("points", 3)])).unwrap_err(),
            ProblemError::UnknownMeasurement { session: "points".into(), index: 3 }
        );
        let mut empty = cell.clone();
        empty.sessions.retain(|s| s.purpose == Purpose::Validation);
        assert_eq!(problem(&empty, &MeasurementSelection::default()).unwrap_err(), ProblemError::Empty);
        let mut bare = cell.clone();
        bare.artefact = None;
        assert_eq!(problem(&bare, &MeasurementSelection::default()).unwrap_err(), ProblemError::NoArtefact);
    }

    /// r = target − model: the residual at the nominal parameters against forward kinematics
    /// computed apart, for a ball (its centre), a position and a pose (its rotation rows the
    /// rotation vector of R_target·R_modelᵀ, weighted).
    #[test]
    fn residual_is_target_minus_model() {
        let cell = cell();
        let p = problem(&cell, &MeasurementSelection::default()).unwrap();
        let r = residual(&p, &p.nominal);
        for o in &p.obs {
            let m = &cell.sessions[o.session].measurements[o.index];
            let tool = &cell.sessions[o.session].tool;
            let model = nominal_fk(tool, &m.q);
            let (target, rot) = match &m.observation {
                Observation::Ball(k) => (cell.artefact.as_ref().unwrap().triangle.ball(*k).unwrap(), None),
                Observation::Position(t) => (*t, None),
                Observation::Pose(f) => (f.t, Some(rotation_vector(&(f.r * model.r.transpose())) * ROTATION_WEIGHT)),
            };
            let d = target - model.t;
            for k in 0..3 {
                assert!(
                    (r[o.row + k] - d[k]).abs() < 1e-12,
                    "{:?} row {k}: {} vs {}",
                    m.observation,
                    r[o.row + k],
                    d[k]
                );
            }
            if let Some(w) = rot {
                for k in 0..3 {
                    assert!((r[o.row + 3 + k] - w[k]).abs() < 1e-12);
                }
                assert!(w.norm() > 1e-3 * ROTATION_WEIGHT, "the targets are off in rotation");
            }
        }
        // The position session's targets are off the nominal model by (1, −2, 0.5) mm.
        assert!((r[9] - 0.001).abs() < 1e-12 && (r[10] + 0.002).abs() < 1e-12 && (r[11] - 0.0005).abs() < 1e-12);
    }

    /// A ball target is the ball's centre: the same rows as a position target there. With
    /// indicator readings the target moves by the trilaterated offset, turned into {W} by the
    /// model's tool orientation.
    #[test]
    fn ball_target_against_position_target() {
        let q = random_configurations(1, 8).remove(0);
        let centre = crate::cell::fixtures::artefact().triangle.ball(2).unwrap();
        let readings = [120e-6, -40e-6, 75e-6];
        let mut with_readings = measurement(q.clone(), Observation::Ball(2));
        with_readings.indicators = Some(readings);
        let cell = irb120_cell(vec![session(
            "s",
            Purpose::Identification,
            trical_tool(),
            vec![
                measurement(q.clone(), Observation::Ball(2)),
                measurement(q.clone(), Observation::Position(centre)),
                with_readings,
            ],
        )]);
        let p = problem(&cell, &MeasurementSelection::default()).unwrap();
        let r = residual(&p, &p.nominal);
        assert_eq!(r[0..3], r[3..6]);
        let offset = TriCal::default().offset(readings).unwrap();
        assert!(offset.norm() > 1e-5);
        let model = nominal_fk(&trical_tool(), &q);
        let want = centre - model.r * offset - model.t;
        for k in 0..3 {
            assert!((r[6 + k] - want[k]).abs() < 1e-12, "{} vs {}", r[6 + k], want[k]);
        }
    }

    /// The Jacobian J = ∂model/∂ρ of every parameter is −∂r/∂ρ by central differences of the
    /// residual, at the nominal parameters (where the pose targets' rotation residual is a few
    /// mrad) and, for the position rows, at a point away from nominal. The rotation rows are the
    /// linearisation of the rotation vector at a small residual rotation, exact only as that
    /// rotation vanishes: compared within 1e-2 of their column there (the residual is 4 mrad).
    #[test]
    fn jacobian_matches_central_differences_of_the_residual() {
        let cell = cell();
        let p = problem(&cell, &MeasurementSelection::default()).unwrap();
        let all: Vec<usize> = (0..p.n_params()).collect();
        let mut away = p.nominal.clone();
        for (g, v) in away.iter_mut().enumerate() {
            *v += 1e-3 * ((g % 7) as f64 - 3.0);
        }
        for (x, rotation_rows) in [(&p.nominal, true), (&away, false)] {
            let mut jac = Mat::<f64>::zeros(p.n_rows, all.len());
            let mut r0 = vec![0.0; p.n_rows];
            p.linearise(x, &all, &mut jac, &mut r0);
            assert_eq!(r0, residual(&p, x), "linearise returns the residual too");
            let h = 1e-6;
            for g in all.iter().copied() {
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[g] += h;
                xm[g] -= h;
                let (rp, rm) = (residual(&p, &xp), residual(&p, &xm));
                let col_norm = (0..p.n_rows).map(|row| jac[(row, g)].powi(2)).sum::<f64>().sqrt();
                for o in &p.obs {
                    let rows = if rotation_rows { o.rows } else { 3 };
                    for k in 0..rows {
                        let row = o.row + k;
                        let fd = -(rp[row] - rm[row]) / (2.0 * h);
                        let tol = if k < 3 { 1e-7 * col_norm.max(1.0) } else { 1e-2 * col_norm.max(1e-3) };
                        assert!(
                            (fd - jac[(row, g)]).abs() <= tol,
                            "{} row {row}: analytic {} vs fd {fd}",
                            p.name(g),
                            jac[(row, g)]
                        );
                    }
                }
            }
        }
    }

    /// A DETMAX block is the observation's rows of the Jacobian of the free columns.
    #[test]
    fn block_is_the_jacobian_rows_of_one_observation() {
        let cell = cell();
        let p = problem(&cell, &MeasurementSelection::default()).unwrap();
        let free: Vec<usize> = (0..p.n_params()).filter(|g| g % 3 != 1).collect();
        let mut jac = Mat::<f64>::zeros(p.n_rows, free.len());
        let mut r = vec![0.0; p.n_rows];
        p.linearise(&p.nominal, &free, &mut jac, &mut r);
        let chains = p.chains(&p.nominal);
        for o in &p.obs {
            let b = p.block(&chains, o, &free);
            for k in 0..o.rows {
                for c in 0..free.len() {
                    let (got, want) = (b[k * free.len() + c], jac[(o.row + k, c)]);
                    assert!((got - want).abs() <= 1e-14 * want.abs().max(1.0), "obs {} row {k} column {c}", o.row);
                }
            }
        }
    }
}
