//! Program filtering (issue 26): for each language, a generated program of several hundred
//! targets (several tools and work frames, named and inline targets, joint targets, comments and
//! strings holding target-like text) is filtered with a calibrated parameter set, then read back
//! by the same parser, and:
//! - every filtered pose, put through the *nominal* model (the controller's closed-form inverse
//!   kinematics on the configuration written with it, or for URScript the numerical solution
//!   nearest the joints it was made from), lands the *calibrated* model's TCP on the original
//!   target within 1 µm (the rotation within the written angles' resolution); every recomputed
//!   joint target puts the calibrated TCP where the nominal model put the original joints;
//! - only target lines differ, and every other byte is as it was (line endings, ISO-8859-1);
//! - the targets meant to fail (out of reach) fail, are left as written and are marked on their
//!   own line in the language's comment syntax.

use crate::programs;

use std::collections::HashSet;

use programs::{Sample, fanuc, irb120_set, krl, rapid, ur10_set, urscript};
use robocal::domain::program::{
    Calibration, FilterOptions, Filtered, JointTargets, Language, ReadTarget, TargetStatus, filter, read,
};
use robocal::kinematics::frame::rotation_angle;
use robocal::kinematics::ik_numeric::{self, IkOptions};
use robocal::kinematics::{AnalyticIk, Compensator, Frame, JointState, ParameterSet, Tool};

/// The calibrated TCP at joints `q` with `tool`, in work frame `base` (the calibrated base frame).
fn calibrated_in_work(set: &ParameterSet, tool: &Tool, base: &Frame, q: &[f64]) -> Frame {
    let s = set.with_tool(tool.clone());
    let chain = s.chain();
    let tau = s.gravity().torques(q);
    base.inverse().compose(&chain.base().inverse()).compose(&chain.fk(&JointState::with_torques(q, &tau[..q.len()])))
}

/// The controller's joints for a pose in its work frame: the nominal closed form on the written
/// branch, each axis with a written interval moved into it by whole turns.
fn controller_joints(set: &ParameterSet, t: &ReadTarget) -> Vec<f64> {
    let s = set.with_tool(t.tool.clone().unwrap());
    let nominal = s.nominal_chain();
    let world = nominal.base().compose(t.base.as_ref().unwrap()).compose(&t.pose.unwrap());
    let ik = AnalyticIk::new(&s.model, nominal.base(), nominal.tool()).unwrap();
    let mut q = ik.solve_unchecked(&world, t.branch.expect("a written configuration")).unwrap();
    for (j, r) in t.ranges.iter().enumerate() {
        if let Some((lo, hi)) = r {
            let tau = std::f64::consts::TAU;
            let k = ((lo - q[j]) / tau).ceil();
            if q[j] < *lo || q[j] >= *hi {
                q[j] += k * tau;
            }
            assert!(
                q[j] >= *lo - 1e-12 && q[j] < *hi + 1e-12,
                "{}: axis {} not in its written interval",
                t.name,
                j + 1
            );
        }
    }
    q.to_vec()
}

/// `files` filtered with `set` alone: no envelope, covariance or held-out uncertainty model.
fn filter_with(set: &ParameterSet, files: &[robocal::domain::program::ProgramFile], opts: &FilterOptions) -> Filtered {
    let comp = Compensator::new(set);
    let cal = Calibration {
        set,
        compensator: &comp,
        envelope: None,
        allow_outside_envelope: false,
        covariance: None,
        held_out: None,
    };
    filter(&cal, files, opts).unwrap_or_else(|e| panic!("{e}"))
}

