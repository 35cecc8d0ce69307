//! Errors as `application/problem+json` (RFC 9457): `type`, `title`, `status`, `detail` and the
//! offending `field`. Bad input is 400 (malformed), 413 (too large), 415 (not JSON/CSV) or 422
//! (well-formed but invalid: NaN, wrong lengths, joints outside limits, a degenerate artefact, a
//! session of the wrong purpose); unknown ids 404, in the path or in a field that refers to
//! stored data (`parameter_set_id`, `sessions[2]`, `artefact_id`: `unknown-reference`, naming the
//! field); conflicts 409. Internal errors are logged with
//! their context and answered with a bare 500 that echoes nothing.

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::app::AppError;
use crate::db;
use crate::domain::DomainError;
use crate::domain::measurement_csv::CsvError;
use crate::jobs::JobError;

/// A problem document (RFC 9457).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Problem {
    /// A URI naming the kind of problem, e.g. `urn:robocal:problem:invalid-value`.
    #[serde(rename = "type")]
    pub type_: String,
    pub title: String,
    pub status: u16,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub detail: Option<String>,
    /// The request field at fault, as a path (`measurements[3].joints_deg[1]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
    /// What to do instead (a refused correction, a duplicate upload, a method the resource does
    /// not have).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hint: Option<String>,
}

