//! `POST /v1/robots/{id}/programs/filter` on the real router: the answer is the library's filter of
//! the same program with the same set, byte for byte (the CLI makes the same call); the set is gated
//! as compensation is; a KRL pair as multipart/form-data; refusals name the field.

use crate::common;

use axum::http::{Method, StatusCode};
use common::{TestApp, assert_problem, robot};
use robocal::domain::ParameterSetDoc;
use robocal::domain::program::{Calibration, FilterOptions, ProgramFile, filter};
use robocal::http::ServiceConfig;
use robocal::kinematics::Compensator;

const TABLE: &str = include_str!("../../examples/irb120_table_5_1.json");
const WELD_MOD: &[u8] = include_bytes!("../../examples/programs/weld.mod");
const WELD_SRC: &[u8] = include_bytes!("../../examples/programs/weld.src");
const WELD_DAT: &[u8] = include_bytes!("../../examples/programs/weld.dat");

/// A robot with the Table 5.1 set imported (not validated): robot id, set id.
async fn robot_with_set(app: &TestApp) -> (String, String) {
    let rid = robot(app, "programs").await;
    let set = app
        .raw(Method::POST, &format!("/v1/robots/{rid}/parameter-sets"), Some("application/json"), TABLE.into(), &[])
        .await;
    assert_eq!(set.status, StatusCode::CREATED, "{}", set.text);
    (rid, set.body["id"].as_str().unwrap().to_string())
}

/// The library's answer for the same files and options.
fn library(files: &[ProgramFile], opts: &FilterOptions) -> robocal::domain::program::Filtered {
    let doc = ParameterSetDoc::from_json(TABLE).unwrap();
    let comp = Compensator::new(&doc.set);
    let cal = Calibration {
        set: &doc.set,
        compensator: &comp,
        envelope: None,
        allow_outside_envelope: false,
        covariance: None,
        held_out: None,
    };
    filter(&cal, files, opts).unwrap()
}

fn multipart(parts: &[(&str, &[u8])]) -> (String, Vec<u8>) {
    let boundary = "robocal-test-boundary-7f3a";
    let mut body = Vec::new();
    for (name, bytes) in parts {
        body.extend_from_slice(
            format!(
                "--{boundary}\r\nContent-Disposition: form-data; name=\"files\"; filename=\"{name}\"\r\nContent-Type: application/octet-stream\r\n\r\n"
            )
            .as_bytes(),
        );
        body.extend_from_slice(bytes);
        body.extend_from_slice(b"\r\n");
    }
    body.extend_from_slice(format!("--{boundary}--\r\n").as_bytes());
    (format!("multipart/form-data; boundary={boundary}"), body)
}

#[tokio::test]
async fn a_program_is_filtered_as_the_library_filters_it() {
    let app = TestApp::default().await;
    let (rid, set_id) = robot_with_set(&app).await;
    let path = format!("/v1/robots/{rid}/programs/filter");
    let octet = Some("application/octet-stream");
    // No active set, none named: 409; the set is not validated: 409 saying how to proceed.
    assert_problem(
        &app.raw(Method::POST, &format!("{path}?name=weld.mod"), octet, WELD_MOD.into(), &[]).await,
        409,
        None,
    );
    let named = format!("{path}?name=weld.mod&parameter_set_id={set_id}");
    let r = app.raw(Method::POST, &named, octet, WELD_MOD.into(), &[]).await;
    assert_problem(&r, 409, None);
    assert!(r.body["hint"].as_str().unwrap().contains("allow_unvalidated"), "{}", r.text);

    // The file itself, byte for byte the library's answer, with the counts in headers.
    let ok = format!("{named}&allow_unvalidated=true");
    let r = app.raw(Method::POST, &ok, octet, WELD_MOD.into(), &[]).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert_eq!(r.headers["content-type"], "application/octet-stream");
    assert_eq!(r.headers["content-disposition"], "attachment; filename=\"weld.mod\"");
    let want = library(&[ProgramFile { name: "weld.mod".into(), bytes: WELD_MOD.to_vec() }], &FilterOptions::default());
    assert_eq!(r.text.as_bytes(), &want.files[0].bytes[..]);
    assert_ne!(&want.files[0].bytes[..], WELD_MOD);
    assert_eq!(r.headers["x-compensated-targets"], "6");
    assert_eq!(r.headers["x-kept-targets"], "1");
    assert_eq!(r.headers["x-failed-targets"], "0");

    // As JSON: the report, the files as text, what was checked.
    let r = app.raw(Method::POST, &ok, octet, WELD_MOD.into(), &[("accept", "application/json")]).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert_eq!(r.body["language"], "rapid");
    assert_eq!(r.body["compensated"], 6);
    assert_eq!(r.body["parameter_set_id"], set_id.as_str());
    assert_eq!(r.body["files"][0]["content"].as_str().unwrap().as_bytes(), &want.files[0].bytes[..]);
    let t = &r.body["targets"][2];
    assert_eq!((t["name"].as_str(), t["line"].as_u64()), (Some("seam{1}"), Some(8)));
    assert_eq!(t["correction_mm"].as_f64(), want.report[2].correction_mm);
    assert!(r.body["validity"]["notes"].as_array().unwrap().iter().any(|n| n.as_str().unwrap().contains("envelope")));

    // Joint targets recomputed, as asked.
    let r = app
        .raw(
            Method::POST,
            &format!("{ok}&joint_targets=recompute"),
            octet,
            WELD_MOD.into(),
            &[("accept", "application/json")],
        )
        .await;
    assert_eq!((r.body["compensated"].as_u64(), r.body["kept"].as_u64()), (Some(7), Some(0)), "{}", r.text);

    // A KRL pair as multipart/form-data, frames by number in the query: JSON, ISO-8859-1 kept.
    let (ct, body) = multipart(&[("weld.src", WELD_SRC), ("weld.dat", WELD_DAT)]);
    let krl = format!(
        "{path}?parameter_set_id={set_id}&allow_unvalidated=true&tool=1:30,0,210,0,45,0,2.5,0,0,80&base=2:400,-100,60,30,0,0"
    );
    let r = app.raw(Method::POST, &krl, Some(&ct), body.clone(), &[]).await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert_eq!(r.body["language"], "krl");
    assert_eq!((r.body["compensated"].as_u64(), r.body["failed"].as_u64()), (Some(6), Some(0)), "{}", r.text);
    let mut frames = robocal::domain::program::GivenFrames::default();
    frames.add_tool("1:30,0,210,0,45,0,2.5,0,0,80", robocal::domain::program::AngleOrder::Abc, "tool").unwrap();
    frames.add_base("2:400,-100,60,30,0,0", robocal::domain::program::AngleOrder::Abc, "base").unwrap();
    let want = library(
        &[
            ProgramFile { name: "weld.src".into(), bytes: WELD_SRC.to_vec() },
            ProgramFile { name: "weld.dat".into(), bytes: WELD_DAT.to_vec() },
        ],
        &FilterOptions { frames, ..Default::default() },
    );
    let dat = &r.body["files"][1];
    assert_eq!(dat["encoding"], "iso-8859-1");
    let bytes: Vec<u8> = dat["content"].as_str().unwrap().chars().map(|c| c as u32 as u8).collect();
    assert_eq!(bytes, want.files[1].bytes);
    // Without the base: those targets fail, are marked, and the answer says so.
    let r = app
        .raw(
            Method::POST,
            &format!("{path}?parameter_set_id={set_id}&allow_unvalidated=true&tool=1:30,0,210,0,45,0"),
            Some(&ct),
            body,
            &[],
        )
        .await;
    assert_eq!(r.status, StatusCode::OK, "{}", r.text);
    assert_eq!(r.body["failed"], 6);
    // The .src's inline retract first, then the .dat's points: XHOME (kept), XP1, …
    assert_eq!(r.body["targets"][2]["name"], "XP1");
    assert!(r.body["targets"][2]["error"].as_str().unwrap().contains("work frame '2'"), "{}", r.body["targets"][2]);
    assert!(r.body["files"][1]["content"].as_str().unwrap().contains("; robocal: NOT COMPENSATED:"));
    app.stop().await;
}

