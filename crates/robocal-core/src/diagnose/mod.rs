//! The sim-to-real diagnosis: where the calibrated model still misses, which physical effect it
//! is missing, and how far the held-out error shrinks once that effect is added (DIAGNOSIS.md).
//! Pure math, like `identify/`: no I/O; SI units; `domain::diagnosis` writes the wire format.
//!
//! The pipeline:
//! 1. the current model (the parameter set's structure) is refitted on the pooled data —
//!    identification and validation sessions, weighted by the instrument model, its geometry
//!    anchored to the set's values — and linearised ([`stage`]);
//! 2. the held-out error is decomposed into the noise floor, the extrapolation gap and the
//!    unmodelled gap (`floor`);
//! 3. where the misses lie (`locate`);
//! 4. which effect: screening, confirmation on held-out poses, greedy acceptance and honest
//!    verdicts (`search`, [`library`], `screen`, [`cv`]);
//! 5. how far it shrinks: the held-out figures of every accepted model, and last of the model
//!    with an unknown payload that the named terms determine, when it predicts held-out poses
//!    better (`search::adopt_payload`).
//!
//! Held-out means: grouped K-fold cross-validation over the validation poses, every fold's model
//! trained on all identification measurements and the other folds (the "refit with part of the
//! validation poses added" of the decomposition); without a validation session, over the
//! identification poses themselves.

pub mod cv;
pub mod drift;
mod evidence;
pub(crate) mod floor;
pub mod library;
pub(crate) mod linalg;
pub(crate) mod locate;
pub(crate) mod refit;
pub(crate) mod screen;
pub(crate) mod search;
pub mod stage;
pub(crate) mod stats;
mod verdict;

use nalgebra::Vector3;

use crate::cell::order::{self, ApproachSource};
use crate::cell::{Cell, Purpose};
use crate::identify::{Anchor, Identification, IdentifyError, IdentifyOptions, ModelOptions, NoiseModel, identify};
use crate::kinematics::{JointTerm, Param, ParamLayout, ParameterSet, Unit};
use crate::validate::report::{Reference, validate};
use crate::validate::stats::ErrorStats;
use cv::Folds;
use evidence::evidence;
pub use evidence::{Evidence, EvidenceBin, EvidenceVariable};
pub use floor::Floor;
use library::{Candidate, Kind, Unavailable};
pub use locate::{Against, Axis, Voxel, Where};
pub use screen::Score;
pub use search::{Apart, Decision, Evaluated, Round, Screened, SearchOptions};
pub use stats::PairedChange;
pub use verdict::experiment;
use verdict::verdict;

/// Everything a diagnosis can be told.
#[derive(Clone, Debug, PartialEq)]
pub struct DiagnoseOptions {
    /// Identification sessions (empty: every identification session of the cell).
    pub identification: Vec<String>,
    /// Validation sessions (`None`: every validation session of the cell; empty, or none in the
    /// cell: cross-validate on the identification sessions).
    pub validation: Option<Vec<String>>,
    /// The instrument model: the weights of the pooled fits (the instrument's σ, not the readings'
    /// own) and the noise floor.
    pub noise: NoiseModel,
    /// K of the grouped K-fold cross-validation (at least 2, with at least 2K tested poses).
    pub folds: usize,
    /// Seed of the folds' random assignment of poses and of the floor's Monte Carlo.
    pub seed: u64,
    /// κ limit of the pooled fits (scaled columns).
    pub kappa_limit: f64,
    /// m per rad for orientation rows.
    pub rotation_weight: f64,
    /// Weak prior on the geometry of the pooled fits, towards the parameter set's values.
    pub anchor: Anchor,
    /// Thresholds and sizes of the search.
    pub search: SearchOptions,
    /// Edge of the workspace voxels, m (0: about ten tested positions per voxel on average over
    /// the positions' bounding box).
    pub voxel_size: f64,
    /// False-discovery rate of the voxel tests.
    pub fdr: f64,
    /// Sessions of other set-ups to carry the starting and the final model to, base and tools
    /// refitted there (how a calibration transfers).
    pub transfer: Vec<String>,
    /// κ limit of those refits (base and tools are nuisance parameters there).
    pub transfer_kappa_limit: f64,
    /// Base or tool parameters kept at the model's values in those refits.
    pub transfer_fixed: Vec<String>,
    /// Threads for the held-out refits (1: sequential).
    pub threads: usize,
    /// Readings left out of every fit and every test, (session, 0-based index in it): the
    /// outliers an identification refused and was given as `exclude`. Only diagnosed sessions'.
    pub exclude: Vec<(String, usize)>,
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        Self {
            identification: Vec::new(),
            validation: None,
            noise: NoiseModel::default(),
            folds: 5,
            seed: 1,
            kappa_limit: 1e4,
            rotation_weight: 0.1,
            anchor: Anchor::default(),
            search: SearchOptions::default(),
            voxel_size: 0.0,
            fdr: 0.05,
            transfer: Vec::new(),
            transfer_kappa_limit: 1e4,
            transfer_fixed: Vec::new(),
            threads: 1,
            exclude: Vec::new(),
        }
    }
}

/// What is diagnosed: a cell's measurements and a calibrated parameter set.
#[derive(Clone, Debug)]
pub struct Input<'a> {
    /// The cell: robot model, sessions and measurements.
    pub cell: &'a Cell,
    /// The calibrated parameter set: the starting model's structure and values.
    pub set: &'a ParameterSet,
    /// Per layout entry of `set`: whether its identification fitted it. `None`: a parameter is
    /// taken as fitted when its value differs from its nominal.
    pub identified: Option<Vec<bool>>,
    /// Parameters the set's identification held fixed on the user's request (kept fixed).
    pub fixed: Vec<String>,
    /// The readings the set's identification was told to leave out (outliers it refused): (session,
    /// index as recorded, fingerprint when recorded). Those this cell holds — found by their
    /// content where a fingerprint is recorded, by the index otherwise — are left out of every fit
    /// and every test, as the options' `exclude`.
    pub excluded: Vec<(String, usize, Option<String>)>,
}

impl Input<'_> {
    /// Whether the set's identification fitted its `i`-th layout entry ([`Input::identified`]).
    fn fitted(&self, i: usize) -> bool {
        match &self.identified {
            Some(f) => f.get(i).copied().unwrap_or(false),
            None => self.set.values[i] != self.set.nominal[i],
        }
    }

    /// Whether the set's identification held an undeclared payload (its data did not determine
    /// the mass): the set carries `tool_mass` and did not fit it.
    fn payload_held(&self) -> bool {
        self.set.layout.index_of(Param::ToolMass).is_some_and(|i| !self.fitted(i))
    }
}

/// Why a diagnosis was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DiagnoseError {
    /// The options do not fit the cell or its data (the message says how): an unknown session, a
    /// session named for both identification and validation, no identification session, fewer
    /// than 2 folds, fewer than 2 tested poses per fold.
    #[error("{0}")]
    Option(String),
    /// The starting model cannot be set up on the pooled data (measurements, registration, an
    /// option, too few rows). A fit that diverges or is refused for its conditioning is not an
    /// error: the model is then linearised at the parameter set ([`Diagnosis::start_note`]).
    #[error("the current model on the pooled data: {0}")]
    Identify(#[from] IdentifyError),
}

/// The verdict's status; on the wire and in files, its snake_case name (`not_separable`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema), schema(as = VerdictStatus))]
pub enum Status {
    /// One or more effects named, each confirmed on held-out poses.
    Named,
    /// No effect above the floor.
    None,
    /// An effect is likely but these data cannot tell it from the current model or from a
    /// look-alike.
    NotSeparable,
    /// Structure no candidate explains.
    UnknownEffect,
    /// A library term explains part of what a smooth function of the configuration explains,
    /// not most of it: named as a partial explanation with its share, the rest unexplained.
    Partial,
}

impl std::fmt::Display for Status {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl Status {
    /// The snake_case name, as on the wire and in files.
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Named => "named",
            Status::None => "none",
            Status::NotSeparable => "not_separable",
            Status::UnknownEffect => "unknown_effect",
            Status::Partial => "partial",
        }
    }
}

/// One parameter of an effect: value and standard deviation, SI.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamEstimate {
    /// The parameter.
    pub param: Param,
    /// Its value, SI.
    pub value: f64,
    /// Its standard deviation in the model that accepted the effect, SI, at the data's own scale:
    /// the larger of σ̂²(JᵀWJ)⁻¹ (σ̂² the weighted residual per degree of freedom) and the
    /// cluster-robust σ with the readings of one stop grouped, as an identification reports it;
    /// `None` for a suspect (its value is then the screening's linear estimate) and for a
    /// parameter that model holds fixed.
    pub std: Option<f64>,
}

/// A named (or suspected) effect.
#[derive(Clone, Debug, PartialEq)]
pub struct Effect {
    /// The candidate it stands for.
    pub candidate: Candidate,
    /// Its size in `unit` (SI): cyclic amplitude, backlash half-play, compliance, α, kg, …
    pub estimate: Option<f64>,
    /// Standard deviation of `estimate`, SI; `None` where it is not known (a suspect, a table).
    pub std: Option<f64>,
    /// The file unit of `estimate` (the values here are SI: [`Unit::to_si`]).
    pub unit: Unit,
    /// Its parameters: as fitted in the model that accepted it, or the screening's linear estimates
    /// for a suspect.
    pub parameters: Vec<ParamEstimate>,
    /// Held-out gain when added: mean and RMS of |e|, m.
    pub gain_mean: f64,
    /// For a named effect, both gains are those of the model refitted in full on the folds against
    /// the model before it; for a suspect, the linearised confirmation's (0 when it was not
    /// cross-validated).
    pub gain_rms: f64,
    /// Confirmation p-value (one-sided Wilcoxon) and the screening's Holm-corrected log10 p.
    pub confirm_p: Option<f64>,
    /// log10 of the screening's Holm-corrected p (F form of the score test).
    pub screen_log10_p: f64,
    /// Separability ρ = ‖J̃_k‖_F/‖J_k‖_F: the share of its columns the model before it cannot absorb
    /// (0: absorbed; 1: orthogonal to the model).
    pub separability: f64,
}

