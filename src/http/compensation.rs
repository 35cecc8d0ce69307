//! Compensation: a batch of targets (TCP pose as `position_mm` + `quaternion` or ZY'X''
//! `rotation_deg`, with the configuration branch; or nominal `joints_deg` targets) and a tool →
//! per target the joints to command, the fake pose to program, the residual and iterations, or
//! that target's own error. Uses the robot's active parameter set unless one is named.

use axum::Json;
use axum::extract::{Path, State};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::extract::{Authorized, COMPENSATE, JsonBody};
use super::robots::find as find_robot;
use super::{ApiError, AppState};
use crate::domain::pose::{FrameKind, FrameOut, TargetFrames, WorkObjectSpec, compensate_target, compensate_targets};
use crate::domain::{CompensationResult, TargetSpec, ToolSpec};
use crate::kinematics::{Compensator, Param, ParameterSet, Tool};

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
    /// At most the server's batch limit (`serve --max-batch`, default 10,000; the served document
    /// states the server's).
    #[schema(max_items = 10000)]
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
    /// One per target, in order: joints_deg, fake_pose (in `frame`, in the target's own Euler
    /// family and quaternion sign), confdata, residual_mm, residual_urad, iterations — or error;
    /// notes when the target was mended (a quaternion within 1e-3 of unit norm, normalised).
    pub results: Vec<CompensationResult>,
    /// Targets that could not be compensated.
    pub failed: usize,
}

/// The set with another tool: its TCP (nominal and calibrated) and payload.
pub fn with_tool(set: &ParameterSet, tool: Tool) -> ParameterSet {
    let mut s = set.clone();
    for k in 0..6 {
        if let Some(i) = s.layout.index_of(Param::Tool(k)) {
            s.values[i] = tool.tcp[k];
            s.nominal[i] = tool.tcp[k];
        }
    }
    s.tool = tool;
    s
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
        (status = 409, description = "No parameter set named and none active", body = super::Problem, content_type = "application/problem+json"),
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
    if body.targets.len() > state.config.max_batch {
        return Err(ApiError::TooLarge {
            detail: format!("{} targets in one batch; the limit is {}", body.targets.len(), state.config.max_batch),
            field: Some("targets".into()),
        });
    }
    let set_id = match (&body.parameter_set_id, &robot.active_parameter_set_id) {
        (Some(id), _) => id.clone(),
        (None, Some(id)) => id.clone(),
        (None, None) => {
            return Err(ApiError::conflict(format!(
                "robot '{}' has no active parameter set: activate one or name parameter_set_id",
                robot.name
            )));
        }
    };
    let compiled = state
        .caches
        .parameter_set(&state.pool, &set_id)
        .await?
        .ok_or_else(|| ApiError::invalid("parameter_set_id", format!("no parameter set '{set_id}'")))?;
    if compiled.row.robot_id != robot.id {
        return Err(ApiError::invalid("parameter_set_id", "the set belongs to another robot"));
    }
    let custom = match &body.tool {
        None => None,
        Some(t) => Some(with_tool(&compiled.set, t.to_tool().map_err(|e| ApiError::domain(e, "tool"))?)),
    };
    let frames = TargetFrames::new(&compiled.compensator, body.frame, body.work_object.as_ref())
        .map_err(|e| ApiError::domain(e, ""))?;
    let frame = frames.out.clone();
    let targets = body.targets;
    let results = if custom.is_none() && targets.len() <= INLINE_TARGETS {
        // A few solves (~4 µs each) cost less than handing them to the blocking pool.
        let dof = compiled.set.dof();
        targets.iter().enumerate().map(|(i, t)| compensate_target(&compiled.compensator, dof, &frames, i, t)).collect()
    } else {
        let frames = frames.clone();
        let compiled = compiled.clone();
        tokio::task::spawn_blocking(move || {
            let own;
            let (comp, dof) = match &custom {
                None => (&compiled.compensator, compiled.set.dof()),
                Some(set) => {
                    own = Compensator::new(set);
                    (&own, set.dof())
                }
            };
            compensate_targets(comp, dof, &frames, &targets)
        })
        .await?
    };
    let failed = results.iter().filter(|r| r.error.is_some()).count();
    Ok(Json(CompensationOut {
        parameter_set_id: compiled.row.id.clone(),
        version: compiled.row.version,
        frame,
        results,
        failed,
    }))
}
