//! Calibration of a real robot (issue 4, item 8): the UR10 of `../shared/datasets/ur10-ipa/`
//! (Landgraf et al., IEEE CASE 2021, MIT licence), 6D laser-tracker poses in the tracker's own
//! frame, no hidden answers. Reference figures: an independent careful fit on exactly these data
//! (issue 4): nominal 0.90 mm mean; geometric calibration 0.437 mm mean (median 0.41, p95 0.85)
//! under 5-fold cross-validation on series C; 0.47 / 0.45 / 0.44 mm with 50 / 100 / 200 poses;
//! orientation about 0.9 mrad; transfer to series B with base and probe refitted: geometry 0.83,
//! geometry + compliance 0.45 mm. robocal must match or beat each within 0.01 mm. The full
//! tables (all sizes, 10 draws, series D) are in BENCHMARKS.md; this test runs the parts that
//! fit the default test budget.

use std::path::PathBuf;

use robocal::cell::{Cell, Observation, Purpose};
use robocal::identify::crossval::{CrossvalOptions, Variant, crossval};
use robocal::identify::{IdentifyOptions, ModelOptions, identify};
use robocal::import::ur10_ipa::{Ur10Options, import_cell};

const MM: f64 = 1e-3;

fn series(letter: &str) -> PathBuf {
    [env!("CARGO_MANIFEST_DIR"), "..", "shared", "datasets", "ur10-ipa", &format!("Series_{letter}")].iter().collect()
}

fn cell() -> Cell {
    import_cell(&[(series("C"), Purpose::Identification), (series("B"), Purpose::Validation)], &Ur10Options::default())
        .unwrap()
        .cell
}

/// Series C (identification) and D (validation, the ISO cubes).
fn cell_c_and_d() -> Cell {
    import_cell(&[(series("C"), Purpose::Identification), (series("D"), Purpose::Validation)], &Ur10Options::default())
        .unwrap()
        .cell
}

fn geometry() -> Variant {
    Variant {
        name: "geometry".into(),
        options: IdentifyOptions {
            model: ModelOptions { compliance: false, ..Default::default() },
            ..Default::default()
        },
    }
}

fn compliance() -> Variant {
    Variant { name: "geometry+compliance".into(), options: IdentifyOptions::default() }
}

fn options(variants: Vec<Variant>) -> CrossvalOptions {
    CrossvalOptions {
        sessions: vec!["series-C".into()],
        folds: 0,
        sizes: Vec::new(),
        draws: 0,
        transfer: Vec::new(),
        transfer_fixed: Vec::new(),
        transfer_kappa_limit: None,
        variants,
        before: IdentifyOptions::default(),
        seed: 1,
        threads: 2,
    }
}

/// 5-fold cross-validation on series C: before (nominal, base and probe fitted) 0.90 mm, geometric
/// calibration 0.437 / 0.41 / 0.85 mm (mean / median / p95), orientation ≈ 0.9 mrad.
#[test]
fn five_fold_cross_validation_matches_the_reference() {
    let cv = crossval(&cell(), &CrossvalOptions { folds: 5, ..options(vec![geometry()]) }).unwrap();
    assert_eq!(cv.measurements, 2773);
    let before = cv.folds[0].pooled.as_ref().unwrap();
    let geo = cv.folds[1].pooled.as_ref().unwrap();
    assert_eq!(before.position.n, 2773, "every measurement is predicted exactly once");
    assert_eq!(geo.position.n, 2773);
    let mm = |v: f64| v / MM;
    eprintln!(
        "before {:.4} mm; geometry {:.4} / {:.4} / {:.4} mm, orientation {:.3} mrad",
        mm(before.position.mean),
        mm(geo.position.mean),
        mm(geo.position.median),
        mm(geo.position.p95),
        geo.orientation.unwrap().mean * 1e3
    );
    // The uncalibrated reference is a figure to reproduce, not to beat.
    assert!((mm(before.position.mean) - 0.90).abs() <= 0.01, "before: {}", mm(before.position.mean));
    assert!(mm(geo.position.mean) <= 0.437 + 0.01, "mean {}", mm(geo.position.mean));
    assert!(mm(geo.position.median) <= 0.41 + 0.01, "median {}", mm(geo.position.median));
    assert!(mm(geo.position.p95) <= 0.85 + 0.01, "p95 {}", mm(geo.position.p95));
    let ori = geo.orientation.unwrap().mean * 1e3;
    assert!(ori <= 0.9 + 0.05, "orientation {ori} mrad");
    // 30 parameters: the UR10's 24 MDH less the four of joint 1 and d2, d3 (parallel axes 2–4),
    // plus β of joints 3 and 4, six base, four probe (tool_z and tool_a go with d6 and θ6).
    assert_eq!(cv.folds[1].identified, 30);
}

