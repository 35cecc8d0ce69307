//! The diagnosis on the wire: the report in millimetres and degrees with the unit in every field
//! name (its options as given are [`super::diagnosis_spec`]'s, re-exported here). Top-level keys:
//! `verdict`, `decomposition`, `where`, `candidates`, `shrink` (and `rounds`, `unavailable`,
//! `model`, `sessions`, `transfer`, `evidence`, `notes`).

use serde::{Deserialize, Serialize};

use super::ParameterSetDoc;
pub use super::diagnosis_spec::{DiagnoseSpec, NoiseSpec, input_of};
use super::validation::ErrorFigures;
use crate::diagnose::floor::Floor;
use crate::diagnose::library::Candidate;
use crate::diagnose::locate::Where;
use crate::diagnose::search::Decision;
use crate::diagnose::{Diagnosis, Effect, Status};
use crate::kinematics::{Param, Unit};
use crate::units::{DEG, MM, OUT_DEG, OUT_MM, round_to};
use crate::validate::stats::ErrorStats;

/// A diagnosis report: what the calibrated model misses, where, and which named effects
/// (DIAGNOSIS.md's library) explain it on held-out poses, in mm and degrees.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct DiagnosisOut {
    /// What the diagnosis concludes.
    pub verdict: VerdictOut,
    /// The starting model's error decomposed: calibrated, held out, noise floor.
    pub decomposition: DecompositionOut,
    /// Where the starting model misses (`where`): per axis, against configuration variables,
    /// per workspace voxel.
    #[serde(rename = "where")]
    pub location: WhereOut,
    /// Every candidate of every round, with its screening statistics and, for the ones
    /// confirmed on held-out poses, their held-out figures.
    pub candidates: Vec<CandidateOut>,
    /// From the starting model to the last accepted one, and last the model with an adopted
    /// payload when there is one: held-out figures of each.
    pub shrink: Vec<ShrinkOut>,
    /// The rounds of the search, in order, each with its decision.
    pub rounds: Vec<RoundOut>,
    /// Candidates these data cannot test, and why.
    pub unavailable: Vec<UnavailableOut>,
    /// The final model as `identify --model` options.
    pub model: String,
    /// The sessions used and how they were cross-validated.
    pub sessions: SessionsOut,
    /// The starting and the final model carried to other sessions (base and tools refitted).
    pub transfer: Vec<TransferOut>,
    /// The evidence of each named joint effect: the held-out residual before it, as the
    /// joint-angle error at its joint, against its own variable, beside what it predicts and the
    /// residual after it (binned). Absent in a diagnosis stored before this field.
    #[serde(default)]
    pub evidence: Vec<EvidenceOut>,
    /// Remarks in words: where the approach directions came from, a starting model that did not
    /// converge, what accepting fits.
    pub notes: Vec<String>,
}

/// The evidence for one named joint effect (see [`DiagnosisOut::evidence`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct EvidenceOut {
    /// The effect's label, as in `verdict.effects`.
    pub effect: String,
    /// The joint whose angle it corrects, 1-based.
    pub joint: usize,
    /// The x axis: `q<j>` (joint reading), `approach<j>` (its approach direction, −1/0/+1),
    /// `tau<j>` (its holding torque), 1-based, or for a periodic term `phase of <f> cycles per turn
    /// of q<j>` ((f·q_j) mod 360°: the residual folded onto one period).
    pub variable: String,
    /// Unit of the x axis: `deg`, `direction` or `N·m`.
    pub unit: String,
    /// 1 − Σ after² / Σ before² over the poses' residual angles at this joint: the share of the
    /// held-out residual there that the model with the effect removes.
    pub explained_share: Option<f64>,
    /// Poses used: tested poses where joint j moves the TCP by at least a fifth of the median.
    pub n: usize,
    /// The residuals binned along the x axis.
    pub bins: Vec<EvidenceBinOut>,
}

/// One bin of an evidence plot: angles at the effect's joint, deg.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct EvidenceBinOut {
    /// The bin's centre on the x axis (the variable's unit).
    pub at: f64,
    /// Poses in the bin.
    pub n: usize,
    /// Mean of the held-out residual before the effect, as the joint angle that explains it best.
    pub before_deg: f64,
    /// Its standard error.
    pub before_sem_deg: f64,
    /// Mean of the effect's own term (its parameters times their basis). It need not match the
    /// residual before: the model before took what its parameters could of the effect.
    pub predicted_deg: f64,
    /// Mean of the held-out residual after the effect.
    pub after_deg: f64,
}

/// A model carried to another set-up's session: its base and tools refitted there, its position
/// errors on that session.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct TransferOut {
    /// The transfer session, by name.
    pub session: String,
    /// `start`, `start + <effect> + …` (an intermediate model of the search, with the first
    /// effects accepted) or `final` (every accepted effect, fitted on the pooled data).
    pub model: String,
    /// Position |e| statistics of the model on the session, mm; `null` when the refit or its
    /// validation failed (then `error` says why).
    pub errors: Option<StatsOut>,
    /// Why the refit or its validation failed; `null` when it did not.
    pub error: Option<String>,
    /// Condition number κ of the column-scaled Jacobian of the base-and-tools refit; `null` when
    /// not known.
    pub kappa_scaled: Option<f64>,
    /// The errors split by whether the pose lies inside the joint ranges the model was identified
    /// on: outside them a table, harmonic or compliance term is extrapolated, and the transfer
    /// figure tests that extrapolation, not the model where it was measured. Absent when the
    /// refit failed (or from a diagnosis stored before this field).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_range: Option<JointRangeSplitOut>,
    /// The change of the mean error from the starting model's on the same session, paired reading
    /// by reading, with its standard error. Absent for `start`, when a refit failed, with fewer
    /// than 50 readings, or from a diagnosis stored before this field.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub change_from_start: Option<PairedChangeOut>,
    /// Base or tool parameters held in every model's refit on this session beyond the options'
    /// (`transfer_fix`): the session's data left them undetermined in some refit, so every model is
    /// carried with the same registration. Absent when the refits agreed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub held_in_every_refit: Vec<String>,
    /// `start` and `final`: the model registered with the joints' zero offsets refitted as well
    /// as base and tools, against base and tools alone, both held out on alternate poses. Absent
    /// for the intermediate models (or from a diagnosis stored before this field).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zeros_refitted: Option<ZerosRefitOut>,
}