#[tokio::test]
async fn refusals_name_the_field() {
    let app = TestApp::new(ServiceConfig { max_batch: 5, ..ServiceConfig::default() }, false).await;
    let (rid, set_id) = robot_with_set(&app).await;
    let path = format!("/v1/robots/{rid}/programs/filter?parameter_set_id={set_id}&allow_unvalidated=true");
    let octet = Some("application/octet-stream");
    // A program that does not parse: 422 naming the program, its line in the detail.
    let bad = String::from_utf8_lossy(WELD_MOD).replace("[[110.00,-40.00,5.00]", "[[110.00,-40.00]");
    let r = app.raw(Method::POST, &format!("{path}&name=weld.mod"), octet, bad.into_bytes(), &[]).await;
    assert_problem(&r, 422, Some("program"));
    assert!(r.body["detail"].as_str().unwrap().starts_with("weld.mod line 9: robtarget seam{2}"), "{}", r.text);
    // More targets than the batch limit (5 here; weld.mod has 7).
    assert_problem(
        &app.raw(Method::POST, &format!("{path}&name=weld.mod"), octet, WELD_MOD.into(), &[]).await,
        413,
        Some("program"),
    );
    // Options.
    for (query, field) in [
        ("&language=cobol", "language"),
        ("&joint_targets=sometimes", "joint_targets"),
        ("&tool=gun:1,2,3", "tool"),
        ("&uframe=1:0,0,0,0,0,nan", "uframe"),
        ("&seed_joints_deg=1,x", "seed_joints_deg"),
        ("&nonsense=1", "nonsense"),
    ] {
        let r = app.raw(Method::POST, &format!("{path}&name=weld.mod{query}"), octet, WELD_MOD.into(), &[]).await;
        assert_problem(&r, 422, Some(field));
    }
    // A frame the program declares must not be given.
    let small = "MODULE M\r\n  PERS tooldata gun:=[TRUE,[[30,0,210],[1,0,0,0]],[2.5,[0,0,80],[1,0,0,0],0,0,0]];\r\nENDMODULE\r\n";
    let r = app.raw(Method::POST, &format!("{path}&name=m.mod&tool=gun:0,0,100,0,0,0"), octet, small.into(), &[]).await;
    assert!(r.body["detail"].as_str().unwrap().contains("m.mod line 2"), "{}", r.text);
    assert_problem(&r, 422, Some("tool"));
    // The language cannot be told: named.
    let r = app.raw(Method::POST, &path, octet, b"hello".to_vec(), &[]).await;
    assert_problem(&r, 422, Some("language"));
    // JSON is not a program; an empty body is none.
    assert_problem(&app.raw(Method::POST, &path, Some("application/json"), b"{}".to_vec(), &[]).await, 415, None);
    assert_problem(&app.raw(Method::POST, &path, octet, Vec::new(), &[]).await, 422, Some("program"));
    // Unknown robot.
    let r = app
        .raw(
            Method::POST,
            "/v1/robots/00000000-0000-0000-0000-000000000000/programs/filter",
            octet,
            WELD_MOD.into(),
            &[],
        )
        .await;
    assert_problem(&r, 404, None);
    app.stop().await;
}
