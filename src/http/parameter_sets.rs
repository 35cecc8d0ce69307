//! Parameter sets: immutable and versioned per robot. A robot's calibration history (created,
//! sessions used, quality, validation figures when known); activating one is an explicit call;
//! export as the parameter-set file (`robocal compensate --params` reads it); import of a set made
//! elsewhere (e.g. the thesis's Table 5.1).

use axum::Json;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::IntoResponse;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use utoipa::ToSchema;

use super::extract::{Authorized, CALIBRATE, JsonBody, READ};
use super::paging::{PageQuery, Paging};
use super::robots::find as find_robot;
use super::{ApiError, AppState};
use crate::app::robots::model_of;
use crate::db::{self, records};
use crate::domain::ParameterSetFile;

/// Validation figures of a set (mm).
#[derive(Debug, Serialize, ToSchema)]
pub struct ValidationSummary {
    pub validation_id: String,
    pub created_at: String,
    pub sessions: Vec<String>,
    #[schema(value_type = Object)]
    pub figures: Value,
}

/// A parameter set in a robot's history.
#[derive(Debug, Serialize, ToSchema)]
pub struct ParameterSetOut {
    pub id: String,
    pub robot_id: String,
    /// 1, 2, 3 … per robot.
    pub version: i64,
    pub created_at: String,
    /// Whether compensation uses it.
    pub active: bool,
    /// Names of the sessions it was identified from (empty when imported).
    pub sessions: Vec<String>,
    /// The identification job, when it came from one.
    pub job_id: Option<String>,
    /// Quality summary: `identified`, `kappa_si`, `kappa_scaled`, `rms_residual_mm`,
    /// `measurements` (from the set's quality report, when it has one).
    #[schema(value_type = Object)]
    pub quality: Value,
    /// Validations of this set, newest first.
    pub validations: Vec<ValidationSummary>,
    /// The parameter-set file (only in single-set answers).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<Object>)]
    pub parameter_set: Option<Value>,
}

fn quality_summary(doc: &Value) -> Value {
    let q = &doc["quality"];
    if q.is_null() {
        return Value::Null;
    }
    serde_json::json!({
        "identified": q["n_parameters"], "measurements": q["n_measurements"], "iterations": q["iterations"],
        "kappa_si": q["kappa_si"], "kappa_scaled": q["kappa_scaled"], "rms_residual_mm": q["rms_residual_mm"],
    })
}

pub(super) async fn set_out(
    state: &AppState,
    row: &records::ParameterSetRow,
    active: bool,
    full: bool,
) -> Result<ParameterSetOut, ApiError> {
    let doc: Value = serde_json::from_str(&row.doc_json).map_err(|e| ApiError::Internal(e.to_string()))?;
    let mut validations = Vec::new();
    for v in records::validations_of_set(&state.pool, &row.id).await? {
        let report: Value = serde_json::from_str(&v.report_json).map_err(|e| ApiError::Internal(e.to_string()))?;
        let pick = |r: &Value| {
            serde_json::json!({
                "n": r["n"], "mean_mm": r["mean_mm"], "median_mm": r["median_mm"], "std_mm": r["std_mm"],
                "rms_mm": r["rms_mm"], "p95_mm": r["p95_mm"], "max_mm": r["max_mm"],
            })
        };
        let mut figures = pick(&report);
        figures["nominal"] = pick(&report["nominal"]);
        validations.push(ValidationSummary {
            validation_id: v.id.clone(),
            created_at: v.created_at.clone(),
            sessions: serde_json::from_str(&v.sessions_json).map_err(|e| ApiError::Internal(e.to_string()))?,
            figures,
        });
    }
    Ok(ParameterSetOut {
        id: row.id.clone(),
        robot_id: row.robot_id.clone(),
        version: row.version,
        created_at: row.created_at.clone(),
        active,
        sessions: serde_json::from_str(&row.sessions_json).map_err(|e| ApiError::Internal(e.to_string()))?,
        job_id: row.job_id.clone(),
        quality: quality_summary(&doc),
        validations,
        parameter_set: full.then_some(doc),
    })
}

async fn find(state: &AppState, id: &str) -> Result<records::ParameterSetRow, ApiError> {
    records::parameter_set(&state.pool, id).await?.ok_or_else(|| ApiError::not_found("parameter set", id))
}

pub(super) async fn is_active(state: &AppState, row: &records::ParameterSetRow) -> Result<bool, ApiError> {
    Ok(find_robot(state, &row.robot_id).await?.active_parameter_set_id.as_deref() == Some(row.id.as_str()))
}

