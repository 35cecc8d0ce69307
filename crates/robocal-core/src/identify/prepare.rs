//! A problem ready to solve: the layout, the base, the starting point, the fixed parameters and
//! the identifiable set.

use std::collections::HashMap;

use faer::Mat;

use super::base::{Registration, estimate_base_of, miss_at, register_base_and_tcps};
use super::noise::NoiseModel;
use super::problem::{GlobalParam, Prior, Problem, tool_blocks};
use super::{
    Anchor, FixedReason, IdentifyError, IdentifyOptions, ModelOptions, ModelTerm, Status, identifiability, map_knots,
};
use crate::cell::Cell;
use crate::kinematics::{JointTerm, Param, ParamLayout};

/// A problem ready to solve: its starting point, free parameters and every parameter's status.
pub struct Prepared {
    /// The problem to solve (the correction tables' regularisation rows among its priors).
    pub problem: Problem,
    /// The starting point: the global parameter vector (SI) with the base, the start set's values
    /// (or nominal) and the registered unknown TCPs.
    pub x0: Vec<f64>,
    /// Global indices of the parameters identifiable at the start, ascending.
    pub free: Vec<usize>,
    /// Per global parameter: identified, or fixed and why.
    pub status: Vec<Status>,
    /// T_0^W the fit starts from (the cell's guess, or a registration).
    pub base: [f64; 6],
    /// Parameters fixed by the options and the sessions (global index → reason), before
    /// identifiability.
    pub fixed: HashMap<usize, FixedReason>,
    /// The payload is unknown (every tool declares 0 kg) and identified as `tool_mass`.
    pub payload_unknown: bool,
    /// The nominal robot's RMS miss on the measured positions from where the fit starts (m): what
    /// [`super::convention`] looks into. `None` when no position is observed.
    pub start_rms: Option<f64>,
    /// Why the fit did not start from the cell's base guess, when it did not.
    pub start_note: Option<String>,
}

/// A model with backlash terms acts through each measurement's approach direction (the sign of
/// each joint's move into the stop). When some measurement does not log it, the cell with the
/// directions derived from the measuring order (times, sequence numbers, or the rows' order, as
/// the diagnosis derives them: [`crate::cell::order::fill_approach`]) and what was done, in
/// sentences; `None` when the model has no backlash term or every direction is logged. A
/// session marked resampled or shuffled is refused there (its order says nothing of the moves),
/// and its backlash terms stay fixed with their reason.
pub fn with_approach(cell: &Cell, models: &[&ModelOptions]) -> Option<(Cell, Vec<String>)> {
    let wants = models.iter().any(|m| m.extra.iter().any(|p| matches!(p, Param::Joint(_, JointTerm::Backlash))));
    if !wants || cell.sessions.iter().all(|s| s.measurements.iter().all(|m| m.approach.is_some())) {
        return None;
    }
    let mut filled = cell.clone();
    let notes = crate::cell::order::fill_approach(&mut filled, &[]).notes();
    Some((filled, notes))
}

/// The start set's own effect terms and correction tables that `opts.model` does not name
/// (its payload excepted: an unknown payload has its own rule; and its drift along its own run), in
/// its layout's order.
fn start_terms_missing(cell: &Cell, opts: &IdentifyOptions) -> Vec<Param> {
    let Some(start) = &opts.start else { return Vec::new() };
    let full = ParamLayout::full(&cell.model);
    let named = |p: &Param| {
        opts.model.extra.contains(p)
            || matches!(p, Param::Joint(j, JointTerm::Map { step_deg, .. }) if opts.model.maps.contains(&(*j, *step_deg)))
    };
    start
        .layout
        .params()
        .iter()
        .copied()
        .filter(|p| full.index_of(*p).is_none() && full.admits(*p))
        // A drift along the start set's run is that run's own: never carried to another.
        .filter(|p| !matches!(p, Param::ToolMass | Param::ToolMoment(_) | Param::Drift(..)))
        .filter(|p| !named(p))
        .collect()
}

