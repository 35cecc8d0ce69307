//! Why a parameter is held instead of identified: a closed set of reasons, each with the figures
//! it rests on (issue 28, item 3). Their text — what the parameter-set files and the wire carry in
//! `status` — is written by the formats ([`crate::formats::identification`]), not here.

/// Why a parameter is held at its start value (or nominal) instead of identified. Each variant
/// names the parameter (`name`, as [`super::Problem::name`] gives it).
#[derive(Clone, Debug, PartialEq)]
pub enum FixedReason {
    /// Named in the options' `fixed` list; held at the start set's value (`at_start`) or nominal.
    ByUser { name: String, at_start: bool },
    /// Not named by the options' `only` list (nor a group it names).
    NotInOnly { name: String, at_start: bool },
    /// A term the model leaves out.
    NotInModel { name: String, term: ModelTerm },
    /// A TCP component the session declares (measured, e.g. on a CMM).
    DeclaredTcp { name: String },
    /// A compliance of an axis gravity does not load.
    NoGravityTorque { name: String, axis: usize },
    /// A direction-of-motion term of an axis whose approach direction is not in the data.
    NoApproachDirection { name: String, axis: usize },
    /// A thermal term without a temperature change in the data.
    NoTemperatureChange { name: String },
    /// The last joint's offset when the TCP lies on its axis and orientation is not measured.
    TcpOnLastAxis { name: String, axis: usize },
    /// A tool orientation component when orientation is not measured.
    OrientationNotMeasured { name: String },
    /// A column the measurements do not see at all.
    NoEffect { name: String },
    /// A combination of parameters kept before it, with the structural reason when there is one.
    Dependent { name: String, on: Vec<String>, structure: Option<Structure> },
    /// Independent, but the data's residual would leave it a standard deviation above `bound`
    /// (metres, or radians when `angle`).
    Undetermined { name: String, std: f64, bound: f64, angle: bool },
    /// An unknown payload whose mass is not significant: `mass_kg ± std_kg`, below `sigmas` σ.
    PayloadInsignificant { mass_kg: f64, std_kg: f64, sigmas: f64 },
    /// An unknown payload whose fit does not settle (the solver's message).
    PayloadUnsettled { error: String },
    /// A compliance whose change from its start is not significant (rad/(N·m)): `change ± std`,
    /// `t` σ (not finite when undefined), below `sigmas` σ, held at `held_at`.
    ComplianceInsignificant { name: String, change: f64, std: f64, t: f64, sigmas: f64, held_at: f64 },
    /// A layout entry no parameter of the identification problem maps to.
    NotInProblem,
}

/// A model term switched off in the options.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelTerm {
    Beta,
    Compliance,
}

/// Why a dependent parameter depends on others, when the structure says so.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Structure {
    /// Axes `lo`–`hi` (1-based) are parallel.
    ParallelAxes { lo: usize, hi: usize },
    /// A joint-1 parameter, redundant with the base pose.
    Base,
    /// Redundant with the parameters of joint `joint` (1-based).
    Joint { joint: usize },
}

impl FixedReason {
    /// The parameter it holds, when it names one.
    pub fn parameter(&self) -> Option<&str> {
        use FixedReason::*;
        match self {
            ByUser { name, .. }
            | NotInOnly { name, .. }
            | NotInModel { name, .. }
            | DeclaredTcp { name }
            | NoGravityTorque { name, .. }
            | NoApproachDirection { name, .. }
            | NoTemperatureChange { name }
            | TcpOnLastAxis { name, .. }
            | OrientationNotMeasured { name }
            | NoEffect { name }
            | Dependent { name, .. }
            | Undetermined { name, .. }
            | ComplianceInsignificant { name, .. } => Some(name),
            PayloadInsignificant { .. } | PayloadUnsettled { .. } | NotInProblem => None,
        }
    }
}
