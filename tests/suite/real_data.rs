//! Real data nobody here has seen (issue 24), on its realistic twin: a tracker following three
//! SMRs on a plate over random workspace poses in measuring order, written as three-reflector
//! text files and imported as a user would — no base or TCP guess, no payload, errors from pose
//! to pose of 0.1–0.3 mm that no term explains, rows removed ([`robocal::sim::tracker_run`]).
//!
//! - Identification converges from zero guesses with one, two or three reflectors, to the
//!   minimum a plain Levenberg–Marquardt with finite differences reaches on the same problem.
//! - Cross-validation with several targets predicts each held-out measurement with its own
//!   target's TCP: a plate's per-reflector figures agree with the one-reflector ones.
//! - An unknown payload is identified, not taken as 0 kg.

use std::path::PathBuf;

use nalgebra::{DMatrix, DVector};

use robocal::cell::{Cell, Purpose};
use robocal::identify::crossval::{CrossvalOptions, Variant, crossval};
use robocal::identify::{IdentifyOptions, ModelOptions, Prepared, Problem, identify, prepare};
use robocal::import::three_reflector;
use robocal::kinematics::model::irb120;
use robocal::kinematics::{JointTerm, Param};
use robocal::sim::tracker_run::{TrackerRun, TrackerRunOptions, tracker_run};
use robocal::units::{DEG, MM};

use crate::common;

/// A run of `poses` stops, the plate centred on the flange axis (so the first SMR lies on the
/// flange's y axis: its x is 0, the case where a TCP left in polar form crawls), written and
/// imported. Returns the run and the cell.
fn twin(poses: usize, seed: u64) -> (TrackerRun, Cell) {
    let centre = nalgebra::Vector3::new(0.0, 0.0, 0.040);
    let r = 0.150 / 3f64.sqrt();
    let smrs = [90.0f64, 210.0, 330.0]
        .iter()
        .map(|a| centre + nalgebra::Vector3::new(r * (a * DEG).cos(), r * (a * DEG).sin(), 0.0))
        .collect();
    let o = TrackerRunOptions { seed, poses, removed: poses / 100, smrs, ..Default::default() };
    let run = tracker_run(&o).unwrap();
    let dir = common::fresh_dir("real-data");
    let (joints, files) = run.write(&dir, "run", 6).unwrap();
    let cell = import(&joints, &files);
    (run, cell)
}

fn import(joints: &std::path::Path, files: &[PathBuf]) -> Cell {
    three_reflector::import(joints, files, irb120(), Purpose::Identification).unwrap().cell
}

fn options(model: &str, sessions: &[&str]) -> IdentifyOptions {
    let mut o = IdentifyOptions { model: ModelOptions::parse(model, 6).unwrap(), ..Default::default() };
    o.selection.sessions = sessions.iter().map(|s| s.to_string()).collect();
    o
}

/// A plain Levenberg–Marquardt on the same problem, written apart: central finite differences of
/// the problem's residual for the Jacobian, Marquardt's damping λ·diag(JᵀJ), normal equations by
/// nalgebra's Cholesky; until 8 accepted steps in a row lower the cost by less than 1e-14 of it,
/// or 300 iterations. Returns the cost reached.
fn plain_lm(problem: &Problem, free: &[usize], x0: &[f64]) -> f64 {
    let n = problem.n_rows;
    let cost_at = |x: &[f64]| {
        let mut r = vec![0.0; n];
        problem.residual(x, &mut r);
        (r.iter().map(|v| v * v).sum::<f64>(), r)
    };
    let mut x = x0.to_vec();
    let (mut cost, mut r) = cost_at(&x);
    let mut lambda = 1e-3;
    let mut quiet = 0;
    for _ in 0..300 {
        let mut j = DMatrix::<f64>::zeros(n, free.len());
        for (c, &g) in free.iter().enumerate() {
            let h = 1e-7 * x[g].abs().max(1.0);
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[g] += h;
            xm[g] -= h;
            let (_, rp) = cost_at(&xp);
            let (_, rm) = cost_at(&xm);
            for i in 0..n {
                // The residual is target − model: its derivative is −∂model/∂x.
                j[(i, c)] = -(rp[i] - rm[i]) / (2.0 * h);
            }
        }
        let a = j.transpose() * &j;
        let g = j.transpose() * DVector::from_vec(r.clone());
        loop {
            let mut ad = a.clone();
            for k in 0..free.len() {
                ad[(k, k)] += lambda * a[(k, k)];
            }
            let step = ad.cholesky().map(|c| c.solve(&g));
            let Some(step) = step else {
                lambda *= 10.0;
                continue;
            };
            let mut xt = x.clone();
            for (c, &gl) in free.iter().enumerate() {
                xt[gl] += step[c];
            }
            let (ct, rt) = cost_at(&xt);
            if ct <= cost {
                quiet = if cost - ct < 1e-14 * cost { quiet + 1 } else { 0 };
                (x, cost, r) = (xt, ct, rt);
                lambda = (lambda / 3.0).max(1e-12);
                break;
            }
            lambda *= 2.0;
            if lambda > 1e12 {
                return cost;
            }
        }
        if quiet >= 8 {
            break;
        }
    }
    cost
}

/// Issue 24, item 1: one, two or three reflectors, from zero base and TCP guesses, converge —
/// geometry alone and the default model with an unknown payload — and each one-reflector fit
/// reaches the cost a plain LM reaches on the same problem (it stops no later than that: within
/// 1e-6 of it).
#[test]
fn one_two_or_three_reflectors_converge_from_zero_guesses() {
    let (_, cell) = twin(400, 3);
    for sessions in [
        vec!["reflector-1"],
        vec!["reflector-2"],
        vec!["reflector-3"],
        vec!["reflector-1", "reflector-3"],
        vec!["reflector-1", "reflector-2", "reflector-3"],
    ] {
        for model in ["-compliance", ""] {
            let o = options(model, &sessions);
            let id = identify(&cell, &o).unwrap_or_else(|e| panic!("{sessions:?} {model:?}: {e}"));
            // 10–30 times the tracker's noise, as on real data: the pose-to-pose error.
            assert!(
                (3.0..60.0).contains(&id.quality.residual_ratio),
                "{sessions:?} {model:?}: ratio {}",
                id.quality.residual_ratio
            );
            if sessions.len() == 1 && model == "-compliance" {
                let Prepared { problem, x0, .. } = prepare(&cell, &o).unwrap();
                let reference = plain_lm(&problem, &id.free, &x0);
                let ours: f64 = id.linearised().1.iter().map(|v| v * v).sum();
                assert!(
                    ours <= reference * (1.0 + 1e-6),
                    "{sessions:?}: robocal's cost {ours:.6e} m² against a plain LM's {reference:.6e} m²"
                );
            }
        }
    }
}

/// One SMR in a nest at the flange's centre, a fraction of a millimetre off its axis — as a real
/// nest sits (a UR5's public 1,000-pose tracker data set, never used here before: 0.23 mm off).
/// On the axis θ5 and a5 (and d5, α5) are one direction; 0.2 mm off it they are formally
/// independent, each passes the start's sweep by the share of its column beyond the parameters
/// kept before it, and together they leave σ of degrees and millimetres: that fit was refused at
/// κ 20,438 ("the weakest combination is +0.71·theta5 +0.71·a5"). Now a geometric parameter whose
/// σ at the solution exceeds the undetermined bound (1°, 10 mm) is held at its start value and
/// the rest refitted: the fit converges, κ within its limit, every kept geometric σ within the
/// bound, the held one's status names its σ and its partner, and it fits the data as well as a
/// plain Levenberg–Marquardt does with the same free parameters.
#[test]
fn a_reflector_a_fraction_of_a_millimetre_off_the_flange_axis_is_identified() {
    let o = TrackerRunOptions {
        seed: 11,
        poses: 400,
        removed: 4,
        smrs: vec![nalgebra::Vector3::new(0.15 * MM, -0.1 * MM, 30.0 * MM)],
        payload_kg: 0.1,
        ..Default::default()
    };
    let run = tracker_run(&o).unwrap();
    let dir = common::fresh_dir("on-axis");
    let (joints, files) = run.write(&dir, "run", 6).unwrap();
    let cell = import(&joints, &files);
    let opts = options("-compliance", &[]);
    let id = identify(&cell, &opts).unwrap_or_else(|e| panic!("{e}"));
    assert!(id.quality.kappa_scaled <= opts.kappa_limit, "κ {}", id.quality.kappa_scaled);
    let held: Vec<String> = id.status.iter().map(|s| s.to_string()).filter(|s| s.contains("at the solution")).collect();
    eprintln!("held at the solution: {held:?}");
    assert!(!held.is_empty(), "no parameter held at the solution: {:?}", id.status);
    assert!(held.iter().all(|s| s.contains("correlation")), "{held:?}");
    for (c, name) in id.free_names.iter().enumerate() {
        let angle = name.starts_with("alpha") || name.starts_with("theta") || name.starts_with("beta");
        let length = ["a", "d", "base_x", "base_y", "base_z", "tool_x", "tool_y", "tool_z"]
            .iter()
            .any(|p| name == p || (p.len() == 1 && name.starts_with(p) && name[1..].parse::<u32>().is_ok()));
        let s = id.quality.std[c];
        assert!(!angle || s <= 1.0 * DEG, "{name} σ {}°", s / DEG);
        assert!(!length || s <= 10.0 * MM, "{name} σ {} mm", s / MM);
    }
    assert!((1.0..60.0).contains(&id.quality.residual_ratio), "ratio {}", id.quality.residual_ratio);
    // Every parameter held as not determined stands at its start value (nominal here), as its
    // status says — not where the fit had taken it along the valley before it was held.
    for (i, st) in id.status.iter().enumerate() {
        if st.to_string().contains("not determined by these data") {
            assert_eq!(id.set.values[i], id.set.nominal[i], "{st}");
        }
    }
    let Prepared { problem, x0, .. } = prepare(&cell, &opts).unwrap();
    let reference = plain_lm(&problem, &id.free, &x0);
    let ours: f64 = id.linearised().1.iter().map(|v| v * v).sum();
    assert!(ours <= reference * (1.0 + 1e-6), "robocal's cost {ours:.6e} m² against a plain LM's {reference:.6e} m²");
}

/// Issue 24, item 2: cross-validation of the three reflectors together predicts each held-out
/// measurement with its own reflector's TCP. Each reflector's held-out figure agrees with the one
/// it gets when cross-validated alone on the same folds of poses (same seed; within 25 %: the
/// three-reflector model is fitted on three times the data), and every figure is at the scale
/// of the pose-to-pose error (a wrong TCP is ~150 mm).
#[test]
fn several_targets_are_cross_validated_each_with_its_own_tcp() {
    let (_, cell) = twin(300, 5);
    let names = ["reflector-1", "reflector-2", "reflector-3"];
    let run = |sessions: &[&str]| {
        let variant = Variant { name: "geometry".into(), options: options("-compliance", &[]) };
        let o = CrossvalOptions {
            sessions: sessions.iter().map(|s| s.to_string()).collect(),
            folds: 5,
            sizes: Vec::new(),
            draws: 0,
            transfer: Vec::new(),
            transfer_kappa_limit: None,
            transfer_fixed: Vec::new(),
            variants: vec![variant],
            before: IdentifyOptions::default(),
            seed: 1,
            threads: 2,
        };
        let cv = crossval(&cell, &o).unwrap();
        let f = cv.folds.iter().find(|f| f.variant == "geometry").unwrap();
        f.pooled.clone().unwrap_or_else(|| panic!("{sessions:?}: {:?}", f.per_fold))
    };
    let together = run(&names);
    assert!(together.position.mean < 1.0 * MM, "pooled held-out mean {} mm", together.position.mean / MM);
    for (k, name) in names.iter().enumerate() {
        let alone = run(&[name]);
        let mine = together.per_session.iter().find(|s| s.session == *name).unwrap();
        let (a, b) = (mine.position.mean, alone.position.mean);
        eprintln!("{name}: together {:.4} mm, alone {:.4} mm", a / MM, b / MM);
        assert!((a - b).abs() <= 0.25 * b, "reflector {}: {:.4} mm together, {:.4} mm alone", k + 1, a / MM, b / MM);
    }
}

/// Issue 24, item 3: the import says the payload is unknown and puts its centre of mass at the
/// reflectors' centroid; the default model identifies its mass (the true plate weighs 1 kg)
/// within three standard deviations, and predicts held-out poses better than compliance fitted
/// with 0 kg.
#[test]
fn an_unknown_payload_is_identified() {
    let (run, cell) = twin(500, 7);
    let dir = common::fresh_dir("payload");
    let (joints, files) = run.write(&dir, "p", 6).unwrap();
    let imported = three_reflector::import(&joints, &files, irb120(), Purpose::Identification).unwrap();
    assert!(imported.notes.iter().any(|n| n.contains("payload unknown")), "{:?}", imported.notes);
    let com = imported.cell.sessions[0].tool.com;
    let centroid = nalgebra::Vector3::new(0.0, 0.0, 0.040);
    assert!((com - centroid).norm() < 2.0 * MM, "centre of mass {com:?}");
    assert_eq!(imported.cell.sessions[0].tool.mass, 0.0);

    let id = identify(&cell, &options("", &[])).unwrap();
    let i = id.set.layout.index_of(Param::ToolMass).expect("a payload term");
    let (m, s) = (id.set.values[i], id.std[i].expect("identified"));
    eprintln!("payload {m:.3} ± {s:.3} kg");
    assert!((m - 1.0).abs() < 3.0 * s && s < 0.3, "payload {m} ± {s} kg (true 1 kg)");

    let without = IdentifyOptions { identify_payload: false, ..options("", &[]) };
    let mean_of = |options: IdentifyOptions| {
        let o = CrossvalOptions {
            sessions: vec!["reflector-1".into(), "reflector-2".into(), "reflector-3".into()],
            folds: 5,
            sizes: Vec::new(),
            draws: 0,
            transfer: Vec::new(),
            transfer_kappa_limit: None,
            transfer_fixed: Vec::new(),
            variants: vec![Variant { name: "m".into(), options }],
            before: IdentifyOptions::default(),
            seed: 1,
            threads: 2,
        };
        let cv = crossval(&cell, &o).unwrap();
        cv.folds.iter().find(|f| f.variant == "m").unwrap().pooled.clone().unwrap().position.mean
    };
    let (with_payload, zero) = (mean_of(options("", &[])), mean_of(without));
    eprintln!("held-out mean: payload identified {:.4} mm, 0 kg {:.4} mm", with_payload / MM, zero / MM);
    assert!(with_payload < zero, "payload identified {with_payload} m, 0 kg {zero} m");
}

/// An unknown payload's mass is read only beside where it is assumed to sit. A 2 kg plate whose
/// centre of mass is at the flange, imported as unknown: the import puts it at the reflectors'
/// centroid, 40 mm up, and the mass read there is 7 σ off (its σ is for the centre of mass it
/// assumes). `payload_at_flange` identifies it again at the flange, where the truth lies within
/// 3 σ; the identification's file carries both readings (`quality.payload`). The same plate with
/// its centre of mass at the centroid: the roles swap. In both cases the
/// two readings lie further apart than three of either σ, which is why both are said. The
/// residuals do not tell the two apart here (within 1 %), so no test asks them to.
#[test]
fn an_unknown_payloads_mass_is_read_beside_where_it_sits() {
    let read = |com: nalgebra::Vector3<f64>, tag: &str| {
        let o = TrackerRunOptions {
            seed: 4,
            poses: 500,
            payload_kg: 2.0,
            payload_com: Some(com),
            jitter: 0.006 * DEG,
            effects: robocal::sim::effects::Effects::parse("", 6).unwrap(),
            ..Default::default()
        };
        let dir = common::fresh_dir(tag);
        let (joints, files) = tracker_run(&o).unwrap().write(&dir, "run", 6).unwrap();
        let cell = import(&joints, &files);
        // As every front end runs it: the file's `quality.payload` carries both readings.
        let (id, doc) =
            robocal::domain::identification::run_identification(&cell, options("", &[]), None, &|| ()).unwrap();
        let i = id.set.layout.index_of(Param::ToolMass).expect("an unknown payload");
        let at_centroid = (id.set.values[i], id.std[i].expect("identified"), id.quality.rms_residual);
        let payload = doc.quality.unwrap().payload.expect("an unknown payload");
        let close = |a: Option<f64>, b: f64| (a.unwrap() - b).abs() <= 1e-10 * b.abs();
        assert!(close(payload.mass_kg, at_centroid.0) && close(payload.std_kg, at_centroid.1), "{payload:?}");
        let com = cell.sessions[0].tool.com / MM;
        assert!(payload.com_mm.unwrap().iter().zip(com.iter()).all(|(a, b)| (a - b).abs() < 1e-4), "{payload:?}");
        let f = payload.at_flange.expect("the second fit");
        let at_flange = (f.mass_kg.unwrap(), f.std_kg.expect("identified"), f.rms_residual_mm.unwrap() * MM);
        eprintln!("{tag}: centroid {at_centroid:?}, flange {at_flange:?}");
        (at_centroid, at_flange)
    };
    let within = |(m, s, _): (f64, f64, f64)| (m - 2.0).abs() < 3.0 * s;
    let apart = |a: (f64, f64, f64), b: (f64, f64, f64)| (a.0 - b.0).abs() > 3.0 * a.1.max(b.1);
    let (centroid, flange) = read(nalgebra::Vector3::zeros(), "payload-at-flange");
    assert!(within(flange) && !within(centroid) && apart(centroid, flange), "centroid {centroid:?}, flange {flange:?}");
    let (centroid, flange) = read(nalgebra::Vector3::new(0.0, 0.0, 0.040), "payload-at-centroid");
    assert!(within(centroid) && apart(centroid, flange), "centroid {centroid:?}, flange {flange:?}");
}

/// A fit started from its own calibrated set (`identify --start`) stands where it started: the
/// same free parameters, values and standard deviations as the fit from nominal. Before, the
/// compliances were tested against their start values (0 σ from a calibrated start) and all held
/// there, the payload alone moved, and its σ came out five times too small (0.046 against
/// 0.241 kg on an IRB 120 twin of the independent simulator, `scripts/independent_analysis.py`).
#[test]
fn a_fit_from_its_own_calibrated_set_keeps_its_parameters_and_their_sigmas() {
    let (_, cell) = twin(500, 7);
    let first = identify(&cell, &options("", &[])).unwrap();
    let again = identify(&cell, &IdentifyOptions { start: Some(first.set.clone()), ..options("", &[]) }).unwrap();
    assert_eq!(again.free_names, first.free_names);
    for (i, p) in first.set.layout.params().iter().enumerate() {
        let (a, b) = (first.std[i], again.std[i]);
        assert_eq!(a.is_some(), b.is_some(), "{p}: {} / {}", first.status[i], again.status[i]);
        if let (Some(a), Some(b)) = (a, b) {
            let (va, vb) = (first.set.values[i], again.set.values[i]);
            assert!((va - vb).abs() < 0.1 * a, "{p}: {va:e} then {vb:e} (σ {a:e})");
            assert!((b / a - 1.0).abs() < 0.1, "{p}: σ {a:e} then {b:e}");
        }
    }
    let identified_compliances = (first.set.layout.params().iter().enumerate())
        .filter(|(i, p)| matches!(p, Param::Joint(_, JointTerm::Compliance)) && again.std[*i].is_some())
        .count();
    assert!(identified_compliances >= 2, "the compliances the data determine stay identified");
}

