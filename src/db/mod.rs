//! The store (sqlx, runtime-checked queries): one module per table group, one set of functions
//! for both backends — embedded SQLite (the default) and PostgreSQL (a plant's shared server,
//! issue 27), chosen by the `--db` value ([`Target`]). Documents are stored as the JSON text of
//! the file formats (mm, deg), so the store and the files share one contract.
//!
//! # One set of store functions on two databases: `sqlx::Any`
//!
//! The store runs on [`Pool`] = `sqlx::AnyPool` (sqlx 0.9's runtime-chosen driver), not on an
//! enum of a `SqlitePool` and a `PgPool`. Why, as checked in sqlx 0.9.0's sources:
//! - **One query text for both.** PostgreSQL takes `$1`, `$2`, …; SQLite takes them too (sqlx's
//!   SQLite driver reads the number after `$` as the parameter's index), so a store query is
//!   written once, with `$N`. (SQLite also takes `?`, PostgreSQL does not.)
//! - **The types the store uses are the ones `Any` carries**: `bool`, `i16/i32/i64`, `f32/f64`,
//!   `String`/`&str`, `Vec<u8>`, and NULLs of each. The schema needs nothing else: documents are
//!   TEXT on both sides (not jsonb), counts BIGINT, `progress` DOUBLE PRECISION, flags BOOLEAN
//!   (`migrations/postgres/0001_initial.sql`). Two gaps, closed in [`types`]: a flag comes back
//!   from SQLite as an INTEGER, which `Any` refuses to decode as `bool` ([`types::Flag`]); and
//!   sqlx's derived `Type` for text enums has no `Any` impl ([`types`]'s `text_enum!`).
//! - **Errors keep their driver's codes** (`Any` passes the driver's `DatabaseError` through), so
//!   [`storage_trouble`], [`is_busy`] and [`is_unique_violation`] (SQLite 2067/1555, SQLSTATE
//!   23505 — `DatabaseError::is_unique_violation` knows both) work unchanged.
//! - An enum would have put a `match` with two copies of every call in each of ~140 functions and
//!   doubled every executor type (pool, connection, transaction); `Any` costs a copy of each row
//!   into its own value type, small next to the JSON parsing every stored document gets.
//!
//! What `Any` loses — SQLite's typed connect options — is restored at connect: the pragmas
//! (WAL, `synchronous`, foreign keys, busy timeout) are set on every new connection
//! ([`connect_with`]), as `SqliteConnectOptions` did. Where the dialects differ the store asks
//! [`Backend::of`] and picks the text:
//! - **Write transactions.** SQLite: `BEGIN IMMEDIATE` (the one write lock, taken up front).
//!   PostgreSQL: `BEGIN` and then `pg_advisory_xact_lock(WRITE_LOCK)`, one lock per database
//!   held to COMMIT, so writers take turns there too: every read-then-write the store does
//!   (allocating a batch's `seq`, a set's version) stays correct as written for SQLite. Row locks
//!   (`SELECT … FOR UPDATE`, `SKIP LOCKED` for job claims) that let writers to different robots
//!   run at once are issue 27 item 2's step, measured then.
//! - `INSERT … ON CONFLICT` is the same on both; SQLite's two-argument `MAX(a, b)` is
//!   `GREATEST(a, b)`; `json_each` is `jsonb_array_elements(x::jsonb)`; booleans are bound as
//!   `bool` (SQLite stores 0/1, PostgreSQL BOOLEAN).
//! - **Sorting.** Ids and times are text compared bytewise by SQLite; PostgreSQL sorts text by
//!   the database's collation, so a database whose `datcollate` is not `C` (or its alias `POSIX`)
//!   is refused at connect ([`connect_url`]), with the command that makes a right one.
//!
//! SQLite durability: WAL with `synchronous = FULL`, so a transaction is on the disk (the WAL
//! fsynced) before its COMMIT returns — an answered write survives a power cut, not only a
//! killed process. Connections go back to the pool only outside a transaction ([`connect`]).

