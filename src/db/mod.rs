//! The SQLite store (sqlx, runtime-checked queries): one module per table group. Documents are
//! stored as the JSON text of the file formats (mm, deg), so the store and the files share one
//! contract. Every write that must be all-or-nothing runs in one `BEGIN IMMEDIATE` transaction
//! (immediate: the write lock is taken up front, so two writers never deadlock upgrading a
//! read lock).
//!
//! Durability: WAL with `synchronous = FULL`, so a transaction is on the disk (the WAL fsynced)
//! before its COMMIT returns — an answered write survives a power cut, not only a killed
//! process. Connections go back to the pool only outside a transaction ([`connect`]).

pub mod corrections;
pub mod health;
pub mod iso9283;
pub mod jobs;
pub mod paging;
pub mod records;
pub mod tokens;
pub mod transfer;

use std::path::Path;
use std::str::FromStr;
use std::time::{Duration, SystemTime};

pub use health::StorageHealth;
pub use sqlx::sqlite::SqliteSynchronous;
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions};
pub use sqlx::{Sqlite, SqlitePool, Transaction};

/// The SQLite migrations (`migrations/sqlite/`), embedded at compile time and applied at start-up.
pub static MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("./migrations/sqlite");

/// The PostgreSQL migrations (`migrations/postgres/`): the same schema in PostgreSQL's dialect,
/// step for step (`tests/postgres_schema.rs` compares the two). Not used by the store yet.
pub static POSTGRES_MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("./migrations/postgres");

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
pub async fn connect(path: &Path) -> Result<SqlitePool, sqlx::Error> {
    connect_with(path, SqliteSynchronous::Full).await
}

/// [`connect`] with another `synchronous` setting. The service always uses `Full` (an answered
/// 201 survives a power cut); `Normal` exists for the benchmark that measures what that costs
/// (`benches/upload.rs`) and for scratch databases whose loss at a power cut does not matter.
pub async fn connect_with(path: &Path, synchronous: SqliteSynchronous) -> Result<SqlitePool, sqlx::Error> {
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

async fn open_and_migrate(path: &Path, synchronous: SqliteSynchronous) -> Result<SqlitePool, sqlx::Error> {
    let opts = SqliteConnectOptions::new()
        .filename(path)
        .create_if_missing(true)
        .journal_mode(SqliteJournalMode::Wal)
        .synchronous(synchronous)
        .foreign_keys(true)
        .busy_timeout(BUSY_TIMEOUT);
    let pool = SqlitePoolOptions::new()
        .max_connections(8)
        .acquire_timeout(BUSY_TIMEOUT)
        .after_release(|conn, _| {
            Box::pin(async move {
                // A dropped transaction's ROLLBACK is queued on the connection's worker: the ping
                // waits for it, so the depth read next is the one it left.
                sqlx::Connection::ping(&mut *conn).await?;
                Ok(outside_transaction(conn, "returned to the pool"))
            })
        })
        .before_acquire(|conn, _| Box::pin(async move { Ok(outside_transaction(conn, "taken from the pool")) }))
        .connect_with(opts)
        .await?;
    migrate(&pool).await?;
    Ok(pool)
}

/// Whether a pooled connection is outside any transaction (sqlx's count); logged when not, since
/// the pool then closes it.
fn outside_transaction(conn: &sqlx::SqliteConnection, when: &str) -> bool {
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
async fn migrate(pool: &SqlitePool) -> Result<(), sqlx::Error> {
    let mut conn = pool.acquire().await?;
    sqlx::query("PRAGMA foreign_keys = OFF").execute(&mut *conn).await?;
    let migrated = migrate_locked(&mut conn).await;
    let restored = async {
        sqlx::query("PRAGMA foreign_keys = ON").execute(&mut *conn).await?;
        sqlx::query_scalar::<_, bool>("PRAGMA foreign_keys").fetch_one(&mut *conn).await
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

async fn migrate_locked(conn: &mut sqlx::SqliteConnection) -> Result<(), sqlx::Error> {
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

/// A private in-memory database (tests): one connection that is never recycled.
pub async fn connect_memory() -> Result<SqlitePool, sqlx::Error> {
    let opts = SqliteConnectOptions::from_str("sqlite::memory:")?.foreign_keys(true);
    let pool =
        SqlitePoolOptions::new().max_connections(1).idle_timeout(None).max_lifetime(None).connect_with(opts).await?;
    migrate(&pool).await?;
    Ok(pool)
}

/// A write transaction that holds the write lock from its first statement.
pub async fn begin_write(pool: &SqlitePool) -> Result<Transaction<'static, Sqlite>, sqlx::Error> {
    pool.begin_with("BEGIN IMMEDIATE").await
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
