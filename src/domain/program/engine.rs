//! The engine of [`super::filter`]: the program's frames joined with the caller's, one
//! compensator per tool, every target solved (the motion before a "nearest" target seeds it) on
//! the machine's cores, and each result handed back to its language as edits and a report line.

use super::lex::{self, Edit, Lines};
use super::{
    Calibration, Dialect, FilterError, FilterOptions, Filtered, GivenFrames, JointTargets, Kind, Language, Parsed,
    Posture, ProgramFile, Ref, Solution, Target, TargetKind, TargetReport, TargetStatus,
};
use crate::domain::pose::{TargetUncertainty, guard_target};
use crate::domain::validity::{Guard, PredictionCovariance};
use crate::domain::{DEG, DomainError, MM};
use crate::kinematics::{Compensated, Compensator, Frame, IkError, JointState, Seed, Tool};
use crate::units::{OUT_DEG, OUT_MM, round_to};

/// The program's declared frames joined with the caller's.
pub(super) struct Frames<'a> {
    parsed: &'a Parsed,
    given: &'a GivenFrames,
}

impl<'a> Frames<'a> {
    /// Refuses a frame given by the caller that the program declares itself.
    pub(super) fn new(parsed: &'a Parsed, given: &'a GivenFrames, files: &[ProgramFile]) -> Result<Self, FilterError> {
        for (kind, names, declared) in [
            ("tool", given.tools.keys().collect::<Vec<_>>(), parsed.tools.keys().collect::<Vec<_>>()),
            ("base", given.bases.keys().collect(), parsed.bases.keys().collect()),
        ] {
            for n in names {
                if declared.contains(&n) {
                    let d = if kind == "tool" { &parsed.tools[n].file } else { &parsed.bases[n].file };
                    let line = if kind == "tool" { parsed.tools[n].line } else { parsed.bases[n].line };
                    return Err(FilterError::Input(DomainError::new(
                        kind,
                        format!(
                            "'{n}' is declared in the program ({} line {line}): the program's declaration is what the \
                             controller uses; do not give it",
                            files[*d].name
                        ),
                    )));
                }
            }
        }
        Ok(Frames { parsed, given })
    }

    pub(super) fn tool(&self, t: &Target) -> Result<Tool, String> {
        let mut tool = match &t.tool {
            Ref::Given(x) => x.clone(),
            Ref::Missing(why) => return Err(why.clone()),
            Ref::Named(n) => match (self.parsed.tools.get(n), self.given.tools.get(n)) {
                (Some(d), _) => d.value.clone()?,
                (None, Some(g)) => g.clone(),
                (None, None) => return Err(format!("tool '{n}' is not declared in the program and was not given")),
            },
        };
        if let Some((mass, com)) = t.payload {
            tool.mass = mass;
            tool.com = com;
        }
        Ok(tool)
    }

    pub(super) fn base(&self, t: &Target) -> Result<Frame, String> {
        match &t.base {
            Ref::Given(x) => Ok(*x),
            Ref::Missing(why) => Err(why.clone()),
            Ref::Named(n) => match (self.parsed.bases.get(n), self.given.bases.get(n)) {
                (Some(d), _) => d.value.clone(),
                (None, Some(g)) => Ok(*g),
                (None, None) => Err(format!("work frame '{n}' is not declared in the program and was not given")),
            },
        }
    }
}

/// A compensator per tool: the set's own (shared) or one built for a program's tool, with the
/// covariance that applies (without the tool's parameters for a tool the identification did not
/// see).
struct Rig<'a> {
    own: Option<Compensator>,
    covariance: Option<PredictionCovariance>,
    cal: &'a Calibration<'a>,
}

impl Rig<'_> {
    fn comp(&self) -> &Compensator {
        self.own.as_ref().unwrap_or(self.cal.compensator)
    }

    fn guard(&self) -> Guard<'_> {
        Guard {
            envelope: self.cal.envelope,
            allow_outside: self.cal.allow_outside_envelope,
            covariance: if self.own.is_some() { self.covariance.as_ref() } else { self.cal.covariance },
            held_out: self.cal.held_out,
        }
    }
}

/// A target's frames and compensator, resolved.
struct Setup {
    rig: usize,
    base: Frame,
}

/// How one target ended.
enum Outcome {
    Solved { solution: Solution, sigma: Box<TargetUncertainty>, notes: Vec<String>, correction: (f64, f64) },
    Kept,
    Failed(String),
}

/// Targets per thread below which splitting across cores is not worth a thread.
const TARGETS_PER_THREAD: usize = 128;

