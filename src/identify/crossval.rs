//! Held-out evaluation of a calibration on one session of real data: what a metrologist asks of
//! a calibration before trusting it on a robot whose true parameters nobody knows.
//!
//! - **k-fold cross-validation**: the session's measurements are shuffled (seeded) into k folds;
//!   each fold is predicted by a model identified on the other k − 1; the pooled held-out errors
//!   (every measurement predicted exactly once) give mean, median, p95 and max.
//! - **Few poses**: for each size n and each draw, the session is split at random into two halves;
//!   n poses drawn from the first half identify the model, the whole second half (disjoint) tests
//!   it. How many poses a calibration of this robot needs.
//! - **Transfer**: the model identified on the whole session is carried to other sessions (other
//!   days, another tracker set-up) where only the base and the tools are refitted — the
//!   re-registration a cell does after the instrument moved — and scored there. A model that
//!   only absorbed the first session's quirks degrades; a physically right one transfers.
//!
//! Every scheme is run for each model variant and for the "before" reference: the nominal model
//! with only the base and the tools fitted (a cell without a base guess has no other honest
//! "uncalibrated" figure). Identification and test sets never share a measurement, and each
//! identification sees only its own measurements — also for the base registration that starts
//! it. Jobs are independent and run on scoped threads; every seed depends only on the job, so the
//! result does not depend on the thread count.

use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

use super::{IdentifyError, IdentifyOptions, identify};
use crate::cell::{Cell, Session};
use crate::validate::report::{Reference, validate};
use crate::validate::stats::ErrorStats;

/// A model to evaluate: a name for the reports and its identification options.
#[derive(Clone, Debug)]
pub struct Variant {
    pub name: String,
    pub options: IdentifyOptions,
}

impl Variant {
    /// The "before calibration" reference: the nominal robot, base and tools fitted only. It is
    /// never refused for its residual: that the nominal model misses is what it measures.
    pub fn before(options: &IdentifyOptions) -> Variant {
        let options = IdentifyOptions { only: before_scope(), residual_ratio_limit: f64::INFINITY, ..options.clone() };
        Variant { name: "before".into(), options }
    }
}

fn before_scope() -> Vec<String> {
    vec!["base".into(), "tool".into()]
}

/// What to run.
#[derive(Clone, Debug)]
pub struct CrossvalOptions {
    /// The session whose measurements are split.
    pub session: String,
    /// Folds of the cross-validation (0: skip it; otherwise ≥ 2).
    pub folds: usize,
    /// Identification sizes of the few-poses scheme (empty: skip it).
    pub sizes: Vec<usize>,
    /// Draws per size.
    pub draws: usize,
    /// Sessions the whole-session model is transferred to.
    pub transfer: Vec<String>,
    /// κ limit of the transfer refits (default: each variant's own). The refitted base and tools
    /// are nuisance parameters there: only the errors they leave are reported, so a weaker
    /// conditioning can be accepted knowingly — the κ of each refit is reported beside it.
    pub transfer_kappa_limit: Option<f64>,
    /// Base or tool parameters kept at the whole-session model's values in the transfer refit
    /// (e.g. `tool_z` when the transfer session's orientations barely vary, so that the probe's
    /// offset along the flange axis and the base translation cannot be told apart there).
    pub transfer_fixed: Vec<String>,
    /// The models, evaluated in this order after the "before" reference.
    pub variants: Vec<Variant>,
    /// Options of the "before" reference (rotation weight, solver; `only` is set to base + tools).
    pub before: IdentifyOptions,
    pub seed: u64,
    pub threads: usize,
}

/// Errors of a model on a test set.
#[derive(Clone, Debug, PartialEq)]
pub struct HeldOut {
    /// |position error|, m.
    pub position: ErrorStats,
    /// Orientation error, rad, when the test set observed full poses.
    pub orientation: Option<ErrorStats>,
}

impl HeldOut {
    fn of(position: &[f64], orientation: &[f64]) -> Option<HeldOut> {
        Some(HeldOut { position: ErrorStats::of(position)?, orientation: ErrorStats::of(orientation) })
    }
}