/// The conclusion of a diagnosis: its status, the named effects or the suspects, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Verdict {
    /// What the diagnosis concludes.
    pub status: Status,
    /// Named effects, most important (first accepted) first. For any other status, the suspects:
    /// not added to the model, each with the screening's one-step linear estimate and no σ.
    pub effects: Vec<Effect>,
    /// The verdict in a sentence or two, for the report.
    pub summary: String,
    /// A look-alike that the data cannot tell from the best (not_separable).
    pub lookalike: Option<Candidate>,
    /// The largest canonical correlation between the unabsorbed columns of the best and of the
    /// look-alike (not_separable with a look-alike).
    pub canonical_correlation: Option<f64>,
    /// Model parameters absorbing the suspect (name, share).
    pub absorbed_by: Vec<(String, f64)>,
    /// The experiment that would separate it.
    pub experiment: Option<String>,
    /// After the named effects: what remains (another verdict's status and summary), if any.
    pub remaining: Option<(Status, String)>,
}

/// Held-out figures of one model of the search.
#[derive(Clone, Debug, PartialEq)]
pub struct ShrinkEntry {
    /// The effects added to the starting model so far (labels).
    pub model: Vec<String>,
    /// Held-out |e| statistics of the model, m: refitted in full on the folds (the linearised folds'
    /// where that refit failed).
    pub stats: ErrorStats,
    /// (E_start − E)/(E_start − E_floor) on the mean; `None` for the starting model.
    pub closure: Option<f64>,
}

/// The starting model's error split into the noise floor, the extrapolation gap and the
/// unmodelled gap (means of |e|, m).
#[derive(Clone, Debug, PartialEq)]
pub struct Decomposition {
    /// The parameter set as given, on the validation poses (no refit); `None` without validation.
    pub calibrated: Option<ErrorStats>,
    /// The starting model cross-validated with the identification data and part of the
    /// validation poses.
    pub heldout: ErrorStats,
    /// The noise floor at the tested positions.
    pub floor: Floor,
    /// calibrated − held-out, on the mean (what coverage explains).
    pub extrapolation_gap: Option<f64>,
    /// held-out − floor, on the mean (what missing physics explains).
    pub unmodelled_gap: f64,
}

/// The whole diagnosis.
pub struct Diagnosis {
    /// The verdict.
    pub verdict: Verdict,
    /// The starting model's error decomposed.
    pub decomposition: Decomposition,
    /// Where the starting model misses.
    pub location: Where,
    /// The rounds of the search, in order.
    pub rounds: Vec<Round>,
    /// Held-out figures of the starting model and of each model the search accepted, in acceptance
    /// order.
    pub shrink: Vec<ShrinkEntry>,
    /// The weakest source of the approach directions backlash was screened with; `None` when it was
    /// not screened or no session has directions.
    pub approach: Option<ApproachSource>,
    /// Where the directions came from, said in sentences (derived from the order, not logged;
    /// sessions whose order is lost), when backlash was looked for.
    pub approach_notes: Vec<String>,
    /// Candidates these data cannot test, with the reason.
    pub unavailable: Vec<Unavailable>,
    /// Why the starting model could not be fitted on the pooled data (it was linearised at the
    /// parameter set instead), if so.
    pub start_note: Option<String>,
    /// The identification sessions used.
    pub identification: Vec<String>,
    /// The validation sessions used (empty: cross-validated on the identification sessions).
    pub validation: Vec<String>,
    /// The options of the final model (the starting model plus the accepted effects).
    pub model: IdentifyOptions,
    /// The final model fitted on the pooled data without anchors: what accepting produces.
    pub accepted: Option<Identification>,
    /// K of the cross-validation.
    pub folds: usize,
    /// Joints of the robot.
    pub dof: usize,
    /// Rows of the robot whose axis is parallel to the previous one (where β belongs).
    pub parallel_rows: usize,
    /// The starting and the final model carried to other sessions.
    pub transfer: Vec<Transfer>,
    /// The evidence of each accepted joint effect, in acceptance order.
    pub evidence: Vec<Evidence>,
    /// The readings left out of every fit and every test (session, index in the cell): the
    /// options' `exclude` and the set's identification's.
    pub excluded: Vec<(String, usize)>,
    /// What was left out for the set, in a sentence, when it left some readings out.
    pub excluded_note: Option<String>,
    /// The set's drift terms along its run, left out of every model here, in a sentence, when it
    /// has some.
    pub drift_note: Option<String>,
}

/// A model carried to another session, base and tools refitted there.
#[derive(Clone, Debug, PartialEq)]
pub struct Transfer {
    /// The transfer session.
    pub session: String,
    /// `start`, `start + <effect> + …` (the intermediate models of the search) or `final`.
    pub model: String,
    /// Position |e| statistics of the model on the session, its base and tools refitted there, m; or
    /// why that refit or its validation failed.
    pub errors: Result<ErrorStats, String>,
    /// κ of the column-scaled Jacobian of the base-and-tools refit.
    pub kappa_scaled: Option<f64>,
    /// The same errors split by whether the pose lies inside the joint ranges the model was
    /// identified on (every joint within the identification sessions' [min, max]): a term of the
    /// model (a table, a harmonic, a compliance) is only known where its joint was measured, and a
    /// transfer session outside those ranges tests extrapolation. `None` when the refit failed.
    pub range: Option<RangeSplit>,
    /// The change of the mean error from the starting model's, pose by pose on the same readings,
    /// with its standard error; `None` for the start itself, when either refit failed, or with
    /// too few poses for the standard error.
    pub change: Option<PairedChange>,
    /// Base or tool parameters held in every model's refit on this session, beyond the options'
    /// `transfer_fixed`: the session's data left them undetermined in some refit, and every model
    /// is carried with the same registration. Empty when the refits agreed.
    pub held: Vec<String>,
    /// The start and the final model registered with the joints' zero offsets refitted as well
    /// ([`ZerosRefit`]); `None` for the intermediate models.
    pub zeros: Option<Result<ZerosRefit, String>>,
}

/// A model carried to a transfer session with its joints' zero offsets refitted there as well as
/// base and tools, against base and tools alone, both held out: the session's readings are
/// split into alternate poses in measuring order, each half registers the model and the other
/// half is scored. A robot re-mastered between the set-ups, or whose zeros drifted, differs by a
/// constant angle per joint, which a base-and-tool registration cannot take. So does, in part, a
/// model error outside the identification's joint ranges (the verdict's clause on it has the figures). The
/// UR10's series B and D read θ2 +0.032° and +0.035° from series C (σ 0.005°, the registration's and the model's own combined).
#[derive(Clone, Debug, PartialEq)]
pub struct ZerosRefit {
    /// Held-out |e| with base and tools registered, m.
    pub base_tool: ErrorStats,
    /// Held-out |e| with the zeros registered too, m.
    pub with_zeros: ErrorStats,
    /// The change from `base_tool` to `with_zeros`, paired reading by reading in measuring order.
    pub change: Option<PairedChange>,
    /// Per zero offset the registration on the whole session frees: its name, its change from
    /// the model's value and the change's standard deviation (the registration's and the model's
    /// own, from disjoint data, combined), rad.
    pub shifts: Vec<(String, f64, f64)>,
}

/// A transfer's errors inside and outside the identification's joint ranges.
#[derive(Clone, Debug, PartialEq)]
pub struct RangeSplit {
    /// Per joint, the identification sessions' [min, max], rad.
    pub joints: Vec<[f64; 2]>,
    /// Poses inside every range / all poses.
    pub inside_share: f64,
    /// |e| statistics of the positions inside every range, m; `None` when there is none.
    pub inside: Option<ErrorStats>,
    /// |e| statistics of the positions outside a range, m; `None` when there is none.
    pub outside: Option<ErrorStats>,
    /// Per joint, the share of the transfer's poses outside that joint's range.
    pub outside_share_per_joint: Vec<f64>,
}

/// The identification sessions' joint ranges, rad (`None` without a measurement).
fn joint_ranges(cell: &Cell, sessions: &[String]) -> Option<Vec<[f64; 2]>> {
    let dof = cell.model.dof();
    let mut r = vec![[f64::INFINITY, f64::NEG_INFINITY]; dof];
    let mut any = false;
    for s in sessions.iter().filter_map(|n| cell.session(n)) {
        for m in &s.measurements {
            any = true;
            for (j, q) in m.q.iter().take(dof).enumerate() {
                r[j] = [r[j][0].min(*q), r[j][1].max(*q)];
            }
        }
    }
    any.then_some(r)
}

/// A transfer's residuals split by the identification's joint ranges.
fn range_split(cell: &Cell, ranges: &[[f64; 2]], residuals: &[crate::validate::report::Residual]) -> RangeSplit {
    let dof = ranges.len();
    let mut inside = Vec::new();
    let mut outside = Vec::new();
    let mut per_joint = vec![0usize; dof];
    for r in residuals {
        let Some(m) = cell.session(&r.session).and_then(|s| s.measurements.get(r.index)) else { continue };
        let mut ok = true;
        for (j, q) in m.q.iter().take(dof).enumerate() {
            if *q < ranges[j][0] || *q > ranges[j][1] {
                per_joint[j] += 1;
                ok = false;
            }
        }
        if ok { inside.push(r.error.norm()) } else { outside.push(r.error.norm()) }
    }
    let n = (inside.len() + outside.len()).max(1) as f64;
    RangeSplit {
        joints: ranges.to_vec(),
        inside_share: inside.len() as f64 / n,
        inside: ErrorStats::of(&inside),
        outside: ErrorStats::of(&outside),
        outside_share_per_joint: per_joint.iter().map(|&c| c as f64 / n).collect(),
    }
}

