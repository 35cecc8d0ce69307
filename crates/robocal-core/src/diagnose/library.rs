//! The library of candidate effects: each a model extension with its own parameters, whose
//! Jacobian columns at the current solution are what the screening tests.
//!
//! | kind | parameters | needs |
//! |---|---|---|
//! | `hayati_beta` | β of a row whose axis is nominally parallel to the previous one | a parallel pair whose β the model does not fit |
//! | `compliance` | c_j (one joint), or every c_j the model lacks (the group) | gravity torque varying on the joint |
//! | `compliance_cubic` | d_j (Δθ_j = d_j·τ_j³) | torque varying on the joint |
//! | `cyclic` | sin and cos of h·q_j, h = 1, 2, and the best quarter-cycle frequency up to 40 cycles/rev (the periodogram) | — |
//! | `joint_map` | a correction table of q_j, knots a few degrees apart, smoothness-regularised | — |
//! | `backlash` | Δθ_j = b_j·(direction of joint j's last move), one joint or every joint | an approach log, or sessions in measuring order |
//! | `thermal` | α of every link length (× (T − 20 °C)) | logged temperatures that vary |
//! | `coupling` | Δθ_k = ε·q_j | — |
//! | `tool_mass` | the payload error δm (through the compliances) | compliance in the model |
//! | `base` | T_0^W re-registration | base parameters the model holds fixed |
//! | `tool` | a tool's TCP (x, y, z, and orientation when poses are measured) | a declared (fixed) TCP |

use crate::kinematics::{JointTerm, Param};

/// What kind of physics a candidate stands for (the verdict's `name`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Kind {
    /// Hayati β of a row whose axis is nominally parallel to the previous one.
    HayatiBeta,
    /// Linear gear compliance, Δθ_j = c_j·τ_j with τ_j the gravity holding torque: one joint, or
    /// every joint the model lacks (the group).
    Compliance,
    /// Cubic compliance, Δθ_j = d_j·τ_j³.
    ComplianceCubic,
    /// A periodic error of one joint, sin and cos of f·q_j: the harmonics f = 1, 2, or the frequency
    /// scan's best, in quarter cycles from 1/4 to 40 cycles per revolution.
    Cyclic,
    /// A correction table of one joint's angle over its reading, knots a few degrees apart,
    /// smoothness-regularised.
    JointMap,
    /// Backlash, Δθ_j = b_j·(direction of joint j's last move), −1, 0 or +1: one joint, or every
    /// joint.
    Backlash,
    /// Thermal growth: every link length scaled by 1 + α·(T − 20 °C).
    Thermal,
    /// A coupling between joints, Δθ_k = ε·q_j.
    Coupling,
    /// An error δm of the declared payload mass, kg, acting through the compliances.
    ToolMass,
    /// A re-registration of the base, T_0^W: the base parameters the model holds fixed, freed.
    Base,
    /// A tool's TCP identified: its declared (fixed) TCP freed. The candidate's `joint` holds the
    /// tool's index.
    Tool,
}

impl Kind {
    /// The kind's snake_case name, as in the verdict and in files (`hayati_beta`, `joint_map`, …).
    pub fn name(self) -> &'static str {
        match self {
            Kind::HayatiBeta => "hayati_beta",
            Kind::Compliance => "compliance",
            Kind::ComplianceCubic => "compliance_cubic",
            Kind::Cyclic => "cyclic",
            Kind::JointMap => "joint_map",
            Kind::Backlash => "backlash",
            Kind::Thermal => "thermal",
            Kind::Coupling => "coupling",
            Kind::ToolMass => "tool_mass",
            Kind::Base => "base",
            Kind::Tool => "tool",
        }
    }

    /// Kinds that describe the joint angle of one joint as a function of that joint's own
    /// reading: nested forms of one transmission error (a table contains the harmonics), so the
    /// diagnosis prefers the simplest that predicts as well instead of calling them look-alikes.
    pub fn is_transmission(self) -> bool {
        matches!(self, Kind::Cyclic | Kind::JointMap)
    }
}

/// One candidate effect.
#[derive(Clone, Debug, PartialEq)]
pub struct Candidate {
    /// What kind of effect it is.
    pub kind: Kind,
    /// The joint it acts on (0-based): the joint whose angle it corrects, the Hayati row, the
    /// coupling's destination.
    pub joint: Option<usize>,
    /// Coupling source joint (0-based).
    pub from: Option<usize>,
    /// Cyclic frequency in quarter cycles per revolution.
    pub quarters: Option<u16>,
    /// Found by the frequency scan (its p-value carries the scan's multiplicity).
    pub scanned: bool,
    /// Knot spacing of a table, degrees.
    pub step_deg: Option<u8>,
    /// The model parameters it adds.
    pub params: Vec<Param>,
    /// Global indices of existing parameters it frees instead (a fixed base or TCP).
    pub frees: Vec<usize>,
}

impl Candidate {
    pub(crate) fn new(kind: Kind, joint: Option<usize>, params: Vec<Param>) -> Self {
        Self { kind, joint, from: None, quarters: None, scanned: false, step_deg: None, params, frees: Vec::new() }
    }

