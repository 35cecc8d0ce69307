//! The fit (§4.2.1) from a prepared problem: identifiability judged again at the solution, an
//! unknown payload kept only when determined, the fitness and conditioning checks, and the
//! parameter set with its uncertainties.

use faer::Mat;
use rayon::prelude::*;

use super::hold::PAYLOAD_SIGNIFICANCE;
use super::noise::NoiseModel;
use super::prepare::{Prepared, prepare, row_sigmas};
use super::problem::{GlobalParam, Problem};
use super::solver::{self, Fit, SolveError};
use super::{FixedReason, IdentifyError, IdentifyOptions, Quality, Status, Worst, identifiability};
use crate::cell::Cell;
use crate::kinematics::{Param, ParameterSet, Tool};

/// An identified tool (beyond the parameter set's own).
#[derive(Clone, Debug, PartialEq)]
pub struct ToolResult {
    /// The sessions measured with it (one tool block of the problem).
    pub sessions: Vec<String>,
    /// The tool, its TCP as fitted: x, y, z (m) and a, b, c (rad, ZY'X'') of T_T^6.
    pub tool: Tool,
    /// Standard deviation of each TCP component when identified (SI).
    pub std: [Option<f64>; 6],
    /// Per TCP component: `identified`, or why it is held ([`Status`] as text).
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
    /// Conditioning (κ SI and scaled), O1–O5, σ̂ and the covariance of the free parameters.
    pub quality: Quality,
    /// Names of the free parameters, in the covariance's order.
    pub free_names: Vec<String>,
    /// Solver iterations of the final fit.
    pub iterations: usize,
    /// Observations down-weighted by the robust loss: (session, index, weight).
    pub downweighted: Vec<(String, usize, f64)>,
    /// The readings the options left out (`selection.exclude`: outliers), in the options' order:
    /// (session, index, the reading's [`crate::cell::fingerprint`] — `None` for a ball of a cell
    /// without its artefact). What a diagnosis of the set leaves out too.
    pub excluded: Vec<(String, usize, Option<String>)>,
    /// The measurements with the largest residuals against their expected noise, largest first
    /// (at most [`WORST_REPORTED`]).
    pub worst: Vec<Worst>,
    /// The problem solved: measurements, global parameters, priors.
    pub problem: Problem,
    /// The free parameters' global indices (into `problem.params`), in the covariance's order.
    pub free: Vec<usize>,
    /// The global parameter vector at the solution (SI): robot parameters, then six per tool block.
    pub x: Vec<f64>,
    /// What was derived rather than given, in sentences (e.g. approach directions taken from the
    /// measuring order).
    pub notes: Vec<String>,
    /// Per parameter held because the data leave it undetermined, the free parameters whose
    /// values and σ assume its held value (it would move them beyond their σ): [`super::Conditional`].
    pub conditional: Vec<super::conditional::Conditional>,
}

/// The parameters free in some of several registrations and held in others (`free`: each
/// registration's free names), in first-seen order. Models compared after registering on one
/// session must share one registration's freedoms: a base or tool parameter the session leaves at
/// the edge of determined is held by one fit and freed by another (the UR10 probe's z on series D:
/// κ 7 against 2,055), so every caller holds these in all of them and refits.
pub fn free_in_some_only(free: &[&[String]]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for n in free.iter().flat_map(|f| f.iter()) {
        if !out.contains(n) && !free.iter().all(|f| f.contains(n)) {
            out.push(n.clone());
        }
    }
    out
}

impl Identification {
    /// A payload the parameter set's tool does not declare (0 kg), as identified: its mass (kg) and
    /// standard deviation (`None` when the data did not determine it and it is held at 0); `None`
    /// when the tool declares a payload or the model has no payload mass.
    pub fn undeclared_payload(&self) -> Option<(f64, Option<f64>)> {
        let i = self.set.layout.index_of(Param::ToolMass)?;
        (self.set.tool.mass == 0.0).then(|| (self.set.values[i], self.std[i]))
    }
}

/// The global index of the payload's mass, when the problem has one.
fn payload_mass(problem: &Problem) -> Option<usize> {
    let i = problem.layout.index_of(Param::ToolMass)?;
    problem.params.iter().position(|p| *p == GlobalParam::Robot(i))
}

