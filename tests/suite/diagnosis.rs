//! The sim-to-real diagnosis (issue 11): a fast version of `robocal bench-diagnosis` (one seed of
//! a case of every kind: the full table over ten seeds is in BENCHMARKS.md), the real UR10 data
//! against the figures of an independent analysis, compensation with an accepted effect on the
//! virtual robot that has it, and the held-out refits checked against full nonlinear ones.

use std::path::PathBuf;

use robocal::cell::{Cell, Purpose};
use robocal::diagnose::cv::{Folds, cross_validate};
use robocal::diagnose::stage::Stage;
use robocal::diagnose::{DiagnoseOptions, Input, Status, diagnose};
use robocal::experiments::withheld::{Expect, run_suite, suite};
use robocal::identify::{Anchor, IdentifyOptions, NoiseModel, identify};
use robocal::import::ur10_ipa::{Ur10Options, import_cell};
use robocal::kinematics::{Compensator, JointTerm, Param, Seed};
use robocal::sim::effects::Effects;
use robocal::sim::simulate::{SimulateOptions, simulate};

const MM: f64 = 1e-3;

/// One seed of every kind of case: separable effects named with the right joint and harmonic,
/// no false alarm, `not_separable` where the data cannot separate, never a name for the
/// out-of-library link bending, and the named model closing the gap as the oracle does.
#[test]
fn withheld_effects_one_seed_of_each_kind() {
    let keep = [
        "none",
        "none (tracker +50 %)",
        "cyclic j3 h2 (no logs)",
        "cyclic j4 h17 (gear mesh)",
        "backlash j2",
        "backlash j2 (no logs)",
        "backlash j2 (no logs, shuffled)",
        "thermal",
        "thermal (no logs)",
        "coupling 5→6",
        "compliance_cubic j2",
        "tool_mass (one payload)",
        "tool_mass (2.7 kg validation tool)",
        "link_bending",
        "-beta",
        "-compliance",
    ];
    let cases: Vec<_> = suite().into_iter().filter(|c| keep.contains(&c.name.as_str())).collect();
    assert_eq!(cases.len(), keep.len(), "every case of the fast suite is in the suite");
    let out = run_suite(&cases, &[7], &DiagnoseOptions::default(), 2, &|_, _| {});
    for (c, o) in cases.iter().zip(&out) {
        assert!(o.error.is_none(), "{}: {:?}", c.name, o.error);
        assert!(o.correct, "{}: expected {:?}, got {} ({:?})", c.name, c.expect, o.status.as_str(), o.first);
        assert!(!o.wrong_name, "{}: a confident wrong name {:?}", c.name, o.first);
        // A drift whose log is missing: the verdict says that thermal could not be tested.
        if c.name == "thermal (no logs)" {
            assert!(o.summary.contains("not testable on these data: thermal (no temperature log)"), "{}", o.summary);
        }
        if let (Expect::Named { .. }, Some(r)) = (&c.expect, o.closure_ratio) {
            assert!(r >= 0.8, "{}: gap closure {r:.3} of the oracle's", c.name);
        }
    }
}

fn series(letter: &str) -> PathBuf {
    [env!("CARGO_MANIFEST_DIR"), "..", "shared", "datasets", "ur10-ipa", &format!("Series_{letter}")].iter().collect()
}

