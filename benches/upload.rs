//! What durability costs (issue 25, item 6): the 10,000-measurement upload through the real
//! router (JSON parsing, the plausibility checks, the duplicate check, one `BEGIN IMMEDIATE`
//! transaction) on a database opened with `synchronous = FULL` — the service's setting, the WAL
//! fsynced at every COMMIT so an answered 201 survives a power cut — against the same build with
//! `synchronous = NORMAL` (fsync only at checkpoints). Also a 100-measurement batch, where the one
//! fsync per commit weighs more.
//!
//! Run: `cargo bench --bench upload`. The databases are in `target/` (on the disk the build is on:
//! a tmpfs would make fsync free and the comparison empty). Each batch goes into a new session.

use std::hint::black_box;
use std::path::PathBuf;

use axum::body::Body;
use axum::http::{Request, StatusCode, header};
use criterion::{BatchSize, BenchmarkId, Criterion, criterion_group, criterion_main};
use http_body_util::BodyExt;
use robocal::db::SqliteSynchronous;
use robocal::domain::cell::CellFile;
use robocal::http::{AppState, ServiceConfig, app};
use robocal::sim::simulate::{SimulateOptions, simulate};
use serde_json::{Value, json};
use tower::ServiceExt;

/// POST `body` to `path`; the answer's status and JSON.
async fn post(router: &axum::Router, path: &str, body: Vec<u8>) -> (StatusCode, Value) {
    let req = Request::builder()
        .method("POST")
        .uri(path)
        .header(header::CONTENT_TYPE, "application/json")
        .body(Body::from(body))
        .unwrap();
    let res = router.clone().oneshot(req).await.unwrap();
    let status = res.status();
    let bytes = res.into_body().collect().await.unwrap().to_bytes();
    (status, serde_json::from_slice(&bytes).unwrap_or(Value::Null))
}

/// A router on a fresh database with one robot and a TriCal plate; the robot's id and the
/// plate's.
async fn service(dir: &PathBuf, sync: SqliteSynchronous) -> (axum::Router, String, String) {
    std::fs::create_dir_all(dir).unwrap();
    let pool = robocal::db::connect_with(&dir.join("robocal.db"), sync).await.unwrap();
    let router = app(AppState::new(pool, ServiceConfig::default()));
    let robot = json!({"name": "bench", "robot": {"preset": "irb120"},
        "base_guess": {"x_mm": 160.211, "y_mm": -255.727, "z_mm": -220.548, "a_deg": 91.603, "b_deg": 0.496, "c_deg": -1.384}});
    let (s, r) = post(&router, "/v1/robots", serde_json::to_vec(&robot).unwrap()).await;
    assert_eq!(s, StatusCode::CREATED, "{r}");
    let plate =
        json!({"name": "plate", "distances_mm": {"d12": 300, "d13": 300, "d23": 300}, "ball_diameter_mm": 12.7});
    let (s, a) = post(&router, "/v1/artefacts", serde_json::to_vec(&plate).unwrap()).await;
    assert_eq!(s, StatusCode::CREATED, "{a}");
    (router, r["id"].as_str().unwrap().to_string(), a["id"].as_str().unwrap().to_string())
}

/// A new TriCal session of the robot; its upload path.
async fn session(router: &axum::Router, robot: &str, plate: &str, n: usize) -> String {
    let session = json!({"name": format!("trical-{n}"), "purpose": "identification", "instrument": "trical",
        "tool": {"tcp_mm": [40, 0, 130], "mass_kg": 1.7, "com_mm": [30, 0, 64]}, "artefact_id": plate});
    let (s, sn) = post(router, &format!("/v1/robots/{robot}/sessions"), serde_json::to_vec(&session).unwrap()).await;
    assert_eq!(s, StatusCode::CREATED, "{sn}");
    format!("/v1/sessions/{}/measurements", sn["id"].as_str().unwrap())
}

fn bench(c: &mut Criterion) {
    // The simulated TriCal poses (360), repeated to 10,000 as scripts/bench_service.sh does.
    let sim = simulate(&SimulateOptions { seed: 1, ..Default::default() }).unwrap();
    let cell = serde_json::to_value(CellFile::from_cell(&sim.cell)).unwrap();
    let m = cell["sessions"][0]["measurements"].as_array().unwrap().clone();
    let big: Vec<Value> = m.iter().cycle().take(10_000).cloned().collect();
    let small: Vec<Value> = m.iter().take(100).cloned().collect();
    let bodies = [
        (10_000, serde_json::to_vec(&json!({ "measurements": big })).unwrap()),
        (100, serde_json::to_vec(&json!({ "measurements": small })).unwrap()),
    ];
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target").join("bench-upload");
    let _ = std::fs::remove_dir_all(&root);
    let mut g = c.benchmark_group("upload");
    g.sample_size(20);
    for (name, sync) in [("full", SqliteSynchronous::Full), ("normal", SqliteSynchronous::Normal)] {
        let (router, robot, plate) = rt.block_on(service(&root.join(name), sync));
        let mut n = 0;
        for (size, body) in &bodies {
            g.bench_with_input(BenchmarkId::new(name, size), body, |b, body| {
                // Each batch into a session of its own (created outside the timing), as the first
                // upload of a measuring run is.
                b.iter_batched(
                    || {
                        n += 1;
                        (rt.block_on(session(&router, &robot, &plate, n)), body.clone())
                    },
                    |(path, body)| {
                        let (s, out) = rt.block_on(post(&router, &path, body));
                        assert_eq!(s, StatusCode::CREATED, "{out}");
                        black_box(out)
                    },
                    BatchSize::PerIteration,
                )
            });
        }
    }
    g.finish();
    let _ = std::fs::remove_dir_all(&root);
}

criterion_group!(benches, bench);
criterion_main!(benches);