/// The starting model's identification options: the set's structure and values.
fn start_options(input: &Input<'_>, opts: &DiagnoseOptions, sessions: Vec<String>) -> IdentifyOptions {
    let set = input.set;
    let full = ParamLayout::full(&set.model);
    let fitted = |i: usize| input.fitted(i);
    let mut model = ModelOptions { beta: false, compliance: false, ..ModelOptions::default() };
    for (i, p) in set.layout.params().iter().enumerate() {
        match p {
            Param::Beta(_) | Param::Joint(_, JointTerm::Compliance) if fitted(i) => model.extra.push(*p),
            // A payload the identification held (not determined by its data) stays held.
            Param::ToolMass if !fitted(i) => {}
            // A drift along the set's run is a nuisance of that run, not a term of the robot: every
            // figure here predicts a reading at the run's mean, as the refits do, and the order is
            // tested for a drift by `where.order_drift` (its nuisance refit adds the terms back).
            // Kept, the screening would have predicted held-out readings at their place in the run
            // while the refitted figures predicted them at its mean. [`drift_left_out_note`].
            Param::Drift(..) => {}
            p if full.index_of(*p).is_none() => model.extra.push(*p),
            _ => {}
        }
    }
    let mut o = IdentifyOptions {
        model,
        fixed: input.fixed.clone(),
        kappa_limit: opts.kappa_limit,
        rotation_weight: opts.rotation_weight,
        start: Some(set.clone()),
        // Weighted by the instrument model, not by the readings' own σ: on the UR10 (series B–D
        // carry the tracker's σ) those made the extended model transfer worse to series B
        // (0.541 mm against 0.458 without the effects).
        noise: Some(NoiseModel { own: false, ..opts.noise.clone() }),
        map_smoothing: opts.search.map_smoothing,
        anchor: Some(opts.anchor.clone()),
        ..unrefused()
    };
    o.selection.sessions = sessions;
    o.selection.exclude = opts.exclude.clone();
    o
}

/// The sentence for a set identified with drift terms along its run (`--model +drift`), which the
/// diagnosis leaves out of every model ([`start_options`]): `None` when the set has none.
fn drift_left_out_note(set: &ParameterSet) -> Option<String> {
    let n = set.layout.params().iter().filter(|p| matches!(p, Param::Drift(..))).count();
    (n > 0).then(|| {
        format!(
            "the set's {n} drift terms along its measuring run are left out of every model here: the diagnosis predicts each reading at the run's mean, and tests the measuring order for a drift itself (where.order_drift); accepting gives a set without them"
        )
    })
}

/// Identification options whose fits are never refused for their residual: the diagnosis studies
/// models that miss (a withheld effect, a nominal start) and poses they miss by much; that is its
/// evidence, not an error (issue 13's refusals are for calibrations). The set's own decision
/// about an undeclared payload (identified: a term of its model; held: left out) and about each
/// compliance (held when its data did not determine it) is every model's here; the search does
/// not decide them again. One decision is revisited after it: a payload held at 0 kg that the
/// model with the named terms determines, adopted when held-out poses confirm it
/// (`search::adopt_payload`).
fn unrefused() -> IdentifyOptions {
    IdentifyOptions {
        residual_ratio_limit: f64::INFINITY,
        outlier_factor: f64::INFINITY,
        identify_payload: false,
        hold_undetermined_compliance: false,
        ..IdentifyOptions::default()
    }
}

/// Diagnose `input`: what the model still misses, where, and which effect explains it — screened,
/// refitted and confirmed on held-out poses, or said to be unknown or not separable.
///
/// A virtual IRB 120 with a gear error the model does not have (a twice-per-turn error of 0.01° on
/// joint 3), identified with the default model, then diagnosed:
///
/// ```
/// use robocal_core::diagnose::library::Kind;
/// use robocal_core::diagnose::{DiagnoseOptions, Input, Status, diagnose};
/// use robocal_core::identify::{self, IdentifyOptions, identify};
/// use robocal_core::sim::effects::Effects;
/// use robocal_core::sim::simulate::{SimulateOptions, simulate};
///
/// let effects = Effects::parse("cyclic:j=3:h=2:amp_deg=0.01", 6)?;
/// let sim = simulate(&SimulateOptions { seed: 7, effects, ..Default::default() })?;
/// let id = identify(&sim.cell, &IdentifyOptions::default())?;
/// let identified = id.status.iter().map(|s| *s == identify::Status::Identified).collect();
/// let input = Input { cell: &sim.cell, set: &id.set, identified: Some(identified), fixed: vec![], excluded: vec![] };
/// let d = diagnose(&input, &DiagnoseOptions::default())?;
/// assert_eq!(d.verdict.status, Status::Named, "{}", d.verdict.summary);
/// let first = &d.verdict.effects[0].candidate;
/// assert_eq!((first.kind, first.joint), (Kind::Cyclic, Some(2)), "{}", d.verdict.summary);
/// // The shrink table: held-out mean of each model, the start first; the named one is better.
/// let (start, last) = (&d.shrink[0], d.shrink.last().unwrap());
/// assert!(last.stats.mean < start.stats.mean);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn diagnose(input: &Input<'_>, opts: &DiagnoseOptions) -> Result<Diagnosis, DiagnoseError> {
    diagnose_with_progress(input, opts, &|_, _| {})
}