pub mod corrections;
pub mod health;
pub mod iso9283;
pub mod jobs;
pub mod paging;
pub mod records;
pub mod tokens;
pub mod transfer;
pub mod types;

use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

pub use health::StorageHealth;
use sqlx::any::AnyPoolOptions;
pub use sqlx::any::{Any, AnyExecutor};
pub use sqlx::sqlite::SqliteSynchronous;
pub use sqlx::{AnyConnection, AnyPool};
pub use sqlx::{Sqlite, Transaction};

/// The store's connection pool, on either backend.
pub type Pool = AnyPool;
/// One of the store's connections (what a transaction dereferences to).
pub type Conn = AnyConnection;

/// The SQLite migrations (`migrations/sqlite/`), embedded at compile time and applied at start-up.
pub static MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("./migrations/sqlite");

/// The PostgreSQL migrations (`migrations/postgres/`): the same schema in PostgreSQL's dialect,
/// step for step (`tests/suite/postgres_schema.rs` compares the two).
pub static POSTGRES_MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("./migrations/postgres");

/// The advisory-lock key a PostgreSQL write transaction holds to its end ("robocalw" in ASCII):
/// writers take turns, as SQLite's one write lock makes them.
pub const WRITE_LOCK: i64 = 0x726f_626f_6361_6c77;

/// Which database a pool or connection speaks to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    Sqlite,
    Postgres,
}

impl Backend {
    /// The backend of a pool.
    pub fn of(pool: &Pool) -> Backend {
        Backend::of_scheme(pool.connect_options().database_url.scheme())
    }

    /// The backend of a connection (or of a transaction, through `&*tx`).
    pub fn of_conn(conn: &Conn) -> Backend {
        if conn.backend_name().eq_ignore_ascii_case("postgresql") { Backend::Postgres } else { Backend::Sqlite }
    }

    fn of_scheme(scheme: &str) -> Backend {
        if scheme.starts_with("postgres") { Backend::Postgres } else { Backend::Sqlite }
    }
}

/// Where the store is, as `--db` / `ROBOCAL_DB` say it: a path or a `sqlite:` URL is an embedded
/// SQLite file; `postgres://…` (or `postgresql://…`) is a PostgreSQL server's database.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Target {
    Sqlite(PathBuf),
    Postgres(String),
}

impl Target {
    /// Read a `--db` value. `sqlite:x.db`, `sqlite://x.db` and `x.db` are the same file.
    pub fn parse(db: &Path) -> Target {
        let s = db.to_string_lossy();
        if s.starts_with("postgres://") || s.starts_with("postgresql://") {
            return Target::Postgres(s.into_owned());
        }
        match s.strip_prefix("sqlite:") {
            Some(rest) => Target::Sqlite(PathBuf::from(rest.strip_prefix("//").unwrap_or(rest))),
            None => Target::Sqlite(db.to_path_buf()),
        }
    }

    /// How to name the store in a message: the file, or the server URL without its password.
    pub fn display(&self) -> String {
        match self {
            Target::Sqlite(p) => p.display().to_string(),
            Target::Postgres(url) => redact(url),
        }
    }
}

/// Open (creating and migrating it as needed) the store `--db` names ([`Target::parse`]).
pub async fn open(db: &Path) -> Result<Pool, sqlx::Error> {
    match Target::parse(db) {
        Target::Sqlite(path) => connect(&path).await,
        Target::Postgres(url) => connect_url(&url).await,
    }
}