/// k-fold cross-validation of one variant.
#[derive(Clone, Debug, PartialEq)]
pub struct FoldsResult {
    pub variant: String,
    /// The pooled held-out errors (each measurement predicted by the fold that did not see it);
    /// `None` when a fold failed.
    pub pooled: Option<HeldOut>,
    pub per_fold: Vec<Result<HeldOut, String>>,
    /// Parameters identified in the first fold (the others agree unless the data are marginal).
    pub identified: usize,
}

/// One identification size of the few-poses scheme, one variant.
#[derive(Clone, Debug, PartialEq)]
pub struct SizeResult {
    pub variant: String,
    pub n: usize,
    /// Per draw: the errors on the disjoint test half, or why the fit was refused.
    pub draws: Vec<Result<HeldOut, String>>,
}

impl SizeResult {
    /// Mean over the successful draws of a statistic.
    pub fn mean(&self, f: impl Fn(&HeldOut) -> f64) -> Option<f64> {
        let v: Vec<f64> = self.draws.iter().filter_map(|d| d.as_ref().ok()).map(f).collect();
        if v.is_empty() { None } else { Some(v.iter().sum::<f64>() / v.len() as f64) }
    }

    /// Quartiles (min, q1, median, q3, max) over the successful draws of a statistic.
    pub fn quartiles(&self, f: impl Fn(&HeldOut) -> f64) -> Option<[f64; 5]> {
        let mut v: Vec<f64> = self.draws.iter().filter_map(|d| d.as_ref().ok()).map(f).collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        Some([0.0, 0.25, 0.5, 0.75, 1.0].map(|p| crate::validate::stats::quantile(&v, p)))
    }
}

/// The whole-session model of one variant on another session, base and tools refitted there.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferResult {
    pub variant: String,
    pub session: String,
    pub errors: Result<HeldOut, String>,
    /// κ of the column-scaled Jacobian of the base-and-tools refit.
    pub kappa_scaled: Option<f64>,
}

/// Everything a cross-validation run measured.
#[derive(Clone, Debug)]
pub struct Crossval {
    pub session: String,
    pub measurements: usize,
    pub folds: Vec<FoldsResult>,
    pub sizes: Vec<SizeResult>,
    pub transfer: Vec<TransferResult>,
}

/// A cell holding one session with the given measurements of `session` (the artefact, model and
/// base guess kept).
pub fn subset_cell(cell: &Cell, session: &Session, indices: &[usize]) -> Cell {
    Cell {
        model: cell.model.clone(),
        base_guess: cell.base_guess,
        artefact: cell.artefact.clone(),
        sessions: vec![Session {
            measurements: indices.iter().map(|&i| session.measurements[i].clone()).collect(),
            ..session.clone()
        }],
    }
}

/// Identify on `train` measurements of `session` and score the model on `test`.
fn fit_and_score(
    cell: &Cell,
    session: &Session,
    train: &[usize],
    test: &[usize],
    options: &IdentifyOptions,
) -> Result<(HeldOut, f64), String> {
    let e = fold_errors(cell, session, train, test, options)?;
    let h = HeldOut::of(&e.position, &e.orientation).ok_or_else(|| "no test measurement".to_string())?;
    Ok((h, e.kappa_scaled))
}

/// The errors of every measurement of `test` (positions, orientations), for pooling folds.
fn fold_errors(
    cell: &Cell,
    session: &Session,
    train: &[usize],
    test: &[usize],
    options: &IdentifyOptions,
) -> Result<FoldErrors, String> {
    let id_cell = subset_cell(cell, session, train);
    let mut o = options.clone();
    o.selection.sessions = vec![session.name.clone()];
    o.selection.subset.clear();
    let id = identify(&id_cell, &o).map_err(|e| e.to_string())?;
    let test_cell = subset_cell(cell, session, test);
    let r = validate(&id.set, &test_cell, std::slice::from_ref(&session.name), Reference::Measured)
        .map_err(|e| e.to_string())?;
    Ok(FoldErrors {
        position: r.residuals.iter().map(|x| x.error.norm()).collect(),
        orientation: r.residuals.iter().filter_map(|x| x.orientation_error).collect(),
        identified: id.free_names.len(),
        kappa_scaled: id.quality.kappa_scaled,
    })
}

