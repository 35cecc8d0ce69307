//! Cancelling a job at every point of its life (issue 16, item 3): queued, just claimed, while
//! its solver runs, between the solver's return and the store, at the same instant as the store,
//! and after it ended. Whatever the moment, the job ends either `cancelled` with no parameter set
//! stored, or `succeeded` with exactly one — never both, never a cancel answered 200 and then
//! lost. The phases are driven one at a time through `robocal::jobs::phases` (the functions the
//! workers run back to back), and then with real workers and randomized cancel times.

use crate::common;

use std::time::Duration;

use axum::http::StatusCode;
use common::{TestApp, artefact, robot, upload};
use rand::{Rng, SeedableRng};
use robocal::domain::cell::CellFile;
use robocal::http::ServiceConfig;
use robocal::jobs::{JobContext, phases};
use robocal::sim::simulate::{SimulateOptions, simulate};
use serde_json::{Value, json};

/// A small simulated cell (thesis truth, default noise): 90 TriCal poses, 30 tracker poses.
fn small_cell() -> CellFile {
    let s = simulate(&SimulateOptions { seed: 5, id_per_ball: 30, validation: 30, ..Default::default() }).unwrap();
    CellFile::from_cell(&s.cell)
}

/// A robot with the cell uploaded; the identification route.
async fn setup(app: &TestApp) -> String {
    let rid = robot(app, "r").await;
    let aid = artefact(app, "a").await;
    upload(app, &rid, &aid, &small_cell()).await;
    format!("/v1/robots/{rid}/identifications")
}

async fn submit(app: &TestApp, path: &str) -> String {
    let r = app.post(path, &json!({"sessions": ["trical-1"]})).await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", r.text);
    r.body["id"].as_str().unwrap().to_string()
}

/// Parameter sets stored by job `id` (read from the table, not the API).
async fn sets_of(app: &TestApp, id: &str) -> i64 {
    sqlx::query_scalar("SELECT COUNT(*) FROM parameter_sets WHERE job_id = $1")
        .bind(id)
        .fetch_one(&app.state.pool)
        .await
        .unwrap()
}

async fn job(app: &TestApp, id: &str) -> Value {
    app.get(&format!("/v1/jobs/{id}")).await.body
}

async fn cancel(app: &TestApp, id: &str) -> u16 {
    let r = app.post(&format!("/v1/jobs/{id}/cancel"), &json!({})).await;
    assert!(matches!(r.status.as_u16(), 200 | 409), "{}", r.text);
    r.status.as_u16()
}

/// The invariant: ended; cancelled ⇔ no set; succeeded ⇔ exactly one set and a result; a cancel
/// answered 200 ⇒ cancelled; answered 409 ⇒ it had ended otherwise.
async fn check(app: &TestApp, id: &str, cancel_status: u16, at: &str) -> &'static str {
    let j = job(app, id).await;
    let sets = sets_of(app, id).await;
    match j["state"].as_str().unwrap() {
        "cancelled" => {
            assert_eq!(sets, 0, "{at}: a cancelled job stored a parameter set: {j}");
            assert!(j["result"].is_null(), "{at}: {j}");
            assert_eq!(cancel_status, 200, "{at}: cancelled, yet the cancel was refused: {j}");
            "cancelled"
        }
        "succeeded" => {
            assert_eq!(sets, 1, "{at}: {j}");
            assert!(j["result"]["parameter_set_id"].is_string(), "{at}: {j}");
            assert_eq!(cancel_status, 409, "{at}: the cancel was accepted (200) and then lost: {j}");
            "succeeded"
        }
        other => panic!("{at}: the job is {other}: {j}"),
    }
}

