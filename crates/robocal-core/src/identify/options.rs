//! What an identification can be told: the model's blocks and effect terms, the fixed and only
//! parameters, the limits a fit must meet.

use super::noise::NoiseModel;
use super::problem::MeasurementSelection;
use super::solver::SolverOptions;
use crate::kinematics::{JointTerm, Param, ParameterSet};

/// Which model is fitted: the structure's optional blocks and effect terms.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelOptions {
    /// Hayati β on the joints that have it.
    pub beta: bool,
    /// Linear gear compliance on every joint.
    pub compliance: bool,
    /// Further effect terms (cyclic, backlash, coupling, cubic compliance, thermal, payload
    /// error). A compliance `c{j}` or a `beta{j}` listed here is free even when `compliance` or
    /// `beta` is off: the model has that one term.
    pub extra: Vec<Param>,
    /// Correction tables: (joint, knot spacing in degrees). The knots cover the joint's range in
    /// the identified measurements.
    pub maps: Vec<(usize, u8)>,
}

impl Default for ModelOptions {
    fn default() -> Self {
        Self { beta: true, compliance: true, extra: Vec::new(), maps: Vec::new() }
    }
}

impl ModelOptions {
    /// Parse `+beta,-compliance,+cyc2_h1,+backlash2,+coupling5_6,+c2_cubic,+thermal_alpha`
    /// (a `+cyc{j}_h{h}` or `+cyc{j}_f{f}` adds its sine and cosine terms), `+tool_mass`,
    /// `+map{j}_s{step}` (a correction table of joint j with knots every `step` degrees), `+drift`
    /// (a drift of the readings along the measuring run, [`crate::identify::run`]: the nine
    /// `drift_{x,y,z}_p{1,2,3}`, or one of them by its name), and
    /// single terms of a block that is off (`-compliance,+c3`; `-beta,+beta2`). Unsigned items
    /// add.
    pub fn parse(spec: &str, dof: usize) -> Result<ModelOptions, String> {
        let mut m = ModelOptions::default();
        for item in spec.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (on, name) = match item.strip_prefix('-') {
                Some(n) => (false, n),
                None => (true, item.strip_prefix('+').unwrap_or(item)),
            };
            match name {
                "beta" => m.beta = on,
                "compliance" => m.compliance = on,
                "drift" if on => {
                    for p in drift_terms() {
                        if !m.extra.contains(&p) {
                            m.extra.push(p);
                        }
                    }
                }
                "drift" => return Err(format!("'{item}': effect terms are added with +, not removed")),
                _ if parse_map(name).is_some() => {
                    let (j, step) = parse_map(name).expect("checked");
                    if j >= dof {
                        return Err(format!("'{item}': not an effect term of a {dof}-joint robot"));
                    }
                    if !on {
                        return Err(format!("'{item}': effect terms are added with +, not removed"));
                    }
                    if !m.maps.contains(&(j, step)) {
                        m.maps.push((j, step));
                    }
                }
                _ => {
                    let params: Vec<Param> = if let Some(p) = Param::parse(name) {
                        vec![p]
                    } else if let Some(p) = Param::parse(&format!("{name}_sin")) {
                        let Param::Joint(j, t) = p else { unreachable!() };
                        let cos = match t {
                            JointTerm::Cyclic { harmonic, .. } => JointTerm::Cyclic { harmonic, cosine: true },
                            JointTerm::Periodic { quarters, .. } => JointTerm::Periodic { quarters, cosine: true },
                            _ => unreachable!("only cyclic names end in _sin"),
                        };
                        vec![p, Param::Joint(j, cos)]
                    } else {
                        return Err(format!(
                            "'{item}': unknown model option (beta, compliance, or an effect term such as cyc2_h1, cyc2_f7.25, backlash2, coupling5_6, c2_cubic, c3, beta2, map2_s3, thermal_alpha, tool_mass, drift)"
                        ));
                    };
                    for p in params {
                        let ok = match p {
                            Param::Joint(j, JointTerm::Coupling { from }) => j < dof && from < dof,
                            Param::Joint(_, JointTerm::Map { .. }) => false,
                            Param::Joint(j, _) => j < dof,
                            Param::Beta(j) => j < dof,
                            Param::Thermal | Param::ToolMass | Param::Drift(..) => true,
                            _ => false,
                        };
                        if !ok {
                            return Err(format!("'{item}': not an effect term of a {dof}-joint robot"));
                        }
                        if !on {
                            return Err(format!("'{item}': effect terms are added with +, not removed"));
                        }
                        if !m.extra.contains(&p) {
                            m.extra.push(p);
                        }
                    }
                }
            }
        }
        Ok(m)
    }
}