/// Per-measurement errors of one fit on its test set.
struct FoldErrors {
    position: Vec<f64>,
    orientation: Vec<f64>,
    identified: usize,
    kappa_scaled: f64,
}

/// Run `f` on every job on `threads` scoped threads; results in job order.
fn par_map<J: Sync, R: Send>(jobs: &[J], threads: usize, f: impl Fn(&J) -> R + Sync) -> Vec<R> {
    let next = AtomicUsize::new(0);
    let out: Mutex<Vec<Option<R>>> = Mutex::new((0..jobs.len()).map(|_| None).collect());
    std::thread::scope(|scope| {
        for _ in 0..threads.clamp(1, jobs.len().max(1)) {
            scope.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(job) = jobs.get(k) else { break };
                    let r = f(job);
                    out.lock().expect("no worker panics while holding the lock")[k] = Some(r);
                }
            });
        }
    });
    out.into_inner().expect("workers joined").into_iter().map(|r| r.expect("every job ran")).collect()
}

/// The seed of draw d: distinct runs' draws do not overlap (seed + d would share draws between
/// seeds 3 and 4).
fn draw_seed(seed: u64, d: usize) -> u64 {
    seed.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(1 + d as u64)
}

/// A seeded permutation of 0..n.
fn shuffled(n: usize, seed: u64) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..n).collect();
    idx.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
    idx
}