/// Few poses: n poses of one random half identify, the other half tests; the mean over 10 draws
/// of the held-out mean reaches 0.47 / 0.45 / 0.44 mm with 50 / 100 / 200 poses.
#[test]
fn few_poses_reach_the_reference() {
    let cv = crossval(&cell(), &CrossvalOptions { sizes: vec![50, 100, 200], draws: 10, ..options(vec![geometry()]) })
        .unwrap();
    for (n, reference) in [(50, 0.47), (100, 0.45), (200, 0.44)] {
        let geo = cv.sizes.iter().find(|s| s.variant == "geometry" && s.n == n).unwrap();
        assert!(geo.draws.iter().all(|d| d.is_ok()), "{:?}", geo.draws);
        let mean = geo.mean(|h| h.position.mean).unwrap() / MM;
        eprintln!("{n} poses, 10 draws: {mean:.4} mm (reference {reference})");
        assert!(mean <= reference + 0.01, "{n} poses: {mean}");
        // Disjoint halves: the test half holds the other half of the session.
        assert_eq!(geo.draws[0].as_ref().unwrap().position.n, 2773 - 2773 / 2);
    }
    // More poses, smaller error: the model is not over-fitted at 200 poses.
    let at =
        |n: usize| cv.sizes.iter().find(|s| s.variant == "geometry" && s.n == n).unwrap().mean(|h| h.position.mean);
    assert!(at(50) > at(100) && at(100) > at(200));
}

/// Transfer: calibrate on all of series C, refit only base and probe on series B. Geometry alone
/// degrades (0.83 mm in the reference); the compliance model transfers (0.45 mm).
#[test]
fn compliance_transfers_to_another_series() {
    let cv = crossval(
        &cell(),
        &CrossvalOptions { transfer: vec!["series-B".into()], ..options(vec![geometry(), compliance()]) },
    )
    .unwrap();
    let get =
        |v: &str| cv.transfer.iter().find(|t| t.variant == v).unwrap().errors.as_ref().unwrap().position.mean / MM;
    let (before, geo, comp) = (get("before"), get("geometry"), get("geometry+compliance"));
    eprintln!("series B: before {before:.4}, geometry {geo:.4}, geometry + compliance {comp:.4} mm");
    assert!(geo <= 0.83 + 0.01, "{geo}");
    assert!(comp <= 0.45 + 0.01, "{comp}");
    assert!(comp < geo - 0.3, "compliance must transfer where geometry alone does not");
    assert!(geo < before);
}

/// Position-only fits of this probe (0.2 mm off axis 6) lose θ6 to the probe's x and y, and a5 and
/// d5 to joint 5's other parameters; identifiability says so instead of failing at the solution.
#[test]
fn position_only_fit_reports_what_it_cannot_identify() {
    let mut c = cell();
    c.sessions.truncate(1);
    for m in &mut c.sessions[0].measurements {
        if let Observation::Pose(f) = m.observation {
            m.observation = Observation::Position(f.t);
        }
    }
    let opts =
        IdentifyOptions { model: ModelOptions { compliance: false, ..Default::default() }, ..Default::default() };
    let id = identify(&c, &opts).unwrap();
    let status = |name: &str| id.status[id.set.layout.find(name).unwrap()].to_string();
    assert_eq!(status("theta6"), "theta6: no effect, the TCP lies on axis 6 and orientation is not measured");
    assert!(status("a5").starts_with("a5: dependent on"), "{}", status("a5"));
    assert_eq!(status("tool_a"), "tool_a: orientation not measured");
    assert!(!id.free_names.iter().any(|n| n == "theta6" || n == "a5"));
    assert!(id.quality.kappa_scaled < 1000.0);
}

