//! The measurements of one robot cell, in SI units: the robot, an optional base guess, the
//! artefact, and sessions of measurements taken with one tool each. Parsed from and written to
//! cell files by the service's `domain::cell`; consumed by identification, validation and the simulator.

use nalgebra::Vector3;

use crate::kinematics::{Frame, RobotModel, Tool};
use crate::metrology::BallTriangle;

/// What a session is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Purpose {
    /// Measurements to identify the parameters from (the default identification selection).
    Identification,
    /// Measurements to score an identified parameter set on (the default validation selection).
    Validation,
}

impl Purpose {
    /// The name cell files use: `identification` or `validation`.
    pub fn as_str(self) -> &'static str {
        match self {
            Purpose::Identification => "identification",
            Purpose::Validation => "validation",
        }
    }
}

/// The instrument that produced a session's measurements.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Instrument {
    /// Closed loop on the artefact's balls: each measurement is a ball index.
    TriCal,
    /// A laser tracker (or any 3D/6D instrument): each measurement is a position, maybe a pose.
    LaserTracker,
}

impl Instrument {
    /// The name cell files use: `trical` or `laser_tracker`.
    pub fn as_str(self) -> &'static str {
        match self {
            Instrument::TriCal => "trical",
            Instrument::LaserTracker => "laser_tracker",
        }
    }
}

/// What was observed at a configuration.
#[derive(Clone, Debug, PartialEq)]
pub enum Observation {
    /// The TCP sat on the centre of ball k (1-based) of the artefact.
    Ball(usize),
    /// The TCP position in {W}, m.
    Position(Vector3<f64>),
    /// The TCP pose in {W}.
    Pose(Frame),
}

/// The order a session's measurements are listed in, as whoever wrote them knows it. Backlash
/// depends on the direction of each joint's last move, which consecutive measurements give only
/// when they are consecutive stops ([`order`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum MeasuringOrder {
    /// Listed as measured (an instrument's log, an importer keeping its file's order, the
    /// simulator).
    Measured,
    /// Permuted after measuring: the list says nothing of the measuring order (`time_s` and
    /// `sequence`, which travel with their measurements, still do).
    Shuffled,
    /// Drawn from measured sessions (a subset, a bootstrap sample, a selection): stops are
    /// missing or repeated, so the move into a measurement is unknown.
    Resampled,
    /// Not said (cells written before the marker existed).
    #[default]
    Unknown,
}

impl MeasuringOrder {
    /// The name cell files use: `measured`, `shuffled`, `resampled` or `unknown`.
    pub fn as_str(self) -> &'static str {
        match self {
            MeasuringOrder::Measured => "measured",
            MeasuringOrder::Shuffled => "shuffled",
            MeasuringOrder::Resampled => "resampled",
            MeasuringOrder::Unknown => "unknown",
        }
    }
}

/// One measurement.
#[derive(Clone, Debug, PartialEq)]
pub struct Measurement {
    /// Joint readings, rad.
    pub q: Vec<f64>,
    /// What the instrument observed at `q`.
    pub observation: Observation,
    /// Robot temperature, °C; `None`: the reference temperature (20 °C) is assumed.
    pub temperature_c: Option<f64>,
    /// Time stamp of the reading, s, any origin (epoch seconds fit); gives the measuring order
    /// where the list does not ([`order`]).
    pub time_s: Option<f64>,
    /// Place in the measuring order of the session's run (measurements at one stop share it).
    pub sequence: Option<u64>,
    /// Per-joint direction of the last motion (−1, 0, +1).
    pub approach: Option<Vec<i8>>,
    /// TriCal indicator readings left after centring (dx, dy, dz), m.
    pub indicators: Option<[f64; 3]>,
    /// The instrument's own standard uncertainty of this reading, 1σ per axis of {W}: position (m)
    /// and, for a full pose, rotation (rad, per axis of the world rotation vector). `None`: the
    /// instrument model's σ applies (`identify::NoiseModel`).
    pub sigma: Option<Sigma>,
}

