//! The persisted job queue. A job is a row; a worker claims the oldest queued one with a single
//! atomic `UPDATE … RETURNING` (so two workers never take the same job; on PostgreSQL, replicas
//! claiming at once skip each other's rows), holds a lease it renews while the solver runs, and
//! writes the result and the final state in one transaction. Leases left by a killed server are
//! requeued (SQLite: at the next start; PostgreSQL: by any replica once they expire): the job runs
//! again from its request.

use std::fmt;
use std::time::{Duration, SystemTime};

use crate::db::AnyExecutor;
use crate::db::Pool;
use serde::{Deserialize, Serialize};

use super::paging::{self, Page};
use super::{now, time_text};

/// What a job does; stored (and served) as `pose_plan`, `identification`, `validation`,
/// `diagnosis`, `iso9283`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, sqlx::Type, Serialize, Deserialize, utoipa::ToSchema)]
#[sqlx(rename_all = "snake_case")]
#[serde(rename_all = "snake_case")]
pub enum JobKind {
    PosePlan,
    Identification,
    Validation,
    Diagnosis,
    /// ISO 9283 pose characteristics of a session (migration 0007).
    Iso9283,
}

impl JobKind {
    pub fn as_str(self) -> &'static str {
        match self {
            JobKind::PosePlan => "pose_plan",
            JobKind::Identification => "identification",
            JobKind::Validation => "validation",
            JobKind::Diagnosis => "diagnosis",
            JobKind::Iso9283 => "iso9283",
        }
    }
}

impl fmt::Display for JobKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Where a job is; stored (and served) as `queued`, `running`, `succeeded`, `failed`,
/// `cancelled`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, sqlx::Type, Serialize, Deserialize, utoipa::ToSchema)]
#[sqlx(rename_all = "snake_case")]
#[serde(rename_all = "snake_case")]
pub enum JobState {
    Queued,
    Running,
    Succeeded,
    Failed,
    Cancelled,
}

impl JobState {
    pub const ALL: [JobState; 5] =
        [JobState::Queued, JobState::Running, JobState::Succeeded, JobState::Failed, JobState::Cancelled];

    pub fn as_str(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Running => "running",
            JobState::Succeeded => "succeeded",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
        }
    }

    /// The state named `s`, as stored.
    pub fn parse(s: &str) -> Option<JobState> {
        JobState::ALL.into_iter().find(|k| k.as_str() == s)
    }

    /// Succeeded, failed or cancelled: nothing more happens to the job.
    pub fn has_ended(self) -> bool {
        matches!(self, JobState::Succeeded | JobState::Failed | JobState::Cancelled)
    }
}

impl fmt::Display for JobState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A job row.
#[derive(Clone, Debug, PartialEq, sqlx::FromRow)]
pub struct JobRow {
    pub id: String,
    #[sqlx(try_from = "String")]
    pub kind: JobKind,
    pub robot_id: String,
    #[sqlx(try_from = "String")]
    pub state: JobState,
    pub progress: f64,
    pub request_json: String,
    pub result_json: Option<String>,
    pub error_json: Option<String>,
    pub attempts: i64,
    pub lease_owner: Option<String>,
    pub lease_expires_at: Option<String>,
    #[sqlx(try_from = "crate::db::types::Flag")]
    pub cancel_requested: bool,
    pub created_at: String,
    pub started_at: Option<String>,
    pub finished_at: Option<String>,
    pub updated_at: String,
    /// What the job is doing now (the last phase once it ended).
    pub phase: Option<String>,
}

/// Queue a new job.
pub async fn insert(
    db: impl AnyExecutor<'_>,
    id: &str,
    kind: JobKind,
    robot_id: &str,
    request_json: &str,
) -> Result<(), sqlx::Error> {
    let t = now();
    sqlx::query(
        "INSERT INTO jobs (id, kind, robot_id, state, progress, request_json, created_at, updated_at) \
         VALUES ($1, $2, $3, 'queued', 0, $4, $5, $6)",
    )
    .bind(id)
    .bind(kind)
    .bind(robot_id)
    .bind(request_json)
    .bind(&t)
    .bind(&t)
    .execute(db)
    .await?;
    Ok(())
}

pub async fn get(db: impl AnyExecutor<'_>, id: &str) -> Result<Option<JobRow>, sqlx::Error> {
    sqlx::query_as("SELECT * FROM jobs WHERE id = $1").bind(id).fetch_optional(db).await
}

/// Jobs, newest first, optionally of one robot and/or one state.
pub async fn list(
    db: &Pool,
    robot_id: Option<&str>,
    state: Option<JobState>,
    offset: i64,
    limit: i64,
) -> Result<Page<JobRow>, sqlx::Error> {
    let query = sqlx::query_as(
        "SELECT *, COUNT(*) OVER () AS total_rows FROM jobs \
         WHERE ($1 IS NULL OR robot_id = $1) AND ($2 IS NULL OR state = $2) \
         ORDER BY created_at DESC, id DESC LIMIT $3 OFFSET $4",
    )
    .bind(robot_id)
    .bind(state);
    paging::fetch(db, query, offset, limit, count(db, robot_id, state)).await
}

