//! Validation of a parameter set on a virtual cell: the true parameters against the truth (zero
//! error, whatever the tool), against the tracker readings (the tracker's noise), the nominal
//! model (millimetres), and the statistics against a recomputation here.

use nalgebra::{DMatrix, DVector};
use robocal::cell::{Cell, Observation, Purpose};
use robocal::domain::validation::report_to_json;
use robocal::kinematics::frame::{rot_x, rot_z};
use robocal::kinematics::model::{irb120, ur10};
use robocal::kinematics::thesis::TABLE_5_1_NOMINAL_BASE;
use robocal::kinematics::{Frame, Param, ParameterSet, Tool};
use robocal::sim::simulate::{SimulateOptions, Simulated, simulate};
use robocal::validate::normality::shapiro_wilk;
use robocal::validate::report::{Reference, ValidateError, validate, validation_sessions};

fn sim() -> Simulated {
    simulate(&SimulateOptions { seed: 11, id_per_ball: 10, validation: 50, ..Default::default() }).unwrap()
}

fn names(cell: &Cell, purpose: Purpose) -> Vec<String> {
    cell.sessions_for(purpose).map(|s| s.name.clone()).collect()
}

/// The cell's nominal base, T_0^W as the controller knows it (m, rad).
fn nominal_base() -> [f64; 6] {
    let b = TABLE_5_1_NOMINAL_BASE;
    [b[0] * 1e-3, b[1] * 1e-3, b[2] * 1e-3, b[3].to_radians(), b[4].to_radians(), b[5].to_radians()]
}

/// (a) The true parameters reproduce the true positions on every session, each nest being a tool
/// of its own (declared TCP) and the TriCal the set's own tool (its tool parameters).
#[test]
fn true_parameters_against_the_truth_have_no_error() {
    let sim = sim();
    let set = &sim.truth.set;
    let validation = names(&sim.cell, Purpose::Validation);
    assert!(validation.len() >= 2, "the plan uses several nests: {validation:?}");
    for name in &validation {
        assert_ne!(sim.cell.session(name).unwrap().tool, set.tool, "a nest is not the set's tool");
    }
    let report = validate(set, &sim.cell, &validation, Reference::Truth(&sim.run)).unwrap();
    assert_eq!(report.residuals.len(), 50);
    assert!(report.against_truth);
    assert!(report.purposes.iter().all(|p| *p == Purpose::Validation));
    let worst = report.residuals.iter().map(|r| r.error.norm()).fold(0.0, f64::max);
    assert!(worst <= 1e-12, "worst error {worst:e} m");
    assert!(report.calibrated.position.max <= 1e-12);
    assert!(report.calibrated.orientation.is_none());

    // The identification session, with the set's own tool, too.
    let id = names(&sim.cell, Purpose::Identification);
    let report = validate(set, &sim.cell, &id, Reference::Truth(&sim.run)).unwrap();
    assert_eq!(report.purposes, vec![Purpose::Identification]);
    assert!(report.calibrated.position.max <= 1e-12, "{:e}", report.calibrated.position.max);

    // The tool rule matters: declaring the nests' sessions with the TriCal's tool moves the TCP
    // by the nest offset (~0.1 m).
    let mut wrong = sim.cell.clone();
    for s in wrong.sessions.iter_mut().filter(|s| s.purpose == Purpose::Validation) {
        s.tool = set.tool.clone();
    }
    let report = validate(set, &wrong, &validation, Reference::Truth(&sim.run)).unwrap();
    assert!(report.calibrated.position.mean > 0.05, "{}", report.calibrated.position.mean);
}

