//! Whether the database can be written now: what the service's own writes last met, and a probe.
//! `/readyz` answers 503 while writes fail, so a load balancer stops sending writes to a server
//! whose disk is full or read-only, and sends them again once it is not.
//!
//! Two signals, because neither is enough alone:
//! - the probe, a committed one-page write (`PRAGMA user_version` set to its own value, which
//!   SQLite writes as a page of the WAL), sees a read-only file system or an I/O error at once,
//!   even when no client writes — but on a nearly full disk a one-page write may still fit
//!   where a 10,000-measurement batch does not;
//! - the record of the last write that failed for storage trouble (a request answered 507 or
//!   503 for it, a job that could not store its result) sees that. It holds for
//!   [`TROUBLE_HOLDS`] unless a write succeeds after it: a server nobody writes to (taken out
//!   of rotation because it was not ready) is probed ready again once the probe passes and the
//!   trouble is that old.

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use crate::db::Pool;

use super::{StorageTrouble, storage_trouble};

/// How long a failed write keeps the server unready when no write has succeeded since.
pub const TROUBLE_HOLDS: Duration = Duration::from_secs(30);

/// The probe's own bound: a write lock held longer by a large batch is not a failure.
const PROBE_WAIT: Duration = Duration::from_secs(2);

/// The last storage trouble a write met, unless a write succeeded after it; and the jobs whose
/// end is computed but waits for the storage to take it.
#[derive(Debug, Default)]
pub struct StorageHealth {
    last: Mutex<Option<(StorageTrouble, Instant)>>,
    /// Job id → what it waits for. Held in memory: the job's row is what cannot be written.
    waits: Mutex<HashMap<String, String>>,
}

impl StorageHealth {
    /// A write failed for storage trouble.
    pub fn failed(&self, trouble: StorageTrouble) {
        *self.last.lock().unwrap_or_else(|e| e.into_inner()) = Some((trouble, Instant::now()));
    }

    /// A write was committed: the storage takes writes again.
    pub fn succeeded(&self) {
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        if last.is_some() {
            *last = None;
        }
    }

    /// The trouble a write met within [`TROUBLE_HOLDS`] with none succeeding since, and how long
    /// ago.
    pub fn recent(&self) -> Option<(StorageTrouble, Duration)> {
        let last = *self.last.lock().unwrap_or_else(|e| e.into_inner());
        last.map(|(t, at)| (t, at.elapsed())).filter(|(_, ago)| *ago < TROUBLE_HOLDS)
    }

    /// A job's end is computed and waits for the storage: `what` says so (its `phase`).
    pub fn job_waits(&self, job_id: &str, what: String) {
        self.waits.lock().unwrap_or_else(|e| e.into_inner()).insert(job_id.to_string(), what);
    }

    /// The job no longer waits (its end was written, or it was put back in the queue).
    pub fn job_done(&self, job_id: &str) {
        self.waits.lock().unwrap_or_else(|e| e.into_inner()).remove(job_id);
    }

    /// What a job waits for, if it does.
    pub fn job_waiting(&self, job_id: &str) -> Option<String> {
        self.waits.lock().unwrap_or_else(|e| e.into_inner()).get(job_id).cloned()
    }
}

/// What the probe found.
#[derive(Debug, Clone, PartialEq)]
pub enum Probe {
    /// A one-page write was committed.
    Written,
    /// The write lock stayed taken (a long write transaction): no verdict, not a failure.
    Busy,
    /// The write failed for storage trouble.
    Trouble(StorageTrouble),
    /// Any other failure (logged by the caller).
    Failed(String),
}

/// A committed one-page write: `PRAGMA user_version` set to the value it has (the version is not
/// used by robocal or by sqlx's migrations; SQLite writes page 1 all the same). On PostgreSQL, a
/// committed transaction that was given an id (its commit record goes to the WAL).
pub async fn probe(pool: &Pool) -> Probe {
    let write = async {
        let mut tx = super::begin_write(pool).await?;
        match super::Backend::of(pool) {
            super::Backend::Sqlite => {
                let v: i64 = sqlx::query_scalar("PRAGMA user_version").fetch_one(&mut *tx).await?;
                sqlx::query(sqlx::AssertSqlSafe(format!("PRAGMA user_version = {v}"))).execute(&mut *tx).await?;
            }
            // A transaction id is assigned, so its COMMIT is written to PostgreSQL's WAL.
            super::Backend::Postgres => {
                sqlx::query("SELECT txid_current()").execute(&mut *tx).await?;
            }
        }
        tx.commit().await
    };
    match tokio::time::timeout(PROBE_WAIT, write).await {
        Err(_) => Probe::Busy,
        Ok(Ok(())) => Probe::Written,
        Ok(Err(e)) => match storage_trouble(&e) {
            Some(t) => Probe::Trouble(t),
            None if super::is_busy(&e) => Probe::Busy,
            None => Probe::Failed(e.to_string()),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failure_holds_until_a_write_succeeds() {
        let h = StorageHealth::default();
        assert_eq!(h.recent(), None);
        h.failed(StorageTrouble::Full);
        assert_eq!(h.recent().map(|(t, _)| t), Some(StorageTrouble::Full));
        h.failed(StorageTrouble::ReadOnly);
        assert_eq!(h.recent().map(|(t, _)| t), Some(StorageTrouble::ReadOnly), "the latest trouble is said");
        h.succeeded();
        assert_eq!(h.recent(), None);
    }

    #[test]
    fn a_failure_expires() {
        let h = StorageHealth::default();
        *h.last.lock().unwrap() = Some((StorageTrouble::Io, Instant::now() - TROUBLE_HOLDS - Duration::from_millis(1)));
        assert_eq!(h.recent(), None);
    }

    /// The probe commits a write: the WAL grows by a frame, and the version is unchanged.
    #[tokio::test]
    async fn the_probe_commits_a_page_and_changes_nothing() {
        let dir = std::env::temp_dir().join(format!("robocal-probe-{}", super::super::new_id()));
        std::fs::create_dir_all(&dir).unwrap();
        let db = dir.join("p.db");
        let pool = super::super::connect(&db).await.unwrap();
        sqlx::query("PRAGMA user_version = 7").execute(&pool).await.unwrap();
        sqlx::query("PRAGMA wal_checkpoint(TRUNCATE)").execute(&pool).await.unwrap();
        let wal = || std::fs::metadata(dir.join("p.db-wal")).map(|m| m.len()).unwrap_or(0);
        assert_eq!(wal(), 0);
        assert_eq!(probe(&pool).await, Probe::Written);
        assert!(wal() > 4096, "the probe wrote {} bytes of WAL", wal());
        let v: i64 = sqlx::query_scalar("PRAGMA user_version").fetch_one(&pool).await.unwrap();
        assert_eq!(v, 7);
        pool.close().await;
        let _ = std::fs::remove_dir_all(&dir);
    }
}