/// An undeclared payload identified once more with its centre of mass at the flange's origin
/// instead of where the sessions put it (an import puts it at the reflectors' centroid); `None`
/// when the chosen sessions declare a payload or the model identifies none.
///
/// The gravity torques of an unknown payload enter the fit only through the compliances, so the
/// data tell its mass little apart from where it sits. On an independent simulator's twin
/// (2.9 kg, 20 mm nearer the flange than the reflectors' centroid, BENCHMARKS "The payload's σ
/// against an independent twin") the centroid gave 1.24 ± 0.28 kg and the flange 2.64 ± 0.76 kg;
/// each fit's σ holds only for the centre of mass it assumes. Said beside the mass, this is what a
/// reader needs to judge it.
pub fn payload_at_flange(cell: &Cell, opts: &IdentifyOptions) -> Result<Option<PayloadAtFlange>, IdentifyError> {
    let picks = opts.selection.picks(cell)?;
    let mut at_flange = cell.clone();
    for s in picks.iter().map(|p| p.0) {
        if at_flange.sessions[s].tool.mass != 0.0 {
            return Ok(None);
        }
        at_flange.sessions[s].tool.com = nalgebra::Vector3::zeros();
    }
    let id = identify(&at_flange, opts)?;
    let Some(i) = id.set.layout.index_of(Param::ToolMass) else { return Ok(None) };
    Ok(Some(PayloadAtFlange { mass: id.set.values[i], std: id.std[i], rms_residual: id.quality.rms_residual }))
}

/// An undeclared payload identified with its centre of mass at the flange ([`payload_at_flange`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PayloadAtFlange {
    /// The mass, kg.
    pub mass: f64,
    /// Its standard deviation, kg; `None` when that fit holds the mass as not determined.
    pub std: Option<f64>,
    /// That fit's residual RMS, m.
    pub rms_residual: f64,
}

