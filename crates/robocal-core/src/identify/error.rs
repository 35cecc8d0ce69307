//! Why an identification is refused, and the measurements its refusal names.

use super::problem::ProblemError;
use super::solver::SolveError;
use crate::metrology::registration::RegistrationError;

/// Why an identification is refused (also a DETMAX pool, a study or a cross-validation).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IdentifyError {
    /// The measurements do not form a problem (selection, artefact).
    #[error("{0}")]
    Problem(#[from] ProblemError),
    /// The starting base T_0^W (and the unknown TCPs) could not be registered from the measurements.
    #[error("base estimate: {0}")]
    Registration(#[from] RegistrationError),
    /// An option refused: the option's name, spelled as the identification's own field (`fix`,
    /// `only`, `folds`), the item of a list option that was refused, and why. Each front end
    /// writes the field its way: `--fix` on the command line, `fix[2]` in a request.
    #[error("{}", option_message(*field, *index, reason))]
    Option {
        /// The option's field name; `None` when no single option is to blame.
        field: Option<&'static str>,
        /// The refused item of a list option, 0-based.
        index: Option<usize>,
        /// Why it is refused.
        reason: String,
    },
    /// The start parameter set ([`super::IdentifyOptions::start`]) is for another robot: another
    /// joint count, or another built-in preset.
    #[error(
        "the start parameter set is for robot '{set}' ({set_dof} joints), not for the cell's robot '{cell}' ({cell_dof} joints)"
    )]
    StartRobot {
        /// The start set's robot name.
        set: String,
        /// Its joint count.
        set_dof: usize,
        /// The cell's robot name.
        cell: String,
        /// Its joint count.
        cell_dof: usize,
    },
    /// The measurement rows plus the priors' rows do not exceed the free parameters.
    #[error("{rows} residual rows cannot determine {params} parameters")]
    Underdetermined {
        /// Measurement rows (3 per position, 6 per full pose; the priors' rows not counted).
        rows: usize,
        /// Free parameters.
        params: usize,
    },
    /// A rank-deficient fit: κ of the column-scaled Jacobian at the solution above 10¹⁰, or a zero
    /// singular value of J.
    #[error(
        "rank-deficient fit: these data do not separate {combination}: hold one of them at a known value, or measure poses that separate them"
    )]
    RankDeficient {
        /// The weakest direction: the right singular vector of the scaled Jacobian's smallest singular
        /// value, its coefficients above 0.1 in magnitude, largest first (at most four), written
        /// `+0.71·a2 -0.70·d3`.
        combination: String,
    },
    /// κ of the column-scaled Jacobian at the solution exceeds [`super::IdentifyOptions::kappa_limit`].
    #[error(
        "ill-conditioned fit: κ of the scaled Jacobian = {kappa:.1} exceeds the limit {limit:.0}; the weakest combination is {combination}: hold one of its parameters at a known value (the one known best, e.g. a TCP measured apart; a parameter equivalent to it may then take its place and need holding too), or measure poses that change that combination"
    )]
    IllConditioned {
        /// κ = σ_max/σ_min of the Jacobian with unit-norm columns.
        kappa: f64,
        /// The limit it exceeds.
        limit: f64,
        /// The weakest direction: the right singular vector of the scaled Jacobian's smallest singular
        /// value, its coefficients above 0.1 in magnitude, largest first (at most four), written
        /// `+0.71·a2 -0.70·d3`.
        combination: String,
    },
    /// The solver did not converge.
    #[error("{0}")]
    Solve(#[from] SolveError),
    /// The residual is too large for the noise the instrument predicts: ρ = `rms`/`expected` exceeds
    /// [`super::IdentifyOptions::residual_ratio_limit`].
    #[error(
        "residual RMS {} mm against an expected ~{} mm ({ratio:.0} times, above the limit of {limit:.0}): the model does not describe these data (check the TCPs, the sessions' frames, outliers), or the robot does not repeat to this level (then the residual is spread over every pose, not in a few: raise the residual-ratio limit to fit anyway); largest residuals: {}",
        mm(*rms), mm(*expected), worst_list(worst)
    )]
    Misfit {
        /// RMS over the measurements (outliers left out) of |residual|, m (rotation rows as
        /// rotation_weight·angle).
        rms: f64,
        /// RMS of the noise the instrument predicts for the same measurements, √(mean Σ σ²), m.
        expected: f64,
        /// ρ = `rms`/`expected` (≈ 1 for a right model).
        ratio: f64,
        /// The limit ρ exceeds.
        limit: f64,
        /// The largest residuals in units of their σ, largest first (at most [`super::WORST_REPORTED`]).
        worst: Vec<Worst>,
    },
    /// A session's measured positions spread over a different scale than the nominal robot's TCP
    /// at the same joint readings: a unit mistake, refused before it is fitted.
    #[error(
        "session '{session}': its measured positions spread {} mm around their centroid, where the nominal robot's TCP spreads {} mm at the same joint readings ({ratio:.3} times) and a point up to {} mm from it between {} and {} mm: a calibration changes the robot by millimetres, not by this factor. Check the positions' unit (position_mm: centimetres read as mm give 0.1, inches 0.039, metres 0.001) and that the joints are in degrees (joints_deg)",
        mm(*measured), mm(*nominal), mm(super::scale::MAX_TCP_OFFSET), mm(reach.0), mm(reach.1)
    )]
    PositionScale {
        /// The session.
        session: String,
        /// RMS distance of its measured positions from their centroid, m.
        measured: f64,
        /// The same of the nominal robot's declared TCP (the flange where none is declared), m.
        nominal: f64,
        /// `measured` / `nominal`.
        ratio: f64,
        /// The least and the most RMS spread, m, of a point up to 500 mm
        /// from the declared TCP at the same readings (a reflector or tool the file does not
        /// declare).
        reach: (f64, f64),
    },
    /// A session's joint readings are radians read as degrees: every one, taken as radians, lies
    /// within its joint's limits, the nominal robot hardly moves at them, and read as radians its TCP spreads as the measured
    /// positions do. Refused before it is fitted.
    #[error(
        "session '{session}': its joint readings are in radians, not degrees (joints_deg): taken as radians, every one lies within its joint's limits, and its measured positions spread {} mm around their centroid where the nominal robot's TCP spreads {} mm with the readings taken as degrees but {} mm taken as radians. Convert them to degrees (× 57.2958) and import again",
        mm(*measured), mm(*nominal), mm(*nominal_radians)
    )]
    JointUnit {
        /// The session.
        session: String,
        /// RMS distance of its measured positions from their centroid, m.
        measured: f64,
        /// The same of the nominal robot's declared TCP at the readings as degrees, m.
        nominal: f64,
        /// The same with the readings taken as radians, m.
        nominal_radians: f64,
    },
    /// The joint readings follow another convention than the robot model: the nominal robot
    /// registered on the measured positions misses them by a good part of its size, and a quarter
    /// turn, a sign or a coupling of some joints' readings brings it back to a real robot's few
    /// millimetres ([`super::convention`]). Refused before it is fitted.
    #[error(
        "the joint readings do not follow the robot model's conventions: the nominal robot, registered on the measured positions, misses them by {} mm RMS, and with {} by {} mm. {}: a fit would take the difference into the joint offsets, twists and lengths by quarter turns and signs, and compute the gravity torques, the joint limits and the links' masses at the wrong angles",
        mm(finding.rms), finding.describe(), mm(finding.rms_changed), finding.remedy()
    )]
    JointConvention {
        /// What was found.
        finding: super::convention::ConventionFinding,
    },
    /// Measured positions paired with the joint readings of another stop ([`super::convention`]):
    /// shifted by a line or a few, the nominal robot fits them as a real robot does. Refused
    /// before it is fitted.
    #[error(
        "the measured positions are not paired with their joint readings: the nominal robot, registered on them, misses them by {} mm RMS, but {} by {} mm. Align the files line for line (a header or a line deleted in one file only shifts the rest) and import again",
        mm(finding.rms), finding.describe(), mm(finding.rms_shifted)
    )]
    RowsShifted {
        /// What was found.
        finding: super::convention::PairingFinding,
    },
    /// Positions measured in a mirrored frame ([`super::convention`]): with one axis reversed the
    /// nominal robot fits them as a real robot does. Refused before it is fitted.
    #[error(
        "the measured positions are mirrored against the robot: the nominal robot, registered on them, misses them by {} mm RMS, and with one of their axes reversed by {} mm{}. The instrument's frame is left-handed (an axis exported with the other sign): reverse one axis of the positions, then import or identify again",
        mm(finding.rms), mm(finding.rms_mirrored), finding.alternative()
    )]
    MirroredFrame {
        /// What was found.
        finding: super::convention::MirrorFinding,
    },
    /// Gross outliers the robust loss did not down-weight: measurements whose z (the RMS over their
    /// rows of e/√(σ² + τ²), τ² the spread the model leaves beyond the instrument) exceeds `factor`
    /// times the larger of the median z and 1.
    #[error("{}", outliers_message(outliers, *factor, "exclude", "huber"))]
    Outliers {
        /// The outlier measurements, largest z first.
        outliers: Vec<Worst>,
        /// [`super::IdentifyOptions::outlier_factor`]: the multiple of the median z beyond which a
        /// measurement is an outlier.
        factor: f64,
    },
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
    /// The session's name.
    pub session: String,
    /// 0-based index in the session.
    pub index: usize,
    /// |residual| (position and, for a pose, rotation_weight·angle), m.
    pub residual: f64,
    /// How many times the typical measurement's residual it is, each row against its σ and the
    /// spread the model leaves ([`IdentifyError::Outliers`]).
    pub ratio: f64,
    /// Another target's session whose fitted TCP, at this measurement's own joint readings, the
    /// measured position fits, and by how much (m): the instrument measured that target here (a
    /// tracker that locked onto the neighbouring reflector). `None` when none fits.
    pub fits_other: Option<(String, f64)>,
}

