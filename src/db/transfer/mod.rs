//! Moving a plant's store from SQLite to PostgreSQL (issue 27, item 3): `robocal migrate`.
//!
//! Every row of every table is copied, table by table in foreign-key order, each in primary-key
//! order and in batches (one INSERT of up to `batch_rows` rows each, so one transaction each).
//! The tables, their columns and their types are read from the two catalogues (SQLite's
//! `sqlite_master` and pragmas, PostgreSQL's `information_schema` and `pg_constraint`), not
//! listed here: a table or column one side lacks is a schema mismatch, said before anything is
//! copied. Values are converted by the *target* column's type: SQLite's 0/1 to BOOLEAN, INTEGER
//! to BIGINT, REAL to DOUBLE PRECISION, TEXT to TEXT, BLOB to BYTEA, NULL kept; anything else
//! (a 2 in a flag column, text in a number column) is refused naming the table, row and column.
//!
//! - **Source**: opened read-only, refused unless it is at this robocal's latest SQLite migration.
//!   It is read inside one read transaction from the first count to the last checksum, so the
//!   copy and its verification see one snapshot.
//! - **Target**: refused unless every table in its schema is empty — checked before anything is
//!   written to it, migrations included — then migrated (`db::POSTGRES_MIGRATOR`) and marked: a
//!   table `_robocal_migration` records the source (its canonical path) and its fingerprint (the
//!   migration it is at and each table's row count). A target holding that marker for the same
//!   source and fingerprint is an unfinished migration, and the same command resumes it: each
//!   table continues after the last primary key the target holds (the batches commit in key
//!   order, so the target holds a prefix of each table). A session-level advisory lock keeps two
//!   `migrate` runs off one target.
//! - **Cycles**: `robots.active_parameter_set_id` → `parameter_sets` → `robots`. Such a nullable
//!   foreign-key column is written NULL with its row and set once every table is copied.
//! - **Verification**: per table, the row count and a SHA-256 over a canonical text of every row
//!   in primary-key order, computed on both sides with one encoding (below). The marker is removed
//!   only when every table matches.
//!
//! Primary-key order is the same on both sides: SQLite compares text bytewise (BINARY), and the
//! PostgreSQL side orders text keys `COLLATE "C"` (bytewise too), whatever the database's default.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

mod tables;
mod values;

use sqlx::postgres::{PgArguments, PgConnectOptions, PgRow};
use sqlx::sqlite::{SqliteArguments, SqliteConnectOptions, SqliteRow};
use sqlx::{Connection, PgConnection, Postgres, Row, Sqlite, SqliteConnection};
pub use tables::{Column, ForeignKey, TableCheck, TableOrder, TablePlan, Verification, order_tables};
pub use values::{PgType, Value, convert, encode_row};
use values::{hex, quote};

/// The marker of a migration in progress, in the target.
pub const MARKER_TABLE: &str = "_robocal_migration";

/// sqlx's own bookkeeping table, never copied.
const SQLX_TABLE: &str = "_sqlx_migrations";

/// The advisory-lock key `migrate` holds on the target for its whole run ("robocalm" in ASCII).
const ADVISORY_KEY: i64 = 0x726f_626f_6361_6c6d;

/// PostgreSQL's limit on bind parameters per statement.
const MAX_BINDS: usize = 65_535;

/// How a run copies.
#[derive(Clone, Debug)]
pub struct Options {
    /// Rows per batch (one INSERT, one transaction); fewer when the table has so many columns
    /// that the batch would pass PostgreSQL's 65,535 bind parameters.
    pub batch_rows: usize,
    /// Stop with [`TransferError::Interrupted`] once this many batches are committed: a test hook
    /// standing for a killed process (the CLI never sets it).
    pub stop_after_batches: Option<usize>,
}

impl Default for Options {
    fn default() -> Self {
        Options { batch_rows: 1000, stop_after_batches: None }
    }
}

/// Why a migration was refused or stopped; each names its reason.
#[derive(Debug, thiserror::Error)]
pub enum TransferError {
    #[error("the source {path}: {reason}")]
    Source { path: String, reason: String },
    #[error(
        "the source {path} is not at this robocal's latest migration ({detail}): run `robocal serve --db {path}` (or `robocal token list --db {path}`) once on it to bring it up to date, then migrate"
    )]
    SourceNotMigrated { path: String, detail: String },
    #[error("cannot reach the PostgreSQL server {server}: {reason}")]
    Unreachable { server: String, reason: String },
    #[error("schema mismatch between the source and the target: {0}")]
    SchemaMismatch(String),
    #[error("the target database is not empty ({0}): migrate copies into an empty database only; nothing was written")]
    TargetNotEmpty(String),
    #[error("the target holds an unfinished migration of another source: {0}; nothing was written")]
    OtherMigration(String),
    #[error("another `robocal migrate` is writing the target database")]
    Busy,
    #[error("{table}, row {key}, column {column}: {reason}")]
    Value { table: String, key: String, column: String, reason: String },
    #[error("{during}: {source}")]
    Database {
        during: String,
        #[source]
        source: sqlx::Error,
    },
    #[error("stopped after {0} batches (test hook)")]
    Interrupted(usize),
}

fn db_err(during: impl Into<String>) -> impl FnOnce(sqlx::Error) -> TransferError {
    let during = during.into();
    move |source| TransferError::Database { during, source }
}

/// `--from`: `sqlite:PATH`, `sqlite://PATH` or a plain path.
pub fn source_path(arg: &str) -> PathBuf {
    let rest = arg.strip_prefix("sqlite://").or_else(|| arg.strip_prefix("sqlite:")).unwrap_or(arg);
    PathBuf::from(rest)
}

/// What a copy did, per table: rows found already in the target, rows copied, batches.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CopyStats {
    pub tables: Vec<(String, u64, u64, u64)>,
}

