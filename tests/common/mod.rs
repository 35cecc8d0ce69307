//! Helpers for the HTTP tests: the real router on a fresh database, with or without job workers,
//! and one-line requests.
//!
//! The backend is chosen by `ROBOCAL_TEST_BACKEND`: unset or `sqlite`, a fresh SQLite file (WAL,
//! as in production); `postgres`, a fresh database of its own on the server `ROBOCAL_TEST_PG`
//! names (`scripts/pg_cluster.sh start` prints one), created with the C collation and dropped
//! when the test's app is dropped.

#![allow(dead_code)]

use std::path::PathBuf;
use std::time::Duration;

use axum::Router;
use axum::body::Body;
use axum::http::{HeaderMap, Method, Request, StatusCode, header};
use http_body_util::BodyExt;
use robocal::domain::cell::CellFile;
use robocal::http::{AppState, ServiceConfig, app};
use robocal::jobs::Workers;
use serde_json::{Value, json};
use tower::ServiceExt;

pub struct TestApp {
    pub router: Router,
    pub state: AppState,
    pub workers: Option<Workers>,
    pub dir: PathBuf,
    pub token: Option<String>,
    /// The PostgreSQL database of this app (dropped with it), when the backend is PostgreSQL.
    pub pg: Option<PgDb>,
}

/// Every table of the store, in name order (`tests/suite/postgres_schema.rs` reads them from both
/// catalogues and checks this list; `tests/suite/migrate_pg.rs` copies and counts each).
pub const STORE_TABLES: [&str; 15] = [
    "artefacts",
    "audit_events",
    "batches",
    "diagnoses",
    "iso9283_evaluations",
    "jobs",
    "measurement_exclusions",
    "measurements",
    "parameter_set_activations",
    "parameter_sets",
    "pose_plans",
    "robots",
    "sessions",
    "tokens",
    "validations",
];

/// The backend the HTTP and job tests run on (`ROBOCAL_TEST_BACKEND`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TestBackend {
    Sqlite,
    Postgres,
}

pub fn test_backend() -> TestBackend {
    match std::env::var("ROBOCAL_TEST_BACKEND").as_deref() {
        Err(_) | Ok("" | "sqlite") => TestBackend::Sqlite,
        Ok("postgres") => TestBackend::Postgres,
        Ok(other) => panic!("ROBOCAL_TEST_BACKEND={other}: say sqlite or postgres"),
    }
}

/// The server `ROBOCAL_TEST_PG` names; a clear panic when the PostgreSQL backend is asked for
/// without one.
pub fn test_server() -> String {
    std::env::var("ROBOCAL_TEST_PG").unwrap_or_else(|_| {
        panic!(
            "ROBOCAL_TEST_BACKEND=postgres needs ROBOCAL_TEST_PG=<server URL>: start one with `scripts/pg_cluster.sh start`"
        )
    })
}

/// A database of its own on a PostgreSQL server, created empty with the C collation; dropped
/// (`WITH (FORCE)`, so open connections do not keep it) when this is dropped.
pub struct PgDb {
    pub admin: sqlx::postgres::PgConnectOptions,
    pub name: String,
    pub url: String,
}

impl PgDb {
    pub async fn create(server: &str, prefix: &str) -> PgDb {
        use sqlx::Connection;
        let admin: sqlx::postgres::PgConnectOptions =
            server.parse().unwrap_or_else(|e| panic!("ROBOCAL_TEST_PG={server}: {e}"));
        let name = format!("{prefix}_{}", robocal::db::new_id().replace('-', ""));
        let mut conn = sqlx::PgConnection::connect_with(&admin).await.unwrap_or_else(|e| panic!("{server}: {e}"));
        sqlx::query(sqlx::AssertSqlSafe(format!(
            "CREATE DATABASE {name} TEMPLATE template0 LC_COLLATE 'C' LC_CTYPE 'C' ENCODING 'UTF8'"
        )))
        .execute(&mut conn)
        .await
        .unwrap();
        conn.close().await.unwrap();
        let (base, query) = match server.split_once('?') {
            Some((b, q)) => (b, format!("?{q}")),
            None => (server, String::new()),
        };
        let (host, _) = base.rsplit_once('/').expect("a URL with a database");
        let url = format!("{host}/{name}{query}");
        PgDb { admin, name, url }
    }