/// A measurement's own standard uncertainty (what a laser tracker reports with each reading).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sigma {
    /// 1σ of the position along X_W, Y_W, Z_W, m.
    pub position: [f64; 3],
    /// 1σ of the orientation about X_W, Y_W, Z_W, rad (full-pose measurements only).
    pub rotation: Option<[f64; 3]>,
}

/// A set of measurements taken with one tool.
#[derive(Clone, Debug, PartialEq)]
pub struct Session {
    /// Name, unique within the cell: selections and fit records refer to the session by it.
    pub name: String,
    /// What the session is for.
    pub purpose: Purpose,
    /// The instrument that measured it.
    pub instrument: Instrument,
    /// The tool carried: TCP in the flange frame (m, rad), payload mass (kg), centre of mass (m).
    pub tool: Tool,
    /// The TCP in `tool` is only a guess (e.g. a reflector nest never measured): identify it.
    pub identify_tcp: bool,
    /// The physical target (reflector, nest, probe) the session measured, when sessions share
    /// one: sessions naming the same target are fitted with one TCP. Without a name, a session
    /// whose TCP is identified has a TCP of its own, and sessions with the same declared tool
    /// share it.
    pub target: Option<String>,
    /// The measurements, in list (file) order.
    pub measurements: Vec<Measurement>,
    /// Whether `measurements` are listed in measuring order.
    pub order: MeasuringOrder,
}

/// The artefact: three balls on a plate.
#[derive(Clone, Debug, PartialEq)]
pub struct Artefact {
    /// The ball centres in {W}, m, from the measured centre distances.
    pub triangle: BallTriangle,
    /// Ball diameter, m.
    pub ball_diameter: f64,
}

/// One robot cell's data.
#[derive(Clone, Debug, PartialEq)]
pub struct Cell {
    /// The robot's nominal model.
    pub model: RobotModel,
    /// T_0^W as χ (m, rad), when known approximately.
    pub base_guess: Option<[f64; 6]>,
    /// The artefact that defines {W}; `None` when the cell has none (tracker-only cells, whose
    /// {W} is the instrument's frame).
    pub artefact: Option<Artefact>,
    /// The sessions, in file order.
    pub sessions: Vec<Session>,
}

impl Cell {
    /// The session named `name`, if any.
    pub fn session(&self, name: &str) -> Option<&Session> {
        self.sessions.iter().find(|s| s.name == name)
    }

    /// The TCP a fit identified for `session`'s target, the one place that resolves it: by the
    /// session's own name in `by_name`, else by a session of this cell measuring the same named
    /// `target` (a reflector held out of a fit, or whose readings a fold left out, takes the TCP
    /// fitted on the same reflector's other readings). `None`: nothing fitted for that target.
    pub(crate) fn identified_tcp(
        &self,
        session: &Session,
        by_name: impl Fn(&str) -> Option<[f64; 6]>,
    ) -> Option<[f64; 6]> {
        by_name(&session.name).or_else(|| {
            let target = session.target.as_ref()?;
            self.sessions.iter().filter(|s| s.target.as_ref() == Some(target)).find_map(|s| by_name(&s.name))
        })
    }

    /// Sessions of one purpose, in file order.
    pub fn sessions_for(&self, purpose: Purpose) -> impl Iterator<Item = &Session> {
        self.sessions.iter().filter(move |s| s.purpose == purpose)
    }

    /// The observed TCP position of a measurement in {W} (ball centre or measured position).
    pub fn observed_position(&self, m: &Measurement) -> Option<Vector3<f64>> {
        match &m.observation {
            Observation::Ball(k) => self.artefact.as_ref().and_then(|a| a.triangle.ball(*k)),
            Observation::Position(p) => Some(*p),
            Observation::Pose(f) => Some(f.t),
        }
    }
}

pub mod fingerprint;
pub mod order;
pub mod poses;

#[cfg(test)]
pub(crate) mod fixtures;
