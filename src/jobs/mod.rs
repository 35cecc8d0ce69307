//! Background jobs: rows in the `jobs` table run by a few workers. A worker claims the oldest
//! queued job atomically, loads its inputs, runs the solver in `spawn_blocking` while renewing
//! its lease, and writes the result and the final state in one transaction. At start-up every
//! job left `running` by a previous process is requeued, so a job running when the server was
//! killed completes after the restart. On graceful shutdown, workers stop claiming; a job still
//! in the solver after the grace period is put back in the queue, not lost.

pub mod requests;
pub mod results;
pub mod run;

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use tokio::sync::watch;
use tokio::task::JoinHandle;
use tracing::Instrument;

use crate::db::Pool;
use tokio::sync::Notify;

use crate::app::cache::Caches;
use crate::app::{AppError, Metrics};
use crate::db;
use crate::db::jobs::JobState;
use crate::domain::DomainError;

/// Why a job failed (or, checked at submission, would fail).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum JobError {
    /// Bad input: the request field at fault, when there is one.
    #[error("{detail}")]
    Invalid { detail: String, field: Option<String> },
    /// The request names something the store does not hold (answered 404 naming the field).
    #[error("{detail}")]
    Unknown { detail: String, field: Option<String> },
    /// Numerical trouble: rank deficiency, κ above the limit, divergence, an unreachable pose
    /// plan. `kind` is the problem slug, `title` its short description.
    #[error("{detail}")]
    Numerical { kind: &'static str, title: &'static str, detail: String },
    /// The storage under the database refused (full, read-only, I/O error): the job's inputs
    /// could not be read or its result could not be written.
    #[error("{}", .0.describe())]
    Storage(db::StorageTrouble),
    /// The database stayed locked by other writers longer than its busy timeout: try again.
    #[error("the database is busy (locked by other writes); try again")]
    Busy,
    /// The job ran to its end but its result could not be written (not for storage trouble,
    /// which is waited out): what happened, in words for the user; the cause is logged.
    #[error("{0}")]
    NotStored(String),
    /// Logged, never echoed.
    #[error("internal error: {0}")]
    Internal(String),
}

impl JobError {
    pub fn invalid(field: impl Into<String>, detail: impl Into<String>) -> Self {
        JobError::Invalid { detail: detail.into(), field: Some(field.into()) }
    }

    /// `field` names something the store does not hold.
    pub fn unknown(field: impl Into<String>, detail: impl Into<String>) -> Self {
        JobError::Unknown { detail: detail.into(), field: Some(field.into()) }
    }

    /// A domain error whose path is the request field itself: that field, the bare reason.
    pub fn field(e: DomainError) -> Self {
        JobError::Invalid { field: e.field(), detail: e.reason }
    }

    /// A domain error under `prefix`, its path in the detail.
    pub fn domain(e: DomainError, prefix: &str) -> Self {
        let e = e.under(prefix);
        JobError::Invalid { field: e.field(), detail: e.to_string() }
    }
}

impl From<AppError> for JobError {
    fn from(e: AppError) -> Self {
        match e {
            AppError::Invalid { detail, field } => JobError::Invalid { detail, field },
            AppError::Unknown { detail, field } => JobError::Unknown { detail, field },
            AppError::Storage(t) => JobError::Storage(t),
            AppError::Internal(m) => JobError::Internal(m),
        }
    }
}

impl From<sqlx::Error> for JobError {
    fn from(e: sqlx::Error) -> Self {
        if db::is_busy(&e) {
            return JobError::Busy;
        }
        AppError::from(e).into()
    }
}

/// What the workers need: the store, the queue's wake-up, the caches a finished job invalidates,
/// the metrics they time the solver into, how a failure is written to `jobs.error_json`, and
/// where storage trouble is recorded (for `/readyz`, and a waiting job's `phase`).
#[derive(Clone)]
pub struct JobContext {
    pub pool: Pool,
    pub wake: Arc<Notify>,
    pub caches: Arc<Caches>,
    pub metrics: Arc<Metrics>,
    /// The stored form of a failure: the service's problem document (the HTTP layer supplies it,
    /// so `GET /v1/jobs/{id}` shows a failed job's error as it shows any error).
    pub failure_json: fn(&JobError) -> String,
    pub storage: Arc<db::StorageHealth>,
    /// A claimed job's lease ([`LEASE`] unless `serve --job-lease-s` says otherwise); renewed
    /// every sixth of it while the job runs. How long a job whose server died waits before
    /// another server sharing the database takes it.
    pub lease: Duration,
}