/// Issue 24 (real data): a compliance the data do not determine is held at its start value and
/// says so. On series D (ISO cubes, no payload; the probe's z and d6 held, as its κ requires) the
/// wrist joints carry a few N·m of their own links' weight: c4 and c5 come out at 1–2 σ with signs
/// that change from series to series. Free, they extrapolated one held-out pose of a 5-fold
/// cross-validation 25.8 mm wrong; held, the worst held-out pose is within 2 mm and the mean is
/// lower. Checked here against two independent paths: the fit with every compliance free (the
/// first one held was below 3 σ there) and the fit with the held ones fixed by hand (the same
/// model to 1e-9).
#[test]
fn an_undetermined_compliance_is_held_and_said() {
    use robocal::identify::{COMPLIANCE_SIGNIFICANCE, FixedReason, Identification, Status};
    use robocal::kinematics::{JointTerm, Param};
    let cell = import_cell(&[(series("D"), Purpose::Identification)], &Ur10Options::default()).unwrap().cell;
    let base = IdentifyOptions { fixed: vec!["tool_z".into(), "d6".into()], ..Default::default() };
    let compliance = |id: &Identification, j: usize| {
        let i = id.set.layout.index_of(Param::Joint(j, JointTerm::Compliance)).unwrap();
        (id.set.values[i], id.std[i], id.status[i].clone())
    };
    let held = identify(&cell, &base).unwrap();
    let mut names = Vec::new();
    for j in 0..6 {
        match compliance(&held, j) {
            (v, _, Status::Fixed(why @ FixedReason::ComplianceInsignificant { change, std, sigmas, .. })) => {
                assert_eq!(v, 0.0, "c{} held at its start", j + 1);
                assert_eq!(sigmas, COMPLIANCE_SIGNIFICANCE);
                assert!(change.abs() < sigmas * std, "{why}");
                let why = why.to_string();
                assert!(why.contains("not determined by these data"), "{why}");
                assert!(why.contains(&format!("below {COMPLIANCE_SIGNIFICANCE} σ")), "{why}");
                names.push(format!("c{}", j + 1));
            }
            (v, s, Status::Identified) => {
                let s = s.expect("an identified compliance has a σ");
                assert!(v.abs() >= COMPLIANCE_SIGNIFICANCE * s, "c{} kept at {v} ± {s}", j + 1);
            }
            _ => {}
        }
    }
    eprintln!("held: {names:?}");
    assert!(names.contains(&"c5".to_string()), "{names:?}");

    let no_hold = IdentifyOptions { hold_undetermined_compliance: false, ..base.clone() };
    let free = identify(&cell, &no_hold).unwrap();
    let ratios: Vec<f64> = names
        .iter()
        .map(|n| {
            let (v, s, _) = compliance(&free, n[1..].parse::<usize>().unwrap() - 1);
            v.abs() / s.unwrap()
        })
        .collect();
    eprintln!("their |c|/σ with every compliance free: {ratios:?}");
    assert!(ratios.iter().any(|t| *t < COMPLIANCE_SIGNIFICANCE), "{ratios:?}");

    let by_hand = IdentifyOptions { fixed: [base.fixed.clone(), names.clone()].concat(), ..no_hold.clone() };
    let by_hand = identify(&cell, &by_hand).unwrap();
    for (i, (a, b)) in held.set.values.iter().zip(&by_hand.set.values).enumerate() {
        assert!((a - b).abs() <= 1e-9 * (1.0 + b.abs()), "{}: {a} vs {b}", held.set.layout.params()[i]);
    }

    let variants =
        vec![Variant { name: "held".into(), options: base.clone() }, Variant { name: "free".into(), options: no_hold }];
    let o = CrossvalOptions {
        sessions: vec!["series-D".into()],
        folds: 5,
        before: IdentifyOptions { kappa_limit: f64::INFINITY, ..base },
        ..options(variants)
    };
    let cv = crossval(&cell, &o).unwrap();
    let pooled = |name: &str| cv.folds.iter().find(|f| f.variant == name).unwrap().pooled.clone().unwrap().position;
    let (h, f) = (pooled("held"), pooled("free"));
    eprintln!(
        "held-out mean / max: held {:.4} / {:.3} mm, free {:.4} / {:.3} mm",
        h.mean / MM,
        h.max / MM,
        f.mean / MM,
        f.max / MM
    );
    assert!(h.max < 2.0 * MM && h.mean < f.mean, "held {h:?}, free {f:?}");
}

