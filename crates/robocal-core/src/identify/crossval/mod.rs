//! Held-out evaluation of a calibration on real data: what a metrologist asks of a calibration
//! before trusting it on a robot whose true parameters nobody knows.
//!
//! The data are one session, or several sessions measured at the same joint configurations
//! (several reflectors on the flange, read at each stop). Everything is split by **pose** — the
//! measurements at one configuration, in whichever sessions ([`crate::cell::poses`]) — so that no
//! pose has one reflector in training and another in test. Held-out errors are pooled over every
//! measurement of the held-out poses and also broken down per session (per reflector).
//!
//! - **k-fold cross-validation**: the poses are shuffled (seeded) into k folds; each fold is
//!   predicted by a model identified on the other k − 1; the pooled held-out errors (every
//!   measurement predicted exactly once) give mean, median, p95 and max.
//! - **Few poses**: for each size n and each draw, the poses are split at random into two halves;
//!   n poses drawn from the first half identify the model, the whole second half (disjoint) tests
//!   it. How many poses a calibration of this robot needs.
//! - **Transfer**: the model identified on all the data is carried to other sessions (other
//!   days, another tracker set-up) where only the base and the tools are refitted — the
//!   re-registration a cell does after the instrument moved — and scored there. A model that
//!   only absorbed the first session's quirks degrades; a physically right one transfers.
//!
//! Every scheme is run for each model variant and for the "before" reference: the nominal model
//! with only the base and the tools fitted (a cell without a base guess has no other honest
//! "uncalibrated" figure). Identification and test sets never share a measurement, and each
//! identification sees only its own measurements — also for the base registration that starts
//! it. Jobs are independent and run on scoped threads; every seed depends only on the job, so the
//! result does not depend on the thread count. With one session whose configurations are all
//! distinct, pose p is measurement p, and the splits are the measurement splits of earlier
//! versions.

use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

use super::{IdentifyError, IdentifyOptions, identify};
use crate::cell::poses::group_poses;
use crate::cell::{Cell, MeasuringOrder, Session};
use crate::validate::report::{Reference, validate};

mod held_out;
pub use held_out::{HeldOut, SessionHeldOut};
use held_out::{Scored, paired_change};

/// A model to evaluate: a name for the reports and its identification options.
#[derive(Clone, Debug)]
pub struct Variant {
    /// Its name in the reports (`before` for the reference).
    pub name: String,
    /// Its identification options; each split sets the sessions and the measurements it fits.
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
    /// The sessions whose measurements are split by pose: one, or several measured at the same
    /// configurations (reflectors on the flange).
    pub sessions: Vec<String>,
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
    /// Seed of the k-fold shuffle; each few-poses draw derives its own seed from it.
    pub seed: u64,
    /// Scoped worker threads (0 counts as 1; never more than the jobs).
    pub threads: usize,
}

/// k-fold cross-validation of one variant.
#[derive(Clone, Debug, PartialEq)]
pub struct FoldsResult {
    /// The variant's name.
    pub variant: String,
    /// The pooled held-out errors (each measurement predicted by the fold that did not see it),
    /// with their per-session breakdown; `None` when a fold failed.
    pub pooled: Option<HeldOut>,
    /// Per fold, in fold order: its held-out errors, or why there are none (a refused fit).
    pub per_fold: Vec<Result<HeldOut, String>>,
    /// Parameters identified in the first fold (the others agree unless the data are marginal).
    pub identified: usize,
    /// The change of the pooled mean position error from the variant before this one (the row
    /// above) on the same held-out measurements, m, and its standard error grouped by pose:
    /// whether the model's addition helps, beyond the noise of the test set.
    pub vs_previous: Option<(f64, f64)>,
}

/// One identification size of the few-poses scheme, one variant.
#[derive(Clone, Debug, PartialEq)]
pub struct SizeResult {
    /// The variant's name.
    pub variant: String,
    /// Poses identified on.
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
    /// The variant's name.
    pub variant: String,
    /// The session transferred to.
    pub session: String,
    /// The errors there, or why the whole-session fit or the refit was refused.
    pub errors: Result<HeldOut, String>,
    /// κ of the column-scaled Jacobian of the base-and-tools refit.
    pub kappa_scaled: Option<f64>,
    /// Base or tool parameters held in every variant's refit on this session because some refit
    /// left them undetermined (beyond the options' `transfer_fixed`): one registration's freedoms
    /// for every model compared.
    pub held: Vec<String>,
}