/// Effect terms as `--model` spells them: a sine and its cosine as one `+cyc2_h1`, a table's
/// knots as one `+map2_s3`, the rest `+{name}` (`+backlash2`, `+c3`).
pub fn term_spec(terms: &[Param]) -> Vec<String> {
    let mut items: Vec<String> = Vec::new();
    let mut maps: Vec<(usize, u8)> = Vec::new();
    let every_drift = drift_terms().iter().all(|p| terms.contains(p));
    for p in terms {
        match p {
            Param::Drift(..) if every_drift => {
                if !items.iter().any(|i| i == "+drift") {
                    items.push("+drift".into());
                }
            }
            Param::Joint(j, JointTerm::Map { step_deg, .. }) => {
                if !maps.contains(&(*j, *step_deg)) {
                    maps.push((*j, *step_deg));
                }
            }
            Param::Joint(
                j,
                t @ (JointTerm::Cyclic { cosine: false, .. } | JointTerm::Periodic { cosine: false, .. }),
            ) => {
                let name = Param::Joint(*j, *t).to_string();
                items.push(format!("+{}", name.trim_end_matches("_sin")));
            }
            Param::Joint(_, JointTerm::Cyclic { cosine: true, .. } | JointTerm::Periodic { cosine: true, .. }) => {}
            p => items.push(format!("+{p}")),
        }
    }
    items.extend(maps.iter().map(|(j, s)| format!("+map{}_s{s}", j + 1)));
    items
}

/// The nine terms of a drift along the measuring run (`+drift`).
pub fn drift_terms() -> Vec<Param> {
    (0..3).flat_map(|a| (0..super::run::DRIFT_ORDERS).map(move |k| Param::Drift(a, k))).collect()
}

/// `map{j}_s{step}` → (0-based joint, step in degrees).
fn parse_map(name: &str) -> Option<(usize, u8)> {
    let rest = name.strip_prefix("map")?;
    let (j, step) = rest.split_once("_s")?;
    let j: usize = j.parse().ok().filter(|&j: &usize| j >= 1 && !j.to_string().starts_with('0'))?;
    let step: u8 = step.parse().ok().filter(|&s: &u8| s >= 1 && step == s.to_string())?;
    Some((j - 1, step))
}

/// The knots of a correction table on joint j covering the joint's range in `qs` (rad), one
/// knot beyond each end so every reading sits between two knots.
pub fn map_knots(j: usize, step_deg: u8, qs: impl Iterator<Item = f64>) -> Vec<Param> {
    let step = step_deg as f64 * crate::units::DEG;
    let (lo, hi) = qs.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), q| (lo.min(q), hi.max(q)));
    if !lo.is_finite() {
        return Vec::new();
    }
    let (k0, k1) = ((lo / step).floor() as i64, (hi / step).ceil() as i64);
    (k0.max(i16::MIN as i64)..=k1.min(i16::MAX as i64))
        .map(|k| Param::Joint(j, JointTerm::Map { step_deg, knot: k as i16 }))
        .collect()
}

