//! The reports of `robocal study` (in `study_report`, re-exported here) and `robocal crossval`: one
//! typed document each, serialised as the `--out` JSON and rendered as the text tables. Lengths in
//! mm, orientations in mrad.

use serde::Serialize;

use crate::domain::validation::ErrorFigures;
use crate::identify::crossval::{Crossval, HeldOut, SessionHeldOut, SizeResult};
use crate::units::{MM, MRAD};

pub use super::study_report::StudyReport;

/// Radians → milliradians: × 1e3 exactly (`1 / MRAD` is 1e3 to the bit; ÷ MRAD would round
/// differently from what these reports have always written).
const PER_MRAD: f64 = 1.0 / MRAD;

/// A finite value, or `None` (JSON has no NaN or infinity).
pub(super) fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

/// `robocal crossval`: k-fold, few-poses and transfer errors of every model. With several
/// sessions (reflectors at the same poses), every held-out figure also carries `per_session`.
#[derive(Clone, Debug, Serialize)]
pub struct CrossvalReport {
    /// The split sessions, comma-separated.
    pub session: String,
    #[serde(skip_serializing_if = "single")]
    pub sessions: Vec<String>,
    pub measurements: usize,
    /// Distinct configurations: the unit of the splits.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub poses: Option<usize>,
    pub seed: u64,
    pub folds: usize,
    pub draws: usize,
    pub kfold: Vec<KfoldFigures>,
    pub sizes: Vec<SizeFigures>,
    pub transfer: Vec<TransferFigures>,
    pub quartiles: &'static str,
    /// What the run derived and did not read (approach directions from the measuring order), and
    /// the held-out readings a scheme could not score.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
    /// The readings refused fits named as outliers (session, index in the session).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub outliers: Vec<MeasurementFigure>,
    /// The readings left out of every fit and every score (`--exclude`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub excluded: Vec<MeasurementFigure>,
    /// Wall-clock seconds and worker threads: the text's, not the document's.
    #[serde(skip)]
    pub seconds: f64,
    #[serde(skip)]
    pub threads: usize,
}

fn single(v: &[String]) -> bool {
    v.len() <= 1
}

/// Held-out errors of a model on a test set: pooled over every measurement of the test poses
/// and, when several sessions were split, per session (reflector).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct HeldOutFigures {
    pub n: usize,
    #[serde(flatten)]
    pub position: ErrorFigures,
    /// Standard error of `mean_mm`, the measurements grouped by pose.
    pub mean_se_mm: Option<f64>,
    pub orientation: Option<OrientationFigures>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub per_session: Vec<SessionFigures>,
    /// Test readings left out of these figures, per session: the fit identifies their TCP and saw
    /// no reading of their target, so it has none to predict them with (the notes say where).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub unscored: Vec<UnscoredFigures>,
}

/// A session's test readings that were not scored.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct UnscoredFigures {
    pub session: String,
    pub n: usize,
}

/// A measurement by its session and its 0-based index there, as identify's `--exclude` takes it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MeasurementFigure {
    pub session: String,
    pub index: usize,
}

/// One session's share of a test set's errors.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SessionFigures {
    pub session: String,
    pub n: usize,
    #[serde(flatten)]
    pub position: ErrorFigures,
    pub orientation: Option<OrientationFigures>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct OrientationFigures {
    pub mean_mrad: f64,
    pub median_mrad: f64,
    pub p95_mrad: f64,
    pub max_mrad: f64,
}

/// A fit's held-out errors, or why it was refused.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Outcome {
    HeldOut(HeldOutFigures),
    Refused { refused: String },
}

/// k-fold cross-validation of one model.
#[derive(Clone, Debug, Serialize)]
pub struct KfoldFigures {
    pub model: String,
    pub parameters_identified: usize,
    pub pooled: Option<HeldOutFigures>,
    /// The pooled mean's change from the model above on the same held-out measurements.
    pub vs_previous: Option<PairedChange>,
    pub per_fold: Vec<Outcome>,
}

/// A change of the held-out mean between two models on the same measurements, with its standard
/// error grouped by pose.
#[derive(Clone, Debug, Serialize)]
pub struct PairedChange {
    pub change_mm: f64,
    pub se_mm: f64,
}

