//! What the jobs produce, typed and documented: each kind's result as the job reports it (where
//! the output is stored, and a summary), and the pose plan itself. Stored as their JSON in
//! `jobs.result_json` and `pose_plans.result_json`; field order is the wire order.

use serde::{Deserialize, Serialize};
use serde_json::Value;
use utoipa::ToSchema;

use crate::db::jobs::JobKind;
use crate::domain::ToolSpec;
use crate::domain::validation::ErrorFigures;

/// An identification configuration of a pose plan, in measuring order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct PlannedBallPose {
    /// Joint targets, deg.
    pub joints_deg: Vec<f64>,
    /// The ball (1–3) the TriCal centres on.
    pub ball: Option<usize>,
    /// Angle ν between the TriCal's axis and the ball's rod, deg.
    pub nu_deg: Option<f64>,
}

/// A laser-tracker validation configuration of a pose plan.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct PlannedTrackerPose {
    /// Joint targets, deg.
    pub joints_deg: Vec<f64>,
    /// The reflector nest (0-based index into `nests`) facing the tracker.
    pub nest: Option<usize>,
}

/// A reflector nest of the measuring tool.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct PlanNest {
    /// The nest as a tool: TCP at the reflector centre, in the flange frame.
    pub tool: ToolSpec,
    /// Unit direction the nest opens towards, in the flange frame.
    #[schema(min_items = 3, max_items = 3)]
    pub opening: [f64; 3],
}

/// A pose plan: the joints to measure, in order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct PosePlan {
    /// TriCal configurations in measuring order (the DETMAX selection when one was asked for).
    pub identification: Vec<PlannedBallPose>,
    /// Laser-tracker configurations.
    pub validation: Vec<PlannedTrackerPose>,
    /// Collision-checked candidates the identification poses were chosen from.
    pub candidates: usize,
    /// The DETMAX settings and indices, when a selection was asked for.
    #[schema(value_type = Option<Object>)]
    pub selection: Option<Value>,
    /// The reflector nests, in the flange frame.
    pub nests: Vec<PlanNest>,
    /// The safe start configuration, deg.
    pub home_deg: Vec<f64>,
}

/// A pose-plan job's result.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct PosePlanResult {
    pub pose_plan_id: String,
    /// Identification configurations in the plan.
    pub identification: usize,
    /// Validation configurations in the plan.
    pub validation: usize,
}

/// An identification in figures.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct IdentificationSummary {
    /// Parameters identified.
    pub identified: usize,
    /// Measurements fitted.
    pub measurements: usize,
    /// Measurements of the sessions left out because they are excluded in the store.
    #[serde(default)]
    pub excluded: usize,
    pub iterations: usize,
    /// κ(J) in SI units.
    pub kappa_si: f64,
    /// κ of the column-scaled Jacobian (the one the limit applies to).
    pub kappa_scaled: f64,
    /// Observability index O1, SI units.
    pub o1_si: f64,
    pub rms_residual_mm: f64,
}

/// An identification job's result.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct IdentificationResult {
    pub parameter_set_id: String,
    pub version: i64,
    /// The set was made the robot's active one.
    pub activated: bool,
    pub summary: IdentificationSummary,
}

/// A validation in figures: the calibrated model's errors, and the nominal model's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ValidationJobSummary {
    pub measurements: usize,
    /// Whether the figures are held out: none of the validated sessions was used to fit the set
    /// (absent in results stored before this was recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out: Option<bool>,
    /// The same in words: what the set was fitted on, and whether that includes these sessions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out_statement: Option<String>,
    #[serde(flatten)]
    pub calibrated: ErrorFigures,
    pub nominal: ErrorFigures,
}

/// A validation job's result.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ValidationResult {
    pub validation_id: String,
    pub parameter_set_id: String,
    pub summary: ValidationJobSummary,
}

/// A diagnosis job's result: where the diagnosis is stored and its verdict in brief.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct DiagnosisResult {
    pub diagnosis_id: String,
    pub parameter_set_id: String,
    pub status: crate::diagnose::Status,
    pub summary: String,
    /// Labels of the named effects (for `not_separable`, the suspects), most important first.
    pub effects: Vec<String>,
}

/// An ISO 9283 evaluation job's result: where the evaluation is stored and its summaries.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Iso9283Result {
    /// `GET /v1/iso9283/{evaluation_id}` (JSON) and `…/report` (HTML).
    pub evaluation_id: String,
    /// The session evaluated, by name.
    pub session: String,
    /// The set of the calibrated figures; absent: nominal only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parameter_set_id: Option<String>,
    pub nominal: crate::domain::iso9283::Summary,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibrated: Option<crate::domain::iso9283::Summary>,
}

/// A finished job's result, by its kind.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(untagged)]
pub enum JobResult {
    PosePlan(PosePlanResult),
    Identification(IdentificationResult),
    Validation(ValidationResult),
    Diagnosis(DiagnosisResult),
    Iso9283(Iso9283Result),
}

impl JobResult {
    /// A stored result of a job of `kind`.
    pub fn from_json(kind: JobKind, json: &str) -> Result<JobResult, serde_json::Error> {
        Ok(match kind {
            JobKind::PosePlan => JobResult::PosePlan(serde_json::from_str(json)?),
            JobKind::Identification => JobResult::Identification(serde_json::from_str(json)?),
            JobKind::Validation => JobResult::Validation(serde_json::from_str(json)?),
            JobKind::Diagnosis => JobResult::Diagnosis(serde_json::from_str(json)?),
            JobKind::Iso9283 => JobResult::Iso9283(serde_json::from_str(json)?),
        })
    }
}