/// Everything a cross-validation run measured.
#[derive(Clone, Debug)]
pub struct Crossval {
    /// The split sessions.
    pub sessions: Vec<String>,
    /// Measurements of the split sessions.
    pub measurements: usize,
    /// Distinct configurations among them (the unit of every split).
    pub poses: usize,
    /// Per fold of the k-fold scheme, the measurements it held out: (session, index), sessions in
    /// the options' order, indices increasing.
    pub kfold_test: Vec<Vec<(String, usize)>>,
    /// The k-fold results, one per variant, the "before" reference first (empty when skipped).
    pub folds: Vec<FoldsResult>,
    /// The few-poses results, per variant (the reference first), then per size in the options' order.
    pub sizes: Vec<SizeResult>,
    /// The transfer results, per variant (the reference first), then per transfer session.
    pub transfer: Vec<TransferResult>,
    /// What the run derived and did not read (the backlash terms' approach directions from the
    /// measuring order, or why they could not be), and the held-out measurements a scheme could
    /// not score (their TCP unknown to the fit: [`HeldOut::unscored`]), one sentence each.
    pub notes: Vec<String>,
    /// The measurements refused fits named as outliers, (session, index in the session), sorted.
    /// Cross-validation scores every measurement of its sessions, so one gross reading refuses
    /// every fit that sees it; a front end says how its user can leave it out.
    pub outliers: Vec<(String, usize)>,
}

impl Crossval {
    /// The models evaluated, the "before" reference first.
    pub fn variants(&self) -> Vec<&str> {
        let names = self.folds.iter().map(|f| f.variant.as_str());
        let names = names.chain(self.sizes.iter().map(|s| s.variant.as_str()));
        let mut out: Vec<&str> = Vec::new();
        for n in names.chain(self.transfer.iter().map(|t| t.variant.as_str())) {
            if !out.contains(&n) {
                out.push(n);
            }
        }
        out
    }

    /// The models some scheme scored: pooled k-fold figures (every fold fitted), a few-poses draw
    /// or a transfer. A run whose fitted models (the reference aside) are not among them measured
    /// nothing it was asked to.
    pub fn scored(&self) -> Vec<&str> {
        let kfold = self.folds.iter().filter(|f| f.pooled.is_some()).map(|f| f.variant.as_str());
        let sizes = self.sizes.iter().filter(|s| s.draws.iter().any(|d| d.is_ok())).map(|s| s.variant.as_str());
        let transfer = self.transfer.iter().filter(|t| t.errors.is_ok()).map(|t| t.variant.as_str());
        let all: Vec<&str> = kfold.chain(sizes).chain(transfer).collect();
        self.variants().into_iter().filter(|v| all.contains(v)).collect()
    }
}

/// What the schemes found beside their figures: notes for the reader, and the outliers that
/// refused fits named.
#[derive(Default)]
struct Found {
    notes: Vec<String>,
    outliers: std::collections::BTreeSet<(String, usize)>,
}

impl Found {
    /// `r` with its refusal as the results carry it, the outliers it named kept.
    fn keep<T>(&mut self, r: Result<T, Refusal>) -> Result<T, String> {
        r.map_err(|e| {
            self.outliers.extend(e.outliers);
            e.message
        })
    }

    /// A note that `n` held-out readings of split session `s` were not scored ([`Split::unknown_tcp`]);
    /// `scope` says where ("in fold 2 of 5").
    fn unscored(&mut self, split: &Split, s: usize, n: usize, scope: &str) {
        self.notes.push(format!(
            "{}: {} not scored {scope}: no reading of {} in the training set, so its TCP is unknown; the figures leave {} out",
            split.names[s],
            readings(n),
            target_name(split.sessions[s]),
            if n == 1 { "it" } else { "them" }
        ));
    }
}

/// "1 held-out reading", "3 held-out readings".
fn readings(n: usize) -> String {
    format!("{n} held-out reading{}", if n == 1 { "" } else { "s" })
}

/// The physical target of a session's TCP, as a note names it.
fn target_name(s: &Session) -> String {
    match &s.target {
        Some(t) => format!("its target '{t}'"),
        None => s.name.clone(),
    }
}

/// A cell holding, for each (session, indices), that session with those measurements (sessions
/// left without any are dropped); proper subsets are marked resampled.
fn subsets_cell(cell: &Cell, parts: &[(&Session, Vec<usize>)]) -> Cell {
    Cell {
        model: cell.model.clone(),
        base_guess: cell.base_guess,
        artefact: cell.artefact.clone(),
        sessions: parts
            .iter()
            .filter(|(_, idx)| !idx.is_empty())
            .map(|(session, idx)| {
                let whole = idx.len() == session.measurements.len() && idx.iter().enumerate().all(|(k, &i)| k == i);
                Session {
                    measurements: idx.iter().map(|&i| session.measurements[i].clone()).collect(),
                    order: if whole { session.order } else { MeasuringOrder::Resampled },
                    ..(*session).clone()
                }
            })
            .collect(),
    }
}

/// The split sessions, their measurements as (session, index), and the pose of each.
struct Split<'a> {
    sessions: Vec<&'a Session>,
    names: Vec<String>,
    /// Every measurement of the sessions: (index into `sessions`, index in that session).
    items: Vec<(usize, usize)>,
    /// Per pose: its items (indices into `items`), in item order.
    members: Vec<Vec<usize>>,
}

