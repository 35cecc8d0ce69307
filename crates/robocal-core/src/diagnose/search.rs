//! The greedy search: screen every candidate on the current model, confirm the best few on
//! held-out poses, accept one, refit, repeat — and stop with an honest verdict when the evidence
//! is ambiguous (DIAGNOSIS §1, §3, §4).
//!
//! Statistical decisions, each with its null hypothesis and correction:
//! - **Screening** (`screen`): H0 "the candidate's parameters are zero", F form of the score
//!   test, Holm's correction over the whole family at `alpha` (family-wise error). The frequency
//!   scan is one test per joint with a Bonferroni factor over its independent frequencies.
//! - **Confirmation** (`cv`): H0 "adding the candidate does not lower the held-out squared error
//!   of a pose", one-sided Wilcoxon signed-rank over the tested poses of a grouped K-fold
//!   cross-validation, at `confirm_p`, and the held-out RMS must drop by more than `min_gain`
//!   (the instrument's resolution). The test is over poses and needs no σ: on real data, where
//!   the residual is 10–30 times the instrument's noise, it is the data's own scatter that a gain
//!   is judged against.
//! - **One model, one figure** (`refit`): the accepted candidate's model is refitted in full on
//!   the same folds; H0 "the refitted model does not lower a pose's held-out squared error",
//!   one-sided Wilcoxon at `confirm_p`, and its gain must be at least half the linearised one.
//!   Otherwise the acceptance is withdrawn (`refuted`): the shrink table's figures are the
//!   refitted models', and no model worse than the one before it is ever reported as a gain.
//! - **Parsimony**: nested forms of one effect (a single compliance inside the group, a cyclic
//!   term inside the same joint's table) — the simpler one is kept unless the richer predicts
//!   significantly better (paired test at `confirm_p`).
//! - **Look-alikes**: a confirmed candidate of another effect whose unabsorbed columns have a
//!   canonical correlation above `lookalike_corr` with the best's, or whose held-out RMS gain is
//!   at least [`LOOKALIKE_GAIN_SHARE`] of the best's, and beyond which the best's own columns add
//!   nothing significant (the encompassing score test at `confirm_p`; a correlation above
//!   0.999999 is the same columns): the data cannot tell the two apart → `not_separable` with
//!   both names and the experiment that would.
//! - **Absorption**: separability ρ below `rho_min` → `not_separable`: the current model takes
//!   most of the effect; the parameters that absorb it are named.
//! - **Unknown effect and partial explanations**: a flexible joint-space smoother (every joint's
//!   angle corrected by a linear function of every holding torque, every reading and its square)
//!   cross-validated the same way. If it confirms when no candidate does, and lowers the held-out
//!   mean by `min_rel_gain` as a candidate must, the verdict is `unknown_effect`. A confirmed
//!   candidate that is one of the smoother's own forms (given the smoother it adds nothing:
//!   encompassing score test at `confirm_p`) is named only if it closes
//!   at least `name_closure` of the gap to the floor and the smoother does not predict
//!   significantly better; otherwise it is `partial` — its share of what the smoother explains
//!   said, the rest left unexplained — and below `partial_share` the verdict is
//!   `unknown_effect`. A look-alike takes a third of an out-of-library effect; a name needs most.
//! - **Relative size**: a candidate confirmed on held-out poses must also lower the held-out
//!   mean by `min_rel_gain` of itself: the data's own scatter is the scale of a real cause. A
//!   direction-of-motion term below it is confirmed when, held out, it predicts beyond the
//!   smoother and a drift along the run together, in a random measuring order
//!   ([`Evaluated::apart`]).
//!
//! The thresholds' false-alarm rate is measured on simulated no-effect cells by
//! `robocal bench-diagnosis` (BENCHMARKS.md), not assumed.

use faer::Mat;

use super::cv::{CvBase, Folds, Heldout, Paired, cross_validate, paired};
use super::library::{Candidate, Context, Kind, Unavailable, candidates, scan_multiplicity, scan_quarters};
use super::linalg::{at_b, canonical_correlation, hcat, orthonormal_basis};
use super::refit::{refit_disagrees, refit_heldout};
use super::screen::{Basis, Score, score, score_gram, table_penalty};
use super::stage::Stage;
use super::stats::holm_log10;
use crate::cell::Cell;
use crate::identify::{GlobalParam, IdentifyError, IdentifyOptions, map_knots};
use crate::kinematics::{JointTerm, Param};

mod decide;
mod payload;
use decide::{Smoother, decide};
pub use payload::{PayloadTrial, adopt_payload};

/// Share of the best candidate's held-out RMS gain from which a confirmed candidate of another
/// effect is examined as its look-alike, whatever their correlation.
pub const LOOKALIKE_GAIN_SHARE: f64 = 0.8;