/// The default lease of a claimed job.
pub const LEASE: Duration = Duration::from_secs(60);
/// The shortest lease `serve` accepts: a renewal every sixth of it must not flood the database,
/// and a busy database may delay one by a second or so.
pub const LEASE_MIN: Duration = Duration::from_secs(3);

impl JobContext {
    /// How often a running job's lease is renewed: six renewals per lease, so that a few
    /// delayed or failed ones do not lose it.
    fn heartbeat(&self) -> Duration {
        self.lease / 6
    }
}
/// A running job's progress and phase are written at most this often (when they changed).
pub const PROGRESS_EVERY: Duration = Duration::from_secs(1);
/// Idle workers look for work (and for expired leases) at least this often.
const POLL: Duration = Duration::from_secs(2);
/// A job end the storage refused is written again after this wait, doubled after each refusal up
/// to [`STORE_RETRY_MAX`].
pub const STORE_RETRY_FIRST: Duration = Duration::from_millis(500);
pub const STORE_RETRY_MAX: Duration = Duration::from_secs(10);

/// The workers' stop signal: `None` while they run; the deadline by which running jobs must end
/// once a shutdown began (after it, they are put back in the queue).
type Stop = watch::Receiver<Option<tokio::time::Instant>>;

/// The running workers.
pub struct Workers {
    handles: Vec<JoinHandle<()>>,
    stop: watch::Sender<Option<tokio::time::Instant>>,
    grace: Duration,
}

impl Workers {
    /// Requeue the jobs a previous process left running, then start `n` workers. `grace` is how
    /// long [`Workers::shutdown`] lets running jobs go on.
    pub async fn start(ctx: impl Into<JobContext>, n: usize, grace: Duration) -> Result<Workers, sqlx::Error> {
        let state: JobContext = ctx.into();
        // SQLite: this process holds the database alone (the serve lock), so every running job
        // was left by a previous process. PostgreSQL: other replicas may be running theirs now;
        // only expired leases are taken back (a dead replica's lease runs out).
        let alone = db::Backend::of(&state.pool) == db::Backend::Sqlite;
        let requeued = db::jobs::requeue_stale(&state.pool, alone, None).await?;
        if requeued > 0 {
            tracing::warn!(requeued, "requeued jobs left running by a previous process");
        }
        let (stop, rx) = watch::channel(None);
        let instance = db::new_id();
        let handles = (0..n.max(1))
            .map(|i| {
                let owner = format!("{instance}/{i}");
                tokio::spawn(worker(state.clone(), instance.clone(), owner, rx.clone()))
            })
            .collect();
        Ok(Workers { handles, stop, grace })
    }

    /// Stop claiming now; a running job may go on until `deadline`, then it is put back in the
    /// queue (its solver's thread is abandoned).
    pub fn stop(&self, deadline: tokio::time::Instant) {
        self.stop.send_if_modified(|d| {
            let first = d.is_none();
            if first {
                *d = Some(deadline);
            }
            first
        });
    }

    /// Stop (if [`Workers::stop`] was not called: with the grace period from now) and wait for
    /// the workers: each ends its job by the deadline or requeues it.
    pub async fn shutdown(self) {
        self.stop(tokio::time::Instant::now() + self.grace);
        for h in self.handles {
            let _ = h.await;
        }
    }
}

async fn worker(state: JobContext, instance: String, owner: String, mut stop: Stop) {
    let mine = format!("{instance}/");
    let mut last_sweep = Instant::now();
    loop {
        if stop.borrow().is_some() {
            return;
        }
        if last_sweep.elapsed() > state.lease {
            // Another process sharing the database may have died holding a lease (this process's
            // own workers are alive: their leases are theirs to end).
            if let Err(e) = db::jobs::requeue_stale(&state.pool, false, Some(&mine)).await {
                tracing::warn!(error = %e, "requeueing expired leases");
            }
            last_sweep = Instant::now();
        }
        match db::jobs::claim(&state.pool, &owner, state.lease).await {
            Ok(Some(job)) => {
                let span = tracing::info_span!("job", id = %job.id, kind = %job.kind, attempt = job.attempts);
                if run_one(&state, &owner, job, &stop).instrument(span).await {
                    tokio::select! {
                        _ = tokio::time::sleep(POLL) => {}
                        _ = stop.changed() => {}
                    }
                }
            }
            Ok(None) => {
                tokio::select! {
                    _ = state.wake.notified() => {}
                    _ = tokio::time::sleep(POLL) => {}
                    _ = stop.changed() => {}
                }
            }
            Err(e) => {
                tracing::warn!(error = %e, "claiming a job");
                tokio::select! {
                    _ = tokio::time::sleep(POLL) => {}
                    _ = stop.changed() => {}
                }
            }
        }
    }
}

