//! Stored sessions → a cell file: the one document the CLI and the jobs both identify from, so
//! the server and `robocal identify` give the same parameter set, bit for bit.

use serde_json::Value;
use sqlx::SqlitePool;

use super::AppError;
use crate::db::records::{self, RobotRow, SessionRow};
use crate::domain::ToolSpec;
use crate::domain::cell::{ArtefactSpec, CellFile, MeasurementSpec, PoseXyzAbc, PurposeSpec, SessionSpec};

/// The robot's sessions named (by id or name) in a request field; 422 naming the item when one
/// is unknown or repeated.
pub async fn resolve_sessions(
    pool: &SqlitePool,
    robot_id: &str,
    names: &[String],
    field: &str,
) -> Result<Vec<SessionRow>, AppError> {
    if names.is_empty() {
        return Err(AppError::invalid(field, "name at least one session"));
    }
    let mut out: Vec<SessionRow> = Vec::with_capacity(names.len());
    for (i, n) in names.iter().enumerate() {
        let s = records::session_of_robot(pool, robot_id, n)
            .await?
            .ok_or_else(|| AppError::invalid(format!("{field}[{i}]"), format!("this robot has no session '{n}'")))?;
        if out.iter().any(|o| o.id == s.id) {
            return Err(AppError::invalid(format!("{field}[{i}]"), format!("session '{n}' is named twice")));
        }
        out.push(s);
    }
    Ok(out)
}

/// The robot's sessions named in a request field (see [`resolve_sessions`]), each of `purpose`
/// and holding measurements; 422 naming the item otherwise.
pub async fn checked_sessions(
    pool: &SqlitePool,
    robot_id: &str,
    names: &[String],
    purpose: PurposeSpec,
    field: &str,
) -> Result<Vec<SessionRow>, AppError> {
    let sessions = resolve_sessions(pool, robot_id, names, field).await?;
    for (i, s) in sessions.iter().enumerate() {
        if s.purpose != purpose {
            return Err(AppError::invalid(
                format!("{field}[{i}]"),
                format!(
                    "session '{}' is {} session; this needs {} sessions",
                    s.name,
                    crate::domain::with_article(s.purpose.as_str()),
                    purpose.as_str()
                ),
            ));
        }
        if s.measurements == 0 {
            return Err(AppError::invalid(
                format!("{field}[{i}]"),
                format!("session '{}' has no measurements", s.name),
            ));
        }
    }
    Ok(sessions)
}

/// Every session of the robot with `purpose` that holds measurements, in creation order.
pub async fn sessions_with_purpose(
    pool: &SqlitePool,
    robot_id: &str,
    purpose: PurposeSpec,
) -> Result<Vec<SessionRow>, AppError> {
    Ok(records::sessions_of_robot(pool, robot_id)
        .await?
        .into_iter()
        .filter(|s| s.purpose == purpose && s.measurements > 0)
        .collect())
}

/// Every stored measurement of a session, in order.
pub async fn session_measurements(pool: &SqlitePool, session_id: &str) -> Result<Vec<MeasurementSpec>, AppError> {
    let rows = records::measurements(pool, session_id, 0, i64::MAX).await?;
    rows.iter()
        .map(|(seq, json)| {
            serde_json::from_str(json)
                .map_err(|e| AppError::Internal(format!("measurement {seq} of session {session_id}: {e}")))
        })
        .collect()
}

/// The cell file of `sessions` of `robot`, in the given order. Sessions that use an artefact must
/// all use the same one (a cell has one world frame).
pub async fn cell_file(pool: &SqlitePool, robot: &RobotRow, sessions: &[SessionRow]) -> Result<CellFile, AppError> {
    let internal = |what: &str, e: serde_json::Error| AppError::Internal(format!("robot {}: {what}: {e}", robot.id));
    let robot_json: Value = serde_json::from_str(&robot.model_json).map_err(|e| internal("model", e))?;
    let base_guess: Option<PoseXyzAbc> = robot
        .base_guess_json
        .as_deref()
        .map(serde_json::from_str)
        .transpose()
        .map_err(|e| internal("base guess", e))?;
    let mut artefact_id: Option<&str> = None;
    for s in sessions {
        if let Some(a) = s.artefact_id.as_deref() {
            match artefact_id {
                None => artefact_id = Some(a),
                Some(b) if b != a => {
                    return Err(AppError::invalid(
                        "sessions",
                        format!("sessions use different artefacts ({b} and {a}); a cell has one artefact"),
                    ));
                }
                _ => {}
            }
        }
    }
    let artefact = match artefact_id {
        None => None,
        Some(id) => {
            let row = records::artefact(pool, id)
                .await?
                .ok_or_else(|| AppError::Internal(format!("artefact {id} missing")))?;
            Some(serde_json::from_str::<ArtefactSpec>(&row.spec_json).map_err(|e| internal("artefact", e))?)
        }
    };
    let mut specs = Vec::with_capacity(sessions.len());
    for s in sessions {
        specs.push(SessionSpec {
            name: s.name.clone(),
            purpose: s.purpose,
            instrument: s.instrument,
            tool: serde_json::from_str::<ToolSpec>(&s.tool_json).map_err(|e| internal("tool", e))?,
            identify_tcp: s.identify_tcp,
            order: s.order,
            target: s.target.clone(),
            measurements: session_measurements(pool, &s.id).await?,
        });
    }
    Ok(CellFile { robot: robot_json, base_guess, artefact, sessions: specs })
}

/// The artefact the robot was calibrated on: the one its identification sessions use, when they
/// all use the same one. A validation on sessions without an artefact (a laser tracker's) places
/// its calibration zone (the ball triangle's centroid) with it, as a cell file does.
pub async fn calibration_artefact(pool: &SqlitePool, robot_id: &str) -> Result<Option<ArtefactSpec>, AppError> {
    let sessions = sessions_with_purpose(pool, robot_id, PurposeSpec::Identification).await?;
    let mut ids: Vec<&str> = sessions.iter().filter_map(|s| s.artefact_id.as_deref()).collect();
    ids.sort_unstable();
    ids.dedup();
    let [id] = ids[..] else { return Ok(None) };
    let row = records::artefact(pool, id).await?.ok_or_else(|| AppError::Internal(format!("artefact {id} missing")))?;
    serde_json::from_str::<ArtefactSpec>(&row.spec_json)
        .map(Some)
        .map_err(|e| AppError::Internal(format!("artefact {id}: {e}")))
}
