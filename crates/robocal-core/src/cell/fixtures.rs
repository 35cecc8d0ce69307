//! Small cells for unit tests: the IRB 120 with the thesis's ball triangle, measurements at
//! random configurations inside the joint limits. No planning and no instrument model: a test
//! says what each measurement observes.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{Artefact, Cell, Instrument, Measurement, Observation, Purpose, Session};
use crate::kinematics::Tool;
use crate::kinematics::model::irb120;
use crate::metrology::BallTriangle;

/// A measurement of `observation` at joint readings `q` (rad), with nothing else logged.
pub(crate) fn measurement(q: Vec<f64>, observation: Observation) -> Measurement {
    Measurement {
        q,
        observation,
        temperature_c: None,
        time_s: None,
        sequence: None,
        approach: None,
        indicators: None,
        sigma: None,
    }
}

/// A session of `measurements` taken with `tool` (its TCP declared, not to be identified).
pub(crate) fn session(name: &str, purpose: Purpose, tool: Tool, measurements: Vec<Measurement>) -> Session {
    let instrument = if measurements.iter().all(|m| matches!(m.observation, Observation::Ball(_))) {
        Instrument::TriCal
    } else {
        Instrument::LaserTracker
    };
    Session {
        name: name.into(),
        purpose,
        instrument,
        tool,
        identify_tcp: false,
        target: None,
        measurements,
        order: Default::default(),
    }
}

/// The thesis cell's artefact: a 300 mm equilateral triangle of 12.7 mm balls.
pub(crate) fn artefact() -> Artefact {
    Artefact {
        triangle: BallTriangle::from_distances(0.300, 0.300, 0.300).expect("equilateral"),
        ball_diameter: 0.0127,
    }
}

/// The IRB 120 (nominal model), no base guess, the thesis's artefact, these sessions.
pub(crate) fn irb120_cell(sessions: Vec<Session>) -> Cell {
    Cell { model: irb120(), base_guess: None, artefact: Some(artefact()), sessions }
}

/// `n` IRB 120 configurations drawn uniformly inside the joint limits shrunk by 5°, away from
/// the wrist singularity (|q5| ≥ 3°), seeded.
pub(crate) fn random_configurations(n: usize, seed: u64) -> Vec<Vec<f64>> {
    let model = irb120();
    let margin = 5f64.to_radians();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let q: Vec<f64> =
            model.links.iter().map(|l| rng.random_range(l.limits[0] + margin..l.limits[1] - margin)).collect();
        if q[4].abs() >= 3f64.to_radians() {
            out.push(q);
        }
    }
    out
}