/// How a job ended, for the final write.
#[derive(Clone)]
enum End {
    Done(run::Output),
    Failed(JobError),
    /// Shutdown overtook the solver: requeue.
    Released,
}

/// The shutdown deadline, once one is set: resolves then (never before a shutdown).
async fn deadline(stop: &mut Stop) {
    loop {
        let d = *stop.borrow_and_update();
        match d {
            Some(d) => return tokio::time::sleep_until(d).await,
            None => {
                if stop.changed().await.is_err() {
                    return std::future::pending().await;
                }
            }
        }
    }
}

/// Run a claimed job to its end (written). `true` when the worker should wait before claiming
/// again (the storage would not give the job's inputs).
async fn run_one(state: &JobContext, owner: &str, job: db::jobs::JobRow, stop: &Stop) -> bool {
    tracing::info!("job started");
    let mut backoff = false;
    let started = Instant::now();
    // Progress in thousandths and the phase, shared with the blocking solver.
    let progress = Arc::new(AtomicU64::new(0));
    let phase: Arc<std::sync::Mutex<&'static str>> = Arc::new(std::sync::Mutex::new("loading"));
    let _ = db::jobs::progress(&state.pool, &job.id, owner, 0.0, "loading").await;
    let end = match run::load(&state.pool, job.kind, &job.robot_id, &job.request_json).await {
        // The storage failed to give the inputs: not the job's fault; it goes back in the queue,
        // and this worker waits a poll interval before claiming again.
        Err(JobError::Storage(t)) => {
            state.storage.failed(t);
            tracing::warn!(trouble = t.cause(), "the job's inputs could not be read; it goes back in the queue");
            backoff = true;
            End::Released
        }
        Err(e) => End::Failed(e),
        Ok(inputs) => {
            progress.store(50, Ordering::Relaxed);
            let (p, ph) = (progress.clone(), phase.clone());
            let mut task = tokio::task::spawn_blocking(move || {
                let report = move |f: f64, what: &'static str| {
                    p.fetch_max((f.clamp(0.0, 1.0) * 1000.0) as u64, Ordering::Relaxed);
                    *ph.lock().unwrap_or_else(|e| e.into_inner()) = what;
                };
                run::compute(inputs, &report)
            });
            let mut beat = tokio::time::interval(state.heartbeat());
            beat.tick().await;
            // Progress is written when it changed, at most every PROGRESS_EVERY.
            let mut tick = tokio::time::interval(PROGRESS_EVERY);
            tick.tick().await;
            let mut written = (0u64, "loading");
            let mut stop_at = stop.clone();
            let shutdown = deadline(&mut stop_at);
            tokio::pin!(shutdown);
            loop {
                tokio::select! {
                    r = &mut task => {
                        break match r {
                            Ok(Ok(out)) => End::Done(out),
                            Ok(Err(e)) => End::Failed(e),
                            Err(e) => End::Failed(JobError::Internal(format!("the solver task failed: {e}"))),
                        };
                    }
                    _ = tick.tick() => {
                        let now = (progress.load(Ordering::Relaxed), *phase.lock().unwrap_or_else(|e| e.into_inner()));
                        if now != written {
                            match db::jobs::progress(&state.pool, &job.id, owner, now.0 as f64 / 1000.0, now.1).await {
                                Ok(_) => written = now,
                                Err(e) => tracing::warn!(error = %e, "recording progress"),
                            }
                        }
                    }
                    _ = beat.tick() => {
                        let f = progress.load(Ordering::Relaxed) as f64 / 1000.0;
                        match db::jobs::heartbeat(&state.pool, &job.id, owner, state.lease, f).await {
                            Ok(true) => {}
                            Ok(false) => {
                                tracing::warn!("lease lost (requeued elsewhere); abandoning the result");
                                return false;
                            }
                            Err(e) => tracing::warn!(error = %e, "heartbeat"),
                        }
                    }
                    _ = &mut shutdown => break End::Released,
                }
            }
        }
    };
    let elapsed = started.elapsed().as_secs_f64();
    let outcome = match &end {
        End::Done(_) => "succeeded",
        End::Failed(_) => "failed",
        End::Released => "released",
    };
    state.metrics.solver.with_label_values(&[job.kind.as_str(), outcome]).observe(elapsed);
    write_end(state, owner, &job, end, stop).await;
    backoff
}

