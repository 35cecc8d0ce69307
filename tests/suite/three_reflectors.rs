//! Several reflectors on one flange, their TCPs unknown (issue 13): one TCP per physical target,
//! found from zero guesses; a fit that does not fit (one TCP for three nests, an outlier) refused
//! with the reason; per-measurement σ as weights. Data: the virtual cell's three tracker nests,
//! and a three-reflector file written from the true robot (every reflector at every pose).

use std::path::Path;
use std::process::Command;

use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use robocal::cell::{Cell, Observation, Purpose, Sigma};
use robocal::domain::ParameterSetDoc;
use robocal::identify::{Identification, IdentifyError, IdentifyOptions, MeasurementSelection, NoiseModel, identify};
use robocal::kinematics::{JointState, Param, ParameterSet, Tool};
use robocal::sim::effects::Effects;
use robocal::sim::instruments::Noise;
use robocal::sim::simulate::{SimulateOptions, Simulated, simulate};
use robocal::units::{MM, UM};

use crate::common;

const NESTS: [&str; 3] = ["tracker-n1", "tracker-n2", "tracker-n3"];

fn sim(noise: Noise) -> Simulated {
    simulate(&SimulateOptions { seed: 1, effects: Effects::parse("", 6).unwrap(), noise, ..Default::default() })
        .unwrap()
}

/// The three tracker sessions as identification sessions: declared (true) nests, or zero TCP
/// guesses to be identified.
fn nest_cell(sim: &Simulated, zero_guesses: bool) -> Cell {
    let mut cell = sim.cell.clone();
    cell.sessions.retain(|s| NESTS.contains(&s.name.as_str()));
    for s in &mut cell.sessions {
        s.purpose = Purpose::Identification;
        if zero_guesses {
            s.tool.tcp = [0.0; 6];
            s.identify_tcp = true;
        }
    }
    cell
}

/// The TCP position of tool block `block` of an identification at joints q.
fn predict(id: &Identification, block: usize, q: &[f64]) -> Vector3<f64> {
    let tool = &id.tools[block].tool;
    let chain = id.set.chain().with_base_tool(id.set.pose_of(Param::Base), tool.tcp);
    let tau = id.set.gravity_for(tool).torques(q);
    chain.fk(&JointState::with_torques(q, &tau[..6])).t
}

/// A nest seen from the frame of joint 6 before its rotation: Rz(θ6)·(t + d6·z). The TCPs and
/// d6, θ6 are one gauge (the data see only their composition), so nests are compared there.
fn nest_in_link5(set: &ParameterSet, tcp: &[f64; 6]) -> Vector3<f64> {
    let (d6, th6) = (set.value(Param::D(5)).unwrap(), set.value(Param::Theta(5)).unwrap());
    let t = Vector3::new(tcp[0], tcp[1], tcp[2] + d6);
    nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), th6) * t
}

fn sessions(names: &[&str]) -> IdentifyOptions {
    IdentifyOptions {
        selection: MeasurementSelection {
            sessions: names.iter().map(|s| s.to_string()).collect(),
            ..Default::default()
        },
        ..Default::default()
    }
}

/// Issue 13, item 1. Three nests with zero TCP guesses, identified together: each session gets a
/// TCP of its own, started by the alternating registration. Without noise the nests come back
/// to ≤ 5 µm of the truth (in the gauge-free frame of joint 6); with the default noise the model
/// predicts every tracker pose as the identification with the true TCPs given does (≤ 5 µm RMS),
/// and fits as well.
#[test]
fn three_nests_with_zero_guesses_are_recovered() {
    let exact = sim(Noise::none());
    let id = identify(&nest_cell(&exact, true), &sessions(&NESTS)).unwrap();
    assert_eq!(id.tools.len(), 3, "one TCP per nest");
    for (t, name) in id.tools.iter().zip(NESTS) {
        assert_eq!(t.sessions, [name]);
        let declared = &exact.cell.session(name).unwrap().tool;
        let err = (nest_in_link5(&id.set, &t.tool.tcp) - nest_in_link5(&exact.truth.set, &declared.tcp)).norm();
        assert!(err <= 5.0 * UM, "{name}: {:.3} µm from the true nest", err / UM);
    }

    let noisy = sim(Noise::default());
    let zero = identify(&nest_cell(&noisy, true), &sessions(&NESTS)).unwrap();
    let given = identify(&nest_cell(&noisy, false), &sessions(&NESTS)).unwrap();
    let (mut ss, mut n) = (0.0, 0);
    for (b, name) in NESTS.iter().enumerate() {
        let gb = given.tools.iter().position(|t| t.sessions == [*name]).unwrap();
        for m in &noisy.cell.session(name).unwrap().measurements {
            ss += (predict(&zero, b, &m.q) - predict(&given, gb, &m.q)).norm_squared();
            n += 1;
        }
    }
    let rms = (ss / n as f64).sqrt();
    assert!(rms <= 5.0 * UM, "the two models differ by {:.2} µm RMS", rms / UM);
    let (a, b) = (zero.quality.rms_residual, given.quality.rms_residual);
    assert!(a <= b * 1.001, "residual RMS {:.4} mm with zero guesses, {:.4} mm with the true TCPs", a / MM, b / MM);
    assert!(zero.quality.residual_ratio < 2.0, "ratio {}", zero.quality.residual_ratio);
}

