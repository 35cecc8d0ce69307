//! The parameter vector ρ (§4): geometry, Hayati β, joint terms (compliance and, later, other
//! joint-angle effects), base and tool — named with Craig's subscripts as in thesis Table 5.1.
//!
//! Values are SI inside the solver (m, rad, rad/(N·m)); [`Unit`] converts to and from the file
//! units (mm, deg, deg/(N·m)).
//!
//! Extension point: a parameter that perturbs a joint angle, Δθ_j = value · φ(sample), is a
//! [`Param::Joint`] with a [`JointTerm`] that says what φ is. Gravity compliance is the first such
//! term (φ = holding torque τ_j). Cyclic errors, backlash, couplings and correction tables are more
//! [`JointTerm`] variants: each gets its Jacobian column as the joint-angle column times φ, and
//! nothing else in the kinematics changes.

use std::fmt;

use super::model::{RobotModel, Tool};

/// The six components of a pose vector χ = (x, y, z, a, b, c).
pub const POSE_COMPONENTS: [&str; 6] = ["x", "y", "z", "a", "b", "c"];

/// What a joint-angle parameter multiplies.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum JointTerm {
    /// Linear gear compliance: Δθ_j = c_j · τ_j(q), τ the static holding torque (§3.6.2).
    Compliance,
}

/// One scalar parameter of the model. Joint indices are 0-based internally; names are Craig's.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Param {
    /// α_{j} of row j+1: name `alpha{j}`.
    Alpha(usize),
    /// a_{j} of row j+1: name `a{j}`.
    A(usize),
    /// d of joint j: name `d{j+1}`.
    D(usize),
    /// Zero offset of joint j: name `theta{j+1}`.
    Theta(usize),
    /// Hayati β of joint j (β_{j} in Craig's subscripts): name `beta{j}`.
    Beta(usize),
    /// A joint-angle term on joint j; `c{j+1}` for compliance.
    Joint(usize, JointTerm),
    /// Component k (x, y, z, a, b, c) of T_0^W: `base_x` …
    Base(usize),
    /// Component k of T_T^6: `tool_x` …
    Tool(usize),
}

/// File/wire unit of a parameter.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Unit {
    Mm,
    Deg,
    DegPerNm,
}

impl Unit {
    pub fn as_str(self) -> &'static str {
        match self {
            Unit::Mm => "mm",
            Unit::Deg => "deg",
            Unit::DegPerNm => "deg/(N·m)",
        }
    }

    /// Accepts the canonical spelling and the ASCII `deg/(N*m)` / `deg/Nm`.
    pub fn parse(s: &str) -> Option<Unit> {
        match s {
            "mm" => Some(Unit::Mm),
            "deg" => Some(Unit::Deg),
            "deg/(N·m)" | "deg/(N*m)" | "deg/Nm" | "deg/(Nm)" => Some(Unit::DegPerNm),
            _ => None,
        }
    }

    /// Multiply a file value by this to get SI.
    pub fn to_si(self) -> f64 {
        match self {
            Unit::Mm => 1e-3,
            Unit::Deg | Unit::DegPerNm => std::f64::consts::PI / 180.0,
        }
    }
}

impl Param {
    pub fn unit(self) -> Unit {
        match self {
            Param::A(_) | Param::D(_) => Unit::Mm,
            Param::Alpha(_) | Param::Theta(_) | Param::Beta(_) => Unit::Deg,
            Param::Joint(_, JointTerm::Compliance) => Unit::DegPerNm,
            Param::Base(k) | Param::Tool(k) => {
                if k < 3 {
                    Unit::Mm
                } else {
                    Unit::Deg
                }
            }
        }
    }

    /// Parse a Craig-style name (`alpha0`, `d4`, `theta2`, `beta2`, `c3`, `base_x`, `tool_c`).
    /// Whether the robot has such a parameter is checked by the layout, not here.
    pub fn parse(name: &str) -> Option<Param> {
        if let Some(k) = name.strip_prefix("base_") {
            return POSE_COMPONENTS.iter().position(|c| *c == k).map(Param::Base);
        }
        if let Some(k) = name.strip_prefix("tool_") {
            return POSE_COMPONENTS.iter().position(|c| *c == k).map(Param::Tool);
        }
        let split = name.find(|c: char| c.is_ascii_digit())?;
        let (stem, digits) = name.split_at(split);
        if digits.len() > 1 && digits.starts_with('0') {
            return None;
        }
        let i: usize = digits.parse().ok()?;
        match stem {
            "alpha" => Some(Param::Alpha(i)),
            "a" => Some(Param::A(i)),
            "beta" => Some(Param::Beta(i)),
            "d" if i >= 1 => Some(Param::D(i - 1)),
            "theta" if i >= 1 => Some(Param::Theta(i - 1)),
            "c" if i >= 1 => Some(Param::Joint(i - 1, JointTerm::Compliance)),
            _ => None,
        }
    }
}