/// Write a job's end, whatever the storage does meanwhile:
/// - refused for storage trouble (a full disk, a read-only file system, an I/O error): the end
///   stays in memory and is written again after a wait that doubles from [`STORE_RETRY_FIRST`]
///   to [`STORE_RETRY_MAX`], until it is taken (nothing is computed again) or a shutdown's
///   deadline passes (then the job is put back in the queue, or, if even that cannot be written,
///   requeued at the next start). Meanwhile the job's `phase` says what it waits for (from
///   memory: its row is what cannot be written), its lease is renewed when it can be, and
///   `/readyz` answers 503;
/// - refused for any other reason: the job ends `failed` with a problem that says its result
///   could not be stored (the cause is logged).
async fn write_end(state: &JobContext, owner: &str, job: &db::jobs::JobRow, mut end: End, stop: &Stop) {
    let mut wait = STORE_RETRY_FIRST;
    let mut refusals = 0u32;
    let mut past_deadline = false;
    let mut stop_at = stop.clone();
    let shutdown = deadline(&mut stop_at);
    tokio::pin!(shutdown);
    loop {
        let e = match finish(state, owner, job, end.clone()).await {
            Ok(()) => {
                state.storage.succeeded();
                state.storage.job_done(&job.id);
                if refusals > 0 {
                    tracing::info!(refusals, "the job's end was written once the storage took it");
                }
                return;
            }
            Err(e) => e,
        };
        match e {
            JobError::Storage(_) | JobError::Busy => {
                let cause = match e {
                    JobError::Storage(t) => {
                        state.storage.failed(t);
                        t.cause()
                    }
                    _ => "the database stays locked by other writes",
                };
                refusals += 1;
                let what = match end {
                    End::Released => "putting the job back in the queue",
                    _ => "storing the result",
                };
                state.storage.job_waits(
                    &job.id,
                    format!(
                        "{what}: waiting for the storage ({cause}); refused {refusals}×, next try in {:.1} s",
                        wait.as_secs_f64()
                    ),
                );
                tracing::warn!(
                    refusals,
                    retry_in_s = wait.as_secs_f64(),
                    trouble = cause,
                    "{what}: the storage refused; waiting"
                );
                if past_deadline {
                    tracing::error!("shutdown: the job could not be put back in the queue; the next start requeues it");
                    state.storage.job_done(&job.id);
                    return;
                }
                tokio::select! {
                    _ = tokio::time::sleep(wait) => {}
                    _ = &mut shutdown, if !past_deadline => {
                        // Out of time: put the job back in the queue (one try), the result dropped.
                        past_deadline = true;
                        end = End::Released;
                        continue;
                    }
                }
                wait = (wait * 2).min(STORE_RETRY_MAX);
                if let Ok(false) = db::jobs::heartbeat(&state.pool, &job.id, owner, state.lease, 0.0).await {
                    tracing::warn!("lease lost while waiting for the storage; abandoning the result");
                    state.storage.job_done(&job.id);
                    return;
                }
            }
            other => {
                if matches!(end, End::Done(_)) {
                    tracing::error!(error = %other, "the job's result could not be stored; it ends failed");
                    end = End::Failed(JobError::NotStored(format!(
                        "job {} computed its result, but the database refused to store it (the server's log has the cause); submit it again",
                        job.id
                    )));
                } else {
                    tracing::error!(error = %other, "writing the job's end failed; it stays leased and is requeued at the next start");
                    state.storage.job_done(&job.id);
                    return;
                }
            }
        }
    }
}