/// The hysteresis the diagnosis names can be fitted as a user would next: `identify
/// --model=+backlash1,+backlash2,+backlash3` on the imported files, which log no approach
/// direction. The directions come from the rows' order (rows removed included) and the fit says
/// so; the estimates agree with the fit that is given the simulator's true directions (within one
/// σ: a few rows removed change a few directions), and with the truth (0.006° on joints 1–3, within 3 σ). The payload, which the
/// unmodelled hysteresis biased low, is then within 3 σ of its 1 kg.
#[test]
fn the_named_hysteresis_is_fitted_from_the_row_order() {
    let (run, cell) = twin(500, 3);
    let o = options("+backlash1,+backlash2,+backlash3", &[]);
    let id = identify(&cell, &o).unwrap();
    assert!(id.notes.iter().any(|n| n.contains("derived from the measuring order")), "{:?}", id.notes);

    let mut logged = cell.clone();
    for s in &mut logged.sessions {
        for (m, a) in s.measurements.iter_mut().zip(&run.approach) {
            m.approach = Some(a[..6].to_vec());
        }
    }
    let reference = identify(&logged, &o).unwrap();
    assert!(reference.notes.is_empty(), "{:?}", reference.notes);
    for j in 0..3 {
        let i = id.set.layout.index_of(Param::Joint(j, robocal::kinematics::JointTerm::Backlash)).unwrap();
        let (b, s) = (id.set.values[i], id.std[i].expect("identified"));
        let (r, rs) = (reference.set.values[i], reference.std[i].expect("identified"));
        eprintln!(
            "backlash{}: {:.5} ± {:.5} deg (true directions {:.5} ± {:.5})",
            j + 1,
            b / DEG,
            s / DEG,
            r / DEG,
            rs / DEG
        );
        assert!((b - r).abs() < s, "backlash{}: {b} vs {r} ± {s} rad", j + 1);
        assert!((b - 0.006 * DEG).abs() < 3.0 * s, "backlash{}: {} ± {} deg", j + 1, b / DEG, s / DEG);
    }
    let i = id.set.layout.index_of(Param::ToolMass).expect("a payload term");
    let (m, s) = (id.set.values[i], id.std[i].expect("identified"));
    eprintln!("payload {m:.3} ± {s:.3} kg");
    assert!((m - 1.0).abs() < 3.0 * s && s < 0.3, "payload {m} ± {s} kg (true 1 kg)");

    // Cross-validation derives them as well, from the whole sessions before any fold, and says so.
    let o = CrossvalOptions {
        sessions: cell.sessions.iter().map(|s| s.name.clone()).collect(),
        folds: 2,
        sizes: Vec::new(),
        draws: 0,
        transfer: Vec::new(),
        transfer_kappa_limit: None,
        transfer_fixed: Vec::new(),
        variants: vec![Variant { name: "hysteresis".into(), options: o.clone() }],
        before: IdentifyOptions::default(),
        seed: 1,
        threads: 2,
    };
    let cv = crossval(&cell, &o).unwrap();
    assert_eq!(cv.notes, id.notes);
    let f = cv.folds.iter().find(|f| f.variant == "hysteresis").unwrap();
    assert!(f.pooled.is_some(), "{:?}", f.per_fold);
}

/// A row rejected as an outlier and *blanked* (`nan nan nan` in every positions file, its joints
/// kept) leaves the robot's stop in the joints file: the import writes every measurement's
/// approach from the joints file's order with that stop counted, the simulator's true directions
/// exactly, and the hysteresis fitted from them is unbiased. The same rows *deleted* leave the
/// move after each a guess from the stop before it, wrong for about a third of the joints there;
/// with 30 % of the rows deleted that shrinks the estimates by about a fifth, many σ. (With
/// less pose-to-pose scatter than the twin's 0.2 mm, the stops after a deleted row read 10 times
/// the typical residual, and the fit refuses them as outliers.)
#[test]
fn a_row_blanked_as_an_outlier_keeps_the_directions_that_a_deleted_row_guesses() {
    use robocal::import::three_reflector::{Payload, import_with_payload};
    let o = TrackerRunOptions {
        seed: 3,
        poses: 600,
        removed: 0,
        effects: robocal::sim::effects::Effects::parse(
            "backlash:j=1:deg=0.03,backlash:j=2:deg=0.03,backlash:j=3:deg=0.03",
            6,
        )
        .unwrap(),
        ..Default::default()
    };
    let run = tracker_run(&o).unwrap();
    let dir = common::fresh_dir("real-data-blanked");
    let (joints, files) = run.write(&dir, "run", 6).unwrap();
    let rejected = |k: usize| k > 0 && (k * 7919) % 10 < 3;
    // Each file: its `#` line, then one line per row.
    let rewrite = |path: &std::path::Path, tag: &str, edit: &dyn Fn(usize, &str) -> Option<String>| {
        let text = std::fs::read_to_string(path).unwrap();
        let mut lines = text.lines();
        let mut out = format!("{}\n", lines.next().unwrap());
        for (k, l) in lines.enumerate() {
            if let Some(l) = edit(k, l) {
                out.push_str(&l);
                out.push('\n');
            }
        }
        let to = dir.join(format!("{tag}-{}", path.file_name().unwrap().to_str().unwrap()));
        std::fs::write(&to, out).unwrap();
        to
    };
    let keep = |_: usize, l: &str| Some(l.to_string());
    let blank = |k: usize, l: &str| Some(if rejected(k) { "nan nan nan".to_string() } else { l.to_string() });
    let delete = |k: usize, l: &str| (!rejected(k)).then(|| l.to_string());
    // The joints file edited by `joints_edit`, every positions file by `edit`, imported.
    let imported = |tag: &str,
                    joints_edit: &dyn Fn(usize, &str) -> Option<String>,
                    edit: &dyn Fn(usize, &str) -> Option<String>| {
        import_with_payload(
            &rewrite(&joints, tag, joints_edit),
            &files.iter().map(|f| rewrite(f, tag, edit)).collect::<Vec<_>>(),
            irb120(),
            Purpose::Identification,
            Payload::Declared { mass_kg: 1.0, com: None },
        )
        .unwrap()
    };
    let blanked = imported("blanked", &keep, &blank);
    let deleted = imported("deleted", &delete, &delete);
    let n_rejected = (0..run.joints.len()).filter(|&k| rejected(k)).count();
    let notes = blanked.notes.join("\n");
    assert!(
        notes.contains(&format!("{n_rejected} pose(s) without a reading in any file")),
        "{n_rejected} rejected: {notes}"
    );
    assert!(!deleted.notes.join("\n").contains("without a reading"), "{:?}", deleted.notes);

    // The blanked import's directions are the true ones at every stop after the first.
    for s in &blanked.cell.sessions {
        assert_eq!(s.measurements.len(), run.joints.len() - n_rejected);
        for m in &s.measurements {
            let k = m.sequence.unwrap() as usize;
            let want = if k == 0 { vec![0; 6] } else { run.approach[k][..6].to_vec() };
            assert_eq!(m.approach.as_ref(), Some(&want), "{} stop {k}", s.name);
        }
    }
    // The deleted one's, derived from the rows that are left, are wrong after some deleted rows.
    let mut derived = deleted.cell.clone();
    robocal::cell::order::fill_approach(&mut derived, &[]);
    let kept: Vec<usize> = (0..run.joints.len()).filter(|&k| !rejected(k)).collect();
    let wrong = derived.sessions[0]
        .measurements
        .iter()
        .zip(&kept)
        .skip(1)
        .filter(|(m, k)| m.approach.as_deref() != Some(&run.approach[**k][..6]))
        .count();
    assert!(
        wrong > n_rejected / 4 && wrong < n_rejected,
        "{wrong} stops with a wrong direction, {n_rejected} rows deleted"
    );

    let o = options("+backlash1,+backlash2,+backlash3", &[]);
    let fit = |cell: &Cell| {
        let id = identify(cell, &o).unwrap();
        (0..3)
            .map(|j| {
                let i = id.set.layout.index_of(Param::Joint(j, robocal::kinematics::JointTerm::Backlash)).unwrap();
                (id.set.values[i] / DEG, id.std[i].expect("identified") / DEG)
            })
            .collect::<Vec<_>>()
    };
    let (b, d) = (fit(&blanked.cell), fit(&deleted.cell));
    eprintln!("backlash, blanked rows {b:?}; deleted rows {d:?} (true 0.03 deg)");
    for (j, (vb, sb)) in b.iter().enumerate() {
        assert!((vb - 0.03).abs() < 3.0 * sb, "blanked: backlash{} {vb} ± {sb} deg", j + 1);
    }
    // The deleted rows' three estimates, averaged: low by many σ of their mean.
    let mean = d.iter().map(|(v, _)| v).sum::<f64>() / 3.0;
    let sd = d.iter().map(|(_, s)| s * s).sum::<f64>().sqrt() / 3.0;
    assert!(0.03 - mean > 3.0 * sd && mean < 0.9 * 0.03, "deleted: mean {mean} ± {sd} deg: no shrinkage to show");
}

/// A twin of `poses` stops, `removed` of them removed, with `effects`, imported, identified with
/// the default model and diagnosed on 5 folds of its poses.
fn diagnose_twin(poses: usize, removed: usize, effects: &str, seed: u64) -> robocal::diagnose::Diagnosis {
    diagnose_twin_with(TrackerRunOptions {
        seed,
        poses,
        removed,
        effects: robocal::sim::effects::Effects::parse(effects, 6).unwrap(),
        ..Default::default()
    })
}

/// As [`diagnose_twin`], for a twin of any options.
fn diagnose_twin_with(o: TrackerRunOptions) -> robocal::diagnose::Diagnosis {
    let dir = common::fresh_dir("real-data-diagnose");
    let (joints, files) = tracker_run(&o).unwrap().write(&dir, "run", 6).unwrap();
    diagnose_cell(&import(&joints, &files))
}

/// `cell` identified with the default model and diagnosed on 5 folds of its poses.
fn diagnose_cell(cell: &Cell) -> robocal::diagnose::Diagnosis {
    diagnose_cell_identified_with(cell, "")
}

/// `cell` identified with the default model changed by `model` (`--model` syntax) and diagnosed on
/// 5 folds of its poses.
fn diagnose_cell_identified_with(cell: &Cell, model: &str) -> robocal::diagnose::Diagnosis {
    diagnose_identified(cell, &options(model, &[]))
}

/// `cell` identified with `o` and diagnosed on 5 folds of its poses.
fn diagnose_identified(cell: &Cell, o: &IdentifyOptions) -> robocal::diagnose::Diagnosis {
    use robocal::diagnose::{DiagnoseOptions, Input, diagnose};
    let id = identify(cell, o).unwrap();
    let identified = id.status.iter().map(|s| matches!(s, robocal::identify::Status::Identified)).collect();
    let input = Input { cell, set: &id.set, identified: Some(identified), fixed: Vec::new(), excluded: Vec::new() };
    let opts = DiagnoseOptions { validation: Some(Vec::new()), threads: 2, ..DiagnoseOptions::default() };
    diagnose(&input, &opts).unwrap()
}

/// A coupling 2→3 in a real run's pose-to-pose scatter: it takes all that a smooth function of
/// the configuration explains beyond the model, but a fifth of the gap to the floor, the rest
/// being the scatter. `partial`, not named — and the summary says why (the closure it states),
/// not that an effect outside the library lies beyond it, which the smoother's figures deny.
#[test]
fn a_term_that_takes_all_the_smooth_structure_but_little_of_the_gap_is_not_called_a_look_alike() {
    use robocal::diagnose::Status;
    let d = diagnose_twin(982, 10, "coupling:from=2:to=3:ratio=0.001,backlash:j=2:deg=0.01", 17);
    let v = &d.verdict;
    assert_eq!(v.status, Status::Partial, "{}", v.summary);
    assert!(v.summary.starts_with("coupling 2→3 explains"), "{}", v.summary);
    let round = d.rounds.last().unwrap();
    let closure = round.closure.expect("a closure");
    let (share, _) = round.share.expect("a share");
    assert!(share > 0.9 && closure < 0.5, "share {share}, closure {closure}");
    let said =
        format!("but closes only {:.0} % of the gap to the floor; the rest changes from pose to pose", closure * 100.0);
    assert!(
        v.summary.contains(&said) && !v.summary.contains("an effect outside the library, of which"),
        "{}",
        v.summary
    );
}

/// A hysteresis that the held-out poses confirm in all but its size is said, not called absent:
/// with 150 of 500 rows removed, the direction into a row that followed a removed one is a guess
/// (wrong a third of the time between random poses), and the hysteresis the full run names lowers
/// the held-out mean by 3–4 % only here, below the 5 % that names an effect. The verdict stays `not_separable` but says backlash predicts, with its p-value and
/// its gain — the figures of the suspect it reports — and that this is too little to name it. The
/// same run without hysteresis says no candidate predicts the error.
#[test]
fn a_hysteresis_too_small_to_name_is_said_not_called_absent() {
    use robocal::diagnose::Status;
    let run = |effects: &str| diagnose_twin(500, 150, effects, 1);
    let d = run("backlash:j=1:deg=0.006,backlash:j=2:deg=0.006,backlash:j=3:deg=0.006");
    let v = &d.verdict;
    assert_eq!(v.status, Status::NotSeparable, "{}", v.summary);
    let e = v.effects.iter().find(|e| e.candidate.label() == "backlash").expect(&v.summary);
    let start = d.shrink[0].stats.mean;
    assert!(e.gain_mean > 0.0 && e.gain_mean < 0.05 * start, "{} of {start} m", e.gain_mean);
    let p = e.confirm_p.expect("a held-out p");
    let said = format!(
        "the best candidate, backlash, predicts held-out poses better (p = {p:.1e}) but lowers the held-out mean by only {:.4} mm",
        e.gain_mean * 1e3
    );
    assert!(v.summary.contains(&said), "{}\n(expected: {said})", v.summary);
    for (j, b) in e.parameters.iter().take(3).enumerate() {
        let deg = b.value / DEG;
        assert!((deg - 0.006).abs() < 0.003, "backlash{}: {deg} deg (true 0.006)", j + 1);
    }

    let d = run("");
    assert_eq!(d.verdict.status, Status::NotSeparable, "{}", d.verdict.summary);
    assert!(d.verdict.summary.contains("neither a candidate"), "{}", d.verdict.summary);
    assert!(d.verdict.effects.is_empty(), "{:?}", d.verdict.effects);
}

/// A hysteresis weaker than the 5 % of the held-out mean a name needs, in a run measured in random
/// order, is named all the same when it predicts held-out poses beyond a smooth function of the
/// configuration and a drift along the run together — what is left for it then is its own: the
/// sign of each move, a property of the path, not of the pose or the time. A 0.004° hysteresis on
/// joints 1–3 among 0.2 mm of pose-to-pose scatter lowers the held-out mean by 3–4 %; it is named,
/// the summary says on what grounds, the JSON carries the figures, and its terms read the truth:
/// 0.004° on joints 1–3 within 3 σ, joints 4–6 within 3 σ of zero. The same run without
/// hysteresis names nothing (independent twins: BENCHMARKS.md, "Weak hysteresis named").
#[test]
fn a_weak_hysteresis_beyond_the_smoother_and_a_drift_is_named() {
    use robocal::diagnose::Status;
    let d = diagnose_twin(982, 10, "backlash:j=1:deg=0.004,backlash:j=2:deg=0.004,backlash:j=3:deg=0.004", 1);
    let v = &d.verdict;
    assert_eq!(v.status, Status::Named, "{}", v.summary);
    assert!(v.summary.starts_with("backlash ("), "{}", v.summary);
    assert!(
        v.summary.contains("smaller than the 5 % of the held-out mean a name otherwise needs, but beyond a smooth function of the configuration and a drift along the run it still predicts held-out poses better (p = "),
        "{}",
        v.summary
    );
    let (start, named) = (d.shrink[0].stats.mean, d.shrink[1].stats.mean);
    assert!(named < start && start - named < 0.05 * start, "held-out mean {start} → {named} m");
    let e = &v.effects[0];
    for (j, b) in e.parameters.iter().enumerate() {
        let (deg, sd) = (b.value / DEG, b.std.expect("a σ") / DEG);
        let truth = if j < 3 { 0.004 } else { 0.0 };
        assert!((deg - truth).abs() < 3.0 * sd, "backlash{}: {deg} ± {sd} deg (true {truth})", j + 1);
    }
    let json = robocal::domain::diagnosis::diagnosis_out(&d);
    let beyond = json
        .candidates
        .iter()
        .filter_map(|c| c.heldout.as_ref().filter(|h| h.confirmed)?.beyond_smoother_and_drift.as_ref())
        .next()
        .expect("the comparison beyond the smoother and a drift, in the JSON");
    assert!(beyond.p.is_some_and(|p| p < 0.01) && beyond.gain_mean_mm > 0.0, "{beyond:?}");

    let d = diagnose_twin(982, 10, "", 1);
    assert_ne!(d.verdict.status, Status::Named, "{}", d.verdict.summary);
    assert!(
        d.verdict.effects.iter().all(|e| e.candidate.kind != robocal::diagnose::library::Kind::Backlash),
        "{}",
        d.verdict.summary
    );
}

