//! Joint readings in another convention than the robot model, caught before they are fitted.
//!
//! A controller's joint reading and a kinematic table's joint angle can differ by a quarter or
//! half turn, a sign, or a coupling (a Fanuc J3 is read against the horizontal, so the table's
//! θ3 is J3 ± J2). A fit from the nominal robot does not refuse such data: a zero offset θ or a
//! twist α takes the quarter turns (θ2 −179.9° for a nominal −90°, α2 −899.96°), the lengths flip
//! their sign, and the fit converges — on an IRB 120 twin to 0.45–0.56 mm where the right
//! readings give 0.33 mm, since the gravity torques of the compliances, the joint limits and the
//! link masses' frames are all taken at the wrong angles. The parameter set then reads as a
//! calibration and is none.
//!
//! The starting registration shows it first: the nominal robot registered on the measured
//! positions ([`super::base`]) misses them by a few millimetres on any real robot (IRB 120 twin
//! 1.5 mm, UR5 0.6 mm, a cable-driven WAM 4.2 mm), and by a good part of the robot's size when a
//! reading means another angle. When the miss exceeds [`SUSPICIOUS_M`] and [`SUSPICIOUS_SHARE`] of
//! the positions' spread, each change of one joint's reading ([`ReadingChange`]) is tried on the
//! nominal robot — a pair of them to two joints when no single one helps — the best kept while it
//! at least halves the miss, up to [`MAX_CHANGES`] — and, when that explains nothing, every set of
//! reversed joints with every turn of joints 2 and 3 at once (`whole_convention`); the readings are refused ([`super::IdentifyError::JointConvention`]) only
//! when the changes bring the miss back under the same bound and to a third of what it was. A
//! miss that no change explains (a wrong link length in a robot file, a wrong declared TCP) is
//! left to the fit and said in its notes.

use super::base::{estimate_base_of, register_base_and_tcps};
use super::problem::tool_blocks;
use crate::cell::Cell;

/// A starting registration missing the positions by more than this (m) and by more than
/// [`SUSPICIOUS_SHARE`] of their spread is looked into.
pub const SUSPICIOUS_M: f64 = 0.010;
/// The share of the measured positions' spread (RMS distance from their centroid) above which the
/// starting registration's miss is looked into.
pub const SUSPICIOUS_SHARE: f64 = 0.03;
/// Measurements the candidates are scored on, at most (evenly spaced over the picks).
const SAMPLE: usize = 300;
/// Most reading changes combined.
pub const MAX_CHANGES: usize = 4;

/// One change of how a joint's reading maps onto the robot model's joint angle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ReadingChange {
    /// The model's angle of joint `joint` (0-based) is `±q + offset`.
    Joint {
        /// 0-based joint.
        joint: usize,
        /// The reading's sign is reversed.
        flip: bool,
        /// Added after the sign, rad.
        offset: f64,
    },
    /// The model's angle of joint `joint` is its reading plus `sign` times the reading of joint
    /// `with` (a reading taken against the horizontal, not against the link before).
    Coupled {
        /// 0-based joint.
        joint: usize,
        /// 0-based joint whose reading is added.
        with: usize,
        /// +1 or −1.
        sign: f64,
    },
}

impl ReadingChange {
    /// The joint this change moves.
    pub fn joint(&self) -> usize {
        match *self {
            ReadingChange::Joint { joint, .. } | ReadingChange::Coupled { joint, .. } => joint,
        }
    }

    /// The model's angle of the joint from the readings as the file holds them (rad).
    fn angle(&self, readings: &[f64]) -> f64 {
        match *self {
            ReadingChange::Joint { joint, flip, offset } => {
                if flip {
                    offset - readings[joint]
                } else {
                    readings[joint] + offset
                }
            }
            ReadingChange::Coupled { joint, with, sign } => readings[joint] + sign * readings[with],
        }
    }

