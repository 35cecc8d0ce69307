//! Validation of a parameter set on a cell's sessions (thesis §5.4, digest §9, Tables 5.2–5.4):
//! the error of every selected measurement for the calibrated model and for the nominal model,
//! their summary statistics, per-axis statistics in {W}, Shapiro–Wilk tests and the regressions
//! of the error on the distance to the base and to the calibration zone.
//!
//! Rules, per measurement (SI units throughout):
//! - error = reference position − model position, in {W};
//! - the reference is the measured position (ball centre for TriCal, the reading for a tracker)
//!   or, in a virtual cell, the true robot's position at the recorded joints (`RunTruth`);
//! - the model position uses the session's tool: the parameter set's own tool parameters
//!   (`tool_x` … `tool_c`, possibly identified) when the session's tool is the set's tool (same
//!   TCP, mass and centre of mass), otherwise the session's declared TCP;
//! - joint state: readings, gravity torques of the set's robot carrying the session's tool, the
//!   measurement's approach directions and temperature (20 °C when not logged);
//! - the nominal model is the same with the set's nominal values (nominal base, declared tool);
//! - distances (the regressions' abscissae) are those of the reference position, to the
//!   calibrated base origin (T_0^W translation) and to the artefact's ball centroid; the nominal
//!   model's regressions use the same abscissae.
//!
//! Any session of the cell can be validated on: scoring a set on its own identification data is
//! legitimate (the identification residual), but it is not a validation. The report lists each
//! session's purpose so a front end can flag it, and — given what the set was fitted on
//! ([`FitData`], from its document) — which sessions and measurements the set has already seen:
//! a validation is **held out** ([`ValidationReport::held_out`]) only when none of its sessions
//! was fitted on and at least one is a validation session. A set accepted from a diagnosis that
//! pooled the validation sessions is fitted on them, so validating it on them again is in-sample.

use std::collections::BTreeMap;

use nalgebra::Vector3;

use super::normality::{ShapiroWilk, shapiro_wilk};
use super::regression::{LinearFit, linear_fit};
use super::stats::ErrorStats;
use crate::cell::{Cell, Observation, Purpose, Session};
use crate::kinematics::frame::rotation_angle;
use crate::kinematics::{Chain, GravityModel, JointState, JointTerm, MAX_JOINTS, Param, ParameterSet};
use crate::sim::measure::RunTruth;

/// What the model positions are scored against.
#[derive(Clone, Copy, Debug)]
pub enum Reference<'a> {
    /// The cell's observations (ball centres, tracker readings): what a real cell offers.
    Measured,
    /// The true robot's positions at the recorded joints (virtual cell): the best any model can
    /// do, free of instrument noise and robot repeatability.
    Truth(&'a RunTruth),
}

/// Statistics of the signed error along one axis of {W}, m.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisStats {
    /// Mean signed error.
    pub mean: f64,
    /// Sample standard deviation (n − 1).
    pub std: f64,
    /// Smallest (most negative) signed error.
    pub min: f64,
    /// Largest signed error.
    pub max: f64,
    /// `None` for fewer than 3 or more than 5000 values, or all equal.
    pub shapiro: Option<ShapiroWilk>,
}

/// One model's errors over the selected measurements.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelErrors {
    /// |error|, m.
    pub position: ErrorStats,
    /// Orientation error, rad: over the measurements that observed a full pose (n tells how
    /// many); `None` when none did or the reference is the truth.
    pub orientation: Option<ErrorStats>,
    /// x, y, z of {W}.
    pub per_axis: [AxisStats; 3],
    /// Shapiro–Wilk on |error|.
    pub shapiro: Option<ShapiroWilk>,
    /// |error| against the reference position's distance to the base origin.
    pub vs_base_distance: Option<LinearFit>,
    /// |error| against the distance to the calibration-zone centre (the artefact's ball
    /// centroid); `None` without an artefact.
    pub vs_zone_distance: Option<LinearFit>,
}