/// Issue 24: the σ of a fit that held a compliance are those of the model with it held. Where the
/// hold moves another parameter by more than its σ, a note says so, with both values: two fits
/// that held different compliances (the two halves of series C with tables, one holding c3, the
/// other c2) read θ2 4 σ apart though each σ holds for its own model. On series C the default
/// model holds c5, c4 and then c3 (1.5 σ), which moves a3 by about twice its σ. Checked against
/// two fits by hand: c4 and c5 fixed with c3 free (the "with it free" value), and all three fixed
/// (the value and σ the set reports).
#[test]
fn a_hold_that_moves_a_parameter_beyond_its_sigma_says_so() {
    use robocal::identify::Status;
    let cell = import_cell(&[(series("C"), Purpose::Identification)], &Ur10Options::default()).unwrap().cell;
    let held = identify(&cell, &IdentifyOptions::default()).unwrap();
    for c in ["c3", "c4", "c5"] {
        assert!(matches!(held.status[held.set.layout.find(c).unwrap()], Status::Fixed(_)), "{c} held");
    }
    let note = held.notes.iter().find(|n| n.starts_with("holding c3 (see its status) moved ")).unwrap_or_else(|| {
        panic!("{:?}", held.notes);
    });
    eprintln!("{note}");
    // "a3 from -571.659 mm with it free to -571.756 ± 0.049 mm"
    let moved = note.split(" moved ").nth(1).unwrap();
    let name = moved.split(' ').next().unwrap();
    let number = |s: &str| s.trim().split(' ').next().unwrap().parse::<f64>().unwrap();
    let from = number(moved.split(" from ").nth(1).unwrap());
    let to = number(moved.split(" with it free to ").nth(1).unwrap());
    let sd = number(moved.split(" ± ").nth(1).unwrap());
    let decimals = moved.split(" ± ").nth(1).unwrap().split(' ').next().unwrap().split('.').nth(1).map_or(0, str::len);
    let tolerance = 0.5 * 10f64.powi(-(decimals as i32)) * 1.001;
    assert!((from - to).abs() > sd, "{note}");

    let i = held.set.layout.find(name).unwrap();
    let unit = held.set.layout.params()[i].unit().to_si();
    let by_hand = |fixed: &[&str]| {
        let o = IdentifyOptions {
            fixed: fixed.iter().map(|s| s.to_string()).collect(),
            hold_undetermined_compliance: false,
            ..Default::default()
        };
        identify(&cell, &o).unwrap()
    };
    let free = by_hand(&["c4", "c5"]);
    let all = by_hand(&["c3", "c4", "c5"]);
    assert!((free.set.values[i] / unit - from).abs() <= tolerance, "{name}: {} vs {from}", free.set.values[i] / unit);
    assert!((all.set.values[i] / unit - to).abs() <= tolerance, "{name}: {} vs {to}", all.set.values[i] / unit);
    assert!((held.set.values[i] / unit - to).abs() <= tolerance, "{name}: {} vs {to}", held.set.values[i] / unit);
    let s = all.std[i].unwrap() / unit;
    assert!((s - sd).abs() <= tolerance, "{name}: σ {s} vs {sd}");
}