    /// Every change tried for a robot of `dof` joints: per joint a quarter turn either way and a
    /// half turn, the sign reversed alone or with a quarter or half turn; per joint after the
    /// first, its reading plus or minus the reading before.
    pub fn candidates(dof: usize) -> Vec<ReadingChange> {
        use std::f64::consts::{FRAC_PI_2, PI};
        let mut out = Vec::new();
        for joint in 0..dof {
            for offset in [FRAC_PI_2, -FRAC_PI_2, PI] {
                out.push(ReadingChange::Joint { joint, flip: false, offset });
            }
            for offset in [0.0, FRAC_PI_2, -FRAC_PI_2, PI] {
                out.push(ReadingChange::Joint { joint, flip: true, offset });
            }
            if joint > 0 {
                for sign in [1.0, -1.0] {
                    out.push(ReadingChange::Coupled { joint, with: joint - 1, sign });
                }
            }
        }
        out
    }
}

impl std::fmt::Display for ReadingChange {
    /// The model's angle in terms of the readings, 1-based: `q2 − 90°`, `90° − q3`, `−q3`,
    /// `q3 + q2`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let deg = |x: f64| format!("{}°", (x.to_degrees() * 1e6).round() / 1e6);
        match *self {
            ReadingChange::Joint { joint, flip: false, offset } => {
                let sign = if offset < 0.0 { '−' } else { '+' };
                write!(f, "q{} {sign} {}", joint + 1, deg(offset.abs()))
            }
            ReadingChange::Joint { joint, flip: true, offset: 0.0 } => write!(f, "−q{}", joint + 1),
            ReadingChange::Joint { joint, flip: true, offset } => {
                let o = if offset < 0.0 { format!("−{}", deg(-offset)) } else { deg(offset) };
                write!(f, "{o} − q{}", joint + 1)
            }
            ReadingChange::Coupled { joint, with, sign } => {
                write!(f, "q{} {} q{}", joint + 1, if sign < 0.0 { '−' } else { '+' }, with + 1)
            }
        }
    }
}

/// One step of the search: the change (or pair of changes) taken, and the others that explained
/// as much at that step (within [`EQUALLY`]): on positions alone a wrist's sign and a half turn of
/// the joint before it can be one and the same.
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    /// The change, or the pair, taken.
    pub changes: Vec<ReadingChange>,
    /// The others as good.
    pub equally: Vec<Vec<ReadingChange>>,
}

/// Equals of a step named in its description; the rest are counted.
const SHOWN: usize = 2;

/// Readings that another convention explains: the starting registration's miss as read, and with
/// the changes.
#[derive(Clone, Debug, PartialEq)]
pub struct ConventionFinding {
    /// RMS miss of the nominal robot registered on the positions, readings as given, m.
    pub rms: f64,
    /// The same with every step's changes made, m.
    pub rms_changed: f64,
    /// The steps, in the order found.
    pub steps: Vec<Step>,
}

impl ConventionFinding {
    /// Every change taken, in order.
    pub fn changes(&self) -> Vec<ReadingChange> {
        self.steps.iter().flat_map(|s| s.changes.iter().copied()).collect()
    }

    /// `joint 2 as q2 − 90°` (further joints joined by "and"), each step's equals after it.
    pub fn describe(&self) -> String {
        let list = |cs: &[ReadingChange]| {
            cs.iter().map(|c| format!("joint {} as {c}", c.joint() + 1)).collect::<Vec<_>>().join(" and ")
        };
        self.steps
            .iter()
            .map(|step| {
                let mut s = list(&step.changes);
                if !step.equally.is_empty() {
                    let mut others = step.equally.iter().take(SHOWN).map(|e| list(e)).collect::<Vec<_>>().join("; or ");
                    if step.equally.len() > SHOWN {
                        others.push_str(&format!("; or {} more", step.equally.len() - SHOWN));
                    }
                    s.push_str(&format!(" (or, as well on these positions, {others})"));
                }
                s
            })
            .collect::<Vec<_>>()
            .join(" and ")
    }