impl Split<'_> {
    /// Per session, per measurement: its pose.
    fn poses_by_measurement(&self) -> Vec<Vec<usize>> {
        let mut out: Vec<Vec<usize>> = self.sessions.iter().map(|s| vec![usize::MAX; s.measurements.len()]).collect();
        for (p, its) in self.members.iter().enumerate() {
            for &it in its {
                let (s, i) = self.items[it];
                out[s][i] = p;
            }
        }
        out
    }
}

impl Split<'_> {
    /// The items of `poses`, as one index list per session (sorted).
    fn indices(&self, poses: &[usize]) -> Vec<(&Session, Vec<usize>)> {
        let mut per: Vec<Vec<usize>> = vec![Vec::new(); self.sessions.len()];
        for &p in poses {
            for &it in &self.members[p] {
                let (s, i) = self.items[it];
                per[s].push(i);
            }
        }
        self.sessions
            .iter()
            .zip(per)
            .map(|(s, mut idx)| {
                idx.sort_unstable();
                (*s, idx)
            })
            .collect()
    }

    /// Identify on the measurements of the `train` poses and score the model on those of `test`.
    fn fit_and_score(
        &self,
        cell: &Cell,
        train: &[usize],
        test: &[usize],
        options: &IdentifyOptions,
    ) -> Result<(HeldOut, f64), Refusal> {
        let e = self.fold_errors(cell, train, test, options, false)?;
        let h = HeldOut::of(&e.scored, &self.names, &e.unscored).ok_or_else(|| Refusal::plain(NOTHING_SCORED))?;
        Ok((h, e.kappa_scaled))
    }

    /// The errors of every measurement of the `test` poses, for pooling folds; those whose TCP the
    /// fit cannot know ([`Split::unknown_tcp`]) are counted, not scored.
    ///
    /// `fold`: the fit is one fold of a k-fold scheme, which predicts with 1/k of the poses out.
    /// Refused for its κ alone (every σ within its bound: a parameter that is not is held before
    /// κ is judged), it is fitted again without the limit, and [`FoldErrors::above_limit`] says so:
    /// the limit is the rule for a calibration, and a fold's conditioning, a little worse than the
    /// whole set's, must not leave the scheme without a figure. On joint sweeps of a six-axis robot
    /// (ten stops a joint) the whole set fitted at κ 913–922 and one fold in five was refused at
    /// 1,140–1,180, so `crossval` scored nothing.
    fn fold_errors(
        &self,
        cell: &Cell,
        train: &[usize],
        test: &[usize],
        options: &IdentifyOptions,
        fold: bool,
    ) -> Result<FoldErrors, Refusal> {
        // Readings the options exclude are neither fitted nor scored. They are named by their index
        // in the whole session, which a fold's subset renumbers, so they are taken out here.
        let excluded = &options.selection.exclude;
        let train = without_excluded(self.indices(train), excluded);
        let id_cell = subsets_cell(cell, &train);
        let mut test_idx = without_excluded(self.indices(test), excluded);
        let unscored = self.unknown_tcp(&train, &test_idx);
        for &(s, _) in &unscored {
            test_idx[s].1.clear();
        }
        let poses = self.poses_by_measurement();
        let mut o = options.clone();
        o.selection.sessions = id_cell.sessions.iter().map(|s| s.name.clone()).collect();
        o.selection.subset.clear();
        o.selection.exclude.clear();
        let (id, above_limit) = match identify(&id_cell, &o) {
            Ok(id) => (id, None),
            Err(IdentifyError::IllConditioned { kappa, limit, .. }) if fold && limit.is_finite() => {
                let relaxed = IdentifyOptions { kappa_limit: f64::INFINITY, ..o.clone() };
                (identify(&id_cell, &relaxed).map_err(|e| refusal(e, &train))?, Some((kappa, limit)))
            }
            Err(e) => return Err(refusal(e, &train)),
        };
        let mut test_cell = subsets_cell(cell, &test_idx);
        with_identified_tools(&mut test_cell, cell, &id);
        let names: Vec<String> = test_cell.sessions.iter().map(|s| s.name.clone()).collect();
        let residuals = if names.is_empty() {
            Vec::new()
        } else {
            let r = validate(&id.set, &test_cell, &names, Reference::Measured);
            r.map_err(|e| Refusal::plain(e.to_string()))?.residuals
        };
        let scored = residuals
            .iter()
            .map(|x| {
                let session = self.names.iter().position(|n| *n == x.session).expect("a split session");
                let index = test_idx[session].1[x.index];
                Scored {
                    session,
                    index,
                    pose: poses[session][index],
                    position: x.error.norm(),
                    orientation: x.orientation_error,
                }
            })
            .collect();
        Ok(FoldErrors {
            scored,
            unscored,
            identified: id.free_names.len(),
            free: id.free_names.clone(),
            kappa_scaled: id.quality.kappa_scaled,
            above_limit,
        })
    }

    /// The test sessions (index into the split, test measurements) whose TCP a fit on `train`
    /// cannot know: the fit identifies their target's TCP and no session of that target (itself,
    /// or one naming the same `target`) has a training measurement. Their declared TCP is a guess
    /// (the flange, for reflectors imported without one): scoring them with it would report the
    /// guess's error, 100 mm and more, as the model's. The same for every model of one split.
    fn unknown_tcp(&self, train: &[(&Session, Vec<usize>)], test: &[(&Session, Vec<usize>)]) -> Vec<(usize, usize)> {
        let trained = |s: &Session| {
            train
                .iter()
                .any(|(t, idx)| !idx.is_empty() && (t.name == s.name || (s.target.is_some() && t.target == s.target)))
        };
        test.iter()
            .enumerate()
            .filter(|(_, (s, idx))| !idx.is_empty() && s.identify_tcp && !trained(s))
            .map(|(k, (_, idx))| (k, idx.len()))
            .collect()
    }
}