/// Jobs matching the filters of [`list`].
pub async fn count(
    db: impl AnyExecutor<'_>,
    robot_id: Option<&str>,
    state: Option<JobState>,
) -> Result<i64, sqlx::Error> {
    sqlx::query_scalar("SELECT COUNT(*) FROM jobs WHERE ($1 IS NULL OR robot_id = $1) AND ($2 IS NULL OR state = $2)")
        .bind(robot_id)
        .bind(state)
        .fetch_one(db)
        .await
}

/// Claim the oldest queued job for `owner` with a lease of `lease`: one atomic statement. On
/// PostgreSQL the pick skips rows another claim has locked (`FOR UPDATE SKIP LOCKED`): replicas
/// claiming at once each take a different job instead of queueing behind one and finding it
/// gone. (SQLite has one writer at a time: the statement alone is enough.)
pub async fn claim(pool: &Pool, owner: &str, lease: Duration) -> Result<Option<JobRow>, sqlx::Error> {
    let t = now();
    let until = time_text(SystemTime::now() + lease);
    let sql = match super::Backend::of(pool) {
        super::Backend::Sqlite => CLAIM_SQLITE,
        super::Backend::Postgres => CLAIM_POSTGRES,
    };
    sqlx::query_as(sql).bind(owner).bind(&until).bind(&t).bind(&t).fetch_optional(pool).await
}

/// The claim, one text for both backends: the oldest queued job becomes this worker's. On
/// PostgreSQL the inner SELECT adds `FOR UPDATE SKIP LOCKED`, so replicas claiming at once take
/// different jobs instead of waiting on one row; SQLite has one writer at a time and no such clause.
macro_rules! claim_sql {
    ($lock:literal) => {
        concat!(
            "UPDATE jobs SET state = 'running', lease_owner = $1, lease_expires_at = $2, ",
            "attempts = attempts + 1, started_at = COALESCE(started_at, $3), updated_at = $4, progress = 0 ",
            "WHERE id = (SELECT id FROM jobs WHERE state = 'queued' ORDER BY created_at, id LIMIT 1",
            $lock,
            ") AND state = 'queued' RETURNING *"
        )
    };
}

const CLAIM_SQLITE: &str = claim_sql!("");
const CLAIM_POSTGRES: &str = claim_sql!(" FOR UPDATE SKIP LOCKED");

/// Record a running job's progress (0–1, never backwards) and phase.
pub async fn progress(pool: &Pool, id: &str, owner: &str, progress: f64, phase: &str) -> Result<bool, sqlx::Error> {
    let r = sqlx::query(
        "UPDATE jobs SET progress = CASE WHEN progress > $1 THEN progress ELSE $1 END, phase = $2, updated_at = $3 \
         WHERE id = $4 AND lease_owner = $5 AND state = 'running'",
    )
    .bind(progress)
    .bind(phase)
    .bind(now())
    .bind(id)
    .bind(owner)
    .execute(pool)
    .await?;
    Ok(r.rows_affected() == 1)
}

/// Extend a running job's lease and record its progress; `false` when the job is no longer this
/// owner's (requeued by another process after the lease expired).
pub async fn heartbeat(
    pool: &Pool,
    id: &str,
    owner: &str,
    lease: Duration,
    progress: f64,
) -> Result<bool, sqlx::Error> {
    let r = sqlx::query(
        "UPDATE jobs SET lease_expires_at = $1, progress = CASE WHEN progress > $2 THEN progress ELSE $2 END, updated_at = $3 \
         WHERE id = $4 AND lease_owner = $5 AND state = 'running'",
    )
    .bind(time_text(SystemTime::now() + lease))
    .bind(progress)
    .bind(now())
    .bind(id)
    .bind(owner)
    .execute(pool)
    .await?;
    Ok(r.rows_affected() == 1)
}

/// Whether cancellation was asked for.
pub async fn cancel_requested(db: impl AnyExecutor<'_>, id: &str) -> Result<bool, sqlx::Error> {
    Ok(sqlx::query_scalar::<_, crate::db::types::Flag>("SELECT cancel_requested FROM jobs WHERE id = $1")
        .bind(id)
        .fetch_optional(db)
        .await?
        .is_some_and(bool::from))
}

