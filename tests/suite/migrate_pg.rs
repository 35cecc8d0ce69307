//! `robocal migrate` (issue 27, item 3) against a real PostgreSQL server: the walkthrough's data
//! copied and compared row by row (independently of the tool's own checksums), a non-empty target
//! refused with nothing written, an interrupted run resumed to the same result, a damaged copy
//! told apart by table.
//!
//! The source is built the way the README's walkthrough builds one: `scripts/api_walkthrough.sh`
//! run against `robocal serve` on a fresh file (robots, an artefact, a pose plan, sessions and
//! measurements, identification, validation, diagnosis and ISO 9283 jobs and their results,
//! activations, exclusions, archiving, audit events), then tokens made and one revoked with
//! `robocal token`. It is built once per run of this file and only read afterwards.
//!
//! The server is the one `ROBOCAL_TEST_PG` names (`scripts/pg_cluster.sh start` prints such a
//! URL; `.ci/run` always sets it); each test works in a database of its own
//! (`robocal_mig_<random>`), dropped at the end. Without the variable the tests that need the
//! server say loudly that they were skipped.

use crate::common;

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use common::fresh_dir;
use robocal::db;
use robocal::db::transfer::{self, Options, TransferError};
use sqlx::sqlite::SqliteConnectOptions;
use sqlx::{Column, Connection, PgConnection, Row, SqliteConnection, TypeInfo, ValueRef};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");
const BIN: &str = env!("CARGO_BIN_EXE_robocal");

/// Every table of the store.
const TABLES: [&str; 15] = common::STORE_TABLES;

fn server_url(test: &str) -> Option<String> {
    match std::env::var("ROBOCAL_TEST_PG") {
        Ok(url) => Some(url),
        Err(_) => {
            // Written to the process's stderr itself: the harness hides `eprintln!` of a passing test.
            let _ = writeln!(
                std::io::stderr(),
                "\n*** SKIPPED {test}: ROBOCAL_TEST_PG is not set, so `robocal migrate` was NOT tested against PostgreSQL. \
                 Start a server with `scripts/pg_cluster.sh start` and export ROBOCAL_TEST_PG=<its URL>. ***\n"
            );
            None
        }
    }
}

/// A database of its own on the test server, empty (not migrated): `tests/common`'s, with what
/// these tests read of it.
use common::PgDb;

trait PgDbExt {
    async fn tables(&self) -> Vec<String>;
    async fn counts(&self) -> BTreeMap<String, i64>;
    async fn has_marker(&self) -> bool;
}

impl PgDbExt for PgDb {
    /// The base tables of its schema.
    async fn tables(&self) -> Vec<String> {
        let mut c = self.connect().await;
        let t = sqlx::query_scalar(
            "SELECT table_name::text FROM information_schema.tables \
             WHERE table_schema = current_schema() AND table_type = 'BASE TABLE' ORDER BY 1",
        )
        .fetch_all(&mut c)
        .await
        .unwrap();
        c.close().await.unwrap();
        t
    }

    async fn counts(&self) -> BTreeMap<String, i64> {
        let mut c = self.connect().await;
        let mut out = BTreeMap::new();
        for t in TABLES {
            let n: i64 = sqlx::query_scalar(sqlx::AssertSqlSafe(format!("SELECT count(*) FROM {t}")))
                .fetch_one(&mut c)
                .await
                .unwrap();
            out.insert(t.to_string(), n);
        }
        c.close().await.unwrap();
        out
    }

    async fn has_marker(&self) -> bool {
        self.tables().await.iter().any(|t| t == transfer::MARKER_TABLE)
    }
}