impl fmt::Display for Param {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Param::Alpha(j) => write!(f, "alpha{j}"),
            Param::A(j) => write!(f, "a{j}"),
            Param::D(j) => write!(f, "d{}", j + 1),
            Param::Theta(j) => write!(f, "theta{}", j + 1),
            Param::Beta(j) => write!(f, "beta{j}"),
            Param::Joint(j, JointTerm::Compliance) => write!(f, "c{}", j + 1),
            Param::Base(k) => write!(f, "base_{}", POSE_COMPONENTS[k]),
            Param::Tool(k) => write!(f, "tool_{}", POSE_COMPONENTS[k]),
        }
    }
}

/// The ordered list of parameters of one robot model: the columns of its identification Jacobian.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ParamLayout {
    params: Vec<Param>,
    dof: usize,
}

impl ParamLayout {
    /// The full §4 vector in the thesis's order (eq. 4.10): α, a, d, θ offsets, β, compliances,
    /// base, tool. 43 parameters for the IRB 120.
    pub fn full(model: &RobotModel) -> Self {
        let n = model.dof();
        let mut params = Vec::with_capacity(5 * n + 13);
        params.extend((0..n).map(Param::Alpha));
        params.extend((0..n).map(Param::A));
        params.extend((0..n).map(Param::D));
        params.extend((0..n).map(Param::Theta));
        params.extend((0..n).filter(|&j| model.links[j].beta.is_some()).map(Param::Beta));
        params.extend((0..n).map(|j| Param::Joint(j, JointTerm::Compliance)));
        params.extend((0..6).map(Param::Base));
        params.extend((0..6).map(Param::Tool));
        Self { params, dof: n }
    }

    pub fn len(&self) -> usize {
        self.params.len()
    }

    pub fn is_empty(&self) -> bool {
        self.params.is_empty()
    }

    pub fn dof(&self) -> usize {
        self.dof
    }

    pub fn params(&self) -> &[Param] {
        &self.params
    }

    pub fn index_of(&self, p: Param) -> Option<usize> {
        self.params.iter().position(|&x| x == p)
    }

    /// Look a name up; `None` when this robot has no such parameter.
    pub fn find(&self, name: &str) -> Option<usize> {
        Param::parse(name).and_then(|p| self.index_of(p))
    }

    /// The nominal value of every parameter: the model's table, zero compliance, the given base
    /// pose and the tool's declared TCP (SI units).
    pub fn nominal_values(&self, model: &RobotModel, tool: &Tool, base: &[f64; 6]) -> Vec<f64> {
        self.params
            .iter()
            .map(|p| match *p {
                Param::Alpha(j) => model.links[j].alpha,
                Param::A(j) => model.links[j].a,
                Param::D(j) => model.links[j].d,
                Param::Theta(j) => model.links[j].theta,
                Param::Beta(j) => model.links[j].beta.unwrap_or(0.0),
                Param::Joint(_, JointTerm::Compliance) => 0.0,
                Param::Base(k) => base[k],
                Param::Tool(k) => tool.tcp[k],
            })
            .collect()
    }

    /// Append a further parameter block (e.g. extra joint terms for the diagnosis).
    /// Returns the index of each added parameter; parameters already present are not duplicated.
    pub fn extend(&mut self, extra: &[Param]) -> Vec<usize> {
        extra
            .iter()
            .map(|&p| match self.index_of(p) {
                Some(i) => i,
                None => {
                    self.params.push(p);
                    self.params.len() - 1
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::model::{irb120, ur10};

    #[test]
    fn irb120_has_the_43_parameters_of_section_4() {
        let l = ParamLayout::full(&irb120());
        assert_eq!(l.len(), 43);
        let names: Vec<String> = l.params().iter().map(|p| p.to_string()).collect();
        for n in [
            "alpha0", "alpha5", "a0", "a5", "d1", "d6", "theta1", "theta6", "beta2", "c1", "c6", "base_x", "base_c",
            "tool_x", "tool_c",
        ] {
            assert!(names.iter().any(|x| x == n), "{n} missing");
        }
        assert_eq!(ParamLayout::full(&ur10()).len(), 44);
    }

    #[test]
    fn names_round_trip() {
        for model in [irb120(), ur10()] {
            let l = ParamLayout::full(&model);
            for (i, p) in l.params().iter().enumerate() {
                assert_eq!(Param::parse(&p.to_string()), Some(*p));
                assert_eq!(l.find(&p.to_string()), Some(i));
            }
        }
        for bad in ["d0", "theta0", "c0", "alpha", "alpha01", "gamma1", "base_q", "tool_", "a1x"] {
            assert_eq!(Param::parse(bad), None, "{bad}");
        }
        assert_eq!(ParamLayout::full(&irb120()).find("beta3"), None);
        assert_eq!(ParamLayout::full(&irb120()).find("a7"), None);
    }

    #[test]
    fn units() {
        assert_eq!(Param::A(2).unit(), Unit::Mm);
        assert_eq!(Param::Base(3).unit(), Unit::Deg);
        assert_eq!(Param::Tool(1).unit(), Unit::Mm);
        assert_eq!(Param::Joint(1, JointTerm::Compliance).unit(), Unit::DegPerNm);
        assert_eq!(Unit::parse("deg/(N*m)"), Some(Unit::DegPerNm));
        assert_eq!(Unit::parse("m"), None);
    }
}