/// Why a fold's figures are missing when the fit was not refused.
const NOTHING_SCORED: &str = "no test measurement could be scored";

/// A refused fit of one split: why, and the measurements it named as outliers (session, index in
/// the whole session).
#[derive(Clone, Debug)]
struct Refusal {
    message: String,
    outliers: Vec<(String, usize)>,
}

impl Refusal {
    fn plain(message: impl Into<String>) -> Refusal {
        Refusal { message: message.into(), outliers: Vec::new() }
    }
}

/// Why identifying on `parts` (each split session's measurements the fit saw) was refused, each
/// measurement it names by its index in its whole session: the fit numbers a subset from 0, and
/// the 13th reading of a fold's subset is no reading the user can find. An outlier refusal names
/// no remedy option: cross-validation has neither `exclude` nor a loss of its own (the front end
/// says what its user can do, from [`Crossval::outliers`]).
fn refusal(e: IdentifyError, parts: &[(&Session, Vec<usize>)]) -> Refusal {
    let whole = |w: &mut super::Worst| {
        if let Some(&i) = parts.iter().find(|(s, _)| s.name == w.session).and_then(|(_, idx)| idx.get(w.index)) {
            w.index = i;
        }
    };
    match e {
        IdentifyError::Outliers { mut outliers, factor } => {
            outliers.iter_mut().for_each(whole);
            Refusal {
                message: format!(
                    "{}; cross-validation scores every measurement of its sessions: remove them from the sessions to cross-validate without them",
                    super::outliers_found(&outliers, factor)
                ),
                outliers: outliers.into_iter().map(|w| (w.session, w.index)).collect(),
            }
        }
        IdentifyError::Misfit { rms, expected, ratio, limit, mut worst } => {
            worst.iter_mut().for_each(whole);
            Refusal::plain(IdentifyError::Misfit { rms, expected, ratio, limit, worst }.to_string())
        }
        e => Refusal::plain(e.to_string()),
    }
}

/// Give every session of `scored` the TCP `id` identified for its target ([`Cell::identified_tcp`],
/// the targets read from `cell`, the cell fitted on): its own tool block's, or that of a session
/// measuring the same named target, so that each held-out measurement is predicted with its own
/// target's TCP. Sessions whose declared tools are equal (several reflectors imported with the
/// flange as their guess) would otherwise all be predicted with the parameter set's one tool — the
/// first reflector's. The others keep their declared TCP: fixed ones, since
/// [`Split::unknown_tcp`] left the rest out of the test.
pub(crate) fn with_identified_tools(scored: &mut Cell, cell: &Cell, id: &super::Identification) {
    let by_name = |name: &str| id.tools.iter().find(|t| t.sessions.iter().any(|n| n == name)).map(|t| t.tool.tcp);
    for s in &mut scored.sessions {
        if let Some(tcp) = cell.identified_tcp(s, by_name) {
            s.tool.tcp = tcp;
        }
    }
}

/// `parts` without the readings `excluded` names (session, index in the whole session).
fn without_excluded<'s>(
    mut parts: Vec<(&'s Session, Vec<usize>)>,
    excluded: &[(String, usize)],
) -> Vec<(&'s Session, Vec<usize>)> {
    for (session, idx) in &mut parts {
        idx.retain(|&i| !excluded.iter().any(|(n, k)| *n == session.name && *k == i));
    }
    parts
}

/// Identify on all the measurements of `session` with `options` and score the model there.
/// Fit `options` on the whole of `session` and score it there: the errors, κ and the fit's free
/// parameters by name.
fn fit_and_score_whole(
    cell: &Cell,
    session: &Session,
    options: &IdentifyOptions,
) -> Result<(HeldOut, f64, Vec<String>), Refusal> {
    let all: Vec<usize> = (0..session.measurements.len()).collect();
    let split = Split {
        sessions: vec![session],
        names: vec![session.name.clone()],
        items: all.iter().map(|&i| (0, i)).collect(),
        members: all.iter().map(|&i| vec![i]).collect(),
    };
    let e = split.fold_errors(cell, &all, &all, options, false)?;
    let h = HeldOut::of(&e.scored, &split.names, &e.unscored).ok_or_else(|| Refusal::plain(NOTHING_SCORED))?;
    Ok((h, e.kappa_scaled, e.free))
}