    /// Where the fix can go: the robot model's zero offsets when every change is a turn, else
    /// the readings only.
    pub fn remedy(&self) -> &'static str {
        if self.changes().iter().all(|c| matches!(c, ReadingChange::Joint { flip: false, .. })) {
            "Convert the readings, or write the turns into the robot model's zero offsets (theta_deg), then import or identify again"
        } else {
            "Convert the readings (a sign or a coupling has no place in the robot model's table), then import or identify again"
        }
    }
}

/// The bound above which a starting registration's miss is looked into (m), for the picked
/// measurements' positions: the larger of [`SUSPICIOUS_M`] and [`SUSPICIOUS_SHARE`] of their
/// spread. `None` when fewer than ten positions are picked.
pub(crate) fn suspicious_above(cell: &Cell, picks: &[(usize, usize)]) -> Option<f64> {
    let p: Vec<_> =
        picks.iter().filter_map(|&(s, i)| cell.observed_position(&cell.sessions[s].measurements[i])).collect();
    if p.len() < 10 {
        return None;
    }
    Some(SUSPICIOUS_M.max(SUSPICIOUS_SHARE * super::scale::spread(p.into_iter())))
}

/// The starting registration's RMS miss (m) for the picked measurements with the readings
/// changed: both registered in turn when a TCP is unknown, else the base alone; `None` when the
/// cell has a base guess and no unknown TCP (nothing is registered: [`check`] sets the guess
/// aside first) or the registration fails.
pub(crate) fn start_miss(cell: &Cell, picks: &[(usize, usize)], changes: &[ReadingChange]) -> Option<f64> {
    if changes.is_empty() {
        return registration_miss(cell, picks);
    }
    let mut c = cell.clone();
    for &(s, i) in picks {
        let q = &mut c.sessions[s].measurements[i].q;
        let read = q.clone();
        for ch in changes {
            q[ch.joint()] = ch.angle(&read);
        }
    }
    registration_miss(&c, picks)
}

/// The starting registration's RMS miss (m) of the picked measurements as they are.
fn registration_miss(cell: &Cell, picks: &[(usize, usize)]) -> Option<f64> {
    let (blocks, session_tool) = tool_blocks(cell, picks);
    if blocks.iter().any(|b| b.identify_tcp && b.tool.tcp[..3] == [0.0; 3]) {
        register_base_and_tcps(cell, picks, &blocks, &session_tool, cell.base_guess).ok().map(|r| r.rms)
    } else if cell.base_guess.is_none() {
        estimate_base_of(cell, picks).ok().map(|(_, rms)| rms)
    } else {
        None
    }
}

/// At most [`SAMPLE`] of the picks, evenly spaced: what candidates are scored on.
fn sample(picks: &[(usize, usize)]) -> Vec<(usize, usize)> {
    picks.iter().copied().step_by(picks.len().div_ceil(SAMPLE).max(1)).collect()
}

/// Another step's miss within this share of the best one's is as good (two conventions the
/// positions cannot tell apart).
pub const EQUALLY: f64 = 0.02;

/// Look into a starting registration that missed by `rms` (m), beyond `bound`
/// ([`suspicious_above`]): `None` when no change of the readings explains it (see the module's
/// documentation). Each step takes the single change that misses least, or, when none halves
/// the miss, the pair of changes to two joints that does (a quarter turn of a shoulder and the
/// opposite one of the elbow move the wrist together).
pub(crate) fn search(cell: &Cell, picks: &[(usize, usize)], rms: f64, bound: f64) -> Option<ConventionFinding> {
    // The candidates are scored on a sample of the measurements (the registration's RMS settles
    // long before thousands), the finding judged on all of them.
    let sample = sample(picks);
    let candidates = ReadingChange::candidates(cell.model.dof());
    let mut steps: Vec<Step> = Vec::new();
    let mut taken: Vec<ReadingChange> = Vec::new();
    let mut now = rms;
    while taken.len() < MAX_CHANGES && now > bound {
        let open: Vec<ReadingChange> =
            candidates.iter().copied().filter(|c| taken.iter().all(|d| d.joint() != c.joint())).collect();
        let singles: Vec<Vec<ReadingChange>> = open.iter().map(|c| vec![*c]).collect();
        let mut step = best_of(cell, &sample, &taken, singles, now);
        if step.is_none() && taken.len() + 2 <= MAX_CHANGES {
            let pairs: Vec<Vec<ReadingChange>> = open
                .iter()
                .enumerate()
                .flat_map(|(i, a)| open[i + 1..].iter().filter(|b| b.joint() != a.joint()).map(|b| vec![*a, *b]))
                .collect();
            step = best_of(cell, &sample, &taken, pairs, now);
        }
        let Some((step, r)) = step else { break };
        taken.extend(step.changes.iter().copied());
        steps.push(step);
        now = r;
    }
    if !steps.is_empty() {
        let now = start_miss(cell, picks, &taken)?;
        if now <= bound && now <= rms / 3.0 {
            return Some(ConventionFinding { rms, rms_changed: now, steps });
        }
    }
    whole_convention(cell, picks, &sample, rms, bound)
}