/// Everything an identification can be told.
#[derive(Clone, Debug)]
pub struct IdentifyOptions {
    /// Which measurements the fit uses.
    pub selection: MeasurementSelection,
    /// Which model is fitted: its optional blocks and effect terms.
    pub model: ModelOptions,
    /// Parameters held at their nominal values (names, e.g. `a2`, `tool_x`, `tool2_y`).
    pub fixed: Vec<String>,
    /// Refuse fits whose column-scaled κ(J) exceeds this (thesis §4.2.3: κ ≤ 1000, at most 3 of
    /// 16 digits lost). The limit applies to the scaled Jacobian because that is the system the
    /// solver factorises: its κ is what the solve loses. κ in SI units (the thesis's own figure)
    /// depends on the units chosen for each column — compliance in rad/(N·m) multiplies its
    /// column by the torques — and is reported beside it for comparison.
    pub kappa_limit: f64,
    /// The least-squares solver's settings.
    pub solver: SolverOptions,
    /// Metres per radian for orientation residual rows.
    pub rotation_weight: f64,
    /// Start from this parameter set instead of the nominal model: every robot parameter it has
    /// (base excepted) and the TCP of a tool equal to its declared tool take its values, and
    /// parameters held fixed stay at them. The base always comes from the cell (its guess or a
    /// registration): a new setup is what re-identifying from a calibrated set is for.
    pub start: Option<ParameterSet>,
    /// When non-empty, only these parameters are free; every other one is fixed (at its start
    /// value). Items are parameter names (`a2`, `tool2_x`) or the groups `base` (base_x … base_c),
    /// `tool` (every tool's six) and `zeros` (the joints' zero offsets θ1 … θn). `["base", "tool"]`
    /// re-registers a calibrated robot in a new cell, or gives the "before calibration" reference
    /// of a cell without a base guess; `["base", "tool", "zeros"]` re-registers it after its
    /// joints were re-mastered (or their zeros drifted) as well.
    pub only: Vec<String>,
    /// Weight every measurement by its instrument's σ (weighted least squares); `None` = every
    /// residual row weighs the same (the thesis's plain least squares).
    pub noise: Option<NoiseModel>,
    /// Smoothing of correction tables (`map` terms): the weight of the second-difference rows
    /// relative to the data's information on one knot (η in λ² = η·mean‖J_knot‖²). Larger is
    /// smoother.
    pub map_smoothing: f64,
    /// Sessions whose tool TCP is identified although they declare it (a reflector nest whose
    /// declared offset is suspect).
    pub free_tcp: Vec<String>,
    /// Keep the geometry (α, a, d, θ offsets, β) within a plausible distance of its start values.
    pub anchor: Option<Anchor>,
    /// Refuse a fit whose residual RMS exceeds this many times the RMS the instrument model and
    /// the measurements' own σ predict ([`RESIDUAL_RATIO_LIMIT`]); `f64::INFINITY` accepts any.
    pub residual_ratio_limit: f64,
    /// Refuse a fit with a measurement whose residual exceeds this many times the typical one
    /// ([`OUTLIER_FACTOR`]), unless the Huber loss down-weighted it; `f64::INFINITY` never does.
    pub outlier_factor: f64,
    /// When every chosen session's tool declares no payload (0 kg: unknown, as a three-reflector
    /// file or a tracker run without a tool mass) and the model has compliance, identify the
    /// payload's mass (`tool_mass`, at the tools' declared centre of mass) instead of fitting the
    /// compliances with 0 kg. A compliance is a deflection per N·m of holding torque: with the
    /// payload's torque left out, the wrist's compliances have almost nothing to act on.
    pub identify_payload: bool,
    /// Hold every compliance whose fitted change is below [`super::COMPLIANCE_SIGNIFICANCE`] of
    /// its own standard deviation at its start value, and say so in its status (`hold.rs`: an
    /// undetermined compliance extrapolates to poses of larger torque by millimetres).
    pub hold_undetermined_compliance: bool,
}

