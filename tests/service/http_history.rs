//! The calibration history for dashboards (`GET /v1/robots/{id}/history`: a time series, paged,
//! filtered by date), the drift between two sets (`GET /v1/parameter-sets/{a}/drift?against=b`),
//! and the exports (`GET …/export?format=json|csv-dh|urdf`, `POST …/export?format=rapid`).

use crate::common;

use axum::http::{Method, StatusCode, header};
use common::{TestApp, assert_problem, robot};
use robocal::db::records;
use serde_json::{Value, json};

/// The Table 5.1 file with `a2`, `theta2` and `c5` given a value, a σ and the status
/// "identified" (so the drift has something to compare).
fn set_file(a2: f64, a2_std: f64, theta2: f64, theta2_std: f64, c5_identified: bool) -> Value {
    let table =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/examples/irb120_table_5_1.json")).unwrap();
    let mut v: Value = serde_json::from_str(&table).unwrap();
    for p in v["parameters"].as_array_mut().unwrap() {
        match p["name"].as_str().unwrap() {
            "a2" => {
                p["value"] = json!(a2);
                p["std"] = json!(a2_std);
                p["status"] = json!("identified");
            }
            "theta2" => {
                p["value"] = json!(theta2);
                p["std"] = json!(theta2_std);
                p["status"] = json!("identified");
            }
            "c5" if c5_identified => {
                p["std"] = json!(0.001);
                p["status"] = json!("identified");
            }
            _ => {}
        }
    }
    v
}

async fn import(app: &TestApp, rid: &str, file: &Value) -> String {
    let r = app.post(&format!("/v1/robots/{rid}/parameter-sets"), file).await;
    assert_eq!(r.status, StatusCode::CREATED, "{}", r.text);
    r.body["id"].as_str().unwrap().to_string()
}

async fn set_created(app: &TestApp, id: &str, at: &str) {
    sqlx::query("UPDATE parameter_sets SET created_at = $1 WHERE id = $2")
        .bind(at)
        .bind(id)
        .execute(&app.state.pool)
        .await
        .unwrap();
}

async fn validation(app: &TestApp, set: &str, at: &str, mean: f64, p95: f64, max: f64) -> String {
    let id = robocal::db::new_id();
    // A stored report names its sessions' purposes: a validation session the set (imported, its
    // fit unrecorded) was not fitted on makes it held out.
    let report = json!({"n": 120, "mean_mm": mean, "p95_mm": p95, "max_mm": max, "nominal": {"mean_mm": 1.234},
                        "purposes": ["validation"]});
    records::insert_validation(
        &app.state.pool,
        &records::ValidationRow {
            id: id.clone(),
            parameter_set_id: set.to_string(),
            sessions_json: json!(["tracker-n1"]).to_string(),
            report_json: report.to_string(),
            job_id: None,
            created_at: at.to_string(),
        },
    )
    .await
    .unwrap();
    id
}

