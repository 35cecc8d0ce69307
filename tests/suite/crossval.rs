//! Cross-validation, few-pose draws and transfer (`robocal crossval`), and re-identification from
//! a calibrated set (`identify --start … --only base,tool`), on the virtual cell where the truth
//! is known.

use robocal::cell::Observation;
use robocal::identify::crossval::{CrossvalOptions, Variant, crossval};
use robocal::identify::{FixedReason, IdentifyOptions, Status, identify};
use robocal::kinematics::{Frame, Param};
use robocal::sim::instruments::Noise;
use robocal::sim::simulate::{SimulateOptions, Simulated, simulate};

fn sim(seed: u64, noise: Noise) -> Simulated {
    simulate(&SimulateOptions { seed, noise, id_per_ball: 30, validation: 60, ..Default::default() }).unwrap()
}

fn options(threads: usize) -> CrossvalOptions {
    CrossvalOptions {
        sessions: vec!["trical-1".into()],
        folds: 3,
        sizes: vec![30],
        draws: 2,
        transfer: vec!["tracker-n1".into()],
        transfer_fixed: Vec::new(),
        transfer_kappa_limit: None,
        variants: vec![Variant { name: "default".into(), options: IdentifyOptions::default() }],
        before: IdentifyOptions::default(),
        seed: 7,
        threads,
    }
}

/// Without noise the model is exact, so every held-out error vanishes, while the "before"
/// reference (nominal robot, base fitted) keeps the millimetres of the nominal model.
#[test]
fn noise_free_held_out_errors_vanish() {
    let s = sim(3, Noise::none());
    assert!(s.cell.session("trical-1").is_some() && s.cell.session("tracker-n1").is_some());
    let cv = crossval(&s.cell, &options(2)).unwrap();
    let before = cv.folds[0].pooled.as_ref().unwrap();
    let model = cv.folds[1].pooled.as_ref().unwrap();
    assert_eq!(model.position.n, 90, "every measurement predicted once");
    assert!(model.position.max < 1e-8, "{:e}", model.position.max);
    assert!(before.position.mean > 0.3e-3, "{:e}", before.position.mean);
    for d in &cv.sizes.iter().find(|x| x.variant == "default").unwrap().draws {
        let h = d.as_ref().unwrap();
        assert!(h.position.max < 1e-8, "{:e}", h.position.max);
        assert_eq!(h.position.n, 45);
    }
    // Transfer to the tracker session: its tool is declared (not identified), so only the base
    // is refitted there, and the tracker readings are exact.
    let t = cv.transfer.iter().find(|t| t.variant == "default").unwrap();
    let e = t.errors.as_ref().unwrap();
    assert!(e.position.max < 1e-8, "{:e}", e.position.max);
}

/// The result does not depend on the number of worker threads.
#[test]
fn thread_count_does_not_change_the_result() {
    let s = sim(4, Noise::default());
    let a = crossval(&s.cell, &options(1)).unwrap();
    let b = crossval(&s.cell, &options(2)).unwrap();
    assert_eq!(a.folds, b.folds);
    assert_eq!(a.sizes, b.sizes);
    assert_eq!(a.transfer, b.transfer);
}

/// Bad requests are refused with the reason.
#[test]
fn bad_options_are_refused() {
    let s = sim(5, Noise::none());
    let err = |o: CrossvalOptions| crossval(&s.cell, &o).unwrap_err().to_string();
    assert!(err(CrossvalOptions { sessions: vec!["nope".into()], ..options(1) }).contains("no session named 'nope'"));
    assert!(err(CrossvalOptions { folds: 1, ..options(1) }).contains("folds: must be 0 (skip) or at least 2"));
    assert!(err(CrossvalOptions { sizes: vec![46], ..options(1) }).contains("exceeds half the session"));
    assert!(err(CrossvalOptions { transfer: vec!["trical-1".into()], ..options(1) }).contains("session identified on"));
}

