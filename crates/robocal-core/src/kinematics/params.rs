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
pub(crate) const POSE_COMPONENTS: [&str; 6] = ["x", "y", "z", "a", "b", "c"];

/// What a joint-angle parameter multiplies: Δθ_j = value · φ(sample).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum JointTerm {
    /// Linear gear compliance: φ = τ_j(q), the static holding torque (§3.6.2).
    Compliance,
    /// Cubic (hardening/softening) compliance: φ = τ_j³.
    ComplianceCubic,
    /// Cyclic error of harmonic h (eccentricity h = 1, 2; gear mesh e.g. 17):
    /// φ = sin(h·q_j), or cos(h·q_j) when `cosine`.
    Cyclic {
        /// Harmonic h, cycles per revolution (1–255).
        harmonic: u8,
        /// cos instead of sin.
        cosine: bool,
    },
    /// Backlash: φ = the logged approach direction of joint j (−1, 0, +1).
    Backlash,
    /// Coupling from another joint: φ = q_from (e.g. axis 5 → 6 on a wrist with coupled gears).
    Coupling {
        /// The driving joint, 0-based.
        from: usize,
    },
    /// A periodic error at a frequency that is not a whole harmonic (transmission and encoder
    /// errors of gear stages whose ratio is not an integer): `quarters`/4 cycles per revolution,
    /// φ = sin(f·q_j), or cos when `cosine`. Whole frequencies are [`JointTerm::Cyclic`]; build
    /// either with [`JointTerm::cyclic`].
    Periodic {
        /// Frequency f in quarter cycles per revolution (f = `quarters`/4).
        quarters: u16,
        /// cos instead of sin.
        cosine: bool,
    },
    /// One knot of a per-joint correction table (a lookup table interpolated linearly): knot k sits
    /// at q_j = k·step, and φ is its hat function — 1 at the knot, falling linearly to 0 at the
    /// neighbouring knots. The table's first and last knots hold their value beyond the table
    /// (constant extrapolation), which the chain works out from the knots present (see
    /// [`MapEdge`]). A smooth, regularised table captures non-periodic transmission errors that
    /// a few harmonics miss.
    Map {
        /// Knot spacing of the table, deg.
        step_deg: u8,
        /// Knot index k (may be negative): the knot sits at q_j = k·`step_deg`.
        knot: i16,
    },
}

/// Where a [`JointTerm::Map`] knot sits in its table: the first and last knots extend their value
/// beyond the table.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct MapEdge {
    /// Lowest knot of its table: holds its value below the table.
    pub first: bool,
    /// Highest knot of its table: holds its value above the table.
    pub last: bool,
}

impl JointTerm {
    /// The cyclic term of frequency `quarters`/4 cycles per revolution: a whole harmonic (1–255)
    /// is [`JointTerm::Cyclic`], any other [`JointTerm::Periodic`]. `None` for frequency zero.
    pub fn cyclic(quarters: u16, cosine: bool) -> Option<JointTerm> {
        match quarters {
            0 => None,
            q if q % 4 == 0 && q / 4 <= 255 => Some(JointTerm::Cyclic { harmonic: (q / 4) as u8, cosine }),
            q => Some(JointTerm::Periodic { quarters: q, cosine }),
        }
    }

    /// Cycles per revolution of a cyclic or periodic term.
    pub fn frequency(self) -> Option<f64> {
        match self {
            JointTerm::Cyclic { harmonic, .. } => Some(harmonic as f64),
            JointTerm::Periodic { quarters, .. } => Some(quarters as f64 / 4.0),
            _ => None,
        }
    }
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
    /// Thermal expansion coefficient of the link lengths (every a and d scales by
    /// 1 + α·(T − 20 °C)): `thermal_alpha`.
    Thermal,
    /// Error of the declared payload mass, kg: the true payload of every tool is its declared
    /// mass plus this, at the tool's declared centre of mass. It acts through the compliances
    /// (the holding torques change): `tool_mass`.
    ToolMass,
    /// Component k (x, y, z in the flange frame) of the payload's first moment beyond the one
    /// its declared mass and centre of mass give, kg·m: the true payload's mass times its centre
    /// of mass is the declared one's plus this. Like [`Param::ToolMass`] it acts through the
    /// compliances; with it, the payload's centre of mass is identified beside its mass:
    /// `tool_moment_x` …
    ToolMoment(usize),
    /// Drift of the readings along the measuring run, m: component (axis a = x, y, z of {W},
    /// order k = 0, 1, 2) of a translation of {W} by Σ_k d_{a,k}·P̃_{k+1}(u), P̃ the Legendre
    /// polynomial of the measurement's place in its run, centred over the run
    /// ([`crate::identify::run`]). A nuisance of the identification's run: it averages to zero
    /// over the run, and a state with no place in a run (a compensation) has none:
    /// `drift_x_p1` … `drift_z_p3`.
    Drift(usize, usize),
}