/// A model registered on a transfer session with its joints' zero offsets refitted too. The
/// session's readings are split into alternate poses in measuring order; each half registers
/// the model (base and tools; base, tools and zeros) and the other half is scored. A robot
/// re-mastered between the set-ups, or whose zeros drifted, differs there by a constant angle
/// per joint that a base-and-tool registration cannot take.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ZerosRefitOut {
    /// Held-out |e| with base and tools registered, mm; `null` when a registration failed.
    pub held_out_base_tool: Option<StatsOut>,
    /// Held-out |e| with base, tools and the joints' zeros registered, mm; `null` when a
    /// registration failed.
    pub held_out_with_zeros: Option<StatsOut>,
    /// The change from the first to the second, paired reading by reading (negative: the zeros'
    /// registration predicts better); `null` with too few readings.
    pub change: Option<PairedChangeOut>,
    /// Each zero offset the registration on the whole session identifies: its change from the
    /// model's value, with its standard deviation.
    pub zero_shifts: Vec<ZeroShiftOut>,
    /// Why a registration failed; `null` when none did.
    pub error: Option<String>,
}

/// A joint's zero offset as a transfer session registers it, against the model's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ZeroShiftOut {
    /// The parameter (`theta2`).
    pub parameter: String,
    /// Registered value − the model's, degrees.
    pub change_deg: f64,
    /// Its standard deviation (the registration's and the model's own, from disjoint data,
    /// combined), degrees.
    pub std_deg: f64,
}

/// A transfer's change of the mean |e| from the starting model's, paired reading by reading.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct PairedChangeOut {
    /// Mean of |e|(model) − |e|(start) over the readings both were validated on, mm (negative: the
    /// model is the better).
    pub mean_mm: f64,
    /// Its standard error, mm, by batch means: the readings in measuring order cut into `batches`
    /// runs of consecutive poses, and the spread of the change's mean over the runs (neighbouring
    /// poses share their errors, so the poses are not taken as independent).
    pub standard_error_mm: f64,
    /// Readings paired.
    pub n: usize,
    /// Runs of consecutive readings (5–20, each of at least 10 readings).
    pub batches: usize,
}

/// A transfer's errors inside and outside the identification sessions' joint ranges.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct JointRangeSplitOut {
    /// Per joint, the identification sessions' [min, max], deg.
    pub identified_range_deg: Vec<[f64; 2]>,
    /// Share of the transfer session's poses with every joint inside its range (0–1).
    pub inside_share: f64,
    /// Per joint, the share of the poses outside that joint's range (0–1).
    pub outside_share_per_joint: Vec<f64>,
    /// Errors of the poses inside every range (absent: none is).
    pub inside: Option<StatsOut>,
    /// Errors of the poses outside at least one range (absent: none is).
    pub outside: Option<StatsOut>,
}

/// The sessions a diagnosis used.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct SessionsOut {
    /// The identification sessions, by name.
    pub identification: Vec<String>,
    /// The validation sessions, by name (empty: cross-validated on the identification sessions).
    pub validation: Vec<String>,
    /// Whose poses the folds test: `validation`, or `identification` when there is none.
    pub tested: String,
    /// K of the grouped K-fold cross-validation.
    pub folds: usize,
    /// Readings left out of every fit and every test: those the request named and those the
    /// parameter set's identification was told to leave out (the service names them by their
    /// stored index).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub excluded: Vec<super::identify_options::MeasurementRef>,
}

/// What a diagnosis concludes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct VerdictOut {
    /// `named`, `none`, `not_separable`, `unknown_effect` or `partial`.
    pub status: Status,
    /// The verdict in a sentence or two.
    pub summary: String,
    /// Named effects, most important first. For any other status, the suspects: not added to the
    /// model, each `estimate` is the screening's one-step linear estimate and has no σ.
    pub effects: Vec<EffectOut>,
    /// For `not_separable`: a look-alike the data cannot tell from the best candidate; `null`
    /// otherwise.
    pub lookalike: Option<CandidateRef>,
    /// For `not_separable` with a look-alike: the largest canonical correlation between the
    /// unabsorbed columns of the two; `null` otherwise.
    pub canonical_correlation: Option<f64>,
    /// Model parameters that absorb the suspect.
    pub absorbed_by: Vec<AbsorbedOut>,
    /// The experiment that would separate the effect.
    pub experiment: Option<String>,
    /// What remains after the named effects, when something does.
    pub remaining: Option<RemainingOut>,
    /// Where the joints' approach directions came from: `logged`, or derived from the measuring
    /// order — `time_order`, `sequence_order`, `file_order` (the notes say which sessions).
    pub approach_source: Option<String>,
}

/// What remains after the named effects, as another verdict.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct RemainingOut {
    /// The remainder's status (`unknown_effect`, `partial`, …).
    pub status: Status,
    /// The remainder in words.
    pub summary: String,
}

/// A model parameter that absorbs part of a candidate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct AbsorbedOut {
    /// The parameter's name (e.g. `theta3`).
    pub parameter: String,
    /// Share of the candidate the parameter absorbs.
    pub share: f64,
}

