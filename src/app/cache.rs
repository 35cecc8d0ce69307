//! In-process read caches for the hot path of compensation: a single-target request must not pay
//! two database round trips and a parameter-set parse (measured: that was 80% of its time).
//!
//! - Parameter sets are immutable once stored (archiving changes only what the history lists
//!   and whether the set may be activated, both read from the store), so a compiled set (parsed
//!   document + ready [`Compensator`]) is valid for as long as it exists; the cache is bounded
//!   (least-recently used entries go) and never needs invalidation.
//! - Robot rows change in one way only: their active parameter set. Every writer of that pointer
//!   calls [`Caches::robot_changed`] after its transaction commits. A reader that started before
//!   such a commit could otherwise put the old row back after the invalidation; a generation
//!   counter, read before the database and checked before inserting, prevents that.
//! - Bearer tokens: a verified token is trusted for [`RECHECK`] before the store is asked
//!   again. Revoking over HTTP clears the cache at once; `robocal token revoke`, which writes the
//!   database from another process, takes effect within that second. Unknown and revoked
//!   secrets are never cached.
//!
//! Several replicas on one PostgreSQL database ([`Caches::shared`]): a change made by another
//! replica must reach this one's caches too.
//! - Each change is announced after its commit on the `robocal_cache` channel (`pg_notify`:
//!   `robot:<id>` or `tokens`), and every replica listens ([`listen`]): the entry goes as soon as
//!   the notification arrives, typically within milliseconds.
//! - The fallback, for a notification lost with the listener's connection or never sent (a
//!   replica killed between its commit and its announcement): a cached robot row, like a token,
//!   is read again from the store once it is [`RECHECK`] old. No change made on one replica is
//!   served stale by another for longer than that; a listener that loses its connection also
//!   empties the caches at once.
//!
//! On SQLite one server holds the database (its lock), so its own invalidations are the only ones.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use crate::db::Pool;
use quick_cache::sync::Cache;

use super::AppError;
use crate::db::records::{self, ParameterSetRow, RobotRow};
use crate::db::tokens::{self, TokenRow};
use crate::domain::ParameterSetDoc;
use crate::domain::validity::{Envelope, PredictionCovariance};
use crate::kinematics::{Compensator, ParameterSet};

/// A stored parameter set, parsed and ready to compensate with its own tool.
pub struct CompiledSet {
    pub row: ParameterSetRow,
    pub set: ParameterSet,
    pub compensator: Compensator,
    /// The envelope the set was calibrated in, when it records one.
    pub envelope: Option<Envelope>,
    /// Its parameter covariance, when it records one.
    pub covariance: Option<PredictionCovariance>,
    /// The sessions it was fitted on (its document's and the store's record joined): a
    /// validation on any of them is not held out.
    pub fit_sessions: Vec<String>,
}

/// How long a verified token (and, with several replicas, a robot row) is trusted before the
/// store is asked again.
pub const RECHECK: Duration = Duration::from_secs(1);

/// The PostgreSQL channel changes are announced on.
pub const CHANNEL: &str = "robocal_cache";

pub struct Caches {
    /// Another process may change robots (replicas sharing a PostgreSQL database): robot rows
    /// are read again once [`RECHECK`] old.
    shared: bool,
    /// Robot id → the row and when the store last gave it.
    robots: Cache<String, (Arc<RobotRow>, Instant)>,
    sets: Cache<String, Arc<CompiledSet>>,
    /// Bumped by every robot write, after its commit.
    robot_generation: AtomicU64,
    /// Token hash → the row and when the store last vouched for it.
    tokens: Cache<String, (Arc<TokenRow>, Instant)>,
    /// Bumped by every revocation in this process, after its commit.
    token_generation: AtomicU64,
}

impl Caches {
    pub fn new(capacity: usize) -> Self {
        Caches {
            shared: false,
            robots: Cache::new(capacity),
            sets: Cache::new(capacity),
            robot_generation: AtomicU64::new(0),
            tokens: Cache::new(capacity),
            token_generation: AtomicU64::new(0),
        }
    }

    /// Caches for a store other processes write too (see the module's documentation).
    pub fn shared(capacity: usize) -> Self {
        Caches { shared: true, ..Self::new(capacity) }
    }