/// Issue 24: a correction table carried to another series (base and probe refitted there) is
/// applied as the set applies it wherever it is used: its own knots, whose first and last hold
/// their value beyond the identified range. The refit used to lay new knots over the other
/// series' range, started at 0, so the table fell to zero one knot step past series C's range and
/// `crossval --transfer` scored a model that compensation does not apply (table j2 on series B:
/// 0.686 mm so, 0.597 mm as applied). Checked against the set refitted by hand with the table's
/// knots named one by one (`extra`, the diagnosis's way) and validated on series B, whose q2
/// lies beyond series C's table for most of its poses.
#[test]
fn a_transfer_carries_a_table_as_the_set_applies_it() {
    use robocal::identify::ModelOptions;
    use robocal::kinematics::{JointTerm, Param};
    use robocal::validate::report::{Reference, validate};
    let cell = cell();
    let model = ModelOptions::parse("+map2_s2", 6).unwrap();
    let variant =
        Variant { name: "table".into(), options: IdentifyOptions { model: model.clone(), ..Default::default() } };
    let cv = crossval(&cell, &CrossvalOptions { transfer: vec!["series-B".into()], ..options(vec![variant]) }).unwrap();
    let t = cv.transfer.iter().find(|t| t.variant == "table" && t.session == "series-B").unwrap();
    let carried = t.errors.as_ref().unwrap().position.mean;

    let mut o = IdentifyOptions { model: model.clone(), ..Default::default() };
    o.selection.sessions = vec!["series-C".into()];
    let set = identify(&cell, &o).unwrap().set;
    let knots: Vec<Param> =
        set.layout.params().iter().copied().filter(|p| matches!(p, Param::Joint(1, JointTerm::Map { .. }))).collect();
    let index = |p: &Param| match p {
        Param::Joint(_, JointTerm::Map { knot, .. }) => *knot as f64 * 2.0_f64.to_radians(),
        _ => unreachable!(),
    };
    let (lo, hi) = knots.iter().map(index).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), q| (a.min(q), b.max(q)));
    let b = cell.session("series-B").unwrap();
    let beyond = b.measurements.iter().filter(|m| m.q[1] < lo || m.q[1] > hi).count();
    eprintln!(
        "table j2 over [{:.1}°, {:.1}°]; {beyond} of {} series-B poses beyond it",
        lo.to_degrees(),
        hi.to_degrees(),
        b.measurements.len()
    );
    assert!(beyond * 2 > b.measurements.len(), "{beyond}");

    let named = ModelOptions { maps: Vec::new(), extra: [model.extra.clone(), knots.clone()].concat(), ..model };
    let mut r = IdentifyOptions {
        model: named,
        start: Some(set.clone()),
        only: vec!["base".into(), "tool".into()],
        ..Default::default()
    };
    r.selection.sessions = vec!["series-B".into()];
    let refit = identify(&cell, &r).unwrap();
    let by_hand =
        validate(&refit.set, &cell, &["series-B".into()], Reference::Measured).unwrap().calibrated.position.mean;
    eprintln!("series B: crossval {:.4} mm, by hand {:.4} mm", carried / MM, by_hand / MM);
    assert!((carried - by_hand).abs() <= 1e-6 * by_hand, "crossval {carried} vs by hand {by_hand}");
}