/// [`diagnose`], telling `progress` how far it got (0–1, by the stages' typical share of the
/// time: the candidates' held-out refits dominate) and which stage runs.
pub fn diagnose_with_progress(
    input: &Input<'_>,
    opts: &DiagnoseOptions,
    progress: &(dyn Fn(f64, &'static str) + Sync),
) -> Result<Diagnosis, DiagnoseError> {
    let cell = input.cell;
    progress(0.0, "fitting the current model");
    if opts.folds < 2 {
        return Err(DiagnoseError::Option(format!("folds must be at least 2, got {}", opts.folds)));
    }
    let (identification, validation) = diagnosed_sessions(cell, opts)?;
    let mut sessions = identification.clone();
    sessions.extend(validation.iter().cloned());
    // The readings the set's identification left out stay out: a diagnosis with them in judges
    // another data set than the calibration's (ten readings of the neighbouring reflector read as
    // an 8.9 mm held-out error and a `not_separable` verdict).
    let left_out = LeftOut::of(input, opts, &sessions);
    let opts = &DiagnoseOptions { exclude: left_out.all.clone(), ..opts.clone() };

    // The approach directions for the backlash candidate: logged, or derived from the measuring
    // order where it is known (never from a shuffled or resampled session's list).
    let mut work = cell.clone();
    let derived = order::fill_approach(&mut work, &sessions);

    // 1. The current model, fitted on every diagnosed session.
    let t0 = std::time::Instant::now();
    let stage0 = stage::Stage::fit(&work, start_options(input, opts, sessions.clone()))?;
    search::timing("stage 0", t0);
    // 2. The folds and the noise floor.
    progress(0.1, "estimating the noise floor");
    let t0 = std::time::Instant::now();
    let start_note = stage0.fit.as_ref().err().cloned();
    let tested_sessions = if validation.is_empty() { &identification } else { &validation };
    let tested = Tested::of(&stage0, &work, tested_sessions, &identification, opts)?;
    search::timing("folds + floor", t0);
    // 3. The search: candidates screened, cross-validated and refitted, round by round.
    progress(0.2, "screening and cross-validating candidate effects");
    let t0 = std::time::Instant::now();
    let search_opts = SearchOptions { threads: opts.threads.max(opts.search.threads), ..opts.search.clone() };
    let mut s = search::search(&work, stage0, &tested.folds, tested.floor.rms * tested.floor.rms, &search_opts)?;
    if let Some(reason) = derived.unavailable_reason() {
        for u in s.unavailable.iter_mut().filter(|u| u.kind == Kind::Backlash) {
            u.reason = reason.clone();
        }
    }
    // An unknown payload the set held, which the named terms may determine: adopted when the
    // model refitted with it predicts held-out poses better (`search::adopt_payload`).
    s.payload = search::adopt_payload(&work, &mut s, &tested.folds, input.payload_held(), &search_opts);
    search::timing("search", t0);
    // 4. Where the start model misses, and the decomposition of its error.
    progress(0.85, "locating the residual error");
    let t0 = std::time::Instant::now();
    let mut location = tested.locate(&s, cell, input.set.chain().base().t, opts);
    // One model, one figure: the held-out errors of the models refitted in full on the folds where
    // that worked (always, unless a fold's refit failed: then the linearised folds', and a note
    // says so).
    let figures: Vec<&cv::Heldout> = s.baselines.iter().zip(&s.refits).map(|(b, r)| r.as_ref().unwrap_or(b)).collect();
    let refit_note = s.refits.iter().find_map(|r| r.as_ref().err()).map(|e| {
        format!("a model could not be refitted on the folds ({e}): its held-out figures are the linearised folds'")
    });
    if let Some(d) = location.order_drift.as_mut().filter(|d| d.found()) {
        progress(0.87, "refitting the final model with the drift as a nuisance");
        d.nuisance = drift_nuisance(&work, &s, &figures, &tested.folds, opts.threads);
    }
    let decomposition = decompose(input, &validation, &figures, tested.floor)?;
    let evidence = evidence(&s, &figures);
    let shrink = shrink_table(&s, &figures, &decomposition)?;
    search::timing("where + decomposition", t0);
    // 5. The verdict, the accepted model refitted on all the data, and its transfer.
    let t0 = std::time::Instant::now();
    let mut verdict = verdict(&s, &decomposition);
    let model = s.stages.last().expect("a stage").options.clone();
    let accepted = accepted_identification(&s, &work, &model);
    if verdict.status == Status::Named {
        let named: Vec<ParamEstimate> = verdict.effects.iter().flat_map(|e| e.parameters.iter().cloned()).collect();
        match s.payload.as_ref() {
            Some(t @ search::PayloadTrial { adopted: Ok(()), .. }) => {
                let last = s.stages.last().expect("a stage");
                verdict.summary.push_str(&adopted_payload_clause(t, &shrink, last, &named));
                // What remained was the payload error, not separable from the compliances with a
                // single payload: the adoption answers it, on the premise it states.
                let lr = s.rounds.last().expect("a round");
                if let (Some((_, text)), Decision::NotSeparable { best, .. }) =
                    (verdict.remaining.as_mut(), &lr.decision)
                    && lr.screened[*best].candidate.kind == Kind::ToolMass
                {
                    text.push_str(": the final model adopts the payload these data determine with the robot file's link masses taken as exact, which a second payload would check");
                }
                if let Some(a) = accepted.as_ref() {
                    verdict.summary.push_str(&payload_com_clause(a, &model));
                }
            }
            trial => {
                let said = held_payload_with_named(&work, &model, accepted.as_ref(), &named);
                verdict.summary.push_str(&said);
                if let Some(Err(why)) = trial.map(|t| &t.adopted).filter(|_| !said.is_empty()) {
                    verdict.summary.push_str(&format!("; not adopted in the model: {why}"));
                }
            }
        }
        // The payload the named terms moved, read again with its centre of mass free.
        if let Some(a) = accepted.as_ref().filter(|_| !verdict::payload_change(&s).is_empty()) {
            verdict.summary.push_str(&payload_com_clause(a, &model));
        }
    }
    if let Some(d) = location.order_drift.as_ref().filter(|d| d.found() || d.creep_found()) {
        verdict.summary.push_str(&format!("; {}", d.statement()));
    }
    if let Some(g) = GrossHeldout::of(&s.stages[0].problem, figures[0]) {
        verdict.summary.push_str(&format!("; {}", g.statement()));
    }
    search::timing("verdict + accepted", t0);
    if !opts.transfer.is_empty() {
        progress(0.95, "transfer to other sessions");
    }
    let backlash_screened = s.rounds[0].screened.iter().any(|c| c.candidate.kind == Kind::Backlash);
    let approach = derived.source.filter(|_| backlash_screened);
    let mut approach_notes =
        if backlash_screened || derived.refused().next().is_some() { derived.notes() } else { Vec::new() };
    // The transfer sessions' approach directions, derived as the diagnosed sessions' are: a model
    // with hysteresis carried there and scored without them is scored without its hysteresis (a
    // twin's second run read 0.1766 → 0.1790 mm with the named hysteresis, where the same terms
    // carried by `crossval --transfer`, which derives them, gain 0.013 mm).
    let carried = order::fill_approach(&mut work, &opts.transfer);
    let carries_backlash = s.accepted.iter().any(|c| c.kind == Kind::Backlash)
        || input.set.layout.params().iter().any(|p| matches!(p, Param::Joint(_, JointTerm::Backlash)));
    if carries_backlash {
        approach_notes.extend(carried.notes());
    }
    let transfer = transfers(input, opts, &work, &identification, &s, &model, accepted.as_ref())?;
    if let Some(clause) = transfer_clause(&transfer) {
        verdict.summary.push_str(&format!("; {clause}"));
    }
    if let Some(clause) = zeros_clause(&transfer) {
        verdict.summary.push_str(&format!("; {clause}"));
    }
    Ok(Diagnosis {
        verdict,
        decomposition,
        location,
        shrink,
        approach,
        approach_notes,
        unavailable: s.unavailable.clone(),
        start_note: match (start_note, refit_note) {
            (Some(a), Some(b)) => Some(format!("{a}; {b}")),
            (a, b) => a.or(b),
        },
        identification,
        validation,
        model,
        accepted,
        rounds: s.rounds,
        folds: opts.folds,
        dof: cell.model.dof(),
        parallel_rows: ParamLayout::full(&cell.model).parallel_rows().len(),
        transfer,
        evidence,
        excluded_note: left_out.note(),
        drift_note: drift_left_out_note(input.set),
        excluded: left_out.all,
    })
}

/// A few tested readings that carry most of the starting model's held-out squared error, each more
/// than [`crate::identify::OUTLIER_FACTOR`] times the median held-out error: gross readings (a
/// swapped line, the neighbouring reflector, a slipped nest) that every figure of the diagnosis is
/// then about. Ten readings of the neighbouring reflector among 2856 made a held-out RMS of
/// 8.86 mm where the others read 0.33 mm, and the verdict `not_separable` on it. Effects in the
/// library move neighbouring poses alike: a withheld β or a gear error spreads its held-out error
/// over many readings, not half of it onto a few.
struct GrossHeldout {
    /// (session, index, |error| m), largest first.
    readings: Vec<(String, usize, f64)>,
    /// Tested readings.
    n: usize,
    /// Their share of the held-out squared error (0–1).
    share: f64,
    /// Held-out RMS with them and without them, m.
    rms: (f64, f64),
    /// Median held-out error, m.
    median: f64,
}

impl GrossHeldout {
    /// At most this share of the tested readings: "a few".
    const MAX_SHARE_OF_READINGS: f64 = 0.05;
    /// At least this share of the held-out squared error: the figures are theirs.
    const MIN_SHARE_OF_ERROR: f64 = 0.5;

    fn of(problem: &crate::identify::Problem, h: &cv::Heldout) -> Option<GrossHeldout> {
        let norms = h.norms();
        let n = norms.len();
        let mut sorted = norms.clone();
        sorted.sort_by(f64::total_cmp);
        let median = *sorted.get(n / 2)?;
        let limit = crate::identify::OUTLIER_FACTOR * median;
        let mut readings: Vec<(String, usize, f64)> = h
            .errors
            .iter()
            .zip(&norms)
            .filter(|(_, e)| **e > limit)
            .map(|((o, _), e)| {
                let o = &problem.obs[*o];
                (problem.session_names[o.session].clone(), o.index, *e)
            })
            .collect();
        readings.sort_by(|a, b| b.2.total_cmp(&a.2));
        let all: f64 = norms.iter().map(|e| e * e).sum();
        let theirs: f64 = readings.iter().map(|r| r.2 * r.2).sum();
        let share = theirs / all.max(f64::MIN_POSITIVE);
        let few = (readings.len() as f64) <= Self::MAX_SHARE_OF_READINGS * n as f64;
        let rest = n - readings.len();
        (!readings.is_empty() && few && share >= Self::MIN_SHARE_OF_ERROR && rest > 0).then(|| GrossHeldout {
            share,
            rms: ((all / n as f64).sqrt(), ((all - theirs).max(0.0) / rest as f64).sqrt()),
            median,
            n,
            readings,
        })
    }

    /// In a sentence, with the readings to check.
    fn statement(&self) -> String {
        const LISTED: usize = 50;
        let mm = |v: f64| format!("{:.3} mm", v / crate::units::MM);
        let k = self.readings.len();
        let shown: Vec<String> = self.readings.iter().take(5).map(|(s, i, e)| format!("{s}[{i}] {}", mm(*e))).collect();
        let refs: Vec<String> = self.readings.iter().take(LISTED).map(|(s, i, _)| format!("{s}:{i}")).collect();
        format!(
            "{k} of the {} tested readings carry {:.0} % of the held-out squared error (RMS {}, {} without them), each more than {} times the median held-out error ({}): {}{} — gross readings (a swapped line, the neighbouring reflector, a slipped nest)? These figures are mostly theirs; check them and leave them out (exclude {}{})",
            self.n,
            100.0 * self.share,
            mm(self.rms.0),
            mm(self.rms.1),
            crate::identify::OUTLIER_FACTOR,
            mm(self.median),
            shown.join(", "),
            if k > shown.len() { format!(" and {} more", k - shown.len()) } else { String::new() },
            refs.join(","),
            if k > LISTED { ",…" } else { "" },
        )
    }
}

/// The readings a diagnosis leaves out: those its options name, then those the set's
/// identification left out that the diagnosed sessions hold.
struct LeftOut {
    /// (session, index in the cell), without repeats.
    all: Vec<(String, usize)>,
    /// Of them, the set's not named by the options.
    from_set: usize,
    /// Readings of diagnosed sessions the set left out that this cell does not hold (another
    /// import of a session of the same name).
    missing: usize,
}

impl LeftOut {
    fn of(input: &Input<'_>, opts: &DiagnoseOptions, sessions: &[String]) -> LeftOut {
        let cell = input.cell;
        let mut all = opts.exclude.clone();
        let (mut from_set, mut missing) = (0, 0);
        let mut fingerprints: std::collections::HashMap<&str, Vec<Option<String>>> = Default::default();
        for (name, index, fingerprint) in &input.excluded {
            let Some(session) = cell.session(name).filter(|_| sessions.contains(name)) else { continue };
            let found = match fingerprint {
                Some(f) => {
                    let of = fingerprints.entry(name.as_str()).or_insert_with(|| {
                        session.measurements.iter().map(|m| crate::cell::fingerprint::of_measurement(cell, m)).collect()
                    });
                    // The recorded index first (the same import), then anywhere in the session.
                    if of.get(*index).and_then(|g| g.as_ref()) == Some(f) {
                        Some(*index)
                    } else {
                        of.iter().position(|g| g.as_ref() == Some(f))
                    }
                }
                None => (*index < session.measurements.len()).then_some(*index),
            };
            match found {
                Some(i) if !all.iter().any(|(n, k)| n == name && *k == i) => {
                    all.push((name.clone(), i));
                    from_set += 1;
                }
                Some(_) => {}
                None => missing += 1,
            }
        }
        LeftOut { all, from_set, missing }
    }

    /// What the report says of the set's readings, when it left some out.
    fn note(&self) -> Option<String> {
        let readings = |n: usize| if n == 1 { "1 reading".to_string() } else { format!("{n} readings") };
        let set = "the parameter set's identification left out (its `exclude`)";
        let are = |n: usize| if n == 1 { "is" } else { "are" };
        let found = format!(
            "{} that {set} {} left out of every fit and every test here too (listed in sessions.excluded)",
            readings(self.from_set),
            are(self.from_set)
        );
        let missing = |whose: &str| {
            format!(
                "{} that {whose} left out {} not in these sessions (another import of a session of the same name?): nothing was left out for {}",
                readings(self.missing),
                are(self.missing),
                if self.missing == 1 { "it" } else { "them" }
            )
        };
        match (self.from_set, self.missing) {
            (0, 0) => None,
            (_, 0) => Some(found),
            (0, _) => Some(missing(set.trim_end_matches(" left out (its `exclude`)"))),
            _ => Some(format!("{found}; {}", missing("it"))),
        }
    }
}

/// The identification and validation sessions a diagnosis uses: those named, or the cell's of each
/// purpose (an empty validation list: cross-validate on the identification sessions).
fn diagnosed_sessions(cell: &Cell, opts: &DiagnoseOptions) -> Result<(Vec<String>, Vec<String>), DiagnoseError> {
    let names = |purpose: Purpose, given: &[String]| -> Result<Vec<String>, DiagnoseError> {
        if given.is_empty() {
            return Ok(cell.sessions_for(purpose).map(|s| s.name.clone()).collect());
        }
        for g in given {
            if cell.session(g).is_none() {
                return Err(DiagnoseError::Option(format!("no session named '{g}' in the cell")));
            }
        }
        Ok(given.to_vec())
    };
    let identification = names(Purpose::Identification, &opts.identification)?;
    let validation = match &opts.validation {
        None => names(Purpose::Validation, &[])?,
        Some(v) if v.is_empty() => Vec::new(),
        Some(v) => names(Purpose::Validation, v)?,
    };
    if identification.is_empty() {
        return Err(DiagnoseError::Option("the cell has no identification session".into()));
    }
    if let Some(s) = identification.iter().find(|s| validation.contains(s)) {
        return Err(DiagnoseError::Option(format!("session '{s}' is named for both identification and validation")));
    }
    for (name, index) in &opts.exclude {
        let diagnosed = identification.contains(name) || validation.contains(name);
        match cell.session(name) {
            Some(s) if diagnosed && *index < s.measurements.len() => {}
            Some(s) if diagnosed => {
                return Err(DiagnoseError::Option(format!(
                    "exclude: session '{name}' has {} measurements (0-based), not {index}",
                    s.measurements.len()
                )));
            }
            _ => return Err(DiagnoseError::Option(format!("exclude: '{name}' is not a diagnosed session"))),
        }
    }
    Ok((identification, validation))
}

/// The tested poses of a diagnosis: their folds, the noise floor on them, and the calibration
/// positions and zone the location step measures distances from.
struct Tested {
    folds: Folds,
    floor: Floor,
    obs: Vec<usize>,
    calib: Vec<Vector3<f64>>,
    calib_joints: Vec<Vec<f64>>,
}

impl Tested {
    fn of(
        stage0: &stage::Stage,
        work: &Cell,
        tested_sessions: &[String],
        identification: &[String],
        opts: &DiagnoseOptions,
    ) -> Result<Tested, DiagnoseError> {
        let pr = &stage0.problem;
        let tested: Vec<bool> = pr.obs.iter().map(|o| tested_sessions.contains(&pr.session_names[o.session])).collect();
        let joints: Vec<Vec<f64>> = pr.obs.iter().map(|o| o.state.q[..pr.model.dof()].to_vec()).collect();
        let folds = Folds::new(&joints, &tested, opts.folds, opts.seed);
        if folds.n_poses < 2 * opts.folds {
            return Err(DiagnoseError::Option(format!(
                "{} tested poses are too few for {}-fold cross-validation",
                folds.n_poses, opts.folds
            )));
        }
        let obs: Vec<usize> = (0..pr.obs.len()).filter(|&o| tested[o]).collect();
        let floor = floor::floor(stage0, work, &obs, &opts.noise, opts.seed);
        let id_obs: Vec<usize> =
            (0..pr.obs.len()).filter(|&o| identification.contains(&pr.session_names[pr.obs[o].session])).collect();
        let calib: Vec<Vector3<f64>> = id_obs.iter().map(|&o| pr.target_position(&pr.obs[o])).collect();
        let calib_joints: Vec<Vec<f64>> = id_obs.iter().map(|&o| joints[o].clone()).collect();
        Ok(Tested { folds, floor, obs, calib, calib_joints })
    }

    /// Where the start model misses: binned in voxels (the option's size, or one chosen from the
    /// tested positions), against the distance from the calibration zone (the artefact's centre,
    /// or the calibration positions' centroid) and the base.
    fn locate(&self, s: &search::Search, cell: &Cell, base: Vector3<f64>, opts: &DiagnoseOptions) -> Where {
        let zone = match &cell.artefact {
            Some(a) => a.triangle.centroid(),
            None => self.calib.iter().sum::<Vector3<f64>>() / self.calib.len().max(1) as f64,
        };
        let voxel = if opts.voxel_size > 0.0 {
            opts.voxel_size
        } else {
            let pts: Vec<Vector3<f64>> = self.obs.iter().map(|&o| pr_target(&s.stages[0], o)).collect();
            auto_voxel(&pts)
        };
        let mut w = locate::locate(
            &s.stages[0],
            &s.baselines[0],
            &self.floor,
            &self.calib,
            &self.calib_joints,
            zone,
            base,
            voxel,
            opts.fdr,
        );
        match order_drift(&s.stages[0], cell, &s.baselines[0], opts.seed) {
            Ok(d) => w.order_drift = Some(d),
            Err(why) => w.order_drift_untested = Some(why),
        }
        w
    }
}

/// The drift test ([`drift`]) on the starting model's held-out errors, where every tested
/// observation has a place in one run ([`run_positions`]), with each joint's ∂(position)/∂θ_j at
/// the starting model for the creep of the zeros; `Err`: why the order was not tested, in a
/// sentence.
fn order_drift(
    stage: &stage::Stage,
    cell: &Cell,
    heldout: &cv::Heldout,
    seed: u64,
) -> Result<drift::OrderDrift, String> {
    let pr = &stage.problem;
    let dof = pr.model.dof();
    let obs: Vec<usize> = heldout.errors.iter().map(|(o, _)| *o).collect();
    let (source, at) = run_positions(pr, cell, &obs).ok_or_else(|| {
        "the tested readings have no place in one run (no time_s or sequence logged, and not one session in measuring order)".to_string()
    })?;
    // The weighted joint columns, unweighted row by row (a row of zero weight tells nothing).
    let g = stage.joint_columns();
    let zero_columns = |o: &crate::identify::problem::Obs| -> Vec<Vector3<f64>> {
        let w = |a: usize| if o.weight[a] != 0.0 { 1.0 / o.weight[a] } else { 0.0 };
        (0..dof).map(|j| Vector3::from_fn(|a, _| g[(o.row + a, j)] * w(a))).collect()
    };
    let readings = heldout
        .errors
        .iter()
        .zip(at)
        .map(|((o, e), t)| {
            let ob = &pr.obs[*o];
            (t, ob.state.q[..dof].to_vec(), pr.target_position(ob), *e, zero_columns(ob))
        })
        .collect();
    drift::order_drift(&drift::stops(readings), source, seed)
}

/// The final model with the drift terms (`+drift`), fitted on the pooled data and refitted on the
/// folds ([`drift::DriftNuisance`]). `None` when either fit fails.
fn drift_nuisance(
    work: &Cell,
    s: &search::Search,
    figures: &[&cv::Heldout],
    folds: &Folds,
    threads: usize,
) -> Option<drift::DriftNuisance> {
    let last = s.stages.last()?;
    let terms = crate::identify::drift_terms();
    let mut o = last.options.clone();
    for p in &terms {
        if !o.model.extra.contains(p) {
            o.model.extra.push(*p);
        }
    }
    if let Some(start) = &mut o.start {
        start.extend(&terms);
    }
    let st = stage::Stage::fit(work, o).ok()?;
    st.fit.as_ref().ok()?;
    let h = refit::refit_heldout(work, &st, folds, threads).ok()?;
    let without = ErrorStats::of(&figures.get(s.stages.len() - 1)?.norms())?.mean;
    let with = ErrorStats::of(&h.norms())?.mean;
    let pr = &st.problem;
    let d = nalgebra::Matrix3::<f64>::from_fn(|a, k| pr.robot_index(Param::Drift(a, k)).map_or(0.0, |g| st.x[g]));
    let sq: f64 = h.errors.iter().map(|(o, _)| (d * Vector3::from(pr.obs[*o].state.run)).norm_squared()).sum();
    let fitted_rms = (sq / h.errors.len().max(1) as f64).sqrt();
    Some(drift::DriftNuisance { fitted_rms, without, with })
}

/// Each of the observations `obs`' place in one run ([`crate::identify::run::run_positions`]).
pub(crate) fn run_positions(
    pr: &crate::identify::problem::Problem,
    cell: &Cell,
    obs: &[usize],
) -> Option<(drift::RunPosition, Vec<f64>)> {
    let picks: Vec<(usize, usize)> =
        obs.iter().map(|&o| pr.obs.get(o).map(|ob| (ob.session, ob.index))).collect::<Option<_>>()?;
    crate::identify::run::run_positions(cell, &picks)
}

/// The start model's error split: the floor (what no model removes), the unmodelled gap (held
/// out, above the floor) and, with validation sessions, the extrapolation gap (validation against
/// held out).
fn decompose(
    input: &Input<'_>,
    validation: &[String],
    figures: &[&cv::Heldout],
    floor: Floor,
) -> Result<Decomposition, DiagnoseError> {
    let heldout = ErrorStats::of(&figures[0].norms()).ok_or_else(|| DiagnoseError::Option("no tested pose".into()))?;
    let calibrated = if validation.is_empty() {
        None
    } else {
        validate(input.set, input.cell, validation, Reference::Measured).ok().map(|r| r.calibrated.position)
    };
    Ok(Decomposition {
        extrapolation_gap: calibrated.map(|c| c.mean - heldout.mean),
        unmodelled_gap: heldout.mean - floor.mean,
        calibrated,
        heldout,
        floor,
    })
}

/// The held-out figures of the start model and of each model the search accepted (the start with
/// its first k effects), with the share of the gap above the floor each closes.
fn shrink_table(
    s: &search::Search,
    figures: &[&cv::Heldout],
    decomposition: &Decomposition,
) -> Result<Vec<ShrinkEntry>, DiagnoseError> {
    let mut shrink = Vec::new();
    for (k, b) in figures.iter().enumerate() {
        let stats = ErrorStats::of(&b.norms()).ok_or_else(|| DiagnoseError::Option("no tested pose".into()))?;
        let closure = (k > 0).then(|| {
            let gap = decomposition.heldout.mean - decomposition.floor.mean;
            if gap > 0.0 { (decomposition.heldout.mean - stats.mean) / gap } else { 0.0 }
        });
        // A row beyond the accepted effects is the model with the adopted payload.
        let mut model: Vec<String> = s.accepted[..k.min(s.accepted.len())].iter().map(|c| c.label()).collect();
        if k > s.accepted.len() {
            model.push(Kind::ToolMass.name().to_string());
        }
        shrink.push(ShrinkEntry { model, stats, closure });
    }
    Ok(shrink)
}

/// When the set held an unknown payload (its data did not determine it under the starting model)
/// and effects were named: whether the model with them determines it, as a clause for the verdict
/// ("" when it does not, or the payload was declared or identified), with the `named` parameters
/// that the payload moves by more than their σ. A term the model lacked leaks into the payload
/// through the compliances: on a twin with an unmodelled coupling 2→3 of 0.002 and a 2.3 kg plate,
/// the default model read 0.067 ± 0.086 kg and held it; the model with the named coupling but the
/// payload held read the coupling 0.001888 ± 0.000019, and with the payload 2.349 ± 0.156 kg and
/// the coupling 0.001995 ± 0.000016. The diagnosis keeps the set's decision in its own models
/// (its figures are those models'); this says what the data determine beyond it.
fn held_payload_with_named(
    work: &Cell,
    model: &IdentifyOptions,
    accepted: Option<&Identification>,
    named: &[ParamEstimate],
) -> String {
    let Some(accepted) = accepted else { return String::new() };
    if model.model.extra.contains(&Param::ToolMass) {
        return String::new();
    }
    let mut o = model.clone();
    o.anchor = None;
    o.identify_payload = true;
    o.start = Some(accepted.set.clone());
    let Ok(id) = identify(work, &o) else { return String::new() };
    let Some(i) = id.set.layout.index_of(Param::ToolMass) else { return String::new() };
    let (crate::identify::Status::Identified, Some(sd)) = (&id.status[i], id.std[i]) else { return String::new() };
    let with = moved_clause(named.iter().filter_map(|e| {
        let k = id.set.layout.index_of(e.param)?;
        Some((e, id.set.values[k], id.std[k]?))
    }));
    format!(
        "; with the named terms the data determine the payload the identification held at 0 kg: {:.3} ± {sd:.3} kg{with} (σ with the tool's centre of mass and the robot file's link masses taken as exact; identify with them to use it){}",
        id.set.values[i],
        payload_com_clause(&id, &o)
    )
}

/// "; with the named terms the data determine the payload the identification held at 0 kg, and the
/// model adopts it: … ± … kg (held-out mean … → … mm, p = …; …)": an adopted payload
/// ([`search::adopt_payload`]) with the figures of the shrink table's last two rows.
/// The named parameters it moves by more than their σ are said with their values in that model
/// (the effects keep those of the model that accepted them).
fn adopted_payload_clause(
    t: &search::PayloadTrial,
    shrink: &[ShrinkEntry],
    last: &stage::Stage,
    named: &[ParamEstimate],
) -> String {
    let sd = t.std.map_or(String::new(), |sd| format!(" ± {sd:.3}"));
    let found: Vec<(&ParamEstimate, usize)> =
        named.iter().filter_map(|e| last.problem.robot_index(e.param).map(|g| (e, g))).collect();
    let stds = last.stds_of(&found.iter().map(|f| f.1).collect::<Vec<_>>());
    let with = moved_clause(found.iter().zip(stds).filter_map(|(&(e, g), s)| Some((e, last.x[g], s?))));
    let held = match (shrink.len().checked_sub(2).map(|k| &shrink[k..]), t.refit.as_ref()) {
        (Some([a, b]), Some(r)) => format!(
            "held-out mean {:.4} mm → {:.4} mm, p = {:.1e}; ",
            a.stats.mean * 1e3,
            b.stats.mean * 1e3,
            r.p.unwrap_or(f64::NAN)
        ),
        _ => String::new(),
    };
    format!(
        "; with the named terms the data determine the payload the identification held at 0 kg, and the final model adopts it: {:.3}{sd} kg ({held}σ with the tool's centre of mass and the robot file's link masses taken as exact){with}",
        t.mass
    )
}

/// ", and with it <param> v ± σ, …": the named parameters, given as (estimate, value with the
/// payload, σ with the payload), that the payload moves by more than their σ (the larger of the
/// two fits'); "" when it moves none.
fn moved_clause<'a>(with_payload: impl Iterator<Item = (&'a ParamEstimate, f64, f64)>) -> String {
    let moved: Vec<String> = with_payload
        .filter(|&(e, v, s)| (v - e.value).abs() > s.max(e.std.unwrap_or(0.0)))
        .map(|(e, v, s)| format!("{} {}", e.param, verdict::with_sd(v, Some(s), e.param.unit())))
        .collect();
    if moved.is_empty() { String::new() } else { format!(", and with it {}", moved.join(", ")) }
}

