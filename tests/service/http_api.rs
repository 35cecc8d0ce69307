//! Every endpoint on the real router (`oneshot`) with a fresh SQLite database, error cases
//! included: 400 malformed, 404 unknown id, 409 conflict, 413 too large, 415 media type, 422
//! invalid values — never a 500, never a partial write.

use crate::common;

use axum::http::{Method, StatusCode};
use common::{TestApp, artefact, assert_problem, base_guess, robot, upload};
use robocal::domain::cell::CellFile;
use robocal::http::ServiceConfig;
use robocal::sim::simulate::{SimulateOptions, simulate};
use serde_json::{Value, json};

/// A small simulated cell (thesis truth, default noise): 90 TriCal poses, 60 tracker poses.
fn small_cell(seed: u64) -> CellFile {
    let s = simulate(&SimulateOptions { seed, id_per_ball: 30, validation: 60, ..Default::default() }).unwrap();
    CellFile::from_cell(&s.cell)
}

#[tokio::test]
async fn operations_endpoints() {
    let app = TestApp::default().await;
    let r = app.get("/healthz").await;
    assert_eq!(r.status, StatusCode::OK);
    assert_eq!(r.body["status"], "ok");
    let r = app.get("/readyz").await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert_eq!(r.body["migrations"], robocal::db::MIGRATOR.iter().count());
    // The served OpenAPI document is this (loopback, no-auth) mode's; the committed one is the
    // `--require-auth` form (tests/service/security.rs checks that a server in that mode serves it).
    let r = app.get("/openapi.json").await;
    assert_eq!(r.status, StatusCode::OK);
    assert_eq!(r.body["openapi"], "3.1.0");
    assert_eq!(r.text, robocal::http::openapi_json_for(false));
    // Unknown routes are problems too; metrics count requests by route template and status.
    assert_problem(&app.get("/v1/nope").await, 404, None);
    robot(&app, "m").await;
    assert_problem(&app.get("/v1/robots/00000000-0000-0000-0000-000000000000").await, 404, None);
    let r = app.get("/metrics").await;
    assert_eq!(r.status, StatusCode::OK);
    assert!(r.headers["content-type"].to_str().unwrap().starts_with("text/plain"));
    for needle in [
        r#"robocal_http_requests_total{method="POST",route="/v1/robots",status="201"} 1"#,
        r#"robocal_http_requests_total{method="GET",route="/v1/robots/{robot_id}",status="404"} 1"#,
        "robocal_http_request_duration_seconds_bucket",
        r#"robocal_jobs{state="queued"} 0"#,
    ] {
        assert!(r.text.contains(needle), "missing {needle} in\n{}", r.text);
    }
    app.stop().await;
}

#[tokio::test]
async fn the_openapi_document_matches_the_committed_file() {
    let committed = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/openapi/openapi.json")).unwrap();
    assert_eq!(
        robocal::http::openapi_json(),
        committed,
        "openapi/openapi.json is stale: regenerate with `cargo run -- openapi --out openapi/openapi.json`"
    );
}

#[tokio::test]
async fn robots_and_artefacts() {
    let app = TestApp::default().await;
    let id = robot(&app, "cell-1").await;
    let r = app.get(&format!("/v1/robots/{id}")).await;
    assert_eq!(r.status, StatusCode::OK);
    assert_eq!(r.body["dof"], 6);
    assert_eq!(r.body["parameters"], 43);
    assert_eq!(r.body["robot"], json!({"preset": "irb120"}));
    assert!(r.body["active_parameter_set_id"].is_null());
    // A missing or an unknown field is named in the problem document, nested ones by their path.
    assert_problem(&app.post("/v1/robots", &json!({"robot": {"preset": "irb120"}})).await, 422, Some("name"));
    assert_problem(
        &app.post("/v1/artefacts", &json!({"name": "p", "distances_mm": {"d12": 300, "d13": 300}})).await,
        422,
        Some("distances_mm.d23"),
    );
    assert_problem(
        &app.post("/v1/robots", &json!({"name": "cell-1", "robot": {"preset": "irb120"}})).await,
        409,
        Some("name"),
    );
    assert_problem(
        &app.post("/v1/robots", &json!({"name": "x", "robot": {"preset": "irb999"}})).await,
        422,
        Some("robot.preset"),
    );
    assert_problem(&app.post("/v1/robots", &json!({"name": "x"})).await, 422, Some("robot"));
    // Names are bounded as the spec says (maxLength 200, in characters): 200 fit, 201 do not.
    let long = "é".repeat(200);
    assert_problem(
        &app.post("/v1/robots", &json!({"name": format!("{long}x"), "robot": {"preset": "ur10"}})).await,
        422,
        Some("name"),
    );
    assert_problem(
        &app.post(
            "/v1/artefacts",
            &json!({"name": format!("{long}x"), "distances_mm": {"d12": 300, "d13": 300, "d23": 300}, "ball_diameter_mm": 12.7}),
        )
        .await,
        422,
        Some("name"),
    );
    assert_problem(
        &app.post("/v1/robots", &json!({"name": "x", "robot": {"preset": "ur10"}, "colour": 1})).await,
        422,
        Some("colour"),
    );
    assert_problem(
        &app.post("/v1/robots", &json!({"name": "x", "robot": {"preset": "ur10"}, "base_guess": {"x_mm": 1}})).await,
        422,
        Some("base_guess.y_mm"),
    );
    assert_problem(
        &app.raw(Method::POST, "/v1/robots", Some("application/json"), b"{\"name\": ".to_vec(), &[]).await,
        400,
        None,
    );
    assert_problem(&app.raw(Method::POST, "/v1/robots", Some("text/plain"), b"{}".to_vec(), &[]).await, 415, None);
    let custom = json!({"name": "arm", "joints": [
        {"alpha_deg": 0, "a_mm": 0, "d_mm": 290, "limits_deg": [-165, 165]},
        {"alpha_deg": -90, "a_mm": 0, "d_mm": 0, "theta_deg": -90, "limits_deg": [-110, 110]},
        {"alpha_deg": 0, "a_mm": 270, "d_mm": 0, "limits_deg": [120, -110]}]});
    let r = app.post("/v1/robots", &json!({"name": "custom", "robot": custom})).await;
    assert_problem(&r, 422, None);
    assert!(r.body["field"].as_str().unwrap().starts_with("robot.joints[2]"), "{}", r.text);
    let r = app.get("/v1/robots").await;
    assert_eq!(r.body.as_array().unwrap().len(), 1, "refused robots were not stored");
    let r = app.post("/v1/robots", &json!({"name": long, "robot": {"preset": "ur10"}})).await;
    assert_eq!(r.status, StatusCode::CREATED, "{}", r.body);
    assert_eq!(r.body["name"].as_str().map(|n| n.chars().count()), Some(200));

    let a = artefact(&app, "plate").await;
    let r = app.get(&format!("/v1/artefacts/{a}")).await;
    assert_eq!(r.status, StatusCode::OK);
    let c = &r.body["ball_centres_mm"];
    assert_eq!(c[1], json!([300.0, 0.0, 0.0]));
    assert!((c[2][1].as_f64().unwrap() - 300.0 * 3f64.sqrt() / 2.0).abs() < 1e-9);
    let bad = |d: Value| json!({"name": "bad", "distances_mm": d, "ball_diameter_mm": 12.7});
    assert_problem(
        &app.post("/v1/artefacts", &bad(json!({"d12": 300, "d13": 300, "d23": 700}))).await,
        422,
        Some("distances_mm"),
    );
    assert_problem(
        &app.post("/v1/artefacts", &bad(json!({"d12": -1, "d13": 300, "d23": 300}))).await,
        422,
        Some("distances_mm.d12"),
    );
    let r = app.post("/v1/artefacts", &bad(json!({"d12": 300, "d13": 150, "d23": 150.0001}))).await;
    assert_problem(&r, 422, Some("distances_mm"));
    assert!(r.body["detail"].as_str().unwrap().contains("degenerate"), "{}", r.text);
    assert_problem(
        &app.post(
            "/v1/artefacts",
            &json!({"name": "p2", "distances_mm": {"d12": 300, "d13": 300, "d23": 300}, "ball_diameter_mm": 0}),
        )
        .await,
        422,
        Some("ball_diameter_mm"),
    );
    assert_problem(
        &app.post(
            "/v1/artefacts",
            &json!({"name": "plate", "distances_mm": {"d12": 300, "d13": 300, "d23": 300}, "ball_diameter_mm": 12.7}),
        )
        .await,
        409,
        Some("name"),
    );
    assert_problem(&app.get("/v1/artefacts/none").await, 404, None);
    assert_eq!(app.get("/v1/artefacts").await.body.as_array().unwrap().len(), 1);
    app.stop().await;
}

