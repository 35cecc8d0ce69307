//! The ISO 9283 job through the real router (`oneshot`, a fresh SQLite database, real workers): a
//! simulated tracker session visiting six poses for four cycles, each pose with its own known
//! offset and per-cycle deviation. The job's stored evaluation equals the library call on the cell
//! the server exports; RP equals the hand computation from the measured positions; bad requests
//! are 422 naming the field; the HTML report is served.

use crate::common;

use axum::http::{Method, StatusCode};
use common::{TestApp, artefact, assert_problem, robot, upload};
use robocal::domain::ParameterSetDoc;
use robocal::domain::cell::{CellFile, parse_cell};
use robocal::domain::iso9283::{Evaluation, KAPPA_LIMIT, PoseAssignment, PosePair, assignments_of, evaluate, pairs_of};
use robocal::kinematics::thesis::{irb120_table_5_1, trical_tool};
use robocal::sim::simulate::{SimulateOptions, simulate};
use serde_json::{Value, json};

const POSES: usize = 6;
const CYCLES: usize = 4;

/// The simulated cell, and an `iso` session made from its first tracker session's first six poses:
/// visit (pose k, cycle c) at the same joints, the reading moved by the pose's offset and a
/// deterministic per-cycle deviation (mm). Visits in cycle order: P1 … P6, four times.
fn cell_with_iso_session() -> (CellFile, Vec<[f64; 3]>) {
    let s = simulate(&SimulateOptions { seed: 3, id_per_ball: 30, validation: 60, ..Default::default() }).unwrap();
    let mut cell = CellFile::from_cell(&s.cell);
    let tracker = cell.sessions.iter().find(|s| s.name == "tracker-n1").expect("a tracker session").clone();
    let mut iso = tracker.clone();
    iso.name = "iso".into();
    iso.measurements.clear();
    let mut readings = Vec::new();
    for c in 1..=CYCLES {
        for k in 0..POSES {
            let mut m = tracker.measurements[k].clone();
            let (kf, cf) = (k as f64, c as f64);
            let offset = [0.05 * kf, -0.03 * kf, 0.02 * (kf - 2.0)];
            let dev =
                [0.012 * (1.3 * cf + kf).sin(), 0.009 * (0.7 * cf + 2.0 * kf).cos(), 0.015 * (cf * kf + 0.5).sin()];
            let p = m.position_mm.expect("a tracker reading");
            let moved = [p[0] + offset[0] + dev[0], p[1] + offset[1] + dev[1], p[2] + offset[2] + dev[2]];
            m.position_mm = Some(moved);
            m.sigma_mm = Some([0.01, 0.01, 0.01]);
            readings.push(moved);
            iso.measurements.push(m);
        }
    }
    cell.sessions.retain(|s| s.name == "trical-1");
    cell.sessions.push(iso);
    (cell, readings)
}

/// RP of one pose by hand (ISO 9283 7.2.2): l_j = |P_j − P̄|, RP = l̄ + 3·S_l.
fn rp_by_hand(points: &[[f64; 3]]) -> f64 {
    let n = points.len() as f64;
    let mean: Vec<f64> = (0..3).map(|i| points.iter().map(|p| p[i]).sum::<f64>() / n).collect();
    let l: Vec<f64> = points
        .iter()
        .map(|p| ((p[0] - mean[0]).powi(2) + (p[1] - mean[1]).powi(2) + (p[2] - mean[2]).powi(2)).sqrt())
        .collect();
    let lm = l.iter().sum::<f64>() / n;
    let s = (l.iter().map(|x| (x - lm).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    lm + 3.0 * s
}

/// Two JSON documents equal, numbers to 1e-12 relative (an ulp or two of a JSON round trip).
fn same(a: &Value, b: &Value, at: &str) {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            assert!((x - y).abs() <= 1e-12 * x.abs().max(y.abs()).max(1e-300), "{at}: {x} vs {y}");
        }
        (Value::Array(x), Value::Array(y)) => {
            assert_eq!(x.len(), y.len(), "{at}");
            for (k, (u, v)) in x.iter().zip(y).enumerate() {
                same(u, v, &format!("{at}[{k}]"));
            }
        }
        (Value::Object(x), Value::Object(y)) => {
            assert_eq!(x.keys().collect::<Vec<_>>(), y.keys().collect::<Vec<_>>(), "{at}");
            for (k, u) in x {
                same(u, &y[k], &format!("{at}.{k}"));
            }
        }
        _ => assert_eq!(a, b, "{at}"),
    }
}

fn body(session: &str, set: Option<&str>) -> Value {
    let poses: Vec<Value> = (0..CYCLES * POSES)
        .map(|i| json!({"index": i, "pose_id": format!("P{}", i % POSES + 1), "cycle": i / POSES + 1}))
        .collect();
    let mut b =
        json!({"session": session, "poses": poses, "pairs": [{"from": "P1", "to": "P2"}, {"from": "P1", "to": "P4"}]});
    if let Some(s) = set {
        b["parameter_set_id"] = json!(s);
    }
    b
}

