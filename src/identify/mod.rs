//! Identification (thesis §4.2, §6; digest §4, §6): the parameters of a better model from a
//! cell's measurements — least squares on faer with Levenberg–Marquardt damping, automatic
//! identifiability, conditioning and observability, honest uncertainties, DETMAX pose selection.

pub mod base;
pub mod crossval;
pub mod detmax;
mod hold;
pub mod identifiability;
pub mod noise;
pub mod observability;
pub mod problem;
pub mod quality;
pub mod solver;
pub mod study;

use std::collections::HashMap;

use faer::Mat;

use crate::cell::Cell;
use crate::kinematics::{JointTerm, Param, ParamLayout, ParameterSet, Tool};
use crate::metrology::registration::RegistrationError;
use base::{estimate_base_of, register_base_and_tcps};
pub use hold::COMPLIANCE_SIGNIFICANCE;
pub use identifiability::Status;
pub use noise::NoiseModel;
pub use problem::{GlobalParam, MeasurementSelection, Prior, Problem, ProblemError, tool_blocks};
pub use quality::Quality;
pub use solver::{Fit, SolveError, SolverOptions};

/// Which model is fitted: the structure's optional blocks and effect terms.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelOptions {
    /// Hayati β on the joints that have it.
    pub beta: bool,
    /// Linear gear compliance on every joint.
    pub compliance: bool,
    /// Further effect terms (cyclic, backlash, coupling, cubic compliance, thermal, payload
    /// error). A compliance `c{j}` or a `beta{j}` listed here is free even when `compliance` or
    /// `beta` is off: the model has that one term.
    pub extra: Vec<Param>,
    /// Correction tables: (joint, knot spacing in degrees). The knots cover the joint's range in
    /// the identified measurements.
    pub maps: Vec<(usize, u8)>,
}

impl Default for ModelOptions {
    fn default() -> Self {
        Self { beta: true, compliance: true, extra: Vec::new(), maps: Vec::new() }
    }
}