/// Final state of a job this owner holds, inside the caller's transaction (with the result rows).
/// `false` when the job is no longer held by `owner`, or when it ends `succeeded` or `failed` but
/// its cancellation was asked for meanwhile (then the caller must roll back, and a cancelled job
/// is ended with `state = Cancelled`, which the flag does not block). The flag is checked by this
/// very statement, so a cancel committed before it is never overwritten by a result.
pub async fn finish(
    db: impl AnyExecutor<'_>,
    id: &str,
    owner: &str,
    state: JobState,
    result_json: Option<&str>,
    error_json: Option<&str>,
) -> Result<bool, sqlx::Error> {
    let t = now();
    let r = sqlx::query(
        "UPDATE jobs SET state = $1, result_json = $2, error_json = $3, progress = CASE WHEN $1 = 'succeeded' THEN 1 ELSE progress END, \
             finished_at = $4, updated_at = $4, lease_owner = NULL, lease_expires_at = NULL \
         WHERE id = $5 AND lease_owner = $6 AND state = 'running' AND ($1 = 'cancelled' OR cancel_requested = FALSE)",
    )
    .bind(state)
    .bind(result_json)
    .bind(error_json)
    .bind(&t)
    .bind(id)
    .bind(owner)
    .execute(db)
    .await?;
    Ok(r.rows_affected() == 1)
}

/// Put a held job back in the queue (graceful shutdown with the solver still running).
pub async fn release(pool: &Pool, id: &str, owner: &str) -> Result<bool, sqlx::Error> {
    let r = sqlx::query(
        "UPDATE jobs SET state = 'queued', lease_owner = NULL, lease_expires_at = NULL, updated_at = $1 \
         WHERE id = $2 AND lease_owner = $3 AND state = 'running'",
    )
    .bind(now())
    .bind(id)
    .bind(owner)
    .execute(pool)
    .await?;
    Ok(r.rows_affected() == 1)
}

/// Requeue running jobs whose lease has expired — at start-up, every running job (`all`): the
/// process that held them is gone. Leases whose owner starts with `except` (this process's
/// workers: `instance/`) are left alone: their worker is alive, and may hold a computed result
/// it waits to store while the disk is full — the lease it could not renew meanwhile must not
/// make the job run again. Returns the number requeued.
pub async fn requeue_stale(pool: &Pool, all: bool, except: Option<&str>) -> Result<u64, sqlx::Error> {
    let t = now();
    let r = sqlx::query(
        "UPDATE jobs SET state = 'queued', lease_owner = NULL, lease_expires_at = NULL, updated_at = $1 \
         WHERE state = 'running' AND ($2 OR lease_expires_at IS NULL OR lease_expires_at < $3) \
           AND ($4 IS NULL OR lease_owner IS NULL OR substr(lease_owner, 1, length($5)) <> $6)",
    )
    .bind(&t)
    .bind(all)
    .bind(&t)
    .bind(except)
    .bind(except)
    .bind(except)
    .execute(pool)
    .await?;
    Ok(r.rows_affected())
}

/// What a cancel did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cancel {
    /// The job was queued: it is now `cancelled`.
    Ended,
    /// The job was running: it is flagged, and ends `cancelled` when its solver returns (its
    /// result is then discarded; the worker's final write checks the flag in its transaction).
    Flagged,
    /// The job had already ended (succeeded, failed or cancelled): nothing changed.
    AlreadyEnded,
}

/// Cancel, in one write transaction: a queued job ends at once; a running one is flagged; an
/// ended one is left as it is. Returns what was done and the row after it, `None` if unknown.
/// Because a worker ends its job in a write transaction that reads the flag (and its final UPDATE
/// requires it clear), a cancel is either seen by that transaction or finds the job ended: never
/// both a stored result and a `cancelled` job, and never a cancel answered yet lost.
pub async fn cancel(pool: &Pool, id: &str) -> Result<Option<(Cancel, JobRow)>, sqlx::Error> {
    let t = now();
    let mut tx = super::begin_write(pool).await?;
    let ended = sqlx::query(
        "UPDATE jobs SET state = 'cancelled', finished_at = $1, updated_at = $2 WHERE id = $3 AND state = 'queued'",
    )
    .bind(&t)
    .bind(&t)
    .bind(id)
    .execute(&mut *tx)
    .await?
    .rows_affected();
    let flagged =
        sqlx::query("UPDATE jobs SET cancel_requested = TRUE, updated_at = $1 WHERE id = $2 AND state = 'running'")
            .bind(&t)
            .bind(id)
            .execute(&mut *tx)
            .await?
            .rows_affected();
    let row = get(&mut *tx, id).await?;
    tx.commit().await?;
    let what = match (ended, flagged) {
        (1, _) => Cancel::Ended,
        (_, 1) => Cancel::Flagged,
        _ => Cancel::AlreadyEnded,
    };
    Ok(row.map(|r| (what, r)))
}

