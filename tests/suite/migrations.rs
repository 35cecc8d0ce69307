//! Migrating a database made by an earlier schema: its rows survive, its foreign keys are still
//! enforced afterwards, and a database whose rows would violate them is refused whole.

use crate::common;

use std::path::Path;

use common::fresh_dir;
use robocal::db;
use robocal::db::Pool as SqlitePool;

/// A database file at schema version `version` only, with foreign-key enforcement as asked.
async fn at_version(path: &Path, version: i64, foreign_keys: bool) -> SqlitePool {
    // Through `Any`, as the store opens it: the pragmas on each new connection.
    sqlx::any::install_default_drivers();
    let pool = sqlx::any::AnyPoolOptions::new()
        .max_connections(1)
        .after_connect(move |conn, _| {
            Box::pin(async move {
                use sqlx::Executor;
                conn.execute("PRAGMA journal_mode = WAL").await?;
                conn.execute(if foreign_keys { "PRAGMA foreign_keys = ON" } else { "PRAGMA foreign_keys = OFF" })
                    .await?;
                Ok(())
            })
        })
        .connect(&format!("sqlite://{}?mode=rwc", path.display()))
        .await
        .unwrap();
    db::MIGRATOR.run_to(version, &pool).await.unwrap();
    pool
}

async fn exec(pool: &SqlitePool, sql: &str) {
    sqlx::query(sqlx::AssertSqlSafe(sql.to_string())).execute(pool).await.unwrap_or_else(|e| panic!("{sql}: {e}"));
}

/// Rows in every table that references jobs (and one job of each kind and state), as the 0001
/// schema stored them.
async fn fill_v1(pool: &SqlitePool) {
    exec(
        pool,
        "INSERT INTO robots (id, name, model_json, created_at) VALUES ('r1', 'cell', '{\"preset\": \"irb120\"}', 't0')",
    )
    .await;
    for (id, kind, state) in [
        ("j1", "pose_plan", "succeeded"),
        ("j2", "identification", "succeeded"),
        ("j3", "validation", "failed"),
        ("j4", "identification", "queued"),
    ] {
        exec(
            pool,
            &format!(
                "INSERT INTO jobs (id, kind, robot_id, state, progress, request_json, result_json, attempts, created_at, updated_at) \
                 VALUES ('{id}', '{kind}', 'r1', '{state}', 0.5, '{{\"k\": \"{id}\"}}', '{{}}', 2, 't-{id}', 'u-{id}')"
            ),
        )
        .await;
    }
    exec(pool, "INSERT INTO parameter_sets (id, robot_id, version, doc_json, sessions_json, job_id, created_at) VALUES ('s1', 'r1', 1, '{}', '[]', 'j2', 't1')").await;
    exec(pool, "UPDATE robots SET active_parameter_set_id = 's1'").await;
    exec(pool, "INSERT INTO validations (id, parameter_set_id, sessions_json, report_json, job_id, created_at) VALUES ('v1', 's1', '[]', '{}', 'j3', 't2')").await;
    exec(pool, "INSERT INTO pose_plans (id, robot_id, request_json, result_json, job_id, created_at) VALUES ('p1', 'r1', '{}', '{}', 'j1', 't3')").await;
}

type JobText = (String, String, String, String, f64, String, Option<String>, i64, String, String);

async fn jobs_text(pool: &SqlitePool) -> Vec<JobText> {
    sqlx::query_as(
        "SELECT id, kind, robot_id, state, progress, request_json, result_json, attempts, created_at, updated_at \
         FROM jobs ORDER BY id",
    )
    .fetch_all(pool)
    .await
    .unwrap()
}

async fn applied(pool: &SqlitePool) -> i64 {
    sqlx::query_scalar("SELECT COUNT(*) FROM _sqlx_migrations WHERE success = 1").fetch_one(pool).await.unwrap()
}

