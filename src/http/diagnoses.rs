//! Diagnoses (job): a parameter set and its robot's identification and validation sessions → the
//! sim-to-real diagnosis of issue 11, as `robocal diagnose` makes it: where the calibrated model
//! still misses, which unmodelled effect it lacks, and how far the held-out error shrinks once
//! that effect is added. Stored beside the set. Accepting a diagnosis that named an effect stores
//! the extended model's parameter set as the robot's next version (not activated: activation
//! stays an explicit call).

use axum::Json;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, StatusCode};
use axum::response::Response;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use utoipa::ToSchema;

use super::extract::{Authorized, CALIBRATE, JsonBody, READ};
use super::paging::{PageQuery, Paging};
use super::parameter_sets::{ParameterSetOut, is_active, set_out};
use super::{ApiError, AppState};
use crate::db::jobs::JobKind;
use crate::db::{self, records};
use crate::domain::diagnosis::{DiagnoseSpec, DiagnosisOut};
use crate::jobs::requests::DiagnosisJob;
use crate::jobs::run;

/// Start a diagnosis of a parameter set (a job; its result names the stored diagnosis).
#[utoipa::path(post, path = "/v1/parameter-sets/{set_id}/diagnoses", tag = "diagnoses",
    params(("set_id" = String, Path, description = "Parameter set id")),
    request_body(content = DiagnoseSpec, description = "Every field has a default: `{}` diagnoses the set on every identification and validation session of its robot.", content_type = "application/json"),
    responses(
        (status = 202, description = "Queued; follow the job. A diagnosis that cannot run ends as a failed job whose error says why.", body = super::jobs::JobOut),
        (status = 404, description = "Unknown parameter set", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Bad options, an unknown session, a session of the wrong purpose or empty, no identification session", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["calibrate"])))]
pub async fn create(
    State(state): State<AppState>,
    _auth: Authorized<CALIBRATE>,
    Path(set_id): Path<String>,
    JsonBody(mut body): JsonBody<DiagnoseSpec>,
) -> Result<Response, ApiError> {
    let set = find_set(&state, &set_id).await?;
    body.to_options().map_err(ApiError::field)?;
    let (identification, validation) =
        run::diagnosis_sessions(&state.pool, &set.robot_id, &body.identification, body.validation.as_deref()).await?;
    body.identification = identification.into_iter().map(|s| s.id).collect();
    body.validation = Some(validation.into_iter().map(|s| s.id).collect());
    let job = DiagnosisJob { parameter_set_id: set.id.clone(), request: body };
    super::jobs::submit(&state, JobKind::Diagnosis, &set.robot_id, &job).await
}

/// The sessions a diagnosis used, by name.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct DiagnosedSessions {
    pub identification: Vec<String>,
    /// Empty: the identification sessions were cross-validated on themselves.
    pub validation: Vec<String>,
}

/// A stored diagnosis.
#[derive(Debug, Serialize, ToSchema)]
pub struct Diagnosis {
    pub id: String,
    /// The parameter set diagnosed.
    pub parameter_set_id: String,
    pub sessions: DiagnosedSessions,
    pub job_id: Option<String>,
    pub created_at: String,
    /// The parameter set accepting created, once accepted.
    pub accepted_parameter_set_id: Option<String>,
    /// The diagnosis, as `robocal diagnose` prints it: `verdict`, `decomposition`, `where`,
    /// `candidates`, `shrink`, …
    #[schema(value_type = DiagnosisOut)]
    pub report: Value,
}

fn stored<T: serde::de::DeserializeOwned>(d: &records::DiagnosisRow, json: &str) -> Result<T, ApiError> {
    serde_json::from_str(json).map_err(|e| ApiError::Internal(format!("diagnosis {}: {e}", d.id)))
}

pub fn diagnosis_out(d: &records::DiagnosisRow) -> Result<Diagnosis, ApiError> {
    Ok(Diagnosis {
        id: d.id.clone(),
        parameter_set_id: d.parameter_set_id.clone(),
        sessions: stored(d, &d.sessions_json)?,
        job_id: d.job_id.clone(),
        created_at: d.created_at.clone(),
        accepted_parameter_set_id: d.accepted_parameter_set_id.clone(),
        report: stored(d, &d.report_json)?,
    })
}

async fn find_set(state: &AppState, id: &str) -> Result<records::ParameterSetRow, ApiError> {
    records::parameter_set(&state.pool, id).await?.ok_or_else(|| ApiError::not_found("parameter set", id))
}

async fn find(state: &AppState, id: &str) -> Result<records::DiagnosisRow, ApiError> {
    records::diagnosis(&state.pool, id).await?.ok_or_else(|| ApiError::not_found("diagnosis", id))
}

/// A parameter set's diagnoses, newest first, a page at a time.
#[utoipa::path(get, path = "/v1/parameter-sets/{set_id}/diagnoses", tag = "diagnoses",
    params(("set_id" = String, Path, description = "Parameter set id"), PageQuery),
    responses(
        (status = 200, description = "The set's diagnoses, newest first", body = Vec<Diagnosis>, headers(
            ("X-Total-Count" = i64, description = "The set's diagnoses in all"),
            ("Link" = String, description = "`rel=\"next\"` / `rel=\"prev\"` pages, when there are"))),
        (status = 404, description = "Unknown parameter set", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Bad `offset` or `limit`", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn list(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(set_id): Path<String>,
    page: Paging,
) -> Result<(HeaderMap, Json<Vec<Diagnosis>>), ApiError> {
    let set = find_set(&state, &set_id).await?;
    page.respond(records::diagnoses_of_set(&state.pool, &set.id, page.offset, page.limit).await?, |r| diagnosis_out(&r))
}

/// Get a diagnosis.
#[utoipa::path(get, path = "/v1/diagnoses/{diagnosis_id}", tag = "diagnoses",
    params(("diagnosis_id" = String, Path, description = "Diagnosis id")),
    responses(
        (status = 200, description = "The diagnosis and its report", body = Diagnosis),
        (status = 404, description = "Unknown diagnosis", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn get(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(diagnosis_id): Path<String>,
) -> Result<Json<Diagnosis>, ApiError> {
    Ok(Json(diagnosis_out(&find(&state, &diagnosis_id).await?)?))
}

/// Why a diagnosis has nothing to accept (409).
fn nothing_to_accept(d: &records::DiagnosisRow) -> Result<ApiError, ApiError> {
    let report: Value = stored(d, &d.report_json)?;
    let status = report["verdict"]["status"].as_str().unwrap_or("unknown");
    let summary = report["verdict"]["summary"].as_str().unwrap_or("");
    let detail = if status == "named" {
        format!(
            "diagnosis {}: the verdict is `named` ({summary}), but the extended model could not be fitted on the pooled sessions; there is nothing to accept",
            d.id
        )
    } else {
        format!(
            "diagnosis {}: the verdict is `{status}`: {summary}. No effect was named; there is nothing to accept",
            d.id
        )
    };
    Ok(ApiError::conflict(detail))
}

/// 200 with the set an earlier accept created.
async fn already_accepted(state: &AppState, set_id: &str) -> Result<(StatusCode, Json<ParameterSetOut>), ApiError> {
    let row = records::parameter_set(&state.pool, set_id)
        .await?
        .ok_or_else(|| ApiError::Internal(format!("accepted parameter set {set_id} missing")))?;
    let active = is_active(state, &row).await?;
    Ok((StatusCode::OK, Json(set_out(state, &row, active, true).await?)))
}

/// Accept a diagnosis: its named effects' model, fitted on the diagnosed identification and
/// validation sessions together, becomes the robot's next parameter-set version (not activated).
/// Accepting again answers the same set. The new set was fitted on those validation sessions, so
/// a validation on them is in-sample: compensation needs a new held-out validation (sessions it
/// was not fitted on), and the answer's `validation_needed` says what to measure.
#[utoipa::path(post, path = "/v1/diagnoses/{diagnosis_id}/accept", tag = "diagnoses",
    params(("diagnosis_id" = String, Path, description = "Diagnosis id")),
    responses(
        (status = 201, description = "The new parameter set (the robot's next version, not activated); `validation_needed` says which held-out validation it still needs", body = ParameterSetOut),
        (status = 200, description = "Already accepted: the set it created, nothing new written", body = ParameterSetOut),
        (status = 404, description = "Unknown diagnosis", body = super::Problem, content_type = "application/problem+json"),
        (status = 409, description = "The diagnosis named no effect (its verdict is `none`, `not_separable` or `unknown_effect`): nothing to accept", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["calibrate"])))]
pub async fn accept(
    State(state): State<AppState>,
    _auth: Authorized<CALIBRATE>,
    Path(diagnosis_id): Path<String>,
) -> Result<(StatusCode, Json<ParameterSetOut>), ApiError> {
    let d = find(&state, &diagnosis_id).await?;
    if let Some(set_id) = &d.accepted_parameter_set_id {
        return already_accepted(&state, set_id).await;
    }
    let Some(doc_json) = d.accepted_doc_json.as_deref() else { return Err(nothing_to_accept(&d)?) };
    let diagnosed = records::parameter_set(&state.pool, &d.parameter_set_id)
        .await?
        .ok_or_else(|| ApiError::Internal(format!("diagnosed parameter set {} missing", d.parameter_set_id)))?;
    // The new set's sessions: the ones it was fitted on, identification then validation.
    let sessions: DiagnosedSessions = stored(&d, &d.sessions_json)?;
    let names: Vec<&String> = sessions.identification.iter().chain(&sessions.validation).collect();
    let sessions_json = serde_json::to_string(&names).expect("names serialise");

    let mut tx = db::begin_write(&state.pool).await?;
    // Under the write lock: a concurrent accept may have been first.
    let current = records::diagnosis(&mut *tx, &d.id)
        .await?
        .ok_or_else(|| ApiError::Internal(format!("diagnosis {} vanished", d.id)))?;
    if let Some(set_id) = &current.accepted_parameter_set_id {
        tx.rollback().await?;
        return already_accepted(&state, set_id).await;
    }
    // The diagnosis job fitted this set: it is the set's job, as an identification job is.
    let row =
        records::insert_parameter_set(&mut tx, &diagnosed.robot_id, doc_json, &sessions_json, d.job_id.as_deref())
            .await?;
    if !records::set_diagnosis_accepted(&mut *tx, &d.id, &row.id).await? {
        return Err(ApiError::Internal(format!("diagnosis {}: recording the accepted set", d.id)));
    }
    tx.commit().await?;
    Ok((StatusCode::CREATED, Json(set_out(&state, &row, false, true).await?)))
}