/// One measurement's errors.
#[derive(Clone, Debug, PartialEq)]
pub struct Residual {
    /// The measurement's session, by name.
    pub session: String,
    /// Index of the measurement within its session (0-based).
    pub index: usize,
    /// Reference − calibrated model, {W}, m.
    pub error: Vector3<f64>,
    /// Reference − nominal model, {W}, m.
    pub nominal_error: Vector3<f64>,
    /// Angle of R_ref·R_modelᵀ, rad (pose observations against the measured reference only).
    pub orientation_error: Option<f64>,
    /// The same for the nominal model, rad.
    pub nominal_orientation_error: Option<f64>,
    /// The reference position, {W}, m.
    pub position: Vector3<f64>,
    /// Distance of the reference position to the base origin, m.
    pub distance_to_base: f64,
    /// Distance of the reference position to the ball centroid, m.
    pub distance_to_zone: Option<f64>,
}

/// The joint ranges and the box of {W} a set of measurements covers (SI): the region where a
/// validation has shown the model to hold.
#[derive(Clone, Debug, PartialEq)]
pub struct Region {
    /// Per joint, [min, max], rad.
    pub joints: Vec<[f64; 2]>,
    /// The positions' box: lower and upper corners, m.
    pub lo: Vector3<f64>,
    /// Upper corner of the box, {W}, m (`lo` is the lower).
    pub hi: Vector3<f64>,
    /// Number of (joints, position) points, one per measurement.
    pub n: usize,
}

impl Region {
    /// The region of (joints, position) pairs; `None` without any.
    pub fn of<'a>(points: impl IntoIterator<Item = (&'a [f64], Vector3<f64>)>) -> Option<Region> {
        let mut r: Option<Region> = None;
        for (q, p) in points {
            let r = r.get_or_insert_with(|| Region {
                joints: vec![[f64::INFINITY, f64::NEG_INFINITY]; q.len()],
                lo: Vector3::repeat(f64::INFINITY),
                hi: Vector3::repeat(f64::NEG_INFINITY),
                n: 0,
            });
            for (range, &v) in r.joints.iter_mut().zip(q) {
                range[0] = range[0].min(v);
                range[1] = range[1].max(v);
            }
            r.lo = r.lo.inf(&p);
            r.hi = r.hi.sup(&p);
            r.n += 1;
        }
        r
    }
}

/// What a parameter set was fitted on, as its document records it: the sessions and, when
/// recorded, each session's measurement indices (a DETMAX subset fits only some).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FitData {
    /// Whether the set records its fit data at all (a table typed in or imported from elsewhere
    /// does not: nothing is known to be in-sample, which the report says).
    pub recorded: bool,
    /// The sessions fitted on, by name.
    pub sessions: Vec<String>,
    /// Per fitted session, the indices of the measurements the fit used; a session missing here
    /// counts as fitted on whole.
    pub measurements: BTreeMap<String, Vec<usize>>,
    /// Per fitted session, the TCP (χ: m, rad) the fit identified for its tool, where it did. A
    /// plate of reflectors has one TCP per reflector while the set's chain carries only the first:
    /// each session is predicted with its own.
    pub tcps: BTreeMap<String, [f64; 6]>,
    /// Per fitted session, the fingerprints of the readings fitted ([`crate::cell::fingerprint`]),
    /// where the set records them.
    pub fingerprints: BTreeMap<String, std::collections::BTreeSet<String>>,
    /// Sessions of the validated cell that bear a fitted session's name but hold none of the
    /// readings it was fitted on: not in-sample ([`FitData::match_readings`]). Their TCP is still
    /// the fitted session's.
    pub other_data: Vec<String>,
}

impl FitData {
    /// Nothing recorded.
    pub fn unknown() -> FitData {
        FitData::default()
    }

    /// Whether the set was fitted on (some of) this session's measurements: a fitted session's
    /// name, unless the cell's session of that name holds other data ([`FitData::other_data`]).
    pub(crate) fn has_session(&self, name: &str) -> bool {
        self.sessions.iter().any(|s| s == name) && !self.other_data.iter().any(|s| s == name)
    }

    /// The fitted sessions that are the validated cell's sessions of the same name (all of them
    /// but [`FitData::other_data`]).
    pub fn fitted_here(&self) -> Vec<String> {
        self.sessions.iter().filter(|s| self.has_session(s)).cloned().collect()
    }