#[tokio::test]
async fn a_version_1_database_migrates_keeps_its_rows_and_still_enforces_foreign_keys() {
    let dir = fresh_dir("migrate");
    let path = dir.join("robocal.db");
    let old = at_version(&path, 1, true).await;
    fill_v1(&old).await;
    let before = jobs_text(&old).await;
    old.close().await;

    let pool = db::connect(&path).await.unwrap();
    assert_eq!(applied(&pool).await, db::MIGRATOR.iter().count() as i64);
    assert_eq!(jobs_text(&pool).await, before, "the rebuilt jobs table holds the same rows");
    for (table, n) in [("robots", 1), ("parameter_sets", 1), ("validations", 1), ("pose_plans", 1), ("diagnoses", 0)] {
        let count: i64 = sqlx::query_scalar(sqlx::AssertSqlSafe(format!("SELECT COUNT(*) FROM {table}")))
            .fetch_one(&pool)
            .await
            .unwrap();
        assert_eq!(count, n, "{table}");
    }
    // The references to jobs point at the rebuilt table, and its indexes are back.
    let parents: Vec<String> = sqlx::query_scalar("SELECT \"table\" FROM pragma_foreign_key_list('parameter_sets')")
        .fetch_all(&pool)
        .await
        .unwrap();
    assert!(parents.contains(&"jobs".to_string()), "{parents:?}");
    let indexes: Vec<String> =
        sqlx::query_scalar("SELECT name FROM sqlite_master WHERE type = 'index' AND tbl_name = 'jobs' AND name NOT LIKE 'sqlite_%' ORDER BY name")
            .fetch_all(&pool)
            .await
            .unwrap();
    assert_eq!(indexes, ["jobs_by_robot", "jobs_by_state"]);
    assert!(
        sqlx::query_scalar::<_, Option<String>>("SELECT name FROM sqlite_master WHERE name = 'jobs_new'")
            .fetch_optional(&pool)
            .await
            .unwrap()
            .is_none()
    );

    // Every connection of the pool enforces foreign keys again.
    let mut conns = Vec::new();
    for _ in 0..3 {
        let mut c = pool.acquire().await.unwrap();
        let on = sqlx::query_scalar::<_, db::types::Flag>("PRAGMA foreign_keys").fetch_one(&mut *c).await.unwrap().0;
        assert!(on);
        conns.push(c);
    }
    drop(conns);
    let dangling = [
        "INSERT INTO parameter_sets (id, robot_id, version, doc_json, sessions_json, job_id, created_at) VALUES ('s2', 'r1', 2, '{}', '[]', 'no-such-job', 't')",
        "INSERT INTO validations (id, parameter_set_id, sessions_json, report_json, job_id, created_at) VALUES ('v2', 's1', '[]', '{}', 'no-such-job', 't')",
        "INSERT INTO jobs (id, kind, robot_id, state, request_json, created_at, updated_at) VALUES ('j9', 'diagnosis', 'no-such-robot', 'queued', '{}', 't', 't')",
        "INSERT INTO diagnoses (id, parameter_set_id, request_json, sessions_json, report_json, job_id, created_at) VALUES ('d1', 'no-such-set', '{}', '{}', '{}', 'j2', 't')",
        "DELETE FROM jobs WHERE id = 'j2'",
    ];
    for sql in dangling {
        let e = sqlx::query(sql).execute(&pool).await.expect_err(sql);
        assert!(e.to_string().contains("FOREIGN KEY"), "{sql}: {e}");
    }
    // The widened CHECK: a diagnosis job is admitted, an unknown kind is not.
    exec(&pool, "INSERT INTO jobs (id, kind, robot_id, state, request_json, created_at, updated_at) VALUES ('j5', 'diagnosis', 'r1', 'queued', '{}', 't', 't')").await;
    let e = sqlx::query("INSERT INTO jobs (id, kind, robot_id, state, request_json, created_at, updated_at) VALUES ('j6', 'dance', 'r1', 'queued', '{}', 't', 't')")
        .execute(&pool)
        .await
        .unwrap_err();
    assert!(e.to_string().contains("CHECK"), "{e}");
    exec(&pool, "INSERT INTO diagnoses (id, parameter_set_id, request_json, sessions_json, report_json, job_id, created_at) VALUES ('d1', 's1', '{}', '{}', '{}', 'j5', 't')").await;
    pool.close().await;

    // Opening the migrated database again changes nothing.
    let pool = db::connect(&path).await.unwrap();
    assert_eq!(applied(&pool).await, db::MIGRATOR.iter().count() as i64);
    assert_eq!(jobs_text(&pool).await.len(), before.len() + 1);
    pool.close().await;
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test]
async fn a_database_with_dangling_references_is_not_migrated() {
    let dir = fresh_dir("migrate-dangling");
    let path = dir.join("robocal.db");
    // Written with enforcement off: a validation of a job that does not exist.
    let old = at_version(&path, 1, false).await;
    fill_v1(&old).await;
    exec(&old, "INSERT INTO validations (id, parameter_set_id, sessions_json, report_json, job_id, created_at) VALUES ('v2', 's1', '[]', '{}', 'gone', 't')").await;
    old.close().await;

    let e = db::connect(&path).await.expect_err("dangling references are refused");
    let msg = e.to_string();
    assert!(
        msg.contains("foreign key") && msg.contains("validations") && msg.contains("nothing was migrated"),
        "{msg}"
    );
    // Rolled back whole: still at version 1, the old jobs table as it was.
    let old = at_version(&path, 1, false).await;
    assert_eq!(applied(&old).await, 1);
    let tables: Vec<String> =
        sqlx::query_scalar("SELECT name FROM sqlite_master WHERE type = 'table' AND name IN ('diagnoses', 'jobs_new')")
            .fetch_all(&old)
            .await
            .unwrap();
    assert!(tables.is_empty(), "{tables:?}");
    assert_eq!(jobs_text(&old).await.len(), 4);
    old.close().await;
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test]
async fn the_in_memory_database_is_migrated_with_foreign_keys_on() {
    let pool = db::connect_memory().await.unwrap();
    assert_eq!(applied(&pool).await, db::MIGRATOR.iter().count() as i64);
    let on = sqlx::query_scalar::<_, db::types::Flag>("PRAGMA foreign_keys").fetch_one(&pool).await.unwrap().0;
    assert!(on);
    let e = sqlx::query("INSERT INTO jobs (id, kind, robot_id, state, request_json, created_at, updated_at) VALUES ('j', 'diagnosis', 'none', 'queued', '{}', 't', 't')")
        .execute(&pool)
        .await
        .unwrap_err();
    assert!(e.to_string().contains("FOREIGN KEY"), "{e}");
}