/// An undeclared payload's centre of mass, identified with its mass where the data determine it
/// (the identification's undeclared payload must have been kept, [`Identification::undeclared_payload`]):
/// the solution is fitted once more with the payload's first moment beyond its assumed centre of
/// mass free (`tool_moment_x`, `_y`, `_z` in the flange frame, [`Param::ToolMoment`]), from the
/// solution and with every other free parameter still free. `None` when there is no determined
/// undeclared payload.
///
/// The mass this gives carries the uncertainty of where the payload sits, which the first fit's σ
/// takes as exact (BENCHMARKS "The payload's σ against an independent twin"). The centre of mass
/// c = c₀ + h/m and its standard deviations come by the delta method: for each component the
/// larger of the classic and the cluster-robust variance of that combination (as every σ of an
/// identification is the larger of the two), so they do not depend on the centre of mass assumed
/// at the start.
///
/// The centre of mass is `determined` when every component's σ is within
/// `UNDETERMINED_LENGTH_M` (10 mm, the bound of every length the
/// identification keeps), the fit's κ within the limit and the mass still above
/// [`PAYLOAD_SIGNIFICANCE`] of its σ; otherwise the reading stands with its σ as what these data
/// say about it, and only the first fit's mass is used.
pub fn payload_centre_of_mass(
    id: &Identification,
    opts: &IdentifyOptions,
) -> Result<Option<PayloadCentreOfMass>, IdentifyError> {
    let Some((_, Some(_))) = id.undeclared_payload() else { return Ok(None) };
    let Some(gm) = payload_mass(&id.problem).filter(|g| id.free.contains(g)) else { return Ok(None) };
    let moments = [Param::ToolMoment(0), Param::ToolMoment(1), Param::ToolMoment(2)];
    let (problem, remap) = id.problem.extended(&moments);
    let mut x = problem.nominal.clone();
    for (old, &new) in remap.iter().enumerate() {
        x[new] = id.x[old];
    }
    // The moments start at their nominal, 0: the centre of mass the sessions assume.
    let hs: Vec<usize> =
        moments.iter().map(|&p| problem.robot_index(p).expect("the moments were just added")).collect();
    let mut free: Vec<usize> = id.free.iter().map(|&g| remap[g]).collect();
    free.extend(&hs);
    let fit = solver::solve(&problem, &free, &x, &opts.solver)?;
    let rows: Vec<(usize, usize)> = problem.obs.iter().map(|o| (o.row, o.rows)).collect();
    let dof = problem.model.dof();
    let (pose_of_obs, n_poses) = crate::cell::poses::group_poses(problem.obs.iter().map(|o| &o.state.q[..dof]));
    let mut q = Quality::of(&fit, problem.obs.len(), &rows);
    let col = |g: usize| free.iter().position(|&f| f == g).expect("free");
    let cm = col(remap[gm]);
    let ch: Vec<usize> = hs.iter().map(|&g| col(g)).collect();
    let m = fit.x[remap[gm]];
    let h = nalgebra::Vector3::from_fn(|k, _| fit.x[hs[k]]);
    let c0 = problem.tools[0].tool.com;
    // c = c₀ + h/m: ∂c_k/∂h_k = 1/m, ∂c_k/∂m = −h_k/m². Each σ the larger of the classic and the
    // cluster-robust one of that combination, so it does not depend on the parameters it is
    // derived from (the centre of mass assumed at the start).
    let com_std: [f64; 3] = std::array::from_fn(|k| {
        let mut w = vec![0.0; free.len()];
        w[ch[k]] = 1.0 / m;
        w[cm] = -h[k] / (m * m);
        let cov = |a: usize, b: usize| q.covariance[(a, b)];
        let classic = w[ch[k]] * w[ch[k]] * cov(ch[k], ch[k])
            + 2.0 * w[ch[k]] * w[cm] * cov(ch[k], cm)
            + w[cm] * w[cm] * cov(cm, cm);
        let robust = q.cluster_robust_variance(&fit, &rows, &pose_of_obs, n_poses, &w).unwrap_or(0.0);
        classic.max(robust).max(0.0).sqrt()
    });
    q.make_robust(&fit, &rows, &pose_of_obs, n_poses);
    let std_mass = q.std[cm];
    let rms_residual = if opts.noise.is_some() || fit.weights.iter().any(|&w| w != 1.0) {
        weighted_rms(&problem, &fit)
    } else {
        q.rms_residual
    };
    let determined = q.kappa_scaled <= opts.kappa_limit
        && m > PAYLOAD_SIGNIFICANCE * std_mass
        && com_std.iter().all(|s| *s <= super::identifiability::UNDETERMINED_LENGTH_M);
    // A mass the free fit takes to 0 or below places no centre of mass (and `determined` is
    // false: the mass is not above 3 σ).
    let placed = m > 0.0 && (h / m).iter().chain(&com_std).all(|v| v.is_finite());
    Ok(Some(PayloadCentreOfMass {
        mass: m,
        std: std_mass,
        com: placed.then(|| c0 + h / m),
        com_std: placed.then_some(com_std),
        rms_residual,
        kappa: q.kappa_scaled,
        determined,
    }))
}

/// An undeclared payload's mass and centre of mass identified together ([`payload_centre_of_mass`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PayloadCentreOfMass {
    /// The mass, kg.
    pub mass: f64,
    /// Its standard deviation, kg, with the centre of mass free.
    pub std: f64,
    /// The centre of mass in the flange frame, m; `None` when the mass is not above 0.
    pub com: Option<nalgebra::Vector3<f64>>,
    /// Its standard deviations, m; `None` when the mass is not above 0.
    pub com_std: Option<[f64; 3]>,
    /// That fit's residual RMS, m.
    pub rms_residual: f64,
    /// That fit's κ (unit-norm columns).
    pub kappa: f64,
    /// Whether the data determine the centre of mass (see [`payload_centre_of_mass`]).
    pub determined: bool,
}

