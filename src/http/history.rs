//! A robot's calibration history for dashboards — a time series, one entry per parameter set,
//! oldest first, filterable by date and paged like every list — and the parameter drift between
//! two sets.

use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::HeaderMap;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use super::extract::{Authorized, READ};
use super::paging::{PageQuery, Paging};
use super::robots::find as find_robot;
use super::{ApiError, AppState};
use crate::app::history::{HistoryEntry, HistoryFilter, history as load_history};
use crate::db::records;
use crate::domain::ParameterSetDoc;
use crate::domain::drift::{DriftReport, drift as drift_of};
use crate::domain::history::TimeRange;

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct HistoryRangeQuery {
    /// Sets created at or after this: an RFC 3339 date-time with its offset
    /// (`2026-11-24T13:00:00Z`) or a date (`2026-11-24`, midnight UTC).
    #[param(schema_with = instant)]
    pub from: Option<String>,
    /// Sets created before this (same forms; at or before `from`: an empty range).
    #[param(schema_with = instant)]
    pub to: Option<String>,
    /// Archived sets too (default false).
    pub include_archived: Option<bool>,
}

/// `from` and `to` as the document states them: a `date-time` or a `date` (RFC 3339), what
/// [`TimeRange::parse`] reads.
fn instant() -> utoipa::openapi::schema::Schema {
    use utoipa::openapi::schema::{AnyOfBuilder, KnownFormat, ObjectBuilder, Schema, SchemaFormat, Type};
    let of = |f| ObjectBuilder::new().schema_type(Type::String).format(Some(SchemaFormat::KnownFormat(f)));
    Schema::AnyOf(AnyOfBuilder::new().item(of(KnownFormat::DateTime)).item(of(KnownFormat::Date)).build())
}

/// A robot's calibration history as a time series, oldest first: per parameter set its version,
/// date, sessions, the latest validation's mean/p95/max (mm), the latest diagnosis's verdict, and
/// whether it is or was active. Filtered by creation date (`from` inclusive, `to` exclusive),
/// archived sets only with `include_archived=true`, a page at a time.
#[utoipa::path(get, path = "/v1/robots/{robot_id}/history", tag = "robots",
    params(("robot_id" = String, Path, description = "Robot id"), HistoryRangeQuery, PageQuery),
    responses(
        (status = 200, description = "One entry per parameter set, oldest first", body = Vec<HistoryEntry>, headers(
            ("X-Total-Count" = i64, description = "Entries in the filtered history"),
            ("Link" = String, description = "`rel=\"next\"` / `rel=\"prev\"` pages, when there are"))),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Bad `from` or `to` (not an RFC 3339 date-time or date), `offset` or `limit`", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn history(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(robot_id): Path<String>,
    Query(q): Query<HistoryRangeQuery>,
    page: Paging,
) -> Result<(HeaderMap, Json<Vec<HistoryEntry>>), ApiError> {
    let range = TimeRange::parse(q.from.as_deref(), q.to.as_deref()).map_err(|e| ApiError::domain(e, ""))?;
    let robot = find_robot(&state, &robot_id).await?;
    let filter = HistoryFilter {
        range,
        include_archived: q.include_archived.unwrap_or(false),
        offset: page.offset,
        limit: Some(page.limit),
    };
    let h = load_history(&state.pool, &robot.id, &filter).await?;
    Ok((page.headers(h.total, h.entries.len()), Json(h.entries)))
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct DriftQuery {
    /// The set to compare against (required): another set of the same robot.
    #[param(value_type = String, required = true)]
    pub against: Option<String>,
}

/// A set named in a drift.
#[derive(Debug, Serialize, ToSchema)]
pub struct SetRef {
    pub parameter_set_id: String,
    pub version: i64,
    pub created_at: String,
}

/// The drift of a set against another.
#[derive(Debug, Serialize, ToSchema)]
pub struct DriftOut {
    /// The set asked about (A).
    pub parameter_set: SetRef,
    /// The set it is compared against (B).
    pub against: SetRef,
    /// Per parameter both identify: value_a, value_b, change = value_a − value_b, std_a, std_b,
    /// combined_std = √(std_a² + std_b²), n_sigma = |change|/combined_std, moved = |change| >
    /// combined_std; in the parameter's unit (mm, deg, deg/(N·m)). Parameters identified in one
    /// set only are listed by name.
    pub drift: DriftReport,
}

fn set_ref(row: &records::ParameterSetRow) -> SetRef {
    SetRef { parameter_set_id: row.id.clone(), version: row.version, created_at: row.created_at.clone() }
}

fn doc_of(row: &records::ParameterSetRow) -> Result<ParameterSetDoc, ApiError> {
    ParameterSetDoc::from_json(&row.doc_json)
        .map_err(|e| ApiError::Internal(format!("parameter set {}: stored file invalid: {e}", row.id)))
}

/// How far a parameter set's parameters moved from another set's of the same robot, against the
/// sets' own uncertainties.
#[utoipa::path(get, path = "/v1/parameter-sets/{set_id}/drift", tag = "parameter-sets",
    params(("set_id" = String, Path, description = "Parameter set id (A)"), DriftQuery),
    responses(
        (status = 200, description = "The drift of A against B", body = DriftOut),
        (status = 404, description = "Unknown parameter set", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "`against` missing, unknown, or a set of another robot", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn drift(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(set_id): Path<String>,
    Query(q): Query<DriftQuery>,
) -> Result<Json<DriftOut>, ApiError> {
    let a = records::parameter_set(&state.pool, &set_id)
        .await?
        .ok_or_else(|| ApiError::not_found("parameter set", &set_id))?;
    let against =
        q.against.as_deref().map(str::trim).filter(|s| !s.is_empty()).ok_or_else(|| {
            ApiError::invalid("against", "name the set to compare against: ?against=<parameter set id>")
        })?;
    let b = records::parameter_set(&state.pool, against)
        .await?
        .ok_or_else(|| ApiError::unknown("against", format!("no parameter set '{against}'")))?;
    if b.robot_id != a.robot_id {
        return Err(ApiError::foreign_set("against"));
    }
    let report = drift_of(&doc_of(&a)?, &doc_of(&b)?, "against").map_err(|e| ApiError::domain(e, ""))?;
    Ok(Json(DriftOut { parameter_set: set_ref(&a), against: set_ref(&b), drift: report }))
}
