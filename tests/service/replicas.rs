//! Several replicas on one PostgreSQL database (issue 27, items 2 and 5): real `robocal serve`
//! processes on one fresh database of the server `ROBOCAL_TEST_PG` names, with a 3 s job lease.
//!
//! 1. A replica is SIGKILLed while it runs a job: another replica takes the job over once its
//!    lease has expired, and it completes with the result an uninterrupted run gives, bit for bit.
//! 2. Load spread over three replicas (measurement batches with idempotency keys, identification
//!    jobs submitted to each): nothing lost or duplicated, every job ends once, each succeeded
//!    identification stored exactly one parameter set.
//! 3. A replica SIGKILLed while it receives a 10,000-measurement batch: the batch is all or
//!    nothing, and the client's retry with the same key on another replica stores it once.
//! 4. Caches: an activation made on one replica is served by another within
//!    `robocal::http::cache::RECHECK` (measured, printed); a token revoked on one replica is
//!    refused by another within that bound, and from then on.
//! 5. A replica whose database is gone answers `/readyz` with 503 within 3 s, and 200 once it
//!    is back.
//!
//! Part of the `service` test binary (`tests/service/main.rs`); skipped on SQLite, where one server
//! holds the database.

use crate::common;

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use axum::http::Method;
use robocal::domain::cell::CellFile;
use robocal::http::client::Client;
use robocal::sim::simulate::{SimulateOptions, simulate};
use serde_json::{Value, json};

use common::{PgDb, TestBackend, base_guess, test_backend, test_server};

const LEASE_S: u64 = 3;

struct Replica {
    child: Child,
    client: Client,
}

impl Replica {
    async fn start(url: &str, token: &str) -> Replica {
        let port = common::free_port();
        let child = Command::new(env!("CARGO_BIN_EXE_robocal"))
            .args(["serve", "--db", url, "--bind", &format!("127.0.0.1:{port}"), "--require-auth"])
            .args(["--job-lease-s", &LEASE_S.to_string(), "--grace-s", "1"])
            .env("RUST_LOG", "warn")
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("robocal serve starts");
        let client = Client::new(&format!("http://127.0.0.1:{port}"), Some(token.to_string())).unwrap();
        common::wait_ready(&client).await;
        Replica { child, client }
    }

    fn kill(&mut self) {
        self.child.kill().unwrap(); // SIGKILL: no cleanup of any kind
        let _ = self.child.wait();
    }

    async fn get(&self, path: &str) -> Value {
        self.client.get(path).await.unwrap_or_else(|e| panic!("GET {path}: {e}"))
    }

    async fn post(&self, path: &str, body: &Value) -> Value {
        self.client.post(path, body).await.unwrap_or_else(|e| panic!("POST {path}: {e}"))
    }