/// One identification size of the few-poses scheme, one model.
#[derive(Clone, Debug, Serialize)]
pub struct SizeFigures {
    pub model: String,
    pub n: usize,
    pub refused: usize,
    pub mean_mm_over_draws: Option<f64>,
    /// Per session (several split): the mean over the successful draws of each draw's mean, mm.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub per_session_mean_mm_over_draws: Vec<SessionMean>,
    pub mean_mm_quartiles: Option<[f64; 5]>,
    pub median_mm_quartiles: Option<[f64; 5]>,
    pub orientation_mean_mrad_quartiles: Option<[f64; 5]>,
    pub draws: Vec<Outcome>,
    #[serde(skip)]
    pub table: SizeTableRow,
}

/// A session's mean over the draws.
#[derive(Clone, Debug, Serialize)]
pub struct SessionMean {
    pub session: String,
    pub mean_mm: Option<f64>,
}

/// The few-poses table's figures, computed as the table always computed them (statistics of
/// the per-draw values in mm or mrad; the document scales the statistics of the SI values, which
/// can differ in the last bit).
#[derive(Clone, Debug, Default)]
pub struct SizeTableRow {
    pub mean_mm: Option<f64>,
    pub range_mm: Option<[f64; 2]>,
    pub median_mm: Option<f64>,
    pub orientation_mrad: Option<f64>,
}

/// A transfer of the whole-session model to another session.
#[derive(Clone, Debug, Serialize)]
pub struct TransferFigures {
    pub model: String,
    pub session: String,
    pub errors: Outcome,
    pub kappa_scaled: Option<f64>,
    /// Base or tool parameters held in every model's refit on this session because some refit
    /// left them undetermined (the notes say so too).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub held: Vec<String>,
}

fn orientation_figures(o: &Option<crate::validate::stats::ErrorStats>) -> Option<OrientationFigures> {
    o.map(|o| OrientationFigures {
        mean_mrad: o.mean * PER_MRAD,
        median_mrad: o.median * PER_MRAD,
        p95_mrad: o.p95 * PER_MRAD,
        max_mrad: o.max * PER_MRAD,
    })
}

impl SessionFigures {
    fn of(s: &SessionHeldOut) -> Self {
        SessionFigures {
            session: s.session.clone(),
            n: s.position.n,
            position: ErrorFigures::of(&s.position),
            orientation: orientation_figures(&s.orientation),
        }
    }

    /// mean, median, p95, max (mm) and the orientation mean (mrad), as table cells.
    fn cells(&self) -> String {
        let p = &self.position;
        let o = self.orientation.as_ref().map_or("      —".to_string(), |o| format!("{:7.3}", o.mean_mrad));
        format!("{:7.3} {:7.3} {:7.3} {:7.3} {}", p.mean_mm, p.median_mm, p.p95_mm, p.max_mm, o)
    }
}

impl HeldOutFigures {
    /// The figures of `h`; its per-session breakdown when `several` sessions were split.
    fn of(h: &HeldOut, several: bool) -> Self {
        HeldOutFigures {
            n: h.position.n,
            position: ErrorFigures::of(&h.position),
            mean_se_mm: h.mean_se.map(|v| v / MM),
            orientation: orientation_figures(&h.orientation),
            per_session: if several { h.per_session.iter().map(SessionFigures::of).collect() } else { Vec::new() },
            unscored: h
                .unscored
                .iter()
                .map(|(session, n)| UnscoredFigures { session: session.clone(), n: *n })
                .collect(),
        }
    }

    /// mean, median, p95, max (mm) and the orientation mean (mrad), as table cells.
    fn cells(&self) -> String {
        let p = &self.position;
        let o = self.orientation.as_ref().map_or("      —".to_string(), |o| format!("{:7.3}", o.mean_mrad));
        format!("{:7.3} {:7.3} {:7.3} {:7.3} {}", p.mean_mm, p.median_mm, p.p95_mm, p.max_mm, o)
    }
}

impl Outcome {
    fn of(r: &Result<HeldOut, String>, several: bool) -> Self {
        match r {
            Ok(h) => Outcome::HeldOut(HeldOutFigures::of(h, several)),
            Err(e) => Outcome::Refused { refused: e.clone() },
        }
    }