/// "; with its centre of mass identified too, it reads … ± … kg at (… ± …, …) mm in the flange
/// frame[, which these data do not determine]": the payload of `id` fitted again with its centre of
/// mass free ([`crate::identify::payload_centre_of_mass`]), whose σ carries where the payload sits
/// ("" when there is no such reading). The σ of the statement before it takes the tool's centre
/// of mass as exact; on the independent simulator's twins with the hysteresis named, that σ left
/// 3 masses of 15 beyond 3 σ, this one none beyond 1.7 σ (BENCHMARKS, "The payload's centre of
/// mass, identified with its mass").
fn payload_com_clause(id: &Identification, model: &IdentifyOptions) -> String {
    let Ok(Some(c)) = crate::identify::payload_centre_of_mass(id, model) else { return String::new() };
    let (Some(com), Some(sd)) = (c.com, c.com_std) else {
        return format!(
            "; with its centre of mass identified too, it reads {:.3} ± {:.3} kg, which places no centre of mass",
            c.mass, c.std
        );
    };
    let mm = |v: f64| v / crate::units::MM;
    format!(
        "; with its centre of mass identified too, it reads {:.3} ± {:.3} kg at ({:.1} ± {:.1}, {:.1} ± {:.1}, {:.1} ± {:.1}) mm in the flange frame{}",
        c.mass,
        c.std,
        mm(com.x),
        mm(sd[0]),
        mm(com.y),
        mm(sd[1]),
        mm(com.z),
        mm(sd[2]),
        if c.determined { "" } else { ", which these data do not determine" }
    )
}

