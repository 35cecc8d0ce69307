//! Compensation: a batch of targets (TCP pose as `position_mm` + `quaternion` or ZY'X''
//! `rotation_deg`, with the configuration branch; or nominal `joints_deg` targets) and a tool →
//! per target the joints to command, the fake pose to program, the residual and iterations, or
//! that target's own error. Uses the robot's active parameter set unless one is named.

use axum::Json;
use axum::extract::{Path, State};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use std::sync::Arc;

use super::extract::{Authorized, COMPENSATE, JsonBody};
use super::robots::find as find_robot;
use super::{ApiError, AppState};
use crate::app::cache::CompiledSet;
use crate::db::records::RobotRow;
use crate::domain::pose::{FrameKind, FrameOut, TargetFrames, WorkObjectSpec, compensate_target, compensate_targets};
use crate::domain::validity::{Envelope, EnvelopeFile, Guard, HeldOutUncertainty, ValidationCheck, ValidityOut};
use crate::domain::{CompensationResult, TargetSpec, ToolSpec};
use crate::kinematics::Compensator;

/// A batch of targets to compensate.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CompensationRequest {
    /// The parameter set to use; default: the robot's active one.
    #[serde(default)]
    pub parameter_set_id: Option<String>,
    /// The tool the targets are for; default: the parameter set's own (identified) tool.
    #[serde(default)]
    pub tool: Option<ToolSpec>,
    /// The frame targets are given in and fake poses returned in: `world` (default; {W}, the
    /// measurement frame, fake poses through the nominal base) or `base` (targets in the
    /// calibrated base frame, fake poses in the controller's base frame, wobj0).
    #[serde(default)]
    pub frame: Option<FrameKind>,
    /// Targets and fake poses relative to this work object, declared in the robot's base frame
    /// as on the controller.
    #[serde(default)]
    pub work_object: Option<WorkObjectSpec>,
    /// Use a parameter set that has no held-out validation, or whose latest one found it no
    /// better than the nominal model (refused otherwise, 409).
    #[serde(default)]
    pub allow_unvalidated: bool,
    /// Compensate targets outside the envelope the set was calibrated in (the joint ranges of its
    /// identification and held-out validation measurements, ± 5°) instead of refusing each; each
    /// is noted.
    #[serde(default)]
    pub allow_outside_envelope: bool,
    /// At least one, at most the server's batch limit (`serve --max-batch`, default 10,000; the
    /// served document states the server's); ids for all or none, each once.
    #[schema(min_items = 1, max_items = 10000)]
    pub targets: Vec<TargetSpec>,
}

/// The compensated batch.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct CompensationOut {
    pub parameter_set_id: String,
    pub version: i64,
    /// The frame the targets were read in and the fake poses are written in, and how to program
    /// them.
    pub frame: FrameOut,
    /// What was checked: the validation the set was accepted on, the calibrated envelope, and
    /// whether each result carries its predicted uncertainty.
    pub validity: ValidityOut,
    /// One per target, in order: joints_deg, fake_pose (in `frame`, in the target's own Euler
    /// family and quaternion sign), confdata, residual_mm, residual_urad, iterations — or error;
    /// notes when the target was mended (a quaternion within 1e-3 of unit norm, normalised).
    pub results: Vec<CompensationResult>,
    /// Targets that could not be compensated.
    pub failed: usize,
}

/// The parameter set a robot's request works with: the one it names, or the robot's active one
/// (409 when there is neither); 422 naming `parameter_set_id` when it is unknown or another
/// robot's.
pub(super) async fn robot_set(
    state: &AppState,
    robot: &RobotRow,
    named: Option<&str>,
) -> Result<Arc<CompiledSet>, ApiError> {
    let Some(set_id) = named.or(robot.active_parameter_set_id.as_deref()) else {
        return Err(ApiError::conflict(format!(
            "robot '{}' has no active parameter set: activate one or name parameter_set_id",
            robot.name
        )));
    };
    let compiled = state
        .caches
        .parameter_set(&state.pool, set_id)
        .await?
        .ok_or_else(|| ApiError::unknown("parameter_set_id", format!("no parameter set '{set_id}'")))?;
    if compiled.row.robot_id != robot.id {
        return Err(ApiError::foreign_set("parameter_set_id"));
    }
    Ok(compiled)
}