/// Thresholds and sizes of the search.
#[derive(Clone, Debug, PartialEq)]
pub struct SearchOptions {
    /// Family-wise error rate of the screening (Holm).
    pub alpha: f64,
    /// Level of the held-out confirmation (one-sided Wilcoxon).
    pub confirm_p: f64,
    /// Smallest held-out RMS gain that counts, m.
    pub min_gain: f64,
    /// Candidates confirmed per round, best by screening first.
    pub top: usize,
    /// Effects accepted at most.
    pub max_effects: usize,
    /// Separability ρ below which the best confirmed candidate is `not_separable` (absorbed by the
    /// current model), unless its held-out RMS gain reaches a quarter of the floor's RMS.
    pub rho_min: f64,
    /// Canonical correlation of the unabsorbed columns above which a confirmed candidate of
    /// another effect is examined as a look-alike of the best (DIAGNOSIS §1); the encompassing
    /// score test then decides.
    pub lookalike_corr: f64,
    /// Knot spacing of tables, degrees (0: about 60 knots over each joint's range).
    pub map_step_deg: u8,
    /// η of the tables' smoothness.
    pub map_smoothing: f64,
    /// Smallest held-out gain a named effect must bring, as a fraction of the current model's
    /// held-out mean: the data's own scatter, not the instrument's. On real data most of the
    /// residual changes from pose to pose and nothing predicts it; a term that takes a sliver of
    /// it (a couple of per cent) is a real correlation — the drift of an unlogged temperature
    /// along a planned sequence, a backlash whose directions were lost — but not a cause to name.
    /// One exception: a direction-of-motion term (backlash), which depends on the path and not on
    /// the pose, is confirmed below this when, held out on the same folds, it still predicts
    /// significantly better than the smoother together with a drift along the run (P1…P3 of the
    /// run position times every joint's angle and the three axes of {W}), in a measuring order
    /// whose consecutive stops are as far apart as any two (the drift test's locality guard):
    /// what is left for it then is neither a smooth function of the configuration nor of the time
    /// ([`Evaluated::apart`]).
    pub min_rel_gain: f64,
    /// Smallest gap closure — (RMS before − RMS after)/(RMS before − the floor's RMS) — that a
    /// candidate inside the smoother's span must reach to be named. Such a term is one of the
    /// smoother's forms, so it can be a look-alike of an out-of-library effect: a coupling 2→3
    /// takes a third of link 2's bending. Below this the verdict is `partial`. Chosen on simulated
    /// in- and out-of-library effects (BENCHMARKS.md, "Partial explanations").
    pub name_closure: f64,
    /// Below this share of what the smoother explains, a candidate is not even a partial
    /// explanation: `unknown_effect`.
    pub partial_share: f64,
    /// Threads for confirming candidates (results do not depend on it).
    pub threads: usize,
}

impl Default for SearchOptions {
    fn default() -> Self {
        Self {
            alpha: 0.05,
            confirm_p: 0.01,
            min_gain: 0.5e-6,
            top: 6,
            max_effects: 5,
            rho_min: 0.05,
            lookalike_corr: 0.9,
            map_step_deg: 0,
            map_smoothing: crate::identify::DEFAULT_MAP_SMOOTHING,
            min_rel_gain: 0.05,
            name_closure: 0.5,
            partial_share: 0.15,
            threads: 1,
        }
    }
}

/// A candidate with its screening statistics.
#[derive(Clone, Debug)]
pub struct Screened {
    /// The candidate, realised (a table's knots laid over the pooled readings).
    pub candidate: Candidate,
    /// Its score test on the round's model.
    pub score: Score,
    /// Holm-corrected log10 p.
    pub log10_p_holm: f64,
    /// Whether the Holm-corrected p is below `alpha` (and the candidate has a testable direction).
    pub significant: bool,
    /// The model parameters that absorb most of the candidate: name and share ‖B_i‖ / Σ‖B‖ of the
    /// coefficients of its columns' regression on the model's (B = J⁺J_k, unit-scaled columns); at
    /// most three, each above 5 %.
    pub absorbed_by: Vec<(String, f64)>,
}

/// A candidate confirmed (or not) on held-out poses.
#[derive(Clone, Debug)]
pub struct Evaluated {
    /// Index into the round's `screened`.
    pub index: usize,
    /// Held-out errors of the model plus the candidate, on the linearised folds.
    pub heldout: Heldout,
    /// Against the model alone on the same folds (H1: the candidate lowers a pose's squared error).
    pub vs_model: Paired,
    /// Share of the held-out variance above the floor it explains.
    pub share: f64,
    /// Whether it confirms: Wilcoxon p below `confirm_p`/m, m the candidates cross-validated this
    /// round (Bonferroni); RMS gain above `min_gain`; mean gain at least `min_rel_gain` of the
    /// model's held-out mean.
    pub confirmed: bool,
    /// Not confirmed for its size alone: significant at the same level, above `min_gain`, but
    /// lowering the held-out mean by less than `min_rel_gain` of it. A real cause too small to
    /// name, which a summary must not call absent.
    pub too_small: bool,
    /// For a direction-of-motion term below `min_rel_gain`: whether it stands apart from the
    /// smoother and a drift along the run, and so is confirmed all the same
    /// ([`SearchOptions::min_rel_gain`]). `None` for every other candidate.
    pub apart: Option<Apart>,
}

/// A direction-of-motion term below `min_rel_gain`, against the smoother and a drift along the
/// run ([`SearchOptions::min_rel_gain`]).
#[derive(Clone, Debug)]
pub enum Apart {
    /// It predicts held-out poses significantly better than both together: confirmed.
    Beyond(Paired),
    /// It does not (the held-out comparison, of both with and without it).
    NotBeyond(Paired),
    /// Not tested: consecutive stops are neighbours (this locality, below the drift test's
    /// [`super::drift::LOCALITY_LIMIT`]).
    NeighbourOrder(f64),
    /// Not tested: the observations have no place in one run.
    NoOrder,
}

impl Apart {
    /// The held-out comparison, when it was made.
    pub fn comparison(&self) -> Option<&Paired> {
        match self {
            Apart::Beyond(p) | Apart::NotBeyond(p) => Some(p),
            _ => None,
        }
    }
}