/// Which candidate: kind and place.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct CandidateRef {
    /// hayati_beta, compliance, compliance_cubic, cyclic, joint_map, backlash, thermal, coupling,
    /// tool_mass, base, tool.
    pub name: String,
    /// A short human label: `cyclic j2 h1`, `coupling 5→6`, `joint_map j3 (3° knots)`.
    pub label: String,
    /// The joint it acts on (1-based): the corrected joint, the coupling's destination, the
    /// Hayati joint (β of `beta{j−1}` tilts joint j), the tool's index (1-based) for `tool`.
    pub joint: Option<usize>,
    /// Coupling source joint (1-based).
    pub from_joint: Option<usize>,
    /// Cyclic: the whole harmonic, when the frequency is one.
    pub harmonic: Option<u16>,
    /// Cyclic: cycles per revolution.
    pub frequency_cpr: Option<f64>,
    /// Found by the frequency scan.
    pub scanned: bool,
    /// Joint tables: knot spacing, deg.
    pub step_deg: Option<u8>,
}

/// A named effect (or, for `not_separable`, a suspect) with its size and evidence.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct EffectOut {
    /// Which candidate (flattened).
    #[serde(flatten)]
    pub which: CandidateRef,
    /// The effect's size in `unit`: cyclic amplitude, backlash half-play, table RMS, α, kg, …
    /// For a group of terms over several joints (`backlash` on j1–j6), its most significant
    /// term's value (the largest |estimate|/σ); `parameters` has every term.
    pub estimate: Option<f64>,
    /// Standard deviation of `estimate`, in `unit`; `null` where not known (a suspect, a table).
    pub std: Option<f64>,
    /// The unit of `estimate` and `std` (`deg`, `mm`, `deg/(N·m)`, `ppm/K`, `kg`, …).
    pub unit: String,
    /// Its parameters: as fitted in the model that accepted it, or the screening's linear
    /// estimates for a suspect.
    pub parameters: Vec<ParamOut>,
    /// Held-out gain when it is added: mean |e| before minus after, mm.
    pub gain_mean_mm: f64,
    /// Held-out gain when it is added: RMS of |e| before minus after, mm.
    pub gain_rms_mm: f64,
    /// One-sided Wilcoxon p-value of the held-out confirmation.
    pub confirm_p: Option<f64>,
    /// Holm-corrected screening p-value (log10).
    pub screen_log10_p: f64,
    /// ρ = ‖J̃_k‖/‖J_k‖.
    pub separability: f64,
}

/// One parameter of an effect.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ParamOut {
    /// The parameter's name, as in parameter-set files (e.g. `cyc2_h1_sin`, `backlash3`).
    pub name: String,
    /// Its value, in `unit`.
    pub estimate: f64,
    /// Its standard deviation, in `unit`; `null` for a suspect or a parameter held fixed.
    pub std: Option<f64>,
    /// The unit of `estimate` and `std`.
    pub unit: String,
}

/// Error magnitudes over `n` poses: the validation report's figures (mean, median, std, RMS, p95,
/// max in mm) with their count.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct StatsOut {
    /// Number of poses (observations).
    pub n: usize,
    /// The figures, mm (flattened).
    #[serde(flatten)]
    pub figures: ErrorFigures,
}

/// The noise floor: the |e| the instrument and the robot's repeatability alone would give at the
/// tested positions, mm.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct FloorOut {
    /// Mean |e| under the floor (Monte Carlo), mm.
    pub mean_mm: f64,
    /// RMS of |e| under the floor (exact), mm.
    pub rms_mm: f64,
    /// 95th percentile of |e| under the floor (Monte Carlo), mm.
    pub p95_mm: f64,
    /// Mean instrument-and-repeatability σ per axis, mm.
    pub instrument_sigma_mm: f64,
    /// RMS of σ_pred(q) from the parameter covariance, mm.
    pub prediction_rms_mm: f64,
}

/// The starting model's error decomposed into coverage, missing physics and noise.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct DecompositionOut {
    /// The parameter set as given, on the validation poses (no refit); `null` without validation
    /// sessions.
    pub calibrated: Option<StatsOut>,
    /// The starting model, cross-validated (trained on the identification data and the other
    /// folds of the validation poses).
    pub heldout: StatsOut,
    /// The noise floor at the tested positions.
    pub floor: FloorOut,
    /// calibrated − held-out mean, mm: what the calibration poses' coverage explains; `null`
    /// without validation sessions.
    pub extrapolation_gap_mm: Option<f64>,
    /// held-out − floor mean, mm: what missing physics explains; gap closure is measured against
    /// it.
    pub unmodelled_gap_mm: f64,
}

/// The held-out signed error along one axis of {W}.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct AxisOut {
    /// Mean signed error, mm.
    pub mean_mm: f64,
    /// Sample standard deviation (divisor n − 1), mm.
    pub std_mm: f64,
    /// Shapiro–Wilk p-value of the signed errors (H0: normal); `null` when the test refuses the
    /// sample (fewer than 3 or more than 5000 values, or all equal).
    pub shapiro_p: Option<f64>,
}

/// The held-out signed error along each axis of {W}.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct PerAxisOut {
    /// Along X of {W}.
    pub x: AxisOut,
    /// Along Y of {W}.
    pub y: AxisOut,
    /// Along Z of {W}.
    pub z: AxisOut,
}

/// One bin of an error profile.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct BinOut {
    /// Bin centre in the variable's unit.
    pub at: f64,
    /// Mean |e| of the bin's poses, mm.
    pub mean_mm: f64,
    /// Poses in the bin.
    pub n: usize,
}

