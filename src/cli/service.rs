//! Service commands: run the server, manage its tokens, print its OpenAPI document, run the demo
//! loop through it.

use std::path::PathBuf;

use clap::{Args, Subcommand};
use serde_json::{Value, json};

use super::CliError;
use crate::domain::origin::CorsOrigins;

#[derive(Args, Debug)]
pub struct ServeArgs {
    /// SQLite database file or `sqlite:` URL (created and migrated on first start), or a
    /// `postgres://user@host/db` URL (migrated on start; its collation must be C).
    #[arg(long, env = "ROBOCAL_DB", default_value = "robocal.db")]
    pub db: PathBuf,
    /// Address to listen on. Any non-loopback address requires bearer tokens.
    #[arg(long, env = "ROBOCAL_BIND", default_value = "127.0.0.1:8080")]
    pub bind: String,
    /// Job workers (each runs one solver at a time).
    #[arg(long, env = "ROBOCAL_WORKERS", default_value_t = 1)]
    pub workers: usize,
    /// Require bearer tokens on a loopback address too.
    #[arg(long, env = "ROBOCAL_REQUIRE_AUTH")]
    pub require_auth: bool,
    /// Most measurements or compensation targets per request.
    #[arg(long, env = "ROBOCAL_MAX_BATCH", default_value_t = 10_000)]
    pub max_batch: usize,
    /// Seconds a shutdown (SIGTERM, Ctrl-C) waits for requests in flight and running jobs: then
    /// jobs still running go back in the queue, open connections are dropped, and the process
    /// exits (within a second or two more).
    #[arg(long, env = "ROBOCAL_SHUTDOWN_GRACE_S", default_value_t = 10)]
    pub grace_s: u64,
    /// Seconds of a claimed job's lease (renewed every sixth of it while the job runs): how long
    /// a job whose server died waits before a replica sharing the PostgreSQL database takes it
    /// over (on SQLite, the next start takes it at once). At least 3.
    #[arg(long, env = "ROBOCAL_JOB_LEASE_S", default_value_t = 60)]
    pub job_lease_s: u64,
    /// Seconds a client may take to send a request's headers; a kept-alive connection idle that
    /// long is closed too.
    #[arg(long, env = "ROBOCAL_HEADER_TIMEOUT_S", default_value_t = 10)]
    pub header_timeout_s: u64,
    /// Most client connections open at once; past it new connections wait (in the listener's
    /// backlog) until one closes. Keep it under the process's open-file limit (`ulimit -n`).
    #[arg(long, env = "ROBOCAL_MAX_CONNECTIONS", default_value_t = 1000)]
    pub max_connections: usize,
    /// Slowest accepted request body, bytes per second on average once 10 s have passed (the
    /// time allowed grows by a second for each this many bytes received); slower is cut with 408.
    #[arg(long, env = "ROBOCAL_MIN_BODY_RATE", default_value_t = 1024)]
    pub min_body_rate: u64,
    /// Log format on stderr: text (coloured only on a terminal, never with NO_COLOR set) or json
    /// (one object per line, for log shippers). RUST_LOG sets the levels (default info).
    #[arg(long, env = "ROBOCAL_LOG_FORMAT", value_enum, default_value_t = LogFormat::Text)]
    pub log_format: LogFormat,
    /// A browser origin whose pages may call the API (CORS), e.g. https://dash.example.com:
    /// repeat it or separate origins with commas; * alone allows any origin. Off by default: no
    /// CORS headers, so browsers keep other sites' pages from reading the API.
    #[arg(long = "cors-origin", env = "ROBOCAL_CORS_ORIGINS", value_name = "ORIGIN", value_delimiter = ',')]
    pub cors_origins: Vec<String>,
}

/// How `serve` writes its log (to stderr).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum LogFormat {
    /// Lines for people; ANSI colour only when stderr is a terminal and NO_COLOR is unset.
    Text,
    /// One JSON object per line: timestamp, level, fields (message and the event's own), target,
    /// the current span (an HTTP request's method, uri and request_id) and the span list.
    Json,
}

#[derive(Subcommand, Debug)]
pub enum TokenCommand {
    /// Create a token; prints its secret once.
    Create {
        #[command(flatten)]
        db: TokenDb,
        /// Who uses it, e.g. cell-3-pc.
        #[arg(long)]
        name: String,
        /// Comma-separated: measure, calibrate, compensate, read, admin.
        #[arg(long)]
        scopes: String,
    },
    /// List tokens (never their secrets).
    List {
        #[command(flatten)]
        db: TokenDb,
    },
    /// Revoke a token by id (a running server stops accepting it within a second; revoking
    /// over HTTP, DELETE /v1/tokens/{id}, takes effect at once).
    Revoke {
        #[command(flatten)]
        db: TokenDb,
        id: String,
    },
}