/// A fit from a start set whose model lacks some of the set's own terms (a cyclic term, a
/// backlash, a correction table): the options to fit with and a sentence for the notes.
///
/// With `only` (a re-registration, `only: ["base", "tool"]`) every robot parameter outside
/// `only` is held at the set's value, so the set's terms are held with them: the fit is of the
/// set as it is, whatever `model` says. Before, a model that did not name them (the default
/// one, `identify --start set.json --only base,tool`, and the ISO 9283 evaluation's
/// registration) dropped them without a word, and the parameter set written and the figures
/// described a model without its tables (the UR10's set with tables j2, j1, j3, j5 and a cyclic
/// j1 term, re-registered on series D: 0.348 mm, the same geometry without its terms, where the
/// set itself reads 0.449 mm). Without `only` the model is the caller's choice: the options
/// stand and the note says what the start set had that this fit leaves out.
pub(crate) fn carry_start_terms(cell: &Cell, opts: &IdentifyOptions) -> Option<(Option<IdentifyOptions>, String)> {
    let missing = start_terms_missing(cell, opts);
    if missing.is_empty() {
        return None;
    }
    let spelled = super::term_spec(&missing).join(",");
    if opts.only.is_empty() {
        return Some((
            None,
            format!(
                "the start set's terms {spelled} are not in this model and are left out (name them in the model to fit them)"
            ),
        ));
    }
    let mut carried = opts.clone();
    carried.model.extra.extend(missing);
    Some((
        Some(carried),
        format!(
            "the start set's terms {spelled} are carried at its values (the fit frees only {}, and holds the rest of the set as it is)",
            opts.only.join(", ")
        ),
    ))
}

/// Build the problem, the starting point and the identifiable set: the layout, the base, the
/// weighted problem, the start values, the fixed parameters, the unknown TCPs' start, the
/// identifiable set, the anchors — each step below, in that order.
pub fn prepare(cell: &Cell, opts: &IdentifyOptions) -> Result<Prepared, IdentifyError> {
    let (layout, payload_unknown) = layout_of(cell, opts)?;
    let picks = opts.selection.picks(cell)?;
    let Start { base, registration, rms: start_rms, note: start_note } = starting_base(cell, &picks)?;
    let mut problem = Problem::new(cell, layout, base, &opts.selection, opts.rotation_weight)?;
    if let Some(noise) = &opts.noise {
        noise.check().map_err(IdentifyError::option)?;
        weight_by_instrument(&mut problem, cell, noise);
    }
    let (mut x0, from_start) = start_values(&problem, cell, opts)?;
    let fixed = fixed_parameters(&problem, opts)?;
    if let Some(r) = &registration {
        start_unknown_tcps(&problem, r, &from_start, &fixed, &mut x0);
    }
    let (free, status) = identifiable(&mut problem, &x0, &fixed, opts.map_smoothing)?;
    if let Some(a) = &opts.anchor {
        let priors = anchor_priors(&problem, &free, &x0, a, opts.noise.is_some());
        problem.add_priors(priors);
    }
    Ok(Prepared { problem, x0, free, status, base, fixed, payload_unknown, start_rms, start_note })
}

/// The parameter layout: the robot's full layout, the model's effect terms, the payload's mass
/// when it is unknown ([`payload_is_unknown`], the second value), and the correction tables'
/// knots over the chosen measurements' joint ranges.
fn layout_of(cell: &Cell, opts: &IdentifyOptions) -> Result<(ParamLayout, bool), IdentifyError> {
    let dof = cell.model.dof();
    let mut layout = ParamLayout::full(&cell.model);
    for p in &opts.model.extra {
        if !layout.admits(*p) {
            return Err(IdentifyError::field("model", format!("{p} is not a parameter of a {dof}-joint robot")));
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
            let knots = carried_table(opts, j, step).unwrap_or_else(|| {
                map_knots(j, step, picks.iter().map(|&(s, i)| cell.sessions[s].measurements[i].q[j]))
            });
            layout.extend(&knots);
        }
    }
    Ok((layout, payload_unknown))
}