/// A migration under way: the source in its read transaction, the target locked and marked.
pub struct Migration {
    source_label: String,
    src: SqliteConnection,
    dst: PgConnection,
    plans: Vec<TablePlan>,
    resumed: bool,
    batches: usize,
    /// Whether text keys need `COLLATE "C"` on the target (its collation is not bytewise).
    collate_c: bool,
}

/// The server a URL names, for messages (never its password).
pub fn server_label(opts: &PgConnectOptions) -> String {
    format!(
        "{}@{}:{}/{}",
        opts.get_username(),
        opts.get_host(),
        opts.get_port(),
        opts.get_database().unwrap_or(opts.get_username())
    )
}

/// Open the source read-only and check it, reach the target, check it is empty (or holds this
/// source's unfinished migration), migrate and mark it, and plan the copy.
pub async fn prepare(source: &Path, target: &PgConnectOptions) -> Result<Migration, TransferError> {
    let shown = source.display().to_string();
    let src_err = |reason: String| TransferError::Source { path: shown.clone(), reason };
    let canonical = std::fs::canonicalize(source).map_err(|e| src_err(format!("cannot open: {e}")))?;
    if !canonical.is_file() {
        return Err(src_err("not a file".into()));
    }
    let opts = SqliteConnectOptions::new().filename(&canonical).read_only(true).create_if_missing(false);
    let mut src = SqliteConnection::connect_with(&opts).await.map_err(|e| src_err(format!("cannot open: {e}")))?;
    // One read transaction (a snapshot, in WAL mode) from here to the last checksum.
    sqlx::query("BEGIN").execute(&mut src).await.map_err(|e| src_err(format!("cannot read: {e}")))?;
    check_source_migrations(&mut src, &shown).await?;
    let source_tables =
        sqlite_tables(&mut src).await.map_err(|e| src_err(format!("cannot read its catalogue: {e}")))?;
    let mut counts = BTreeMap::new();
    for t in source_tables.keys() {
        let n: i64 = sqlx::query_scalar(sqlx::AssertSqlSafe(format!("SELECT count(*) FROM {}", quote(t))))
            .fetch_one(&mut src)
            .await
            .map_err(|e| src_err(format!("cannot count {t}: {e}")))?;
        counts.insert(t.clone(), n);
    }
    let latest = crate::db::MIGRATOR.iter().map(|m| m.version).max().unwrap_or(0);
    let fingerprint = serde_json::json!({ "migration": latest, "rows": counts }).to_string();
    let source_label = canonical.display().to_string();

    let server = server_label(target);
    let mut dst = PgConnection::connect_with(target)
        .await
        .map_err(|e| TransferError::Unreachable { server: server.clone(), reason: e.to_string() })?;
    // A run killed a moment ago holds the lock until its server session notices the closed
    // socket: wait a little before calling the target busy.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(5);
    loop {
        let locked: bool = sqlx::query_scalar("SELECT pg_try_advisory_lock($1)")
            .bind(ADVISORY_KEY)
            .fetch_one(&mut dst)
            .await
            .map_err(db_err("taking the target's migration lock"))?;
        if locked {
            break;
        }
        if std::time::Instant::now() > deadline {
            return Err(TransferError::Busy);
        }
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    }

    let resumed = match read_marker(&mut dst).await? {
        Some((marked_source, marked_fp)) => {
            if marked_source != source_label {
                return Err(TransferError::OtherMigration(format!(
                    "it was started from {marked_source}, not {source_label}; run the same command as then, or empty the target"
                )));
            }
            if marked_fp != fingerprint {
                return Err(TransferError::OtherMigration(format!(
                    "{source_label} changed since it was started (then {marked_fp}, now {fingerprint}); empty the target and start again"
                )));
            }
            true
        }
        None => {
            let occupied = occupied_tables(&mut dst).await?;
            if !occupied.is_empty() {
                return Err(TransferError::TargetNotEmpty(occupied.join(", ")));
            }
            false
        }
    };

    crate::db::POSTGRES_MIGRATOR.run(&mut dst).await.map_err(|e| {
        TransferError::SchemaMismatch(format!("the target's migrations do not match this robocal's: {e}"))
    })?;
    let (target_tables, keys, fks) = postgres_catalogue(&mut dst).await?;
    let plans = plan(&source_tables, &target_tables, &keys, &fks)?;

    if !resumed {
        let mut tx = dst.begin().await.map_err(db_err("marking the target"))?;
        sqlx::query(sqlx::AssertSqlSafe(format!(
            "CREATE TABLE {MARKER_TABLE} (only_row BOOLEAN PRIMARY KEY DEFAULT TRUE CHECK (only_row), \
             source TEXT NOT NULL, fingerprint TEXT NOT NULL, started_at TEXT NOT NULL)"
        )))
        .execute(&mut *tx)
        .await
        .map_err(db_err("marking the target"))?;
        sqlx::query(sqlx::AssertSqlSafe(format!(
            "INSERT INTO {MARKER_TABLE} (source, fingerprint, started_at) VALUES ($1, $2, $3)"
        )))
        .bind(&source_label)
        .bind(&fingerprint)
        .bind(crate::db::now())
        .execute(&mut *tx)
        .await
        .map_err(db_err("marking the target"))?;
        tx.commit().await.map_err(db_err("marking the target"))?;
    }
    let collation: String =
        sqlx::query_scalar("SELECT datcollate::text FROM pg_database WHERE datname = current_database()")
            .fetch_one(&mut dst)
            .await
            .map_err(db_err("reading the target's collation"))?;
    let collate_c = !matches!(collation.as_str(), "C" | "POSIX");
    Ok(Migration { source_label, src, dst, plans, resumed, batches: 0, collate_c })
}