/// The held-out |e| of the starting model against one configuration variable.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct AgainstOut {
    /// distance_to_base, distance_to_zone, distance_to_nearest_calibration,
    /// joint_distance_to_nearest_calibration, q1…, tau1…, sigma_pred.
    pub variable: String,
    /// The variable's unit: mm, deg, N·m.
    pub unit: String,
    /// Pearson correlation of |e| with the variable; `null` when the line cannot be fitted
    /// (n < 3, zero variance).
    pub r: Option<f64>,
    /// Coefficient of determination, r²; `null` with `r`.
    pub r2: Option<f64>,
    /// mm of |e| per unit of the variable (least squares); `null` with `r`.
    pub slope: Option<f64>,
    /// Two-sided p-value of a zero slope; `null` with `r`.
    pub p_value: Option<f64>,
    /// Mean |e| over equal-count bins of the variable.
    pub profile: Vec<BinOut>,
}

/// A workspace voxel whose held-out error stands above the noise floor.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct VoxelOut {
    /// Centre of the voxel in {W}, mm.
    pub centre_mm: [f64; 3],
    /// Tested positions in the voxel.
    pub n: usize,
    /// Mean |e| of its positions, mm.
    pub mean_mm: f64,
    /// The floor's mean |e| there, mm.
    pub floor_mean_mm: f64,
    /// Uncorrected p-value of "the errors in this voxel are the floor's" (χ² test).
    pub p: f64,
    /// Benjamini–Hochberg q-value.
    pub q: f64,
}

/// The voxel tests of the workspace.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct VoxelsOut {
    /// Edge of the voxels, mm.
    pub size_mm: f64,
    /// Number of voxels tested.
    pub tested: usize,
    /// Voxels whose error stands above the floor at the false-discovery rate, worst first.
    pub above_floor: Vec<VoxelOut>,
}

/// Where the starting model misses.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct WhereOut {
    /// The residuals used: held-out errors of the starting model at the tested poses.
    pub n: usize,
    /// Signed error statistics along X, Y and Z of {W}.
    pub per_axis: PerAxisOut,
    /// |e| against each configuration variable.
    pub against: Vec<AgainstOut>,
    /// Workspace voxels tested against the floor.
    pub voxels: VoxelsOut,
    /// Whether the errors drift along the measuring order (`diagnose::drift`): a warm-up or a
    /// settling tracker or base, unlogged. `null` where the stops' places in the run are unknown
    /// (no times, no one sequence numbering, not one session listed as measured) or fewer than
    /// 40 stops are tested.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub order_drift: Option<OrderDriftOut>,
}

/// A drift of the starting model's held-out errors along the measuring order, beyond what the
/// configuration explains: a Freedman–Lane permutation test of cubic Legendre terms of each stop's
/// place in the run, with sin and cos of every joint in the reduced model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct OrderDriftOut {
    /// Whether a drift is said: p below 0.01 and the order not carrying the configuration
    /// (`order_on_configuration_r2` at most 0.2 and `order_locality` at least 0.8).
    pub found: bool,
    /// Where the places in the run came from: `time_s`, `sequence` or `file_order`.
    pub source: String,
    /// Stops tested (the readings at one stop averaged).
    pub stops: usize,
    /// Permutation p-value of "the errors do not depend on the place in the run".
    pub p: f64,
    /// Permutations drawn.
    pub permutations: usize,
    /// The fitted trend's mean over the last tenth of the stops minus over the first tenth, X, Y,
    /// Z of {W}, mm.
    pub first_to_last_mm: [f64; 3],
    /// Its standard deviation per axis, mm.
    pub first_to_last_std_mm: [f64; 3],
    /// Adjusted R² of the place in the run on the configuration (sin and cos of every joint):
    /// above 0.2 the order follows the pose and no drift is claimed.
    pub order_on_configuration_r2: f64,
    /// Mean joint distance between consecutive stops over that between any two: about 1 in random
    /// order; below 0.8 (a sweep, a grid, an order planned for short moves) neighbouring poses'
    /// alike errors make a trend along the order and no drift is claimed.
    pub order_locality: f64,
    /// Whether the joints' zeros creep along the run beyond a trend common to every pose: each
    /// joint's ∂(position)/∂θ_j times P1…P3 of the place in the run, beyond the configuration, the
    /// common trend and the fixed zeros, by the same permutations. Absent where no joint column
    /// was available (and in documents of earlier versions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_creep: Option<JointCreepOut>,
    /// Where a drift is found: the last model the search accepted, refitted on the same folds with
    /// the drift as a nuisance of the run (`identify --model +drift`). Absent otherwise, when that
    /// model could not be fitted, and in documents of earlier versions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nuisance: Option<DriftNuisanceOut>,
    /// What it says, in a sentence.
    pub statement: String,
}

/// The drift fitted as a nuisance of the run beside the diagnosis's last accepted model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct DriftNuisanceOut {
    /// RMS over the tested readings of the drift the pooled fit reads at each one's place in the
    /// run, mm.
    pub fitted_rms_mm: f64,
    /// The held-out mean of the last model the search accepted, mm (its shrink-table figure).
    pub without_mm: f64,
    /// The same model with the drift terms, refitted on the same folds: held-out mean at the run's
    /// mean (where the drift is zero, as a compensation serves), mm.
    pub with_mm: f64,
}

/// The test of the joints' zeros creeping along the measuring order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct JointCreepOut {
    /// Whether a creep is said: p below 0.01 and the order not carrying the configuration (the
    /// same guards as the common trend's).
    pub found: bool,
    /// Permutation p-value of "no joint's zero moves along the run beyond the configuration, a
    /// common trend and the fixed zeros".
    pub p: f64,
    /// Per joint, the fitted creep's mean over the last tenth of the stops minus over the first
    /// tenth, deg; `null` for a joint whose zero moves no stop here beyond the others' (its
    /// standard deviation would exceed 1°).
    pub first_to_last_deg: Vec<Option<f64>>,
    /// Its standard deviation per joint, deg (the regression's, stops independent).
    pub first_to_last_std_deg: Vec<Option<f64>>,
}

