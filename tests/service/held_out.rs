//! Held out means held out (issue 25, item 1): a validation records which of its sessions and
//! measurements the parameter set was fitted on, says whether it is held out, and only a held-out
//! validation unlocks compensation — on the command line (`validate`, `compensate --validation`)
//! and on the service (the validation job, the compensation gate, the set and history answers).

use crate::common;

use std::process::Command;

use axum::http::StatusCode;
use common::{TestApp, artefact, assert_problem, robot, upload};
use robocal::domain::cell::CellFile;
use robocal::sim::simulate::{SimulateOptions, simulate};
use serde_json::{Value, json};

fn robocal(args: &[&str]) -> (i32, Value, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_robocal")).args(args).output().expect("runs");
    let stdout = String::from_utf8(out.stdout).unwrap();
    let v = serde_json::from_str(&stdout).unwrap_or(Value::Null);
    (out.status.code().unwrap(), v, String::from_utf8(out.stderr).unwrap())
}

fn dir() -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("robocal-held-out-{}-{}", std::process::id(), robocal::db::new_id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A small virtual cell: 40 TriCal candidates per ball, 150 tracker poses (three sessions).
fn small_cell(seed: u64) -> CellFile {
    let s = simulate(&SimulateOptions { seed, id_per_ball: 40, validation: 150, ..Default::default() }).unwrap();
    CellFile::from_cell(&s.cell)
}

#[test]
fn the_command_line_tells_held_out_from_in_sample_by_session_and_measurement() {
    let d = dir();
    let p = |n: &str| d.join(n).display().to_string();
    std::fs::write(p("cell.json"), serde_json::to_string(&small_cell(5)).unwrap()).unwrap();
    // A set fitted on the TriCal session and on one tracker session.
    let (code, _, err) =
        robocal(&["identify", &p("cell.json"), "--sessions", "trical-1,tracker-n1", "--out", &p("pooled.json")]);
    assert_eq!(code, 0, "{err}");
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(p("pooled.json")).unwrap()).unwrap();
    assert_eq!(doc["quality"]["sessions"], json!(["trical-1", "tracker-n1"]));
    let fitted = doc["quality"]["fit_measurements"].as_array().unwrap();
    assert_eq!(fitted.len(), 2);
    assert_eq!(fitted[1]["session"], "tracker-n1");
    let n1 = fitted[1]["indices"].as_array().unwrap().len();
    assert!(n1 > 10, "{n1}");

    // On the session it was fitted on: in-sample, said so, every measurement counted.
    let (code, v, err) =
        robocal(&["validate", &p("pooled.json"), &p("cell.json"), "--session", "tracker-n1", "--json"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(v["held_out"], false, "{v}");
    assert_eq!(v["in_sample_sessions"], json!(["tracker-n1"]));
    assert_eq!(v["fit"], json!({"recorded": true, "sessions": ["trical-1", "tracker-n1"]}));
    assert_eq!(v["per_session"][0]["fitted"], true);
    assert_eq!(v["per_session"][0]["fitted_measurements"], n1);
    assert_eq!(v["n"], n1, "all of tracker-n1 was fitted");
    let why = v["held_out_statement"].as_str().unwrap();
    assert!(why.starts_with("in-sample") && why.contains("tracker-n1") && why.contains(&format!("{n1} of")), "{why}");
    assert!(v.get("validated_envelope").is_none() && v.get("uncertainty").is_none(), "{v}");
    std::fs::write(p("in_sample.json"), v.to_string()).unwrap();
    // Mixed with a session it was not fitted on: still not held out (not disjoint).
    let (_, v, _) = robocal(&[
        "validate",
        &p("pooled.json"),
        &p("cell.json"),
        "--session",
        "tracker-n1",
        "--session",
        "tracker-n2",
        "--json",
    ]);
    assert_eq!(v["held_out"], false);
    assert_eq!(v["per_session"][1]["fitted"], false);
    assert_eq!(v["per_session"][1]["fitted_measurements"], 0);
    // On the others alone: held out, with its uncertainty model.
    let (code, v, err) = robocal(&[
        "validate",
        &p("pooled.json"),
        &p("cell.json"),
        "--session",
        "tracker-n2",
        "--session",
        "tracker-n3",
        "--json",
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(v["held_out"], true, "{v}");
    assert!(
        v["held_out_statement"].as_str().unwrap().starts_with("held out: the set was fitted on trical-1, tracker-n1")
    );
    assert!(v["validated_envelope"].is_object() && v["uncertainty"]["unexplained_mm"].is_f64(), "{v}");
    std::fs::write(p("held_out.json"), v.to_string()).unwrap();
    // The text form says it on its second line.
    let out = Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["validate", &p("pooled.json"), &p("cell.json"), "--session", "tracker-n1", "--format", "text"])
        .output()
        .unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.lines().nth(1).unwrap().starts_with("in-sample, not held out"), "{text}");

    // A DETMAX subset: the TriCal measurements it did not select are not in the fit, and the
    // validation counts exactly the selected ones.
    let (code, _, err) = robocal(&[
        "identify",
        &p("cell.json"),
        "--sessions",
        "trical-1",
        "--select",
        "detmax",
        "--n",
        "40",
        "--out",
        &p("detmax.json"),
    ]);
    assert_eq!(code, 0, "{err}");
    let (_, v, _) = robocal(&["validate", &p("detmax.json"), &p("cell.json"), "--session", "trical-1", "--json"]);
    assert_eq!(v["per_session"][0]["fitted_measurements"], 40, "{}", v["per_session"][0]);
    assert!(v["n"].as_u64().unwrap() > 100);
    assert_eq!(v["held_out"], false);

    // Compensation trusts a held-out validation's uncertainty, and refuses an in-sample one.
    std::fs::write(
        p("targets.json"),
        json!({"targets": [{"id": "t", "joints_deg": [5, 10, 5, 0, 40, 0]}]}).to_string(),
    )
    .unwrap();
    let base =
        ["compensate", "--params", &p("pooled.json"), "--targets", &p("targets.json"), "--allow-outside-envelope"];
    let (code, _, err) = robocal(&[&base[..], &["--validation", &p("in_sample.json")]].concat());
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("held_out: not a held-out validation: in-sample"), "{err}");
    let (code, c, err) = robocal(&[&base[..], &["--validation", &p("held_out.json")]].concat());
    assert_eq!(code, 0, "{err}");
    let r = &c["results"][0];
    assert!(r["uncertainty_mm"].as_f64().unwrap() > 0.0, "{c}");
    assert!(r["uncertainty"]["unexplained_mm"].is_f64() && r["uncertainty"]["bound_95_mm"].is_f64(), "{r}");
    let _ = std::fs::remove_dir_all(&d);
}

/// On the service: a set whose file records that it was fitted on a validation session (a set
/// identified elsewhere from TriCal and tracker data, imported) is validated in-sample on that
/// session and held out on the others; the answers say which, and the compensation gate counts
/// only the held-out one.
#[tokio::test]
async fn the_service_counts_only_held_out_validations() {
    let app = TestApp::default().await;
    let cell = small_cell(6);
    let rid = robot(&app, "held-out").await;
    let aid = artefact(&app, "held-out-plate").await;
    upload(&app, &rid, &aid, &cell).await;
    // Identify from the TriCal and one tracker session as the command line would, and import it.
    let c = robocal::domain::cell::parse_cell(&serde_json::to_string(&cell).unwrap()).unwrap();
    let opts = robocal::identify::IdentifyOptions {
        selection: robocal::identify::MeasurementSelection {
            sessions: vec!["trical-1".into(), "tracker-n1".into()],
            ..Default::default()
        },
        ..Default::default()
    };
    let (_, doc) = robocal::domain::identification::run_identification(&c, opts, None, &|| ()).unwrap();
    let file: Value = serde_json::from_str(&doc.to_json_pretty()).unwrap();
    let r = app.post(&format!("/v1/robots/{rid}/parameter-sets"), &file).await;
    assert_eq!(r.status, StatusCode::CREATED, "{}", r.text);
    let set = r.body["id"].as_str().unwrap().to_string();
    assert_eq!(r.body["sessions"], json!([]), "imported: the store lists no session");
    assert_eq!(r.body["fit_sessions"], json!(["trical-1", "tracker-n1"]), "but its file records them");
    let needed = r.body["validation_needed"].as_str().unwrap();
    assert!(
        needed.contains("tracker-n1: a validation on them is in-sample") && needed.contains("tracker-n2"),
        "{needed}"
    );

    let validate = |sessions: Value| {
        let app = &app;
        let set = set.clone();
        async move {
            let r = app.post(&format!("/v1/parameter-sets/{set}/validations"), &json!({"sessions": sessions})).await;
            assert_eq!(r.status, StatusCode::ACCEPTED, "{}", r.text);
            let j = app.wait(&r.body).await;
            assert_eq!(j["state"], "succeeded", "{j}");
            j
        }
    };
    // In-sample: the job's summary and the stored report say so.
    let j = validate(json!(["tracker-n1"])).await;
    assert_eq!(j["result"]["summary"]["held_out"], false, "{j}");
    assert!(j["result"]["summary"]["held_out_statement"].as_str().unwrap().starts_with("in-sample"));
    let vid = j["result"]["validation_id"].as_str().unwrap();
    let v = app.get(&format!("/v1/validations/{vid}")).await.body;
    assert_eq!(v["report"]["held_out"], false);
    assert_eq!(v["report"]["in_sample_sessions"], json!(["tracker-n1"]));
    let n1 = cell.sessions.iter().find(|s| s.name == "tracker-n1").unwrap().measurements.len();
    assert_eq!(v["report"]["per_session"][0]["fitted_measurements"], n1);

    // The gate: in-sample does not count.
    let cpath = format!("/v1/robots/{rid}/compensate");
    let count = |name: &str| cell.sessions.iter().find(|s| s.name == name).unwrap().measurements.len();
    // A pose the held-out validation measured: inside every envelope.
    let q = &cell.sessions.iter().find(|s| s.name == "tracker-n2").unwrap().measurements[0].joints_deg;
    let target = json!([{"joints_deg": q}]);
    let r = app.post(&cpath, &json!({"parameter_set_id": set, "targets": target})).await;
    assert_problem(&r, 409, None);
    let detail = r.body["detail"].as_str().unwrap();
    assert!(detail.contains("no held-out validation") && detail.contains("fitted on trical-1, tracker-n1"), "{detail}");
    // The history shows the in-sample figure apart, not as the set's validation.
    let h = app.get(&format!("/v1/robots/{rid}/history")).await.body;
    assert!(h[0]["validation"].is_null(), "{h}");
    assert_eq!(h[0]["in_sample"]["validation_id"], vid);
    assert_eq!(h[0]["in_sample"]["held_out"], false);
    assert_eq!(h[0]["fit_sessions"], json!(["trical-1", "tracker-n1"]));

    // Held out: counted, named in the answer, and the history shows it as the validation.
    let j = validate(json!(["tracker-n2", "tracker-n3"])).await;
    assert_eq!(j["result"]["summary"]["held_out"], true, "{j}");
    let held = j["result"]["validation_id"].as_str().unwrap().to_string();
    let r = app.post(&cpath, &json!({"parameter_set_id": set, "targets": target})).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert_eq!(r.body["validity"]["validation"]["validation_id"], held);
    assert_eq!(r.body["validity"]["held_out_uncertainty"]["n"], json!(count("tracker-n2") + count("tracker-n3")));
    let s = app.get(&format!("/v1/parameter-sets/{set}")).await.body;
    assert!(s.get("validation_needed").is_none(), "{s}");
    let flags: Vec<bool> =
        s["validations"].as_array().unwrap().iter().map(|v| v["held_out"].as_bool().unwrap()).collect();
    assert_eq!(flags, [true, false], "newest first");
    let listed = app.get(&format!("/v1/robots/{rid}/parameter-sets")).await.body;
    assert_eq!(listed[0]["validations"], s["validations"]);
    let h = app.get(&format!("/v1/robots/{rid}/history")).await.body;
    assert_eq!(h[0]["validation"]["validation_id"], held);
    assert_eq!(h[0]["validation"]["held_out"], true);
    assert!(h[0].get("in_sample").is_none(), "the in-sample one is older than the held-out one: {h}");
    // A newer in-sample validation is shown beside the held-out one, which still counts.
    validate(json!(["tracker-n1"])).await;
    let h = app.get(&format!("/v1/robots/{rid}/history")).await.body;
    assert_eq!(h[0]["validation"]["validation_id"], held);
    assert_eq!(h[0]["in_sample"]["held_out"], false);
    let r = app.post(&cpath, &json!({"parameter_set_id": set, "targets": target})).await;
    assert_eq!(r.body["validity"]["validation"]["validation_id"], held, "{}", r.text);
    let page = app.get(&format!("/v1/robots/{rid}/history/report")).await.text;
    assert!(page.contains("in-sample (not held out)") && page.contains("tracker-n1"), "the page shows it apart");
    app.stop().await;
}
