//! In-process read caches for the hot path of compensation: a single-target request must not pay
//! two database round trips and a parameter-set parse (measured: that was 80% of its time).
//!
//! - Parameter sets are immutable once stored, so a compiled set (parsed document + ready
//!   [`Compensator`]) is valid for as long as it exists; the cache is bounded (least-recently
//!   used entries go) and never needs invalidation.
//! - Robot rows change in one way only: their active parameter set. Every writer of that pointer
//!   calls [`Caches::robot_changed`] after its transaction commits. A reader that started before
//!   such a commit could otherwise put the old row back after the invalidation; a generation
//!   counter, read before the database and checked before inserting, prevents that.
//!
//! - Bearer tokens: a verified token is trusted for [`TOKEN_RECHECK`] before the store is asked
//!   again. Revoking over HTTP clears the cache at once; `robocal token revoke`, which writes the
//!   database from another process, takes effect within that second. Unknown and revoked
//!   secrets are never cached.
//!
//! One server process per database (README): another process writing robots or sets in the same
//! file would not invalidate this one's cache.

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

/// How long a verified token is trusted before the store is asked again.
pub const TOKEN_RECHECK: Duration = Duration::from_secs(1);

pub struct Caches {
    robots: Cache<String, Arc<RobotRow>>,
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
            robots: Cache::new(capacity),
            sets: Cache::new(capacity),
            robot_generation: AtomicU64::new(0),
            tokens: Cache::new(capacity),
            token_generation: AtomicU64::new(0),
        }
    }

    /// The live token with this secret (`None`: unknown or revoked).
    pub async fn token(&self, pool: &Pool, secret: &str) -> Result<Option<Arc<TokenRow>>, sqlx::Error> {
        let hash = tokens::hash(secret);
        if let Some((t, checked)) = self.tokens.get(&hash)
            && checked.elapsed() < TOKEN_RECHECK
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

    /// Call after committing a revocation.
    pub fn tokens_changed(&self) {
        self.token_generation.fetch_add(1, Ordering::AcqRel);
        self.tokens.clear();
    }

    /// The robot row, from the cache or the database.
    pub async fn robot(&self, pool: &Pool, id: &str) -> Result<Option<Arc<RobotRow>>, sqlx::Error> {
        if let Some(r) = self.robots.get(id) {
            return Ok(Some(r));
        }
        let generation = self.robot_generation.load(Ordering::Acquire);
        let Some(row) = records::robot(pool, id).await? else { return Ok(None) };
        let row = Arc::new(row);
        if self.robot_generation.load(Ordering::Acquire) == generation {
            self.robots.insert(id.to_string(), row.clone());
        }
        Ok(Some(row))
    }

    /// Call after committing a change to a robot row.
    pub fn robot_changed(&self, id: &str) {
        self.robot_generation.fetch_add(1, Ordering::AcqRel);
        self.robots.remove(id);
    }

    /// The parameter set, compiled, from the cache or the database (`None`: no such set).
    pub async fn parameter_set(&self, pool: &Pool, id: &str) -> Result<Option<Arc<CompiledSet>>, AppError> {
        if let Some(s) = self.sets.get(id) {
            return Ok(Some(s));
        }
        let Some(row) = records::parameter_set(pool, id).await? else { return Ok(None) };
        let doc = ParameterSetDoc::from_json(&row.doc_json)
            .map_err(|e| AppError::Internal(format!("stored set {}: {e}", row.id)))?;
        let stored = |e: crate::domain::DomainError| AppError::Internal(format!("stored set {}: {e}", row.id));
        let envelope = Envelope::of_doc(&doc).map_err(stored)?;
        let covariance = PredictionCovariance::of_doc(&doc).map_err(stored)?;
        let compensator = Compensator::new(&doc.set);
        let listed: Vec<String> = serde_json::from_str(&row.sessions_json)
            .map_err(|e| AppError::Internal(format!("stored set {}: sessions: {e}", row.id)))?;
        let fit_sessions = crate::domain::validation::fit_data(&doc, &listed).sessions;
        let compiled = Arc::new(CompiledSet { row, set: doc.set, compensator, envelope, covariance, fit_sessions });
        self.sets.insert(id.to_string(), compiled.clone());
        Ok(Some(compiled))
    }
}