/// The σ a named effect is printed with holds at the data's own scale: on twins whose readings
/// scatter 6× the instrument's noise by a turn of the joints at every stop (shared by the stop's
/// three reflectors), every backlash term's estimate lies within 3 σ of the truth, and the true
/// 0.006° is still told from zero by more than 3 σ. The σ was the instrument model's
/// (JᵀJ)⁻¹ alone, ten times too small: 0.005888 ± 0.000045° for a true 0.006°.
#[test]
fn a_named_effects_uncertainty_covers_the_truth_under_pose_to_pose_scatter() {
    use robocal::diagnose::Status;
    for seed in [1, 2] {
        let d = diagnose_twin(982, 10, "backlash:j=1:deg=0.006,backlash:j=2:deg=0.006,backlash:j=3:deg=0.006", seed);
        let v = &d.verdict;
        assert_eq!(v.status, Status::Named, "seed {seed}: {}", v.summary);
        let e = v.effects.iter().find(|e| e.candidate.label() == "backlash").expect(&v.summary);
        assert_eq!(e.parameters.len(), 6, "{:?}", e.parameters);
        for (j, b) in e.parameters.iter().enumerate() {
            let truth = if j < 3 { 0.006 * DEG } else { 0.0 };
            let sd = b.std.expect("a σ");
            let z = (b.value - truth) / sd;
            assert!(
                z.abs() < 3.0,
                "seed {seed}, backlash{}: {} ± {} deg, truth {}",
                j + 1,
                b.value / DEG,
                sd / DEG,
                truth / DEG
            );
            if j < 3 {
                assert!(truth > 3.0 * sd, "seed {seed}, backlash{}: σ {} deg tells nothing", j + 1, sd / DEG);
            }
        }
        // The group is confirmed as a whole; the summary lists the terms it tells from zero, then
        // apart those within 2 σ of it (joints 4–6 here carry none).
        let (told, near) = v.summary.split_once("within 2 σ of zero: ").unwrap_or((v.summary.as_str(), ""));
        for (j, b) in e.parameters.iter().enumerate() {
            let name = format!("backlash{} ", j + 1);
            let beyond = b.value.abs() >= 2.0 * b.std.expect("a σ");
            assert!(
                told.contains(&name) == beyond && near.contains(&name) != beyond,
                "seed {seed}, {name}: {}",
                v.summary
            );
        }
        assert!(!near.is_empty(), "seed {seed}: no term within 2 σ of zero listed: {}", v.summary);
    }
}

/// A smooth structure too small to name is no unknown effect. A twin with hysteresis on
/// joints 1 and 5, a cyclic error of joint 2 (h2, 0.016°) and of joint 1 (h7), and a cubic
/// compliance on joint 2 in 0.3 mm of pose-to-pose scatter: the diagnosis answered
/// `unknown_effect`, "a smooth function of the configuration predicts the residual; no candidate
/// does", while its own figures had a cyclic term of joint 2 predicting held-out poses at
/// p = 2e-10, by more than the smooth regression, and too little (4.6 %) to name. Now the
/// regression must reach the 5 % a candidate must, and the verdict says what predicts.
#[test]
fn a_smooth_structure_too_small_to_name_is_not_called_an_unknown_effect() {
    use robocal::diagnose::Status;
    let d = diagnose_twin_with(TrackerRunOptions {
        seed: 434,
        removed: 0,
        payload_kg: 2.46,
        jitter: 0.021 * DEG,
        effects: robocal::sim::effects::Effects::parse(
            "backlash:j=1:deg=0.0093,backlash:j=5:deg=0.0192,cyclic:j=2:h=2:amp_deg=0.0158,compliance_cubic:j=2:d=2.01e-07,cyclic:j=1:h=7:amp_deg=0.0072",
            6,
        )
        .unwrap(),
        ..Default::default()
    });
    let v = &d.verdict;
    assert_ne!(v.status, Status::UnknownEffect, "{}", v.summary);
    if v.status != Status::Named {
        assert!(v.summary.contains("too little to name"), "{}", v.summary);
        let s = v.effects.first().expect("the candidate that predicts, as the suspect");
        assert_eq!(s.candidate.joint, Some(1), "{}", v.summary);
    }
}

/// The first "X ± s kg" after `after` in `text`: (X, s).
fn kg_after(text: &str, after: &str) -> (f64, f64) {
    let rest = &text[text.find(after).unwrap_or_else(|| panic!("'{after}' not in: {text}")) + after.len()..];
    let mut words = rest.split_whitespace();
    let v = words.next().unwrap().parse().unwrap();
    assert_eq!(words.next(), Some("±"), "{rest}");
    let s = words.next().unwrap().parse().unwrap();
    (v, s)
}

/// A term the model lacked leaks into an unknown payload through the compliances; once it is named,
/// the data can determine the payload, and the final model adopts it when the model refitted with
/// it predicts held-out poses better. With an unmodelled coupling 2→3 of 0.002 on a 2.3 kg plate,
/// the identification held the payload (not determined: near 0 kg), and the coupling named with
/// the payload held reads 5 σ low. The diagnosis adopts the payload: it reads within 2 σ of the
/// truth, the coupling with it too — as an identification with the named term finds (a second
/// path) — and the shrink table's last row, the model with it, predicts held-out poses about as
/// well as the diagnosis of the same run given the true payload (an independent reference). On
/// the default twin (hysteresis), whose identification found the payload but biased low, the
/// verdict says the named terms move it towards the truth. In both, the verdict reads it again with
/// its centre of mass free, with a wider σ; the set the diagnosis accepts carries that reading, as
/// `identify` with the accepted model gives it.
#[test]
fn the_payload_that_the_named_terms_determine_is_adopted() {
    use robocal::diagnose::Status;
    let o = TrackerRunOptions {
        seed: 1,
        payload_kg: 2.3,
        jitter: 0.0075 * DEG,
        effects: robocal::sim::effects::Effects::parse("coupling:from=2:to=3:ratio=0.002", 6).unwrap(),
        ..Default::default()
    };
    let dir = common::fresh_dir("real-data-payload");
    let (joints, files) = tracker_run(&o).unwrap().write(&dir, "run", 6).unwrap();
    let cell = import(&joints, &files);
    let d = diagnose_cell(&cell);
    let v = &d.verdict;
    assert_eq!(v.status, Status::Named, "{}", v.summary);
    assert_eq!(v.effects[0].candidate.label(), "coupling 2→3", "{}", v.summary);
    let (mass, sd) = kg_after(&v.summary, "the final model adopts it:");
    assert!((mass - 2.3).abs() < 2.0 * sd && sd < 0.3, "{mass} ± {sd} kg: {}", v.summary);
    assert!(d.model.model.extra.contains(&Param::ToolMass), "{:?}", d.model.model);
    // The shrink table's last row is the model with it, better than the one before.
    let rows: Vec<(&[String], f64)> = d.shrink.iter().map(|r| (r.model.as_slice(), r.stats.mean)).collect();
    let [.., (_, before), (last, after)] = rows[..] else { panic!("{rows:?}") };
    assert_eq!(last, ["coupling 2→3", "tool_mass"], "{rows:?}");
    assert!(after < before, "{rows:?}");
    // The same run imported with the true payload declared: its diagnosis's last model is the
    // reference the adopted one must reach.
    let mut declared = cell.clone();
    for s in &mut declared.sessions {
        s.tool.mass = 2.3;
    }
    let reference = diagnose_cell(&declared);
    let reference_mean = reference.shrink.last().unwrap().stats.mean;
    // A declared payload is the user's: never tried again, never adopted.
    assert!(reference.shrink.iter().all(|r| !r.model.iter().any(|m| m == "tool_mass")), "{:?}", reference.model.model);
    assert!(!reference.verdict.summary.contains("adopts"), "{}", reference.verdict.summary);
    eprintln!(
        "adopted {:.4} mm, before it {:.4} mm, true payload declared {:.4} mm",
        after / MM,
        before / MM,
        reference_mean / MM
    );
    assert!(after < 1.03 * reference_mean, "adopted {after} m, with the true payload {reference_mean} m");
    let with = &v.summary[v.summary.find("and with it coupling2_3").expect(&v.summary)..];
    let mut words = with.split_whitespace().skip(4);
    let ratio: f64 = words.next().unwrap().parse().unwrap();
    let ratio_sd: f64 = words.nth(1).unwrap().parse().unwrap();
    assert!((ratio - 0.002).abs() < 2.0 * ratio_sd, "{ratio} ± {ratio_sd}: {}", v.summary);
    let named = v.effects[0].estimate.unwrap();
    assert!((named - 0.002).abs() > 3.0 * v.effects[0].std.unwrap(), "the payload held biases it: {named}");
    // What remained (a payload error not separable with a single payload) says it was adopted.
    let (_, remaining) = v.remaining.as_ref().expect("what remains");
    assert!(remaining.contains("the final model adopts the payload"), "{remaining}");
    // Read again with its centre of mass free: a wider σ, which still covers the truth.
    let (free, free_sd) = kg_after(&v.summary, "with its centre of mass identified too, it reads");
    assert!((free - 2.3).abs() < 3.0 * free_sd && free_sd > sd, "{free} ± {free_sd}: {}", v.summary);
    // A second path: identify the imported twin with the named term.
    let held = identify(&cell, &options("", &[])).unwrap();
    let i = held.set.layout.index_of(Param::ToolMass).expect("an unknown payload");
    assert!(!matches!(held.status[i], robocal::identify::Status::Identified), "{:?}", held.status[i]);
    let id = identify(&cell, &options("+coupling2_3", &[])).unwrap();
    let i = id.set.layout.index_of(Param::ToolMass).unwrap();
    assert!((id.set.values[i] - mass).abs() < 0.01 && (id.std[i].unwrap() - sd).abs() < 0.01, "{mass} ± {sd}");

    let d = diagnose_twin(982, 10, "backlash:j=1:deg=0.006,backlash:j=2:deg=0.006,backlash:j=3:deg=0.006", 1);
    let v = &d.verdict;
    assert_eq!(v.status, Status::Named, "{}", v.summary);
    let (after, sd_after) = kg_after(&v.summary, "with the named terms the payload reads");
    let (before, _) = kg_after(&v.summary, "(the model without them:");
    assert!((after - 1.0).abs() < 2.0 * sd_after && (before - 1.0).abs() > (after - 1.0).abs(), "{}", v.summary);
    // The set the diagnosis accepts carries the payload's centre of mass identified with it, as
    // `identify` with the accepted model gives it (a second path, from nominal).
    let doc = robocal::domain::diagnosis::accepted_doc(&d).expect("an accepted set");
    let c = doc.quality.unwrap().payload.unwrap().with_centre_of_mass.expect("the payload's centre of mass");
    let (mass, sd) = (c.mass_kg.unwrap(), c.std_kg.unwrap());
    assert!((mass - 1.0).abs() < 3.0 * sd && sd > sd_after, "{c:?}");
    // The summary says the same reading.
    let said = kg_after(&v.summary, "with its centre of mass identified too, it reads");
    assert!((said.0 - mass).abs() < 1e-3 && (said.1 - sd).abs() < 1e-3, "{said:?} vs {c:?}: {}", v.summary);
    let run = tracker_run(&TrackerRunOptions { seed: 1, poses: 982, removed: 10, ..Default::default() }).unwrap();
    let (joints, files) = run.write(&common::fresh_dir("real-data-payload-com"), "run", 6).unwrap();
    let cell = import(&joints, &files);
    let id = identify(&cell, &IdentifyOptions { anchor: None, ..d.model.clone() }).unwrap();
    let again = robocal::identify::payload_centre_of_mass(&id, &d.model).unwrap().expect("a determined payload");
    assert!((again.mass - mass).abs() < 1e-3 * mass && (again.std - sd).abs() < 1e-3 * sd, "{again:?} vs {c:?}");
}

/// The k-fold options of the twin tests below: `sessions` split, the default model only.
fn cv_options(sessions: &[&str], folds: usize, sizes: Vec<usize>) -> CrossvalOptions {
    CrossvalOptions {
        sessions: sessions.iter().map(|s| s.to_string()).collect(),
        folds,
        sizes,
        draws: 3,
        transfer: Vec::new(),
        transfer_kappa_limit: None,
        transfer_fixed: Vec::new(),
        variants: vec![Variant { name: "geometry".into(), options: options("-compliance", &[]) }],
        before: IdentifyOptions::default(),
        seed: 1,
        threads: 2,
    }
}

/// A reflector with no reading in a fold's training set has no identified TCP there: its held-out
/// readings are counted and named, not scored with the declared (zero) TCP, which gave 110–150 mm
/// "held-out errors" and polluted the pooled figures.
#[test]
fn a_reflector_absent_from_training_is_not_scored() {
    let (_, mut cell) = twin(300, 5);
    let names = ["reflector-1", "reflector-2", "reflector-3"];
    let r3 = cell.sessions.iter().position(|s| s.name == "reflector-3").unwrap();
    cell.sessions[r3].measurements.truncate(1);
    let cv = crossval(&cell, &cv_options(&names, 5, Vec::new())).unwrap();
    let total: usize = names.iter().map(|n| cell.session(n).unwrap().measurements.len()).sum();
    for f in &cv.folds {
        let pooled = f.pooled.as_ref().unwrap_or_else(|| panic!("{}: {:?}", f.variant, f.per_fold));
        assert_eq!(pooled.unscored, vec![("reflector-3".to_string(), 1)], "{}", f.variant);
        assert_eq!(pooled.position.n, total - 1);
        assert!(pooled.per_session.iter().all(|s| s.session != "reflector-3"));
        assert!(pooled.position.max < 5.0 * MM, "{}: max {} mm", f.variant, pooled.position.max / MM);
        let unscored: Vec<usize> = f.per_fold.iter().map(|r| r.as_ref().unwrap().unscored.len()).collect();
        assert_eq!(unscored.iter().sum::<usize>(), 1, "one fold holds it: {unscored:?}");
    }
    let note = cv.notes.iter().find(|n| n.starts_with("reflector-3: 1 held-out reading not scored in fold "));
    assert!(note.is_some_and(|n| n.contains("no reading of reflector-3 in the training set")), "{:?}", cv.notes);

    // Few poses: reflector-3 read at every 30th pose, rarely among 12 identification poses.
    let (_, mut cell) = twin(300, 5);
    let r3 = cell.sessions.iter().position(|s| s.name == "reflector-3").unwrap();
    let kept = cell.sessions[r3].measurements.iter().step_by(30).cloned().collect();
    cell.sessions[r3].measurements = kept;
    let cv = crossval(&cell, &cv_options(&names, 0, vec![12])).unwrap();
    let mut unscored = 0;
    for s in &cv.sizes {
        for d in &s.draws {
            let h = d.as_ref().unwrap();
            unscored += h.unscored.iter().map(|u| u.1).sum::<usize>();
            assert!(h.position.max < 5.0 * MM, "{} n = {}: max {} mm", s.variant, s.n, h.position.max / MM);
        }
    }
    assert!(unscored > 0, "no draw left reflector-3 out of training: {:?}", cv.notes);
    assert!(cv.notes.iter().any(|n| n.starts_with("reflector-3: ") && n.contains("draws of n = 12")), "{:?}", cv.notes);
}

/// A gross reading refuses the fits that see it; the refusal names it by its index in its session
/// (not in the fold's subset), offers no option cross-validation lacks, and the run lists it.
#[test]
fn an_outlier_is_named_by_its_index_in_the_session() {
    let (_, mut cell) = twin(300, 5);
    let r2 = cell.sessions.iter().position(|s| s.name == "reflector-2").unwrap();
    let robocal::cell::Observation::Position(p) = &mut cell.sessions[r2].measurements[17].observation else {
        panic!("a position")
    };
    p.x += 5.0 * MM;
    let mut o = cv_options(&["reflector-1", "reflector-2", "reflector-3"], 5, Vec::new());
    o.variants = vec![Variant { name: "default".into(), options: options("", &[]) }];
    let cv = crossval(&cell, &o).unwrap();
    assert_eq!(cv.outliers, vec![("reflector-2".to_string(), 17)]);
    let f = cv.folds.iter().find(|f| f.variant == "default").unwrap();
    let refused: Vec<&String> = f.per_fold.iter().filter_map(|r| r.as_ref().err()).collect();
    assert!(!refused.is_empty(), "{:?}", f.per_fold);
    for e in refused {
        assert!(e.contains("reflector-2[17] "), "{e}");
        assert!(!e.contains("exclude") && !e.contains("huber") && !e.contains("Huber"), "{e}");
    }
}

/// The twin's files with `edit` applied to reflector-2's positions (its lines after the header),
/// imported by the command line; `robocal crossval` on them: (exit status, stdout, stderr).
fn crossval_cli(tag: &str, edit: impl Fn(&mut Vec<String>)) -> (i32, String, String) {
    let o = TrackerRunOptions { seed: 5, poses: 200, removed: 2, ..Default::default() };
    let dir = common::fresh_dir(tag);
    let (joints, files) = tracker_run(&o).unwrap().write(&dir, "run", 6).unwrap();
    let text = std::fs::read_to_string(&files[1]).unwrap();
    let (header, mut rows): (Vec<String>, Vec<String>) =
        text.lines().map(String::from).partition(|l| l.starts_with('#'));
    edit(&mut rows);
    std::fs::write(&files[1], [header, rows].concat().join("\n") + "\n").unwrap();
    let cell = dir.join("cell.json");
    let run = |args: Vec<&str>| std::process::Command::new(env!("CARGO_BIN_EXE_robocal")).args(args).output().unwrap();
    let f: Vec<&str> = files.iter().flat_map(|f| ["--positions", f.to_str().unwrap()]).collect();
    let j = joints.to_str().unwrap();
    let import = run([
        vec!["import", "three-reflector", "--robot", "irb120", "--joints", j],
        f.clone(),
        vec!["--out", cell.to_str().unwrap()],
    ]
    .concat());
    if !import.status.success() {
        return (import.status.code().unwrap(), String::new(), String::from_utf8_lossy(&import.stderr).to_string());
    }
    let sessions = "reflector-1,reflector-2,reflector-3";
    let out = run(vec![
        "crossval",
        cell.to_str().unwrap(),
        "--session",
        sessions,
        "--folds",
        "3",
        "--model=",
        "--threads",
        "2",
    ]);
    let s = |b: &[u8]| String::from_utf8_lossy(b).to_string();
    (out.status.code().unwrap(), s(&out.stdout), s(&out.stderr))
}

/// `robocal crossval` with a gross reading: the default model is refused in the folds that train on
/// it, only the "before" reference is scored, so the run fails (exit 1, tables printed), and the
/// advice names the reading by its session index with what this command's user can do.
#[test]
fn crossval_cli_fails_when_only_the_reference_is_scored_and_advises_on_outliers() {
    let (code, out, err) = crossval_cli("cv-outlier", |rows| {
        let v: Vec<f64> = rows[17].split_whitespace().map(|x| x.parse().unwrap()).collect();
        rows[17] = format!("{:.4} {} {}", v[0] + 5.0, v[1], v[2]);
    });
    assert_eq!(code, 1, "{out}\n{err}");
    assert!(out.lines().any(|l| l.starts_with("before ") && !l.contains("refused")), "{out}");
    assert!(
        out.lines()
            .any(|l| l.starts_with("default ") && l.contains("refused: 1 outlier") && l.contains("reflector-2[17] ")),
        "{out}"
    );
    assert!(out.contains("outliers named by the refused fits: reflector-2[17]."), "{out}");
    assert!(out.contains("--sessions reflector-1,reflector-2,reflector-3 --exclude reflector-2:17`"), "{out}");
    assert!(!out.contains("(exclude ") && !out.contains("(huber "), "{out}");
    assert!(err.contains("error: no fitted model was scored (default: every fit refused;"), "{err}");

    // Reflector-2's file in reverse order, which no shift of its lines pairs: every fit refused,
    // the reference's too.
    let (code, out, err) = crossval_cli("cv-refused", |rows| rows.reverse());
    assert_eq!(code, 1, "{out}\n{err}");
    assert!(out.lines().filter(|l| l.contains(" refused: ")).count() >= 2, "{out}");
    assert!(err.contains("every fit refused, the \"before\" reference's too;"), "{err}");
    // Off by one line, it is refused at the import, with the shift named (before: imported, and
    // every fit of the cross-validation refused).
    let (code, out, err) = crossval_cli("cv-shifted", |rows| rows.rotate_left(1));
    assert_ne!(code, 0, "{out}\n{err}");
    assert!(err.contains("each measured position of 'reflector-2' fits the joint readings of the stop after"), "{err}");
}