/// (b) Against the tracker readings the true model's error is the tracker noise plus the robot's
/// repeatability: error = reading − true model position, here recomputed from the truth.
#[test]
fn true_parameters_against_the_readings_see_the_tracker_noise() {
    let sim = sim();
    let validation = validation_sessions(&sim.cell);
    let report = validate(&sim.truth.set, &sim.cell, &validation, Reference::Measured).unwrap();
    assert!(!report.against_truth);
    let mut k = 0;
    for name in &validation {
        let session = sim.cell.session(name).unwrap();
        let (_, truths) = sim.run.sessions.iter().find(|(n, _)| n == name).unwrap();
        for (i, (m, t)) in session.measurements.iter().zip(truths).enumerate() {
            let Observation::Position(reading) = m.observation else { panic!("tracker readings are positions") };
            let r = &report.residuals[k];
            assert_eq!((r.session.as_str(), r.index), (name.as_str(), i));
            assert!((r.error - (reading - t.model_position)).norm() < 1e-12);
            k += 1;
        }
    }
    assert_eq!(k, report.residuals.len());
    // Default noise: σ = 16 µm per axis (+0.8 µm/m) and 10 µm repeatability; the mean of |e| for
    // an isotropic Gaussian is σ·√(8/π) ≈ 1.6σ ≈ 26 µm.
    let s = report.calibrated.position;
    assert!(s.mean > 16e-6 && s.mean < 40e-6, "mean {:.1} µm", s.mean * 1e6);
    assert!(s.max < 150e-6, "max {:.1} µm", s.max * 1e6);
}

/// (c) The nominal model is millimetres off; its errors match a direct computation with a fresh
/// nominal parameter set whose own tool is the session's nest.
#[test]
fn nominal_model_errors_are_millimetres() {
    let sim = sim();
    let validation = validation_sessions(&sim.cell);
    let report = validate(&sim.truth.set, &sim.cell, &validation, Reference::Truth(&sim.run)).unwrap();
    let mut k = 0;
    for name in &validation {
        let session = sim.cell.session(name).unwrap();
        let direct = ParameterSet::nominal(irb120(), session.tool.clone(), nominal_base());
        let (_, truths) = sim.run.sessions.iter().find(|(n, _)| n == name).unwrap();
        for (m, t) in session.measurements.iter().zip(truths) {
            let want = t.model_position - direct.fk(&m.q).t;
            assert!((report.residuals[k].nominal_error - want).norm() < 1e-12);
            k += 1;
        }
    }
    let n = report.nominal.position;
    assert!(n.mean > 0.5e-3 && n.max < 20e-3, "nominal mean {:.3} mm, max {:.3} mm", n.mean * 1e3, n.max * 1e3);
    assert!(n.mean > 100.0 * report.calibrated.position.mean.max(1e-15));
}

