//! Why a parameter is held instead of identified: a closed set of reasons, each with the figures
//! it rests on (issue 28, item 3). Their text — what the parameter-set files and the wire carry in
//! `status` — is written by the formats ([`crate::formats::identification`]), not here.

/// Why a parameter is held at its start value (or nominal) instead of identified. Each variant
/// names the parameter (`name`, as [`super::Problem::name`] gives it).
#[derive(Clone, Debug, PartialEq)]
pub enum FixedReason {
    /// Named in the options' `fixed` list; held at the start set's value (`at_start`) or nominal.
    ByUser {
        /// The parameter's name.
        name: String,
        /// Held at the start set's value (`true`) or at nominal.
        at_start: bool,
    },
    /// Not named by the options' `only` list (nor a group it names).
    NotInOnly {
        /// The parameter's name.
        name: String,
        /// Held at the start set's value (`true`) or at nominal.
        at_start: bool,
    },
    /// A term the model leaves out.
    NotInModel {
        /// The parameter's name.
        name: String,
        /// The term left out.
        term: ModelTerm,
    },
    /// A TCP component the session declares (measured, e.g. on a CMM).
    DeclaredTcp {
        /// The parameter's name.
        name: String,
    },
    /// A compliance of an axis gravity does not load.
    NoGravityTorque {
        /// The parameter's name.
        name: String,
        /// The axis, 1-based.
        axis: usize,
        /// Because the model carries no mass at all: its links declare none and its tools no
        /// payload (a custom robot without `mass_kg`), not because of the axis's direction.
        massless: bool,
    },
    /// A direction-of-motion term of an axis whose approach direction is not in the data.
    NoApproachDirection {
        /// The parameter's name.
        name: String,
        /// The axis, 1-based.
        axis: usize,
    },
    /// A thermal term without a temperature change in the data.
    NoTemperatureChange {
        /// The parameter's name.
        name: String,
    },
    /// A drift term whose measurements have no common place in one run (no `time_s`, no
    /// `sequence`, and not one session listed as measured), or all the same place.
    NoRunOrder {
        /// The parameter's name.
        name: String,
    },
    /// The last joint's offset when the TCP lies on its axis and orientation is not measured.
    TcpOnLastAxis {
        /// The parameter's name.
        name: String,
        /// The last axis, 1-based.
        axis: usize,
    },
    /// A tool orientation component when orientation is not measured.
    OrientationNotMeasured {
        /// The parameter's name.
        name: String,
    },
    /// A column the measurements do not see at all.
    NoEffect {
        /// The parameter's name.
        name: String,
    },
    /// A combination of parameters kept before it, with the structural reason when there is one.
    Dependent {
        /// The parameter's name.
        name: String,
        /// The names of the parameters kept before it that span its column.
        on: Vec<String>,
        /// Why, when the structure says so.
        structure: Option<Structure>,
    },
    /// Independent, but the data's residual would leave it a standard deviation above `bound`
    /// (metres, or radians when `angle`).
    Undetermined {
        /// The parameter's name.
        name: String,
        /// The least its standard deviation could be, σ/lever: σ the residual's standard deviation
        /// per row, lever the norm of its Jacobian column's component outside the span of the
        /// parameters kept before it (m, or rad when `angle`).
        std: f64,
        /// The limit `std` exceeds: `super::identifiability::UNDETERMINED_LENGTH_M` or
        /// `super::identifiability::UNDETERMINED_ANGLE_RAD`.
        bound: f64,
        /// The parameter is an angle: `std` and `bound` in rad, not m.
        angle: bool,
    },
    /// Free at the start and in the fit, but its standard deviation at the solution (as reported:
    /// the larger of the classic and the cluster-robust) is above `bound` (metres, or radians
    /// when `angle`): one direction with other parameters (`with`) that the data barely see.
    /// Held at its start value and the rest refitted.
    UndeterminedAtSolution {
        /// The parameter's name.
        name: String,
        /// Its standard deviation at the solution (m, or rad when `angle`).
        std: f64,
        /// The limit `std` exceeds, as for [`FixedReason::Undetermined`].
        bound: f64,
        /// The parameter is an angle: `std` and `bound` in rad, not m.
        angle: bool,
        /// The free parameter most correlated with it, and the correlation.
        with: Option<(String, f64)>,
    },
    /// An unknown payload whose mass is not significantly above zero: `mass_kg ± std_kg`, below
    /// `sigmas` σ (or negative, which its statement says apart).
    PayloadInsignificant {
        /// The fitted payload mass, kg.
        mass_kg: f64,
        /// Its standard deviation, kg.
        std_kg: f64,
        /// The multiple of `std_kg` the mass must exceed ([`super::PAYLOAD_SIGNIFICANCE`]).
        sigmas: f64,
    },
    /// An unknown payload whose fit does not settle (the solver's message).
    PayloadUnsettled {
        /// The solver's refusal of the fit with the payload.
        error: String,
    },
    /// A compliance whose difference from its nominal is not significant (rad/(N·m)): `change ± std`,
    /// `t` σ (not finite when undefined), below `sigmas` σ, held at `held_at`.
    ComplianceInsignificant {
        /// The parameter's name.
        name: String,
        /// Fitted value minus nominal value, rad/(N·m).
        change: f64,
        /// Its standard deviation (as reported: the larger of the classic and the cluster-robust),
        /// rad/(N·m).
        std: f64,
        /// |`change`|/`std` (a NaN ratio counts as 0).
        t: f64,
        /// The multiple of `std` the change must exceed ([`super::COMPLIANCE_SIGNIFICANCE`]).
        sigmas: f64,
        /// The start value it is held at, rad/(N·m).
        held_at: f64,
    },
    /// A layout entry no parameter of the identification problem maps to.
    NotInProblem,
}