/// A robot that repeats to millimetres only (a cable-driven Barrett WAM's public tracker data:
/// 2.25 mm RMS, 77 times the instrument) is refused as a misfit, the refusal saying that such a
/// robot leaves this residual too and how to fit it anyway; `crossval --residual-ratio-limit inf`
/// then scores it, as `identify` does (before, crossval had no such option and could only fail).
#[test]
fn crossval_fits_a_robot_that_does_not_repeat_when_told_to() {
    let o = TrackerRunOptions { seed: 9, poses: 200, removed: 2, jitter: 0.25 * DEG, ..Default::default() };
    let dir = common::fresh_dir("cv-unrepeatable");
    let (joints, files) = tracker_run(&o).unwrap().write(&dir, "run", 6).unwrap();
    let cell = dir.join("cell.json");
    let run = |args: Vec<&str>| std::process::Command::new(env!("CARGO_BIN_EXE_robocal")).args(args).output().unwrap();
    let f: Vec<&str> = files.iter().flat_map(|f| ["--positions", f.to_str().unwrap()]).collect();
    let import = run([
        vec!["import", "three-reflector", "--robot", "irb120", "--joints", joints.to_str().unwrap()],
        f,
        vec!["--out", cell.to_str().unwrap()],
    ]
    .concat());
    assert!(import.status.success(), "{}", String::from_utf8_lossy(&import.stderr));
    let crossval = |extra: &[&str]| {
        let mut args = vec!["crossval", cell.to_str().unwrap(), "--session", "reflector-1,reflector-2,reflector-3"];
        args.extend_from_slice(&["--folds", "3", "--model=", "--threads", "2"]);
        args.extend_from_slice(extra);
        let out = run(args);
        let s = |b: &[u8]| String::from_utf8_lossy(b).to_string();
        (out.status.code().unwrap(), s(&out.stdout), s(&out.stderr))
    };
    let (code, out, err) = crossval(&[]);
    assert_eq!(code, 1, "{out}\n{err}");
    assert!(
        out.lines().any(|l| l.starts_with("default ") && l.contains("or the robot does not repeat to this level")),
        "{out}"
    );
    let (code, out, err) = crossval(&["--residual-ratio-limit", "inf"]);
    assert_eq!(code, 0, "{out}\n{err}");
    let row = out.lines().find(|l| l.starts_with("default ")).unwrap_or_else(|| panic!("{out}"));
    let mean: f64 = row.split_whitespace().nth(2).unwrap().parse().unwrap_or_else(|_| panic!("{row}"));
    // The scatter is a turn of 0.25° of every joint at every stop: millimetres, as such a robot's.
    assert!((1.0..20.0).contains(&mean), "{row}");
}

/// A custom robot whose joints declare no mass (a public robot's DH table, as a user first
/// writes it) has no gravity torque anywhere, so no compliance can be fitted: each compliance's
/// status says that this model carries no mass and what to give, not that the axis takes no
/// gravity torque; and `identify` does not claim to have fitted compliance with 0 kg.
#[test]
fn compliances_of_a_robot_without_masses_say_what_to_declare() {
    use robocal::domain::robot::RobotSpec;
    let o = TrackerRunOptions { seed: 4, poses: 150, removed: 0, ..Default::default() };
    let dir = common::fresh_dir("massless");
    let (joints, files) = tracker_run(&o).unwrap().write(&dir, "run", 6).unwrap();
    let mut model = irb120();
    model.preset = None;
    model.name = "irb120 without masses".into();
    for l in &mut model.links {
        l.mass = 0.0;
    }
    let robot = dir.join("robot.json");
    std::fs::write(&robot, RobotSpec::from_model(&model).to_json_value().to_string()).unwrap();
    let (cell, params) = (dir.join("cell.json"), dir.join("params.json"));
    let run = |args: Vec<&str>| std::process::Command::new(env!("CARGO_BIN_EXE_robocal")).args(args).output().unwrap();
    let f: Vec<&str> = files.iter().flat_map(|f| ["--positions", f.to_str().unwrap()]).collect();
    let imported = run([
        vec!["import", "three-reflector", "--robot", robot.to_str().unwrap(), "--joints", joints.to_str().unwrap()],
        f,
        vec!["--out", cell.to_str().unwrap()],
    ]
    .concat());
    assert!(imported.status.success(), "{}", String::from_utf8_lossy(&imported.stderr));
    let out = run(vec!["identify", cell.to_str().unwrap(), "--out", params.to_str().unwrap()]);
    let said = String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{said}");
    assert!(said.contains("no compliance fitted") && !said.contains("compliance fitted with 0 kg"), "{said}");
    let doc: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&params).unwrap()).unwrap();
    let status = |name: &str| {
        doc["parameters"].as_array().unwrap().iter().find(|p| p["name"] == name).unwrap()["status"]
            .as_str()
            .unwrap()
            .to_string()
    };
    for j in 1..=6 {
        let s = status(&format!("c{j}"));
        assert!(s.contains("its links declare no mass") && s.contains("mass_kg"), "c{j}: {s}");
    }
    // With the masses, axis 1 (vertical) still takes no gravity torque, and says only that.
    let id = identify(&import(&joints, &files), &options("", &[])).unwrap();
    let c1 = id.set.layout.index_of(Param::Joint(0, JointTerm::Compliance)).unwrap();
    assert_eq!(id.status[c1].to_string(), "c1: no gravity torque on axis 1");
}