/// Changes that only explain the miss all together, which no stepwise search finds: the readings
/// of a controller and a DH table can differ as a KUKA's do, joints 1, 4 and 6 reversed, joint 2
/// a quarter turn one way and joint 3 the other. On a Fanuc's sweeps read so, the five changes
/// added one at a time left the miss at 173, 157, 177 and 117 mm (153 mm as read) and took it to
/// 1.2 mm only together, while a wrong single change ("joint 3 as q3 + 90°", 43 mm) halved it and
/// the greedy search stopped there. Tried when that search explains nothing: every set of
/// reversed joints with every quarter or half turn of joints 2 and 3 (2ᵈᵒᶠ · 16 registrations on
/// the sample), the best kept on the same terms as a search's finding.
fn whole_convention(
    cell: &Cell,
    picks: &[(usize, usize)],
    sample: &[(usize, usize)],
    rms: f64,
    bound: f64,
) -> Option<ConventionFinding> {
    use std::f64::consts::{FRAC_PI_2, PI};
    let dof = cell.model.dof();
    let turned: Vec<usize> = (1..dof.min(3)).collect();
    let turns = [0.0, FRAC_PI_2, -FRAC_PI_2, PI];
    let mut tried: Vec<(Vec<ReadingChange>, f64)> = Vec::new();
    for flips in 0u32..(1 << dof) {
        for t in 0..turns.len().pow(turned.len() as u32) {
            let offset_of = |j: usize| {
                turned
                    .iter()
                    .position(|&k| k == j)
                    .map_or(0.0, |i| turns[(t / turns.len().pow(i as u32)) % turns.len()])
            };
            let changes: Vec<ReadingChange> = (0..dof)
                .filter_map(|joint| {
                    let (flip, offset) = (flips & (1 << joint) != 0, offset_of(joint));
                    (flip || offset != 0.0).then_some(ReadingChange::Joint { joint, flip, offset })
                })
                .collect();
            if changes.is_empty() {
                continue;
            }
            if let Some(r) = start_miss(cell, sample, &changes) {
                tried.push((changes, r));
            }
        }
    }
    let (step, _) = simplest_of_best(tried)?;
    let now = start_miss(cell, picks, &step.changes)?;
    (now <= bound && now <= rms / 3.0).then(|| ConventionFinding { rms, rms_changed: now, steps: vec![step] })
}

/// The option (one change or a pair) added to `taken` that misses least, with the others within
/// [`EQUALLY`] of it, when it at least halves the miss `now`.
fn best_of(
    cell: &Cell,
    picks: &[(usize, usize)],
    taken: &[ReadingChange],
    options: Vec<Vec<ReadingChange>>,
    now: f64,
) -> Option<(Step, f64)> {
    let tried: Vec<(Vec<ReadingChange>, f64)> = options
        .into_iter()
        .filter_map(|o| {
            let trial: Vec<ReadingChange> = taken.iter().chain(&o).copied().collect();
            start_miss(cell, picks, &trial).map(|r| (o, r))
        })
        .collect();
    if tried.iter().map(|t| t.1).min_by(f64::total_cmp)? >= now / 2.0 {
        return None;
    }
    simplest_of_best(tried)
}