/// Identify a cell's robot. A model with backlash terms on sessions that do not log the approach
/// directions takes them from the measuring order (its `with_approach` step; said in
/// [`Identification::notes`]).
///
/// Each parameter comes back with its value, its standard deviation and its status: identified,
/// or held with the reason ([`super::FixedReason`]). On the thesis's virtual cell (an IRB 120 on a
/// TriCal artefact, three balls, no orientation measured):
///
/// ```
/// use robocal_core::identify::{FixedReason, IdentifyOptions, Status, identify};
/// use robocal_core::kinematics::{JointTerm, Param};
/// use robocal_core::sim::simulate::{SimulateOptions, simulate};
///
/// let sim = simulate(&SimulateOptions { seed: 3, ..Default::default() })?;
/// let id = identify(&sim.cell, &IdentifyOptions::default())?;
/// let at = |p: Param| id.set.layout.index_of(p).unwrap();
///
/// // Axis 1 is vertical: gravity never loads it, so its compliance is held, and said why.
/// let c1 = at(Param::Joint(0, JointTerm::Compliance));
/// assert_eq!(id.status[c1], Status::Fixed(FixedReason::NoGravityTorque { name: "c1".into(), axis: 1, massless: false }));
/// assert_eq!(id.status[c1].to_string(), "c1: no gravity torque on axis 1");
///
/// // a2 (the upper arm's length) is identified to a few micrometres of the true robot's.
/// let a2 = at(Param::A(2));
/// let truth = sim.truth.set.values[sim.truth.set.layout.index_of(Param::A(2)).unwrap()];
/// let (value, std) = (id.set.values[a2], id.std[a2].unwrap());
/// assert_eq!(id.status[a2], Status::Identified);
/// assert!(std < 10e-6 && (value - truth).abs() < 4.0 * std, "{value} ± {std} m, truth {truth} m");
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn identify(cell: &Cell, opts: &IdentifyOptions) -> Result<Identification, IdentifyError> {
    let (carried, carry_note) = match super::prepare::carry_start_terms(cell, opts) {
        Some((o, note)) => (o, Some(note)),
        None => (None, None),
    };
    let opts = carried.as_ref().unwrap_or(opts);
    let mut id = match super::prepare::with_approach(cell, &[&opts.model]) {
        Some((filled, notes)) => {
            let mut id = identify_cell(&filled, opts)?;
            id.notes.extend(notes);
            id
        }
        None => identify_cell(cell, opts)?,
    };
    id.notes.extend(carry_note);
    Ok(id)
}

