//! Audited correction (migration 0005): measurement exclusions and their history, the audit
//! timeline, parameter-set activations and archiving, and what a session or an artefact is still
//! referenced by before it may be deleted.

use crate::db::AnyExecutor;
use crate::db::{Backend, Pool};

use super::paging::{self, Page};
use super::records::{ArtefactRow, SessionRow};

/// An exclusion of one measurement: open until restored.
#[derive(Clone, Debug, PartialEq, sqlx::FromRow)]
pub struct ExclusionRow {
    pub id: String,
    pub session_id: String,
    pub seq: i64,
    pub reason: String,
    pub excluded_by: Option<String>,
    pub excluded_at: String,
    pub restore_reason: Option<String>,
    pub restored_by: Option<String>,
    pub restored_at: Option<String>,
}

/// The measurement's open exclusion, if it is excluded.
pub async fn open_exclusion(
    db: impl AnyExecutor<'_>,
    session_id: &str,
    seq: i64,
) -> Result<Option<ExclusionRow>, sqlx::Error> {
    sqlx::query_as("SELECT * FROM measurement_exclusions WHERE session_id = $1 AND seq = $2 AND restored_at IS NULL")
        .bind(session_id)
        .bind(seq)
        .fetch_optional(db)
        .await
}

/// Every exclusion a measurement had, oldest first.
pub async fn exclusion_history(
    db: impl AnyExecutor<'_>,
    session_id: &str,
    seq: i64,
) -> Result<Vec<ExclusionRow>, sqlx::Error> {
    sqlx::query_as("SELECT * FROM measurement_exclusions WHERE session_id = $1 AND seq = $2 ORDER BY excluded_at, id")
        .bind(session_id)
        .bind(seq)
        .fetch_all(db)
        .await
}

/// The open exclusions of a session's measurements `first..first + count`, by index.
pub async fn open_exclusions(
    db: impl AnyExecutor<'_>,
    session_id: &str,
    first: i64,
    count: i64,
) -> Result<Vec<ExclusionRow>, sqlx::Error> {
    sqlx::query_as(
        "SELECT * FROM measurement_exclusions WHERE session_id = $1 AND seq >= $2 AND seq < $3 AND restored_at IS NULL \
         ORDER BY seq",
    )
    .bind(session_id)
    .bind(first)
    .bind(first.saturating_add(count))
    .fetch_all(db)
    .await
}

pub async fn insert_exclusion(db: impl AnyExecutor<'_>, e: &ExclusionRow) -> Result<(), sqlx::Error> {
    sqlx::query(
        "INSERT INTO measurement_exclusions (id, session_id, seq, reason, excluded_by, excluded_at) VALUES ($1, $2, $3, $4, $5, $6)",
    )
    .bind(&e.id)
    .bind(&e.session_id)
    .bind(e.seq)
    .bind(&e.reason)
    .bind(&e.excluded_by)
    .bind(&e.excluded_at)
    .execute(db)
    .await?;
    Ok(())
}

/// Close an open exclusion; `false` when it is no longer open.
pub async fn close_exclusion(
    db: impl AnyExecutor<'_>,
    id: &str,
    reason: &str,
    by: Option<&str>,
    at: &str,
) -> Result<bool, sqlx::Error> {
    let r = sqlx::query(
        "UPDATE measurement_exclusions SET restore_reason = $1, restored_by = $2, restored_at = $3 \
         WHERE id = $4 AND restored_at IS NULL",
    )
    .bind(reason)
    .bind(by)
    .bind(at)
    .bind(id)
    .execute(db)
    .await?;
    Ok(r.rows_affected() == 1)
}

/// One correction in the audit timeline.
#[derive(Clone, Debug, PartialEq, sqlx::FromRow)]
pub struct AuditRow {
    pub id: String,
    pub at: String,
    pub actor: Option<String>,
    /// `measurement_excluded`, `measurement_restored`, `session_deleted`, `artefact_deleted`,
    /// `parameter_set_archived`, `parameter_set_unarchived`.
    pub action: String,
    pub robot_id: Option<String>,
    pub subject_id: String,
    pub reason: String,
    pub detail_json: String,
}

