//! `robocal serve`: one long-running process on an embedded SQLite database. Takes the database's
//! lock (one server per database: [`lock`]), opens (creating it on first start) and migrates the
//! database, binds, requeues jobs a killed predecessor left running, starts the job workers, serves
//! HTTP until SIGTERM or Ctrl-C, then stops accepting, lets requests in flight and running jobs
//! finish within a grace period, requeues the jobs still running and drops the connections still
//! open when it ends.

pub mod conn;
pub mod lock;

use std::future::Future;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use tokio::sync::oneshot;

use crate::db;
use crate::http::{AppState, ServiceConfig, app};
use crate::jobs::Workers;
use lock::{DbLock, LockError};

/// How to serve.
#[derive(Clone, Debug)]
pub struct ServeOptions {
    pub db: PathBuf,
    pub bind: SocketAddr,
    /// Job workers (solver threads); each runs one job at a time.
    pub workers: usize,
    /// Require bearer tokens even on a loopback address (always required on other addresses).
    pub require_auth: bool,
    /// How long a shutdown waits for requests in flight and running jobs: then jobs still running
    /// are put back in the queue and connections still open are dropped.
    pub grace: Duration,
    /// How long a client may take to send a request's headers (and an idle kept-alive
    /// connection may stay open).
    pub header_timeout: Duration,
    /// Most connections open at once; past it new ones wait in the listener's backlog.
    pub max_connections: usize,
    pub config: ServiceConfig,
}