/// (d) Per-axis statistics, distances, Shapiro–Wilk and the regressions, recomputed here from
/// the residuals and the cell (two-pass moments, least squares by QR).
#[test]
fn statistics_match_a_recomputation() {
    let sim = sim();
    let validation = validation_sessions(&sim.cell);
    let set = &sim.truth.set;
    let report = validate(set, &sim.cell, &validation, Reference::Measured).unwrap();
    let base = Frame::from_xyzabc(&set.pose_of(Param::Base)).t;
    let a = &sim.cell.artefact.as_ref().unwrap().triangle;
    let zone = (a.ball(1).unwrap() + a.ball(2).unwrap() + a.ball(3).unwrap()) / 3.0;
    let mut k = 0;
    for name in &validation {
        for m in &sim.cell.session(name).unwrap().measurements {
            let p = sim.cell.observed_position(m).unwrap();
            let r = &report.residuals[k];
            assert!((r.distance_to_base - (p - base).norm()).abs() < 1e-12);
            assert!((r.distance_to_zone.unwrap() - (p - zone).norm()).abs() < 1e-12);
            k += 1;
        }
    }

    for (model, errors) in [
        (&report.calibrated, report.residuals.iter().map(|r| r.error).collect::<Vec<_>>()),
        (&report.nominal, report.residuals.iter().map(|r| r.nominal_error).collect::<Vec<_>>()),
    ] {
        let n = errors.len() as f64;
        for axis in 0..3 {
            let v: Vec<f64> = errors.iter().map(|e| e[axis]).collect();
            let mean = v.iter().sum::<f64>() / n;
            let std = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            let s = &model.per_axis[axis];
            let scale = std.max(mean.abs());
            assert!((s.mean - mean).abs() < 1e-12 * scale);
            assert!((s.std - std).abs() < 1e-12 * scale);
            assert_eq!(s.min, v.iter().copied().fold(f64::INFINITY, f64::min));
            assert_eq!(s.max, v.iter().copied().fold(f64::NEG_INFINITY, f64::max));
            assert_eq!(s.shapiro, Some(shapiro_wilk(&v).unwrap()));
        }
        let norms: Vec<f64> = errors.iter().map(|e| e.norm()).collect();
        assert_eq!(model.shapiro, Some(shapiro_wilk(&norms).unwrap()));
        assert_eq!(model.position.n, norms.len());
        assert!((model.position.mean - norms.iter().sum::<f64>() / n).abs() < 1e-15);

        // |e| = slope·d + intercept by least squares (QR), r from the explained variance.
        for (fit, d) in [
            (model.vs_base_distance.unwrap(), report.residuals.iter().map(|r| r.distance_to_base).collect::<Vec<_>>()),
            (
                model.vs_zone_distance.unwrap(),
                report.residuals.iter().map(|r| r.distance_to_zone.unwrap()).collect::<Vec<_>>(),
            ),
        ] {
            let a = DMatrix::from_fn(d.len(), 2, |i, j| if j == 0 { d[i] } else { 1.0 });
            let y = DVector::from_column_slice(&norms);
            let x = a.clone().svd(true, true).solve(&y, 1e-14).unwrap();
            let fitted = &a * &x;
            let ybar = y.mean();
            let ss_tot: f64 = y.iter().map(|v| (v - ybar).powi(2)).sum();
            let ss_res: f64 = (&y - &fitted).iter().map(|v| v * v).sum();
            let r2 = 1.0 - ss_res / ss_tot;
            assert_eq!(fit.n, d.len());
            assert!((fit.slope - x[0]).abs() < 1e-9 * x[0].abs().max(1e-6), "slope {} vs {}", fit.slope, x[0]);
            assert!((fit.intercept - x[1]).abs() < 1e-9 * x[1].abs().max(1e-6));
            assert!((fit.r2 - r2).abs() < 1e-9, "r² {} vs {r2}", fit.r2);
            assert_eq!(fit.r.signum(), x[0].signum());
        }
    }
}

/// Pose readings give an orientation error: a reading turned by a known angle about a known
/// axis from the true pose shows exactly that angle (and no position error).
#[test]
fn pose_readings_give_the_orientation_error() {
    let sim = sim();
    let set = &sim.truth.set;
    let mut cell = sim.cell.clone();
    let name = validation_sessions(&cell)[0].clone();
    let session = cell.sessions.iter_mut().find(|s| s.name == name).unwrap();
    let robot = sim.truth.robot(&session.tool);
    let angles: Vec<f64> = (0..session.measurements.len()).map(|i| 1e-4 * (i + 1) as f64).collect();
    for (m, angle) in session.measurements.iter_mut().zip(&angles) {
        let approach: Vec<f64> = m.approach.as_ref().unwrap().iter().map(|&a| a as f64).collect();
        let f = robot.tcp(&robot.state(&m.q, &approach, m.temperature_c.unwrap()));
        m.observation = Observation::Pose(Frame::new(rot_z(*angle) * rot_x(0.5 * angle) * f.r, f.t));
    }
    let report = validate(set, &cell, std::slice::from_ref(&name), Reference::Measured).unwrap();
    for (r, angle) in report.residuals.iter().zip(&angles) {
        // rot_z(a)·rot_x(a/2) turns by the angle of that product, computed here by the trace.
        let rr = rot_z(*angle) * rot_x(0.5 * angle);
        let want = ((rr.trace() - 1.0) / 2.0).clamp(-1.0, 1.0).acos();
        assert!((r.orientation_error.unwrap() - want).abs() < 1e-9, "{} vs {want}", r.orientation_error.unwrap());
        assert!(r.error.norm() < 1e-12);
        assert!(r.nominal_orientation_error.unwrap() > 1e-4);
    }
    let o = report.calibrated.orientation.unwrap();
    assert_eq!(o.n, angles.len());
    // Against the truth there is no orientation.
    let report = validate(set, &cell, &[name], Reference::Truth(&sim.run)).unwrap();
    assert!(report.calibrated.orientation.is_none() && report.residuals[0].orientation_error.is_none());
}