fn robocal(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// The walkthrough's database (built once per run of this file, then only read).
fn walkthrough_db() -> &'static Path {
    static DB: OnceLock<PathBuf> = OnceLock::new();
    DB.get_or_init(|| {
        let started = Instant::now();
        let dir = fresh_dir("migrate-walkthrough");
        let db = dir.join("walkthrough.db");
        let port = common::free_port();
        let mut server = Command::new(BIN)
            .args(["serve", "--db", db.to_str().unwrap(), "--bind", &format!("127.0.0.1:{port}")])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let deadline = Instant::now() + Duration::from_secs(30);
        while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
            assert!(Instant::now() < deadline, "the server did not start");
            std::thread::sleep(Duration::from_millis(50));
        }
        let out = Command::new("bash")
            .arg(Path::new(ROOT).join("scripts/api_walkthrough.sh"))
            .env("API", format!("http://127.0.0.1:{port}"))
            .env("ROBOCAL", BIN)
            .output()
            .unwrap();
        // A clean stop (SIGTERM), so the lock is released and the server's work is on disk.
        let _ = Command::new("kill").args(["-TERM", &server.id().to_string()]).status();
        let _ = server.wait();
        assert!(
            out.status.success(),
            "scripts/api_walkthrough.sh exited {:?}\nstdout: {}\nstderr: {}",
            out.status.code(),
            text(&out.stdout),
            text(&out.stderr)
        );
        let db_arg = db.to_str().unwrap();
        for (name, scopes) in [("admin", "admin"), ("cell-3-pc", "measure,read")] {
            let out = robocal(&["token", "create", "--db", db_arg, "--name", name, "--scopes", scopes]);
            assert!(out.status.success(), "{}", text(&out.stderr));
            if name == "cell-3-pc" {
                let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
                let out = robocal(&["token", "revoke", "--db", db_arg, v["id"].as_str().unwrap()]);
                assert!(out.status.success(), "{}", text(&out.stderr));
            }
        }
        let _ =
            writeln!(std::io::stderr(), "the walkthrough's database built in {:.1} s", started.elapsed().as_secs_f64());
        db
    })
}

/// A value as this test reads it, independently of `db::transfer`: a SQLite value by its
/// storage class; a PostgreSQL BOOLEAN as the 0/1 it was on SQLite, a DOUBLE PRECISION by its bits.
#[derive(Clone, Debug, PartialEq)]
enum V {
    Null,
    Int(i64),
    Real(u64),
    Text(String),
    Blob(Vec<u8>),
}

type Rows = Vec<BTreeMap<String, V>>;

/// A table's primary-key columns, from SQLite's catalogue.
async fn sqlite_key(conn: &mut SqliteConnection, table: &str) -> Vec<String> {
    let cols: Vec<(String, i64)> =
        sqlx::query_as("SELECT name, pk FROM pragma_table_info(?1) WHERE pk > 0 ORDER BY pk")
            .bind(table)
            .fetch_all(&mut *conn)
            .await
            .unwrap();
    cols.into_iter().map(|c| c.0).collect()
}

async fn open_sqlite(path: &Path) -> SqliteConnection {
    SqliteConnection::connect_with(&SqliteConnectOptions::new().filename(path).read_only(true)).await.unwrap()
}

async fn sqlite_rows(conn: &mut SqliteConnection, table: &str, key: &[String]) -> Rows {
    let rows = sqlx::query(sqlx::AssertSqlSafe(format!("SELECT * FROM {table} ORDER BY {}", key.join(", "))))
        .fetch_all(&mut *conn)
        .await
        .unwrap();
    rows.iter()
        .map(|r| {
            r.columns()
                .iter()
                .map(|c| {
                    let i = c.ordinal();
                    let raw = r.try_get_raw(i).unwrap();
                    let v = if raw.is_null() {
                        V::Null
                    } else {
                        match raw.type_info().name() {
                            "INTEGER" => V::Int(r.try_get_unchecked(i).unwrap()),
                            "REAL" => V::Real(r.try_get_unchecked::<f64, _>(i).unwrap().to_bits()),
                            "TEXT" => V::Text(r.try_get_unchecked(i).unwrap()),
                            "BLOB" => V::Blob(r.try_get_unchecked(i).unwrap()),
                            other => panic!("{table}.{}: SQLite type {other}", c.name()),
                        }
                    };
                    (c.name().to_string(), v)
                })
                .collect()
        })
        .collect()
}