/// What can go wrong answering a request (or running a job).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ApiError {
    #[error("{detail}")]
    Malformed { detail: String, field: Option<String> },
    #[error("{0}")]
    Unauthorized(String),
    #[error("{0}")]
    Forbidden(String),
    #[error("{what} '{id}' does not exist")]
    NotFound { what: &'static str, id: String },
    /// A body or query field names something the store does not hold (a session, an artefact, a
    /// parameter set of this robot): 404, naming the field. The request is well-formed and within
    /// every bound the document states; what it refers to is not there.
    #[error("{detail}")]
    UnknownReference { detail: String, field: Option<String> },
    #[error("{detail}")]
    Conflict { detail: String, field: Option<String>, hint: Option<String> },
    /// The resource does not have this method (and never will): `allow` lists those it has.
    #[error("{detail}")]
    MethodNotAllowed { detail: String, hint: String, allow: &'static str },
    #[error("{detail}")]
    TooLarge { detail: String, field: Option<String> },
    #[error("{0}")]
    UnsupportedMediaType(String),
    #[error("{detail}")]
    Invalid { detail: String, field: Option<String> },
    /// Numerical trouble in a job: rank deficiency, κ above the limit, divergence, an
    /// unreachable pose plan. `kind` is the problem slug.
    #[error("{detail}")]
    Numerical { kind: &'static str, title: &'static str, detail: String },
    #[error("{0}")]
    Unavailable(String),
    /// The storage under the database refused a write or a read: 507 when full, 503 when
    /// read-only or an I/O error. The answer carries [`StorageRefused`] for the readiness record.
    #[error("{}", .0.describe())]
    Storage(db::StorageTrouble),
    /// A job ran to its end but its result could not be stored: said in the job's `error`.
    #[error("{0}")]
    NotStored(String),
    /// The request body arrived slower than the server's minimum rate (408).
    #[error("{0}")]
    BodyTooSlow(String),
    /// Logged, never echoed.
    #[error("internal error: {0}")]
    Internal(String),
}

impl ApiError {
    pub fn invalid(field: impl Into<String>, detail: impl Into<String>) -> Self {
        ApiError::Invalid { detail: detail.into(), field: Some(field.into()) }
    }

    pub fn malformed(field: Option<String>, detail: impl Into<String>) -> Self {
        ApiError::Malformed { detail: detail.into(), field }
    }

    pub fn conflict(detail: impl Into<String>) -> Self {
        ApiError::Conflict { detail: detail.into(), field: None, hint: None }
    }

    /// A conflict with what to do about it.
    pub fn conflict_hint(detail: impl Into<String>, hint: impl Into<String>) -> Self {
        ApiError::Conflict { detail: detail.into(), field: None, hint: Some(hint.into()) }
    }

    /// `field` names something the store does not hold (see [`ApiError::UnknownReference`]).
    pub fn unknown(field: impl Into<String>, detail: impl Into<String>) -> Self {
        ApiError::UnknownReference { detail: detail.into(), field: Some(field.into()) }
    }

    /// `field` names a parameter set of another robot: for this robot, one it does not have.
    pub fn foreign_set(field: &str) -> Self {
        Self::unknown(field, "this robot has no such parameter set: it belongs to another robot")
    }

    pub fn not_found(what: &'static str, id: &str) -> Self {
        ApiError::NotFound { what, id: id.to_string() }
    }

    /// A domain validation error whose path is the request field itself: that field, and the
    /// bare reason as the detail.
    pub fn field(e: DomainError) -> Self {
        ApiError::Invalid { field: e.field(), detail: e.reason }
    }

    /// A domain validation error under a request-body prefix (`measurements[3]`).
    pub fn domain(e: DomainError, prefix: &str) -> Self {
        let e = e.under(prefix);
        ApiError::Invalid { field: e.field(), detail: e.to_string() }
    }

    pub fn status(&self) -> StatusCode {
        match self {
            ApiError::Malformed { .. } => StatusCode::BAD_REQUEST,
            ApiError::Unauthorized(_) => StatusCode::UNAUTHORIZED,
            ApiError::Forbidden(_) => StatusCode::FORBIDDEN,
            ApiError::NotFound { .. } | ApiError::UnknownReference { .. } => StatusCode::NOT_FOUND,
            ApiError::Conflict { .. } => StatusCode::CONFLICT,
            ApiError::MethodNotAllowed { .. } => StatusCode::METHOD_NOT_ALLOWED,
            ApiError::TooLarge { .. } => StatusCode::PAYLOAD_TOO_LARGE,
            ApiError::UnsupportedMediaType(_) => StatusCode::UNSUPPORTED_MEDIA_TYPE,
            ApiError::Invalid { .. } | ApiError::Numerical { .. } => StatusCode::UNPROCESSABLE_ENTITY,
            ApiError::Unavailable(_) => StatusCode::SERVICE_UNAVAILABLE,
            ApiError::Storage(db::StorageTrouble::Full) => StatusCode::INSUFFICIENT_STORAGE,
            ApiError::Storage(_) => StatusCode::SERVICE_UNAVAILABLE,
            ApiError::BodyTooSlow(_) => StatusCode::REQUEST_TIMEOUT,
            ApiError::NotStored(_) | ApiError::Internal(_) => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }

    /// The problem document (an internal error says nothing about itself).
    pub fn problem(&self) -> Problem {
        let (slug, title, field) = match self {
            ApiError::Malformed { field, .. } => ("malformed", "Malformed request", field.clone()),
            ApiError::Unauthorized(_) => ("unauthorized", "Missing or unknown bearer token", None),
            ApiError::Forbidden(_) => ("forbidden", "The token lacks the scope", None),
            ApiError::NotFound { .. } => ("not-found", "Not found", None),
            ApiError::UnknownReference { field, .. } => ("unknown-reference", "Unknown reference", field.clone()),
            ApiError::Conflict { field, .. } => ("conflict", "Conflict", field.clone()),
            ApiError::MethodNotAllowed { .. } => ("method-not-allowed", "Method Not Allowed", None),
            ApiError::TooLarge { field, .. } => ("too-large", "Request too large", field.clone()),
            ApiError::UnsupportedMediaType(_) => ("unsupported-media-type", "Unsupported media type", None),
            ApiError::Invalid { field, .. } => ("invalid-value", "Invalid value", field.clone()),
            ApiError::Numerical { kind, title, .. } => (*kind, *title, None),
            ApiError::Unavailable(_) => ("unavailable", "Service unavailable", None),
            ApiError::Storage(db::StorageTrouble::Full) => ("insufficient-storage", "Insufficient storage", None),
            ApiError::Storage(_) => ("unavailable", "Service unavailable", None),
            ApiError::BodyTooSlow(_) => ("request-timeout", "Request Timeout", None),
            ApiError::NotStored(_) => ("result-not-stored", "The job's result could not be stored", None),
            ApiError::Internal(_) => ("internal", "Internal error", None),
        };
        let detail = match self {
            ApiError::Internal(_) => None,
            other => Some(other.to_string()),
        };
        let hint = match self {
            ApiError::Conflict { hint, .. } => hint.clone(),
            ApiError::MethodNotAllowed { hint, .. } => Some(hint.clone()),
            _ => None,
        };
        Problem {
            type_: format!("urn:robocal:problem:{slug}"),
            title: title.to_string(),
            status: self.status().as_u16(),
            detail,
            field,
            hint,
        }
    }
}

/// Storage trouble (disk full, read-only, I/O) is said as such — 507 or 503 — and logged;
/// any other database error is internal.
impl From<sqlx::Error> for ApiError {
    fn from(e: sqlx::Error) -> Self {
        match db::storage_trouble(&e) {
            Some(t) => {
                tracing::error!(error = %e, "storage trouble");
                ApiError::Storage(t)
            }
            None => AppError::from(e).into(),
        }
    }
}

/// What a create's insert answers: a UNIQUE violation is 409 naming `field` (what the request gave
/// that is taken) with `detail`; any other database error maps as `From<sqlx::Error>` does.
pub trait OrConflict<T> {
    fn or_conflict(self, field: &str, detail: impl FnOnce() -> String) -> Result<T, ApiError>;
}

impl<T> OrConflict<T> for Result<T, sqlx::Error> {
    fn or_conflict(self, field: &str, detail: impl FnOnce() -> String) -> Result<T, ApiError> {
        self.map_err(|e| {
            if db::is_unique_violation(&e) {
                ApiError::Conflict { detail: detail(), field: Some(field.into()), hint: None }
            } else {
                e.into()
            }
        })
    }
}

impl From<AppError> for ApiError {
    fn from(e: AppError) -> Self {
        match e {
            AppError::Invalid { detail, field } => ApiError::Invalid { detail, field },
            AppError::Unknown { detail, field } => ApiError::UnknownReference { detail, field },
            AppError::Storage(t) => ApiError::Storage(t),
            AppError::Internal(m) => ApiError::Internal(m),
        }
    }
}

/// A CSV batch that does not read is malformed (400); one whose values do not fit is invalid
/// (422); either names the header, column or line.
impl From<CsvError> for ApiError {
    fn from(e: CsvError) -> Self {
        match e {
            CsvError::Malformed(e) => ApiError::Malformed { field: e.field(), detail: e.reason },
            CsvError::Invalid(e) => ApiError::field(e),
        }
    }
}

/// A job's failure is answered (at submission) and stored (when it runs) as the same problem.
impl From<JobError> for ApiError {
    fn from(e: JobError) -> Self {
        match e {
            JobError::Invalid { detail, field } => ApiError::Invalid { detail, field },
            JobError::Unknown { detail, field } => ApiError::UnknownReference { detail, field },
            JobError::Numerical { kind, title, detail } => ApiError::Numerical { kind, title, detail },
            JobError::Storage(t) => ApiError::Storage(t),
            JobError::NotStored(d) => ApiError::NotStored(d),
            JobError::Busy => ApiError::Unavailable(JobError::Busy.to_string()),
            JobError::Internal(m) => ApiError::Internal(m),
        }
    }
}

impl From<tokio::task::JoinError> for ApiError {
    fn from(e: tokio::task::JoinError) -> Self {
        ApiError::Internal(format!("worker task: {e}"))
    }
}

/// The content type of problem documents.
pub const PROBLEM_JSON: &str = "application/problem+json";

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        if let ApiError::Internal(msg) = &self {
            tracing::error!(error = %msg, "internal error");
        }
        let status = self.status();
        let body = serde_json::to_vec(&self.problem()).expect("problem serialises");
        let mut res = (status, [(header::CONTENT_TYPE, HeaderValue::from_static(PROBLEM_JSON))], body).into_response();
        if status == StatusCode::UNAUTHORIZED {
            res.headers_mut().insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
        }
        if let ApiError::MethodNotAllowed { allow, .. } = &self {
            res.headers_mut().insert(header::ALLOW, HeaderValue::from_static(allow));
        }
        if let ApiError::Storage(t) = &self {
            res.extensions_mut().insert(StorageRefused(*t));
        }
        res
    }
}