/// `--start SET --only base,tool`: the calibrated robot re-registered in a cell whose base moved.
/// The robot parameters keep the start set's values exactly; the new base comes back exactly.
#[test]
fn reidentification_from_a_calibrated_set_refits_the_base_only() {
    let s = sim(6, Noise::none());
    let calibrated = identify(&s.cell, &IdentifyOptions::default()).unwrap();

    // The same robot, moved: every observed position seen from a new world frame.
    let moved = Frame::from_xyzabc(&[0.3, -0.2, 0.05, 0.4, 0.02, -0.01]);
    let mut cell = s.cell.clone();
    cell.base_guess = None;
    cell.artefact = None;
    cell.sessions.retain(|x| x.name == "tracker-n1");
    for m in &mut cell.sessions[0].measurements {
        if let Observation::Position(p) = &mut m.observation {
            *p = moved.transform_point(p);
        }
    }
    let opts = IdentifyOptions {
        start: Some(calibrated.set.clone()),
        only: vec!["base".into(), "tool".into()],
        selection: robocal::identify::MeasurementSelection {
            sessions: vec!["tracker-n1".into()],
            ..Default::default()
        },
        ..Default::default()
    };
    let id = identify(&cell, &opts).unwrap();
    assert_eq!(id.free_names, ["base_x", "base_y", "base_z", "base_a", "base_b", "base_c"]);
    for (i, p) in id.set.layout.params().iter().enumerate() {
        match p {
            Param::Base(_) | Param::Tool(_) => {}
            _ => assert_eq!(id.set.values[i], calibrated.set.value(*p).unwrap(), "{p} kept at the start value"),
        }
    }
    let want = moved.compose(&Frame::from_xyzabc(&calibrated.set.pose_of(Param::Base)));
    let got = Frame::from_xyzabc(&id.set.pose_of(Param::Base));
    let (dt, dr) = want.distance(&got);
    assert!(dt < 1e-9 && dr < 1e-9, "{dt:e} m, {dr:e} rad");
    let reason = &id.status[id.set.layout.find("a2").unwrap()];
    assert_eq!(*reason, Status::Fixed(FixedReason::NotInOnly { name: "a2".into(), at_start: true }));
    assert_eq!(reason.to_string(), "a2: fixed at its start value, not in `only`");

    // Unknown names are refused.
    let bad = IdentifyOptions { only: vec!["bass".into()], ..opts };
    assert!(identify(&cell, &bad).unwrap_err().to_string().contains("'bass'"));
}

/// A cell whose three reflectors on one plate are read at the same validation poses.
fn plate(seed: u64, noise: Noise) -> Simulated {
    let mut o = SimulateOptions { seed, noise, id_per_ball: 10, validation: 60, all_nests: true, ..Default::default() };
    o.layout.nests = robocal::sim::poses::reflector_plate();
    simulate(&o).unwrap()
}

fn reflectors() -> Vec<String> {
    ["tracker-n1", "tracker-n2", "tracker-n3"].map(String::from).to_vec()
}

/// A variant's excluded readings are named by their index in the whole session; a fold fits and
/// scores a renumbered subset, so they are taken out before it: the reading corrupted by 5 mm is
/// neither fitted nor scored, and the rest are predicted exactly. (The fold once applied the
/// index to its subset: another reading was left out and the corrupted one fitted.)
#[test]
fn a_variants_excluded_reading_is_left_out_of_every_fold() {
    let mut s = plate(9, Noise::none());
    let session = s.cell.sessions.iter_mut().find(|x| x.name == "tracker-n2").unwrap();
    let Observation::Position(p) = &mut session.measurements[17].observation else { panic!("a position") };
    p.x += 5e-3;
    let mut variant = IdentifyOptions::default();
    variant.selection.exclude = vec![("tracker-n2".into(), 17)];
    let opts = CrossvalOptions {
        sessions: reflectors(),
        transfer: Vec::new(),
        sizes: Vec::new(),
        variants: vec![Variant { name: "default".into(), options: variant }],
        ..options(2)
    };
    let cv = crossval(&s.cell, &opts).unwrap();
    let model = cv.folds[1].pooled.as_ref().unwrap();
    let total: usize = reflectors().iter().map(|r| s.cell.session(r).unwrap().measurements.len()).sum();
    assert_eq!(model.position.n, total - 1, "every reading but the excluded one scored");
    assert!(model.unscored.is_empty(), "{:?}", model.unscored);
    assert!(model.position.max < 1e-8, "{:e}", model.position.max);
}