/// Why a round ended the search, or what it accepted.
#[derive(Clone, Debug, PartialEq)]
pub enum Decision {
    /// This candidate (index into `screened`) is named and added.
    Accept(usize),
    /// Nothing passes screening and confirmation, and the smoother finds no structure.
    Nothing,
    /// The best candidate's evidence cannot be told from the current model or from another
    /// candidate.
    NotSeparable {
        /// The best confirmed candidate (index into `screened`).
        best: usize,
        /// The look-alike it cannot be told from (index into `screened`); `None` when the model
        /// absorbs it, or when it is a payload error with a single payload in the data.
        lookalike: Option<usize>,
        /// The largest canonical correlation between the two candidates' unabsorbed columns;
        /// `None` without a look-alike.
        canonical: Option<f64>,
        /// Why, in a sentence.
        reason: String,
    },
    /// Structure no candidate explains (the smoother predicts it, better than any name).
    Unknown {
        /// The best confirmed candidate, when it lies in the smoother's span, is not named, and
        /// explains less than `partial_share` of what the smoother does; `None` when no candidate
        /// confirmed.
        best: Option<usize>,
    },
    /// The best candidate, one of the smoother's own forms, explains only `share` of what the
    /// smoother explains beyond the model: a partial explanation, the rest unexplained. It is
    /// not added to the model.
    Partial {
        /// The candidate (index into `screened`).
        best: usize,
        /// Its held-out gain in mean squared |e| over the largest of its own, the smoother's and
        /// that of the model with both, in [0, 1].
        share: f64,
        /// Held-out RMS gain of the smoother over the model, or of the candidate and the smoother
        /// together when larger, m.
        smoother_gain_rms: f64,
        /// The candidate's gap closure when the smoother does not predict significantly better
        /// than it: the candidate is partial for closing too little of the gap to the floor
        /// alone — the rest is not a smooth function of the configuration. `None`: the smoother
        /// predicts better (structure beyond the candidate).
        closure_only: Option<f64>,
    },
    /// The best candidate was confirmed on the linearised folds, but the model refitted in full
    /// on the same folds does not reproduce the gain: it is not named, and the model stays as it
    /// was (one model, one figure).
    Refuted {
        /// The candidate (index into `screened`).
        best: usize,
        /// Its confirmation on the linearised folds, against the model.
        linear: Paired,
        /// The model with it refitted in full on the folds, against the model before it refitted
        /// the same way; `None` when a fit or a refit failed.
        refit: Option<Paired>,
        /// Why the acceptance is withdrawn.
        reason: String,
    },
}

/// One round of the search.
#[derive(Clone, Debug)]
pub struct Round {
    /// Every candidate screened: the library's, then the frequency scan's.
    pub screened: Vec<Screened>,
    /// The significant candidates cross-validated on held-out poses, confirmed or not, highest BIC
    /// gain first (at most `top`).
    pub evaluated: Vec<Evaluated>,
    /// The smoother against the model on the same folds (H1: the smoother is better).
    pub smoother: Paired,
    /// The smoother's held-out errors (the model plus its ridge-penalised columns).
    pub smoother_heldout: Heldout,
    /// The smoother against the best confirmed candidate (H1: the smoother is better).
    pub smoother_vs_best: Option<Paired>,
    /// The best confirmed candidate's share of what a smooth function of the configuration
    /// explains beyond the model, and whether it lies inside the smoother's span.
    pub share: Option<(f64, bool)>,
    /// The best confirmed candidate's gap closure on the RMS, (RMS before − RMS with it)/(RMS
    /// before − the floor's RMS): what `name_closure` is compared with.
    pub closure: Option<f64>,
    /// The accepted candidate's model refitted in full on the folds, against the model before
    /// it refitted the same way.
    pub refit: Option<Paired>,
    /// What the round decided.
    pub decision: Decision,
}

/// The whole search.
pub struct Search {
    /// Stage 0 (the starting model) and one per accepted effect.
    pub stages: Vec<Stage>,
    /// Held-out errors of each stage's model (linearised folds).
    pub baselines: Vec<Heldout>,
    /// Held-out errors of each stage's model refitted in full on the same folds: the figures of
    /// the models that are reported ([`super::refit`]).
    pub refits: Vec<Result<Heldout, String>>,
    /// The rounds, in order: every round but the last accepted an effect (the last too when
    /// `max_effects` was reached).
    pub rounds: Vec<Round>,
    /// The accepted candidates, in acceptance order: stage k + 1 adds the k-th (0-based).
    pub accepted: Vec<Candidate>,
    /// Library candidates these data cannot test (from the first round).
    pub unavailable: Vec<Unavailable>,
    /// The smallest relative held-out gain a name needs ([`SearchOptions::min_rel_gain`]).
    pub min_rel_gain: f64,
    /// A payload the set held, tried after the named terms ([`adopt_payload`]); when adopted, the
    /// last stage (and baseline and refit) is the model with it, one more than `accepted` has.
    pub payload: Option<PayloadTrial>,
}