    /// The TCP the fit identified for `session`'s tool ([`Cell::identified_tcp`]).
    pub(crate) fn tcp_of(&self, session: &Session, cell: &Cell) -> Option<[f64; 6]> {
        cell.identified_tcp(session, |name| self.tcps.get(name).copied())
    }

    /// Whether the fit used measurement `index` of session `name`.
    pub(crate) fn has_measurement(&self, name: &str, index: usize) -> bool {
        self.has_session(name) && self.measurements.get(name).is_none_or(|ix| ix.binary_search(&index).is_ok())
    }

    /// Match the fitted readings in `cell` by their content, where the set records fingerprints:
    /// each fitted session's measurements become those of the cell's session of that name whose
    /// readings the fit used (whatever their indices — the service's stored numbering, a job's
    /// without the excluded ones, another run's), and a session none of whose readings was fitted
    /// — a calibration run and a validation run imported apart both name their sessions
    /// `reflector-1`, … — is not in-sample at all: its name goes to [`FitData::other_data`]. It
    /// keeps the fitted session's TCP (the same reflector, by name). Where no fingerprint is
    /// recorded the name and the indices decide, as before.
    pub fn match_readings(&mut self, cell: &Cell) {
        for (name, fitted) in &self.fingerprints {
            let Some(session) = cell.session(name) else { continue };
            let found: Vec<usize> = session
                .measurements
                .iter()
                .enumerate()
                .filter(|(_, m)| crate::cell::fingerprint::of_measurement(cell, m).is_some_and(|f| fitted.contains(&f)))
                .map(|(i, _)| i)
                .collect();
            if found.is_empty() {
                self.other_data.push(name.clone());
            }
            self.measurements.insert(name.clone(), found);
        }
    }
}

/// The rule of a held-out validation, in one place (the service's compensation gate states the
/// same in SQL, `db::records::latest_held_out_validation`): none of the validated sessions was
/// fitted on, and at least one of them is a validation session.
pub fn is_held_out(sessions: &[String], purposes: &[Purpose], fit_sessions: &[String]) -> bool {
    !sessions.iter().any(|s| fit_sessions.contains(s)) && purposes.contains(&Purpose::Validation)
}

/// The validation of one parameter set on selected sessions.
#[derive(Clone, Debug, PartialEq)]
pub struct ValidationReport {
    /// The selected sessions, in the caller's order.
    pub sessions: Vec<String>,
    /// The purpose of each selected session (an identification session scores the fit, not the
    /// model's validity).
    pub purposes: Vec<Purpose>,
    /// Scored against the truth (`true`) or against the measurements.
    pub against_truth: bool,
    /// The calibrated model's errors (the set's parameters) over all selected measurements.
    pub calibrated: ModelErrors,
    /// The nominal model's errors (the set's nominal values) over the same measurements.
    pub nominal: ModelErrors,
    /// The same per selected session that holds measurements, in selection order (several
    /// reflectors, or identification and validation sessions, scored apart).
    pub per_session: Vec<SessionErrors>,
    /// One per measurement, sessions in selection order, measurements in file order.
    pub residuals: Vec<Residual>,
    /// The region the held-out sessions' measurements cover (validation sessions the set was not
    /// fitted on): where this validation shows the model to hold. `None` without such a session.
    pub region: Option<Region>,
    /// What the set was fitted on, when the caller said ([`validate_fitted`]); `None`: not said.
    pub fit: Option<FitData>,
    /// The artefact's ball centres in {W}, m (the calibration zone), when the cell has one.
    pub balls: Option<[Vector3<f64>; 3]>,
    /// What the validation derived rather than read, in sentences: the approach directions of
    /// sessions that do not log them, for a set with hysteresis terms.
    pub notes: Vec<String>,
}

/// One session's share of a validation: both models' errors over its measurements.
#[derive(Clone, Debug, PartialEq)]
pub struct SessionErrors {
    /// The session, by name.
    pub session: String,
    /// Its purpose.
    pub purpose: Purpose,
    /// The calibrated model's errors over the session's measurements.
    pub calibrated: ModelErrors,
    /// The nominal model's errors over the same measurements.
    pub nominal: ModelErrors,
}