/// Issue 13, item 2. The three nests declared one target (the merge the issue found): the fit
/// converges, but its residual is far above the tracker's noise, and it is refused with that.
#[test]
fn one_tcp_for_three_nests_is_refused() {
    let noisy = sim(Noise::default());
    let mut cell = nest_cell(&noisy, true);
    for s in &mut cell.sessions {
        s.target = Some("flange".into());
    }
    let e = identify(&cell, &sessions(&NESTS)).unwrap_err();
    let IdentifyError::Misfit { rms, expected, ratio, limit, .. } = &e else { panic!("{e}") };
    assert!(*ratio > 100.0 && *limit == 50.0, "{e}");
    assert!(*rms > 1.0 * MM && *expected < 0.05 * MM, "{e}");
    let text = e.to_string();
    assert!(text.contains("the model does not describe these data (check the TCPs, the sessions' frames, outliers)"));
    assert!(text.starts_with("residual RMS 3.5"), "{text}");
    // Given a target each, the same sessions calibrate.
    for (s, n) in cell.sessions.iter_mut().zip(1..) {
        s.target = Some(format!("nest-{n}"));
    }
    assert_eq!(identify(&cell, &sessions(&NESTS)).unwrap().tools.len(), 3);
}

/// Issue 13, item 2. One reading 5 mm off: refused, naming it; left out with an exclusion, or
/// down-weighted by the Huber loss, the fit is accepted.
#[test]
fn an_outlier_is_named_and_then_excluded_or_down_weighted() {
    let noisy = sim(Noise::default());
    let mut cell = nest_cell(&noisy, false);
    if let Observation::Position(p) = &mut cell.sessions[1].measurements[17].observation {
        p.y += 5.0 * MM;
    }
    let e = identify(&cell, &sessions(&NESTS)).unwrap_err();
    let IdentifyError::Outliers { outliers, .. } = &e else { panic!("{e}") };
    assert_eq!(outliers.len(), 1, "{e}");
    assert_eq!((outliers[0].session.as_str(), outliers[0].index), ("tracker-n2", 17));
    assert!(e.to_string().contains("(exclude tracker-n2:17) or fit with the Huber loss (huber 2.5)"), "{e}");

    let mut opts = sessions(&NESTS);
    opts.selection.exclude = vec![("tracker-n2".into(), 17)];
    let id = identify(&cell, &opts).unwrap();
    assert_eq!(id.quality.n_configs, 505);
    let mut opts = sessions(&NESTS);
    opts.solver.huber = Some(2.5);
    let id = identify(&cell, &opts).unwrap();
    assert!(id.downweighted.iter().any(|(s, i, _)| s == "tracker-n2" && *i == 17));
}

/// Issue 13, item 5. A measurement's own σ weighs its rows (repeatability added): a reading with a
/// tenfold σ barely moves the weighted fit; the expected-noise check uses the same σ.
#[test]
fn per_measurement_sigmas_are_weights() {
    let noisy = sim(Noise::default());
    let mut cell = nest_cell(&noisy, false);
    let noise = NoiseModel::default();
    for (k, m) in cell.sessions[0].measurements.iter_mut().enumerate() {
        let s = if k == 3 { 200.0 } else { 16.0 } * UM;
        m.sigma = Some(Sigma { position: [s, s, 2.0 * s], rotation: None });
    }
    let mut opts = sessions(&NESTS);
    opts.noise = Some(noise.clone());
    let id = identify(&cell, &opts).unwrap();
    let o = id.problem.obs.iter().find(|o| o.session == 0 && o.index == 3).unwrap();
    let want = 1.0 / (200.0 * UM).hypot(noise.repeatability);
    assert!(
        (o.weight[0] - want).abs() < 1e-9 * want && (o.weight[2] - want / 2.0).abs() < 1e-3 * want,
        "{:?}",
        o.weight
    );
    let other = id.problem.obs.iter().find(|o| o.session == 1).unwrap();
    let model = 1.0 / noise.position_sigma(robocal::cell::Instrument::LaserTracker, &id.problem.target_position(other));
    assert!((other.weight[0] - model).abs() < 1e-9 * model, "no σ of its own: the instrument model's");
    assert!(id.quality.residual_ratio > 0.5 && id.quality.residual_ratio < 2.0, "{}", id.quality.residual_ratio);
}

