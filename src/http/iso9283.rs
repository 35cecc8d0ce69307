//! ISO 9283 evaluations (job): a robot's session measured at the test poses, with which pose and
//! cycle each measurement is → AP, RP, vAP, AD and RD of the nominal model and, with a parameter
//! set (default: the robot's active one), the calibrated model's predicted figures — the call
//! `robocal iso9283 evaluate` makes. Stored beside the robot, served as JSON and as an HTML page.

use axum::Json;
use axum::extract::{Path, State};
use axum::http::HeaderMap;
use axum::response::Response;
use serde::Serialize;
use serde_json::Value;
use utoipa::ToSchema;

use super::extract::{Authorized, CALIBRATE, JsonBody, READ};
use super::robots::find as find_robot;
use super::{ApiError, AppState};
use crate::app::cells;
use crate::db::iso9283::Iso9283Row;
use crate::db::jobs::JobKind;
use crate::db::records;
use crate::domain::iso9283::{Evaluation, assignments_of, pairs_of};
use crate::jobs::requests::Iso9283Request;

/// Start an ISO 9283 evaluation of a session (a job; its result names the stored evaluation).
#[utoipa::path(post, path = "/v1/robots/{robot_id}/iso9283", tag = "iso9283",
    params(("robot_id" = String, Path, description = "Robot id")),
    request_body(content = Iso9283Request, content_type = "application/json"),
    responses(
        (status = 202, description = "Queued; follow the job. An evaluation that cannot be made (the base and tool cannot be registered) ends as a failed job whose error says why.", body = super::jobs::JobOut),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Unknown or empty session; a pose assignment naming a measurement the session lacks, an excluded one or a ball measurement, a measurement or a (pose, cycle) twice; a pair naming a pose no measurement is assigned to; a parameter set not of this robot", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["calibrate"])))]
pub async fn create(
    State(state): State<AppState>,
    _auth: Authorized<CALIBRATE>,
    Path(robot_id): Path<String>,
    JsonBody(mut body): JsonBody<Iso9283Request>,
) -> Result<Response, ApiError> {
    let robot = find_robot(&state, &robot_id).await?;
    let assignments = assignments_of(&body.poses).map_err(ApiError::field)?;
    pairs_of(&body.pairs, &assignments).map_err(ApiError::field)?;
    let session = records::session_of_robot(&state.pool, &robot.id, &body.session)
        .await?
        .ok_or_else(|| ApiError::unknown("session", format!("this robot has no session '{}'", body.session)))?;
    if session.usable() == 0 {
        return Err(ApiError::invalid(
            "session",
            format!("session '{}' has no measurements to evaluate", session.name),
        ));
    }
    // Every assigned measurement: in the session, not excluded, a position or a pose.
    let stored = cells::session_measurements(&state.pool, &session.id).await?;
    for (i, a) in assignments.iter().enumerate() {
        let field = format!("poses[{i}].index");
        let found = stored.binary_search_by_key(&a.index, |(seq, _, _)| *seq).ok().map(|k| &stored[k]);
        let Some((_, m, excluded)) = found else {
            return Err(ApiError::invalid(
                field,
                format!("session '{}' has {} measurements (0-based)", session.name, stored.len()),
            ));
        };
        if *excluded {
            return Err(ApiError::invalid(
                field,
                format!("measurement {} of session '{}' is excluded", a.index, session.name),
            ));
        }
        if m.position_mm.is_none() {
            return Err(ApiError::invalid(
                field,
                format!(
                    "measurement {} of session '{}' is a ball on the artefact, not a position or pose",
                    a.index, session.name
                ),
            ));
        }
    }
    let set_id = match &body.parameter_set_id {
        Some(id) => {
            let set = records::parameter_set(&state.pool, id).await?.filter(|s| s.robot_id == robot.id);
            Some(
                set.ok_or_else(|| {
                    ApiError::unknown("parameter_set_id", format!("this robot has no parameter set '{id}'"))
                })?
                .id,
            )
        }
        None => robot.active_parameter_set_id.clone(),
    };
    body.session = session.id;
    body.parameter_set_id = set_id;
    super::jobs::submit(&state, JobKind::Iso9283, &robot.id, &body).await
}

/// A stored ISO 9283 evaluation.
#[derive(Debug, Serialize, ToSchema)]
pub struct Iso9283Out {
    pub id: String,
    pub robot_id: String,
    pub session_id: String,
    /// The set of the calibrated figures; absent: the nominal model only.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub parameter_set_id: Option<String>,
    /// The request as stored (the session and the set as ids).
    #[schema(value_type = Object)]
    pub request: Value,
    pub job_id: Option<String>,
    pub created_at: String,
    /// The evaluation as `robocal iso9283 evaluate --json` prints it, mm and deg: `session`,
    /// `nominal` and `calibrated` (null without a set), each with `model`, `summary`, `poses`
    /// (per pose: `cycles`, `ap_p_mm`, `ap_xyz_mm`, `ap_abc_deg`, `rp_l_mm`, `vap_p_mm`, … and the
    /// instrument's uncertainty `*_u_mm`), `distances` (per pair: `ad_p_mm`, `rd_mm`, …),
    /// `registration` and `notes`.
    #[schema(value_type = Object)]
    pub report: Value,
}

fn stored<T: serde::de::DeserializeOwned>(row: &Iso9283Row, json: &str) -> Result<T, ApiError> {
    serde_json::from_str(json).map_err(|e| ApiError::Internal(format!("ISO 9283 evaluation {}: {e}", row.id)))
}

async fn find(state: &AppState, id: &str) -> Result<Iso9283Row, ApiError> {
    crate::db::iso9283::get(&state.pool, id).await?.ok_or_else(|| ApiError::not_found("ISO 9283 evaluation", id))
}

/// Get an ISO 9283 evaluation.
#[utoipa::path(get, path = "/v1/iso9283/{evaluation_id}", tag = "iso9283",
    params(("evaluation_id" = String, Path, description = "Evaluation id (the job's result names it)")),
    responses(
        (status = 200, description = "The evaluation, mm and deg", body = Iso9283Out),
        (status = 404, description = "Unknown evaluation (an evaluation exists once its job has succeeded)", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn get(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(evaluation_id): Path<String>,
) -> Result<Json<Iso9283Out>, ApiError> {
    let row = find(&state, &evaluation_id).await?;
    Ok(Json(Iso9283Out {
        request: stored(&row, &row.request_json)?,
        report: stored(&row, &row.report_json)?,
        id: row.id,
        robot_id: row.robot_id,
        session_id: row.session_id,
        parameter_set_id: row.parameter_set_id,
        job_id: row.job_id,
        created_at: row.created_at,
    }))
}

/// An ISO 9283 evaluation's report.
#[utoipa::path(get, path = "/v1/iso9283/{evaluation_id}/report", tag = "iso9283",
    params(("evaluation_id" = String, Path, description = "Evaluation id")),
    responses(
        (status = 200, description = "The ISO 9283 report: per pose AP, RP, vAP nominal and calibrated (predicted) with the instrument's uncertainty, the distances, the registration, the clauses implemented; self-contained HTML, the page `robocal iso9283 evaluate --html` writes", body = String, content_type = "text/html"),
        (status = 404, description = "Unknown evaluation (an evaluation exists once its job has succeeded)", body = super::Problem, content_type = "application/problem+json"),
        (status = 406, description = "The client accepts no HTML", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn report(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    headers: HeaderMap,
    Path(evaluation_id): Path<String>,
) -> Result<Response, ApiError> {
    if !super::reports::accepts_html(&headers) {
        return Ok(super::reports::not_acceptable());
    }
    let row = find(&state, &evaluation_id).await?;
    let e: Evaluation = stored(&row, &row.report_json)?;
    Ok(super::reports::html(crate::report::iso9283::render(&e.session, &e.nominal, e.calibrated.as_ref())))
}
