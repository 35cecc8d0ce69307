//! Operations: liveness, readiness, Prometheus metrics, the OpenAPI document.

use std::sync::LazyLock;

use axum::Json;
use axum::extract::State;
use axum::http::{StatusCode, Uri, header};
use axum::response::IntoResponse;
use serde::Serialize;
use utoipa::ToSchema;

use super::{ApiError, AppState};
use crate::db;

#[derive(Serialize, ToSchema)]
pub struct Health {
    /// `ok`.
    pub status: String,
    pub version: String,
}

/// Liveness: the process answers.
#[utoipa::path(get, path = "/healthz", tag = "ops",
    responses((status = 200, description = "The process is alive", body = Health)))]
pub async fn healthz() -> Json<Health> {
    Json(Health { status: "ok".into(), version: env!("CARGO_PKG_VERSION").into() })
}

#[derive(Serialize, ToSchema)]
pub struct Readiness {
    /// `ready`.
    pub status: String,
    /// Migrations applied to the database.
    pub migrations: i64,
}

/// Readiness: the database answers, is migrated and takes writes.
///
/// Writes are taken when none has failed for storage trouble lately (a full disk, a read-only
/// file system, an I/O error; a failure counts for 30 s unless a write succeeds after it) and a
/// one-page probe write is committed — all within 2 s: a database that does not answer by then
/// (a replica that lost its PostgreSQL server) is not ready, and a load balancer drains it.
#[utoipa::path(get, path = "/readyz", tag = "ops",
    responses(
        (status = 200, description = "Ready to serve", body = Readiness),
        (status = 503, description = "The database is not usable, or writes are failing", body = super::Problem, content_type = "application/problem+json")))]
pub async fn readyz(State(state): State<AppState>) -> Result<Json<Readiness>, ApiError> {
    match tokio::time::timeout(READY_WITHIN, ready(&state)).await {
        Ok(r) => r,
        Err(_) => {
            tracing::warn!("readiness: the database did not answer within {} s", READY_WITHIN.as_secs());
            Err(ApiError::Unavailable(format!("the database does not answer within {} s", READY_WITHIN.as_secs())))
        }
    }
}

/// How long `/readyz` waits for the database.
const READY_WITHIN: std::time::Duration = std::time::Duration::from_secs(2);

async fn ready(state: &AppState) -> Result<Json<Readiness>, ApiError> {
    let applied: Result<i64, sqlx::Error> =
        sqlx::query_scalar("SELECT COUNT(*) FROM _sqlx_migrations WHERE success = TRUE").fetch_one(&state.pool).await;
    let n = match applied {
        Ok(n) if n as usize == db::MIGRATOR.iter().count() => n,
        Ok(n) => {
            return Err(ApiError::Unavailable(format!("{n} of {} migrations applied", db::MIGRATOR.iter().count())));
        }
        Err(e) => {
            tracing::warn!(error = %e, "readiness: database check failed");
            return Err(ApiError::Unavailable("the database does not answer".into()));
        }
    };
    if let Some((t, ago)) = state.storage.recent() {
        return Err(ApiError::Unavailable(format!(
            "writes are failing: {} ({:.0} s ago)",
            t.cause(),
            ago.as_secs_f64()
        )));
    }
    match db::health::probe(&state.pool).await {
        db::health::Probe::Written | db::health::Probe::Busy => {
            Ok(Json(Readiness { status: "ready".into(), migrations: n }))
        }
        db::health::Probe::Trouble(t) => Err(ApiError::Unavailable(format!("writes are failing: {}", t.cause()))),
        db::health::Probe::Failed(e) => {
            tracing::warn!(error = %e, "readiness: the probe write failed");
            Err(ApiError::Unavailable("the database cannot be written".into()))
        }
    }
}

/// Prometheus metrics (text format): requests by route and status, latency histograms, jobs by
/// state, solver durations.
#[utoipa::path(get, path = "/metrics", tag = "ops",
    responses((status = 200, description = "Prometheus text exposition format", body = String, content_type = "text/plain; version=0.0.4")))]
pub async fn metrics(State(state): State<AppState>) -> Result<impl IntoResponse, ApiError> {
    let counts = db::jobs::counts(&state.pool).await?;
    for s in db::jobs::JobState::ALL {
        let n = counts.iter().find(|(k, _)| *k == s).map_or(0, |(_, n)| *n);
        state.metrics.jobs.with_label_values(&[s.as_str()]).set(n);
    }
    Ok(([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], state.metrics.render()))
}

/// This OpenAPI 3.1 document, as this server's mode makes it: with authentication required every
/// `/v1` operation needs a bearer token; on loopback without it only token management does.
#[utoipa::path(get, path = "/openapi.json", tag = "ops",
    responses((status = 200, description = "The OpenAPI 3.1 document", body = Object)))]
pub async fn openapi(State(state): State<AppState>) -> impl IntoResponse {
    static WITH_AUTH: LazyLock<String> = LazyLock::new(|| super::openapi_json_for(true));
    static LOOPBACK: LazyLock<String> = LazyLock::new(|| super::openapi_json_for(false));
    let config = &state.config;
    let doc = if config.max_batch == crate::app::ServiceConfig::default().max_batch {
        if config.require_auth { WITH_AUTH.clone() } else { LOOPBACK.clone() }
    } else {
        super::openapi_json_with(config.require_auth, config.max_batch)
    };
    ([(header::CONTENT_TYPE, "application/json")], doc)
}

/// Unknown paths: a problem document, not an empty 404.
pub async fn not_found(uri: Uri) -> impl IntoResponse {
    let e = ApiError::NotFound { what: "route", id: uri.path().to_string() };
    (StatusCode::NOT_FOUND, e).into_response()
}