    /// A short human label: `cyclic j2 h1`, `coupling 5→6`, `joint_map j3 (3° knots)`.
    pub fn label(&self) -> String {
        let j = |j: usize| format!("j{}", j + 1);
        match self.kind {
            Kind::Cyclic => {
                let q = self.quarters.unwrap_or(0);
                let f = if q.is_multiple_of(4) { format!("h{}", q / 4) } else { format!("f{}", q as f64 / 4.0) };
                format!("cyclic {} {f}{}", j(self.joint.unwrap_or(0)), if self.scanned { " (scan)" } else { "" })
            }
            Kind::Coupling => format!("coupling {}→{}", self.from.unwrap_or(0) + 1, self.joint.unwrap_or(0) + 1),
            Kind::JointMap => {
                format!("joint_map {} ({}° knots)", j(self.joint.unwrap_or(0)), self.step_deg.unwrap_or(0))
            }
            Kind::HayatiBeta => format!("hayati_beta beta{}", self.joint.unwrap_or(0)),
            _ => match self.joint {
                Some(jj) => format!("{} {}", self.kind.name(), j(jj)),
                None => self.kind.name().to_string(),
            },
        }
    }

    /// Cycles per revolution of a cyclic candidate.
    pub fn frequency(&self) -> Option<f64> {
        self.quarters.map(|q| q as f64 / 4.0)
    }

    /// Same physical effect at the same place (for de-duplicating a scan that lands on h1/h2).
    pub(crate) fn same_effect(&self, other: &Candidate) -> bool {
        self.kind == other.kind
            && self.joint == other.joint
            && self.from == other.from
            && self.quarters == other.quarters
    }
}

/// What the library needs to know about the data and the current model.
pub struct Context<'a> {
    /// Joints of the robot.
    pub dof: usize,
    /// The layout's parameters and, per layout entry, whether the current model fits it.
    pub layout: &'a [Param],
    /// Per entry of `layout`: whether the current model fits it.
    pub free: &'a [bool],
    /// Rows whose axis is nominally parallel to the previous one.
    pub parallel_rows: Vec<usize>,
    /// Per joint: the range of the holding torque over the data, N·m.
    pub torque_range: Vec<f64>,
    /// Per joint: the range of the readings, rad.
    pub joint_range: Vec<f64>,
    /// Whether any observation has a non-zero approach direction (logged, or derived from the
    /// measuring order): backlash needs it.
    pub approach_available: bool,
    /// Temperatures logged for every measurement, and their spread, °C.
    pub temperature_range: Option<f64>,
    /// Fixed base parameters (global indices) and fixed TCP blocks (per tool: global indices).
    pub fixed_base: Vec<usize>,
    /// Per tool: the global indices of its TCP components the model holds fixed (x, y, z, and the
    /// orientation when poses are measured).
    pub fixed_tools: Vec<Vec<usize>>,
    /// Knot spacing for tables, degrees (0: automatic).
    pub map_step_deg: u8,
}

/// Torque range below which a joint carries no gravity torque worth a compliance (axis 1 of an
/// upright robot: exactly zero up to rounding).
const NO_TORQUE: f64 = 1e-6;

impl Context<'_> {
    fn has(&self, p: Param) -> bool {
        self.layout.iter().zip(self.free).any(|(q, f)| *q == p && *f)
    }

    fn any_compliance(&self) -> bool {
        (0..self.dof).any(|j| self.has(Param::Joint(j, JointTerm::Compliance)))
    }

    /// Knot spacing of joint j's table: the requested one, or about 60 knots over the readings'
    /// range, 2° to 10° apart.
    pub(crate) fn step_for(&self, j: usize) -> u8 {
        if self.map_step_deg > 0 {
            return self.map_step_deg;
        }
        let range = self.joint_range[j].to_degrees();
        (range / 60.0).ceil().clamp(2.0, 10.0) as u8
    }
}

/// Candidates that cannot be tested on these data, with the reason (reported, so the engineer
/// knows what was not looked for).
#[derive(Clone, Debug, PartialEq)]
pub struct Unavailable {
    /// The kind not tested.
    pub kind: Kind,
    /// Why, in a clause for the report.
    pub reason: String,
}