/// Run the schemes of `opts` on `cell`.
pub fn crossval(cell: &Cell, opts: &CrossvalOptions) -> Result<Crossval, IdentifyError> {
    let session = cell
        .session(&opts.session)
        .ok_or_else(|| IdentifyError::Option(format!("no session named '{}' in the cell", opts.session)))?;
    let n_meas = session.measurements.len();
    if opts.folds == 1 {
        return Err(IdentifyError::Option("--folds must be 0 (skip) or at least 2".into()));
    }
    if opts.folds > n_meas {
        return Err(IdentifyError::Option(format!(
            "--folds {} exceeds the session's {n_meas} measurements",
            opts.folds
        )));
    }
    if !opts.sizes.is_empty() && opts.draws == 0 {
        return Err(IdentifyError::Option("--draws must be at least 1".into()));
    }
    if let Some(&n) = opts.sizes.iter().find(|&&n| n > n_meas / 2) {
        return Err(IdentifyError::Option(format!(
            "size {n} exceeds half the session ({} of {n_meas} measurements): identification and test halves must be disjoint",
            n_meas / 2
        )));
    }
    for t in &opts.transfer {
        if cell.session(t).is_none() {
            return Err(IdentifyError::Option(format!("--transfer: no session named '{t}' in the cell")));
        }
        if *t == opts.session {
            return Err(IdentifyError::Option(format!("--transfer: '{t}' is the session identified on")));
        }
    }
    let mut variants = vec![Variant::before(&opts.before)];
    variants.extend(opts.variants.iter().cloned());

    // k-fold cross-validation: fold f holds the shuffled positions f, f + k, f + 2k, …
    let mut folds = Vec::new();
    if opts.folds >= 2 {
        let order = shuffled(n_meas, opts.seed);
        let k = opts.folds;
        let jobs: Vec<(usize, usize)> = (0..variants.len()).flat_map(|v| (0..k).map(move |f| (v, f))).collect();
        let results = par_map(&jobs, opts.threads, |&(v, f)| {
            let mut test: Vec<usize> = order.iter().skip(f).step_by(k).copied().collect();
            test.sort_unstable();
            let train: Vec<usize> = (0..n_meas).filter(|i| test.binary_search(i).is_err()).collect();
            fold_errors(cell, session, &train, &test, &variants[v].options)
        });
        for (v, variant) in variants.iter().enumerate() {
            let mine: Vec<&Result<FoldErrors, String>> =
                jobs.iter().zip(&results).filter(|((jv, _), _)| *jv == v).map(|(_, r)| r).collect();
            let per_fold: Vec<Result<HeldOut, String>> = mine
                .iter()
                .map(|r| match r {
                    Ok(e) => HeldOut::of(&e.position, &e.orientation).ok_or_else(|| "empty fold".to_string()),
                    Err(e) => Err(e.clone()),
                })
                .collect();
            let pooled = if mine.iter().all(|r| r.is_ok()) {
                let (mut p, mut o) = (Vec::new(), Vec::new());
                for e in mine.iter().filter_map(|r| r.as_ref().ok()) {
                    p.extend_from_slice(&e.position);
                    o.extend_from_slice(&e.orientation);
                }
                HeldOut::of(&p, &o)
            } else {
                None
            };
            let identified = mine.first().and_then(|r| r.as_ref().ok()).map_or(0, |r| r.identified);
            folds.push(FoldsResult { variant: variant.name.clone(), pooled, per_fold, identified });
        }
    }

    // Few poses: draw d splits the session in halves (the same split for every size and variant)
    // and identifies on the first n of the shuffled first half.
    let mut sizes = Vec::new();
    if !opts.sizes.is_empty() {
        let jobs: Vec<(usize, usize, usize)> = (0..variants.len())
            .flat_map(|v| opts.sizes.iter().flat_map(move |&n| (0..opts.draws).map(move |d| (v, n, d))))
            .collect();
        let results = par_map(&jobs, opts.threads, |&(v, n, d)| {
            let order = shuffled(n_meas, draw_seed(opts.seed, d));
            let half = n_meas / 2;
            let mut train: Vec<usize> = order[..n].to_vec();
            train.sort_unstable();
            let mut test: Vec<usize> = order[half..].to_vec();
            test.sort_unstable();
            fit_and_score(cell, session, &train, &test, &variants[v].options).map(|r| r.0)
        });
        for (v, variant) in variants.iter().enumerate() {
            for &n in &opts.sizes {
                let draws = jobs
                    .iter()
                    .zip(&results)
                    .filter(|((jv, jn, _), _)| *jv == v && *jn == n)
                    .map(|(_, r)| r.clone())
                    .collect();
                sizes.push(SizeResult { variant: variant.name.clone(), n, draws });
            }
        }
    }

    // Transfer: identify each variant on the whole session, then refit base and tools only on
    // each transfer session and score there.
    let mut transfer = Vec::new();
    if !opts.transfer.is_empty() {
        let all: Vec<usize> = (0..n_meas).collect();
        let fitted = par_map(&variants, opts.threads, |v| {
            let mut o = v.options.clone();
            o.selection.sessions = vec![session.name.clone()];
            identify(&subset_cell(cell, session, &all), &o).map_err(|e| e.to_string())
        });
        let jobs: Vec<(usize, usize)> =
            (0..variants.len()).flat_map(|v| (0..opts.transfer.len()).map(move |t| (v, t))).collect();
        let results = par_map(&jobs, opts.threads, |&(v, t)| {
            let id = fitted[v].as_ref().map_err(|e| format!("identification on '{}': {e}", session.name))?;
            let target = cell.session(&opts.transfer[t]).expect("checked above");
            let idx: Vec<usize> = (0..target.measurements.len()).collect();
            let mut o = IdentifyOptions {
                start: Some(id.set.clone()),
                only: before_scope(),
                selection: Default::default(),
                ..variants[v].options.clone()
            };
            o.fixed.extend(opts.transfer_fixed.iter().cloned());
            if let Some(k) = opts.transfer_kappa_limit {
                o.kappa_limit = k;
            }
            fit_and_score(cell, target, &idx, &idx, &o)
        });
        for (&(v, t), r) in jobs.iter().zip(results) {
            let (errors, kappa_scaled) = match r {
                Ok((h, k)) => (Ok(h), Some(k)),
                Err(e) => (Err(e), None),
            };
            transfer.push(TransferResult {
                variant: variants[v].name.clone(),
                session: opts.transfer[t].clone(),
                errors,
                kappa_scaled,
            });
        }
    }

    Ok(Crossval { session: session.name.clone(), measurements: n_meas, folds, sizes, transfer })
}