/// 0003 gives every stored session a measuring-order marker: `unknown` for the sessions stored
/// before it (nobody said), one of the four words only, read back by the store's queries.
#[tokio::test]
async fn sessions_stored_before_the_order_marker_are_unknown() {
    let dir = fresh_dir("migrate-order");
    let path = dir.join("robocal.db");
    let old = at_version(&path, 2, true).await;
    fill_v1(&old).await;
    exec(&old, "INSERT INTO sessions (id, robot_id, name, purpose, instrument, tool_json, created_at) VALUES ('se1', 'r1', 'n1', 'validation', 'laser_tracker', '{\"tcp_mm\": [0, 0, 0]}', 't4')").await;
    exec(&old, "INSERT INTO batches (id, session_id, request_hash, first_seq, count, created_at) VALUES ('b1', 'se1', 'h', 0, 1, 't5')").await;
    exec(&old, "INSERT INTO measurements (session_id, seq, batch_id, spec_json) VALUES ('se1', 0, 'b1', '{\"joints_deg\": [0, 0, 0, 0, 30, 0], \"position_mm\": [1, 2, 3]}')").await;
    old.close().await;

    let pool = db::connect(&path).await.unwrap();
    assert_eq!(applied(&pool).await, db::MIGRATOR.iter().count() as i64);
    let s = robocal::db::records::session(&pool, "se1").await.unwrap().unwrap();
    assert_eq!(s.order, robocal::domain::cell::OrderSpec::Unknown);
    assert_eq!(s.measurements, 1, "the measurements are kept");
    exec(&pool, "UPDATE sessions SET measuring_order = 'shuffled' WHERE id = 'se1'").await;
    let s = robocal::db::records::session(&pool, "se1").await.unwrap().unwrap();
    assert_eq!(s.order, robocal::domain::cell::OrderSpec::Shuffled);
    let e = sqlx::query("UPDATE sessions SET measuring_order = 'sorted' WHERE id = 'se1'")
        .execute(&pool)
        .await
        .unwrap_err();
    assert!(e.to_string().contains("CHECK"), "{e}");
    pool.close().await;
    let _ = std::fs::remove_dir_all(&dir);
}

/// 0004 gives sessions a physical target: none for the sessions stored before it (each identified
/// TCP its own, as they were identified), read back by the store's queries; a blank one is refused.
#[tokio::test]
async fn sessions_stored_before_targets_have_none() {
    let dir = fresh_dir("migrate-target");
    let path = dir.join("robocal.db");
    let old = at_version(&path, 3, true).await;
    fill_v1(&old).await;
    exec(&old, "INSERT INTO sessions (id, robot_id, name, purpose, instrument, tool_json, created_at) VALUES ('se1', 'r1', 'n1', 'validation', 'laser_tracker', '{\"tcp_mm\": [0, 0, 0]}', 't4')").await;
    old.close().await;

    let pool = db::connect(&path).await.unwrap();
    assert_eq!(applied(&pool).await, db::MIGRATOR.iter().count() as i64);
    let s = robocal::db::records::session(&pool, "se1").await.unwrap().unwrap();
    assert_eq!(s.target, None);
    exec(&pool, "UPDATE sessions SET target = 'nest-1' WHERE id = 'se1'").await;
    assert_eq!(robocal::db::records::session(&pool, "se1").await.unwrap().unwrap().target.as_deref(), Some("nest-1"));
    let e = sqlx::query("UPDATE sessions SET target = '  ' WHERE id = 'se1'").execute(&pool).await.unwrap_err();
    assert!(e.to_string().contains("CHECK"), "{e}");
    pool.close().await;
    let _ = std::fs::remove_dir_all(&dir);
}

