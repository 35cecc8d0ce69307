//! Measuring order: which way each joint last moved before a measurement, from the logged
//! `approach` or, where a session has none, from consecutive measurements in measuring order —
//! the direction of the last move of each joint, what backlash depends on.
//!
//! Where the order comes from, best first, per session:
//! - **logged**: every measurement of the session logs its `approach`; kept as it is;
//! - **time order**: every measurement has a `time_s`. When every derived session is timed, they
//!   are one sequence (a run measured one session after another, or nests taking turns);
//! - **sequence order**: every measurement has a `sequence` number. Sessions whose numbers never
//!   name two different configurations are one run (several reflectors read at the same stops
//!   share the stop's number; the simulator's nests take turns in one numbering); sessions
//!   numbered independently (each from 0, e.g. series measured on different days) conflict and
//!   stay separate;
//! - **file order**: the session's list order, which is only right if the file was written as
//!   measured (`order` `measured`, or `unknown` for cells that do not say).
//!
//! Refused: a session marked `resampled` (its measurements are a selection of the stops: the move
//! into each is unknown) and a session marked `shuffled` whose measurements carry neither times
//! nor sequence numbers (times and sequence numbers travel with their measurements, the list
//! order does not). Their measurements get no direction.
//!
//! Within a sequence, consecutive measurements at the same configuration are one stop (several
//! reflectors, or a re-read): they share the direction of the move into the stop. The first stop
//! of a sequence and a joint that did not move get 0.

use std::collections::HashMap;

use super::{Cell, MeasuringOrder};

/// Where the approach directions came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum ApproachSource {
    /// Logged with the measurements.
    Logged,
    /// Inferred from consecutive measurements ordered by their logged times.
    TimeOrder,
    /// Inferred from consecutive measurements ordered by their sequence numbers.
    SequenceOrder,
    /// Inferred from consecutive measurements in each session's list (file) order.
    FileOrder,
}

impl ApproachSource {
    /// The name diagnosis reports use: `logged`, `time_order`, `sequence_order` or `file_order`.
    pub fn as_str(self) -> &'static str {
        match self {
            ApproachSource::Logged => "logged",
            ApproachSource::TimeOrder => "time_order",
            ApproachSource::SequenceOrder => "sequence_order",
            ApproachSource::FileOrder => "file_order",
        }
    }

    /// Derived from the measuring order rather than logged.
    pub(crate) fn is_derived(self) -> bool {
        self != ApproachSource::Logged
    }
}

/// What one session's directions are.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SessionApproach {
    /// From this source.
    From(ApproachSource),
    /// Not derived, and why.
    Refused(String),
}

/// The outcome of [`fill_approach`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Approach {
    /// The weakest source any session's directions came from (logged < time < sequence < file
    /// order); `None` when no session has directions.
    pub source: Option<ApproachSource>,
    /// Per chosen session, in cell order.
    pub sessions: Vec<(String, SessionApproach)>,
}

impl Approach {
    /// The sessions refused, with why.
    pub fn refused(&self) -> impl Iterator<Item = (&str, &str)> {
        self.sessions.iter().filter_map(|(n, a)| match a {
            SessionApproach::Refused(r) => Some((n.as_str(), r.as_str())),
            SessionApproach::From(_) => None,
        })
    }

    /// Why no direction is known, when none is: the refusals, or the lack of any order.
    pub(crate) fn unavailable_reason(&self) -> Option<String> {
        if self.source.is_some() {
            return None;
        }
        let refused: Vec<String> = self.refused().map(|(n, r)| format!("session '{n}' {r}")).collect();
        Some(if refused.is_empty() {
            "no approach log, and no session whose measuring order is known".into()
        } else {
            format!("no approach log, and directions are not derived from a lost order: {}", refused.join("; "))
        })
    }

    /// Sentences for a report: what was derived from the order (not logged), and what was refused.
    pub fn notes(&self) -> Vec<String> {
        let mut notes = Vec::new();
        let derived: Vec<String> = self
            .sessions
            .iter()
            .filter_map(|(n, a)| match a {
                SessionApproach::From(s) if s.is_derived() => Some(format!("{n} ({})", s.as_str())),
                _ => None,
            })
            .collect();
        if !derived.is_empty() {
            notes.push(format!(
                "approach directions are not logged: derived from the measuring order of {} (the direction of each joint's move into each stop; a stop deleted from the list leaves the move after it a guess, which shrinks a fitted hysteresis)",
                derived.join(", ")
            ));
        }
        for (n, r) in self.refused() {
            notes.push(format!("approach directions of session '{n}' are not derived: it {r}"));
        }
        notes
    }
}

