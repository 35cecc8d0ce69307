//! Stored sessions → a cell file: the one document the CLI and the jobs both identify from, so
//! the server and `robocal identify` give the same parameter set, bit for bit.
//!
//! Excluded measurements (an open exclusion, migration 0005) are left out of the cell the jobs
//! build and of the exported cell file, so `robocal identify` on the export still reproduces the
//! server's fit. A cell's measurement indices then differ from the stored ones after the first
//! excluded measurement: [`StoredIndices`] maps them back, so that what the jobs report (the
//! worst residuals, outliers, validation residuals) names measurements by their stored index,
//! the one the API lists and excludes by.

use crate::db::Pool;
use serde_json::Value;

use super::AppError;
use crate::db::records::{self, RobotRow, SessionRow};
use crate::domain::ToolSpec;
use crate::domain::cell::{ArtefactSpec, CellFile, MeasurementSpec, PoseXyzAbc, PurposeSpec, SessionSpec};

/// The robot's sessions named (by id or name) in a request field; 422 naming the item when one
/// is unknown or repeated.
pub async fn resolve_sessions(
    pool: &Pool,
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
            .ok_or_else(|| AppError::unknown(format!("{field}[{i}]"), format!("this robot has no session '{n}'")))?;
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
    pool: &Pool,
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
        if s.usable() == 0 {
            let detail = if s.measurements == 0 {
                format!("session '{}' has no measurements", s.name)
            } else {
                format!("session '{}' has no measurements left: all {} are excluded", s.name, s.measurements)
            };
            return Err(AppError::invalid(format!("{field}[{i}]"), detail));
        }
    }
    Ok(sessions)
}

/// Every session of the robot with `purpose` that holds measurements not excluded, in creation
/// order.
pub async fn sessions_with_purpose(
    pool: &Pool,
    robot_id: &str,
    purpose: PurposeSpec,
) -> Result<Vec<SessionRow>, AppError> {
    Ok(records::sessions_of_robot(pool, robot_id)
        .await?
        .into_iter()
        .filter(|s| s.purpose == purpose && s.usable() > 0)
        .collect())
}

/// Which stored measurement each measurement of an assembled cell is: per session (by name), the
/// stored index of each cell index, increasing. Sessions not listed keep their indices.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StoredIndices {
    sessions: Vec<(String, Vec<usize>)>,
}

impl StoredIndices {
    fn of<'a>(&'a self, session: &str) -> Option<&'a [usize]> {
        self.sessions.iter().find(|(n, _)| n == session).map(|(_, v)| v.as_slice())
    }

    /// The stored index of measurement `cell_index` of `session` in the cell.
    pub fn stored(&self, session: &str, cell_index: usize) -> usize {
        self.of(session).and_then(|v| v.get(cell_index).copied()).unwrap_or(cell_index)
    }

    /// The cell index of stored measurement `stored` of `session`; `None` when it is excluded
    /// (not in the cell).
    pub fn cell(&self, session: &str, stored: usize) -> Option<usize> {
        match self.of(session) {
            None => Some(stored),
            Some(v) => v.binary_search(&stored).ok(),
        }
    }
}

/// Every stored measurement of a session, in order, and whether it is excluded.
pub async fn session_measurements(
    pool: &Pool,
    session_id: &str,
) -> Result<Vec<(usize, MeasurementSpec, bool)>, AppError> {
    let rows = records::measurements_with_state(pool, session_id).await?;
    rows.into_iter()
        .map(|(seq, json, excluded)| {
            serde_json::from_str(&json)
                .map(|m| (seq as usize, m, excluded))
                .map_err(|e| AppError::Internal(format!("measurement {seq} of session {session_id}: {e}")))
        })
        .collect()
}

/// A cell file assembled from the store, with where its measurements came from.
#[derive(Clone, Debug)]
pub struct StoredCell {
    pub file: CellFile,
    pub indices: StoredIndices,
    /// Excluded measurements left out, in all.
    pub excluded: usize,
}

/// The cell file of `sessions` of `robot`, in the given order, without the excluded
/// measurements: what the jobs identify, validate and diagnose from. Sessions that use an
/// artefact must all use the same one (a cell has one world frame).
pub async fn cell_file(pool: &Pool, robot: &RobotRow, sessions: &[SessionRow]) -> Result<CellFile, AppError> {
    Ok(stored_cell(pool, robot, sessions, false).await?.file)
}

/// As [`cell_file`], with the stored index of every measurement; `include_excluded` keeps the
/// excluded measurements in (the store's whole content).
pub async fn stored_cell(
    pool: &Pool,
    robot: &RobotRow,
    sessions: &[SessionRow],
    include_excluded: bool,
) -> Result<StoredCell, AppError> {
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
    let mut indices = StoredIndices::default();
    let mut excluded = 0;
    for s in sessions {
        let mut measurements = Vec::new();
        let mut stored = Vec::new();
        for (index, m, out) in session_measurements(pool, &s.id).await? {
            if out && !include_excluded {
                excluded += 1;
                continue;
            }
            measurements.push(m);
            stored.push(index);
        }
        indices.sessions.push((s.name.clone(), stored));
        specs.push(SessionSpec {
            name: s.name.clone(),
            purpose: s.purpose,
            instrument: s.instrument,
            tool: serde_json::from_str::<ToolSpec>(&s.tool_json).map_err(|e| internal("tool", e))?,
            identify_tcp: s.identify_tcp,
            order: s.order,
            target: s.target.clone(),
            measurements,
        });
    }
    Ok(StoredCell { file: CellFile { robot: robot_json, base_guess, artefact, sessions: specs }, indices, excluded })
}

/// The artefact the robot was calibrated on: the one its identification sessions use, when they
/// all use the same one. A validation on sessions without an artefact (a laser tracker's) places
/// its calibration zone (the ball triangle's centroid) with it, as a cell file does.
pub async fn calibration_artefact(pool: &Pool, robot_id: &str) -> Result<Option<ArtefactSpec>, AppError> {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stored_indices_map_both_ways() {
        let idx = StoredIndices { sessions: vec![("a".into(), vec![0, 2, 3, 7])] };
        assert_eq!((idx.stored("a", 1), idx.stored("a", 3)), (2, 7));
        assert_eq!((idx.cell("a", 3), idx.cell("a", 1), idx.cell("a", 7)), (Some(2), None, Some(3)));
        assert_eq!((idx.stored("b", 5), idx.cell("b", 5)), (5, Some(5)), "other sessions keep theirs");
    }
}
