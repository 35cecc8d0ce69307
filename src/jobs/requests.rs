//! What a job is asked to do, as posted and as stored in `jobs.request_json` (sessions resolved to
//! ids at submission, so the stored request runs the same after a restart).

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::domain::ToolSpec;
use crate::domain::diagnosis::DiagnoseSpec;
pub use crate::domain::identification::SelectSpec;
use crate::domain::identification::{
    IdentifySpec, MeasurementRef, default_kappa_limit, default_residual_ratio_limit, default_rotation_weight_mm,
};

fn per_ball() -> usize {
    120
}
fn validation_poses() -> usize {
    506
}
fn one() -> u64 {
    1
}
fn yes() -> bool {
    true
}

/// A pose plan: collision-checked TriCal configurations on the artefact's balls (ν ≤ 50° from
/// each ball's rod), optionally a DETMAX selection of them re-sequenced into a collision-free
/// measuring order, and laser-tracker validation configurations over the workspace.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PosePlanRequest {
    pub artefact_id: String,
    /// The measuring tool (its TCP is the constrained ball's centre).
    pub tool: ToolSpec,
    /// Candidate configurations per ball (default 120: 360 in all, as the thesis).
    #[serde(default = "per_ball")]
    #[schema(minimum = 1, maximum = 2000)]
    pub per_ball: usize,
    /// Laser-tracker validation configurations (default 506; 0 for none).
    #[serde(default = "validation_poses")]
    #[schema(maximum = 10000)]
    pub validation: usize,
    /// Keep only a DETMAX-selected subset of the candidates (e.g. `{"n": 75}`).
    #[serde(default)]
    pub select: Option<SelectSpec>,
    /// Seed of the candidate draws.
    #[serde(default = "one")]
    pub seed: u64,
}

/// An identification: the robot's parameters from identification sessions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct IdentificationRequest {
    /// Identification sessions (ids or names), in order.
    #[schema(min_items = 1)]
    pub sessions: Vec<String>,
    /// Model options as `robocal identify --model`: `+beta,-compliance,+cyc2_h1,…` (default:
    /// geometry + β + compliance).
    #[serde(default)]
    pub model: String,
    /// Parameters held at their nominal values.
    #[serde(default)]
    pub fix: Vec<String>,
    /// Refuse fits whose column-scaled κ(J) exceeds this (thesis §4.2.3).
    #[serde(default = "default_kappa_limit")]
    #[schema(exclusive_minimum = 1.0)]
    pub kappa_limit: f64,
    /// Huber loss threshold in robust standard deviations; default plain least squares.
    #[serde(default)]
    pub huber: Option<f64>,
    /// Length weighting orientation residuals of full-pose measurements, mm per rad.
    #[serde(default = "default_rotation_weight_mm")]
    #[schema(exclusive_minimum = 0.0)]
    pub rotation_weight_mm: f64,
    /// Identify from a DETMAX-selected subset of the sessions' measurements.
    #[serde(default)]
    pub select: Option<SelectSpec>,
    /// Make the new parameter set the robot's active one when the job succeeds.
    #[serde(default)]
    pub activate: bool,
    /// Measurements left out of the fit (outliers a refused fit named): session (id or name) and
    /// 0-based index.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub exclude: Vec<MeasurementRef>,
    /// Weighted least squares: each residual row by 1/σ, the measurement's own `sigma_mm` where it
    /// has one, the default instrument model's otherwise.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub weighted: bool,
    /// Refuse a fit whose residual RMS exceeds this many times the RMS the instrument's noise
    /// predicts (default 50).
    #[serde(default = "default_residual_ratio_limit")]
    #[schema(exclusive_minimum = 1.0)]
    pub residual_ratio_limit: f64,
}

impl IdentificationRequest {
    /// The options as `robocal identify` takes them (every parameter may be freed).
    pub fn spec(&self) -> IdentifySpec {
        IdentifySpec {
            model: self.model.clone(),
            fix: self.fix.clone(),
            kappa_limit: self.kappa_limit,
            huber: self.huber,
            rotation_weight_mm: self.rotation_weight_mm,
            only: Vec::new(),
            exclude: self.exclude.clone(),
            weighted: self.weighted,
            residual_ratio_limit: self.residual_ratio_limit,
        }
    }
}

/// A validation of a parameter set on validation sessions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ValidationRequest {
    /// Validation sessions (ids or names) of the parameter set's robot.
    #[schema(min_items = 1)]
    pub sessions: Vec<String>,
    /// Keep the per-measurement residuals in the report (default true).
    #[serde(default = "yes")]
    pub residuals: bool,
}

/// A validation job as stored: the request and the set it validates.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ValidationJob {
    pub parameter_set_id: String,
    #[serde(flatten)]
    pub request: ValidationRequest,
}

/// A diagnosis job as stored: the set it diagnoses and the request, its sessions resolved at
/// submission to the ids of the robot's sessions (the defaults made explicit: every
/// identification session, every validation session), so it runs the same after a restart.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DiagnosisJob {
    pub parameter_set_id: String,
    #[serde(flatten)]
    pub request: DiagnoseSpec,
}

/// An ISO 9283 evaluation of a session: AP, RP, vAP, AD and RD of the nominal model and, with a
/// parameter set, the calibrated model's predicted ones (as `robocal iso9283 evaluate`). Stored
/// as sent, with the session and the set resolved to ids at submission.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Iso9283Request {
    /// The session measured at the test poses (id or name) of the robot: a laser-tracker or other
    /// position or pose session, not a ball session.
    pub session: String,
    /// Which pose (and cycle, approach) each evaluated measurement is; measurements not listed are
    /// not evaluated. The cell format has no pose id, so the assignment comes with the request,
    /// as the pose-assignment file comes with the cell on the command line.
    #[schema(min_items = 1, max_items = 100000)]
    pub poses: Vec<crate::domain::iso9283::PoseAssignment>,
    /// Pose pairs for distance accuracy and repeatability (AD, RD).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    #[schema(max_items = 1000)]
    pub pairs: Vec<crate::domain::iso9283::PosePair>,
    /// The parameter set of the calibrated figures (a set of this robot). Default: the robot's
    /// active set; the nominal figures only when it has none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(pattern = "^[0-9a-fA-F]{8}-[0-9a-fA-F]{4}-[0-9a-fA-F]{4}-[0-9a-fA-F]{4}-[0-9a-fA-F]{12}$")]
    pub parameter_set_id: Option<String>,
}
