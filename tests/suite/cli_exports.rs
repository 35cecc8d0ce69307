//! `robocal export` and `robocal drift`: the formats, the exit statuses (0 done, 1 ran with failed
//! targets, 2 refused) and the errors naming the argument.

use std::process::{Command, Output};

const TABLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/irb120_table_5_1.json");
const TARGETS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/targets.json");

fn robocal(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_robocal")).args(args).output().expect("runs")
}

fn text(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

#[test]
fn every_format_from_the_command_line() {
    let json = robocal(&["export", "--format", "json", "--params", TABLE]);
    assert_eq!(json.status.code(), Some(0), "{}", String::from_utf8_lossy(&json.stderr));
    let doc = robocal::domain::ParameterSetDoc::from_json(&text(&json)).unwrap();
    let original = robocal::domain::ParameterSetDoc::from_json(&std::fs::read_to_string(TABLE).unwrap()).unwrap();
    assert_eq!(doc.set.values, original.set.values);

    let csv = robocal(&["export", "--format", "csv-dh", "--params", TABLE]);
    assert_eq!(csv.status.code(), Some(0));
    let csv = text(&csv);
    assert!(csv.contains("robot irb120, parameter-set file") && csv.contains("modified DH (Craig)"), "{csv}");
    assert_eq!(csv.lines().filter(|l| !l.starts_with('#')).count(), 1 + 8);

    let urdf = robocal(&["export", "--format", "urdf", "--params", TABLE]);
    assert_eq!(urdf.status.code(), Some(0));
    assert_eq!(urdf_rs::read_from_string(&text(&urdf)).unwrap().joints.len(), 8);

    // The README's targets include one out of reach on purpose: the module is written without it,
    // and the status is 1.
    let out = std::env::temp_dir().join(format!("robocal-export-{}.mod", std::process::id()));
    let rapid = robocal(&[
        "export",
        "--format",
        "rapid",
        "--params",
        TABLE,
        "--targets",
        TARGETS,
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(rapid.status.code(), Some(1), "{}", String::from_utf8_lossy(&rapid.stderr));
    assert!(String::from_utf8_lossy(&rapid.stderr).contains("too-far"));
    let module = std::fs::read_to_string(&out).unwrap();
    assert!(module.starts_with("MODULE robocal_irb120_table_5_1\n"), "{module}");
    assert!(module.contains("'too-far'") && module.contains("CONST jointtarget j_above_ball_1:=[["), "{module}");
    let _ = std::fs::remove_file(&out);

    // Refused input: exit 2, the argument named.
    for (args, named) in [
        (vec!["export", "--format", "step", "--params", TABLE], "--format"),
        (vec!["export", "--format", "rapid", "--params", TABLE], "--targets"),
        (vec!["export", "--format", "urdf", "--params", TABLE, "--targets", TARGETS], "--targets"),
    ] {
        let o = robocal(&args);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(String::from_utf8_lossy(&o.stderr).contains(named), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
    }
}

/// Two files, a2 identified in both (270.146 ± 0.003 and 270.140 ± 0.004 mm): by hand the change
/// is 0.006 mm against a combined σ of 0.005 mm, 1.2σ.
#[test]
fn drift_between_two_files() {
    let write = |name: &str, a2: f64, std: f64| {
        let mut v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(TABLE).unwrap()).unwrap();
        for p in v["parameters"].as_array_mut().unwrap() {
            if p["name"] == "a2" {
                p["value"] = a2.into();
                p["std"] = std.into();
                p["status"] = "identified".into();
            }
        }
        let path = std::env::temp_dir().join(format!("robocal-drift-{}-{name}.json", std::process::id()));
        std::fs::write(&path, v.to_string()).unwrap();
        path
    };
    let (a, b) = (write("a", 270.146, 0.003), write("b", 270.140, 0.004));
    let o = robocal(&["drift", a.to_str().unwrap(), b.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_str(&text(&o)).unwrap();
    assert_eq!(v["robot"], "irb120");
    assert_eq!(v["moved"], 1);
    let p = &v["parameters"][0];
    assert_eq!((p["name"].as_str(), p["unit"].as_str()), (Some("a2"), Some("mm")));
    assert!((p["change"].as_f64().unwrap() - 0.006).abs() < 1e-9);
    assert!((p["n_sigma"].as_f64().unwrap() - 1.2).abs() < 1e-6);
    let o = robocal(&["drift", a.to_str().unwrap(), "missing.json"]);
    assert_eq!(o.status.code(), Some(2));
    let _ = (std::fs::remove_file(a), std::fs::remove_file(b));
}