/// Filter a sample, check the failures and the diff; the filtered program with both readings.
fn filtered(sample: &Sample, set: &ParameterSet, joints: JointTargets) -> (Filtered, Vec<ReadTarget>, Vec<ReadTarget>) {
    let opts = FilterOptions {
        language: None,
        joint_targets: joints,
        frames: sample.frames.clone(),
        seed_joints: sample.seed_joints.clone(),
    };
    let out = filter_with(set, &sample.files, &opts);
    let (_, before) = read(&sample.files, &opts).unwrap();
    let (_, after) = read(&out.files, &opts).unwrap();
    assert_eq!(before.len(), after.len());
    assert_eq!(before.len(), out.report.len());
    assert!(out.report.len() >= 300, "{} targets", out.report.len());
    // The failures are the ones meant to fail, marked on their line.
    let failed: Vec<_> = out.report.iter().filter(|r| r.status == TargetStatus::Failed).collect();
    assert_eq!(
        failed.len(),
        sample.failing.len(),
        "{:?}",
        failed.iter().map(|r| format!("{} line {}: {:?}", r.name, r.line, r.error)).collect::<Vec<_>>()
    );
    for r in &failed {
        assert!(sample.failing.contains(&r.name), "{} line {} failed: {:?}", r.name, r.line, r.error);
        assert!(r.error.as_deref().unwrap().contains("reach"), "{:?}", r.error);
    }
    // Only target lines differ; line endings and every other byte are kept.
    for (k, (a, b)) in sample.files.iter().zip(&out.files).enumerate() {
        let lines_a: Vec<&[u8]> = a.bytes.split(|c| *c == b'\n').collect();
        let lines_b: Vec<&[u8]> = b.bytes.split(|c| *c == b'\n').collect();
        assert_eq!(lines_a.len(), lines_b.len(), "{}: line count", a.name);
        let targets: HashSet<usize> =
            before.iter().filter(|t| t.file == k).flat_map(|t| t.lines.0..=t.lines.1).collect();
        let mut changed = 0;
        for (i, (x, y)) in lines_a.iter().zip(&lines_b).enumerate() {
            if x != y {
                changed += 1;
                assert!(
                    targets.contains(&(i + 1)),
                    "{} line {} is not a target's and changed:\n{}\n{}",
                    a.name,
                    i + 1,
                    String::from_utf8_lossy(x),
                    String::from_utf8_lossy(y)
                );
                assert_eq!(x.ends_with(b"\r"), y.ends_with(b"\r"), "{} line {}: line ending", a.name, i + 1);
            }
        }
        if targets.is_empty() {
            assert_eq!(changed, 0);
        } else {
            assert!(changed > 0, "{}: nothing changed", a.name);
        }
    }
    for (r, (b, a)) in out.report.iter().zip(before.iter().zip(&after)) {
        if r.status == TargetStatus::Failed {
            assert_eq!((a.pose, &a.joints), (b.pose, &b.joints), "{} changed", r.name);
            let file = &out.files[a.file].bytes;
            let line = file.split(|c| *c == b'\n').nth(a.lines.1 - 1).unwrap();
            let text = String::from_utf8_lossy(line);
            let marked = text.contains("NOT COMPENSATED") || {
                // Fanuc: the comment of the position's first line.
                let first = file.split(|c| *c == b'\n').nth(a.lines.0 - 1).unwrap();
                String::from_utf8_lossy(first).contains("NOT COMPENSATED")
            };
            assert!(marked, "{} is not marked: {text}", r.name);
        }
    }
    (out, before, after)
}

/// The round trip for languages whose poses state their configuration (IRB 120).
fn round_trip(
    set: &ParameterSet,
    out: &Filtered,
    before: &[ReadTarget],
    after: &[ReadTarget],
    rot_tol: f64,
) -> (f64, f64) {
    let (mut worst_p, mut worst_r) = (0.0f64, 0.0f64);
    let mut shift = Vec::new();
    for (r, (b, a)) in out.report.iter().zip(before.iter().zip(after)) {
        if r.status != TargetStatus::Compensated {
            continue;
        }
        let tool = a.tool.clone().unwrap();
        let base = a.base.clone().unwrap();
        let (reached, wanted) = match (&a.pose, &a.joints) {
            (Some(_), _) => {
                let q = controller_joints(set, a);
                (calibrated_in_work(set, &tool, &base, &q), b.pose.unwrap())
            }
            (None, Some(q)) => {
                // A recomputed joint target: the calibrated TCP at the new joints where the nominal
                // model put it at the old ones (both in their own base frame).
                let s = set.with_tool(tool.clone());
                let nominal = s.nominal_chain();
                let want = nominal.base().inverse().compose(&nominal.fk(&JointState::new(b.joints.as_ref().unwrap())));
                (calibrated_in_work(set, &tool, &Frame::identity(), q), want)
            }
            _ => unreachable!(),
        };
        let dp = (reached.t - wanted.t).norm();
        let dr = rotation_angle(&(reached.r.transpose() * wanted.r));
        assert!(dp <= 1e-6, "{} line {}: {:.3} µm from the target", r.name, r.line, dp * 1e6);
        assert!(dr <= rot_tol, "{} line {}: {:.3e} rad from the target", r.name, r.line, dr);
        worst_p = worst_p.max(dp);
        worst_r = worst_r.max(dr);
        shift.push(r.correction_mm.unwrap());
    }
    let mean = shift.iter().sum::<f64>() / shift.len() as f64;
    assert!(mean > 0.3, "the fake targets should move by about a millimetre, mean {mean} mm");
    (worst_p, worst_r)
}