#[tokio::test]
async fn an_evaluation_job_gives_the_library_figures_and_its_report() {
    let app = TestApp::default().await;
    let (cell, readings) = cell_with_iso_session();
    let rid = robot(&app, "iso-cell").await;
    let aid = artefact(&app, "iso-plate").await;
    let ids = upload(&app, &rid, &aid, &cell).await;
    let iso_id = ids.iter().find(|(n, _)| n == "iso").unwrap().1.clone();
    // A calibrated set: the thesis's identified IRB 120 (the simulation's truth without effects).
    let doc = ParameterSetDoc::new(irb120_table_5_1(trical_tool()));
    let file: Value = serde_json::from_str(&doc.to_json_pretty()).unwrap();
    let r = app.post(&format!("/v1/robots/{rid}/parameter-sets"), &file).await;
    assert_eq!(r.status, StatusCode::CREATED, "{}", r.text);
    let set_id = r.body["id"].as_str().unwrap().to_string();

    let path = format!("/v1/robots/{rid}/iso9283");
    let r = app.post(&path, &body("iso", Some(&set_id))).await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", r.text);
    assert_eq!(r.body["kind"], "iso9283");
    // Stored with the session as its id.
    assert_eq!(r.body["request"]["session"], iso_id.as_str());
    let job = app.wait(&r.body).await;
    assert_eq!(job["state"], "succeeded", "{job}");
    let result = &job["result"];
    assert_eq!((result["session"].as_str(), result["parameter_set_id"].as_str()), (Some("iso"), Some(set_id.as_str())));
    assert_eq!(result["nominal"]["poses"], POSES);
    assert_eq!(result["nominal"]["visits"], POSES * CYCLES);
    let eid = result["evaluation_id"].as_str().unwrap().to_string();
    let stored = app.get(&format!("/v1/iso9283/{eid}")).await;
    assert_eq!(stored.status, StatusCode::OK, "{}", stored.text);
    assert_eq!(stored.body["session_id"], iso_id.as_str());

    // The library call on the cell the server exports (what the job loaded).
    let exported = app.get(&format!("/v1/robots/{rid}/cell?sessions=iso")).await;
    assert_eq!(exported.status, StatusCode::OK, "{}", exported.text);
    let c = parse_cell(&exported.text).unwrap();
    let rows: Vec<PoseAssignment> = serde_json::from_value(body("iso", None)["poses"].clone()).unwrap();
    let pairs: Vec<PosePair> = serde_json::from_value(body("iso", None)["pairs"].clone()).unwrap();
    let assignments = assignments_of(&rows).unwrap();
    let pairs = pairs_of(&pairs, &assignments).unwrap();
    let library = evaluate(&c, "iso", Some(&doc.set), &assignments, &pairs, KAPPA_LIMIT).unwrap();
    // Equal to the last bits a JSON round trip keeps (serde_json parses decimals to within an ulp).
    same(&stored.body["report"], &serde_json::to_value(&library).unwrap(), "report");
    let e: Evaluation = serde_json::from_value(stored.body["report"].clone()).unwrap();
    let cal = e.calibrated.as_ref().expect("calibrated figures");
    // RP by hand from the readings (a rigid registration changes no distance), both models.
    for k in 0..POSES {
        let pts: Vec<[f64; 3]> = (0..CYCLES).map(|c| readings[c * POSES + k]).collect();
        let want = rp_by_hand(&pts);
        for r in [&e.nominal, cal] {
            let p = r.poses.iter().find(|p| p.pose == format!("P{}", k + 1)).unwrap();
            assert_eq!(p.cycles, CYCLES);
            let got = p.rp_l_mm.unwrap();
            assert!((got - want).abs() < 1e-9, "{} P{}: RP {got} vs {want} by hand", r.model, k + 1);
        }
    }
    // The known offsets differ pose to pose (up to 0.3 mm), more than the registration absorbs:
    // AP is of that size, and the instrument's share of it is σ/√n = 0.005 mm.
    assert!(e.nominal.summary.ap_p_max_mm > 0.05, "{:?}", e.nominal.summary);
    let p1 = &e.nominal.poses[0];
    assert!((p1.ap_p_u_mm.unwrap() - 0.01 / (CYCLES as f64).sqrt()).abs() < 1e-12, "{p1:?}");
    assert_eq!(e.nominal.distances.len(), 2);

    // The report: HTML, and 406 to a client that accepts only JSON.
    let page = app.get(&format!("/v1/iso9283/{eid}/report")).await;
    assert_eq!(page.status, StatusCode::OK);
    assert!(page.headers["content-type"].to_str().unwrap().starts_with("text/html"));
    assert!(page.text.contains("<td>P1</td>") && page.text.contains("not implemented"), "{}", &page.text[..400]);
    let r = app
        .raw(Method::GET, &format!("/v1/iso9283/{eid}/report"), None, Vec::new(), &[("accept", "application/json")])
        .await;
    assert_problem(&r, 406, None);
    assert_problem(&app.get("/v1/iso9283/00000000-0000-0000-0000-000000000000").await, 404, None);
    assert_problem(&app.get("/v1/iso9283/00000000-0000-0000-0000-000000000000/report").await, 404, None);

    // The robot's active set is the default; without one, the nominal figures only.
    let r = app.post(&path, &body("iso", None)).await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", r.text);
    assert!(r.body["request"]["parameter_set_id"].is_null(), "{}", r.text);
    let job = app.wait(&r.body).await;
    assert_eq!(job["state"], "succeeded", "{job}");
    assert!(job["result"]["calibrated"].is_null() && job["result"]["parameter_set_id"].is_null(), "{job}");
    let r = app.put(&format!("/v1/robots/{rid}/active-parameter-set"), &json!({"parameter_set_id": set_id})).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    let r = app.post(&path, &body("iso", None)).await;
    assert_eq!(r.body["request"]["parameter_set_id"], set_id.as_str(), "{}", r.text);

    // The session is in use: deleting it is refused, naming the evaluation.
    let r = app.raw(Method::DELETE, &format!("/v1/sessions/{iso_id}?reason=test"), None, Vec::new(), &[]).await;
    assert_problem(&r, 409, None);
    assert!(r.body["detail"].as_str().unwrap().contains(&format!("ISO 9283 evaluation {eid}")), "{}", r.text);
    app.stop().await;
}