/// Run the search from `start` (the current model on the pooled data).
/// `floor_ms` is the floor's mean squared error at the tested positions (m²).
pub fn search(
    cell: &Cell,
    start: Stage,
    folds: &Folds,
    floor_ms: f64,
    opts: &SearchOptions,
) -> Result<Search, IdentifyError> {
    let mut stages = vec![start];
    let mut baselines = vec![cross_validate(&stages[0], folds, None)];
    let mut refits = vec![refit_heldout(cell, &stages[0], folds, opts.threads)];
    let mut rounds: Vec<Round> = Vec::new();
    let mut accepted = Vec::new();
    let mut unavailable = Vec::new();
    loop {
        let stage = stages.last().expect("a stage");
        let base = baselines.last().expect("a baseline");
        let (mut round, missing, chosen) = run_round(cell, stage, base, folds, floor_ms, opts);
        if rounds.is_empty() {
            unavailable = missing;
        }
        let Decision::Accept(best) = round.decision else {
            rounds.push(round);
            break;
        };
        let (cand, cols) = chosen.expect("an accepted candidate");
        let linear = round.evaluated.iter().find(|e| e.index == best).expect("evaluated").vs_model.clone();
        let next_opts = extend_options(&stage.options, stage, &cand);
        // One model, one figure: the accepted model is refitted in full on the same folds, and
        // must reproduce the gain its linearised confirmation found ([`refit_disagrees`]).
        let next = stage.extend(cell, next_opts, &cand.params, &cand.frees, &cols, opts.map_smoothing);
        let checked = match (&next, refits.last().expect("a refit")) {
            (Err(e), _) => Err((None, format!("the model with it cannot be fitted: {e}"))),
            (_, Err(e)) => Err((None, format!("the model before it cannot be refitted on the folds: {e}"))),
            (Ok(next), Ok(before)) => match refit_heldout(cell, next, folds, opts.threads) {
                Err(e) => Err((None, format!("the model with it cannot be refitted on the folds: {e}"))),
                Ok(after) => {
                    let r = paired(before, &after);
                    match refit_disagrees(&linear, &r, opts) {
                        None => Ok((r, after)),
                        Some(reason) => Err((Some(r), reason)),
                    }
                }
            },
        };
        match checked {
            Ok((r, after)) => {
                let next = next.expect("checked");
                round.refit = Some(r);
                rounds.push(round);
                baselines.push(cross_validate(&next, folds, None));
                refits.push(Ok(after));
                stages.push(next);
                accepted.push(cand);
                if accepted.len() >= opts.max_effects {
                    break;
                }
            }
            Err((refit, reason)) => {
                round.refit = refit.clone();
                round.decision = Decision::Refuted { best, linear, refit, reason };
                rounds.push(round);
                break;
            }
        }
    }
    Ok(Search {
        stages,
        baselines,
        refits,
        rounds,
        accepted,
        unavailable,
        min_rel_gain: opts.min_rel_gain,
        payload: None,
    })
}

/// `f` over `items` on up to `threads` scoped threads; results in item order.
pub(crate) fn par_map<T: Sync, R: Send>(items: &[T], threads: usize, f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    use std::sync::Mutex;
    use std::sync::atomic::{AtomicUsize, Ordering};
    if threads <= 1 || items.len() <= 1 {
        return items.iter().map(f).collect();
    }
    let next = AtomicUsize::new(0);
    let out: Mutex<Vec<Option<R>>> = Mutex::new((0..items.len()).map(|_| None).collect());
    std::thread::scope(|scope| {
        for _ in 0..threads.min(items.len()) {
            scope.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(item) = items.get(k) else { break };
                    let r = f(item);
                    out.lock().expect("no panic while holding the lock")[k] = Some(r);
                }
            });
        }
    });
    out.into_inner().expect("joined").into_iter().map(|r| r.expect("every item ran")).collect()
}

/// Distinct payloads (mass and centre of mass) among the tools of the pooled data.
fn payloads(stage: &Stage) -> usize {
    let mut seen: Vec<(f64, [f64; 3])> = Vec::new();
    for t in &stage.problem.tools {
        let key = (t.tool.mass, [t.tool.com.x, t.tool.com.y, t.tool.com.z]);
        if !seen.contains(&key) {
            seen.push(key);
        }
    }
    seen.len()
}

/// Mean squared |e| over the tested observations, m².
fn rms2(h: &Heldout) -> f64 {
    h.errors.iter().map(|(_, e)| e.norm_squared()).sum::<f64>() / h.errors.len().max(1) as f64
}

/// The model options with a candidate added.
pub(crate) fn extend_options(options: &IdentifyOptions, stage: &Stage, cand: &Candidate) -> IdentifyOptions {
    let mut o = options.clone();
    for p in &cand.params {
        if !o.model.extra.contains(p) {
            o.model.extra.push(*p);
        }
    }
    let pr = &stage.problem;
    for &g in &cand.frees {
        let name = pr.name(g);
        o.fixed.retain(|f| *f != name);
        if let GlobalParam::Tool { tool, .. } = pr.params[g] {
            for s in &pr.tools[tool].sessions {
                if !o.free_tcp.contains(s) {
                    o.free_tcp.push(s.clone());
                }
            }
        }
    }
    // Start from the current solution: the refit only adds the effect.
    let mut start = stage.set.clone();
    for p in &cand.params {
        start.extend(&[*p]);
    }
    o.start = Some(start);
    o
}

/// A candidate's columns at the stage (weighted) and its penalty, its parameters realised
/// (a table's knots laid over the pooled readings).
fn realise(stage: &Stage, cand: &mut Candidate, opts: &SearchOptions) -> (Mat<f64>, Option<Mat<f64>>) {
    let pr = &stage.problem;
    if cand.kind == Kind::JointMap && cand.params.is_empty() {
        let j = cand.joint.expect("a table has a joint");
        cand.params = map_knots(j, cand.step_deg.expect("a step"), pr.obs.iter().map(|o| o.state.q[j]));
    }
    if !cand.frees.is_empty() {
        return (stage.global_columns(&cand.frees), None);
    }
    let c = stage.columns(&cand.params);
    let penalty = (cand.kind == Kind::JointMap).then(|| table_penalty(c.as_ref(), opts.map_smoothing));
    (c, penalty)
}