/// A joint moving by less than this between two measurements has no defined direction (the
/// centring loop's corrections are larger; a joint left where it was is 0).
const STILL: f64 = 1e-9;

fn sign(d: f64) -> i8 {
    if d > STILL {
        1
    } else if d < -STILL {
        -1
    } else {
        0
    }
}

/// Two readings of the same configuration (every joint within [`STILL`]).
fn same_stop(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= STILL)
}

/// The direction of each joint's move into each reading of a run, readings in measuring order:
/// consecutive readings of one configuration are one stop and share the move into it; the first
/// stop, and a joint that did not move, get 0. Importers that know stops without a reading (a
/// row whose every reflector is hidden) pass them too, so the move after them is the true one.
pub fn directions<'a>(readings: impl IntoIterator<Item = &'a [f64]>) -> Vec<Vec<i8>> {
    let mut stop: Option<&[f64]> = None;
    let mut dir: Vec<i8> = Vec::new();
    let mut out = Vec::new();
    for q in readings {
        match stop {
            Some(p) if same_stop(p, q) => {}
            Some(p) => {
                dir = q.iter().zip(p).map(|(a, b)| sign(a - b)).collect();
                stop = Some(q);
            }
            None => {
                dir = vec![0; q.len()];
                stop = Some(q);
            }
        }
        out.push(dir.clone());
    }
    out
}

/// Sessions numbered as one run, and the configuration each number names.
type Run = (Vec<usize>, HashMap<u64, Vec<f64>>);

/// How a session's measurements are ordered.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Key {
    Time,
    Sequence,
    List,
}

