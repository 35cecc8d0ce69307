//! The `robocal` binary: outputs checked against the library, errors naming the argument.

use std::process::Command;

use serde_json::{Value, json};

fn robocal(args: &[&str]) -> (bool, Value, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_robocal")).args(args).output().expect("runs");
    let stdout = String::from_utf8(out.stdout).unwrap();
    let stderr = String::from_utf8(out.stderr).unwrap();
    let v = serde_json::from_str(&stdout).unwrap_or(Value::Null);
    (out.status.success(), v, stderr)
}

/// The exit status: 0 success, 1 ran and reported a failure, 2 input refused.
fn status(args: &[&str]) -> i32 {
    Command::new(env!("CARGO_BIN_EXE_robocal")).args(args).output().expect("runs").status.code().unwrap()
}

fn tmp(name: &str, contents: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("robocal-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, contents).unwrap();
    p
}

fn nums(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

#[test]
fn fk_then_ik_round_trips_through_the_command_line() {
    let (ok, fk, err) =
        robocal(&["fk", "--robot", "irb120", "--joints-deg", "10,-20,30,-40,50,-60", "--tcp-mm", "40,0,130"]);
    assert!(ok, "{err}");
    let p = nums(&fk["position_mm"]);
    let r = nums(&fk["rotation_deg"]);
    let cfx = fk["confdata"][3].as_u64().unwrap().to_string();
    let pos = format!("{},{},{}", p[0], p[1], p[2]);
    let rot = format!("{},{},{}", r[0], r[1], r[2]);
    let (ok, ik, err) = robocal(&[
        "ik",
        "--robot",
        "irb120",
        "--position-mm",
        &pos,
        "--rotation-deg",
        &rot,
        "--cfx",
        &cfx,
        "--tcp-mm",
        "40,0,130",
    ]);
    assert!(ok, "{err}");
    let q = nums(&ik["joints_deg"]);
    // fk prints at 0.1 µm and 1e-6°, so the joints come back to that resolution.
    for (a, b) in q.iter().zip([10.0, -20.0, 30.0, -40.0, 50.0, -60.0]) {
        assert!((a - b).abs() < 1e-4, "{q:?}");
    }
    // Without a branch: all eight, each a solution or its reason.
    let (ok, all, _) =
        robocal(&["ik", "--robot", "irb120", "--position-mm", &pos, "--rotation-deg", &rot, "--tcp-mm", "40,0,130"]);
    assert!(ok);
    assert_eq!(all["solutions"].as_array().unwrap().len(), 8);
    // Out of reach: the reason is printed as before, and the status is 1, with one branch or all.
    let far = ["ik", "--robot", "irb120", "--position-mm", "4000,0,500", "--rotation-deg", "0,90,0"];
    let (ok, out, err) = robocal(&[&far[..], &["--cfx", "1"]].concat());
    assert!(!ok && out["error"].as_str().unwrap().contains("out of reach") && err.starts_with("error: "), "{err}");
    assert_eq!(status(&[&far[..], &["--cfx", "1"]].concat()), 1);
    let (ok, out, err) = robocal(&far);
    assert!(!ok && out["solutions"].as_array().unwrap().len() == 8 && err.contains("no branch reaches"), "{err}");
    assert_eq!(status(&far), 1);
    // Refused input stays status 2.
    assert_eq!(status(&["ik", "--robot", "irb120", "--position-mm", "400,0", "--rotation-deg", "0,0,0"]), 2);
}

/// Printed numbers are rounded to the output resolution, without binary noise; a quaternion
/// stored with 5 decimals is normalised and the output says so; one off by more is refused.
#[test]
fn outputs_are_readable_and_sloppy_quaternions_are_normalised() {
    let out = Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["fk", "--robot", "irb120", "--joints-deg", "0,0,0,0,30,0"])
        .output()
        .unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(!text.contains("e-") && !text.contains("99999") && !text.contains("00001"), "{text}");
    let fk: Value = serde_json::from_str(&text).unwrap();
    assert_eq!(fk["joints_deg"][4], 30.0);
    assert_eq!(fk["position_mm"], json!([364.3538, 0.0, 594.0]), "302 + 72·cos 30° + 374 … at 0.1 µm");
    let (ok, ik, err) = robocal(&[
        "ik",
        "--robot",
        "irb120",
        "--position-mm",
        "374,0,630",
        "--quaternion",
        "0,0.70711,0.70711,0",
        "--cfx",
        "0",
    ]);
    assert!(ok, "{err}");
    assert!(ik["notes"][0].as_str().unwrap().contains("normalised: its norm was 1.000004552"), "{ik}");
    assert_eq!(ik["joints_deg"][5], 90.0);
    let (ok, _, err) = robocal(&[
        "ik",
        "--robot",
        "irb120",
        "--position-mm",
        "374,0,630",
        "--quaternion",
        "0,0.7,0.7,0",
        "--cfx",
        "0",
    ]);
    assert!(!ok && err.starts_with("error: --quaternion") && err.contains("0.98994"), "{err}");
}

#[test]
fn errors_name_the_argument() {
    for (args, needle) in [
        (vec!["fk", "--robot", "irb120", "--joints-deg", "0,0,0"], "--joints-deg: expected 6"),
        (vec!["fk", "--robot", "irb120", "--joints-deg", "0,0,0,0,x,0"], "--joints-deg: 'x'"),
        (vec!["fk", "--robot", "irb120", "--joints-deg", "0,0,0,0,130,0"], "q5"),
        (vec!["fk", "--robot", "abb", "--joints-deg", "0,0,0,0,0,0"], "--robot: unknown preset"),
        (vec!["fk", "--robot", "irb120", "--joints-deg", "0,0,0,0,0,0", "--payload-kg", "-1"], "--payload-kg"),
        (vec!["ik", "--robot", "irb120", "--position-mm", "400,0", "--rotation-deg", "0,0,0"], "--position-mm"),
        (
            vec!["ik", "--robot", "irb120", "--position-mm", "400,0,500", "--rotation-deg", "0,0,0", "--cfx", "8"],
            "--cfx",
        ),
        (vec!["ik", "--robot", "ur10", "--position-mm", "400,0,500", "--rotation-deg", "0,0,0"], "--seed-joints-deg"),
    ] {
        let (ok, _, err) = robocal(&args);
        assert!(!ok, "{args:?} should fail");
        assert!(err.contains(needle), "{args:?}: {err}");
    }
}

#[test]
fn compensate_writes_joints_and_fake_poses() {
    let (ok, _, err) = robocal(&[
        "nominal",
        "--robot",
        "irb120",
        "--tcp-mm",
        "40,0,130",
        "--payload-kg",
        "1.7",
        "--payload-com-mm",
        "30,0,64",
    ]);
    assert!(ok, "{err}");
    // A calibrated set: the nominal one with a longer upper arm, a joint-2 offset and compliance.
    let params = json!({"robot": {"preset": "irb120"},
        "tool": {"tcp_mm": [40, 0, 130], "mass_kg": 1.7, "com_mm": [30, 0, 64]},
        "parameters": [{"name": "a2", "value": 270.146, "nominal": 270.0, "unit": "mm"},
                       {"name": "theta2", "value": -89.91, "unit": "deg"},
                       {"name": "c2", "value": -0.00206, "unit": "deg/(N·m)"}]});
    let targets = json!({"targets": [
        {"id": "p1", "position_mm": [400, 50, 450], "rotation_deg": [0, 90, 0], "cfx": 1},
        {"id": "j1", "joints_deg": [10, 20, -10, 5, 40, 0]},
        {"id": "bad", "position_mm": [400, 50, 450], "rotation_deg": [0, 90, 0]},
        {"id": "far", "position_mm": [2000, 0, 0], "rotation_deg": [0, 0, 0], "cfx": 0}]});
    let pp = tmp("params.json", &params.to_string());
    let tp = tmp("targets.json", &targets.to_string());
    let args = ["compensate", "--params", pp.to_str().unwrap(), "--targets", tp.to_str().unwrap()];
    // Two targets fail: the results are printed all the same, the status is 1 and says which.
    let (ok, out, err) = robocal(&args);
    assert!(!ok && err.contains("2 of 4 targets not compensated (bad, far)"), "{err}");
    assert_eq!(status(&args), 1);
    let r = out["results"].as_array().unwrap();
    assert_eq!(out["failed"], 2);
    assert!(r[0]["residual_mm"].as_f64().unwrap() < 1e-6);
    assert_eq!(r[0]["confdata"][3], 1);
    // The fake pose differs from the target by the model error (a few tenths of a mm here).
    let fp = nums(&r[0]["fake_pose"]["position_mm"]);
    let d = ((fp[0] - 400.0).powi(2) + (fp[1] - 50.0).powi(2) + (fp[2] - 450.0).powi(2)).sqrt();
    assert!(d > 0.05 && d < 5.0, "{d}");
    assert!(r[2]["error"].as_str().unwrap().contains("targets[2].cfx"), "{}", r[2]["error"]);
    assert!(r[3]["error"].as_str().unwrap().contains("out of reach"), "{}", r[3]["error"]);
    // All good: status 0.
    let good = json!({"targets": [targets["targets"][0], targets["targets"][1]]});
    let gp = tmp("good_targets.json", &good.to_string());
    assert_eq!(status(&["compensate", "--params", pp.to_str().unwrap(), "--targets", gp.to_str().unwrap()]), 0);
    // A bad parameter file names its field.
    let bad = tmp("bad.json", r#"{"robot": {"preset": "irb120"}, "parameters": [{"name": "a9", "value": 1}]}"#);
    let (ok, _, err) = robocal(&["compensate", "--params", bad.to_str().unwrap(), "--targets", tp.to_str().unwrap()]);
    assert!(!ok && err.contains("parameters[0].name"), "{err}");
}

/// A set with hysteresis (backlash terms): a target that says which way each joint arrives is
/// compensated for it, and its joints differ from the band-middle answer by exactly −b_j·approach_j
/// (the backlash adds b_j·approach_j to joint j's angle and nothing else). A target without its
/// approach is compensated for the middle of the bands, and its note says so with the spread; a
/// wrong length fails that target alone, naming the field; a value other than −1, 0, 1 is refused
/// at the door.
#[test]
fn compensate_applies_a_sets_hysteresis_for_the_approach_given_and_says_when_it_cannot() {
    let b = [0.02, -0.03, 0.025];
    let params = json!({"robot": {"preset": "irb120"},
        "tool": {"tcp_mm": [40, 0, 130], "mass_kg": 1.7, "com_mm": [30, 0, 64]},
        "parameters": [{"name": "a2", "value": 270.146, "nominal": 270.0, "unit": "mm"},
                       {"name": "c2", "value": -0.00206, "unit": "deg/(N·m)"},
                       {"name": "backlash1", "value": b[0], "unit": "deg"},
                       {"name": "backlash2", "value": b[1], "unit": "deg"},
                       {"name": "backlash3", "value": b[2], "unit": "deg"}]});
    let pose = json!({"position_mm": [400, 50, 450], "rotation_deg": [0, 90, 0], "cfx": 1});
    let approach = [1, -1, -1, 1, 0, 0];
    let with = |id: &str, a: Option<Value>| {
        let mut t = pose.clone();
        t["id"] = json!(id);
        if let Some(a) = a {
            t["approach"] = a;
        }
        t
    };
    let targets = json!({"targets": [
        with("unknown", None),
        with("known", Some(json!(approach))),
        with("short", Some(json!([1, -1]))),
        {"id": "joints", "joints_deg": [10, 20, -10, 5, 40, 0], "approach": [-1, 1, 1, 0, 0, 0]}]});
    let pp = tmp("hysteresis_params.json", &params.to_string());
    let tp = tmp("hysteresis_targets.json", &targets.to_string());
    let (ok, out, err) = robocal(&["compensate", "--params", pp.to_str().unwrap(), "--targets", tp.to_str().unwrap()]);
    assert!(!ok && err.contains("1 of 4 targets not compensated (short)"), "{err}");
    let r = out["results"].as_array().unwrap();
    let note = r[0]["notes"].as_array().unwrap().iter().map(|n| n.as_str().unwrap()).collect::<Vec<_>>().join(" ");
    assert!(
        note.contains("hysteresis (joint 1 ±0.0200°, joint 2 ±0.0300°, joint 3 ±0.0250°)")
            && note.contains("middle of each band")
            && note.contains("give approach"),
        "{note}"
    );
    let spread: f64 = note.split(" mm RMS").next().unwrap().rsplit(' ').next().unwrap().parse().unwrap();
    // Each band moves this TCP by about its angle times the TCP's lever (0.3–0.7 m).
    assert!(spread > 0.1 && spread < 0.6, "{spread} mm");
    assert!(r[1]["notes"].as_array().is_none_or(|n| n.iter().all(|n| !n.as_str().unwrap().contains("hysteresis"))));
    let (mid, known) = (nums(&r[0]["joints_deg"]), nums(&r[1]["joints_deg"]));
    for j in 0..6 {
        let want = if j < 3 { mid[j] - b[j] * f64::from(approach[j]) } else { mid[j] };
        assert!((known[j] - want).abs() < 2e-4, "joint {}: {} vs {want}", j + 1, known[j]);
    }
    assert!(r[2]["error"].as_str().unwrap().contains("targets[2].approach"), "{}", r[2]["error"]);
    assert!(r[3]["error"].is_null() && r[3]["notes"].as_array().is_none_or(|n| n.is_empty()), "{}", r[3]);
    // A value that is not a direction: refused before anything is solved.
    let bad = json!({"targets": [with("two", Some(json!([2, 0, 0, 0, 0, 0])))]});
    let bp = tmp("hysteresis_bad.json", &bad.to_string());
    let args = ["compensate", "--params", pp.to_str().unwrap(), "--targets", bp.to_str().unwrap()];
    let (ok, _, err) = robocal(&args);
    assert!(!ok && err.contains("targets[0].approach[0]") && err.contains("must be -1, 0 or 1"), "{err}");
    assert_eq!(status(&args), 2);
}

/// A set whose calibrated TCP is a reflector declared at the flange (a three-reflector import):
/// compensated with its own tool, a joint target sends the reflector where the nominal model puts
/// the flange, and the answer says so; with the controller's tool in the targets file, only the
/// robot's parameters correct it, exactly as a set without the tool correction does.
#[test]
fn compensate_notes_a_calibrated_tcp_far_from_the_declared_one_and_takes_the_controllers_tool() {
    let robot = json!([{"name": "a2", "value": 270.146, "nominal": 270.0, "unit": "mm"},
                       {"name": "c2", "value": -0.00206, "unit": "deg/(N·m)"}]);
    let mut reflector = robot.as_array().unwrap().clone();
    for (k, v) in [("x", 19.6), ("y", 86.7), ("z", 40.2)] {
        reflector.push(json!({"name": format!("tool_{k}"), "value": v, "nominal": 0.0, "unit": "mm"}));
    }
    let set = |parameters: Value| {
        json!({"robot": {"preset": "irb120"}, "tool": {"tcp_mm": [0, 0, 0], "mass_kg": 1.0, "com_mm": [20, 0, 40]},
               "parameters": parameters})
    };
    let (own, plain) = (
        tmp("reflector_set.json", &set(json!(reflector)).to_string()),
        tmp("flange_set.json", &set(robot).to_string()),
    );
    let q = [10.0, 20.0, -10.0, 5.0, 40.0, 0.0];
    let targets = |tool: Option<Value>| {
        let mut t = json!({"targets": [{"joints_deg": q}]});
        if let Some(tool) = tool {
            t["tool"] = tool;
        }
        t
    };
    let compensate = |params: &std::path::Path, name: &str, t: Value| {
        let tp = tmp(name, &t.to_string());
        let (ok, out, err) =
            robocal(&["compensate", "--params", params.to_str().unwrap(), "--targets", tp.to_str().unwrap()]);
        assert!(ok, "{err}");
        let notes: Vec<String> =
            out["validity"]["notes"].as_array().unwrap().iter().map(|n| n.as_str().unwrap().to_string()).collect();
        (nums(&out["results"][0]["joints_deg"]), notes.join(" "))
    };
    let (moved, note) = compensate(&own, "reflector_targets.json", targets(None));
    let d = (19.6f64.powi(2) + 86.7f64.powi(2) + 40.2f64.powi(2)).sqrt();
    assert!(
        note.contains(&format!("calibrated TCP lies {d:.1} mm from the TCP it declares (0.0, 0.0, 0.0) mm")),
        "{note}"
    );
    assert!(note.contains("the targets file's \"tool\""), "{note}");
    // The reflector sent to the flange's place: the joints move by degrees, not by a correction.
    // (The controller's tool below carries the set's payload: a tool given is the payload too.)
    assert!(moved.iter().zip(&q).any(|(a, b)| (a - b).abs() > 1.0), "{moved:?}");
    let (given, note) = compensate(
        &own,
        "reflector_tool.json",
        targets(Some(json!({"tcp_mm": [0, 0, 0], "mass_kg": 1.0, "com_mm": [20, 0, 40]}))),
    );
    assert!(!note.contains("calibrated TCP"), "{note}");
    let (reference, note) = compensate(&plain, "flange_targets.json", targets(None));
    assert!(!note.contains("calibrated TCP"), "{note}");
    for j in 0..6 {
        assert!((given[j] - reference[j]).abs() < 1e-6, "joint {}: {} vs {}", j + 1, given[j], reference[j]);
        assert!((given[j] - q[j]).abs() < 0.5, "joint {}: {} vs the target's {}", j + 1, given[j], q[j]);
    }
    // The RAPID export says it in the module's header (and on stderr), and with the targets
    // file's tool declares that tool as the module's tooldata.
    let export = |name: &str, t: Value| {
        let tp = tmp(name, &t.to_string());
        let o = Command::new(env!("CARGO_BIN_EXE_robocal"))
            .args(["export", "--format", "rapid", "--params", own.to_str().unwrap(), "--targets", tp.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        // The header's comment lines joined: a long note wraps.
        (String::from_utf8(o.stdout).unwrap().replace("\n    ! ", " "), String::from_utf8(o.stderr).unwrap())
    };
    let (module, err) = export("reflector_export.json", targets(None));
    assert!(module.contains("calibrated TCP lies") && err.contains("calibrated TCP lies"), "{module}\n{err}");
    let (module, err) =
        export("reflector_export_tool.json", targets(Some(json!({"tcp_mm": [0, 0, 100], "mass_kg": 1.0}))));
    assert!(!module.contains("calibrated TCP lies") && !err.contains("calibrated TCP lies"), "{module}\n{err}");
    assert!(module.contains("the targets file's tool") && module.contains("[[0,0,100]"), "{module}");
    // A tool out of bounds is refused, naming it.
    let tp = tmp("bad_tool.json", &targets(Some(json!({"tcp_mm": [0, 0, 1e9]}))).to_string());
    let (ok, _, err) = robocal(&["compensate", "--params", own.to_str().unwrap(), "--targets", tp.to_str().unwrap()]);
    assert!(!ok && err.contains("tool.tcp_mm"), "{err}");
}

#[test]
fn import_writes_a_valid_cell() {
    let series = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/datasets/ur10-ipa/Series_D");
    let out = std::env::temp_dir().join(format!("robocal-cli-{}-d.json", std::process::id()));
    let o = Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["import", "ur10-ipa", "--series", &format!("{series}:validation"), "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cell = robocal::domain::cell::parse_cell(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(cell.sessions[0].measurements.len(), 632);
    assert_eq!(cell.sessions[0].purpose, robocal::cell::Purpose::Validation);
    let (ok, _, err) = robocal(&["import", "ur10-ipa", "--series", "/nonexistent/Series_Q", "--out", "/tmp/x.json"]);
    assert!(!ok && err.contains("/nonexistent/Series_Q"), "{err}");
}

#[test]
fn simulate_is_deterministic_and_names_bad_effects() {
    let dir = std::env::temp_dir().join(format!("robocal-sim-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = |n: &str| dir.join(n).to_str().unwrap().to_string();
    let args = |o: &str| {
        vec![
            "simulate",
            "--seed",
            "7",
            "--id-per-ball",
            "10",
            "--validation",
            "20",
            "--effects",
            "cyclic:j=3:h=2,thermal",
            "--out",
            o,
        ]
        .into_iter()
        .map(String::from)
        .collect::<Vec<_>>()
    };
    for o in [out("a.json"), out("b.json")] {
        let a = args(&o);
        let (ok, _, err) = robocal(&a.iter().map(|s| s.as_str()).collect::<Vec<_>>());
        assert!(ok, "{err}");
    }
    assert!(std::fs::read(out("a.json")).unwrap() == std::fs::read(out("b.json")).unwrap());
    let cell = robocal::domain::cell::parse_cell(&std::fs::read_to_string(out("a.json")).unwrap()).unwrap();
    assert_eq!(cell.sessions[0].measurements.len(), 30);
    let (ok, _, err) = robocal(&["simulate", "--seed", "1", "--effects", "cyclic:j=9", "--out", &out("c.json")]);
    assert!(!ok && err.contains("--effects") && err.contains("joint number"), "{err}");
    let (ok, _, err) = robocal(&["simulate", "--seed", "1", "--epsilon-mm", "-1", "--out", &out("c.json")]);
    assert!(!ok && err.contains("--epsilon-mm"), "{err}");
    // The service's bounds, shared: beyond them the CLI asks for --force, with the run's cost, and
    // writes nothing.
    let big = ["simulate", "--seed", "1", "--id-per-ball", "100000", "--out", &out("big.json")];
    let (ok, _, err) = robocal(&big);
    assert!(!ok && err.starts_with("error: --id-per-ball: must be 1–2000, got 100000"), "{err}");
    assert!(err.contains("--force") && err.contains(" s and write ~"), "{err}");
    assert_eq!(status(&big), 2);
    assert!(!std::path::Path::new(&out("big.json")).exists());
    let (ok, _, err) = robocal(&["simulate", "--seed", "1", "--validation", "10001", "--out", &out("big.json")]);
    assert!(!ok && err.contains("--validation: must be 0–10000"), "{err}");
}

/// simulate → identify (DETMAX 75) → validate → study, through the binary: the identified values
/// land near the thesis's Table 5.1 (the simulator's truth) within their reported uncertainty, the
/// validation JSON carries the statistics in mm, and bad options name themselves.
#[test]
fn simulate_identify_validate_study() {
    let dir = std::env::temp_dir().join(format!("robocal-cli-id-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = |n: &str| dir.join(n).to_string_lossy().to_string();
    let (cell, params) = (path("cell.json"), path("params.json"));
    let out =
        Command::new(env!("CARGO_BIN_EXE_robocal")).args(["simulate", "--seed", "2", "--out", &cell]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    // Piped, a long command draws no progress bar.
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains('\r') && !err.contains("ETA"), "{err}");

    let out = Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["identify", &cell, "--select", "detmax", "--n", "75", "--seed", "3", "--out", &params])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&params).unwrap()).unwrap();
    let ps = doc["parameters"].as_array().unwrap();
    let identified: Vec<&Value> = ps.iter().filter(|p| p["status"] == "identified").collect();
    assert_eq!(identified.len(), 31);
    // Table 5.1 (the truth): a2 270.146 mm, d4 302.296 mm, c3 −5.522e-3 °/(N·m).
    for (name, truth) in [("a2", 270.146), ("d4", 302.296), ("c3", -5.522e-3)] {
        let p = ps.iter().find(|p| p["name"] == name).unwrap();
        let (v, sd) = (p["value"].as_f64().unwrap(), p["std"].as_f64().unwrap());
        assert!((v - truth).abs() <= 5.0 * sd, "{name}: {v} ± {sd} vs {truth}");
    }
    assert!(ps.iter().any(|p| p["status"] == "c1: no gravity torque on axis 1"));
    assert_eq!(doc["quality"]["selection"]["n"], 75);
    assert!(doc["quality"]["kappa_si"].as_f64().unwrap() > 1.0);

    // The set records the envelope of its measurements: compensation refuses a target beyond
    // it (exit 1, the target's own error) unless asked, and gives each target its predicted
    // uncertainty from the parameter covariance.
    let env = &doc["quality"]["envelope"];
    assert_eq!(env["n_measurements"], 75, "{env}");
    let j1 = nums(&env["joints_deg"][0]);
    let out_j1 = if j1[1] + 10.0 < 160.0 { j1[1] + 10.0 } else { j1[0] - 10.0 };
    let mid: Vec<f64> = (0..6).map(|j| nums(&env["joints_deg"][j]).iter().sum::<f64>() / 2.0).collect();
    let mut far = mid.clone();
    far[0] = out_j1;
    let targets = path("targets.json");
    std::fs::write(
        &targets,
        json!({"targets": [{"id": "in", "joints_deg": mid}, {"id": "out", "joints_deg": far}]}).to_string(),
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["compensate", "--params", &params, "--targets", &targets])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", String::from_utf8_lossy(&out.stderr));
    let c: Value = serde_json::from_slice(&out.stdout).unwrap();
    // Without a held-out validation only the covariance part is known: it is given, named for
    // what it includes, and no uncertainty_mm claims more (issue 25).
    let u = c["results"][0]["uncertainty"]["covariance_mm"].as_f64().unwrap();
    assert!(u > 1e-4 && u < 0.05, "{u}");
    assert!(c["results"][0].get("uncertainty_mm").is_none(), "{c}");
    assert!(c["results"][0]["uncertainty"]["unknown"][0].as_str().unwrap().starts_with("unexplained"), "{c}");
    let e = c["results"][1]["error"].as_str().unwrap();
    assert!(e.contains("outside the calibrated envelope") && e.contains("joint 1"), "{e}");
    assert_eq!(c["validity"]["envelope"]["n_measurements"], 75);
    let out = Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["compensate", "--params", &params, "--targets", &targets, "--allow-outside-envelope"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let c: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(c["results"][1]["notes"][0].as_str().unwrap().contains("outside the calibrated envelope"), "{c}");

    let (ok, v, err) = robocal(&["validate", &params, &cell]);
    assert!(ok, "{err}");
    let mean = v["mean_mm"].as_f64().unwrap();
    let nominal = v["nominal"]["mean_mm"].as_f64().unwrap();
    assert!(mean < 0.1 && nominal > 1.0, "calibrated {mean} mm, nominal {nominal} mm");
    for k in ["median_mm", "std_mm", "rms_mm", "p95_mm", "max_mm"] {
        assert!(v[k].as_f64().unwrap() > 0.0, "{k}");
    }
    for axis in ["x", "y", "z"] {
        assert!(v["per_axis"][axis]["std_mm"].as_f64().unwrap() > 0.0, "{axis}");
    }

    // On a terminal (or with --format text): the before/after table and per-axis statistics.
    let out = Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["validate", &params, &cell, "--format", "text"])
        .output()
        .unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    for row in ["nominal model", "calibrated model", "per axis", "distance to base", "distance to zone"] {
        assert!(text.contains(row), "{row}: {text}");
    }
    let line = text.lines().find(|l| l.trim_start().starts_with("calibrated model")).unwrap();
    let printed: f64 = line.split_whitespace().nth(3).unwrap().parse().unwrap();
    assert!((printed - mean).abs() <= 0.0005, "{line} vs mean {mean}");
    assert!(!text.trim_start().starts_with('{'));
    // A wrong robot is blamed on the two files, not on a --session nobody gave.
    let ur10 = path("ur10.json");
    let out = Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["nominal", "--robot", "ur10", "--out", &ur10])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (ok, _, err) = robocal(&["validate", &ur10, &cell]);
    assert!(!ok && !err.contains("--session") && err.contains("do not match") && err.contains("ur10"), "{err}");

    let study = path("study.json");
    let out = Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["study", &cell, "--sizes", "20,75", "--sets", "3", "--out", &study])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains('\r') && !err.contains("ETA"), "{err}");
    let st: Value = serde_json::from_str(&std::fs::read_to_string(&study).unwrap()).unwrap();
    assert_eq!(st["rows"].as_array().unwrap().len(), 2);
    assert_eq!(st["runs"].as_array().unwrap().len(), 6);
    for row in st["rows"].as_array().unwrap() {
        assert_eq!(row["refused"], 0);
        let q = nums(&row["mean_mm_quartiles"]);
        assert!(q.windows(2).all(|w| w[0] <= w[1]) && q[0] > 0.0, "{q:?}");
    }
    // A validation session that is not there is refused up front (status 2), not a table of NaN.
    let out = Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["study", &cell, "--sizes", "20", "--sets", "1", "--validation", "nope"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("no session 'nope'") && out.stdout.is_empty(), "{err}");

    // Cross-validation on the TriCal session, transfer to the tracker session (base refitted).
    let cv = path("cv.json");
    let out = Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["crossval", &cell, "--session", "trical-1", "--folds", "3", "--sizes", "60", "--draws", "2"])
        .args(["--transfer", "tracker-n1", "--out", &cv])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let cvd: Value = serde_json::from_str(&std::fs::read_to_string(&cv).unwrap()).unwrap();
    let kfold = cvd["kfold"].as_array().unwrap();
    assert_eq!(kfold.len(), 3, "before, geometry, geometry + compliance");
    assert_eq!(kfold[0]["model"], "before");
    let held = |k: &Value| k["pooled"]["mean_mm"].as_f64().unwrap();
    assert!(held(&kfold[0]) > 0.3 && held(&kfold[2]) < 0.02, "{kfold:?}");
    assert_eq!(kfold[2]["pooled"]["n"], 360);
    assert_eq!(cvd["sizes"].as_array().unwrap().len(), 3);
    let t = &cvd["transfer"][2];
    assert_eq!(t["session"], "tracker-n1");
    assert!(t["errors"]["mean_mm"].as_f64().unwrap() < 0.1, "{t}");

    for (args, name) in [
        (vec!["identify", &cell, "--n", "75", "--out", &params], "--n"),
        (vec!["identify", &cell, "--select", "random", "--out", &params], "--select"),
        (vec!["identify", &cell, "--kappa-limit", "0.5", "--out", &params], "--kappa-limit"),
        (vec!["identify", &cell, "--model", "+warp", "--out", &params], "--model"),
        (vec!["validate", &params, &cell, "--session", "nope"], "--session"),
        (vec!["study", &cell, "--sizes", "30..20"], "--sizes"),
        (vec!["study", &cell, "--sets", "0"], "--sets"),
        (vec!["identify", &cell, "--only", "bass", "--out", &params], "'bass'"),
        (vec!["identify", &cell, "--start", "/nonexistent.json", "--out", &params], "/nonexistent.json"),
        (vec!["crossval", &cell, "--session", "nope"], "no session named 'nope'"),
        (vec!["crossval", &cell, "--session", "trical-1", "--sizes", "x"], "--sizes"),
        (vec!["crossval", &cell, "--session", "trical-1", "--transfer-kappa-limit", "0"], "--transfer-kappa-limit"),
        (vec!["crossval", &cell, "--session", "trical-1", "--exclude", "trical-1"], "--exclude"),
        (
            vec!["crossval", &cell, "--session", "trical-1", "--exclude", "tracker-n1:0"],
            "'tracker-n1' is not one of the sessions split",
        ),
        (vec!["crossval", &cell, "--session", "trical-1", "--exclude", "trical-1:100000"], "not 100000"),
    ] {
        let (ok, _, err) = robocal(&args);
        assert!(!ok && err.contains(name), "{args:?}: {err}");
    }
}

/// `robocal diagnose`: the JSON report with its top-level keys, the verdict schema, the accepted
/// parameter set; accepting when nothing is named fails with the verdict in the message; bad
/// options name their flag; `bench-diagnosis` runs a case.
#[test]
fn diagnose_names_accepts_and_refuses() {
    let dir = std::env::temp_dir().join(format!("robocal-cli-diag-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = |n: &str| dir.join(n).to_string_lossy().to_string();
    for (name, effects) in [("bl", "backlash:j=2:deg=0.01"), ("none", "")] {
        let args = ["simulate", "--seed", "2", "--id-per-ball", "50", "--validation", "200", "--effects", effects];
        let (ok, _, err) = robocal(&[&args[..], &["--out", &p(&format!("{name}.json"))]].concat());
        assert!(ok, "{err}");
        let (ok, _, err) = robocal(&["identify", &p(&format!("{name}.json")), "--out", &p(&format!("{name}-p.json"))]);
        assert!(ok, "{err}");
    }
    // The report on stdout (the accepted file's note on stderr).
    let (ok, d, err) = robocal(&["diagnose", &p("bl-p.json"), &p("bl.json"), "--accept", &p("acc.json")]);
    assert!(ok, "{err}");
    assert!(err.contains("acc.json"), "{err}");
    for key in ["verdict", "decomposition", "where", "candidates", "shrink"] {
        assert!(d.get(key).is_some(), "missing top-level key {key}");
    }
    assert_eq!(d["verdict"]["status"], "named");
    let e = &d["verdict"]["effects"][0];
    assert_eq!((e["name"].as_str(), e["joint"].as_u64()), (Some("backlash"), Some(2)));
    let deg = e["estimate"].as_f64().unwrap();
    assert!((deg - 0.01).abs() < 0.002 && e["std"].as_f64().unwrap() > 0.0, "{e}");
    let shrink = d["shrink"].as_array().unwrap();
    assert_eq!(shrink.len(), 2);
    for s in shrink {
        for k in ["model", "mean_mm", "rms_mm", "p95_mm", "max_mm"] {
            assert!(s.get(k).is_some(), "shrink entry without {k}");
        }
    }
    assert!(shrink[1]["mean_mm"].as_f64() < shrink[0]["mean_mm"].as_f64());
    let acc: Value = serde_json::from_str(&std::fs::read_to_string(p("acc.json")).unwrap()).unwrap();
    assert!(acc["parameters"].as_array().unwrap().iter().any(|q| q["name"] == "backlash2"));
    // Nothing to accept.
    let (ok, _, err) = robocal(&["diagnose", &p("none-p.json"), &p("none.json"), "--out", &p("none-d.json")]);
    assert!(ok, "{err}");
    let report: Value = serde_json::from_str(&std::fs::read_to_string(p("none-d.json")).unwrap()).unwrap();
    assert_eq!(report["verdict"]["status"], "none");
    let (ok, _, err) = robocal(&["diagnose", &p("none-p.json"), &p("none.json"), "--accept", &p("no.json")]);
    assert!(!ok && err.contains("--accept") && err.contains("none"), "{err}");
    let (ok, _, err) = robocal(&["diagnose", &p("none-p.json"), &p("none.json"), "--folds", "1"]);
    assert!(!ok && err.contains("--folds"), "{err}");
    let (ok, _, err) = robocal(&["diagnose", &p("none-p.json"), &p("none.json"), "--validation", "nope"]);
    assert!(!ok && err.contains("nope"), "{err}");
    // The core names a refused option by its field; the command line says which flag.
    let (ok, _, err) = robocal(&["identify", &p("none.json"), "--fix", "a2,nonsense", "--out", &p("no-set.json")]);
    assert!(!ok && err.contains("error: --fix: 'nonsense' is not a parameter of this problem"), "{err}");
    let (ok, _, err) = robocal(&["crossval", &p("none.json"), "--session", "nope", "--folds", "3"]);
    assert!(!ok && err.contains("error: --session: no session named 'nope' in the cell"), "{err}");
    let out = Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["bench-diagnosis", "--seeds", "1", "--cases", "cyclic j5 h1 (no logs)", "--markdown"])
        .output()
        .expect("runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let out = String::from_utf8(out.stdout).unwrap();
    // One case row, its confusion row (named: cyclic), and the summary table.
    assert!(out.contains("| cyclic j5 h1 (no logs) | `cyclic"), "{out}");
    assert!(out.contains("| cyclic j5 h1 (no logs) | 1 |"), "{out}");
    assert!(out.contains("| top-1 naming, separable effects (right kind, joint, harmonic) | 1/1 |"), "{out}");
    let (ok, _, err) = robocal(&["bench-diagnosis", "--cases", "no such case"]);
    assert!(!ok && err.contains("--cases"), "{err}");
}

/// Three reflectors at the same poses through the binary: `simulate --reflector-plate` marks its
/// sessions measured and numbers the stops; `crossval --session a,b,c` splits by pose and
/// reports pooled and per-reflector figures (JSON and text); `validate` reports per session.
#[test]
fn reflector_plate_crossval_and_validate_per_session() {
    let dir = std::env::temp_dir().join(format!("robocal-cli-plate-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = |n: &str| dir.join(n).to_string_lossy().to_string();
    let (cell, params, cv) = (path("plate.json"), path("params.json"), path("cv.json"));
    let sim = ["simulate", "--seed", "4", "--id-per-ball", "20", "--validation", "60", "--reflector-plate"];
    let (ok, _, err) = robocal(&[&sim[..], &["--out", &cell]].concat());
    assert!(ok, "{err}");
    let c: Value = serde_json::from_str(&std::fs::read_to_string(&cell).unwrap()).unwrap();
    let sessions = c["sessions"].as_array().unwrap();
    assert_eq!(sessions.len(), 4);
    assert!(sessions.iter().all(|s| s["order"] == "measured"));
    assert_eq!(sessions[0]["measurements"][5]["sequence"], 5);
    let reflectors = "tracker-n1,tracker-n2,tracker-n3";

    let out = Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["crossval", &cell, "--session", reflectors, "--folds", "3", "--sizes", "15", "--draws", "2"])
        .args(["--model=", "--out", &cv])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("at 60 poses, split by pose") && text.contains("per session"), "{text}");
    let d: Value = serde_json::from_str(&std::fs::read_to_string(&cv).unwrap()).unwrap();
    assert_eq!(d["session"], reflectors);
    assert_eq!(d["poses"], 60);
    let pooled = &d["kfold"][1]["pooled"];
    let per: Vec<&Value> = pooled["per_session"].as_array().unwrap().iter().collect();
    assert_eq!(
        per.iter().map(|p| p["session"].as_str().unwrap()).collect::<Vec<_>>(),
        reflectors.split(',').collect::<Vec<_>>()
    );
    let n: u64 = per.iter().map(|p| p["n"].as_u64().unwrap()).sum();
    assert_eq!(n, pooled["n"].as_u64().unwrap());
    assert_eq!(n, d["measurements"].as_u64().unwrap());
    assert_eq!(d["sizes"][1]["per_session_mean_mm_over_draws"].as_array().unwrap().len(), 3);

    let (ok, _, err) = robocal(&["identify", &cell, "--sessions", "trical-1", "--out", &params]);
    assert!(ok, "{err}");
    let (ok, v, err) = robocal(&["validate", &params, &cell]);
    assert!(ok, "{err}");
    let rows = v["per_session"].as_array().unwrap();
    assert_eq!(rows.len(), 3);
    assert_eq!(rows.iter().map(|r| r["n"].as_u64().unwrap()).sum::<u64>(), v["n"].as_u64().unwrap());
    assert!(rows.iter().all(|r| r["purpose"] == "validation" && r["mean_mm"].as_f64().unwrap() < 0.1));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A plate of three reflectors imported from a tracker's files, each reflector's TCP unknown and
/// identified: `validate` predicts every reflector's readings with its own identified TCP, so each
/// reads what the fit's residual says (it once predicted reflectors 2 and 3 with reflector 1's TCP
/// and read 150 mm), in-sample as they are.
#[test]
fn validate_predicts_each_reflector_with_its_own_identified_tcp() {
    let dir = std::env::temp_dir().join(format!("robocal-cli-tcps-{}", std::process::id()));
    let cell = reflector_plate_cell(&dir, "3");
    let params = dir.join("params.json").to_string_lossy().to_string();
    let (ok, _, err) = robocal(&["identify", &cell, "--out", &params]);
    assert!(ok, "{err}");
    let p: Value = serde_json::from_str(&std::fs::read_to_string(&params).unwrap()).unwrap();
    let fit_rms = p["quality"]["rms_residual_mm"].as_f64().unwrap();
    let tools = p["quality"]["tools"].as_array().unwrap();
    assert_eq!(tools.len(), 3, "one TCP per reflector");
    for k in 1..=3 {
        let session = format!("reflector-{k}");
        let (ok, v, err) = robocal(&["validate", &params, &cell, "--session", &session]);
        assert!(ok, "{err}");
        assert_eq!(v["held_out"], false, "{session} was fitted on: in-sample");
        let rms = v["rms_mm"].as_f64().unwrap();
        // Each reflector's share of the pooled residual: within a third of it.
        assert!((rms / fit_rms - 1.0).abs() < 0.35, "{session}: rms {rms} mm against the fit's {fit_rms} mm");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A three-reflector tracker run of `simulate-tracker` (150 poses), imported as the README says;
/// returns the cell file's path.
fn reflector_plate_cell(dir: &std::path::Path, seed: &str) -> String {
    reflector_plate_cell_of(dir, seed, "150")
}

/// [`reflector_plate_cell`] with `poses` poses.
fn reflector_plate_cell_of(dir: &std::path::Path, seed: &str, poses: &str) -> String {
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir).unwrap();
    let path = |n: &str| dir.join(n).to_string_lossy().to_string();
    let twin = path("twin");
    let (ok, _, err) = robocal(&["simulate-tracker", "--seed", seed, "--poses", poses, "--out-dir", &twin]);
    assert!(ok, "{err}");
    let file = |n: &str| format!("{twin}/run-{n}.txt");
    let cell = path("cell.json");
    let mut args = vec!["import", "three-reflector", "--robot", "irb120", "--joints"];
    let (joints, smr) = (file("joints"), [file("smr1"), file("smr2"), file("smr3")]);
    args.push(&joints);
    for f in &smr {
        args.extend(["--positions", f.as_str()]);
    }
    args.extend(["--out", &cell]);
    let (ok, _, err) = robocal(&args);
    assert!(ok, "{err}");
    cell
}

/// Under the Huber loss the residual RMS a fit reports is the residual as measured, the one its
/// ratio to the instrument's noise divides: it once reported the rows the loss had weighted
/// (0.017 mm at `--huber 0.01`, beside "6.0 times the 0.031 mm the instrument predicts").
#[test]
fn a_huber_fit_reports_the_residual_its_ratio_divides() {
    let dir = std::env::temp_dir().join(format!("robocal-cli-huber-{}", std::process::id()));
    let cell = reflector_plate_cell(&dir, "2");
    for huber in ["0.05", "2.5"] {
        let params = dir.join(format!("p{huber}.json")).to_string_lossy().to_string();
        let (ok, _, err) = robocal(&["identify", &cell, "--huber", huber, "--out", &params]);
        assert!(ok, "{err}");
        let p: Value = serde_json::from_str(&std::fs::read_to_string(&params).unwrap()).unwrap();
        let q = &p["quality"];
        let (rms, expected) = (q["rms_residual_mm"].as_f64().unwrap(), q["expected_rms_mm"].as_f64().unwrap());
        let ratio = q["residual_ratio"].as_f64().unwrap();
        // The ratio leaves gross outliers out (none here): equal to the rounding of the mm figures.
        assert!((rms / expected / ratio - 1.0).abs() < 0.01, "huber {huber}: {rms} / {expected} mm against {ratio}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Positions in centimetres, inches or metres where the file says millimetres are refused before
/// they are fitted, with the unit named: fitted, they made a robot a tenth of its size (a2 27 mm
/// for 270 mm) with a residual below the instrument's noise, and exit 0.
#[test]
fn positions_in_another_unit_are_refused_with_the_unit_named() {
    let dir = std::env::temp_dir().join(format!("robocal-cli-units-{}", std::process::id()));
    let cell = reflector_plate_cell(&dir, "4");
    let text = std::fs::read_to_string(&cell).unwrap();
    for (unit, k) in [("cm", 0.1), ("in", 1.0 / 25.4), ("m", 1e-3), ("x10", 10.0)] {
        let mut c: Value = serde_json::from_str(&text).unwrap();
        scale_field(&mut c, "position_mm", k);
        let scaled = dir.join(format!("cell-{unit}.json"));
        std::fs::write(&scaled, c.to_string()).unwrap();
        let params = dir.join(format!("params-{unit}.json"));
        let out = Command::new(env!("CARGO_BIN_EXE_robocal"))
            .arg("identify")
            .arg(&scaled)
            .arg("--out")
            .arg(&params)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{unit}: {err}");
        assert!(err.contains("position_mm") && !params.exists(), "{unit}: {err}");
        // The factor it states is the scale's (the reflectors' offsets from the flange, not
        // scaled by the robot's joints, move it a little).
        let stated: f64 = err.split(" times)").next().unwrap().rsplit('(').next().unwrap().parse().expect(&err);
        assert!((stated / k - 1.0).abs() < 0.2, "{unit}: states {stated} for {k}");
    }
    // Joints in radians, written as degrees: the robot hardly moves at them, so the positions'
    // check alone could not judge; the readings are named, with the conversion.
    let mut c: Value = serde_json::from_str(&text).unwrap();
    scale_field(&mut c, "joints_deg", std::f64::consts::PI / 180.0);
    let radians = dir.join("cell-rad.json");
    std::fs::write(&radians, c.to_string()).unwrap();
    let params = dir.join("params-rad.json").to_string_lossy().to_string();
    let (ok, _, err) = robocal(&["identify", &radians.to_string_lossy(), "--out", &params]);
    assert!(!ok && err.contains("radians, not degrees (joints_deg)") && err.contains("57.2958"), "{err}");
    let params = dir.join("params.json").to_string_lossy().to_string();
    let (ok, _, err) = robocal(&["identify", &cell, "--out", &params]);
    assert!(ok, "the file as written: {err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `diagnose --exclude` leaves an outlier out of every fit and every test, as `identify
/// --exclude` leaves it out of the set: a reading 20 mm off, fitted and scored, makes the held-out
/// maximum 20 mm; excluded, it is neither, and a bad exclusion is refused naming the option. The
/// set records what its identification left out, and `diagnose` leaves that out unasked.
#[test]
fn diagnose_leaves_out_the_readings_it_is_told_to() {
    let dir = std::env::temp_dir().join(format!("robocal-cli-diag-exclude-{}", std::process::id()));
    let cell = reflector_plate_cell_of(&dir, "5", "60");
    let mut c: Value = serde_json::from_str(&std::fs::read_to_string(&cell).unwrap()).unwrap();
    let p = &mut c["sessions"][0]["measurements"][7]["position_mm"][0];
    *p = Value::from(p.as_f64().unwrap() + 20.0);
    let name = c["sessions"][0]["name"].as_str().unwrap().to_string();
    let outlier = format!("{name}:7");
    let bad = dir.join("bad.json").to_string_lossy().to_string();
    std::fs::write(&bad, c.to_string()).unwrap();
    let params = dir.join("params.json").to_string_lossy().to_string();
    let (ok, _, err) = robocal(&["identify", &bad, "--exclude", &outlier, "--out", &params]);
    assert!(ok, "{err}");
    // The same set without its record of what it left out (a file of an earlier version).
    let mut unrecorded: Value = serde_json::from_str(&std::fs::read_to_string(&params).unwrap()).unwrap();
    assert_eq!(unrecorded["quality"]["excluded"][0]["indices"], serde_json::json!([7]), "recorded");
    unrecorded["quality"].as_object_mut().unwrap().remove("excluded");
    let blind = dir.join("unrecorded.json").to_string_lossy().to_string();
    std::fs::write(&blind, unrecorded.to_string()).unwrap();
    let diagnose = |set: &str, extra: &[&str]| {
        let mut args = vec!["diagnose", set, &bad, "--validation", "none", "--threads", "2"];
        args.extend_from_slice(extra);
        let (ok, d, err) = robocal(&args);
        assert!(ok, "{err}");
        let start = &d["shrink"][0];
        (start["n"].as_u64().unwrap(), start["max_mm"].as_f64().unwrap(), d["sessions"]["excluded"].clone())
    };
    let (n_all, max_all, none) = diagnose(&blind, &[]);
    let (n, max, named) = diagnose(&blind, &["--exclude", &outlier]);
    assert!(max_all > 15.0 && none.is_null(), "the outlier scored: {max_all} mm");
    assert!(max < 2.0 && n < n_all, "excluded: {n} readings (of {n_all}), max {max} mm");
    let listed = serde_json::json!([{"session": name, "index": 7}]);
    assert_eq!(named, listed);
    assert_eq!(diagnose(&params, &[]), (n, max, listed), "the set's record leaves it out unasked");
    let (ok, _, err) = robocal(&["diagnose", &params, &bad, "--exclude", &format!("{name}:600")]);
    assert!(!ok && err.contains("exclude") && err.contains("600"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Multiply every number of every `field` array in `v` by `k`.
fn scale_field(v: &mut Value, field: &str, k: f64) {
    match v {
        Value::Object(m) => {
            for (key, x) in m.iter_mut() {
                match x {
                    Value::Array(p) if key == field => {
                        p.iter_mut().for_each(|c| *c = Value::from(c.as_f64().unwrap() * k))
                    }
                    x => scale_field(x, field, k),
                }
            }
        }
        Value::Array(a) => a.iter_mut().for_each(|x| scale_field(x, field, k)),
        _ => {}
    }
}
