//! Cross-validation, few-pose draws and transfer (`robocal crossval`), and re-identification from
//! a calibrated set (`identify --start … --only base,tool`), on the virtual cell where the truth
//! is known.

use robocal::cell::Observation;
use robocal::identify::crossval::{CrossvalOptions, Variant, crossval};
use robocal::identify::{IdentifyOptions, identify};
use robocal::kinematics::{Frame, Param};
use robocal::sim::instruments::Noise;
use robocal::sim::simulate::{SimulateOptions, Simulated, simulate};

fn sim(seed: u64, noise: Noise) -> Simulated {
    simulate(&SimulateOptions { seed, noise, id_per_ball: 30, validation: 60, ..Default::default() }).unwrap()
}

fn options(threads: usize) -> CrossvalOptions {
    CrossvalOptions {
        session: "trical-1".into(),
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
    assert!(err(CrossvalOptions { session: "nope".into(), ..options(1) }).contains("no session named 'nope'"));
    assert!(err(CrossvalOptions { folds: 1, ..options(1) }).contains("--folds"));
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
    assert_eq!(reason, "a2: fixed at its start value, not in --only");

    // Unknown names are refused.
    let bad = IdentifyOptions { only: vec!["bass".into()], ..opts };
    assert!(identify(&cell, &bad).unwrap_err().to_string().contains("'bass'"));
}
