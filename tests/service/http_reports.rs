//! The HTML reports on the service (issue 15), on the real router with job workers: a virtual
//! cell is identified, validated and diagnosed, and each stored result's report is a
//! self-contained page with the plots its data call for — the same page, byte for byte, that
//! `robocal identify|validate --report` writes from the service's exported files. JSON-only
//! clients get 406; unknown ids 404; a token without `read` 403.

use crate::common;

use axum::http::{StatusCode, header};
use common::{Res, TestApp, artefact, assert_problem, robot, upload};
use robocal::domain::cell::CellFile;
use robocal::http::ServiceConfig;
use robocal::sim::simulate::{SimulateOptions, simulate};
use serde_json::{Value, json};

fn small_cell(seed: u64) -> CellFile {
    let s = simulate(&SimulateOptions { seed, id_per_ball: 30, validation: 60, ..Default::default() }).unwrap();
    CellFile::from_cell(&s.cell)
}

async fn get_html(app: &TestApp, path: &str) -> Res {
    let r = app.raw(axum::http::Method::GET, path, None, Vec::new(), &[("accept", "text/html,*/*;q=0.8")]).await;
    assert_eq!(r.status, StatusCode::OK, "{path}: {}", r.text);
    assert_eq!(r.headers[header::CONTENT_TYPE], "text/html; charset=utf-8");
    self_contained(&r.text);
    r
}

fn self_contained(html: &str) {
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert!(!html.contains("<script") && !html.contains("http") && !html.contains("src="), "fetches or runs something");
    assert!(!html.contains("plot not drawn"));
}

fn svgs(html: &str) -> usize {
    html.matches("<svg").count()
}