/// (e) Bad selections and mismatches are errors that name the culprit.
#[test]
fn bad_selections_are_named() {
    let sim = sim();
    let set = &sim.truth.set;
    let err = validate(set, &sim.cell, &["tracker-n1".into(), "nope".into()], Reference::Measured).unwrap_err();
    assert_eq!(err, ValidateError::UnknownSession("nope".into()));
    assert!(err.to_string().contains("'nope'"), "{err}");
    assert_eq!(validate(set, &sim.cell, &[], Reference::Measured).unwrap_err(), ValidateError::NoSession);
    let v = validation_sessions(&sim.cell);
    let twice = vec![v[0].clone(), v[0].clone()];
    assert_eq!(
        validate(set, &sim.cell, &twice, Reference::Measured).unwrap_err(),
        ValidateError::DuplicateSession(v[0].clone())
    );
    // The truth of another run does not fit.
    let mut run = sim.run.clone();
    run.sessions.retain(|(n, _)| *n != v[0]);
    assert_eq!(
        validate(set, &sim.cell, &v, Reference::Truth(&run)).unwrap_err(),
        ValidateError::TruthMissing(v[0].clone())
    );
    let mut run = sim.run.clone();
    run.sessions.iter_mut().find(|(n, _)| *n == v[0]).unwrap().1.pop();
    assert!(matches!(validate(set, &sim.cell, &v, Reference::Truth(&run)), Err(ValidateError::TruthCount { .. })));
    // A UR10 parameter set on the IRB 120's cell.
    let ur = ParameterSet::nominal(ur10(), Tool::flange(), [0.0; 6]);
    assert!(matches!(validate(&ur, &sim.cell, &v, Reference::Measured), Err(ValidateError::RobotMismatch { .. })));
    // A ball the artefact does not have.
    let mut cell = sim.cell.clone();
    cell.sessions[0].measurements[1].observation = Observation::Ball(4);
    let id = names(&cell, Purpose::Identification);
    assert_eq!(
        validate(set, &cell, &id, Reference::Measured).unwrap_err(),
        ValidateError::NoBall { session: id[0].clone(), index: 1, ball: 4 }
    );
    // A measurement with the wrong number of joints.
    let mut cell = sim.cell.clone();
    cell.sessions.iter_mut().find(|s| s.name == v[0]).unwrap().measurements[2].q.pop();
    assert_eq!(
        validate(set, &cell, &v, Reference::Measured).unwrap_err(),
        ValidateError::JointCount { session: v[0].clone(), index: 2, got: 5, dof: 6 }
    );
}

/// The JSON: mm and mrad with the unit in the names, calibrated fields at the top level, the
/// nominal ones under `nominal`, residuals on request.
#[test]
fn json_report_is_in_millimetres() {
    let sim = sim();
    let v = validation_sessions(&sim.cell);
    let report = validate(&sim.truth.set, &sim.cell, &v, Reference::Measured).unwrap();
    let j = report_to_json(&report, true);
    let num = |v: &serde_json::Value| v.as_f64().unwrap();
    assert_eq!(j["sessions"], serde_json::json!(v));
    assert_eq!(j["reference"], "measured");
    assert_eq!(j["n"], 50);
    // Rounded as README promises: mm fields to 0.1 µm, other numbers to 12 significant digits.
    let mm = |a: f64, b: f64| (a - b).abs() <= 0.5e-4 + 1e-12;
    let sig = |a: f64, b: f64| (a - b).abs() <= 1e-11 * b.abs();
    assert!(mm(num(&j["mean_mm"]), report.calibrated.position.mean * 1e3));
    assert!(mm(num(&j["nominal"]["max_mm"]), report.nominal.position.max * 1e3));
    assert!(mm(num(&j["per_axis"]["z"]["std_mm"]), report.calibrated.per_axis[2].std * 1e3));
    assert!(sig(num(&j["per_axis"]["y"]["shapiro_p"]), report.calibrated.per_axis[1].shapiro.unwrap().p_value));
    assert!(sig(num(&j["shapiro"]["w"]), report.calibrated.shapiro.unwrap().w));
    let fit = report.nominal.vs_zone_distance.unwrap();
    assert!(sig(num(&j["nominal"]["vs_zone_distance"]["r"]), fit.r));
    assert!(mm(num(&j["nominal"]["vs_zone_distance"]["intercept_mm"]), fit.intercept * 1e3));
    assert!(j["orientation"].is_null());
    let rows = j["residuals"].as_array().unwrap();
    assert_eq!(rows.len(), 50);
    let e = report.residuals[7].error * 1e3;
    let r = robocal::units::round_all([e.x, e.y, e.z], robocal::units::OUT_MM);
    assert_eq!(rows[7]["error_mm"], serde_json::json!(r));
    assert!(mm(num(&rows[7]["error_norm_mm"]), e.norm()));
    assert!(report_to_json(&report, false).get("residuals").is_none());
}