/// Marks an answer given because the storage refused (see [`ApiError::Storage`]): the service's
/// middleware records it for `/readyz`.
#[derive(Clone, Copy, Debug)]
pub struct StorageRefused(pub db::StorageTrouble);

/// Errors produced outside the handlers — a query string or path that does not parse, a method
/// the route does not have, a request timeout — arrive as plain text or empty bodies; give them
/// the same problem+json shape as every other error (the text becomes the detail).
pub async fn problem_fallback(res: Response) -> Response {
    let status = res.status();
    let is_problem = res
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.starts_with(PROBLEM_JSON));
    if !(status.is_client_error() || status.is_server_error()) || is_problem {
        return res;
    }
    let (parts, body) = res.into_parts();
    let text = axum::body::to_bytes(body, 64 * 1024)
        .await
        .map(|b| String::from_utf8_lossy(&b).trim().to_string())
        .unwrap_or_default();
    let slug = match status.as_u16() {
        400 => "malformed",
        404 => "not-found",
        405 => "method-not-allowed",
        406 => "not-acceptable",
        408 | 503 => "unavailable",
        413 => "too-large",
        415 => "unsupported-media-type",
        422 => "invalid-value",
        s if s >= 500 => "internal",
        _ => "client-error",
    };
    let title = status.canonical_reason().unwrap_or("Error").to_string();
    let detail = if status.is_server_error() && status != StatusCode::SERVICE_UNAVAILABLE {
        None
    } else if text.is_empty() {
        Some(match status.as_u16() {
            503 => "the request took longer than the server's request timeout".to_string(),
            _ => title.clone(),
        })
    } else {
        Some(text)
    };
    let problem = Problem {
        type_: format!("urn:robocal:problem:{slug}"),
        title,
        status: status.as_u16(),
        detail,
        field: None,
        hint: None,
    };
    let mut out = (
        status,
        [(header::CONTENT_TYPE, HeaderValue::from_static(PROBLEM_JSON))],
        serde_json::to_vec(&problem).expect("problem serialises"),
    )
        .into_response();
    for (k, v) in parts.headers.iter() {
        if k != header::CONTENT_TYPE && k != header::CONTENT_LENGTH && k != header::CONTENT_ENCODING {
            out.headers_mut().insert(k.clone(), v.clone());
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn internal_errors_echo_nothing() {
        let p = ApiError::Internal("disk full at /secret/path".into()).problem();
        assert_eq!(p.status, 500);
        assert!(p.detail.is_none());
        let p = ApiError::invalid("measurements[2].ball", "ball 4 is not on the artefact").problem();
        assert_eq!(p.status, 422);
        assert_eq!(p.field.as_deref(), Some("measurements[2].ball"));
        assert_eq!(p.type_, "urn:robocal:problem:invalid-value");
    }

    #[tokio::test]
    async fn a_unique_violation_is_a_conflict_naming_the_field_and_nothing_else_is() {
        let db = crate::db::connect_memory().await.unwrap();
        sqlx::query("CREATE TABLE t (name TEXT UNIQUE)").execute(&db).await.unwrap();
        let insert = || sqlx::query("INSERT INTO t (name) VALUES ('a')").execute(&db);
        insert().await.or_conflict("name", || unreachable!("no conflict")).unwrap();
        let e = insert().await.or_conflict("name", || "a thing named 'a' exists".into()).unwrap_err();
        assert_eq!(
            e,
            ApiError::Conflict { detail: "a thing named 'a' exists".into(), field: Some("name".into()), hint: None }
        );
        let p = e.problem();
        assert_eq!(
            (p.status, p.field.as_deref(), p.type_.as_str()),
            (409, Some("name"), "urn:robocal:problem:conflict")
        );
        // Another database error (no such table) is not a conflict: internal, echoing nothing.
        let e = sqlx::query("INSERT INTO nowhere VALUES (1)").execute(&db).await.or_conflict("name", String::new);
        assert_eq!(e.unwrap_err().problem().status, 500);
    }
}