#[tokio::test]
async fn the_history_is_a_paged_time_series_filtered_by_date() {
    let app = TestApp::new(Default::default(), false).await;
    let rid = robot(&app, "r1").await;
    let v1 = import(&app, &rid, &set_file(270.140, 0.004, -89.905, 0.010, false)).await;
    let v2 = import(&app, &rid, &set_file(270.146, 0.003, -89.910, 0.010, true)).await;
    let v3 = import(&app, &rid, &set_file(270.150, 0.003, -89.910, 0.010, true)).await;
    set_created(&app, &v1, "2026-01-01T10:00:00.000Z").await;
    set_created(&app, &v2, "2026-02-01T10:00:00.000Z").await;
    set_created(&app, &v3, "2026-03-01T10:00:00.000Z").await;
    // Two validations of v2: the history shows the latest.
    validation(&app, &v2, "2026-02-02T00:00:00.000Z", 0.30, 0.60, 0.90).await;
    let latest = validation(&app, &v2, "2026-02-03T00:00:00.000Z", 0.25, 0.50, 0.75).await;
    let diagnosis = robocal::db::new_id();
    records::insert_diagnosis(
        &app.state.pool,
        &records::DiagnosisRow {
            id: diagnosis.clone(),
            parameter_set_id: v2.clone(),
            request_json: "{}".into(),
            sessions_json: "[]".into(),
            report_json: json!({"verdict": {"status": "named", "summary": "cyclic error on joint 2"}}).to_string(),
            accepted_doc_json: None,
            accepted_parameter_set_id: None,
            job_id: None,
            created_at: "2026-02-04T00:00:00.000Z".into(),
        },
    )
    .await
    .unwrap();
    for id in [&v2, &v3] {
        let r = app.put(&format!("/v1/robots/{rid}/active-parameter-set"), &json!({"parameter_set_id": id})).await;
        assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    }

    let r = app.get(&format!("/v1/robots/{rid}/history")).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert_eq!(r.headers["x-total-count"], "3");
    let h = r.body.as_array().unwrap();
    let ids: Vec<&str> = h.iter().map(|e| e["parameter_set_id"].as_str().unwrap()).collect();
    assert_eq!(ids, [v1.as_str(), v2.as_str(), v3.as_str()], "oldest first");
    assert_eq!(h.iter().map(|e| e["version"].as_i64().unwrap()).collect::<Vec<_>>(), [1, 2, 3]);
    assert_eq!(h[0]["created_at"], "2026-01-01T10:00:00.000Z");
    assert_eq!((h[0]["active"].as_bool(), h[0]["was_active"].as_bool()), (Some(false), Some(false)));
    assert_eq!((h[1]["active"].as_bool(), h[1]["was_active"].as_bool()), (Some(false), Some(true)));
    assert_eq!((h[2]["active"].as_bool(), h[2]["was_active"].as_bool()), (Some(true), Some(true)));
    assert!(h[1]["first_activated_at"].is_string());
    assert!(h[0]["validation"].is_null() && h[0]["diagnosis"].is_null());
    let v = &h[1]["validation"];
    assert_eq!(v["validation_id"], latest.as_str());
    assert_eq!(
        (v["mean_mm"].as_f64(), v["p95_mm"].as_f64(), v["max_mm"].as_f64()),
        (Some(0.25), Some(0.5), Some(0.75))
    );
    assert_eq!(v["nominal_mean_mm"], 1.234);
    assert_eq!(v["sessions"], json!(["tracker-n1"]));
    assert_eq!(h[1]["diagnosis"]["verdict"], "named");
    assert_eq!(h[1]["diagnosis"]["diagnosis_id"], diagnosis.as_str());
    assert_eq!(h[1]["sessions"], json!([]));

    // The typed function behind the route gives the same series.
    let page = robocal::app::history::history(&app.state.pool, &rid, &Default::default()).await.unwrap();
    assert_eq!(page.total, 3);
    assert_eq!(serde_json::to_value(&page.entries).unwrap(), r.body);

    // Dates: `from` inclusive, `to` exclusive, offsets read as UTC.
    let dated = async |q: &str| app.get(&format!("/v1/robots/{rid}/history?{q}")).await;
    let r = dated("from=2026-01-15&to=2026-03-01T10:00:00.000Z").await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert_eq!(r.headers["x-total-count"], "1");
    assert_eq!(r.body[0]["parameter_set_id"], v2.as_str());
    let r = dated("from=2026-02-01T05:00:00-05:00").await; // 10:00 UTC: v2 included
    assert_eq!(r.body.as_array().unwrap().len(), 2, "{}", r.text);
    let r = dated("from=2026-02-01T05:00:01-05:00").await;
    assert_eq!(r.body.as_array().unwrap().len(), 1, "{}", r.text);
    let r = dated("to=2026-02-01T11:00:00%2B02:00").await; // 09:00 UTC: v1 only
    assert_eq!(r.body.as_array().unwrap().len(), 1, "{}", r.text);

    // Paged like every list; the links keep the filter.
    let r = dated("from=2026-01-01&limit=2").await;
    assert_eq!(r.headers["x-total-count"], "3");
    assert_eq!(r.body.as_array().unwrap().len(), 2);
    let link = r.headers[header::LINK].to_str().unwrap();
    assert!(
        link.contains(&format!("/v1/robots/{rid}/history?from=2026-01-01&offset=2&limit=2>; rel=\"next\"")),
        "{link}"
    );
    let r = dated("from=2026-01-01&offset=2&limit=2").await;
    assert_eq!(r.body.as_array().unwrap().len(), 1);
    assert_eq!(r.body[0]["version"], 3);

    // Bad input names the field.
    assert_problem(&dated("from=yesterday").await, 422, Some("from"));
    assert_problem(&dated("to=2026-02-30").await, 422, Some("to"));
    assert_problem(&dated("from=2026-02-01T10:00:00").await, 422, Some("from"));
    assert_problem(&dated("from=").await, 422, Some("from"));
    // A to before from is an empty range; a year before 1970 (when nothing was stored) the start.
    let r = dated("from=2026-03-01&to=2026-01-01").await;
    assert_eq!((r.status, r.body.clone()), (StatusCode::OK, json!([])), "{}", r.text);
    assert_eq!(r.headers["x-total-count"], "0");
    let r = dated("from=0001-01-01&to=2026-02-01T11:00:00%2B02:00").await;
    assert_eq!(r.body.as_array().unwrap().len(), 1, "{}", r.text);
    assert_problem(&dated("limit=0").await, 422, Some("limit"));
    assert_problem(&app.get("/v1/robots/nope/history").await, 404, None);

    // An archived set leaves the series unless asked for.
    let r = app
        .raw(
            Method::PATCH,
            &format!("/v1/parameter-sets/{v1}"),
            Some("application/json"),
            serde_json::to_vec(&json!({"archived": true, "reason": "wrong tool mass"})).unwrap(),
            &[],
        )
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    let r = dated("").await;
    assert_eq!(r.headers["x-total-count"], "2");
    let r = dated("include_archived=true").await;
    assert_eq!(r.headers["x-total-count"], "3");
    assert_eq!(r.body[0]["archived"], true);

    // The history page plots the same series: one plot, a row per set, the validated figures.
    let r = app.get(&format!("/v1/robots/{rid}/history/report?include_archived=true")).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert!(r.headers["content-type"].to_str().unwrap().starts_with("text/html"));
    assert_eq!(r.text.matches("<svg").count(), 1);
    assert_eq!(r.text.matches("<tr>").count(), 4, "a header and three sets");
    assert!(r.text.contains("0.2500") && r.text.contains("named"), "{}", r.text);
    let r = app
        .raw(
            Method::GET,
            &format!("/v1/robots/{rid}/history/report"),
            None,
            Vec::new(),
            &[("accept", "application/json")],
        )
        .await;
    assert_problem(&r, 406, None);
    assert_problem(&app.get(&format!("/v1/robots/{rid}/history/report?from=yesterday")).await, 422, Some("from"));
    app.stop().await;
}