fn identify_cell(cell: &Cell, opts: &IdentifyOptions) -> Result<Identification, IdentifyError> {
    let Prepared { problem, x0, mut free, mut status, base, fixed, payload_unknown, start_rms, start_note } =
        prepare(cell, opts)?;
    super::scale::check_position_scale(&problem, &x0, cell)?;
    let check_note = super::convention::check(cell, opts, start_rms)?;
    if problem.n_obs_rows + problem.priors.len() <= free.len() {
        return Err(IdentifyError::Underdetermined { rows: problem.n_obs_rows, params: free.len() });
    }

    let mut notes: Vec<String> = start_note.into_iter().chain(check_note).collect();
    if opts.model.beta {
        notes.extend(parallel_axes_without_beta(&cell.model));
    }
    notes.extend(super::run::drift_order_note(&problem));
    // Parameters held where a first fit stopped: not freed again below.
    let mut held_where_stopped = Vec::new();
    let mut fit = match solver::solve(&problem, &free, &x0, &opts.solver) {
        Ok(fit) => fit,
        Err(e) => {
            let (f, again, again_status, note) =
                judge_where_it_stopped(&problem, &x0, &free, &status, &fixed, &opts.solver, e)?;
            notes.push(note);
            held_where_stopped = free.iter().copied().filter(|g| !again.contains(g)).collect();
            (free, status) = (again, again_status);
            f
        }
    };
    // Identifiability is judged at the start. An unknown TCP (no guess: the flange) may end far
    // from where the registration started it, and which of its components is one gauge with d6
    // and θ6 depends on where it lies (a point on the flange's y axis moves along x when θ6
    // turns): judge again at the solution, and refit from there when the choice changed. A TCP
    // with a guess stays judged at its guess (the UR10 probe: θ6 has no effect there). An
    // unknown payload acts through the compliances, which are zero at the start: its mass has
    // no effect there and is judged at the solution too.
    rejudge_at_solution(
        &problem,
        &x0,
        opts,
        payload_unknown,
        &fixed,
        &held_where_stopped,
        &mut fit,
        &mut free,
        &mut status,
    )?;
    let rows: Vec<(usize, usize)> = problem.obs.iter().map(|o| (o.row, o.rows)).collect();
    // The pose of each measurement, for standard deviations that hold when the readings of one
    // stop share an error (several reflectors, a turn no term explains): the larger of the classic
    // and the cluster-robust σ ([`Quality::make_robust`]).
    let (pose_of_obs, n_poses) =
        crate::cell::poses::group_poses(problem.obs.iter().map(|o| &o.state.q[..cell.model.dof()]));
    // An unknown payload, and the compliances, are kept only when the data determine them.
    let f = super::hold::Fitted {
        problem: &problem,
        x0: &x0,
        rows: &rows,
        pose_of_obs: &pose_of_obs,
        n_poses,
        solver: &opts.solver,
        payload: payload_unknown.then(|| payload_mass(&problem)).flatten(),
        compliances: opts.hold_undetermined_compliance,
        kappa_limit: opts.kappa_limit,
    };
    let mut shifts = Vec::new();
    let mut quality = super::hold::hold_undetermined(&f, &mut fit, &mut free, &mut status, &mut shifts)?;
    notes.extend(super::hold::hold_notes(&problem, &free, &quality, &shifts));
    if opts.noise.is_some() {
        quality.weighted = true;
    }
    // The residual in metres, as measured: without the instrument's weights and without the robust
    // loss's (a Huber fit's rows carry its weights; the RMS of those would not be the residual
    // `residual_ratio` divides). Unweighted rows convert exactly (x / 1).
    if opts.noise.is_some() || fit.weights.iter().any(|&w| w != 1.0) {
        quality.rms_residual = weighted_rms(&problem, &fit);
    }
    let worst = judge_fit(&problem, cell, opts, &fit, &free, &mut quality)?;
    let conditional = super::conditional::conditionals(&problem, &fit, &free, &status, &quality);
    notes.extend(super::conditional::conditional_notes(&conditional));

    // The parameter set of the first tool, and every tool's result.
    let mut std_g = vec![None; problem.n_params()];
    for (c, &g) in free.iter().enumerate() {
        std_g[g] = Some(quality.std[c]);
    }
    let tools = tool_results(&problem, &fit, &std_g, &status);
    let (set, std, st) = layout_results(cell, &problem, base, &fit, &std_g, &status);
    let downweighted = problem
        .obs
        .iter()
        .zip(&fit.weights)
        .filter(|(_, w)| **w < 1.0)
        .map(|(o, w)| (problem.session_names[o.session].clone(), o.index, *w))
        .collect();
    // `picks` checked every excluded reading is in the cell.
    let excluded = opts
        .selection
        .exclude
        .iter()
        .filter_map(|(name, i)| {
            let m = cell.session(name)?.measurements.get(*i)?;
            Some((name.clone(), *i, crate::cell::fingerprint::of_measurement(cell, m)))
        })
        .collect();
    Ok(Identification {
        worst,
        set,
        std,
        status: st,
        tools,
        free_names: free.iter().map(|&g| problem.name(g)).collect(),
        iterations: fit.iterations,
        downweighted,
        excluded,
        quality,
        x: fit.x,
        notes,
        conditional,
        problem,
        free,
    })
}