/// Job counts by state (for /metrics).
pub async fn counts(db: impl AnyExecutor<'_>) -> Result<Vec<(JobState, i64)>, sqlx::Error> {
    let rows: Vec<(String, i64)> =
        sqlx::query_as("SELECT state, COUNT(*) FROM jobs GROUP BY state").fetch_all(db).await?;
    rows.into_iter()
        .map(|(s, n)| JobState::try_from(s).map(|s| (s, n)).map_err(|e| sqlx::Error::Decode(e.into())))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An in-memory database holding one robot, `r`, for jobs to point at.
    async fn pool_with_robot() -> Pool {
        let pool = crate::db::connect_memory().await.unwrap();
        sqlx::query("INSERT INTO robots (id, name, model_json, created_at) VALUES ('r', 'r', '{}', 't')")
            .execute(&pool)
            .await
            .unwrap();
        pool
    }

    /// The enums are stored as the text the column always held, so existing databases read
    /// the same and the API serves the same strings.
    #[tokio::test]
    async fn kinds_and_states_are_stored_as_their_names() {
        let pool = pool_with_robot().await;
        for (i, kind) in [JobKind::PosePlan, JobKind::Identification, JobKind::Validation].into_iter().enumerate() {
            insert(&pool, &i.to_string(), kind, "r", "{}").await.unwrap();
        }
        let job = claim(&pool, "w", Duration::from_secs(60)).await.unwrap().unwrap();
        assert_eq!((job.kind, job.state), (JobKind::PosePlan, JobState::Running));
        assert!(finish(&pool, &job.id, "w", JobState::Succeeded, Some("{}"), None).await.unwrap());
        let text: Vec<(String, String)> =
            sqlx::query_as("SELECT kind, state FROM jobs ORDER BY id").fetch_all(&pool).await.unwrap();
        assert_eq!(
            text,
            [("pose_plan", "succeeded"), ("identification", "queued"), ("validation", "queued")]
                .map(|(k, s)| (k.to_string(), s.to_string()))
        );
        for s in JobState::ALL {
            assert_eq!(JobState::parse(s.as_str()), Some(s));
            assert_eq!(serde_json::to_value(s).unwrap(), s.as_str());
        }
        assert_eq!(JobState::parse("done"), None);
    }

    /// The kind added by migration 0002 is stored as its name too (the rebuilt CHECK admits it).
    #[tokio::test]
    async fn the_diagnosis_kind_is_stored_as_its_name() {
        let pool = pool_with_robot().await;
        insert(&pool, "d", JobKind::Diagnosis, "r", "{}").await.unwrap();
        let text: String = sqlx::query_scalar("SELECT kind FROM jobs WHERE id = 'd'").fetch_one(&pool).await.unwrap();
        assert_eq!(text, "diagnosis");
        assert_eq!(get(&pool, "d").await.unwrap().unwrap().kind, JobKind::Diagnosis);
        assert_eq!(serde_json::to_value(JobKind::Diagnosis).unwrap(), JobKind::Diagnosis.as_str());
    }

    /// The periodic sweep requeues an expired lease of another process, never one of this
    /// process's workers (alive, perhaps waiting for the disk to store a computed result); the
    /// start-up requeue takes every running job.
    #[tokio::test]
    async fn the_sweep_leaves_this_processs_leases_alone() {
        let pool = pool_with_robot().await;
        for id in ["mine", "theirs"] {
            insert(&pool, id, JobKind::Identification, "r", "{}").await.unwrap();
        }
        let a = claim(&pool, "inst-1/0", Duration::ZERO).await.unwrap().unwrap();
        let b = claim(&pool, "inst-2/0", Duration::ZERO).await.unwrap().unwrap();
        assert_eq!((a.id.as_str(), b.id.as_str()), ("mine", "theirs"));
        tokio::time::sleep(Duration::from_millis(5)).await; // both leases expired
        assert_eq!(requeue_stale(&pool, false, Some("inst-1/")).await.unwrap(), 1);
        assert_eq!(get(&pool, "mine").await.unwrap().unwrap().state, JobState::Running);
        assert_eq!(get(&pool, "theirs").await.unwrap().unwrap().state, JobState::Queued);
        // A prefix of the owner's text only, not a pattern: `inst-1` does not match `inst-1/0`'s
        // sibling `inst-10/0`.
        let c = claim(&pool, "inst-10/0", Duration::ZERO).await.unwrap().unwrap();
        tokio::time::sleep(Duration::from_millis(5)).await;
        assert_eq!(requeue_stale(&pool, false, Some("inst-1/")).await.unwrap(), 1);
        assert_eq!(get(&pool, &c.id).await.unwrap().unwrap().state, JobState::Queued);
        assert_eq!(requeue_stale(&pool, true, None).await.unwrap(), 1);
        assert_eq!(get(&pool, "mine").await.unwrap().unwrap().state, JobState::Queued);
    }
}
