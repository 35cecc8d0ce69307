//! Unmodelled effects the virtual cell's true robot can carry, each off by default, each with a
//! magnitude. Defaults are sized to move the TCP by roughly 0.05–0.2 mm somewhere in the default
//! cell's measuring volume (the tests measure each one).
//!
//! | effect | truth | default | size at the TCP |
//! |---|---|---|---|
//! | `cyclic:j=2:h=1:amp_deg=0.01:phase_deg=0` | Δθ_j = amp·sin(h·q_j + phase) | joint 2, h = 1, 0.01° | 0.01° at ~0.5 m lever ≈ 0.09 mm |
//! | `backlash:j=2:deg=0.01` | Δθ_j = ±deg by the logged approach direction | joint 2, ±0.01° | ≈ ±0.09 mm |
//! | `thermal:alpha_ppm=23:rise_c=8:tau_s=3600:start_c=20` | every a, d × (1 + α·(T − 20 °C)); T warms from `start_c` by `rise_c` with time constant `tau_s` | aluminium, +8 °C | 0.57 m·23e-6·8 ≈ 0.1 mm |
//! | `coupling:from=5:to=6:ratio=0.001` | Δθ_to = ratio·q_from | 5 → 6, 1e-3 | 2e-3 rad at the 40 mm TCP offset ≈ 0.08 mm |
//! | `compliance_cubic:j=2:d=2.5e-7` | Δθ_j += d·τ_j³ (d in deg/(N·m)³) | joint 2 | at τ₂ ≈ 32 N·m: 8e-3° ≈ 0.07 mm |
//! | `tool_mass:delta_kg=0.5` | the true payload is the declared one + delta | +0.5 kg | through the compliances ≈ 0.05 mm |
//! | `link_bending:deg_per_nm=5.7e-4` | link 2 bends with its root moment τ₂: slope φ = k·τ₂ and tip offset φ·a₂/2 at joint 3 | 1e-5 rad/(N·m) | at 32 N·m: 3.2e-4 rad ≈ 0.1 mm |
//! | `no_beta`, `no_compliance` | model-side switches: the truth has β₂ and the compliances, the model used with this cell should not | off | |
//!
//! `link_bending` is deliberately *not* a joint-angle term: it rotates and displaces the end of
//! link 2, in proportion to joint 2's torque, at joint 3 — none of the diagnosis's candidate forms.

use serde::{Deserialize, Serialize};

use crate::kinematics::ParameterSet;
use crate::kinematics::params::{JointTerm, Param};
use crate::units::DEG;

/// Per-joint cyclic error, Δθ_j = amp·sin(h·q_j + phase).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cyclic {
    /// Joint, 1-based.
    pub j: usize,
    /// Harmonic h, cycles per joint revolution (1–255).
    pub h: u8,
    /// Amplitude, degrees.
    pub amp_deg: f64,
    /// Phase, degrees (0 when absent).
    #[serde(default)]
    pub phase_deg: f64,
}

/// Backlash of one joint: Δθ_j = ±deg by the logged approach direction (0 when the joint did not
/// move).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Backlash {
    /// Joint, 1-based.
    pub j: usize,
    /// Half play: Δθ = ±deg by the approach direction.
    pub deg: f64,
}

/// Thermal expansion: every link length a, d scales by 1 + α·(T − 20 °C), with the robot's
/// temperature T from [`Effects::temperature_at`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Thermal {
    /// Expansion coefficient α, 10⁻⁶/K (23 for aluminium).
    pub alpha_ppm: f64,
    /// Temperature rise over the run, °C (the asymptote of the warm-up).
    pub rise_c: f64,
    /// Warm-up time constant, s (positive).
    pub tau_s: f64,
    /// Temperature at the start of the run, °C.
    pub start_c: f64,
}

/// Coupling between two joints: Δθ_to = ratio·q_from (q_from in rad).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Coupling {
    /// The driving joint, 1-based.
    pub from: usize,
    /// The driven joint, 1-based (not `from`).
    pub to: usize,
    /// Radians of `to` per radian of `from`.
    pub ratio: f64,
}

/// Cubic gear compliance of one joint, on top of the linear one: Δθ_j += d·τ_j³, τ_j the holding
/// torque.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ComplianceCubic {
    /// Joint, 1-based.
    pub j: usize,
    /// Coefficient d, deg/(N·m)³.
    pub d: f64,
}

/// A payload that differs from the declared one: every tool's true mass is its declared mass plus
/// `delta_kg`, at its declared centre of mass. It acts through the compliances.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ToolMass {
    /// True minus declared payload mass, kg.
    pub delta_kg: f64,
}

/// Link 2 bending under its gravity load: at the end of link 2 (after joint 3's row
/// Rx(α₂)·Tx(a₂)) the chain turns by φ = −k·τ₂ about that frame's z axis and shifts by φ·a₂/2
/// along its y, k being `deg_per_nm` in rad/(N·m) (a cantilever under an end moment; τ₂ is the
/// holding torque, so −τ₂ is the root moment). Robots with more than two joints only.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkBending {
    /// Bending slope of link 2 per N·m of its root moment, deg/(N·m).
    pub deg_per_nm: f64,
}