/// Per reflector, per pose: the joints (rad) and the true reflector position (m).
type TruePositions = Vec<Vec<(Vec<f64>, Vector3<f64>)>>;

/// A three-reflector file written from the true robot: every reflector at every pose, tracker
/// noise of 16 µm per axis; poses `range` of the virtual cell's tracker poses. Returns the
/// joints file, the positions files and, per reflector and pose, the true position.
fn write_three_reflector_files(
    sim: &Simulated,
    dir: &Path,
    tag: &str,
    range: std::ops::Range<usize>,
    seed: u64,
) -> (std::path::PathBuf, Vec<std::path::PathBuf>, TruePositions) {
    let poses: Vec<Vec<f64>> =
        NESTS.iter().flat_map(|n| sim.cell.session(n).unwrap().measurements.iter().map(|m| m.q.clone())).collect();
    let poses = &poses[range];
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, 16e-6).unwrap();
    let joints = dir.join(format!("{tag}-joints.txt"));
    let deg = |v: &[f64]| v.iter().map(|x| format!("{:.12}", x.to_degrees())).collect::<Vec<_>>().join(" ");
    std::fs::write(&joints, poses.iter().map(|q| deg(q) + "\n").collect::<String>()).unwrap();
    let mut files = Vec::new();
    let mut truth = Vec::new();
    for (k, name) in NESTS.iter().enumerate() {
        // The reflectors weigh nothing, as the import declares them.
        let tcp = sim.cell.session(name).unwrap().tool.tcp;
        let robot = sim.truth.robot(&Tool { tcp, ..Tool::flange() });
        let mut text = String::from("# x y z (mm)\n");
        let mut t = Vec::new();
        for q in poses {
            let p = robot.tcp(&robot.state(q, &[0.0; 6], 20.0)).t;
            let r = p + Vector3::from_fn(|_, _| noise.sample(&mut rng));
            text.push_str(&format!("{:.6} {:.6} {:.6}\n", r.x / MM, r.y / MM, r.z / MM));
            t.push((q.clone(), p));
        }
        let f = dir.join(format!("{tag}-r{}.txt", k + 1));
        std::fs::write(&f, text).unwrap();
        files.push(f);
        truth.push(t);
    }
    (joints, files, truth)
}

