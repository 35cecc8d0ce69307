//! Robots, artefacts, sessions, measurements, parameter sets, validations, diagnoses and pose
//! plans.
//! Functions take any SQLite executor: the pool for single statements, `&mut *tx` inside a
//! transaction. A list's page ([`Page`]) takes the pool: past the list's end it counts the list
//! with a second statement.

use crate::db::AnyExecutor;
use crate::db::{Backend, Pool};

use super::paging::{self, Page};
use crate::domain::cell::{InstrumentSpec, OrderSpec, PurposeSpec};

/// A robot row.
#[derive(Clone, Debug, PartialEq, sqlx::FromRow)]
pub struct RobotRow {
    pub id: String,
    pub name: String,
    pub model_json: String,
    pub base_guess_json: Option<String>,
    pub active_parameter_set_id: Option<String>,
    pub created_at: String,
}

pub async fn insert_robot(db: impl AnyExecutor<'_>, r: &RobotRow) -> Result<(), sqlx::Error> {
    sqlx::query(
        "INSERT INTO robots (id, name, model_json, base_guess_json, active_parameter_set_id, created_at) \
         VALUES ($1, $2, $3, $4, $5, $6)",
    )
    .bind(&r.id)
    .bind(&r.name)
    .bind(&r.model_json)
    .bind(&r.base_guess_json)
    .bind(&r.active_parameter_set_id)
    .bind(&r.created_at)
    .execute(db)
    .await?;
    Ok(())
}

pub async fn robot(db: impl AnyExecutor<'_>, id: &str) -> Result<Option<RobotRow>, sqlx::Error> {
    sqlx::query_as("SELECT * FROM robots WHERE id = $1").bind(id).fetch_optional(db).await
}

/// Robots `offset..offset + limit`, oldest first.
pub async fn robots(db: &Pool, offset: i64, limit: i64) -> Result<Page<RobotRow>, sqlx::Error> {
    let query = sqlx::query_as(
        "SELECT *, COUNT(*) OVER () AS total_rows FROM robots ORDER BY created_at, id LIMIT $1 OFFSET $2",
    );
    paging::fetch(db, query, offset, limit, robot_count(db)).await
}

pub async fn robot_count(db: impl AnyExecutor<'_>) -> Result<i64, sqlx::Error> {
    sqlx::query_scalar("SELECT COUNT(*) FROM robots").fetch_one(db).await
}

pub async fn set_active_parameter_set(
    db: impl AnyExecutor<'_>,
    robot_id: &str,
    set_id: &str,
) -> Result<bool, sqlx::Error> {
    let r = sqlx::query("UPDATE robots SET active_parameter_set_id = $1 WHERE id = $2")
        .bind(set_id)
        .bind(robot_id)
        .execute(db)
        .await?;
    Ok(r.rows_affected() == 1)
}

/// An artefact row.
#[derive(Clone, Debug, PartialEq, sqlx::FromRow)]
pub struct ArtefactRow {
    pub id: String,
    pub name: String,
    pub spec_json: String,
    pub created_at: String,
}

pub async fn insert_artefact(db: impl AnyExecutor<'_>, a: &ArtefactRow) -> Result<(), sqlx::Error> {
    sqlx::query("INSERT INTO artefacts (id, name, spec_json, created_at) VALUES ($1, $2, $3, $4)")
        .bind(&a.id)
        .bind(&a.name)
        .bind(&a.spec_json)
        .bind(&a.created_at)
        .execute(db)
        .await?;
    Ok(())
}

pub async fn artefact(db: impl AnyExecutor<'_>, id: &str) -> Result<Option<ArtefactRow>, sqlx::Error> {
    sqlx::query_as("SELECT * FROM artefacts WHERE id = $1").bind(id).fetch_optional(db).await
}

/// Artefacts `offset..offset + limit`, oldest first.
pub async fn artefacts(db: &Pool, offset: i64, limit: i64) -> Result<Page<ArtefactRow>, sqlx::Error> {
    let query = sqlx::query_as(
        "SELECT *, COUNT(*) OVER () AS total_rows FROM artefacts ORDER BY created_at, id LIMIT $1 OFFSET $2",
    );
    paging::fetch(db, query, offset, limit, artefact_count(db)).await
}