    /// The live token with this secret (`None`: unknown or revoked).
    pub async fn token(&self, pool: &Pool, secret: &str) -> Result<Option<Arc<TokenRow>>, sqlx::Error> {
        let hash = tokens::hash(secret);
        if let Some((t, checked)) = self.tokens.get(&hash)
            && checked.elapsed() < RECHECK
        {
            return Ok(Some(t));
        }
        let generation = self.token_generation.load(Ordering::Acquire);
        let checked = Instant::now();
        let Some(row) = tokens::by_hash(pool, &hash).await? else {
            self.tokens.remove(&hash);
            return Ok(None);
        };
        let row = Arc::new(row);
        if self.token_generation.load(Ordering::Acquire) == generation {
            self.tokens.insert(hash, (row.clone(), checked));
        }
        Ok(Some(row))
    }

    /// Call after committing a revocation: forgets every cached token here and announces it to
    /// the other replicas.
    pub async fn tokens_changed(&self, pool: &Pool) {
        self.forget_tokens();
        announce(pool, "tokens").await;
    }

    fn forget_tokens(&self) {
        self.token_generation.fetch_add(1, Ordering::AcqRel);
        self.tokens.clear();
    }

    /// The robot row, from the cache or the database.
    pub async fn robot(&self, pool: &Pool, id: &str) -> Result<Option<Arc<RobotRow>>, sqlx::Error> {
        if let Some((r, read)) = self.robots.get(id)
            && (!self.shared || read.elapsed() < RECHECK)
        {
            return Ok(Some(r));
        }
        let generation = self.robot_generation.load(Ordering::Acquire);
        let read = Instant::now();
        let Some(row) = records::robot(pool, id).await? else {
            self.robots.remove(id);
            return Ok(None);
        };
        let row = Arc::new(row);
        if self.robot_generation.load(Ordering::Acquire) == generation {
            self.robots.insert(id.to_string(), (row.clone(), read));
        }
        Ok(Some(row))
    }

    /// Call after committing a change to a robot row: forgets it here and announces it to the
    /// other replicas.
    pub async fn robot_changed(&self, pool: &Pool, id: &str) {
        self.forget_robot(id);
        announce(pool, &format!("robot:{id}")).await;
    }

    fn forget_robot(&self, id: &str) {
        self.robot_generation.fetch_add(1, Ordering::AcqRel);
        self.robots.remove(id);
    }

    /// Forget every robot row and token (a listener that lost its connection may have missed
    /// announcements).
    fn forget_all(&self) {
        self.robot_generation.fetch_add(1, Ordering::AcqRel);
        self.robots.clear();
        self.forget_tokens();
    }

    /// Apply an announcement (see [`announce`]); unknown ones forget everything.
    pub fn apply(&self, payload: &str) {
        match payload.strip_prefix("robot:") {
            Some(id) => self.forget_robot(id),
            None if payload == "tokens" => self.forget_tokens(),
            None => self.forget_all(),
        }
    }

    /// The parameter set, compiled, from the cache or the database (`None`: no such set).
    pub async fn parameter_set(&self, pool: &Pool, id: &str) -> Result<Option<Arc<CompiledSet>>, AppError> {
        if let Some(s) = self.sets.get(id) {
            return Ok(Some(s));
        }
        let Some(row) = records::parameter_set(pool, id).await? else { return Ok(None) };
        let doc = ParameterSetDoc::from_json(&row.doc_json)
            .map_err(|e| AppError::Internal(format!("stored set {}: {e}", row.id)))?;
        let (envelope, covariance) =
            usable_parts(&doc).map_err(|e| AppError::Internal(format!("stored set {}: {e}", row.id)))?;
        let compensator = Compensator::new(&doc.set);
        let listed: Vec<String> = serde_json::from_str(&row.sessions_json)
            .map_err(|e| AppError::Internal(format!("stored set {}: sessions: {e}", row.id)))?;
        let fit_sessions = crate::domain::validation::fit_data(&doc, &listed).sessions;
        let compiled = Arc::new(CompiledSet { row, set: doc.set, compensator, envelope, covariance, fit_sessions });
        self.sets.insert(id.to_string(), compiled.clone());
        Ok(Some(compiled))
    }
}

/// What a compensation compiles from a set's document besides its chain: the calibrated envelope
/// and the parameters' covariance, each checked (a correlation matrix of another shape than the
/// free parameters, a free parameter without σ, an envelope whose corners are upside down).
/// The cache compiles a stored set with it, and an imported file is checked with it before it is
/// stored: a file it refuses, stored, would answer 500 to every later use of the set.
pub fn usable_parts(
    doc: &ParameterSetDoc,
) -> Result<(Option<Envelope>, Option<PredictionCovariance>), crate::domain::DomainError> {
    Ok((Envelope::of_doc(doc)?, PredictionCovariance::of_doc(doc)?))
}