/// The knots of table (j, step) of the start set, when the fit carries that table as it is: the
/// set has it and `only` does not free it (a re-registration, `only: ["base", "tool"]`). A
/// carried table keeps its own knots and so its edges, which hold their value beyond it as
/// the set does wherever it is used (compensation, validation). Built over the new session's
/// joint range instead, its knots beyond the set's started at 0: the table fell to zero one knot
/// step past the identified range, and a transfer's figure described a model that compensation
/// does not apply.
fn carried_table(opts: &IdentifyOptions, j: usize, step: u8) -> Option<Vec<Param>> {
    let start = opts.start.as_ref()?;
    let prefix = format!("map{}_s{step}", j + 1);
    let frees = |n: &String| *n == prefix || n.strip_prefix(&prefix).is_some_and(|k| k.starts_with("_k"));
    if opts.only.is_empty() || opts.only.iter().any(frees) {
        return None;
    }
    let knots: Vec<Param> = start
        .layout
        .params()
        .iter()
        .copied()
        .filter(|p| matches!(p, Param::Joint(k, JointTerm::Map { step_deg, .. }) if *k == j && *step_deg == step))
        .collect();
    (!knots.is_empty()).then_some(knots)
}

/// Where the fit starts: the base, the registration of the TCPs to identify (their start
/// values), the starting miss of the nominal robot on the positions (m) and, when a base guess
/// was set aside, why.
pub(crate) struct Start {
    base: [f64; 6],
    registration: Option<Registration>,
    rms: Option<f64>,
    note: Option<String>,
}

/// The base, and the TCPs to identify, from the nominal robot: registered in turn when a TCP is
/// unknown, else the cell's guess or one registration; with the nominal robot's RMS miss on the
/// positions from there.
///
/// A base guess is a start, not a measurement: one that misses the positions beyond what a real
/// robot's nominal model does ([`super::convention::suspicious_above`]: a frame typed with the
/// wrong angle, the readings in another convention) is weighed against the registration without
/// it, and the fit starts from whichever misses less. The miss that [`super::convention::check`]
/// then looks into is the registration's, so a cell posted with a base guess and its tools' TCPs
/// is checked as an import is.
fn starting_base(cell: &Cell, picks: &[(usize, usize)]) -> Result<Start, IdentifyError> {
    let (blocks, session_tool) = tool_blocks(cell, picks);
    let unknown_tcp = blocks.iter().any(|b| b.identify_tcp && b.tool.tcp[..3] == [0.0; 3]);
    let from = |guess: Option<[f64; 6]>| -> Result<Start, IdentifyError> {
        let start = |base, rms, registration| Start { base, registration, rms, note: None };
        Ok(match (guess, unknown_tcp) {
            (guess, true) => {
                let r = register_base_and_tcps(cell, picks, &blocks, &session_tool, guess)?;
                start(guess.unwrap_or(r.base), Some(r.rms), Some(r))
            }
            (Some(b), false) => start(b, miss_at(cell, picks, &b), None),
            (None, false) => {
                let (b, rms) = estimate_base_of(cell, picks)?;
                start(b, Some(rms), None)
            }
        })
    };
    let guessed = from(cell.base_guess)?;
    let Some(guess) = cell.base_guess else { return Ok(guessed) };
    let suspicious = super::convention::suspicious_above(cell, picks);
    let Some(rms) = guessed.rms.filter(|&r| suspicious.is_some_and(|b| r > b)) else { return Ok(guessed) };
    match from(None) {
        Ok(free) if free.rms.is_some_and(|r| r < rms) => {
            let note = format!(
                "the base guess missed the measured positions by {} mm RMS on the nominal robot, where the nominal robot registered on them misses by {} mm: the fit started from the registration (check the base guess: {} mm, {}°)",
                super::error::mm(rms),
                super::error::mm(free.rms.unwrap_or(rms)),
                fmt3(&guess[..3], 1.0 / crate::units::MM),
                fmt3(&guess[3..], 1f64.to_degrees()),
            );
            Ok(Start { note: Some(note), ..free })
        }
        _ => Ok(guessed),
    }
}

/// Three values scaled and rounded to 0.1, in parentheses.
fn fmt3(v: &[f64], scale: f64) -> String {
    let s: Vec<String> = v.iter().map(|x| format!("{:.1}", x * scale)).collect();
    format!("({})", s.join(", "))
}

