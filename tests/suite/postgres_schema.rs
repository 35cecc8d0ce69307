//! The two migration sets describe one schema (issue 27, item 1): `migrations/sqlite` applied to a
//! SQLite file and `migrations/postgres` applied to a real PostgreSQL server give, table by table,
//! the same columns (name, normalised type, nullability, in order), primary keys, unique
//! constraints and indexes (column sets, uniqueness, partial or not; the names of created
//! indexes) and foreign keys (columns, parent table and columns, actions). Each side is read from
//! the database's own catalogue (SQLite's pragmas; PostgreSQL's `information_schema` and
//! `pg_catalog`), not from the SQL text. The comparison is shown to tell altered schemas apart.
//!
//! The server is the one `ROBOCAL_TEST_PG` names (`scripts/pg_cluster.sh start` prints such a
//! URL; `.ci/run` always sets it); each test works in a database of its own, dropped at the end.
//! Without the variable the PostgreSQL tests say loudly that they were skipped.

use crate::common;

use std::collections::{BTreeMap, BTreeSet};
use std::io::Write;

use common::fresh_dir;
use robocal::db;
use sqlx::postgres::PgPoolOptions;
use sqlx::{Connection, PgConnection, PgPool, SqliteConnection};

/// SQLite has no boolean type: these INTEGER columns hold 0/1 flags (read as `bool` by the store)
/// and are BOOLEAN on PostgreSQL.
const BOOLEAN_FLAGS: [(&str, &str); 2] = [("sessions", "identify_tcp"), ("jobs", "cancel_requested")];

#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Ty {
    Integer,
    Real,
    Text,
    Blob,
    Boolean,
}

#[derive(Clone, Debug, PartialEq, Eq)]
struct Column {
    name: String,
    ty: Result<Ty, String>,
    not_null: bool,
}

#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct Index {
    /// The name of an index made by CREATE INDEX; `None` for one made by a UNIQUE constraint
    /// (SQLite calls those `sqlite_autoindex_…`, PostgreSQL `…_key`).
    name: Option<String>,
    columns: Vec<String>,
    unique: bool,
    partial: bool,
}

#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct ForeignKey {
    columns: Vec<String>,
    parent: String,
    parent_columns: Vec<String>,
    on_update: String,
    on_delete: String,
}

#[derive(Clone, Debug, Default, PartialEq, Eq)]
struct Table {
    columns: Vec<Column>,
    primary_key: Vec<String>,
    indexes: BTreeSet<Index>,
    foreign_keys: BTreeSet<ForeignKey>,
}

type Schema = BTreeMap<String, Table>;

/// A row of SQLite's `pragma_foreign_key_list`: (id, seq, parent, from, to, on_update, on_delete).
type SqliteForeignKeyRow = (i64, i64, String, String, Option<String>, String, String);

/// A foreign key read from `pg_constraint`: (parent, columns, parent columns, on update, on delete).
type PgForeignKeyRow = (String, Vec<String>, Vec<String>, String, String);

fn sqlite_type(table: &str, column: &str, declared: &str) -> Result<Ty, String> {
    match declared.to_ascii_uppercase().as_str() {
        "INTEGER" if BOOLEAN_FLAGS.contains(&(table, column)) => Ok(Ty::Boolean),
        "INTEGER" => Ok(Ty::Integer),
        "REAL" => Ok(Ty::Real),
        "TEXT" => Ok(Ty::Text),
        "BLOB" => Ok(Ty::Blob),
        other => Err(other.to_string()),
    }
}

fn postgres_type(data_type: &str) -> Result<Ty, String> {
    match data_type {
        "bigint" | "integer" | "smallint" => Ok(Ty::Integer),
        "double precision" | "real" => Ok(Ty::Real),
        "text" => Ok(Ty::Text),
        "bytea" => Ok(Ty::Blob),
        "boolean" => Ok(Ty::Boolean),
        other => Err(other.to_string()),
    }
}