/// The library's context for a stage.
fn context<'a>(cell: &Cell, stage: &'a Stage, free: &'a [bool], opts: &SearchOptions, approach: bool) -> Context<'a> {
    let pr = &stage.problem;
    let dof = pr.model.dof();
    let range = |f: &dyn Fn(&crate::identify::problem::Obs) -> f64| -> f64 {
        let (lo, hi) = pr.obs.iter().map(f).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
        if lo.is_finite() { hi - lo } else { 0.0 }
    };
    let torque_range = (0..dof).map(|j| range(&|o| o.state.tau[j])).collect();
    let joint_range = (0..dof).map(|j| range(&|o| o.state.q[j])).collect();
    let temps: Vec<Option<f64>> =
        pr.obs.iter().map(|o| cell.sessions[o.session].measurements[o.index].temperature_c).collect();
    let temperature_range = if temps.iter().all(|t| t.is_some()) {
        let v: Vec<f64> = temps.iter().map(|t| t.expect("all logged")).collect();
        Some(v.iter().copied().fold(f64::NEG_INFINITY, f64::max) - v.iter().copied().fold(f64::INFINITY, f64::min))
    } else {
        None
    };
    let fixed_base: Vec<usize> = (0..pr.n_params())
        .filter(|&g| matches!(pr.params[g], GlobalParam::Robot(i) if matches!(pr.layout.params()[i], Param::Base(_))))
        .filter(|&g| !stage.is_free(g))
        .collect();
    let fixed_tools: Vec<Vec<usize>> = (0..pr.tools.len())
        .map(|t| {
            let k_max = if pr.tools[t].has_orientation { 6 } else { 3 };
            (0..pr.n_params())
                .filter(|&g| matches!(pr.params[g], GlobalParam::Tool { tool, k } if tool == t && k < k_max))
                .filter(|&g| !stage.is_free(g))
                .collect()
        })
        .collect();
    Context {
        dof,
        layout: pr.layout.params(),
        free,
        parallel_rows: pr.layout.parallel_rows(),
        torque_range,
        joint_range,
        approach_available: approach,
        temperature_range,
        fixed_base,
        fixed_tools,
        map_step_deg: opts.map_step_deg,
    }
}

/// The smoother's columns: every joint's angle corrected by a linear function of every holding
/// torque, every reading and every reading squared (weighted, n_rows × 3n²). Not a name: a
/// generic stand-in for "a smooth function of the configuration".
pub(crate) fn smoother_columns(stage: &Stage, g: &Mat<f64>) -> Mat<f64> {
    let pr = &stage.problem;
    let n = pr.model.dof();
    let mut out = Mat::<f64>::zeros(stage.n_rows(), 3 * n * n);
    for o in &pr.obs {
        let s = &o.state;
        let feats: Vec<f64> =
            (0..n).map(|j| s.tau[j]).chain((0..n).map(|j| s.q[j])).chain((0..n).map(|j| s.q[j] * s.q[j])).collect();
        for k in 0..n {
            for (f, v) in feats.iter().enumerate() {
                let c = k * 3 * n + f;
                for r in o.row..o.row + o.rows {
                    out[(r, c)] = g[(r, k)] * v;
                }
            }
        }
    }
    out
}

/// A direction-of-motion term that confirms on held-out poses but lowers the held-out mean by
/// less than `min_rel_gain` is confirmed after all when it predicts better than the smoother and a
/// drift along the run together, held out on the same folds (Wilcoxon over poses at `level`).
///
/// Why a backlash alone: its regressor is the sign of each joint's last move, a property of the
/// path. In random order that sign leans with the pose (a stop high in a joint's range was more
/// likely reached moving up), so a smooth error of the configuration lends it a sliver of gain —
/// the look-alike the relative size guards against; and along a planned sweep it follows the
/// time, so a drift lends it one too. Beyond both, what it predicts is its own. Twins without
/// hysteresis but with out-of-library deflections, sweeps and warm-ups (BENCHMARKS.md, "Weak
/// hysteresis named") measure the rate at which this names a backlash that is not there.
#[allow(clippy::too_many_arguments)]
fn apart_direction_terms(
    cell: &Cell,
    stage: &Stage,
    cvb: &CvBase<'_>,
    g: &Mat<f64>,
    (sm, sm_pen): (&Mat<f64>, &Mat<f64>),
    screened: &[Screened],
    columns: &[(Mat<f64>, Option<Mat<f64>>)],
    evaluated: &mut [Evaluated],
    level: f64,
) {
    let small: Vec<usize> = (0..evaluated.len())
        .filter(|&k| evaluated[k].too_small && screened[evaluated[k].index].candidate.kind == Kind::Backlash)
        .collect();
    if small.is_empty() {
        return;
    }
    // Where consecutive stops are neighbours (a sweep, a grid), the sign of each move follows the
    // neighbourhood and the errors of neighbouring poses are alike: a direction term takes a
    // sliver of that pose-to-pose structure, which neither the smoother nor a drift spans. So
    // the exception holds only in an order whose consecutive stops are as far apart as any two
    // (the drift test's own locality guard); without a known order, not at all.
    let mark = |evaluated: &mut [Evaluated], a: Apart| small.iter().for_each(|&k| evaluated[k].apart = Some(a.clone()));
    let Some((d, locality)) = drift_columns(cell, stage, g) else {
        return mark(evaluated, Apart::NoOrder);
    };
    if locality < super::drift::LOCALITY_LIMIT {
        return mark(evaluated, Apart::NeighbourOrder(locality));
    }
    let d_pen = ridge(&d, 1e-6);
    let (alt, alt_pen) = (hcat(sm, &d), block_diag(Some(sm_pen), sm.ncols(), Some(&d_pen), d.ncols()));
    let alt_heldout = cvb.heldout(Some((&alt, Some(&alt_pen))));
    for k in small {
        let e = &mut evaluated[k];
        let (c, c_pen) = &columns[e.index];
        let joint = hcat(c, &alt);
        let pen = block_diag(c_pen.as_ref(), c.ncols(), Some(&alt_pen), alt.ncols());
        let beyond = paired(&alt_heldout, &cvb.heldout(Some((&joint, Some(&pen)))));
        if beyond.p.is_some_and(|p| p < level) && beyond.gain_mean > 0.0 {
            e.confirmed = true;
            e.too_small = false;
            e.apart = Some(Apart::Beyond(beyond));
        } else {
            e.apart = Some(Apart::NotBeyond(beyond));
        }
    }
}