/// Of the options tried (each with its miss) as good as the best one (within [`EQUALLY`]), the
/// simplest (a turn before a sign with a turn), then the closest, as a step whose equals are the
/// rest; with its miss. `None` when nothing was tried.
fn simplest_of_best(tried: Vec<(Vec<ReadingChange>, f64)>) -> Option<(Step, f64)> {
    let best = tried.iter().map(|t| t.1).min_by(f64::total_cmp)?;
    let mut equal: Vec<(Vec<ReadingChange>, f64)> =
        tried.into_iter().filter(|(_, r)| *r <= best * (1.0 + EQUALLY)).collect();
    equal.sort_by(|a, b| complexity(&a.0).cmp(&complexity(&b.0)).then(a.1.total_cmp(&b.1)));
    let mut it = equal.into_iter();
    let (changes, r) = it.next()?;
    Some((Step { changes, equally: it.map(|(o, _)| o).collect() }, r))
}

/// How much a set of changes asks of the readings: one for a turn, a sign or a coupling, two for
/// a sign with a turn.
fn complexity(cs: &[ReadingChange]) -> usize {
    cs.iter()
        .map(|c| if matches!(c, ReadingChange::Joint { flip: true, offset, .. } if *offset != 0.0) { 2 } else { 1 })
        .sum()
}

/// Measured positions paired with the joint readings of another line: each position of
/// `sessions` fits the readings `shift` stops later (earlier when negative).
#[derive(Clone, Debug, PartialEq)]
pub struct PairingFinding {
    /// RMS miss of the nominal robot registered on the positions as paired, m.
    pub rms: f64,
    /// The same with the positions paired `shift` stops on, m.
    pub rms_shifted: f64,
    /// The sessions whose positions are shifted (all of them when every file is).
    pub sessions: Vec<String>,
    /// Whether every session of the picks is shifted (the joints file is the odd one out).
    pub all: bool,
    /// Stops on: the position measured at stop n fits the readings of stop n + `shift`.
    pub shift: i64,
}

/// Most stops a pairing is shifted by when looked into.
pub const MAX_SHIFT: i64 = 3;

/// The picks with each measurement of `shifted` sessions given the joint readings of the stop
/// `shift` on in its session (by sequence number when the session has them, else by its list);
/// one without such a stop is left out.
fn shifted(cell: &Cell, picks: &[(usize, usize)], shifted: &[usize], shift: i64) -> (Cell, Vec<(usize, usize)>) {
    let mut c = cell.clone();
    let mut kept = Vec::with_capacity(picks.len());
    // Per shifted session, its measurements by sequence number.
    let by_sequence: std::collections::HashMap<(usize, i64), usize> = shifted
        .iter()
        .flat_map(|&s| {
            cell.sessions[s]
                .measurements
                .iter()
                .enumerate()
                .filter_map(move |(j, m)| m.sequence.map(|n| ((s, n as i64), j)))
        })
        .collect();
    for &(s, i) in picks {
        if !shifted.contains(&s) {
            kept.push((s, i));
            continue;
        }
        let ms = &cell.sessions[s].measurements;
        let from = match ms[i].sequence {
            Some(n) => by_sequence.get(&(s, n as i64 + shift)).copied(),
            None => usize::try_from(i as i64 + shift).ok().filter(|&j| j < ms.len()),
        };
        if let Some(j) = from {
            c.sessions[s].measurements[i].q = ms[j].q.clone();
            kept.push((s, i));
        }
    }
    (c, kept)
}

