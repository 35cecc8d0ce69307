//! Request metrics: every request counted and timed into the registry ([`Metrics`], shared with
//! the job workers in [`crate::app`]) by its route template, and a `Server-Timing` header on
//! every response.

use std::time::Instant;

use axum::extract::{MatchedPath, Request, State};
use axum::http::{HeaderName, HeaderValue};
use axum::middleware::Next;
use axum::response::Response;

use super::AppState;
pub use crate::app::Metrics;

/// Middleware: count and time every request by its route template (`/v1/robots/{robot_id}`),
/// never by the raw path (ids would make unbounded label sets).
pub async fn track(State(state): State<AppState>, req: Request, next: Next) -> Response {
    let route =
        req.extensions().get::<MatchedPath>().map_or_else(|| "unmatched".to_string(), |m| m.as_str().to_string());
    let method = req.method().as_str().to_string();
    let start = Instant::now();
    let mut res = next.run(req).await;
    let elapsed = start.elapsed();
    let m = &state.metrics;
    m.latency.with_label_values(&[route.as_str(), method.as_str()]).observe(elapsed.as_secs_f64());
    m.requests.with_label_values(&[route.as_str(), method.as_str(), res.status().as_str()]).inc();
    // W3C Server-Timing: the server's own time (body read, handler, response built), so a client
    // can tell it from the network's.
    if let Ok(v) = HeaderValue::from_str(&format!("app;dur={:.3}", elapsed.as_secs_f64() * 1e3)) {
        res.headers_mut().insert(SERVER_TIMING, v);
    }
    res
}

/// The `Server-Timing` response header.
pub const SERVER_TIMING: HeaderName = HeaderName::from_static("server-timing");