/// Columns of a drift along the run: each position row's axis of {W} and each joint's angle
/// (`g`), times the Legendre polynomials P1…P3 of the observation's place in the run scaled to
/// [−1, 1] ([`super::run_positions`]), with the order's locality ([`super::drift::locality`]);
/// `None` when the observations have no place in one run.
fn drift_columns(cell: &Cell, stage: &Stage, g: &Mat<f64>) -> Option<(Mat<f64>, f64)> {
    let pr = &stage.problem;
    let obs: Vec<usize> = (0..pr.obs.len()).collect();
    let (_, at) = super::run_positions(pr, cell, &obs)?;
    let u = super::drift::unit_scale(at.iter().copied())?;
    let dof = pr.model.dof();
    let zero = nalgebra::Vector3::zeros();
    let stops = super::drift::stops(
        pr.obs.iter().zip(&at).map(|(o, &t)| (t, o.state.q[..dof].to_vec(), zero, zero, Vec::new())).collect(),
    );
    if stops.len() < 2 {
        return None;
    }
    let locality = super::drift::locality(&stops);
    let per = 3 + dof;
    let degree = super::drift::legendre(0.0).len();
    let mut out = Mat::<f64>::zeros(stage.n_rows(), degree * per);
    for (o, t) in pr.obs.iter().zip(&at) {
        let p = super::drift::legendre(u(*t));
        for (k, pk) in p.iter().enumerate() {
            for a in 0..o.rows.min(3) {
                out[(o.row + a, k * per + a)] = o.weight[a] * pk;
            }
            for j in 0..dof {
                for r in o.row..o.row + o.rows {
                    out[(r, k * per + 3 + j)] = g[(r, j)] * pk;
                }
            }
        }
    }
    Some((out, locality))
}

/// The block-diagonal penalty of columns concatenated by [`hcat`]: `a` (of `na` columns; zero
/// when `None`) then `b` (of `nb`).
pub(crate) fn block_diag(a: Option<&Mat<f64>>, na: usize, b: Option<&Mat<f64>>, nb: usize) -> Mat<f64> {
    Mat::<f64>::from_fn(na + nb, na + nb, |i, k| match (i < na, k < na) {
        (true, true) => a.map_or(0.0, |p| p[(i, k)]),
        (false, false) => b.map_or(0.0, |p| p[(i - na, k - na)]),
        _ => 0.0,
    })
}

/// A small ridge for the smoother (its columns overlap the model's and each other's).
fn ridge(c: &Mat<f64>, rel: f64) -> Mat<f64> {
    let m = c.ncols();
    Mat::<f64>::from_fn(
        m,
        m,
        |i, k| if i == k { rel * (0..c.nrows()).map(|r| c[(r, i)].powi(2)).sum::<f64>() } else { 0.0 },
    )
}

/// The accepted candidate and its columns at the round's stage.
type Chosen = (Candidate, Mat<f64>);

pub(crate) fn timing(what: &str, t: std::time::Instant) {
    if std::env::var_os("ROBOCAL_TIMING").is_some() {
        eprintln!("{what}: {:.3} s", t.elapsed().as_secs_f64());
    }
}

/// Screening of one round: every library candidate realised and scored, the frequency scan of each
/// joint, Holm over the family, and what the current model absorbs of each significant one.
#[allow(clippy::type_complexity)]
fn screen(
    stage: &Stage,
    basis: &Basis<'_>,
    g: &Mat<f64>,
    mut cands: Vec<Candidate>,
    opts: &SearchOptions,
) -> (Vec<Screened>, Vec<(Mat<f64>, Option<Mat<f64>>)>) {
    let pr = &stage.problem;
    let t0 = std::time::Instant::now();
    // The library.
    let mut screened: Vec<Screened> = Vec::new();
    let mut columns: Vec<(Mat<f64>, Option<Mat<f64>>)> = Vec::new();
    for mut c in cands.drain(..) {
        let (cols, pen) = realise(stage, &mut c, opts);
        let sc = score(basis, cols.as_ref(), pen.as_ref());
        screened.push(Screened {
            candidate: c,
            score: sc,
            log10_p_holm: 0.0,
            significant: false,
            absorbed_by: Vec::new(),
        });
        columns.push((cols, pen));
    }
    timing("screen library", t0);
    let t0 = std::time::Instant::now();
    // The frequency scan, one test per joint.
    for j in 0..pr.model.dof() {
        if let Some((c, cols)) = scan_joint(stage, basis, g, j, &screened) {
            screened.push(c);
            columns.push((cols, None));
        }
    }
    timing("scan", t0);
    let t0 = std::time::Instant::now();
    // Holm over the family.
    let lp: Vec<f64> = screened.iter().map(|s| s.score.log10_p).collect();
    for (s, h) in screened.iter_mut().zip(holm_log10(&lp)) {
        s.log10_p_holm = h;
        s.significant = h < opts.alpha.log10() && s.score.dof > 0.0;
    }
    let absorber = Absorber::new(stage);
    for (s, (cols, _)) in screened.iter_mut().zip(&columns) {
        if s.significant {
            s.absorbed_by = absorber.absorbed_by(cols);
        }
    }
    timing("holm + absorbed", t0);
    (screened, columns)
}