/// Announce a committed change to the replicas sharing a PostgreSQL database (nothing on SQLite).
/// A failed announcement is logged: the other replicas then see the change within [`RECHECK`].
async fn announce(pool: &Pool, payload: &str) {
    if crate::db::Backend::of(pool) != crate::db::Backend::Postgres {
        return;
    }
    // `pg_notify` returns `void`, which the Any driver cannot carry: select a constant instead.
    let sent =
        sqlx::query("SELECT 1 FROM (SELECT pg_notify($1, $2)) AS sent").bind(CHANNEL).bind(payload).execute(pool).await;
    if let Err(e) = sent {
        tracing::warn!(error = %e, payload, "cannot announce a change to the other replicas; they see it within 1 s");
    }
}

/// Listen for the other replicas' announcements and apply them to `caches`, until the task is
/// aborted. Reconnects after a lost connection (forgetting everything cached meanwhile: an
/// announcement may have been missed); the [`RECHECK`] fallback covers the time it takes.
pub async fn listen(url: String, caches: Arc<Caches>) {
    let mut wait = Duration::from_millis(100);
    loop {
        let mut listener = match subscribe(&url).await {
            Ok(l) => l,
            Err(e) => {
                tracing::warn!(error = %e, retry_in = ?wait, "cache listener: cannot subscribe; retrying");
                tokio::time::sleep(wait).await;
                wait = (wait * 2).min(Duration::from_secs(5));
                continue;
            }
        };
        // Listening from here on; anything changed before is re-read (forget all).
        caches.forget_all();
        wait = Duration::from_millis(100);
        loop {
            let lost = match listener.try_recv().await {
                Ok(Some(n)) => {
                    caches.apply(n.payload());
                    continue;
                }
                Ok(None) => "connection lost".to_string(),
                Err(e) => e.to_string(),
            };
            tracing::warn!(error = %lost, "cache listener: caches emptied, reconnecting");
            caches.forget_all();
            break;
        }
    }
}

/// A connection to the database that listens on [`CHANNEL`].
async fn subscribe(url: &str) -> Result<sqlx::postgres::PgListener, sqlx::Error> {
    let mut listener = sqlx::postgres::PgListener::connect(url).await?;
    listener.listen(CHANNEL).await?;
    Ok(listener)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fallback of shared caches: a robot row changed behind this process's back (by a
    /// replica whose announcement never came) is served stale for less than [`RECHECK`], then
    /// read again; an announcement applied forgets it at once. Unshared caches (one server per
    /// SQLite file) keep it, which is why a shared store needs `shared`.
    #[tokio::test]
    async fn shared_caches_read_a_robot_again_once_it_is_recheck_old() {
        let pool = crate::db::connect_memory().await.unwrap();
        let row = RobotRow {
            id: crate::db::new_id(),
            name: "r".into(),
            model_json: "{}".into(),
            base_guess_json: None,
            active_parameter_set_id: None,
            created_at: crate::db::now(),
        };
        records::insert_robot(&pool, &row).await.unwrap();
        let (shared, alone) = (Caches::shared(8), Caches::new(8));
        for c in [&shared, &alone] {
            assert_eq!(c.robot(&pool, &row.id).await.unwrap().unwrap().name, "r");
        }
        let rename = |name: &'static str| {
            sqlx::query("UPDATE robots SET name = $1 WHERE id = $2").bind(name).bind(&row.id).execute(&pool)
        };
        rename("renamed").await.unwrap();
        assert_eq!(shared.robot(&pool, &row.id).await.unwrap().unwrap().name, "r", "cached, not yet RECHECK old");
        tokio::time::sleep(RECHECK + Duration::from_millis(20)).await;
        assert_eq!(shared.robot(&pool, &row.id).await.unwrap().unwrap().name, "renamed");
        assert_eq!(alone.robot(&pool, &row.id).await.unwrap().unwrap().name, "r");
        // An announcement forgets the row at once.
        rename("again").await.unwrap();
        shared.apply(&format!("robot:{}", row.id));
        assert_eq!(shared.robot(&pool, &row.id).await.unwrap().unwrap().name, "again");
        shared.apply("something new");
        rename("fourth").await.unwrap();
        assert_eq!(shared.robot(&pool, &row.id).await.unwrap().unwrap().name, "fourth", "unknown: forget all");
    }
}
