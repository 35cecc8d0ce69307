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
    /// An option refused: the option's name, spelled as the identification's own field (`fix`,
    /// `only`, `folds`), the item of a list option that was refused, and why. Each front end
    /// writes the field its way: `--fix` on the command line, `fix[2]` in a request.
    #[error("{}", option_message(*field, *index, reason))]
    Option { field: Option<&'static str>, index: Option<usize>, reason: String },
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
    #[error("{}", outliers_message(outliers, *factor, "exclude", "huber"))]
    Outliers { outliers: Vec<Worst>, factor: f64 },
}

impl IdentifyError {
    /// An option refused for a reason that no single option carries.
    pub fn option(reason: impl Into<String>) -> Self {
        IdentifyError::Option { field: None, index: None, reason: reason.into() }
    }

    /// An option refused: which one, and why.
    pub fn field(field: &'static str, reason: impl Into<String>) -> Self {
        IdentifyError::Option { field: Some(field), index: None, reason: reason.into() }
    }

    /// An item of a list option refused: which option, which item (0-based), and why.
    pub fn item(field: &'static str, index: usize, reason: impl Into<String>) -> Self {
        IdentifyError::Option { field: Some(field), index: Some(index), reason: reason.into() }
    }

    /// The refused option's field path as a request writes it (`fix[2]`, `folds`), if one is named.
    pub fn field_path(&self) -> Option<String> {
        match self {
            IdentifyError::Option { field: Some(f), index, .. } => {
                Some(index.map_or_else(|| f.to_string(), |i| format!("{f}[{i}]")))
            }
            _ => None,
        }
    }
}

fn option_message(field: Option<&str>, index: Option<usize>, reason: &str) -> String {
    match (field, index) {
        (Some(f), Some(i)) => format!("{f}[{i}]: {reason}"),
        (Some(f), None) => format!("{f}: {reason}"),
        (None, _) => reason.to_string(),
    }
}

impl IdentifyError {}

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

/// The outlier refusal, its two remedies named as the front end spells its options (`exclude`
/// and `huber` in a request or in Python, `--exclude` and `--huber` on the command line).
pub fn outliers_message(outliers: &[Worst], factor: f64, exclude: &str, huber: &str) -> String {
    let refs = outliers.iter().take(5).map(|w| format!("{}:{}", w.session, w.index)).collect::<Vec<_>>().join(",");
    format!(
        "{} outlier measurement(s), each more than {factor:.0} times the typical residual: {}; leave them out ({exclude} {refs}) or fit with the Huber loss ({huber} 2.5)",
        outliers.len(),
        worst_list(outliers)
    )
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