#[tokio::test]
async fn bad_requests_name_the_field() {
    let app = TestApp::default().await;
    let (cell, _) = cell_with_iso_session();
    let rid = robot(&app, "iso-bad").await;
    let aid = artefact(&app, "iso-bad-plate").await;
    upload(&app, &rid, &aid, &cell).await;
    let path = format!("/v1/robots/{rid}/iso9283");
    let with = |f: &dyn Fn(&mut Value)| {
        let mut b = body("iso", None);
        f(&mut b);
        b
    };
    let cases: Vec<(Value, &str, &str)> = vec![
        (with(&|b| b["poses"][3]["pose_id"] = json!("P 4")), "poses[3].pose_id", "letters"),
        (with(&|b| b["poses"][3]["pose_id"] = json!(4)), "poses[3].pose_id", ""),
        (with(&|b| b["poses"][2]["index"] = json!(500)), "poses[2].index", "has 24 measurements"),
        (with(&|b| b["poses"][7]["index"] = json!(1)), "poses[7].index", "assigned twice"),
        (with(&|b| b["poses"][9]["cycle"] = json!(1)), "poses[9].cycle", "visited twice in cycle 1"),
        (with(&|b| b["poses"][1]["cycle"] = json!(0)), "poses[1].cycle", "from 1"),
        (with(&|b| b["poses"][0]["approach"] = json!("")), "poses[0].approach", ""),
        (with(&|b| b["pairs"][1]["to"] = json!("P9")), "pairs[1].to", "no measurement is assigned to pose 'P9'"),
        (with(&|b| b["pairs"][0]["to"] = json!("P1")), "pairs[0].to", "two different poses"),
        (with(&|b| b["poses"] = json!([])), "poses", "at least one"),
        (with(&|b| b["session"] = json!("trical-1")), "poses[0].index", "is a ball"),
        (with(&|b| b["colour"] = json!(1)), "colour", ""),
    ];
    for (b, field, words) in cases {
        let r = app.post(&path, &b).await;
        assert_problem(&r, 422, Some(field));
        assert!(r.body["detail"].as_str().unwrap().contains(words), "{field}: {}", r.text);
    }
    // What the store does not hold: 404 naming the field.
    for (b, field, words) in [
        (with(&|b| b["session"] = json!("nope")), "session", "no session 'nope'"),
        (
            with(&|b| b["parameter_set_id"] = json!("00000000-0000-0000-0000-000000000000")),
            "parameter_set_id",
            "no parameter set",
        ),
    ] {
        let r = app.post(&path, &b).await;
        assert_problem(&r, 404, Some(field));
        assert!(r.body["detail"].as_str().unwrap().contains(words), "{field}: {}", r.text);
    }
    assert_problem(
        &app.post("/v1/robots/00000000-0000-0000-0000-000000000000/iso9283", &body("iso", None)).await,
        404,
        None,
    );
    // An excluded measurement is refused too.
    let sid = app
        .get(&format!("/v1/robots/{rid}/sessions"))
        .await
        .body
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == "iso")
        .unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string();
    let r = app
        .raw(
            Method::PATCH,
            &format!("/v1/sessions/{sid}/measurements/5"),
            Some("application/json"),
            serde_json::to_vec(&json!({"excluded": true, "reason": "test"})).unwrap(),
            &[],
        )
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    let r = app.post(&path, &body("iso", None)).await;
    assert_problem(&r, 422, Some("poses[5].index"));
    assert!(r.body["detail"].as_str().unwrap().contains("excluded"), "{}", r.text);
    app.stop().await;
}
