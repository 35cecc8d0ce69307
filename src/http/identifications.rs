//! Identifications (job): identification sessions + model options (+ an optional DETMAX subset)
//! → a new, immutable parameter set with its quality report, or a failed job whose problem says
//! why (rank deficiency, κ above the limit, divergence).

use axum::extract::{Path, State};
use axum::response::Response;

use super::extract::{Authorized, CALIBRATE, JsonBody};
use super::robots::find as find_robot;
use super::{ApiError, AppState};
use crate::app::cells;
use crate::app::robots::model_of;
use crate::db::jobs::JobKind;
use crate::domain::cell::PurposeSpec;
use crate::jobs::requests::IdentificationRequest;
use crate::jobs::run;

/// Check that the named sessions exist, have `purpose` and hold measurements; their ids.
pub async fn checked_sessions(
    state: &AppState,
    robot_id: &str,
    names: &[String],
    purpose: PurposeSpec,
) -> Result<Vec<String>, ApiError> {
    let sessions = cells::checked_sessions(&state.pool, robot_id, names, purpose, "sessions").await?;
    Ok(sessions.into_iter().map(|s| s.id).collect())
}

/// Start an identification (a job; its result is a parameter set, activated if asked).
#[utoipa::path(post, path = "/v1/robots/{robot_id}/identifications", tag = "identifications",
    params(("robot_id" = String, Path, description = "Robot id")),
    request_body(content = IdentificationRequest, content_type = "application/json"),
    responses(
        (status = 202, description = "Queued; follow the job. A refused fit ends as a failed job whose error names the reason.", body = super::jobs::JobOut),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Unknown session, a session of the wrong purpose or empty, bad options", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["calibrate"])))]
pub async fn create(
    State(state): State<AppState>,
    _auth: Authorized<CALIBRATE>,
    Path(robot_id): Path<String>,
    JsonBody(mut body): JsonBody<IdentificationRequest>,
) -> Result<Response, ApiError> {
    let robot = find_robot(&state, &robot_id).await?;
    let model = model_of(&robot)?;
    let rows = cells::checked_sessions(&state.pool, &robot.id, &body.sessions, PurposeSpec::Identification, "sessions")
        .await?;
    // Excluded measurements name their session as the cell the job builds does: by name.
    for (i, m) in body.exclude.iter_mut().enumerate() {
        let s = rows.iter().find(|s| s.id == m.session || s.name == m.session).ok_or_else(|| {
            ApiError::invalid(format!("exclude[{i}].session"), format!("'{}' is not one of the sessions", m.session))
        })?;
        if m.index as i64 >= s.measurements {
            return Err(ApiError::invalid(
                format!("exclude[{i}].index"),
                format!("session '{}' has {} measurements", s.name, s.measurements),
            ));
        }
        m.session = s.name.clone();
    }
    body.sessions = rows.into_iter().map(|s| s.id).collect();
    run::identify_options(&body, model.dof(), Vec::new())?;
    if let Some(s) = &body.select {
        run::selection(s)?;
    }
    super::jobs::submit(&state, JobKind::Identification, &robot.id, &body).await
}