/// The starting point: the nominal values, or the start parameter set's (its base excepted) for
/// the robot and for the tool blocks whose tool is its tool (the second value, per block).
fn start_values(
    problem: &Problem,
    cell: &Cell,
    opts: &IdentifyOptions,
) -> Result<(Vec<f64>, Vec<bool>), IdentifyError> {
    let mut x0 = problem.nominal.clone();
    // Tool blocks whose TCP the start parameter set gives.
    let mut from_start = vec![false; problem.tools.len()];
    let Some(start) = &opts.start else { return Ok((x0, from_start)) };
    for (t, b) in problem.tools.iter().enumerate() {
        from_start[t] = b.tool == start.tool;
    }
    // As validation decides: a set starts a fit of the same joint count, unless both robots
    // are built-in presets and differ (a custom table may be a preset re-measured; the set's
    // values are absolute, so they start its fit as well).
    let dof = cell.model.dof();
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
                // A drift along the start set's run is that run's, not this one's: the drift terms
                // start at zero, this run's mean.
                Param::Base(_) | Param::Drift(..) => None,
                p => start.value(p),
            },
            GlobalParam::Tool { tool, k } if problem.tools[tool].tool == start.tool => start.value(Param::Tool(k)),
            GlobalParam::Tool { .. } => None,
        };
        if let Some(v) = v {
            x0[g] = v;
        }
    }
    Ok((x0, from_start))
}

/// Parameters fixed by the model options, the sessions' declarations, `only` and the user
/// (global index → reason), after checking that every free-TCP session is one of the problem's.
fn fixed_parameters(problem: &Problem, opts: &IdentifyOptions) -> Result<HashMap<usize, FixedReason>, IdentifyError> {
    let mut fixed = fixed_by_model(problem, opts);
    if !opts.only.is_empty() {
        fix_all_but_only(problem, opts, &mut fixed)?;
    }
    for (i, f) in opts.fixed.iter().enumerate() {
        let g = (0..problem.n_params())
            .find(|&g| &problem.name(g) == f)
            .ok_or_else(|| IdentifyError::item("fix", i, format!("'{f}' is not a parameter of this problem")))?;
        fixed.insert(g, FixedReason::ByUser { name: f.clone(), at_start: opts.start.is_some() });
    }
    for (i, s) in opts.free_tcp.iter().enumerate() {
        if !problem.tools.iter().any(|b| b.sessions.contains(s)) {
            return Err(IdentifyError::item("free_tcp", i, format!("'{s}' is not a session of this problem")));
        }
    }
    Ok(fixed)
}

/// β and compliances the model leaves out, and the TCP components a session declares (unless
/// its TCP is freed).
fn fixed_by_model(problem: &Problem, opts: &IdentifyOptions) -> HashMap<usize, FixedReason> {
    let mut fixed: HashMap<usize, FixedReason> = HashMap::new();
    for (g, gp) in problem.params.iter().enumerate() {
        let name = problem.name(g);
        match *gp {
            GlobalParam::Robot(i) => match problem.layout.params()[i] {
                p @ Param::Beta(_) if !opts.model.beta && !opts.model.extra.contains(&p) => {
                    fixed.insert(g, FixedReason::NotInModel { name, term: ModelTerm::Beta });
                }
                p @ Param::Joint(_, JointTerm::Compliance)
                    if !opts.model.compliance && !opts.model.extra.contains(&p) =>
                {
                    fixed.insert(g, FixedReason::NotInModel { name, term: ModelTerm::Compliance });
                }
                _ => {}
            },
            GlobalParam::Tool { tool, k } => {
                let b = &problem.tools[tool];
                let freed = b.sessions.iter().any(|s| opts.free_tcp.contains(s));
                if !b.identify_tcp && !freed && (k < 3 || b.has_orientation) {
                    fixed.insert(g, FixedReason::DeclaredTcp { name });
                }
            }
        }
    }
    fixed
}

