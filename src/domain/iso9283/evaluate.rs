//! A cell's session evaluated by ISO 9283 with a model: the measured poses (attained) against the
//! model's prediction from each measurement's joint readings (commanded), both in the robot base
//! frame, after registering the base (instrument → robot) and the tool (target → flange) by a fit
//! of only those two on the same session — the "before calibration" reference of `crossval` and
//! `identify --start SET --only base,tool`.
//!
//! - Without a parameter set, the model is the nominal robot: "commanded" is where the controller's
//!   nominal model puts the TCP for the joints it read, which is where the program asked it to go
//!   when the controller uses the nominal model (on the UR10 of series D the recorded joints' nominal
//!   pose and the logged goal differ by ≤ 0.45 mm: the joints are readings, not commands).
//! - With a calibrated set, "commanded" is that set's prediction, so AP is the error the calibrated
//!   model leaves: the **predicted** AP after compensation. Compensating means commanding the
//!   joints q′ = IK_cal(goal), which put the real TCP at goal + (real − cal)(q′) ≈ goal + (real −
//!   cal)(q), since the residual varies slowly over the millidegrees between q and q′. No robot was
//!   re-run with compensated targets: this is a prediction, never a measurement.
//! - RP, RD use only the attained (measured) positions, so both models give the same RP (a rigid
//!   registration changes no distance): compensation does not change a robot's repeatability.
//!
//! The registration is fitted on the same data, so it absorbs any error common to all poses:
//! AP here measures the pose-to-pose variation of the error, not an absolute offset of the cell.

use crate::cell::{Cell, Observation, Session};
use crate::identify::{IdentifyOptions, identify};
use crate::kinematics::{Frame, Param, ParameterSet};
use crate::validate::report::{approach_for, joint_state};

use super::stats::{Visit, VisitSigma};

/// Which pose (and cycle, approach) each measurement of a session is.
#[derive(Clone, Debug, PartialEq)]
pub struct Assignment {
    /// 0-based index of the measurement in its session.
    pub index: usize,
    pub pose: String,
    pub cycle: u32,
    pub approach: Option<String>,
}

/// How the base and tool were registered.
#[derive(Clone, Debug, PartialEq)]
pub struct Registration {
    /// T_0^W: the robot base in the instrument frame, χ (m, rad).
    pub base: [f64; 6],
    /// The session's TCP in the flange frame, χ (m, rad).
    pub tool: [f64; 6],
    /// Column-scaled κ of the registration fit.
    pub kappa_scaled: f64,
    /// RMS of the position residual after the registration, m.
    pub rms_position: f64,
    /// The registration's free parameters, by name (a base or tool parameter the data leave
    /// undetermined is held at its start value and is not among them).
    pub free: Vec<String>,
    /// The parameters the caller asked to hold ([`evaluate_session`]'s `held`).
    pub held: Vec<String>,
}

/// The evaluated visits and how they were registered.
#[derive(Clone, Debug)]
pub struct Evaluated {
    pub visits: Vec<Visit>,
    pub registration: Registration,
    /// What the evaluation did that its figures depend on (a set's hysteresis applied with
    /// directions derived from the measuring order).
    pub notes: Vec<String>,
}

/// Why a session cannot be evaluated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EvaluateError {
    #[error("no session named '{0}' in the cell")]
    UnknownSession(String),
    #[error("pose assignment {row}: measurement {index} is not in session '{session}' ({count} measurements)")]
    UnknownMeasurement { row: usize, index: usize, session: String, count: usize },
    #[error("measurement {index} of session '{session}' is a ball on the artefact, not a position or pose")]
    NotMeasured { session: String, index: usize },
    #[error("the registration of base and tool failed: {0}")]
    Registration(String),
}

/// Register base and tool of `session` with `set` (nominal model when `None`), the base or tool
/// parameters `held` kept at their start values, and pair each assigned measurement with the
/// model's prediction, both in the base frame.
pub fn evaluate_session(
    cell: &Cell,
    session: &str,
    set: Option<&ParameterSet>,
    assignments: &[Assignment],
    kappa_limit: f64,
    held: &[String],
) -> Result<Evaluated, EvaluateError> {
    let s: &Session = cell.session(session).ok_or_else(|| EvaluateError::UnknownSession(session.to_string()))?;
    for (row, a) in assignments.iter().enumerate() {
        if a.index >= s.measurements.len() {
            return Err(EvaluateError::UnknownMeasurement {
                row,
                index: a.index,
                session: session.to_string(),
                count: s.measurements.len(),
            });
        }
        if matches!(s.measurements[a.index].observation, Observation::Ball(_)) {
            return Err(EvaluateError::NotMeasured { session: session.to_string(), index: a.index });
        }
    }
    // A set with hysteresis predicts each reading from the direction of the move into its stop:
    // where the session does not log it, derive it from the measuring order as the registration
    // (an identification) does, or the backlash terms would act nowhere in the figures.
    let (filled, notes) = match set {
        Some(set) => approach_for(set, cell, &[session.to_string()]),
        None => (None, Vec::new()),
    };
    let cell = filled.as_ref().unwrap_or(cell);
    let s: &Session = cell.session(session).ok_or_else(|| EvaluateError::UnknownSession(session.to_string()))?;
    let mut opts = IdentifyOptions {
        start: set.cloned(),
        only: vec!["base".into(), "tool".into()],
        residual_ratio_limit: f64::INFINITY,
        kappa_limit,
        fixed: held.to_vec(),
        ..Default::default()
    };
    opts.selection.sessions = vec![session.to_string()];
    let id = identify(cell, &opts).map_err(|e| EvaluateError::Registration(e.to_string()))?;
    let tool = id.tools.iter().find(|t| t.sessions.iter().any(|n| n == session)).map_or(s.tool.tcp, |t| t.tool.tcp);
    let base = id.set.pose_of(Param::Base);
    let chain = id.set.chain().with_base_tool(base, tool);
    let gravity = id.set.gravity_for(&s.tool);
    let dof = id.set.dof();
    let to_base = Frame::from_xyzabc(&base).inverse();
    let mut sq = 0.0;
    let mut visits = Vec::with_capacity(assignments.len());
    for a in assignments {
        let m = &s.measurements[a.index];
        let state = joint_state(&gravity, &m.q, m.approach.as_deref(), m.temperature_c, dof);
        let predicted = chain.fk(&state);
        let (observed, orientation) = match &m.observation {
            Observation::Pose(f) => (*f, true),
            Observation::Position(p) => (Frame::new(predicted.r, *p), false),
            Observation::Ball(_) => unreachable!("checked above"),
        };
        sq += (observed.t - predicted.t).norm_squared();
        visits.push(Visit {
            pose: a.pose.clone(),
            cycle: a.cycle,
            attained: to_base.compose(&observed),
            commanded: to_base.compose(&predicted),
            orientation,
            approach: a.approach.clone(),
            sigma: m.sigma.map(|s| VisitSigma::from_axes(s.position, s.rotation)),
        });
    }
    let rms_position = if visits.is_empty() { 0.0 } else { (sq / visits.len() as f64).sqrt() };
    Ok(Evaluated {
        visits,
        registration: Registration {
            base,
            tool,
            kappa_scaled: id.quality.kappa_scaled,
            rms_position,
            free: id.free_names.clone(),
            held: held.to_vec(),
        },
        notes,
    })
}