/// The UR10 (issue 11, item 9). An independent analysis of these data found that geometry
/// leaves 0.44 mm held-out, that fine joint-angle structure on joints 1–3 (7–30 cycles per
/// revolution, 0.2–0.36 mrad) explains most of it, and that per-joint correction tables bring the
/// held-out error to 0.18 mm mean (p95 0.36). The diagnosis must find that from the data alone:
/// the kind (a transmission error: tables or periodic terms) on joints 1–3 first, and ≤ 0.20 mm
/// held-out mean under 5-fold cross-validation on series C. Carried to series B and D (base and
/// probe refitted there, nearly every pose outside C's joint ranges) the extended model does better
/// on D and at most 0.03 mm worse on B than the starting one, and the report says those poses lie
/// outside the identified ranges.
#[test]
fn ur10_fine_joint_structure_on_joints_1_to_3() {
    let cell = import_cell(
        &[
            (series("C"), Purpose::Identification),
            (series("B"), Purpose::Validation),
            (series("D"), Purpose::Validation),
        ],
        &Ur10Options::default(),
    )
    .unwrap()
    .cell;
    let mut id_opts = IdentifyOptions::default();
    id_opts.selection.sessions = vec!["series-C".into()];
    let id = identify(&cell, &id_opts).unwrap();
    let identified: Vec<bool> = id.status.iter().map(|s| matches!(s, robocal::identify::Status::Identified)).collect();
    let input =
        Input { cell: &cell, set: &id.set, identified: Some(identified), fixed: Vec::new(), excluded: Vec::new() };
    let opts = DiagnoseOptions {
        identification: vec!["series-C".into()],
        validation: Some(Vec::new()),
        transfer: vec!["series-B".into(), "series-D".into()],
        threads: 2,
        ..DiagnoseOptions::default()
    };
    let d = diagnose(&input, &opts).unwrap();
    let v = &d.verdict;
    assert_eq!(v.status, Status::Named, "{}", v.summary);
    let joints: Vec<usize> = v.effects.iter().filter_map(|e| e.candidate.joint).collect();
    for e in &v.effects {
        assert!(e.candidate.kind.is_transmission(), "{}: not a transmission error", e.candidate.label());
    }
    // The structure the independent analysis found comes first: joints 1–3 before anything else
    // (later rounds may add smaller terms that the refitted model confirms).
    for e in v.effects.iter().take(3) {
        assert!(e.candidate.joint.is_some_and(|j| j < 3), "{}: not on joints 1–3", e.candidate.label());
    }
    for j in 0..3 {
        assert!(joints.contains(&j), "joint {} not named: {joints:?}", j + 1);
    }
    // The size of the structure: table RMS or cyclic amplitude 0.1–0.5 mrad.
    for e in &v.effects {
        let a = e.estimate.unwrap();
        assert!((0.1e-3..0.5e-3).contains(&a), "{}: {a:.3e} rad", e.candidate.label());
    }
    let start = &d.shrink[0].stats;
    let last = &d.shrink.last().unwrap().stats;
    assert!(
        (0.42 * MM..0.45 * MM).contains(&start.mean),
        "geometry + compliance held-out mean {:.4} mm",
        start.mean / MM
    );
    assert!(last.mean <= 0.20 * MM, "held-out mean after the effects {:.4} mm", last.mean / MM);
    assert!(last.p95 <= 0.40 * MM, "held-out p95 after the effects {:.4} mm", last.p95 / MM);
    // Carried to the other series (base and probe refitted there): nearly every pose of B and D
    // lies outside series C's joint ranges, so the tables are extrapolated there, and the report
    // says so. On D they still help (0.487 → 0.453 mm); on B they cost 0.011 mm (0.442 → 0.452),
    // since C's wrist compliances, which the data do not determine, are held (BENCHMARKS.md,
    // "Compliances the data do not determine, held").
    for (s, worse_by_at_most) in [("series-B", 0.03 * MM), ("series-D", 0.0)] {
        let get = |m: &str| d.transfer.iter().find(|t| t.session == s && t.model == m).unwrap();
        let (a, b) = (get("start").errors.clone().unwrap(), get("final").errors.clone().unwrap());
        eprintln!("{s}: transferred {:.4} mm with the effects, {:.4} without", b.mean / MM, a.mean / MM);
        assert!(
            b.mean <= a.mean + worse_by_at_most,
            "{s}: transferred {:.4} mm with the effects, {:.4} without",
            b.mean / MM,
            a.mean / MM
        );
        // Every model is carried with one registration: series D's probe z, at the edge of what
        // its data determine (σ ≈ 10 mm), was held in some refits and free in others (κ 6.6
        // against 2,100–2,300); it is now held in all of them, and said.
        let of_session: Vec<&robocal::diagnose::Transfer> = d.transfer.iter().filter(|t| t.session == s).collect();
        let held = &of_session[0].held;
        assert_eq!(*held, if s == "series-D" { vec!["tool_z".to_string()] } else { Vec::new() }, "{s}");
        let kappa: Vec<f64> = of_session.iter().map(|t| t.kappa_scaled.unwrap()).collect();
        for t in &of_session {
            assert_eq!(&t.held, held, "{s} {}", t.model);
            assert!((t.kappa_scaled.unwrap() / kappa[0] - 1.0).abs() < 0.05, "{s}: κ {kappa:?}");
        }
        let range = get("final").range.clone().expect("a range split");
        assert!(range.inside_share < 0.01, "{s}: {:.3} of the poses inside C's ranges", range.inside_share);
        // The change paired pose by pose is the difference of the two means (the same readings),
        // with a batch-means standard error over runs of consecutive poses.
        let c = get("final").change.clone().expect("a paired change");
        assert!((c.mean - (b.mean - a.mean)).abs() < 1e-12, "{s}: {c:?} against {a:?} → {b:?}");
        assert_eq!((c.n, c.batches), (a.n, 20), "{s}");
        assert!((0.002 * MM..0.05 * MM).contains(&c.se), "{s}: SE {:.4} mm", c.se / MM);
        assert!(get("start").change.is_none());
        // The verdict's summary carries both figures, the change with its SE and the share
        // outside, as the transfer table has them: "series-B 0.4418 mm → 0.4525 mm (+0.0107 ±
        // 0.0157 mm, 100 % of its poses …".
        let said = format!(
            "{s} {:.4} mm → {:.4} mm ({:+.4} ± {:.4} mm, {:.0} % of its poses outside the identification's joint ranges)",
            a.mean / MM,
            b.mean / MM,
            c.mean / MM,
            c.se / MM,
            100.0 * (1.0 - range.inside_share)
        );
        assert!(v.summary.contains(&said), "{said} not in: {}", v.summary);
        // The closing remark names a session made worse only beyond twice the SE, and one whose
        // change lies within it as such.
        let worse = c.mean > 0.0 && c.beyond_2se();
        assert_eq!(v.summary.contains(&format!("they made {s}")), worse, "{}", v.summary);
        let level = v.summary.find(" the change is within twice its uncertainty").is_some_and(|end| {
            let from = v.summary[..end].rfind("; on ").expect("the clause begins '; on '");
            v.summary[from..end].contains(s)
        });
        assert_eq!(level, !c.beyond_2se(), "{}", v.summary);
        // The start registered with the joints' zeros too, held out on alternate poses: the same
        // registrations by hand (each half's poses left out, the session validated, the left-out
        // half scored).
        let z = get("start").zeros.clone().expect("start has a zeros registration").unwrap();
        let n = cell.session(s).unwrap().measurements.len();
        let mut by_hand = [Vec::new(), Vec::new()];
        for half in 0..2 {
            for (k, only) in [&["base", "tool"][..], &["base", "tool", "zeros"][..]].iter().enumerate() {
                let mut o = IdentifyOptions {
                    start: Some(id.set.clone()),
                    only: only.iter().map(|x| x.to_string()).collect(),
                    fixed: held.clone(),
                    kappa_limit: opts.transfer_kappa_limit,
                    residual_ratio_limit: f64::INFINITY,
                    outlier_factor: f64::INFINITY,
                    identify_payload: false,
                    hold_undetermined_compliance: false,
                    ..Default::default()
                };
                o.selection.sessions = vec![s.to_string()];
                o.selection.exclude = (0..n).filter(|i| i % 2 == half).map(|i| (s.to_string(), i)).collect();
                let r = robocal::validate::report::validate(
                    &identify(&cell, &o).unwrap().set,
                    &cell,
                    &[s.to_string()],
                    robocal::validate::report::Reference::Measured,
                )
                .unwrap();
                by_hand[k].extend(r.residuals.iter().filter(|x| x.index % 2 == half).map(|x| x.error.norm()));
            }
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        eprintln!(
            "{s}: held out on alternate poses, base and tools {:.4} mm, with the zeros {:.4} mm",
            z.base_tool.mean / MM,
            z.with_zeros.mean / MM
        );
        assert!((z.base_tool.mean - mean(&by_hand[0])).abs() < 1e-9 * MM, "{s}: {z:?}");
        assert!((z.with_zeros.mean - mean(&by_hand[1])).abs() < 1e-9 * MM, "{s}: {z:?}");
        assert_eq!(z.base_tool.n, n);
    }
    let out = robocal::domain::diagnosis::diagnosis_out(&d);
    assert!(out.notes.iter().any(|n| n.starts_with("series-D: tool_z held at each model's value")), "{:?}", out.notes);
    let d_final = out.transfer.iter().find(|t| t.session == "series-D" && t.model == "final").unwrap();
    assert_eq!(d_final.held_in_every_refit, ["tool_z"]);
    // The report's table of the zeros' registration carries the verdict's figures.
    let html = robocal::report::diagnosis_report(&out);
    let b_start = out.transfer.iter().find(|t| t.session == "series-B" && t.model == "start").unwrap();
    let z = b_start.zeros_refitted.as_ref().unwrap();
    let theta2 = z.zero_shifts.iter().find(|x| x.parameter == "theta2").unwrap();
    assert!(
        html.contains("Registered with the joints&#39; zeros too")
            || html.contains("Registered with the joints' zeros too")
    );
    let with_zeros = z.held_out_with_zeros.as_ref().unwrap().figures.mean_mm;
    let shift = format!("theta2 {:+.4} ± {:.4}°", theta2.change_deg, theta2.std_deg);
    assert!(html.contains(&format!("<td class=\"n\">{with_zeros:.3}</td>")), "{with_zeros:.3} mm not in the report");
    assert!(v.summary.contains(&format!("→ {with_zeros:.4} mm")), "{with_zeros:.4} mm not in the verdict");
    assert!(html.contains(&shift) && v.summary.contains(&shift), "{shift} not in the report and the verdict");
}

/// Accepting a named effect gives a parameter set whose model carries it; compensating targets
/// with it puts the *true* robot (which has the effect) on them, where the set without the
/// effect misses by the effect's size.
#[test]
fn compensation_with_an_accepted_effect_lands_on_the_virtual_robot() {
    let effects = Effects::parse("cyclic:j=3:h=2:amp_deg=0.01", 6).unwrap();
    let sim = simulate(&SimulateOptions { seed: 4, effects, ..SimulateOptions::default() }).unwrap();
    let cell = sim.cell;
    let id = identify(&cell, &IdentifyOptions::default()).unwrap();
    let identified: Vec<bool> = id.status.iter().map(|s| matches!(s, robocal::identify::Status::Identified)).collect();
    let input =
        Input { cell: &cell, set: &id.set, identified: Some(identified), fixed: Vec::new(), excluded: Vec::new() };
    let d = diagnose(&input, &DiagnoseOptions::default()).unwrap();
    assert_eq!(d.verdict.status, Status::Named, "{}", d.verdict.summary);
    let accepted = d.accepted.as_ref().expect("an accepted model").set.clone();
    assert!(accepted.value(Param::Joint(2, JointTerm::Cyclic { harmonic: 2, cosine: false })).is_some());

    // The evidence plot's figures against the simulated truth, Δθ3 = 0.01°·sin(2·q3): the
    // effect's term follows the truth up to the constant the joint offset takes, the held-out
    // residual before it shows the part the geometry could not absorb, and after it is flat.
    let out = robocal::domain::diagnosis::diagnosis_out(&d);
    let ev = out.evidence.iter().find(|e| e.joint == 3).expect("evidence for the cyclic term on joint 3");
    // A periodic term's residual is folded onto one period: x is the phase 2·q3 mod 360°.
    assert_eq!(ev.variable, "phase of 2 cycles per turn of q3");
    let explained = ev.explained_share.unwrap();
    assert!(explained > 0.3, "share of the residual angle removed: {explained}");
    assert!(ev.bins.len() >= 10 && ev.n >= 50, "{} bins, {} poses", ev.bins.len(), ev.n);
    let truth: Vec<f64> = ev.bins.iter().map(|b| 0.01 * b.at.to_radians().sin()).collect();
    let offset = ev.bins.iter().zip(&truth).map(|(b, t)| b.predicted_deg - t).sum::<f64>() / truth.len() as f64;
    let rms = |f: &dyn Fn(usize) -> f64| {
        (ev.bins.iter().enumerate().map(|(i, _)| f(i).powi(2)).sum::<f64>() / ev.bins.len() as f64).sqrt()
    };
    let pred_vs_truth = rms(&|i| ev.bins[i].predicted_deg - offset - truth[i]);
    let before = rms(&|i| ev.bins[i].before_deg);
    let after = rms(&|i| ev.bins[i].after_deg);
    assert!(pred_vs_truth < 0.0015, "prediction − truth: {pred_vs_truth:.5}° RMS over the bins");
    assert!(before > 0.002 && after < before / 3.0, "binned residual angle RMS before {before:.5}°, after {after:.5}°");

    // Targets: where the true robot's TCP is at the validation poses (TriCal tool).
    let tool = cell.sessions[0].tool.clone();
    let robot = sim.truth.robot(&tool);
    let val: Vec<&Vec<f64>> =
        cell.sessions_for(Purpose::Validation).flat_map(|s| s.measurements.iter().map(|m| &m.q)).collect();
    let miss = |set: &robocal::kinematics::ParameterSet| -> (f64, f64) {
        let comp = Compensator::new(set);
        let mut errs = Vec::new();
        for q in val.iter().step_by(5) {
            let target = robot.tcp(&robot.state(q, &[0.0; 6], 20.0));
            let c = comp.pose(&target, Seed::Joints(q)).unwrap();
            let landed = robot.tcp(&robot.state(c.joints(), &[0.0; 6], 20.0));
            errs.push((landed.t - target.t).norm());
        }
        let mean = errs.iter().sum::<f64>() / errs.len() as f64;
        (mean, errs.iter().copied().fold(0.0, f64::max))
    };
    let (before_mean, _) = miss(&id.set);
    let (after_mean, after_max) = miss(&accepted);
    assert!(before_mean > 0.02 * MM, "the calibrated set without the effect misses by {:.4} mm", before_mean / MM);
    assert!(
        after_mean < 0.006 * MM && after_max < 0.02 * MM,
        "with the accepted effect: mean {:.4}, max {:.4} mm",
        after_mean / MM,
        after_max / MM
    );
    assert!(after_mean < before_mean / 4.0);
}

/// The folds' one-step refits against full nonlinear identifications on the same training rows,
/// with the same weights and anchors: the held-out errors agree to a small fraction of a
/// micrometre (second-order terms of sub-millimetre residuals).
#[test]
fn linearised_folds_agree_with_nonlinear_refits() {
    let effects = Effects::parse("backlash:j=2:deg=0.01", 6).unwrap();
    let o = SimulateOptions { seed: 3, effects, id_per_ball: 40, validation: 150, ..SimulateOptions::default() };
    let cell: Cell = simulate(&o).unwrap().cell;
    let id = identify(&cell, &IdentifyOptions::default()).unwrap();
    let mut opts = IdentifyOptions {
        start: Some(id.set.clone()),
        noise: Some(NoiseModel::default()),
        anchor: Some(Anchor::default()),
        ..IdentifyOptions::default()
    };
    opts.selection.sessions = cell.sessions.iter().map(|s| s.name.clone()).collect();
    let stage = Stage::fit(&cell, opts.clone()).unwrap();
    let pr = &stage.problem;
    let tested: Vec<bool> = pr.obs.iter().map(|o| cell.sessions[o.session].purpose == Purpose::Validation).collect();
    let joints: Vec<Vec<f64>> = pr.obs.iter().map(|o| o.state.q[..6].to_vec()).collect();
    let folds = Folds::new(&joints, &tested, 3, 1);
    let h = cross_validate(&stage, &folds, None);
    let mut worst: f64 = 0.0;
    for f in 0..3 {
        let train: Vec<(String, usize)> = pr
            .obs
            .iter()
            .enumerate()
            .filter(|(i, _)| folds.fold_of_obs[*i] != Some(f))
            .map(|(_, o)| (cell.sessions[o.session].name.clone(), o.index))
            .collect();
        let mut fo = opts.clone();
        fo.selection.subset = train;
        let fit = identify(&cell, &fo).unwrap();
        for (i, e) in h.errors.iter().filter(|(i, _)| folds.fold_of_obs[*i] == Some(f)) {
            let ob = &pr.obs[*i];
            let s = &cell.sessions[ob.session];
            let m = &s.measurements[ob.index];
            let chain = fit.set.chain().with_base_tool(fit.set.pose_of(Param::Base), s.tool.tcp);
            let tau = fit.set.gravity_for(&s.tool).torques(&m.q);
            let mut state = robocal::kinematics::JointState::with_torques(&m.q, &tau[..6]);
            for (j, a) in m.approach.as_ref().unwrap().iter().enumerate() {
                state.approach[j] = *a as f64;
            }
            let model = chain.fk(&state).t;
            let full = cell.observed_position(m).unwrap() - model;
            worst = worst.max((full - e).norm());
        }
    }
    assert!(worst < 0.2e-6, "linearised and nonlinear held-out errors differ by {worst:.3e} m");
}

/// A session marked shuffled is not in measuring order: the diagnosis derives no backlash
/// direction from its list, lists backlash as untestable with the reason, says so in its notes,
/// and names nothing; the same list unmarked is taken for the file order (what the marker is for).
#[test]
fn a_shuffled_session_gives_no_backlash_direction() {
    use rand::SeedableRng;
    use rand::seq::SliceRandom;
    use robocal::cell::MeasuringOrder;
    use robocal::cell::order::ApproachSource;
    use robocal::diagnose::library::Kind;
    let effects = Effects::parse("backlash:j=2:deg=0.01", 6).unwrap();
    let sim = simulate(&SimulateOptions { seed: 5, id_per_ball: 40, validation: 150, effects, ..Default::default() })
        .unwrap();
    let mut cell = sim.cell.clone();
    for s in &mut cell.sessions {
        for m in &mut s.measurements {
            (m.approach, m.time_s, m.sequence) = (None, None, None);
        }
        s.measurements.shuffle(&mut rand_chacha::ChaCha8Rng::seed_from_u64(11));
        s.order = MeasuringOrder::Shuffled;
    }
    let run = |cell: &Cell| {
        let id = identify(cell, &IdentifyOptions::default()).unwrap();
        let identified: Vec<bool> =
            id.status.iter().map(|s| matches!(s, robocal::identify::Status::Identified)).collect();
        let input = Input { cell, set: &id.set, identified: Some(identified), fixed: Vec::new(), excluded: Vec::new() };
        diagnose(&input, &DiagnoseOptions::default()).unwrap()
    };
    let d = run(&cell);
    assert_eq!(d.approach, None);
    let u = d.unavailable.iter().find(|u| u.kind == Kind::Backlash).expect("backlash is untestable");
    assert!(u.reason.contains("session 'trical-1' is marked shuffled"), "{}", u.reason);
    assert_ne!(d.verdict.status, Status::Named, "{}", d.verdict.summary);
    let out = robocal::domain::diagnosis::diagnosis_out(&d);
    assert!(out.verdict.approach_source.is_none());
    assert!(
        out.notes.iter().any(|n| n.contains("'tracker-n1' are not derived") && n.contains("shuffled")),
        "{:?}",
        out.notes
    );
    assert!(out.unavailable.iter().any(|u| u.name == "backlash" && u.reason.contains("marked shuffled")));

    for s in &mut cell.sessions {
        s.order = MeasuringOrder::Unknown;
    }
    let d = run(&cell);
    assert_eq!(d.approach, Some(ApproachSource::FileOrder));
    assert!(d.unavailable.iter().all(|u| u.kind != Kind::Backlash));
}

/// A transfer registers the model with the joints' zero offsets as well (issue 24: what limits
/// a transfer). The virtual cell's robot is measured again on another "day", once as it was and
/// once re-mastered (θ2 +0.03°, θ3 −0.02°). Registered with base and tools alone, the re-mastered
/// day's held-out poses miss by far more than the same robot's; with the zeros registered too
/// they come back to the other day's, the zeros read the re-mastering within 3 σ (the unchanged
/// day's read 0 within 3 σ), and the verdict says what that can mean there and not on the
/// unchanged day.
#[test]
fn a_transfer_registers_the_joint_zeros_a_re_mastering_moved() {
    let a = simulate(&SimulateOptions { seed: 4, ..Default::default() }).unwrap();
    let day = |seed: u64, shift: [f64; 2], name: &str| {
        let mut truth = a.truth.clone();
        for (j, d) in [(1, shift[0]), (2, shift[1])] {
            let i = truth.set.layout.index_of(Param::Theta(j)).unwrap();
            truth.set.values[i] += d.to_radians();
        }
        let sim = simulate(&SimulateOptions { seed, truth: Some(truth), ..Default::default() }).unwrap();
        let mut s = sim.cell.session("tracker-n1").unwrap().clone();
        s.name = name.into();
        s.purpose = Purpose::Validation;
        s
    };
    let mut cell = a.cell.clone();
    cell.sessions.retain(|s| s.purpose == Purpose::Identification);
    let balls: Vec<String> = cell.sessions.iter().map(|s| s.name.clone()).collect();
    cell.sessions.push(day(5, [0.03, -0.02], "remastered"));
    cell.sessions.push(day(6, [0.0, 0.0], "same"));
    let mut o = IdentifyOptions::default();
    o.selection.sessions = balls.clone();
    let id = identify(&cell, &o).unwrap();
    let identified: Vec<bool> = id.status.iter().map(|s| matches!(s, robocal::identify::Status::Identified)).collect();
    let input =
        Input { cell: &cell, set: &id.set, identified: Some(identified), fixed: Vec::new(), excluded: Vec::new() };
    let opts = DiagnoseOptions {
        identification: balls,
        validation: Some(Vec::new()),
        transfer: vec!["remastered".into(), "same".into()],
        threads: 2,
        ..DiagnoseOptions::default()
    };
    let d = diagnose(&input, &opts).unwrap();
    let zeros = |s: &str| {
        d.transfer.iter().find(|t| t.session == s && t.model == "start").unwrap().zeros.clone().unwrap().unwrap()
    };
    let (moved, same) = (zeros("remastered"), zeros("same"));
    for (s, z) in [("remastered", &moved), ("same", &same)] {
        eprintln!(
            "{s}: base and tools {:.4} mm, with the zeros {:.4} mm; {:?}",
            z.base_tool.mean / MM,
            z.with_zeros.mean / MM,
            z.shifts
                .iter()
                .map(|(n, v, sd)| format!("{n} {:+.4} ± {:.4}°", v.to_degrees(), sd.to_degrees()))
                .collect::<Vec<_>>()
        );
    }
    assert!(moved.base_tool.mean > 3.0 * same.base_tool.mean, "the re-mastering shows with base and tools alone");
    assert!(moved.with_zeros.mean < 1.2 * same.base_tool.mean, "and registering the zeros takes it");
    assert!(moved.change.as_ref().unwrap().beyond_2se());
    let shift = |z: &robocal::diagnose::ZerosRefit, n: &str| z.shifts.iter().find(|s| s.0 == n).cloned().unwrap();
    for (n, truth) in [("theta2", 0.03), ("theta3", -0.02)] {
        let (_, v, sd) = shift(&moved, n);
        assert!((v.to_degrees() - truth).abs() < 3.0 * sd.to_degrees(), "{n}: {v} ± {sd} rad, truth {truth}°");
        let (_, v, sd) = shift(&same, n);
        assert!(v.abs() < 3.0 * sd, "{n} on the unchanged day: {v} ± {sd} rad");
    }
    let summary = &d.verdict.summary;
    assert!(summary.contains("on remastered registering the zeros too predicts held-out poses better"), "{summary}");
    assert!(!summary.contains("on remastered, same") && !summary.contains("on same "), "{summary}");
}