/// The default of [`IdentifyOptions::residual_ratio_limit`]: a fit is refused when its residual RMS
/// is more than 50 times the RMS the instrument predicts.
///
/// Why 50. The ratio ρ = RMS(residual)/RMS(σ) is 1 when the model and the noise model are right
/// (χ²/dof = ρ²). A real robot's calibrated model leaves effects it lacks, and a nominal model
/// more: against the tracker's own σ, ρ = 20 for the UR10 of series C calibrated with the default
/// model (13 for series B) and 40 for its nominal model with base and probe fitted (crossval's
/// "before" reference is exempt); 2.3 for the virtual IRB 120 identified without β. A structure error leaves residuals of the size of the
/// error itself: one TCP for the three nests of the virtual cell (60–85 mm apart) leaves ρ = 118,
/// the IRB 120 of issue 13 with three reflectors ~100 mm apart ρ ≈ 2,700 (86.8 mm against a
/// tracker's ~0.03 mm). At ρ > 50 the unexplained variance is 2,500 times the instrument's: no
/// longer noise or a missing small effect but a wrong TCP, a session in another frame, or outliers.
pub const RESIDUAL_RATIO_LIMIT: f64 = 50.0;

/// A measurement is an outlier when its residual, in units of its own σ, exceeds this many times
/// the median measurement's (and 10σ of the instrument). Unmodelled effects are smooth over the
/// workspace and move neighbouring poses alike: their residuals' tail reaches 3–6 times the median
/// (UR10 calibrated: the largest is 3.6 times in series C, 5.8 in series B). A reading 10 times the median is a gross error — a
/// swapped line, a reflector that slipped, a broken beam — which least squares would spread over
/// every parameter.
pub const OUTLIER_FACTOR: f64 = 10.0;

/// A weak prior on the geometry: each free α, a, d, θ offset and β is an extra observation of
/// its start value with standard deviation `length` or `angle`. A built robot's geometry differs
/// from its calibrated values by micrometres, so σ of a millimetre or a tenth of a degree changes
/// nothing where the model fits; where it cannot — plain DH on tilted parallel axes, whose
/// least-squares solution lies at infinity (§3.4) — it keeps the fit finite, and the misfit
/// visible, instead of letting the parameters run away.
#[derive(Clone, Debug, PartialEq)]
pub struct Anchor {
    /// m.
    pub length: f64,
    /// rad.
    pub angle: f64,
}

impl Default for Anchor {
    fn default() -> Self {
        Self { length: 1e-3, angle: 0.1 * crate::units::DEG }
    }
}

impl Default for IdentifyOptions {
    fn default() -> Self {
        Self {
            selection: MeasurementSelection::default(),
            model: ModelOptions::default(),
            fixed: Vec::new(),
            kappa_limit: 1000.0,
            solver: SolverOptions::default(),
            rotation_weight: 0.1,
            start: None,
            only: Vec::new(),
            noise: None,
            map_smoothing: DEFAULT_MAP_SMOOTHING,
            free_tcp: Vec::new(),
            anchor: None,
            residual_ratio_limit: RESIDUAL_RATIO_LIMIT,
            outlier_factor: OUTLIER_FACTOR,
            identify_payload: true,
            hold_undetermined_compliance: true,
        }
    }
}

/// Default η of [`IdentifyOptions::map_smoothing`].
pub const DEFAULT_MAP_SMOOTHING: f64 = 1.0;

#[cfg(test)]
mod tests {
    use super::*;

    /// `+drift` adds the nine terms of a drift along the run and is written back as one item;
    /// one of them is added by its name; a drift is not removed with `-`.
    #[test]
    fn a_drift_is_added_as_one_item_and_spelled_back_as_one() {
        let m = ModelOptions::parse("+drift,+backlash2", 6).unwrap();
        assert_eq!(m.extra.len(), 10);
        assert!(drift_terms().iter().all(|p| m.extra.contains(p)));
        assert_eq!(term_spec(&m.extra), ["+drift", "+backlash2"]);
        let one = ModelOptions::parse("+drift_y_p2", 6).unwrap();
        assert_eq!(one.extra, [Param::Drift(1, 1)]);
        assert_eq!(term_spec(&one.extra), ["+drift_y_p2"]);
        let err = ModelOptions::parse("-drift", 6).unwrap_err();
        assert!(err.contains("added with +"), "{err}");
        assert!(ModelOptions::parse("+drift_w_p1", 6).unwrap_err().contains("unknown model option"));
    }
}
