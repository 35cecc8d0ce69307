//! Plausibility at the door (issue 25, item 5): no job panics on any stored input. Extreme finite
//! values — up to ±1e308, at and just past the bounds of `domain::limits`, the smallest
//! subnormal — are put into one field of a stored cell (a measurement's joints, position,
//! rotation, time, temperature, σ; the base guess; a session's tool; the artefact; a custom
//! robot's table) and every job kind is run on it as a worker runs it (`jobs::run::compute`):
//! it must answer — a result, or an error naming the field — and never panic. The refusals name
//! where the value is.

use std::sync::OnceLock;

use proptest::prelude::*;
use robocal::app::cells::StoredIndices;
use robocal::db::records::RobotRow;
use robocal::domain::cell::CellFile;
use robocal::domain::robot::RobotSpec;
use robocal::jobs::JobError;
use robocal::jobs::requests::{DiagnosisJob, IdentificationRequest, PosePlanRequest, ValidationJob};
use robocal::jobs::run::{DiagnosisSessions, Inputs, compute};
use robocal::sim::simulate::{SimulateOptions, simulate};
use serde_json::{Value, json};

/// A small virtual cell (10 TriCal candidates per ball, 30 tracker poses) and a set identified
/// from it.
fn base() -> &'static (CellFile, String) {
    static B: OnceLock<(CellFile, String)> = OnceLock::new();
    B.get_or_init(|| {
        let s = simulate(&SimulateOptions { seed: 11, id_per_ball: 12, validation: 30, ..Default::default() }).unwrap();
        let opts = robocal::identify::IdentifyOptions {
            selection: robocal::identify::MeasurementSelection {
                sessions: vec!["trical-1".into()],
                ..Default::default()
            },
            ..Default::default()
        };
        let (_, doc) = robocal::domain::identification::run_identification(&s.cell, opts, None, &|| ()).unwrap();
        (CellFile::from_cell(&s.cell), doc.to_json_pretty())
    })
}

fn extreme() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(1e308),
        Just(-1e308),
        Just(1e160),
        Just(-1e160),
        Just(1e9),
        Just(-1e9),
        Just(100_000.0),
        Just(100_000.5),
        Just(-100_000.0),
        Just(10_000.5),
        Just(5_000.5),
        Just(720.5),
        Just(1e10 + 1.0),
        Just(150.5),
        Just(-0.0),
        Just(5e-324),
        Just(f64::MAX),
        (-1e12f64..1e12),
        any::<f64>().prop_filter("finite", |v| v.is_finite()),
    ]
}

/// Which field of the cell gets the value.
#[derive(Clone, Debug)]
enum Field {
    Joint { session: usize, index: usize, joint: usize },
    Position { index: usize, axis: usize },
    Rotation { index: usize, axis: usize },
    Time { session: usize, index: usize },
    Temperature { session: usize, index: usize },
    Sigma { index: usize, axis: usize },
    BaseGuess(usize),
    ToolTcp { session: usize, axis: usize },
    ToolMass { session: usize },
    ToolCom { session: usize, axis: usize },
    Artefact(usize),
    Robot { joint: usize, field: usize },
    Gravity(usize),
}

fn field() -> impl Strategy<Value = Field> {
    prop_oneof![
        (0..4usize, 0..8usize, 0..6usize).prop_map(|(session, index, joint)| Field::Joint { session, index, joint }),
        (0..10usize, 0..3usize).prop_map(|(index, axis)| Field::Position { index, axis }),
        (0..10usize, 0..3usize).prop_map(|(index, axis)| Field::Rotation { index, axis }),
        (0..4usize, 0..8usize).prop_map(|(session, index)| Field::Time { session, index }),
        (0..4usize, 0..8usize).prop_map(|(session, index)| Field::Temperature { session, index }),
        (0..10usize, 0..3usize).prop_map(|(index, axis)| Field::Sigma { index, axis }),
        (0..6usize).prop_map(Field::BaseGuess),
        (0..4usize, 0..3usize).prop_map(|(session, axis)| Field::ToolTcp { session, axis }),
        (0..4usize).prop_map(|session| Field::ToolMass { session }),
        (0..4usize, 0..3usize).prop_map(|(session, axis)| Field::ToolCom { session, axis }),
        (0..4usize).prop_map(Field::Artefact),
        (0..6usize, 0..8usize).prop_map(|(joint, field)| Field::Robot { joint, field }),
        (0..3usize).prop_map(Field::Gravity),
    ]
}