impl ModelOptions {
    /// Parse `+beta,-compliance,+cyc2_h1,+backlash2,+coupling5_6,+c2_cubic,+thermal_alpha`
    /// (a `+cyc{j}_h{h}` or `+cyc{j}_f{f}` adds its sine and cosine terms), `+tool_mass`,
    /// `+map{j}_s{step}` (a correction table of joint j with knots every `step` degrees), and
    /// single terms of a block that is off (`-compliance,+c3`; `-beta,+beta2`). Unsigned items
    /// add.
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
                _ if parse_map(name).is_some() => {
                    let (j, step) = parse_map(name).expect("checked");
                    if j >= dof {
                        return Err(format!("'{item}': not an effect term of a {dof}-joint robot"));
                    }
                    if !on {
                        return Err(format!("'{item}': effect terms are added with +, not removed"));
                    }
                    if !m.maps.contains(&(j, step)) {
                        m.maps.push((j, step));
                    }
                }
                _ => {
                    let params: Vec<Param> = if let Some(p) = Param::parse(name) {
                        vec![p]
                    } else if let Some(p) = Param::parse(&format!("{name}_sin")) {
                        let Param::Joint(j, t) = p else { unreachable!() };
                        let cos = match t {
                            JointTerm::Cyclic { harmonic, .. } => JointTerm::Cyclic { harmonic, cosine: true },
                            JointTerm::Periodic { quarters, .. } => JointTerm::Periodic { quarters, cosine: true },
                            _ => unreachable!("only cyclic names end in _sin"),
                        };
                        vec![p, Param::Joint(j, cos)]
                    } else {
                        return Err(format!(
                            "'{item}': unknown model option (beta, compliance, or an effect term such as cyc2_h1, cyc2_f7.25, backlash2, coupling5_6, c2_cubic, c3, beta2, map2_s3, thermal_alpha, tool_mass)"
                        ));
                    };
                    for p in params {
                        let ok = match p {
                            Param::Joint(j, JointTerm::Coupling { from }) => j < dof && from < dof,
                            Param::Joint(_, JointTerm::Map { .. }) => false,
                            Param::Joint(j, _) => j < dof,
                            Param::Beta(j) => j < dof,
                            Param::Thermal | Param::ToolMass => true,
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

/// `map{j}_s{step}` → (0-based joint, step in degrees).
fn parse_map(name: &str) -> Option<(usize, u8)> {
    let rest = name.strip_prefix("map")?;
    let (j, step) = rest.split_once("_s")?;
    let j: usize = j.parse().ok().filter(|&j: &usize| j >= 1 && !j.to_string().starts_with('0'))?;
    let step: u8 = step.parse().ok().filter(|&s: &u8| s >= 1 && step == s.to_string())?;
    Some((j - 1, step))
}

/// The knots of a correction table on joint j covering the joint's range in `qs` (rad), one
/// knot beyond each end so every reading sits between two knots.
pub fn map_knots(j: usize, step_deg: u8, qs: impl Iterator<Item = f64>) -> Vec<Param> {
    let step = step_deg as f64 * crate::units::DEG;
    let (lo, hi) = qs.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), q| (lo.min(q), hi.max(q)));
    if !lo.is_finite() {
        return Vec::new();
    }
    let (k0, k1) = ((lo / step).floor() as i64, (hi / step).ceil() as i64);
    (k0.max(i16::MIN as i64)..=k1.min(i16::MAX as i64))
        .map(|k| Param::Joint(j, JointTerm::Map { step_deg, knot: k as i16 }))
        .collect()
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
    /// Weight every measurement by its instrument's σ (weighted least squares); `None` = every
    /// residual row weighs the same (the thesis's plain least squares).
    pub noise: Option<NoiseModel>,
    /// Smoothing of correction tables (`map` terms): the weight of the second-difference rows
    /// relative to the data's information on one knot (η in λ² = η·mean‖J_knot‖²). Larger is
    /// smoother.
    pub map_smoothing: f64,
    /// Sessions whose tool TCP is identified although they declare it (a reflector nest whose
    /// declared offset is suspect).
    pub free_tcp: Vec<String>,
    /// Keep the geometry (α, a, d, θ offsets, β) within a plausible distance of its start values.
    pub anchor: Option<Anchor>,
    /// Refuse a fit whose residual RMS exceeds this many times the RMS the instrument model and
    /// the measurements' own σ predict ([`RESIDUAL_RATIO_LIMIT`]); `f64::INFINITY` accepts any.
    pub residual_ratio_limit: f64,
    /// Refuse a fit with a measurement whose residual exceeds this many times the typical one
    /// ([`OUTLIER_FACTOR`]), unless the Huber loss down-weighted it; `f64::INFINITY` never does.
    pub outlier_factor: f64,
    /// When every chosen session's tool declares no payload (0 kg: unknown, as a three-reflector
    /// file or a tracker run without a tool mass) and the model has compliance, identify the
    /// payload's mass (`tool_mass`, at the tools' declared centre of mass) instead of fitting the
    /// compliances with 0 kg. A compliance is a deflection per N·m of holding torque: with the
    /// payload's torque left out, the wrist's compliances have almost nothing to act on.
    pub identify_payload: bool,
    /// Hold every compliance whose fitted change is below [`COMPLIANCE_SIGNIFICANCE`] of its own
    /// standard deviation at its start value, and say so in its status (`hold.rs`: an
    /// undetermined compliance extrapolates to poses of larger torque by millimetres).
    pub hold_undetermined_compliance: bool,
}

/// The default of [`IdentifyOptions::residual_ratio_limit`]: a fit is refused when its residual RMS
/// is more than 50 times the RMS the instrument predicts.
///
/// Why 50. The ratio ρ = RMS(residual)/RMS(σ) is 1 when the model and the noise model are right
/// (χ²/dof = ρ²). A real robot's calibrated model leaves effects it lacks, and a nominal model
/// more: against the tracker's own σ, ρ = 20 for the UR10 of series C calibrated with the default
/// model (13 for series B) and 40 for its nominal model with base and probe fitted (crossval's
/// "before" reference is exempt); 2.3 for the virtual IRB 120 identified without β. A structure error leaves residuals of the size of the
/// error itself: one TCP for the three nests of the virtual cell (60–85 mm apart) leaves ρ = 118,
/// the IRB 120 of issue 13 with three reflectors ~100 mm apart ρ ≈ 2,700 (86.8 mm against a
/// tracker's ~0.03 mm). At ρ > 50 the unexplained variance is 2,500 times the instrument's: no
/// longer noise or a missing small effect but a wrong TCP, a session in another frame, or outliers.
pub const RESIDUAL_RATIO_LIMIT: f64 = 50.0;

/// A measurement is an outlier when its residual, in units of its own σ, exceeds this many times
/// the median measurement's (and 10σ of the instrument). Unmodelled effects are smooth over the
/// workspace and move neighbouring poses alike: their residuals' tail reaches 3–6 times the median
/// (UR10 calibrated: the largest is 3.6 times in series C, 5.8 in series B). A reading 10 times the median is a gross error — a
/// swapped line, a reflector that slipped, a broken beam — which least squares would spread over
/// every parameter.
pub const OUTLIER_FACTOR: f64 = 10.0;

/// A weak prior on the geometry: each free α, a, d, θ offset and β is an extra observation of
/// its start value with standard deviation `length` or `angle`. A built robot's geometry differs
/// from its calibrated values by micrometres, so σ of a millimetre or a tenth of a degree changes
/// nothing where the model fits; where it cannot — plain DH on tilted parallel axes, whose
/// least-squares solution lies at infinity (§3.4) — it keeps the fit finite, and the misfit
/// visible, instead of letting the parameters run away.
#[derive(Clone, Debug, PartialEq)]
pub struct Anchor {
    /// m.
    pub length: f64,
    /// rad.
    pub angle: f64,
}

impl Default for Anchor {
    fn default() -> Self {
        Self { length: 1e-3, angle: 0.1 * crate::units::DEG }
    }
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
            noise: None,
            map_smoothing: DEFAULT_MAP_SMOOTHING,
            free_tcp: Vec::new(),
            anchor: None,
            residual_ratio_limit: RESIDUAL_RATIO_LIMIT,
            outlier_factor: OUTLIER_FACTOR,
            identify_payload: true,
            hold_undetermined_compliance: true,
        }
    }
}