/// Every parameter not named by [`IdentifyOptions::only`] (a name, or the groups `base`, `tool`
/// and `zeros`, the joints' zero offsets θ1…θn) is fixed at its start value; a reason already
/// given stays.
fn fix_all_but_only(
    problem: &Problem,
    opts: &IdentifyOptions,
    fixed: &mut HashMap<usize, FixedReason>,
) -> Result<(), IdentifyError> {
    let mut keep = vec![false; problem.n_params()];
    for (i, item) in opts.only.iter().enumerate() {
        let hits: Vec<usize> = (0..problem.n_params())
            .filter(|&g| match (item.as_str(), problem.params[g]) {
                ("base", GlobalParam::Robot(i)) => matches!(problem.layout.params()[i], Param::Base(_)),
                ("tool", GlobalParam::Tool { .. }) => true,
                ("zeros", GlobalParam::Robot(i)) => matches!(problem.layout.params()[i], Param::Theta(_)),
                (name, _) => problem.name(g) == name,
            })
            .collect();
        if hits.is_empty() {
            return Err(IdentifyError::item(
                "only",
                i,
                format!("'{item}' is neither a parameter of this problem nor a group (base, tool, zeros)"),
            ));
        }
        hits.into_iter().for_each(|g| keep[g] = true);
    }
    for (g, k) in keep.iter().enumerate() {
        if !k {
            let at_start = opts.start.is_some();
            fixed.entry(g).or_insert_with(|| FixedReason::NotInOnly { name: problem.name(g), at_start });
        }
    }
    Ok(())
}

/// Unknown TCPs start from the registration (not where the start set gives them, and not the
/// components held fixed, which stay at nominal).
fn start_unknown_tcps(
    problem: &Problem,
    registration: &Registration,
    from_start: &[bool],
    fixed: &HashMap<usize, FixedReason>,
    x0: &mut [f64],
) {
    for (g, gp) in problem.params.iter().enumerate() {
        if let GlobalParam::Tool { tool, k } = *gp
            && problem.tools[tool].identify_tcp
            && !from_start[tool]
            && !fixed.contains_key(&g)
        {
            x0[g] = registration.tcps[tool][k];
        }
    }
}

/// Identifiability at the starting point, the correction tables' regularisation rows added to
/// the problem first: the free parameters and every parameter's status.
fn identifiable(
    problem: &mut Problem,
    x0: &[f64],
    fixed: &HashMap<usize, FixedReason>,
    map_smoothing: f64,
) -> Result<(Vec<usize>, Vec<Status>), IdentifyError> {
    let has_tables = problem.layout.params().iter().any(|p| matches!(p, Param::Joint(_, JointTerm::Map { .. })));
    let (free, status) = if has_tables {
        let (mut j0, _) = problem.linearise_all(x0);
        let priors = map_priors(problem, &j0, map_smoothing)?;
        if !priors.is_empty() {
            problem.add_priors(priors);
            j0 = problem.linearise_all(x0).0;
        }
        identifiability::select(problem, &j0, fixed)
    } else {
        identifiability::select(problem, &columns_not_fixed(problem, x0, fixed), fixed)
    };
    if free.is_empty() {
        return Err(IdentifyError::option("no parameter is free to identify"));
    }
    Ok((free, status))
}

/// The Jacobian at `x0` as the identifiability sweep reads it (its columns' inner products, global
/// column g for parameter g), computed for the parameters not fixed in advance only: their
/// columns, by R of J = Q·R when J is tall, and a zero column for each fixed one, which the sweep
/// never reads. On the peers' 5,000-pose problem (43 parameters, 20 fixed by the model and the
/// user) this halves the columns computed and quarters the factorisation.
pub(super) fn columns_not_fixed(problem: &Problem, x0: &[f64], fixed: &HashMap<usize, FixedReason>) -> Mat<f64> {
    let n = problem.n_params();
    let wanted: Vec<usize> = (0..n).filter(|g| !fixed.contains_key(g)).collect();
    let mut j = Mat::<f64>::zeros(problem.n_rows, wanted.len());
    let mut r = vec![0.0; problem.n_rows];
    problem.linearise(x0, &wanted, &mut j, &mut r);
    let j = if j.nrows() > 4 * wanted.len() { super::solver::r_factor(j.as_ref()) } else { j };
    let mut col = vec![None; n];
    for (c, &g) in wanted.iter().enumerate() {
        col[g] = Some(c);
    }
    Mat::from_fn(j.nrows(), n, |i, g| col[g].map_or(0.0, |c| j[(i, c)]))
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
        return Err(IdentifyError::field("map_smoothing", format!("must be a positive number, got {eta}")));
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