/// [`super::filter`] on a parsed program: the frames and compensators of every target, the
/// targets solved (on several threads when there are many), and the edits and the report.
pub(super) fn filter_parsed(
    cal: &Calibration,
    files: &[ProgramFile],
    opts: &FilterOptions,
    lang: Language,
    d: &dyn Dialect,
    parsed: &Parsed,
) -> Result<Filtered, FilterError> {
    let dof = cal.set.dof();
    if let Some(q) = &opts.seed_joints
        && q.len() != dof
    {
        return Err(FilterError::Input(DomainError::new(
            "seed_joints_deg",
            format!("expected {dof} joint values, got {}", q.len()),
        )));
    }
    let frames = Frames::new(parsed, &opts.frames, files)?;
    // Frames and compensators: one compensator per distinct tool.
    let mut rigs: Vec<(Option<Tool>, Rig)> = vec![(None, Rig { own: None, covariance: None, cal })];
    let mut setups: Vec<Result<Setup, String>> = Vec::with_capacity(parsed.targets.len());
    for t in &parsed.targets {
        let setup = (|| {
            if let Some(p) = &t.problem {
                return Err(p.clone());
            }
            let tool = frames.tool(t)?;
            let base = frames.base(t)?;
            let rig = if tool == cal.set.tool {
                0
            } else if let Some(i) = rigs.iter().position(|(k, _)| k.as_ref() == Some(&tool)) {
                i
            } else {
                let own = Compensator::new(&cal.set.with_tool(tool.clone()));
                rigs.push((
                    Some(tool),
                    Rig { own: Some(own), covariance: cal.covariance.map(|c| c.without_tool()), cal },
                ));
                rigs.len() - 1
            };
            Ok(Setup { rig, base })
        })();
        setups.push(setup);
    }
    let rigs: Vec<Rig> = rigs.into_iter().map(|(_, r)| r).collect();
    let seeds = nearest_seeds(parsed, &setups, &rigs, opts.seed_joints.as_deref());
    let limits: Vec<[f64; 2]> = cal.set.model.links.iter().map(|l| l.limits).collect();
    let solve = |i: usize| -> Outcome {
        let t = &parsed.targets[i];
        if matches!(t.kind, Kind::Joints { .. }) && opts.joint_targets == JointTargets::Keep {
            return Outcome::Kept;
        }
        let setup = match &setups[i] {
            Ok(s) => s,
            Err(why) => return Outcome::Failed(why.clone()),
        };
        solve_target(t, setup, &rigs[setup.rig], &seeds[i], &limits, opts.joint_targets)
    };
    let n = parsed.targets.len();
    let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
    let threads = cores.min(n / TARGETS_PER_THREAD).max(1);
    let outcomes: Vec<Outcome> = if threads <= 1 {
        (0..n).map(solve).collect()
    } else {
        let chunk = n.div_ceil(threads);
        std::thread::scope(|s| {
            let parts: Vec<_> = (0..threads)
                .map(|k| {
                    let solve = &solve;
                    s.spawn(move || (k * chunk..((k + 1) * chunk).min(n)).map(solve).collect::<Vec<_>>())
                })
                .collect();
            parts.into_iter().flat_map(|p| p.join().expect("a filter thread panicked")).collect()
        })
    };
    // Edits per file, and the report.
    let lines: Vec<Lines> = files.iter().map(|f| Lines::new(&f.bytes)).collect();
    let mut edits: Vec<Vec<Edit>> = vec![Vec::new(); files.len()];
    let mut report = Vec::with_capacity(n);
    for (t, outcome) in parsed.targets.iter().zip(outcomes) {
        let bytes = &files[t.file].bytes;
        let original = collapse(&bytes[t.extent.0..t.extent.1]);
        let kind = match t.kind {
            Kind::Pose { .. } => TargetKind::Pose,
            Kind::Joints { .. } => TargetKind::Joints,
        };
        let mut r = TargetReport {
            file: files[t.file].name.clone(),
            name: t.name.clone(),
            line: t.line,
            kind,
            status: TargetStatus::Kept,
            original,
            compensated: None,
            correction_mm: None,
            correction_deg: None,
            joints_deg: None,
            uncertainty_mm: None,
            error: None,
            notes: t.notes.clone(),
        };
        match outcome {
            Outcome::Kept => {}
            Outcome::Failed(why) => {
                edits[t.file].push(d.mark(bytes, &lines[t.file], t, &why));
                r.status = TargetStatus::Failed;
                r.error = Some(why);
            }
            Outcome::Solved { solution, sigma, notes, correction } => {
                let mut own = d.render(t, &solution);
                let shifted: Vec<Edit> = own
                    .iter()
                    .map(|e| Edit { at: e.at - t.extent.0, len: e.len, text: e.text.clone() })
                    .collect::<Vec<_>>();
                let mut shifted = shifted;
                r.compensated = Some(collapse(&lex::apply(&bytes[t.extent.0..t.extent.1], &mut shifted)));
                r.status = TargetStatus::Compensated;
                r.correction_mm = Some(round_to(correction.0 / MM, OUT_MM));
                r.correction_deg = Some(round_to(correction.1 / DEG, OUT_DEG));
                r.joints_deg = Some(solution.joints.iter().map(|v| round_to(v / DEG, OUT_DEG)).collect());
                r.uncertainty_mm = sigma.and_then(|(_, bound)| bound).map(|mm| round_to(mm, OUT_MM));
                r.notes.extend(notes);
                edits[t.file].append(&mut own);
            }
        }
        report.push(r);
    }
    let files = files
        .iter()
        .zip(edits.iter_mut())
        .map(|(f, e)| ProgramFile { name: f.name.clone(), bytes: lex::apply(&f.bytes, e) })
        .collect();
    Ok(Filtered { language: lang, files, report })
}