#[tokio::test]
async fn drift_between_two_sets() {
    let app = TestApp::new(Default::default(), false).await;
    let rid = robot(&app, "r1").await;
    let other = robot(&app, "r2").await;
    let b = import(&app, &rid, &set_file(270.140, 0.004, -89.905, 0.010, false)).await;
    let a = import(&app, &rid, &set_file(270.146, 0.003, -89.910, 0.010, true)).await;
    let foreign = import(&app, &other, &set_file(270.146, 0.003, -89.910, 0.010, true)).await;
    let r = app.get(&format!("/v1/parameter-sets/{a}/drift?against={b}")).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert_eq!(r.body["parameter_set"]["version"], 2);
    assert_eq!(r.body["against"]["parameter_set_id"], b.as_str());
    let d = &r.body["drift"];
    let params = d["parameters"].as_array().unwrap();
    assert_eq!(params.len(), 2, "{}", r.text);
    // By hand: a2 moved 270.146 − 270.140 = 0.006 mm against √(0.003² + 0.004²) = 0.005 mm: 1.2σ.
    let a2 = params.iter().find(|p| p["name"] == "a2").unwrap();
    assert_eq!(a2["unit"], "mm");
    assert!((a2["change"].as_f64().unwrap() - 0.006).abs() < 1e-9, "{a2}");
    assert!((a2["combined_std"].as_f64().unwrap() - 0.005).abs() < 1e-12);
    assert!((a2["n_sigma"].as_f64().unwrap() - 1.2).abs() < 1e-6);
    assert_eq!(a2["moved"], true);
    // theta2: −0.005 deg against √2·0.010 deg: 0.35σ, not moved.
    let t2 = params.iter().find(|p| p["name"] == "theta2").unwrap();
    assert!((t2["change"].as_f64().unwrap() + 0.005).abs() < 1e-9);
    assert_eq!(t2["moved"], false);
    assert_eq!(d["moved"], 1);
    assert_eq!(d["only_in_a"], json!(["c5"]));
    assert_eq!(d["only_in_b"], json!([]));

    assert_problem(&app.get(&format!("/v1/parameter-sets/{a}/drift")).await, 422, Some("against"));
    assert_problem(&app.get(&format!("/v1/parameter-sets/{a}/drift?against=nope")).await, 404, Some("against"));
    assert_problem(&app.get(&format!("/v1/parameter-sets/{a}/drift?against={foreign}")).await, 404, Some("against"));
    assert_problem(&app.get(&format!("/v1/parameter-sets/nope/drift?against={b}")).await, 404, None);
    app.stop().await;
}