/// The set's latest held-out validation (on validation sessions it was not fitted on), refused
/// when there is none or when it found the set no better than the nominal model; with the
/// envelope it validated and the uncertainty model it measured, when it records them.
async fn validation_check(
    state: &AppState,
    compiled: &CompiledSet,
) -> Result<(ValidationCheck, Option<Envelope>, Option<HeldOutUncertainty>), ApiError> {
    let (set_id, version) = (&compiled.row.id, compiled.row.version);
    let hint = format!(
        "validate it on held-out sessions: validation sessions it was not fitted on (POST \
         /v1/parameter-sets/{set_id}/validations), or set allow_unvalidated to use it anyway"
    );
    let found = crate::db::records::latest_held_out_validation(&state.pool, set_id, &compiled.fit_sessions).await?;
    let Some(v) = found else {
        let fitted = if compiled.fit_sessions.is_empty() {
            String::new()
        } else {
            format!(
                " (it was fitted on {}: a validation on any of them is in-sample and does not count)",
                compiled.fit_sessions.join(", ")
            )
        };
        return Err(ApiError::conflict_hint(
            format!(
                "parameter set v{version} has no held-out validation: none on validation sessions it was not fitted on{fitted}"
            ),
            hint,
        ));
    };
    if v.mean_mm >= v.nominal_mean_mm {
        return Err(ApiError::conflict_hint(
            format!(
                "parameter set v{version} failed its latest held-out validation ({}): its mean error {:.4} mm is no \
                 better than the nominal model's {:.4} mm",
                v.id, v.mean_mm, v.nominal_mean_mm
            ),
            hint,
        ));
    }
    let internal = |what: &str, e: String| ApiError::Internal(format!("stored validation {}: {what}: {e}", v.id));
    let envelope = match &v.envelope {
        None => None,
        Some(text) => {
            let file: EnvelopeFile =
                serde_json::from_str(text).map_err(|e| internal("validated_envelope", e.to_string()))?;
            Some(Envelope::from_file(&file).map_err(|e| internal("validated_envelope", e.to_string()))?)
        }
    };
    let uncertainty = match &v.uncertainty {
        None => None,
        Some(text) => Some(serde_json::from_str(text).map_err(|e| internal("uncertainty", e.to_string()))?),
    };
    Ok((
        ValidationCheck { validation_id: v.id, mean_mm: v.mean_mm, nominal_mean_mm: v.nominal_mean_mm },
        envelope,
        uncertainty,
    ))
}

/// Batches up to this size are solved on the request's own task.
const INLINE_TARGETS: usize = 8;