#[tokio::test]
async fn sessions_and_measurement_batches() {
    let app =
        TestApp::new(ServiceConfig { max_batch: 100, max_body_bytes: 200_000, ..Default::default() }, false).await;
    let rid = robot(&app, "r").await;
    let aid = artefact(&app, "a").await;
    let trical = json!({"tcp_mm": [40, 0, 130], "mass_kg": 1.7, "com_mm": [30, 0, 64]});
    let sess = |name: &str, inst: &str, art: Option<&str>| {
        let mut v = json!({"name": name, "purpose": "identification", "instrument": inst, "tool": trical});
        if let Some(a) = art {
            v["artefact_id"] = json!(a);
        }
        v
    };
    let path = format!("/v1/robots/{rid}/sessions");
    assert_problem(&app.post(&path, &sess("t", "trical", None)).await, 422, Some("artefact_id"));
    assert_problem(&app.post(&path, &sess("t", "trical", Some("nope"))).await, 404, Some("artefact_id"));
    let mut bad_tool = sess("t", "trical", Some(&aid));
    bad_tool["tool"]["mass_kg"] = json!(-1);
    assert_problem(&app.post(&path, &bad_tool).await, 422, Some("tool.mass_kg"));
    let r = app.post(&path, &sess("t", "trical", Some(&aid))).await;
    assert_eq!(r.status, StatusCode::CREATED, "{}", r.text);
    let sid = r.body["id"].as_str().unwrap().to_string();
    assert_problem(&app.post(&path, &sess("t", "laser_tracker", None)).await, 409, Some("name"));
    assert_problem(&app.post("/v1/robots/none/sessions", &sess("u", "trical", Some(&aid))).await, 404, None);
    assert_eq!(app.get(&path).await.body.as_array().unwrap().len(), 1);
    assert_eq!(app.get(&format!("/v1/sessions/{sid}")).await.body["measurements"], 0);
    assert_problem(&app.get("/v1/sessions/none").await, 404, None);

    // A batch: all or nothing.
    let mpath = format!("/v1/sessions/{sid}/measurements");
    let m = |q4: f64, ball: u64| json!({"joints_deg": [0, 10, 20, 0, q4, 0], "ball": ball});
    let r = app.post(&mpath, &json!({"measurements": [m(30.0, 1), m(150.0, 2)]})).await;
    assert_problem(&r, 422, Some("measurements[1].joints_deg[4]"));
    assert!(r.body["detail"].as_str().unwrap().contains("outside joint 5's limits"), "{}", r.text);
    assert_problem(
        &app.post(&mpath, &json!({"measurements": [m(30.0, 1), m(30.0, 4)]})).await,
        422,
        Some("measurements[1].ball"),
    );
    assert_problem(
        &app.post(&mpath, &json!({"measurements": [{"joints_deg": [0, 10, 20], "ball": 1}]})).await,
        422,
        Some("measurements[0].joints_deg"),
    );
    assert_problem(
        &app.post(&mpath, &json!({"measurements": [{"joints_deg": [0, 10, 20, 0, 30, 0], "position_mm": [1, 2, 3]}]}))
            .await,
        422,
        Some("measurements[0].position_mm"),
    );
    assert_problem(
        &app.post(&mpath, &json!({"measurements": [{"joints_deg": [0, 10, 20, 0, 30, "x"], "ball": 1}]})).await,
        422,
        Some("measurements[0].joints_deg[5]"),
    );
    let nan = br#"{"measurements": [{"joints_deg": [0, 10, 20, 0, NaN, 0], "ball": 1}]}"#.to_vec();
    assert_problem(&app.raw(Method::POST, &mpath, Some("application/json"), nan, &[]).await, 400, None);
    assert_problem(&app.post(&mpath, &json!({"measurements": []})).await, 422, Some("measurements"));
    assert_eq!(
        app.get(&format!("/v1/sessions/{sid}")).await.body["measurements"],
        0,
        "nothing stored by refused batches"
    );

    let key = [("idempotency-key", "run-7-batch-1")];
    let body = serde_json::to_vec(&json!({"measurements": [m(30.0, 1), m(31.0, 2), m(32.0, 3)]})).unwrap();
    let first = app.raw(Method::POST, &mpath, Some("application/json"), body.clone(), &key).await;
    assert_eq!(first.status, StatusCode::CREATED, "{}", first.text);
    assert_eq!(
        (first.body["first_index"].as_i64(), first.body["count"].as_i64(), first.body["total"].as_i64()),
        (Some(0), Some(3), Some(3))
    );
    let again = app.raw(Method::POST, &mpath, Some("application/json"), body, &key).await;
    assert_eq!(again.status, StatusCode::CREATED);
    assert_eq!(again.headers["idempotency-replayed"], "true");
    assert_eq!(again.body["batch_id"], first.body["batch_id"]);
    let other = serde_json::to_vec(&json!({"measurements": [m(33.0, 1)]})).unwrap();
    assert_problem(
        &app.raw(Method::POST, &mpath, Some("application/json"), other, &key).await,
        409,
        Some("Idempotency-Key"),
    );
    assert_eq!(app.get(&format!("/v1/sessions/{sid}")).await.body["measurements"], 3, "the retry did not append");

    // CSV, with its own errors.
    let csv = "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,ball,temperature_c,approach_1,approach_2,approach_3,approach_4,approach_5,approach_6\n\
               0,10,20,0,40,0,2,21.5,1,-1,1,1,1,-1\n0,10,20,0,41,0,3,,,,,,,\n";
    let r = app.raw(Method::POST, &mpath, Some("text/csv"), csv.as_bytes().to_vec(), &[]).await;
    assert_eq!(r.status, StatusCode::CREATED, "{}", r.text);
    assert_eq!(r.body["first_index"], 3);
    let r = app
        .raw(
            Method::POST,
            &mpath,
            Some("text/csv"),
            b"q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,colour\n0,0,0,0,30,0,red\n".to_vec(),
            &[],
        )
        .await;
    assert_problem(&r, 422, Some("csv column 'colour'"));
    let r = app
        .raw(
            Method::POST,
            &mpath,
            Some("text/csv"),
            b"q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,ball\n0,0,0,0,30,0,1\n0,0,0,0,3x,0,1\n".to_vec(),
            &[],
        )
        .await;
    assert_problem(&r, 422, Some("csv line 3, column q5_deg"));
    let r = app
        .raw(
            Method::POST,
            &mpath,
            Some("text/csv"),
            b"q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,ball\n0,0,0,0,30,0,1\n0,0,0,0,30,0,7\n".to_vec(),
            &[],
        )
        .await;
    assert_problem(&r, 422, Some("csv line 3.ball"));
    assert_problem(&app.raw(Method::POST, &mpath, Some("text/xml"), b"<m/>".to_vec(), &[]).await, 415, None);

    // Limits: more measurements than the batch limit, a body over the size limit.
    let many: Vec<Value> = (0..101).map(|i| m(30.0 + i as f64 * 0.1, 1)).collect();
    assert_problem(&app.post(&mpath, &json!({"measurements": many})).await, 413, Some("measurements"));
    let huge = format!(
        "{{\"measurements\": [{}]}}",
        vec![r#"{"joints_deg": [0, 10, 20, 0, 30, 0], "ball": 1}"#; 5000].join(",")
    );
    assert_problem(&app.raw(Method::POST, &mpath, Some("application/json"), huge.into_bytes(), &[]).await, 413, None);
    assert_eq!(app.get(&format!("/v1/sessions/{sid}")).await.body["measurements"], 5);

    // Paging.
    let r = app.get(&format!("{mpath}?offset=1&limit=2")).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert_eq!(r.body["total"], 5);
    assert_eq!(r.body["items"][0]["index"], 1);
    assert_eq!(r.body["items"][0]["joints_deg"][4], 31.0);
    assert_eq!(r.body["next_offset"], 3);
    let r = app.get(&format!("{mpath}?offset=3&limit=10")).await;
    assert_eq!(r.body["items"].as_array().unwrap().len(), 2);
    assert_eq!(r.body["items"][0]["approach"], json!([1, -1, 1, 1, 1, -1]));
    assert!(r.body["next_offset"].is_null());
    assert_problem(&app.get(&format!("{mpath}?limit=0")).await, 422, Some("limit"));
    assert_problem(&app.get(&format!("{mpath}?offset=-1")).await, 422, Some("offset"));
    assert_problem(&app.get(&format!("{mpath}?offset=abc")).await, 422, Some("offset"));
    assert_problem(&app.get(&format!("{mpath}?limit=10001")).await, 422, Some("limit"));
    assert_eq!(r.headers["x-total-count"], "5");
    // Errors raised before a handler runs (query strings, methods) are problems too.
    assert_problem(&app.get("/v1/jobs?state=failed&state=queued").await, 400, None);
    assert_problem(&app.raw(Method::DELETE, &mpath, None, vec![], &[]).await, 405, None);
    // … also when the client accepts gzip: the problem document is what gets compressed.
    let r =
        app.raw(Method::GET, "/v1/jobs?state=failed&state=queued", None, vec![], &[("accept-encoding", "gzip")]).await;
    assert_eq!(r.status.as_u16(), 400);
    assert_eq!(r.headers["content-type"], "application/problem+json");
    assert_eq!(r.headers["content-encoding"], "gzip");
    // An array of the wrong length is an invalid value (422) at its path, not malformed JSON.
    let r = app
        .post(
            &mpath,
            &json!({"measurements": [{"joints_deg": [0, 10, 20, 0, 30, 0], "ball": 1, "indicators_mm": [0, 0, 0, 0]}]}),
        )
        .await;
    assert_problem(&r, 422, Some("measurements[0].indicators_mm"));
    app.stop().await;
}

/// The measuring order survives the service: the session's marker (stored, listed, exported)
/// and each measurement's sequence number, posted as JSON or CSV, read back in pages and in the
/// exported cell file.
#[tokio::test]
async fn measuring_order_round_trips_through_the_service() {
    let app = TestApp::new(ServiceConfig::default(), false).await;
    let rid = robot(&app, "r").await;
    let path = format!("/v1/robots/{rid}/sessions");
    let tool = json!({"tcp_mm": [0, 60, 80]});
    let sess = |name: &str| json!({"name": name, "purpose": "validation", "instrument": "laser_tracker", "tool": tool});
    let mut measured = sess("n1");
    measured["order"] = json!("measured");
    let r = app.post(&path, &measured).await;
    assert_eq!(r.status, StatusCode::CREATED, "{}", r.text);
    assert_eq!(r.body["order"], "measured");
    let sid = r.body["id"].as_str().unwrap().to_string();
    let r = app.post(&path, &sess("n2")).await;
    assert_eq!(r.body["order"], "unknown", "the default");
    let mut bad = sess("n3");
    bad["order"] = json!("sorted");
    assert_problem(&app.post(&path, &bad).await, 422, Some("order"));
    let mut shuffled = sess("n3");
    shuffled["order"] = json!("shuffled");
    assert_eq!(app.post(&path, &shuffled).await.body["order"], "shuffled");
    assert_eq!(app.get(&format!("/v1/sessions/{sid}")).await.body["order"], "measured");
    let listed: Vec<Value> = app.get(&path).await.body.as_array().unwrap().iter().map(|s| s["order"].clone()).collect();
    assert_eq!(listed, [json!("measured"), json!("unknown"), json!("shuffled")]);

    // Sequence numbers as JSON (one beyond 2^53) and as CSV, a retried batch, a bad number.
    let mpath = format!("/v1/sessions/{sid}/measurements");
    let m = |q: f64, seq: u64| json!({"joints_deg": [q, 10, 20, 0, 30, 0], "position_mm": [1, 2, 3], "sequence": seq});
    let r = app.post(&mpath, &json!({"measurements": [m(0.0, 0), m(1.0, 9_007_199_254_740_993)]})).await;
    assert_eq!(r.status, StatusCode::CREATED, "{}", r.text);
    let csv = "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,x_mm,y_mm,z_mm,time_s,sequence
2,10,20,0,30,0,1,2,3,12.5,2
3,10,20,0,30,0,1,2,3,,
";
    let r = app.raw(Method::POST, &mpath, Some("text/csv"), csv.as_bytes().to_vec(), &[]).await;
    assert_eq!(r.status, StatusCode::CREATED, "{}", r.text);
    let bad_csv = "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,x_mm,y_mm,z_mm,sequence
2,10,20,0,30,0,1,2,3,-4
";
    let r = app.raw(Method::POST, &mpath, Some("text/csv"), bad_csv.as_bytes().to_vec(), &[]).await;
    assert_problem(&r, 422, Some("csv line 2, column sequence"));
    let items = app.get(&format!("{mpath}?offset=0&limit=10")).await.body["items"].clone();
    let seqs: Vec<Value> = items.as_array().unwrap().iter().map(|i| i["sequence"].clone()).collect();
    assert_eq!(seqs, [json!(0), json!(9_007_199_254_740_993_u64), json!(2), Value::Null]);
    assert_eq!(items[2]["time_s"], 12.5);

    // The exported cell carries both, and parses back to the same SI cell.
    let r = app.get(&format!("/v1/robots/{rid}/cell?sessions=n1")).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert_eq!(r.body["sessions"][0]["order"], "measured");
    let cell = robocal::domain::cell::parse_cell(&r.text).unwrap();
    let s = &cell.sessions[0];
    assert_eq!(s.order, robocal::cell::MeasuringOrder::Measured);
    assert_eq!(
        s.measurements.iter().map(|m| m.sequence).collect::<Vec<_>>(),
        [Some(0), Some(9_007_199_254_740_993), Some(2), None]
    );
    app.stop().await;
}

/// A session's physical target: stored, returned, exported; sessions naming one target declare
/// one tool; a blank target is refused. An identification request's exclusions are checked
/// against the sessions and applied: the excluded reading is not in the fit.
#[tokio::test]
async fn targets_and_exclusions_through_the_service() {
    let app = TestApp::default().await;
    let rid = robot(&app, "r").await;
    let aid = artefact(&app, "plate").await;
    let path = format!("/v1/robots/{rid}/sessions");
    let sess = |name: &str, tcp: [f64; 3], target: &str| {
        json!({"name": name, "purpose": "validation", "instrument": "laser_tracker", "tool": {"tcp_mm": tcp},
               "identify_tcp": true, "target": target})
    };
    let r = app.post(&path, &sess("day-1", [0.0, 0.0, 0.0], " nest-1 ")).await;
    assert_eq!(r.status, StatusCode::CREATED, "{}", r.text);
    assert_eq!(r.body["target"], "nest-1", "trimmed");
    let sid = r.body["id"].as_str().unwrap().to_string();
    assert_eq!(app.post(&path, &sess("day-2", [0.0, 0.0, 0.0], "nest-1")).await.status, StatusCode::CREATED);
    let r = app.post(&path, &sess("day-3", [0.0, 60.0, 80.0], "nest-1")).await;
    assert_problem(&r, 422, Some("target"));
    assert!(r.body["detail"].as_str().unwrap().contains("same tool"), "{}", r.text);
    assert_problem(&app.post(&path, &sess("day-4", [0.0, 0.0, 0.0], "  ")).await, 422, Some("target"));
    let mut plain = sess("other", [0.0, 0.0, 0.0], "x");
    plain.as_object_mut().unwrap().remove("target");
    let r = app.post(&path, &plain).await;
    assert!(r.body.get("target").is_none(), "no target, none written: {}", r.text);
    assert_eq!(app.get(&format!("/v1/sessions/{sid}")).await.body["target"], "nest-1");
    let m = json!({"joints_deg": [0, 10, 20, 0, 30, 0], "position_mm": [400, 0, 500]});
    assert_eq!(
        app.post(&format!("/v1/sessions/{sid}/measurements"), &json!({"measurements": [m]})).await.status,
        StatusCode::CREATED
    );
    let r = app.get(&format!("/v1/robots/{rid}/cell?sessions=day-1")).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    let cell = robocal::domain::cell::parse_cell(&r.text).unwrap();
    assert_eq!(cell.sessions[0].target.as_deref(), Some("nest-1"));

    // Exclusions: checked at submission, applied in the fit.
    let cell = small_cell(3);
    let ids = upload(&app, &rid, &aid, &cell).await;
    let trical = ids.iter().find(|(n, _)| n == "trical-1").unwrap().1.clone();
    let n = cell.sessions.iter().find(|s| s.name == "trical-1").unwrap().measurements.len();
    let path = format!("/v1/robots/{rid}/identifications");
    let req = |exclude: Value| json!({"sessions": ["trical-1"], "exclude": exclude, "weighted": true});
    assert_problem(
        &app.post(&path, &req(json!([{"session": "nope", "index": 0}]))).await,
        422,
        Some("exclude[0].session"),
    );
    assert_problem(
        &app.post(&path, &req(json!([{"session": "trical-1", "index": n}]))).await,
        422,
        Some("exclude[0].index"),
    );
    let all = app.wait(&app.post(&path, &req(json!([]))).await.body).await;
    let one_out = app.wait(&app.post(&path, &req(json!([{"session": trical, "index": 7}]))).await.body).await;
    assert_eq!(
        (all["state"].as_str(), one_out["state"].as_str()),
        (Some("succeeded"), Some("succeeded")),
        "{all} {one_out}"
    );
    let measurements = async |j: &Value| {
        let set = j["result"]["parameter_set_id"].as_str().unwrap();
        app.get(&format!("/v1/parameter-sets/{set}")).await.body["quality"]["measurements"].as_u64()
    };
    assert_eq!(measurements(&all).await, Some(n as u64));
    assert_eq!(measurements(&one_out).await, Some(n as u64 - 1), "the excluded reading is not in the fit");
    // An option the fit refuses is named as the request writes it, with no command-line flag.
    let r = app.post(&path, &json!({"sessions": ["trical-1"], "fix": ["a2", "nonsense"]})).await;
    let j = app.wait(&r.body).await;
    assert_eq!((j["state"].as_str(), j["error"]["field"].as_str()), (Some("failed"), Some("fix[1]")), "{j}");
    let detail = j["error"]["detail"].as_str().unwrap();
    assert!(detail.contains("'nonsense' is not a parameter") && !detail.contains("--"), "{j}");
    app.stop().await;
}

/// A cell PC posts a run whose joint 5 was read with the other sign. The robot has a base guess
/// and the session its declared tool, so nothing was registered and the starting checks were
/// skipped: the fit took the sign into the model. Now the job fails as a joint convention, the
/// change named, and no parameter set is stored.
#[tokio::test]
async fn readings_in_another_convention_fail_the_job_with_the_change_named() {
    let app = TestApp::default().await;
    let rid = robot(&app, "cell").await;
    let aid = artefact(&app, "plate").await;
    let mut cell = small_cell(3);
    let t = cell.sessions.iter().position(|s| s.name == "trical-1").unwrap();
    cell.sessions[t].measurements.iter_mut().for_each(|m| m.joints_deg[4] = -m.joints_deg[4]);
    upload(&app, &rid, &aid, &cell).await;
    let path = format!("/v1/robots/{rid}/identifications");
    let j = app.wait(&app.post(&path, &json!({"sessions": ["trical-1"]})).await.body).await;
    assert_eq!(j["state"], "failed", "{j}");
    assert_eq!(j["error"]["type"], "urn:robocal:problem:joint-convention", "{j}");
    let detail = j["error"]["detail"].as_str().unwrap();
    assert!(
        detail.contains("do not follow the robot model's conventions") && detail.contains("joint 5 as −q5"),
        "{detail}"
    );
    assert!(app.get(&format!("/v1/robots/{rid}/parameter-sets")).await.body.as_array().unwrap().is_empty());
}

/// The loop: identification, its refusal with the reason, validation, history, activation,
/// export, import, compensation — and the server's parameter set is the CLI's, bit for bit.
#[tokio::test]
async fn identification_validation_and_compensation() {
    let app = TestApp::default().await;
    let rid = robot(&app, "cell").await;
    let aid = artefact(&app, "plate").await;
    let cell = small_cell(3);
    let ids = upload(&app, &rid, &aid, &cell).await;
    let id_of = |n: &str| ids.iter().find(|(k, _)| k == n).unwrap().1.clone();

    // Submission-time checks.
    let path = format!("/v1/robots/{rid}/identifications");
    assert_problem(&app.post(&path, &json!({"sessions": ["tracker-n1"]})).await, 422, Some("sessions[0]"));
    assert_problem(&app.post(&path, &json!({"sessions": ["nope"]})).await, 404, Some("sessions[0]"));
    assert_problem(&app.post(&path, &json!({"sessions": ["trical-1"], "model": "+warp"})).await, 422, Some("model"));
    assert_problem(
        &app.post(&path, &json!({"sessions": ["trical-1"], "kappa_limit": 0.5})).await,
        422,
        Some("kappa_limit"),
    );
    assert_problem(
        &app.post(&path, &json!({"sessions": ["trical-1"], "select": {"n": 10, "index": "O9"}})).await,
        422,
        Some("select.index"),
    );
    assert_problem(&app.post("/v1/robots/none/identifications", &json!({"sessions": ["trical-1"]})).await, 404, None);

    // A refused fit: the job fails with the reason, no parameter set is written.
    let r = app.post(&path, &json!({"sessions": ["trical-1"], "kappa_limit": 2.0})).await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", r.text);
    assert_eq!(r.headers["location"], format!("/v1/jobs/{}", r.body["id"].as_str().unwrap()));
    let j = app.wait(&r.body).await;
    assert_eq!(j["state"], "failed", "{j}");
    assert_eq!(j["error"]["type"], "urn:robocal:problem:ill-conditioned");
    assert!(j["error"]["detail"].as_str().unwrap().contains("weakest combination"), "{j}");
    assert!(app.get(&format!("/v1/robots/{rid}/parameter-sets")).await.body.as_array().unwrap().is_empty());

    // The identification.
    let r = app.post(&path, &json!({"sessions": [id_of("trical-1")]})).await;
    let j = app.wait(&r.body).await;
    assert_eq!(j["state"], "succeeded", "{j}");
    assert_eq!(j["progress"], 1.0);
    assert_eq!(j["attempts"], 1);
    assert_eq!(j["result"]["summary"]["identified"], 31);
    assert_eq!(j["result"]["version"], 1);
    let set_id = j["result"]["parameter_set_id"].as_str().unwrap().to_string();

    // Bit for bit: the real `robocal identify` on the exported cell file writes the server's
    // parameter-set file (plus the newline that ends every file the CLI writes).
    let exported = app.get(&format!("/v1/robots/{rid}/cell?sessions=trical-1")).await;
    assert_eq!(exported.status, StatusCode::OK, "{}", exported.text);
    let (cell_path, cli_path) = (app.dir.join("exported.json"), app.dir.join("cli_params.json"));
    std::fs::write(&cell_path, &exported.text).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_robocal"))
        .arg("identify")
        .arg(&cell_path)
        .args(["--sessions", "trical-1", "--out"])
        .arg(&cli_path)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let cli_file = std::fs::read_to_string(&cli_path).unwrap();
    let server_doc = app.get(&format!("/v1/parameter-sets/{set_id}/export")).await;
    assert_eq!(cli_file, format!("{}\n", server_doc.text), "the server's parameter set is the CLI's");
    // … and the export parses as a parameter-set file.
    robocal::domain::ParameterSetDoc::from_json(&server_doc.text).unwrap();

    // Compensation needs an active set (or a named one).
    let cpath = format!("/v1/robots/{rid}/compensate");
    let targets = json!([
        {"id": "a", "position_mm": [150, 80, 120], "rotation_deg": [0, 180, 0], "cfx": 0},
        {"id": "b", "joints_deg": [10, 20, -10, 0, 45, 0]},
        {"id": "far", "position_mm": [3000, 0, 0], "rotation_deg": [0, 180, 0], "cfx": 0},
        {"id": "bad", "position_mm": [150, 80, 120], "rotation_deg": [0, 180, 0]}]);
    assert_problem(&app.post(&cpath, &json!({"targets": targets})).await, 409, None);
    // A set without a held-out validation is refused unless asked for, saying what to do.
    let r = app.post(&cpath, &json!({"targets": targets, "parameter_set_id": set_id})).await;
    assert_problem(&r, 409, None);
    assert!(r.body["detail"].as_str().unwrap().contains("no held-out validation"), "{}", r.text);
    assert!(r.body["hint"].as_str().unwrap().contains("allow_unvalidated"), "{}", r.text);
    let r = app.post(&cpath, &json!({"targets": targets, "parameter_set_id": set_id, "allow_unvalidated": true})).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert_eq!(r.body["failed"], 2);
    let res = r.body["results"].as_array().unwrap();
    assert!(res[0]["residual_mm"].as_f64().unwrap() < 1e-6 && res[0]["joints_deg"].as_array().unwrap().len() == 6);
    assert!(res[1]["fake_pose"]["position_mm"].is_array());
    assert!(res[2]["error"].as_str().unwrap().contains("reach"), "{}", res[2]);
    assert!(res[3]["error"].as_str().unwrap().starts_with("targets[3].cfx"), "{}", res[3]);
    // The response states its frame; a fake pose comes back in the Euler family the target used.
    assert_eq!(r.body["frame"]["kind"], "world");
    assert!(r.body["frame"]["description"].as_str().unwrap().contains("nominal base"), "{}", r.body["frame"]);
    let rot: Vec<f64> =
        res[0]["fake_pose"]["rotation_deg"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert!((rot[1] - 180.0).abs() < 2.0 && rot[0].abs() < 2.0 && rot[2].abs() < 2.0, "{rot:?}");
    // A quaternion rounded as a program stores it is normalised, and the answer says so; the
    // same target in the base frame and relative to a work object is answered in those frames.
    let q = json!([{"id": "q", "position_mm": [150, 80, 120], "quaternion": [0, 0, 1.0004, 0], "cfx": 0}]);
    let r = app.post(&cpath, &json!({"targets": q, "parameter_set_id": set_id, "allow_unvalidated": true})).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    let notes = r.body["results"][0]["notes"].as_array().unwrap();
    assert!(
        notes.iter().any(|n| n.as_str().unwrap().contains("normalised") && n.as_str().unwrap().contains("1.0004")),
        "{}",
        r.text
    );
    // 120 mm above the plate: noted with its distance to the measured region, not refused.
    assert!(notes.iter().any(|n| n.as_str().unwrap().contains("70.0 mm outside the measured region")), "{}", r.text);
    assert_eq!(r.body["results"][0]["joints_deg"], res[0]["joints_deg"], "the same rotation as [0, 180, 0]");
    let r = app
        .post(&cpath, &json!({"targets": q, "parameter_set_id": set_id, "allow_unvalidated": true, "frame": "base"}))
        .await;
    assert_eq!((r.status, &r.body["frame"]["kind"]), (StatusCode::OK, &json!("base")), "{}", r.text);
    let wobj = json!({"name": "fixture-2", "position_mm": [0, 0, 0], "rotation_deg": [0, 0, 0]});
    let r = app
        .post(&cpath, &json!({"targets": q, "parameter_set_id": set_id, "allow_unvalidated": true, "frame": "base", "work_object": wobj}))
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert_eq!(r.body["frame"]["work_object"], "fixture-2");
    let bad = json!({"name": "w", "position_mm": [0, 0, 0], "quaternion": [0, 0, 2, 0]});
    let r = app
        .post(&cpath, &json!({"targets": q, "parameter_set_id": set_id, "allow_unvalidated": true, "work_object": bad}))
        .await;
    assert_problem(&r, 422, Some("work_object.quaternion"));
    let r = app
        .post(&cpath, &json!({"targets": q, "parameter_set_id": set_id, "allow_unvalidated": true, "frame": "world", "work_object": wobj}))
        .await;
    assert_problem(&r, 422, Some("work_object"));
    assert_problem(
        &app.post(&cpath, &json!({"targets": [], "parameter_set_id": "none"})).await,
        404,
        Some("parameter_set_id"),
    );
    assert_problem(
        &app.post(&cpath, &json!({"targets": [], "parameter_set_id": set_id, "allow_unvalidated": true, "tool": {"tcp_mm": [0, 0, "x"]}})).await,
        422,
        None,
    );

    // Validation.
    let vpath = format!("/v1/parameter-sets/{set_id}/validations");
    assert_problem(&app.post(&vpath, &json!({"sessions": ["trical-1"]})).await, 422, Some("sessions[0]"));
    assert_problem(
        &app.post("/v1/parameter-sets/none/validations", &json!({"sessions": ["tracker-n1"]})).await,
        404,
        None,
    );
    let r = app.post(&vpath, &json!({"sessions": ["tracker-n1", "tracker-n2", "tracker-n3"]})).await;
    let j = app.wait(&r.body).await;
    assert_eq!(j["state"], "succeeded", "{j}");
    let vid = j["result"]["validation_id"].as_str().unwrap();
    let v = app.get(&format!("/v1/validations/{vid}")).await;
    assert_eq!(v.status, StatusCode::OK);
    let rep = &v.body["report"];
    assert_eq!(rep["n"], 60);
    assert!(rep["mean_mm"].as_f64().unwrap() < 0.1 && rep["nominal"]["mean_mm"].as_f64().unwrap() > 1.0, "{rep}");
    assert_eq!(rep["residuals"].as_array().unwrap().len(), 60);
    for k in ["median_mm", "std_mm", "rms_mm", "p95_mm", "max_mm", "per_axis", "vs_zone_distance"] {
        assert!(!rep[k].is_null(), "{k}");
    }
    // The two front ends give the same report: `robocal validate` on the exported cell (whose
    // artefact places the calibration zone) prints what the service stored, field for field.
    let exported = app.get(&format!("/v1/robots/{rid}/cell?sessions=trical-1,tracker-n1,tracker-n2,tracker-n3")).await;
    assert_eq!(exported.status, StatusCode::OK, "{}", exported.text);
    let (cell_path, set_path) = (app.dir.join("validate_cell.json"), app.dir.join("validate_set.json"));
    std::fs::write(&cell_path, &exported.text).unwrap();
    std::fs::write(&set_path, &app.get(&format!("/v1/parameter-sets/{set_id}/export")).await.text).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_robocal"))
        .arg("validate")
        .args([&set_path, &cell_path])
        .args([
            "--session",
            "tracker-n1",
            "--session",
            "tracker-n2",
            "--session",
            "tracker-n3",
            "--residuals",
            "--json",
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let cli: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(&cli, rep, "the CLI's validation report is the service's");
    assert_problem(&app.get("/v1/validations/none").await, 404, None);

    // History with validation figures; explicit activation; the active set.
    let h = app.get(&format!("/v1/robots/{rid}/parameter-sets")).await;
    let h0 = &h.body[0];
    assert_eq!((h0["version"].as_i64(), h0["active"].as_bool()), (Some(1), Some(false)));
    assert_eq!(h0["sessions"], json!(["trical-1"]));
    assert_eq!(h0["quality"]["identified"], 31);
    assert_eq!(h0["validations"][0]["figures"]["n"], 60);
    // The listing (which parses only the summary fields, and reads the page's validations in one
    // query) says what the single-set answer (which parses the whole document) says.
    let mut single = app.get(&format!("/v1/parameter-sets/{set_id}")).await.body;
    assert!(single.as_object_mut().unwrap().remove("parameter_set").is_some());
    assert_eq!(h0, &single);
    assert_eq!(h0["validations"][0]["figures"]["mean_mm"], rep["mean_mm"]);
    assert!(rep["nominal"]["mean_mm"].is_f64());
    assert_eq!(h0["validations"][0]["figures"]["nominal"]["mean_mm"], rep["nominal"]["mean_mm"]);
    assert_problem(&app.get(&format!("/v1/robots/{rid}/active-parameter-set")).await, 404, None);
    let apath = format!("/v1/robots/{rid}/active-parameter-set");
    assert_problem(&app.put(&apath, &json!({"parameter_set_id": "none"})).await, 404, Some("parameter_set_id"));
    let r = app.put(&apath, &json!({"parameter_set_id": set_id})).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert_eq!(r.body["active"], true);
    assert_eq!(app.get(&apath).await.body["id"], set_id);
    assert_eq!(app.get(&format!("/v1/robots/{rid}")).await.body["active_parameter_set_id"], set_id);
    let r = app.post(&cpath, &json!({"targets": [{"joints_deg": [10, 20, -10, 0, 45, 0]}]})).await;
    assert_eq!(r.body["parameter_set_id"], set_id);
    assert_eq!(r.body["failed"], 0);
    // Validated now: the answer names the validation it relied on, and each target carries the
    // model's predicted uncertainty there (a few µm for a 31-parameter fit on 0.01 mm noise).
    let validity = &r.body["validity"];
    assert_eq!(validity["validation"]["validation_id"], vid, "{validity}");
    assert_eq!(validity["validation"]["mean_mm"], rep["mean_mm"]);
    let u = r.body["results"][0]["uncertainty_mm"].as_f64().unwrap();
    assert!(u > 1e-4 && u < 0.05, "{u}");
    // Outside the calibrated envelope (joint 1 beyond its measured range and the 5° margin) a
    // target is refused, saying why, unless asked for.
    let j1 = &validity["envelope"]["joints_deg"][0];
    let (lo, hi) = (j1[0].as_f64().unwrap(), j1[1].as_f64().unwrap());
    let out_j1 = if hi + 10.0 < 160.0 { hi + 10.0 } else { lo - 10.0 };
    let outside = json!([{"id": "out", "joints_deg": [out_j1, 20, -10, 0, 45, 0]}]);
    let r = app.post(&cpath, &json!({"targets": outside})).await;
    assert_eq!((r.status, r.body["failed"].as_u64()), (StatusCode::OK, Some(1)), "{}", r.text);
    let e = r.body["results"][0]["error"].as_str().unwrap();
    assert!(e.contains("outside the calibrated envelope") && e.contains("joint 1"), "{e}");
    let r = app.post(&cpath, &json!({"targets": outside, "allow_outside_envelope": true})).await;
    assert_eq!(r.body["failed"], 0, "{}", r.text);
    assert!(r.body["results"][0]["notes"][0].as_str().unwrap().contains("outside the calibrated envelope"));
    assert!(r.body["results"][0]["uncertainty_mm"].as_f64().unwrap() > 0.0);

    // Import (the thesis's Table 5.1) as version 2; a set of another robot is refused.
    let table =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/examples/irb120_table_5_1.json")).unwrap();
    let ipath = format!("/v1/robots/{rid}/parameter-sets");
    let r = app.raw(Method::POST, &ipath, Some("application/json"), table.into_bytes(), &[]).await;
    assert_eq!(r.status, StatusCode::CREATED, "{}", r.text);
    assert_eq!(r.body["version"], 2);
    assert_eq!(r.body["active"], false);
    assert_problem(
        &app.post(&ipath, &json!({"robot": {"preset": "ur10"}, "parameters": []})).await,
        422,
        Some("robot"),
    );
    assert_problem(
        &app.post(&ipath, &json!({"robot": {"preset": "irb120"}, "parameters": [{"name": "a9", "value": 1}]})).await,
        422,
        None,
    );
    assert_eq!(app.get(&ipath).await.body.as_array().unwrap().len(), 2);
    let v2_id = r.body["id"].as_str().unwrap().to_string();

    // Compensation follows every activation at once (the robot and its sets are cached in the
    // server): by an explicit call…
    // (The imported table carries no validation, envelope or covariance: used as asked.)
    let one = json!({"targets": [{"joints_deg": [10, 20, -10, 0, 45, 0]}], "allow_unvalidated": true});
    let joints = |r: &common::Res| r.body["results"][0]["joints_deg"].clone();
    let with_v1 = app.post(&cpath, &one).await;
    assert_eq!(with_v1.body["version"], 1);
    assert_eq!(app.put(&apath, &json!({"parameter_set_id": v2_id})).await.status, StatusCode::OK);
    let with_v2 = app.post(&cpath, &one).await;
    assert_eq!((with_v2.body["parameter_set_id"].as_str(), with_v2.body["version"].as_i64()), (Some(&*v2_id), Some(2)));
    assert_ne!(joints(&with_v1), joints(&with_v2), "another set compensates differently");
    // … and by an identification job that activates its result.
    let r = app.post(&path, &json!({"sessions": ["trical-1"], "activate": true})).await;
    let j = app.wait(&r.body).await;
    assert_eq!((j["state"].as_str(), j["result"]["version"].as_i64()), (Some("succeeded"), Some(3)), "{j}");
    let with_v3 = app.post(&cpath, &one).await;
    assert_eq!(with_v3.body["parameter_set_id"], j["result"]["parameter_set_id"]);
    assert_eq!(joints(&with_v3), joints(&with_v1), "v3 is v1 identified again from the same data");
    // Every answer carries the server's own time.
    let st = with_v3.headers["server-timing"].to_str().unwrap();
    let ms: f64 = st.strip_prefix("app;dur=").unwrap().parse().unwrap();
    assert!(ms > 0.0 && ms < 10_000.0, "{st}");

    assert_problem(&app.get("/v1/parameter-sets/none").await, 404, None);
    assert_problem(&app.get("/v1/parameter-sets/none/export").await, 404, None);
    let g = app.get(&format!("/v1/parameter-sets/{set_id}")).await;
    assert_eq!(g.body["parameter_set"]["parameters"].as_array().unwrap().len(), 43);

    // Jobs: list and filters.
    let all = app.get(&format!("/v1/jobs?robot_id={rid}")).await;
    assert_eq!(all.body.as_array().unwrap().len(), 4);
    assert_eq!(app.get("/v1/jobs?state=failed").await.body.as_array().unwrap().len(), 1);
    assert_problem(&app.get("/v1/jobs?state=stuck").await, 422, Some("state"));
    assert_problem(&app.get("/v1/jobs/none").await, 404, None);
    let done = all.body[0]["id"].as_str().unwrap();
    assert_problem(&app.post(&format!("/v1/jobs/{done}/cancel"), &json!({})).await, 409, None);
    let _ = id_of;
    app.stop().await;
}

#[tokio::test]
async fn pose_plans() {
    let app = TestApp::default().await;
    let rid = robot(&app, "r").await;
    let aid = artefact(&app, "a").await;
    let tool = json!({"tcp_mm": [40, 0, 130], "mass_kg": 1.7, "com_mm": [30, 0, 64]});
    let path = format!("/v1/robots/{rid}/pose-plans");
    assert_problem(&app.post(&path, &json!({"artefact_id": "none", "tool": tool})).await, 404, Some("artefact_id"));
    assert_problem(
        &app.post(&path, &json!({"artefact_id": aid, "tool": tool, "per_ball": 0})).await,
        422,
        Some("per_ball"),
    );
    assert_problem(
        &app.post(&path, &json!({"artefact_id": aid, "tool": tool, "per_ball": 10, "select": {"n": 30}})).await,
        422,
        Some("select.n"),
    );
    let ur =
        app.post("/v1/robots", &json!({"name": "ur", "robot": {"preset": "ur10"}, "base_guess": base_guess()})).await;
    let ur = ur.body["id"].as_str().unwrap();
    assert_problem(
        &app.post(&format!("/v1/robots/{ur}/pose-plans"), &json!({"artefact_id": aid, "tool": tool})).await,
        422,
        Some("robot"),
    );
    let nob = app.post("/v1/robots", &json!({"name": "nob", "robot": {"preset": "irb120"}})).await;
    let nob = nob.body["id"].as_str().unwrap();
    assert_problem(
        &app.post(&format!("/v1/robots/{nob}/pose-plans"), &json!({"artefact_id": aid, "tool": tool})).await,
        422,
        Some("base_guess"),
    );

    let r = app
        .post(&path, &json!({"artefact_id": aid, "tool": tool, "per_ball": 20, "validation": 12, "select": {"n": 35, "seed": 4}, "seed": 2}))
        .await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", r.text);
    let j = app.wait(&r.body).await;
    assert_eq!(j["state"], "succeeded", "{j}");
    let plan_id = j["result"]["pose_plan_id"].as_str().unwrap();
    let p = app.get(&format!("/v1/pose-plans/{plan_id}")).await;
    assert_eq!(p.status, StatusCode::OK);
    let plan = &p.body["plan"];
    assert_eq!(plan["candidates"], 60);
    let id = plan["identification"].as_array().unwrap();
    assert_eq!(id.len(), 35);
    assert!(
        id.iter()
            .all(|x| x["nu_deg"].as_f64().unwrap() <= 50.0 + 1e-9 && (1..=3).contains(&x["ball"].as_u64().unwrap()))
    );
    assert!(plan["selection"]["index_final"].as_f64().unwrap() > plan["selection"]["index_initial"].as_f64().unwrap());
    assert_eq!(plan["validation"].as_array().unwrap().len(), 12);
    // The sequence is collision-free from home, as the planner checks it.
    let layout = robocal::sim::poses::CellLayout::default();
    let pc = robocal::sim::poses::PlanningCell::new(&layout).unwrap();
    let poses: Vec<robocal::sim::poses::PlannedPose> = id
        .iter()
        .map(|x| {
            let q: Vec<f64> = serde_json::from_value(x["joints_deg"].clone()).unwrap();
            robocal::sim::poses::PlannedPose {
                q: std::array::from_fn(|j| q[j].to_radians()),
                ball: Some(x["ball"].as_u64().unwrap() as usize),
                nest: None,
                nu: None,
            }
        })
        .collect();
    assert!(pc.check_sequence(&poses).is_ok());
    // `robocal plan` with the same request writes the same plan (base guess and artefact are the
    // CLI's defaults: the thesis's lab, 300 mm sides, 12.7 mm balls).
    let cli_plan = app.dir.join("plan.json");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["plan", "--tcp-mm", "40,0,130", "--payload-kg", "1.7", "--payload-com-mm", "30,0,64"])
        .args([
            "--per-ball",
            "20",
            "--validation",
            "12",
            "--select",
            "35",
            "--select-seed",
            "4",
            "--seed",
            "2",
            "--out",
        ])
        .arg(&cli_plan)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("35 identification poses (a DETMAX selection of 60"), "{stdout}");
    let written: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&cli_plan).unwrap()).unwrap();
    assert_eq!(&written, plan, "the CLI's plan is the service's");
    // The CLI applies the service's bounds, or asks for --force with what the run would cost.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["plan", "--per-ball", "100000"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("--per-ball: must be 1–2000") && err.contains("--force") && err.contains(" MB"), "{err}");
    assert_problem(&app.get("/v1/pose-plans/none").await, 404, None);

    // The robot's plans, listed without their configurations.
    let r = app.get(&path).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert_eq!(r.headers["x-total-count"], "1");
    let listed = r.body.as_array().unwrap();
    assert_eq!(listed.len(), 1);
    let s = &listed[0];
    assert_eq!((s["id"].as_str(), s["job_id"].as_str()), (Some(plan_id), j["id"].as_str()));
    assert_eq!(
        (s["identification"].as_u64(), s["validation"].as_u64(), s["candidates"].as_u64()),
        (Some(35), Some(12), Some(60))
    );
    assert_eq!(s["request"]["per_ball"], 20);
    assert_eq!(s["selection"]["n"], 35);
    assert!(s.get("plan").is_none() && s.get("identification_poses").is_none(), "no configurations in the list: {s}");
    assert_eq!(app.get(&format!("/v1/robots/{ur}/pose-plans")).await.body, json!([]));
    assert_problem(&app.get("/v1/robots/none/pose-plans").await, 404, None);
    app.stop().await;
}

