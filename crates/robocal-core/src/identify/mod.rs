//! Identification (thesis §4.2, §6; digest §4, §6): the parameters of a better model from a
//! cell's measurements — least squares on faer with Levenberg–Marquardt damping, automatic
//! identifiability, conditioning and observability, honest uncertainties, DETMAX pose selection.

pub mod base;
pub mod convention;
pub mod crossval;
pub mod detmax;
pub(crate) mod identifiability;
pub(crate) mod noise;
pub mod observability;
pub mod problem;
pub(crate) mod quality;
pub mod run;
pub(crate) mod solver;
pub mod study;

mod conditional;
mod error;
mod fixed;
mod hold;
#[allow(clippy::module_inception)] // the fit itself: `identify::identify`, as issue 28 names the parts
mod identify;
mod options;
mod pool;
mod prepare;
mod scale;

pub use conditional::Conditional;
pub(crate) use error::outliers_found;
pub use error::{IdentifyError, Worst, outliers_message};
pub use fixed::{FixedReason, ModelTerm, Structure};
pub use hold::{COMPLIANCE_SIGNIFICANCE, PAYLOAD_SIGNIFICANCE};
pub use identifiability::Status;
pub use identify::{
    Identification, PayloadAtFlange, PayloadCentreOfMass, ToolResult, WORST_REPORTED, free_in_some_only, identify,
    payload_at_flange, payload_centre_of_mass,
};
pub use noise::NoiseModel;
pub use options::{
    Anchor, DEFAULT_MAP_SMOOTHING, IdentifyOptions, ModelOptions, OUTLIER_FACTOR, RESIDUAL_RATIO_LIMIT, drift_terms,
    map_knots, term_spec,
};
pub use pool::{DetmaxPool, select_detmax};
pub use prepare::{Prepared, map_priors, prepare, row_sigmas, table_priors, weight_by_instrument};
pub use problem::{GlobalParam, MeasurementSelection, Prior, Problem, ProblemError, tool_blocks};
pub use quality::Quality;
pub use scale::check_readings;
pub use solver::{Fit, SolveError, SolverOptions};

impl std::fmt::Display for Status {
    /// `identified`, or the reason the parameter is fixed: the text the files and the wire carry.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Status::Identified => f.write_str("identified"),
            Status::Fixed(reason) => reason.fmt(f),
        }
    }
}