/// A calibration run and a validation run imported apart both name their reflectors
/// `reflector-1`, …: validating the first run's set on the second is held out, though the names
/// match (it was reported "in-sample, … were in its fit" — a UR5's 20 random test poses against
/// its 1,000 grid poses); each reflector is still predicted with its own fitted TCP. The set's
/// fingerprint of what it was fitted on tells the runs apart; the fitted run itself stays
/// in-sample.
#[test]
fn a_run_imported_apart_is_held_out_though_its_sessions_bear_the_fitted_names() {
    let dir = common::fresh_dir("two-runs");
    let run = |args: Vec<&str>| std::process::Command::new(env!("CARGO_BIN_EXE_robocal")).args(args).output().unwrap();
    let mut cells = Vec::new();
    for (seed, purpose) in [(21, "identification"), (22, "validation")] {
        let o = TrackerRunOptions { seed, poses: 150, removed: 0, ..Default::default() };
        let (joints, files) = tracker_run(&o).unwrap().write(&dir, &format!("run{seed}"), 6).unwrap();
        let cell = dir.join(format!("run{seed}.json"));
        let f: Vec<&str> = files.iter().flat_map(|f| ["--positions", f.to_str().unwrap()]).collect();
        let out = run([
            vec!["import", "three-reflector", "--robot", "irb120", "--joints", joints.to_str().unwrap()],
            f,
            vec!["--purpose", purpose, "--out", cell.to_str().unwrap()],
        ]
        .concat());
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        cells.push(cell);
    }
    let params = dir.join("params.json");
    let out = run(vec!["identify", cells[0].to_str().unwrap(), "--out", params.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let validate = |cell: &std::path::Path, extra: &[&str]| {
        let v = dir.join("v.json");
        let mut args = vec!["validate", params.to_str().unwrap(), cell.to_str().unwrap()];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--out", v.to_str().unwrap()]);
        let out = run(args);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_str::<serde_json::Value>(&std::fs::read_to_string(&v).unwrap()).unwrap()
    };
    let other = validate(&cells[1], &[]);
    let statement = other["held_out_statement"].as_str().unwrap();
    assert_eq!(other["held_out"], true, "{statement}");
    assert!(
        statement.contains("reflector-1, reflector-2, reflector-3 here bear the name of a fitted session"),
        "{statement}"
    );
    // Predicted with each reflector's fitted TCP: the pose-to-pose scale, not the plate's 150 mm.
    let mean = other["mean_mm"].as_f64().unwrap();
    assert!(mean < 1.0, "held-out mean {mean} mm");
    let own = validate(&cells[0], &["--session", "reflector-1"]);
    assert_eq!(own["held_out"], false);
    assert!(own["held_out_statement"].as_str().unwrap().starts_with("in-sample, not held out"), "{own}");
}

/// A custom robot file with parallel axes and no `beta_deg` (a UR5's standard DH table as first
/// written for its public data set) fits no β there; the identification says so, naming the
/// joints and what to give, and the preset, which declares β, says nothing.
#[test]
fn parallel_axes_without_beta_are_said() {
    let o = TrackerRunOptions { seed: 6, poses: 150, removed: 0, ..Default::default() };
    let dir = common::fresh_dir("no-beta");
    let (joints, files) = tracker_run(&o).unwrap().write(&dir, "run", 6).unwrap();
    let mut model = irb120();
    model.preset = None;
    model.links[2].beta = None;
    let cell = three_reflector::import(&joints, &files, model, Purpose::Identification).unwrap().cell;
    let id = identify(&cell, &options("", &[])).unwrap();
    let said = "axes 2 and 3 are nominally parallel and joint 3 carries no Hayati β in this robot's model";
    assert!(id.notes.iter().any(|n| n.starts_with(said) && n.contains("\"beta_deg\": 0")), "{:?}", id.notes);
    let id = identify(&import(&joints, &files), &options("", &[])).unwrap();
    assert!(!id.notes.iter().any(|n| n.contains("Hayati β")), "{:?}", id.notes);
}

/// A warm-up that nothing logs is said where the model misses, not named as a term of the robot:
/// a twin warming up along its run (a stop every 10 s, the thermal effect, no time or temperature
/// in the files) and the same run cold. The warm run's held-out errors drift along the measuring
/// order (p at the permutations' floor), the summary says so with what to log; the cold run's do
/// not, and its summary says nothing of it. Where the drift is said, the last accepted model is
/// refitted with the drift as a nuisance (`+drift`) and the figures are given. (The trend's size
/// and σ against a known drift: `diagnose::drift`'s unit tests.)
#[test]
fn an_unlogged_warm_up_is_said_as_a_drift_along_the_measuring_order() {
    let run = |effects: &str, stop_s: f64| {
        diagnose_twin_with(TrackerRunOptions {
            seed: 2,
            poses: 600,
            removed: 6,
            stop_s,
            effects: robocal::sim::effects::Effects::parse(effects, 6).unwrap(),
            ..Default::default()
        })
    };
    let warm_cell = {
        let dir = common::fresh_dir("real-data-warm-up");
        let o = TrackerRunOptions {
            seed: 2,
            poses: 600,
            removed: 6,
            stop_s: 10.0,
            effects: robocal::sim::effects::Effects::parse("thermal:rise_c=20:tau_s=1800", 6).unwrap(),
            ..Default::default()
        };
        let (joints, files) = tracker_run(&o).unwrap().write(&dir, "run", 6).unwrap();
        import(&joints, &files)
    };
    let warm = diagnose_cell(&warm_cell);
    assert_eq!(warm.drift_note, None);
    let d = warm.location.order_drift.as_ref().expect("tested: the import numbers the stops");
    assert!(d.found() && d.p <= 0.002 && d.order_locality > 0.9, "{d:?}");
    assert!(
        warm.verdict.summary.contains("held-out errors drift along the measuring order"),
        "{}",
        warm.verdict.summary
    );
    assert!(warm.verdict.summary.contains("log time_s and temperature_c"), "{}", warm.verdict.summary);
    // The drift fitted as a nuisance of the run beside the last accepted model: of the trend's
    // size (a warm-up's curve about its mean is a fraction of its first-to-last change), and the
    // robot's parameters fitted without it predict held-out poses no worse at the run's mean.
    let n = d.nuisance.expect("the last model refitted with +drift");
    eprintln!("nuisance {n:?}, first to last {:.4} mm", d.first_to_last.norm() / MM);
    assert!((0.15..1.0).contains(&(n.fitted_rms / d.first_to_last.norm())), "{n:?} {d:?}");
    assert!(n.with <= 1.02 * n.without, "{n:?}");
    assert!(warm.verdict.summary.contains("`identify --model +drift`"), "{}", warm.verdict.summary);
    // A set identified with the drift terms is diagnosed as the same set without them: every figure
    // predicts at the run's mean (before, its screening predicted held-out readings at their place
    // in the run while its refitted figures predicted them at the run's mean), and a note says so.
    let drifted = diagnose_cell_identified_with(&warm_cell, "+drift");
    let note = drifted.drift_note.as_deref().expect("a note");
    assert!(note.starts_with("the set's 9 drift terms along its measuring run are left out"), "{note}");
    assert!(!drifted.model.model.extra.iter().any(|p| matches!(p, robocal::kinematics::Param::Drift(..))));
    assert_eq!(drifted.verdict.status, warm.verdict.status, "{}", drifted.verdict.summary);
    assert_eq!(drifted.shrink.len(), warm.shrink.len());
    for (a, b) in drifted.shrink.iter().zip(&warm.shrink) {
        assert_eq!(a.model, b.model);
        assert!((a.stats.mean - b.stats.mean).abs() < 1e-9, "{:?} against {:?}", a.stats, b.stats);
    }
    let cold = run("", 0.0);
    let c = cold.location.order_drift.as_ref().expect("tested");
    assert!(!c.found() && c.nuisance.is_none(), "{c:?}");
    assert!(!cold.verdict.summary.contains("along the measuring order"), "{}", cold.verdict.summary);
    assert!(d.first_to_last.norm() > 3.0 * c.first_to_last.norm().max(d.first_to_last_std.norm()), "{d:?} {c:?}");
}

/// A unit mistake is refused by the import, before a payload centre is registered on it: joints
/// written in radians and positions written in metres, each from a twin whose files in degrees and
/// millimetres import. (Before, both imported, the radian one with a "centre of mass at (−266.7,
/// −6.1, 589.5) mm … at the reflectors' centroid" that meant nothing, and `identify` refused.)
#[test]
fn an_import_refuses_joints_in_radians_and_positions_in_metres() {
    let o = TrackerRunOptions { seed: 3, poses: 60, removed: 0, ..Default::default() };
    let dir = common::fresh_dir("real-data-units");
    let (joints, files) = tracker_run(&o).unwrap().write(&dir, "run", 6).unwrap();
    // Every line of numbers scaled by `k`, comments kept.
    let scaled = |from: &std::path::Path, to: &str, k: f64| {
        let text: String = std::fs::read_to_string(from)
            .unwrap()
            .lines()
            .map(|l| match l.split_whitespace().map(str::parse::<f64>).collect::<Result<Vec<_>, _>>() {
                Ok(v) if !v.is_empty() => {
                    v.iter().map(|x| format!("{:.9}", x * k)).collect::<Vec<_>>().join(" ") + "\n"
                }
                _ => format!("{l}\n"),
            })
            .collect();
        let path = dir.join(to);
        std::fs::write(&path, text).unwrap();
        path
    };
    let refused = |joints: &std::path::Path, files: &[PathBuf]| {
        three_reflector::import(joints, files, irb120(), Purpose::Identification).err().map(|e| e.to_string())
    };
    assert_eq!(refused(&joints, &files), None, "the files as written import");
    let radians = scaled(&joints, "rad.txt", DEG);
    let e = refused(&radians, &files).expect("joints in radians refused");
    assert!(e.contains("session 'reflector-1': its joint readings are in radians, not degrees"), "{e}");
    let metres: Vec<PathBuf> = files.iter().enumerate().map(|(i, f)| scaled(f, &format!("m{i}.txt"), 1e-3)).collect();
    let e = refused(&joints, &metres).expect("positions in metres refused");
    assert!(e.contains("Check the positions' unit") && e.contains("metres 0.001"), "{e}");
}

/// Joint readings in another convention than the robot model (issue 24, item 1: "when a fit truly
/// fails, the error says why"): before, a twin whose joint 2 read 90° more imported and
/// identified — θ2 −179.9° for a nominal −90°, residual 0.56 mm where the right readings give
/// 0.33, the payload "below 3 σ" at −4.2 ± 0.09 kg — and read as a calibration. Now the import and
/// the identification refuse it and name the change that makes the nominal robot fit: a turn, a
/// coupling (a Fanuc J3 read against the horizontal), a pair of turns (a shoulder and an elbow
/// counted from other zeros); positions in a mirrored frame are named as such. A robot model with a
/// wrong length, which no change of the readings
/// explains, is still fitted, with a note. The robot's limits are opened so that only the
/// convention check can refuse.
#[test]
fn joint_readings_in_another_convention_are_refused_with_the_change_that_explains_them() {
    use robocal::identify::IdentifyError;
    use robocal::identify::convention::ReadingChange;
    use std::f64::consts::FRAC_PI_2;
    let mut robot = irb120();
    robot.preset = None;
    robot.name = "irb120, limits opened".into();
    for l in &mut robot.links {
        l.limits = [-400.0 * DEG, 400.0 * DEG];
    }
    let o = TrackerRunOptions { seed: 5, poses: 200, removed: 0, ..Default::default() };
    let dir = common::fresh_dir("real-data-convention");
    let (joints, files) = tracker_run(&o).unwrap().write(&dir, "run", 6).unwrap();
    // The joints file with each line's readings (deg) changed by `edit`.
    let edited = |tag: &str, edit: &dyn Fn(&mut [f64])| {
        let text: String = std::fs::read_to_string(&joints)
            .unwrap()
            .lines()
            .map(|l| match l.split_whitespace().map(str::parse::<f64>).collect::<Result<Vec<_>, _>>() {
                Ok(mut v) if !v.is_empty() => {
                    edit(&mut v);
                    v.iter().map(|x| format!("{x:.6}")).collect::<Vec<_>>().join(" ") + "\n"
                }
                _ => format!("{l}\n"),
            })
            .collect();
        let path = dir.join(format!("{tag}.txt"));
        std::fs::write(&path, text).unwrap();
        path
    };
    let import_with = |robot: &robocal::kinematics::model::RobotModel, joints: &std::path::Path| {
        three_reflector::import(joints, &files, robot.clone(), Purpose::Identification).map(|i| i.cell)
    };
    let cell = import_with(&robot, &joints).expect("the readings as written import");
    let id = identify(&cell, &options("", &[])).unwrap();
    assert!(!id.notes.iter().any(|n| n.contains("missed them by")), "{:?}", id.notes);

    // Refused by the import, the change named.
    for (tag, edit, named) in [
        ("turn", &(|q: &mut [f64]| q[1] += 90.0) as &dyn Fn(&mut [f64]), "with joint 2 as q2 − 90° by"),
        ("coupled", &|q: &mut [f64]| q[2] += q[1], "with joint 3 as q3 − q2 by"),
        (
            "pair",
            &|q: &mut [f64]| (q[1], q[2]) = (q[1] - 90.0, q[2] + 90.0),
            "with joint 2 as q2 + 90° and joint 3 as q3 − 90° by",
        ),
    ] {
        let e = import_with(&robot, &edited(tag, edit)).err().map(|e| e.to_string()).expect(tag);
        assert!(e.contains("do not follow the robot model's conventions") && e.contains(named), "{tag}: {e}");
    }
    // Five joints at once, as a KUKA's readings differ from a DH table. On these random poses the
    // stepwise search finds a convention the positions cannot tell from it (another arm branch
    // reaches the same flange positions); on a Fanuc's joint sweeps read so it found nothing, and
    // only the search over every set of reversed joints with turns of joints 2 and 3
    // (`whole_convention`) names the five. Either way the change named brings the miss back to
    // this twin's 1.6 mm.
    let kuka = |q: &mut [f64]| (q[0], q[1], q[2], q[3], q[5]) = (-q[0], q[1] - 90.0, q[2] + 90.0, -q[3], -q[5]);
    let e = import_with(&robot, &edited("kuka", &kuka)).err().map(|e| e.to_string()).expect("kuka");
    assert!(e.contains("do not follow the robot model's conventions"), "{e}");
    let after: f64 = e.split(" by ").nth(2).unwrap().split(" mm").next().unwrap().parse().unwrap();
    assert!(after < 2.0, "{e}");

    // Positions with one axis reversed (a left-handed frame): the mirror named first, the joint
    // signs that fit as well after it — not three joints' signs alone, a confident wrong name
    // for the likelier mistake.
    let mirrored: Vec<PathBuf> = files
        .iter()
        .enumerate()
        .map(|(k, f)| {
            let text: String = std::fs::read_to_string(f)
                .unwrap()
                .lines()
                .map(|l| match l.split_whitespace().map(str::parse::<f64>).collect::<Result<Vec<_>, _>>() {
                    Ok(v) if v.len() == 3 => format!("{} {} {}\n", v[0], -v[1], v[2]),
                    _ => format!("{l}\n"),
                })
                .collect();
            let to = dir.join(format!("mirrored-{k}.txt"));
            std::fs::write(&to, text).unwrap();
            to
        })
        .collect();
    let e = three_reflector::import(&joints, &mirrored, robot.clone(), Purpose::Identification)
        .err()
        .map(|e| e.to_string())
        .expect("mirrored positions refused");
    assert!(
        e.contains("the measured positions are mirrored against the robot")
            && e.contains("the joints read otherwise: joint 1 as −q1 and joint 4 as −q4 and joint "),
        "{e}"
    );

    // With the preset's limits the quarter turn puts readings beyond joint 2's: the refusal says
    // that, and the change that explains them.
    let e = import_with(&irb120(), &dir.join("turn.txt")).err().map(|e| e.to_string()).unwrap();
    assert!(
        e.contains("is outside joint 2's limits")
            && e.contains(". The joint readings do not follow")
            && e.contains("with joint 2 as q2 − 90° by"),
        "{e}"
    );

    // Refused by the identification of a cell that never saw the import's check: the finding
    // holds the change, and with it the nominal robot misses as with the readings as written.
    let mut turned = cell.clone();
    turned.sessions.iter_mut().flat_map(|s| &mut s.measurements).for_each(|m| m.q[1] += FRAC_PI_2);
    let Err(IdentifyError::JointConvention { finding }) = identify(&turned, &options("", &[])) else {
        panic!("a quarter turn of joint 2 refused");
    };
    assert_eq!(finding.changes(), [ReadingChange::Joint { joint: 1, flip: false, offset: -FRAC_PI_2 }]);
    let registered = robocal::identify::prepare(&cell, &options("", &[])).unwrap().start_rms.unwrap();
    assert!(finding.rms > 0.1, "{} m", finding.rms);
    assert!((finding.rms_changed - registered).abs() < 1e-6 * registered.max(1e-3), "{finding:?} {registered}");

    // A robot model whose a2 is 30 mm long: the nominal robot misses by more than the bound, no
    // change of the readings explains it, and the fit finds the length, saying how far it started.
    let mut long = robot.clone();
    long.links[2].a += 30.0 * MM;
    let cell = import_with(&long, &joints).expect("a wrong length is no convention");
    let id = identify(&cell, &options("", &[])).unwrap();
    let note = id.notes.iter().find(|n| n.contains("missed them by")).expect("the start's miss said");
    assert!(note.contains("no quarter turn, sign or coupling"), "{note}");
    let a2 = id.set.layout.index_of(Param::A(2)).unwrap();
    assert!((id.set.values[a2] - 0.270).abs() < 0.5 * MM, "a2 {} mm", id.set.values[a2] / MM);
}

/// A cell PC posts its measurements with the robot's base guess and its tools' TCPs: nothing was
/// registered, so the starting checks used to be skipped, and joint 2 read a quarter turn off
/// converged to θ2 −179.9° and 0.56 mm where the right readings give 0.33 mm. The checks now
/// set the guess aside and look at the registration; a guess typed wrong (a 37.5° error in the
/// base's rotation) is weighed against the registration, and the fit starts from the better.
#[test]
fn a_cell_with_a_base_guess_and_declared_tools_is_checked_as_an_import_is() {
    use robocal::identify::IdentifyError;
    use robocal::identify::convention::ReadingChange;
    use std::f64::consts::FRAC_PI_2;
    let mut robot = irb120();
    robot.preset = None;
    for l in &mut robot.links {
        l.limits = [-400.0 * DEG, 400.0 * DEG];
    }
    let o = TrackerRunOptions { seed: 5, poses: 200, removed: 0, ..Default::default() };
    let dir = common::fresh_dir("real-data-guess");
    let (joints, files) = tracker_run(&o).unwrap().write(&dir, "run", 6).unwrap();
    let cell = three_reflector::import(&joints, &files, robot, Purpose::Identification).unwrap().cell;
    let id = identify(&cell, &options("", &[])).unwrap();
    // The cell as a cell PC posts it: the identified base as its guess, each reflector's TCP
    // declared and not identified.
    let mut posted = cell.clone();
    let base: Vec<f64> = (0..6).map(|k| id.set.value(Param::Base(k)).unwrap()).collect();
    posted.base_guess = Some(base.clone().try_into().unwrap());
    for s in &mut posted.sessions {
        let t = id.tools.iter().find(|t| t.sessions.contains(&s.name)).unwrap();
        s.tool.tcp = t.tool.tcp;
        s.identify_tcp = false;
    }
    let right = identify(&posted, &options("", &[])).unwrap();
    assert!(!right.notes.iter().any(|n| n.contains("base guess") || n.contains("missed them")), "{:?}", right.notes);
    let rms = right.quality.rms_residual;
    assert!((rms - id.quality.rms_residual).abs() < 0.02 * rms, "{rms} against {}", id.quality.rms_residual);

    let mut turned = posted.clone();
    turned.sessions.iter_mut().flat_map(|s| &mut s.measurements).for_each(|m| m.q[1] += FRAC_PI_2);
    match identify(&turned, &options("", &[])) {
        Err(IdentifyError::JointConvention { finding }) => {
            assert_eq!(finding.changes(), [ReadingChange::Joint { joint: 1, flip: false, offset: -FRAC_PI_2 }])
        }
        other => panic!("a quarter turn of joint 2 with a base guess: {:?}", other.map(|i| i.quality.rms_residual)),
    }

    let mut typo = posted.clone();
    typo.base_guess.as_mut().unwrap()[3] -= 37.5 * DEG;
    let from_typo = identify(&typo, &options("", &[])).unwrap();
    let note = from_typo.notes.iter().find(|n| n.contains("the base guess missed")).expect("the guess set aside, said");
    assert!(note.contains("the fit started from the registration"), "{note}");
    assert!(
        (from_typo.quality.rms_residual - rms).abs() < 1e-6 * rms,
        "{} against {rms}",
        from_typo.quality.rms_residual
    );
}

/// A tracker following three reflectors can lock onto the neighbouring one: that stop's line in
/// reflector 1's file holds reflector 2's position and the other way round. The refusal named
/// them as outliers, 150 mm off, and its `--exclude` listed only the five it showed (followed, it
/// was refused again for the rest). Now each says which target's TCP it fits at its own joints,
/// the remedy lists every one, and with the ratio printed beside a robust fit's RMS it says what
/// the ratio is of.
#[test]
fn readings_of_the_neighbouring_reflector_are_named_and_all_listed() {
    use robocal::identify::{IdentifyError, outliers_message};
    let (dir, clean, cell, stops) = swapped_run("real-data-swapped");

    let (outliers, factor) = match identify(&cell, &options("", &[])) {
        Err(IdentifyError::Outliers { outliers, factor }) => (outliers, factor),
        other => panic!(
            "swapped readings refused as outliers: {:?}",
            other.map(|i| i.quality.rms_residual).map_err(|e| e.to_string())
        ),
    };
    let mut named: Vec<(String, usize)> = outliers.iter().map(|w| (w.session.clone(), w.index)).collect();
    named.sort();
    let mut expected: Vec<(String, usize)> =
        stops.iter().flat_map(|&k| [("reflector-1".to_string(), k), ("reflector-2".to_string(), k)]).collect();
    expected.sort();
    assert_eq!(named, expected);
    for w in &outliers {
        let other = if w.session == "reflector-1" { "reflector-2" } else { "reflector-1" };
        let (s, d) = w.fits_other.as_ref().unwrap_or_else(|| panic!("{w:?}"));
        // The fit they biased predicts the other reflector within a few mm, against 150 mm off.
        assert!(s == other && *d < w.residual / 20.0, "{w:?}");
    }
    let message = outliers_message(&outliers, factor, "--exclude", "--huber");
    assert!(message.contains(" and 3 more. 8 of them fit another target's TCP"), "{message}");
    let refs = message.split("(--exclude ").nth(1).unwrap().split(')').next().unwrap();
    assert_eq!(refs.split(',').count(), 8, "{message}");

    // Left out as the message says, the fit is the clean files' less those readings.
    let mut opts = options("", &[]);
    opts.selection.exclude = outliers.iter().map(|w| (w.session.clone(), w.index)).collect();
    let left_out = identify(&cell, &opts).unwrap();
    let reference = identify(&clean, &opts).unwrap();
    let rms = reference.quality.rms_residual;
    assert!((left_out.quality.rms_residual - rms).abs() < 1e-9 * rms, "{} {rms}", left_out.quality.rms_residual);
    // A 5 mm error is an outlier of its own: no other target is named for it.
    let mut off = clean.clone();
    if let robocal::cell::Observation::Position(p) = &mut off.sessions[2].measurements[40].observation {
        p.z += 5.0 * MM;
    }
    let Err(IdentifyError::Outliers { outliers, .. }) = identify(&off, &options("", &[])) else { panic!("5 mm off") };
    assert!(outliers.len() == 1 && outliers[0].fits_other.is_none(), "{outliers:?}");

    // With the Huber loss the swapped readings stay in the RMS, not in the ratio: the command
    // says what the ratio is of.
    let path = dir.join("swapped.json");
    std::fs::write(&path, serde_json::to_string(&robocal::domain::cell::CellFile::from_cell(&cell)).unwrap()).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["identify", path.to_str().unwrap(), "--huber", "2.5", "--out", dir.join("p.json").to_str().unwrap()])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && text.contains("mm with its outliers left out ("), "{text}");
    // Cross-validation's advice: the command that checks the fit without them lists all eight.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["crossval", path.to_str().unwrap(), "--session", "reflector-1,reflector-2,reflector-3"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    let refs = text.split("--exclude ").nth(1).and_then(|t| t.split('`').next()).unwrap_or_else(|| panic!("{text}"));
    assert_eq!(refs.split(',').count(), 8, "{text}");
    // Its first remedy, run as printed: cross-validated without them, each reflector's figure as
    // the clean files' less those readings.
    let command = text.split("`robocal ").nth(1).and_then(|t| t.split('`').next()).unwrap_or_else(|| panic!("{text}"));
    assert!(command.starts_with("crossval "), "{command}");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(command.split_whitespace())
        .args(["--out", dir.join("cv.json").to_str().unwrap(), "--report", dir.join("cv.html").to_str().unwrap()])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && text.contains("8 reading(s) left out of every fit and every score"), "{text}");
    let html = std::fs::read_to_string(dir.join("cv.html")).unwrap();
    assert!(html.contains("8 reading(s) left out of every fit and every score"), "the HTML report says so too");
    let cv: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("cv.json")).unwrap()).unwrap();
    assert_eq!(cv["excluded"].as_array().map(Vec::len), Some(8), "{cv}");
    assert!(cv.get("outliers").is_none(), "none refused again: {cv}");
    // The same command on the clean files: the same figures, to the last digit written.
    let clean_path = dir.join("clean.json");
    std::fs::write(&clean_path, serde_json::to_string(&robocal::domain::cell::CellFile::from_cell(&clean)).unwrap())
        .unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(command.replace(path.to_str().unwrap(), clean_path.to_str().unwrap()).split_whitespace())
        .args(["--out", dir.join("cv-clean.json").to_str().unwrap()])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let reference: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("cv-clean.json")).unwrap()).unwrap();
    let pooled = |v: &serde_json::Value| {
        v["kfold"].as_array().unwrap().iter().find(|k| k["model"] == "default").unwrap()["pooled"]["mean_mm"]
            .as_f64()
            .unwrap()
    };
    let want = pooled(&reference);
    assert!((pooled(&cv) - want).abs() < 1e-6, "{} against the clean files' {want} mm", pooled(&cv));
}

/// A run of 200 stops whose readings of reflectors 1 and 2 were swapped at four stops (a tracker
/// that locked onto the neighbouring SMR), written and imported: the directory, the clean files'
/// cell, the swapped files' cell and the stops' 0-based measurement indices (every stop is
/// visible to both reflectors in this run).
fn swapped_run(name: &str) -> (PathBuf, Cell, Cell, [usize; 4]) {
    let o = TrackerRunOptions { seed: 8, poses: 200, removed: 0, ..Default::default() };
    let dir = common::fresh_dir(name);
    let (joints, files) = tracker_run(&o).unwrap().write(&dir, "run", 6).unwrap();
    let read = |f: &PathBuf| std::fs::read_to_string(f).unwrap().lines().map(str::to_owned).collect::<Vec<_>>();
    let (mut one, mut two) = (read(&files[0]), read(&files[1]));
    let data: Vec<usize> = (0..one.len()).filter(|&i| !one[i].starts_with('#')).collect();
    let stops = [11, 57, 120, 163];
    for &k in &stops {
        let l = data[k];
        std::mem::swap(&mut one[l], &mut two[l]);
    }
    let swapped = [dir.join("s1.txt"), dir.join("s2.txt"), files[2].clone()];
    std::fs::write(&swapped[0], one.join("\n") + "\n").unwrap();
    std::fs::write(&swapped[1], two.join("\n") + "\n").unwrap();
    let clean = three_reflector::import(&joints, &files, irb120(), Purpose::Identification).unwrap().cell;
    let cell = three_reflector::import(&joints, &swapped, irb120(), Purpose::Identification).unwrap().cell;
    (dir, clean, cell, stops)
}

/// A set identified with the neighbouring reflector's readings left out (`--exclude`, as the
/// refusal advised) and then diagnosed: the diagnosis fitted and tested every reading, the
/// swapped ones too, and answered `not_separable` on a held-out RMS of 8.9 mm — another data set
/// than the calibration's. The set now records what it left out (with each reading's
/// fingerprint) and the diagnosis leaves the same readings out, found by their content; and a
/// diagnosis of a set without that record says that a few readings carry its figures.
#[test]
fn a_diagnosis_leaves_out_the_readings_the_sets_identification_left_out() {
    use robocal::diagnose::{DiagnoseOptions, diagnose};
    use robocal::domain::ParameterSetDoc;
    use robocal::domain::diagnosis::input_of;
    let (_dir, clean, cell, stops) = swapped_run("real-data-swapped-diagnosis");
    let mut left: Vec<(String, usize)> =
        stops.iter().flat_map(|&k| [("reflector-1".to_string(), k), ("reflector-2".to_string(), k)]).collect();
    left.sort();
    let mut opts = options("", &[]);
    opts.selection.exclude = left.clone();
    let (_, written) = robocal::domain::identification::run_identification(&cell, opts, None, &|| {}).unwrap();
    // As the file carries it: per session, the indices and each reading's fingerprint.
    let doc = ParameterSetDoc::from_json(&written.to_json_pretty()).unwrap();
    let recorded = doc.quality.as_ref().and_then(|q| q.excluded.clone()).expect("recorded");
    assert_eq!(recorded.len(), 2, "{recorded:?}");
    for f in &recorded {
        let s = cell.session(&f.session).unwrap();
        assert_eq!(f.indices, stops.to_vec(), "{f:?}");
        let of = |i: usize| robocal::cell::fingerprint::of_measurement(&cell, &s.measurements[i]).unwrap();
        assert_eq!(f.fingerprints.clone().unwrap(), stops.iter().map(|&i| of(i)).collect::<Vec<_>>());
    }
    let mut without = doc.clone();
    without.quality.as_mut().unwrap().excluded = None;

    let dopts = DiagnoseOptions { validation: Some(Vec::new()), threads: 2, ..DiagnoseOptions::default() };
    let sorted = |d: &robocal::diagnose::Diagnosis| {
        let mut e = d.excluded.clone();
        e.sort();
        e
    };
    let d = diagnose(&input_of(&cell, &doc), &dopts).unwrap();
    assert_eq!(sorted(&d), left);
    let note = d.excluded_note.clone().unwrap_or_default();
    assert!(note.starts_with("8 readings that the parameter set's identification left out"), "{note}");
    // The same diagnosis as naming them (`--exclude`), figure for figure.
    let named =
        diagnose(&input_of(&cell, &without), &DiagnoseOptions { exclude: left.clone(), ..dopts.clone() }).unwrap();
    let mean = |d: &robocal::diagnose::Diagnosis| d.decomposition.heldout.mean;
    assert_eq!(
        (mean(&d), d.verdict.status, &d.verdict.summary),
        (mean(&named), named.verdict.status, &named.verdict.summary)
    );
    assert!(named.excluded_note.is_none(), "{:?}", named.excluded_note);
    // Without them the held-out error is the swapped readings' (150 mm each), and the verdict
    // says so, naming all eight to check and leave out.
    let blind = diagnose(&input_of(&cell, &without), &dopts).unwrap();
    assert!(mean(&blind) > 5.0 * mean(&d), "{} against {} mm", mean(&blind) / MM, mean(&d) / MM);
    assert!(blind.excluded.is_empty());
    let summary = &blind.verdict.summary;
    assert!(summary.contains("; 8 of the ") && summary.contains("tested readings carry 9"), "{summary}");
    let refs = summary.rsplit("(exclude ").next().unwrap().trim_end_matches(')');
    let mut named: Vec<(String, usize)> = refs
        .split(',')
        .map(|r| {
            let (s, i) = r.rsplit_once(':').unwrap();
            (s.to_string(), i.parse().unwrap())
        })
        .collect();
    named.sort();
    assert_eq!(named, left, "{summary}");
    assert!(!d.verdict.summary.contains("tested readings carry"), "{}", d.verdict.summary);

    // Another import of the same run that starts one stop later: the same readings, by content.
    let mut later = cell.clone();
    for s in &mut later.sessions {
        s.measurements.remove(0);
    }
    let shifted = diagnose(&input_of(&later, &doc), &dopts).unwrap();
    let moved: Vec<(String, usize)> = left.iter().map(|(s, i)| (s.clone(), i - 1)).collect();
    assert_eq!(sorted(&shifted), moved);
    // The corrected files hold none of them: nothing is left out, and the note says so.
    let corrected = diagnose(&input_of(&clean, &doc), &dopts).unwrap();
    assert!(corrected.excluded.is_empty());
    let note = corrected.excluded_note.unwrap_or_default();
    assert!(
        note.starts_with("8 readings that the parameter set's identification left out are not in these sessions"),
        "{note}"
    );
}