#[tokio::test]
async fn a_cancel_at_each_phase_ends_the_job_one_way() {
    let app = TestApp::new(ServiceConfig::default(), false).await;
    let path = setup(&app).await;
    let ctx = JobContext::from(app.state.clone());

    // Queued: ends at once; no worker ever claims it.
    let id = submit(&app, &path).await;
    assert_eq!(cancel(&app, &id).await, 200);
    assert!(phases::claim(&ctx, "w").await.unwrap().is_none(), "a cancelled job was claimed");
    assert_eq!(check(&app, &id, 200, "queued").await, "cancelled");
    assert_eq!(cancel(&app, &id).await, 409, "cancelling a cancelled job again is refused");

    // Just claimed, before the solver: flagged, then discarded at the end.
    let id = submit(&app, &path).await;
    let row = phases::claim(&ctx, "w").await.unwrap().unwrap();
    assert_eq!(cancel(&app, &id).await, 200);
    assert_eq!(job(&app, &id).await["cancel_requested"], true);
    let solved = phases::solve(&ctx, &row).await;
    assert_eq!(solved.outcome(), "succeeded");
    phases::end(&ctx, "w", &row, solved).await.unwrap();
    assert_eq!(check(&app, &id, 200, "just claimed").await, "cancelled");

    // While the solver runs.
    let id = submit(&app, &path).await;
    let row = phases::claim(&ctx, "w").await.unwrap().unwrap();
    let solving = {
        let (ctx, row) = (ctx.clone(), row.clone());
        tokio::spawn(async move { phases::solve(&ctx, &row).await })
    };
    tokio::time::sleep(Duration::from_millis(5)).await;
    let status = cancel(&app, &id).await;
    assert_eq!(status, 200);
    phases::end(&ctx, "w", &row, solving.await.unwrap()).await.unwrap();
    assert_eq!(check(&app, &id, status, "mid-solve").await, "cancelled");

    // Between the solver's return and the store (the window the old code lost a cancel in).
    let id = submit(&app, &path).await;
    let row = phases::claim(&ctx, "w").await.unwrap().unwrap();
    let solved = phases::solve(&ctx, &row).await;
    assert_eq!(cancel(&app, &id).await, 200);
    phases::end(&ctx, "w", &row, solved).await.unwrap();
    assert_eq!(check(&app, &id, 200, "between solve and store").await, "cancelled");

    // After it ended: refused, and the result stands.
    let id = submit(&app, &path).await;
    let row = phases::claim(&ctx, "w").await.unwrap().unwrap();
    let solved = phases::solve(&ctx, &row).await;
    phases::end(&ctx, "w", &row, solved).await.unwrap();
    assert_eq!(cancel(&app, &id).await, 409);
    assert_eq!(check(&app, &id, 409, "after done").await, "succeeded");

    // At the same instant as the store, many times: the store and the cancel race for the write
    // lock; whichever wins, the two agree.
    let mut seen = std::collections::BTreeMap::<&str, usize>::new();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(16);
    for round in 0..24 {
        let id = submit(&app, &path).await;
        let row = phases::claim(&ctx, "w").await.unwrap().unwrap();
        let solved = phases::solve(&ctx, &row).await;
        let lead = Duration::from_micros(rng.random_range(0..3000));
        let store = {
            let (ctx, row) = (ctx.clone(), row.clone());
            tokio::spawn(async move {
                tokio::time::sleep(lead).await;
                phases::end(&ctx, "w", &row, solved).await.unwrap()
            })
        };
        let status = cancel(&app, &id).await;
        store.await.unwrap();
        *seen.entry(check(&app, &id, status, &format!("concurrent, round {round}")).await).or_default() += 1;
    }
    eprintln!("cancel concurrent with the store, 24 rounds: {seen:?}");
    app.stop().await;
}

/// Real workers, cancels at randomized times over the jobs' lives (seeded): every job ends one
/// way, in agreement with the answer its cancel got.
#[tokio::test]
async fn cancels_at_random_times_with_real_workers() {
    let app = TestApp::default().await;
    let path = setup(&app).await;
    // How long one identification takes here, to spread the cancels over it.
    let t = std::time::Instant::now();
    let first = submit(&app, &path).await;
    app.wait(&json!({"id": first})).await;
    let span = t.elapsed().as_micros() as u64;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let mut seen = std::collections::BTreeMap::<&str, usize>::new();
    for round in 0..16 {
        let id = submit(&app, &path).await;
        tokio::time::sleep(Duration::from_micros(rng.random_range(0..span * 5 / 4))).await;
        let status = cancel(&app, &id).await;
        app.wait(&json!({"id": id})).await;
        *seen.entry(check(&app, &id, status, &format!("random, round {round}")).await).or_default() += 1;
    }
    eprintln!("random cancels (one identification ≈ {} ms): {seen:?}", span / 1000);
    assert!(seen.get("cancelled").is_some_and(|&n| n > 0), "no cancel landed: {seen:?}");
    app.stop().await;
}