/// PostgreSQL's one-letter referential actions, spelled as SQLite's pragma spells them.
fn postgres_action(code: &str) -> String {
    match code {
        "a" => "NO ACTION",
        "r" => "RESTRICT",
        "c" => "CASCADE",
        "n" => "SET NULL",
        "d" => "SET DEFAULT",
        other => other,
    }
    .to_string()
}

/// A plain SQLite connection to a file the store made (the catalogue's pragmas, typed).
async fn sqlite_file(path: &std::path::Path) -> SqliteConnection {
    SqliteConnection::connect_with(&sqlx::sqlite::SqliteConnectOptions::new().filename(path)).await.unwrap()
}

async fn describe_sqlite(conn: &mut SqliteConnection) -> Schema {
    let tables: Vec<String> = sqlx::query_scalar(
        "SELECT name FROM sqlite_master WHERE type = 'table' AND name NOT LIKE 'sqlite_%' AND name <> '_sqlx_migrations'",
    )
    .fetch_all(&mut *conn)
    .await
    .unwrap();
    let mut schema = Schema::new();
    for table in tables {
        let mut t = Table::default();
        // (cid, name, type, notnull, pk): pk is the column's 1-based place in the primary key.
        let cols: Vec<(i64, String, String, bool, i64)> =
            sqlx::query_as("SELECT cid, name, type, \"notnull\", pk FROM pragma_table_info(?1) ORDER BY cid")
                .bind(&table)
                .fetch_all(&mut *conn)
                .await
                .unwrap();
        let mut pk: Vec<(i64, String)> = Vec::new();
        for (_, name, declared, not_null, pk_place) in cols {
            if pk_place > 0 {
                pk.push((pk_place, name.clone()));
            }
            t.columns.push(Column {
                ty: sqlite_type(&table, &name, &declared),
                // A primary key's columns are NOT NULL on PostgreSQL; on SQLite a rowid table's
                // non-integer key admits NULL (a documented legacy quirk) unless declared NOT
                // NULL. The store never writes a NULL id, so both count as not null here.
                not_null: not_null || pk_place > 0,
                name,
            });
        }
        pk.sort();
        t.primary_key = pk.into_iter().map(|(_, n)| n).collect();

        // (name, unique, origin c/u/pk, partial)
        let indexes: Vec<(String, bool, String, bool)> =
            sqlx::query_as("SELECT name, \"unique\", origin, partial FROM pragma_index_list(?1)")
                .bind(&table)
                .fetch_all(&mut *conn)
                .await
                .unwrap();
        for (name, unique, origin, partial) in indexes {
            if origin == "pk" {
                continue;
            }
            let columns: Vec<String> = sqlx::query_scalar("SELECT name FROM pragma_index_info(?1) ORDER BY seqno")
                .bind(&name)
                .fetch_all(&mut *conn)
                .await
                .unwrap();
            t.indexes.insert(Index { name: (origin == "c").then_some(name), columns, unique, partial });
        }

        // One row per column of each key.
        let fks: Vec<SqliteForeignKeyRow> = sqlx::query_as(
            "SELECT id, seq, \"table\", \"from\", \"to\", on_update, on_delete FROM pragma_foreign_key_list(?1) ORDER BY id, seq",
        )
        .bind(&table)
        .fetch_all(&mut *conn)
        .await
        .unwrap();
        let mut by_id: BTreeMap<i64, ForeignKey> = BTreeMap::new();
        for (id, _, parent, from, to, on_update, on_delete) in fks {
            let fk = by_id.entry(id).or_insert_with(|| ForeignKey {
                columns: vec![],
                parent,
                parent_columns: vec![],
                on_update,
                on_delete,
            });
            fk.columns.push(from);
            // Every reference in the migrations names its parent columns.
            fk.parent_columns.push(to.unwrap_or_else(|| panic!("{table}: a foreign key without parent columns")));
        }
        t.foreign_keys = by_id.into_values().collect();
        schema.insert(table, t);
    }
    schema
}