/// The model with every accepted effect, identified on all the diagnosed data from where the search
/// left it (no anchors); the search's last fit when that refit fails; `None` without an effect.
fn accepted_identification(s: &search::Search, work: &Cell, model: &IdentifyOptions) -> Option<Identification> {
    if s.accepted.is_empty() {
        return None;
    }
    let mut o = model.clone();
    o.anchor = None;
    o.start = Some(s.stages.last().expect("a stage").set.clone());
    identify(work, &o).ok().or_else(|| s.stages.last().and_then(|st| st.fit.as_ref().ok().cloned()))
}

/// The final model against the starting one on each transfer session, as a clause of the verdict:
/// held-out poses of the identification's own set-up confirm a term where it was measured, and a
/// session of another day or set-up tests whether it carries. On the UR10 the joint tables named on
/// series C, confirmed there (0.4319 → 0.1491 mm), read 0.4418 → 0.4525 mm on series B, every pose of
/// which lies outside series C's range of joint 1: a summary that said only "confirmed" would be
/// read as a calibration that holds there. Each change carries its batch-means standard error
/// ([`PairedChange`]): neither B's +0.0107 ± 0.0157 mm nor D's −0.0340 ± 0.0176 mm is a change
/// the runs can tell from none. `None` without a final model (no effect accepted) or transfer
/// session.
fn transfer_clause(transfer: &[Transfer]) -> Option<String> {
    let mm = |v: f64| format!("{:.4} mm", v / crate::units::MM);
    let mut sessions: Vec<&str> = transfer.iter().map(|t| t.session.as_str()).collect();
    sessions.dedup();
    let parts: Vec<String> = sessions
        .iter()
        .filter_map(|name| {
            let of = |model: &str| transfer.iter().find(|t| t.session == *name && t.model == model);
            let (start, fin) = (of("start")?, of("final")?);
            Some(match (&start.errors, &fin.errors) {
                (Ok(a), Ok(b)) => {
                    let outside = fin
                        .range
                        .as_ref()
                        .filter(|r| r.inside_share < 1.0)
                        .map(|r| {
                            format!(
                                ", {:.0} % of its poses outside the identification's joint ranges",
                                100.0 * (1.0 - r.inside_share)
                            )
                        })
                        .unwrap_or_default();
                    let change = match &fin.change {
                        Some(c) => format!("{:+.4} ± {:.4} mm", c.mean / crate::units::MM, c.se / crate::units::MM),
                        None => format!("{:+.4} mm", (b.mean - a.mean) / crate::units::MM),
                    };
                    format!("{name} {} → {} ({change}{outside})", mm(a.mean), mm(b.mean))
                }
                (_, Err(e)) | (Err(e), _) => format!("{name} not carried ({e})"),
            })
        })
        .collect();
    if parts.is_empty() {
        return None;
    }
    // What each final mean's change says, judged against twice its standard error where there is
    // one; without one (too few poses) only its sign is known.
    let finals: Vec<(&Transfer, f64, Option<&PairedChange>)> = transfer
        .iter()
        .filter(|t| t.model == "final")
        .filter_map(|f| {
            let start = transfer.iter().find(|t| t.session == f.session && t.model == "start")?;
            match (&start.errors, &f.errors) {
                (Ok(a), Ok(b)) => Some((f, b.mean - a.mean, f.change.as_ref())),
                _ => None,
            }
        })
        .collect();
    let names = |keep: &dyn Fn(f64, Option<&PairedChange>) -> bool| -> Vec<&str> {
        finals.iter().filter(|(_, d, c)| keep(*d, *c)).map(|(f, _, _)| f.session.as_str()).collect()
    };
    let worse = names(&|d, c| d > 0.0 && c.is_none_or(PairedChange::beyond_2se));
    let level = names(&|_, c| c.is_some_and(|c| !c.beyond_2se()));
    // "A", "A and B", "A, B and C".
    let and = |v: &[&str]| match v {
        [] => String::new(),
        [a] => (*a).to_string(),
        [rest @ .., last] => format!("{} and {last}", rest.join(", ")),
    };
    let mut remark = Vec::new();
    if !worse.is_empty() {
        remark.push(format!("they made {} worse", and(&worse)));
    }
    if !level.is_empty() {
        remark.push(format!("on {} the change is within twice its uncertainty", and(&level)));
    }
    let sigma = if finals.iter().any(|(_, _, c)| c.is_some()) {
        " (± one standard error of the change, paired pose by pose, from its means over runs of consecutive poses)"
    } else {
        ""
    };
    Some(format!(
        "carried to other sessions, base and tools refitted there, the mean error of the starting model → the final one: {}{sigma}{}",
        parts.join(", "),
        if remark.is_empty() {
            String::new()
        } else {
            format!(
                " — the named terms are confirmed on held-out poses of the identification's set-up; {} (transfer[] has every intermediate model and the joint ranges)",
                remark.join("; ")
            )
        }
    ))
}