/// A candidate's held-out figures: the model plus the candidate against the model alone, on the
/// linearised folds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct HeldoutOut {
    /// Mean |e| of the model minus that with the candidate, mm.
    pub gain_mean_mm: f64,
    /// RMS of |e| of the model minus that with the candidate, mm.
    pub gain_rms_mm: f64,
    /// One-sided Wilcoxon signed-rank p-value that the candidate lowers the per-pose squared
    /// error; `null` when the test cannot be run.
    pub p: Option<f64>,
    /// Share of the held-out variance above the floor it explains.
    pub share: f64,
    /// Whether it confirms: Wilcoxon p below the confirmation level (Bonferroni over the round's
    /// cross-validated candidates), RMS and mean gains above their thresholds — or, for a
    /// direction-of-motion term below the relative-gain threshold, `beyond_smoother_and_drift`.
    pub confirmed: bool,
    /// A direction-of-motion term (backlash) below the relative gain a name otherwise needs: its
    /// held-out comparison, on the same folds, of the smoother and a drift along the run with and
    /// without it, which confirms it when significant (absent for every other candidate, and where
    /// the measuring order is unknown or moves between neighbouring poses).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beyond_smoother_and_drift: Option<BeyondOut>,
}

/// A held-out comparison of a candidate added to an alternative model against that model alone.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct BeyondOut {
    /// One-sided Wilcoxon signed-rank p-value over poses that the candidate lowers the per-pose
    /// squared error beyond the alternative.
    pub p: Option<f64>,
    /// Mean |e| of the alternative minus that with the candidate too, mm.
    pub gain_mean_mm: f64,
}

/// One candidate of one round: its score test on the round's model and, when cross-validated,
/// its held-out figures.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct CandidateOut {
    /// Search round (1-based).
    pub round: usize,
    /// Which candidate (flattened).
    #[serde(flatten)]
    pub which: CandidateRef,
    /// S: drop of the weighted RSS if added (score statistic).
    pub statistic: f64,
    /// Degrees of freedom d of the test (rank of the candidate's unabsorbed columns, or effective
    /// for a regularised candidate).
    pub dof: f64,
    /// F = (S/d)/((RSS − S)/(n − p − d)); 0 without a testable direction.
    pub f: f64,
    /// log10 of the uncorrected p-value (times the scan's multiplicity for a scanned frequency).
    pub log10_p: f64,
    /// Holm-corrected p-value (and its log10, which stays meaningful below 1e-300).
    pub p_holm: f64,
    /// log10 of the Holm-corrected p-value.
    pub log10_p_holm: f64,
    /// Whether the Holm-corrected p is below `alpha` (and the candidate has a testable direction).
    pub significant: bool,
    /// Separability ρ = ‖J̃_k‖_F/‖J_k‖_F: the share of its columns the model cannot absorb (0:
    /// absorbed; 1: orthogonal to the model).
    pub separability: f64,
    /// BIC gain n·ln(RSS/(RSS − S)) − d·ln n, the ranking (0 when not finite).
    pub bic_gain: f64,
    /// Held-out figures; `null` when the candidate was not cross-validated this round.
    pub heldout: Option<HeldoutOut>,
    /// The model parameters that absorb most of it (at most three, each above 5 %).
    pub absorbed_by: Vec<AbsorbedOut>,
}

/// Held-out figures of one model of the search: the starting model or one with the first
/// accepted effects, refitted in full on the folds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ShrinkOut {
    /// `start`, then `start + …` with each accepted effect, and last `… + tool_mass` when the
    /// diagnosis adopted a payload that the set's identification had held at 0 kg.
    pub model: String,
    /// The effects added to the starting model, by label (empty for `start`; `tool_mass` for an
    /// adopted payload).
    pub effects: Vec<String>,
    /// Number of tested observations.
    pub n: usize,
    /// Mean held-out |e|, mm.
    pub mean_mm: f64,
    /// RMS of held-out |e|, mm.
    pub rms_mm: f64,
    /// 95th percentile of held-out |e|, mm.
    pub p95_mm: f64,
    /// Largest held-out |e|, mm.
    pub max_mm: f64,
    /// (E_start − E)/(E_start − E_floor) on the mean; `null` for the starting model.
    pub gap_closure: Option<f64>,
}

/// One round of the search and what it decided.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct RoundOut {
    /// The round (1-based).
    pub round: usize,
    /// `accept`, `nothing`, `not_separable`, `unknown_effect`, `partial` (the best candidate explains a
    /// minority of what a smooth function explains) or `refuted` (confirmed on linearised folds, not
    /// by the model refitted in full on them).
    pub decision: String,
    /// The label of the candidate the decision is about; `null` for `nothing` (and for
    /// `unknown_effect` when no candidate confirmed).
    pub candidate: Option<String>,
    /// The smoother (a generic joint-space correction) against the round's model: its held-out
    /// RMS gain, mm.
    pub smoother_gain_rms_mm: f64,
    /// One-sided Wilcoxon p-value that the smoother beats the round's model; `null` when the test
    /// cannot be run.
    pub smoother_p: Option<f64>,
    /// Why a `refuted` round's candidate was not named: the linearised and the refitted gains.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

/// A kind of candidate these data cannot test.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct UnavailableOut {
    /// The kind (`backlash`, `thermal`, …).
    pub name: String,
    /// Why, in a clause.
    pub reason: String,
}

fn stats(s: &ErrorStats) -> StatsOut {
    StatsOut { n: s.n, figures: ErrorFigures::of(s) }
}

