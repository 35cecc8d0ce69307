//! Identification (thesis §4.2, §6; digest §4, §6): the parameters of a better model from a
//! cell's measurements — least squares on faer with Levenberg–Marquardt damping, automatic
//! identifiability, conditioning and observability, honest uncertainties, DETMAX pose selection.

pub mod crossval;
pub mod detmax;
pub mod identifiability;
pub mod observability;
pub mod problem;
pub mod quality;
pub mod solver;
pub mod study;

use std::collections::HashMap;

use faer::Mat;

use crate::cell::Cell;
use crate::kinematics::{JointTerm, Param, ParamLayout, ParameterSet, Tool};
use crate::metrology::registration::{RegistrationError, estimate_base_of};
pub use identifiability::Status;
pub use problem::{GlobalParam, MeasurementSelection, Problem, ProblemError};
pub use quality::Quality;
pub use solver::{Fit, SolveError, SolverOptions};

/// Which model is fitted: the structure's optional blocks and effect terms.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelOptions {
    /// Hayati β on the joints that have it.
    pub beta: bool,
    /// Linear gear compliance on every joint.
    pub compliance: bool,
    /// Further effect terms (cyclic, backlash, coupling, cubic compliance, thermal).
    pub extra: Vec<Param>,
}

impl Default for ModelOptions {
    fn default() -> Self {
        Self { beta: true, compliance: true, extra: Vec::new() }
    }
}

impl ModelOptions {
    /// Parse `+beta,-compliance,+cyc2_h1,+backlash2,+coupling5_6,+c2_cubic,+thermal_alpha`
    /// (a `+cyc{j}_h{h}` adds its sine and cosine terms). Unsigned items add.
    pub fn parse(spec: &str, dof: usize) -> Result<ModelOptions, String> {
        let mut m = ModelOptions::default();
        for item in spec.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (on, name) = match item.strip_prefix('-') {
                Some(n) => (false, n),
                None => (true, item.strip_prefix('+').unwrap_or(item)),
            };
            match name {
                "beta" => m.beta = on,
                "compliance" => m.compliance = on,
                _ => {
                    let params: Vec<Param> = if let Some(p) = Param::parse(name) {
                        vec![p]
                    } else if let Some(p) = Param::parse(&format!("{name}_sin")) {
                        let Param::Joint(j, JointTerm::Cyclic { harmonic, .. }) = p else { unreachable!() };
                        vec![p, Param::Joint(j, JointTerm::Cyclic { harmonic, cosine: true })]
                    } else {
                        return Err(format!(
                            "'{item}': unknown model option (beta, compliance, or an effect term such as cyc2_h1, backlash2, coupling5_6, c2_cubic, thermal_alpha)"
                        ));
                    };
                    for p in params {
                        let ok = match p {
                            Param::Joint(j, JointTerm::Coupling { from }) => j < dof && from < dof,
                            Param::Joint(j, t) => j < dof && t != JointTerm::Compliance,
                            Param::Thermal => true,
                            _ => false,
                        };
                        if !ok {
                            return Err(format!("'{item}': not an effect term of a {dof}-joint robot"));
                        }
                        if !on {
                            return Err(format!("'{item}': effect terms are added with +, not removed"));
                        }
                        if !m.extra.contains(&p) {
                            m.extra.push(p);
                        }
                    }
                }
            }
        }
        Ok(m)
    }
}