/// The cell as JSON with `v` put into `f` (tracker measurements for positions and σ).
fn mutated(f: &Field, v: f64) -> Value {
    let (cell, _) = base();
    let mut c = serde_json::to_value(cell).unwrap();
    let n_sessions = c["sessions"].as_array().unwrap().len();
    let s = |i: usize| i % n_sessions;
    // sessions[0] is trical-1, the others the tracker sessions.
    let tracker = 1;
    let put = |c: &mut Value, session: usize, index: usize, edit: &dyn Fn(&mut Value)| {
        let len = c["sessions"][session]["measurements"].as_array().unwrap().len();
        edit(&mut c["sessions"][session]["measurements"][index % len]);
    };
    match *f {
        Field::Joint { session, index, joint } => {
            put(&mut c, s(session), index, &|x| x["joints_deg"][joint] = json!(v))
        }
        Field::Position { index, axis } => put(&mut c, tracker, index, &|x| x["position_mm"][axis] = json!(v)),
        Field::Rotation { index, axis } => put(&mut c, tracker, index, &|x| {
            let mut r = [0.0, 0.0, 0.0];
            r[axis] = v;
            x["rotation_deg"] = json!(r);
        }),
        Field::Time { session, index } => put(&mut c, s(session), index, &|x| x["time_s"] = json!(v)),
        Field::Temperature { session, index } => put(&mut c, s(session), index, &|x| x["temperature_c"] = json!(v)),
        Field::Sigma { index, axis } => put(&mut c, tracker, index, &|x| {
            let mut sg = [0.01, 0.01, 0.01];
            sg[axis] = v;
            x["sigma_mm"] = json!(sg);
        }),
        Field::BaseGuess(k) => {
            let key = ["x_mm", "y_mm", "z_mm", "a_deg", "b_deg", "c_deg"][k];
            c["base_guess"][key] = json!(v);
        }
        Field::ToolTcp { session, axis } => c["sessions"][s(session)]["tool"]["tcp_mm"][axis] = json!(v),
        Field::ToolMass { session } => c["sessions"][s(session)]["tool"]["mass_kg"] = json!(v),
        Field::ToolCom { session, axis } => c["sessions"][s(session)]["tool"]["com_mm"][axis] = json!(v),
        Field::Artefact(k) => {
            if k < 3 {
                c["artefact"]["distances_mm"][["d12", "d13", "d23"][k]] = json!(v);
            } else {
                c["artefact"]["ball_diameter_mm"] = json!(v);
            }
        }
        Field::Robot { joint, field } => {
            let model = robocal::kinematics::Preset::Irb120.model();
            let mut robot = match RobotSpec::from_model(&robocal::kinematics::RobotModel { preset: None, ..model }) {
                RobotSpec::Custom(c) => serde_json::to_value(c).unwrap(),
                RobotSpec::Preset(_) => unreachable!(),
            };
            let key =
                ["alpha_deg", "a_mm", "theta_deg", "d_mm", "mass_kg", "limits_deg", "limits_deg", "com_mm"][field];
            match field {
                5 => robot["joints"][joint]["limits_deg"][0] = json!(v),
                6 => robot["joints"][joint]["limits_deg"][1] = json!(v),
                7 => robot["joints"][joint]["com_mm"][2] = json!(v),
                _ => robot["joints"][joint][key] = json!(v),
            }
            c["robot"] = robot;
        }
        Field::Gravity(k) => {
            let model = robocal::kinematics::Preset::Irb120.model();
            let mut robot = match RobotSpec::from_model(&robocal::kinematics::RobotModel { preset: None, ..model }) {
                RobotSpec::Custom(c) => serde_json::to_value(c).unwrap(),
                RobotSpec::Preset(_) => unreachable!(),
            };
            robot["gravity_mps2"][k] = json!(v);
            c["robot"] = robot;
        }
    }
    c
}

fn robot_row(cell: &CellFile) -> RobotRow {
    RobotRow {
        id: "r".into(),
        name: "r".into(),
        model_json: cell.robot.to_string(),
        base_guess_json: cell.base_guess.as_ref().map(|b| serde_json::to_string(b).unwrap()),
        active_parameter_set_id: None,
        created_at: "2026-01-01T00:00:00Z".into(),
    }
}

/// An error must say what is wrong: a refusal names where the value is (a field path, or the
/// session and measurement); a numerical failure says why; none is an internal error (a 500).
fn names_the_place(e: &JobError) {
    match e {
        JobError::Invalid { field, detail } | JobError::Unknown { field, detail } => assert!(
            field.is_some() || detail.contains("measurement") || detail.contains("sessions["),
            "a refusal that names no place: {e:?}"
        ),
        JobError::Numerical { detail, .. } => assert!(!detail.is_empty()),
        JobError::Internal(why) => panic!("an internal error: {why}"),
        // Storage faults are the disk's, not the input's: none happens on these runs.
        JobError::Storage(_) | JobError::Busy | JobError::NotStored(_) => {
            panic!("a storage fault on an input test: {e:?}")
        }
    }
}

fn tracker_names(cell: &CellFile) -> Vec<String> {
    cell.sessions.iter().filter(|s| s.name.starts_with("tracker")).map(|s| s.name.clone()).collect()
}