/// Approach directions and temperatures reach the model's effect terms.
#[test]
fn effect_terms_see_the_logged_state() {
    use robocal::sim::effects::Effects;
    let opts = SimulateOptions {
        seed: 12,
        id_per_ball: 10,
        validation: 50,
        effects: Effects::parse("backlash,thermal", 6).unwrap(),
        ..Default::default()
    };
    let sim = simulate(&opts).unwrap();
    let v = validation_sessions(&sim.cell);
    let report = validate(&sim.truth.set, &sim.cell, &v, Reference::Truth(&sim.run)).unwrap();
    assert!(report.calibrated.position.max <= 1e-12, "{:e}", report.calibrated.position.max);
    // Without the logged state the same set is measurably wrong.
    let mut bare = sim.cell.clone();
    for m in bare.sessions.iter_mut().flat_map(|s| s.measurements.iter_mut()) {
        m.approach = None;
        m.temperature_c = None;
    }
    let report = validate(&sim.truth.set, &bare, &v, Reference::Truth(&sim.run)).unwrap();
    assert!(report.calibrated.position.mean > 1e-6, "{:e}", report.calibrated.position.mean);
}

/// Per session: each session's figures are exactly those of a validation on that session alone,
/// and the pooled figures are their union (an identification session scored beside validation
/// ones keeps its purpose).
#[test]
fn each_session_is_reported_apart() {
    let sim = sim();
    let set = &sim.truth.set;
    let mut all = vec!["trical-1".to_string()];
    all.extend(validation_sessions(&sim.cell));
    let report = validate(set, &sim.cell, &all, Reference::Measured).unwrap();
    assert_eq!(report.per_session.len(), all.len());
    let mut n = 0;
    let mut weighted = 0.0;
    for (s, name) in report.per_session.iter().zip(&all) {
        assert_eq!(&s.session, name);
        let alone = validate(set, &sim.cell, std::slice::from_ref(name), Reference::Measured).unwrap();
        assert_eq!(s.calibrated, alone.calibrated, "{name}");
        assert_eq!(s.nominal, alone.nominal, "{name}");
        assert_eq!(s.purpose, sim.cell.session(name).unwrap().purpose);
        assert_eq!(alone.per_session.len(), 1);
        assert_eq!(alone.per_session[0].calibrated, alone.calibrated);
        n += s.calibrated.position.n;
        weighted += s.calibrated.position.n as f64 * s.calibrated.position.mean;
    }
    assert_eq!(n, report.calibrated.position.n);
    assert!((weighted / n as f64 - report.calibrated.position.mean).abs() < 1e-15);
    let j = report_to_json(&report, false);
    let rows = j["per_session"].as_array().unwrap();
    assert_eq!(rows.len(), all.len());
    assert_eq!(rows[0]["session"], "trical-1");
    assert_eq!(rows[0]["purpose"], "identification");
    assert_eq!(rows[1]["purpose"], "validation");
    let first = &report.per_session[1].calibrated.position;
    assert_eq!(rows[1]["n"], first.n);
    assert!((rows[1]["mean_mm"].as_f64().unwrap() - first.mean * 1e3).abs() <= 0.5e-4 + 1e-12, "0.1 µm");
    assert!(rows[1]["nominal"]["max_mm"].as_f64().unwrap() > 0.1);
}