/// Whitespace runs as one space: a value for the report.
fn collapse(bytes: &[u8]) -> String {
    lex::latin1(bytes).split_whitespace().collect::<Vec<_>>().join(" ")
}

/// The seed of every [`Posture::Nearest`] pose: the controller's (nominal) solution nearest the
/// joints of the motion before it, in the order the motions use the targets. `Ok(None)` for the
/// targets that do not need one.
fn nearest_seeds(
    parsed: &Parsed,
    setups: &[Result<Setup, String>],
    rigs: &[Rig],
    start: Option<&[f64]>,
) -> Vec<Result<Option<Vec<f64>>, String>> {
    let mut seeds: Vec<Result<Option<Vec<f64>>, String>> = vec![Ok(None); parsed.targets.len()];
    if !parsed.targets.iter().any(|t| matches!(t.kind, Kind::Pose { posture: Posture::Nearest, .. })) {
        return seeds;
    }
    let mut done = vec![false; parsed.targets.len()];
    let mut current: Option<Vec<f64>> = start.map(<[f64]>::to_vec);
    let mut order: Vec<usize> = parsed.sequence.clone();
    // Targets no motion uses come last, in file order.
    let used: std::collections::HashSet<usize> = order.iter().copied().collect();
    order.extend((0..parsed.targets.len()).filter(|i| !used.contains(i)));
    for i in order {
        let t = &parsed.targets[i];
        if let Kind::Joints { q } = &t.kind {
            if t.problem.is_none() {
                current = Some(q.clone());
            }
            continue;
        }
        let Ok(setup) = &setups[i] else { continue };
        let comp = rigs[setup.rig].comp();
        let nominal_base = *comp.nominal_chain().base();
        match &t.kind {
            Kind::Joints { .. } => {}
            Kind::Pose { .. } if done[i] => {
                if let Ok(Some(q)) = &seeds[i] {
                    current = Some(q.clone());
                }
            }
            Kind::Pose { pose, posture } => {
                done[i] = true;
                let world = nominal_base.compose(&setup.base).compose(pose);
                let q = match posture {
                    Posture::Nearest => match &current {
                        None => {
                            seeds[i] = Err("its configuration is that of the motion before it, and none precedes \
                                            it: give the starting joints (seed_joints_deg)"
                                .into());
                            continue;
                        }
                        Some(c) => match comp.nominal_ik(&world, c) {
                            Ok(s) => s.joints().to_vec(),
                            Err(e) => {
                                seeds[i] = Err(format!(
                                    "the controller's model does not reach it from the joints before it (out of \
                                     reach, or too far from them): {e}"
                                ));
                                continue;
                            }
                        },
                    },
                    Posture::Confdata(c) => match comp.seed_on_branch(&world, c.cfx) {
                        Ok(q) => q.to_vec(),
                        Err(_) => continue,
                    },
                    Posture::Turns { branch, .. } => match comp.seed_on_branch(&world, *branch) {
                        Ok(q) => q.to_vec(),
                        Err(_) => continue,
                    },
                };
                if matches!(posture, Posture::Nearest) {
                    seeds[i] = Ok(Some(q.clone()));
                }
                current = Some(q);
            }
        }
    }
    seeds
}