/// Default η of [`IdentifyOptions::map_smoothing`].
pub const DEFAULT_MAP_SMOOTHING: f64 = 1.0;

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
    #[error(
        "the start parameter set is for robot '{set}' ({set_dof} joints), not for the cell's robot '{cell}' ({cell_dof} joints)"
    )]
    StartRobot { set: String, set_dof: usize, cell: String, cell_dof: usize },
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
    #[error(
        "residual RMS {} mm against an expected ~{} mm ({ratio:.0} times, above the limit of {limit:.0}): the model does not describe these data (check the TCPs, the sessions' frames, outliers); largest residuals: {}",
        mm(*rms), mm(*expected), worst_list(worst)
    )]
    Misfit { rms: f64, expected: f64, ratio: f64, limit: f64, worst: Vec<Worst> },
    #[error(
        "{} outlier measurement(s), each more than {factor:.0} times the typical residual: {}; leave them out (identify --exclude {}, or `exclude` in a request) or fit with the Huber loss (--huber 2.5)",
        outliers.len(), worst_list(outliers), outliers.iter().take(5).map(|w| format!("{}:{}", w.session, w.index)).collect::<Vec<_>>().join(",")
    )]
    Outliers { outliers: Vec<Worst>, factor: f64 },
}

/// A measurement with a large residual.
#[derive(Clone, Debug, PartialEq)]
pub struct Worst {
    pub session: String,
    /// 0-based index in the session.
    pub index: usize,
    /// |residual| (position and, for a pose, rotation_weight·angle), m.
    pub residual: f64,
    /// How many times the typical measurement's residual it is, each row against its σ and the
    /// spread the model leaves ([`IdentifyError::Outliers`]).
    pub ratio: f64,
}

fn mm(v: f64) -> String {
    let v = v / crate::units::MM;
    if v >= 10.0 {
        format!("{v:.1}")
    } else if v >= 0.1 {
        format!("{v:.3}")
    } else {
        format!("{v:.4}")
    }
}