    fn refused(&self) -> Option<&str> {
        match self {
            Outcome::Refused { refused } => Some(refused),
            Outcome::HeldOut(_) => None,
        }
    }
}

/// Every draw of the size succeeded and observed orientations.
fn all_oriented(s: &SizeResult) -> bool {
    s.draws.iter().all(|d| d.as_ref().is_ok_and(|h| h.orientation.is_some()))
}

impl SizeFigures {
    fn of(s: &SizeResult, sessions: &[String]) -> Self {
        let scaled = |q: Option<[f64; 5]>, scale: f64| q.map(|q| q.map(|v| v * scale));
        let mean_q = s.quartiles(|h| h.position.mean);
        let several = sessions.len() > 1;
        let session_mean = |name: &String| {
            let v: Vec<f64> = s
                .draws
                .iter()
                .filter_map(|d| d.as_ref().ok())
                .filter_map(|h| h.per_session.iter().find(|x| x.session == *name))
                .map(|x| x.position.mean / MM)
                .collect();
            SessionMean {
                session: name.clone(),
                mean_mm: (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64),
            }
        };
        SizeFigures {
            model: s.variant.clone(),
            n: s.n,
            refused: s.draws.iter().filter(|d| d.is_err()).count(),
            mean_mm_over_draws: s.mean(|h| h.position.mean).map(|v| v / MM),
            per_session_mean_mm_over_draws: if several {
                sessions.iter().map(session_mean).collect()
            } else {
                Vec::new()
            },
            mean_mm_quartiles: scaled(mean_q, 1.0 / MM),
            median_mm_quartiles: scaled(s.quartiles(|h| h.position.median), 1.0 / MM),
            orientation_mean_mrad_quartiles: scaled(
                if all_oriented(s) { s.quartiles(|h| h.orientation.map_or(f64::NAN, |o| o.mean)) } else { None },
                PER_MRAD,
            ),
            draws: s.draws.iter().map(|d| Outcome::of(d, several)).collect(),
            table: SizeTableRow {
                mean_mm: s.mean(|h| h.position.mean / MM),
                range_mm: mean_q.map(|q| [q[0] / MM, q[4] / MM]),
                median_mm: s.quartiles(|h| h.position.median / MM).map(|q| q[2]),
                orientation_mrad: if all_oriented(s) {
                    s.mean(|h| h.orientation.map_or(f64::NAN, |o| o.mean) * PER_MRAD)
                } else {
                    None
                },
            },
        }
    }
}

impl CrossvalReport {
    pub fn new(cv: &Crossval, seed: u64, folds: usize, draws: usize, seconds: f64, threads: usize) -> Self {
        let several = cv.sessions.len() > 1;
        CrossvalReport {
            session: cv.sessions.join(","),
            sessions: cv.sessions.clone(),
            measurements: cv.measurements,
            poses: several.then_some(cv.poses),
            seed,
            folds,
            draws,
            kfold: cv
                .folds
                .iter()
                .map(|f| KfoldFigures {
                    model: f.variant.clone(),
                    parameters_identified: f.identified,
                    pooled: f.pooled.as_ref().map(|h| HeldOutFigures::of(h, several)),
                    vs_previous: f.vs_previous.map(|(c, se)| PairedChange { change_mm: c / MM, se_mm: se / MM }),
                    per_fold: f.per_fold.iter().map(|r| Outcome::of(r, several)).collect(),
                })
                .collect(),
            sizes: cv.sizes.iter().map(|s| SizeFigures::of(s, &cv.sessions)).collect(),
            transfer: cv
                .transfer
                .iter()
                .map(|t| TransferFigures {
                    model: t.variant.clone(),
                    session: t.session.clone(),
                    errors: Outcome::of(&t.errors, false),
                    kappa_scaled: t.kappa_scaled,
                    held: t.held.clone(),
                })
                .collect(),
            quartiles: "min, q1, median, q3, max over the draws",
            notes: cv.notes.clone(),
            outliers: cv
                .outliers
                .iter()
                .map(|(session, index)| MeasurementFigure { session: session.clone(), index: *index })
                .collect(),
            excluded: Vec::new(),
            seconds,
            threads,
        }
    }