/// A re-registration (`only: base, tool`) holds every robot parameter at the start set's value,
/// so it holds the set's own terms too, whatever model it is given. It used to build the layout
/// from the model alone: `identify --start set.json --only base,tool` with the default model, and
/// the ISO 9283 evaluation's registration, dropped the set's correction tables and cyclic terms
/// without a word, and wrote and scored a set without them. Checked against the same refit with
/// the terms named in the model, and against the set with its terms stripped (the old figure).
/// A full refit from the set with a model that leaves them out says so in its notes.
#[test]
fn a_re_registration_carries_the_sets_own_terms() {
    use robocal::kinematics::{JointTerm, Param};
    use robocal::validate::report::{Reference, validate};
    let cell = cell();
    let model = ModelOptions::parse("+map2_s2,+cyc1_h1", 6).unwrap();
    let mut o = IdentifyOptions { model: model.clone(), ..Default::default() };
    o.selection.sessions = vec!["series-C".into()];
    let set = identify(&cell, &o).unwrap().set;
    let is_term = |p: &Param| matches!(p, Param::Joint(_, JointTerm::Map { .. } | JointTerm::Cyclic { .. }));
    let terms = set.layout.params().iter().filter(|p| is_term(p)).count();
    assert!(terms > 10, "{terms} table and cyclic parameters");

    let register = |model: ModelOptions, only: bool| {
        let mut r = IdentifyOptions {
            model,
            start: Some(set.clone()),
            only: if only { vec!["base".into(), "tool".into()] } else { Vec::new() },
            ..Default::default()
        };
        r.selection.sessions = vec!["series-B".into()];
        identify(&cell, &r).unwrap()
    };
    let mean = |s: &robocal::kinematics::ParameterSet| {
        validate(s, &cell, &["series-B".into()], Reference::Measured).unwrap().calibrated.position.mean
    };
    let default = register(ModelOptions::default(), true);
    let named = register(model.clone(), true);
    let carried = default.set.layout.params().iter().filter(|p| is_term(p)).count();
    assert_eq!(carried, terms, "the re-registered set keeps every term of the set");
    let note = default.notes.iter().find(|n| n.contains("are carried at its values")).expect("a note");
    assert!(note.contains("+cyc1_h1") && note.contains("+map2_s2"), "{note}");
    let (a, b) = (mean(&default.set), mean(&named.set));
    assert!((a - b).abs() <= 1e-9 * b, "default model {a} vs terms named {b}");

    // What the registration used to score: the same refit of the set without its terms.
    let mut stripped = set.clone();
    for (i, p) in set.layout.params().iter().enumerate() {
        if is_term(p) {
            stripped.values[i] = 0.0;
        }
    }
    let mut r =
        IdentifyOptions { start: Some(stripped), only: vec!["base".into(), "tool".into()], ..Default::default() };
    r.selection.sessions = vec!["series-B".into()];
    let without = mean(&identify(&cell, &r).unwrap().set);
    eprintln!("series B: carried {:.4} mm, named {:.4} mm, without the terms {:.4} mm", a / MM, b / MM, without / MM);
    assert!((a - without).abs() > 0.01 * MM, "the terms change series B's figure: {a} vs {without}");

    let refit = register(ModelOptions::default(), false);
    assert!(!refit.set.layout.params().iter().any(is_term));
    let note = refit.notes.iter().find(|n| n.contains("are not in this model")).expect("a note");
    assert!(note.contains("+map2_s2"), "{note}");
}

/// `crossval --transfer` registers every model on a transfer session with the same freedoms.
/// On series D the probe's z is at the edge of determined (σ ≈ 10 mm along base x): the refits of
/// "before" and the default model held it (κ 7), that of a model with the tables j2, j1, j3, j5
/// and the periodic j1 term freed it (κ 2,055), so the table compared models registered
/// differently. Now what some refit held is held in all, a note says so, and the table model's
/// figure is that of its registration done by hand with the probe's z held (`identify` with
/// `only: base, tool` and `fixed: tool_z`, then `validate`).
#[test]
fn a_transfer_registers_every_model_with_the_same_freedoms() {
    use robocal::validate::report::{Reference, validate};
    let cell = cell_c_and_d();
    let model = ModelOptions::parse("+map2_s2,+map1_s3,+map3_s3,+cyc1_f22.75,+map5_s3", 6).unwrap();
    let tables =
        Variant { name: "tables".into(), options: IdentifyOptions { model: model.clone(), ..Default::default() } };
    let default = Variant { name: "default".into(), options: IdentifyOptions::default() };
    let cv = crossval(
        &cell,
        &CrossvalOptions {
            transfer: vec!["series-D".into()],
            transfer_kappa_limit: Some(1e4),
            ..options(vec![default, tables])
        },
    )
    .unwrap();
    for t in &cv.transfer {
        eprintln!("{} on {}: κ {:?}, held {:?}", t.variant, t.session, t.kappa_scaled, t.held);
        assert_eq!(t.held, vec!["tool_z".to_string()], "{}", t.variant);
        assert!(t.kappa_scaled.is_some_and(|k| k < 100.0), "{}: κ {:?}", t.variant, t.kappa_scaled);
    }
    assert!(cv.notes.iter().any(|n| n.contains("'series-D': tool_z held")), "{:?}", cv.notes);
    let carried = cv.transfer.iter().find(|t| t.variant == "tables").unwrap().errors.as_ref().unwrap().position.mean;

    let mut o = IdentifyOptions { model, ..Default::default() };
    o.selection.sessions = vec!["series-C".into()];
    let set = identify(&cell, &o).unwrap().set;
    let mut r = IdentifyOptions {
        start: Some(set),
        only: vec!["base".into(), "tool".into()],
        fixed: vec!["tool_z".into()],
        kappa_limit: 1e4,
        ..Default::default()
    };
    r.selection.sessions = vec!["series-D".into()];
    let refit = identify(&cell, &r).unwrap();
    assert!(!refit.free_names.iter().any(|n| n == "tool_z"));
    let by_hand =
        validate(&refit.set, &cell, &["series-D".into()], Reference::Measured).unwrap().calibrated.position.mean;
    eprintln!("series D, tables: crossval {:.4} mm, by hand {:.4} mm", carried / MM, by_hand / MM);
    assert!((carried - by_hand).abs() <= 1e-6 * by_hand, "crossval {carried} vs by hand {by_hand}");
}