/// Positions paired with the wrong line of joint readings — a line deleted from one file only,
/// a header counted as data — imported as a run whose residual is hundreds of millimetres, and
/// `identify` refused it as a misfit that advised checking the TCPs, the frames and outliers.
/// Now the import names the shift: every file against the joints, or one reflector's file alone.
#[test]
fn positions_paired_with_another_line_of_joints_are_refused_with_the_shift() {
    let o = TrackerRunOptions { seed: 6, poses: 200, removed: 0, ..Default::default() };
    let dir = common::fresh_dir("real-data-pairing");
    let (joints, files) = tracker_run(&o).unwrap().write(&dir, "run", 6).unwrap();
    // The file with its data lines from `skip` on, `pad` copies of its last line added.
    let cut = |from: &std::path::Path, tag: &str, skip: usize, drop_last: usize, pad: usize| {
        let text = std::fs::read_to_string(from).unwrap();
        let (comments, data): (Vec<&str>, Vec<&str>) = text.lines().partition(|l| l.starts_with('#'));
        let mut lines: Vec<&str> = comments;
        let kept = &data[skip..data.len() - drop_last];
        lines.extend(kept);
        lines.extend(std::iter::repeat_n(*kept.last().unwrap(), pad));
        let to = dir.join(format!("{tag}-{}", from.file_name().unwrap().to_str().unwrap()));
        std::fs::write(&to, lines.join("\n") + "\n").unwrap();
        to
    };
    let refused = |joints: &std::path::Path, files: &[PathBuf]| {
        three_reflector::import(joints, files, irb120(), Purpose::Identification).err().map(|e| e.to_string())
    };
    assert_eq!(refused(&joints, &files), None, "the files as written import");
    // The joints file lost its first line, every positions file its last.
    let e = refused(&cut(&joints, "all", 1, 0, 0), &files.iter().map(|f| cut(f, "all", 0, 1, 0)).collect::<Vec<_>>())
        .expect("every file shifted against the joints");
    assert!(
        e.contains("not paired with their joint readings")
            && e.contains("each measured position of every session fits the joint readings of the stop before"),
        "{e}"
    );
    // Reflector 2's file alone lost its first line (its last repeated to keep the count).
    let mut one = files.clone();
    one[1] = cut(&files[1], "one", 1, 0, 1);
    let e = refused(&joints, &one).expect("one file shifted");
    assert!(e.contains("each measured position of 'reflector-2' fits the joint readings of the stop after"), "{e}");
}

/// A twin of joint sweeps, one joint moved at a time from one home pose (the layout of a public
/// three-SMR tracker run of a Fanuc R-2000iC/165F: joint 1 swept over 9° only, joint 3 over 4°),
/// on that robot's nominal geometry with a built robot's errors: a 360 mm plate, an offset turn
/// of every joint per sweep (σ `offset_deg`: the sweeps were approached apart), a turn of 0.003°
/// at every stop and 50 µm of tracker noise. Written as three-reflector files and imported.
fn sweeps_twin(seed: u64, offset_deg: f64) -> Cell {
    let (joints, files, model) = sweeps_twin_files(seed, offset_deg);
    three_reflector::import(&joints, &files, model, Purpose::Identification).unwrap().cell
}

/// The files of [`sweeps_twin`] and its robot model.
fn sweeps_twin_files(seed: u64, offset_deg: f64) -> (PathBuf, Vec<PathBuf>, robocal::kinematics::model::RobotModel) {
    sweeps_twin_files_as(seed, offset_deg, false)
}

/// The files of [`sweeps_twin`], or with `fanuc` those of the same sweeps as a FANUC makes them:
/// the links' masses in the robot file, and joint 2 swept with the J3 reading held, which is read
/// against the horizontal, so that the model's θ3 turns with θ2 and the forearm keeps its angle
/// (its holding torque τ3 hardly changes along the sweep).
fn sweeps_twin_files_as(
    seed: u64,
    offset_deg: f64,
    fanuc: bool,
) -> (PathBuf, Vec<PathBuf>, robocal::kinematics::model::RobotModel) {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    use robocal::domain::robot::RobotSpec;
    use robocal::kinematics::{JointState, ParameterSet, Tool};
    let spec = serde_json::json!({"name": "r2000ic-165f-like", "convention": "standard", "joints": [
        {"alpha_deg": -90, "a_mm": 312, "d_mm": 670, "limits_deg": [-185, 185]},
        {"alpha_deg": 180, "a_mm": 1075, "d_mm": 0, "theta_deg": -90, "limits_deg": [-60, 76]},
        {"alpha_deg": -90, "a_mm": 225, "d_mm": 0, "beta_deg": 0, "limits_deg": [-180, 180]},
        {"alpha_deg": 90, "a_mm": 0, "d_mm": -1280, "limits_deg": [-360, 360]},
        {"alpha_deg": -90, "a_mm": 0, "d_mm": 0, "limits_deg": [-125, 125]},
        {"alpha_deg": 0, "a_mm": 0, "d_mm": -215, "limits_deg": [-360, 360]}]});
    let mut spec = spec;
    if fanuc {
        let masses = [
            (300.0, [0.0, 0.0, 0.0]),
            (150.0, [-537.5, 0.0, 0.0]),
            (120.0, [0.0; 3]),
            (80.0, [0.0; 3]),
            (30.0, [0.0; 3]),
            (5.0, [0.0; 3]),
        ];
        for (joint, (m, com)) in spec["joints"].as_array_mut().unwrap().iter_mut().zip(masses) {
            joint["mass_kg"] = serde_json::json!(m);
            joint["com_mm"] = serde_json::json!(com);
        }
    }
    let model = RobotSpec::from_json_value(&spec).unwrap().to_model().unwrap();
    let base = [4.36, 0.43, -1.35, 156.8 * DEG, 0.5 * DEG, -0.3 * DEG];
    let mut truth = ParameterSet::nominal(model.clone(), Tool::flange(), base);
    for (name, change) in [
        ("alpha1", 0.03 * DEG),
        ("a1", -0.8 * MM),
        ("a2", 0.4 * MM),
        ("a3", -0.6 * MM),
        ("d4", -1.1 * MM),
        ("theta2", -0.04 * DEG),
        ("theta3", 0.03 * DEG),
        ("theta4", 0.05 * DEG),
        ("beta2", 0.02 * DEG),
    ] {
        let p = Param::parse(name).unwrap();
        let v = truth.value(p).unwrap();
        assert!(truth.set(p, v + change), "{name}");
    }
    let smrs = [[0.202, -0.056, -0.202], [-0.050, 0.250, -0.100], [0.150, 0.230, -0.320]];
    let chains: Vec<_> = smrs
        .iter()
        .map(|s| truth.with_tool(Tool { tcp: [s[0], s[1], s[2], 0.0, 0.0, 0.0], ..Tool::flange() }).chain())
        .collect();
    // Home, then each joint swept alone through ten stops (degrees).
    let home = [24.7, 18.5, 7.4, -81.4, -7.2, 172.8];
    let sweeps: [(usize, f64, f64); 6] =
        [(0, 19.6, 28.6), (1, -45.0, 49.0), (2, 5.6, 9.6), (3, -275.0, -50.0), (4, -62.0, 11.0), (5, -120.0, 350.0)];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let offset = Normal::new(0.0, offset_deg * DEG).unwrap();
    let (jitter, noise) = (Normal::new(0.0, 0.003 * DEG).unwrap(), Normal::new(0.0, 0.05 * MM).unwrap());
    let (mut joints, mut positions) = (String::new(), vec![String::new(); 3]);
    for (j, from, to) in sweeps {
        let turn: Vec<f64> = (0..6).map(|_| offset.sample(&mut rng)).collect();
        for k in 0..10 {
            let mut q: Vec<f64> = home.iter().map(|v| v * DEG).collect();
            q[j] = (from + (to - from) * k as f64 / 9.0) * DEG;
            if fanuc && j == 1 {
                q[2] += q[1] - home[1] * DEG;
            }
            let line: Vec<String> = q.iter().map(|v| format!("{:.4}", v / DEG)).collect();
            joints.push_str(&(line.join(" ") + "\n"));
            let moved: Vec<f64> = q.iter().zip(&turn).map(|(v, t)| v + t + jitter.sample(&mut rng)).collect();
            for (c, text) in chains.iter().zip(&mut positions) {
                let p = c.fk(&JointState::new(&moved)).t;
                let r: Vec<String> = (0..3).map(|i| format!("{:.4}", (p[i] + noise.sample(&mut rng)) / MM)).collect();
                text.push_str(&(r.join(" ") + "\n"));
            }
        }
    }
    let dir = common::fresh_dir("sweeps");
    let joints_path = dir.join("joints.txt");
    std::fs::write(&joints_path, joints).unwrap();
    let files: Vec<PathBuf> = positions
        .iter()
        .enumerate()
        .map(|(k, text)| {
            let path = dir.join(format!("smr{}.txt", k + 1));
            std::fs::write(&path, text).unwrap();
            path
        })
        .collect();
    (joints_path, files, model)
}

/// Left without the arm's sweeps, a run measured at reflectors 200–390 mm off the flange moves them
/// mostly by the wrist's turns: the reflectors spread more than three times the flange. That was
/// refused as a unit mistake ("Check the positions' unit") on the public FANUC run without its J2
/// sweep; the spread a point that far off can reach from the turns themselves now bounds it. The
/// same readings in centimetres are still refused.
#[test]
fn a_run_that_mostly_turns_the_wrist_is_not_read_as_a_unit_mistake() {
    let (joints, files, model) = sweeps_twin_files(2, 0.04);
    let cell = three_reflector::import(&joints, &files, model.clone(), Purpose::Identification).unwrap().cell;
    let mut o = options("-compliance", &[]);
    o.residual_ratio_limit = f64::INFINITY;
    // Without the sweeps of joints 1–3 (rows 0–29), only the wrist sweeps are left.
    o.selection.exclude = (1..=3).flat_map(|r| (0..30).map(move |i| (format!("reflector-{r}"), i))).collect();
    let wrist_only: Vec<(String, usize)> = o.selection.exclude.clone();
    let id = identify(&cell, &o).unwrap_or_else(|e| panic!("{e}"));
    assert!(id.quality.rms_residual < 5.0 * MM, "{}", id.quality.rms_residual);
    // The same readings in centimetres: refused, the bound said.
    let dir = common::fresh_dir("wrist-cm");
    let cm: Vec<PathBuf> = files
        .iter()
        .enumerate()
        .map(|(k, f)| {
            let text: String = std::fs::read_to_string(f)
                .unwrap()
                .lines()
                .map(|l| {
                    l.split_whitespace()
                        .map(|v| format!("{:.5}", v.parse::<f64>().unwrap() / 10.0))
                        .collect::<Vec<_>>()
                        .join(" ")
                        + "\n"
                })
                .collect();
            let path = dir.join(format!("cm{k}.txt"));
            std::fs::write(&path, text).unwrap();
            path
        })
        .collect();
    let e = match three_reflector::import(&joints, &cm, model, Purpose::Identification) {
        Err(e) => e.to_string(),
        Ok(imported) => {
            let mut o = options("-compliance", &[]);
            o.selection.exclude = wrist_only;
            identify(&imported.cell, &o).expect_err("centimetres refused").to_string()
        }
    };
    assert!(e.contains("Check the positions' unit") && e.contains("a point up to 500.0 mm from it between"), "{e}");
}

/// A geometric parameter held for its near-dependence on a compliance that is then held too is
/// fitted again: its reason is gone. On the public FANUC sweeps (no payload) θ3 was held (σ 5.8°,
/// correlation −1.000 with c3), c3 then held at 0, and every value assumed θ3 = 0 — a worse fit
/// than the same model with c3 held from the start (1.0935 against 1.0914 mm). The identification
/// must equal that fit: the same parameters free, the same residual.
#[test]
fn a_parameter_held_for_a_compliance_that_is_then_held_is_fitted_again() {
    let mut released = 0;
    for (seed, offset_deg) in [(2, 0.04), (3, 0.03), (7, 0.03), (1, 0.03)] {
        let (joints, files, model) = sweeps_twin_files_as(seed, offset_deg, true);
        let cell = three_reflector::import(&joints, &files, model, Purpose::Identification).unwrap().cell;
        let mut o = options("", &[]);
        o.residual_ratio_limit = f64::INFINITY;
        let id = identify(&cell, &o).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
        let status: Vec<String> = id.status.iter().map(|s| s.to_string()).collect();
        // Every compliance held, each named partner of a geometric hold is not one of them.
        let held_compliances: Vec<String> = status
            .iter()
            .filter(|s| s.starts_with('c') && s.contains("held at"))
            .map(|s| s.split(' ').next().unwrap().to_string())
            .collect();
        for s in status.iter().filter(|s| s.contains("at the solution")) {
            assert!(!held_compliances.iter().any(|c| s.contains(&format!("with {c})"))), "seed {seed}: {s}");
        }
        // The same fit as the model with those compliances held from the start.
        let mut fixed = options("", &[]);
        fixed.residual_ratio_limit = f64::INFINITY;
        fixed.fixed = held_compliances.clone();
        let reference = identify(&cell, &fixed).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
        if id.free_names.iter().any(|n| n == "theta3") {
            released += 1;
        }
        // As good as it: holding the compliances first frees what they alone made undetermined
        // (before: 1.6313 against 1.6229 mm for seed 2, θ3 held in all four).
        let (rms, against) = (id.quality.rms_residual, reference.quality.rms_residual);
        assert!(rms <= against + 1e-9, "seed {seed}: {rms} against {against}");
    }
    assert_eq!(released, 4);
}

/// A pose line copied in every file (the public FANUC run's rows 36 and 37) is imported as written
/// and said; the diagnosis of such a run, left with 59 stops, says that its order was not tested
/// for a drift and why (before, `where.order_drift` was absent without a word).
#[test]
fn a_copied_pose_line_is_said_and_an_order_too_short_for_the_drift_test_is_said() {
    let (joints, files, model) = sweeps_twin_files(2, 0.04);
    // Line 38 becomes a copy of line 37, in the joints file and in every positions file.
    let copy = |path: &PathBuf| {
        let mut lines: Vec<String> = std::fs::read_to_string(path).unwrap().lines().map(String::from).collect();
        lines[37] = lines[36].clone();
        std::fs::write(path, lines.join("\n") + "\n").unwrap();
    };
    let imported = three_reflector::import(&joints, &files, model.clone(), Purpose::Identification).unwrap();
    assert!(!imported.notes.iter().any(|n| n.contains("repeat an earlier one exactly")), "{:?}", imported.notes);
    copy(&joints);
    files.iter().for_each(copy);
    let imported = three_reflector::import(&joints, &files, model, Purpose::Identification).unwrap();
    let note = imported.notes.iter().find(|n| n.contains("repeat an earlier one exactly")).expect("said");
    assert!(note.starts_with("1 pose line(s)") && note.contains("line(s) 38 (as 37)"), "{note}");
    assert_eq!(imported.cell.sessions[0].measurements.len(), 60, "imported as written");

    let cell = imported.cell;
    let mut o = options("-compliance", &[]);
    o.residual_ratio_limit = f64::INFINITY;
    let d = diagnose_identified(&cell, &o);
    assert!(d.location.order_drift.is_none());
    let why = d.location.order_drift_untested.as_deref().expect("said");
    assert!(why.starts_with("59 stops") && why.ends_with("fewer than the 60 it needs"), "{why}");
    let doc = robocal::domain::diagnosis::diagnosis_out(&d);
    assert!(
        doc.notes.iter().any(|n| n.starts_with("the measuring order was not tested for a drift")),
        "{:?}",
        doc.notes
    );
}

/// A diagnosis whose payload trial has a column of no effect (every compliance held: nothing free
/// carries a payload's torque to the TCP) runs to its verdict. The column's scale,
/// floored at the smallest positive number, squared to 0 and made the scaled Gram matrix 0/0: the
/// eigendecomposition panicked on these sweeps.
#[test]
fn a_payload_trial_with_no_effect_does_not_stop_a_diagnosis() {
    let (joints, files, model) = sweeps_twin_files_as(2, 0.04, true);
    let cell = three_reflector::import(&joints, &files, model, Purpose::Identification).unwrap().cell;
    let mut o = options("", &[]);
    o.residual_ratio_limit = f64::INFINITY;
    let d = diagnose_identified(&cell, &o);
    assert!(d.shrink[0].stats.mean.is_finite() && d.shrink[0].stats.mean > 0.5 * MM, "{:?}", d.shrink[0].stats);
}