/// All effects of a truth. Empty = a truth exactly in the model family.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Effects {
    /// Cyclic errors, any number.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub cyclic: Vec<Cyclic>,
    /// Backlash terms, any number.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub backlash: Vec<Backlash>,
    /// Thermal expansion of the link lengths; without it the robot is near 20 °C (see
    /// [`Effects::temperature_at`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub thermal: Option<Thermal>,
    /// Joint couplings, any number.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub coupling: Vec<Coupling>,
    /// Cubic compliances, any number.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub compliance_cubic: Vec<ComplianceCubic>,
    /// Payload mass error (outside the parameter vector: applied by
    /// [`super::truth::Truth::robot`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tool_mass: Option<ToolMass>,
    /// Link-2 bending (outside the parameter vector: applied by
    /// [`super::truth::TrueRobot::tcp`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link_bending: Option<LinkBending>,
    /// Model-side switch: the model fitted to this cell should leave out β (the truth keeps it).
    /// The simulator does not read it; the caller that chooses the fitted model does.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub no_beta: bool,
    /// Model-side switch: the model fitted to this cell should leave out the compliances (the
    /// truth keeps them). The simulator does not read it; the caller that chooses the fitted
    /// model does.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub no_compliance: bool,
}

/// A bad `--effects` specification.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{item}: {reason}")]
pub struct EffectError {
    /// The offending comma-separated item, as written.
    pub item: String,
    /// What is wrong with it.
    pub reason: String,
}

impl Effects {
    /// No effect and no model-side switch: equal to `Effects::default()`.
    pub fn is_empty(&self) -> bool {
        *self == Effects::default()
    }