/// A robot's calibration history, newest version first, a page at a time.
#[utoipa::path(get, path = "/v1/robots/{robot_id}/parameter-sets", tag = "parameter-sets",
    params(("robot_id" = String, Path, description = "Robot id"), PageQuery),
    responses(
        (status = 200, description = "Parameter sets, newest first, with quality and validation figures", body = Vec<ParameterSetOut>, headers(
            ("X-Total-Count" = i64, description = "Parameter sets in the history"),
            ("Link" = String, description = "`rel=\"next\"` / `rel=\"prev\"` pages, when there are"))),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Bad `offset` or `limit`", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = [])))]
pub async fn history(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(robot_id): Path<String>,
    page: Paging,
) -> Result<(HeaderMap, Json<Vec<ParameterSetOut>>), ApiError> {
    let robot = find_robot(&state, &robot_id).await?;
    let total = records::parameter_set_count(&state.pool, &robot.id).await?;
    let mut out = Vec::new();
    for row in records::parameter_sets_of_robot(&state.pool, &robot.id, page.offset, page.limit).await? {
        let active = robot.active_parameter_set_id.as_deref() == Some(row.id.as_str());
        out.push(set_out(&state, &row, active, false).await?);
    }
    Ok((page.headers(total, out.len()), Json(out)))
}

/// Import a parameter set made elsewhere (a parameter-set file) as the robot's next version.
#[utoipa::path(post, path = "/v1/robots/{robot_id}/parameter-sets", tag = "parameter-sets",
    params(("robot_id" = String, Path, description = "Robot id")),
    request_body(content = Object, description = "A parameter-set file: {\"robot\", \"tool\", \"parameters\": [{\"name\", \"value\", \"nominal\", \"unit\"}, …]}", content_type = "application/json"),
    responses(
        (status = 201, description = "Stored as the next version (not activated)", body = ParameterSetOut),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid file, or made for another robot", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = [])))]
pub async fn import(
    State(state): State<AppState>,
    _auth: Authorized<CALIBRATE>,
    Path(robot_id): Path<String>,
    JsonBody(file): JsonBody<ParameterSetFile>,
) -> Result<(StatusCode, Json<ParameterSetOut>), ApiError> {
    let robot = find_robot(&state, &robot_id).await?;
    let model = model_of(&robot)?;
    let doc = file.to_doc().map_err(|e| ApiError::domain(e, ""))?;
    if doc.set.model != model {
        return Err(ApiError::invalid(
            "robot",
            format!("the file is for robot '{}', this robot is '{}'", doc.set.model.name, model.name),
        ));
    }
    let mut tx = db::begin_write(&state.pool).await?;
    let row = records::insert_parameter_set(&mut tx, &robot.id, &doc.to_json_pretty(), "[]", None).await?;
    tx.commit().await?;
    Ok((StatusCode::CREATED, Json(set_out(&state, &row, false, true).await?)))
}

/// Get a parameter set with its file.
#[utoipa::path(get, path = "/v1/parameter-sets/{set_id}", tag = "parameter-sets",
    params(("set_id" = String, Path, description = "Parameter set id")),
    responses(
        (status = 200, description = "The set, its quality, validations and file", body = ParameterSetOut),
        (status = 404, description = "Unknown parameter set", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = [])))]
pub async fn get(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(set_id): Path<String>,
) -> Result<Json<ParameterSetOut>, ApiError> {
    let row = find(&state, &set_id).await?;
    let active = is_active(&state, &row).await?;
    Ok(Json(set_out(&state, &row, active, true).await?))
}

/// Export a parameter set as its file, exactly as stored (mm, deg, deg/(N·m); per parameter value,
/// nominal, std, unit, status; the quality report).
#[utoipa::path(get, path = "/v1/parameter-sets/{set_id}/export", tag = "parameter-sets",
    params(("set_id" = String, Path, description = "Parameter set id")),
    responses(
        (status = 200, description = "The parameter-set file", body = Object),
        (status = 404, description = "Unknown parameter set", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = [])))]
pub async fn export(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(set_id): Path<String>,
) -> Result<impl IntoResponse, ApiError> {
    let row = find(&state, &set_id).await?;
    Ok((
        [
            (header::CONTENT_TYPE, "application/json".to_string()),
            (header::CONTENT_DISPOSITION, format!("attachment; filename=\"parameter-set-v{}.json\"", row.version)),
        ],
        row.doc_json,
    ))
}

/// The robot's active parameter set.
#[utoipa::path(get, path = "/v1/robots/{robot_id}/active-parameter-set", tag = "parameter-sets",
    params(("robot_id" = String, Path, description = "Robot id")),
    responses(
        (status = 200, description = "The active set", body = ParameterSetOut),
        (status = 404, description = "Unknown robot, or no set is active", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = [])))]
pub async fn active(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(robot_id): Path<String>,
) -> Result<Json<ParameterSetOut>, ApiError> {
    let robot = find_robot(&state, &robot_id).await?;
    let id = robot
        .active_parameter_set_id
        .clone()
        .ok_or_else(|| ApiError::NotFound { what: "active parameter set of robot", id: robot_id.clone() })?;
    let row = find(&state, &id).await?;
    Ok(Json(set_out(&state, &row, true, true).await?))
}

/// Which set to activate.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Activate {
    pub parameter_set_id: String,
}

/// Activate one of the robot's parameter sets: compensation uses it from now on.
#[utoipa::path(put, path = "/v1/robots/{robot_id}/active-parameter-set", tag = "parameter-sets",
    params(("robot_id" = String, Path, description = "Robot id")),
    request_body(content = Activate, content_type = "application/json"),
    responses(
        (status = 200, description = "Activated", body = ParameterSetOut),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Unknown set, or a set of another robot", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = [])))]
pub async fn activate(
    State(state): State<AppState>,
    _auth: Authorized<CALIBRATE>,
    Path(robot_id): Path<String>,
    JsonBody(body): JsonBody<Activate>,
) -> Result<Json<ParameterSetOut>, ApiError> {
    let robot = find_robot(&state, &robot_id).await?;
    let row = records::parameter_set(&state.pool, &body.parameter_set_id).await?.ok_or_else(|| {
        ApiError::invalid("parameter_set_id", format!("no parameter set '{}'", body.parameter_set_id))
    })?;
    if row.robot_id != robot.id {
        return Err(ApiError::invalid("parameter_set_id", "the set belongs to another robot"));
    }
    records::set_active_parameter_set(&state.pool, &robot.id, &row.id).await?;
    state.caches.robot_changed(&robot.id);
    Ok(Json(set_out(&state, &row, true, true).await?))
}