/// The source's applied migrations against this build's.
async fn check_source_migrations(src: &mut SqliteConnection, shown: &str) -> Result<(), TransferError> {
    let has_table: bool =
        sqlx::query_scalar("SELECT EXISTS (SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?1)")
            .bind(SQLX_TABLE)
            .fetch_one(&mut *src)
            .await
            .map_err(|e| TransferError::Source {
                path: shown.to_string(),
                reason: format!("not a SQLite database robocal can read: {e}"),
            })?;
    if !has_table {
        return Err(TransferError::SourceNotMigrated {
            path: shown.to_string(),
            detail: "it has no migration table: not a robocal database, or one never opened by robocal".into(),
        });
    }
    let applied: Vec<i64> = sqlx::query_scalar(sqlx::AssertSqlSafe(format!(
        "SELECT version FROM {SQLX_TABLE} WHERE success ORDER BY version"
    )))
    .fetch_all(&mut *src)
    .await
    .map_err(|e| TransferError::Source {
        path: shown.to_string(),
        reason: format!("cannot read its migrations: {e}"),
    })?;
    let known: Vec<i64> = crate::db::MIGRATOR.iter().map(|m| m.version).collect();
    if applied != known {
        let at = applied.last().copied().unwrap_or(0);
        let latest = known.last().copied().unwrap_or(0);
        if at > latest {
            return Err(TransferError::Source {
                path: shown.to_string(),
                reason: format!("it was written by a newer robocal (migration {at}; this one knows up to {latest})"),
            });
        }
        return Err(TransferError::SourceNotMigrated {
            path: shown.to_string(),
            detail: format!("it is at migration {at}, the latest is {latest}"),
        });
    }
    Ok(())
}

/// The source's tables (not SQLite's own, not sqlx's), each with its columns and primary key.
async fn sqlite_tables(
    src: &mut SqliteConnection,
) -> Result<BTreeMap<String, (Vec<String>, Vec<String>)>, sqlx::Error> {
    let names: Vec<String> = sqlx::query_scalar(
        "SELECT name FROM sqlite_master WHERE type = 'table' AND name NOT LIKE 'sqlite_%' AND name <> ?1",
    )
    .bind(SQLX_TABLE)
    .fetch_all(&mut *src)
    .await?;
    let mut out = BTreeMap::new();
    for t in names {
        let cols: Vec<(String, i64)> = sqlx::query_as("SELECT name, pk FROM pragma_table_info(?1) ORDER BY cid")
            .bind(&t)
            .fetch_all(&mut *src)
            .await?;
        let mut pk: Vec<(i64, String)> = cols.iter().filter(|c| c.1 > 0).map(|(n, p)| (*p, n.clone())).collect();
        pk.sort();
        out.insert(t, (cols.into_iter().map(|c| c.0).collect(), pk.into_iter().map(|p| p.1).collect()));
    }
    Ok(out)
}

/// The marker, if the target has one: (source, fingerprint).
async fn read_marker(dst: &mut PgConnection) -> Result<Option<(String, String)>, TransferError> {
    let exists: bool = sqlx::query_scalar("SELECT to_regclass($1) IS NOT NULL")
        .bind(MARKER_TABLE)
        .fetch_one(&mut *dst)
        .await
        .map_err(db_err("reading the target's catalogue"))?;
    if !exists {
        return Ok(None);
    }
    sqlx::query_as(sqlx::AssertSqlSafe(format!("SELECT source, fingerprint FROM {MARKER_TABLE}")))
        .fetch_optional(&mut *dst)
        .await
        .map_err(db_err("reading the target's migration marker"))
}

/// The target's tables (current schema, sqlx's excepted) that hold a row.
async fn occupied_tables(dst: &mut PgConnection) -> Result<Vec<String>, TransferError> {
    let tables: Vec<String> = sqlx::query_scalar(
        "SELECT table_name::text FROM information_schema.tables \
         WHERE table_schema = current_schema() AND table_type = 'BASE TABLE' AND table_name <> $1 ORDER BY 1",
    )
    .bind(SQLX_TABLE)
    .fetch_all(&mut *dst)
    .await
    .map_err(db_err("reading the target's catalogue"))?;
    let mut occupied = Vec::new();
    for t in tables {
        let n: i64 = sqlx::query_scalar(sqlx::AssertSqlSafe(format!("SELECT count(*) FROM {}", quote(&t))))
            .fetch_one(&mut *dst)
            .await
            .map_err(db_err(format!("counting the target's {t}")))?;
        if n > 0 {
            occupied.push(format!("{t}: {n} row{}", if n == 1 { "" } else { "s" }));
        }
    }
    Ok(occupied)
}

type PgCatalogue = (BTreeMap<String, Vec<Column>>, BTreeMap<String, Vec<String>>, Vec<ForeignKey>);