/// Why a validation cannot be made. Measurement indices are 0-based within their session.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ValidateError {
    /// The selection is empty.
    #[error("no session selected for validation")]
    NoSession,
    /// The cell has no session of this name.
    #[error("unknown session '{0}'")]
    UnknownSession(String),
    /// This session is named twice in the selection.
    #[error("session '{0}' is selected twice")]
    DuplicateSession(String),
    /// The selected sessions hold no measurement.
    #[error("the selected sessions hold no measurement")]
    NoMeasurement,
    /// A session whose TCP is to be identified (declared without one) for which the set, which
    /// records the TCPs it fitted, has none: its readings would be predicted at the flange.
    #[error(
        "session '{session}' declares no TCP (it is to be identified) and the parameter set fitted none for it (it fitted {known}): its readings would be predicted at the flange, not where they were measured. Score it with its TCP registered (`crossval --transfer {session}` refits base and tools for each model; or `identify --start SET --sessions {session} --only base,tool`, then validate that), or give it the `target` of the fitted session that measured the same point"
    )]
    TcpUnknown {
        /// The session, by name.
        session: String,
        /// The sessions the set fitted a TCP for, comma-separated.
        known: String,
    },
    /// The set is for another robot: a different number of joints, or a different preset.
    #[error(
        "the parameter set is for robot '{set}' ({set_dof} joints), the cell's robot is '{cell}' ({cell_dof} joints)"
    )]
    RobotMismatch {
        /// The set's robot, by name.
        set: String,
        /// The set's number of joints.
        set_dof: usize,
        /// The cell's robot, by name.
        cell: String,
        /// The cell's number of joints.
        cell_dof: usize,
    },
    /// A measurement's joint readings do not match the robot's number of joints.
    #[error("measurement {index} of session '{session}' has {got} joint values, the robot has {dof}")]
    JointCount {
        /// The session, by name.
        session: String,
        /// The measurement.
        index: usize,
        /// Joint readings it has.
        got: usize,
        /// Joints the robot has.
        dof: usize,
    },
    /// A measurement observes a ball the cell's artefact does not have, or the cell has none.
    #[error("measurement {index} of session '{session}' observes ball {ball}, which the cell's artefact does not have")]
    NoBall {
        /// The session, by name.
        session: String,
        /// The measurement.
        index: usize,
        /// The ball, 1-based.
        ball: usize,
    },
    /// Against the truth: the run's truth has no session of this name.
    #[error("the truth has no session '{0}'")]
    TruthMissing(String),
    /// Against the truth: the truth and the cell differ in a session's number of measurements.
    #[error("the truth of session '{session}' has {truth} measurements, the cell has {cell}")]
    TruthCount {
        /// The session, by name.
        session: String,
        /// Measurements in the truth.
        truth: usize,
        /// Measurements in the cell.
        cell: usize,
    },
    /// A measurement's error, or a length the statistics need (|error|, distance to the base), is
    /// not finite; when a sum over the errors overflows, the measurement of largest |error|.
    #[error("measurement {index} of session '{session}' gives a non-finite error")]
    NotFinite {
        /// The session, by name.
        session: String,
        /// The measurement.
        index: usize,
    },
}

/// The names of the cell's validation sessions, in file order: the default selection.
pub fn validation_sessions(cell: &Cell) -> Vec<String> {
    cell.sessions_for(Purpose::Validation).map(|s| s.name.clone()).collect()
}

/// Validate `set` on the named sessions of `cell` against `reference`, not saying what the set was
/// fitted on (every validation session counts as held out).
pub fn validate(
    set: &ParameterSet,
    cell: &Cell,
    sessions: &[String],
    reference: Reference<'_>,
) -> Result<ValidationReport, ValidateError> {
    validate_fitted(set, cell, sessions, reference, None)
}