/// Compensate one target.
fn solve_target(
    t: &Target,
    setup: &Setup,
    rig: &Rig,
    seed: &Result<Option<Vec<f64>>, String>,
    limits: &[[f64; 2]],
    joint_targets: JointTargets,
) -> Outcome {
    let comp = rig.comp();
    let nominal = comp.nominal_chain();
    let (c, correction) = match &t.kind {
        Kind::Joints { .. } if joint_targets == JointTargets::Keep => return Outcome::Kept,
        Kind::Joints { q } => {
            // Where the controller's model puts the TCP at the written joints, relative to its base;
            // the real robot is to be there relative to its own (calibrated) base, as a pose target.
            let before = nominal.fk(&JointState::new(q));
            let desired = comp.calibrated_chain().base().compose(&nominal.base().inverse()).compose(&before);
            let c = match comp.pose(&desired, Seed::Joints(q)) {
                Ok(c) => c,
                Err(e) => return Outcome::Failed(e.to_string()),
            };
            let after = nominal.fk(&JointState::new(c.joints()));
            (c, before.distance(&after))
        }
        Kind::Pose { pose, posture } => {
            let calibrated_base = *comp.calibrated_chain().base();
            let desired = calibrated_base.compose(&setup.base).compose(pose);
            let res: Result<Compensated, IkError> = match posture {
                Posture::Confdata(cd) => comp.pose(&desired, Seed::Confdata(*cd)),
                Posture::Turns { branch, ranges } => comp.seed_on_branch(&desired, *branch).and_then(|mut q| {
                    for (j, r) in ranges.iter().enumerate() {
                        if let Some((lo, hi)) = r {
                            q[j] = into_range(q[j], *lo, *hi, limits[j]);
                        }
                    }
                    comp.pose(&desired, Seed::Joints(&q))
                }),
                Posture::Nearest => match seed {
                    Ok(Some(q)) => comp.pose(&desired, Seed::Joints(q)),
                    Ok(None) => Err(IkError::InvalidTarget("no joints to start from".into())),
                    Err(why) => return Outcome::Failed(why.clone()),
                },
            };
            let c = match res {
                Ok(c) => c,
                Err(e) => return Outcome::Failed(e.to_string()),
            };
            let fake = setup.base.inverse().compose(&nominal.base().inverse()).compose(&c.fake_pose);
            let correction = pose.distance(&fake);
            (c, correction)
        }
    };
    // A program does not say which way the robot arrives at a target (that depends on the path
    // the controller runs): a set's hysteresis is left at the middle of its bands, and said.
    let hint = "; a program does not say which way its joints arrive (compensate the targets through \
                `robocal compensate` with approach to include it)";
    let (sigma, mut notes) = match guard_target(comp, &rig.guard(), &c, hint) {
        Ok(x) => x,
        Err(why) => {
            return Outcome::Failed(format!(
                "outside the calibrated envelope: {why}; the model is not validated there (allow_outside_envelope \
                 compensates it anyway)"
            ));
        }
    };
    // The program's tool is the set's declared one: compensated for the set's calibrated TCP,
    // which a set fitted on a point other than the controller's tool puts far from it.
    if rig.own.is_none() {
        notes.extend(crate::domain::validity::tool_note(
            comp,
            "the program declares the set's tool; declare the tool as the controller holds it to compensate for it",
        ));
    }
    if let Kind::Pose { posture: Posture::Turns { ranges, .. }, .. } = &t.kind {
        for (j, r) in ranges.iter().enumerate() {
            if let Some((lo, hi)) = r
                && !(c.q[j] >= *lo && c.q[j] < *hi)
            {
                notes.push(format!(
                    "axis {} ends at {:.4}°, outside the turn the program asked for ([{:.0}°, {:.0}°)): its turn is \
                     written as it is",
                    j + 1,
                    c.q[j] / DEG,
                    lo / DEG,
                    hi / DEG
                ));
            }
        }
    }
    let pose = match &t.kind {
        Kind::Pose { .. } => Some(setup.base.inverse().compose(&nominal.base().inverse()).compose(&c.fake_pose)),
        Kind::Joints { .. } => None,
    };
    Outcome::Solved {
        solution: Solution { pose, joints: c.joints().to_vec(), confdata: c.confdata },
        sigma: Box::new(sigma),
        notes,
        correction,
    }
}

/// `q` moved by whole turns into [lo, hi) when that keeps it within the joint's limits.
pub(super) fn into_range(q: f64, lo: f64, hi: f64, limits: [f64; 2]) -> f64 {
    let tau = std::f64::consts::TAU;
    if q >= lo && q < hi {
        return q;
    }
    let k = ((lo - q) / tau).ceil();
    let moved = q + k * tau;
    if moved >= lo && moved < hi && moved >= limits[0] && moved <= limits[1] { moved } else { q }
}