    /// Parse `name[:key=value]*` items separated by commas, e.g.
    /// `cyclic:j=2:h=1:amp_deg=0.01,backlash,thermal:rise_c=5,no_beta`. Names, keys and defaults
    /// are those of the module's table; joints are 1-based and at most `dof`. Blank items are
    /// skipped; the list effects (cyclic, backlash, coupling, compliance_cubic) add one entry per
    /// item, the others keep the last item.
    ///
    /// Errors, naming the item: a part that is not `key=value`, a value that is not a finite
    /// number, a joint outside 1–`dof` or not whole, a harmonic `h` not whole in 1–255, `tau_s`
    /// not positive, a coupling with `from` = `to`, an unknown effect or an unknown key.
    pub fn parse(spec: &str, dof: usize) -> Result<Effects, EffectError> {
        let mut e = Effects::default();
        for item in spec.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let mut parts = item.split(':');
            let name = parts.next().unwrap_or_default();
            let mut kv = Vec::new();
            for p in parts {
                let (k, v) = p.split_once('=').ok_or_else(|| err(item, format!("'{p}' is not key=value")))?;
                let v: f64 = v
                    .parse()
                    .ok()
                    .filter(|x: &f64| x.is_finite())
                    .ok_or_else(|| err(item, format!("{k}: '{v}' is not a finite number")))?;
                kv.push((k.to_string(), v));
            }
            let mut take = |key: &str, default: f64| -> f64 {
                match kv.iter().position(|(k, _)| k == key) {
                    Some(i) => kv.remove(i).1,
                    None => default,
                }
            };
            let joint = |v: f64, what: &str| -> Result<usize, EffectError> {
                if v.fract() != 0.0 || v < 1.0 || v > dof as f64 {
                    return Err(err(item, format!("{what} must be a joint number 1–{dof}, got {v}")));
                }
                Ok(v as usize)
            };
            match name {
                "cyclic" => {
                    let j = joint(take("j", 2.0), "j")?;
                    let h = take("h", 1.0);
                    if h.fract() != 0.0 || !(1.0..=255.0).contains(&h) {
                        return Err(err(item, format!("h must be a whole harmonic ≥ 1, got {h}")));
                    }
                    e.cyclic.push(Cyclic {
                        j,
                        h: h as u8,
                        amp_deg: take("amp_deg", 0.01),
                        phase_deg: take("phase_deg", 0.0),
                    });
                }
                "backlash" => {
                    let j = joint(take("j", 2.0), "j")?;
                    e.backlash.push(Backlash { j, deg: take("deg", 0.01) });
                }
                "thermal" => {
                    let t = Thermal {
                        alpha_ppm: take("alpha_ppm", 23.0),
                        rise_c: take("rise_c", 8.0),
                        tau_s: take("tau_s", 3600.0),
                        start_c: take("start_c", 20.0),
                    };
                    if t.tau_s <= 0.0 {
                        return Err(err(item, "tau_s must be positive".into()));
                    }
                    e.thermal = Some(t);
                }
                "coupling" => {
                    let from = joint(take("from", 5.0), "from")?;
                    let to = joint(take("to", 6.0), "to")?;
                    if from == to {
                        return Err(err(item, "from and to must differ".into()));
                    }
                    e.coupling.push(Coupling { from, to, ratio: take("ratio", 1e-3) });
                }
                "compliance_cubic" => {
                    let j = joint(take("j", 2.0), "j")?;
                    e.compliance_cubic.push(ComplianceCubic { j, d: take("d", 2.5e-7) });
                }
                "tool_mass" => e.tool_mass = Some(ToolMass { delta_kg: take("delta_kg", 0.5) }),
                "link_bending" => e.link_bending = Some(LinkBending { deg_per_nm: take("deg_per_nm", 1e-5 / DEG) }),
                "no_beta" => e.no_beta = true,
                "no_compliance" => e.no_compliance = true,
                other => {
                    return Err(err(
                        item,
                        format!(
                            "unknown effect '{other}' (cyclic, backlash, thermal, coupling, compliance_cubic, tool_mass, link_bending, no_beta, no_compliance)"
                        ),
                    ));
                }
            }
            if let Some((k, _)) = kv.first() {
                return Err(err(item, format!("unknown key '{k}' for {name}")));
            }
        }
        Ok(e)
    }

    /// Attach the joint-angle effects to a true parameter set as parameters (cyclic terms,
    /// backlash, coupling, cubic compliance) and the thermal coefficient, converted to SI (rad,
    /// rad/(N·m)³, 1/K); a cyclic term becomes its sin and cos parameters, amp·cos(phase) and
    /// amp·sin(phase). Values add to a parameter the set already has. The other effects act
    /// outside the parameter vector (see [`super::truth`]).
    pub(crate) fn apply_to(&self, set: &mut ParameterSet) {
        let mut add = |p: Param, v: f64| {
            let i = set.extend(&[p])[0];
            set.values[i] += v;
        };
        for c in &self.cyclic {
            let (a, b) = (c.amp_deg * (c.phase_deg * DEG).cos(), c.amp_deg * (c.phase_deg * DEG).sin());
            add(Param::Joint(c.j - 1, JointTerm::Cyclic { harmonic: c.h, cosine: false }), a * DEG);
            add(Param::Joint(c.j - 1, JointTerm::Cyclic { harmonic: c.h, cosine: true }), b * DEG);
        }
        for b in &self.backlash {
            add(Param::Joint(b.j - 1, JointTerm::Backlash), b.deg * DEG);
        }
        for c in &self.coupling {
            add(Param::Joint(c.to - 1, JointTerm::Coupling { from: c.from - 1 }), c.ratio);
        }
        for c in &self.compliance_cubic {
            add(Param::Joint(c.j - 1, JointTerm::ComplianceCubic), c.d * DEG);
        }
        if let Some(t) = &self.thermal {
            add(Param::Thermal, t.alpha_ppm * 1e-6);
        }
    }

    /// Robot temperature at time t (s) since the start of the run, °C. Without the thermal
    /// effect the lab holds 20 °C within ±0.3 °C (thesis Table 2.1), logged as a slow drift: a
    /// sine of amplitude 0.3 °C and period 4 h. With it, the warm-up
    /// `start_c + rise_c·(1 − e^(−t/tau_s))` plus that same drift.
    pub fn temperature_at(&self, t: f64) -> f64 {
        let drift = 0.3 * (std::f64::consts::TAU * t / 14_400.0).sin();
        match &self.thermal {
            Some(th) => th.start_c + th.rise_c * (1.0 - (-t / th.tau_s).exp()) + drift,
            None => 20.0 + drift,
        }
    }
}

fn err(item: &str, reason: String) -> EffectError {
    EffectError { item: item.to_string(), reason }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_with_defaults_and_overrides() {
        let e = Effects::parse("cyclic:j=3:h=17:amp_deg=0.005, backlash, thermal:rise_c=5, coupling, compliance_cubic, tool_mass, link_bending, no_beta", 6).unwrap();
        assert_eq!(e.cyclic, vec![Cyclic { j: 3, h: 17, amp_deg: 0.005, phase_deg: 0.0 }]);
        assert_eq!(e.backlash[0], Backlash { j: 2, deg: 0.01 });
        assert_eq!(e.thermal.as_ref().unwrap().rise_c, 5.0);
        assert_eq!(e.coupling[0], Coupling { from: 5, to: 6, ratio: 1e-3 });
        assert!(e.no_beta && !e.no_compliance);
        assert!(Effects::parse("", 6).unwrap().is_empty());
        let json = serde_json::to_string(&e).unwrap();
        assert_eq!(serde_json::from_str::<Effects>(&json).unwrap(), e);
    }

    #[test]
    fn bad_specs_name_the_item() {
        for (spec, needle) in [
            ("cyclic:j=9", "joint number"),
            ("cyclic:h=0", "harmonic"),
            ("cyclic:amp=1", "unknown key 'amp'"),
            ("wobble", "unknown effect"),
            ("backlash:deg", "key=value"),
            ("thermal:tau_s=-1", "positive"),
            ("coupling:from=5:to=5", "differ"),
            ("cyclic:amp_deg=x", "finite"),
        ] {
            let e = Effects::parse(spec, 6).unwrap_err();
            assert!(e.to_string().contains(needle), "{spec}: {e}");
        }
    }
}