/// Cancelling: a queued job ends at once (no worker runs here).
#[tokio::test]
async fn queued_jobs_cancel() {
    let app = TestApp::new(ServiceConfig::default(), false).await;
    let rid = robot(&app, "r").await;
    let aid = artefact(&app, "a").await;
    let tool = json!({"tcp_mm": [40, 0, 130]});
    let r = app.post(&format!("/v1/robots/{rid}/pose-plans"), &json!({"artefact_id": aid, "tool": tool})).await;
    assert_eq!(r.body["state"], "queued");
    let id = r.body["id"].as_str().unwrap();
    let c = app.post(&format!("/v1/jobs/{id}/cancel"), &json!({})).await;
    assert_eq!(c.status, StatusCode::OK, "{}", c.text);
    assert_eq!(c.body["state"], "cancelled");
    assert!(c.body["finished_at"].is_string());
    assert_problem(&app.post(&format!("/v1/jobs/{id}/cancel"), &json!({})).await, 409, None);
    assert_problem(&app.post("/v1/jobs/none/cancel", &json!({})).await, 404, None);
    app.stop().await;
}

/// Bearer tokens with scopes, stored hashed; required when the server says so.
#[tokio::test]
async fn tokens_and_scopes() {
    let mut app = TestApp::new(ServiceConfig { require_auth: true, ..Default::default() }, false).await;
    let r = app.get("/v1/robots").await;
    assert_problem(&r, 401, None);
    assert_eq!(r.headers["www-authenticate"], "Bearer");
    assert_eq!(app.get("/healthz").await.status, StatusCode::OK, "health needs no token");
    let (admin, secret) =
        robocal::db::tokens::create(&app.state.pool, "admin", &[robocal::db::tokens::Scope::Admin]).await.unwrap();
    assert_ne!(admin.hash, secret, "only the hash is stored");
    app.token = Some("rc_wrong".into());
    assert_problem(&app.get("/v1/robots").await, 401, None);
    app.token = Some(secret.clone());
    assert_eq!(app.get("/v1/robots").await.status, StatusCode::OK);
    let r = app.post("/v1/tokens", &json!({"name": "dashboard", "scopes": ["read"]})).await;
    assert_eq!(r.status, StatusCode::CREATED, "{}", r.text);
    let reader = r.body["token"].as_str().unwrap().to_string();
    let reader_id = r.body["id"].as_str().unwrap().to_string();
    assert_problem(&app.post("/v1/tokens", &json!({"name": "x", "scopes": ["write"]})).await, 422, Some("scopes[0]"));
    assert_problem(&app.post("/v1/tokens", &json!({"name": "x", "scopes": []})).await, 422, Some("scopes"));
    let list = app.get("/v1/tokens").await;
    assert_eq!(list.body.as_array().unwrap().len(), 2);
    assert!(list.body.as_array().unwrap().iter().all(|t| t.get("token").is_none()), "secrets never listed");

    app.token = Some(reader.clone());
    assert_eq!(app.get("/v1/robots").await.status, StatusCode::OK);
    let r = app.post("/v1/robots", &json!({"name": "x", "robot": {"preset": "irb120"}})).await;
    assert_problem(&r, 403, None);
    assert!(r.body["detail"].as_str().unwrap().contains("'measure'"), "{}", r.text);
    assert_problem(&app.get("/v1/tokens").await, 403, None);
    // Corrections need the scope of what they correct; the audit timeline is readable.
    let exclude = br#"{"excluded": true, "reason": "x"}"#.to_vec();
    let r = app.raw(Method::PATCH, "/v1/sessions/s/measurements/0", Some("application/json"), exclude, &[]).await;
    assert_problem(&r, 403, None);
    assert_problem(&app.raw(Method::DELETE, "/v1/sessions/s?reason=x", None, vec![], &[]).await, 403, None);
    let archive = br#"{"archived": true, "reason": "x"}"#.to_vec();
    let r = app.raw(Method::PATCH, "/v1/parameter-sets/p", Some("application/json"), archive, &[]).await;
    assert!(r.body["detail"].as_str().unwrap().contains("'calibrate'"), "{}", r.text);
    assert_eq!(app.get("/v1/audit-events").await.status, StatusCode::OK);

    app.token = Some(secret);
    assert_eq!(
        app.raw(Method::DELETE, &format!("/v1/tokens/{reader_id}"), None, vec![], &[]).await.status,
        StatusCode::NO_CONTENT
    );
    assert_problem(&app.raw(Method::DELETE, &format!("/v1/tokens/{reader_id}"), None, vec![], &[]).await, 404, None);
    app.token = Some(reader);
    assert_problem(&app.get("/v1/robots").await, 401, None);

    // Revoked from another process (`robocal token revoke` writes the database): the server
    // trusts a verified token for at most RECHECK.
    let (cli, cli_secret) =
        robocal::db::tokens::create(&app.state.pool, "cli", &[robocal::db::tokens::Scope::Read]).await.unwrap();
    app.token = Some(cli_secret);
    assert_eq!(app.get("/v1/robots").await.status, StatusCode::OK);
    assert!(robocal::db::tokens::revoke(&app.state.pool, &cli.id).await.unwrap());
    tokio::time::sleep(robocal::http::cache::RECHECK + std::time::Duration::from_millis(50)).await;
    assert_problem(&app.get("/v1/robots").await, 401, None);
    app.stop().await;
}