fn run_round(
    cell: &Cell,
    stage: &Stage,
    base: &Heldout,
    folds: &Folds,
    floor_ms: f64,
    opts: &SearchOptions,
) -> (Round, Vec<Unavailable>, Option<Chosen>) {
    let pr = &stage.problem;
    let approach = pr.obs.iter().any(|o| o.state.approach.iter().any(|&a| a != 0.0));
    let free = stage.free_layout();
    let ctx = context(cell, stage, &free, opts, approach);
    let (cands, missing) = candidates(&ctx);
    let rp = Basis::project(stage.q.as_ref(), &stage.r);
    let basis = Basis { q: stage.q.as_ref(), r: &rp, rss: stage.rss, n: stage.n_obs_rows(), p: stage.p() };

    let g = stage.joint_columns();
    let (screened, columns) = screen(stage, &basis, &g, cands, opts);
    let t0 = std::time::Instant::now();
    // Confirmation of the best few by screening.
    let mut order: Vec<usize> = (0..screened.len()).filter(|&i| screened[i].significant).collect();
    order.sort_by(|&a, &b| screened[b].score.bic_gain.total_cmp(&screened[a].score.bic_gain));
    order.truncate(opts.top);
    // Bonferroni over the candidates confirmed this round; the share of the excess variance.
    let level = opts.confirm_p / order.len().max(1) as f64;
    let excess = (rms2(base) - floor_ms).max(f64::MIN_POSITIVE);
    let base_mean = base.errors.iter().map(|(_, e)| e.norm()).sum::<f64>() / base.errors.len().max(1) as f64;
    let cvb = CvBase::new(stage, folds);
    let heldouts = par_map(&order, opts.threads, |&i| {
        let (cols, pen) = &columns[i];
        cvb.heldout(Some((cols, pen.as_ref())))
    });
    let mut evaluated: Vec<Evaluated> = order
        .iter()
        .zip(heldouts)
        .map(|(&i, heldout)| {
            let vs_model = paired(base, &heldout);
            let share = (rms2(base) - rms2(&heldout)) / excess;
            let significant = vs_model.p.is_some_and(|p| p < level) && vs_model.gain_rms > opts.min_gain;
            let large = vs_model.gain_mean >= opts.min_rel_gain * base_mean;
            let confirmed = significant && large;
            let too_small = significant && !large && vs_model.gain_mean > 0.0;
            Evaluated { index: i, heldout, vs_model, share, confirmed, too_small, apart: None }
        })
        .collect();

    timing("confirm", t0);
    let t0 = std::time::Instant::now();
    // The smoother.
    let sm = smoother_columns(stage, &g);
    let sm_pen = ridge(&sm, 1e-6);
    let smoother_heldout = cvb.heldout(Some((&sm, Some(&sm_pen))));
    let smoother = paired(base, &smoother_heldout);
    let smoother_ok = smoother.p.is_some_and(|p| p < opts.confirm_p) && smoother.gain_rms > opts.min_gain;
    // An effect outside the library is held to the size a candidate must reach: a smooth
    // structure that lowers the held-out mean by less than `min_rel_gain` is no more a cause to
    // call unknown than a candidate of that size is one to name (and a candidate too small to
    // name may predict more of it than the smoother does).
    let smoother_large = smoother.gain_mean >= opts.min_rel_gain * base_mean;
    apart_direction_terms(cell, stage, &cvb, &g, (&sm, &sm_pen), &screened, &columns, &mut evaluated, level);

    timing("smoother", t0);
    let t0 = std::time::Instant::now();
    // Decide.
    let confirmed: Vec<&Evaluated> = evaluated.iter().filter(|e| e.confirmed).collect();
    let (decision, smoother_vs_best, share_of_best, closure_of_best) = if confirmed.is_empty() {
        let unknown = smoother_ok && smoother_large;
        (if unknown { Decision::Unknown { best: None } } else { Decision::Nothing }, None, None, None)
    } else {
        let sm = Smoother { cols: &sm, pen: &sm_pen, heldout: &smoother_heldout, vs_model: &smoother, ok: smoother_ok };
        let d = decide(stage, base, floor_ms, &cvb, &confirmed, &screened, &columns, &sm, opts);
        (d.decision, Some(d.smoother_vs_best), Some(d.share), Some(d.closure))
    };
    timing("decide", t0);
    let chosen = match decision {
        Decision::Accept(i) => Some((screened[i].candidate.clone(), columns[i].0.clone())),
        _ => None,
    };
    (
        Round {
            screened,
            evaluated,
            smoother,
            smoother_heldout,
            smoother_vs_best,
            share: share_of_best,
            closure: closure_of_best,
            refit: None,
            decision,
        },
        missing,
        chosen,
    )
}