/// The outlier refusal, its two remedies named as the front end spells its options (`exclude`
/// and `huber` in a request or in Python, `--exclude` and `--huber` on the command line).
///
/// The remedy lists every outlier, not only the ones shown: followed, it must not be refused for
/// the rest.
pub fn outliers_message(outliers: &[Worst], factor: f64, exclude: &str, huber: &str) -> String {
    let refs = outliers.iter().map(|w| format!("{}:{}", w.session, w.index)).collect::<Vec<_>>().join(",");
    format!(
        "{}; leave them out ({exclude} {refs}) or fit with the Huber loss ({huber} 2.5)",
        outliers_found(outliers, factor)
    )
}

/// The outliers of a refusal without its remedies, for a caller whose remedies differ (a
/// cross-validation has neither `exclude` nor `huber`).
pub(crate) fn outliers_found(outliers: &[Worst], factor: f64) -> String {
    let more = outliers.len().saturating_sub(SHOWN);
    let more = if more > 0 { format!(" and {more} more") } else { String::new() };
    let others = outliers.iter().filter(|w| w.fits_other.is_some()).count();
    let others = if others > 0 {
        format!(
            ". {others} of them fit another target's TCP at their own joint readings (the ones listed say which): the instrument measured that target there (a tracker that locked onto the neighbouring reflector), so those readings belong in that target's file"
        )
    } else {
        String::new()
    };
    format!(
        "{} outlier measurement(s), each more than {factor:.0} times the typical residual: {}{more}{others}",
        outliers.len(),
        worst_list(outliers)
    )
}

/// Measurements a refusal lists by name.
const SHOWN: usize = 5;

pub(super) fn mm(v: f64) -> String {
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
        .take(SHOWN)
        .map(|w| {
            let other = match &w.fits_other {
                Some((s, d)) => format!("; it fits {s}'s TCP by {} mm", mm(*d)),
                None => String::new(),
            };
            format!("{}[{}] {} mm ({:.1} times the typical{other})", w.session, w.index, mm(w.residual), w.ratio)
        })
        .collect::<Vec<_>>()
        .join(", ")
}