/// Units among the parameters that carry a σ: one error-bar plot each.
fn units_with_sigma(set: &Value) -> usize {
    let mut units: Vec<&str> = set["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| p["std"].is_number() && p["nominal"].is_number())
        .map(|p| p["unit"].as_str().unwrap_or(""))
        .collect();
    units.sort();
    units.dedup();
    units.len()
}

fn cli(args: &[&std::ffi::OsStr]) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_robocal")).args(args).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

#[tokio::test]
async fn identification_validation_and_diagnosis_reports() {
    let app = TestApp::default().await;
    let rid = robot(&app, "cell").await;
    let aid = artefact(&app, "plate").await;
    upload(&app, &rid, &aid, &small_cell(3)).await;

    let j = app
        .wait(&app.post(&format!("/v1/robots/{rid}/identifications"), &json!({"sessions": ["trical-1"]})).await.body)
        .await;
    assert_eq!(j["state"], "succeeded", "{j}");
    let set_id = j["result"]["parameter_set_id"].as_str().unwrap().to_string();
    let export = app.get(&format!("/v1/parameter-sets/{set_id}/export")).await;
    let set: Value = serde_json::from_str(&export.text).unwrap();
    let groups = units_with_sigma(&set);
    assert!(groups >= 2, "mm and deg parameters were identified");

    // The identification's report before any validation.
    let path = format!("/v1/parameter-sets/{set_id}/report");
    let before = get_html(&app, &path).await;
    assert_eq!(svgs(&before.text), groups);
    assert!(before.text.contains("No validation of this parameter set yet."));
    let kappa = set["quality"]["kappa_si"].as_f64().unwrap();
    assert!(before.text.contains(&format!("{kappa:.1}")), "κ {kappa}");
    // Content negotiation: HTML unless the client accepts JSON only.
    let r = app.raw(axum::http::Method::GET, &path, None, vec![], &[("accept", "application/json")]).await;
    assert_eq!(r.status, StatusCode::NOT_ACCEPTABLE);
    assert_eq!(r.headers[header::CONTENT_TYPE], "application/problem+json");
    assert_eq!(r.body["status"], 406);
    let r = app.get(&path).await;
    assert_eq!(r.status, StatusCode::OK, "no Accept: HTML");
    assert_eq!(r.text, before.text);

    // The CLI writes the same page from the same files.
    let exported = app.get(&format!("/v1/robots/{rid}/cell?sessions=trical-1,tracker-n1,tracker-n2,tracker-n3")).await;
    assert_eq!(exported.status, StatusCode::OK, "{}", exported.text);
    let dir = &app.dir;
    let (cell_path, set_path) = (dir.join("cell.json"), dir.join("set.json"));
    std::fs::write(&cell_path, &exported.text).unwrap();
    std::fs::write(&set_path, &export.text).unwrap();
    let id_cell = dir.join("id_cell.json");
    std::fs::write(&id_cell, &app.get(&format!("/v1/robots/{rid}/cell?sessions=trical-1")).await.text).unwrap();
    let (id_out, id_report) = (dir.join("id.json"), dir.join("id.html"));
    cli(&[
        "identify".as_ref(),
        id_cell.as_os_str(),
        "--sessions".as_ref(),
        "trical-1".as_ref(),
        "--out".as_ref(),
        id_out.as_os_str(),
        "--report".as_ref(),
        id_report.as_os_str(),
    ]);
    // The same page but for the one line saying where the set comes from (the service names
    // its stored set, version and date; the command line its files).
    let source =
        |t: &str| t.lines().filter(|l| !l.starts_with("<p class=\"meta source\">")).collect::<Vec<_>>().join("\n");
    let cli_page = std::fs::read_to_string(&id_report).unwrap();
    assert_eq!(source(&cli_page), source(&before.text), "the CLI's identification report is the service's");
    assert!(before.text.contains(&format!("Parameter set {set_id}, version 1; made ")), "date and set id");
    assert!(before.text.contains("from sessions trical-1 of robot cell."), "the input");
    assert!(cli_page.contains("from sessions trical-1 of cell file "), "the CLI names its input file");

    // The validation's report: histogram, CDF, Q–Q, per-axis grid, two regressions, projections.
    let r = app
        .post(
            &format!("/v1/parameter-sets/{set_id}/validations"),
            &json!({"sessions": ["tracker-n1", "tracker-n2", "tracker-n3"]}),
        )
        .await;
    let j = app.wait(&r.body).await;
    assert_eq!(j["state"], "succeeded", "{j}");
    let vid = j["result"]["validation_id"].as_str().unwrap().to_string();
    let v = get_html(&app, &format!("/v1/validations/{vid}/report")).await;
    assert_eq!(svgs(&v.text), 10);
    let stored = app.get(&format!("/v1/validations/{vid}")).await.body;
    let mean = stored["report"]["mean_mm"].as_f64().unwrap();
    let nominal = stored["report"]["nominal"]["mean_mm"].as_f64().unwrap();
    assert!(
        v.text.contains(&format!("<td>mean |e|</td><td class=\"n\">{nominal:.3}</td><td class=\"n\">{mean:.3}</td>"))
    );
    let v_report = dir.join("v.html");
    cli(&[
        "validate".as_ref(),
        set_path.as_os_str(),
        cell_path.as_os_str(),
        "--session".as_ref(),
        "tracker-n1".as_ref(),
        "--session".as_ref(),
        "tracker-n2".as_ref(),
        "--session".as_ref(),
        "tracker-n3".as_ref(),
        "--json".as_ref(),
        "--report".as_ref(),
        v_report.as_os_str(),
    ]);
    assert_eq!(std::fs::read_to_string(&v_report).unwrap(), v.text, "the CLI's validation report is the service's");

    // The identification's report now ends with its validation.
    let after = get_html(&app, &path).await;
    assert_eq!(svgs(&after.text), groups + 10);
    assert!(after.text.contains("Latest validation"));

    // The diagnosis's report: the decomposition bar and the residual profiles.
    let r = app.post(&format!("/v1/parameter-sets/{set_id}/diagnoses"), &json!({})).await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", r.text);
    let j = app.wait(&r.body).await;
    assert_eq!(j["state"], "succeeded", "{j}");
    let did = j["result"]["diagnosis_id"].as_str().unwrap().to_string();
    let d = get_html(&app, &format!("/v1/diagnoses/{did}/report")).await;
    let stored = app.get(&format!("/v1/diagnoses/{did}")).await.body;
    let summary = stored["report"]["verdict"]["summary"].as_str().unwrap();
    assert!(d.text.contains(&robocal::report::html::esc(summary)), "the verdict");
    let profiles = stored["report"]["where"]["against"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|a| a["profile"].as_array().unwrap().len() >= 2)
        .count();
    assert_eq!(svgs(&d.text), 1 + usize::from(profiles > 0));
    assert!(d.text.contains("Decomposition of the error") && d.text.contains("How far the error shrinks"));

    // A validation stored by a version before held out was recorded (8de8956, 2026-11-27): no
    // `held_out`, `fit`, `in_sample_sessions`, `held_out_statement`, `uncertainty`, nor each
    // session's `fitted` and `fitted_measurements`. Its page is today's without the statement.
    let mut report = app.get(&format!("/v1/validations/{vid}")).await.body["report"].clone();
    let statement = report["held_out_statement"].as_str().unwrap().to_string();
    for k in ["held_out", "fit", "in_sample_sessions", "held_out_statement", "uncertainty"] {
        report.as_object_mut().unwrap().remove(k);
    }
    for s in report["per_session"].as_array_mut().unwrap() {
        s.as_object_mut().unwrap().retain(|k, _| k != "fitted" && k != "fitted_measurements");
    }
    let set_page = get_html(&app, &path).await.text;
    let old = robocal::db::records::ValidationRow {
        id: "v-stored-2026-11-25".into(),
        parameter_set_id: set_id.clone(),
        sessions_json: json!(["tracker-n1", "tracker-n2", "tracker-n3"]).to_string(),
        report_json: report.to_string(),
        job_id: None,
        created_at: "2026-11-25T12:00:00.000Z".into(),
    };
    robocal::db::records::insert_validation(&app.state.pool, &old).await.unwrap();
    let o = get_html(&app, "/v1/validations/v-stored-2026-11-25/report").await;
    assert_eq!(svgs(&o.text), 10);
    let said = v.text.find(&robocal::report::html::esc(&statement[1..])).expect("today's page states it");
    let (from, to) = (v.text[..said].rfind("<p class=").unwrap(), said + v.text[said..].find("</p>").unwrap() + 4);
    assert_eq!(o.text, format!("{}{}", &v.text[..from], &v.text[to..]), "today's page but for the statement");
    // The set's report still shows its latest validation, today's.
    assert_eq!(get_html(&app, &path).await.text, set_page);

    // Unknown ids.
    for p in ["/v1/validations/none/report", "/v1/parameter-sets/none/report", "/v1/diagnoses/none/report"] {
        assert_problem(&app.get(p).await, 404, None);
    }
    app.stop().await;
}

#[tokio::test]
async fn reports_need_the_read_scope() {
    let mut app = TestApp::new(ServiceConfig { require_auth: true, ..Default::default() }, false).await;
    assert_problem(&app.get("/v1/validations/x/report").await, 401, None);
    let (_, measure) =
        robocal::db::tokens::create(&app.state.pool, "m", &[robocal::db::tokens::Scope::Measure]).await.unwrap();
    app.token = Some(measure);
    for p in ["/v1/validations/x/report", "/v1/parameter-sets/x/report", "/v1/diagnoses/x/report"] {
        assert_problem(&app.get(p).await, 403, None);
    }
    let (_, read) =
        robocal::db::tokens::create(&app.state.pool, "r", &[robocal::db::tokens::Scope::Read]).await.unwrap();
    app.token = Some(read);
    assert_problem(&app.get("/v1/diagnoses/x/report").await, 404, None);
    app.stop().await;
}
