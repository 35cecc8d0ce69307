//! The direction of each joint's last move, for the backlash candidate: from the logged
//! `approach` when every measurement has one; otherwise from consecutive measurements in
//! measuring order — the order of the logged times when every measurement has a time (across
//! sessions: a run measured one session after another is one sequence), else the file order of
//! each session, which is only right if the file was written as measured. The verdict reports
//! which source was used.

use crate::cell::Cell;

/// Where the approach directions came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ApproachSource {
    /// Every measurement logs its approach.
    Logged,
    /// Inferred from consecutive measurements ordered by their logged times.
    TimeOrder,
    /// Inferred from consecutive measurements in each session's file order (no time log).
    FileOrder,
}

impl ApproachSource {
    pub fn as_str(self) -> &'static str {
        match self {
            ApproachSource::Logged => "logged",
            ApproachSource::TimeOrder => "time_order",
            ApproachSource::FileOrder => "file_order",
        }
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

/// Fill every measurement's `approach` of the named sessions (all sessions when empty) from the
/// best available source, and say which it was.
pub fn fill_approach(cell: &mut Cell, sessions: &[String]) -> ApproachSource {
    let chosen: Vec<usize> = (0..cell.sessions.len())
        .filter(|&s| sessions.is_empty() || sessions.contains(&cell.sessions[s].name))
        .collect();
    let all = || chosen.iter().flat_map(|&s| cell.sessions[s].measurements.iter());
    if all().all(|m| m.approach.is_some()) {
        return ApproachSource::Logged;
    }
    let timed = all().all(|m| m.time_s.is_some_and(f64::is_finite));
    // The measuring sequence: (session, index) in order.
    let mut seq: Vec<(usize, usize)> =
        chosen.iter().flat_map(|&s| (0..cell.sessions[s].measurements.len()).map(move |i| (s, i))).collect();
    if timed {
        seq.sort_by(|a, b| {
            let t = |(s, i): (usize, usize)| cell.sessions[s].measurements[i].time_s.unwrap_or(0.0);
            t(*a).total_cmp(&t(*b))
        });
    }
    let mut prev: Option<Vec<f64>> = None;
    let mut prev_session = usize::MAX;
    for (s, i) in seq {
        // Without times, sessions are separate sequences: their relative order is unknown.
        if !timed && s != prev_session {
            prev = None;
        }
        prev_session = s;
        let m = &mut cell.sessions[s].measurements[i];
        let dir: Vec<i8> = match &prev {
            Some(p) => m.q.iter().zip(p).map(|(a, b)| sign(a - b)).collect(),
            None => vec![0; m.q.len()],
        };
        prev = Some(m.q.clone());
        m.approach = Some(dir);
    }
    if timed { ApproachSource::TimeOrder } else { ApproachSource::FileOrder }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::simulate::{SimulateOptions, simulate};

    fn small() -> Cell {
        let o = SimulateOptions { id_per_ball: 10, validation: 20, ..SimulateOptions::default() };
        simulate(&o).expect("simulate").cell
    }

    /// The simulator logs each joint's direction as the sign of the move from the previous
    /// planned pose; inferring it from the recorded joints in time order gives the same signs
    /// wherever the joint really moved.
    #[test]
    fn inferred_directions_match_the_simulators_log() {
        let cell = small();
        let mut stripped = cell.clone();
        for s in &mut stripped.sessions {
            for m in &mut s.measurements {
                m.approach = None;
            }
        }
        assert_eq!(fill_approach(&mut stripped, &[]), ApproachSource::TimeOrder);
        let (mut agree, mut total) = (0, 0);
        for (a, b) in cell.sessions.iter().zip(&stripped.sessions) {
            for (ma, mb) in a.measurements.iter().zip(&b.measurements) {
                for (x, y) in ma.approach.as_ref().unwrap().iter().zip(mb.approach.as_ref().unwrap()) {
                    if *y != 0 {
                        total += 1;
                        agree += (x == y) as usize;
                    }
                }
            }
        }
        assert!(total > 250 && agree as f64 >= 0.98 * total as f64, "{agree} of {total}");
        // Logged approaches are kept as they are.
        let mut logged = cell.clone();
        assert_eq!(fill_approach(&mut logged, &[]), ApproachSource::Logged);
        assert_eq!(logged, cell);
        // Without times: file order, each session its own sequence (first measurement unknown).
        for s in &mut stripped.sessions {
            for m in &mut s.measurements {
                m.approach = None;
                m.time_s = None;
            }
        }
        assert_eq!(fill_approach(&mut stripped, &[]), ApproachSource::FileOrder);
        for s in &stripped.sessions {
            assert!(s.measurements[0].approach.as_ref().unwrap().iter().all(|&d| d == 0));
        }
    }
}