#[test]
fn rapid_modules_filter_with_a_round_trip_and_only_target_lines_changed() {
    let set = irb120_set();
    let sample = rapid(7, 400);
    let (out, before, after) = filtered(&sample, &set, JointTargets::Recompute);
    assert_eq!(out.language, Language::Rapid);
    // The quaternion is written to 1e-9: the rotation holds to a few nrad.
    let (p, r) = round_trip(&set, &out, &before, &after, 1e-7);
    eprintln!("RAPID: {} targets, worst {:.3} µm, {:.2e} rad", out.report.len(), p * 1e6, r);
    let text = String::from_utf8_lossy(&out.files[0].bytes).into_owned();
    // The ISO-8859-1 byte and the commented and quoted target text are kept.
    assert!(out.files[0].bytes.windows(7).any(|w| w == b"Schwei\xdf"));
    assert!(
        text.contains(
            "! Generated for the filter tests. MoveL [[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]"
        )
    );
    assert!(text.contains("TPWrite \"Reached p10:=[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]\";"));
    // External axes kept byte for byte, confdata rewritten for the compensated joints.
    assert_eq!(
        text.matches("[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]").count(),
        String::from_utf8_lossy(&sample.files[0].bytes).matches("[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]").count()
    );
    assert!(text.contains("MoveL p_far, v100, fine, gun;") && text.contains("! robocal: NOT COMPENSATED:"));
    // Kept joint targets: the bytes of every jointtarget as written.
    let (kept, _, _) = filtered(&sample, &set, JointTargets::Keep);
    let kept_joints = kept.report.iter().filter(|r| r.status == TargetStatus::Kept).count();
    assert!(kept_joints > 10);
    for r in kept.report.iter().filter(|r| r.status == TargetStatus::Kept) {
        assert!(r.compensated.is_none());
        let line =
            String::from_utf8_lossy(kept.files[0].bytes.split(|c| *c == b'\n').nth(r.line - 1).unwrap()).into_owned();
        let orig =
            String::from_utf8_lossy(sample.files[0].bytes.split(|c| *c == b'\n').nth(r.line - 1).unwrap()).into_owned();
        assert_eq!(line, orig);
    }
}

/// A set with hysteresis: a program does not say which way the robot arrives at its targets,
/// so each is compensated for the middle of the bands (the calibrated TCP with every joint at
/// its band's middle lands on it, the round trip above), and each says so with its spread.
#[test]
fn a_program_filtered_with_a_sets_hysteresis_says_it_is_left_at_the_bands_middle() {
    use robocal::kinematics::{JointTerm, Param};
    let mut set = irb120_set();
    set.extend(&[Param::Joint(0, JointTerm::Backlash), Param::Joint(1, JointTerm::Backlash)]);
    set.set(Param::Joint(0, JointTerm::Backlash), 0.015_f64.to_radians());
    set.set(Param::Joint(1, JointTerm::Backlash), -0.02_f64.to_radians());
    let sample = rapid(7, 400);
    let (out, before, after) = filtered(&sample, &set, JointTargets::Recompute);
    round_trip(&set, &out, &before, &after, 1e-7);
    let mut spreads = Vec::new();
    for r in out.report.iter().filter(|r| r.status == TargetStatus::Compensated) {
        let note =
            r.notes.iter().find(|n| n.contains("hysteresis")).unwrap_or_else(|| panic!("{}: {:?}", r.name, r.notes));
        assert!(
            note.contains("(joint 1 ±0.0150°, joint 2 ±0.0200°)") && note.contains("a program does not say"),
            "{note}"
        );
        spreads.push(note.split(" mm RMS").next().unwrap().rsplit(' ').next().unwrap().parse::<f64>().unwrap());
    }
    // Each band moves the TCP by its angle times the lever: 0.1–0.3 mm over this workspace.
    let (lo, hi) = spreads.iter().fold((f64::INFINITY, 0.0f64), |(l, h), s| (l.min(*s), h.max(*s)));
    assert!(lo > 0.02 && hi < 0.4 && hi > lo, "{lo}–{hi} mm");
}