/// A model term switched off in the options.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelTerm {
    /// Hayati's β of the joints whose axis is (nearly) parallel to the previous one
    /// ([`super::ModelOptions::beta`]).
    Beta,
    /// The joints' linear gear compliance ([`super::ModelOptions::compliance`]).
    Compliance,
}

/// Why a dependent parameter depends on others, when the structure says so.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Structure {
    /// Axes `lo`–`hi` (1-based) are parallel.
    ParallelAxes {
        /// The first of them.
        lo: usize,
        /// The last of them.
        hi: usize,
    },
    /// A joint-1 parameter, redundant with the base pose.
    Base,
    /// Redundant with the parameters of joint `joint` (1-based).
    Joint {
        /// The joint, 1-based.
        joint: usize,
    },
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
            | NoRunOrder { name }
            | TcpOnLastAxis { name, .. }
            | OrientationNotMeasured { name }
            | NoEffect { name }
            | Dependent { name, .. }
            | Undetermined { name, .. }
            | UndeterminedAtSolution { name, .. }
            | ComplianceInsignificant { name, .. } => Some(name),
            PayloadInsignificant { .. } | PayloadUnsettled { .. } | NotInProblem => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::FixedReason;

    /// A payload held at 0 kg says why: a mass within 3 σ of zero is not determined; a mass
    /// below zero by more than 3 σ is no payload, and is not called "below 3 σ" (an IRB 120 twin
    /// whose joint 3 was read 90° off gave −4.245 ± 0.091 kg, stated as "below 3 σ").
    #[test]
    fn a_payload_held_says_whether_it_was_small_or_impossible() {
        let held =
            |mass_kg: f64, std_kg: f64| FixedReason::PayloadInsignificant { mass_kg, std_kg, sigmas: 3.0 }.to_string();
        let small = held(0.064, 0.175);
        assert!(small.contains("(0.064 ± 0.175 kg, below 3 σ)"), "{small}");
        let slightly_negative = held(-0.3, 0.175);
        assert!(slightly_negative.contains("below 3 σ"), "{slightly_negative}");
        let impossible = held(-4.245, 0.091);
        assert!(
            impossible.contains("reads -4.245 ± 0.091 kg, negative by 46.6 σ, which no payload weighs")
                && !impossible.contains("below 3 σ"),
            "{impossible}"
        );
    }
}