/// Open (creating it if missing) and migrate the database at `path`: WAL, `synchronous = FULL`,
/// foreign keys on, a busy timeout so concurrent writers wait instead of failing.
///
/// A connection goes back to the pool only outside any transaction. When a statement or the
/// COMMIT of a transaction fails for a full disk, a read-only file system or an I/O error,
/// SQLite may roll the transaction back by itself; the ROLLBACK sqlx then sends finds none, fails,
/// and sqlx goes on counting the transaction open. Back in the pool, that connection would answer
/// every later `BEGIN IMMEDIATE` with "attempted to call begin_with at non-zero transaction
/// depth" — each write that drew it a 500, long after the disk had space again. Such a connection
/// is closed instead (the pool opens a fresh one when needed).
pub async fn connect(path: &Path) -> Result<Pool, sqlx::Error> {
    connect_with(path, SqliteSynchronous::Full).await
}

/// [`connect`] with another `synchronous` setting. The service always uses `Full` (an answered
/// 201 survives a power cut); `Normal` exists for the benchmark that measures what that costs
/// (`benches/upload.rs`) and for scratch databases whose loss at a power cut does not matter.
pub async fn connect_with(path: &Path, synchronous: SqliteSynchronous) -> Result<Pool, sqlx::Error> {
    sqlx::any::install_default_drivers();
    // SQLite's name for a private in-memory database: one per connection, so the pool must keep
    // exactly one (a file URL would create a file named `:memory:` instead).
    if path.as_os_str() == ":memory:" {
        return connect_memory().await;
    }
    // Switching a new database to WAL needs an exclusive lock that SQLite's busy timeout does not
    // wait for, so a process opening the file while another creates it can get "database is
    // locked" at once: retry that for as long as the busy timeout would have waited.
    let deadline = tokio::time::Instant::now() + BUSY_TIMEOUT;
    loop {
        match open_and_migrate(path, synchronous).await {
            Err(e) if is_busy(&e) && tokio::time::Instant::now() < deadline => {
                tokio::time::sleep(Duration::from_millis(25)).await;
            }
            r => return r,
        }
    }
}

const BUSY_TIMEOUT: Duration = Duration::from_secs(10);

/// The `sqlite://` URL of a file, created when missing (`mode=rwc`). The path is made absolute
/// and every byte but `[A-Za-z0-9/._~-]` percent-encoded, so a `?`, `#`, `%` or space in it
/// stays part of the name (sqlx decodes the path before opening it).
fn sqlite_url(path: &Path) -> Result<String, sqlx::Error> {
    let abs = std::path::absolute(path).map_err(|e| sqlx::Error::Configuration(Box::new(e)))?;
    let mut url = String::from("sqlite://");
    for b in abs.as_os_str().as_encoded_bytes() {
        match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'/' | b'.' | b'_' | b'~' | b'-' => url.push(*b as char),
            _ => url.push_str(&format!("%{b:02X}")),
        }
    }
    url.push_str("?mode=rwc");
    Ok(url)
}

async fn open_and_migrate(path: &Path, synchronous: SqliteSynchronous) -> Result<Pool, sqlx::Error> {
    let sync = match synchronous {
        SqliteSynchronous::Off => "OFF",
        SqliteSynchronous::Normal => "NORMAL",
        SqliteSynchronous::Full => "FULL",
        SqliteSynchronous::Extra => "EXTRA",
    };
    let pool = AnyPoolOptions::new()
        .max_connections(8)
        .acquire_timeout(BUSY_TIMEOUT)
        .after_connect(move |conn, _| {
            Box::pin(async move {
                // What `SqliteConnectOptions` set, on every new connection: the busy timeout
                // first (the others may wait for a lock), WAL, then durability and foreign keys.
                use sqlx::Executor;
                conn.execute(sqlx::AssertSqlSafe(format!("PRAGMA busy_timeout = {}", BUSY_TIMEOUT.as_millis())))
                    .await?;
                conn.execute("PRAGMA journal_mode = WAL").await?;
                conn.execute(sqlx::AssertSqlSafe(format!("PRAGMA synchronous = {sync}"))).await?;
                conn.execute("PRAGMA foreign_keys = ON").await?;
                Ok(())
            })
        })
        .after_release(|conn, _| {
            Box::pin(async move {
                // A dropped transaction's ROLLBACK is queued on the connection's worker: the ping
                // waits for it, so the depth read next is the one it left.
                sqlx::Connection::ping(&mut *conn).await?;
                Ok(outside_transaction(conn, "returned to the pool"))
            })
        })
        .before_acquire(|conn, _| Box::pin(async move { Ok(outside_transaction(conn, "taken from the pool")) }))
        .connect(&sqlite_url(path)?)
        .await?;
    migrate(&pool).await?;
    Ok(pool)
}