/// Everything an identification can be told.
#[derive(Clone, Debug)]
pub struct IdentifyOptions {
    pub selection: MeasurementSelection,
    pub model: ModelOptions,
    /// Parameters held at their nominal values (names, e.g. `a2`, `tool_x`, `tool2_y`).
    pub fixed: Vec<String>,
    /// Refuse fits whose column-scaled κ(J) exceeds this (thesis §4.2.3: κ ≤ 1000, at most 3 of
    /// 16 digits lost). The limit applies to the scaled Jacobian because that is the system the
    /// solver factorises: its κ is what the solve loses. κ in SI units (the thesis's own figure)
    /// depends on the units chosen for each column — compliance in rad/(N·m) multiplies its
    /// column by the torques — and is reported beside it for comparison.
    pub kappa_limit: f64,
    pub solver: SolverOptions,
    /// Metres per radian for orientation residual rows.
    pub rotation_weight: f64,
    /// Start from this parameter set instead of the nominal model: every robot parameter it has
    /// (base excepted) and the TCP of a tool equal to its declared tool take its values, and
    /// parameters held fixed stay at them. The base always comes from the cell (its guess or a
    /// registration): a new setup is what re-identifying from a calibrated set is for.
    pub start: Option<ParameterSet>,
    /// When non-empty, only these parameters are free; every other one is fixed (at its start
    /// value). Items are parameter names (`a2`, `tool2_x`) or the groups `base` (base_x … base_c)
    /// and `tool` (every tool's six). `["base", "tool"]` re-registers a calibrated robot in a new
    /// cell, or gives the "before calibration" reference of a cell without a base guess.
    pub only: Vec<String>,
}

impl Default for IdentifyOptions {
    fn default() -> Self {
        Self {
            selection: MeasurementSelection::default(),
            model: ModelOptions::default(),
            fixed: Vec::new(),
            kappa_limit: 1000.0,
            solver: SolverOptions::default(),
            rotation_weight: 0.1,
            start: None,
            only: Vec::new(),
        }
    }
}

impl Status {
    /// `identified`, or the reason the parameter is fixed: the text files and the wire carry.
    pub fn as_str(&self) -> &str {
        match self {
            Status::Identified => "identified",
            Status::Fixed(reason) => reason,
        }
    }
}

