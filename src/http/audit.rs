//! The audit timeline: every correction of stored data (a measurement excluded or restored, a
//! session or an artefact deleted, a parameter set archived or unarchived), with who, when and
//! why; and the reason every correction must give.

use axum::Json;
use axum::extract::{Query, State};
use axum::http::HeaderMap;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use utoipa::{IntoParams, ToSchema};

use super::extract::{Authorized, READ};
use super::paging::{PageQuery, Paging};
use super::{ApiError, AppState};
use crate::db::{self, corrections};
use crate::domain::limits;

/// Why a correction is made: required, non-empty (trimmed), at most 2000 characters; 422 naming
/// `reason` otherwise.
pub fn reason(text: Option<&str>) -> Result<String, ApiError> {
    Ok(limits::reason(text.unwrap_or(""), "reason").map_err(|e| ApiError::domain(e, ""))?.to_string())
}

/// The reason of a DELETE, as a query parameter (`?reason=…`, URL-encoded).
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct ReasonQuery {
    /// Why (required, not blank, at most 2000 characters; recorded in the audit timeline).
    #[param(value_type = String, required = true, min_length = 1, max_length = 2000, pattern = "^[^\\u0000]*[^\\s\\u0000][^\\u0000]*$")]
    pub reason: Option<String>,
}

/// A correction to record: what, of which robot, about which subject, why, and what the subject
/// was.
pub struct Event<'a> {
    pub action: &'a str,
    pub robot_id: Option<&'a str>,
    pub subject_id: &'a str,
    pub reason: &'a str,
    pub detail: Value,
}

/// Record a correction (inside the transaction that makes it).
pub async fn record(tx: &mut crate::db::Conn, actor: Option<&str>, at: &str, e: Event<'_>) -> Result<(), ApiError> {
    let row = corrections::AuditRow {
        id: db::new_id(),
        at: at.to_string(),
        actor: actor.map(str::to_string),
        action: e.action.to_string(),
        robot_id: e.robot_id.map(str::to_string),
        subject_id: e.subject_id.to_string(),
        reason: e.reason.to_string(),
        detail_json: e.detail.to_string(),
    };
    corrections::insert_audit(&mut *tx, &row).await?;
    Ok(())
}

/// One correction.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct AuditEventOut {
    pub id: String,
    pub at: String,
    /// The bearer token's name; absent when the server took the request without a token.
    pub actor: Option<String>,
    /// `measurement_excluded`, `measurement_restored`, `session_deleted`, `artefact_deleted`,
    /// `parameter_set_archived` or `parameter_set_unarchived`.
    pub action: String,
    pub robot_id: Option<String>,
    /// The id of what was corrected (a session's for its measurements; it may no longer exist).
    pub subject_id: String,
    pub reason: String,
    /// What the subject was: a measurement's session and index, a deleted session's name,
    /// purpose and measurement count, a deleted artefact's specification, a set's version.
    #[schema(value_type = Object)]
    pub detail: Value,
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct AuditQuery {
    /// Only the corrections of this robot.
    pub robot_id: Option<String>,
    /// Only the corrections of this subject (a session, an artefact, a parameter set).
    pub subject_id: Option<String>,
}

/// The audit timeline, newest first, a page at a time.
#[utoipa::path(get, path = "/v1/audit-events", tag = "audit", params(AuditQuery, PageQuery),
    responses(
        (status = 200, description = "Corrections, newest first", body = Vec<AuditEventOut>, headers(
            ("X-Total-Count" = i64, description = "Corrections matching the filters"),
            ("Link" = String, description = "`rel=\"next\"` / `rel=\"prev\"` pages, when there are"))),
        (status = 422, description = "Bad `offset` or `limit`", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn list(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Query(q): Query<AuditQuery>,
    page: Paging,
) -> Result<(HeaderMap, Json<Vec<AuditEventOut>>), ApiError> {
    let robot = q.robot_id.as_deref().filter(|s| !s.is_empty());
    let subject = q.subject_id.as_deref().filter(|s| !s.is_empty());
    let rows = corrections::audit_events(&state.pool, robot, subject, page.offset, page.limit).await?;
    page.respond(rows, |r| {
        let detail = serde_json::from_str(&r.detail_json)
            .map_err(|e| ApiError::Internal(format!("audit event {}: {e}", r.id)))?;
        Ok(AuditEventOut {
            id: r.id,
            at: r.at,
            actor: r.actor,
            action: r.action,
            robot_id: r.robot_id,
            subject_id: r.subject_id,
            reason: r.reason,
            detail,
        })
    })
}
