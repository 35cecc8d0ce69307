//! Measuring sessions of a robot: purpose, instrument, tool, artefact. Their measurements are
//! [`super::measurements`]. A session no stored result refers to can be deleted, with a reason
//! kept in the audit timeline.

use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::{HeaderMap, StatusCode};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::audit::{Event, ReasonQuery, reason};
use super::error::OrConflict;
use super::extract::{Authorized, JsonBody, MEASURE, READ};
use super::paging::{PageQuery, Paging};
use super::robots::find as find_robot;
use super::{ApiError, AppState};
use crate::db::{self, corrections, records};
use crate::domain::ToolSpec;
use crate::domain::cell::{InstrumentSpec, OrderSpec, PurposeSpec};
use crate::domain::limits;

/// A session to create.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct NewSession {
    /// Unique per robot, e.g. `trical-1` (not blank).
    #[schema(min_length = 1, max_length = 200, pattern = "^[^\\u0000]*[^\\s\\u0000][^\\u0000]*$")]
    pub name: String,
    pub purpose: PurposeSpec,
    pub instrument: InstrumentSpec,
    /// The tool measured with: TCP (and payload) in the flange frame.
    pub tool: ToolSpec,
    /// The TCP is only a guess (e.g. an unmeasured reflector nest): identify it.
    #[serde(default)]
    pub identify_tcp: bool,
    /// The artefact whose balls a TriCal session measures (required for `trical`).
    #[serde(default)]
    pub artefact_id: Option<String>,
    /// Whether the measurements will be appended in measuring order: `measured`, `shuffled`
    /// (permuted afterwards), `resampled` (drawn from measured sessions) or `unknown` (default).
    /// Backlash directions are never derived from the order of a shuffled or resampled session.
    #[serde(default)]
    pub order: OrderSpec,
    /// The physical target measured (a reflector, a nest), e.g. `nest-1`. Sessions of a robot
    /// naming the same target share one identified TCP and must declare the same tool; without
    /// it, a session whose TCP is identified gets a TCP of its own.
    #[serde(default)]
    #[schema(min_length = 1, max_length = 200, pattern = "^[^\\u0000]*[^\\s\\u0000][^\\u0000]*$")]
    pub target: Option<String>,
}

/// A session.
#[derive(Debug, Serialize, ToSchema)]
pub struct SessionOut {
    pub id: String,
    pub robot_id: String,
    pub name: String,
    pub purpose: PurposeSpec,
    pub instrument: InstrumentSpec,
    pub tool: ToolSpec,
    pub identify_tcp: bool,
    pub artefact_id: Option<String>,
    /// Whether the measurements are in measuring order.
    pub order: OrderSpec,
    /// The physical target measured, when the session names one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub target: Option<String>,
    /// Measurements stored.
    pub measurements: i64,
    /// Of them, excluded: the jobs leave them out.
    pub excluded_measurements: i64,
    pub created_at: String,
}

pub fn session_out(s: &records::SessionRow) -> Result<SessionOut, ApiError> {
    Ok(SessionOut {
        id: s.id.clone(),
        robot_id: s.robot_id.clone(),
        name: s.name.clone(),
        purpose: s.purpose,
        instrument: s.instrument,
        tool: serde_json::from_str(&s.tool_json).map_err(|e| ApiError::Internal(format!("session {}: {e}", s.id)))?,
        identify_tcp: s.identify_tcp,
        artefact_id: s.artefact_id.clone(),
        order: s.order,
        target: s.target.clone(),
        measurements: s.measurements,
        excluded_measurements: s.excluded,
        created_at: s.created_at.clone(),
    })
}

pub(super) async fn find(state: &AppState, id: &str) -> Result<records::SessionRow, ApiError> {
    records::session(&state.pool, id).await?.ok_or_else(|| ApiError::not_found("session", id))
}

