//! HTML reports of stored results (issue 15): a validation, a parameter set (its identification's
//! quality, parameters with error bars and its latest validation) and a diagnosis, each one
//! self-contained `text/html` page (inline CSS and SVG; nothing fetched), rendered by
//! `crate::report` from the stored documents — the same calls `robocal … --report` makes on the
//! same documents, so both give the same page.
//!
//! Content negotiation: a client whose `Accept` admits HTML (or says nothing) gets the page; one
//! that accepts only other types (`application/json`) gets 406 as problem+json.

use axum::extract::{Path, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde_json::Value;

use super::error::PROBLEM_JSON;
use super::extract::{Authorized, READ};
use super::{ApiError, AppState, Problem};
use crate::db::records;
use crate::domain::ParameterSetFile;
use crate::domain::diagnosis::DiagnosisOut;
use crate::domain::validation::ValidationOut;
use crate::report;

/// Whether `Accept` admits `text/html`: absent, or a range `text/html`, `text/*` or `*/*` with a
/// non-zero q.
pub fn accepts_html(headers: &HeaderMap) -> bool {
    let values: Vec<&str> = headers.get_all(header::ACCEPT).iter().filter_map(|v| v.to_str().ok()).collect();
    if values.is_empty() {
        return true;
    }
    values.iter().flat_map(|v| v.split(',')).any(|range| {
        let mut parts = range.split(';').map(str::trim);
        let media = parts.next().unwrap_or("").to_ascii_lowercase();
        let q = parts
            .filter_map(|p| p.strip_prefix("q=").or_else(|| p.strip_prefix("Q=")))
            .filter_map(|q| q.trim().parse::<f64>().ok())
            .next()
            .unwrap_or(1.0);
        q > 0.0 && matches!(media.as_str(), "text/html" | "text/*" | "*/*")
    })
}

pub(super) fn not_acceptable() -> Response {
    let problem = Problem {
        type_: "urn:robocal:problem:not-acceptable".into(),
        title: "Not acceptable".into(),
        status: 406,
        detail: Some("this resource is an HTML report: accept text/html".into()),
        field: None,
        hint: Some("the same figures as JSON are at the resource without /report".into()),
    };
    let body = serde_json::to_vec(&problem).expect("problem serialises");
    (StatusCode::NOT_ACCEPTABLE, [(header::CONTENT_TYPE, HeaderValue::from_static(PROBLEM_JSON))], body).into_response()
}

pub(super) fn html(page: String) -> Response {
    (
        StatusCode::OK,
        [
            (header::CONTENT_TYPE, HeaderValue::from_static("text/html; charset=utf-8")),
            // The report draws everything inline: forbid the page any fetch and any script.
            (
                header::CONTENT_SECURITY_POLICY,
                HeaderValue::from_static("default-src 'none'; style-src 'unsafe-inline'; img-src data:"),
            ),
        ],
        page,
    )
        .into_response()
}

fn stored<T: serde::de::DeserializeOwned>(json: &str, what: &str) -> Result<T, ApiError> {
    serde_json::from_str(json).map_err(|e| ApiError::Internal(format!("stored {what}: {e}")))
}

fn validation_doc(row: &records::ValidationRow) -> Result<ValidationOut, ApiError> {
    let v: Value = stored(&row.report_json, "validation")?;
    report::read_validation(&v).map_err(|e| ApiError::Internal(format!("validation {}: {e}", row.id)))
}

/// A validation's report.
#[utoipa::path(get, path = "/v1/validations/{validation_id}/report", tag = "validations",
    params(("validation_id" = String, Path, description = "Validation id")),
    responses(
        (status = 200, description = "The validation report: before/after table, per-axis statistics, error distributions (histogram, CDF, Q–Q), error against distance, the poses shaded by error; self-contained HTML", body = String, content_type = "text/html"),
        (status = 404, description = "Unknown validation (a validation exists once its job has succeeded)", body = super::Problem, content_type = "application/problem+json"),
        (status = 406, description = "The client accepts no HTML", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn validation(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    headers: HeaderMap,
    Path(validation_id): Path<String>,
) -> Result<Response, ApiError> {
    if !accepts_html(&headers) {
        return Ok(not_acceptable());
    }
    let row = records::validation(&state.pool, &validation_id)
        .await?
        .ok_or_else(|| ApiError::not_found("validation", &validation_id))?;
    let doc = validation_doc(&row)?;
    Ok(html(report::validation_report(&doc)))
}

/// A parameter set's report: its identification (or import) and its latest validation.
#[utoipa::path(get, path = "/v1/parameter-sets/{set_id}/report", tag = "parameter-sets",
    params(("set_id" = String, Path, description = "Parameter set id")),
    responses(
        (status = 200, description = "The identification report: quality (κ, O1, residual), parameters with their change from nominal and 95 % error bars, and the latest validation of the set when there is one; self-contained HTML", body = String, content_type = "text/html"),
        (status = 404, description = "Unknown parameter set (a parameter set exists once its identification job has succeeded)", body = super::Problem, content_type = "application/problem+json"),
        (status = 406, description = "The client accepts no HTML", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn parameter_set(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    headers: HeaderMap,
    Path(set_id): Path<String>,
) -> Result<Response, ApiError> {
    if !accepts_html(&headers) {
        return Ok(not_acceptable());
    }
    let row = records::parameter_set(&state.pool, &set_id)
        .await?
        .ok_or_else(|| ApiError::not_found("parameter set", &set_id))?;
    let set: ParameterSetFile = stored(&row.doc_json, "parameter set")?;
    let latest = records::validations_of_set(&state.pool, &set_id).await?;
    let validation = latest.first().map(validation_doc).transpose()?;
    let robot = records::robot(&state.pool, &row.robot_id).await?;
    let sessions: Vec<String> = stored(&row.sessions_json, "parameter set sessions")?;
    let robot_name = robot.map_or_else(|| row.robot_id.clone(), |r| r.name);
    let source = report::ReportSource {
        set: format!("Parameter set {}, version {}", row.id, row.version),
        made: Some(row.created_at.clone()),
        input: Some(if sessions.is_empty() {
            format!("a file imported for robot {robot_name}")
        } else {
            format!("sessions {} of robot {robot_name}", sessions.join(", "))
        }),
    };
    Ok(html(report::parameter_set_report(&set, validation.as_ref(), &source)))
}

/// A diagnosis's report.
#[utoipa::path(get, path = "/v1/diagnoses/{diagnosis_id}/report", tag = "diagnoses",
    params(("diagnosis_id" = String, Path, description = "Diagnosis id")),
    responses(
        (status = 200, description = "The diagnosis report: verdict, decomposition bar, candidates, residual profiles, voxels above the floor, shrink table; self-contained HTML", body = String, content_type = "text/html"),
        (status = 404, description = "Unknown diagnosis (a diagnosis exists once its job has succeeded)", body = super::Problem, content_type = "application/problem+json"),
        (status = 406, description = "The client accepts no HTML", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn diagnosis(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    headers: HeaderMap,
    Path(diagnosis_id): Path<String>,
) -> Result<Response, ApiError> {
    if !accepts_html(&headers) {
        return Ok(not_acceptable());
    }
    let row = records::diagnosis(&state.pool, &diagnosis_id)
        .await?
        .ok_or_else(|| ApiError::not_found("diagnosis", &diagnosis_id))?;
    let d: DiagnosisOut = stored(&row.report_json, "diagnosis")?;
    Ok(html(report::diagnosis_report(&d)))
}

/// A robot's calibration history as a page: each parameter set's held-out error (its latest
/// validation's mean, p95 and max, and the nominal mean) against its version, and the table of
/// the sets. Filtered like the JSON history.
#[utoipa::path(get, path = "/v1/robots/{robot_id}/history/report", tag = "robots",
    params(("robot_id" = String, Path, description = "Robot id"), super::history::HistoryRangeQuery),
    responses(
        (status = 200, description = "The history page: held-out error per parameter set version, and the sets with their dates, sessions, activation and diagnosis verdicts; self-contained HTML", body = String, content_type = "text/html"),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json"),
        (status = 406, description = "The client accepts no HTML", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Bad `from` or `to`", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn history(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    headers: HeaderMap,
    Path(robot_id): Path<String>,
    axum::extract::Query(q): axum::extract::Query<super::history::HistoryRangeQuery>,
) -> Result<Response, ApiError> {
    use crate::app::history::{HistoryFilter, history as load_history};
    if !accepts_html(&headers) {
        return Ok(not_acceptable());
    }
    let range = crate::domain::history::TimeRange::parse(q.from.as_deref(), q.to.as_deref())
        .map_err(|e| ApiError::domain(e, ""))?;
    let robot = super::robots::find(&state, &robot_id).await?;
    let filter = HistoryFilter { range, include_archived: q.include_archived.unwrap_or(false), offset: 0, limit: None };
    let page = load_history(&state.pool, &robot.id, &filter).await?;
    let points: Vec<report::HistoryPoint> = page
        .entries
        .iter()
        .map(|e| report::HistoryPoint {
            version: e.version,
            created_at: e.created_at.clone(),
            sessions: e.sessions.clone(),
            active: e.active,
            archived: e.archived,
            mean_mm: e.validation.as_ref().and_then(|v| v.mean_mm),
            p95_mm: e.validation.as_ref().and_then(|v| v.p95_mm),
            max_mm: e.validation.as_ref().and_then(|v| v.max_mm),
            nominal_mean_mm: e.validation.as_ref().and_then(|v| v.nominal_mean_mm),
            in_sample_mean_mm: e.in_sample.as_ref().and_then(|v| v.mean_mm),
            in_sample_sessions: e
                .in_sample
                .as_ref()
                .map(|v| v.sessions.iter().filter(|s| e.fit_sessions.contains(s)).cloned().collect())
                .unwrap_or_default(),
            verdict: e.diagnosis.as_ref().map(|d| d.verdict.to_string()),
        })
        .collect();
    Ok(html(report::history_report(&robot.name, &points)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn accept(v: &str) -> bool {
        let mut h = HeaderMap::new();
        h.insert(header::ACCEPT, HeaderValue::from_str(v).unwrap());
        accepts_html(&h)
    }

    #[test]
    fn negotiation() {
        assert!(accepts_html(&HeaderMap::new()));
        assert!(accept("text/html,application/xhtml+xml,application/xml;q=0.9,*/*;q=0.8"));
        assert!(accept("*/*"));
        assert!(accept("application/json, text/*;q=0.5"));
        assert!(!accept("application/json"));
        assert!(!accept("application/json, application/problem+json"));
        assert!(!accept("text/html;q=0, application/json"));
    }
}