/// Every candidate the library offers for this model and these data (the frequency scan is
/// generated separately, one joint at a time), and those it cannot offer.
pub fn candidates(ctx: &Context<'_>) -> (Vec<Candidate>, Vec<Unavailable>) {
    let n = ctx.dof;
    let mut out = Vec::new();
    let mut missing = Vec::new();
    // Hayati β on parallel pairs the model does not fit.
    for &j in &ctx.parallel_rows {
        if !ctx.has(Param::Beta(j)) {
            out.push(Candidate::new(Kind::HayatiBeta, Some(j), vec![Param::Beta(j)]));
        }
    }
    // Compliance, per joint and as a group.
    let lacking: Vec<usize> = (0..n)
        .filter(|&j| ctx.torque_range[j] > NO_TORQUE && !ctx.has(Param::Joint(j, JointTerm::Compliance)))
        .collect();
    for &j in &lacking {
        out.push(Candidate::new(Kind::Compliance, Some(j), vec![Param::Joint(j, JointTerm::Compliance)]));
    }
    if lacking.len() > 1 {
        out.push(Candidate::new(
            Kind::Compliance,
            None,
            lacking.iter().map(|&j| Param::Joint(j, JointTerm::Compliance)).collect(),
        ));
    }
    for j in (0..n).filter(|&j| ctx.torque_range[j] > NO_TORQUE) {
        let p = Param::Joint(j, JointTerm::ComplianceCubic);
        if !ctx.has(p) {
            out.push(Candidate::new(Kind::ComplianceCubic, Some(j), vec![p]));
        }
    }
    // Cyclic: the two eccentricity harmonics (prespecified, no scan multiplicity).
    for j in 0..n {
        for h in [1u8, 2] {
            let (s, c) = (
                Param::Joint(j, JointTerm::Cyclic { harmonic: h, cosine: false }),
                Param::Joint(j, JointTerm::Cyclic { harmonic: h, cosine: true }),
            );
            if !ctx.has(s) {
                let mut cand = Candidate::new(Kind::Cyclic, Some(j), vec![s, c]);
                cand.quarters = Some(4 * h as u16);
                out.push(cand);
            }
        }
    }
    // Correction tables.
    for j in 0..n {
        let already = ctx
            .layout
            .iter()
            .zip(ctx.free)
            .any(|(p, f)| *f && matches!(p, Param::Joint(k, JointTerm::Map { .. }) if *k == j));
        if !already && ctx.joint_range[j] > 0.0 {
            let mut cand = Candidate::new(Kind::JointMap, Some(j), Vec::new());
            cand.step_deg = Some(ctx.step_for(j));
            out.push(cand); // knots are laid over the data by the caller
        }
    }
    // Backlash.
    if ctx.approach_available {
        let lacking: Vec<usize> =
            (0..n).filter(|&j| ctx.joint_range[j] > 0.0 && !ctx.has(Param::Joint(j, JointTerm::Backlash))).collect();
        for &j in &lacking {
            out.push(Candidate::new(Kind::Backlash, Some(j), vec![Param::Joint(j, JointTerm::Backlash)]));
        }
        // Every joint's at once: hysteresis is a property of every gear, and a greedy search
        // taking one joint a round would spend its rounds on them.
        if lacking.len() > 1 {
            out.push(Candidate::new(
                Kind::Backlash,
                None,
                lacking.iter().map(|&j| Param::Joint(j, JointTerm::Backlash)).collect(),
            ));
        }
    } else {
        missing.push(Unavailable {
            kind: Kind::Backlash,
            reason: "no approach log, and no session whose measuring order is known".into(),
        });
    }
    // Thermal.
    match ctx.temperature_range {
        Some(r) if r >= 0.5 => {
            if !ctx.has(Param::Thermal) {
                out.push(Candidate::new(Kind::Thermal, None, vec![Param::Thermal]));
            }
        }
        Some(r) => missing.push(Unavailable {
            kind: Kind::Thermal,
            reason: format!("the logged temperatures vary by {r:.2} °C only (at least 0.5 °C needed)"),
        }),
        None => missing.push(Unavailable { kind: Kind::Thermal, reason: "no temperature log".into() }),
    }
    // Couplings.
    for to in 0..n {
        for from in (0..n).filter(|&f| f != to) {
            let p = Param::Joint(to, JointTerm::Coupling { from });
            if !ctx.has(p) {
                let mut cand = Candidate::new(Kind::Coupling, Some(to), vec![p]);
                cand.from = Some(from);
                out.push(cand);
            }
        }
    }
    // Payload error.
    if ctx.any_compliance() {
        if !ctx.has(Param::ToolMass) {
            out.push(Candidate::new(Kind::ToolMass, None, vec![Param::ToolMass]));
        }
    } else {
        missing.push(Unavailable {
            kind: Kind::ToolMass,
            reason: "the model has no compliance: a payload error acts only through it".into(),
        });
    }
    // Base and tools held fixed.
    if !ctx.fixed_base.is_empty() {
        let mut c = Candidate::new(Kind::Base, None, Vec::new());
        c.frees = ctx.fixed_base.clone();
        out.push(c);
    }
    for (t, fixed) in ctx.fixed_tools.iter().enumerate() {
        if !fixed.is_empty() {
            let mut c = Candidate::new(Kind::Tool, Some(t), Vec::new());
            c.frees = fixed.clone();
            out.push(c);
        }
    }
    (out, missing)
}

/// The frequencies of the scan for one joint, quarter cycles: 1/4 … 40 cycles per revolution.
pub(crate) fn scan_quarters() -> impl Iterator<Item = u16> {
    1..=160u16
}

/// The effective number of independent frequencies a scan over `range` rad of a joint tests:
/// two frequencies closer than one cycle over the range are nearly the same regressor
/// (DIAGNOSIS §2: ≈ range in revolutions × highest frequency), at least 1.
pub(crate) fn scan_multiplicity(range: f64) -> f64 {
    (range / std::f64::consts::TAU * 40.0).max(1.0)
}