/// On joint sweeps base, a1, θ2 and the base's tilt are nearly one direction, several at once:
/// base_x's σ at the solution is beyond the 10 mm bound while its strongest pairwise correlation
/// stays below 0.99, the test the hold at the solution asked for, so the fit stood at κ just above
/// the limit and was refused. On the public Fanuc run one cross-validation fold in five was
/// refused so (base_x σ 20 mm, correlation 0.9899), and `crossval` scored nothing. A fit that
/// would be refused for its κ now holds its parameter beyond the bound whatever its pairwise
/// correlations, and says so.
#[test]
fn joint_sweeps_hold_what_several_parameters_together_leave_undetermined() {
    for (seed, offset_deg) in [(2, 0.04), (3, 0.03), (7, 0.03)] {
        let cell = sweeps_twin(seed, offset_deg);
        let mut o = options("", &[]);
        // 0.03–0.04° per sweep at a 2.4 m reach leaves a residual of 1–2 mm, 35–65 times the
        // instrument's: a robot that does not repeat between sweeps.
        o.residual_ratio_limit = f64::INFINITY;
        let id = identify(&cell, &o).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
        assert!(id.quality.kappa_scaled <= o.kappa_limit, "seed {seed}: κ {}", id.quality.kappa_scaled);
        let held: Vec<String> =
            id.status.iter().map(|s| s.to_string()).filter(|s| s.contains("at the solution")).collect();
        let pairwise = |s: &str| -> f64 {
            let r = s.split("correlation ").nth(1).unwrap().split(' ').next().unwrap();
            r.parse::<f64>().unwrap().abs()
        };
        assert!(
            held.iter().any(|s| s.starts_with("base_x: not determined by these data") && pairwise(s) < 0.99),
            "seed {seed}: {held:?}"
        );
        assert!(held.iter().all(|s| s.ends_with("held at its start value")), "seed {seed}: {held:?}");
    }
}

/// On the same joint sweeps one cross-validation fold in five came out at κ 1,140–1,180, above the
/// limit of 1,000, with every σ within its bound, while the whole set fits below it: the fold was
/// refused and `crossval` scored nothing. A fold refused for its κ alone is fitted again without
/// the limit, its figure kept and a note says so. A second path: the same scheme with the limit
/// raised by the user gives the same pooled figure.
#[test]
fn a_fold_refused_for_its_kappa_alone_keeps_its_figure_and_says_so() {
    let mut noted = 0;
    for (seed, offset_deg) in [(1, 0.03), (5, 0.04), (3, 0.03)] {
        let cell = sweeps_twin(seed, offset_deg);
        let names = ["reflector-1", "reflector-2", "reflector-3"];
        let mut o = cv_options(&names, 5, Vec::new());
        let mut model = options("", &[]);
        model.residual_ratio_limit = f64::INFINITY;
        o.variants = vec![Variant { name: "default".into(), options: model.clone() }];
        let cv = crossval(&cell, &o).unwrap();
        let f = cv.folds.iter().find(|f| f.variant == "default").unwrap();
        let pooled = f.pooled.as_ref().unwrap_or_else(|| panic!("seed {seed}: {:?}", f.per_fold));
        let notes: Vec<&String> = cv.notes.iter().filter(|n| n.starts_with("default: fold ")).collect();
        for n in &notes {
            let kappa: f64 = n.split("at κ ").nth(1).unwrap().split(',').next().unwrap().parse().unwrap();
            assert!(kappa > model.kappa_limit && n.contains("with every σ within its bound"), "seed {seed}: {n}");
        }
        noted += notes.len();
        // The user's own way: the limit raised for every fit. The folds fitted again read the
        // same (the others may differ: below the limit a fit holds what its κ alone would refuse).
        o.variants[0].options.kappa_limit = 1e9;
        let raised = crossval(&cell, &o).unwrap();
        let r = raised.folds.iter().find(|f| f.variant == "default").unwrap();
        assert!(
            r.pooled.is_some() && raised.notes.iter().all(|n| !n.starts_with("default: fold ")),
            "{:?}",
            raised.notes
        );
        for n in &notes {
            let k: usize = n["default: fold ".len()..].split(' ').next().unwrap().parse().unwrap();
            let (a, b) = (f.per_fold[k - 1].as_ref().unwrap(), r.per_fold[k - 1].as_ref().unwrap());
            assert!((a.position.mean - b.position.mean).abs() < 1e-9, "seed {seed} fold {k}: {a:?} vs {b:?}");
        }
        eprintln!("seed {seed} {offset_deg}: pooled mean {:.4} mm; {notes:?}", pooled.position.mean / MM);
    }
    assert!(noted >= 2, "{noted} fold(s) above the limit: the case this test is about did not occur");
}

/// A robot file with a wrong length (a2 typed 370 mm for the IRB 120's 270 mm): the nominal robot
/// misses the positions by tens of millimetres and no change of the readings explains it. The
/// import writes the cell — a fit identifies the length — and says so; the check's note was
/// dropped there, so such a file (or readings in a convention further off than the search goes:
/// a Fanuc's sweeps with five joints changed) imported silently.
#[test]
fn an_import_says_when_the_nominal_robot_misses_by_far_more_than_a_real_robot() {
    let o = TrackerRunOptions { seed: 6, poses: 200, removed: 0, ..Default::default() };
    let dir = common::fresh_dir("real-data-wrong-length");
    let (joints, files) = tracker_run(&o).unwrap().write(&dir, "run", 6).unwrap();
    let said = |model| three_reflector::import(&joints, &files, model, Purpose::Identification).unwrap().notes;
    let right = said(irb120());
    assert!(!right.iter().any(|n| n.contains("missed them by")), "{right:?}");
    let mut wrong = irb120();
    wrong.preset = None;
    wrong.name = "irb120, a2 mistyped".into();
    wrong.links[2].a += 100.0 * MM;
    let notes = said(wrong);
    let note = notes.iter().find(|n| n.contains("missed them by")).unwrap_or_else(|| panic!("{notes:?}"));
    let miss: f64 = note.split("missed them by ").nth(1).unwrap().split(' ').next().unwrap().parse().unwrap();
    assert!(miss > 20.0, "{note}");
    assert!(note.contains("no quarter turn, sign or coupling") && note.contains("robot model's lengths"), "{note}");
}

/// Joint sweeps read as a KUKA's readings differ from a DH table: joints 1, 4 and 6 reversed,
/// joint 2 a quarter turn one way and joint 3 the other. Added one at a time the five changes
/// leave the miss as large as read (the public Fanuc run: 173, 157, 177, 117 mm against 153 mm),
/// and a wrong single change halves it, so the stepwise search found nothing and the file
/// imported. Every set of reversed joints with turns of joints 2 and 3 is tried when the steps
/// explain nothing: the five are named.
#[test]
fn joint_sweeps_read_in_a_kuka_convention_are_refused_with_the_five_changes() {
    let (joints, files, mut model) = sweeps_twin_files(2, 0.02);
    for l in &mut model.links {
        l.limits = [-400.0 * DEG, 400.0 * DEG];
    }
    let text: String = std::fs::read_to_string(&joints)
        .unwrap()
        .lines()
        .map(|l| {
            let q: Vec<f64> = l.split_whitespace().map(|v| v.parse().unwrap()).collect();
            let k = [-q[0], q[1] - 90.0, q[2] + 90.0, -q[3], q[4], -q[5]];
            k.iter().map(|v| format!("{v:.4}")).collect::<Vec<_>>().join(" ") + "\n"
        })
        .collect();
    let kuka = joints.with_file_name("kuka.txt");
    std::fs::write(&kuka, text).unwrap();
    let e = match three_reflector::import(&kuka, &files, model, Purpose::Identification) {
        Ok(_) => panic!("imported"),
        Err(e) => e.to_string(),
    };
    assert!(
        e.contains("do not follow the robot model's conventions")
            && e.contains(
                "with joint 1 as −q1 and joint 2 as q2 + 90° and joint 3 as q3 − 90° and joint 4 as −q4 and joint 6 as −q6 by"
            ),
        "{e}"
    );
}

/// A payload's centre of mass, identified with its mass (`quality.payload.with_centre_of_mass`,
/// [`robocal::identify::payload_centre_of_mass`]).
/// - Where the data determine it (2 kg at (0, 10, 70) mm, a plate whose centroid is (20, 0, 40)
///   mm, no random turn, tracker noise only): the identification's mass, which assumes the
///   centroid, misses the truth by more than 3 σ; with the centre of mass identified too, the mass
///   and every component lie within 3 σ, and the reading says it is determined.
/// - On 16 twins with a 0.006° random turn (8 seeds, the plate's centre of mass at the flange or
///   at the centroid), the same reading's σ holds: every mass within 3 σ of 2 kg, the z-scores'
///   RMS below 1.5 — where the assumed centre of mass gave masses 7 σ off.
/// - The default twin (1 kg, 0.012° turn, hysteresis): the data do not determine where the
///   payload sits, and the reading says so, with σ above 10 mm.
#[test]
fn the_payloads_centre_of_mass_is_identified_where_the_data_determine_it() {
    let read = |seed: u64, kg: f64, jitter_deg: f64, com: nalgebra::Vector3<f64>, effects: &str| {
        let o = TrackerRunOptions {
            seed,
            poses: 500,
            payload_kg: kg,
            payload_com: Some(com),
            jitter: jitter_deg * DEG,
            effects: robocal::sim::effects::Effects::parse(effects, 6).unwrap(),
            ..Default::default()
        };
        let dir = common::fresh_dir("payload-com");
        let (joints, files) = tracker_run(&o).unwrap().write(&dir, "run", 6).unwrap();
        let cell = import(&joints, &files);
        let (_, doc) =
            robocal::domain::identification::run_identification(&cell, options("", &[]), None, &|| ()).unwrap();
        let p = doc.quality.unwrap().payload.expect("an unknown payload");
        let c = p.with_centre_of_mass.clone().expect("the mass was determined");
        assert!(c.failed.is_none(), "{c:?}");
        let z = |v: Option<f64>, s: Option<f64>, truth: f64| (v.unwrap() - truth) / s.unwrap();
        let com_z: Vec<f64> =
            (0..3).map(|k| z(c.com_mm.map(|m| m[k]), c.com_std_mm.map(|s| s[k]), com[k] / MM)).collect();
        let first_z = z(p.mass_kg, p.std_kg, kg);
        eprintln!("seed {seed}: first z {first_z:+.2}, {c:?}, com z {com_z:?}");
        (first_z, z(c.mass_kg, c.std_kg, kg), com_z, c)
    };
    for seed in 1..=3 {
        let (first, mass, com, c) = read(seed, 2.0, 0.0, nalgebra::Vector3::new(0.0, 0.010, 0.070), "");
        assert!(first.abs() > 3.0, "seed {seed}: the assumed centroid reads the truth ({first:+.2} σ)");
        assert!(mass.abs() < 3.0 && com.iter().all(|z| z.abs() < 3.0), "seed {seed}: {mass:+.2}, {com:?}");
        assert_eq!(c.determined, Some(true), "seed {seed}: {c:?}");
    }
    let mut zs = Vec::new();
    for seed in 1..=8 {
        for com in [nalgebra::Vector3::zeros(), nalgebra::Vector3::new(0.020, 0.0, 0.040)] {
            let (_, mass, _, _) = read(seed, 2.0, 0.006, com, "");
            zs.push(mass);
        }
    }
    let rms = (zs.iter().map(|z| z * z).sum::<f64>() / zs.len() as f64).sqrt();
    assert!(zs.iter().all(|z| z.abs() < 3.0) && rms < 1.5, "z {zs:?}, RMS {rms:.2}");
    let hysteresis = "backlash:j=1:deg=0.006,backlash:j=2:deg=0.006,backlash:j=3:deg=0.006";
    let (_, mass, _, c) = read(1, 1.0, 0.012, nalgebra::Vector3::new(0.020, 0.0, 0.040), hysteresis);
    assert!(mass.abs() < 3.0, "{mass:+.2}");
    assert_eq!(c.determined, Some(false), "{c:?}");
    assert!(c.com_std_mm.unwrap().iter().any(|s| *s > 10.0), "{c:?}");
}