/// [`validate`], knowing what the set was fitted on: the report marks the sessions it has seen,
/// and its validated region leaves them out.
pub fn validate_fitted(
    set: &ParameterSet,
    cell: &Cell,
    sessions: &[String],
    reference: Reference<'_>,
    fit: Option<&FitData>,
) -> Result<ValidationReport, ValidateError> {
    if sessions.is_empty() {
        return Err(ValidateError::NoSession);
    }
    let dof = set.dof();
    let presets_differ = matches!((set.model.preset, cell.model.preset), (Some(a), Some(b)) if a != b);
    if dof != cell.model.dof() || presets_differ {
        return Err(ValidateError::RobotMismatch {
            set: set.model.name.clone(),
            set_dof: dof,
            cell: cell.model.name.clone(),
            cell_dof: cell.model.dof(),
        });
    }
    let (filled, notes) = approach_for(set, cell, sessions);
    let cell = filled.as_ref().unwrap_or(cell);
    let mut selected: Vec<&Session> = Vec::with_capacity(sessions.len());
    for name in sessions {
        let s = cell.session(name).ok_or_else(|| ValidateError::UnknownSession(name.clone()))?;
        if selected.iter().any(|t| t.name == *name) {
            return Err(ValidateError::DuplicateSession(name.clone()));
        }
        selected.push(s);
    }

    let base_origin = set.chain().base().t;
    let zone = cell.artefact.as_ref().map(|a| a.triangle.centroid());
    let mut residuals = Vec::new();
    let mut held_out: Vec<(&[f64], Vector3<f64>)> = Vec::new();
    for session in &selected {
        let truth = match reference {
            Reference::Measured => None,
            Reference::Truth(run) => {
                let (_, t) = run
                    .sessions
                    .iter()
                    .find(|(n, _)| *n == session.name)
                    .ok_or_else(|| ValidateError::TruthMissing(session.name.clone()))?;
                if t.len() != session.measurements.len() {
                    return Err(ValidateError::TruthCount {
                        session: session.name.clone(),
                        truth: t.len(),
                        cell: session.measurements.len(),
                    });
                }
                Some(t)
            }
        };
        let (cal_chain, nom_chain) = session_chains(set, session);
        let fitted_tcp = fit.and_then(|f| f.tcp_of(session, cell));
        // A reflector imported without a TCP, in a run the set was not fitted on under that name
        // (a second run merged as `day2-1`, …): the declared TCP is the flange's origin, and
        // figures taken there are 80–110 mm of plate, not the calibration's error.
        if let Some(f) = fit.filter(|f| f.recorded && !f.tcps.is_empty())
            && fitted_tcp.is_none()
            && session.identify_tcp
            && session.tool.tcp[..3] == [0.0; 3]
        {
            return Err(ValidateError::TcpUnknown {
                session: session.name.clone(),
                known: f.tcps.keys().cloned().collect::<Vec<_>>().join(", "),
            });
        }
        let cal_chain = match fitted_tcp {
            // Not for the chain's own TCP (the first tool's): the document's mm and degrees convert back
            // to within an ulp, and its figures stay bit for bit.
            Some(tcp) if tcp.iter().zip(&cal_chain.tool_pose()).any(|(a, b)| (a - b).abs() > 1e-9) => {
                cal_chain.with_base_tool(cal_chain.base_pose(), tcp)
            }
            _ => cal_chain,
        };
        let gravity = set.gravity_for(&session.tool);
        for (index, m) in session.measurements.iter().enumerate() {
            if m.q.len() != dof {
                return Err(ValidateError::JointCount { session: session.name.clone(), index, got: m.q.len(), dof });
            }
            let state = joint_state(&gravity, &m.q, m.approach.as_deref(), m.temperature_c, dof);
            let cal = cal_chain.fk(&state);
            let nom = nom_chain.fk(&state);
            let (reference_position, reference_rotation) = match truth {
                Some(t) => (t[index].model_position, None),
                None => match &m.observation {
                    Observation::Pose(f) => (f.t, Some(f.r)),
                    Observation::Position(p) => (*p, None),
                    Observation::Ball(k) => {
                        let c = cell.artefact.as_ref().and_then(|a| a.triangle.ball(*k));
                        (
                            c.ok_or_else(|| ValidateError::NoBall { session: session.name.clone(), index, ball: *k })?,
                            None,
                        )
                    }
                },
            };
            let error = reference_position - cal.t;
            let nominal_error = reference_position - nom.t;
            // Finite components can still overflow a norm (a reading at 1e160 mm): both the
            // vectors and their lengths must be numbers the statistics can hold.
            let lengths = [error.norm(), nominal_error.norm(), (reference_position - base_origin).norm()];
            if !(error.iter().chain(nominal_error.iter()).chain(&lengths).all(|v| v.is_finite())) {
                return Err(ValidateError::NotFinite { session: session.name.clone(), index });
            }
            if session.purpose == Purpose::Validation && !fit.is_some_and(|f| f.has_session(&session.name)) {
                held_out.push((&m.q[..], reference_position));
            }
            residuals.push(Residual {
                session: session.name.clone(),
                index,
                error,
                nominal_error,
                orientation_error: reference_rotation.map(|r| rotation_angle(&(r * cal.r.transpose()))),
                nominal_orientation_error: reference_rotation.map(|r| rotation_angle(&(r * nom.r.transpose()))),
                position: reference_position,
                distance_to_base: (reference_position - base_origin).norm(),
                distance_to_zone: zone.map(|z| (reference_position - z).norm()),
            });
        }
    }
    if residuals.is_empty() {
        return Err(ValidateError::NoMeasurement);
    }
    let calibrated = |r: &Residual| (r.error, r.orientation_error);
    let nominal = |r: &Residual| (r.nominal_error, r.nominal_orientation_error);
    let mut per_session = Vec::new();
    for s in &selected {
        let mine: Vec<Residual> = residuals.iter().filter(|r| r.session == s.name).cloned().collect();
        if !mine.is_empty() {
            per_session.push(SessionErrors {
                session: s.name.clone(),
                purpose: s.purpose,
                calibrated: model_errors(&mine, calibrated)?,
                nominal: model_errors(&mine, nominal)?,
            });
        }
    }
    Ok(ValidationReport {
        sessions: selected.iter().map(|s| s.name.clone()).collect(),
        purposes: selected.iter().map(|s| s.purpose).collect(),
        against_truth: matches!(reference, Reference::Truth(_)),
        calibrated: model_errors(&residuals, calibrated)?,
        nominal: model_errors(&residuals, nominal)?,
        per_session,
        residuals,
        region: Region::of(held_out),
        balls: cell.artefact.as_ref().map(|a| *a.triangle.centres()),
        fit: fit.cloned(),
        notes,
    })
}