/// CORS is off unless configured: a request from a page of another origin gets no
/// Access-Control-Allow-Origin (so the browser keeps the answer from the page), and OPTIONS is
/// not answered as a preflight.
#[tokio::test]
async fn cors_is_off_by_default() {
    let app = TestApp::new(ServiceConfig::default(), false).await;
    let origin = ("origin", "https://dash.example.com");
    let r = app.raw(Method::GET, "/v1/robots", None, vec![], &[origin]).await;
    assert_eq!(r.status, StatusCode::OK);
    assert!(r.headers.keys().all(|k| !k.as_str().starts_with("access-control-")), "{:?}", r.headers);
    let r = app
        .raw(Method::OPTIONS, "/v1/robots", None, vec![], &[origin, ("access-control-request-method", "POST")])
        .await;
    assert!(r.headers.keys().all(|k| !k.as_str().starts_with("access-control-")), "{:?}", r.headers);
    assert_ne!(r.status, StatusCode::OK, "{}", r.text);
    app.stop().await;
}

/// `--cors-origin` configured: a preflight from that origin is answered (before any token is
/// asked for, on a server that requires them) with the origin, the methods and the request
/// headers the API takes; a request from it gets the origin and the readable response headers,
/// a 401 included; another origin gets no CORS header at all. `*` answers any origin with `*`.
#[tokio::test]
async fn cors_answers_the_configured_origins_only() {
    use robocal::http::CorsOrigins;
    let cors = CorsOrigins::parse(&["https://dash.example.com,http://localhost:3000"], "--cors-origin").unwrap();
    let app = TestApp::new(ServiceConfig { require_auth: true, cors, ..Default::default() }, false).await;
    let preflight = |origin: &'static str| {
        [
            ("origin", origin),
            ("access-control-request-method", "POST"),
            ("access-control-request-headers", "authorization, content-type, idempotency-key"),
        ]
    };
    for origin in ["https://dash.example.com", "http://localhost:3000"] {
        let r = app.raw(Method::OPTIONS, "/v1/sessions/abc/measurements", None, vec![], &preflight(origin)).await;
        assert!(r.status.is_success(), "{} {}", r.status, r.text);
        assert_eq!(r.headers["access-control-allow-origin"], origin);
        let methods = r.headers["access-control-allow-methods"].to_str().unwrap().to_string();
        for m in ["GET", "POST", "PUT", "PATCH", "DELETE"] {
            assert!(methods.contains(m), "{methods}");
        }
        let allowed = r.headers["access-control-allow-headers"].to_str().unwrap().to_string();
        for h in ["authorization", "content-type", "idempotency-key", "x-request-id"] {
            assert!(allowed.contains(h), "{allowed}");
        }
        assert!(r.headers.get("access-control-allow-credentials").is_none());
        assert!(r.headers.contains_key("x-request-id"), "a preflight has its request id too");
    }
    // The real request (no token yet): 401, readable by the page.
    let r = app.raw(Method::GET, "/v1/robots", None, vec![], &[("origin", "https://dash.example.com")]).await;
    assert_problem(&r, 401, None);
    assert_eq!(r.headers["access-control-allow-origin"], "https://dash.example.com");
    let exposed = r.headers["access-control-expose-headers"].to_str().unwrap().to_string();
    for h in ["x-request-id", "server-timing", "location", "link", "x-total-count"] {
        assert!(exposed.contains(h), "{exposed}");
    }
    assert!(r.headers.get_all("vary").iter().any(|v| v.to_str().unwrap().contains("origin")), "{:?}", r.headers);
    // Another origin (an origin differs by scheme and port too): no CORS header, nothing to read.
    for other in ["https://evil.example.com", "http://dash.example.com", "http://localhost:3001"] {
        let r = app.raw(Method::OPTIONS, "/v1/robots", None, vec![], &preflight(other)).await;
        assert!(r.headers.get("access-control-allow-origin").is_none(), "{other}: {:?}", r.headers);
        let r = app.raw(Method::GET, "/v1/robots", None, vec![], &[("origin", other)]).await;
        assert!(r.headers.get("access-control-allow-origin").is_none(), "{other}: {:?}", r.headers);
    }
    app.stop().await;

    let app = TestApp::new(ServiceConfig { cors: CorsOrigins::Any, ..Default::default() }, false).await;
    let r = app.raw(Method::OPTIONS, "/v1/robots", None, vec![], &preflight("https://anyone.example")).await;
    assert!(r.status.is_success());
    assert_eq!(r.headers["access-control-allow-origin"], "*");
    let r = app.raw(Method::GET, "/v1/robots", None, vec![], &[("origin", "https://anyone.example")]).await;
    assert_eq!(r.status, StatusCode::OK);
    assert_eq!(r.headers["access-control-allow-origin"], "*");
    app.stop().await;
}