/// Connect to a PostgreSQL database (`postgres://user@host/db`), check its collation and apply
/// [`POSTGRES_MIGRATOR`]. No exclusive lock: several servers may share the database (sqlx's
/// PostgreSQL migrations take an advisory lock, so servers starting together take turns).
pub async fn connect_url(url: &str) -> Result<Pool, sqlx::Error> {
    sqlx::any::install_default_drivers();
    let shown = redact(url);
    // One connection first: the pool's own error for an unreachable server is a timeout that
    // hides the reason (refused, unknown host, bad password).
    let unreachable = |e: sqlx::Error| match e {
        sqlx::Error::Database(_) => e,
        other => config_error(&format!("cannot reach the PostgreSQL server {shown}: {other}")),
    };
    sqlx::Connection::close(<AnyConnection as sqlx::Connection>::connect(url).await.map_err(unreachable)?).await?;
    let pool = AnyPoolOptions::new()
        .max_connections(16)
        .acquire_timeout(BUSY_TIMEOUT)
        .after_release(|conn, _| Box::pin(async move { Ok(outside_transaction(conn, "returned to the pool")) }))
        .connect(url)
        .await
        .map_err(unreachable)?;
    let collation: String =
        sqlx::query_scalar("SELECT datcollate::text FROM pg_database WHERE datname = current_database()")
            .fetch_one(&pool)
            .await?;
    if collation != "C" && collation != "POSIX" {
        pool.close().await;
        return Err(config_error(&format!(
            "the PostgreSQL database {shown} sorts text by the collation '{collation}', not bytewise as robocal needs \
             (ids and times must sort as in SQLite): create it with `CREATE DATABASE <name> LC_COLLATE 'C' LC_CTYPE 'C' \
             TEMPLATE template0` and point --db at it"
        )));
    }
    POSTGRES_MIGRATOR.run(&pool).await?;
    Ok(pool)
}

/// A PostgreSQL URL for messages: user, host, port and database, never the password.
pub fn redact(url: &str) -> String {
    url.parse::<sqlx::postgres::PgConnectOptions>()
        .map(|o| transfer::server_label(&o))
        .unwrap_or_else(|_| "(an unreadable PostgreSQL URL)".to_string())
}

fn config_error(msg: &str) -> sqlx::Error {
    sqlx::Error::Configuration(msg.to_string().into())
}

/// Whether a pooled connection is outside any transaction (sqlx's count); logged when not, since
/// the pool then closes it.
fn outside_transaction(conn: &Conn, when: &str) -> bool {
    let clean = !sqlx::Connection::is_in_transaction(conn);
    if !clean {
        tracing::warn!(
            "a database connection {when} was still inside a transaction (its rollback failed after a storage error): closed"
        );
    }
    clean
}