/// The target's tables (columns with type and nullability), primary keys and foreign keys.
async fn postgres_catalogue(dst: &mut PgConnection) -> Result<PgCatalogue, TransferError> {
    let err = db_err("reading the target's catalogue");
    let rows: Vec<(String, String, String, String)> = sqlx::query_as(
        "SELECT c.table_name::text, c.column_name::text, c.data_type::text, c.is_nullable::text \
         FROM information_schema.columns c JOIN information_schema.tables t \
           ON t.table_schema = c.table_schema AND t.table_name = c.table_name \
         WHERE c.table_schema = current_schema() AND t.table_type = 'BASE TABLE' AND c.table_name NOT IN ($1, $2) \
         ORDER BY c.table_name, c.ordinal_position",
    )
    .bind(SQLX_TABLE)
    .bind(MARKER_TABLE)
    .fetch_all(&mut *dst)
    .await
    .map_err(err)?;
    let mut tables: BTreeMap<String, Vec<Column>> = BTreeMap::new();
    for (table, name, data_type, nullable) in rows {
        let ty = PgType::parse(&data_type).ok_or_else(|| {
            TransferError::SchemaMismatch(format!("{table}.{name} has the type {data_type}, which migrate cannot fill"))
        })?;
        tables.entry(table).or_default().push(Column { name, ty, nullable: nullable == "YES" });
    }
    let keys: Vec<(String, Vec<String>)> = sqlx::query_as(
        "SELECT r.relname::text, ARRAY(SELECT a.attname::text FROM unnest(c.conkey) WITH ORDINALITY AS k(attnum, ord) \
                JOIN pg_attribute a ON a.attrelid = c.conrelid AND a.attnum = k.attnum ORDER BY k.ord) \
         FROM pg_constraint c JOIN pg_class r ON r.oid = c.conrelid \
         WHERE c.contype = 'p' AND r.relnamespace = current_schema()::regnamespace",
    )
    .fetch_all(&mut *dst)
    .await
    .map_err(db_err("reading the target's primary keys"))?;
    let fks: Vec<(String, Vec<String>, String)> = sqlx::query_as(
        "SELECT r.relname::text, ARRAY(SELECT a.attname::text FROM unnest(c.conkey) WITH ORDINALITY AS k(attnum, ord) \
                JOIN pg_attribute a ON a.attrelid = c.conrelid AND a.attnum = k.attnum ORDER BY k.ord), p.relname::text \
         FROM pg_constraint c JOIN pg_class r ON r.oid = c.conrelid JOIN pg_class p ON p.oid = c.confrelid \
         WHERE c.contype = 'f' AND r.relnamespace = current_schema()::regnamespace",
    )
    .fetch_all(&mut *dst)
    .await
    .map_err(db_err("reading the target's foreign keys"))?;
    Ok((
        tables,
        keys.into_iter().collect(),
        fks.into_iter().map(|(child, columns, parent)| ForeignKey { child, columns, parent }).collect(),
    ))
}

/// The copy plan, after checking that both sides have the same tables, columns and keys.
fn plan(
    source: &BTreeMap<String, (Vec<String>, Vec<String>)>,
    target: &BTreeMap<String, Vec<Column>>,
    keys: &BTreeMap<String, Vec<String>>,
    fks: &[ForeignKey],
) -> Result<Vec<TablePlan>, TransferError> {
    let mismatch = TransferError::SchemaMismatch;
    for t in source.keys() {
        if !target.contains_key(t) {
            return Err(mismatch(format!("the target has no table {t}")));
        }
    }
    for t in target.keys() {
        if !source.contains_key(t) {
            return Err(mismatch(format!("the source has no table {t}, which the target has")));
        }
    }
    let (order, deferred) = order_tables(target, fks).map_err(mismatch)?;
    let mut plans = Vec::new();
    for name in order {
        let columns = target[&name].clone();
        let (src_cols, src_key) = &source[&name];
        let a: BTreeSet<&String> = src_cols.iter().collect();
        let b: BTreeSet<&String> = columns.iter().map(|c| &c.name).collect();
        if a != b {
            let only_src: Vec<&str> = a.difference(&b).map(|s| s.as_str()).collect();
            let only_dst: Vec<&str> = b.difference(&a).map(|s| s.as_str()).collect();
            return Err(mismatch(format!(
                "table {name}: columns only in the source [{}], only in the target [{}]",
                only_src.join(", "),
                only_dst.join(", ")
            )));
        }
        let key_names = keys.get(&name).cloned().unwrap_or_default();
        if key_names.is_empty() {
            return Err(mismatch(format!(
                "table {name} has no primary key in the target: it cannot be copied in key order"
            )));
        }
        if &key_names != src_key {
            return Err(mismatch(format!(
                "table {name}: primary key ({}) in the source, ({}) in the target",
                src_key.join(", "),
                key_names.join(", ")
            )));
        }
        let index = |c: &str| columns.iter().position(|x| x.name == c).expect("checked above");
        let key: Vec<usize> = key_names.iter().map(|c| index(c)).collect();
        let deferred: Vec<usize> = deferred.iter().filter(|(t, _)| t == &name).map(|(_, c)| index(c)).collect();
        plans.push(TablePlan { name, columns, key, deferred });
    }
    Ok(plans)
}

/// A batch of a plan's rows from SQLite, each column as a `typeof(c), c` pair, in key order.
fn sqlite_select(p: &TablePlan, after: bool) -> String {
    let cols: Vec<String> = p.columns.iter().map(|c| format!("typeof({0}), {0}", quote(&c.name))).collect();
    let key: Vec<String> = p.key.iter().map(|&i| quote(&p.columns[i].name)).collect();
    let mut sql = format!("SELECT {} FROM {}", cols.join(", "), quote(&p.name));
    if after {
        let marks: Vec<String> = (1..=key.len()).map(|i| format!("?{i}")).collect();
        let _ = write!(sql, " WHERE ({}) > ({})", key.join(", "), marks.join(", "));
    }
    let _ = write!(sql, " ORDER BY {} LIMIT ?{}", key.join(", "), if after { key.len() + 1 } else { 1 });
    sql
}

/// The PostgreSQL side's key expression list, text keys compared bytewise: `COLLATE "C"` when the
/// database's own collation is another (then the primary-key index cannot serve the order, and
/// each page is a sort; in a C database it can, and the pages are index range scans).
fn pg_key(p: &TablePlan, collate_c: bool) -> Vec<String> {
    p.key
        .iter()
        .map(|&i| {
            let c = &p.columns[i];
            if collate_c && c.ty.is_text() { format!("{} COLLATE \"C\"", quote(&c.name)) } else { quote(&c.name) }
        })
        .collect()
}