/// Every list pages the same way: `offset` and `limit` (1–1000, default 100; measurements up to
/// 10000), bad values refused at the parameter, the bodies as they were, the whole list's length
/// in `X-Total-Count` and the neighbouring pages in `Link`.
#[tokio::test]
async fn every_list_pages_the_same_way() {
    let mut app = TestApp::new(ServiceConfig::default(), false).await;
    // Token management needs an admin token even on loopback.
    let (_, admin) =
        robocal::db::tokens::create(&app.state.pool, "admin", &[robocal::db::tokens::Scope::Admin]).await.unwrap();
    app.token = Some(admin);
    let rid = robot(&app, "r1").await;
    robot(&app, "r2").await;
    robot(&app, "r3").await;
    let r = app.get("/v1/robots?limit=2").await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    let names: Vec<&str> = r.body.as_array().unwrap().iter().map(|x| x["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["r1", "r2"], "the limit is honoured, oldest first");
    assert_eq!(r.headers["x-total-count"], "3");
    assert_eq!(r.headers["link"], "</v1/robots?offset=2&limit=2>; rel=\"next\"");
    let r = app.get("/v1/robots?offset=2&limit=2").await;
    let names: Vec<&str> = r.body.as_array().unwrap().iter().map(|x| x["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["r3"]);
    assert_eq!(r.headers["link"], "</v1/robots?offset=0&limit=2>; rel=\"prev\"");
    let r = app.get("/v1/robots").await;
    assert_eq!((r.body.as_array().unwrap().len(), r.headers.get("link")), (3, None), "default limit 100");
    let past = app.get("/v1/robots?offset=5").await;
    assert_eq!(past.body, json!([]));
    assert_eq!(past.headers["x-total-count"], "3", "a page past the end still counts the list");

    // Filters stay in the links.
    let aid = artefact(&app, "a").await;
    let tool = json!({"tcp_mm": [40, 0, 130]});
    for _ in 0..3 {
        let r = app.post(&format!("/v1/robots/{rid}/pose-plans"), &json!({"artefact_id": aid, "tool": tool})).await;
        assert_eq!(r.status, StatusCode::ACCEPTED, "{}", r.text);
    }
    let r = app.get(&format!("/v1/jobs?robot_id={rid}&state=queued&offset=1&limit=1")).await;
    assert_eq!((r.body.as_array().unwrap().len(), r.headers["x-total-count"].to_str().unwrap()), (1, "3"));
    assert_eq!(
        r.headers["link"],
        format!(
            "</v1/jobs?robot_id={rid}&state=queued&offset=2&limit=1>; rel=\"next\", </v1/jobs?robot_id={rid}&state=queued&offset=0&limit=1>; rel=\"prev\""
        )
    );
    assert_eq!(app.get("/v1/jobs?state=failed").await.headers["x-total-count"], "0");

    // Every list: the same parameters, the same refusals.
    let session = app
        .post(
            &format!("/v1/robots/{rid}/sessions"),
            &json!({"name": "s", "purpose": "validation", "instrument": "laser_tracker", "tool": {"tcp_mm": [0, 0, 0]}}),
        )
        .await;
    let sid = session.body["id"].as_str().unwrap();
    let table =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/examples/irb120_table_5_1.json")).unwrap();
    let set = app
        .raw(
            Method::POST,
            &format!("/v1/robots/{rid}/parameter-sets"),
            Some("application/json"),
            table.into_bytes(),
            &[],
        )
        .await;
    let set_id = set.body["id"].as_str().unwrap();
    let lists = [
        "/v1/robots".to_string(),
        "/v1/artefacts".to_string(),
        format!("/v1/robots/{rid}/sessions"),
        format!("/v1/robots/{rid}/parameter-sets"),
        format!("/v1/robots/{rid}/pose-plans"),
        format!("/v1/parameter-sets/{set_id}/diagnoses"),
        "/v1/jobs".to_string(),
        "/v1/tokens".to_string(),
        format!("/v1/sessions/{sid}/measurements"),
        format!("/v1/robots/{rid}/activations"),
        "/v1/audit-events".to_string(),
    ];
    for path in &lists {
        let r = app.get(&format!("{path}?offset=0&limit=1")).await;
        assert_eq!(r.status, StatusCode::OK, "{path}: {}", r.text);
        // The whole list's length, on the first page and on one past the end (no row carries it).
        let all = app.get(&format!("{path}?limit=1000")).await;
        let len = all.body.as_array().or_else(|| all.body["items"].as_array()).map(Vec::len).unwrap();
        assert_eq!(r.headers["x-total-count"].to_str().unwrap(), len.to_string(), "{path}");
        let past = app.get(&format!("{path}?offset=100000")).await;
        assert_eq!(past.headers["x-total-count"].to_str().unwrap(), len.to_string(), "{path} past the end");
        for (query, field) in [
            ("limit=0", "limit"),
            ("limit=x", "limit"),
            ("offset=-1", "offset"),
            ("offset=1.5", "offset"),
            ("limit=10001", "limit"),
        ] {
            let r = app.get(&format!("{path}?{query}")).await;
            assert_problem(&r, 422, Some(field));
        }
        let r = app.get(&format!("{path}?limit=1001")).await;
        if path.ends_with("/measurements") {
            assert_eq!(r.status, StatusCode::OK, "measurements keep their larger cap: {}", r.text);
        } else {
            assert_problem(&r, 422, Some("limit"));
        }
    }
    app.stop().await;
}

/// Excluding a measurement is a record with a reason, and changes what the jobs use: a gross
/// outlier refuses the fit (named by its stored index, even with another measurement excluded
/// before it), excluding it lets the fit succeed, restoring brings measurements back; the
/// listing, the measurement's history, the export and the audit timeline show each step.
#[tokio::test]
async fn excluded_measurements_leave_the_jobs_and_restoring_brings_them_back() {
    let app = TestApp::default().await;
    let rid = robot(&app, "r").await;
    let aid = artefact(&app, "plate").await;
    let mut cell = small_cell(3);
    let t = cell.sessions.iter().position(|s| s.name == "trical-1").unwrap();
    // Measurement 10 read with joint 1 off by 0.1°: ~0.9 mm at the ball, a gross outlier.
    cell.sessions[t].measurements[10].joints_deg[0] += 0.1;
    let n = cell.sessions[t].measurements.len();
    let ids = upload(&app, &rid, &aid, &cell).await;
    let sid = ids.iter().find(|(name, _)| name == "trical-1").unwrap().1.clone();
    let m = |i: i64| format!("/v1/sessions/{sid}/measurements/{i}");
    let patch = async |i: i64, body: Value| {
        app.raw(Method::PATCH, &m(i), Some("application/json"), serde_json::to_vec(&body).unwrap(), &[]).await
    };

    // Refusals: no reason, a blank one, an unknown index or session, an unknown field.
    assert_problem(&patch(3, json!({"excluded": true})).await, 422, Some("reason"));
    assert_problem(&patch(3, json!({"excluded": true, "reason": "  "})).await, 422, Some("reason"));
    assert_problem(&patch(n as i64, json!({"excluded": true, "reason": "x"})).await, 404, None);
    assert_problem(&patch(-1, json!({"excluded": true, "reason": "x"})).await, 404, None);
    assert_problem(&patch(3, json!({"excluded": true, "reason": "x", "why": 1})).await, 422, Some("why"));
    assert_problem(
        &app.raw(
            Method::PATCH,
            "/v1/sessions/none/measurements/0",
            Some("application/json"),
            br#"{"excluded": true, "reason": "x"}"#.to_vec(),
            &[],
        )
        .await,
        404,
        None,
    );
    assert_problem(&patch(5, json!({"excluded": false, "reason": "x"})).await, 409, None);
    assert_problem(&app.get(&m(n as i64)).await, 404, None);

    // Measurement 3 excluded first: from here on the cell's indices differ from the stored ones.
    let r = patch(3, json!({"excluded": true, "reason": "nest not cleaned before this reading"})).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert_eq!((r.body["index"].as_i64(), r.body["excluded"].as_bool()), (Some(3), Some(true)));
    assert_eq!(r.body["exclusion"]["reason"], "nest not cleaned before this reading");
    assert!(r.body["exclusion"]["excluded_at"].is_string() && r.body["exclusion"]["restored_at"].is_null());
    assert_eq!(r.body["joints_deg"], json!(cell.sessions[t].measurements[3].joints_deg));
    assert_problem(&patch(3, json!({"excluded": true, "reason": "again"})).await, 409, None);

    // The outlier refuses the fit, named by its stored index.
    let path = format!("/v1/robots/{rid}/identifications");
    let identify = async || app.wait(&app.post(&path, &json!({"sessions": ["trical-1"]})).await.body).await;
    let j = identify().await;
    assert_eq!(j["state"], "failed", "{j}");
    assert_eq!(j["error"]["type"], "urn:robocal:problem:outliers", "{j}");
    let detail = j["error"]["detail"].as_str().unwrap();
    assert!(detail.contains("trical-1[10]") && detail.contains("trical-1:10"), "stored index: {detail}");

    // Excluded, the fit succeeds without both.
    let r = patch(10, json!({"excluded": true, "reason": "joint 1 slipped: refused fit named it an outlier"})).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    let j = identify().await;
    assert_eq!(j["state"], "succeeded", "{j}");
    let summary = &j["result"]["summary"];
    assert_eq!((summary["measurements"].as_u64(), summary["excluded"].as_u64()), (Some(n as u64 - 2), Some(2)));
    let set = app.get(&format!("/v1/parameter-sets/{}", j["result"]["parameter_set_id"].as_str().unwrap())).await;
    assert_eq!(set.body["quality"]["measurements"], n - 2);
    for w in set.body["parameter_set"]["quality"]["worst"].as_array().unwrap() {
        assert!(![3, 10].contains(&w["index"].as_u64().unwrap()), "worst names stored indices: {w}");
    }

    // The listing, the session, the export show the exclusions.
    let page = app.get(&format!("/v1/sessions/{sid}/measurements?offset=2&limit=10")).await;
    let items = page.body["items"].as_array().unwrap();
    let excluded: Vec<i64> =
        items.iter().filter(|i| i["excluded"] == true).map(|i| i["index"].as_i64().unwrap()).collect();
    assert_eq!(excluded, [3, 10]);
    assert_eq!(items[1]["exclusion"]["reason"], "nest not cleaned before this reading");
    assert!(items[0].get("exclusion").is_none() && items[0]["excluded"] == false);
    let s = app.get(&format!("/v1/sessions/{sid}")).await;
    assert_eq!((s.body["measurements"].as_u64(), s.body["excluded_measurements"].as_u64()), (Some(n as u64), Some(2)));
    let export = app.get(&format!("/v1/robots/{rid}/cell?sessions=trical-1")).await;
    assert_eq!(export.body["sessions"][0]["measurements"].as_array().unwrap().len(), n - 2);
    let export = app.get(&format!("/v1/robots/{rid}/cell?sessions=trical-1&include_excluded=true")).await;
    assert_eq!(export.body["sessions"][0]["measurements"].as_array().unwrap().len(), n);

    // Restoring measurement 3 brings it back into the fit; its history keeps both records.
    assert_problem(&patch(3, json!({"excluded": false})).await, 422, Some("reason"));
    let r = patch(3, json!({"excluded": false, "reason": "the nest was clean: checked the photo log"})).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert_eq!((r.body["excluded"].as_bool(), r.body["exclusion"].is_null()), (Some(false), true));
    let h = &r.body["history"];
    assert_eq!(h.as_array().unwrap().len(), 1);
    assert_eq!(h[0]["reason"], "nest not cleaned before this reading");
    assert_eq!(h[0]["restore_reason"], "the nest was clean: checked the photo log");
    assert!(h[0]["restored_at"].is_string());
    let j = identify().await;
    assert_eq!(j["state"], "succeeded", "{j}");
    assert_eq!(
        (j["result"]["summary"]["measurements"].as_u64(), j["result"]["summary"]["excluded"].as_u64()),
        (Some(n as u64 - 1), Some(1))
    );
    // Excluded again with another reason: a second record, the first one kept.
    assert_eq!(patch(3, json!({"excluded": true, "reason": "second look: it was dirty"})).await.status, StatusCode::OK);
    let g = app.get(&m(3)).await;
    assert_eq!(g.body["history"].as_array().unwrap().len(), 2);
    assert_eq!(g.body["exclusion"]["reason"], "second look: it was dirty");

    // The audit timeline: newest first, with the reasons.
    let a = app.get(&format!("/v1/audit-events?subject_id={sid}")).await;
    assert_eq!(a.status, StatusCode::OK, "{}", a.text);
    assert_eq!(a.headers["x-total-count"], "4");
    let steps: Vec<(&str, i64, &str)> = a
        .body
        .as_array()
        .unwrap()
        .iter()
        .map(|e| (e["action"].as_str().unwrap(), e["detail"]["index"].as_i64().unwrap(), e["reason"].as_str().unwrap()))
        .collect();
    assert_eq!(
        steps,
        [
            ("measurement_excluded", 3, "second look: it was dirty"),
            ("measurement_restored", 3, "the nest was clean: checked the photo log"),
            ("measurement_excluded", 10, "joint 1 slipped: refused fit named it an outlier"),
            ("measurement_excluded", 3, "nest not cleaned before this reading"),
        ]
    );
    assert!(a.body[0]["actor"].is_null(), "no token on loopback");
    assert_eq!(a.body[0]["robot_id"], rid);

    // Validation leaves an excluded reading out too, and names the others by their stored index.
    let set_id = j["result"]["parameter_set_id"].as_str().unwrap();
    let n1 = ids.iter().find(|(name, _)| name == "tracker-n1").unwrap().1.clone();
    let count = cell.sessions.iter().find(|s| s.name == "tracker-n1").unwrap().measurements.len();
    let r = app
        .raw(
            Method::PATCH,
            &format!("/v1/sessions/{n1}/measurements/0"),
            Some("application/json"),
            serde_json::to_vec(&json!({"excluded": true, "reason": "tracker warming up"})).unwrap(),
            &[],
        )
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    let v = app.post(&format!("/v1/parameter-sets/{set_id}/validations"), &json!({"sessions": ["tracker-n1"]})).await;
    let v = app.wait(&v.body).await;
    assert_eq!(v["state"], "succeeded", "{v}");
    assert_eq!(v["result"]["summary"]["measurements"], count - 1);
    let rep = app.get(&format!("/v1/validations/{}", v["result"]["validation_id"].as_str().unwrap())).await;
    let indices: Vec<u64> =
        rep.body["report"]["residuals"].as_array().unwrap().iter().map(|r| r["index"].as_u64().unwrap()).collect();
    assert_eq!(indices, (1..count as u64).collect::<Vec<_>>());
    app.stop().await;
}

/// A session or an artefact nothing refers to is deleted with a reason (204), the audit keeping
/// what it was; one that results were made from, or that a queued job reads, is refused (409,
/// naming them).
#[tokio::test]
async fn sessions_and_artefacts_are_deleted_only_when_unused() {
    let app = TestApp::new(ServiceConfig::default(), false).await;
    let rid = robot(&app, "r").await;
    let aid = artefact(&app, "plate").await;
    let spare = artefact(&app, "spare").await;
    let sess = |name: &str| {
        json!({"name": name, "purpose": "identification", "instrument": "trical", "tool": {"tcp_mm": [40, 0, 130]},
               "artefact_id": aid})
    };
    let mk = async |name: &str| {
        let r = app.post(&format!("/v1/robots/{rid}/sessions"), &sess(name)).await;
        assert_eq!(r.status, StatusCode::CREATED, "{}", r.text);
        let id = r.body["id"].as_str().unwrap().to_string();
        let ms = json!({"measurements": [{"joints_deg": [0, 10, 20, 0, 30, 0], "ball": 1}, {"joints_deg": [0, 10, 20, 0, 31, 0], "ball": 2}]});
        assert_eq!(app.post(&format!("/v1/sessions/{id}/measurements"), &ms).await.status, StatusCode::CREATED);
        id
    };
    let del = async |path: &str| app.raw(Method::DELETE, path, None, vec![], &[]).await;
    let wrong = mk("wrong-upload").await;
    let used = mk("used").await;

    assert_problem(&del(&format!("/v1/sessions/{wrong}")).await, 422, Some("reason"));
    assert_problem(&del(&format!("/v1/sessions/{wrong}?reason=")).await, 422, Some("reason"));
    // A reason starting with NUL (found by schemathesis: SQLite's length() stops at NUL, so the
    // store's not-blank check failed with a 500) is refused by the server, as the spec's pattern says.
    let r = del(&format!("/v1/sessions/{wrong}?reason=%00%C2%86p")).await;
    assert_problem(&r, 422, Some("reason"));
    assert!(r.text.contains("NUL"), "{}", r.text);
    let spec: Value = serde_json::from_str(include_str!("../../openapi/openapi.json")).unwrap();
    let reason = spec["paths"]["/v1/sessions/{session_id}"]["delete"]["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == "reason")
        .cloned()
        .unwrap();
    assert_eq!(reason["schema"]["pattern"], robocal::domain::limits::TEXT_PATTERN);
    assert_problem(&del("/v1/sessions/none?reason=x").await, 404, None);

    // A queued identification reads "used": refused while it waits, allowed once it is cancelled.
    let r = app.post(&format!("/v1/robots/{rid}/identifications"), &json!({"sessions": ["used"]})).await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", r.text);
    let job = r.body["id"].as_str().unwrap().to_string();
    let r = del(&format!("/v1/sessions/{used}?reason=test")).await;
    assert_problem(&r, 409, None);
    assert!(r.body["detail"].as_str().unwrap().contains(&format!("identification job {job} (queued)")), "{}", r.text);
    assert!(r.body["hint"].as_str().unwrap().contains("exclude"), "{}", r.text);
    // A parameter set made from it (its sessions name it) holds it too.
    sqlx::query("INSERT INTO parameter_sets (id, robot_id, version, doc_json, sessions_json, created_at) VALUES ('ps', $1, 7, '{}', '[\"used\"]', 't')")
        .bind(&rid)
        .execute(&app.state.pool)
        .await
        .unwrap();
    assert_eq!(app.post(&format!("/v1/jobs/{job}/cancel"), &json!({})).await.status, StatusCode::OK);
    let r = del(&format!("/v1/sessions/{used}?reason=test")).await;
    assert_problem(&r, 409, None);
    let detail = r.body["detail"].as_str().unwrap();
    assert!(detail.contains("parameter set version 7") && !detail.contains("job"), "{detail}");
    assert_eq!(app.get(&format!("/v1/sessions/{used}")).await.body["measurements"], 2, "nothing deleted");

    // The wrong upload goes, with its measurements; the audit says what it was.
    let r = del(&format!("/v1/sessions/{wrong}?reason=uploaded%20to%20the%20wrong%20robot")).await;
    assert_eq!(r.status, StatusCode::NO_CONTENT, "{}", r.text);
    assert_problem(&app.get(&format!("/v1/sessions/{wrong}")).await, 404, None);
    assert_problem(&app.get(&format!("/v1/sessions/{wrong}/measurements")).await, 404, None);
    assert_problem(&del(&format!("/v1/sessions/{wrong}?reason=again")).await, 404, None);
    let left: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM measurements WHERE session_id = $1")
        .bind(&wrong)
        .fetch_one(&app.state.pool)
        .await
        .unwrap();
    assert_eq!(left, 0);
    let a = app.get(&format!("/v1/audit-events?robot_id={rid}")).await;
    assert_eq!(a.body[0]["action"], "session_deleted");
    assert_eq!(a.body[0]["reason"], "uploaded to the wrong robot");
    assert_eq!(
        (a.body[0]["detail"]["name"].as_str(), a.body[0]["detail"]["measurements"].as_i64()),
        (Some("wrong-upload"), Some(2))
    );
    assert_eq!(app.get(&format!("/v1/robots/{rid}/sessions")).await.body.as_array().unwrap().len(), 1);
    // A new session may take the deleted one's name.
    mk("wrong-upload").await;

    // Artefacts: the one measured on is refused, naming the sessions; the spare one goes.
    let r = del(&format!("/v1/artefacts/{aid}?reason=x")).await;
    assert_problem(&r, 409, None);
    assert!(r.body["detail"].as_str().unwrap().contains("session 'used' of robot 'r'"), "{}", r.text);
    assert_problem(&del(&format!("/v1/artefacts/{spare}")).await, 422, Some("reason"));
    assert_problem(&del("/v1/artefacts/none?reason=x").await, 404, None);
    assert_eq!(del(&format!("/v1/artefacts/{spare}?reason=duplicate%20entry")).await.status, StatusCode::NO_CONTENT);
    assert_problem(&app.get(&format!("/v1/artefacts/{spare}")).await, 404, None);
    let a = app.get(&format!("/v1/audit-events?subject_id={spare}")).await;
    assert_eq!(
        (a.body[0]["action"].as_str(), a.body[0]["detail"]["name"].as_str()),
        (Some("artefact_deleted"), Some("spare"))
    );
    assert!(a.body[0]["robot_id"].is_null());
    app.stop().await;
}

/// Parameter sets are archived, never deleted: the active one cannot be, an archived one is
/// hidden from the history and never activated, and the activation history keeps every set that
/// was active.
#[tokio::test]
async fn parameter_sets_are_archived_not_deleted() {
    let mut app = TestApp::new(ServiceConfig { require_auth: true, ..Default::default() }, false).await;
    let (_, secret) = robocal::db::tokens::create(&app.state.pool, "metrologist", &[robocal::db::tokens::Scope::Admin])
        .await
        .unwrap();
    app.token = Some(secret);
    let rid = robot(&app, "r").await;
    let table =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/examples/irb120_table_5_1.json")).unwrap();
    let import = async || {
        let r = app
            .raw(
                Method::POST,
                &format!("/v1/robots/{rid}/parameter-sets"),
                Some("application/json"),
                table.clone().into_bytes(),
                &[],
            )
            .await;
        assert_eq!(r.status, StatusCode::CREATED, "{}", r.text);
        r.body["id"].as_str().unwrap().to_string()
    };
    let v1 = import().await;
    let v2 = import().await;
    let apath = format!("/v1/robots/{rid}/active-parameter-set");
    let patch = async |id: &str, body: Value| {
        app.raw(
            Method::PATCH,
            &format!("/v1/parameter-sets/{id}"),
            Some("application/json"),
            serde_json::to_vec(&body).unwrap(),
            &[],
        )
        .await
    };
    assert_eq!(app.put(&apath, &json!({"parameter_set_id": v1})).await.status, StatusCode::OK);

    // The active set is not archived; a reason is needed; an unknown set is 404.
    let r = patch(&v1, json!({"archived": true, "reason": "wrong tool mass"})).await;
    assert_problem(&r, 409, None);
    assert!(r.body["hint"].as_str().unwrap().contains("activate another set first"), "{}", r.text);
    assert_problem(&patch(&v2, json!({"archived": true})).await, 422, Some("reason"));
    assert_problem(&patch("none", json!({"archived": true, "reason": "x"})).await, 404, None);
    assert_problem(&patch(&v2, json!({"archived": false, "reason": "x"})).await, 409, None);

    // Once v2 is active, v1 — active before — is archived: hidden, not activated, still on record.
    assert_eq!(app.put(&apath, &json!({"parameter_set_id": v2})).await.status, StatusCode::OK);
    let r = patch(&v1, json!({"archived": true, "reason": "identified with the wrong tool mass"})).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert_eq!(r.body["archived"]["reason"], "identified with the wrong tool mass");
    assert_eq!(r.body["archived"]["by"], "metrologist");
    assert_eq!(r.body["active"], false);
    assert_problem(&patch(&v1, json!({"archived": true, "reason": "again"})).await, 409, None);
    let history = |q: &str| format!("/v1/robots/{rid}/parameter-sets{q}");
    let h = app.get(&history("")).await;
    let versions: Vec<i64> = h.body.as_array().unwrap().iter().map(|s| s["version"].as_i64().unwrap()).collect();
    assert_eq!((versions, h.headers["x-total-count"].to_str().unwrap()), (vec![2], "1"));
    let h = app.get(&history("?include_archived=true")).await;
    let versions: Vec<i64> = h.body.as_array().unwrap().iter().map(|s| s["version"].as_i64().unwrap()).collect();
    assert_eq!(versions, [2, 1]);
    assert!(h.body[0].get("archived").is_none() && h.body[1]["archived"]["at"].is_string());
    assert_problem(&app.get(&history("?include_archived=maybe")).await, 400, None);
    let r = app.put(&apath, &json!({"parameter_set_id": v1})).await;
    assert_problem(&r, 409, None);
    assert!(r.body["hint"].as_str().unwrap().contains("\"archived\": false"), "{}", r.text);
    assert_eq!(app.get(&format!("/v1/parameter-sets/{v1}")).await.status, StatusCode::OK, "still readable");
    assert_eq!(app.get(&format!("/v1/parameter-sets/{v1}/export")).await.status, StatusCode::OK);
    let acts = app.get(&format!("/v1/robots/{rid}/activations")).await;
    assert_eq!(acts.status, StatusCode::OK, "{}", acts.text);
    let seen: Vec<(i64, bool, bool)> = acts
        .body
        .as_array()
        .unwrap()
        .iter()
        .map(|a| (a["version"].as_i64().unwrap(), a["active"].as_bool().unwrap(), a["archived"].as_bool().unwrap()))
        .collect();
    assert_eq!(seen, [(2, true, false), (1, false, true)], "the archived set stays in the activation history");
    assert_eq!(acts.body[1]["activated_by"], "metrologist");
    assert!(acts.body[1]["activated_at"].is_string());

    // DELETE: 405 with what to do instead.
    let r = app.raw(Method::DELETE, &format!("/v1/parameter-sets/{v2}"), None, vec![], &[]).await;
    assert_problem(&r, 405, None);
    assert!(r.body["detail"].as_str().unwrap().contains("archived, not deleted"), "{}", r.text);
    assert!(r.body["hint"].as_str().unwrap().contains("\"archived\": true"), "{}", r.text);
    assert_eq!(r.headers["allow"], "GET, PATCH");
    assert_problem(&app.raw(Method::DELETE, "/v1/parameter-sets/none", None, vec![], &[]).await, 404, None);

    // Unarchived, it can be activated again; the audit timeline has both steps.
    let r = patch(&v1, json!({"archived": false, "reason": "the tool mass was right after all"})).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert!(r.body.get("archived").is_none());
    assert_eq!(app.put(&apath, &json!({"parameter_set_id": v1})).await.status, StatusCode::OK);
    let a = app.get(&format!("/v1/audit-events?subject_id={v1}")).await;
    let actions: Vec<&str> = a.body.as_array().unwrap().iter().map(|e| e["action"].as_str().unwrap()).collect();
    assert_eq!(actions, ["parameter_set_unarchived", "parameter_set_archived"]);
    assert_eq!(a.body[1]["actor"], "metrologist");
    app.stop().await;
}

/// A keyless re-upload of a batch the session already holds is refused (409) — as JSON or CSV —
/// with the batch it duplicates and how to resend; `allow_duplicate=true` appends it on purpose;
/// a keyed retry is still replayed.
#[tokio::test]
async fn a_keyless_duplicate_batch_is_refused() {
    let app = TestApp::new(ServiceConfig::default(), false).await;
    let rid = robot(&app, "r").await;
    let r = app
        .post(
            &format!("/v1/robots/{rid}/sessions"),
            &json!({"name": "s", "purpose": "validation", "instrument": "laser_tracker", "tool": {"tcp_mm": [0, 0, 0]}}),
        )
        .await;
    let sid = r.body["id"].as_str().unwrap().to_string();
    let mpath = format!("/v1/sessions/{sid}/measurements");
    let body = json!({"measurements": [
        {"joints_deg": [0, 10, 20, 0, 30, 0], "position_mm": [400, 0, 500]},
        {"joints_deg": [1, 10, 20, 0, 30, 0], "position_mm": [401, 7, 500]}]});
    let first = app.post(&mpath, &body).await;
    assert_eq!(first.status, StatusCode::CREATED, "{}", first.text);
    let batch = first.body["batch_id"].as_str().unwrap();

    let again = app.post(&mpath, &body).await;
    assert_problem(&again, 409, None);
    let detail = again.body["detail"].as_str().unwrap();
    assert!(detail.contains(batch) && detail.contains("appended") && detail.contains("measurements 0–1"), "{detail}");
    let hint = again.body["hint"].as_str().unwrap();
    assert!(hint.contains("Idempotency-Key") && hint.contains("allow_duplicate=true"), "{hint}");
    // The same measurements as CSV are the same batch.
    let csv = "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,x_mm,y_mm,z_mm\n0,10,20,0,30,0,400,0,500\n1,10,20,0,30,0,401,7,500\n";
    assert_problem(&app.raw(Method::POST, &mpath, Some("text/csv"), csv.as_bytes().to_vec(), &[]).await, 409, None);
    // A subset, or another reading, is not a duplicate.
    let one = json!({"measurements": [{"joints_deg": [0, 10, 20, 0, 30, 0], "position_mm": [400, 0, 500]}]});
    assert_eq!(app.post(&mpath, &one).await.status, StatusCode::CREATED);
    assert_eq!(app.get(&format!("/v1/sessions/{sid}")).await.body["measurements"], 3);
    // On purpose: appended again.
    let r = app.post(&format!("{mpath}?allow_duplicate=true"), &body).await;
    assert_eq!((r.status, r.body["first_index"].as_i64()), (StatusCode::CREATED, Some(3)), "{}", r.text);
    assert_problem(&app.post(&format!("{mpath}?allow_duplicate=perhaps"), &body).await, 400, None);
    // With a key the client says what a retry is: a new key appends, the same key replays.
    let key = [("idempotency-key", "day-2-batch-1")];
    let bytes = serde_json::to_vec(&body).unwrap();
    let k1 = app.raw(Method::POST, &mpath, Some("application/json"), bytes.clone(), &key).await;
    assert_eq!((k1.status, k1.body["first_index"].as_i64()), (StatusCode::CREATED, Some(5)), "{}", k1.text);
    let k2 = app.raw(Method::POST, &mpath, Some("application/json"), bytes, &key).await;
    assert_eq!(
        (k2.status, k2.headers.get("idempotency-replayed").map(|v| v.to_str().unwrap())),
        (StatusCode::CREATED, Some("true"))
    );
    assert_eq!(app.get(&format!("/v1/sessions/{sid}")).await.body["measurements"], 7);
    app.stop().await;
}

/// A parameter-set file whose quality a compensation could not compile is refused at import (422
/// naming the field), not stored: stored, every compensation with the set answered 500 (the
/// fuzzer, schemathesis 4.32.5: ST101 on `POST /v1/robots/{id}/compensate` naming such a set).
/// The same file with a well-formed quality is stored and compensates.
#[tokio::test]
async fn an_imported_set_that_a_compensation_cannot_compile_is_refused() {
    let app = TestApp::default().await;
    let rid = robot(&app, "uncompilable-set").await;
    let table =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/examples/irb120_table_5_1.json")).unwrap();
    let file: Value = serde_json::from_str(&table).unwrap();
    let with = |quality: Value| {
        let mut f = file.clone();
        f["quality"] = quality;
        f
    };
    let envelope = |lo: [f64; 3], hi: [f64; 3]| {
        json!({"joints_deg": [[-10, 10], [-10, 10], [-10, 10], [-10, 10], [-10, 10], [-10, 10]],
               "position_min_mm": lo, "position_max_mm": hi, "joint_margin_deg": 5, "position_margin_mm": 50,
               "n_measurements": 10})
    };
    for (quality, field) in [
        (json!({"free": [], "correlation": [[]]}), "quality.correlation"),
        (json!({"free": ["a2"], "correlation": [[1.0, 0.5]]}), "quality.correlation"),
        // Table 5.1's a2 carries no σ.
        (json!({"free": ["a2"], "correlation": [[1.0]]}), "parameters"),
        (json!({"envelope": envelope([500.0, 0.0, 0.0], [400.0, 10.0, 10.0])}), "quality.envelope.position_min_mm"),
    ] {
        let r = app.post(&format!("/v1/robots/{rid}/parameter-sets"), &with(quality.clone())).await;
        assert_problem(&r, 422, Some(field));
    }
    let r = app.get(&format!("/v1/robots/{rid}/parameter-sets")).await;
    assert_eq!(r.body.as_array().map(Vec::len), Some(0), "nothing stored: {}", r.text);

    let r = app
        .post(
            &format!("/v1/robots/{rid}/parameter-sets"),
            &with(json!({"free": [], "correlation": [], "envelope": envelope([0.0; 3], [400.0, 10.0, 10.0])})),
        )
        .await;
    assert_eq!(r.status, StatusCode::CREATED, "{}", r.text);
    let set = r.body["id"].as_str().unwrap();
    let r = app
        .post(
            &format!("/v1/robots/{rid}/compensate"),
            &json!({"parameter_set_id": set, "allow_unvalidated": true, "targets": [{"joints_deg": [1, 2, 3, 4, 5, 6]}]}),
        )
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
}

/// A set whose calibrated TCP is a reflector fitted on a plate declared at the flange: the
/// service compensates for it and says so in the answer's validity notes; given the controller's
/// tool, it compensates for that tool and the note goes.
#[tokio::test]
async fn a_calibrated_tcp_far_from_the_declared_one_is_noted_with_the_compensation() {
    let app = TestApp::default().await;
    let rid = robot(&app, "reflector-plate").await;
    let file = json!({"robot": {"preset": "irb120"}, "tool": {"tcp_mm": [0, 0, 0], "mass_kg": 1.0, "com_mm": [20, 0, 40]},
        "parameters": [{"name": "a2", "value": 270.146, "nominal": 270.0, "unit": "mm"},
                       {"name": "tool_x", "value": 19.6, "nominal": 0.0, "unit": "mm"},
                       {"name": "tool_y", "value": 86.7, "nominal": 0.0, "unit": "mm"},
                       {"name": "tool_z", "value": 40.2, "nominal": 0.0, "unit": "mm"}]});
    let r = app.post(&format!("/v1/robots/{rid}/parameter-sets"), &file).await;
    assert_eq!(r.status, StatusCode::CREATED, "{}", r.text);
    let set_id = r.body["id"].as_str().unwrap().to_string();
    let cpath = format!("/v1/robots/{rid}/compensate");
    let body = |tool: Option<Value>| {
        let mut b = json!({"targets": [{"joints_deg": [10, 20, -10, 5, 40, 0]}], "parameter_set_id": set_id,
                           "allow_unvalidated": true});
        if let Some(t) = tool {
            b["tool"] = t;
        }
        b
    };
    let noted = |r: &common::Res| {
        r.body["validity"]["notes"]
            .as_array()
            .unwrap()
            .iter()
            .any(|n| n.as_str().unwrap().contains("calibrated TCP lies"))
    };
    let r = app.post(&cpath, &body(None)).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert!(noted(&r), "{}", r.body["validity"]);
    assert!(r.body["validity"]["notes"].to_string().contains("the request's tool"), "{}", r.body["validity"]);
    let r = app.post(&cpath, &body(Some(json!({"tcp_mm": [0, 0, 0], "mass_kg": 1.0, "com_mm": [20, 0, 40]})))).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert!(!noted(&r), "{}", r.body["validity"]);
    let q: Vec<f64> =
        r.body["results"][0]["joints_deg"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    for (j, (a, b)) in q.iter().zip([10.0, 20.0, -10.0, 5.0, 40.0, 0.0]).enumerate() {
        assert!((a - b).abs() < 0.5, "joint {}: {a} for {b}", j + 1);
    }
}