/// Apply the pending migrations on one connection of `pool`.
///
/// - Holding the write lock (`BEGIN IMMEDIATE`), so two processes opening a new database at once
///   (a server starting while `robocal token create` runs) take turns: the second waits, then
///   finds every migration applied. sqlx's own migration lock is a no-op on SQLite. (`run_direct`
///   is sqlx's documented way round `Acquire` lifetimes in spawned futures.)
/// - With foreign-key enforcement off while they run: a migration that rebuilds a table (SQLite
///   cannot alter a CHECK constraint) drops it, which the tables referencing it forbid otherwise.
///   `PRAGMA foreign_keys` is a no-op inside a transaction, so it is switched before `BEGIN`.
///   Before the commit `PRAGMA foreign_key_check` must find nothing, or everything is rolled
///   back. Enforcement is switched back on before the connection returns to the pool; a
///   connection where that cannot be confirmed is closed instead.
async fn migrate(pool: &Pool) -> Result<(), sqlx::Error> {
    let mut conn = pool.acquire().await?;
    sqlx::query("PRAGMA foreign_keys = OFF").execute(&mut *conn).await?;
    let migrated = migrate_locked(&mut conn).await;
    let restored = async {
        sqlx::query("PRAGMA foreign_keys = ON").execute(&mut *conn).await?;
        sqlx::query_scalar::<_, types::Flag>("PRAGMA foreign_keys").fetch_one(&mut *conn).await.map(|f| f.0)
    }
    .await;
    if !matches!(restored, Ok(true)) {
        let _ = conn.close().await;
    }
    migrated?;
    match restored {
        Ok(true) => Ok(()),
        Ok(false) => Err(migration_error("foreign-key enforcement could not be switched back on after migrating")),
        Err(e) => Err(e),
    }
}

async fn migrate_locked(conn: &mut Conn) -> Result<(), sqlx::Error> {
    let mut tx = sqlx::Connection::begin_with(&mut *conn, "BEGIN IMMEDIATE").await?;
    MIGRATOR.run_direct(None, &mut *tx, false).await?;
    // (table, rowid, parent table, foreign-key index) per violating row.
    let violations: Vec<(String, Option<i64>, String, i64)> =
        sqlx::query_as("PRAGMA foreign_key_check").fetch_all(&mut *tx).await?;
    if !violations.is_empty() {
        tx.rollback().await?;
        let shown: Vec<String> = violations
            .iter()
            .take(5)
            .map(|(table, rowid, parent, _)| match rowid {
                Some(r) => format!("{table} row {r} → {parent}"),
                None => format!("{table} → {parent}"),
            })
            .collect();
        return Err(migration_error(&format!(
            "the migrated database violates {} foreign key(s) ({}{}); nothing was migrated",
            violations.len(),
            shown.join(", "),
            if violations.len() > shown.len() { ", …" } else { "" }
        )));
    }
    tx.commit().await
}

fn migration_error(msg: &str) -> sqlx::Error {
    sqlx::Error::Migrate(Box::new(sqlx::migrate::MigrateError::Execute(sqlx::Error::Protocol(msg.to_string()))))
}

/// SQLITE_BUSY ("database is locked", primary result code 5).
pub fn is_busy(e: &sqlx::Error) -> bool {
    e.as_database_error().and_then(|d| d.code()).is_some_and(|c| c.parse::<i32>().is_ok_and(|c| c & 0xff == 5))
}

/// A private in-memory SQLite database (tests): one connection that is never recycled.
pub async fn connect_memory() -> Result<Pool, sqlx::Error> {
    sqlx::any::install_default_drivers();
    let pool = AnyPoolOptions::new()
        .max_connections(1)
        .idle_timeout(None)
        .max_lifetime(None)
        .after_connect(|conn, _| {
            Box::pin(async move {
                sqlx::Executor::execute(conn, "PRAGMA foreign_keys = ON").await?;
                Ok(())
            })
        })
        .connect("sqlite::memory:")
        .await?;
    migrate(&pool).await?;
    Ok(pool)
}