#[test]
fn krl_pairs_filter_with_a_round_trip_and_only_target_lines_changed() {
    let set = irb120_set();
    let sample = krl(11, 400);
    let (out, before, after) = filtered(&sample, &set, JointTargets::Recompute);
    assert_eq!(out.language, Language::Krl);
    // A, B, C are written to 1e-6°.
    let (p, r) = round_trip(&set, &out, &before, &after, 1e-7);
    eprintln!("KRL: {} targets, worst {:.3} µm, {:.2e} rad", out.report.len(), p * 1e6, r);
    let dat = &out.files[1].bytes;
    assert!(dat.windows(7).any(|w| w == b"Schwei\xdf"));
    assert!(String::from_utf8_lossy(dat).contains("; robocal: NOT COMPENSATED:"));
    assert!(String::from_utf8_lossy(&out.files[0].bytes).contains("PTP {A1 0,A2 -90} in a comment"));
}

#[test]
fn fanuc_programs_filter_with_a_round_trip_and_only_target_lines_changed() {
    let set = irb120_set();
    let sample = fanuc(5, 400);
    let (out, before, after) = filtered(&sample, &set, JointTargets::Recompute);
    assert_eq!(out.language, Language::Fanuc);
    // Three decimals, as the controller writes them: 0.5 µm per coordinate at most (the round trip
    // still holds to 1 µm), 0.0005° per angle.
    let (p, r) = round_trip(&set, &out, &before, &after, 2e-5);
    eprintln!("Fanuc: {} targets, worst {:.3} µm, {:.2e} rad", out.report.len(), p * 1e6, r);
    let text = String::from_utf8_lossy(&out.files[0].bytes).into_owned();
    assert!(text.contains(":\"NOT COMPENSATED\"]{"), "the failed position's comment");
    assert!(text.contains("!P[17] X = 100.000 mm, CONFIG : 'N U T, 0, 0, 0' ;"));
    assert!(text.contains("COMMENT\t\t= \"P[1] X = 5 mm\";"));
}