/// Per-measurement errors of one fit on its test set.
struct FoldErrors {
    scored: Vec<Scored>,
    /// Test measurements not scored, their TCP unknown ([`Split::unknown_tcp`]): (session, count).
    unscored: Vec<(usize, usize)>,
    identified: usize,
    /// The fit's free parameters, by name.
    free: Vec<String>,
    kappa_scaled: f64,
    /// (κ, the limit) when the fit was refused for its κ alone and fitted again without the limit
    /// (a k-fold fold: [`Split::fold_errors`]).
    above_limit: Option<(f64, f64)>,
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
    crossval_with_progress(cell, opts, &|_, _| {})
}

/// Calls its function when dropped: a tick however the closure returns.
struct Tick<'a, F: Fn()>(&'a F);

impl<F: Fn()> Drop for Tick<'_, F> {
    fn drop(&mut self) {
        (self.0)();
    }
}

/// [`crossval`], calling `progress` with (fits done, fits in all) after each identification.
/// The steps: the split's poses, the options checked against them, then each scheme in turn
/// (k-fold, few poses, transfer) for the "before" reference and every variant.
pub fn crossval_with_progress(
    cell: &Cell,
    opts: &CrossvalOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Crossval, IdentifyError> {
    // Approach directions from the measuring order of the whole sessions, before any fold takes
    // a subset of them (a subset's consecutive rows are not consecutive stops).
    let models: Vec<&super::ModelOptions> =
        std::iter::once(&opts.before.model).chain(opts.variants.iter().map(|v| &v.options.model)).collect();
    let filled = super::prepare::with_approach(cell, &models);
    let (cell, notes) = match &filled {
        Some((f, notes)) => (f, notes.clone()),
        None => (cell, Vec::new()),
    };
    let split = Split::of(cell, &opts.sessions)?;
    check_schemes(cell, opts, &split)?;
    let mut variants = vec![Variant::before(&opts.before)];
    variants.extend(opts.variants.iter().cloned());
    // Every identification the run makes, for the progress callback.
    let total = variants.len()
        * (if opts.folds >= 2 { opts.folds } else { 0 }
            + opts.sizes.len() * opts.draws
            + if opts.transfer.is_empty() { 0 } else { 1 + opts.transfer.len() });
    let done = AtomicUsize::new(0);
    let tick = || progress(done.fetch_add(1, Ordering::Relaxed) + 1, total);
    let mut found = Found { notes, ..Default::default() };
    let (kfold_test, folds) =
        if opts.folds >= 2 { kfold(cell, opts, &split, &variants, &tick, &mut found) } else { Default::default() };
    let sizes =
        if opts.sizes.is_empty() { Vec::new() } else { few_poses(cell, opts, &split, &variants, &tick, &mut found) };
    let transfer =
        if opts.transfer.is_empty() { Vec::new() } else { transfer(cell, opts, &split, &variants, &tick, &mut found) };
    Ok(Crossval {
        sessions: split.names.clone(),
        measurements: split.items.len(),
        poses: split.members.len(),
        kfold_test,
        folds,
        sizes,
        transfer,
        notes: found.notes,
        outliers: found.outliers.into_iter().collect(),
    })
}

impl<'a> Split<'a> {
    /// The named sessions of `cell` (each once) and their measurements grouped into poses.
    fn of(cell: &'a Cell, names: &[String]) -> Result<Split<'a>, IdentifyError> {
        if names.is_empty() {
            return Err(IdentifyError::field("session", "name at least one session to split"));
        }
        let mut sessions: Vec<&Session> = Vec::with_capacity(names.len());
        for name in names {
            let s = cell
                .session(name)
                .ok_or_else(|| IdentifyError::field("session", format!("no session named '{name}' in the cell")))?;
            if sessions.iter().any(|t| t.name == *name) {
                return Err(IdentifyError::field("session", format!("session '{name}' is named twice")));
            }
            sessions.push(s);
        }
        let items: Vec<(usize, usize)> =
            sessions.iter().enumerate().flat_map(|(s, x)| (0..x.measurements.len()).map(move |i| (s, i))).collect();
        let (pose_of, n_poses) = group_poses(items.iter().map(|&(s, i)| sessions[s].measurements[i].q.as_slice()));
        let mut members = vec![Vec::new(); n_poses];
        for (it, &p) in pose_of.iter().enumerate() {
            members[p].push(it);
        }
        Ok(Split { names: sessions.iter().map(|s| s.name.clone()).collect(), sessions, items, members })
    }
}

/// The schemes' options against the split: folds, draws and sizes its poses allow, transfer
/// sessions that exist and are not split.
fn check_schemes(cell: &Cell, opts: &CrossvalOptions, split: &Split) -> Result<(), IdentifyError> {
    let n_poses = split.members.len();
    let what = if split.sessions.len() == 1 {
        format!("the session's {n_poses} poses")
    } else {
        format!("the {n_poses} poses of the sessions")
    };
    if opts.folds == 1 {
        return Err(IdentifyError::field("folds", "must be 0 (skip) or at least 2"));
    }
    if opts.folds == 0 && opts.sizes.is_empty() && opts.transfer.is_empty() {
        return Err(IdentifyError::field("folds", "0 with no sizes and no transfer sessions: no scheme to run"));
    }
    if opts.folds > n_poses {
        return Err(IdentifyError::field("folds", format!("{} exceeds {what}", opts.folds)));
    }
    if !opts.sizes.is_empty() && opts.draws == 0 {
        return Err(IdentifyError::field("draws", "must be at least 1"));
    }
    if let Some(&n) = opts.sizes.iter().find(|&&n| n > n_poses / 2) {
        return Err(IdentifyError::field(
            "sizes",
            format!(
                "size {n} exceeds half the session{} ({} of {n_poses} poses): identification and test halves must be disjoint",
                if split.sessions.len() == 1 { "" } else { "s" },
                n_poses / 2
            ),
        ));
    }
    for (i, t) in opts.transfer.iter().enumerate() {
        if cell.session(t).is_none() {
            return Err(IdentifyError::item("transfer", i, format!("no session named '{t}' in the cell")));
        }
        if opts.sessions.contains(t) {
            return Err(IdentifyError::item("transfer", i, format!("'{t}' is the session identified on")));
        }
    }
    Ok(())
}

/// k-fold cross-validation: fold f holds the shuffled poses f, f + k, f + 2k, … Returns each
/// fold's held-out measurements and, per variant, its pooled result.
fn kfold(
    cell: &Cell,
    opts: &CrossvalOptions,
    split: &Split,
    variants: &[Variant],
    tick: &(impl Fn() + Sync),
    found: &mut Found,
) -> (Vec<Vec<(String, usize)>>, Vec<FoldsResult>) {
    let n_poses = split.members.len();
    let order = shuffled(n_poses, opts.seed);
    let k = opts.folds;
    let tests: Vec<Vec<usize>> = (0..k)
        .map(|f| {
            let mut test: Vec<usize> = order.iter().skip(f).step_by(k).copied().collect();
            test.sort_unstable();
            test
        })
        .collect();
    let kfold_test = tests
        .iter()
        .map(|t| {
            split.indices(t).into_iter().flat_map(|(s, idx)| idx.into_iter().map(|i| (s.name.clone(), i))).collect()
        })
        .collect();
    let train_of = |test: &[usize]| -> Vec<usize> { (0..n_poses).filter(|p| test.binary_search(p).is_err()).collect() };
    let jobs: Vec<(usize, usize)> = (0..variants.len()).flat_map(|v| (0..k).map(move |f| (v, f))).collect();
    let results = par_map(&jobs, opts.threads, |&(v, f)| {
        let r = split.fold_errors(cell, &train_of(&tests[f]), &tests[f], &variants[v].options, true);
        tick();
        r
    });
    let results: Vec<Result<FoldErrors, String>> = results.into_iter().map(|r| found.keep(r)).collect();
    for (&(v, f), r) in jobs.iter().zip(&results) {
        if let Ok(FoldErrors { above_limit: Some((kappa, limit)), .. }) = r {
            found.notes.push(format!(
                "{}: fold {} of {k} was fitted at κ {kappa:.0}, above the limit of {limit:.0} that a calibration must meet, with every σ within its bound; its figure is kept (a fold predicts with 1/{k} of the poses out; `identify` judges the whole set's κ)",
                variants[v].name,
                f + 1
            ));
        }
    }
    for (f, test) in tests.iter().enumerate() {
        for (s, n) in split.unknown_tcp(&split.indices(&train_of(test)), &split.indices(test)) {
            found.unscored(split, s, n, &format!("in fold {} of {k}", f + 1));
        }
    }
    let mut folds = Vec::new();
    let mut previous: Option<Vec<Scored>> = None;
    for (v, variant) in variants.iter().enumerate() {
        let mine: Vec<&Result<FoldErrors, String>> =
            jobs.iter().zip(&results).filter(|((jv, _), _)| *jv == v).map(|(_, r)| r).collect();
        let (result, all) = pooled_folds(&variant.name, &mine, &split.names, previous.as_deref());
        folds.push(result);
        previous = all;
    }
    (kfold_test, folds)
}

/// One variant's k-fold result from its folds' errors, compared with the previous variant's
/// pooled errors; also its own pooled errors (`None` when a fold failed), for the next.
fn pooled_folds(
    variant: &str,
    mine: &[&Result<FoldErrors, String>],
    names: &[String],
    previous: Option<&[Scored]>,
) -> (FoldsResult, Option<Vec<Scored>>) {
    let per_fold: Vec<Result<HeldOut, String>> = mine
        .iter()
        .map(|r| match r {
            Ok(e) => HeldOut::of(&e.scored, names, &e.unscored).ok_or_else(|| NOTHING_SCORED.to_string()),
            Err(e) => Err(e.clone()),
        })
        .collect();
    let pooled = if mine.iter().all(|r| r.is_ok()) {
        let ok = || mine.iter().filter_map(|r| r.as_ref().ok());
        let all: Vec<Scored> = ok().flat_map(|e| e.scored.iter().copied()).collect();
        let unscored: Vec<(usize, usize)> = ok().flat_map(|e| e.unscored.iter().copied()).collect();
        HeldOut::of(&all, names, &unscored)
    } else {
        None
    };
    let identified = mine.first().and_then(|r| r.as_ref().ok()).map_or(0, |r| r.identified);
    let all: Option<Vec<Scored>> =
        mine.iter().map(|r| r.as_ref().ok().map(|e| e.scored.clone())).collect::<Option<Vec<_>>>().map(|v| v.concat());
    let vs_previous = match (previous, &all) {
        (Some(a), Some(b)) => paired_change(a, b),
        _ => None,
    };
    (FoldsResult { variant: variant.to_string(), pooled, per_fold, identified, vs_previous }, all)
}

/// Few poses: draw d splits the poses in halves (the same split for every size and variant)
/// and identifies on the first n of the shuffled first half.
fn few_poses(
    cell: &Cell,
    opts: &CrossvalOptions,
    split: &Split,
    variants: &[Variant],
    tick: &(impl Fn() + Sync),
    found: &mut Found,
) -> Vec<SizeResult> {
    let n_poses = split.members.len();
    let jobs: Vec<(usize, usize, usize)> = (0..variants.len())
        .flat_map(|v| opts.sizes.iter().flat_map(move |&n| (0..opts.draws).map(move |d| (v, n, d))))
        .collect();
    let halves = |n: usize, d: usize| {
        let order = shuffled(n_poses, draw_seed(opts.seed, d));
        let mut train: Vec<usize> = order[..n].to_vec();
        train.sort_unstable();
        let mut test: Vec<usize> = order[n_poses / 2..].to_vec();
        test.sort_unstable();
        (train, test)
    };
    let results = par_map(&jobs, opts.threads, |&(v, n, d)| {
        let (train, test) = halves(n, d);
        let r = split.fit_and_score(cell, &train, &test, &variants[v].options).map(|r| r.0);
        tick();
        r
    });
    let results: Vec<Result<HeldOut, String>> = results.into_iter().map(|r| found.keep(r)).collect();
    // One note per size and session: over how many draws, how many readings in all.
    for &n in &opts.sizes {
        let mut per: std::collections::BTreeMap<usize, (usize, usize)> = Default::default();
        for d in 0..opts.draws {
            let (train, test) = halves(n, d);
            for (s, c) in split.unknown_tcp(&split.indices(&train), &split.indices(&test)) {
                let e = per.entry(s).or_default();
                e.0 += 1;
                e.1 += c;
            }
        }
        for (s, (draws, c)) in per {
            found.unscored(split, s, c, &format!("in {draws} of the {} draws of n = {n}", opts.draws));
        }
    }
    let mut sizes = Vec::new();
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
    sizes
}

/// Transfer: identify each variant on all the split data, then refit base and tools only on
/// each transfer session and score there.
fn transfer(
    cell: &Cell,
    opts: &CrossvalOptions,
    split: &Split,
    variants: &[Variant],
    tick: &(impl Fn() + Sync),
    found: &mut Found,
) -> Vec<TransferResult> {
    let all_poses: Vec<usize> = (0..split.members.len()).collect();
    let parts = split.indices(&all_poses);
    let whole = subsets_cell(cell, &parts);
    let fitted = par_map(variants, opts.threads, |v| {
        let mut o = v.options.clone();
        o.selection.sessions = split.names.clone();
        let r = identify(&whole, &o).map_err(|e| refusal(e, &parts));
        tick();
        r
    });
    let fitted: Vec<Result<super::Identification, String>> = fitted.into_iter().map(|r| found.keep(r)).collect();
    let on = split.names.join(", ");
    let jobs: Vec<(usize, usize)> =
        (0..variants.len()).flat_map(|v| (0..opts.transfer.len()).map(move |t| (v, t))).collect();
    let refit = |v: usize, t: usize, held: &[String]| {
        let id = fitted[v].as_ref().map_err(|e| Refusal::plain(format!("identification on '{on}': {e}")))?;
        let target = cell.session(&opts.transfer[t]).expect("checked above");
        let mut o = IdentifyOptions {
            start: Some(id.set.clone()),
            only: before_scope(),
            selection: Default::default(),
            ..variants[v].options.clone()
        };
        for n in opts.transfer_fixed.iter().chain(held) {
            if !o.fixed.contains(n) {
                o.fixed.push(n.clone());
            }
        }
        if let Some(k) = opts.transfer_kappa_limit {
            o.kappa_limit = k;
        }
        fit_and_score_whole(cell, target, &o)
    };
    let mut results = par_map(&jobs, opts.threads, |&(v, t)| {
        let _done = Tick(tick);
        refit(v, t, &[])
    });
    // One registration's freedoms for every model on a session ([`super::free_in_some_only`]):
    // what some refit held is held in all.
    let held: Vec<Vec<String>> = (0..opts.transfer.len())
        .map(|t| {
            let free: Vec<&[String]> = jobs
                .iter()
                .zip(&results)
                .filter(|((_, jt), _)| *jt == t)
                .filter_map(|(_, r)| r.as_ref().ok().map(|x| x.2.as_slice()))
                .collect();
            super::free_in_some_only(&free)
        })
        .collect();
    let again: Vec<usize> = (0..jobs.len())
        .filter(|&k| results[k].as_ref().is_ok_and(|x| x.2.iter().any(|n| held[jobs[k].1].contains(n))))
        .collect();
    let redone = par_map(&again, opts.threads, |&k| refit(jobs[k].0, jobs[k].1, &held[jobs[k].1]));
    for (k, r) in again.into_iter().zip(redone) {
        results[k] = r;
    }
    for (t, h) in held.iter().enumerate().filter(|(_, h)| !h.is_empty()) {
        found.notes.push(format!(
            "transfer to '{}': {} held at its start value in every model's refit there (some refit left it \
             undetermined by that session's data), so the models are compared with the same freedoms",
            opts.transfer[t],
            h.join(", ")
        ));
    }
    jobs.iter()
        .zip(results.into_iter().map(|r| found.keep(r)))
        .map(|(&(v, t), r)| {
            let (errors, kappa_scaled) = match r {
                Ok((h, k, _)) => (Ok(h), Some(k)),
                Err(e) => (Err(e), None),
            };
            TransferResult {
                variant: variants[v].name.clone(),
                session: opts.transfer[t].clone(),
                errors,
                kappa_scaled,
                held: held[t].clone(),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::held_out::clustered_mean_se;
    use super::*;

    fn scored(session: usize, index: usize, pose: usize, position: f64) -> Scored {
        Scored { session, index, pose, position, orientation: None }
    }

    /// The clustered standard error by hand: three poses holding (1, 3), (2) and (6, 6, 6).
    /// mean = 24/6 = 4; S_g − n_g·mean = 4 − 8, 2 − 4, 18 − 12 → −4, −2, 6; Σ² = 56;
    /// se = √(3/2 · 56)/6 = √84/6.
    #[test]
    fn clustered_mean_se_by_hand() {
        let v = [(0, 1.0), (0, 3.0), (1, 2.0), (2, 6.0), (2, 6.0), (2, 6.0)];
        let se = clustered_mean_se(v.into_iter()).unwrap();
        assert!((se - 84f64.sqrt() / 6.0).abs() < 1e-15, "{se}");
        // One value per pose: the ordinary s/√n, since G/(G−1)·Σ(x−m)²/n² = Σ(x−m)²/(n(n−1)).
        let w = [(0, 1.0), (1, 2.0), (2, 4.0), (3, 7.0)];
        let m = 3.5;
        let s2 = w.iter().map(|x| (x.1 - m) * (x.1 - m)).sum::<f64>() / 3.0;
        let se1 = clustered_mean_se(w.into_iter()).unwrap();
        assert!((se1 - (s2 / 4.0).sqrt()).abs() < 1e-15, "{se1}");
        assert!(clustered_mean_se([(5, 1.0), (5, 2.0)].into_iter()).is_none(), "one pose");
    }

    /// The paired change matches measurements by (session, index) whatever their order, is the
    /// difference of the two means, and refuses different test sets.
    #[test]
    fn paired_change_matches_by_measurement() {
        let a = [scored(0, 0, 0, 1.0), scored(0, 1, 1, 2.0), scored(1, 0, 0, 3.0), scored(1, 1, 1, 5.0)];
        let b = [scored(1, 1, 1, 4.0), scored(0, 0, 0, 0.5), scored(1, 0, 0, 2.0), scored(0, 1, 1, 2.5)];
        let (c, se) = paired_change(&a, &b).unwrap();
        // Differences: pose 0: −0.5, −1.0; pose 1: +0.5, −1.0 → mean −0.5; S_g − n_g·mean: −0.5, 0.5.
        assert!((c + 0.5).abs() < 1e-15);
        assert!((se - (2.0f64 * 0.5).sqrt() / 4.0).abs() < 1e-15, "{se}");
        assert!(paired_change(&a, &b[..3]).is_none());
        let mut c2 = b;
        c2[0].index = 7;
        assert!(paired_change(&a, &c2).is_none());
    }
}