    pub fn options(&self) -> sqlx::postgres::PgConnectOptions {
        self.admin.clone().database(&self.name)
    }

    pub async fn connect(&self) -> sqlx::PgConnection {
        use sqlx::Connection;
        sqlx::PgConnection::connect_with(&self.options()).await.unwrap()
    }
}

impl Drop for PgDb {
    fn drop(&mut self) {
        // On a thread of its own with its own runtime: drop runs inside the test's runtime,
        // which must not be blocked on.
        let (admin, name) = (self.admin.clone(), self.name.clone());
        let _ = std::thread::spawn(move || {
            let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
            rt.block_on(async move {
                use sqlx::Connection;
                if let Ok(mut conn) = sqlx::PgConnection::connect_with(&admin).await {
                    let _ = sqlx::query(sqlx::AssertSqlSafe(format!("DROP DATABASE IF EXISTS {name} WITH (FORCE)")))
                        .execute(&mut conn)
                        .await;
                    let _ = conn.close().await;
                }
            })
        })
        .join();
    }
}

pub struct Res {
    pub status: StatusCode,
    pub headers: HeaderMap,
    pub body: Value,
    pub text: String,
}

/// A fresh directory under the system temp dir.
pub fn fresh_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("robocal-test-{tag}-{}-{}", std::process::id(), robocal::db::new_id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

impl TestApp {
    pub async fn new(config: ServiceConfig, workers: bool) -> TestApp {
        let dir = fresh_dir("http");
        let (pool, pg) = match test_backend() {
            TestBackend::Sqlite => (robocal::db::connect(&dir.join("robocal.db")).await.unwrap(), None),
            TestBackend::Postgres => {
                let pg = PgDb::create(&test_server(), "robocal_t").await;
                (robocal::db::connect_url(&pg.url).await.unwrap(), Some(pg))
            }
        };
        let state = AppState::new(pool, config);
        let w =
            if workers { Some(Workers::start(state.clone(), 1, Duration::from_secs(5)).await.unwrap()) } else { None };
        TestApp { router: app(state.clone()), state, workers: w, dir, token: None, pg }
    }

    pub async fn default() -> TestApp {
        Self::new(ServiceConfig::default(), true).await
    }

    pub async fn raw(
        &self,
        method: Method,
        path: &str,
        content_type: Option<&str>,
        body: Vec<u8>,
        headers: &[(&str, &str)],
    ) -> Res {
        let mut req = Request::builder().method(method).uri(path);
        if let Some(ct) = content_type {
            req = req.header(header::CONTENT_TYPE, ct);
        }
        if let Some(t) = &self.token {
            req = req.header(header::AUTHORIZATION, format!("Bearer {t}"));
        }
        for (k, v) in headers {
            req = req.header(*k, *v);
        }
        let res = self.router.clone().oneshot(req.body(Body::from(body)).unwrap()).await.unwrap();
        let status = res.status();
        let headers = res.headers().clone();
        let bytes = res.into_body().collect().await.unwrap().to_bytes();
        let text = String::from_utf8_lossy(&bytes).into_owned();
        let body = serde_json::from_slice(&bytes).unwrap_or(Value::Null);
        Res { status, headers, body, text }
    }

    pub async fn get(&self, path: &str) -> Res {
        self.raw(Method::GET, path, None, Vec::new(), &[]).await
    }

    pub async fn post(&self, path: &str, body: &Value) -> Res {
        self.raw(Method::POST, path, Some("application/json"), serde_json::to_vec(body).unwrap(), &[]).await
    }

    pub async fn put(&self, path: &str, body: &Value) -> Res {
        self.raw(Method::PUT, path, Some("application/json"), serde_json::to_vec(body).unwrap(), &[]).await
    }

    /// Wait for a job to end (the workers must be running); its final representation.
    pub async fn wait(&self, job: &Value) -> Value {
        let id = job["id"].as_str().unwrap_or_else(|| panic!("not a job: {job}")).to_string();
        for _ in 0..6000 {
            let j = self.get(&format!("/v1/jobs/{id}")).await.body;
            if matches!(j["state"].as_str(), Some("succeeded" | "failed" | "cancelled")) {
                return j;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        panic!("job {id} did not finish");
    }

    pub async fn stop(mut self) {
        if let Some(w) = self.workers.take() {
            w.shutdown().await;
        }
        self.state.pool.close().await;
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// An expected problem: status, problem+json content type, and the field when given.
pub fn assert_problem(r: &Res, status: u16, field: Option<&str>) {
    assert_eq!(r.status.as_u16(), status, "{}", r.text);
    assert_eq!(r.headers[header::CONTENT_TYPE], "application/problem+json", "{}", r.text);
    assert_eq!(r.body["status"], status, "{}", r.text);
    assert!(r.body["type"].as_str().unwrap().starts_with("urn:robocal:problem:"), "{}", r.text);
    assert!(r.body["title"].is_string() && r.body["detail"].is_string(), "{}", r.text);
    if let Some(f) = field {
        assert_eq!(r.body["field"], f, "{}", r.text);
    }
}

/// The thesis's robot position (Table 5.1 nominal base) as a base guess.
pub fn base_guess() -> Value {
    serde_json::json!({"x_mm": 160.211, "y_mm": -255.727, "z_mm": -220.548, "a_deg": 91.603, "b_deg": 0.496, "c_deg": -1.384})
}

/// A robot (the irb120 preset at the thesis's base guess); its id.
pub async fn robot(app: &TestApp, name: &str) -> String {
    let r =
        app.post("/v1/robots", &json!({"name": name, "robot": {"preset": "irb120"}, "base_guess": base_guess()})).await;
    assert_eq!(r.status, StatusCode::CREATED, "{}", r.text);
    r.body["id"].as_str().unwrap().to_string()
}

/// A ball-triangle artefact (300 mm sides); its id.
pub async fn artefact(app: &TestApp, name: &str) -> String {
    let r = app
        .post(
            "/v1/artefacts",
            &json!({"name": name, "distances_mm": {"d12": 300, "d13": 300, "d23": 300}, "ball_diameter_mm": 12.7}),
        )
        .await;
    assert_eq!(r.status, StatusCode::CREATED, "{}", r.text);
    r.body["id"].as_str().unwrap().to_string()
}

/// Create the cell's sessions on a robot (with their measuring-order marker, identified TCP and
/// target) and upload their
/// measurements; session name → id.
pub async fn upload(app: &TestApp, robot_id: &str, artefact_id: &str, cell: &CellFile) -> Vec<(String, String)> {
    let mut ids = Vec::new();
    for s in &cell.sessions {
        let r = app
            .post(
                &format!("/v1/robots/{robot_id}/sessions"),
                &json!({"name": s.name, "purpose": s.purpose, "instrument": s.instrument, "tool": s.tool, "artefact_id": artefact_id,
                        "order": s.order, "identify_tcp": s.identify_tcp, "target": s.target}),
            )
            .await;
        assert_eq!(r.status, StatusCode::CREATED, "{}", r.text);
        let sid = r.body["id"].as_str().unwrap().to_string();
        let r = app.post(&format!("/v1/sessions/{sid}/measurements"), &json!({"measurements": s.measurements})).await;
        assert_eq!(r.status, StatusCode::CREATED, "{}", r.text);
        assert_eq!(r.body["count"], s.measurements.len());
        ids.push((s.name.clone(), sid));
    }
    ids
}

/// A TCP port free on the loopback interface now (for a `robocal serve` process to bind).
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// Waits until a server answers `/readyz` with 2xx (at most 60 s, then panics).
pub async fn wait_ready(client: &robocal::http::client::Client) {
    let t = std::time::Instant::now();
    while t.elapsed() < Duration::from_secs(60) {
        if let Ok(a) = client.send(Method::GET, "/readyz", None, &[]).await
            && a.status.is_success()
        {
            return;
        }
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    panic!("the server did not become ready within 60 s");
}