/// Compensate a batch of targets.
#[utoipa::path(post, path = "/v1/robots/{robot_id}/compensate", tag = "compensation",
    params(("robot_id" = String, Path, description = "Robot id")),
    request_body(content = CompensationRequest, content_type = "application/json"),
    responses(
        (status = 200, description = "One result per target; a target that cannot be reached carries its own error", body = CompensationOut),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json"),
        (status = 409, description = "No parameter set named and none active; the set has no held-out validation, or its latest found it no better than nominal (unless allow_unvalidated)", body = super::Problem, content_type = "application/problem+json"),
        (status = 413, description = "More targets than the batch limit", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Unknown set, a set of another robot, invalid tool", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["compensate"])))]
pub async fn compensate(
    State(state): State<AppState>,
    _auth: Authorized<COMPENSATE>,
    Path(robot_id): Path<String>,
    JsonBody(body): JsonBody<CompensationRequest>,
) -> Result<Json<CompensationOut>, ApiError> {
    let robot = find_robot(&state, &robot_id).await?;
    check_batch(&state, &body.targets)?;
    let compiled = robot_set(&state, &robot, body.parameter_set_id.as_deref()).await?;
    crate::domain::pose::check_targets(&body.targets, &compiled.set.model).map_err(|e| ApiError::domain(e, ""))?;
    let mut checked = checks(&state, &compiled, body.allow_unvalidated).await?;
    let validation = checked.validation.take();
    let (frame, results, mut validity) = run_batch(
        compiled.clone(),
        body.tool.as_ref(),
        body.frame,
        body.work_object.as_ref(),
        checked,
        body.allow_outside_envelope,
        body.targets,
    )
    .await?;
    validity.validation = validation;
    let failed = results.iter().filter(|r| r.error.is_some()).count();
    Ok(Json(CompensationOut {
        parameter_set_id: compiled.row.id.clone(),
        version: compiled.row.version,
        frame,
        validity,
        results,
        failed,
    }))
}

/// What the checks before a batch found.
pub(super) struct Checked {
    /// The held-out validation the set is accepted on (none when unvalidated use was asked for).
    pub validation: Option<ValidationCheck>,
    /// The envelope targets are checked against: the identification's data and the validation's.
    pub envelope: Option<Envelope>,
    /// The uncertainty model that validation measured.
    pub held_out: Option<HeldOutUncertainty>,
}

/// The set's held-out validation (unless `allow_unvalidated`), the envelope targets are checked
/// against (the identification's data and the validation's, joined) and the uncertainty model.
/// With `allow_unvalidated` a held-out validation is still used when there is one that passed.
pub(super) async fn checks(
    state: &AppState,
    compiled: &CompiledSet,
    allow_unvalidated: bool,
) -> Result<Checked, ApiError> {
    let (validation, validated, held_out) = match validation_check(state, compiled).await {
        Ok((check, envelope, held_out)) => (Some(check), envelope, held_out),
        Err(ApiError::Conflict { .. }) if allow_unvalidated => (None, None, None),
        Err(e) => return Err(e),
    };
    let envelope = match (&compiled.envelope, validated) {
        (Some(a), Some(b)) => Some(a.union(&b)),
        (a, b) => a.clone().or(b),
    };
    Ok(Checked { validation, envelope, held_out })
}

/// 413 naming `targets` when a batch is over the server's limit.
pub(super) fn check_batch(state: &AppState, targets: &[TargetSpec]) -> Result<(), ApiError> {
    if targets.len() > state.config.max_batch {
        return Err(ApiError::TooLarge {
            detail: format!("{} targets in one batch; the limit is {}", targets.len(), state.config.max_batch),
            field: Some("targets".into()),
        });
    }
    Ok(())
}

/// Compensate a batch with a compiled set (its own tool, or `tool`), reading targets and writing
/// fake poses in the request's frame, each target checked against `envelope` and given its
/// predicted uncertainty: the compensation route and the RAPID export share it.
/// How a request compensates for another tool than the set's own: said where a set's calibrated
/// TCP lies far from the one it declares.
pub(super) const GIVE_TOOL: &str = "give the controller's tool (the request's tool) to compensate for it";

pub(super) async fn run_batch(
    compiled: Arc<CompiledSet>,
    tool: Option<&ToolSpec>,
    frame: Option<FrameKind>,
    work_object: Option<&WorkObjectSpec>,
    checked: Checked,
    allow_outside: bool,
    targets: Vec<TargetSpec>,
) -> Result<(FrameOut, Vec<CompensationResult>, ValidityOut), ApiError> {
    let Checked { envelope, held_out, .. } = checked;
    let custom = match tool {
        None => None,
        Some(t) => Some(compiled.set.with_tool(t.to_tool().map_err(|e| ApiError::domain(e, "tool"))?)),
    };
    let frames = TargetFrames::new(&compiled.compensator, frame, work_object).map_err(|e| ApiError::domain(e, ""))?;
    let out = frames.out.clone();
    // With another tool, only the robot's parameters carry uncertainty (the identification did
    // not see that tool).
    let robot_only = custom.as_ref().and(compiled.covariance.as_ref()).map(|c| c.without_tool());
    let guard =
        |covariance| Guard { envelope: envelope.as_ref(), allow_outside, covariance, held_out: held_out.as_ref() };
    let mut validity = ValidityOut::new(&guard(robot_only.as_ref().or(compiled.covariance.as_ref())));
    if custom.is_none() {
        validity.notes.extend(crate::domain::validity::tool_note(&compiled.compensator, GIVE_TOOL));
    }
    let results = if custom.is_none() && targets.len() <= INLINE_TARGETS {
        // A few solves (~4 µs each) cost less than handing them to the blocking pool.
        let dof = compiled.set.dof();
        let g = guard(compiled.covariance.as_ref());
        targets
            .iter()
            .enumerate()
            .map(|(i, t)| compensate_target(&compiled.compensator, dof, &frames, &g, i, t))
            .collect()
    } else {
        let envelope = envelope.clone();
        let held_out = held_out.clone();
        tokio::task::spawn_blocking(move || {
            let own;
            let (comp, dof, covariance) = match &custom {
                None => (&compiled.compensator, compiled.set.dof(), compiled.covariance.as_ref()),
                Some(set) => {
                    own = Compensator::new(set);
                    (&own, set.dof(), robot_only.as_ref())
                }
            };
            let g = Guard { envelope: envelope.as_ref(), allow_outside, covariance, held_out: held_out.as_ref() };
            compensate_targets(comp, dof, &frames, &g, &targets)
        })
        .await?
    };
    Ok((out, results, validity))
}