/// Look into a starting registration that missed by `rms` (m) for positions paired with the wrong
/// line of joint readings — a header counted in one file, a line deleted from one file only: every
/// session shifted together by up to [`MAX_SHIFT`] stops either way, then each alone. `None` when
/// no shift brings it under `bound` and to a third.
pub(crate) fn search_pairing(cell: &Cell, picks: &[(usize, usize)], rms: f64, bound: f64) -> Option<PairingFinding> {
    let mut sessions: Vec<usize> = picks.iter().map(|p| p.0).collect();
    sessions.dedup();
    sessions.sort_unstable();
    sessions.dedup();
    let mut options: Vec<Vec<usize>> = vec![sessions.clone()];
    if sessions.len() > 1 {
        options.extend(sessions.iter().map(|&s| vec![s]));
    }
    // Scored on a sample, as the conventions are; the best judged on every pick.
    let sample = sample(picks);
    let miss = |picks: &[(usize, usize)], o: &[usize], k: i64| {
        let (c, kept) = shifted(cell, picks, o, k);
        (kept.len() >= picks.len() / 2).then(|| registration_miss(&c, &kept)).flatten()
    };
    let shifts = (1..=MAX_SHIFT).flat_map(|k| [-k, k]);
    let (o, shift, _) = options
        .iter()
        .flat_map(|o| shifts.clone().map(move |k| (o, k)))
        .filter_map(|(o, k)| miss(&sample, o, k).map(|r| (o, k, r)))
        .min_by(|a, b| a.2.total_cmp(&b.2))?;
    let r = miss(picks, o, shift)?;
    (r <= bound && r <= rms / 3.0).then(|| PairingFinding {
        rms,
        rms_shifted: r,
        sessions: o.iter().map(|&s| cell.sessions[s].name.clone()).collect(),
        all: o.len() == sessions.len(),
        shift,
    })
}

impl PairingFinding {
    /// `each measured position of every session fits the joint readings of the stop before`.
    pub fn describe(&self) -> String {
        let whose = if self.all {
            "every session".to_string()
        } else {
            self.sessions.iter().map(|s| format!("'{s}'")).collect::<Vec<_>>().join(", ")
        };
        let k = self.shift.unsigned_abs();
        let when = match (k, self.shift < 0) {
            (1, true) => "the stop before".to_string(),
            (1, false) => "the stop after".to_string(),
            (k, true) => format!("{k} stops before"),
            (k, false) => format!("{k} stops after"),
        };
        format!("each measured position of {whose} fits the joint readings of {when}")
    }
}

/// Positions measured in a mirrored (left-handed) frame: with one axis reversed the nominal robot
/// fits them. A robot symmetric about its first joint's plane fits them as well with some joints'
/// signs reversed (1, 4 and 6 of an IRB 120): the positions cannot tell the two apart, and a
/// frame exported with an axis reversed is the likelier mistake.
#[derive(Clone, Debug, PartialEq)]
pub struct MirrorFinding {
    /// RMS miss of the nominal robot registered on the positions as given, m.
    pub rms: f64,
    /// The same with one axis of the positions reversed, m.
    pub rms_mirrored: f64,
    /// The change of the joint readings that explains them as well, when one does.
    pub joints: Option<ConventionFinding>,
}

impl MirrorFinding {
    /// The alternative the positions cannot tell from the mirror, or nothing.
    pub fn alternative(&self) -> String {
        match &self.joints {
            Some(j) if j.rms_changed <= self.rms_mirrored * (1.0 + EQUALLY) => {
                let taken: Vec<String> =
                    j.changes().iter().map(|c| format!("joint {} as {c}", c.joint() + 1)).collect();
                format!(
                    " (or, which these positions cannot tell apart, the joints read otherwise: {}, {} mm)",
                    taken.join(" and "),
                    super::error::mm(j.rms_changed)
                )
            }
            _ => String::new(),
        }
    }
}

/// Look into a starting registration that missed by `rms` (m) for positions in a mirrored frame:
/// every picked position with its x reversed (any reflection is that one and a rotation, which
/// the registration finds). Only for measured points: `None` when a pick observes a pose or a
/// ball, or when the mirror does not bring the miss under `bound` and to a third.
pub(crate) fn search_mirror(cell: &Cell, picks: &[(usize, usize)], rms: f64, bound: f64) -> Option<MirrorFinding> {
    use crate::cell::Observation;
    if picks.iter().any(|&(s, i)| !matches!(cell.sessions[s].measurements[i].observation, Observation::Position(_))) {
        return None;
    }
    let mut mirrored = cell.clone();
    for &(s, i) in picks {
        if let Observation::Position(p) = &mut mirrored.sessions[s].measurements[i].observation {
            p.x = -p.x;
        }
    }
    let r = registration_miss(&mirrored, picks)?;
    (r <= bound && r <= rms / 3.0).then(|| MirrorFinding {
        rms,
        rms_mirrored: r,
        joints: search(cell, picks, rms, bound),
    })
}

