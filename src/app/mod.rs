//! What the routes and the jobs share, on top of the store: the service's state (the pool, its
//! settings, the in-memory caches, the metrics registry, the job queue's wake-up), loading a
//! robot's model, and assembling a cell file from stored sessions. It knows nothing of HTTP or of
//! the job workers: both sit above it and turn [`AppError`] into their own errors.

pub mod cache;
pub mod cells;
pub mod history;
pub mod metrics;
pub mod robots;

use std::sync::Arc;
use std::time::Duration;

use crate::db::Pool;
use tokio::sync::Notify;

pub use crate::domain::origin::CorsOrigins;
pub use metrics::Metrics;

/// Service settings.
#[derive(Clone, Debug)]
pub struct ServiceConfig {
    /// Every `/v1` request needs a bearer token with the right scope (always when the server is
    /// bound to a non-loopback address).
    pub require_auth: bool,
    /// Most measurements (or compensation targets) in one request: 413 beyond.
    pub max_batch: usize,
    /// Largest request body, bytes: 413 beyond.
    pub max_body_bytes: usize,
    /// Requests taking longer are answered 503 (jobs run in the background and are not affected).
    pub request_timeout: Duration,
    /// Browser origins allowed to call the API from a web page (CORS); off by default.
    pub cors: CorsOrigins,
    /// The slowest a request body may arrive: after `body_grace` from its first read, on average
    /// at least `body_min_rate` bytes a second (the time allowed grows by a second for each
    /// `body_min_rate` bytes received); slower is cut with 408.
    pub body_min_rate: u64,
    pub body_grace: Duration,
    /// A claimed job's lease (see [`crate::jobs::JobContext::lease`]).
    pub job_lease: Duration,
}

impl Default for ServiceConfig {
    fn default() -> Self {
        Self {
            require_auth: false,
            max_batch: 10_000,
            max_body_bytes: 32 * 1024 * 1024,
            request_timeout: Duration::from_secs(60),
            cors: CorsOrigins::Off,
            body_min_rate: 1024,
            body_grace: Duration::from_secs(10),
            job_lease: crate::jobs::LEASE,
        }
    }
}

/// What every handler shares (and the job workers take their context from).
#[derive(Clone)]
pub struct AppState {
    pub pool: Pool,
    pub config: Arc<ServiceConfig>,
    pub metrics: Arc<Metrics>,
    /// Wakes the job workers when a job is queued.
    pub wake: Arc<Notify>,
    /// Robots and compiled parameter sets (the compensation hot path).
    pub caches: Arc<cache::Caches>,
    /// Whether writes are failing for storage trouble, and which jobs wait for storage (for
    /// `/readyz` and the jobs' `phase`).
    pub storage: Arc<crate::db::StorageHealth>,
}

impl AppState {
    pub fn new(pool: Pool, config: ServiceConfig) -> Self {
        let backend = crate::db::Backend::of(&pool);
        AppState {
            pool,
            config: Arc::new(config),
            metrics: Arc::new(Metrics::new()),
            wake: Arc::new(Notify::new()),
            // Replicas sharing a PostgreSQL database change robots behind each other's back.
            caches: Arc::new(match backend {
                crate::db::Backend::Sqlite => cache::Caches::new(256),
                crate::db::Backend::Postgres => cache::Caches::shared(256),
            }),
            storage: Arc::new(crate::db::StorageHealth::default()),
        }
    }
}

/// What can go wrong loading from the store.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AppError {
    /// The request named something the store cannot serve (an unknown or repeated session,
    /// sessions on different artefacts, a robot without a base guess): the field and why.
    #[error("{detail}")]
    Invalid { detail: String, field: Option<String> },
    /// The request names, in `field`, something the store does not hold (a session, an artefact,
    /// a parameter set): well-formed and within every bound, refused because of what is stored,
    /// not because of what was sent. Answered 404 naming the field.
    #[error("{detail}")]
    Unknown { detail: String, field: Option<String> },
    /// The storage under the database refused: full, read-only or an I/O error.
    #[error("{}", .0.describe())]
    Storage(crate::db::StorageTrouble),
    /// The store failed, or holds what it should not; logged, never echoed.
    #[error("internal error: {0}")]
    Internal(String),
}

impl AppError {
    pub fn invalid(field: impl Into<String>, detail: impl Into<String>) -> Self {
        AppError::Invalid { detail: detail.into(), field: Some(field.into()) }
    }

    /// `field` names something the store does not hold (see [`AppError::Unknown`]).
    pub fn unknown(field: impl Into<String>, detail: impl Into<String>) -> Self {
        AppError::Unknown { detail: detail.into(), field: Some(field.into()) }
    }
}

impl From<sqlx::Error> for AppError {
    fn from(e: sqlx::Error) -> Self {
        match crate::db::storage_trouble(&e) {
            Some(t) => {
                tracing::error!(error = %e, "storage trouble");
                AppError::Storage(t)
            }
            None => AppError::Internal(format!("database: {e}")),
        }
    }
}