    /// The tables: k-fold, few poses, transfer (each when there is one); with several sessions,
    /// each split scheme's figures per session too.
    pub fn text(&self) -> String {
        let mut text = match self.poses {
            Some(poses) => format!(
                "sessions {} ({} measurements at {poses} poses, split by pose), {:.1} s on {} threads\n",
                self.session, self.measurements, self.seconds, self.threads
            ),
            None => format!(
                "session {} ({} measurements), {:.1} s on {} threads\n",
                self.session, self.measurements, self.seconds, self.threads
            ),
        };
        for note in &self.notes {
            text.push_str(&format!("note: {note}\n"));
        }
        if !self.kfold.is_empty() {
            text.push_str(&format!(
                "\n{}-fold cross-validation, pooled held-out errors (mm; orientation mrad)\n",
                self.folds
            ));
            text.push_str(&format!(
                "{:<24} {:>6} {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} {:>17}\n",
                "model", "params", "mean", "median", "p95", "max", "ori", "s.e.", "vs above ± s.e."
            ));
            for f in &self.kfold {
                let r = match (&f.pooled, f.per_fold.iter().find_map(Outcome::refused)) {
                    (Some(h), _) => format!(
                        "{} {} {}",
                        h.cells(),
                        h.mean_se_mm.map_or("      —".into(), |v| format!("{v:7.4}")),
                        f.vs_previous
                            .as_ref()
                            .map_or(format!("{:>17}", "—"), |c| format!("{:>+9.4} ± {:<6.4}", c.change_mm, c.se_mm))
                    ),
                    (None, Some(e)) => format!("refused: {e}"),
                    (None, None) => "—".into(),
                };
                text.push_str(&format!("{:<24} {:>6} {}\n", f.model, f.parameters_identified, r));
            }
            text.push_str(
                "(s.e.: of the mean, the measurements grouped by pose; vs above: the change of the mean from the model in the row above on the same held-out measurements)\n",
            );
            if self.poses.is_some() {
                text.push_str(&format!(
                    "\n{}-fold cross-validation per session: the held-out poses' errors of each (mm; orientation mrad)\n",
                    self.folds
                ));
                text.push_str(&format!(
                    "{:<24} {:<12} {:>6} {:>7} {:>7} {:>7} {:>7} {:>7}\n",
                    "model", "session", "n", "mean", "median", "p95", "max", "ori"
                ));
                for f in &self.kfold {
                    for s in f.pooled.iter().flat_map(|h| &h.per_session) {
                        text.push_str(&format!("{:<24} {:<12} {:>6} {}\n", f.model, s.session, s.n, s.cells()));
                    }
                }
            }
        }
        if !self.sizes.is_empty() {
            text.push_str(&format!(
                "\nfew poses: identify on n poses of a random half, test on the other half; over {} draws: mean, [min, max] of each draw's mean, median of the medians (mm); orientation mean (mrad)\n",
                self.draws
            ));
            text.push_str(&format!(
                "{:<24} {:>5} {:>7} {:>17} {:>7} {:>7} {:>7}\n",
                "model", "n", "mean", "[min, max]", "median", "ori", "refused"
            ));
            let f3 = |v: Option<f64>| v.map_or_else(|| "      —".to_string(), |v| format!("{v:7.3}"));
            for s in &self.sizes {
                let t = &s.table;
                let range = t.range_mm.map_or_else(|| "—".to_string(), |[lo, hi]| format!("[{lo:.3}, {hi:.3}]"));
                text.push_str(&format!(
                    "{:<24} {:>5} {} {:>17} {} {} {:>7}\n",
                    s.model,
                    s.n,
                    f3(t.mean_mm),
                    range,
                    f3(t.median_mm),
                    f3(t.orientation_mrad),
                    s.refused
                ));
            }
            if self.poses.is_some() {
                text.push_str("\nfew poses per session: mean over the draws of each draw's mean (mm)\n");
                text.push_str(&format!(
                    "{:<24} {:>5} {}\n",
                    "model",
                    "n",
                    self.sessions.iter().map(|s| format!("{s:>12}")).collect::<String>()
                ));
                for s in &self.sizes {
                    let cells: String = s
                        .per_session_mean_mm_over_draws
                        .iter()
                        .map(|m| format!("{:>12}", f3(m.mean_mm).trim()))
                        .collect();
                    text.push_str(&format!("{:<24} {:>5} {}\n", s.model, s.n, cells));
                }
            }
        }
        if !self.transfer.is_empty() {
            text.push_str(&format!(
                "\ntransfer: identified on all of {}, base and tools refitted on each session (mm; orientation mrad)\n",
                self.session
            ));
            text.push_str(&format!(
                "{:<24} {:<12} {:>7} {:>7} {:>7} {:>7} {:>7} {:>8}\n",
                "model", "session", "mean", "median", "p95", "max", "ori", "κ refit"
            ));
            for t in &self.transfer {
                let r = match &t.errors {
                    Outcome::HeldOut(h) => format!("{} {:>8.0}", h.cells(), t.kappa_scaled.unwrap_or(f64::NAN)),
                    Outcome::Refused { refused } => format!("refused: {refused}"),
                };
                text.push_str(&format!("{:<24} {:<12} {}\n", t.model, t.session, r));
            }
        }
        text
    }