fn floor_out(f: &Floor) -> FloorOut {
    FloorOut {
        mean_mm: f.mean / MM,
        rms_mm: f.rms / MM,
        p95_mm: f.p95 / MM,
        instrument_sigma_mm: f.instrument_sigma / MM,
        prediction_rms_mm: f.prediction_rms / MM,
    }
}

/// The wire form of a candidate: its kind, label and place (joints 1-based).
pub fn candidate_ref(c: &Candidate) -> CandidateRef {
    let q = c.quarters;
    CandidateRef {
        name: c.kind.name().to_string(),
        label: c.label(),
        joint: c.joint.map(|j| j + 1),
        from_joint: c.from.map(|j| j + 1),
        harmonic: q.filter(|q| q.is_multiple_of(4)).map(|q| q / 4),
        frequency_cpr: c.frequency(),
        scanned: c.scanned,
        step_deg: c.step_deg,
    }
}

/// A value in SI → its file unit.
fn file(v: f64, unit: Unit) -> f64 {
    v / unit.to_si()
}

fn param_out(p: Param, value: f64, std: Option<f64>) -> ParamOut {
    let u = p.unit();
    ParamOut {
        name: p.to_string(),
        estimate: file(value, u),
        std: std.map(|s| file(s, u)),
        unit: u.as_str().to_string(),
    }
}

fn effect_out(e: &Effect) -> EffectOut {
    EffectOut {
        which: candidate_ref(&e.candidate),
        estimate: e.estimate.map(|v| file(v, e.unit)),
        std: e.std.map(|v| file(v, e.unit)),
        unit: e.unit.as_str().to_string(),
        parameters: e.parameters.iter().map(|p| param_out(p.param, p.value, p.std)).collect(),
        gain_mean_mm: e.gain_mean / MM,
        gain_rms_mm: e.gain_rms / MM,
        confirm_p: e.confirm_p,
        screen_log10_p: e.screen_log10_p,
        separability: e.separability,
    }
}

fn absorbed(v: &[(String, f64)]) -> Vec<AbsorbedOut> {
    v.iter().map(|(p, s)| AbsorbedOut { parameter: p.clone(), share: *s }).collect()
}

/// The unit a "where" variable is reported in, and its SI factor.
fn variable_unit(name: &str) -> (&'static str, f64) {
    if name.starts_with('q') {
        ("deg", DEG)
    } else if name.starts_with("tau") {
        ("N·m", 1.0)
    } else if name.starts_with("joint_distance") {
        ("deg", DEG)
    } else {
        ("mm", MM)
    }
}

fn where_out(w: &Where) -> WhereOut {
    let axis = |a: &crate::diagnose::locate::Axis| AxisOut {
        mean_mm: a.mean / MM,
        std_mm: a.std / MM,
        shapiro_p: a.shapiro_p,
    };
    WhereOut {
        n: w.n,
        per_axis: PerAxisOut { x: axis(&w.per_axis[0]), y: axis(&w.per_axis[1]), z: axis(&w.per_axis[2]) },
        against: w
            .against
            .iter()
            .map(|a| {
                let (unit, k) = variable_unit(&a.variable);
                AgainstOut {
                    variable: a.variable.clone(),
                    unit: unit.to_string(),
                    r: a.fit.map(|f| f.r),
                    r2: a.fit.map(|f| f.r2),
                    slope: a.fit.map(|f| f.slope / MM * k),
                    p_value: a.fit.map(|f| f.p_value),
                    profile: a.profile.iter().map(|&(x, m, n)| BinOut { at: x / k, mean_mm: m / MM, n }).collect(),
                }
            })
            .collect(),
        voxels: VoxelsOut {
            size_mm: w.voxel_size / MM,
            tested: w.voxels_tested,
            above_floor: w
                .voxels
                .iter()
                .map(|v| VoxelOut {
                    centre_mm: [v.centre.x / MM, v.centre.y / MM, v.centre.z / MM],
                    n: v.n,
                    mean_mm: v.mean_error / MM,
                    floor_mean_mm: v.floor_mean / MM,
                    p: v.p,
                    q: v.q,
                })
                .collect(),
        },
        order_drift: w.order_drift.as_ref().map(|d| OrderDriftOut {
            found: d.found(),
            source: d.source.as_str().to_string(),
            stops: d.stops,
            p: d.p,
            permutations: d.permutations,
            first_to_last_mm: [0, 1, 2].map(|k| d.first_to_last[k] / MM),
            first_to_last_std_mm: [0, 1, 2].map(|k| d.first_to_last_std[k] / MM),
            order_on_configuration_r2: d.order_on_configuration_r2,
            order_locality: d.order_locality,
            joint_creep: d.joint_creep.as_ref().map(|c| JointCreepOut {
                found: d.creep_found(),
                p: c.p,
                first_to_last_deg: c.first_to_last.iter().map(|v| v.map(|v| v / DEG)).collect(),
                first_to_last_std_deg: c.first_to_last_std.iter().map(|v| v.map(|v| v / DEG)).collect(),
            }),
            nuisance: d.nuisance.map(|n| DriftNuisanceOut {
                fitted_rms_mm: n.fitted_rms / MM,
                without_mm: n.without / MM,
                with_mm: n.with / MM,
            }),
            statement: d.statement(),
        }),
    }
}