pub async fn insert_audit(db: impl AnyExecutor<'_>, a: &AuditRow) -> Result<(), sqlx::Error> {
    sqlx::query(
        "INSERT INTO audit_events (id, at, actor, action, robot_id, subject_id, reason, detail_json) \
         VALUES ($1, $2, $3, $4, $5, $6, $7, $8)",
    )
    .bind(&a.id)
    .bind(&a.at)
    .bind(&a.actor)
    .bind(&a.action)
    .bind(&a.robot_id)
    .bind(&a.subject_id)
    .bind(&a.reason)
    .bind(&a.detail_json)
    .execute(db)
    .await?;
    Ok(())
}

/// Audit events `offset..offset + limit`, newest first, optionally of one robot and/or about one
/// subject.
pub async fn audit_events(
    db: &Pool,
    robot_id: Option<&str>,
    subject_id: Option<&str>,
    offset: i64,
    limit: i64,
) -> Result<Page<AuditRow>, sqlx::Error> {
    let query = sqlx::query_as(
        "SELECT *, COUNT(*) OVER () AS total_rows FROM audit_events \
         WHERE ($1 IS NULL OR robot_id = $1) AND ($2 IS NULL OR subject_id = $2) \
         ORDER BY at DESC, id DESC LIMIT $3 OFFSET $4",
    )
    .bind(robot_id)
    .bind(subject_id);
    paging::fetch(db, query, offset, limit, audit_count(db, robot_id, subject_id)).await
}

pub async fn audit_count(
    db: impl AnyExecutor<'_>,
    robot_id: Option<&str>,
    subject_id: Option<&str>,
) -> Result<i64, sqlx::Error> {
    sqlx::query_scalar(
        "SELECT COUNT(*) FROM audit_events WHERE ($1 IS NULL OR robot_id = $1) AND ($2 IS NULL OR subject_id = $2)",
    )
    .bind(robot_id)
    .bind(subject_id)
    .fetch_one(db)
    .await
}

/// One activation of a parameter set.
#[derive(Clone, Debug, PartialEq, sqlx::FromRow)]
pub struct ActivationRow {
    pub id: String,
    pub robot_id: String,
    pub parameter_set_id: String,
    /// NULL: activated before activations were recorded (migration 0005).
    pub activated_at: Option<String>,
    pub activated_by: Option<String>,
    pub job_id: Option<String>,
}

/// Make `set_id` the robot's active set and record the activation (call inside a transaction
/// when it must go with other writes). `false` when the robot does not exist.
pub async fn activate(
    tx: &mut crate::db::Conn,
    robot_id: &str,
    set_id: &str,
    by: Option<&str>,
    job_id: Option<&str>,
) -> Result<bool, sqlx::Error> {
    if !super::records::set_active_parameter_set(&mut *tx, robot_id, set_id).await? {
        return Ok(false);
    }
    sqlx::query(
        "INSERT INTO parameter_set_activations (id, robot_id, parameter_set_id, activated_at, activated_by, job_id) \
         VALUES ($1, $2, $3, $4, $5, $6)",
    )
    .bind(super::new_id())
    .bind(robot_id)
    .bind(set_id)
    .bind(super::now())
    .bind(by)
    .bind(job_id)
    .execute(&mut *tx)
    .await?;
    Ok(true)
}