    /// What a user of this command can do about the outliers refused fits named (`cell`: the cell
    /// file's path): run again with them left out (with those this run left out), or see the fit
    /// without them or with identify's `--huber`.
    pub fn outlier_advice(&self, cell: &str) -> String {
        if self.outliers.is_empty() {
            return String::new();
        }
        let mut sessions: Vec<&str> = self.session.split(',').collect();
        for m in &self.outliers {
            if !sessions.contains(&m.session.as_str()) {
                sessions.push(&m.session);
            }
        }
        // A handful is named; the command to check the fit without them lists every one (with
        // five of ten it is refused again for the rest), up to a number that points at the data
        // rather than at outliers (a shared TCP, sessions in different frames).
        const SHOWN: usize = 5;
        const LISTED: usize = 50;
        let n = self.outliers.len();
        let named: Vec<String> =
            self.outliers.iter().take(SHOWN).map(|m| format!("{}[{}]", m.session, m.index)).collect();
        let refs: Vec<String> = self
            .outliers
            .iter()
            .take(if n > LISTED { SHOWN } else { n })
            .map(|m| format!("{}:{}", m.session, m.index))
            .collect();
        // The next run leaves out what this one did, and these.
        let mut all: Vec<String> = self.excluded.iter().map(|m| format!("{}:{}", m.session, m.index)).collect();
        for r in refs {
            if !all.contains(&r) {
                all.push(r);
            }
        }
        let more = match n {
            n if n > LISTED => format!(
                " and {} more (so many point at the data: a shared TCP, sessions in different frames; the command below names the first {SHOWN})",
                n - SHOWN
            ),
            n if n > SHOWN => format!(" and {} more", n - SHOWN),
            _ => String::new(),
        };
        format!(
            "\noutliers named by the refused fits: {}{more}. Cross-validate without them with `robocal crossval {cell} --session {} --exclude {}` (and the other options of this run); see the fit without them with `robocal identify {cell} --sessions {} --exclude {}` (or `--huber 2.5`)\n",
            named.join(", "),
            self.session,
            all.join(","),
            sessions.join(","),
            all.join(",")
        )
    }
}

/// `robocal bench-diagnosis`: the withheld-effect suite, per case and overall, with the confusion
/// matrix (rows: cases; columns: what the verdict said — the first named kind, or the status).
#[derive(Clone, Debug, Serialize)]
pub struct BenchDiagnosisReport {
    pub summary: BenchSummary,
    pub cases: Vec<BenchCase>,
    /// Column labels of the confusion matrix, in order.
    pub columns: Vec<String>,
    pub confusion: Vec<ConfusionRow>,
    pub outcomes: Vec<BenchOutcome>,
    #[serde(skip)]
    pub errors: usize,
    #[serde(skip)]
    pub threads: usize,
}