/// Reference temperature of the nominal link lengths (ISO 1), °C.
pub(crate) const REFERENCE_TEMPERATURE_C: f64 = 20.0;

/// File/wire unit of a parameter.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Unit {
    /// Millimetres: link lengths and base/tool translations.
    Mm,
    /// Degrees: angles, and the joint-angle terms other than compliance and coupling.
    Deg,
    /// deg/(N·m), for linear compliance.
    DegPerNm,
    /// deg/(N·m)³, for cubic compliance.
    DegPerNm3,
    /// A plain ratio (rad per rad).
    Ratio,
    /// Parts per million per kelvin (µm/(m·K)).
    PpmPerK,
    /// Kilograms, for the payload mass error.
    Kg,
    /// Kilogram-millimetres, for the payload's first moment.
    KgMm,
}

impl Unit {
    /// The canonical spelling, as written to files.
    pub fn as_str(self) -> &'static str {
        match self {
            Unit::Mm => "mm",
            Unit::Deg => "deg",
            Unit::DegPerNm => "deg/(N·m)",
            Unit::DegPerNm3 => "deg/(N·m)³",
            Unit::Ratio => "rad/rad",
            Unit::PpmPerK => "ppm/K",
            Unit::Kg => "kg",
            Unit::KgMm => "kg·mm",
        }
    }

    /// Accepts the canonical spelling and the ASCII `deg/(N*m)` / `deg/Nm`.
    pub fn parse(s: &str) -> Option<Unit> {
        match s {
            "mm" => Some(Unit::Mm),
            "deg" => Some(Unit::Deg),
            "deg/(N·m)" | "deg/(N*m)" | "deg/Nm" | "deg/(Nm)" => Some(Unit::DegPerNm),
            "deg/(N·m)³" | "deg/(N*m)^3" | "deg/Nm3" => Some(Unit::DegPerNm3),
            "rad/rad" | "deg/deg" | "1" => Some(Unit::Ratio),
            "ppm/K" | "um/(m*K)" | "µm/(m·K)" => Some(Unit::PpmPerK),
            "kg" => Some(Unit::Kg),
            "kg·mm" | "kg*mm" | "kg mm" => Some(Unit::KgMm),
            _ => None,
        }
    }

    /// Multiply a file value by this to get SI.
    pub fn to_si(self) -> f64 {
        match self {
            Unit::Mm | Unit::KgMm => 1e-3,
            Unit::Deg | Unit::DegPerNm | Unit::DegPerNm3 => std::f64::consts::PI / 180.0,
            Unit::Ratio | Unit::Kg => 1.0,
            Unit::PpmPerK => 1e-6,
        }
    }
}