/// A PostgreSQL table's rows in the same key order (text bytewise), and its BOOLEAN columns.
async fn pg_rows(conn: &mut PgConnection, table: &str, key: &[String]) -> (Rows, Vec<String>) {
    let order: Vec<String> = key.iter().map(|k| format!("{k} COLLATE \"C\"")).collect();
    // `seq` is the only non-text key column: COLLATE on a BIGINT is an error, so it goes bare.
    let order: Vec<String> = order.into_iter().zip(key).map(|(o, k)| if k == "seq" { k.clone() } else { o }).collect();
    let rows = sqlx::query(sqlx::AssertSqlSafe(format!("SELECT * FROM {table} ORDER BY {}", order.join(", "))))
        .fetch_all(&mut *conn)
        .await
        .unwrap();
    let mut booleans = Vec::new();
    let rows = rows
        .iter()
        .map(|r| {
            r.columns()
                .iter()
                .map(|c| {
                    let i = c.ordinal();
                    let ty = c.type_info().name().to_string();
                    let v = match ty.as_str() {
                        "INT8" => r.try_get::<Option<i64>, _>(i).unwrap().map(V::Int),
                        "FLOAT8" => r.try_get::<Option<f64>, _>(i).unwrap().map(|x| V::Real(x.to_bits())),
                        "TEXT" => r.try_get::<Option<String>, _>(i).unwrap().map(V::Text),
                        "BYTEA" => r.try_get::<Option<Vec<u8>>, _>(i).unwrap().map(V::Blob),
                        "BOOL" => {
                            if !booleans.contains(&c.name().to_string()) {
                                booleans.push(c.name().to_string());
                            }
                            r.try_get::<Option<bool>, _>(i).unwrap().map(|b| V::Int(b.into()))
                        }
                        other => panic!("{table}.{}: PostgreSQL type {other}", c.name()),
                    };
                    (c.name().to_string(), v.unwrap_or(V::Null))
                })
                .collect()
        })
        .collect();
    (rows, booleans)
}

/// Every table of the source and the target read in key order and compared value by value; the
/// source's row counts.
async fn assert_same_rows(source: &Path, target: &PgDb) -> BTreeMap<String, usize> {
    let mut s = open_sqlite(source).await;
    let mut p = target.connect().await;
    let mut counts = BTreeMap::new();
    let mut all_booleans = Vec::new();
    for table in TABLES {
        let key = sqlite_key(&mut s, table).await;
        assert!(!key.is_empty(), "{table}: no primary key");
        let a = sqlite_rows(&mut s, table, &key).await;
        let (b, booleans) = pg_rows(&mut p, table, &key).await;
        all_booleans.extend(booleans.into_iter().map(|c| format!("{table}.{c}")));
        assert_eq!(a.len(), b.len(), "{table}: {} rows in the source, {} in the target", a.len(), b.len());
        for (i, (x, y)) in a.iter().zip(&b).enumerate() {
            assert_eq!(x, y, "{table}: row {i} (in key order) differs");
        }
        counts.insert(table.to_string(), a.len());
    }
    // The two flags went to BOOLEAN columns (and compared as the 0/1 they were).
    all_booleans.sort();
    assert_eq!(all_booleans, ["jobs.cancel_requested", "sessions.identify_tcp"]);
    s.close().await.unwrap();
    p.close().await.unwrap();
    counts
}