async fn describe_postgres(conn: &mut PgConnection) -> Schema {
    let tables: Vec<String> = sqlx::query_scalar(
        "SELECT table_name::text FROM information_schema.tables \
         WHERE table_schema = current_schema() AND table_type = 'BASE TABLE' AND table_name <> '_sqlx_migrations'",
    )
    .fetch_all(&mut *conn)
    .await
    .unwrap();
    let mut schema = Schema::new();
    for table in tables {
        let mut t = Table::default();
        let cols: Vec<(String, String, String)> = sqlx::query_as(
            "SELECT column_name::text, data_type::text, is_nullable::text FROM information_schema.columns \
             WHERE table_schema = current_schema() AND table_name = $1 ORDER BY ordinal_position",
        )
        .bind(&table)
        .fetch_all(&mut *conn)
        .await
        .unwrap();
        t.columns = cols
            .into_iter()
            .map(|(name, ty, nullable)| Column { name, ty: postgres_type(&ty), not_null: nullable == "NO" })
            .collect();

        t.primary_key = sqlx::query_scalar(
            "SELECT a.attname::text FROM pg_constraint c \
             CROSS JOIN LATERAL unnest(c.conkey) WITH ORDINALITY AS k(attnum, ord) \
             JOIN pg_attribute a ON a.attrelid = c.conrelid AND a.attnum = k.attnum \
             WHERE c.conrelid = $1::text::regclass AND c.contype = 'p' ORDER BY k.ord",
        )
        .bind(&table)
        .fetch_all(&mut *conn)
        .await
        .unwrap();

        // (name, unique, partial, made by a UNIQUE constraint, columns), primary keys left out.
        let indexes: Vec<(String, bool, bool, bool, Vec<String>)> = sqlx::query_as(
            "SELECT ic.relname::text, i.indisunique, i.indpred IS NOT NULL, \
                    EXISTS (SELECT 1 FROM pg_constraint c WHERE c.conindid = i.indexrelid \
                            AND c.conrelid = i.indrelid AND c.contype = 'u'), \
                    ARRAY(SELECT a.attname::text FROM unnest(i.indkey::int2[]) WITH ORDINALITY AS k(attnum, ord) \
                          JOIN pg_attribute a ON a.attrelid = i.indrelid AND a.attnum = k.attnum ORDER BY k.ord) \
             FROM pg_index i JOIN pg_class ic ON ic.oid = i.indexrelid \
             WHERE i.indrelid = $1::text::regclass AND NOT i.indisprimary",
        )
        .bind(&table)
        .fetch_all(&mut *conn)
        .await
        .unwrap();
        t.indexes = indexes
            .into_iter()
            .map(|(name, unique, partial, constraint, columns)| Index {
                name: (!constraint).then_some(name),
                columns,
                unique,
                partial,
            })
            .collect();

        let fks: Vec<PgForeignKeyRow> = sqlx::query_as(
            "SELECT p.relname::text, \
                    ARRAY(SELECT a.attname::text FROM unnest(c.conkey) WITH ORDINALITY AS k(attnum, ord) \
                          JOIN pg_attribute a ON a.attrelid = c.conrelid AND a.attnum = k.attnum ORDER BY k.ord), \
                    ARRAY(SELECT a.attname::text FROM unnest(c.confkey) WITH ORDINALITY AS k(attnum, ord) \
                          JOIN pg_attribute a ON a.attrelid = c.confrelid AND a.attnum = k.attnum ORDER BY k.ord), \
                    c.confupdtype::text, c.confdeltype::text \
             FROM pg_constraint c JOIN pg_class p ON p.oid = c.confrelid \
             WHERE c.conrelid = $1::text::regclass AND c.contype = 'f'",
        )
        .bind(&table)
        .fetch_all(&mut *conn)
        .await
        .unwrap();
        t.foreign_keys = fks
            .into_iter()
            .map(|(parent, columns, parent_columns, upd, del)| ForeignKey {
                columns,
                parent,
                parent_columns,
                on_update: postgres_action(&upd),
                on_delete: postgres_action(&del),
            })
            .collect();
        schema.insert(table, t);
    }
    schema
}