#[tokio::test]
async fn exports_in_every_format() {
    let app = TestApp::new(Default::default(), false).await;
    let rid = robot(&app, "r1").await;
    let set = import(&app, &rid, &set_file(270.146, 0.003, -89.910, 0.010, true)).await;
    let get = async |q: &str| app.get(&format!("/v1/parameter-sets/{set}/export{q}")).await;

    let json_file = get("").await;
    assert_eq!(json_file.status, StatusCode::OK);
    assert_eq!(json_file.headers[header::CONTENT_TYPE], "application/json");
    assert_eq!(json_file.headers[header::CONTENT_DISPOSITION], "attachment; filename=\"parameter-set-v1.json\"");
    assert_eq!(get("?format=json").await.text, json_file.text);
    let doc = robocal::domain::ParameterSetDoc::from_json(&json_file.text).unwrap();

    let csv = get("?format=csv-dh").await;
    assert_eq!(csv.status, StatusCode::OK, "{}", csv.text);
    assert!(csv.headers[header::CONTENT_TYPE].to_str().unwrap().starts_with("text/csv"));
    assert_eq!(csv.headers[header::CONTENT_DISPOSITION], "attachment; filename=\"parameter-set-v1.csv\"");
    assert!(
        csv.text.starts_with(&format!(
            "# robocal calibrated kinematic model: robot irb120, parameter set {set}, version 1"
        ))
    );
    let row = csv.text.lines().find(|l| l.starts_with("joint3,")).unwrap();
    let a_mm: f64 = row.split(',').nth(2).unwrap().parse().unwrap();
    assert!((a_mm - 270.146).abs() < 1e-12, "{row}");
    let a_std: f64 = row.split(',').nth(14).unwrap().parse().unwrap();
    assert!((a_std - 0.003).abs() < 1e-15, "{row}");

    let u = get("?format=urdf").await;
    assert_eq!(u.status, StatusCode::OK, "{}", u.text);
    assert_eq!(u.headers[header::CONTENT_TYPE], "application/xml");
    assert_eq!(u.headers[header::CONTENT_DISPOSITION], "attachment; filename=\"parameter-set-v1.urdf\"");
    let parsed = urdf_rs::read_from_string(&u.text).unwrap();
    assert_eq!(parsed.joints.len(), 8);
    assert!(u.text.contains("GEOMETRY ONLY"));

    assert_problem(&get("?format=step").await, 422, Some("format"));
    assert_problem(&get("?format=rapid").await, 422, Some("format"));
    assert_problem(&app.get("/v1/parameter-sets/nope/export?format=urdf").await, 404, None);

    // RAPID: the targets compensated as the compensation route does them.
    let targets = json!([
        {"id": "pick-1", "position_mm": [0, 0, 60], "rotation_deg": [0, 180, 0], "cfx": 0},
        {"id": "home", "joints_deg": [0, 0, 0, 0, 30, 0]}]);
    let post = async |q: &str, body: Value| app.post(&format!("/v1/parameter-sets/{set}/export{q}"), &body).await;
    // An imported set has no validation: refused as compensation refuses it, unless asked for.
    assert_problem(&post("?format=rapid", json!({"targets": targets})).await, 409, None);
    let m = post("?format=rapid", json!({"targets": targets, "allow_unvalidated": true})).await;
    assert_eq!(m.status, StatusCode::OK, "{}", m.text);
    assert_eq!(m.headers[header::CONTENT_TYPE], "text/plain; charset=utf-8");
    assert_eq!(m.headers[header::CONTENT_DISPOSITION], "attachment; filename=\"targets-v1.mod\"");
    assert_eq!(m.headers["x-failed-targets"], "0");
    assert!(m.text.starts_with("MODULE robocal_v1\n") && m.text.trim_end().ends_with("ENDMODULE"), "{}", m.text);
    let c = app
        .post(
            &format!("/v1/robots/{rid}/compensate"),
            &json!({"parameter_set_id": set, "targets": targets, "allow_unvalidated": true}),
        )
        .await;
    assert_eq!(c.status, StatusCode::OK, "{}", c.text);
    for (name, result) in [("pick_1", &c.body["results"][0]), ("home", &c.body["results"][1])] {
        let line = m.text.lines().find(|l| l.contains(&format!("jointtarget j_{name}:="))).unwrap();
        let inner = line.split(":=[[").nth(1).unwrap().split(']').next().unwrap();
        let joints: Vec<f64> = inner.split(',').map(|v| v.parse().unwrap()).collect();
        let expected: Vec<f64> = result["joints_deg"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        assert_eq!(joints, expected, "{name}");
        let line = m.text.lines().find(|l| l.contains(&format!("robtarget p_{name}:="))).unwrap();
        let pos = line.split(":=[[").nth(1).unwrap().split(']').next().unwrap();
        let pos: Vec<f64> = pos.split(',').map(|v| v.parse().unwrap()).collect();
        let expected: Vec<f64> =
            result["fake_pose"]["position_mm"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        assert_eq!(pos, expected, "{name}");
    }
    // The header names the set (comment lines wrap at about 100 characters) and the frame.
    assert!(
        m.text.contains(set.as_str()) && m.text.contains("version 1") && m.text.contains("frame: world"),
        "{}",
        m.text
    );

    // A target out of reach: 422 naming it, unless allow_partial.
    let with_bad = json!({"targets": [targets[0], {"id": "far", "position_mm": [3000, 0, 60], "rotation_deg": [0, 180, 0], "cfx": 0}],
        "allow_unvalidated": true});
    assert_problem(&post("?format=rapid", with_bad.clone()).await, 422, Some("targets[1]"));
    let m = post("?format=rapid&allow_partial=true", with_bad).await;
    assert_eq!(m.status, StatusCode::OK, "{}", m.text);
    assert_eq!(m.headers["x-failed-targets"], "1");
    assert!(m.text.contains("targets[1] 'far'") && !m.text.contains("j_far"), "{}", m.text);
    assert_problem(&post("?format=urdf", json!({"targets": targets})).await, 422, Some("format"));
    assert_problem(&post("?format=rapid", json!({"targets": targets, "parameter_set_id": set})).await, 422, None);
    assert_eq!(doc.set.dof(), 6);
    app.stop().await;
}