fn run_all(c: &Value, diagnosis: bool) {
    let cell: CellFile = match serde_json::from_value(c.clone()) {
        Ok(cell) => cell,
        Err(_) => return, // not JSON the service would store (e.g. a negative where u64 is asked)
    };
    let (_, set_json) = base();
    let progress = |_: f64, _: &'static str| {};
    // Identification.
    let request: IdentificationRequest = serde_json::from_value(json!({"sessions": ["trical-1"]})).unwrap();
    let out = compute(
        Inputs::Identification {
            robot: robot_row(&cell),
            request,
            cell: cell.clone(),
            indices: StoredIndices::default(),
            excluded: 0,
            session_names: vec!["trical-1".into()],
        },
        &progress,
    );
    if let Err(e) = &out {
        names_the_place(e);
    }
    // Validation.
    let job: ValidationJob =
        serde_json::from_value(json!({"parameter_set_id": "s", "sessions": tracker_names(&cell), "residuals": true}))
            .unwrap();
    let out = compute(
        Inputs::Validation {
            job,
            set_json: set_json.clone(),
            set_sessions: vec!["trical-1".into()],
            cell: cell.clone(),
            indices: StoredIndices::default(),
            session_names: tracker_names(&cell),
        },
        &progress,
    );
    if let Err(e) = &out {
        names_the_place(e);
    }
    // Pose plan: the robot's base guess, the first session's tool, the artefact, as stored.
    if let (Some(b), Some(artefact)) = (&cell.base_guess, &cell.artefact)
        && let Ok(base) = b.to_si("base_guess")
        && let Ok(model) = RobotSpec::from_json_value(&cell.robot).and_then(|r| r.to_model())
    {
        let request: PosePlanRequest = serde_json::from_value(json!({
            "artefact_id": "a", "tool": cell.sessions[0].tool, "per_ball": 3, "validation": 3
        }))
        .unwrap();
        let out = compute(Inputs::PosePlan { base, model, request, artefact: artefact.clone() }, &progress);
        if let Err(e) = &out {
            names_the_place(e);
        }
    }
    if diagnosis {
        let job: DiagnosisJob = serde_json::from_value(json!({"parameter_set_id": "s", "folds": 2})).unwrap();
        let out = compute(
            Inputs::Diagnosis {
                job,
                set_json: set_json.clone(),
                cell: cell.clone(),
                indices: StoredIndices::default(),
                sessions: DiagnosisSessions {
                    identification: vec!["trical-1".into()],
                    validation: tracker_names(&cell),
                },
            },
            &progress,
        );
        if let Err(e) = &out {
            names_the_place(e);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, failure_persistence: None, ..ProptestConfig::default() })]

    /// Identification, validation and pose plan on a cell with one extreme value: an answer,
    /// never a panic.
    #[test]
    fn no_job_panics_on_an_extreme_stored_value(f in field(), v in extreme()) {
        run_all(&mutated(&f, v), false);
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, failure_persistence: None, ..ProptestConfig::default() })]

    /// The diagnosis too (fewer cases: each runs held-out refits).
    #[test]
    fn no_diagnosis_panics_on_an_extreme_stored_value(f in field(), v in extreme()) {
        run_all(&mutated(&f, v), true);
    }
}

/// The issue's cases, by hand: each refused naming its field, at the door of a cell file.
#[test]
fn the_issues_values_are_refused_naming_the_field() {
    let cases: [(Field, f64, &str); 8] = [
        (Field::Position { index: 0, axis: 0 }, 1e160, "position_mm[0]"),
        (Field::Position { index: 0, axis: 1 }, 1e308, "position_mm[1]"),
        (Field::Time { session: 0, index: 0 }, -1e308, "time_s"),
        (Field::BaseGuess(0), 1e308, "base_guess.x_mm"),
        (Field::BaseGuess(3), 1e9, "base_guess.a_deg"),
        (Field::Robot { joint: 2, field: 3 }, 1e308, "robot.joints[2].d_mm"),
        (Field::Robot { joint: 1, field: 6 }, 1e9, "robot.joints[1].limits_deg[1]"),
        (Field::Gravity(2), 1e308, "robot.gravity_mps2[2]"),
    ];
    for (f, v, path) in cases {
        let cell: CellFile = serde_json::from_value(mutated(&f, v)).unwrap();
        let e = cell.to_cell().unwrap_err();
        assert!(e.path.ends_with(path), "{f:?} = {v}: {e}");
        assert!(e.reason.contains("plausible") || e.reason.contains("reach"), "{e}");
    }
    let cell: CellFile = serde_json::from_value(mutated(&Field::ToolTcp { session: 1, axis: 2 }, 1e308)).unwrap();
    let e = cell.to_cell().unwrap_err();
    assert!(e.path.ends_with("tool.tcp_mm[2]"), "{e}");
    // The validation job on such a stored reading (a database written before the door was
    // closed) ends with an error naming the measurement, not a panic.
    run_all(&mutated(&Field::Position { index: 3, axis: 0 }, 1e160), true);
    // A robot stored as a custom table under the preset's name (one length re-measured) against a
    // set identified on the preset: the diagnosis starts from the set, or refuses naming it.
    run_all(&mutated(&Field::Robot { joint: 2, field: 3 }, 0.5), true);
}