/// The model options of the final model as `identify --model` would spell them.
fn model_spec(d: &Diagnosis) -> String {
    use crate::kinematics::JointTerm;
    let m = &d.model.model;
    let dof = d.dof;
    // β and compliance as blocks when every joint that can have them does.
    let all_c = (1..dof).all(|j| m.compliance || m.extra.contains(&Param::Joint(j, JointTerm::Compliance)));
    let n_beta = m.extra.iter().filter(|p| matches!(p, Param::Beta(_))).count();
    let all_b = m.beta || (n_beta > 0 && n_beta == d.parallel_rows);
    let mut items: Vec<String> = vec![
        if all_b { "+beta" } else { "-beta" }.to_string(),
        if all_c { "+compliance" } else { "-compliance" }.to_string(),
    ];
    let rest: Vec<Param> = m
        .extra
        .iter()
        .copied()
        .filter(|p| match p {
            Param::Beta(_) => !all_b,
            Param::Joint(_, JointTerm::Compliance) => !all_c,
            _ => true,
        })
        .collect();
    items.extend(crate::identify::term_spec(&rest));
    items.join(",")
}

/// The wire form of a diagnosis, in mm and degrees, with its notes.
pub fn diagnosis_out(d: &Diagnosis) -> DiagnosisOut {
    let v = &d.verdict;
    let verdict = VerdictOut {
        status: v.status,
        summary: v.summary.clone(),
        effects: v.effects.iter().map(effect_out).collect(),
        lookalike: v.lookalike.as_ref().map(candidate_ref),
        canonical_correlation: v.canonical_correlation,
        absorbed_by: absorbed(&v.absorbed_by),
        experiment: v.experiment.clone(),
        remaining: v.remaining.as_ref().map(|(s, t)| RemainingOut { status: *s, summary: t.clone() }),
        approach_source: d.approach.map(|a| a.as_str().to_string()),
    };
    let dc = &d.decomposition;
    let decomposition = DecompositionOut {
        calibrated: dc.calibrated.as_ref().map(stats),
        heldout: stats(&dc.heldout),
        floor: floor_out(&dc.floor),
        extrapolation_gap_mm: dc.extrapolation_gap.map(|g| g / MM),
        unmodelled_gap_mm: dc.unmodelled_gap / MM,
    };
    let mut candidates = Vec::new();
    let mut rounds = Vec::new();
    for (k, r) in d.rounds.iter().enumerate() {
        for (i, s) in r.screened.iter().enumerate() {
            let ev = r.evaluated.iter().find(|e| e.index == i);
            candidates.push(CandidateOut {
                round: k + 1,
                which: candidate_ref(&s.candidate),
                statistic: s.score.s,
                dof: s.score.dof,
                f: s.score.f,
                log10_p: s.score.log10_p,
                p_holm: 10f64.powf(s.log10_p_holm),
                log10_p_holm: s.log10_p_holm,
                significant: s.significant,
                separability: s.score.rho,
                bic_gain: if s.score.bic_gain.is_finite() { s.score.bic_gain } else { 0.0 },
                heldout: ev.map(|e| HeldoutOut {
                    gain_mean_mm: e.vs_model.gain_mean / MM,
                    gain_rms_mm: e.vs_model.gain_rms / MM,
                    p: e.vs_model.p,
                    share: e.share,
                    confirmed: e.confirmed,
                    beyond_smoother_and_drift: e
                        .apart
                        .as_ref()
                        .and_then(|a| a.comparison())
                        .map(|a| BeyondOut { p: a.p, gain_mean_mm: a.gain_mean / MM }),
                }),
                absorbed_by: absorbed(&s.absorbed_by),
            });
        }
        let reason = match &r.decision {
            Decision::Refuted { reason, .. } => Some(reason.clone()),
            _ => None,
        };
        let (decision, cand) = match &r.decision {
            Decision::Accept(i) => ("accept", Some(r.screened[*i].candidate.label())),
            Decision::Nothing => ("nothing", None),
            Decision::NotSeparable { best, .. } => ("not_separable", Some(r.screened[*best].candidate.label())),
            Decision::Unknown { best } => ("unknown_effect", best.map(|i| r.screened[i].candidate.label())),
            Decision::Partial { best, .. } => ("partial", Some(r.screened[*best].candidate.label())),
            Decision::Refuted { best, .. } => ("refuted", Some(r.screened[*best].candidate.label())),
        };
        rounds.push(RoundOut {
            round: k + 1,
            decision: decision.to_string(),
            candidate: cand,
            smoother_gain_rms_mm: r.smoother.gain_rms / MM,
            smoother_p: r.smoother.p,
            reason,
        });
    }
    let shrink = d
        .shrink
        .iter()
        .map(|s| ShrinkOut {
            model: if s.model.is_empty() { "start".into() } else { format!("start + {}", s.model.join(" + ")) },
            effects: s.model.clone(),
            n: s.stats.n,
            mean_mm: s.stats.mean / MM,
            rms_mm: s.stats.rms / MM,
            p95_mm: s.stats.p95 / MM,
            max_mm: s.stats.max / MM,
            gap_closure: s.closure,
        })
        .collect();
    let mut notes = d.approach_notes.clone();
    notes.extend(d.excluded_note.clone());
    notes.extend(d.drift_note.clone());
    if let Some(why) = &d.location.order_drift_untested {
        notes.push(format!("the measuring order was not tested for a drift (where.order_drift): {why}"));
    }
    if let Some(n) = &d.start_note {
        notes.push(format!(
            "the starting model does not converge on the pooled data ({n}); it is linearised at the given parameter set"
        ));
    }
    // Once per session: every model of a session carries the same `held`, and each has one start.
    for t in d.transfer.iter().filter(|t| t.model == "start" && !t.held.is_empty()) {
        notes.push(format!(
            "{}: {} held at each model's value in every model's base-and-tools refit there — the session's data leave {} undetermined in some of the refits (standard deviation beyond the bound), and every model is carried with the same registration",
            t.session,
            t.held.join(", "),
            if t.held.len() == 1 { "it" } else { "them" }
        ));
    }
    if d.verdict.status == Status::Named {
        notes.push(
            "accepting fits the final model on the identification and validation sessions together; its held-out figures are the shrink table's"
                .into(),
        );
    }
    DiagnosisOut {
        verdict,
        decomposition,
        location: where_out(&d.location),
        candidates,
        shrink,
        rounds,
        unavailable: d
            .unavailable
            .iter()
            .map(|u| UnavailableOut { name: u.kind.name().to_string(), reason: u.reason.clone() })
            .collect(),
        model: model_spec(d),
        sessions: SessionsOut {
            identification: d.identification.clone(),
            validation: d.validation.clone(),
            tested: if d.validation.is_empty() { "identification".into() } else { "validation".into() },
            folds: d.folds,
            excluded: d
                .excluded
                .iter()
                .map(|(session, index)| super::identify_options::MeasurementRef {
                    session: session.clone(),
                    index: *index,
                })
                .collect(),
        },
        transfer: d
            .transfer
            .iter()
            .map(|t| TransferOut {
                session: t.session.clone(),
                model: t.model.clone(),
                errors: t.errors.as_ref().ok().map(stats),
                error: t.errors.as_ref().err().cloned(),
                kappa_scaled: t.kappa_scaled,
                joint_range: t.range.as_ref().map(|r| JointRangeSplitOut {
                    identified_range_deg: r
                        .joints
                        .iter()
                        .map(|[a, b]| [round_to(a / DEG, OUT_DEG), round_to(b / DEG, OUT_DEG)])
                        .collect(),
                    inside_share: round_to(r.inside_share, 1e-4),
                    outside_share_per_joint: r.outside_share_per_joint.iter().map(|v| round_to(*v, 1e-4)).collect(),
                    inside: r.inside.as_ref().map(stats),
                    outside: r.outside.as_ref().map(stats),
                }),
                held_in_every_refit: t.held.clone(),
                change_from_start: t.change.as_ref().map(paired_change_out),
                zeros_refitted: t.zeros.as_ref().map(|z| match z {
                    Ok(z) => ZerosRefitOut {
                        held_out_base_tool: Some(stats(&z.base_tool)),
                        held_out_with_zeros: Some(stats(&z.with_zeros)),
                        change: z.change.as_ref().map(paired_change_out),
                        zero_shifts: z
                            .shifts
                            .iter()
                            .map(|(n, d, sd)| ZeroShiftOut {
                                parameter: n.clone(),
                                change_deg: round_to(d / DEG, OUT_DEG),
                                std_deg: round_to(sd / DEG, OUT_DEG),
                            })
                            .collect(),
                        error: None,
                    },
                    Err(e) => ZerosRefitOut {
                        held_out_base_tool: None,
                        held_out_with_zeros: None,
                        change: None,
                        zero_shifts: Vec::new(),
                        error: Some(e.clone()),
                    },
                }),
            })
            .collect(),
        evidence: d.evidence.iter().map(evidence_out).collect(),
        notes,
    }
}