impl Param {
    /// The file unit of this parameter (SI inside the solver, see [`Unit::to_si`]).
    pub fn unit(self) -> Unit {
        match self {
            Param::A(_) | Param::D(_) => Unit::Mm,
            Param::Alpha(_) | Param::Theta(_) | Param::Beta(_) => Unit::Deg,
            Param::Joint(_, JointTerm::Compliance) => Unit::DegPerNm,
            Param::Joint(_, JointTerm::ComplianceCubic) => Unit::DegPerNm3,
            Param::Joint(
                _,
                JointTerm::Cyclic { .. } | JointTerm::Periodic { .. } | JointTerm::Backlash | JointTerm::Map { .. },
            ) => Unit::Deg,
            Param::Joint(_, JointTerm::Coupling { .. }) => Unit::Ratio,
            Param::Thermal => Unit::PpmPerK,
            Param::ToolMass => Unit::Kg,
            Param::ToolMoment(_) => Unit::KgMm,
            Param::Drift(..) => Unit::Mm,
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
        if name == "tool_mass" {
            return Some(Param::ToolMass);
        }
        if let Some(k) = name.strip_prefix("tool_moment_") {
            return POSE_COMPONENTS[..3].iter().position(|c| *c == k).map(Param::ToolMoment);
        }
        if let Some(k) = name.strip_prefix("tool_") {
            return POSE_COMPONENTS.iter().position(|c| *c == k).map(Param::Tool);
        }
        if name == "thermal_alpha" {
            return Some(Param::Thermal);
        }
        if let Some(rest) = name.strip_prefix("drift_") {
            let (axis, order) = rest.split_once("_p")?;
            let axis = POSE_COMPONENTS[..3].iter().position(|c| *c == axis)?;
            let k = index1(order)?;
            return (k < crate::identify::run::DRIFT_ORDERS).then_some(Param::Drift(axis, k));
        }
        if let Some(rest) = name.strip_prefix("cyc") {
            // cyc{j}_h{h}_sin | cyc{j}_h{h}_cos (whole harmonic) | cyc{j}_f{f}_sin (f in quarters)
            let mut parts = rest.split('_');
            let j = index1(parts.next()?)?;
            let freq = parts.next()?;
            let cosine = match parts.next()? {
                "sin" => false,
                "cos" => true,
                _ => return None,
            };
            if parts.next().is_some() {
                return None;
            }
            let term = if let Some(h) = freq.strip_prefix('h') {
                let h: u8 = parse_index(h)?.try_into().ok()?;
                if h == 0 {
                    return None;
                }
                JointTerm::Cyclic { harmonic: h, cosine }
            } else {
                let quarters = parse_quarters(freq.strip_prefix('f')?)?;
                match JointTerm::cyclic(quarters, cosine)? {
                    // A whole harmonic is spelled with h.
                    JointTerm::Cyclic { .. } => return None,
                    t => t,
                }
            };
            return Some(Param::Joint(j, term));
        }
        if let Some(rest) = name.strip_prefix("map") {
            // map{j}_s{step}_k{knot}
            let mut parts = rest.split('_');
            let j = index1(parts.next()?)?;
            let step: u8 = parse_index(parts.next()?.strip_prefix('s')?)?.try_into().ok()?;
            let k = parts.next()?.strip_prefix('k')?;
            let (neg, digits) = match k.strip_prefix('-') {
                Some(d) => (true, d),
                None => (false, k),
            };
            let mag: i16 = parse_index(digits)?.try_into().ok()?;
            if parts.next().is_some() || step == 0 || (neg && mag == 0) {
                return None;
            }
            return Some(Param::Joint(j, JointTerm::Map { step_deg: step, knot: if neg { -mag } else { mag } }));
        }
        if let Some(rest) = name.strip_prefix("backlash") {
            return Some(Param::Joint(index1(rest)?, JointTerm::Backlash));
        }
        if let Some(rest) = name.strip_prefix("coupling") {
            // coupling{from}_{to}: Δθ_to = ε·q_from
            let (from, to) = rest.split_once('_')?;
            let (from, to) = (index1(from)?, index1(to)?);
            if from == to {
                return None;
            }
            return Some(Param::Joint(to, JointTerm::Coupling { from }));
        }
        if let Some(rest) = name.strip_prefix('c')
            && let Some(j) = rest.strip_suffix("_cubic")
        {
            return Some(Param::Joint(index1(j)?, JointTerm::ComplianceCubic));
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

/// A decimal index without a leading zero.
fn parse_index(s: &str) -> Option<usize> {
    if s.is_empty() || (s.len() > 1 && s.starts_with('0')) || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    s.parse().ok()
}

/// A frequency in cycles per revolution written as a decimal with at most two decimals that is a
/// whole number of quarters (`7.25`, `0.5`, `12`) → quarters.
fn parse_quarters(s: &str) -> Option<u16> {
    let (whole, frac) = s.split_once('.').unwrap_or((s, ""));
    let w = parse_index(whole)?;
    let q = match frac {
        "" => 0,
        "25" => 1,
        "5" => 2,
        "75" => 3,
        _ => return None,
    };
    u16::try_from(4 * w + q).ok()
}

/// A frequency in quarters as the shortest decimal (`29` → "7.25").
fn format_quarters(q: u16) -> String {
    let frac = ["", ".25", ".5", ".75"][(q % 4) as usize];
    format!("{}{frac}", q / 4)
}

/// A 1-based joint number in a name → 0-based index.
fn index1(s: &str) -> Option<usize> {
    parse_index(s).filter(|&i| i >= 1).map(|i| i - 1)
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
            Param::Joint(j, JointTerm::ComplianceCubic) => write!(f, "c{}_cubic", j + 1),
            Param::Joint(j, JointTerm::Cyclic { harmonic, cosine }) => {
                write!(f, "cyc{}_h{harmonic}_{}", j + 1, if cosine { "cos" } else { "sin" })
            }
            Param::Joint(j, JointTerm::Backlash) => write!(f, "backlash{}", j + 1),
            Param::Joint(j, JointTerm::Coupling { from }) => write!(f, "coupling{}_{}", from + 1, j + 1),
            Param::Joint(j, JointTerm::Periodic { quarters, cosine }) => {
                write!(f, "cyc{}_f{}_{}", j + 1, format_quarters(quarters), if cosine { "cos" } else { "sin" })
            }
            Param::Joint(j, JointTerm::Map { step_deg, knot }) => write!(f, "map{}_s{step_deg}_k{knot}", j + 1),
            Param::Thermal => f.write_str("thermal_alpha"),
            Param::ToolMass => f.write_str("tool_mass"),
            Param::ToolMoment(k) => write!(f, "tool_moment_{}", POSE_COMPONENTS[k]),
            Param::Drift(a, k) => write!(f, "drift_{}_p{}", POSE_COMPONENTS[a], k + 1),
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
    /// Bit j set: joint j+1's axis is nominally parallel to joint j's (α_j a multiple of π), so
    /// Hayati's β can be given to row j (`beta{j}`).
    parallel: u16,
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
        let parallel = (1..n)
            .filter(|&j| {
                let a = model.links[j].alpha.rem_euclid(std::f64::consts::PI);
                a.min(std::f64::consts::PI - a) < 1e-9
            })
            .fold(0u16, |m, j| m | (1 << j));
        Self { params, dof: n, parallel }
    }

    /// Number of parameters: the Jacobian's columns.
    pub fn len(&self) -> usize {
        self.params.len()
    }

    /// Whether the layout has no parameters.
    pub fn is_empty(&self) -> bool {
        self.params.is_empty()
    }

    /// Number of joints of the robot.
    pub fn dof(&self) -> usize {
        self.dof
    }

    /// Rows j whose joint axis is nominally parallel to the previous joint's: where a Hayati β
    /// belongs (`beta{j}`).
    pub(crate) fn parallel_rows(&self) -> Vec<usize> {
        (0..self.dof).filter(|&j| self.parallel & (1 << j) != 0).collect()
    }

    /// The parameters in column order.
    pub fn params(&self) -> &[Param] {
        &self.params
    }

    /// Column of `p`; `None` when the layout does not have it.
    pub fn index_of(&self, p: Param) -> Option<usize> {
        self.params.iter().position(|&x| x == p)
    }

    /// Whether a parameter outside the base layout (an effect term) fits this robot.
    pub fn admits(&self, p: Param) -> bool {
        match p {
            Param::Joint(j, JointTerm::Coupling { from }) => j < self.dof && from < self.dof,
            Param::Joint(j, _) => j < self.dof,
            Param::Thermal | Param::ToolMass => true,
            Param::ToolMoment(k) => k < 3,
            Param::Drift(a, k) => a < 3 && k < crate::identify::run::DRIFT_ORDERS,
            // Hayati's β can be given to any row whose joint axis is nominally parallel to the
            // previous one (where plain DH is not proportional, §3.4).
            Param::Beta(j) => self.index_of(p).is_some() || (j < self.dof && self.parallel & (1 << j) != 0),
            _ => self.index_of(p).is_some(),
        }
    }

    /// Look a name up; `None` when this robot has no such parameter.
    pub fn find(&self, name: &str) -> Option<usize> {
        Param::parse(name).and_then(|p| self.index_of(p))
    }

    /// The nominal value of every parameter: the model's table, zero compliance, the given base
    /// pose and the tool's declared TCP (SI units).
    pub(crate) fn nominal_values(&self, model: &RobotModel, tool: &Tool, base: &[f64; 6]) -> Vec<f64> {
        self.params
            .iter()
            .map(|p| match *p {
                Param::Alpha(j) => model.links[j].alpha,
                Param::A(j) => model.links[j].a,
                Param::D(j) => model.links[j].d,
                Param::Theta(j) => model.links[j].theta,
                Param::Beta(j) => model.links[j].beta.unwrap_or(0.0),
                Param::Joint(..) | Param::Thermal | Param::ToolMass | Param::ToolMoment(_) | Param::Drift(..) => 0.0,
                Param::Base(k) => base[k],
                Param::Tool(k) => tool.tcp[k],
            })
            .collect()
    }

    /// Append a further parameter block (e.g. extra joint terms for the diagnosis).
    /// Returns the index of each added parameter; parameters already present are not duplicated.
    /// Panics on a parameter this robot cannot have (a joint beyond its dof).
    pub fn extend(&mut self, extra: &[Param]) -> Vec<usize> {
        for p in extra {
            assert!(self.admits(*p), "{p} is not a parameter of a {}-joint robot", self.dof);
        }
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
        let mut ext = ParamLayout::full(&irb120());
        let extra = [
            Param::Joint(1, JointTerm::ComplianceCubic),
            Param::Joint(1, JointTerm::Cyclic { harmonic: 17, cosine: true }),
            Param::Joint(2, JointTerm::Cyclic { harmonic: 1, cosine: false }),
            Param::Joint(1, JointTerm::Backlash),
            Param::Joint(5, JointTerm::Coupling { from: 4 }),
            Param::Thermal,
            Param::Joint(2, JointTerm::Periodic { quarters: 29, cosine: true }),
            Param::Joint(1, JointTerm::Map { step_deg: 3, knot: -12 }),
            Param::Joint(1, JointTerm::Map { step_deg: 3, knot: 0 }),
            Param::ToolMass,
            Param::Drift(2, 0),
            Param::Drift(0, 2),
        ];
        ext.extend(&extra);
        let names: Vec<String> = extra.iter().map(|p| p.to_string()).collect();
        assert_eq!(
            names,
            [
                "c2_cubic",
                "cyc2_h17_cos",
                "cyc3_h1_sin",
                "backlash2",
                "coupling5_6",
                "thermal_alpha",
                "cyc3_f7.25_cos",
                "map2_s3_k-12",
                "map2_s3_k0",
                "tool_mass",
                "drift_z_p1",
                "drift_x_p3",
            ]
        );
        assert_eq!(JointTerm::cyclic(8, false), Some(JointTerm::Cyclic { harmonic: 2, cosine: false }));
        assert_eq!(JointTerm::cyclic(2, true), Some(JointTerm::Periodic { quarters: 2, cosine: true }));
        assert_eq!(JointTerm::cyclic(0, true), None);
        assert_eq!(
            Param::parse("cyc1_f0.5_sin"),
            Some(Param::Joint(0, JointTerm::Periodic { quarters: 2, cosine: false }))
        );
        for p in extra {
            assert_eq!(Param::parse(&p.to_string()), Some(p));
            assert!(ext.find(&p.to_string()).is_some());
        }
        for bad in [
            "d0",
            "theta0",
            "c0",
            "alpha",
            "alpha01",
            "gamma1",
            "base_q",
            "tool_",
            "a1x",
            "cyc2_h0_sin",
            "cyc2_h1",
            "cyc0_h1_sin",
            "coupling5_5",
            "coupling5",
            "backlash0",
            "c_cubic",
            "thermal",
            "cyc2_f8_sin",
            "cyc2_f7.3_sin",
            "cyc2_f0_sin",
            "cyc2_f7.25",
            "map2_s0_k1",
            "map2_s3_k-0",
            "map2_s3_k01",
            "map2_s3",
            "map0_s3_k1",
            "tool_mass2",
            "drift_x_p0",
            "drift_x_p4",
            "drift_a_p1",
            "drift_x",
            "drift_x_p01",
        ] {
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