    async fn wait(&self, job: &str, within: Duration) -> Value {
        let t = Instant::now();
        loop {
            let j = self.get(&format!("/v1/jobs/{job}")).await;
            if matches!(j["state"].as_str(), Some("succeeded" | "failed" | "cancelled")) {
                return j;
            }
            assert!(t.elapsed() < within, "job {job} did not end within {within:?}: {j}");
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }
}

impl Drop for Replica {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn admin_token(url: &str) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["token", "create", "--db", url, "--name", "admin", "--scopes", "admin"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    v["token"].as_str().unwrap().to_string()
}

/// A pose plan big enough to be caught running (as `tests/suite/server_process.rs`), deterministic
/// from its seed.
fn plan_request(artefact: &str) -> Value {
    json!({"artefact_id": artefact, "tool": {"tcp_mm": [40, 0, 130], "mass_kg": 1.7, "com_mm": [30, 0, 64]},
           "per_ball": 1500, "validation": 3000, "select": {"n": 75}, "seed": 3})
}

#[tokio::test]
async fn replicas_share_one_database() {
    if test_backend() != TestBackend::Postgres {
        eprintln!("replicas: skipped (ROBOCAL_TEST_BACKEND is not postgres)");
        return;
    }
    let db = PgDb::create(&test_server(), "robocal_replicas").await;
    // Migrated by the first replica; the token written before it by the CLI (which migrates too).
    let token = admin_token(&db.url);

    // 1. A replica killed mid-job.
    let mut c = Replica::start(&db.url, &token).await;
    let robot = c
        .post("/v1/robots", &json!({"name": "r", "robot": {"preset": "irb120"}, "base_guess": base_guess()}))
        .await["id"]
        .as_str()
        .unwrap()
        .to_string();
    let artefact = c
        .post(
            "/v1/artefacts",
            &json!({"name": "a", "distances_mm": {"d12": 300, "d13": 300, "d23": 300}, "ball_diameter_mm": 12.7}),
        )
        .await["id"]
        .as_str()
        .unwrap()
        .to_string();
    let job = c.post(&format!("/v1/robots/{robot}/pose-plans"), &plan_request(&artefact)).await;
    let killed_job = job["id"].as_str().unwrap().to_string();
    let t = Instant::now();
    loop {
        let j = c.get(&format!("/v1/jobs/{killed_job}")).await;
        match j["state"].as_str().unwrap() {
            "running" => break,
            "queued" => {}
            other => panic!("the job ended ({other}) before it could be killed: make it bigger"),
        }
        assert!(t.elapsed() < Duration::from_secs(30), "the job never started");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    c.kill();
    let killed_at = Instant::now();
    let a = Replica::start(&db.url, &token).await;
    let b = Replica::start(&db.url, &token).await;
    let done = a.wait(&killed_job, Duration::from_secs(600)).await;
    eprintln!(
        "replicas: the killed replica's job ended {:.1} s after the kill (lease {LEASE_S} s)",
        killed_at.elapsed().as_secs_f64()
    );
    assert_eq!(done["state"], "succeeded", "{done}");
    assert_eq!(done["attempts"], 2, "claimed once before the kill and once after: {done}");
    // The same request, uninterrupted: the same plan, bit for bit.
    let again = b.post(&format!("/v1/robots/{robot}/pose-plans"), &plan_request(&artefact)).await;
    let again = b.wait(again["id"].as_str().unwrap(), Duration::from_secs(600)).await;
    assert_eq!(again["attempts"], 1, "{again}");
    let plan = |j: &Value| format!("/v1/pose-plans/{}", j["result"]["pose_plan_id"].as_str().unwrap());
    let (p1, p2) = (b.get(&plan(&done)).await, a.get(&plan(&again)).await);
    assert_ne!(p1["id"], p2["id"]);
    assert_eq!(p1["plan"], p2["plan"], "the requeued job's plan differs from an uninterrupted run's");

    // 2. Load over three replicas.
    let c = Replica::start(&db.url, &token).await;
    let mut replicas = vec![a, b, c];
    let sim = simulate(&SimulateOptions { seed: 11, id_per_ball: 20, validation: 10, ..Default::default() }).unwrap();
    let cell = CellFile::from_cell(&sim.cell);
    let s0 = &cell.sessions[0];
    let new_session = |name: String| {
        json!({"name": name, "purpose": s0.purpose, "instrument": s0.instrument, "tool": s0.tool,
               "artefact_id": artefact, "identify_tcp": s0.identify_tcp})
    };
    let id_session = replicas[0].post(&format!("/v1/robots/{robot}/sessions"), &new_session("id".into())).await["id"]
        .as_str()
        .unwrap()
        .to_string();
    replicas[1]
        .post(&format!("/v1/sessions/{id_session}/measurements"), &json!({"measurements": s0.measurements}))
        .await;
    let batch =
        serde_json::to_vec(&json!({"measurements": s0.measurements.iter().cycle().take(100).collect::<Vec<_>>()}))
            .unwrap();
    const CLIENTS: usize = 6;
    const BATCHES: usize = 8;
    let mut sessions = Vec::new();
    for i in 0..CLIENTS {
        let s = replicas[i % 3].post(&format!("/v1/robots/{robot}/sessions"), &new_session(format!("c{i}"))).await;
        sessions.push(s["id"].as_str().unwrap().to_string());
    }
    let mut jobs = Vec::new();
    for r in &replicas {
        let j = r.post(&format!("/v1/robots/{robot}/identifications"), &json!({"sessions": [id_session]})).await;
        jobs.push(j["id"].as_str().unwrap().to_string());
    }
    let clients: Vec<Client> = replicas.iter().map(|r| r.client.clone()).collect();
    let mut tasks = Vec::new();
    for (i, session) in sessions.iter().enumerate() {
        let (clients, session, batch) = (clients.clone(), session.clone(), batch.clone());
        tasks.push(tokio::spawn(async move {
            let mut served = [0usize; 3];
            for k in 0..BATCHES {
                // Each batch to the next replica: the load is spread over all three.
                let r = (i + k) % 3;
                let key = format!("{session}-{k}");
                let a = clients[r]
                    .send(
                        Method::POST,
                        &format!("/v1/sessions/{session}/measurements"),
                        Some(("application/json", batch.clone())),
                        &[("Idempotency-Key", &key)],
                    )
                    .await
                    .unwrap();
                assert_eq!(a.status.as_u16(), 201, "{}", String::from_utf8_lossy(&a.body));
                served[r] += 1;
            }
            served
        }));
    }
    let mut served = [0usize; 3];
    for t in tasks {
        for (s, n) in served.iter_mut().zip(t.await.unwrap()) {
            *s += n;
        }
    }
    assert!(served.iter().all(|&n| n > 0), "every replica took batches: {served:?}");
    for s in &sessions {
        let a =
            replicas[2].client.send(Method::GET, &format!("/v1/sessions/{s}/measurements?limit=1"), None, &[]).await;
        let total: usize = a.unwrap().headers["x-total-count"].to_str().unwrap().parse().unwrap();
        assert_eq!(total, BATCHES * 100, "session {s}: nothing lost, nothing duplicated");
    }
    let mut sets = Vec::new();
    for j in &jobs {
        let done = replicas[0].wait(j, Duration::from_secs(600)).await;
        assert_eq!(done["state"], "succeeded", "{done}");
        assert_eq!(done["attempts"], 1, "{done}");
        sets.push(done["result"]["parameter_set_id"].as_str().unwrap().to_string());
    }
    let history = replicas[1].get(&format!("/v1/robots/{robot}/parameter-sets?limit=100")).await;
    let listed: Vec<&str> = history.as_array().unwrap().iter().map(|s| s["id"].as_str().unwrap()).collect();
    assert_eq!(listed.len(), jobs.len(), "one set per succeeded identification: {listed:?}");
    for s in &sets {
        assert!(listed.contains(&s.as_str()), "{s} not in {listed:?}");
    }
    let mut pg = db.connect().await;
    let states: Vec<(String, i64)> =
        sqlx::query_as("SELECT state, COUNT(*) FROM jobs GROUP BY state").fetch_all(&mut pg).await.unwrap();
    assert_eq!(states, vec![("succeeded".to_string(), 2 + jobs.len() as i64)], "every job ended once");

    // 3. A replica killed mid-batch.
    let big =
        serde_json::to_vec(&json!({"measurements": s0.measurements.iter().cycle().take(10_000).collect::<Vec<_>>()}))
            .unwrap();
    let target = replicas[1].post(&format!("/v1/robots/{robot}/sessions"), &new_session("big".into())).await["id"]
        .as_str()
        .unwrap()
        .to_string();
    let path = format!("/v1/sessions/{target}/measurements");
    let sending = {
        let (client, path, big) = (replicas[1].client.clone(), path.clone(), big.clone());
        tokio::spawn(async move {
            client.send(Method::POST, &path, Some(("application/json", big)), &[("Idempotency-Key", "big-1")]).await
        })
    };
    tokio::time::sleep(Duration::from_millis(150)).await;
    replicas[1].kill();
    let answered = sending.await.unwrap();
    let stored: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM measurements WHERE session_id = $1")
        .bind(&target)
        .fetch_one(&mut pg)
        .await
        .unwrap();
    eprintln!(
        "replicas: killed mid-batch; the client saw {:?}, the store holds {stored} of 10000",
        answered.as_ref().map(|a| a.status)
    );
    assert!(stored == 0 || stored == 10_000, "a batch is all or nothing: {stored} stored");
    let retry = replicas[0]
        .client
        .send(Method::POST, &path, Some(("application/json", big)), &[("Idempotency-Key", "big-1")])
        .await
        .unwrap();
    assert!(retry.status.is_success(), "{}", String::from_utf8_lossy(&retry.body));
    let stored: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM measurements WHERE session_id = $1")
        .bind(&target)
        .fetch_one(&mut pg)
        .await
        .unwrap();
    assert_eq!(stored, 10_000, "the retry with the same key stores the batch once");
    replicas.remove(1);
    let (a, c) = (&replicas[0], &replicas[1]);

    // 4. Caches: an activation on one replica, seen by another.
    let robot_path = format!("/v1/robots/{robot}");
    for set in [&sets[0], &sets[1]] {
        // The other replica has the robot cached (read just now) when the activation is made.
        let _ = c.get(&robot_path).await;
        a.client
            .call::<Value>(
                Method::PUT,
                &format!("{robot_path}/active-parameter-set"),
                Some(&json!({"parameter_set_id": set})),
            )
            .await
            .unwrap();
        let t = Instant::now();
        loop {
            if c.get(&robot_path).await["active_parameter_set_id"] == json!(set) {
                break;
            }
            assert!(
                t.elapsed() < robocal::http::cache::RECHECK,
                "an activation on one replica was not served by another within {:?}",
                robocal::http::cache::RECHECK
            );
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        eprintln!("replicas: activation seen by another replica after {:.0} ms", t.elapsed().as_secs_f64() * 1e3);
    }

    // A token revoked on one replica is refused by another within the bound, and from then on.
    let created = a.post("/v1/tokens", &json!({"name": "cell-3", "scopes": ["read"]})).await;
    let (id, secret) = (created["id"].as_str().unwrap(), created["token"].as_str().unwrap());
    let cell_client = Client::new(&c.client.base_url(), Some(secret.to_string())).unwrap();
    let status = |client: Client, path: String| async move {
        client.send(Method::GET, &path, None, &[]).await.unwrap().status.as_u16()
    };
    assert_eq!(status(cell_client.clone(), robot_path.clone()).await, 200, "the new token works (and is cached)");
    let r = a.client.send(Method::DELETE, &format!("/v1/tokens/{id}"), None, &[]).await.unwrap();
    assert_eq!(r.status.as_u16(), 204);
    let t = Instant::now();
    while status(cell_client.clone(), robot_path.clone()).await != 401 {
        assert!(t.elapsed() < robocal::http::cache::RECHECK, "a revoked token still worked on another replica");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    eprintln!("replicas: revocation honoured by another replica after {:.0} ms", t.elapsed().as_secs_f64() * 1e3);
    let until = Instant::now() + 2 * robocal::http::cache::RECHECK;
    while Instant::now() < until {
        assert_eq!(status(cell_client.clone(), robot_path.clone()).await, 401, "a revoked token worked again");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }

    // 5. A replica that lost its database answers /readyz with 503 (a load balancer drains it),
    // at once, and is ready again once the database is back.
    {
        use sqlx::Connection;
        let mut admin = sqlx::PgConnection::connect_with(&db.admin).await.unwrap();
        let allow = |on: bool| sqlx::AssertSqlSafe(format!("ALTER DATABASE {} ALLOW_CONNECTIONS {on}", db.name));
        sqlx::query(allow(false)).execute(&mut admin).await.unwrap();
        sqlx::query("SELECT pg_terminate_backend(pid) FROM pg_stat_activity WHERE datname = $1")
            .bind(&db.name)
            .execute(&mut admin)
            .await
            .unwrap();
        let t = Instant::now();
        let r = c.client.send(Method::GET, "/readyz", None, &[]).await.unwrap();
        assert_eq!(r.status.as_u16(), 503, "{}", String::from_utf8_lossy(&r.body));
        assert!(t.elapsed() < Duration::from_secs(3), "/readyz took {:?}", t.elapsed());
        eprintln!("replicas: database gone, /readyz 503 in {:.2} s", t.elapsed().as_secs_f64());
        sqlx::query(allow(true)).execute(&mut admin).await.unwrap();
        let t = Instant::now();
        while !c.client.send(Method::GET, "/readyz", None, &[]).await.unwrap().status.is_success() {
            assert!(t.elapsed() < Duration::from_secs(30), "the replica did not become ready again");
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        eprintln!("replicas: database back, ready again after {:.2} s", t.elapsed().as_secs_f64());
        admin.close().await.unwrap();
    }
    drop(replicas);
    drop(pg);
}