/// The cell with the approach directions of the validated sessions derived from their measuring
/// order (as the identification derives them, [`crate::cell::order::fill_approach`]), and what was
/// done, when the set has hysteresis (a non-zero backlash term) and some validated reading does
/// not log its direction; `(None, [])` otherwise. A set with hysteresis predicts each reading from
/// the direction of the move into its stop: without it the backlash terms act nowhere, and the
/// figures would be of another model than the set (a twin's second run read the named hysteresis
/// as costing 0.002 mm where, applied, it gains 0.013 mm).
pub fn approach_for(set: &ParameterSet, cell: &Cell, sessions: &[String]) -> (Option<Cell>, Vec<String>) {
    let backlash = set
        .layout
        .params()
        .iter()
        .zip(&set.values)
        .any(|(p, v)| matches!(p, Param::Joint(_, JointTerm::Backlash)) && *v != 0.0);
    let missing = cell
        .sessions
        .iter()
        .filter(|s| sessions.contains(&s.name))
        .any(|s| s.measurements.iter().any(|m| m.approach.is_none()));
    if !(backlash && missing) {
        return (None, Vec::new());
    }
    let mut filled = cell.clone();
    let approach = crate::cell::order::fill_approach(&mut filled, sessions);
    let mut notes = approach.notes();
    let refused: Vec<&str> = approach.refused().map(|(n, _)| n).collect();
    if !refused.is_empty() {
        notes.push(format!(
            "the set's backlash terms act nowhere on {}: its figures there are of the set without its hysteresis",
            refused.join(", ")
        ));
    }
    (Some(filled), notes)
}

impl ValidationReport {
    /// Whether this validation is held out ([`is_held_out`]): with no fit data given, whether it
    /// holds a validation session.
    pub fn held_out(&self) -> bool {
        let fitted = self.fit.as_ref().map(FitData::fitted_here).unwrap_or_default();
        is_held_out(&self.sessions, &self.purposes, &fitted)
    }