fn pg_select(p: &TablePlan, after: bool, collate_c: bool) -> String {
    let cols: Vec<String> = p.columns.iter().map(|c| quote(&c.name)).collect();
    let key = pg_key(p, collate_c);
    let mut sql = format!("SELECT {} FROM {}", cols.join(", "), quote(&p.name));
    if after {
        let marks: Vec<String> = (1..=key.len()).map(|i| format!("${i}")).collect();
        let _ = write!(sql, " WHERE ({}) > ({})", key.join(", "), marks.join(", "));
    }
    let _ = write!(sql, " ORDER BY {} LIMIT ${}", key.join(", "), if after { key.len() + 1 } else { 1 });
    sql
}

fn sqlite_value(row: &SqliteRow, i: usize) -> Result<Value, sqlx::Error> {
    let storage: String = row.try_get(2 * i)?;
    let at = 2 * i + 1;
    Ok(match storage.as_str() {
        "null" => Value::Null,
        "integer" => Value::Int(row.try_get_unchecked(at)?),
        "real" => Value::Real(row.try_get_unchecked(at)?),
        "text" => Value::Text(row.try_get_unchecked(at)?),
        _ => Value::Blob(row.try_get_unchecked(at)?),
    })
}

fn pg_value(row: &PgRow, i: usize, ty: PgType) -> Result<Value, sqlx::Error> {
    let v = match ty {
        PgType::Boolean => row.try_get::<Option<bool>, _>(i)?.map(Value::Bool),
        PgType::SmallInt => row.try_get::<Option<i16>, _>(i)?.map(|x| Value::Int(x.into())),
        PgType::Integer => row.try_get::<Option<i32>, _>(i)?.map(|x| Value::Int(x.into())),
        PgType::BigInt => row.try_get::<Option<i64>, _>(i)?.map(Value::Int),
        PgType::Double => row.try_get::<Option<f64>, _>(i)?.map(Value::Real),
        PgType::Text => row.try_get::<Option<String>, _>(i)?.map(Value::Text),
        PgType::Bytea => row.try_get::<Option<Vec<u8>>, _>(i)?.map(Value::Blob),
    };
    Ok(v.unwrap_or(Value::Null))
}

fn bind_sqlite<'q>(
    q: sqlx::query::Query<'q, Sqlite, SqliteArguments>,
    v: &Value,
) -> sqlx::query::Query<'q, Sqlite, SqliteArguments> {
    match v {
        Value::Null => q.bind(None::<i64>),
        Value::Int(i) => q.bind(*i),
        Value::Real(r) => q.bind(*r),
        Value::Text(t) => q.bind(t.clone()),
        Value::Blob(b) => q.bind(b.clone()),
        Value::Bool(b) => q.bind(i64::from(*b)),
    }
}

/// Bind a value converted for a column of type `ty` (a NULL typed as the column).
fn bind_pg<'q>(
    q: sqlx::query::Query<'q, Postgres, PgArguments>,
    v: &Value,
    ty: PgType,
) -> sqlx::query::Query<'q, Postgres, PgArguments> {
    match (v, ty) {
        (Value::Null, PgType::Boolean) => q.bind(None::<bool>),
        (Value::Null, PgType::Double) => q.bind(None::<f64>),
        (Value::Null, PgType::Text) => q.bind(None::<String>),
        (Value::Null, PgType::Bytea) => q.bind(None::<Vec<u8>>),
        (Value::Null, _) => q.bind(None::<i64>),
        (Value::Int(i), _) => q.bind(*i),
        (Value::Real(r), _) => q.bind(*r),
        (Value::Text(t), _) => q.bind(t.clone()),
        (Value::Blob(b), _) => q.bind(b.clone()),
        (Value::Bool(b), _) => q.bind(*b),
    }
}

fn show_key(p: &TablePlan, row: &[Value]) -> String {
    let parts: Vec<String> = p.key.iter().map(|&i| format!("{}={}", p.columns[i].name, row[i].show())).collect();
    parts.join(", ")
}

impl Migration {
    /// Whether this run resumes an unfinished migration of the same source.
    pub fn resumed(&self) -> bool {
        self.resumed
    }

    /// The source's canonical path (as the marker records it).
    pub fn source(&self) -> &str {
        &self.source_label
    }

    /// The tables in copy order.
    pub fn tables(&self) -> Vec<&str> {
        self.plans.iter().map(|p| p.name.as_str()).collect()
    }

    /// One batch of source rows after `after` (all, when `None`), converted to the target's
    /// types: at most `limit` rows.
    async fn source_batch(
        &mut self,
        p: &TablePlan,
        after: Option<&[Value]>,
        limit: usize,
    ) -> Result<Vec<Vec<Value>>, TransferError> {
        let sql = sqlite_select(p, after.is_some());
        let mut q = sqlx::query(sqlx::AssertSqlSafe(sql));
        for v in after.unwrap_or(&[]) {
            q = bind_sqlite(q, v);
        }
        q = q.bind(limit as i64);
        let rows = q.fetch_all(&mut self.src).await.map_err(db_err(format!("reading the source's {}", p.name)))?;
        rows.iter()
            .map(|row| {
                let raw: Vec<Value> = (0..p.columns.len())
                    .map(|i| sqlite_value(row, i))
                    .collect::<Result<_, _>>()
                    .map_err(db_err(format!("reading the source's {}", p.name)))?;
                let key = show_key(p, &raw);
                raw.into_iter()
                    .zip(&p.columns)
                    .map(|(v, c)| {
                        convert(v, c.ty).map_err(|reason| TransferError::Value {
                            table: p.name.clone(),
                            key: key.clone(),
                            column: c.name.clone(),
                            reason,
                        })
                    })
                    .collect()
            })
            .collect()
    }

