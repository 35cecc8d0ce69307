//! Jobs: state (queued, running, succeeded, failed, cancelled), progress, timestamps, result or
//! error; cancel.

use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use utoipa::{IntoParams, ToSchema};

use super::extract::{Authorized, CALIBRATE, READ};
use super::paging::{PageQuery, Paging};
use super::{ApiError, AppState, Problem};
use crate::db;
use crate::db::jobs::{JobKind, JobRow, JobState};
use crate::jobs::results::JobResult;
use crate::jobs::{JobContext, JobError};

/// A background job.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct JobOut {
    pub id: String,
    /// `pose_plan`, `identification`, `validation`, `diagnosis` or `iso9283`.
    pub kind: JobKind,
    pub robot_id: String,
    pub state: JobState,
    /// 0–1, updated about once a second while the job runs.
    pub progress: f64,
    /// What a running job is doing now (`loading`, `selecting poses`, `identifying`,
    /// `validating`, `fitting the current model`, `cross-validating candidate effects`, …); once it
    /// ended, the last phase it reached. A job whose end the storage refused (a full disk, a
    /// read-only file system) says `storing the result: waiting for the storage (…)` until it is
    /// written.
    pub phase: Option<String>,
    /// The request as stored (sessions resolved to ids).
    #[schema(value_type = Object)]
    pub request: Value,
    /// Where the result lives (`parameter_set_id`, `validation_id`, `pose_plan_id`, `diagnosis_id`,
    /// `evaluation_id`) and a summary.
    pub result: Option<JobResult>,
    /// Why it failed (rank deficiency, κ above the limit, divergence, …).
    pub error: Option<Problem>,
    /// Times the job was started (more than 1 after a restart).
    pub attempts: i64,
    /// Cancellation was asked for while it ran; it ends as `cancelled` when the solver returns.
    pub cancel_requested: bool,
    pub created_at: String,
    pub started_at: Option<String>,
    pub finished_at: Option<String>,
    pub updated_at: String,
}

pub fn job_out(j: &JobRow) -> Result<JobOut, ApiError> {
    let parse =
        |s: &str| serde_json::from_str::<Value>(s).map_err(|e| ApiError::Internal(format!("job {}: {e}", j.id)));
    Ok(JobOut {
        id: j.id.clone(),
        kind: j.kind,
        robot_id: j.robot_id.clone(),
        state: j.state,
        progress: j.progress,
        phase: j.phase.clone(),
        request: parse(&j.request_json)?,
        result: j
            .result_json
            .as_deref()
            .map(|s| JobResult::from_json(j.kind, s))
            .transpose()
            .map_err(|e| ApiError::Internal(format!("job {}: {e}", j.id)))?,
        error: j
            .error_json
            .as_deref()
            .map(serde_json::from_str::<Problem>)
            .transpose()
            .map_err(|e| ApiError::Internal(format!("job {}: {e}", j.id)))?,
        attempts: j.attempts,
        cancel_requested: j.cancel_requested,
        created_at: j.created_at.clone(),
        started_at: j.started_at.clone(),
        finished_at: j.finished_at.clone(),
        updated_at: j.updated_at.clone(),
    })
}

/// A job as stored, with what a running job waits for when the storage refused its end (that is
/// held in memory: the row is what could not be written).
fn job_out_now(state: &AppState, j: &JobRow) -> Result<JobOut, ApiError> {
    let mut out = job_out(j)?;
    if j.state == JobState::Running
        && let Some(w) = state.storage.job_waiting(&j.id)
    {
        out.phase = Some(w);
    }
    Ok(out)
}

/// The job workers' context from the service's state; the failures they store are this API's
/// problem documents.
impl From<AppState> for JobContext {
    fn from(s: AppState) -> Self {
        JobContext {
            pool: s.pool,
            wake: s.wake,
            caches: s.caches,
            metrics: s.metrics,
            failure_json,
            storage: s.storage,
            lease: s.config.job_lease,
        }
    }
}

/// A job's failure as stored in `jobs.error_json` and served as the job's `error`.
fn failure_json(e: &JobError) -> String {
    serde_json::to_string(&ApiError::from(e.clone()).problem()).expect("problem serialises")
}

