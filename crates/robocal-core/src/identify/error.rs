//! Why an identification is refused, and the measurements its refusal names.

use super::problem::ProblemError;
use super::solver::SolveError;
use crate::metrology::registration::RegistrationError;

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IdentifyError {
    #[error("{0}")]
    Problem(#[from] ProblemError),
    #[error("base estimate: {0}")]
    Registration(#[from] RegistrationError),
    #[error("{0}")]
    Option(String),
    #[error(
        "the start parameter set is for robot '{set}' ({set_dof} joints), not for the cell's robot '{cell}' ({cell_dof} joints)"
    )]
    StartRobot { set: String, set_dof: usize, cell: String, cell_dof: usize },
    #[error("{rows} residual rows cannot determine {params} parameters")]
    Underdetermined { rows: usize, params: usize },
    #[error(
        "rank-deficient fit: these data do not separate {combination}: hold one of them at a known value, or measure poses that separate them"
    )]
    RankDeficient { combination: String },
    #[error(
        "ill-conditioned fit: κ of the scaled Jacobian = {kappa:.1} exceeds the limit {limit:.0}; the weakest combination is {combination}: hold one of its parameters at a known value (the one known best, e.g. a TCP measured apart; a parameter equivalent to it may then take its place and need holding too), or measure poses that change that combination"
    )]
    IllConditioned { kappa: f64, limit: f64, combination: String },
    #[error("{0}")]
    Solve(#[from] SolveError),
    #[error(
        "residual RMS {} mm against an expected ~{} mm ({ratio:.0} times, above the limit of {limit:.0}): the model does not describe these data (check the TCPs, the sessions' frames, outliers); largest residuals: {}",
        mm(*rms), mm(*expected), worst_list(worst)
    )]
    Misfit { rms: f64, expected: f64, ratio: f64, limit: f64, worst: Vec<Worst> },
    #[error(
        "{} outlier measurement(s), each more than {factor:.0} times the typical residual: {}; leave them out (identify --exclude {}, or `exclude` in a request) or fit with the Huber loss (--huber 2.5)",
        outliers.len(), worst_list(outliers), outliers.iter().take(5).map(|w| format!("{}:{}", w.session, w.index)).collect::<Vec<_>>().join(",")
    )]
    Outliers { outliers: Vec<Worst>, factor: f64 },
}

/// A measurement with a large residual.
#[derive(Clone, Debug, PartialEq)]
pub struct Worst {
    pub session: String,
    /// 0-based index in the session.
    pub index: usize,
    /// |residual| (position and, for a pose, rotation_weight·angle), m.
    pub residual: f64,
    /// How many times the typical measurement's residual it is, each row against its σ and the
    /// spread the model leaves ([`IdentifyError::Outliers`]).
    pub ratio: f64,
}

fn mm(v: f64) -> String {
    let v = v / crate::units::MM;
    if v >= 10.0 {
        format!("{v:.1}")
    } else if v >= 0.1 {
        format!("{v:.3}")
    } else {
        format!("{v:.4}")
    }
}

fn worst_list(w: &[Worst]) -> String {
    w.iter()
        .take(5)
        .map(|w| format!("{}[{}] {} mm ({:.1} times the typical)", w.session, w.index, mm(w.residual), w.ratio))
        .collect::<Vec<_>>()
        .join(", ")
}