fn worst_list(w: &[Worst]) -> String {
    w.iter()
        .take(5)
        .map(|w| format!("{}[{}] {} mm ({:.1} times the typical)", w.session, w.index, mm(w.residual), w.ratio))
        .collect::<Vec<_>>()
        .join(", ")
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
    /// The measurements with the largest residuals against their expected noise, largest first
    /// (at most [`WORST_REPORTED`]).
    pub worst: Vec<Worst>,
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
    /// Parameters fixed by the options and the sessions (global index → reason), before
    /// identifiability.
    pub fixed: HashMap<usize, String>,
    /// The payload is unknown (every tool declares 0 kg) and identified as `tool_mass`.
    pub payload_unknown: bool,
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
    let payload_unknown = payload_is_unknown(cell, opts)?;
    if payload_unknown {
        layout.extend(&[Param::ToolMass]);
    }
    if !opts.model.maps.is_empty() {
        let picks = opts.selection.picks(cell)?;
        for &(j, step) in &opts.model.maps {
            let qs = picks.iter().map(|&(s, i)| cell.sessions[s].measurements[i].q[j]);
            layout.extend(&map_knots(j, step, qs));
        }
    }
    // The base, and the TCPs to identify, from the nominal robot: registered in turn when a TCP is
    // unknown, else the cell's guess or one registration.
    let picks = opts.selection.picks(cell)?;
    let (blocks, session_tool) = tool_blocks(cell, &picks);
    let registration = if blocks.iter().any(|b| b.identify_tcp && b.tool.tcp[..3] == [0.0; 3]) {
        Some(register_base_and_tcps(cell, &picks, &blocks, &session_tool, cell.base_guess)?)
    } else {
        None
    };
    let base = match (cell.base_guess, &registration) {
        (Some(b), _) => b,
        (None, Some(r)) => r.base,
        (None, None) => estimate_base_of(cell, &picks)?.0,
    };
    let mut problem = Problem::new(cell, layout, base, &opts.selection, opts.rotation_weight)?;
    if let Some(noise) = &opts.noise {
        noise.check().map_err(IdentifyError::Option)?;
        weight_by_instrument(&mut problem, cell, noise);
    }
    let mut x0 = problem.nominal.clone();
    // Tool blocks whose TCP the start parameter set gives.
    let mut from_start = vec![false; problem.tools.len()];
    if let Some(start) = &opts.start {
        for (t, b) in problem.tools.iter().enumerate() {
            from_start[t] = b.tool == start.tool;
        }
        // As validation decides: a set starts a fit of the same joint count, unless both robots
        // are built-in presets and differ (a custom table may be a preset re-measured; the set's
        // values are absolute, so they start its fit as well).
        let presets_differ = matches!((start.model.preset, cell.model.preset), (Some(a), Some(b)) if a != b);
        if start.model.dof() != dof || presets_differ {
            return Err(IdentifyError::StartRobot {
                set: start.model.name.clone(),
                set_dof: start.model.dof(),
                cell: cell.model.name.clone(),
                cell_dof: dof,
            });
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
                p @ Param::Beta(_) if !opts.model.beta && !opts.model.extra.contains(&p) => {
                    fixed.insert(g, format!("{name}: fixed, the model has no β (-beta)"));
                }
                p @ Param::Joint(_, JointTerm::Compliance)
                    if !opts.model.compliance && !opts.model.extra.contains(&p) =>
                {
                    fixed.insert(g, format!("{name}: fixed, the model has no compliance (-compliance)"));
                }
                _ => {}
            },
            GlobalParam::Tool { tool, k } => {
                let b = &problem.tools[tool];
                let freed = b.sessions.iter().any(|s| opts.free_tcp.contains(s));
                if !b.identify_tcp && !freed && (k < 3 || b.has_orientation) {
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

    for s in &opts.free_tcp {
        if !problem.tools.iter().any(|b| b.sessions.contains(s)) {
            return Err(IdentifyError::Option(format!("free TCP: '{s}' is not a session of this problem")));
        }
    }

    // Unknown TCPs start from the registration (not where the start set gives them, and not the
    // components held fixed, which stay at nominal).
    if let Some(r) = &registration {
        for (g, gp) in problem.params.iter().enumerate() {
            if let GlobalParam::Tool { tool, k } = *gp
                && problem.tools[tool].identify_tcp
                && !from_start[tool]
                && !fixed.contains_key(&g)
            {
                x0[g] = r.tcps[tool][k];
            }
        }
    }

    // Identifiability at the starting point (correction tables with their regularisation rows).
    let all: Vec<usize> = (0..problem.n_params()).collect();
    let mut j0 = Mat::<f64>::zeros(problem.n_rows, all.len());
    let mut r0 = vec![0.0; problem.n_rows];
    problem.linearise(&x0, &all, &mut j0, &mut r0);
    let priors = map_priors(&problem, &j0, opts.map_smoothing)?;
    if !priors.is_empty() {
        problem.add_priors(priors);
        j0 = Mat::<f64>::zeros(problem.n_rows, all.len());
        r0 = vec![0.0; problem.n_rows];
        problem.linearise(&x0, &all, &mut j0, &mut r0);
    }
    let (free, status) = identifiability::select(&problem, &j0, &fixed);
    if free.is_empty() {
        return Err(IdentifyError::Option("no parameter is free to identify".into()));
    }
    if let Some(a) = &opts.anchor {
        let priors = anchor_priors(&problem, &free, &x0, a, opts.noise.is_some());
        problem.add_priors(priors);
    }
    Ok(Prepared { problem, x0, free, status, base, fixed, payload_unknown })
}

/// Whether the payload is unknown and identified ([`IdentifyOptions::identify_payload`]): every
/// chosen session's tool declares 0 kg, the model has compliance and no payload term of its own
/// (a start set's payload term is taken as the start value).
fn payload_is_unknown(cell: &Cell, opts: &IdentifyOptions) -> Result<bool, IdentifyError> {
    if !opts.identify_payload || opts.model.extra.contains(&Param::ToolMass) {
        return Ok(false);
    }
    let compliance =
        opts.model.compliance || opts.model.extra.iter().any(|p| matches!(p, Param::Joint(_, JointTerm::Compliance)));
    if !compliance {
        return Ok(false);
    }
    let picks = opts.selection.picks(cell)?;
    let mut sessions: Vec<usize> = picks.iter().map(|p| p.0).collect();
    sessions.dedup();
    Ok(!sessions.is_empty() && sessions.iter().all(|&s| cell.sessions[s].tool.mass == 0.0))
}

/// Anchors of the free geometric parameters to their start values (see [`Anchor`]): one row
/// (x − x₀)/σ each, in units of one measurement σ (10 µm when the problem is not weighted).
fn anchor_priors(problem: &Problem, free: &[usize], x0: &[f64], a: &Anchor, weighted: bool) -> Vec<Prior> {
    let unit = if weighted { 1.0 } else { 1e-5 };
    free.iter()
        .filter_map(|&g| {
            let GlobalParam::Robot(i) = problem.params[g] else { return None };
            let sigma = match problem.layout.params()[i] {
                Param::A(_) | Param::D(_) => a.length,
                Param::Alpha(_) | Param::Theta(_) | Param::Beta(_) => a.angle,
                _ => return None,
            };
            Some(Prior { terms: vec![(g, unit / sigma)], target: unit / sigma * x0[g] })
        })
        .collect()
}

/// σ of every residual row of every observation ([`NoiseModel::row_sigmas`]): the measurement's
/// own σ where it has one, the instrument model's where not; position rows m, rotation rows rad.
pub fn row_sigmas(problem: &Problem, cell: &Cell, noise: &NoiseModel) -> Vec<[f64; 6]> {
    problem
        .obs
        .iter()
        .map(|o| {
            let s = &cell.sessions[o.session];
            noise.row_sigmas(s.instrument, &problem.target_position(o), s.measurements[o.index].sigma.as_ref())
        })
        .collect()
}

/// Weight each observation by 1/σ of its rows ([`row_sigmas`]): position rows by the position's σ,
/// rotation rows (whose residual is rotation_weight·angle) by that of the orientation.
pub fn weight_by_instrument(problem: &mut Problem, cell: &Cell, noise: &NoiseModel) {
    let sigmas = row_sigmas(problem, cell, noise);
    let rw = problem.rotation_weight;
    let mut k = 0;
    problem.set_weights(|_| {
        let s = sigmas[k];
        k += 1;
        std::array::from_fn(|r| if r < 3 { 1.0 / s[r] } else { 1.0 / (s[r] * rw) })
    });
}

/// The regularisation rows of every correction table (`map` terms) of the problem: per table, the
/// second differences of consecutive knots, and one row for the table's mean. The mean row fixes
/// the one direction the data cannot see — a constant table is the joint's zero offset — without
/// biasing anything (the offset takes the constant). The second-difference rows weigh
/// λ² = η·(mean squared norm of the table's columns in `j0`), so η is unit-free: η = 1 makes
/// one unit of curvature cost what one unit of a typical knot's value explains.
pub fn map_priors(problem: &Problem, j0: &Mat<f64>, eta: f64) -> Result<Vec<Prior>, IdentifyError> {
    if !(eta.is_finite() && eta > 0.0) {
        return Err(IdentifyError::Option(format!("map smoothing must be a positive number, got {eta}")));
    }
    // Tables: (joint, step) → knots (knot index, global parameter).
    let mut tables: std::collections::BTreeMap<(usize, u8), Vec<(i16, usize)>> = Default::default();
    for (g, gp) in problem.params.iter().enumerate() {
        if let GlobalParam::Robot(i) = *gp
            && let Param::Joint(j, JointTerm::Map { step_deg, knot }) = problem.layout.params()[i]
        {
            tables.entry((j, step_deg)).or_default().push((knot, g));
        }
    }
    let mut priors = Vec::new();
    for knots in tables.values_mut() {
        knots.sort_unstable();
        let with_norms: Vec<(i16, usize, f64)> = knots
            .iter()
            .map(|&(k, g)| (k, g, (0..problem.n_obs_rows).map(|r| j0[(r, g)].powi(2)).sum::<f64>()))
            .collect();
        priors.extend(table_priors(&with_norms, eta));
    }
    Ok(priors)
}

/// The regularisation rows of one table: knots as (knot index, global parameter, squared norm of
/// its weighted column), sorted by knot. See [`map_priors`].
pub fn table_priors(knots: &[(i16, usize, f64)], eta: f64) -> Vec<Prior> {
    let mean = knots.iter().map(|k| k.2).sum::<f64>() / knots.len().max(1) as f64;
    if mean <= 0.0 {
        return Vec::new(); // a table the data never reach: identifiability fixes it
    }
    let lambda = (eta * mean).sqrt();
    let mut priors = Vec::new();
    for w in knots.windows(3) {
        if w[1].0 == w[0].0 + 1 && w[2].0 == w[1].0 + 1 {
            priors
                .push(Prior { terms: vec![(w[0].1, lambda), (w[1].1, -2.0 * lambda), (w[2].1, lambda)], target: 0.0 });
        }
    }
    let m = mean.sqrt() / knots.len() as f64;
    priors.push(Prior { terms: knots.iter().map(|&(_, g, _)| (g, m)).collect(), target: 0.0 });
    priors
}

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
        use crate::kinematics::{GravityModel, JointState, MAX_JOINTS, Rows};
        use rand::{Rng, SeedableRng};
        let p = &self.problem;
        let chain = &p.chains(&self.x0)[0];
        let tool = &p.tools[0].tool;
        let gravity = GravityModel::new(&p.model, tool);
        let heavier = GravityModel::new(&p.model, &Tool { mass: tool.mass + 1.0, ..tool.clone() });
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
                let (tau, t1) = (gravity.torques(&q), heavier.torques(&q));
                let mut s = JointState::with_torques(&q, &tau[..dof]);
                s.temperature_c = crate::kinematics::params::REFERENCE_TEMPERATURE_C;
                for j in 0..dof.min(MAX_JOINTS) {
                    s.tau_per_kg[j] = t1[j] - tau[j];
                }
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
        detmax::Workspace::new(&blocks, self.m).map_err(|e| IdentifyError::Option(format!("DETMAX workspace: {e}")))
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
            .map_err(|e| IdentifyError::Option(format!("DETMAX: {e}")))?;
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

/// An unknown payload's identified mass must exceed this many of its standard deviations to be
/// kept (see [`IdentifyOptions::identify_payload`]).
pub const PAYLOAD_SIGNIFICANCE: f64 = 3.0;

/// The global index of the payload's mass, when the problem has one.
fn payload_mass(problem: &Problem) -> Option<usize> {
    let i = problem.layout.index_of(Param::ToolMass)?;
    problem.params.iter().position(|p| *p == GlobalParam::Robot(i))
}

/// Identify a cell's robot.
pub fn identify(cell: &Cell, opts: &IdentifyOptions) -> Result<Identification, IdentifyError> {
    let Prepared { problem, x0, mut free, mut status, base, fixed, payload_unknown } = prepare(cell, opts)?;
    if problem.n_obs_rows + problem.priors.len() <= free.len() {
        return Err(IdentifyError::Underdetermined { rows: problem.n_obs_rows, params: free.len() });
    }

    let mut fit = solver::solve(&problem, &free, &x0, &opts.solver)?;
    // Identifiability is judged at the start. An unknown TCP (no guess: the flange) may end far
    // from where the registration started it, and which of its components is one gauge with d6
    // and θ6 depends on where it lies (a point on the flange's y axis moves along x when θ6
    // turns): judge again at the solution, and refit from there when the choice changed. A TCP
    // with a guess stays judged at its guess (the UR10 probe: θ6 has no effect there). An
    // unknown payload acts through the compliances, which are zero at the start: its mass has
    // no effect there and is judged at the solution too.
    if payload_unknown || problem.tools.iter().any(|b| b.identify_tcp && b.tool.tcp[..3] == [0.0; 3]) {
        let all: Vec<usize> = (0..problem.n_params()).collect();
        let mut j = Mat::<f64>::zeros(problem.n_rows, all.len());
        let mut r = vec![0.0; problem.n_rows];
        problem.linearise(&fit.x, &all, &mut j, &mut r);
        let (again, mut again_status) = identifiability::select(&problem, &j, &fixed);
        if again != free && !again.is_empty() {
            let mass = payload_unknown.then(|| payload_mass(&problem)).flatten().filter(|g| again.contains(g));
            match solver::solve(&problem, &again, &fit.x, &opts.solver) {
                Ok(f) => (fit, free, status) = (f, again, again_status),
                // An unknown payload whose fit crawls (a valley with the compliances) is not
                // determined by these data: the fit without it stands, and says so.
                Err(e @ SolveError::IterationLimit { .. }) if mass.is_some() => {
                    let g = mass.expect("checked");
                    let without: Vec<usize> = again.iter().copied().filter(|&c| c != g).collect();
                    if without != free {
                        fit = solver::solve(&problem, &without, &fit.x, &opts.solver)?;
                    }
                    again_status[g] = Status::Fixed(format!(
                        "payload not determined by these data (the fit with it does not settle: {e}): held at the declared 0 kg"
                    ));
                    (free, status) = (without, again_status);
                }
                Err(e) => return Err(e.into()),
            }
        }
    }
    let rows: Vec<(usize, usize)> = problem.obs.iter().map(|o| (o.row, o.rows)).collect();
    // The pose of each measurement, for standard deviations that hold when the readings of one
    // stop share an error (several reflectors, a turn no term explains): the larger of the classic
    // and the cluster-robust σ ([`Quality::make_robust`]).
    let (pose_of_obs, n_poses) =
        crate::cell::poses::group_poses(problem.obs.iter().map(|o| &o.state.q[..cell.model.dof()]));
    // An unknown payload is kept only when the data determine it: a mass below
    // PAYLOAD_SIGNIFICANCE of its own σ is one direction with the compliances (c5·m, c3·m… act
    // as products when the arm's own weight barely loads a joint), the fit crawls along it and
    // every fold lands elsewhere. It is then held at the declared 0 kg and reported as such.
    if payload_unknown
        && let Some((g, c)) = payload_mass(&problem).and_then(|g| free.iter().position(|&f| f == g).map(|c| (g, c)))
    {
        let mut q = Quality::of(&fit, problem.obs.len(), &rows);
        q.make_robust(&fit, &rows, &pose_of_obs, n_poses);
        let (m, sd) = (fit.x[g], q.std[c]);
        let determined = m > PAYLOAD_SIGNIFICANCE * sd; // false for a NaN σ too
        if !determined {
            free.remove(c);
            status[g] = Status::Fixed(format!(
                "payload not determined by these data ({:.3} ± {:.3} kg, below {PAYLOAD_SIGNIFICANCE} σ): held at the declared 0 kg",
                m, sd
            ));
            let mut x = fit.x.clone();
            x[g] = x0[g];
            fit = solver::solve(&problem, &free, &x, &opts.solver)?;
        }
    }
    if opts.hold_undetermined_compliance {
        let f = hold::Fitted {
            problem: &problem,
            x0: &x0,
            rows: &rows,
            pose_of_obs: &pose_of_obs,
            n_poses,
            solver: &opts.solver,
        };
        hold::hold_undetermined_compliances(&f, &mut fit, &mut free, &mut status);
    }
    let mut quality = Quality::of(&fit, problem.obs.len(), &rows);
    quality.make_robust(&fit, &rows, &pose_of_obs, n_poses);
    if opts.noise.is_some() {
        // Weighted rows: the RMS of the measurement residuals in metres, from the rows divided
        // by their weights (and the robust weights, which the fit's residual carries too).
        quality.weighted = true;
        let sum: f64 = problem
            .obs
            .iter()
            .zip(&fit.weights)
            .map(|(o, hw)| {
                let hw = hw.sqrt();
                (0..o.rows)
                    .map(|k| {
                        let w = o.weight[k] * hw;
                        (fit.residual[o.row + k] / w).powi(2)
                    })
                    .sum::<f64>()
            })
            .sum();
        quality.rms_residual = (sum / problem.obs.len().max(1) as f64).sqrt();
    }
    // Does the model describe the data? The residual against the noise the instrument predicts.
    let noise = opts.noise.clone().unwrap_or_default();
    let fitness = Fitness::of(&problem, cell, &noise, &fit, opts.outlier_factor);
    quality.expected_rms = fitness.expected_rms;
    quality.residual_ratio = fitness.ratio;
    if fitness.ratio > opts.residual_ratio_limit {
        return Err(IdentifyError::Misfit {
            rms: fitness.rms,
            expected: fitness.expected_rms,
            ratio: fitness.ratio,
            limit: opts.residual_ratio_limit,
            worst: fitness.worst.clone(),
        });
    }
    if !fitness.outliers.is_empty() {
        return Err(IdentifyError::Outliers { outliers: fitness.outliers, factor: opts.outlier_factor });
    }

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
        worst: fitness.worst,
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

/// Measurements listed in [`Identification::worst`].
pub const WORST_REPORTED: usize = 5;

/// The residual of a fit against the noise the instrument model predicts.
struct Fitness {
    /// RMS over the measurements (outliers left out) of |residual|, m.
    rms: f64,
    /// RMS of the noise the instrument predicts for the same measurements, m: √(mean Σ σ²).
    expected_rms: f64,
    /// rms / expected_rms.
    ratio: f64,
    /// The largest residuals in units of their σ.
    worst: Vec<Worst>,
    /// Gross outliers the robust loss did not down-weight.
    outliers: Vec<Worst>,
}

impl Fitness {
    /// Null hypothesis: every residual row is the instrument's noise, e/σ ~ N(0, 1). The statistic
    /// is ρ = √(Σ e² / Σ σ²) over the measurements; a right model gives ρ ≈ 1, and the fit is
    /// refused above [`IdentifyOptions::residual_ratio_limit`] (see [`RESIDUAL_RATIO_LIMIT`] for
    /// why it is a large factor, not a χ² test: real robots leave unmodelled effects far above
    /// a tracker's noise). Outliers: each row's variance is its σ² plus τ², the spread the model
    /// leaves beyond the instrument (from the medians); per measurement z = RMS of e/√(σ² + τ²)
    /// over its rows. One whose z exceeds [`OUTLIER_FACTOR`] times the median z (and 10) is an
    /// outlier, unless the Huber loss down-weighted it. (Without τ, where the model's misses
    /// dominate, a reading with a small σ would look like an outlier for an ordinary residual.) Outliers are left out of ρ, so that one bad line reads as an outlier,
    /// not as a model that does not fit.
    fn of(problem: &Problem, cell: &Cell, noise: &NoiseModel, fit: &Fit, outlier_factor: f64) -> Fitness {
        let sigmas = row_sigmas(problem, cell, noise);
        let chains = problem.chains(&fit.x);
        let rw = problem.rotation_weight;
        // Per measurement: Σ e², Σ σ², z.
        // Per measurement: its residual rows e (m; rotation rows as rotation_weight·angle) and
        // their σ (m).
        let rows: Vec<(Vec<f64>, Vec<f64>)> = problem
            .obs
            .iter()
            .zip(&sigmas)
            .map(|(o, s)| {
                let (d, rot) = problem.error(o, &chains[o.tool].fk(&o.state));
                let (mut e, mut sd) = (d.as_slice().to_vec(), s[..3].to_vec());
                if let Some(w) = rot {
                    e.extend(w.iter().map(|v| rw * v));
                    sd.extend(s[3..].iter().map(|v| rw * v));
                }
                (e, sd)
            })
            .collect();
        let sq = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>();
        // The spread the model leaves beyond the instrument, τ² per row: from the medians, so that
        // outliers do not set it (the median of χ²₃/3 is 0.79).
        let median = |mut v: Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v.get(v.len() / 2).copied().unwrap_or(0.0)
        };
        let tau2 = (median(rows.iter().map(|(e, _)| sq(e) / e.len() as f64).collect()) / 0.79
            - median(rows.iter().map(|(_, s)| sq(s) / s.len() as f64).collect()))
        .max(0.0);
        // z: the RMS over a measurement's rows of e/√(σ² + τ²), ~0.9 for a typical measurement.
        let per: Vec<(f64, f64, f64)> = rows
            .iter()
            .map(|(e, s)| {
                let z = e.iter().zip(s).map(|(e, s)| e * e / (s * s + tau2)).sum::<f64>() / e.len() as f64;
                (sq(e), sq(s), z.sqrt())
            })
            .collect();
        let typical = median(per.iter().map(|p| p.2).collect()).max(1e-300);
        let threshold = outlier_factor * typical.max(1.0);
        let worst_of = |i: usize| {
            let o = &problem.obs[i];
            Worst {
                session: problem.session_names[o.session].clone(),
                index: o.index,
                residual: per[i].0.sqrt(),
                ratio: per[i].2 / typical,
            }
        };
        let mut order: Vec<usize> = (0..per.len()).collect();
        order.sort_by(|&a, &b| per[b].2.total_cmp(&per[a].2));
        let is_outlier = |i: usize| per[i].2 > threshold;
        let (mut ee, mut ss, mut n) = (0.0, 0.0, 0usize);
        for (i, p) in per.iter().enumerate() {
            if !is_outlier(i) {
                ee += p.0;
                ss += p.1;
                n += 1;
            }
        }
        let n = n.max(1) as f64;
        let (rms, expected_rms) = ((ee / n).sqrt(), (ss / n).sqrt());
        Fitness {
            rms,
            expected_rms,
            ratio: if expected_rms > 0.0 { rms / expected_rms } else { f64::INFINITY },
            worst: order.iter().take(WORST_REPORTED).map(|&i| worst_of(i)).collect(),
            outliers: order.iter().copied().filter(|&i| is_outlier(i) && fit.weights[i] >= 1.0).map(worst_of).collect(),
        }
    }
}

impl Identification {
    /// The weighted Jacobian of the free parameters and the weighted residual at the solution
    /// (measurement rows, then prior rows), as the solver saw them.
    pub fn linearised(&self) -> (Mat<f64>, Vec<f64>) {
        let mut j = Mat::<f64>::zeros(self.problem.n_rows, self.free.len());
        let mut r = vec![0.0; self.problem.n_rows];
        self.problem.linearise(&self.x, &self.free, &mut j, &mut r);
        (j, r)
    }

    /// The model's TCP prediction and its standard uncertainty from the parameter covariance, for
    /// each measurement of `session` (any session of the cell, e.g. a validation one measured with
    /// another, declared tool): (position in {W}, √trace(J·Cov·Jᵀ)) in m. Only the robot's free
    /// parameters carry uncertainty for a tool that was not identified.
    pub fn predict(&self, session: &crate::cell::Session) -> Vec<(nalgebra::Vector3<f64>, f64)> {
        use crate::kinematics::{JointState, Rows};
        let tool_tcp = if session.tool == self.set.tool { self.set.pose_of(Param::Tool) } else { session.tool.tcp };
        let chain = self.set.chain().with_base_tool(self.set.pose_of(Param::Base), tool_tcp);
        let gravity = self.set.gravity_for(&session.tool);
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