/// A write transaction that holds the write lock from its first statement: SQLite's
/// `BEGIN IMMEDIATE`; on PostgreSQL `BEGIN` and the [`WRITE_LOCK`] advisory lock, held to the
/// transaction's end (see the module's documentation).
pub async fn begin_write(pool: &Pool) -> Result<Transaction<'static, Any>, sqlx::Error> {
    match Backend::of(pool) {
        Backend::Sqlite => pool.begin_with("BEGIN IMMEDIATE").await,
        Backend::Postgres => {
            let mut tx = pool.begin().await?;
            sqlx::query("SELECT pg_advisory_xact_lock($1)").bind(WRITE_LOCK).execute(&mut *tx).await?;
            Ok(tx)
        }
    }
}

/// Now, RFC 3339 UTC with milliseconds (sorts as text).
pub fn now() -> String {
    humantime::format_rfc3339_millis(SystemTime::now()).to_string()
}

/// `SystemTime` → the stored text form.
pub fn time_text(t: SystemTime) -> String {
    humantime::format_rfc3339_millis(t).to_string()
}

/// A new time-ordered id (UUIDv7).
pub fn new_id() -> String {
    uuid::Uuid::now_v7().to_string()
}

/// Trouble with the storage under the database, not with the request: the disk is full, the
/// database cannot be written (read-only file or file system), or an I/O error. SQLite rolls the
/// statement's transaction back in each case, so nothing partial is left behind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StorageTrouble {
    /// SQLITE_FULL (13): the disk (or file-size limit) is exhausted.
    Full,
    /// SQLITE_READONLY (8): the database file or its file system is read-only.
    ReadOnly,
    /// SQLITE_IOERR (10) or SQLITE_CANTOPEN (14): the operating system refused a read or write.
    Io,
}

impl StorageTrouble {
    /// What is wrong, said plainly, without internals.
    pub fn cause(self) -> &'static str {
        match self {
            StorageTrouble::Full => "the disk holding the database is full (or the file-size limit is reached)",
            StorageTrouble::ReadOnly => "the database is read-only (its file or file system cannot be written)",
            StorageTrouble::Io => "the database could not be written (an I/O error from the operating system)",
        }
    }

    /// What happened to a refused request, for an operator: the cause, and that nothing of it
    /// was stored.
    pub fn describe(self) -> &'static str {
        match self {
            StorageTrouble::Full => {
                "the disk holding the database is full (or the file-size limit is reached): nothing of this request was stored; free space and retry"
            }
            StorageTrouble::ReadOnly => {
                "the database is read-only (its file or file system cannot be written): nothing of this request was stored"
            }
            StorageTrouble::Io => {
                "the database could not be written (an I/O error from the operating system): nothing of this request was stored"
            }
        }
    }
}

/// The storage trouble behind a database error, if that is what it is.
pub fn storage_trouble(e: &sqlx::Error) -> Option<StorageTrouble> {
    let code = e.as_database_error()?.code()?.parse::<i32>().ok()?;
    match code & 0xff {
        13 => Some(StorageTrouble::Full),
        8 => Some(StorageTrouble::ReadOnly),
        10 | 14 => Some(StorageTrouble::Io),
        _ => None,
    }
}

/// Whether an error is a UNIQUE (or primary-key) constraint violation.
pub fn is_unique_violation(e: &sqlx::Error) -> bool {
    e.as_database_error().is_some_and(|d| d.is_unique_violation())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `--db :memory:` is one private database for the whole pool, migrated, and no file.
    #[tokio::test]
    async fn the_memory_name_is_one_database_and_no_file() {
        let pool = connect(Path::new(":memory:")).await.unwrap();
        assert_eq!(Backend::of(&pool), Backend::Sqlite);
        let before: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM robots").fetch_one(&pool).await.unwrap();
        let mut held = pool.acquire().await.unwrap();
        sqlx::query("CREATE TABLE scratch (x INTEGER)").execute(&mut *held).await.unwrap();
        drop(held);
        let after: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM scratch").fetch_one(&pool).await.unwrap();
        assert_eq!((before, after), (0, 0));
        assert!(!Path::new(":memory:").exists(), "a file named :memory: was created");
    }
}