fn robocal(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_robocal")).args(args).output().unwrap();
    assert!(out.status.success(), "robocal {args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The held-out error (mean |model − true position|, m) of a parameter-set file on reflector k's
/// held-out poses, with the TCP it identified for that reflector.
fn held_out(doc: &ParameterSetDoc, k: usize, poses: &[(Vec<f64>, Vector3<f64>)]) -> f64 {
    let quality = doc.quality.as_ref().unwrap();
    let name = format!("reflector-{}", k + 1);
    let tool = quality.tools.iter().flatten().find(|t| t.sessions[0] == name).unwrap();
    let (p, r) = (tool.tcp_mm, tool.tcp_rotation_deg);
    let tcp = [p[0] * MM, p[1] * MM, p[2] * MM, r[0].to_radians(), r[1].to_radians(), r[2].to_radians()];
    let set = &doc.set;
    let chain = set.chain().with_base_tool(set.pose_of(Param::Base), tcp);
    let gravity = set.gravity_for(&Tool::flange());
    let sum: f64 = poses
        .iter()
        .map(|(q, truth)| {
            let tau = gravity.torques(q);
            (chain.fk(&JointState::with_torques(q, &tau[..6])).t - truth).norm()
        })
        .sum();
    sum / poses.len() as f64
}

/// Issue 13, "done when": a three-reflector file with unknown TCPs calibrates in one command
/// (`import three-reflector`, then `identify` with no option), and predicts held-out poses at
/// least as well as the best fit from one reflector alone.
#[test]
fn a_three_reflector_file_calibrates_in_one_command() {
    let noisy = sim(Noise::default());
    let dir = common::fresh_dir("three-reflectors");
    let (joints, files, _) = write_three_reflector_files(&noisy, &dir, "cal", 0..250, 7);
    let (_, _, test) = write_three_reflector_files(&noisy, &dir, "test", 250..506, 8);
    let cell = dir.join("cell.json");
    let (j, c) = (joints.to_str().unwrap(), cell.to_str().unwrap());
    let mut args = vec!["import", "three-reflector", "--robot", "irb120", "--joints", j];
    for f in &files {
        args.extend(["--positions", f.to_str().unwrap()]);
    }
    args.extend(["--out", c]);
    robocal(&args);
    let all = dir.join("all.json");
    let said = robocal(&["identify", c, "--out", all.to_str().unwrap()]);
    assert!(said.contains("times the"), "{said}");
    let all = ParameterSetDoc::from_json(&std::fs::read_to_string(&all).unwrap()).unwrap();
    assert_eq!(all.quality.as_ref().unwrap().tools.as_ref().unwrap().len(), 3);

    let mut best_single = f64::INFINITY;
    let mut together = Vec::new();
    for (k, poses) in test.iter().enumerate() {
        let out = dir.join(format!("single-{k}.json"));
        robocal(&["identify", c, "--sessions", &format!("reflector-{}", k + 1), "--out", out.to_str().unwrap()]);
        let single = ParameterSetDoc::from_json(&std::fs::read_to_string(&out).unwrap()).unwrap();
        best_single = best_single.min(held_out(&single, k, poses));
        together.push(held_out(&all, k, poses));
    }
    let worst_together = together.iter().copied().fold(0.0, f64::max);
    eprintln!("held-out mean: together {together:?} m, best single reflector {best_single} m");
    assert!(
        worst_together <= best_single,
        "together: {:.4} mm on its worst reflector; the best single reflector: {:.4} mm",
        worst_together / MM,
        best_single / MM
    );
}

/// Issue 24, item 1. One reflector in a nest on the flange's axis (80 mm out), no TCP guess, the
/// tracker's noise and pose-to-pose errors of 0.15 mm RMS that no term explains, over the virtual
/// cell's tracker poses. A TCP on axis 6 makes a5 and d5 dependent on θ5 and α5; the fit leaves
/// the TCP a few µm off the axis, where they are formally independent with standard deviations
/// of some 100 mm, and the fit crawled along their valley to its iteration limit (or was refused
/// as ill-conditioned) on most seeds. They are held as not determined by these data; the fit
/// converges and predicts held-out poses of the true robot to the unmodelled errors' share.
#[test]
fn one_reflector_on_the_flange_axis_without_a_guess_converges_under_unmodelled_errors() {
    let exact = sim(Noise::none());
    let tcp = [0.0, 0.0, 80.0 * MM, 0.0, 0.0, 0.0];
    let truth = exact.truth.robot(&Tool { tcp, ..Tool::flange() });
    let poses: Vec<Vec<f64>> =
        NESTS.iter().flat_map(|n| exact.cell.session(n).unwrap().measurements.iter().map(|m| m.q.clone())).collect();
    let (fit_poses, test_poses) = poses.split_at(poses.len() * 2 / 3);
    let at = |q: &[f64]| truth.tcp(&truth.state(q, &[0.0; 6], 20.0)).t;
    for seed in 0..4 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (tracker, unmodelled) =
            (Normal::new(0.0, 16e-6).unwrap(), Normal::new(0.0, 0.15 * MM / 3f64.sqrt()).unwrap());
        let mut cell = nest_cell(&exact, true);
        cell.sessions.truncate(1);
        let session = &mut cell.sessions[0];
        let template = session.measurements[0].clone();
        session.measurements = fit_poses
            .iter()
            .map(|q| {
                let p = at(q) + Vector3::from_fn(|_, _| tracker.sample(&mut rng) + unmodelled.sample(&mut rng));
                robocal::cell::Measurement { q: q.clone(), observation: Observation::Position(p), ..template.clone() }
            })
            .collect();
        let name = session.name.clone();
        let id = identify(&cell, &sessions(&[&name])).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
        for (p, name) in [(Param::A(5), "a5"), (Param::D(4), "d5")] {
            let i = id.set.layout.index_of(p).unwrap();
            assert_ne!(id.status[i], robocal::identify::Status::Identified, "seed {seed}: {name} identified");
        }
        let miss =
            test_poses.iter().map(|q| (predict(&id, 0, q) - at(q)).norm()).sum::<f64>() / test_poses.len() as f64;
        assert!(miss < 0.08 * MM, "seed {seed}: held-out poses missed by {:.3} mm on average", miss / MM);
    }
}