fn paired_change_out(c: &crate::diagnose::PairedChange) -> PairedChangeOut {
    PairedChangeOut {
        mean_mm: round_to(c.mean / MM, OUT_MM),
        standard_error_mm: round_to(c.se / MM, OUT_MM),
        n: c.n,
        batches: c.batches,
    }
}

fn evidence_out(e: &crate::diagnose::Evidence) -> EvidenceOut {
    use crate::diagnose::EvidenceVariable as V;
    let (variable, unit, x_scale) = match e.variable {
        V::Reading(j) => (format!("q{}", j + 1), "deg", 1.0 / DEG),
        V::Approach(j) => (format!("approach{}", j + 1), "direction", 1.0),
        V::Torque(j) => (format!("tau{}", j + 1), "N·m", 1.0),
        V::Phase(j, f) => (format!("phase of {f} cycles per turn of q{}", j + 1), "deg", 1.0 / DEG),
    };
    let deg = |v: f64| round_to(v / DEG, OUT_DEG);
    EvidenceOut {
        effect: e.effect.clone(),
        joint: e.joint + 1,
        variable,
        unit: unit.into(),
        explained_share: e.explained.map(|s| round_to(s, 1e-4)),
        n: e.n,
        bins: e
            .bins
            .iter()
            .map(|b| EvidenceBinOut {
                at: round_to(b.at * x_scale, 1e-4),
                n: b.n,
                before_deg: deg(b.before),
                before_sem_deg: deg(b.before_sem),
                predicted_deg: deg(b.predicted),
                after_deg: deg(b.after),
            })
            .collect(),
    }
}

/// The parameter set an accepted diagnosis produces: the final model fitted on the pooled
/// sessions, as a parameter-set document (statuses, std, quality report); `None` when no effect
/// was named.
pub fn accepted_doc(d: &Diagnosis) -> Option<ParameterSetDoc> {
    let id = d.accepted.as_ref()?;
    if d.verdict.status != Status::Named {
        return None;
    }
    let mut sessions = d.identification.clone();
    sessions.extend(d.validation.iter().cloned());
    // The payload's centre of mass identified with it, as `identify` gives it (one fit from the
    // accepted solution); the fit with the centre of mass at the flange is not run here.
    let payload = super::identification::payload_quality(id, None).map(|p| super::quality::PayloadQuality {
        with_centre_of_mass: super::identification::payload_with_centre_of_mass(&d.model, id, false),
        ..p
    });
    let mut doc = super::identification::identification_doc(id, &sessions, None, payload);
    if let Some(q) = doc.quality.as_mut() {
        q.diagnosis = Some(super::quality::AcceptedDiagnosis {
            accepted: Some(d.verdict.effects.iter().map(|e| e.candidate.label()).collect()),
            model: Some(model_spec(d)),
            other: Default::default(),
        });
    }
    Some(doc)
}