/// Every difference between two schemas, one line each (empty: the same schema).
fn differences(sqlite: &Schema, postgres: &Schema) -> Vec<String> {
    let mut out = Vec::new();
    for name in sqlite.keys().chain(postgres.keys()).collect::<BTreeSet<_>>() {
        let (a, b) = match (sqlite.get(name), postgres.get(name)) {
            (Some(a), Some(b)) => (a, b),
            (Some(_), None) => {
                out.push(format!("table {name}: only on SQLite"));
                continue;
            }
            (None, _) => {
                out.push(format!("table {name}: only on PostgreSQL"));
                continue;
            }
        };
        if a.columns != b.columns {
            out.push(format!(
                "table {name}: columns differ:\n  SQLite     {:?}\n  PostgreSQL {:?}",
                a.columns, b.columns
            ));
        }
        if a.primary_key != b.primary_key {
            out.push(format!(
                "table {name}: primary key {:?} on SQLite, {:?} on PostgreSQL",
                a.primary_key, b.primary_key
            ));
        }
        for i in a.indexes.symmetric_difference(&b.indexes) {
            let side = if a.indexes.contains(i) { "SQLite" } else { "PostgreSQL" };
            out.push(format!("table {name}: index only on {side}: {i:?}"));
        }
        for k in a.foreign_keys.symmetric_difference(&b.foreign_keys) {
            let side = if a.foreign_keys.contains(k) { "SQLite" } else { "PostgreSQL" };
            out.push(format!("table {name}: foreign key only on {side}: {k:?}"));
        }
    }
    out
}

/// The schema the SQLite migrations give, read from a fresh file migrated by the store's own
/// `db::connect`.
async fn sqlite_schema() -> Schema {
    let dir = fresh_dir("schema");
    db::connect(&dir.join("robocal.db")).await.unwrap().close().await;
    let mut conn = sqlite_file(&dir.join("robocal.db")).await;
    let schema = describe_sqlite(&mut conn).await;
    drop(conn);
    let _ = std::fs::remove_dir_all(&dir);
    schema
}

/// A database of its own on the test server, migrated; `None` (said loudly) without a server.
struct PgDatabase {
    db: common::PgDb,
    pool: PgPool,
}

impl PgDatabase {
    async fn create(test: &str) -> Option<PgDatabase> {
        let Ok(url) = std::env::var("ROBOCAL_TEST_PG") else {
            // Written to the process's stderr itself, not with `eprintln!`, which the test
            // harness captures (and hides) for a passing test.
            let _ = writeln!(
                std::io::stderr(),
                "\n*** SKIPPED {test}: ROBOCAL_TEST_PG is not set, so the PostgreSQL schema was NOT checked. \
                 Start a server with `scripts/pg_cluster.sh start` and export ROBOCAL_TEST_PG=<its URL>. ***\n"
            );
            return None;
        };
        let db = common::PgDb::create(&url, "robocal_schema").await;
        let pool = PgPoolOptions::new().max_connections(2).connect_with(db.options()).await.unwrap();
        db::POSTGRES_MIGRATOR.run(&pool).await.unwrap();
        Some(PgDatabase { db, pool })
    }

    async fn drop(self) {
        self.pool.close().await;
        drop(self.db);
    }
}