pub async fn artefact_count(db: impl AnyExecutor<'_>) -> Result<i64, sqlx::Error> {
    sqlx::query_scalar("SELECT COUNT(*) FROM artefacts").fetch_one(db).await
}

/// A session row with its measurement count.
#[derive(Clone, Debug, PartialEq, sqlx::FromRow)]
pub struct SessionRow {
    pub id: String,
    pub robot_id: String,
    pub name: String,
    #[sqlx(try_from = "String")]
    pub purpose: PurposeSpec,
    #[sqlx(try_from = "String")]
    pub instrument: InstrumentSpec,
    pub tool_json: String,
    #[sqlx(try_from = "crate::db::types::Flag")]
    pub identify_tcp: bool,
    pub artefact_id: Option<String>,
    pub created_at: String,
    /// Whether the measurements are listed in measuring order (column `measuring_order`, 0003).
    #[sqlx(rename = "measuring_order")]
    #[sqlx(try_from = "String")]
    pub order: OrderSpec,
    /// The physical target measured (column `target`, 0004): sessions naming one share a TCP.
    pub target: Option<String>,
    /// Measurements stored (not a column: counted on read).
    #[sqlx(default)]
    pub measurements: i64,
    /// Of them, excluded (open exclusions, 0005; counted on read): the jobs leave them out.
    #[sqlx(default)]
    pub excluded: i64,
}

impl SessionRow {
    /// Measurements the jobs use: stored and not excluded.
    pub fn usable(&self) -> i64 {
        self.measurements - self.excluded
    }
}

const SESSION_COLUMNS: &str = "s.id, s.robot_id, s.name, s.purpose, s.instrument, s.tool_json, s.identify_tcp, \
     s.artefact_id, s.created_at, s.measuring_order, s.target, (SELECT COUNT(*) FROM measurements m WHERE m.session_id = s.id) AS measurements, \
     (SELECT COUNT(*) FROM measurement_exclusions e WHERE e.session_id = s.id AND e.restored_at IS NULL) AS excluded";

pub async fn insert_session(db: impl AnyExecutor<'_>, s: &SessionRow) -> Result<(), sqlx::Error> {
    sqlx::query(
        "INSERT INTO sessions (id, robot_id, name, purpose, instrument, tool_json, identify_tcp, artefact_id, created_at, \
         measuring_order, target) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11)",
    )
    .bind(&s.id)
    .bind(&s.robot_id)
    .bind(&s.name)
    .bind(s.purpose.as_str())
    .bind(s.instrument.as_str())
    .bind(&s.tool_json)
    .bind(s.identify_tcp)
    .bind(&s.artefact_id)
    .bind(&s.created_at)
    .bind(s.order.as_str())
    .bind(&s.target)
    .execute(db)
    .await?;
    Ok(())
}

pub async fn session(db: impl AnyExecutor<'_>, id: &str) -> Result<Option<SessionRow>, sqlx::Error> {
    sqlx::query_as(sqlx::AssertSqlSafe(format!("SELECT {SESSION_COLUMNS} FROM sessions s WHERE s.id = $1")))
        .bind(id)
        .fetch_optional(db)
        .await
}

/// A robot's session by id or by name.
pub async fn session_of_robot(
    db: impl AnyExecutor<'_>,
    robot_id: &str,
    id_or_name: &str,
) -> Result<Option<SessionRow>, sqlx::Error> {
    sqlx::query_as(sqlx::AssertSqlSafe(format!(
        "SELECT {SESSION_COLUMNS} FROM sessions s WHERE s.robot_id = $1 AND (s.id = $2 OR s.name = $3)"
    )))
    .bind(robot_id)
    .bind(id_or_name)
    .bind(id_or_name)
    .fetch_optional(db)
    .await
}

