//! Pose plans (job): artefact + tool + counts → a candidate pool of collision-checked TriCal
//! configurations, an optional DETMAX selection re-sequenced into a collision-free measuring
//! order, and laser-tracker validation configurations — the joints to measure, in order.

use axum::Json;
use axum::extract::{Path, State};
use axum::http::HeaderMap;
use axum::response::Response;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use utoipa::ToSchema;

use super::extract::{Authorized, CALIBRATE, JsonBody, READ};
use super::paging::{PageQuery, Paging};
use super::robots::find as find_robot;
use super::{ApiError, AppState};
use crate::app::robots::{model_of, robot_base};
use crate::db::jobs::JobKind;
use crate::db::records;
use crate::domain::cell::ArtefactSpec;
use crate::domain::limits;
use crate::jobs::requests::PosePlanRequest;
use crate::jobs::results::PosePlan;
use crate::jobs::run;

/// Start a pose plan (a job; its result is a pose plan).
#[utoipa::path(post, path = "/v1/robots/{robot_id}/pose-plans", tag = "pose-plans",
    params(("robot_id" = String, Path, description = "Robot id")),
    request_body(content = PosePlanRequest, content_type = "application/json"),
    responses(
        (status = 202, description = "Queued; follow the job", body = super::jobs::JobOut),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Unknown artefact, bad counts, a robot without closed-form IK or base guess", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["calibrate"])))]
pub async fn create(
    State(state): State<AppState>,
    _auth: Authorized<CALIBRATE>,
    Path(robot_id): Path<String>,
    JsonBody(body): JsonBody<PosePlanRequest>,
) -> Result<Response, ApiError> {
    let robot = find_robot(&state, &robot_id).await?;
    let model = model_of(&robot)?;
    let row = records::artefact(&state.pool, &body.artefact_id)
        .await?
        .ok_or_else(|| ApiError::unknown("artefact_id", format!("no artefact '{}'", body.artefact_id)))?;
    let artefact: ArtefactSpec = serde_json::from_str(&row.spec_json).map_err(|e| ApiError::Internal(e.to_string()))?;
    limits::per_ball(body.per_ball, "per_ball").map_err(|e| ApiError::domain(e, ""))?;
    limits::validation(body.validation, "validation").map_err(|e| ApiError::domain(e, ""))?;
    if let Some(s) = &body.select {
        run::selection(s)?;
        if s.n >= 3 * body.per_ball {
            return Err(ApiError::invalid(
                "select.n",
                format!("must be smaller than the {} candidates", 3 * body.per_ball),
            ));
        }
    }
    let base = robot_base(&robot)?;
    run::planning_cell(&model, base, &body, &artefact)?;
    super::jobs::submit(&state, JobKind::PosePlan, &robot.id, &body).await
}

/// A pose plan.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct PosePlanOut {
    pub id: String,
    pub robot_id: String,
    pub job_id: Option<String>,
    pub created_at: String,
    #[schema(value_type = Object)]
    pub request: Value,
    pub plan: PosePlan,
}

/// A pose plan in a robot's list: the plan without its configurations.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct PosePlanSummary {
    pub id: String,
    pub robot_id: String,
    pub job_id: Option<String>,
    pub created_at: String,
    /// The request as stored (artefact, tool, counts, selection, seed).
    #[schema(value_type = Object)]
    pub request: Value,
    /// TriCal configurations in the plan.
    pub identification: usize,
    /// Laser-tracker configurations in the plan.
    pub validation: usize,
    /// Collision-checked candidates the identification configurations were chosen from.
    pub candidates: usize,
    /// The DETMAX settings, when a selection was asked for.
    #[schema(value_type = Option<Object>)]
    pub selection: Option<Value>,
}

/// A robot's pose plans, newest first, a page at a time (each without its configurations: get
/// one plan for them).
#[utoipa::path(get, path = "/v1/robots/{robot_id}/pose-plans", tag = "pose-plans",
    params(("robot_id" = String, Path, description = "Robot id"), PageQuery),
    responses(
        (status = 200, description = "The robot's pose plans, newest first", body = Vec<PosePlanSummary>, headers(
            ("X-Total-Count" = i64, description = "The robot's pose plans in all"),
            ("Link" = String, description = "`rel=\"next\"` / `rel=\"prev\"` pages, when there are"))),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Bad `offset` or `limit`", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn list(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(robot_id): Path<String>,
    page: Paging,
) -> Result<(HeaderMap, Json<Vec<PosePlanSummary>>), ApiError> {
    let robot = find_robot(&state, &robot_id).await?;
    let rows = records::pose_plans_of_robot(&state.pool, &robot.id, page.offset, page.limit).await?;
    page.respond(rows, |row| {
        let internal = |e: serde_json::Error| ApiError::Internal(format!("pose plan {}: {e}", row.id));
        let plan: PosePlan = serde_json::from_str(&row.result_json).map_err(internal)?;
        Ok(PosePlanSummary {
            request: serde_json::from_str(&row.request_json).map_err(internal)?,
            identification: plan.identification.len(),
            validation: plan.validation.len(),
            candidates: plan.candidates,
            selection: plan.selection,
            id: row.id,
            robot_id: row.robot_id,
            job_id: row.job_id,
            created_at: row.created_at,
        })
    })
}

/// Get a pose plan.
#[utoipa::path(get, path = "/v1/pose-plans/{plan_id}", tag = "pose-plans",
    params(("plan_id" = String, Path, description = "Pose plan id")),
    responses(
        (status = 200, description = "The plan", body = PosePlanOut),
        (status = 404, description = "Unknown plan", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn get(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(plan_id): Path<String>,
) -> Result<Json<PosePlanOut>, ApiError> {
    let row =
        records::pose_plan(&state.pool, &plan_id).await?.ok_or_else(|| ApiError::not_found("pose plan", &plan_id))?;
    let internal = |e: serde_json::Error| ApiError::Internal(format!("pose plan {}: {e}", row.id));
    Ok(Json(PosePlanOut {
        request: serde_json::from_str(&row.request_json).map_err(internal)?,
        plan: serde_json::from_str(&row.result_json).map_err(internal)?,
        id: row.id,
        robot_id: row.robot_id,
        job_id: row.job_id,
        created_at: row.created_at,
    }))
}
