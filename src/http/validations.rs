//! Validations (job): a parameter set + validation sessions → the statistics of the
//! identification issue (mean, median, std, RMS, p95, max; per axis of {W} with Shapiro–Wilk;
//! regressions against distance), the nominal model's beside them, and per-measurement residuals.

use axum::Json;
use axum::extract::{Path, State};
use axum::response::Response;
use serde::Serialize;
use serde_json::Value;
use utoipa::ToSchema;

use super::extract::{Authorized, CALIBRATE, JsonBody, READ};
use super::identifications::checked_sessions;
use super::{ApiError, AppState};
use crate::db::jobs::JobKind;
use crate::db::records;
use crate::domain::cell::PurposeSpec;
use crate::jobs::requests::{ValidationJob, ValidationRequest};

/// Start a validation of a parameter set (a job; its result is a validation).
#[utoipa::path(post, path = "/v1/parameter-sets/{set_id}/validations", tag = "validations",
    params(("set_id" = String, Path, description = "Parameter set id")),
    request_body(content = ValidationRequest, content_type = "application/json"),
    responses(
        (status = 202, description = "Queued; follow the job", body = super::jobs::JobOut),
        (status = 404, description = "Unknown parameter set", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Unknown session, a session of the wrong purpose or empty", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["calibrate"])))]
pub async fn create(
    State(state): State<AppState>,
    _auth: Authorized<CALIBRATE>,
    Path(set_id): Path<String>,
    JsonBody(mut body): JsonBody<ValidationRequest>,
) -> Result<Response, ApiError> {
    let set = records::parameter_set(&state.pool, &set_id)
        .await?
        .ok_or_else(|| ApiError::not_found("parameter set", &set_id))?;
    body.sessions = checked_sessions(&state, &set.robot_id, &body.sessions, PurposeSpec::Validation).await?;
    let job = ValidationJob { parameter_set_id: set.id.clone(), request: body };
    super::jobs::submit(&state, JobKind::Validation, &set.robot_id, &job).await
}

/// A validation.
#[derive(Debug, Serialize, ToSchema)]
pub struct ValidationOut {
    pub id: String,
    pub parameter_set_id: String,
    /// Names of the sessions validated on.
    pub sessions: Vec<String>,
    pub job_id: Option<String>,
    pub created_at: String,
    /// `mean_mm`, `median_mm`, `std_mm`, `rms_mm`, `p95_mm`, `max_mm`, `per_axis`, `shapiro`,
    /// `vs_base_distance`, `vs_zone_distance`, `nominal` (the same for the nominal model),
    /// `per_session` (the same per session, with its name and purpose), `residuals`.
    #[schema(value_type = Object)]
    pub report: Value,
}

pub fn validation_out(v: &records::ValidationRow) -> Result<ValidationOut, ApiError> {
    Ok(ValidationOut {
        id: v.id.clone(),
        parameter_set_id: v.parameter_set_id.clone(),
        sessions: serde_json::from_str(&v.sessions_json).map_err(|e| ApiError::Internal(e.to_string()))?,
        job_id: v.job_id.clone(),
        created_at: v.created_at.clone(),
        report: serde_json::from_str(&v.report_json).map_err(|e| ApiError::Internal(e.to_string()))?,
    })
}

/// Get a validation.
#[utoipa::path(get, path = "/v1/validations/{validation_id}", tag = "validations",
    params(("validation_id" = String, Path, description = "Validation id")),
    responses(
        (status = 200, description = "The validation statistics", body = ValidationOut),
        (status = 404, description = "Unknown validation", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn get(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(validation_id): Path<String>,
) -> Result<Json<ValidationOut>, ApiError> {
    let row = records::validation(&state.pool, &validation_id)
        .await?
        .ok_or_else(|| ApiError::not_found("validation", &validation_id))?;
    Ok(Json(validation_out(&row)?))
}
