//! Robots: created from a preset or a custom model, listed, read; a robot's measurements exported
//! as a cell file (the same document `robocal identify` reads).

use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::{HeaderMap, StatusCode};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use utoipa::{IntoParams, ToSchema};

use super::error::OrConflict;
use super::extract::{Authorized, JsonBody, MEASURE, READ};
use super::paging::{PageQuery, Paging};
use super::{ApiError, AppState};
use crate::app::cells;
use crate::app::robots::model_of;
use crate::db::{self, records};
use crate::domain::RobotSpec;
use crate::domain::cell::PoseXyzAbc;
use crate::domain::limits;
use crate::kinematics::ParamLayout;

/// A robot to create.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct NewRobot {
    /// Unique name, e.g. `cell-3-irb120` (not blank).
    #[schema(min_length = 1, max_length = 200, pattern = "^[^\\u0000]*[^\\s\\u0000][^\\u0000]*$")]
    pub name: String,
    /// `{"preset": "irb120"}`, `{"preset": "ur10"}` or a custom joint table (see the README's "Files").
    #[schema(value_type = crate::domain::robot::RobotDoc)]
    pub robot: Value,
    /// Guess of the robot base in the cell's world frame T_0^W (ZY'X''); without it identification
    /// registers the base from the measurements.
    #[serde(default)]
    pub base_guess: Option<PoseXyzAbc>,
}

/// A robot.
#[derive(Debug, Serialize, ToSchema)]
pub struct RobotOut {
    pub id: String,
    pub name: String,
    #[schema(value_type = Object)]
    pub robot: Value,
    pub base_guess: Option<PoseXyzAbc>,
    /// Joints.
    pub dof: usize,
    /// Parameters of the full model (43 for the IRB 120 with base and tool).
    pub parameters: usize,
    /// The parameter set compensation uses, once one is activated.
    pub active_parameter_set_id: Option<String>,
    pub created_at: String,
}

pub fn robot_out(row: &records::RobotRow) -> Result<RobotOut, ApiError> {
    let model = model_of(row)?;
    let base_guess = row
        .base_guess_json
        .as_deref()
        .map(serde_json::from_str::<PoseXyzAbc>)
        .transpose()
        .map_err(|e| ApiError::Internal(format!("robot {}: base guess: {e}", row.id)))?;
    Ok(RobotOut {
        id: row.id.clone(),
        name: row.name.clone(),
        robot: serde_json::from_str(&row.model_json).map_err(|e| ApiError::Internal(e.to_string()))?,
        base_guess,
        dof: model.dof(),
        parameters: ParamLayout::full(&model).len(),
        active_parameter_set_id: row.active_parameter_set_id.clone(),
        created_at: row.created_at.clone(),
    })
}

/// A robot by id, or 404.
pub async fn find(state: &AppState, id: &str) -> Result<std::sync::Arc<records::RobotRow>, ApiError> {
    state.caches.robot(&state.pool, id).await?.ok_or_else(|| ApiError::not_found("robot", id))
}

/// Create a robot.
#[utoipa::path(post, path = "/v1/robots", tag = "robots",
    request_body(content = NewRobot, content_type = "application/json"),
    responses(
        (status = 201, description = "Created", body = RobotOut),
        (status = 409, description = "A robot with this name exists", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid model or base guess", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["measure"])))]
pub async fn create(
    State(state): State<AppState>,
    _auth: Authorized<MEASURE>,
    JsonBody(body): JsonBody<NewRobot>,
) -> Result<(StatusCode, Json<RobotOut>), ApiError> {
    let name = limits::name(&body.name, "name").map_err(|e| ApiError::domain(e, ""))?;
    let spec = RobotSpec::from_json_value(&body.robot).map_err(|e| ApiError::domain(e, "robot"))?;
    spec.to_model().map_err(|e| ApiError::domain(e, "robot"))?;
    if let Some(b) = &body.base_guess {
        b.to_si("base_guess").map_err(|e| ApiError::domain(e, ""))?;
    }
    let row = records::RobotRow {
        id: db::new_id(),
        name: name.to_string(),
        model_json: spec.to_json_value().to_string(),
        base_guess_json: body.base_guess.as_ref().map(|b| serde_json::to_string(b).expect("serialises")),
        active_parameter_set_id: None,
        created_at: db::now(),
    };
    records::insert_robot(&state.pool, &row).await.or_conflict("name", || format!("a robot named '{name}' exists"))?;
    Ok((StatusCode::CREATED, Json(robot_out(&row)?)))
}

/// List robots, oldest first, a page at a time.
#[utoipa::path(get, path = "/v1/robots", tag = "robots", params(PageQuery),
    responses(
        (status = 200, description = "Robots, oldest first", body = Vec<RobotOut>, headers(
            ("X-Total-Count" = i64, description = "Robots in all"),
            ("Link" = String, description = "`rel=\"next\"` / `rel=\"prev\"` pages, when there are"))),
        (status = 422, description = "Bad `offset` or `limit`", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn list(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    page: Paging,
) -> Result<(HeaderMap, Json<Vec<RobotOut>>), ApiError> {
    page.respond(records::robots(&state.pool, page.offset, page.limit).await?, |r| robot_out(&r))
}

/// Get a robot.
#[utoipa::path(get, path = "/v1/robots/{robot_id}", tag = "robots",
    params(("robot_id" = String, Path, description = "Robot id")),
    responses(
        (status = 200, description = "The robot", body = RobotOut),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn get(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(robot_id): Path<String>,
) -> Result<Json<RobotOut>, ApiError> {
    Ok(Json(robot_out(&*find(&state, &robot_id).await?)?))
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct CellQuery {
    /// Sessions to include (comma-separated ids or names); default: all of the robot's sessions.
    pub sessions: Option<String>,
    /// Keep the excluded measurements in (default: left out, as the jobs leave them out).
    pub include_excluded: Option<bool>,
}

/// Export a robot's measurements as a cell file — the document `robocal identify` reads, so a
/// calibration can be reproduced offline bit for bit. Excluded measurements are left out, as the
/// jobs leave them out (so the file's indices are the stored ones less the excluded before
/// them), unless `include_excluded=true`.
#[utoipa::path(get, path = "/v1/robots/{robot_id}/cell", tag = "robots",
    params(("robot_id" = String, Path, description = "Robot id"), CellQuery),
    responses(
        (status = 200, description = "A cell file (mm, deg)", body = Object),
        (status = 404, description = "Unknown robot or session", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Sessions on different artefacts", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn cell(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(robot_id): Path<String>,
    Query(q): Query<CellQuery>,
) -> Result<Json<Value>, ApiError> {
    let robot = find(&state, &robot_id).await?;
    let names: Vec<String> = q
        .sessions
        .as_deref()
        .map(|s| s.split(',').map(|x| x.trim().to_string()).filter(|x| !x.is_empty()).collect())
        .unwrap_or_default();
    let sessions = if names.is_empty() {
        records::sessions_of_robot(&state.pool, &robot.id).await?
    } else {
        cells::resolve_sessions(&state.pool, &robot.id, &names, "sessions").await?
    };
    let file = cells::stored_cell(&state.pool, &robot, &sessions, q.include_excluded.unwrap_or(false)).await?.file;
    Ok(Json(serde_json::to_value(&file).expect("a cell file serialises")))
}