/// 1. The walkthrough's database migrated with the command as a user types it; every table
///    non-empty, every row the same on both sides (read here, not by the tool), the cycle
///    (robots → parameter_sets → robots) closed, and the tool's own table all "match".
#[tokio::test]
async fn the_walkthrough_database_migrates_row_for_row() {
    let Some(server) = server_url("the_walkthrough_database_migrates_row_for_row") else { return };
    let source = walkthrough_db();
    let target = PgDb::create(&server, "robocal_mig").await;
    let started = Instant::now();
    let out = robocal(&[
        "migrate",
        "--from",
        &format!("sqlite:{}", source.display()),
        "--to",
        &target.url,
        "--batch-rows",
        "200",
    ]);
    let took = started.elapsed();
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(out.status.success(), "migrate exited {:?}\nstdout: {stdout}\nstderr: {stderr}", out.status.code());
    for t in TABLES {
        assert!(
            stderr.lines().any(|l| l.starts_with(&format!("{t}: ")) && l.contains(" rows copied in ")),
            "no progress line for {t}:\n{stderr}"
        );
        let line = stdout.lines().find(|l| l.starts_with(&format!("{t} "))).unwrap_or_else(|| panic!("{t}:\n{stdout}"));
        assert!(line.contains(" match "), "{line}");
    }
    assert!(stdout.contains("every table's rows and checksum match"), "{stdout}");
    assert!(stderr.contains("robots: active_parameter_set_id set on 1 rows"), "{stderr}");

    let counts = assert_same_rows(source, &target).await;
    for (t, n) in &counts {
        assert!(*n > 0, "{t} is empty in the walkthrough's database: the round trip would not cover it");
    }
    // Several batches of 200 for the measurements.
    let n = counts["measurements"];
    assert!(n > 400, "{counts:?}");
    let line = format!("measurements: {n} rows copied in {} batches", n.div_ceil(200));
    assert!(stderr.contains(&line), "{line}:\n{stderr}");
    // The cycle: the robot's active set is set in the target, and it is a set the target holds.
    let mut p = target.connect().await;
    let active: Option<String> = sqlx::query_scalar(
        "SELECT r.active_parameter_set_id FROM robots r JOIN parameter_sets s ON s.id = r.active_parameter_set_id",
    )
    .fetch_optional(&mut p)
    .await
    .unwrap();
    assert!(active.is_some(), "the robot's active set was not restored");
    p.close().await.unwrap();
    assert!(!target.has_marker().await, "the marker stays only while a migration is unfinished");
    let _ = writeln!(
        std::io::stderr(),
        "migrate: {} rows in {:.2} s (debug build)",
        counts.values().sum::<usize>(),
        took.as_secs_f64()
    );
    drop(target);
}