/// Create a session of a robot.
#[utoipa::path(post, path = "/v1/robots/{robot_id}/sessions", tag = "sessions",
    params(("robot_id" = String, Path, description = "Robot id")),
    request_body(content = NewSession, content_type = "application/json"),
    responses(
        (status = 201, description = "Created", body = SessionOut),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json"),
        (status = 409, description = "The robot has a session with this name", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid tool, missing or unknown artefact", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["measure"])))]
pub async fn create(
    State(state): State<AppState>,
    _auth: Authorized<MEASURE>,
    Path(robot_id): Path<String>,
    JsonBody(body): JsonBody<NewSession>,
) -> Result<(StatusCode, Json<SessionOut>), ApiError> {
    let robot = find_robot(&state, &robot_id).await?;
    let name = limits::name(&body.name, "name").map_err(|e| ApiError::domain(e, ""))?;
    body.tool.to_tool().map_err(|e| ApiError::domain(e, "tool"))?;
    if body.artefact_id.is_none() && body.instrument == InstrumentSpec::Trical {
        return Err(ApiError::invalid(
            "artefact_id",
            "a trical session measures the balls of an artefact: give its id",
        ));
    }
    if let Some(a) = &body.artefact_id
        && records::artefact(&state.pool, a).await?.is_none()
    {
        return Err(ApiError::unknown("artefact_id", format!("no artefact '{a}'")));
    }
    let target = match &body.target {
        None => None,
        Some(t) => Some(limits::name(t, "target").map_err(|e| ApiError::domain(e, ""))?.to_string()),
    };
    let tool_json = serde_json::to_string(&body.tool).expect("serialises");
    if let Some(t) = &target {
        let sharing = records::sessions_of_robot(&state.pool, &robot.id).await?;
        if let Some(other) = sharing.iter().find(|s| s.target.as_deref() == Some(t) && s.tool_json != tool_json) {
            return Err(ApiError::invalid(
                "target",
                format!(
                    "session '{}' measured target '{t}' with another tool: sessions sharing a target declare the same tool",
                    other.name
                ),
            ));
        }
    }
    let row = records::SessionRow {
        id: db::new_id(),
        robot_id: robot.id.clone(),
        name: name.to_string(),
        purpose: body.purpose,
        instrument: body.instrument,
        tool_json,
        identify_tcp: body.identify_tcp,
        artefact_id: body.artefact_id.clone(),
        created_at: db::now(),
        order: body.order,
        target,
        measurements: 0,
        excluded: 0,
    };
    records::insert_session(&state.pool, &row)
        .await
        .or_conflict("name", || format!("robot '{}' has a session named '{name}'", robot.name))?;
    Ok((StatusCode::CREATED, Json(session_out(&row)?)))
}

/// A robot's sessions, oldest first, a page at a time.
#[utoipa::path(get, path = "/v1/robots/{robot_id}/sessions", tag = "sessions",
    params(("robot_id" = String, Path, description = "Robot id"), PageQuery),
    responses(
        (status = 200, description = "The robot's sessions, oldest first", body = Vec<SessionOut>, headers(
            ("X-Total-Count" = i64, description = "The robot's sessions in all"),
            ("Link" = String, description = "`rel=\"next\"` / `rel=\"prev\"` pages, when there are"))),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Bad `offset` or `limit`", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn list(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(robot_id): Path<String>,
    page: Paging,
) -> Result<(HeaderMap, Json<Vec<SessionOut>>), ApiError> {
    let robot = find_robot(&state, &robot_id).await?;
    page.respond(records::sessions_page(&state.pool, &robot.id, page.offset, page.limit).await?, |r| session_out(&r))
}

/// Get a session.
#[utoipa::path(get, path = "/v1/sessions/{session_id}", tag = "sessions",
    params(("session_id" = String, Path, description = "Session id")),
    responses(
        (status = 200, description = "The session", body = SessionOut),
        (status = 404, description = "Unknown session", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn get(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(session_id): Path<String>,
) -> Result<Json<SessionOut>, ApiError> {
    Ok(Json(session_out(&find(&state, &session_id).await?)?))
}

/// Delete a session with its measurements (and their exclusions), saying why. Refused (409,
/// naming them) while a parameter set, a validation or a diagnosis of the robot was made from the
/// session, or a queued or running job reads it: the history stays true (exclude measurements
/// instead). One transaction; the audit timeline keeps who, when, why and what the session was.
#[utoipa::path(delete, path = "/v1/sessions/{session_id}", tag = "sessions",
    params(("session_id" = String, Path, description = "Session id"), ReasonQuery),
    responses(
        (status = 204, description = "Deleted"),
        (status = 404, description = "Unknown session", body = super::Problem, content_type = "application/problem+json"),
        (status = 409, description = "Stored results or unfinished jobs refer to the session (named in the detail)", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "`reason` missing or empty", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["measure"])))]
pub async fn delete(
    State(state): State<AppState>,
    auth: Authorized<MEASURE>,
    Path(session_id): Path<String>,
    Query(q): Query<ReasonQuery>,
) -> Result<StatusCode, ApiError> {
    find(&state, &session_id).await?;
    let why = reason(q.reason.as_deref())?;
    let mut tx = db::begin_write(&state.pool).await?;
    // Under the write lock: nothing can start using the session between the check and the delete.
    let s =
        records::session(&mut *tx, &session_id).await?.ok_or_else(|| ApiError::not_found("session", &session_id))?;
    let refs = corrections::session_references(&mut tx, &s).await?;
    if !refs.is_empty() {
        return Err(ApiError::conflict_hint(
            format!("session '{}' is used by {}; nothing was deleted", s.name, refs.join(", ")),
            "a session that results were made from stays, so that they can be reproduced: exclude wrong measurements instead (PATCH /v1/sessions/{session_id}/measurements/{index}); a queued job can be cancelled",
        ));
    }
    let detail = serde_json::json!({
        "name": s.name, "purpose": s.purpose, "instrument": s.instrument, "target": s.target,
        "artefact_id": s.artefact_id, "measurements": s.measurements, "excluded_measurements": s.excluded,
        "created_at": s.created_at,
    });
    corrections::delete_session(&mut tx, &s.id).await?;
    let actor = auth.actor();
    super::audit::record(
        &mut tx,
        actor.as_deref(),
        &db::now(),
        Event { action: "session_deleted", robot_id: Some(&s.robot_id), subject_id: &s.id, reason: &why, detail },
    )
    .await?;
    tx.commit().await?;
    Ok(StatusCode::NO_CONTENT)
}