/// A robot's activations `offset..offset + limit`, newest first (those of unknown time last).
pub async fn activations(
    db: &Pool,
    robot_id: &str,
    offset: i64,
    limit: i64,
) -> Result<Page<ActivationRow>, sqlx::Error> {
    let query = sqlx::query_as(
        "SELECT *, COUNT(*) OVER () AS total_rows FROM parameter_set_activations WHERE robot_id = $1 \
         ORDER BY COALESCE(activated_at, '') DESC, id DESC LIMIT $2 OFFSET $3",
    )
    .bind(robot_id);
    paging::fetch(db, query, offset, limit, activation_count(db, robot_id)).await
}

pub async fn activation_count(db: impl AnyExecutor<'_>, robot_id: &str) -> Result<i64, sqlx::Error> {
    sqlx::query_scalar("SELECT COUNT(*) FROM parameter_set_activations WHERE robot_id = $1")
        .bind(robot_id)
        .fetch_one(db)
        .await
}

/// A parameter set's activations, oldest first (those of unknown time first).
pub async fn activations_of_set(db: impl AnyExecutor<'_>, set_id: &str) -> Result<Vec<ActivationRow>, sqlx::Error> {
    sqlx::query_as(
        "SELECT * FROM parameter_set_activations WHERE parameter_set_id = $1 ORDER BY COALESCE(activated_at, ''), id",
    )
    .bind(set_id)
    .fetch_all(db)
    .await
}

/// Archive (`Some((at, by, reason))`) or unarchive (`None`) a parameter set.
pub async fn set_archived(
    db: impl AnyExecutor<'_>,
    set_id: &str,
    archived: Option<(&str, Option<&str>, &str)>,
) -> Result<bool, sqlx::Error> {
    let (at, by, reason) = match archived {
        Some((at, by, reason)) => (Some(at), by, Some(reason)),
        None => (None, None, None),
    };
    let r =
        sqlx::query("UPDATE parameter_sets SET archived_at = $1, archived_by = $2, archive_reason = $3 WHERE id = $4")
            .bind(at)
            .bind(by)
            .bind(reason)
            .bind(set_id)
            .execute(db)
            .await?;
    Ok(r.rows_affected() == 1)
}

/// SQLite's text or PostgreSQL's, where their JSON functions differ.
fn pick(pg: bool, sqlite: &'static str, postgres: &'static str) -> &'static str {
    if pg { postgres } else { sqlite }
}