    /// One batch of target rows after `after`, in the same key order.
    async fn target_batch(
        &mut self,
        p: &TablePlan,
        after: Option<&[Value]>,
        limit: usize,
    ) -> Result<Vec<Vec<Value>>, TransferError> {
        let sql = pg_select(p, after.is_some(), self.collate_c);
        let mut q = sqlx::query(sqlx::AssertSqlSafe(sql));
        if let Some(after) = after {
            for (v, &i) in after.iter().zip(&p.key) {
                q = bind_pg(q, v, p.columns[i].ty);
            }
        }
        q = q.bind(limit as i64);
        let during = format!("reading the target's {}", p.name);
        let rows = q.fetch_all(&mut self.dst).await.map_err(db_err(during.clone()))?;
        rows.iter()
            .map(|row| {
                p.columns
                    .iter()
                    .enumerate()
                    .map(|(i, c)| pg_value(row, i, c.ty))
                    .collect::<Result<Vec<_>, _>>()
                    .map_err(db_err(during.clone()))
            })
            .collect()
    }

    /// The last key the target holds of a table (in key order), if any.
    async fn last_target_key(&mut self, p: &TablePlan) -> Result<Option<Vec<Value>>, TransferError> {
        let key = pg_key(p, self.collate_c);
        let cols: Vec<String> = p.key.iter().map(|&i| quote(&p.columns[i].name)).collect();
        let desc: Vec<String> = key.iter().map(|k| format!("{k} DESC")).collect();
        let sql = format!("SELECT {} FROM {} ORDER BY {} LIMIT 1", cols.join(", "), quote(&p.name), desc.join(", "));
        let row = sqlx::query(sqlx::AssertSqlSafe(sql))
            .fetch_optional(&mut self.dst)
            .await
            .map_err(db_err(format!("reading the target's {}", p.name)))?;
        row.map(|row| {
            p.key
                .iter()
                .enumerate()
                .map(|(j, &i)| pg_value(&row, j, p.columns[i].ty))
                .collect::<Result<Vec<_>, _>>()
                .map_err(db_err(format!("reading the target's {}", p.name)))
        })
        .transpose()
    }

    fn batch_rows(p: &TablePlan, opts: &Options) -> usize {
        opts.batch_rows.clamp(1, MAX_BINDS / p.columns.len().max(1))
    }

    fn count_batch(&mut self, opts: &Options) -> Result<(), TransferError> {
        self.batches += 1;
        match opts.stop_after_batches {
            Some(n) if self.batches >= n => Err(TransferError::Interrupted(self.batches)),
            _ => Ok(()),
        }
    }

    /// Copy every table, continuing each after the last key the target holds; then set the
    /// deferred columns. `progress` gets a line per table.
    pub async fn copy(&mut self, opts: &Options, progress: &mut dyn FnMut(&str)) -> Result<CopyStats, TransferError> {
        if opts.stop_after_batches == Some(0) {
            return Err(TransferError::Interrupted(0));
        }
        let mut stats = CopyStats::default();
        for p in self.plans.clone() {
            let started = std::time::Instant::now();
            let limit = Self::batch_rows(&p, opts);
            let mut after = self.last_target_key(&p).await?;
            let already: i64 =
                sqlx::query_scalar(sqlx::AssertSqlSafe(format!("SELECT count(*) FROM {}", quote(&p.name))))
                    .fetch_one(&mut self.dst)
                    .await
                    .map_err(db_err(format!("counting the target's {}", p.name)))?;
            let (mut copied, mut batches) = (0u64, 0u64);
            loop {
                let rows = self.source_batch(&p, after.as_deref(), limit).await?;
                let Some(last) = rows.last() else { break };
                let next: Vec<Value> = p.key.iter().map(|&i| last[i].clone()).collect();
                self.insert(&p, &rows).await?;
                copied += rows.len() as u64;
                batches += 1;
                after = Some(next);
                self.count_batch(opts)?;
                if rows.len() < limit {
                    break;
                }
            }
            let resumed = if already > 0 { format!(", {already} already there") } else { String::new() };
            progress(&format!(
                "{}: {copied} rows copied in {batches} batch{}{resumed} ({:.1} s)",
                p.name,
                if batches == 1 { "" } else { "es" },
                started.elapsed().as_secs_f64()
            ));
            stats.tables.push((p.name.clone(), already as u64, copied, batches));
        }
        for p in self.plans.clone().iter().filter(|p| !p.deferred.is_empty()) {
            let n = self.set_deferred(p, opts).await?;
            let cols: Vec<&str> = p.deferred.iter().map(|&i| p.columns[i].name.as_str()).collect();
            progress(&format!("{}: {} set on {n} rows (a foreign-key cycle)", p.name, cols.join(", ")));
        }
        Ok(stats)
    }

    /// One multi-row INSERT (its own transaction), deferred columns NULL.
    async fn insert(&mut self, p: &TablePlan, rows: &[Vec<Value>]) -> Result<(), TransferError> {
        let cols: Vec<String> = p.columns.iter().map(|c| quote(&c.name)).collect();
        let mut sql = format!("INSERT INTO {} ({}) VALUES ", quote(&p.name), cols.join(", "));
        let n = p.columns.len();
        for r in 0..rows.len() {
            let marks: Vec<String> = (1..=n).map(|i| format!("${}", r * n + i)).collect();
            let _ = write!(sql, "{}({})", if r == 0 { "" } else { ", " }, marks.join(", "));
        }
        let mut q = sqlx::query(sqlx::AssertSqlSafe(sql));
        for row in rows {
            for (i, (v, c)) in row.iter().zip(&p.columns).enumerate() {
                q = if p.deferred.contains(&i) { bind_pg(q, &Value::Null, c.ty) } else { bind_pg(q, v, c.ty) };
            }
        }
        q.execute(&mut self.dst).await.map_err(|e| {
            let first = rows.first().map(|r| show_key(p, r)).unwrap_or_default();
            TransferError::Database { during: format!("writing {} (the batch from {first})", p.name), source: e }
        })?;
        Ok(())
    }