/// Queue a job and answer 202 with it and its `Location`.
pub async fn submit(
    state: &AppState,
    kind: JobKind,
    robot_id: &str,
    request: &impl Serialize,
) -> Result<Response, ApiError> {
    let id = db::new_id();
    let json = serde_json::to_string(request).expect("requests serialise");
    db::jobs::insert(&state.pool, &id, kind, robot_id, &json).await?;
    state.wake.notify_one();
    let row = db::jobs::get(&state.pool, &id).await?.ok_or_else(|| ApiError::Internal("job vanished".into()))?;
    let mut res = (StatusCode::ACCEPTED, Json(job_out(&row)?)).into_response();
    res.headers_mut().insert(header::LOCATION, HeaderValue::from_str(&format!("/v1/jobs/{id}")).expect("ascii"));
    Ok(res)
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct JobQuery {
    pub robot_id: Option<String>,
    /// `queued`, `running`, `succeeded`, `failed` or `cancelled`.
    #[param(value_type = Option<JobState>)]
    pub state: Option<String>,
}

/// List jobs, newest first, a page at a time.
#[utoipa::path(get, path = "/v1/jobs", tag = "jobs", params(JobQuery, PageQuery),
    responses(
        (status = 200, description = "Jobs, newest first", body = Vec<JobOut>, headers(
            ("X-Total-Count" = i64, description = "Jobs matching the filters"),
            ("Link" = String, description = "`rel=\"next\"` / `rel=\"prev\"` pages, when there are"))),
        (status = 422, description = "Unknown state, bad `offset` or `limit`", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn list(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Query(q): Query<JobQuery>,
    page: Paging,
) -> Result<(HeaderMap, Json<Vec<JobOut>>), ApiError> {
    let state_filter = match q.state.as_deref() {
        None => None,
        Some(s) => Some(JobState::parse(s).ok_or_else(|| {
            let all: Vec<&str> = JobState::ALL.iter().map(|s| s.as_str()).collect();
            ApiError::invalid("state", format!("'{s}' is not one of {}", all.join(", ")))
        })?),
    };
    let robot = q.robot_id.as_deref().filter(|s| !s.is_empty());
    let rows = db::jobs::list(&state.pool, robot, state_filter, page.offset, page.limit).await?;
    page.respond(rows, |r| job_out_now(&state, &r))
}

/// Get a job.
#[utoipa::path(get, path = "/v1/jobs/{job_id}", tag = "jobs",
    params(("job_id" = String, Path, description = "Job id")),
    responses(
        (status = 200, description = "The job", body = JobOut),
        (status = 404, description = "Unknown job", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn get(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(job_id): Path<String>,
) -> Result<Json<JobOut>, ApiError> {
    let row = db::jobs::get(&state.pool, &job_id).await?.ok_or_else(|| ApiError::not_found("job", &job_id))?;
    Ok(Json(job_out_now(&state, &row)?))
}

/// Cancel a job: a queued job ends at once; a running one ends as `cancelled` when its solver
/// returns, its result discarded. A finished job cannot be cancelled (409).
#[utoipa::path(post, path = "/v1/jobs/{job_id}/cancel", tag = "jobs",
    params(("job_id" = String, Path, description = "Job id")),
    responses(
        (status = 200, description = "Cancelled, or flagged for cancellation", body = JobOut),
        (status = 404, description = "Unknown job", body = super::Problem, content_type = "application/problem+json"),
        (status = 409, description = "The job has already finished", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["calibrate"])))]
pub async fn cancel(
    State(state): State<AppState>,
    _auth: Authorized<CALIBRATE>,
    Path(job_id): Path<String>,
) -> Result<Json<JobOut>, ApiError> {
    // One transaction decides (see `db::jobs::cancel`): answered 200, the job ends `cancelled` with
    // no result stored; an ended job (succeeded, failed or already cancelled) is left as it is.
    let (what, row) =
        db::jobs::cancel(&state.pool, &job_id).await?.ok_or_else(|| ApiError::not_found("job", &job_id))?;
    if what == db::jobs::Cancel::AlreadyEnded {
        return Err(ApiError::conflict(format!("job {job_id} has already ended ({})", row.state)));
    }
    Ok(Json(job_out(&row)?))
}