/// What still refers to a session, as sentences for a 409: the robot's parameter sets,
/// validations and diagnoses made from it (they name their sessions), and the jobs queued or
/// running on it (their requests name sessions by id). Finished jobs do not hold a session: their
/// requests stay as they were sent.
pub async fn session_references(db: &mut crate::db::Conn, s: &SessionRow) -> Result<Vec<String>, sqlx::Error> {
    let pg = Backend::of_conn(db) == Backend::Postgres;
    let mut out = Vec::new();
    let sets: Vec<i64> = sqlx::query_scalar(pick(
        pg,
        "SELECT p.version FROM parameter_sets p WHERE p.robot_id = $1 \
             AND EXISTS (SELECT 1 FROM json_each(p.sessions_json) j WHERE j.value = $2) ORDER BY p.version",
        "SELECT p.version FROM parameter_sets p WHERE p.robot_id = $1 \
             AND EXISTS (SELECT 1 FROM jsonb_array_elements_text(p.sessions_json::jsonb) j WHERE j.value = $2) \
             ORDER BY p.version",
    ))
    .bind(&s.robot_id)
    .bind(&s.name)
    .fetch_all(&mut *db)
    .await?;
    out.extend(sets.iter().map(|v| format!("parameter set version {v}")));
    let validations: Vec<String> = sqlx::query_scalar(pick(
        pg,
        "SELECT v.id FROM validations v JOIN parameter_sets p ON p.id = v.parameter_set_id WHERE p.robot_id = $1 \
             AND EXISTS (SELECT 1 FROM json_each(v.sessions_json) j WHERE j.value = $2) ORDER BY v.created_at",
        "SELECT v.id FROM validations v JOIN parameter_sets p ON p.id = v.parameter_set_id WHERE p.robot_id = $1 \
             AND EXISTS (SELECT 1 FROM jsonb_array_elements_text(v.sessions_json::jsonb) j WHERE j.value = $2) \
             ORDER BY v.created_at",
    ))
    .bind(&s.robot_id)
    .bind(&s.name)
    .fetch_all(&mut *db)
    .await?;
    out.extend(validations.iter().map(|v| format!("validation {v}")));
    let diagnoses: Vec<String> = sqlx::query_scalar(pick(
        pg,
        "SELECT d.id FROM diagnoses d JOIN parameter_sets p ON p.id = d.parameter_set_id WHERE p.robot_id = $1 \
             AND (EXISTS (SELECT 1 FROM json_each(d.sessions_json, '$.identification') j WHERE j.value = $2) \
               OR EXISTS (SELECT 1 FROM json_each(d.sessions_json, '$.validation') j WHERE j.value = $2)) \
             ORDER BY d.created_at",
        "SELECT d.id FROM diagnoses d JOIN parameter_sets p ON p.id = d.parameter_set_id WHERE p.robot_id = $1 \
             AND (EXISTS (SELECT 1 FROM jsonb_array_elements_text(d.sessions_json::jsonb -> 'identification') j \
                          WHERE j.value = $2) \
               OR EXISTS (SELECT 1 FROM jsonb_array_elements_text(d.sessions_json::jsonb -> 'validation') j \
                          WHERE j.value = $2)) \
             ORDER BY d.created_at",
    ))
    .bind(&s.robot_id)
    .bind(&s.name)
    .fetch_all(&mut *db)
    .await?;
    out.extend(diagnoses.iter().map(|d| format!("diagnosis {d}")));
    let jobs: Vec<(String, String, String)> = sqlx::query_as(pick(
        pg,
        "SELECT id, kind, state FROM jobs WHERE robot_id = $1 AND state IN ('queued', 'running') \
             AND (EXISTS (SELECT 1 FROM json_each(request_json, '$.sessions') j WHERE j.value IN ($2, $3)) \
               OR EXISTS (SELECT 1 FROM json_each(request_json, '$.identification') j WHERE j.value IN ($2, $3)) \
               OR EXISTS (SELECT 1 FROM json_each(request_json, '$.validation') j WHERE j.value IN ($2, $3))) \
             ORDER BY created_at",
        // `jsonb_path_query` with lax arrays: a key that is absent (or not an array) yields
        // no element, as SQLite's `json_each` of a missing path does.
        "SELECT id, kind, state FROM jobs WHERE robot_id = $1 AND state IN ('queued', 'running') \
             AND EXISTS (SELECT 1 FROM jsonb_path_query(request_json::jsonb, \
                           'lax $.sessions[*] ? (@.type() == \"string\")') j \
                         WHERE j #>> '{}' IN ($2, $3) \
                         UNION ALL SELECT 1 FROM jsonb_path_query(request_json::jsonb, \
                           'lax $.identification[*] ? (@.type() == \"string\")') j \
                         WHERE j #>> '{}' IN ($2, $3) \
                         UNION ALL SELECT 1 FROM jsonb_path_query(request_json::jsonb, \
                           'lax $.validation[*] ? (@.type() == \"string\")') j \
                         WHERE j #>> '{}' IN ($2, $3)) \
             ORDER BY created_at",
    ))
    .bind(&s.robot_id)
    .bind(&s.id)
    .bind(&s.name)
    .fetch_all(&mut *db)
    .await?;
    out.extend(jobs.iter().map(|(id, kind, state)| format!("{kind} job {id} ({state})")));
    // ISO 9283 evaluations of it, and evaluation jobs queued or running on it (their request
    // names one session, by id).
    let evaluations = super::iso9283::of_session(&mut *db, &s.id).await?;
    out.extend(evaluations.iter().map(|e| format!("ISO 9283 evaluation {e}")));
    let iso_jobs: Vec<(String, String)> = sqlx::query_as(pick(
        pg,
        "SELECT id, state FROM jobs WHERE robot_id = $1 AND kind = 'iso9283' AND state IN ('queued', 'running') \
             AND json_extract(request_json, '$.session') = $2 ORDER BY created_at",
        "SELECT id, state FROM jobs WHERE robot_id = $1 AND kind = 'iso9283' AND state IN ('queued', 'running') \
             AND request_json::jsonb ->> 'session' = $2 ORDER BY created_at",
    ))
    .bind(&s.robot_id)
    .bind(&s.id)
    .fetch_all(&mut *db)
    .await?;
    out.extend(iso_jobs.iter().map(|(id, state)| format!("iso9283 job {id} ({state})")));
    Ok(out)
}