/// A registered zero offset is said to have moved from the model's when its change exceeds this
/// many of its standard deviations (the verdict's clause and the report's table).
pub const ZERO_SHIFT_SIGMAS: f64 = 3.0;

/// The joint-zero registrations of the transfer ([`ZerosRefit`]) as a clause of the verdict: per
/// session the start's and the final model's held-out mean with base and tools registered → with
/// the zeros too, and the zeros that read beyond 3 σ from the model's; where both the gain (beyond
/// twice its standard error) and such a zero are there, what they can mean. It names no cause. A robot
/// re-mastered between the set-ups, or whose zeros drifted, gains so; and so does a model whose
/// error outside the identification's joint ranges looks like a zero: the UR10's series C, cut at
/// the median of q1, q2, q3 or q5 and carried from one half to the other on the same day, gains
/// 0.006–0.017 mm with θ2 reading 0.01–0.03° off (5–10 σ), where series B and D gain 0.063 and
/// 0.085 mm with θ2 at +0.032° and +0.035°; cut in time instead (the same poses' spread), it gains
/// nothing. One session does not tell the two apart, and the clause says so. `None` without a
/// transfer session.
fn zeros_clause(transfer: &[Transfer]) -> Option<String> {
    let mm = |v: f64| format!("{:.4}", v / crate::units::MM);
    let mut parts = Vec::new();
    let mut moved = Vec::new();
    let mut gained = Vec::new();
    for t in transfer {
        let Some(z) = &t.zeros else { continue };
        match z {
            Ok(z) => {
                let change = z
                    .change
                    .as_ref()
                    .map(|c| format!(" ({:+.4} ± {:.4} mm)", c.mean / crate::units::MM, c.se / crate::units::MM))
                    .unwrap_or_default();
                parts.push(format!(
                    "{} {} {} → {} mm{change}",
                    t.session,
                    t.model,
                    mm(z.base_tool.mean),
                    mm(z.with_zeros.mean)
                ));
                let beyond: Vec<String> = z
                    .shifts
                    .iter()
                    .filter(|(_, d, sd)| d.abs() > ZERO_SHIFT_SIGMAS * sd)
                    .map(|(n, d, sd)| format!("{n} {:+.4} ± {:.4}°", d.to_degrees(), sd.to_degrees()))
                    .collect();
                // A gain with every zero within 3 σ of the model's is the model's own zeros
                // sharpened by more data (the virtual cell's unchanged day: θ2 1.8 σ, −0.006 mm).
                let gains = z.change.as_ref().is_some_and(|c| c.mean < 0.0 && c.beyond_2se());
                if gains && !beyond.is_empty() && !gained.contains(&t.session) {
                    gained.push(t.session.clone());
                }
                if t.model == "start" && !beyond.is_empty() {
                    moved.push(format!("{} {}", t.session, beyond.join(", ")));
                }
            }
            Err(e) => parts.push(format!("{} {} not registered with its zeros ({e})", t.session, t.model)),
        }
    }
    if parts.is_empty() {
        return None;
    }
    let moved = if moved.is_empty() {
        String::new()
    } else {
        format!(
            "; registered on the whole session, zeros that read beyond 3 σ (the registration's and the model's combined) from the model's: {}",
            moved.join("; ")
        )
    };
    let meaning = if gained.is_empty() {
        String::new()
    } else {
        format!(
            " — on {} registering the zeros too predicts held-out poses better beyond twice its uncertainty, with zeros beyond 3 σ from the model's: a robot re-mastered between the set-ups, or whose zeros drifted, does that, and so does a model error outside the identification's joint ranges that looks like a zero; this session alone does not tell them apart (where the robot was re-mastered, re-register it with `only: base, tool, zeros`)",
            and_list(&gained)
        )
    };
    Some(format!(
        "each half of alternate poses registering the model and the other half scored, base and tools → with the joints' zeros too: {}{moved}{meaning}",
        parts.join(", ")
    ))
}

/// Names joined as English writes them: "B", "B and D", "B, C and D".
fn and_list(names: &[String]) -> String {
    match names {
        [] => String::new(),
        [one] => one.clone(),
        [init @ .., last] => format!("{} and {last}", init.join(", ")),
    }
}

/// The start model, each intermediate model of the search and the final one carried to each
/// transfer session (base and tool refitted there), with their errors and how many of its poses
/// lie inside the identified joint ranges.
fn transfers(
    input: &Input<'_>,
    opts: &DiagnoseOptions,
    work: &Cell,
    identification: &[String],
    s: &search::Search,
    model: &IdentifyOptions,
    accepted: Option<&Identification>,
) -> Result<Vec<Transfer>, DiagnoseError> {
    let mut transfer = Vec::new();
    let ranges = joint_ranges(work, identification);
    for t in &opts.transfer {
        if input.cell.session(t).is_none() {
            return Err(DiagnoseError::Option(format!("transfer: no session named '{t}' in the cell")));
        }
        let start_model = start_options(input, opts, Vec::new());
        let mut models = vec![("start".to_string(), start_model.model.clone(), input.set.clone())];
        // Every intermediate model too (the start with the first k effects, as fitted in the
        // search): which terms carry to another session and which do not. Reported, never used to
        // choose the model (that would select on the session being tested).
        for k in 1..=s.accepted.len() {
            let st = &s.stages[k];
            let labels: Vec<String> = s.accepted[..k].iter().map(|c| c.label()).collect();
            models.push((format!("start + {}", labels.join(" + ")), st.options.model.clone(), st.set.clone()));
        }
        if !s.accepted.is_empty() {
            let fin =
                accepted.map(|id| id.set.clone()).unwrap_or_else(|| s.stages.last().expect("a stage").set.clone());
            models.push(("final".to_string(), model.model.clone(), fin));
        }
        let carry = |m: &ModelOptions, set: &ParameterSet, held: &[String]| -> Result<Carried, String> {
            let o = registration_options(m, set, t, &transfer_fixed(opts, held), opts, false, Vec::new());
            let id = identify(work, &o).map_err(|e| e.to_string())?;
            let r = validate(&id.set, work, std::slice::from_ref(t), Reference::Measured).map_err(|e| e.to_string())?;
            Ok(Carried {
                errors: r.calibrated.position,
                kappa_scaled: id.quality.kappa_scaled,
                range: ranges.as_deref().map(|g| range_split(work, g, &r.residuals)),
                per_reading: r.residuals.iter().map(|x| (x.index, x.error.norm())).collect(),
                free: id.free_names,
            })
        };
        let mut carried: Vec<Result<Carried, String>> = models.iter().map(|(_, m, set)| carry(m, set, &[])).collect();
        // One registration for every model: a base or tool parameter the session's data leave at
        // the edge of determined (the UR10's probe z on series D, σ ≈ 10 mm) is held in some
        // refits and free in others, and the models would be compared with different freedoms.
        // What some refit held is held in all of them.
        let free_sets: Vec<&[String]> =
            carried.iter().filter_map(|c| c.as_ref().ok()).map(|c| c.free.as_slice()).collect();
        let held = crate::identify::free_in_some_only(&free_sets);
        if !held.is_empty() {
            for (c, (_, m, set)) in carried.iter_mut().zip(&models) {
                if c.as_ref().is_ok_and(|c| c.free.iter().any(|n| held.contains(n))) {
                    *c = carry(m, set, &held);
                }
            }
        }
        // The start's |e| per reading (index in the session, in measuring order), which every
        // later model's is paired with.
        let start_readings = carried[0].as_ref().ok().map(|c| c.per_reading.clone());
        for ((name, m, set), c) in models.into_iter().zip(carried) {
            let zeros = (name == "start" || name == "final").then(|| {
                let fixed = transfer_fixed(opts, &held);
                // The model's own σ of each zero: the accepted identification's, or its stage's.
                let stage = if name == "start" { s.stages.first() } else { s.stages.last() };
                let model_std = |p: Param| match (name == "final", accepted) {
                    (true, Some(id)) => id.set.layout.index_of(p).and_then(|i| id.std[i]),
                    _ => stage.and_then(|st| st.problem.robot_index(p).and_then(|g| st.stds_of(&[g])[0])),
                };
                zeros_refit(work, t, &m, &set, &fixed, opts, &model_std)
            });
            let change = match (&start_readings, &c) {
                (Some(a), Ok(b)) if name != "start" => paired_change(a, &b.per_reading),
                _ => None,
            };
            transfer.push(Transfer {
                session: t.clone(),
                model: name,
                kappa_scaled: c.as_ref().ok().map(|x| x.kappa_scaled),
                range: c.as_ref().ok().and_then(|x| x.range.clone()),
                held: held.clone(),
                errors: c.map(|x| x.errors),
                change,
                zeros,
            });
        }
    }
    Ok(transfer)
}