/// Identifiability judged again at the solution, when the start could not judge it: an unknown
/// TCP (no guess) or an unknown payload. Refits from the solution when the choice changed; a
/// payload whose refit does not settle is held, and said so.
#[allow(clippy::too_many_arguments)]
fn rejudge_at_solution(
    problem: &Problem,
    x0: &[f64],
    opts: &IdentifyOptions,
    payload_unknown: bool,
    fixed: &std::collections::HashMap<usize, FixedReason>,
    held_where_stopped: &[usize],
    fit: &mut Fit,
    free: &mut Vec<usize>,
    status: &mut Vec<Status>,
) -> Result<(), IdentifyError> {
    let tcp_unknown = problem.tools.iter().any(|b| b.identify_tcp && b.tool.tcp[..3] == [0.0; 3]);
    if !(payload_unknown || tcp_unknown) {
        return Ok(());
    }
    let (j, r) = problem.linearise_all(&fit.x);
    // Judged again for the payload alone, every other parameter keeps the start's judgement:
    // a TCP guessed on axis 6 that the fit leaves a few µm off it (noise) would otherwise free
    // the parameters its exact position made dependent (a5 on θ5, d5 on α5 for the IRB 120),
    // and the refit would wander in their valley until its iteration limit.
    let mut judged = fixed.clone();
    for &g in held_where_stopped {
        if let Status::Fixed(why) = &status[g] {
            judged.insert(g, why.clone());
        }
    }
    if !tcp_unknown {
        let mass = payload_mass(problem);
        for g in (0..problem.n_params()).filter(|g| !free.contains(g) && Some(*g) != mass) {
            if let Status::Fixed(why) = &status[g] {
                judged.entry(g).or_insert_with(|| why.clone());
            }
        }
    }
    // With the statistical test too (σ from the residual here): a TCP the fit leaves a few µm
    // off the last axis keeps a5 and d5 formally independent of θ5 and α5, with standard
    // deviations of some 180 mm (an SMR in a nest on the flange's axis, no guess).
    let sigma = residual_sigma(&r, problem.n_rows, free.len());
    let (again, mut again_status) = identifiability::select_given_noise(problem, &j, &judged, sigma);
    if again != *free && !again.is_empty() {
        let mass = payload_unknown.then(|| payload_mass(problem)).flatten().filter(|g| again.contains(g));
        // A parameter held now goes back to its start value, as its status says: where the fit
        // took it along a valley the data barely see is no estimate (a Barrett WAM's a6 and d6,
        // one SMR near the last axis, wandered to −6.3 and −35.8 mm; held there, they left α6 a
        // seemingly determined 65.6° for a nominal 90°).
        let from = back_to_start(&fit.x, x0, free, &again);
        match solver::solve(problem, &again, &from, &opts.solver) {
            Ok(f) => (*fit, *free, *status) = (f, again, again_status),
            // An unknown payload whose fit crawls (a valley with the compliances) is not
            // determined by these data: the fit without it stands, and says so.
            Err(e @ SolveError::IterationLimit { .. }) if mass.is_some() => {
                let g = mass.expect("checked");
                let without: Vec<usize> = again.iter().copied().filter(|&c| c != g).collect();
                if without != *free {
                    *fit = solver::solve(problem, &without, &from, &opts.solver)?;
                }
                again_status[g] = Status::Fixed(FixedReason::PayloadUnsettled { error: e.to_string() });
                (*free, *status) = (without, again_status);
            }
            Err(e) => return Err(e.into()),
        }
    }
    Ok(())
}

/// A sentence for each joint whose axis is nominally parallel to the previous one (a twist of 0 or
/// 180°) and that carries no Hayati β in the robot's model: the modified DH row cannot then tilt
/// it about the direction its twist does not cover, and a custom robot file says so with
/// `beta_deg` (the presets do: the IRB 120's joint 3, the UR10's 3 and 4).
fn parallel_axes_without_beta(model: &crate::kinematics::RobotModel) -> Vec<String> {
    model
        .links
        .iter()
        .enumerate()
        .skip(1)
        .filter(|(_, l)| l.beta.is_none() && l.alpha.sin().abs() < 1e-9)
        .map(|(j, _)| {
            format!(
                "axes {} and {} are nominally parallel and joint {} carries no Hayati β in this robot's model: a tilt of axis {} about the direction its twist does not cover cannot be fitted (give joint {} \"beta_deg\": 0 in the robot file)",
                j,
                j + 1,
                j + 1,
                j + 1,
                j + 1
            )
        })
        .collect()
}

/// `x` with every parameter of `free` that `kept` no longer holds free back at its start value in
/// `x0` (what a held parameter's status promises).
fn back_to_start(x: &[f64], x0: &[f64], free: &[usize], kept: &[usize]) -> Vec<f64> {
    let mut from = x.to_vec();
    for g in free.iter().copied().filter(|g| !kept.contains(g)) {
        from[g] = x0[g];
    }
    from
}

/// Every tool's TCP as fitted, with its standard deviations and statuses.
fn tool_results(problem: &Problem, fit: &Fit, std_g: &[Option<f64>], status: &[Status]) -> Vec<ToolResult> {
    let label = |g: usize| status[g].to_string();
    problem
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
        .collect()
}