/// Delete a session with its exclusions, measurements and batches. Call inside the transaction
/// that checked [`session_references`] and writes the audit event.
pub async fn delete_session(tx: &mut crate::db::Conn, session_id: &str) -> Result<bool, sqlx::Error> {
    for sql in [
        "DELETE FROM measurement_exclusions WHERE session_id = $1",
        "DELETE FROM measurements WHERE session_id = $1",
        "DELETE FROM batches WHERE session_id = $1",
    ] {
        sqlx::query(sql).bind(session_id).execute(&mut *tx).await?;
    }
    let r = sqlx::query("DELETE FROM sessions WHERE id = $1").bind(session_id).execute(&mut *tx).await?;
    Ok(r.rows_affected() == 1)
}

/// What still uses an artefact, as sentences for a 409: the sessions measured on it (robot and
/// session name), the pose plans made for it, the pose-plan jobs queued or running on it.
pub async fn artefact_references(db: &mut crate::db::Conn, a: &ArtefactRow) -> Result<Vec<String>, sqlx::Error> {
    let pg = Backend::of_conn(db) == Backend::Postgres;
    let mut out = Vec::new();
    let sessions: Vec<(String, String)> = sqlx::query_as(
        "SELECT r.name, s.name FROM sessions s JOIN robots r ON r.id = s.robot_id WHERE s.artefact_id = $1 \
         ORDER BY s.created_at",
    )
    .bind(&a.id)
    .fetch_all(&mut *db)
    .await?;
    out.extend(sessions.iter().map(|(r, s)| format!("session '{s}' of robot '{r}'")));
    let plans: Vec<String> = sqlx::query_scalar(pick(
        pg,
        "SELECT id FROM pose_plans WHERE json_extract(request_json, '$.artefact_id') = $1 ORDER BY created_at",
        "SELECT id FROM pose_plans WHERE request_json::jsonb ->> 'artefact_id' = $1 ORDER BY created_at",
    ))
    .bind(&a.id)
    .fetch_all(&mut *db)
    .await?;
    out.extend(plans.iter().map(|p| format!("pose plan {p}")));
    let jobs: Vec<(String, String)> = sqlx::query_as(pick(
        pg,
        "SELECT id, state FROM jobs WHERE kind = 'pose_plan' AND state IN ('queued', 'running') \
             AND json_extract(request_json, '$.artefact_id') = $1 ORDER BY created_at",
        "SELECT id, state FROM jobs WHERE kind = 'pose_plan' AND state IN ('queued', 'running') \
             AND request_json::jsonb ->> 'artefact_id' = $1 ORDER BY created_at",
    ))
    .bind(&a.id)
    .fetch_all(&mut *db)
    .await?;
    out.extend(jobs.iter().map(|(id, state)| format!("pose_plan job {id} ({state})")));
    Ok(out)
}

pub async fn delete_artefact(db: impl AnyExecutor<'_>, id: &str) -> Result<bool, sqlx::Error> {
    let r = sqlx::query("DELETE FROM artefacts WHERE id = $1").bind(id).execute(db).await?;
    Ok(r.rows_affected() == 1)
}