    /// Set a table's deferred columns from the source, a batch per transaction; the rows set.
    async fn set_deferred(&mut self, p: &TablePlan, opts: &Options) -> Result<u64, TransferError> {
        let limit = Self::batch_rows(p, opts);
        let sets: Vec<String> = p
            .deferred
            .iter()
            .enumerate()
            .map(|(j, &i)| format!("{} = ${}", quote(&p.columns[i].name), j + 1))
            .collect();
        let wheres: Vec<String> = p
            .key
            .iter()
            .enumerate()
            .map(|(j, &i)| format!("{} = ${}", quote(&p.columns[i].name), p.deferred.len() + j + 1))
            .collect();
        let sql = format!("UPDATE {} SET {} WHERE {}", quote(&p.name), sets.join(", "), wheres.join(" AND "));
        let (mut after, mut set) = (None::<Vec<Value>>, 0u64);
        loop {
            let rows = self.source_batch(p, after.as_deref(), limit).await?;
            let Some(last) = rows.last() else { break };
            after = Some(p.key.iter().map(|&i| last[i].clone()).collect());
            let during = format!("setting {}'s deferred columns", p.name);
            let mut tx = self.dst.begin().await.map_err(db_err(during.clone()))?;
            for row in rows.iter().filter(|r| p.deferred.iter().any(|&i| r[i] != Value::Null)) {
                let mut q = sqlx::query(sqlx::AssertSqlSafe(sql.clone()));
                for &i in &p.deferred {
                    q = bind_pg(q, &row[i], p.columns[i].ty);
                }
                for &i in &p.key {
                    q = bind_pg(q, &row[i], p.columns[i].ty);
                }
                q.execute(&mut *tx).await.map_err(db_err(during.clone()))?;
                set += 1;
            }
            tx.commit().await.map_err(db_err(during))?;
            if rows.len() < limit {
                break;
            }
        }
        Ok(set)
    }

    /// Counts and checksums of every table on both sides.
    pub async fn verify(&mut self, progress: &mut dyn FnMut(&str)) -> Result<Verification, TransferError> {
        const READ: usize = 2000;
        let mut tables = Vec::new();
        for p in self.plans.clone() {
            let (mut src_rows, mut src_hash, mut after) = (0u64, Sha256::new(), None::<Vec<Value>>);
            let mut buf = Vec::new();
            loop {
                let rows = self.source_batch(&p, after.as_deref(), READ).await?;
                let Some(last) = rows.last() else { break };
                after = Some(p.key.iter().map(|&i| last[i].clone()).collect());
                for r in &rows {
                    buf.clear();
                    encode_row(&mut buf, r);
                    src_hash.update(&buf);
                }
                src_rows += rows.len() as u64;
                if rows.len() < READ {
                    break;
                }
            }
            let (mut dst_rows, mut dst_hash, mut after) = (0u64, Sha256::new(), None::<Vec<Value>>);
            loop {
                let rows = self.target_batch(&p, after.as_deref(), READ).await?;
                let Some(last) = rows.last() else { break };
                after = Some(p.key.iter().map(|&i| last[i].clone()).collect());
                for r in &rows {
                    buf.clear();
                    encode_row(&mut buf, r);
                    dst_hash.update(&buf);
                }
                dst_rows += rows.len() as u64;
                if rows.len() < READ {
                    break;
                }
            }
            let check = TableCheck {
                table: p.name.clone(),
                source_rows: src_rows,
                target_rows: dst_rows,
                source_sha256: hex(&src_hash.finalize()),
                target_sha256: hex(&dst_hash.finalize()),
            };
            progress(&format!("{}: verified, {}", p.name, if check.matches() { "match" } else { "MISMATCH" }));
            tables.push(check);
        }
        Ok(Verification { tables })
    }

    /// Verify, remove the marker when every table matches (the migration is then complete), and
    /// close both connections.
    pub async fn finish(mut self, progress: &mut dyn FnMut(&str)) -> Result<Verification, TransferError> {
        let v = self.verify(progress).await?;
        if v.ok() {
            sqlx::query(sqlx::AssertSqlSafe(format!("DROP TABLE {MARKER_TABLE}")))
                .execute(&mut self.dst)
                .await
                .map_err(db_err("removing the migration marker"))?;
        }
        let _ = sqlx::query("COMMIT").execute(&mut self.src).await;
        let _ = self.src.close().await;
        let _ = self.dst.close().await;
        Ok(v)
    }
}

/// The whole migration: prepare, copy, verify.
pub async fn migrate(
    source: &Path,
    target: &PgConnectOptions,
    opts: &Options,
    progress: &mut dyn FnMut(&str),
) -> Result<Verification, TransferError> {
    let mut m = prepare(source, target).await?;
    if m.resumed() {
        progress(&format!("resuming the unfinished migration of {}", m.source()));
    }
    m.copy(opts, progress).await?;
    m.finish(progress).await
}

#[cfg(test)]
mod tests {
    use super::*;

    fn col(name: &str, ty: PgType, nullable: bool) -> Column {
        Column { name: name.into(), ty, nullable }
    }

    fn fk(child: &str, columns: &[&str], parent: &str) -> ForeignKey {
        ForeignKey {
            child: child.into(),
            columns: columns.iter().map(|c| c.to_string()).collect(),
            parent: parent.into(),
        }
    }