pub async fn sessions_of_robot(db: impl AnyExecutor<'_>, robot_id: &str) -> Result<Vec<SessionRow>, sqlx::Error> {
    sqlx::query_as(sqlx::AssertSqlSafe(format!(
        "SELECT {SESSION_COLUMNS} FROM sessions s WHERE s.robot_id = $1 ORDER BY s.created_at, s.id"
    )))
    .bind(robot_id)
    .fetch_all(db)
    .await
}

/// A robot's sessions `offset..offset + limit`, oldest first.
pub async fn sessions_page(
    db: &Pool,
    robot_id: &str,
    offset: i64,
    limit: i64,
) -> Result<Page<SessionRow>, sqlx::Error> {
    let query = sqlx::query_as(sqlx::AssertSqlSafe(format!(
        "SELECT {SESSION_COLUMNS}, COUNT(*) OVER () AS total_rows FROM sessions s WHERE s.robot_id = $1 \
         ORDER BY s.created_at, s.id LIMIT $2 OFFSET $3"
    )))
    .bind(robot_id);
    paging::fetch(db, query, offset, limit, session_count(db, robot_id)).await
}

pub async fn session_count(db: impl AnyExecutor<'_>, robot_id: &str) -> Result<i64, sqlx::Error> {
    sqlx::query_scalar("SELECT COUNT(*) FROM sessions WHERE robot_id = $1").bind(robot_id).fetch_one(db).await
}

/// A stored batch of measurements (for idempotent replays and duplicate checks).
#[derive(Clone, Debug, PartialEq, sqlx::FromRow)]
pub struct BatchRow {
    pub id: String,
    pub session_id: String,
    pub idempotency_key: Option<String>,
    pub request_hash: String,
    pub first_seq: i64,
    pub count: i64,
    pub created_at: String,
    /// SHA-256 of the batch's measurements as stored (0005); NULL for batches stored before.
    pub content_hash: Option<String>,
}