    /// The validated sessions the set was fitted on, in selection order.
    pub fn in_sample_sessions(&self) -> Vec<String> {
        let Some(f) = &self.fit else { return Vec::new() };
        self.sessions.iter().filter(|s| f.has_session(s)).cloned().collect()
    }

    /// How many of the validated measurements of `session` the fit used.
    pub fn fitted_measurements(&self, session: &str) -> usize {
        let Some(f) = &self.fit else { return 0 };
        self.residuals.iter().filter(|r| r.session == session && f.has_measurement(session, r.index)).count()
    }
}

/// The logged state: readings, gravity torques, approach directions, temperature.
pub fn joint_state(
    gravity: &GravityModel,
    q: &[f64],
    approach: Option<&[i8]>,
    temperature_c: Option<f64>,
    dof: usize,
) -> JointState {
    let tau = gravity.torques(q);
    let mut s = JointState::with_torques(q, &tau[..dof]);
    if let Some(a) = approach {
        for (k, v) in a.iter().take(dof.min(MAX_JOINTS)).enumerate() {
            s.approach[k] = f64::from(*v);
        }
    }
    if let Some(t) = temperature_c {
        s.temperature_c = t;
    }
    s
}

/// Statistics of one model's errors; `pick` selects its error vector and orientation error.
fn model_errors(
    residuals: &[Residual],
    pick: impl Fn(&Residual) -> (Vector3<f64>, Option<f64>),
) -> Result<ModelErrors, ValidateError> {
    let errors: Vec<Vector3<f64>> = residuals.iter().map(|r| pick(r).0).collect();
    let norms: Vec<f64> = errors.iter().map(|e| e.norm()).collect();
    let angles: Vec<f64> = residuals.iter().filter_map(|r| pick(r).1).collect();
    let base: Vec<f64> = residuals.iter().map(|r| r.distance_to_base).collect();
    let zone: Option<Vec<f64>> = residuals.iter().map(|r| r.distance_to_zone).collect();
    // The measurement whose error the statistics cannot hold (validate() refuses non-finite
    // errors first, so this names one only if a sum overflows), for the error.
    let culprit = || {
        residuals.iter().zip(&norms).max_by(|a, b| a.1.total_cmp(b.1)).map_or(ValidateError::NoMeasurement, |(r, _)| {
            ValidateError::NotFinite { session: r.session.clone(), index: r.index }
        })
    };
    let stats = |v: &[f64]| ErrorStats::of(v).filter(|s| s.mean.is_finite() && s.rms.is_finite() && s.std.is_finite());
    let axis = |k: usize| -> Result<AxisStats, ValidateError> {
        let v: Vec<f64> = errors.iter().map(|e| e[k]).collect();
        let s = stats(&v).ok_or_else(culprit)?;
        Ok(AxisStats {
            mean: s.mean,
            std: s.std,
            min: v.iter().copied().fold(f64::INFINITY, f64::min),
            max: s.max,
            shapiro: shapiro_wilk(&v).ok(),
        })
    };
    Ok(ModelErrors {
        position: stats(&norms).ok_or_else(culprit)?,
        orientation: ErrorStats::of(&angles),
        per_axis: [axis(0)?, axis(1)?, axis(2)?],
        shapiro: shapiro_wilk(&norms).ok(),
        vs_base_distance: linear_fit(&base, &norms),
        vs_zone_distance: zone.and_then(|z| linear_fit(&z, &norms)),
    })
}

/// The calibrated and nominal chains for a session's measurements: the set's own tool parameters
/// when the session's tool is the set's tool, otherwise the session's declared TCP on the set's
/// (calibrated or nominal) base.
pub fn session_chains(set: &ParameterSet, session: &Session) -> (Chain, Chain) {
    let (calibrated, nominal) = (set.chain(), set.nominal_chain());
    if session.tool == set.tool {
        (calibrated, nominal)
    } else {
        (
            calibrated.with_base_tool(calibrated.base_pose(), session.tool.tcp),
            nominal.with_base_tool(nominal.base_pose(), session.tool.tcp),
        )
    }
}