impl std::fmt::Display for Status {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl PartialEq<str> for Status {
    fn eq(&self, other: &str) -> bool {
        self.as_str() == other
    }
}

impl PartialEq<&str> for Status {
    fn eq(&self, other: &&str) -> bool {
        self.as_str() == *other
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IdentifyError {
    #[error("{0}")]
    Problem(#[from] ProblemError),
    #[error("base estimate: {0}")]
    Registration(#[from] RegistrationError),
    #[error("{0}")]
    Option(String),
    #[error("{rows} residual rows cannot determine {params} parameters")]
    Underdetermined { rows: usize, params: usize },
    #[error("rank-deficient fit: these data do not separate {combination}")]
    RankDeficient { combination: String },
    #[error(
        "ill-conditioned fit: κ of the scaled Jacobian = {kappa:.1} exceeds the limit {limit:.0}; the weakest combination is {combination}"
    )]
    IllConditioned { kappa: f64, limit: f64, combination: String },
    #[error("{0}")]
    Solve(#[from] SolveError),
}

/// An identified tool (beyond the parameter set's own).
#[derive(Clone, Debug, PartialEq)]
pub struct ToolResult {
    pub sessions: Vec<String>,
    pub tool: Tool,
    /// Standard deviation of each TCP component when identified (SI).
    pub std: [Option<f64>; 6],
    pub status: [String; 6],
}

/// The result of an identification.
#[derive(Clone, Debug)]
pub struct Identification {
    /// The calibrated parameter set; its tool is the first tool of the problem.
    pub set: ParameterSet,
    /// Per layout parameter of `set`: standard deviation (SI) when identified.
    pub std: Vec<Option<f64>>,
    /// Per layout parameter: identified, or fixed and why.
    pub status: Vec<Status>,
    /// Every tool of the problem (the first is `set.tool`).
    pub tools: Vec<ToolResult>,
    pub quality: Quality,
    /// Names of the free parameters, in the covariance's order.
    pub free_names: Vec<String>,
    pub iterations: usize,
    /// Observations down-weighted by the robust loss: (session, index, weight).
    pub downweighted: Vec<(String, usize, f64)>,
    pub problem: Problem,
    pub free: Vec<usize>,
    pub x: Vec<f64>,
}

/// A problem ready to solve: its starting point, free parameters and every parameter's status.
pub struct Prepared {
    pub problem: Problem,
    pub x0: Vec<f64>,
    pub free: Vec<usize>,
    pub status: Vec<Status>,
    /// T_0^W the fit starts from (the cell's guess, or a registration).
    pub base: [f64; 6],
}

/// Build the problem, the starting point and the identifiable set.
pub fn prepare(cell: &Cell, opts: &IdentifyOptions) -> Result<Prepared, IdentifyError> {
    let dof = cell.model.dof();
    let mut layout = ParamLayout::full(&cell.model);
    for p in &opts.model.extra {
        if !layout.admits(*p) {
            return Err(IdentifyError::Option(format!("{p} is not a parameter of a {dof}-joint robot")));
        }
    }
    layout.extend(&opts.model.extra);
    let base = match cell.base_guess {
        Some(b) => b,
        None => estimate_base_of(cell, &opts.selection.picks(cell)?)?.0,
    };
    let problem = Problem::new(cell, layout, base, &opts.selection, opts.rotation_weight)?;
    let mut x0 = problem.nominal.clone();
    if let Some(start) = &opts.start {
        if start.model.dof() != dof || start.model.preset != cell.model.preset {
            return Err(IdentifyError::Option(format!(
                "the start parameter set is for robot '{}', the cell's robot is '{}'",
                start.model.name, cell.model.name
            )));
        }
        for (g, gp) in problem.params.iter().enumerate() {
            let v = match *gp {
                GlobalParam::Robot(i) => match problem.layout.params()[i] {
                    Param::Base(_) => None,
                    p => start.value(p),
                },
                GlobalParam::Tool { tool, k } if problem.tools[tool].tool == start.tool => start.value(Param::Tool(k)),
                GlobalParam::Tool { .. } => None,
            };
            if let Some(v) = v {
                x0[g] = v;
            }
        }
    }

    // Parameters fixed by the model options, the user and the sessions' declarations.
    let mut fixed: HashMap<usize, String> = HashMap::new();
    for (g, gp) in problem.params.iter().enumerate() {
        let name = problem.name(g);
        match *gp {
            GlobalParam::Robot(i) => match problem.layout.params()[i] {
                Param::Beta(_) if !opts.model.beta => {
                    fixed.insert(g, format!("{name}: fixed, the model has no β (-beta)"));
                }
                Param::Joint(_, JointTerm::Compliance) if !opts.model.compliance => {
                    fixed.insert(g, format!("{name}: fixed, the model has no compliance (-compliance)"));
                }
                _ => {}
            },
            GlobalParam::Tool { tool, k } => {
                let b = &problem.tools[tool];
                if !b.identify_tcp && (k < 3 || b.has_orientation) {
                    fixed.insert(g, format!("{name}: fixed, the session declares its TCP (measured, e.g. on a CMM)"));
                }
            }
        }
    }
    if !opts.only.is_empty() {
        let mut keep = vec![false; problem.n_params()];
        for item in &opts.only {
            let hits: Vec<usize> = (0..problem.n_params())
                .filter(|&g| match (item.as_str(), problem.params[g]) {
                    ("base", GlobalParam::Robot(i)) => matches!(problem.layout.params()[i], Param::Base(_)),
                    ("tool", GlobalParam::Tool { .. }) => true,
                    (name, _) => problem.name(g) == name,
                })
                .collect();
            if hits.is_empty() {
                return Err(IdentifyError::Option(format!(
                    "--only: '{item}' is neither a parameter of this problem nor a group (base, tool)"
                )));
            }
            hits.into_iter().for_each(|g| keep[g] = true);
        }
        for (g, k) in keep.iter().enumerate() {
            if !k {
                let name = problem.name(g);
                let at = if opts.start.is_some() { "its start value" } else { "nominal" };
                fixed.entry(g).or_insert_with(|| format!("{name}: fixed at {at}, not in --only"));
            }
        }
    }
    for f in &opts.fixed {
        let g = (0..problem.n_params())
            .find(|&g| &problem.name(g) == f)
            .ok_or_else(|| IdentifyError::Option(format!("--fix: '{f}' is not a parameter of this problem")))?;
        let at = if opts.start.is_some() { "at its start value" } else { "at nominal" };
        fixed.insert(g, format!("{f}: fixed by the user ({at})"));
    }

    // Identifiability at the starting point.
    let all: Vec<usize> = (0..problem.n_params()).collect();
    let mut j0 = Mat::<f64>::zeros(problem.n_rows, all.len());
    let mut r0 = vec![0.0; problem.n_rows];
    problem.linearise(&x0, &all, &mut j0, &mut r0);
    let (free, status) = identifiability::select(&problem, &j0, &fixed);
    if free.is_empty() {
        return Err(IdentifyError::Option("no parameter is free to identify".into()));
    }
    Ok(Prepared { problem, x0, free, status, base })
}

/// The candidate pool for DETMAX: every measurement of the chosen sessions, as its Jacobian
/// block on the identifiable parameters at the starting point (SI units, as the thesis computes
/// O1). Build once, select many times (the study draws thousands of sets from one pool).
pub struct DetmaxPool {
    blocks: Vec<detmax::Block>,
    members: Vec<(String, usize)>,
    m: usize,
}

impl DetmaxPool {
    pub fn new(cell: &Cell, opts: &IdentifyOptions) -> Result<DetmaxPool, IdentifyError> {
        let mut pool_opts = opts.clone();
        pool_opts.selection.subset.clear();
        let p = prepare(cell, &pool_opts)?;
        let chains = p.problem.chains(&p.x0);
        let blocks = p
            .problem
            .obs
            .iter()
            .map(|o| detmax::Block { rows: o.rows, data: p.problem.block(&chains, o, &p.free) })
            .collect();
        let members = p.problem.obs.iter().map(|o| (p.problem.session_names[o.session].clone(), o.index)).collect();
        Ok(DetmaxPool { blocks, members, m: p.free.len() })
    }

    /// Candidates in the pool.
    pub fn len(&self) -> usize {
        self.blocks.len()
    }

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
    pub fn select_with(
        &self,
        o: &detmax::DetmaxOptions,
    ) -> Result<(Vec<(String, usize)>, serde_json::Value), IdentifyError> {
        let (n, index, seed) = (o.n, o.index, o.seed);
        let d = detmax::detmax(&self.blocks, self.m, o).map_err(|e| IdentifyError::Option(format!("DETMAX: {e}")))?;
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

/// Identify a cell's robot.
pub fn identify(cell: &Cell, opts: &IdentifyOptions) -> Result<Identification, IdentifyError> {
    let Prepared { problem, x0, free, status, base } = prepare(cell, opts)?;
    if problem.n_rows <= free.len() {
        return Err(IdentifyError::Underdetermined { rows: problem.n_rows, params: free.len() });
    }

    let fit = solver::solve(&problem, &free, &x0, &opts.solver)?;
    let rows: Vec<(usize, usize)> = problem.obs.iter().map(|o| (o.row, o.rows)).collect();
    let quality = Quality::of(&fit, problem.obs.len(), &rows);
    let combination = || {
        quality
            .weakest
            .iter()
            .take(4)
            .map(|(c, w)| format!("{:+.2}·{}", w, problem.name(free[*c])))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let smin = quality.singular_values.last().copied().unwrap_or(0.0);
    if quality.kappa_scaled > 1e10 || smin == 0.0 {
        return Err(IdentifyError::RankDeficient { combination: combination() });
    }
    if quality.kappa_scaled > opts.kappa_limit {
        return Err(IdentifyError::IllConditioned {
            kappa: quality.kappa_scaled,
            limit: opts.kappa_limit,
            combination: combination(),
        });
    }

    // The parameter set of the first tool, and every tool's result.
    let mut std_g = vec![None; problem.n_params()];
    for (c, &g) in free.iter().enumerate() {
        std_g[g] = Some(quality.std[c]);
    }
    let label = |g: usize| status[g].label();
    let tools: Vec<ToolResult> = problem
        .tools
        .iter()
        .enumerate()
        .map(|(t, b)| {
            let off =
                problem.params.iter().position(|p| *p == GlobalParam::Tool { tool: t, k: 0 }).expect("tool block");
            let mut tool = b.tool.clone();
            tool.tcp.copy_from_slice(&fit.x[off..off + 6]);
            ToolResult {
                sessions: b.sessions.clone(),
                tool,
                std: std::array::from_fn(|k| std_g[off + k]),
                status: std::array::from_fn(|k| label(off + k)),
            }
        })
        .collect();
    let mut set = ParameterSet::nominal(cell.model.clone(), problem.tools[0].tool.clone(), base);
    set.layout = problem.layout.clone();
    set.nominal = problem.layout.nominal_values(&cell.model, &problem.tools[0].tool, &base);
    set.values = problem.layout_values(&fit.x, 0);
    let mut std = vec![None; set.layout.len()];
    let mut st = vec![Status::Fixed(String::new()); set.layout.len()];
    for (g, p) in problem.params.iter().enumerate() {
        let i = match *p {
            GlobalParam::Robot(i) => Some(i),
            GlobalParam::Tool { tool: 0, k } => set.layout.index_of(Param::Tool(k)),
            _ => None,
        };
        if let Some(i) = i {
            std[i] = std_g[g];
            st[i] = status[g].clone();
        }
    }
    let downweighted = problem
        .obs
        .iter()
        .zip(&fit.weights)
        .filter(|(_, w)| **w < 1.0)
        .map(|(o, w)| (problem.session_names[o.session].clone(), o.index, *w))
        .collect();
    Ok(Identification {
        set,
        std,
        status: st,
        tools,
        free_names: free.iter().map(|&g| problem.name(g)).collect(),
        iterations: fit.iterations,
        downweighted,
        quality,
        x: fit.x,
        problem,
        free,
    })
}

impl Identification {
    /// The model's TCP prediction and its standard uncertainty from the parameter covariance, for
    /// each measurement of `session` (any session of the cell, e.g. a validation one measured with
    /// another, declared tool): (position in {W}, √trace(J·Cov·Jᵀ)) in m. Only the robot's free
    /// parameters carry uncertainty for a tool that was not identified.
    pub fn predict(&self, session: &crate::cell::Session) -> Vec<(nalgebra::Vector3<f64>, f64)> {
        use crate::kinematics::{GravityModel, JointState, Rows};
        let tool_tcp = if session.tool == self.set.tool { self.set.pose_of(Param::Tool) } else { session.tool.tcp };
        let chain = self.set.chain().with_base_tool(self.set.pose_of(Param::Base), tool_tcp);
        let gravity = GravityModel::new(&self.set.model, &session.tool);
        let same_tool = session.tool == self.set.tool;
        // Layout column of each free parameter (robot parameters, and tool 0's when it is this tool).
        let cols: Vec<Option<usize>> = self
            .free
            .iter()
            .map(|&g| match self.problem.params[g] {
                GlobalParam::Robot(i) => Some(i),
                GlobalParam::Tool { tool: 0, k } if same_tool => self.set.layout.index_of(Param::Tool(k)),
                _ => None,
            })
            .collect();
        let m = self.set.layout.len();
        let mut buf = vec![0.0; 3 * m];
        session
            .measurements
            .iter()
            .map(|meas| {
                let tau = gravity.torques(&meas.q);
                let mut s = JointState::with_torques(&meas.q, &tau[..self.set.dof()]);
                if let Some(a) = &meas.approach {
                    for (j, &v) in a.iter().enumerate() {
                        s.approach[j] = v as f64;
                    }
                }
                if let Some(t) = meas.temperature_c {
                    s.temperature_c = t;
                }
                let f = chain.jacobian_into(&s, &self.set.layout, Rows::Position, &mut buf, 3);
                let cov = &self.quality.covariance;
                let mut var = 0.0;
                for r in 0..3 {
                    for (a, ca) in cols.iter().enumerate() {
                        let Some(ca) = ca else { continue };
                        for (b, cb) in cols.iter().enumerate() {
                            let Some(cb) = cb else { continue };
                            var += buf[ca * 3 + r] * cov[(a, b)] * buf[cb * 3 + r];
                        }
                    }
                }
                (f.t, var.max(0.0).sqrt())
            })
            .collect()
    }
}