/// A parameter held because the data leave it undetermined: the free parameters' values and σ
/// assume its held value, and the identification says by how much each moves per unit of it.
/// Series D registered with a set identified on C holds the probe's z (σ 11 mm, correlation
/// +1.000 with base_x), so "base_x ± 0.03 mm" holds only for that z. The sensitivity the fit
/// reports (linearised at the solution) is checked against two full nonlinear registrations with
/// the probe's declared z 1 mm apart.
#[test]
fn a_held_parameter_says_what_the_free_ones_assume_of_it() {
    use robocal::kinematics::Param;
    let cell = cell_c_and_d();
    let mut o = IdentifyOptions::default();
    o.selection.sessions = vec!["series-C".into()];
    let set = identify(&cell, &o).unwrap().set;
    let registered = |set: &robocal::kinematics::ParameterSet| {
        let mut r = IdentifyOptions {
            start: Some(set.clone()),
            only: vec!["base".into(), "tool".into()],
            kappa_limit: 1e4,
            ..Default::default()
        };
        r.selection.sessions = vec!["series-D".into()];
        let id = identify(&cell, &r).unwrap();
        let tool = id.tools.iter().find(|t| t.sessions.iter().any(|n| n == "series-D")).unwrap().tool.tcp;
        (id.set.pose_of(Param::Base), tool, id)
    };
    let (base, tool, id) = registered(&set);
    assert!(!id.free_names.iter().any(|n| n == "tool_z"), "the probe's z is held: {:?}", id.free_names);
    let c = id.conditional.iter().find(|c| c.held == "tool_z").expect("tool_z's conditional");
    assert!((c.value - tool[2] / MM).abs() < 1e-9 && c.std > 10.0, "{c:?}");
    let per = |name: &str| c.moves.iter().find(|m| m.0 == name).map(|m| m.2);
    assert!(id.notes.iter().any(|n| n.starts_with("tool_z is held at") && n.contains("base_x")), "{:?}", id.notes);

    // The start set's probe z 1 mm further: the registration holds it there.
    let mut moved = set.clone();
    let i = moved.layout.index_of(Param::Tool(2)).unwrap();
    moved.values[i] += 1e-3;
    let (base2, tool2, _) = registered(&moved);
    assert!(
        ((tool2[2] - tool[2]) / MM - 1.0).abs() < 1e-9,
        "the probe's z held 1 mm further: {} {}",
        tool[2],
        tool2[2]
    );
    for (k, name) in ["base_x", "base_y", "base_z"].iter().enumerate() {
        let by_refit = (base2[k] - base[k]) / MM;
        eprintln!("{name}: {by_refit:+.5} mm per mm by two registrations, {:?} reported", per(name));
        // Each moves beyond its σ (0.017–0.029 mm) over the probe's 11 mm: each is reported.
        let reported = per(name).expect("a parameter the held one moves beyond its σ is reported");
        assert!((reported - by_refit).abs() <= 1e-3 * by_refit.abs() + 2e-5, "{name}: {reported} vs {by_refit}");
    }
    assert!(per("base_x").is_some_and(|k| k > 0.9), "base_x follows the probe's z: {c:?}");
}