/// The scan of joint j: the best quarter-cycle frequency by F, its p-value times the effective
/// number of frequencies. Skipped when the best is a prespecified harmonic (1 or 2: already a
/// candidate) or the joint does not move.
fn scan_joint(
    stage: &Stage,
    basis: &Basis<'_>,
    g: &Mat<f64>,
    j: usize,
    screened: &[Screened],
) -> Option<(Screened, Mat<f64>)> {
    let pr = &stage.problem;
    let (lo, hi) =
        pr.obs.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), o| (a.min(o.state.q[j]), b.max(o.state.q[j])));
    let range = hi - lo;
    if range.is_nan() || range <= 1e-3 {
        return None;
    }
    let free = stage.free_layout();
    let in_model = |q: u16| {
        let t = JointTerm::cyclic(q, false).expect("non-zero");
        pr.layout.params().iter().zip(&free).any(|(p, f)| *f && *p == Param::Joint(j, t))
    };
    // Every frequency at once, exactly: a column of the scan is joint j's column times
    // sin(f·q_j) or cos(f·q_j), constant over an observation's rows, so its Gram entries, its
    // product with r̃ and its projection Qᵀc are sums over observations of per-observation
    // aggregates (Σ g², Σ g·r̃, Σ g·Q). One product (2F × n_obs)·(n_obs × p) projects all of them.
    let nq = scan_quarters().count();
    let n_obs = pr.obs.len();
    let pq = stage.q.ncols();
    let mut gg = vec![0.0; n_obs];
    let mut gr = vec![0.0; n_obs];
    let mut u = Mat::<f64>::zeros(n_obs, pq);
    for (i, o) in pr.obs.iter().enumerate() {
        for r in o.row..o.row + o.rows {
            let gv = g[(r, j)];
            gg[i] += gv * gv;
            gr[i] += gv * basis.r[r];
            for k in 0..pq {
                u[(i, k)] += gv * stage.q[(r, k)];
            }
        }
    }
    // sin and cos of (k/4)·q for k = 1 … by the rotation recurrence (rounding ~1e-14 after 160
    // steps), instead of 320 trigonometric calls per observation.
    let mut t = Mat::<f64>::zeros(n_obs, 2 * nq);
    for (i, o) in pr.obs.iter().enumerate() {
        let (s1, c1) = (o.state.q[j] / 4.0).sin_cos();
        let (mut s, mut c) = (0.0f64, 1.0f64);
        for k in 0..nq {
            (s, c) = (s * c1 + c * s1, c * c1 - s * s1);
            t[(i, 2 * k)] = s;
            t[(i, 2 * k + 1)] = c;
        }
    }
    let a = at_b(t.as_ref(), u.as_ref());
    let mut best: Option<(u16, Score)> = None;
    for (k, q) in scan_quarters().enumerate() {
        if in_model(q) {
            continue;
        }
        let mut g0 = Mat::<f64>::zeros(2, 2);
        let mut b = [0.0; 2];
        for i in 0..n_obs {
            let (s, c) = (t[(i, 2 * k)], t[(i, 2 * k + 1)]);
            g0[(0, 0)] += gg[i] * s * s;
            g0[(0, 1)] += gg[i] * s * c;
            g0[(1, 1)] += gg[i] * c * c;
            b[0] += gr[i] * s;
            b[1] += gr[i] * c;
        }
        g0[(1, 0)] = g0[(0, 1)];
        let proj = |x: usize, y: usize| (0..pq).map(|l| a[(2 * k + x, l)] * a[(2 * k + y, l)]).sum::<f64>();
        let gm = Mat::<f64>::from_fn(2, 2, |x, y| g0[(x, y)] - proj(x, y));
        let sc = score_gram(basis, &g0, &gm, &b, None);
        if best.as_ref().is_none_or(|(_, bs)| sc.f > bs.f) {
            best = Some((q, sc));
        }
    }
    let (q, mut sc) = best?;
    let f = q as f64 / 4.0;
    let mut cols = Mat::<f64>::zeros(stage.n_rows(), 2);
    for o in &pr.obs {
        let (s, c) = (f * o.state.q[j]).sin_cos();
        for r in o.row..o.row + o.rows {
            cols[(r, 0)] = g[(r, j)] * s;
            cols[(r, 1)] = g[(r, j)] * c;
        }
    }
    if q == 4 || q == 8 {
        return None;
    }
    if screened
        .iter()
        .any(|s| s.candidate.kind == Kind::Cyclic && s.candidate.joint == Some(j) && s.candidate.quarters == Some(q))
    {
        return None;
    }
    sc.log10_p = (sc.log10_p + scan_multiplicity(range).log10()).min(0.0);
    let t = |cos| Param::Joint(j, JointTerm::cyclic(q, cos).expect("non-zero"));
    let candidate = Candidate {
        kind: Kind::Cyclic,
        joint: Some(j),
        from: None,
        quarters: Some(q),
        scanned: true,
        step_deg: None,
        params: vec![t(false), t(true)],
        frees: Vec::new(),
    };
    Some((Screened { candidate, score: sc, log10_p_holm: 0.0, significant: false, absorbed_by: Vec::new() }, cols))
}

struct Absorber<'a> {
    stage: &'a Stage,
    js: Mat<f64>,
    /// (JsᵀJs)⁺ = V·diag(1/λ)·Vᵀ, formed once per round.
    pinv: Mat<f64>,
}

impl<'a> Absorber<'a> {
    fn new(stage: &'a Stage) -> Self {
        let j = &stage.j;
        let p = j.ncols();
        let norms: Vec<f64> = (0..p).map(|c| (0..j.nrows()).map(|r| j[(r, c)].powi(2)).sum::<f64>().sqrt()).collect();
        let js = Mat::<f64>::from_fn(j.nrows(), p, |r, c| j[(r, c)] / norms[c].max(f64::MIN_POSITIVE));
        let g = at_b(js.as_ref(), js.as_ref());
        let (vals, vecs) = super::linalg::psd_eigen(&g, 1e-13);
        let pinv =
            Mat::<f64>::from_fn(p, p, |a, b| (0..vals.len()).map(|k| vecs[(a, k)] * vecs[(b, k)] / vals[k]).sum());
        Absorber { stage, js, pinv }
    }

    /// The model parameters that absorb most of a candidate: the coefficients of its columns'
    /// regression on the model's (B = J⁺J_k, on unit-scaled columns), each parameter's share
    /// ‖B_i‖ of the total.
    fn absorbed_by(&self, cols: &Mat<f64>) -> Vec<(String, f64)> {
        let rhs = at_b(self.js.as_ref(), cols.as_ref());
        let b = super::linalg::a_b(self.pinv.as_ref(), rhs.as_ref());
        let p = b.nrows();
        let mut share: Vec<(usize, f64)> =
            (0..p).map(|i| (i, (0..b.ncols()).map(|k| b[(i, k)] * b[(i, k)]).sum::<f64>().sqrt())).collect();
        let total: f64 = share.iter().map(|s| s.1).sum();
        share.sort_by(|a, b| b.1.total_cmp(&a.1));
        share
            .into_iter()
            .take(3)
            .filter(|s| total > 0.0 && s.1 / total > 0.05)
            .map(|(i, v)| (self.stage.problem.name(self.stage.free[i]), v / total))
            .collect()
    }
}