/// Fill every measurement's `approach` of the named sessions (all sessions when empty) from the
/// best available source; sessions that log it keep theirs. Says where each session's came from.
pub fn fill_approach(cell: &mut Cell, sessions: &[String]) -> Approach {
    let chosen: Vec<usize> = (0..cell.sessions.len())
        .filter(|&s| sessions.is_empty() || sessions.contains(&cell.sessions[s].name))
        .collect();
    let mut per: Vec<Option<SessionApproach>> = vec![None; cell.sessions.len()];
    let mut keyed: Vec<(usize, Key)> = Vec::new();
    for &s in &chosen {
        let session = &cell.sessions[s];
        let ms = &session.measurements;
        if ms.iter().all(|m| m.approach.is_some()) {
            per[s] = Some(SessionApproach::From(ApproachSource::Logged));
            continue;
        }
        let timed = ms.iter().all(|m| m.time_s.is_some_and(f64::is_finite));
        let sequenced = ms.iter().all(|m| m.sequence.is_some());
        let key = match session.order {
            MeasuringOrder::Resampled => {
                per[s] = Some(SessionApproach::Refused(
                    "is marked resampled: its measurements are a selection of the stops, so the move into each is unknown"
                        .into(),
                ));
                continue;
            }
            _ if timed => Key::Time,
            _ if sequenced => Key::Sequence,
            MeasuringOrder::Shuffled => {
                per[s] = Some(SessionApproach::Refused(
                    "is marked shuffled and its measurements carry neither times nor sequence numbers: the measuring order is lost"
                        .into(),
                ));
                continue;
            }
            MeasuringOrder::Measured | MeasuringOrder::Unknown => Key::List,
        };
        keyed.push((s, key));
    }

    // The sequences: lists of (session, index) in measuring order.
    let mut runs: Vec<Vec<(usize, usize)>> = Vec::new();
    let all_timed = !keyed.is_empty() && keyed.iter().all(|(_, k)| *k == Key::Time);
    if all_timed {
        let mut seq: Vec<(usize, usize)> =
            keyed.iter().flat_map(|&(s, _)| (0..cell.sessions[s].measurements.len()).map(move |i| (s, i))).collect();
        let t = |(s, i): (usize, usize)| cell.sessions[s].measurements[i].time_s.unwrap_or(0.0);
        seq.sort_by(|a, b| t(*a).total_cmp(&t(*b)));
        runs.push(seq);
        for &(s, _) in &keyed {
            per[s] = Some(SessionApproach::From(ApproachSource::TimeOrder));
        }
    } else {
        // Sequence-numbered sessions join the first run whose numbering they agree with.
        let mut numbered: Vec<Run> = Vec::new();
        for &(s, key) in &keyed {
            let ms = &cell.sessions[s].measurements;
            match key {
                Key::Sequence => {
                    let mine: Vec<(u64, &[f64])> =
                        ms.iter().map(|m| (m.sequence.expect("sequenced"), m.q.as_slice())).collect();
                    let agrees = |theirs: &HashMap<u64, Vec<f64>>| {
                        mine.iter().all(|(n, q)| theirs.get(n).is_none_or(|p| same_stop(p, q)))
                    };
                    let k = match numbered.iter().position(|(_, theirs)| agrees(theirs)) {
                        Some(k) => k,
                        None => {
                            numbered.push((Vec::new(), HashMap::new()));
                            numbered.len() - 1
                        }
                    };
                    let (members, theirs) = &mut numbered[k];
                    members.push(s);
                    for (n, q) in mine {
                        theirs.entry(n).or_insert_with(|| q.to_vec());
                    }
                    per[s] = Some(SessionApproach::From(ApproachSource::SequenceOrder));
                }
                Key::Time => {
                    let mut seq: Vec<(usize, usize)> = (0..ms.len()).map(|i| (s, i)).collect();
                    let t = |(s, i): (usize, usize)| cell.sessions[s].measurements[i].time_s.unwrap_or(0.0);
                    seq.sort_by(|a, b| t(*a).total_cmp(&t(*b)));
                    runs.push(seq);
                    per[s] = Some(SessionApproach::From(ApproachSource::TimeOrder));
                }
                Key::List => {
                    runs.push((0..ms.len()).map(|i| (s, i)).collect());
                    per[s] = Some(SessionApproach::From(ApproachSource::FileOrder));
                }
            }
        }
        for (members, _) in numbered {
            let mut seq: Vec<(usize, usize)> =
                members.iter().flat_map(|&s| (0..cell.sessions[s].measurements.len()).map(move |i| (s, i))).collect();
            let n = |(s, i): (usize, usize)| cell.sessions[s].measurements[i].sequence.unwrap_or(0);
            seq.sort_by_key(|x| n(*x));
            runs.push(seq);
        }
    }

    for seq in runs {
        let dirs = directions(seq.iter().map(|&(s, i)| cell.sessions[s].measurements[i].q.as_slice()));
        for ((s, i), dir) in seq.into_iter().zip(dirs) {
            cell.sessions[s].measurements[i].approach = Some(dir);
        }
    }

    let sessions: Vec<(String, SessionApproach)> = chosen
        .iter()
        .map(|&s| (cell.sessions[s].name.clone(), per[s].clone().expect("every chosen session decided")))
        .collect();
    let source = sessions
        .iter()
        .filter_map(|(_, a)| match a {
            SessionApproach::From(s) => Some(*s),
            SessionApproach::Refused(_) => None,
        })
        .max();
    Approach { source, sessions }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::poses::reflector_plate;
    use crate::sim::simulate::{SimulateOptions, simulate};

    fn small() -> Cell {
        let o = SimulateOptions { id_per_ball: 10, validation: 20, ..SimulateOptions::default() };
        simulate(&o).expect("simulate").cell
    }

    fn strip(cell: &mut Cell, edit: impl Fn(&mut crate::cell::Measurement)) {
        for m in cell.sessions.iter_mut().flat_map(|s| s.measurements.iter_mut()) {
            m.approach = None;
            edit(m);
        }
    }

    /// (agreeing, compared) over the non-zero inferred directions of `b` against the log of `a`.
    fn agreement(a: &Cell, b: &Cell) -> (usize, usize) {
        let (mut agree, mut total) = (0, 0);
        for (sa, sb) in a.sessions.iter().zip(&b.sessions) {
            for (ma, mb) in sa.measurements.iter().zip(&sb.measurements) {
                for (x, y) in ma.approach.as_ref().unwrap().iter().zip(mb.approach.as_ref().unwrap()) {
                    if *y != 0 {
                        total += 1;
                        agree += (x == y) as usize;
                    }
                }
            }
        }
        (agree, total)
    }

    fn sources(a: &Approach) -> Vec<SessionApproach> {
        a.sessions.iter().map(|(_, s)| s.clone()).collect()
    }

    /// The simulator logs each joint's direction as the sign of the move from the previous
    /// planned pose; inferring it from the recorded joints in time order, or in sequence order,
    /// gives the same signs wherever the joint really moved.
    #[test]
    fn inferred_directions_match_the_simulators_log() {
        let cell = small();
        assert!(cell.sessions.iter().all(|s| s.order == MeasuringOrder::Measured));
        let mut stripped = cell.clone();
        strip(&mut stripped, |_| {});
        let a = fill_approach(&mut stripped, &[]);
        assert_eq!(a.source, Some(ApproachSource::TimeOrder));
        let (agree, total) = agreement(&cell, &stripped);
        assert!(total > 250 && agree as f64 >= 0.98 * total as f64, "{agree} of {total}");
        assert!(a.notes()[0].contains("derived from the measuring order"), "{:?}", a.notes());
        assert_eq!(a.unavailable_reason(), None);
        // Logged approaches are kept as they are.
        let mut logged = cell.clone();
        assert_eq!(fill_approach(&mut logged, &[]).source, Some(ApproachSource::Logged));
        assert_eq!(logged, cell);
        // Without times, the sequence numbers: one numbering for the TriCal run and the nests'
        // interleaved sessions, so the same directions.
        let mut numbered = cell.clone();
        strip(&mut numbered, |m| m.time_s = None);
        let a = fill_approach(&mut numbered, &[]);
        assert_eq!(a.source, Some(ApproachSource::SequenceOrder));
        assert_eq!(agreement(&cell, &numbered), (agree, total));
        // Without either: file order, each session its own sequence (first measurement unknown).
        strip(&mut stripped, |m| {
            m.time_s = None;
            m.sequence = None;
        });
        assert_eq!(fill_approach(&mut stripped, &[]).source, Some(ApproachSource::FileOrder));
        for s in &stripped.sessions {
            assert!(s.measurements[0].approach.as_ref().unwrap().iter().all(|&d| d == 0));
        }
    }

    /// A shuffled session's list is not its measuring order: with sequence numbers (they travel
    /// with the measurements) the directions come out as before the shuffle; without, none are
    /// derived, and the reason says why. A resampled session is never derived.
    #[test]
    fn shuffled_and_resampled_sessions_are_respected() {
        use rand::SeedableRng;
        use rand::seq::SliceRandom;
        let cell = small();
        let mut reference = cell.clone();
        strip(&mut reference, |m| m.time_s = None);
        fill_approach(&mut reference, &[]);

        let mut shuffled = cell.clone();
        strip(&mut shuffled, |m| m.time_s = None);
        for s in &mut shuffled.sessions {
            s.measurements.shuffle(&mut rand_chacha::ChaCha8Rng::seed_from_u64(3));
            s.order = MeasuringOrder::Shuffled;
        }
        let a = fill_approach(&mut shuffled, &[]);
        assert_eq!(a.source, Some(ApproachSource::SequenceOrder));
        for (r, s) in reference.sessions.iter().zip(&shuffled.sessions) {
            for m in &s.measurements {
                let twin = r.measurements.iter().find(|x| x.sequence == m.sequence).unwrap();
                assert_eq!(twin.approach, m.approach);
            }
        }

        // Order lost: no direction at all, and the reason names the sessions.
        strip(&mut shuffled, |m| m.sequence = None);
        let a = fill_approach(&mut shuffled, &[]);
        assert_eq!(a.source, None);
        assert!(shuffled.sessions.iter().flat_map(|s| &s.measurements).all(|m| m.approach.is_none()));
        let reason = a.unavailable_reason().unwrap();
        assert!(
            reason.contains("session 'trical-1' is marked shuffled") && reason.contains("measuring order is lost"),
            "{reason}"
        );
        assert_eq!(a.refused().count(), shuffled.sessions.len());
        // The same list unmarked is taken for the file order (what the marker prevents).
        let mut unmarked = shuffled.clone();
        unmarked.sessions.iter_mut().for_each(|s| s.order = MeasuringOrder::Unknown);
        assert_eq!(fill_approach(&mut unmarked, &[]).source, Some(ApproachSource::FileOrder));

        // Resampled: refused even with times; the other sessions are still derived.
        let mut resampled = cell.clone();
        strip(&mut resampled, |_| {});
        resampled.sessions[1].order = MeasuringOrder::Resampled;
        let a = fill_approach(&mut resampled, &[]);
        assert_eq!(a.source, Some(ApproachSource::TimeOrder));
        assert!(resampled.sessions[1].measurements.iter().all(|m| m.approach.is_none()));
        assert!(resampled.sessions[0].measurements.iter().all(|m| m.approach.is_some()));
        assert!(matches!(&sources(&a)[1], SessionApproach::Refused(r) if r.contains("resampled")));
        assert!(a.notes().iter().any(|n| n.contains("'tracker-n1'") && n.contains("resampled")), "{:?}", a.notes());
        // Only the named sessions are touched.
        let mut some = cell.clone();
        strip(&mut some, |_| {});
        let a = fill_approach(&mut some, &["trical-1".to_string()]);
        assert_eq!(a.sessions.len(), 1);
        assert!(some.sessions[1].measurements.iter().all(|m| m.approach.is_none()));
    }

    /// Several reflectors read at one stop share the direction of the move into it, in sequence
    /// order (their sessions share the numbering) and in time order alike; sessions numbered
    /// independently (each from 0) are separate runs.
    #[test]
    fn reflectors_at_one_stop_share_the_move_into_it() {
        let mut o = SimulateOptions { id_per_ball: 5, validation: 20, all_nests: true, ..SimulateOptions::default() };
        o.layout.nests = reflector_plate();
        let cell = simulate(&o).expect("simulate").cell;
        let tracker: Vec<&crate::cell::Session> =
            cell.sessions.iter().filter(|s| s.name.starts_with("tracker")).collect();
        assert_eq!(tracker.len(), 3);
        let shared =
            tracker[1].measurements.iter().filter(|m| tracker[0].measurements.iter().any(|x| x.q == m.q)).count();
        assert!(shared >= 10, "{shared} of {} poses shared", tracker[1].measurements.len());
        for by in ["time", "sequence"] {
            let mut c = cell.clone();
            strip(&mut c, |m| {
                if by == "sequence" {
                    m.time_s = None;
                }
            });
            fill_approach(&mut c, &[]);
            // The simulator's log of the tracker run (commanded joints, so exact; the TriCal's
            // recorded joints end the centring loop and agree to 98 %, as above). Its first stop
            // is left out: the robot went home between the runs, which no measurement records.
            let first = cell.sessions[1..].iter().flat_map(|s| &s.measurements).filter_map(|m| m.sequence).min();
            let tracker_only = |x: &Cell| {
                let mut t = Cell { sessions: x.sessions[1..].to_vec(), ..x.clone() };
                t.sessions.iter_mut().for_each(|s| s.measurements.retain(|m| m.sequence != first));
                t
            };
            let (agree, total) = agreement(&tracker_only(&cell), &tracker_only(&c));
            assert!(total > 100 && agree == total, "{by}: {agree} of {total}");
            for s in &c.sessions[1..] {
                for m in &s.measurements {
                    let at_stop: Vec<_> = c.sessions[1..]
                        .iter()
                        .flat_map(|t| &t.measurements)
                        .filter(|x| x.sequence == m.sequence)
                        .collect();
                    assert!(at_stop.iter().all(|x| x.approach == m.approach && x.q == m.q), "{by}");
                }
            }
        }
        // Two runs numbered from 0 each at different configurations: not merged.
        let mut two = cell.clone();
        strip(&mut two, |m| m.time_s = None);
        let first = two.sessions[0].measurements[0].sequence;
        for (k, m) in two.sessions[1].measurements.iter_mut().enumerate() {
            m.sequence = Some(k as u64);
        }
        assert_eq!(first, Some(0));
        fill_approach(&mut two, &[]);
        assert!(two.sessions[1].measurements[0].approach.as_ref().unwrap().iter().all(|&d| d == 0));
    }
}