    #[test]
    fn tables_are_ordered_parents_first_and_a_nullable_cycle_is_deferred() {
        // robocal's own cycle: robots.active_parameter_set_id → parameter_sets → robots.
        let mut tables = BTreeMap::new();
        tables.insert("robots".to_string(), vec![col("id", PgType::Text, false), col("active", PgType::Text, true)]);
        tables.insert(
            "parameter_sets".to_string(),
            vec![
                col("id", PgType::Text, false),
                col("robot_id", PgType::Text, false),
                col("job_id", PgType::Text, true),
            ],
        );
        tables.insert("jobs".to_string(), vec![col("id", PgType::Text, false), col("robot_id", PgType::Text, false)]);
        tables.insert("audit".to_string(), vec![col("id", PgType::Text, false)]);
        let fks = [
            fk("robots", &["active"], "parameter_sets"),
            fk("parameter_sets", &["robot_id"], "robots"),
            fk("parameter_sets", &["job_id"], "jobs"),
            fk("jobs", &["robot_id"], "robots"),
        ];
        let (order, deferred) = order_tables(&tables, &fks).unwrap();
        assert_eq!(order, ["audit", "robots", "jobs", "parameter_sets"]);
        assert_eq!(deferred.into_iter().collect::<Vec<_>>(), [("robots".to_string(), "active".to_string())]);

        // A cycle through NOT NULL columns cannot be broken.
        tables.get_mut("robots").unwrap()[1].nullable = false;
        let e = order_tables(&tables, &fks).unwrap_err();
        assert!(e.contains("cycle") && e.contains("robots") && e.contains("parameter_sets"), "{e}");
    }

    #[test]
    fn values_convert_by_the_target_type_losslessly_or_not_at_all() {
        assert_eq!(convert(Value::Int(1), PgType::Boolean), Ok(Value::Bool(true)));
        assert_eq!(convert(Value::Int(0), PgType::Boolean), Ok(Value::Bool(false)));
        assert!(convert(Value::Int(2), PgType::Boolean).unwrap_err().contains("0/1"));
        assert_eq!(convert(Value::Int(i64::MIN), PgType::BigInt), Ok(Value::Int(i64::MIN)));
        assert!(convert(Value::Int(40_000), PgType::SmallInt).is_err());
        assert_eq!(convert(Value::Real(0.1), PgType::Double), Ok(Value::Real(0.1)));
        assert_eq!(convert(Value::Int(3), PgType::Double), Ok(Value::Real(3.0)));
        assert!(convert(Value::Int((1 << 53) + 1), PgType::Double).is_err(), "not exact as a double");
        assert!(convert(Value::Text("1".into()), PgType::BigInt).unwrap_err().contains("TEXT"));
        assert!(convert(Value::Real(1.5), PgType::BigInt).is_err());
        assert_eq!(convert(Value::Null, PgType::Boolean), Ok(Value::Null));
        assert_eq!(convert(Value::Blob(vec![0, 255]), PgType::Bytea), Ok(Value::Blob(vec![0, 255])));
        assert!(convert(Value::Blob(vec![1]), PgType::Text).is_err());
    }

    #[test]
    fn the_canonical_row_text_is_as_documented_and_unambiguous() {
        let mut out = Vec::new();
        encode_row(
            &mut out,
            &[
                Value::Int(-12),
                Value::Real(0.1),
                Value::Bool(true),
                Value::Text("a:b".into()),
                Value::Blob(vec![0, 171]),
                Value::Null,
            ],
        );
        assert_eq!(String::from_utf8(out).unwrap(), "3:-123:0.11:13:a:b4:00ab-\n");
        // A boolean and the 0/1 integer it came from encode alike.
        let (mut a, mut b) = (Vec::new(), Vec::new());
        encode_row(&mut a, &[Value::Bool(false)]);
        encode_row(&mut b, &[Value::Int(0)]);
        assert_eq!(a, b);
        // Text that looks like framing does not collide.
        let (mut a, mut b) = (Vec::new(), Vec::new());
        encode_row(&mut a, &[Value::Text("ab".into()), Value::Text(String::new())]);
        encode_row(&mut b, &[Value::Text("a".into()), Value::Text("b".into())]);
        assert_ne!(a, b);
        let (mut a, mut b) = (Vec::new(), Vec::new());
        encode_row(&mut a, &[Value::Null]);
        encode_row(&mut b, &[Value::Text("-".into())]);
        assert_ne!(a, b);
        // Reals round-trip: the shortest text that reads back as the same double.
        let mut c = Vec::new();
        encode_row(&mut c, &[Value::Real(1.0 / 3.0)]);
        assert_eq!(String::from_utf8(c).unwrap(), "18:0.3333333333333333\n");
    }

    #[test]
    fn the_source_argument_takes_a_url_or_a_path() {
        assert_eq!(source_path("sqlite:robocal.db"), PathBuf::from("robocal.db"));
        assert_eq!(source_path("sqlite:///data/robocal.db"), PathBuf::from("/data/robocal.db"));
        assert_eq!(source_path("sqlite://rel/robocal.db"), PathBuf::from("rel/robocal.db"));
        assert_eq!(source_path("/data/robocal.db"), PathBuf::from("/data/robocal.db"));
    }

    #[test]
    fn sqlite_batches_continue_after_the_last_key() {
        let p = TablePlan {
            name: "measurements".into(),
            columns: vec![col("session_id", PgType::Text, false), col("seq", PgType::BigInt, false)],
            key: vec![0, 1],
            deferred: vec![],
        };
        assert_eq!(
            sqlite_select(&p, true),
            "SELECT typeof(\"session_id\"), \"session_id\", typeof(\"seq\"), \"seq\" FROM \"measurements\" \
             WHERE (\"session_id\", \"seq\") > (?1, ?2) ORDER BY \"session_id\", \"seq\" LIMIT ?3"
        );
        assert_eq!(
            pg_select(&p, true, true),
            "SELECT \"session_id\", \"seq\" FROM \"measurements\" WHERE (\"session_id\" COLLATE \"C\", \"seq\") > ($1, $2) \
             ORDER BY \"session_id\" COLLATE \"C\", \"seq\" LIMIT $3"
        );
        assert_eq!(
            pg_select(&p, false, false),
            "SELECT \"session_id\", \"seq\" FROM \"measurements\" ORDER BY \"session_id\", \"seq\" LIMIT $1"
        );
    }
}