/// SHA-256 (hex) of a batch's measurements as stored: each spec JSON followed by a newline.
pub fn content_hash(specs_json: &[String]) -> String {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    for s in specs_json {
        h.update(s.as_bytes());
        h.update(b"\n");
    }
    h.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

/// The first batch of a session holding exactly these measurements (`specs_json` as stored,
/// hashed to `hash`): by its content hash, or — for batches stored before 0005 — by hashing
/// their rows.
pub async fn identical_batch(
    tx: &mut crate::db::Conn,
    session_id: &str,
    hash: &str,
    count: i64,
) -> Result<Option<BatchRow>, sqlx::Error> {
    let candidates: Vec<BatchRow> = sqlx::query_as(
        "SELECT * FROM batches WHERE session_id = $1 AND (content_hash = $2 OR (content_hash IS NULL AND count = $3)) \
         ORDER BY first_seq",
    )
    .bind(session_id)
    .bind(hash)
    .bind(count)
    .fetch_all(&mut *tx)
    .await?;
    for b in candidates {
        if b.content_hash.as_deref() == Some(hash) {
            return Ok(Some(b));
        }
        let rows: Vec<String> = sqlx::query_scalar(
            "SELECT spec_json FROM measurements WHERE session_id = $1 AND batch_id = $2 ORDER BY seq",
        )
        .bind(session_id)
        .bind(&b.id)
        .fetch_all(&mut *tx)
        .await?;
        if content_hash(&rows) == hash {
            return Ok(Some(b));
        }
    }
    Ok(None)
}

pub async fn batch_by_key(
    db: impl AnyExecutor<'_>,
    session_id: &str,
    key: &str,
) -> Result<Option<BatchRow>, sqlx::Error> {
    sqlx::query_as("SELECT * FROM batches WHERE session_id = $1 AND idempotency_key = $2")
        .bind(session_id)
        .bind(key)
        .fetch_optional(db)
        .await
}

pub async fn insert_batch(db: impl AnyExecutor<'_>, b: &BatchRow) -> Result<(), sqlx::Error> {
    sqlx::query(
        "INSERT INTO batches (id, session_id, idempotency_key, request_hash, first_seq, count, created_at, content_hash) \
         VALUES ($1, $2, $3, $4, $5, $6, $7, $8)",
    )
    .bind(&b.id)
    .bind(&b.session_id)
    .bind(&b.idempotency_key)
    .bind(&b.request_hash)
    .bind(b.first_seq)
    .bind(b.count)
    .bind(&b.created_at)
    .bind(&b.content_hash)
    .execute(db)
    .await?;
    Ok(())
}

/// Measurements stored in a session.
pub async fn measurement_count(db: impl AnyExecutor<'_>, session_id: &str) -> Result<i64, sqlx::Error> {
    sqlx::query_scalar("SELECT COUNT(*) FROM measurements WHERE session_id = $1").bind(session_id).fetch_one(db).await
}

/// Rows per multi-row INSERT: 4 bound values each, well under SQLite's 32,766 variables, and
/// large enough that a 10,000-row batch is a handful of statements instead of 10,000 round trips
/// to the connection's worker thread.
const MEASUREMENT_ROWS_PER_STATEMENT: usize = 1000;

/// Append the measurements of one batch (their spec JSON, in order) at `first_seq…`. Call inside
/// the batch's transaction: a failure part-way leaves nothing once the transaction is dropped.
pub async fn insert_measurements(
    tx: &mut crate::db::Conn,
    session_id: &str,
    first_seq: i64,
    batch_id: &str,
    specs_json: &[String],
) -> Result<(), sqlx::Error> {
    for (c, chunk) in specs_json.chunks(MEASUREMENT_ROWS_PER_STATEMENT).enumerate() {
        let first = first_seq + (c * MEASUREMENT_ROWS_PER_STATEMENT) as i64;
        // PostgreSQL needs numbered placeholders. SQLite reads them too, but as named ones: its
        // parser looks each new name up in a list of the names before it, so 4,000 of them cost
        // O(n²) — measured, a 10,000-row upload took 350 ms instead of 110. Plain `?` it numbers
        // as it goes.
        let numbered = crate::db::Backend::of_conn(tx) == crate::db::Backend::Postgres;
        let mut sql = String::from("INSERT INTO measurements (session_id, seq, batch_id, spec_json) VALUES ");
        for i in 0..chunk.len() {
            if i > 0 {
                sql.push_str(", ");
            }
            if numbered {
                let b = 4 * i;
                sql.push_str(&format!("(${}, ${}, ${}, ${})", b + 1, b + 2, b + 3, b + 4));
            } else {
                sql.push_str("(?, ?, ?, ?)");
            }
        }
        let mut q = sqlx::query(sqlx::AssertSqlSafe(sql));
        for (i, spec) in chunk.iter().enumerate() {
            q = q.bind(session_id).bind(first + i as i64).bind(batch_id).bind(spec.as_str());
        }
        q.execute(&mut *tx).await?;
    }
    Ok(())
}

/// Measurements `offset..offset + limit` of a session, in order: (index, spec JSON).
pub async fn measurements(
    db: impl AnyExecutor<'_>,
    session_id: &str,
    offset: i64,
    limit: i64,
) -> Result<Vec<(i64, String)>, sqlx::Error> {
    sqlx::query_as("SELECT seq, spec_json FROM measurements WHERE session_id = $1 AND seq >= $2 ORDER BY seq LIMIT $3")
        .bind(session_id)
        .bind(offset)
        .bind(limit)
        .fetch_all(db)
        .await
}

/// Every stored measurement of a session in order, with whether it is excluded: (index, spec
/// JSON, excluded). One statement, so the measurements and their exclusions are read together.
pub async fn measurements_with_state(
    db: impl AnyExecutor<'_>,
    session_id: &str,
) -> Result<Vec<(i64, String, bool)>, sqlx::Error> {
    sqlx::query_as(
        "SELECT m.seq, m.spec_json, EXISTS (SELECT 1 FROM measurement_exclusions e \
             WHERE e.session_id = m.session_id AND e.seq = m.seq AND e.restored_at IS NULL) \
         FROM measurements m WHERE m.session_id = $1 ORDER BY m.seq",
    )
    .bind(session_id)
    .fetch_all(db)
    .await
    .map(|rows: Vec<(i64, String, super::types::Flag)>| rows.into_iter().map(|(s, j, f)| (s, j, f.0)).collect())
}

/// A parameter-set row.
#[derive(Clone, Debug, PartialEq, sqlx::FromRow)]
pub struct ParameterSetRow {
    pub id: String,
    pub robot_id: String,
    pub version: i64,
    pub doc_json: String,
    pub sessions_json: String,
    pub job_id: Option<String>,
    pub created_at: String,
    /// When, by whom and why it was archived (0005): hidden from the history, never activated.
    pub archived_at: Option<String>,
    pub archived_by: Option<String>,
    pub archive_reason: Option<String>,
}

/// Insert a new version of a robot's parameter set (the next version number is taken inside the
/// caller's transaction).
pub async fn insert_parameter_set(
    tx: &mut crate::db::Conn,
    robot_id: &str,
    doc_json: &str,
    sessions_json: &str,
    job_id: Option<&str>,
) -> Result<ParameterSetRow, sqlx::Error> {
    let version: i64 =
        sqlx::query_scalar("SELECT COALESCE(MAX(version), 0) + 1 FROM parameter_sets WHERE robot_id = $1")
            .bind(robot_id)
            .fetch_one(&mut *tx)
            .await?;
    let row = ParameterSetRow {
        id: super::new_id(),
        robot_id: robot_id.to_string(),
        version,
        doc_json: doc_json.to_string(),
        sessions_json: sessions_json.to_string(),
        job_id: job_id.map(str::to_string),
        created_at: super::now(),
        archived_at: None,
        archived_by: None,
        archive_reason: None,
    };
    sqlx::query(
        "INSERT INTO parameter_sets (id, robot_id, version, doc_json, sessions_json, job_id, created_at) \
         VALUES ($1, $2, $3, $4, $5, $6, $7)",
    )
    .bind(&row.id)
    .bind(&row.robot_id)
    .bind(row.version)
    .bind(&row.doc_json)
    .bind(&row.sessions_json)
    .bind(&row.job_id)
    .bind(&row.created_at)
    .execute(&mut *tx)
    .await?;
    Ok(row)
}

pub async fn parameter_set(db: impl AnyExecutor<'_>, id: &str) -> Result<Option<ParameterSetRow>, sqlx::Error> {
    sqlx::query_as("SELECT * FROM parameter_sets WHERE id = $1").bind(id).fetch_optional(db).await
}

/// A robot's parameter sets `offset..offset + limit`, newest version first; archived ones only
/// when asked for.
pub async fn parameter_sets_of_robot(
    db: &Pool,
    robot_id: &str,
    include_archived: bool,
    offset: i64,
    limit: i64,
) -> Result<Page<ParameterSetRow>, sqlx::Error> {
    let query = sqlx::query_as(
        "SELECT *, COUNT(*) OVER () AS total_rows FROM parameter_sets \
         WHERE robot_id = $1 AND ($2 OR archived_at IS NULL) \
         ORDER BY version DESC LIMIT $3 OFFSET $4",
    )
    .bind(robot_id)
    .bind(include_archived);
    paging::fetch(db, query, offset, limit, parameter_set_count(db, robot_id, include_archived)).await
}

pub async fn parameter_set_count(
    db: impl AnyExecutor<'_>,
    robot_id: &str,
    include_archived: bool,
) -> Result<i64, sqlx::Error> {
    sqlx::query_scalar("SELECT COUNT(*) FROM parameter_sets WHERE robot_id = $1 AND ($2 OR archived_at IS NULL)")
        .bind(robot_id)
        .bind(include_archived)
        .fetch_one(db)
        .await
}

/// A robot's parameter sets created in `[from, to)` (store time text; `None`: open), oldest first
/// (the history's time order), `offset..offset + limit`; archived ones only when asked for.
#[allow(clippy::too_many_arguments)]
pub async fn parameter_sets_in_range(
    db: impl AnyExecutor<'_>,
    robot_id: &str,
    include_archived: bool,
    from: Option<&str>,
    to: Option<&str>,
    offset: i64,
    limit: i64,
) -> Result<Vec<ParameterSetRow>, sqlx::Error> {
    sqlx::query_as(
        "SELECT * FROM parameter_sets WHERE robot_id = $1 AND ($2 OR archived_at IS NULL) \
         AND ($3 IS NULL OR created_at >= $3) AND ($4 IS NULL OR created_at < $4) \
         ORDER BY created_at, version LIMIT $5 OFFSET $6",
    )
    .bind(robot_id)
    .bind(include_archived)
    .bind(from)
    .bind(to)
    .bind(limit)
    .bind(offset)
    .fetch_all(db)
    .await
}

/// How many sets [`parameter_sets_in_range`] pages through.
pub async fn parameter_set_count_in_range(
    db: impl AnyExecutor<'_>,
    robot_id: &str,
    include_archived: bool,
    from: Option<&str>,
    to: Option<&str>,
) -> Result<i64, sqlx::Error> {
    sqlx::query_scalar(
        "SELECT COUNT(*) FROM parameter_sets WHERE robot_id = $1 AND ($2 OR archived_at IS NULL) \
         AND ($3 IS NULL OR created_at >= $3) AND ($4 IS NULL OR created_at < $4)",
    )
    .bind(robot_id)
    .bind(include_archived)
    .bind(from)
    .bind(to)
    .fetch_one(db)
    .await
}

/// A validation row.
#[derive(Clone, Debug, PartialEq, sqlx::FromRow)]
pub struct ValidationRow {
    pub id: String,
    pub parameter_set_id: String,
    pub sessions_json: String,
    pub report_json: String,
    pub job_id: Option<String>,
    pub created_at: String,
}

pub async fn insert_validation(db: impl AnyExecutor<'_>, v: &ValidationRow) -> Result<(), sqlx::Error> {
    sqlx::query(
        "INSERT INTO validations (id, parameter_set_id, sessions_json, report_json, job_id, created_at) \
         VALUES ($1, $2, $3, $4, $5, $6)",
    )
    .bind(&v.id)
    .bind(&v.parameter_set_id)
    .bind(&v.sessions_json)
    .bind(&v.report_json)
    .bind(&v.job_id)
    .bind(&v.created_at)
    .execute(db)
    .await?;
    Ok(())
}

pub async fn validation(db: impl AnyExecutor<'_>, id: &str) -> Result<Option<ValidationRow>, sqlx::Error> {
    sqlx::query_as("SELECT * FROM validations WHERE id = $1").bind(id).fetch_optional(db).await
}

/// The latest held-out validation of a set — one that validates at least one validation session
/// and none of `fit_sessions`, the sessions the set was fitted on (the rule of
/// `validate::report::is_held_out`, stated here in SQL so old reports are judged as new ones) —
/// read from the stored report without parsing its residuals.
pub async fn latest_held_out_validation(
    db: &Pool,
    set_id: &str,
    fit_sessions: &[String],
) -> Result<Option<HeldOutValidation>, sqlx::Error> {
    let sql = match Backend::of(db) {
        Backend::Sqlite => {
            "SELECT id, json_extract(report_json, '$.mean_mm') AS mean_mm, \
             json_extract(report_json, '$.nominal.mean_mm') AS nominal_mean_mm, \
             json_extract(report_json, '$.validated_envelope') AS envelope, \
             json_extract(report_json, '$.uncertainty') AS uncertainty \
             FROM validations WHERE parameter_set_id = $1 \
             AND EXISTS (SELECT 1 FROM json_each(report_json, '$.purposes') WHERE value = 'validation') \
             AND NOT EXISTS (SELECT 1 FROM json_each(sessions_json) AS v \
                             WHERE v.value IN (SELECT value FROM json_each($2))) \
             ORDER BY created_at DESC, id DESC LIMIT 1"
        }
        // The numbers read back as their JSON text cast to float8 (correctly rounded, as serde
        // reads them); the objects as JSON text (parsed by the caller).
        Backend::Postgres => {
            "SELECT id, (report_json::jsonb ->> 'mean_mm')::float8 AS mean_mm, \
             (report_json::jsonb #>> '{nominal,mean_mm}')::float8 AS nominal_mean_mm, \
             (report_json::jsonb -> 'validated_envelope')::text AS envelope, \
             (report_json::jsonb -> 'uncertainty')::text AS uncertainty \
             FROM validations WHERE parameter_set_id = $1 \
             AND EXISTS (SELECT 1 FROM jsonb_array_elements_text(report_json::jsonb -> 'purposes') AS p \
                         WHERE p.value = 'validation') \
             AND NOT EXISTS (SELECT 1 FROM jsonb_array_elements_text(sessions_json::jsonb) AS v \
                             WHERE v.value IN (SELECT f.value FROM jsonb_array_elements_text($2::jsonb) AS f)) \
             ORDER BY created_at DESC, id DESC LIMIT 1"
        }
    };
    sqlx::query_as(sql)
        .bind(set_id)
        .bind(serde_json::to_string(fit_sessions).expect("strings serialise"))
        .fetch_optional(db)
        .await
}

/// What compensation reads of a set's latest held-out validation.
#[derive(Clone, Debug, PartialEq, sqlx::FromRow)]
pub struct HeldOutValidation {
    pub id: String,
    /// The calibrated and nominal models' mean errors, mm.
    pub mean_mm: f64,
    pub nominal_mean_mm: f64,
    /// The validated envelope, JSON (absent in reports without one).
    pub envelope: Option<String>,
    /// The uncertainty model the validation measured, JSON (absent in older reports).
    pub uncertainty: Option<String>,
}

/// A parameter set's validations, newest first.
pub async fn validations_of_set(db: impl AnyExecutor<'_>, set_id: &str) -> Result<Vec<ValidationRow>, sqlx::Error> {
    sqlx::query_as("SELECT * FROM validations WHERE parameter_set_id = $1 ORDER BY created_at DESC, id DESC")
        .bind(set_id)
        .fetch_all(db)
        .await
}

/// The validations of several sets (a history page), newest first within each: one query, the
/// ids bound as one JSON array.
pub async fn validations_of_sets(db: &Pool, set_ids: &[&str]) -> Result<Vec<ValidationRow>, sqlx::Error> {
    if set_ids.is_empty() {
        return Ok(Vec::new());
    }
    let sql = match Backend::of(db) {
        Backend::Sqlite => {
            "SELECT * FROM validations WHERE parameter_set_id IN (SELECT value FROM json_each($1)) \
             ORDER BY created_at DESC, id DESC"
        }
        Backend::Postgres => {
            "SELECT * FROM validations WHERE parameter_set_id IN \
             (SELECT value FROM jsonb_array_elements_text($1::jsonb)) ORDER BY created_at DESC, id DESC"
        }
    };
    sqlx::query_as(sql).bind(serde_json::to_string(set_ids).expect("strings serialise")).fetch_all(db).await
}

/// A diagnosis row.
#[derive(Clone, Debug, PartialEq, sqlx::FromRow)]
pub struct DiagnosisRow {
    pub id: String,
    pub parameter_set_id: String,
    pub request_json: String,
    pub sessions_json: String,
    pub report_json: String,
    pub accepted_doc_json: Option<String>,
    pub accepted_parameter_set_id: Option<String>,
    pub job_id: Option<String>,
    pub created_at: String,
}

pub async fn insert_diagnosis(db: impl AnyExecutor<'_>, d: &DiagnosisRow) -> Result<(), sqlx::Error> {
    sqlx::query(
        "INSERT INTO diagnoses (id, parameter_set_id, request_json, sessions_json, report_json, accepted_doc_json, \
             accepted_parameter_set_id, job_id, created_at) \
         VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9)",
    )
    .bind(&d.id)
    .bind(&d.parameter_set_id)
    .bind(&d.request_json)
    .bind(&d.sessions_json)
    .bind(&d.report_json)
    .bind(&d.accepted_doc_json)
    .bind(&d.accepted_parameter_set_id)
    .bind(&d.job_id)
    .bind(&d.created_at)
    .execute(db)
    .await?;
    Ok(())
}

pub async fn diagnosis(db: impl AnyExecutor<'_>, id: &str) -> Result<Option<DiagnosisRow>, sqlx::Error> {
    sqlx::query_as("SELECT * FROM diagnoses WHERE id = $1").bind(id).fetch_optional(db).await
}

/// A parameter set's diagnoses `offset..offset + limit`, newest first.
pub async fn diagnoses_of_set(
    db: &Pool,
    set_id: &str,
    offset: i64,
    limit: i64,
) -> Result<Page<DiagnosisRow>, sqlx::Error> {
    let query = sqlx::query_as(
        "SELECT *, COUNT(*) OVER () AS total_rows FROM diagnoses WHERE parameter_set_id = $1 \
         ORDER BY created_at DESC, id DESC LIMIT $2 OFFSET $3",
    )
    .bind(set_id);
    paging::fetch(db, query, offset, limit, diagnosis_count(db, set_id)).await
}

pub async fn diagnosis_count(db: impl AnyExecutor<'_>, set_id: &str) -> Result<i64, sqlx::Error> {
    sqlx::query_scalar("SELECT COUNT(*) FROM diagnoses WHERE parameter_set_id = $1").bind(set_id).fetch_one(db).await
}

/// Record the parameter set accepting a diagnosis created; `false` when it already has one (or
/// does not exist). Call inside the transaction that inserts the set.
pub async fn set_diagnosis_accepted(
    db: impl AnyExecutor<'_>,
    diagnosis_id: &str,
    set_id: &str,
) -> Result<bool, sqlx::Error> {
    let r = sqlx::query(
        "UPDATE diagnoses SET accepted_parameter_set_id = $1 WHERE id = $2 AND accepted_parameter_set_id IS NULL",
    )
    .bind(set_id)
    .bind(diagnosis_id)
    .execute(db)
    .await?;
    Ok(r.rows_affected() == 1)
}

/// A pose-plan row.
#[derive(Clone, Debug, PartialEq, sqlx::FromRow)]
pub struct PosePlanRow {
    pub id: String,
    pub robot_id: String,
    pub request_json: String,
    pub result_json: String,
    pub job_id: Option<String>,
    pub created_at: String,
}

pub async fn insert_pose_plan(db: impl AnyExecutor<'_>, p: &PosePlanRow) -> Result<(), sqlx::Error> {
    sqlx::query(
        "INSERT INTO pose_plans (id, robot_id, request_json, result_json, job_id, created_at) VALUES ($1, $2, $3, $4, $5, $6)",
    )
    .bind(&p.id)
    .bind(&p.robot_id)
    .bind(&p.request_json)
    .bind(&p.result_json)
    .bind(&p.job_id)
    .bind(&p.created_at)
    .execute(db)
    .await?;
    Ok(())
}

pub async fn pose_plan(db: impl AnyExecutor<'_>, id: &str) -> Result<Option<PosePlanRow>, sqlx::Error> {
    sqlx::query_as("SELECT * FROM pose_plans WHERE id = $1").bind(id).fetch_optional(db).await
}

/// A robot's pose plans `offset..offset + limit`, newest first.
pub async fn pose_plans_of_robot(
    db: &Pool,
    robot_id: &str,
    offset: i64,
    limit: i64,
) -> Result<Page<PosePlanRow>, sqlx::Error> {
    let query = sqlx::query_as(
        "SELECT *, COUNT(*) OVER () AS total_rows FROM pose_plans WHERE robot_id = $1 \
         ORDER BY created_at DESC, id DESC LIMIT $2 OFFSET $3",
    )
    .bind(robot_id);
    paging::fetch(db, query, offset, limit, pose_plan_count(db, robot_id)).await
}

pub async fn pose_plan_count(db: impl AnyExecutor<'_>, robot_id: &str) -> Result<i64, sqlx::Error> {
    sqlx::query_scalar("SELECT COUNT(*) FROM pose_plans WHERE robot_id = $1").bind(robot_id).fetch_one(db).await
}