/// The database the token commands write (the server's, directly).
#[derive(Args, Debug)]
pub struct TokenDb {
    #[arg(long, env = "ROBOCAL_DB", default_value = "robocal.db")]
    pub db: PathBuf,
}

#[derive(Args, Debug)]
pub struct OpenapiArgs {
    /// Write here instead of printing.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct DemoArgs {
    /// A running server (http://host:port); default: start one in-process on a temporary database.
    #[arg(long)]
    pub url: Option<String>,
    /// Bearer token for --url (scopes measure, calibrate, compensate, read).
    #[arg(long, env = "ROBOCAL_TOKEN")]
    pub token: Option<String>,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// DETMAX-selected identification poses.
    #[arg(long, default_value_t = 75)]
    pub select: usize,
    /// Compensated targets checked against the simulator's truth.
    #[arg(long, default_value_t = 300)]
    pub targets: usize,
}

fn runtime() -> Result<tokio::runtime::Runtime, CliError> {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError::msg(format!("cannot start the async runtime: {e}")))
}

fn init_tracing(format: LogFormat) {
    use std::io::IsTerminal;
    use tracing_subscriber::EnvFilter;
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info,sqlx=warn"));
    let log = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr);
    let _ = match format {
        LogFormat::Text => {
            log.with_ansi(colour(std::io::stderr().is_terminal(), std::env::var_os("NO_COLOR"))).try_init()
        }
        LogFormat::Json => log.json().with_ansi(false).try_init(),
    };
}

/// ANSI colour in the text log: only on a terminal (a file, a pipe or journald gets plain text),
/// and never when `NO_COLOR` is set to anything but the empty string (no-color.org).
fn colour(terminal: bool, no_color: Option<std::ffi::OsString>) -> bool {
    terminal && no_color.is_none_or(|v| v.is_empty())
}

pub(super) fn serve(a: ServeArgs) -> Result<String, CliError> {
    use crate::server::{ServeOptions, serve, shutdown_signal};
    let bind: std::net::SocketAddr =
        a.bind.parse().map_err(|e| CliError::arg("--bind", format!("'{}' is not host:port ({e})", a.bind)))?;
    if a.workers == 0 {
        return Err(CliError::arg("--workers", "must be at least 1"));
    }
    if a.max_batch == 0 {
        return Err(CliError::arg("--max-batch", "must be at least 1"));
    }
    if a.header_timeout_s == 0 {
        return Err(CliError::arg("--header-timeout-s", "must be at least 1"));
    }
    if a.max_connections == 0 {
        return Err(CliError::arg("--max-connections", "must be at least 1"));
    }
    if a.min_body_rate == 0 {
        return Err(CliError::arg("--min-body-rate", "must be at least 1 byte a second"));
    }
    let job_lease = std::time::Duration::from_secs(a.job_lease_s);
    if job_lease < crate::jobs::LEASE_MIN {
        return Err(CliError::arg(
            "--job-lease-s",
            format!("must be at least {} s (it is renewed every sixth of it)", crate::jobs::LEASE_MIN.as_secs()),
        ));
    }
    let cors = CorsOrigins::parse(&a.cors_origins, "--cors-origin").map_err(|e| CliError::msg(e.to_string()))?;
    init_tracing(a.log_format);
    let mut opts = ServeOptions::new(a.db.clone(), bind);
    opts.workers = a.workers;
    opts.require_auth = a.require_auth;
    opts.grace = std::time::Duration::from_secs(a.grace_s);
    opts.header_timeout = std::time::Duration::from_secs(a.header_timeout_s);
    opts.max_connections = a.max_connections;
    opts.config.max_batch = a.max_batch;
    opts.config.body_min_rate = a.min_body_rate;
    opts.config.cors = cors;
    opts.config.job_lease = job_lease;
    let rt = runtime()?;
    // The signal handlers are installed now, inside the runtime, before the server answers.
    let shutdown = {
        let _in_runtime = rt.enter();
        shutdown_signal()
    };
    let served = rt.block_on(serve(opts, None, shutdown));
    // A solver thread still running (its job was put back in the queue at the deadline) is not
    // waited for: the process exits and the thread with it.
    rt.shutdown_timeout(std::time::Duration::from_millis(200));
    served.map_err(|e| {
        if a.log_format == LogFormat::Json {
            // A log shipper sees why the server stopped too (the plain `error:` line follows).
            tracing::error!(error = %e, "robocal cannot serve");
        }
        CliError::msg(e.to_string())
    })?;
    Ok("robocal stopped".into())
}