#[test]
fn urscript_programs_filter_with_a_round_trip_and_only_target_lines_changed() {
    let set = ur10_set();
    let sample = urscript(3, 400);
    let (out, before, after) = filtered(&sample, &set, JointTargets::Recompute);
    assert_eq!(out.language, Language::Urscript);
    let (mut worst, mut n) = (0.0f64, 0);
    let mut shift = Vec::new();
    for (r, (b, a)) in out.report.iter().zip(before.iter().zip(&after)) {
        if r.status != TargetStatus::Compensated {
            continue;
        }
        let tool = a.tool.clone().unwrap();
        let (reached, wanted) = match (&a.pose, &a.joints) {
            (Some(fake), _) => {
                // The controller solves the written pose nearest the joints it is at: here the
                // joints the original pose was made from (the compensated ones are a hair away).
                let q0 = sample
                    .joints
                    .get(&(a.line, a.name.clone()))
                    .unwrap_or_else(|| panic!("{} line {}", a.name, a.line));
                let s = set.with_tool(tool.clone());
                let nominal = s.nominal_chain();
                let world = nominal.base().compose(fake);
                let q = ik_numeric::solve(&nominal, &s.gravity(), &world, q0, &IkOptions::default()).unwrap();
                (calibrated_in_work(&set, &tool, &Frame::identity(), q.joints()), b.pose.unwrap())
            }
            (None, Some(q)) => {
                let s = set.with_tool(tool.clone());
                let nominal = s.nominal_chain();
                let want = nominal.base().inverse().compose(&nominal.fk(&JointState::new(b.joints.as_ref().unwrap())));
                (calibrated_in_work(&set, &tool, &Frame::identity(), q), want)
            }
            _ => unreachable!(),
        };
        let dp = (reached.t - wanted.t).norm();
        let dr = rotation_angle(&(reached.r.transpose() * wanted.r));
        assert!(
            dp <= 1e-6 && dr <= 1e-7,
            "{} line {}: {:.3} µm, {:.2e} rad; compensated joints {:?}, made from {:?}",
            r.name,
            r.line,
            dp * 1e6,
            dr,
            r.joints_deg,
            sample
                .joints
                .get(&(a.line, a.name.clone()))
                .map(|q| q.iter().map(|v| v / programs::DEG).collect::<Vec<_>>())
        );
        worst = worst.max(dp);
        n += 1;
        shift.push(r.correction_mm.unwrap());
    }
    assert!(n >= 300, "{n} compensated");
    let mean = shift.iter().sum::<f64>() / shift.len() as f64;
    assert!(mean > 0.3, "mean correction {mean} mm");
    eprintln!("URScript: {n} targets, worst {:.3} µm", worst * 1e6);
    let text = String::from_utf8_lossy(&out.files[0].bytes).into_owned();
    assert!(text.contains("# movel(p[0.1, 0.2, 0.3, 0, 0, 0]) commented out"));
    assert!(text.contains("pose_trans(wp_") && text.contains("p[0, 0, -0.05, 0, 0, 0]"));
    assert!(text.contains("textmsg(\"done: movel(p[1,2,3,4,5,6])\")"));
    assert!(text.contains("# robocal: NOT COMPENSATED:"));
}

/// Without starting joints a URScript pose before any joint motion cannot be solved: it is named.
#[test]
fn a_pose_without_joints_before_it_is_named() {
    let set = ur10_set();
    let files = vec![robocal::domain::program::ProgramFile {
        name: "p.script".into(),
        bytes: b"def p():\n  set_tcp(p[0, 0, 0.1, 0, 0, 0])\n  movel(p[0.6, -0.2, 0.4, 0, 3.14, 0], a=1)\nend\n"
            .to_vec(),
    }];
    let out = filter_with(&set, &files, &FilterOptions::default());
    assert_eq!(out.failed(), 1);
    assert!(out.report[0].error.as_deref().unwrap().contains("seed_joints_deg"), "{:?}", out.report[0].error);
    let text = String::from_utf8(out.files[0].bytes.clone()).unwrap();
    assert!(text.contains("movel(p[0.6, -0.2, 0.4, 0, 3.14, 0], a=1)  # robocal: NOT COMPENSATED:"), "{text}");
}