#[derive(Clone, Debug, Serialize)]
pub struct BenchSummary {
    /// Top-1 naming on the cases whose effect these data separate: named, right kind first, right
    /// joint (and harmonic).
    pub separable_runs: usize,
    pub separable_correct: usize,
    /// Verdicts other than `none` on the no-effect cases.
    pub no_effect_runs: usize,
    pub false_alarms: usize,
    /// `not_separable` where the data cannot separate the effect.
    pub not_separable_runs: usize,
    pub not_separable_correct: usize,
    /// Out-of-library link bending: runs, and those named (must be none).
    pub link_bending_runs: usize,
    pub link_bending_named: usize,
    /// `named` with another effect than the withheld one, over every run.
    pub confident_wrong_names: usize,
    /// Gap closure of the named model relative to the oracle's (true effect added): runs with an
    /// oracle and a named effect, those at ≥ 0.8, and the median ratio.
    pub closure_runs: usize,
    pub closure_at_least_0_8: usize,
    pub median_closure_ratio: Option<f64>,
    pub runs: usize,
    pub seconds: f64,
    pub median_seconds_per_case: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct BenchCase {
    pub name: String,
    pub effects: String,
    pub expect: String,
    pub runs: usize,
    pub correct: usize,
    pub wrong_names: usize,
    pub heldout_mean_mm: f64,
    pub floor_mean_mm: f64,
    pub final_mean_mm: f64,
    pub oracle_mean_mm: Option<f64>,
    pub median_closure_ratio: Option<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct ConfusionRow {
    pub case: String,
    /// Count per column of `columns`.
    pub counts: Vec<usize>,
}

#[derive(Clone, Debug, Serialize)]
pub struct BenchOutcome {
    pub case: String,
    pub seed: u64,
    pub status: &'static str,
    pub first: Option<String>,
    pub summary: String,
    pub correct: bool,
    pub wrong_name: bool,
    pub heldout_mean_mm: f64,
    pub floor_mean_mm: f64,
    pub final_mean_mm: f64,
    pub oracle_mean_mm: Option<f64>,
    pub closure_ratio: Option<f64>,
    /// The first round's best confirmed candidate: its share of what a smooth function of the
    /// configuration explains beyond the model, and whether it lies inside the smoother's span.
    pub share: Option<f64>,
    pub within_smoother: Option<bool>,
    pub closure: Option<f64>,
    pub seconds: f64,
    pub error: Option<String>,
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    Some(crate::validate::stats::quantile(&v, 0.5))
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.filter(|x| x.is_finite()).fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    if n == 0 { f64::NAN } else { s / n as f64 }
}

/// The column of the confusion matrix an outcome falls in.
fn column(o: &crate::experiments::withheld::Outcome) -> String {
    use crate::diagnose::Status;
    match o.status {
        Status::Named => format!("named: {}", o.first.as_deref().and_then(|f| f.split(' ').next()).unwrap_or("?")),
        s => s.as_str().to_string(),
    }
}

impl BenchDiagnosisReport {
    pub fn new(
        cases: &[crate::experiments::withheld::Case],
        outcomes: &[crate::experiments::withheld::Outcome],
        seconds: f64,
        threads: usize,
    ) -> Self {
        use crate::experiments::withheld::Expect;
        let mut columns: Vec<String> = outcomes.iter().map(column).collect();
        columns.sort();
        columns.dedup();
        let mut summary = BenchSummary {
            separable_runs: 0,
            separable_correct: 0,
            no_effect_runs: 0,
            false_alarms: 0,
            not_separable_runs: 0,
            not_separable_correct: 0,
            link_bending_runs: 0,
            link_bending_named: 0,
            confident_wrong_names: outcomes.iter().filter(|o| o.wrong_name).count(),
            closure_runs: 0,
            closure_at_least_0_8: 0,
            median_closure_ratio: median(outcomes.iter().filter_map(|o| o.closure_ratio).collect()),
            runs: outcomes.len(),
            seconds,
            median_seconds_per_case: median(outcomes.iter().map(|o| o.seconds).collect()).unwrap_or(0.0),
        };
        let mut case_rows = Vec::new();
        let mut confusion = Vec::new();
        for c in cases {
            let mine: Vec<&crate::experiments::withheld::Outcome> =
                outcomes.iter().filter(|o| o.case == c.name).collect();
            let correct = mine.iter().filter(|o| o.correct).count();
            match &c.expect {
                Expect::Named { .. } => {
                    summary.separable_runs += mine.len();
                    summary.separable_correct += correct;
                    for o in &mine {
                        if o.status == crate::diagnose::Status::Named
                            && let Some(r) = o.closure_ratio
                        {
                            summary.closure_runs += 1;
                            summary.closure_at_least_0_8 += (r >= 0.8) as usize;
                        }
                    }
                }
                Expect::None => {
                    summary.no_effect_runs += mine.len();
                    summary.false_alarms += mine.len() - correct;
                }
                Expect::NotSeparable => {
                    summary.not_separable_runs += mine.len();
                    summary.not_separable_correct += correct;
                }
                Expect::NotNamed | Expect::NoName => {
                    summary.link_bending_runs += mine.len();
                    summary.link_bending_named +=
                        mine.iter().filter(|o| o.status == crate::diagnose::Status::Named).count();
                }
                Expect::NoWrongName => {}
            }
            case_rows.push(BenchCase {
                name: c.name.clone(),
                effects: c.effects.clone(),
                expect: format!("{:?}", c.expect),
                runs: mine.len(),
                correct,
                wrong_names: mine.iter().filter(|o| o.wrong_name).count(),
                heldout_mean_mm: mean(mine.iter().map(|o| o.heldout_mean)) / MM,
                floor_mean_mm: mean(mine.iter().map(|o| o.floor_mean)) / MM,
                final_mean_mm: mean(mine.iter().map(|o| o.final_mean)) / MM,
                oracle_mean_mm: {
                    let m = mean(mine.iter().filter_map(|o| o.oracle_mean));
                    m.is_finite().then_some(m / MM)
                },
                median_closure_ratio: median(mine.iter().filter_map(|o| o.closure_ratio).collect()),
            });
            confusion.push(ConfusionRow {
                case: c.name.clone(),
                counts: columns.iter().map(|col| mine.iter().filter(|o| column(o) == *col).count()).collect(),
            });
        }
        let out = outcomes
            .iter()
            .map(|o| BenchOutcome {
                case: o.case.clone(),
                seed: o.seed,
                status: o.status.as_str(),
                first: o.first.clone(),
                summary: o.summary.clone(),
                correct: o.correct,
                wrong_name: o.wrong_name,
                heldout_mean_mm: o.heldout_mean / MM,
                floor_mean_mm: o.floor_mean / MM,
                final_mean_mm: o.final_mean / MM,
                oracle_mean_mm: o.oracle_mean.map(|v| v / MM),
                closure_ratio: o.closure_ratio,
                share: o.share.map(|s| s.0),
                within_smoother: o.share.map(|s| s.1),
                closure: o.closure,
                seconds: o.seconds,
                error: o.error.clone(),
            })
            .collect();
        BenchDiagnosisReport {
            summary,
            cases: case_rows,
            columns,
            confusion,
            outcomes: out,
            errors: outcomes.iter().filter(|o| o.error.is_some()).count(),
            threads,
        }
    }

    /// The same tables as Markdown (for BENCHMARKS.md): per case, the confusion matrix, the summary.
    pub fn markdown(&self) -> String {
        let s = &self.summary;
        let mut t = String::from(
            "| case | withheld | runs | correct | held-out mean, mm | floor, mm | final, mm | oracle, mm | closure / oracle's |\n\
             |---|---|---:|---:|---:|---:|---:|---:|---:|\n",
        );
        for c in &self.cases {
            t.push_str(&format!(
                "| {} | `{}` | {} | {}/{} | {:.4} | {:.4} | {:.4} | {} | {} |\n",
                c.name,
                if c.effects.is_empty() { "–" } else { &c.effects },
                c.runs,
                c.correct,
                c.runs,
                c.heldout_mean_mm,
                c.floor_mean_mm,
                c.final_mean_mm,
                c.oracle_mean_mm.map_or("–".into(), |v| format!("{v:.4}")),
                c.median_closure_ratio.map_or("–".into(), |v| format!("{v:.2}")),
            ));
        }
        t.push_str("\nConfusion matrix (rows: cases; columns: the verdict, i.e. the first named kind or the status):\n\n| case |");
        for c in &self.columns {
            t.push_str(&format!(" {c} |"));
        }
        t.push_str("\n|---|");
        t.push_str(&"---:|".repeat(self.columns.len()));
        t.push('\n');
        for r in &self.confusion {
            t.push_str(&format!("| {} |", r.case));
            for n in &r.counts {
                t.push_str(&format!(" {} |", if *n == 0 { ".".to_string() } else { n.to_string() }));
            }
            t.push('\n');
        }
        t.push_str(&format!(
            "\n| overall | measured | target |\n|---|---:|---:|\n\
             | top-1 naming, separable effects (right kind, joint, harmonic) | {}/{} | ≥ 90 % |\n\
             | false alarms, no effect | {}/{} | ≤ 5 % |\n\
             | `not_separable` where the data cannot separate | {}/{} | all |\n\
             | link bending named | {}/{} | 0 |\n\
             | confident wrong names, all runs | {}/{} | 0 |\n\
             | gap closure ≥ 0.8 of the oracle's | {}/{} (median ratio {}) | all |\n\
             | wall clock | {:.0} s for {} runs on {} threads | ≤ 600 s |\n",
            s.separable_correct,
            s.separable_runs,
            s.false_alarms,
            s.no_effect_runs,
            s.not_separable_correct,
            s.not_separable_runs,
            s.link_bending_named,
            s.link_bending_runs,
            s.confident_wrong_names,
            s.runs,
            s.closure_at_least_0_8,
            s.closure_runs,
            s.median_closure_ratio.map_or("–".into(), |v| format!("{v:.3}")),
            s.seconds,
            s.runs,
            self.threads
        ));
        t
    }

    pub fn text(&self) -> String {
        let s = &self.summary;
        let pct = |a: usize, b: usize| {
            if b == 0 { "–".to_string() } else { format!("{:.1} %", 100.0 * a as f64 / b as f64) }
        };
        let mut t = String::new();
        t.push_str(&format!(
            "{:<38} {:>4} {:>7} {:>8} {:>8} {:>8} {:>8} {:>7}\n",
            "case", "runs", "correct", "held mm", "floor mm", "final mm", "oracle", "closure"
        ));
        for c in &self.cases {
            t.push_str(&format!(
                "{:<38} {:>4} {:>7} {:>8.4} {:>8.4} {:>8.4} {:>8} {:>7}\n",
                c.name,
                c.runs,
                format!("{}/{}", c.correct, c.runs),
                c.heldout_mean_mm,
                c.floor_mean_mm,
                c.final_mean_mm,
                c.oracle_mean_mm.map_or("–".into(), |v| format!("{v:.4}")),
                c.median_closure_ratio.map_or("–".into(), |v| format!("{v:.2}")),
            ));
        }
        t.push_str("\nconfusion (rows: case; columns: the verdict — the first named kind, or the status)\n");
        t.push_str(&format!("{:<38}", ""));
        for c in &self.columns {
            t.push_str(&format!(" {:>22}", c));
        }
        t.push('\n');
        for r in &self.confusion {
            t.push_str(&format!("{:<38}", r.case));
            for n in &r.counts {
                t.push_str(&format!(" {:>22}", if *n == 0 { ".".to_string() } else { n.to_string() }));
            }
            t.push('\n');
        }
        t.push_str(&format!(
            "\ntop-1 naming (separable effects, right joint and harmonic): {}/{} = {}\n",
            s.separable_correct,
            s.separable_runs,
            pct(s.separable_correct, s.separable_runs)
        ));
        t.push_str(&format!(
            "false alarms (no effect): {}/{} = {}\n",
            s.false_alarms,
            s.no_effect_runs,
            pct(s.false_alarms, s.no_effect_runs)
        ));
        t.push_str(&format!(
            "not_separable where the data cannot separate: {}/{} = {}\n",
            s.not_separable_correct,
            s.not_separable_runs,
            pct(s.not_separable_correct, s.not_separable_runs)
        ));
        t.push_str(&format!("link bending named: {}/{}\n", s.link_bending_named, s.link_bending_runs));
        t.push_str(&format!("confident wrong names (all runs): {}/{}\n", s.confident_wrong_names, s.runs));
        t.push_str(&format!(
            "gap closure ≥ 0.8 of the oracle's: {}/{} (median ratio {})\n",
            s.closure_at_least_0_8,
            s.closure_runs,
            s.median_closure_ratio.map_or("–".into(), |v| format!("{v:.3}"))
        ));
        t.push_str(&format!(
            "{} runs in {:.1} s on {} threads (median {:.2} s per case: simulate, identify, diagnose, oracle)\n",
            s.runs, s.seconds, self.threads, s.median_seconds_per_case
        ));
        t
    }
}