/// The SQLite side read right, checked against the migrations' text: without this, two empty
/// descriptions would compare equal.
#[tokio::test]
async fn the_sqlite_schema_is_read_from_its_catalogue() {
    let s = sqlite_schema().await;
    let tables: Vec<&str> = s.keys().map(String::as_str).collect();
    assert_eq!(tables, common::STORE_TABLES);
    let m = &s["measurements"];
    assert_eq!(m.primary_key, ["session_id", "seq"]);
    assert_eq!(m.columns[1], Column { name: "seq".into(), ty: Ok(Ty::Integer), not_null: true }, "{:?}", m.columns);
    let jobs = &s["jobs"];
    let names: Vec<&str> = jobs.columns.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names.last(), Some(&"phase"), "0006 appends the phase");
    let cancel = jobs.columns.iter().find(|c| c.name == "cancel_requested").unwrap();
    assert_eq!((cancel.ty.clone(), cancel.not_null), (Ok(Ty::Boolean), true));
    let progress = jobs.columns.iter().find(|c| c.name == "progress").unwrap();
    assert_eq!(progress.ty, Ok(Ty::Real));
    assert_eq!(jobs.primary_key, ["id"]);
    let idx: Vec<Option<&str>> = jobs.indexes.iter().map(|i| i.name.as_deref()).collect();
    assert_eq!(idx, [Some("jobs_by_robot"), Some("jobs_by_state")]);
    assert!(s["measurement_exclusions"].indexes.contains(&Index {
        name: Some("measurement_exclusions_open".into()),
        columns: vec!["session_id".into(), "seq".into()],
        unique: true,
        partial: true,
    }));
    assert!(s["measurement_exclusions"].foreign_keys.contains(&ForeignKey {
        columns: vec!["session_id".into(), "seq".into()],
        parent: "measurements".into(),
        parent_columns: vec!["session_id".into(), "seq".into()],
        on_update: "NO ACTION".into(),
        on_delete: "NO ACTION".into(),
    }));
    assert!(s["sessions"].indexes.contains(&Index {
        name: None,
        columns: vec!["robot_id".into(), "name".into()],
        unique: true,
        partial: false,
    }));
    // The forward reference of 0001 (robots → parameter_sets, declared before that table).
    let robots = &s["robots"];
    assert_eq!(robots.foreign_keys.len(), 1);
    assert_eq!(robots.foreign_keys.iter().next().unwrap().parent, "parameter_sets");
    let total_fks: usize = s.values().map(|t| t.foreign_keys.len()).sum();
    assert_eq!(total_fks, 25, "every REFERENCES of migrations/sqlite");
}

/// The two sets are numbered and named alike, step for step, so a database of either backend
/// says by its `_sqlx_migrations` how far it is.
#[test]
fn both_migration_sets_have_the_same_steps() {
    let steps = |m: &sqlx::migrate::Migrator| -> Vec<(i64, String)> {
        m.iter().map(|s| (s.version, s.description.to_string())).collect()
    };
    let sqlite = steps(&db::MIGRATOR);
    assert_eq!(sqlite.len(), 7);
    assert_eq!(sqlite, steps(&db::POSTGRES_MIGRATOR));
}

#[tokio::test]
async fn the_sqlite_and_postgres_migrations_describe_the_same_schema() {
    let Some(pg) = PgDatabase::create("the_sqlite_and_postgres_migrations_describe_the_same_schema").await else {
        return;
    };
    let sqlite = sqlite_schema().await;
    let mut conn = pg.pool.acquire().await.unwrap();
    let postgres = describe_postgres(&mut conn).await;
    drop(conn);
    let diffs = differences(&sqlite, &postgres);
    assert!(diffs.is_empty(), "the migration sets differ:\n{}", diffs.join("\n"));
    // Not vacuous: both sides hold the whole schema.
    assert_eq!(postgres.len(), 15);
    let columns: usize = postgres.values().map(|t| t.columns.len()).sum();
    let indexes: usize = postgres.values().map(|t| t.indexes.len()).sum();
    let fks: usize = postgres.values().map(|t| t.foreign_keys.len()).sum();
    assert_eq!((columns, indexes, fks), (118, 17, 25));
    pg.drop().await;
}