/// The checks of a starting registration that missed by `start_rms` (m), in turn: positions paired
/// a few stops on, a mirrored frame, another convention of the joint readings — refused when one
/// explains the miss. A miss beyond [`suspicious_above`] that none explains gives a note for the
/// identification; within it, nothing is looked into.
pub(crate) fn check(
    cell: &Cell,
    opts: &super::IdentifyOptions,
    start_rms: Option<f64>,
) -> Result<Option<String>, super::IdentifyError> {
    use super::IdentifyError;
    // Below the bound's floor nothing is looked into, so the picks are not even needed.
    let Some(rms) = start_rms.filter(|&r| r > SUSPICIOUS_M) else { return Ok(None) };
    let picks = opts.selection.picks(cell)?;
    let Some(bound) = suspicious_above(cell, &picks).filter(|&b| rms > b) else { return Ok(None) };
    // The readings are judged on registrations, never on a base guess: a guess is for the
    // readings as they should have been (and the miss was the registration's when the guess
    // missed more: [`super::prepare`]).
    let unguessed;
    let cell = if cell.base_guess.is_some() {
        unguessed = Cell { base_guess: None, ..cell.clone() };
        &unguessed
    } else {
        cell
    };
    if let Some(finding) = search_pairing(cell, &picks, rms, bound) {
        return Err(IdentifyError::RowsShifted { finding });
    }
    if let Some(finding) = search_mirror(cell, &picks, rms, bound) {
        return Err(IdentifyError::MirroredFrame { finding });
    }
    if let Some(finding) = search(cell, &picks, rms, bound) {
        return Err(IdentifyError::JointConvention { finding });
    }
    Ok(Some(format!(
        "the nominal robot, registered on the measured positions, missed them by {:.1} mm RMS at the start (a real robot's nominal model misses by a few mm): no quarter turn, sign or coupling of up to four joints' readings explains it, nor reversed joints with turns of joints 2 and 3 all together, so a fit starts far from the robot; check the robot model's lengths and the declared TCPs (after a fit, against its parameters' changes from nominal)",
        rms / crate::units::MM
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_change_reads_as_the_models_angle() {
        let q = [0.1, 0.2, 0.3];
        let d = |c: ReadingChange| c.angle(&q);
        use std::f64::consts::FRAC_PI_2;
        assert!(
            (d(ReadingChange::Joint { joint: 1, flip: false, offset: -FRAC_PI_2 }) - (0.2 - FRAC_PI_2)).abs() < 1e-15
        );
        assert!(
            (d(ReadingChange::Joint { joint: 2, flip: true, offset: FRAC_PI_2 }) - (FRAC_PI_2 - 0.3)).abs() < 1e-15
        );
        assert!((d(ReadingChange::Coupled { joint: 2, with: 1, sign: -1.0 }) - 0.1).abs() < 1e-15);
        let s: Vec<String> = [
            ReadingChange::Joint { joint: 1, flip: false, offset: -FRAC_PI_2 },
            ReadingChange::Joint { joint: 2, flip: true, offset: 0.0 },
            ReadingChange::Joint { joint: 2, flip: true, offset: -FRAC_PI_2 },
            ReadingChange::Coupled { joint: 2, with: 1, sign: 1.0 },
        ]
        .iter()
        .map(|c| c.to_string())
        .collect();
        assert_eq!(s, ["q2 − 90°", "−q3", "−90° − q3", "q3 + q2"]);
        // Seven per joint, two couplings per joint after the first.
        assert_eq!(ReadingChange::candidates(6).len(), 6 * 7 + 5 * 2);
    }
}