/// The parameter set of the first tool (values, nominal values), with each layout entry's standard
/// deviation and status.
fn layout_results(
    cell: &Cell,
    problem: &Problem,
    base: [f64; 6],
    fit: &Fit,
    std_g: &[Option<f64>],
    status: &[Status],
) -> (ParameterSet, Vec<Option<f64>>, Vec<Status>) {
    let mut set = ParameterSet::nominal(cell.model.clone(), problem.tools[0].tool.clone(), base);
    set.layout = problem.layout.clone();
    set.nominal = problem.layout.nominal_values(&cell.model, &problem.tools[0].tool, &base);
    set.values = problem.layout_values(&fit.x, 0);
    let mut std = vec![None; set.layout.len()];
    let mut st = vec![Status::Fixed(FixedReason::NotInProblem); set.layout.len()];
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
    (set, std, st)
}

/// Weighted rows: the RMS of the measurement residuals in metres, from the rows divided by their
/// weights (and the robust weights, which the fit's residual carries too).
fn weighted_rms(problem: &Problem, fit: &Fit) -> f64 {
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
    (sum / problem.obs.len().max(1) as f64).sqrt()
}

/// Whether the model describes the data (its residual against the noise the instrument predicts,
/// no gross outlier) and whether the fit is determined (rank, conditioning); the quality report
/// gets the expected RMS and the ratio. The worst measurements, in units of their σ.
fn judge_fit(
    problem: &Problem,
    cell: &Cell,
    opts: &IdentifyOptions,
    fit: &Fit,
    free: &[usize],
    quality: &mut Quality,
) -> Result<Vec<Worst>, IdentifyError> {
    // Does the model describe the data? The residual against the noise the instrument predicts.
    let noise = opts.noise.clone().unwrap_or_default();
    let fitness = Fitness::of(problem, cell, &noise, fit, opts.outlier_factor);
    quality.expected_rms = fitness.expected_rms;
    quality.residual_ratio = fitness.ratio;
    // Gross outliers first: they bias the fit, and so the residual of the rest, which may then
    // read as a misfit (eight readings of the neighbouring reflector among 600: 80 times the
    // instrument's noise); left out, the rest is judged again.
    if !fitness.outliers.is_empty() {
        return Err(IdentifyError::Outliers { outliers: fitness.outliers, factor: opts.outlier_factor });
    }
    if fitness.ratio > opts.residual_ratio_limit {
        return Err(IdentifyError::Misfit {
            rms: fitness.rms,
            expected: fitness.expected_rms,
            ratio: fitness.ratio,
            limit: opts.residual_ratio_limit,
            worst: fitness.worst.clone(),
        });
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
    Ok(fitness.worst)
}

/// The residual's standard deviation per row, √(Σr²/(n − m)), when finite.
fn residual_sigma(r: &[f64], n: usize, m: usize) -> Option<f64> {
    let sigma = (r.iter().map(|v| v * v).sum::<f64>() / n.saturating_sub(m).max(1) as f64).sqrt();
    sigma.is_finite().then_some(sigma)
}

/// A fit that stopped before converging (diverged, or at the iteration limit) from the start's
/// judgement of identifiability: judge again where it stopped, with the statistical test of
/// [`identifiability::select_given_noise`] (σ from the residual there), and refit from there when
/// the choice changed. The start's judgement is made where the guesses put the tools and the
/// base; a TCP guessed a few millimetres off the last axis of a reflector that is on it frees θ6
/// (and, on the IRB 120, a5 and d5), whose effects vanish as the fit brings the TCP onto the
/// axis — the step turns singular (noise-free data) or the fit crawls in their valley (noisy
/// data). Returns the fit, the free parameters, their statuses and a note saying what changed;
/// or the first fit's error when nothing changed or the refit failed too.
fn judge_where_it_stopped(
    problem: &Problem,
    x0: &[f64],
    free: &[usize],
    start: &[Status],
    fixed: &std::collections::HashMap<usize, FixedReason>,
    solver_opts: &solver::SolverOptions,
    error: SolveError,
) -> Result<(Fit, Vec<usize>, Vec<Status>, String), IdentifyError> {
    let last = match &error {
        SolveError::Diverged { last, .. } | SolveError::IterationLimit { last, .. } => last.clone(),
    };
    if last.iter().any(|v| !v.is_finite()) {
        return Err(error.into());
    }
    let (j, r) = problem.linearise_all(&last);
    let Some(sigma) = residual_sigma(&r, problem.n_rows, free.len()) else {
        return Err(error.into());
    };
    // Only holding more: a parameter the start held keeps its reason (an unknown payload, which
    // has no effect at the start, is judged at the solution below, as after a converged fit).
    let mut judged = fixed.clone();
    for g in (0..problem.n_params()).filter(|g| !free.contains(g)) {
        if let Status::Fixed(why) = &start[g] {
            judged.entry(g).or_insert_with(|| why.clone());
        }
    }
    let (again, status) = identifiability::select_given_noise(problem, &j, &judged, Some(sigma));
    if again.is_empty() || again == free {
        return Err(error.into());
    }
    // The held parameters go back to their start values: where the fit wandered in their valley
    // is no estimate, and the free parameters they were dependent on take up the difference.
    let from = back_to_start(&last, x0, free, &again);
    let Ok(fit) = solver::solve(problem, &again, &from, solver_opts) else {
        return Err(error.into());
    };
    let named = |set: &[usize], other: &[usize]| {
        set.iter().filter(|g| !other.contains(g)).map(|&g| problem.name(g)).collect::<Vec<_>>().join(", ")
    };
    debug_assert!(again.iter().all(|g| free.contains(g)));
    let stopped = match &error {
        SolveError::Diverged { iteration, reason, .. } => format!("it diverged at iteration {iteration}: {reason}"),
        SolveError::IterationLimit { iterations, .. } => format!("no convergence in {iterations} iterations"),
    };
    let note = format!(
        "the fit with the parameters judged identifiable at the start did not converge ({stopped}); judged again where it stopped, {} were held at their start values (see their status), and the fit from there converged",
        named(free, &again)
    );
    Ok((fit, again, status, note))
}

/// Measurements listed in [`Identification::worst`].
pub const WORST_REPORTED: usize = 5;

/// A measurement "fits another target" when that target's TCP, at its joint readings, predicts its
/// position within this many times the fit's RMS.
const OTHER_TARGET_RMS: f64 = 5.0;

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
    /// over its rows. One whose z exceeds [`OUTLIER_FACTOR`] times the larger of the median z and
    /// 1 is an outlier, unless the Huber loss down-weighted it. (Without τ, where the model's misses
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
            .par_iter()
            .with_min_len(super::problem::PAR_MIN_OBS)
            .zip(&sigmas)
            .map(|(o, s)| {
                let (d, rot) = problem.error(o, &o.fk(&chains[o.tool]));
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
                fits_other: None,
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
        // A measurement far off whose position another target's TCP, at its own joint readings,
        // predicts within what the model misses anyway (a few times the RMS), and at most a third
        // of its own residual: that target was measured there.
        let fits_other = |i: usize| {
            let o = &problem.obs[i];
            if o.is_ball() || problem.tools.len() < 2 {
                return None;
            }
            let own = per[i].0.sqrt();
            let measured = o.measured_position();
            (0..problem.tools.len())
                .filter(|&t| t != o.tool)
                .map(|t| (t, (chains[t].fk(&o.state).t - measured).norm()))
                .filter(|&(_, d)| d <= (OTHER_TARGET_RMS * rms).min(own / 3.0))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(t, d)| (problem.tools[t].sessions[0].clone(), d))
        };
        let with_other = |mut w: Worst, i: usize| {
            w.fits_other = fits_other(i);
            w
        };
        Fitness {
            rms,
            expected_rms,
            ratio: if expected_rms > 0.0 { rms / expected_rms } else { f64::INFINITY },
            worst: order.iter().take(WORST_REPORTED).map(|&i| with_other(worst_of(i), i)).collect(),
            outliers: order
                .iter()
                .copied()
                .filter(|&i| is_outlier(i) && fit.weights[i] >= 1.0)
                .map(|i| with_other(worst_of(i), i))
                .collect(),
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