/// A second run (a validation day, the tracker moved) imported into the first run's cell under
/// its own name: the merged cell holds both runs' sessions exactly as imported apart, the import
/// says the run lies in another tracker frame with the move the registrations read (against the
/// simulated one), and the run is scored against the first run's calibration with its base
/// refitted (`crossval --transfer`). A run in the same frame is said to be so; a taken name and
/// another robot are refused before anything is written.
#[test]
fn a_second_run_merged_into_a_cell_says_whether_the_tracker_moved() {
    use robocal::kinematics::frame::Frame;
    let dir = common::fresh_dir("merge-runs");
    let run = |args: &[&str]| std::process::Command::new(env!("CARGO_BIN_EXE_robocal")).args(args).output().unwrap();
    let first = TrackerRunOptions { seed: 31, poses: 200, removed: 0, ..Default::default() };
    let mut moved = TrackerRunOptions { seed: 32, poses: 200, removed: 0, ..Default::default() };
    let b = &mut moved.base_in_tracker;
    (b[0], b[1], b[2], b[5]) = (b[0] + 0.300, b[1] - 0.200, b[2] + 0.050, b[5] + 20.0 * DEG);
    let (true_mm, true_deg) = {
        let (d, a) = Frame::from_xyzabc(&first.base_in_tracker).distance(&Frame::from_xyzabc(&moved.base_in_tracker));
        (d / MM, a / DEG)
    };
    let same = TrackerRunOptions { seed: 33, poses: 200, removed: 0, ..Default::default() };
    let files = |o: &TrackerRunOptions, tag: &str| {
        let (joints, files) = tracker_run(o).unwrap().write(&dir, tag, 6).unwrap();
        let mut args = vec!["--joints".to_string(), joints.to_str().unwrap().to_string()];
        for f in files {
            args.extend(["--positions".to_string(), f.to_str().unwrap().to_string()]);
        }
        args
    };
    let (f1, f2, f3) = (files(&first, "first"), files(&moved, "moved"), files(&same, "same"));
    let path = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let import = |f: &[String], extra: &[&str]| {
        let mut args: Vec<&str> = vec!["import", "three-reflector", "--robot", "irb120"];
        args.extend(f.iter().map(String::as_str));
        args.extend_from_slice(extra);
        run(&args)
    };
    let ok = |out: std::process::Output| {
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8(out.stdout).unwrap()
    };
    ok(import(&f1, &["--out", &path("a.json")]));
    let said = ok(import(
        &f2,
        &["--name", "day2", "--purpose", "validation", "--into", &path("a.json"), "--out", &path("b.json")],
    ));
    let head = "day2-1, day2-2, day2-3: merged into";
    let note = said.lines().find(|l| l.contains(head)).unwrap_or_else(|| panic!("{said}"));
    assert!(note.contains("measured in another tracker frame than reflector-1"), "{note}");
    assert!(note.contains("--transfer day2-1,day2-2,day2-3"), "{note}");
    let read = |after: &str, unit: &str| -> f64 {
        let rest = &note[note.find(after).unwrap() + after.len()..];
        rest[..rest.find(unit).unwrap()].trim().parse().unwrap()
    };
    let (mm, deg) = (read("registers", " mm"), read("mm and", "°"));
    eprintln!("registered {mm} mm, {deg}°; simulated {true_mm:.1} mm, {true_deg:.2}°");
    assert!((mm - true_mm).abs() < 5.0 && (deg - true_deg).abs() < 0.3, "{note}");

    // The merged cell: the first run's sessions, then the second's exactly as imported apart.
    let cell = |p: &str| serde_json::from_str::<serde_json::Value>(&std::fs::read_to_string(p).unwrap()).unwrap();
    ok(import(&f2, &["--name", "day2", "--purpose", "validation", "--out", &path("apart.json")]));
    let (a, merged, apart) = (cell(&path("a.json")), cell(&path("b.json")), cell(&path("apart.json")));
    let sessions = |v: &serde_json::Value| v["sessions"].as_array().unwrap().clone();
    assert_eq!(merged["robot"], a["robot"]);
    // (Compared as values: a failure would print some 10⁵ numbers.)
    let names =
        |v: &serde_json::Value| sessions(v).iter().map(|s| s["name"].to_string()).collect::<Vec<_>>().join(", ");
    assert!(sessions(&merged) == [sessions(&a), sessions(&apart)].concat(), "merged: {}", names(&merged));

    // Scored against the first run's calibration with its base refitted.
    let x = path("x.json");
    ok(run(&[
        "crossval",
        &path("b.json"),
        "--session",
        "reflector-1,reflector-2,reflector-3",
        "--folds",
        "0",
        "--transfer",
        "day2-1,day2-2,day2-3",
        "--out",
        &x,
    ]));
    let transfer = cell(&x)["transfer"].as_array().unwrap().clone();
    let default: Vec<f64> =
        transfer.iter().filter(|t| t["model"] == "default").map(|t| t["errors"]["mean_mm"].as_f64().unwrap()).collect();
    assert_eq!(default.len(), 3, "{transfer:?}");
    assert!(default.iter().all(|m| *m < 0.5), "day 2 with its base refitted: {default:?} mm");

    // A run in the first one's frame is said to be so.
    let said = ok(import(&f3, &["--name", "day3", "--into", &path("b.json"), "--out", &path("c.json")]));
    assert!(said.contains("day3-1, day3-2, day3-3: merged into") && said.contains("no move of the tracker"), "{said}");
    assert_eq!(sessions(&cell(&path("c.json"))).len(), 9);

    // The same plate, not remounted (`--same-plate-as reflector`): the run's sessions name the
    // first run's reflectors as their targets and declare their tool as written, the first run's
    // sessions gain the targets and nothing else, and the first run's set is validated on the
    // run with the TCPs it fitted. Without the option that validation is refused (the run's
    // readings would be scored at the flange).
    let e = path("e.json");
    let said = ok(import(
        &f3,
        &[
            "--name",
            "day3",
            "--purpose",
            "validation",
            "--into",
            &path("a.json"),
            "--same-plate-as",
            "reflector",
            "--out",
            &e,
        ],
    ));
    assert!(said.contains("the same plate as reflector"), "{said}");
    // The run's payload is the plate's: the note says the plate's tool, not the run's own
    // registration of its centre of mass.
    let plate_tool = &sessions(&a)[0]["tool"];
    assert!(!said.contains("payload unknown (the files carry none)"), "{said}");
    let com: Vec<String> = (0..3).map(|k| format!("{:.1}", plate_tool["com_mm"][k].as_f64().unwrap())).collect();
    assert!(said.contains(&format!("centre of mass at ({})", com.join(", "))), "{said} / {plate_tool}");
    let (shared, first) = (sessions(&cell(&e)), sessions(&a));
    assert_eq!(shared.len(), 6);
    for k in 0..3 {
        let (p, r) = (&shared[k], &shared[k + 3]);
        assert_eq!(p["target"], serde_json::json!(format!("reflector-{}", k + 1)));
        assert_eq!(
            (&r["name"], &r["target"], &r["tool"]),
            (&serde_json::json!(format!("day3-{}", k + 1)), &p["target"], &p["tool"])
        );
        let mut p = p.clone();
        p.as_object_mut().unwrap().remove("target");
        assert_eq!(p, first[k], "the first run's session {k} changed beyond its target");
    }
    let set = path("set.json");
    ok(run(&["identify", &e, "--sessions", "reflector-1,reflector-2,reflector-3", "--out", &set]));
    let v = ok(run(&["validate", &set, &e, "--session", "day3-1", "--format", "json"]));
    let v: serde_json::Value = serde_json::from_str(&v).unwrap();
    let mean = v["mean_mm"].as_f64().unwrap_or_else(|| panic!("{v}"));
    assert!(mean < 0.3, "the first run's set on the same plate's second run: {mean} mm");
    let o = run(&["validate", &set, &path("c.json"), "--session", "day3-1", "--format", "json"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("day3-1"), "{err}");
    // Refused: a plate the cell does not hold, a plate of another number of reflectors.
    let o = import(
        &f3,
        &["--name", "day4", "--into", &path("a.json"), "--same-plate-as", "nope", "--out", &path("f.json")],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--same-plate-as: the cell holds no session nope-1"), "{err}");
    // The cell's own sessions are listed, not the run's being added.
    assert!(
        err.contains("reflector-3)") && !err.contains("day4-1") && err.matches("--same-plate-as").count() == 1,
        "{err}"
    );
    let o = import(
        &f3[..6],
        &["--name", "day4", "--into", &path("a.json"), "--same-plate-as", "reflector", "--out", &path("f.json")],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("reflector has 3 reflectors and this run 2"), "{err}");
    assert!(!dir.join("f.json").exists());

    // Refused, nothing written: a name the cell holds, another robot.
    let (into, out) = (path("a.json"), path("d.json"));
    let refused = |robot: &str, extra: &[&str], why: &str| {
        let mut args: Vec<&str> = vec!["import", "three-reflector", "--robot", robot];
        args.extend(f2.iter().map(String::as_str));
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--into", &into, "--out", &out]);
        let o = run(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(why), "{err}");
        assert!(!dir.join("d.json").exists());
    };
    refused(
        "irb120",
        &[],
        "already holds session(s) reflector-1, reflector-2, reflector-3: import the run under another name",
    );
    refused("ur10", &["--name", "x"], "--into");
    refused("ur10", &["--name", "x"], "robot model differs");
}

/// An ISO 9283 evaluation of a set with hysteresis on a session that does not log its
/// directions applies the hysteresis with the directions derived from the measuring order, as
/// `identify` and `validate` do, and says so: every visit's predicted (commanded) pose equals the
/// same evaluation on the cell with every direction written in beforehand. (Before, the backlash
/// terms acted nowhere there: the figures were of the set without its hysteresis.)
#[test]
fn an_iso_evaluation_applies_a_sets_hysteresis_from_the_measuring_order() {
    use robocal::domain::iso9283::evaluate::{Assignment, evaluate_session};
    let dir = common::fresh_dir("iso-hysteresis");
    let o = TrackerRunOptions { seed: 43, poses: 300, removed: 0, ..Default::default() };
    let (j, f) = tracker_run(&o).unwrap().write(&dir, "run", 6).unwrap();
    let cell = three_reflector::import(&j, &f, irb120(), Purpose::Identification).unwrap().cell;
    let id =
        identify(&cell, &options("+backlash1,+backlash2,+backlash3", &["reflector-1", "reflector-2", "reflector-3"]))
            .unwrap();
    let b1 = id.set.value(Param::Joint(0, JointTerm::Backlash)).unwrap();
    assert!(b1.abs() > 0.003 * DEG, "the twin's hysteresis is fitted: {} deg", b1 / DEG);
    let n = cell.session("reflector-2").unwrap().measurements.len();
    let assignments: Vec<Assignment> = (0..n)
        .map(|i| Assignment { index: i, pose: format!("p{}", i % 5 + 1), cycle: (i / 5) as u32 + 1, approach: None })
        .collect();
    let mut logged = cell.clone();
    robocal::cell::order::fill_approach(&mut logged, &[]);
    let derived = evaluate_session(&cell, "reflector-2", Some(&id.set), &assignments, 1e4, &[]).unwrap();
    let written = evaluate_session(&logged, "reflector-2", Some(&id.set), &assignments, 1e4, &[]).unwrap();
    assert!(derived.notes.iter().any(|n| n.contains("reflector-2")), "{:?}", derived.notes);
    assert!(written.notes.is_empty(), "{:?}", written.notes);
    let mut worst = 0.0f64;
    for (a, b) in derived.visits.iter().zip(&written.visits) {
        worst = worst.max((a.commanded.t - b.commanded.t).norm());
    }
    assert!(worst < 1e-9, "{} µm from the evaluation with the directions written in", worst / 1e-6);
    // The hysteresis matters here: the same set scored with every direction unknown predicts
    // other poses (by the backlash's lever).
    let mut stripped = cell.clone();
    for s in &mut stripped.sessions {
        for m in &mut s.measurements {
            m.approach = Some(vec![0; 6]);
        }
    }
    let none = evaluate_session(&stripped, "reflector-2", Some(&id.set), &assignments, 1e4, &[]).unwrap();
    let apart = none
        .visits
        .iter()
        .zip(&written.visits)
        .map(|(a, b)| (a.commanded.t - b.commanded.t).norm())
        .fold(0.0, f64::max);
    assert!(apart > 10e-6, "the hysteresis moves the prediction by {} µm at most", apart / 1e-6);
}

/// A second run that the diagnosis carries its models to (`transfer`) is scored with the
/// hysteresis the diagnosis named: the run's approach directions are derived from its measuring
/// order, as the diagnosed sessions' are. They were not, and the named hysteresis acted nowhere
/// there: a twin's second run read it as costing 0.002 mm where `crossval --transfer` read a gain
/// of 0.013 mm. The transfer's figures now equal those on the same cell with every direction
/// written in beforehand, the named hysteresis gains on the second run beyond twice its standard
/// error, and the accepted set validated there is scored with its hysteresis too (a set fitted on
/// other sessions, whose TCP for the second run is unknown, is refused rather than scored at the
/// flange).
#[test]
fn a_second_run_is_scored_with_the_named_hysteresis() {
    use robocal::diagnose::{DiagnoseOptions, Input, diagnose};
    use robocal::validate::report::{Reference, ValidateError, validate, validate_fitted};
    let dir = common::fresh_dir("transfer-hysteresis");
    let write = |seed: u64, poses: usize, tag: &str| {
        let o = TrackerRunOptions { seed, poses, removed: 0, ..Default::default() };
        tracker_run(&o).unwrap().write(&dir, tag, 6).unwrap()
    };
    let (j1, f1) = write(41, 600, "first");
    let (j2, f2) = write(42, 300, "second");
    let first = three_reflector::import(&j1, &f1, irb120(), Purpose::Identification).unwrap();
    let second =
        three_reflector::import_run(&j2, &f2, irb120(), Purpose::Validation, three_reflector::Payload::Unknown, "day2")
            .unwrap();
    let cell = robocal::import::merge(first.cell, &dir.join("first.json"), second).unwrap().cell;
    let reflectors = ["reflector-1", "reflector-2", "reflector-3"].map(String::from).to_vec();
    let days = ["day2-1", "day2-2", "day2-3"].map(String::from).to_vec();
    let run = |cell: &Cell| {
        let id = identify(cell, &options("", &["reflector-1", "reflector-2", "reflector-3"])).unwrap();
        let identified = id.status.iter().map(|s| matches!(s, robocal::identify::Status::Identified)).collect();
        let input = Input { cell, set: &id.set, identified: Some(identified), fixed: Vec::new(), excluded: Vec::new() };
        let opts = DiagnoseOptions {
            identification: reflectors.clone(),
            validation: Some(Vec::new()),
            transfer: days.clone(),
            threads: 2,
            ..DiagnoseOptions::default()
        };
        diagnose(&input, &opts).unwrap()
    };
    let derived = run(&cell);
    let mut logged = cell.clone();
    robocal::cell::order::fill_approach(&mut logged, &[]);
    let written = run(&logged);
    assert!(
        derived.verdict.effects.iter().any(|e| e.candidate.kind == robocal::diagnose::library::Kind::Backlash),
        "{}",
        derived.verdict.summary
    );
    assert_eq!(derived.transfer.len(), written.transfer.len());
    for (a, b) in derived.transfer.iter().zip(&written.transfer) {
        let (ma, mb) = (a.errors.as_ref().unwrap().mean, b.errors.as_ref().unwrap().mean);
        assert!((ma - mb).abs() < 1e-9, "{} {}: {ma} against {mb} with the directions written in", a.session, a.model);
    }
    for day in &days {
        let last = derived.transfer.iter().rfind(|t| t.session == *day).unwrap();
        let c = last.change.as_ref().unwrap();
        eprintln!("{day}: {} {:+.4} ± {:.4} mm", last.model, c.mean / MM, c.se / MM);
        assert!(c.mean < -2.0 * c.se, "{day}: {} changes the mean by {} ± {} m", last.model, c.mean, c.se);
    }

    // Validated on the second run: a set registered there (base and tools) applies its
    // hysteresis with the directions derived, and says so; the first run's set, which has no TCP
    // for the second run's reflectors, is refused.
    let accepted = derived.accepted.as_ref().expect("an accepted set");
    let mut o = options("", &["day2-1"]);
    o.start = Some(accepted.set.clone());
    o.only = vec!["base".into(), "tool".into()];
    let registered = identify(&cell, &o).unwrap();
    let plain = validate(&registered.set, &cell, &days[..1], Reference::Measured).unwrap();
    let with_written = validate(&registered.set, &logged, &days[..1], Reference::Measured).unwrap();
    assert_eq!(plain.calibrated.position.mean, with_written.calibrated.position.mean);
    assert!(plain.notes.iter().any(|n| n.contains("derived from the measuring order of day2-1")), "{:?}", plain.notes);
    assert!(with_written.notes.is_empty(), "{:?}", with_written.notes);
    let opts = options("", &["reflector-1", "reflector-2", "reflector-3"]);
    let (_, written) = robocal::domain::identification::run_identification(&cell, opts, None, &|| {}).unwrap();
    let doc = robocal::domain::ParameterSetDoc::from_json(&written.to_json_pretty()).unwrap();
    let fit = robocal::domain::validation::fit_data(&doc, &[]);
    let e = validate_fitted(&doc.set, &cell, &days[..1], Reference::Measured, Some(&fit)).unwrap_err();
    assert!(matches!(e, ValidateError::TcpUnknown { .. }), "{e}");
    assert!(e.to_string().contains("it fitted reflector-1, reflector-2, reflector-3"), "{e}");
    let own = validate_fitted(&doc.set, &cell, &reflectors, Reference::Measured, Some(&fit)).unwrap();
    assert!(own.calibrated.position.mean < 0.5 * MM, "{}", own.calibrated.position.mean);

    // The uncertainty model a held-out validation of a set with hysteresis gives compensation
    // takes the covariance's σ at each reading with the directions the validation applied (the
    // backlash terms' columns act there), as on the cell with them written in. The second run
    // names the first run's reflectors as its targets (the plate not remounted), so the set's
    // TCPs apply to it.
    let shared = |cell: &Cell| {
        let mut c = cell.clone();
        for s in &mut c.sessions {
            s.target = Some(format!("smr-{}", s.name.rsplit('-').next().unwrap()));
        }
        c
    };
    let (cell, logged) = (shared(&cell), shared(&logged));
    let opts = options("+backlash1,+backlash2,+backlash3", &["reflector-1", "reflector-2", "reflector-3"]);
    let (_, written) = robocal::domain::identification::run_identification(&cell, opts, None, &|| {}).unwrap();
    let doc = robocal::domain::ParameterSetDoc::from_json(&written.to_json_pretty()).unwrap();
    let fit = robocal::domain::validation::fit_data(&doc, &[]);
    let uncertainty = |cell: &Cell| {
        let report = validate_fitted(&doc.set, cell, &days[..1], Reference::Measured, Some(&fit)).unwrap();
        robocal::domain::validity::HeldOutUncertainty::of_report(&doc, cell, &report).unwrap().expect("held out")
    };
    let (derived, written) = (uncertainty(&cell), uncertainty(&logged));
    assert!(
        (derived.covariance_rms_mm - written.covariance_rms_mm).abs() < 1e-12,
        "{} mm against {} mm with the directions written in",
        derived.covariance_rms_mm,
        written.covariance_rms_mm
    );
    assert_eq!((derived.rms_mm, derived.unexplained_mm), (written.rms_mm, written.unexplained_mm));
}

/// A tracker that settles along the run: every reading moves by D·(1 − e^(−3t)), t the stop's share
/// of the run (0.27 mm from the first stop to the last), which no term of the robot takes and the
/// files do not log. `+drift` fits it as a nuisance of the run — three translations of {W}, each
/// a cubic in the stop's place (here its sequence number, as the import writes it) — and:
/// - the fitted drift follows the true one (centred over the run, as the term is) to within a
///   quarter of its RMS; on the same twin without the drift, what it fits is a fraction of that;
/// - the residual falls by more than the drift's own share would allow a look-alike;
/// - the set's file keeps the drift terms (mm), and a state with no place in a run (a
///   compensation) is not moved by them.
#[test]
fn a_drift_along_the_run_is_fitted_as_a_nuisance_of_the_run() {
    use robocal::domain::ParameterSetDoc as ParameterSetDocument;
    use robocal::kinematics::JointState;
    let drift = nalgebra::Vector3::new(0.20, -0.10, 0.15) * MM;
    let o = TrackerRunOptions { seed: 21, poses: 600, removed: 6, ..Default::default() };
    let fitted_curve = |with_drift: bool| {
        let mut run = tracker_run(&o).unwrap();
        let n = run.kept.len();
        let truth: Vec<nalgebra::Vector3<f64>> =
            run.kept.iter().map(|&k| drift * (1.0 - (-3.0 * k as f64 / (o.poses - 1) as f64).exp())).collect();
        if with_drift {
            for smr in &mut run.positions {
                for (p, d) in smr.iter_mut().zip(&truth) {
                    *p += d;
                }
            }
        }
        let dir = common::fresh_dir(if with_drift { "drift" } else { "no-drift" });
        let (joints, files) = run.write(&dir, "run", 6).unwrap();
        let cell = import(&joints, &files);
        let without = identify(&cell, &options("", &[])).unwrap();
        let with = identify(&cell, &options("+drift", &[])).unwrap();
        // The fitted drift at each row: the basis of the rows' places (every reflector reads every
        // row, so centring over the measurements is centring over the rows).
        let basis = robocal::identify::run::drift_basis(&(0..n).map(|i| i as f64).collect::<Vec<_>>()).unwrap();
        let value = |p: Param| with.set.values[with.set.layout.index_of(p).expect("a drift term")];
        let curve: Vec<nalgebra::Vector3<f64>> = basis
            .iter()
            .map(|b| nalgebra::Vector3::from_fn(|a, _| (0..3).map(|k| value(Param::Drift(a, k)) * b[k]).sum()))
            .collect();
        let mean = truth.iter().sum::<nalgebra::Vector3<f64>>() / n as f64;
        let rms = |v: &mut dyn Iterator<Item = f64>| {
            let v: Vec<f64> = v.collect();
            (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
        };
        let true_rms = rms(&mut truth.iter().map(|d| (d - mean).norm()));
        let miss = rms(&mut curve.iter().zip(&truth).map(|(c, d)| (c - (d - mean)).norm()));
        let size = rms(&mut curve.iter().map(|c| c.norm()));
        eprintln!(
            "drift {with_drift}: true RMS {:.4} mm, fitted {:.4} mm, miss {:.4} mm; residual {:.4} → {:.4} mm",
            true_rms / MM,
            size / MM,
            miss / MM,
            without.quality.rms_residual / MM,
            with.quality.rms_residual / MM
        );
        (true_rms, size, miss, without, with)
    };
    let (true_rms, _, miss, without, with) = fitted_curve(true);
    assert!(miss < 0.25 * true_rms, "the fitted drift misses the true one by {miss} m RMS (true {true_rms} m)");
    assert!(with.quality.rms_residual < without.quality.rms_residual, "the drift term did not lower the residual");
    let (_, quiet, _, _, _) = fitted_curve(false);
    assert!(quiet < 0.3 * true_rms, "without a drift, the term fits {quiet} m RMS (a drifting run's {true_rms} m)");

    // The set's file keeps the nine terms, in mm, and reads back the same values.
    let text = ParameterSetDocument::new(with.set.clone()).to_json_pretty();
    assert!(text.contains("drift_z_p3"), "{text}");
    let back = ParameterSetDocument::from_json(&text).unwrap().set;
    for a in 0..3 {
        for k in 0..3 {
            let p = Param::Drift(a, k);
            let (x, y) = (with.set.value(p).unwrap(), back.value(p).unwrap());
            assert!((x - y).abs() < 1e-12, "{p}: {x} → {y}");
        }
    }
    // A state with no place in a run is where the drift averages to zero: the drift moves nothing.
    let mut flat = with.set.clone();
    for a in 0..3 {
        for k in 0..3 {
            let i = flat.layout.index_of(Param::Drift(a, k)).unwrap();
            flat.values[i] = 0.0;
        }
    }
    let q = [0.3, -0.2, 0.4, 0.1, 0.8, -0.5];
    let (f1, f0) = (with.set.chain().fk(&JointState::new(&q)), flat.chain().fk(&JointState::new(&q)));
    assert_eq!(f1.t, f0.t);
    // Re-registered on another run (`--start set --only base,tool`), the set's drift stays with its
    // own run: it is neither carried nor applied along the other run's order, and the fit is the
    // re-registration of the same set without a drift.
    let (_, other) = twin(300, 9);
    let register = |start: &robocal::kinematics::ParameterSet| {
        let mut o = options("", &[]);
        o.start = Some(start.clone());
        o.only = vec!["base".into(), "tool".into()];
        identify(&other, &o).unwrap()
    };
    let (moved, plain) = (register(&with.set), register(&flat));
    assert!(!moved.set.layout.params().iter().any(|p| matches!(p, Param::Drift(..))), "{:?}", moved.notes);
    assert!(!moved.notes.iter().any(|n| n.contains("drift")), "{:?}", moved.notes);
    assert_eq!(moved.quality.rms_residual, plain.quality.rms_residual);
}

/// The drift terms in a measuring order that follows the configuration: the same twin's stops
/// renumbered as a sweep over joint 1. There a trend along the order is also an error of the pose,
/// and the identification says so in a note; in the twin's own random order it says nothing.
#[test]
fn drift_terms_along_an_order_that_follows_the_configuration_are_noted() {
    let (_, cell) = twin(300, 5);
    let noted = |cell: &Cell| {
        let id = identify(cell, &options("-compliance,+drift", &[])).unwrap();
        id.notes.iter().find(|n| n.contains("carries the configuration")).cloned()
    };
    assert_eq!(noted(&cell), None);
    let mut q1: Vec<f64> = cell.sessions.iter().flat_map(|s| s.measurements.iter().map(|m| m.q[0])).collect();
    q1.sort_by(f64::total_cmp);
    q1.dedup();
    let mut sweep = cell.clone();
    for m in sweep.sessions.iter_mut().flat_map(|s| s.measurements.iter_mut()) {
        m.sequence = Some(q1.partition_point(|&v| v < m.q[0]) as u64);
    }
    let note = noted(&sweep).expect("a note on the sweep");
    assert!(note.contains("adjusted R²") && note.contains("fit without +drift"), "{note}");
}