pub(super) fn token(t: TokenCommand) -> Result<String, CliError> {
    use crate::db::tokens;
    let rt = runtime()?;
    rt.block_on(async {
        let open = |TokenDb { db }: TokenDb| async move {
            crate::db::open(&db).await.map_err(|e| CliError::msg(format!("{}: {e}", crate::db::Target::parse(&db).display())))
        };
        match t {
            TokenCommand::Create { db, name, scopes } => {
                let scopes = tokens::parse_scopes(&scopes).map_err(|e| CliError::arg("--scopes", e))?;
                let name = crate::domain::limits::name(&name, "--name").map_err(|e| CliError::arg("--name", e.to_string()))?;
                let pool = open(db).await?;
                let (row, secret) = tokens::create(&pool, name.trim(), &scopes).await.map_err(|e| CliError::msg(e.to_string()))?;
                pool.close().await;
                Ok(serde_json::to_string_pretty(&json!({
                    "id": row.id, "name": row.name, "scopes": row.scopes.split(' ').collect::<Vec<_>>(),
                    "token": secret, "note": "the token is shown only now; send it as Authorization: Bearer <token>",
                }))
                .expect("json"))
            }
            TokenCommand::List { db } => {
                let pool = open(db).await?;
                let rows = tokens::list(&pool).await.map_err(|e| CliError::msg(e.to_string()))?;
                pool.close().await;
                let v: Vec<Value> = rows
                    .iter()
                    .map(|r| json!({"id": r.id, "name": r.name, "scopes": r.scopes, "created_at": r.created_at, "revoked_at": r.revoked_at}))
                    .collect();
                Ok(serde_json::to_string_pretty(&v).expect("json"))
            }
            TokenCommand::Revoke { db, id } => {
                let pool = open(db).await?;
                let ok = tokens::revoke(&pool, &id).await.map_err(|e| CliError::msg(e.to_string()))?;
                pool.close().await;
                if ok { Ok(format!("revoked {id}")) } else { Err(CliError::msg(format!("no live token '{id}'"))) }
            }
        }
    })
}

pub(super) fn demo(a: DemoArgs) -> Result<String, CliError> {
    use crate::demo::{DemoOptions, run, table};
    use crate::http::client::Client;
    if a.select < 31 {
        return Err(CliError::arg("--select", "at least 31 poses are needed for the 31 identifiable parameters"));
    }
    if a.targets == 0 {
        return Err(CliError::arg("--targets", "must be at least 1"));
    }
    let opts = DemoOptions { seed: a.seed, select: a.select, targets: a.targets, ..Default::default() };
    runtime()?.block_on(async {
        let bar = super::progress::Progress::steps("demo");
        let mut log = |s: &str| {
            bar.line(s);
            bar.inc();
        };
        match &a.url {
            Some(url) => {
                let client = Client::new(url, a.token.clone()).map_err(|e| CliError::arg("--url", e))?;
                bar.line(&format!("robocal demo against {url}"));
                let r = run(&client, &opts, &mut log).await.map_err(|e| CliError::msg(e.to_string()))?;
                Ok(table(&r))
            }
            None => {
                let dir = std::env::temp_dir();
                let db = dir.join(format!("robocal-demo-{}-{}.db", std::process::id(), crate::db::new_id()));
                let server =
                    crate::server::start(crate::server::ServeOptions::new(db.clone(), ([127, 0, 0, 1], 0).into()))
                        .await
                        .map_err(|e| CliError::msg(e.to_string()))?;
                bar.line(&format!("robocal demo: in-process server at {} on {}", server.url(), db.display()));
                let client = Client::new(&server.url(), None).map_err(|e| CliError::msg(e.to_string()))?;
                let r = run(&client, &opts, &mut log).await;
                let _ = server.stop().await;
                for suffix in ["", "-wal", "-shm", ".lock"] {
                    let _ = std::fs::remove_file(format!("{}{suffix}", db.display()));
                }
                Ok(table(&r.map_err(|e| CliError::msg(e.to_string()))?))
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colour_only_on_a_terminal_without_no_color() {
        assert!(colour(true, None));
        assert!(colour(true, Some("".into())), "an empty NO_COLOR is unset (no-color.org)");
        assert!(!colour(true, Some("1".into())));
        assert!(!colour(false, None));
        assert!(!colour(false, Some("1".into())));
    }
}