/// The transfer's held parameters: the caller's `transfer_fixed` and those held for every model
/// (`held`), each once.
fn transfer_fixed(opts: &DiagnoseOptions, held: &[String]) -> Vec<String> {
    let mut fixed = opts.transfer_fixed.clone();
    for h in held {
        if !fixed.contains(h) {
            fixed.push(h.clone());
        }
    }
    fixed
}

/// The options that re-register `set` (of `model`) on transfer session `t`: base and tools free
/// (and the joints' zeros with `zeros`), `fixed` held, the transfer's κ limit and rotation
/// weight, the readings `exclude` left out. Every registration of a transfer is built here, so
/// the figures compared are of the same registration.
fn registration_options(
    model: &ModelOptions,
    set: &ParameterSet,
    t: &str,
    fixed: &[String],
    opts: &DiagnoseOptions,
    zeros: bool,
    exclude: Vec<(String, usize)>,
) -> IdentifyOptions {
    let mut only: Vec<String> = vec!["base".into(), "tool".into()];
    if zeros {
        only.push("zeros".into());
    }
    let mut o = IdentifyOptions {
        model: model.clone(),
        start: Some(set.clone()),
        only,
        fixed: fixed.to_vec(),
        kappa_limit: opts.transfer_kappa_limit,
        rotation_weight: opts.rotation_weight,
        ..unrefused()
    };
    o.selection.sessions = vec![t.to_string()];
    o.selection.exclude = exclude;
    o
}

/// The joint-zero registration of a model on transfer session `t` ([`ZerosRefit`]): two
/// registrations (base and tools; base, tools and zeros) on each half of alternate poses, each
/// scored on the other half, and the zeros' changes from one registration on the whole session.
fn zeros_refit(
    work: &Cell,
    t: &str,
    model: &ModelOptions,
    set: &ParameterSet,
    fixed: &[String],
    opts: &DiagnoseOptions,
    model_std: &dyn Fn(Param) -> Option<f64>,
) -> Result<ZerosRefit, String> {
    let register = |zeros: bool, exclude: Vec<(String, usize)>| {
        identify(work, &registration_options(model, set, t, fixed, opts, zeros, exclude)).map_err(|e| e.to_string())
    };
    let n = work.session(t).map_or(0, |s| s.measurements.len());
    // Per registration, |e| per held-out reading (index in the session).
    let mut held: [Vec<(usize, f64)>; 2] = [Vec::new(), Vec::new()];
    for half in 0..2 {
        let test: Vec<usize> = (0..n).filter(|i| i % 2 == half).collect();
        let exclude: Vec<(String, usize)> = test.iter().map(|&i| (t.to_string(), i)).collect();
        for (k, zeros) in [false, true].into_iter().enumerate() {
            let id = register(zeros, exclude.clone())?;
            let r = validate(&id.set, work, &[t.to_string()], Reference::Measured).map_err(|e| e.to_string())?;
            held[k].extend(r.residuals.iter().filter(|x| x.index % 2 == half).map(|x| (x.index, x.error.norm())));
        }
    }
    let stats = |v: &[(usize, f64)]| {
        ErrorStats::of(&v.iter().map(|x| x.1).collect::<Vec<_>>()).ok_or_else(|| "no reading held out".to_string())
    };
    let whole = register(true, Vec::new())?;
    let shifts = whole
        .set
        .layout
        .params()
        .iter()
        .enumerate()
        .filter(|(i, p)| {
            matches!(p, Param::Theta(_)) && matches!(whole.status[*i], crate::identify::Status::Identified)
        })
        .filter_map(|(i, p)| {
            let before = set.layout.index_of(*p).map(|k| set.values[k])?;
            // Two estimates from disjoint data: their difference's σ is the root sum of squares
            // (without the model's, the virtual cell's unchanged day read θ2 8 σ off).
            let sd = whole.std[i]?.hypot(model_std(*p).unwrap_or(0.0));
            Some((p.to_string(), whole.set.values[i] - before, sd))
        })
        .collect();
    Ok(ZerosRefit {
        base_tool: stats(&held[0])?,
        with_zeros: stats(&held[1])?,
        change: paired_change(&held[0], &held[1]),
        shifts,
    })
}

/// A model carried to a transfer session: its errors there and what its refit left free.
struct Carried {
    errors: ErrorStats,
    kappa_scaled: f64,
    range: Option<RangeSplit>,
    /// |e| per reading (index in the session).
    per_reading: Vec<(usize, f64)>,
    /// The refit's free parameters, by name.
    free: Vec<String>,
}

/// A model's |e| paired with the start's on the readings both were validated on (by index in the
/// session), in measuring order.
fn paired_change(start: &[(usize, f64)], model: &[(usize, f64)]) -> Option<PairedChange> {
    let of_start: std::collections::HashMap<usize, f64> = start.iter().copied().collect();
    let mut d: Vec<(usize, f64)> = model.iter().filter_map(|(i, e)| of_start.get(i).map(|s| (*i, e - s))).collect();
    d.sort_by_key(|x| x.0);
    PairedChange::of(&d.iter().map(|x| x.1).collect::<Vec<_>>())
}

/// The held-out figures of the starting model with further parameters added (an oracle: the
/// true effect's terms, in a virtual cell), cross-validated exactly as the diagnosis does.
pub fn heldout_with(input: &Input<'_>, opts: &DiagnoseOptions, extra: &[Param]) -> Result<ErrorStats, DiagnoseError> {
    let cell = input.cell;
    let pick = |purpose: Purpose, given: &[String]| -> Vec<String> {
        if given.is_empty() { cell.sessions_for(purpose).map(|s| s.name.clone()).collect() } else { given.to_vec() }
    };
    let identification = pick(Purpose::Identification, &opts.identification);
    let validation = match &opts.validation {
        None => pick(Purpose::Validation, &[]),
        Some(v) if v.is_empty() => Vec::new(),
        Some(v) => v.clone(),
    };
    let mut sessions = identification.clone();
    sessions.extend(validation.iter().cloned());
    let mut work = cell.clone();
    order::fill_approach(&mut work, &sessions);
    let mut o = start_options(input, opts, sessions);
    for p in extra {
        if !o.model.extra.contains(p) {
            o.model.extra.push(*p);
        }
    }
    if let Some(start) = &mut o.start {
        start.extend(extra);
    }
    let st = stage::Stage::fit(&work, o)?;
    let pr = &st.problem;
    let tested_sessions = if validation.is_empty() { &identification } else { &validation };
    let tested: Vec<bool> = pr.obs.iter().map(|o| tested_sessions.contains(&pr.session_names[o.session])).collect();
    let joints: Vec<Vec<f64>> = pr.obs.iter().map(|o| o.state.q[..pr.model.dof()].to_vec()).collect();
    let folds = Folds::new(&joints, &tested, opts.folds, opts.seed);
    // Refitted in full on the folds, as the diagnosis's own figures are.
    let h = refit::refit_heldout(&work, &st, &folds, opts.threads)
        .unwrap_or_else(|_| cv::cross_validate(&st, &folds, None));
    ErrorStats::of(&h.norms()).ok_or_else(|| DiagnoseError::Option("no tested pose".into()))
}

fn pr_target(st: &stage::Stage, o: usize) -> Vector3<f64> {
    st.problem.target_position(&st.problem.obs[o])
}

/// A voxel edge giving about ten positions per voxel over their bounding box, rounded to 10 mm
/// (at least 20 mm).
fn auto_voxel(p: &[Vector3<f64>]) -> f64 {
    if p.is_empty() {
        return 0.1;
    }
    let (lo, hi) = p.iter().fold((p[0], p[0]), |(lo, hi), x| (lo.inf(x), hi.sup(x)));
    let d = hi - lo;
    let volume = d.x.max(0.01) * d.y.max(0.01) * d.z.max(0.01);
    let edge = (volume * 10.0 / p.len() as f64).cbrt();
    ((edge / 0.01).round() * 0.01).max(0.02)
}

#[cfg(test)]
mod tests {
    use super::and_list;

    #[test]
    fn names_are_joined_as_english_writes_them() {
        let s = |v: &[&str]| and_list(&v.iter().map(|x| x.to_string()).collect::<Vec<_>>());
        assert_eq!(s(&[]), "");
        assert_eq!(s(&["series-B"]), "series-B");
        assert_eq!(s(&["series-B", "series-D"]), "series-B and series-D");
        assert_eq!(s(&["a", "b", "c"]), "a, b and c");
    }
}