/// 0005 (audited correction) keeps everything stored before it: the sessions' measurements (none
/// excluded), the batches (their content hash unknown, yet a keyless re-upload of one is still
/// recognised by hashing its rows), the parameter sets (none archived) and the active set, which
/// becomes the first entry of the activation history (time unknown). Its constraints hold: one
/// open exclusion per measurement, of a stored measurement, with a reason.
#[tokio::test]
async fn data_stored_before_audited_correction_survive_it() {
    let dir = fresh_dir("migrate-correction");
    let path = dir.join("robocal.db");
    let old = at_version(&path, 4, true).await;
    fill_v1(&old).await;
    exec(&old, "INSERT INTO sessions (id, robot_id, name, purpose, instrument, tool_json, created_at) VALUES ('se1', 'r1', 'n1', 'validation', 'laser_tracker', '{\"tcp_mm\": [0, 0, 0]}', 't4')").await;
    exec(&old, "INSERT INTO batches (id, session_id, request_hash, first_seq, count, created_at) VALUES ('b1', 'se1', 'h', 0, 2, 't5')").await;
    let specs = [
        r#"{"joints_deg":[0.0,0.0,0.0,0.0,30.0,0.0],"position_mm":[1.0,2.0,3.0]}"#,
        r#"{"joints_deg":[1.0,0.0,0.0,0.0,30.0,0.0],"position_mm":[1.0,2.0,4.0]}"#,
    ];
    for (i, s) in specs.iter().enumerate() {
        exec(
            &old,
            &format!(
                "INSERT INTO measurements (session_id, seq, batch_id, spec_json) VALUES ('se1', {i}, 'b1', '{s}')"
            ),
        )
        .await;
    }
    old.close().await;

    let pool = db::connect(&path).await.unwrap();
    assert_eq!(applied(&pool).await, db::MIGRATOR.iter().count() as i64);
    let s = robocal::db::records::session(&pool, "se1").await.unwrap().unwrap();
    assert_eq!((s.measurements, s.excluded), (2, 0));
    let set = robocal::db::records::parameter_set(&pool, "s1").await.unwrap().unwrap();
    assert_eq!((set.version, set.archived_at), (1, None));
    let acts = robocal::db::corrections::activations(&pool, "r1", 0, 10).await.unwrap().items;
    assert_eq!(acts.len(), 1);
    assert_eq!((acts[0].parameter_set_id.as_str(), acts[0].activated_at.as_deref()), ("s1", None));
    let hash: Option<String> =
        sqlx::query_scalar("SELECT content_hash FROM batches WHERE id = 'b1'").fetch_one(&pool).await.unwrap();
    assert_eq!(hash, None);
    let rows: Vec<String> = specs.iter().map(|s| s.to_string()).collect();
    let mut conn = pool.acquire().await.unwrap();
    let dup = robocal::db::records::identical_batch(&mut conn, "se1", &robocal::db::records::content_hash(&rows), 2)
        .await
        .unwrap();
    assert_eq!(dup.map(|b| b.id).as_deref(), Some("b1"), "an old batch is recognised by its rows");
    drop(conn);

    // The constraints: a reason, a stored measurement, one open exclusion at a time.
    let ins = |id: &str, seq: i64, reason: &str| {
        format!(
            "INSERT INTO measurement_exclusions (id, session_id, seq, reason, excluded_at) VALUES ('{id}', 'se1', {seq}, '{reason}', 't6')"
        )
    };
    exec(&pool, &ins("x1", 1, "outlier")).await;
    assert_eq!(robocal::db::records::session(&pool, "se1").await.unwrap().unwrap().excluded, 1);
    for (sql, want) in
        [(ins("x2", 1, "again"), "UNIQUE"), (ins("x3", 5, "none"), "FOREIGN KEY"), (ins("x4", 0, " "), "CHECK")]
    {
        let e = sqlx::query(sqlx::AssertSqlSafe(sql.clone())).execute(&pool).await.expect_err(&sql);
        assert!(e.to_string().contains(want), "{sql}: {e}");
    }
    let e = sqlx::query("UPDATE measurement_exclusions SET restored_at = 't7' WHERE id = 'x1'")
        .execute(&pool)
        .await
        .unwrap_err();
    assert!(e.to_string().contains("CHECK"), "a restore needs its reason: {e}");
    exec(&pool, "UPDATE measurement_exclusions SET restored_at = 't7', restore_reason = 'fine' WHERE id = 'x1'").await;
    exec(&pool, &ins("x2", 1, "again")).await;
    pool.close().await;
    let _ = std::fs::remove_dir_all(&dir);
}