/// 2. A target holding any row is refused before anything is written to it: one holding another
///    application's table (no migration applied, no marker), and one holding a finished migration.
#[tokio::test]
async fn a_non_empty_target_is_refused_and_nothing_is_written() {
    let Some(server) = server_url("a_non_empty_target_is_refused_and_nothing_is_written") else { return };
    let source = walkthrough_db();
    let from = format!("sqlite:{}", source.display());

    let other = PgDb::create(&server, "robocal_mig").await;
    let mut c = other.connect().await;
    sqlx::raw_sql("CREATE TABLE notes (x INTEGER); INSERT INTO notes VALUES (1)").execute(&mut c).await.unwrap();
    c.close().await.unwrap();
    let out = robocal(&["migrate", "--from", &from, "--to", &other.url]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    let stderr = text(&out.stderr);
    assert!(stderr.contains("the target database is not empty (notes: 1 row)"), "{stderr}");
    assert!(stderr.contains("nothing was written"), "{stderr}");
    assert_eq!(other.tables().await, ["notes"], "no migration, no marker, no table was written");
    drop(other);

    let full = PgDb::create(&server, "robocal_mig").await;
    let v = transfer::migrate(source, &full.options(), &Options::default(), &mut |_| {}).await.unwrap();
    assert!(v.ok(), "{}", v.table());
    let before = full.counts().await;
    let out = robocal(&["migrate", "--from", &from, "--to", &full.url]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    let stderr = text(&out.stderr);
    assert!(stderr.contains("the target database is not empty (") && stderr.contains("robots: 1 row,"), "{stderr}");
    assert_eq!(full.counts().await, before, "nothing written");
    assert!(!full.has_marker().await);
    drop(full);
}

/// 3. A migration stopped after a few batches at a time (as a killed process stops: the batches
///    committed stay, nothing else) is resumed by the same call until it completes: then the
///    checksums match, the counts are the source's (no row twice), the marker is gone. A marker
///    of another source, or of this source before it changed, is refused.
#[tokio::test]
async fn an_interrupted_migration_resumes_to_the_same_result() {
    let Some(server) = server_url("an_interrupted_migration_resumes_to_the_same_result") else { return };
    let source = walkthrough_db();
    let target = PgDb::create(&server, "robocal_mig").await;
    let source_counts = {
        let mut s = open_sqlite(source).await;
        let mut m = BTreeMap::new();
        for t in TABLES {
            let n: i64 = sqlx::query_scalar(sqlx::AssertSqlSafe(format!("SELECT count(*) FROM {t}")))
                .fetch_one(&mut s)
                .await
                .unwrap();
            m.insert(t.to_string(), n);
        }
        s.close().await.unwrap();
        m
    };
    let opts = Options { batch_rows: 150, stop_after_batches: Some(4) };
    let (mut runs, mut partial_measurements) = (0, false);
    let verification = loop {
        runs += 1;
        assert!(runs < 100, "no progress");
        let mut m = transfer::prepare(source, &target.options()).await.unwrap();
        assert_eq!(m.resumed(), runs > 1, "run {runs}");
        match m.copy(&opts, &mut |_| {}).await {
            Err(TransferError::Interrupted(4)) => {
                // A killed process: its connections just go.
                drop(m);
                let now = target.counts().await;
                assert!(target.has_marker().await);
                let copied = now["measurements"];
                partial_measurements |= copied > 0 && copied < source_counts["measurements"];
                for (t, n) in &now {
                    assert!(*n <= source_counts[t], "{t}: {n} rows, more than the source's {}", source_counts[t]);
                }
            }
            Ok(_) => break m.finish(&mut |_| {}).await.unwrap(),
            Err(e) => panic!("run {runs}: {e}"),
        }
    };
    assert!(runs >= 5, "interrupted only {} times", runs - 1);
    assert!(partial_measurements, "no run stopped in the middle of a table");
    assert!(verification.ok(), "{}", verification.table());
    assert_eq!(target.counts().await, source_counts);
    assert!(!target.has_marker().await);
    assert_same_rows(source, &target).await;
    drop(target);

    // A marker is honoured only for the same source, unchanged.
    let dir = fresh_dir("migrate-small");
    let (a, b) = (dir.join("a.db"), dir.join("b.db"));
    for p in [&a, &b] {
        let pool = db::connect(p).await.unwrap();
        db::tokens::create(&pool, "admin", &[db::tokens::Scope::Admin]).await.unwrap();
        pool.close().await;
    }
    let target = PgDb::create(&server, "robocal_mig").await;
    let mut m = transfer::prepare(&a, &target.options()).await.unwrap();
    let stop = Options { batch_rows: 10, stop_after_batches: Some(0) };
    assert!(matches!(m.copy(&stop, &mut |_| {}).await, Err(TransferError::Interrupted(0))));
    drop(m);
    let e = transfer::migrate(&b, &target.options(), &Options::default(), &mut |_| {}).await.err().unwrap();
    assert!(matches!(e, TransferError::OtherMigration(_)), "{e}");
    assert!(e.to_string().contains("it was started from") && e.to_string().contains("a.db"), "{e}");
    let pool = db::connect(&a).await.unwrap();
    db::tokens::create(&pool, "cell-1", &[db::tokens::Scope::Read]).await.unwrap();
    pool.close().await;
    let e = transfer::migrate(&a, &target.options(), &Options::default(), &mut |_| {}).await.err().unwrap();
    assert!(e.to_string().contains("changed since it was started"), "{e}");
    assert_eq!(target.counts().await["tokens"], 0);
    drop(target);
    let _ = std::fs::remove_dir_all(&dir);
}

/// 4. One target value altered after the copy: the verification names that table (and only it),
///    keeps the marker, and the command exits 1 with the table in its output.
#[tokio::test]
async fn a_checksum_mismatch_names_the_table() {
    let Some(server) = server_url("a_checksum_mismatch_names_the_table") else { return };
    let source = walkthrough_db();
    let target = PgDb::create(&server, "robocal_mig").await;
    let mut m = transfer::prepare(source, &target.options()).await.unwrap();
    m.copy(&Options::default(), &mut |_| {}).await.unwrap();
    let mut c = target.connect().await;
    let changed = sqlx::query(
        "UPDATE measurements SET spec_json = spec_json || ' ' WHERE (session_id, seq) = \
         (SELECT session_id, seq FROM measurements ORDER BY session_id COLLATE \"C\" DESC, seq DESC LIMIT 1)",
    )
    .execute(&mut c)
    .await
    .unwrap()
    .rows_affected();
    assert_eq!(changed, 1);
    c.close().await.unwrap();
    let v = m.finish(&mut |_| {}).await.unwrap();
    assert!(!v.ok());
    assert_eq!(v.mismatched(), ["measurements"]);
    let row = v.tables.iter().find(|t| t.table == "measurements").unwrap();
    assert_eq!(row.source_rows, row.target_rows, "the same count, another checksum");
    assert_ne!(row.source_sha256, row.target_sha256);
    assert!(target.has_marker().await, "the marker stays until everything matches");

    // The same command again resumes (nothing left to copy) and fails the same way.
    let out = robocal(&["migrate", "--from", source.to_str().unwrap(), "--to", &target.url]);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert_eq!(out.status.code(), Some(1), "{stdout}\n{stderr}");
    assert!(stderr.contains("resuming the unfinished migration"), "{stderr}");
    let line = stdout.lines().find(|l| l.starts_with("measurements ")).unwrap_or_else(|| panic!("{stdout}"));
    assert!(line.contains("MISMATCH"), "{line}");
    assert_eq!(stdout.matches("MISMATCH").count(), 1, "{stdout}");
    assert!(stderr.contains("the copy differs from the source in measurements"), "{stderr}");
    drop(target);
}

/// Refusals before any server is needed: a source missing or not at the latest migration, an
/// unreachable server, a target that is not a PostgreSQL URL; each names its reason.
#[tokio::test]
async fn refusals_name_their_reason() {
    let dir = fresh_dir("migrate-refusals");
    let missing = dir.join("missing.db");
    let out = robocal(&["migrate", "--from", missing.to_str().unwrap(), "--to", "postgres://robocal@127.0.0.1:1/x"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("--from: the source") && text(&out.stderr).contains("cannot open"),
        "{}",
        text(&out.stderr)
    );
    assert!(!missing.exists(), "a missing source is not created");

    // A database whose last migration is not recorded: as one written by an older robocal.
    let old = dir.join("old.db");
    let pool = db::connect(&old).await.unwrap();
    let latest = db::MIGRATOR.iter().map(|m| m.version).max().unwrap();
    sqlx::query("DELETE FROM _sqlx_migrations WHERE version = ?1").bind(latest).execute(&pool).await.unwrap();
    pool.close().await;
    let out = robocal(&[
        "migrate",
        "--from",
        &format!("sqlite:{}", old.display()),
        "--to",
        "postgres://robocal@127.0.0.1:1/x",
    ]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = text(&out.stderr);
    assert!(stderr.contains("is not at this robocal's latest migration"), "{stderr}");
    assert!(stderr.contains(&format!("it is at migration {}, the latest is {latest}", latest - 1)), "{stderr}");
    assert!(stderr.contains("robocal serve --db"), "{stderr}");

    // A current source, no server at that port.
    let pool = db::connect(&dir.join("ok.db")).await.unwrap();
    pool.close().await;
    let out = robocal(&[
        "migrate",
        "--from",
        dir.join("ok.db").to_str().unwrap(),
        "--to",
        "postgres://robocal@127.0.0.1:1/x",
    ]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = text(&out.stderr);
    assert!(stderr.contains("--to: cannot reach the PostgreSQL server robocal@127.0.0.1:1/x"), "{stderr}");

    // A source a server holds is refused naming it; one a migration reads is not (two
    // migrations may read one source), but a server will not start on it meanwhile.
    let ok = dir.join("ok.db");
    let server = robocal::server::lock::DbLock::acquire(&ok).unwrap().unwrap();
    let out = robocal(&["migrate", "--from", ok.to_str().unwrap(), "--to", "postgres://robocal@127.0.0.1:1/x"]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("is served by another robocal process") && stderr.contains("stop it before migrating"),
        "{stderr}"
    );
    drop(server);
    let reader = robocal::server::lock::DbLock::acquire_shared(&ok).unwrap().unwrap();
    let out = robocal(&["migrate", "--from", ok.to_str().unwrap(), "--to", "postgres://robocal@127.0.0.1:1/x"]);
    assert!(text(&out.stderr).contains("--to: cannot reach"), "{}", text(&out.stderr));
    let out = robocal(&["serve", "--db", ok.to_str().unwrap(), "--bind", "127.0.0.1:0"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("is being read by `robocal migrate`"), "{}", text(&out.stderr));
    drop(reader);

    let out = robocal(&["migrate", "--from", dir.join("ok.db").to_str().unwrap(), "--to", "mysql://x@y/z"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("--to: expected a postgres://"), "{}", text(&out.stderr));
    let _ = std::fs::remove_dir_all(&dir);
}