/// The command line: the example module filtered to a file (exit 0), the report's lines, the same
/// bytes as the library; a failing target exits 1 with the file written; a malformed program exits 2
/// naming the line.
#[test]
fn the_command_line_filters_and_exits_by_the_outcome() {
    let bin = env!("CARGO_BIN_EXE_robocal");
    let root = env!("CARGO_MANIFEST_DIR");
    let dir = std::env::temp_dir().join(format!("robocal-filter-cli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let params = format!("{root}/examples/irb120_table_5_1.json");
    let run = |args: &[&str]| std::process::Command::new(bin).args(args).current_dir(&dir).output().unwrap();
    let out = run(&[
        "filter",
        &format!("{root}/examples/programs/weld.mod"),
        "--params",
        &params,
        "--out",
        "w.mod",
        "--report",
        "r.csv",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("7 targets, 6 compensated, 1 joint targets kept, 0 not compensated"), "{stdout}");
    let written = std::fs::read(dir.join("w.mod")).unwrap();
    let set = robocal::domain::ParameterSetDoc::from_json(&std::fs::read_to_string(&params).unwrap()).unwrap().set;
    let files = vec![robocal::domain::program::ProgramFile {
        name: "weld.mod".into(),
        bytes: std::fs::read(format!("{root}/examples/programs/weld.mod")).unwrap(),
    }];
    let lib = filter_with(&set, &files, &FilterOptions::default());
    assert_eq!(written, lib.files[0].bytes);
    let csv = std::fs::read_to_string(dir.join("r.csv")).unwrap();
    assert_eq!(csv.lines().count(), 8, "{csv}");
    assert!(csv.lines().nth(3).unwrap().starts_with("weld.mod,seam{1},8,pose,compensated,"), "{csv}");
    // To standard output: the program's bytes only.
    let out = run(&["filter", &format!("{root}/examples/programs/weld.mod"), "--params", &params]);
    assert_eq!(out.status.code(), Some(0));
    assert_eq!(out.stdout, lib.files[0].bytes);
    // A target out of reach: exit 1, the file written and marked.
    let far = String::from_utf8_lossy(&files[0].bytes).replace("[[170.00,20.00,120.00]", "[[1700.00,20.00,120.00]");
    std::fs::write(dir.join("far.mod"), far).unwrap();
    let out = run(&["filter", "far.mod", "--params", &params, "--out", "far_filtered.mod"]);
    assert_eq!(out.status.code(), Some(1), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stderr).contains("1 of 7 targets not compensated"));
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("line 21 MoveL (inline): target out of reach"),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    assert!(
        std::fs::read_to_string(dir.join("far_filtered.mod"))
            .unwrap()
            .contains("! robocal: NOT COMPENSATED: target out of reach")
    );
    // A malformed program: exit 2, the line named.
    let bad = String::from_utf8_lossy(&files[0].bytes)
        .replace("[0,0,0.996195,-0.087156],[-1,0,-2,0]", "[0,0,0.996195,-0.087156],[-1,0,-2]");
    std::fs::write(dir.join("bad.mod"), bad).unwrap();
    let out = run(&["filter", "bad.mod", "--params", &params, "--out", "x.mod"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("bad.mod line 7: robtarget approach: expected"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // KRL needs its numbered frames: without them, exit 1 naming them.
    let out = run(&["filter", &format!("{root}/examples/programs/weld.src"), "--params", &params, "--out", "krl/"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stdout).contains("tool '1' is not declared in the program and was not given"));
    assert!(dir.join("krl/weld.src").exists() && dir.join("krl/weld.dat").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// A program whose tool is the set's declared one (`tool0`, the flange, as a set fitted on a
/// reflector declared at the flange declares) is compensated for the set's calibrated TCP, 60 mm
/// away: each such target says so; a target with the program's own tool does not.
#[test]
fn a_program_with_the_sets_declared_tool_says_when_its_calibrated_tcp_is_far_from_it() {
    use robocal::kinematics::Param;
    let mut set = ParameterSet::nominal(robocal::kinematics::model::irb120(), Tool::flange(), [0.0; 6]);
    set.set(Param::A(2), 0.2702);
    set.set(Param::Tool(0), 0.06);
    let text = "MODULE Plate\n\
                PERS tooldata gun:=[TRUE,[[0,0,100],[1,0,0,0]],[1,[0,0,50],[1,0,0,0],0,0,0]];\n\
                PROC main()\n\
                \x20 MoveJ [[350,0,450],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v100, fine, tool0;\n\
                \x20 MoveJ [[350,0,350],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v100, fine, gun;\n\
                ENDPROC\n\
                ENDMODULE\n";
    let files =
        vec![robocal::domain::program::ProgramFile { name: "plate.mod".into(), bytes: text.as_bytes().to_vec() }];
    let opts = FilterOptions { joint_targets: JointTargets::Recompute, ..Default::default() };
    let out = filter_with(&set, &files, &opts);
    assert_eq!(out.report.len(), 2);
    assert!(out.report.iter().all(|r| r.status == TargetStatus::Compensated), "{:?}", out.report);
    let noted = |i: usize| out.report[i].notes.iter().any(|n| n.contains("calibrated TCP lies 60.0 mm"));
    assert!(noted(0), "{:?}", out.report[0].notes);
    assert!(out.report[0].notes.iter().any(|n| n.contains("the program declares the set's tool")));
    assert!(!noted(1), "{:?}", out.report[1].notes);
}