/// Three reflectors at the same poses are split by pose: no configuration is held out in one
/// fold and trained on in it, every measurement is predicted once, and the pooled errors are
/// the union of the per-reflector ones.
#[test]
fn reflectors_at_the_same_poses_are_split_by_pose() {
    let s = plate(8, Noise::default());
    let opts = CrossvalOptions { sessions: reflectors(), sizes: vec![15], transfer: Vec::new(), ..options(2) };
    let cv = crossval(&s.cell, &opts).unwrap();
    let total: usize = reflectors().iter().map(|r| s.cell.session(r).unwrap().measurements.len()).sum();
    assert_eq!(cv.measurements, total);
    assert!(cv.poses == 60 && total > 2 * cv.poses, "{total} measurements at {} poses", cv.poses);
    let q = |(name, i): &(String, usize)| s.cell.session(name).unwrap().measurements[*i].q.clone();
    let mut seen = std::collections::HashSet::new();
    for test in &cv.kfold_test {
        let held: Vec<Vec<f64>> = test.iter().map(q).collect();
        for r in reflectors() {
            for (i, m) in s.cell.session(&r).unwrap().measurements.iter().enumerate() {
                if !test.contains(&(r.clone(), i)) {
                    assert!(!held.contains(&m.q), "{r}[{i}] is trained on at a held-out pose");
                }
            }
        }
        assert!(test.iter().all(|t| seen.insert(t.clone())), "held out twice");
    }
    assert_eq!(seen.len(), total, "every measurement held out once");

    let consistent = |h: &robocal::identify::crossval::HeldOut| {
        let n: usize = h.per_session.iter().map(|x| x.position.n).sum();
        let mean = h.per_session.iter().map(|x| x.position.n as f64 * x.position.mean).sum::<f64>() / n as f64;
        let max = h.per_session.iter().map(|x| x.position.max).fold(0.0, f64::max);
        assert_eq!(n, h.position.n);
        assert!((mean - h.position.mean).abs() < 1e-15, "{mean:e} vs {:e}", h.position.mean);
        assert_eq!(max, h.position.max);
    };
    for f in &cv.folds {
        let pooled = f.pooled.as_ref().unwrap();
        assert_eq!(pooled.position.n, total);
        assert_eq!(pooled.per_session.iter().map(|x| x.session.clone()).collect::<Vec<_>>(), reflectors());
        consistent(pooled);
        f.per_fold.iter().for_each(|r| consistent(r.as_ref().unwrap()));
    }
    for d in &cv.sizes.iter().find(|x| x.variant == "default").unwrap().draws {
        consistent(d.as_ref().unwrap());
    }
    // The calibrated model beats the nominal one on every reflector.
    let (before, model) = (cv.folds[0].pooled.as_ref().unwrap(), cv.folds[1].pooled.as_ref().unwrap());
    for (b, m) in before.per_session.iter().zip(&model.per_session) {
        assert!(
            m.position.mean < 0.5 * b.position.mean,
            "{}: {:e} vs {:e}",
            m.session,
            m.position.mean,
            b.position.mean
        );
    }
}

/// Without noise every reflector's held-out error vanishes, and the transfer target may be the
/// identification session.
#[test]
fn noise_free_reflectors_are_predicted_exactly() {
    let s = plate(9, Noise::none());
    let opts =
        CrossvalOptions { sessions: reflectors(), transfer: vec!["trical-1".into()], sizes: Vec::new(), ..options(2) };
    let cv = crossval(&s.cell, &opts).unwrap();
    let model = cv.folds[1].pooled.as_ref().unwrap();
    for r in &model.per_session {
        assert!(r.position.max < 1e-8, "{}: {:e}", r.session, r.position.max);
    }
    let t = cv.transfer.iter().find(|t| t.variant == "default").unwrap();
    assert!(t.errors.as_ref().unwrap().position.max < 1e-8);
    let err = |o: CrossvalOptions| crossval(&s.cell, &o).unwrap_err().to_string();
    let twice = vec!["tracker-n1".to_string(), "tracker-n1".to_string()];
    assert!(err(CrossvalOptions { sessions: twice, ..opts.clone() }).contains("named twice"));
    assert!(
        err(CrossvalOptions { transfer: vec!["tracker-n2".into()], ..opts.clone() }).contains("session identified on")
    );
    assert!(err(CrossvalOptions { folds: 61, ..opts }).contains("exceeds the 60 poses"));
}