async fn finish(state: &JobContext, owner: &str, job: &db::jobs::JobRow, end: End) -> Result<(), JobError> {
    let end = match end {
        End::Released => {
            db::jobs::release(&state.pool, &job.id, owner).await?;
            tracing::info!("shutdown: job put back in the queue");
            return Ok(());
        }
        End::Done(out) => Ok(out),
        End::Failed(e) => Err(e),
    };
    // One write transaction reads the cancel flag and writes the end (BEGIN IMMEDIATE: the write
    // lock is held from the start, so no cancel can commit in between). A cancel committed before
    // it is seen here; one arriving later waits for the commit and finds the job ended. The final
    // UPDATE also requires the flag clear, so a result is never stored over a cancel.
    let mut tx = db::begin_write(&state.pool).await?;
    let cancelled = db::jobs::cancel_requested(&mut *tx, &job.id).await?;
    let held = match end {
        _ if cancelled => {
            let held = db::jobs::finish(&mut *tx, &job.id, owner, JobState::Cancelled, None, None).await?;
            if held {
                tracing::info!("job cancelled; its result was discarded");
            }
            held
        }
        Err(e) => {
            if let JobError::Internal(m) = &e {
                tracing::error!(error = %m, "job failed with an internal error");
            } else {
                tracing::info!(error = %e, "job failed");
            }
            let problem = (state.failure_json)(&e);
            db::jobs::finish(&mut *tx, &job.id, owner, JobState::Failed, None, Some(&problem)).await?
        }
        Ok(out) => {
            let result = run::store(&mut tx, &job.id, &job.robot_id, &job.request_json, out).await?;
            let result_json = serde_json::to_string(&result).expect("a result serialises");
            db::jobs::finish(&mut *tx, &job.id, owner, JobState::Succeeded, Some(&result_json), None).await?
        }
    };
    if held {
        tx.commit().await?;
        if !cancelled {
            // An identification may have activated its set.
            state.caches.robot_changed(&state.pool, &job.robot_id).await;
            tracing::info!("job finished");
        }
    } else {
        tx.rollback().await?;
        tracing::warn!("job no longer held at the end; its result was discarded");
    }
    Ok(())
}

/// A job's phases one at a time — claim, solve, end — for tests that put a cancel (or anything
/// else) between them. The workers run the same functions back to back (plus lease renewal).
#[doc(hidden)]
pub mod phases {
    use super::*;

    /// A job's computed end, not yet written.
    pub struct Solved(End);

    impl Solved {
        /// `"succeeded"` or `"failed"`: how the solver ended.
        pub fn outcome(&self) -> &'static str {
            match self.0 {
                End::Done(_) => "succeeded",
                End::Failed(_) => "failed",
                End::Released => "released",
            }
        }
    }

    /// Claim the oldest queued job for `owner`.
    pub async fn claim(ctx: &JobContext, owner: &str) -> Result<Option<db::jobs::JobRow>, sqlx::Error> {
        db::jobs::claim(&ctx.pool, owner, ctx.lease).await
    }

    /// Load the job's inputs and run its solver (off the async runtime).
    pub async fn solve(ctx: &JobContext, job: &db::jobs::JobRow) -> Solved {
        Solved(match run::load(&ctx.pool, job.kind, &job.robot_id, &job.request_json).await {
            Err(e) => End::Failed(e),
            Ok(inputs) => match tokio::task::spawn_blocking(move || run::compute(inputs, &|_, _| {})).await {
                Ok(Ok(out)) => End::Done(out),
                Ok(Err(e)) => End::Failed(e),
                Err(e) => End::Failed(JobError::Internal(format!("the solver task failed: {e}"))),
            },
        })
    }

    /// Write the job's end once: stored result, failure or (if asked for) cancelled.
    pub async fn end(ctx: &JobContext, owner: &str, job: &db::jobs::JobRow, solved: Solved) -> Result<(), JobError> {
        finish(ctx, owner, job, solved.0).await
    }

    /// Write the job's end as a worker does: storage trouble waited out (no shutdown comes here),
    /// a result that cannot be stored otherwise ending the job `failed`.
    pub async fn write(ctx: &JobContext, owner: &str, job: &db::jobs::JobRow, solved: Solved) {
        let (_never, stop) = watch::channel(None);
        write_end(ctx, owner, job, solved.0, &stop).await
    }
}