impl ServeOptions {
    pub fn new(db: PathBuf, bind: SocketAddr) -> Self {
        Self {
            db,
            bind,
            workers: 1,
            require_auth: false,
            grace: Duration::from_secs(10),
            header_timeout: Duration::from_secs(10),
            max_connections: 1000,
            config: ServiceConfig::default(),
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// Another server holds the database (or its lock file cannot be made).
    #[error(transparent)]
    Locked(#[from] LockError),
    #[error("database {path}: {source}")]
    Db { path: String, source: sqlx::Error },
    #[error("cannot listen on {addr}: {source}")]
    Bind { addr: SocketAddr, source: std::io::Error },
    #[error("serving: {0}")]
    Serve(std::io::Error),
}

/// Resolves on SIGTERM or Ctrl-C (SIGINT). The handlers are installed by this call, not when the
/// future is first polled: a SIGTERM that arrives after the call — even before the server has
/// started polling its shutdown future, as soon as `/readyz` answers — is a clean stop, never the
/// default action that kills the process. Call it within the runtime (`Runtime::enter`).
pub fn shutdown_signal() -> impl Future<Output = ()> + Send + 'static {
    #[cfg(unix)]
    let (mut terminate, mut interrupt) = {
        use tokio::signal::unix::{SignalKind, signal};
        (signal(SignalKind::terminate()).ok(), signal(SignalKind::interrupt()).ok())
    };
    async move {
        #[cfg(unix)]
        {
            let term = async {
                match terminate.as_mut() {
                    Some(s) => drop(s.recv().await),
                    None => std::future::pending::<()>().await,
                }
            };
            let int = async {
                match interrupt.as_mut() {
                    Some(s) => drop(s.recv().await),
                    None => std::future::pending::<()>().await,
                }
            };
            tokio::select! {
                _ = term => {}
                _ = int => {}
            }
        }
        #[cfg(not(unix))]
        let _ = tokio::signal::ctrl_c().await;
        tracing::info!("shutdown signal received");
    }
}

/// Serve until `shutdown` resolves. `ready` receives the bound address (useful with port 0).
pub async fn serve(
    opts: ServeOptions,
    ready: Option<oneshot::Sender<SocketAddr>>,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> Result<(), ServeError> {
    // Before anything touches the database: a second server on it is refused here.
    // (SQLite only: several servers may share a PostgreSQL database, issue 27.)
    let target = db::Target::parse(&opts.db);
    let mut lock = match &target {
        db::Target::Sqlite(path) => DbLock::acquire(path)?,
        db::Target::Postgres(_) => None,
    };
    let pool = db::open(&opts.db).await.map_err(|source| ServeError::Db { path: target.display(), source })?;
    let require_auth = opts.require_auth || !opts.bind.ip().is_loopback();
    if require_auth {
        let live =
            db::tokens::list(&pool).await.map(|t| t.iter().filter(|t| t.revoked_at.is_none()).count()).unwrap_or(0);
        if live == 0 {
            tracing::warn!(
                "bearer tokens are required but none exists: create one with `robocal token create --db {} --name admin --scopes admin`",
                target.display()
            );
        }
    }
    // Bound before the workers start, so that a refused address leaves no worker behind (an
    // in-process server's would otherwise go on claiming jobs without the lock).
    let listener = match tokio::net::TcpListener::bind(opts.bind).await {
        Ok(l) => l,
        Err(source) => {
            pool.close().await;
            return Err(ServeError::Bind { addr: opts.bind, source });
        }
    };
    let addr = listener.local_addr().map_err(ServeError::Serve)?;
    let config = ServiceConfig { require_auth, ..opts.config.clone() };
    let state = AppState::new(pool.clone(), config);
    // Replicas sharing a PostgreSQL database tell each other what changed (the caches' module).
    let listener_task = match &target {
        db::Target::Postgres(url) => Some(tokio::spawn(crate::app::cache::listen(url.clone(), state.caches.clone()))),
        db::Target::Sqlite(_) => None,
    };
    let workers = Workers::start(state.clone(), opts.workers, opts.grace)
        .await
        .map_err(|source| ServeError::Db { path: target.display(), source })?;
    if let Some(lock) = lock.as_mut()
        && let Err(e) = lock.listening(addr)
    {
        tracing::warn!(lock_file = %lock.path().display(), error = %e, "cannot record the address in the lock file");
    }
    tracing::info!(
        %addr, db = %target.display(), require_auth, workers = opts.workers, cors = %opts.config.cors, "robocal serving"
    );
    if let Some(tx) = ready {
        let _ = tx.send(addr);
    }
    // One deadline for the requests in flight and the running jobs, from the signal on.
    let grace = opts.grace;
    let limits = conn::ConnLimits { header_timeout: opts.header_timeout, max_connections: opts.max_connections };
    conn::serve(listener, app(state), limits, shutdown, || {
        let deadline = tokio::time::Instant::now() + grace;
        tracing::info!(grace_s = grace.as_secs_f64(), "shutting down: no new connections or jobs");
        workers.stop(deadline);
        deadline
    })
    .await;
    workers.shutdown().await;
    if let Some(t) = listener_task {
        t.abort();
    }
    if tokio::time::timeout(Duration::from_secs(1), pool.close()).await.is_err() {
        tracing::warn!("shutdown: database connections still busy after 1 s; closing regardless");
    }
    drop(lock); // only now may another server open the database
    tracing::info!("stopped");
    Ok(())
}

/// A server running in this process (the demo's default, tests): its address and how to stop it.
pub struct Running {
    pub addr: SocketAddr,
    stop: Option<oneshot::Sender<()>>,
    handle: tokio::task::JoinHandle<Result<(), ServeError>>,
}

impl Running {
    pub fn url(&self) -> String {
        format!("http://{}", self.addr)
    }

    /// Graceful shutdown; waits for it.
    pub async fn stop(mut self) -> Result<(), ServeError> {
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        self.handle.await.unwrap_or(Ok(()))
    }
}

/// Start a server in this process on `opts.bind` (use port 0 for any free port).
pub async fn start(opts: ServeOptions) -> Result<Running, ServeError> {
    let (ready_tx, ready_rx) = oneshot::channel();
    let (stop_tx, stop_rx) = oneshot::channel::<()>();
    let handle = tokio::spawn(serve(opts, Some(ready_tx), async {
        let _ = stop_rx.await;
    }));
    match ready_rx.await {
        Ok(addr) => Ok(Running { addr, stop: Some(stop_tx), handle }),
        Err(_) => Err(handle.await.map_or_else(
            |e| ServeError::Serve(std::io::Error::other(e.to_string())),
            |r| {
                r.err()
                    .unwrap_or_else(|| ServeError::Serve(std::io::Error::other("the server stopped before listening")))
            },
        )),
    }
}