/// The comparison fails when one side differs: each alteration below, made on the migrated
/// PostgreSQL database inside a transaction that is rolled back (PostgreSQL's DDL is
/// transactional), is reported on the table and aspect it touched, and nothing else; and so is
/// one made on the SQLite side.
#[tokio::test]
async fn an_altered_schema_is_told_apart() {
    let Some(pg) = PgDatabase::create("an_altered_schema_is_told_apart").await else {
        return;
    };
    let sqlite = sqlite_schema().await;
    let alterations: [(&str, &str); 10] = [
        ("ALTER TABLE jobs ALTER COLUMN phase SET NOT NULL", "table jobs: columns differ"),
        ("ALTER TABLE jobs ALTER COLUMN progress TYPE TEXT", "table jobs: columns differ"),
        (
            "ALTER TABLE sessions ALTER COLUMN identify_tcp DROP DEFAULT, \
             ALTER COLUMN identify_tcp TYPE BIGINT USING identify_tcp::int",
            "table sessions: columns differ",
        ),
        ("ALTER TABLE tokens ADD COLUMN extra TEXT", "table tokens: columns differ"),
        ("DROP INDEX batches_by_content", "table batches: index only on SQLite"),
        ("ALTER TABLE sessions DROP CONSTRAINT sessions_robot_id_name_key", "table sessions: index only on SQLite"),
        (
            "DROP INDEX measurement_exclusions_open; \
             CREATE UNIQUE INDEX measurement_exclusions_open ON measurement_exclusions (session_id, seq)",
            "table measurement_exclusions: index only on",
        ),
        ("ALTER TABLE diagnoses DROP CONSTRAINT diagnoses_job_id_fkey", "table diagnoses: foreign key only on SQLite"),
        (
            "ALTER TABLE measurement_exclusions DROP CONSTRAINT measurement_exclusions_pkey, \
             ADD PRIMARY KEY (id, session_id)",
            "table measurement_exclusions: primary key",
        ),
        ("CREATE TABLE extra (id TEXT PRIMARY KEY)", "table extra: only on PostgreSQL"),
    ];
    let mut conn = pg.pool.acquire().await.unwrap();
    for (sql, want) in alterations {
        let mut tx = conn.begin().await.unwrap();
        sqlx::raw_sql(sqlx::AssertSqlSafe(sql)).execute(&mut *tx).await.unwrap_or_else(|e| panic!("{sql}: {e}"));
        let diffs = differences(&sqlite, &describe_postgres(&mut tx).await);
        tx.rollback().await.unwrap();
        assert!(!diffs.is_empty(), "{sql}: not told apart");
        assert!(diffs.iter().all(|d| d.starts_with(want)), "{sql}: want only {want:?}, got:\n{}", diffs.join("\n"));
    }
    // Rolled back: the same schema again.
    let postgres = describe_postgres(&mut conn).await;
    assert_eq!(differences(&sqlite, &postgres), Vec::<String>::new());
    drop(conn);

    // The SQLite side altered (DDL is transactional there too).
    let dir = fresh_dir("schema-altered");
    db::connect(&dir.join("robocal.db")).await.unwrap().close().await;
    let mut conn = sqlite_file(&dir.join("robocal.db")).await;
    for (sql, want) in [
        ("CREATE INDEX robots_by_time ON robots (created_at)", "table robots: index only on SQLite"),
        ("ALTER TABLE artefacts ADD COLUMN weight_kg REAL", "table artefacts: columns differ"),
    ] {
        let mut tx = conn.begin().await.unwrap();
        sqlx::raw_sql(sqlx::AssertSqlSafe(sql)).execute(&mut *tx).await.unwrap();
        let diffs = differences(&describe_sqlite(&mut tx).await, &postgres);
        tx.rollback().await.unwrap();
        assert!(!diffs.is_empty() && diffs.iter().all(|d| d.starts_with(want)), "{sql}:\n{}", diffs.join("\n"));
    }
    drop(conn);
    let _ = std::fs::remove_dir_all(&dir);
    pg.drop().await;
}
