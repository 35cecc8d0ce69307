//! Robot and tool descriptions in files: `{"preset": "irb120"}` or a custom joint table; tools as
//! a TCP in the flange frame plus the payload.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::{DomainError, finite, from_value, vec3_mm};
use crate::kinematics::model::{
    Link, ModelError, Preset, RobotModel, STANDARD_GRAVITY, StandardDhRow, Tool, modified_from_standard,
};
use crate::units::{DEG, MM};

/// One joint of a custom robot (modified DH unless the robot says `"convention": "standard"`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct JointSpec {
    /// Link twist α, deg (±360).
    pub alpha_deg: f64,
    /// Link length a, mm (±10 000).
    pub a_mm: f64,
    /// Joint-angle offset θ, deg (±360); default 0.
    #[serde(default)]
    pub theta_deg: f64,
    /// Link offset d, mm (±10 000).
    pub d_mm: f64,
    /// Present for a joint carrying Hayati's β (its nominal value, usually 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beta_deg: Option<f64>,
    /// Joint limits [lower, upper], deg, lower below upper (each within ±720).
    #[cfg_attr(feature = "openapi", schema(min_items = 2, max_items = 2))]
    pub limits_deg: [f64; 2],
    /// Mass of the link, kg (0 … 5 000); default 0 (no gravity load from this link).
    #[serde(default)]
    #[cfg_attr(feature = "openapi", schema(minimum = 0))]
    pub mass_kg: f64,
    /// The link's centre of mass, mm (each within ±10 000): in frame {i} (modified DH) or the
    /// distal frame (standard DH); default the frame's origin.
    #[serde(default)]
    #[cfg_attr(feature = "openapi", schema(min_items = 3, max_items = 3))]
    pub com_mm: [f64; 3],
}

/// DH convention of a custom joint table.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "lowercase")]
pub enum Convention {
    /// Craig's modified DH: `Rx(α_{i−1}) Tx(a_{i−1}) Rz(θ_i) Tz(d_i)`; CoM in frame {i}.
    #[default]
    Modified,
    /// Standard DH: `Rz(θ_i) Tz(d_i) Tx(a_i) Rx(α_i)`; CoM in the distal frame; converted exactly.
    Standard,
}

/// A custom robot.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct CustomRobotSpec {
    /// The robot's name (1 … 200 characters, not blank).
    #[cfg_attr(
        feature = "openapi",
        schema(min_length = 1, max_length = 200, pattern = "^[^\\u0000]*[^\\s\\u0000][^\\u0000]*$")
    )]
    pub name: String,
    /// DH convention of `joints`; default `modified`.
    #[serde(default)]
    pub convention: Convention,
    /// Gravity in the base frame {0}, m/s²; default (0, 0, −9.80665).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "openapi", schema(min_items = 3, max_items = 3))]
    pub gravity_mps2: Option<[f64; 3]>,
    /// The joints from the base to the flange (1 … 8). In the standard convention the last row
    /// must have `a_mm` = 0 and `alpha_deg` = 0 (that offset belongs in the tool).
    #[cfg_attr(feature = "openapi", schema(min_items = 1, max_items = 8))]
    pub joints: Vec<JointSpec>,
}

/// A robot preset's name.
#[derive(Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "lowercase")]
#[allow(dead_code)] // a schema only: presets are parsed by `Preset::from_name`
pub enum PresetName {
    /// ABB IRB 120, `irb120`.
    Irb120,
    /// Universal Robots UR10 (CB3), `ur10`.
    Ur10,
}

/// A robot preset: `{"preset": "irb120"}`.
#[derive(Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
#[allow(dead_code)] // a schema only
pub struct PresetRef {
    /// The preset's name.
    pub preset: PresetName,
}

/// A robot as files and requests give it: a preset or a custom joint table (the schema of
/// [`RobotSpec`], which is parsed by [`RobotSpec::from_json_value`]).
#[derive(Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(untagged)]
#[allow(dead_code)] // a schema only
pub enum RobotDoc {
    /// A built-in robot by name.
    Preset(PresetRef),
    /// A custom joint table.
    Custom(CustomRobotSpec),
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct PresetSpec {
    preset: String,
}

/// `{"preset": name}` or a custom robot.
#[derive(Clone, Debug, PartialEq)]
pub enum RobotSpec {
    /// A built-in robot.
    Preset(Preset),
    /// A custom joint table (mm and degrees, not yet validated).
    Custom(CustomRobotSpec),
}

impl RobotSpec {
    /// Parse a robot description from JSON; errors are relative to the robot object.
    pub fn from_json_value(v: &Value) -> Result<RobotSpec, DomainError> {
        let Some(obj) = v.as_object() else {
            return Err(DomainError::new("", "must be an object: {\"preset\": \"irb120\"} or a custom robot"));
        };
        if obj.contains_key("preset") {
            let p: PresetSpec = from_value(v)?;
            let preset = Preset::from_name(&p.preset).ok_or_else(|| {
                let known: Vec<&str> = Preset::ALL.iter().map(|p| p.name()).collect();
                DomainError::new("preset", format!("unknown preset '{}', known: {}", p.preset, known.join(", ")))
            })?;
            Ok(RobotSpec::Preset(preset))
        } else {
            Ok(RobotSpec::Custom(from_value(v)?))
        }
    }

    /// The file form: `{"preset": name}` or the custom robot's object.
    pub fn to_json_value(&self) -> Value {
        match self {
            RobotSpec::Preset(p) => serde_json::json!({ "preset": p.name() }),
            RobotSpec::Custom(c) => serde_json::to_value(c).expect("robot spec serialises"),
        }
    }

    /// The SI model, validated: a custom robot's name, gravity, joint fields and limits are
    /// checked (errors name e.g. `joints[2].a_mm`, `gravity_mps2[1]`).
    pub fn to_model(&self) -> Result<RobotModel, DomainError> {
        let c = match self {
            RobotSpec::Preset(p) => return Ok(p.model()),
            RobotSpec::Custom(c) => c,
        };
        super::limits::name(&c.name, "name")?;
        use super::limits;
        let gravity = match c.gravity_mps2 {
            None => Vector3::new(0.0, 0.0, -STANDARD_GRAVITY),
            Some(g) => {
                for (i, x) in g.iter().enumerate() {
                    limits::gravity(*x, &format!("gravity_mps2[{i}]"))?;
                }
                Vector3::new(g[0], g[1], g[2])
            }
        };
        let mut beta_joints = Vec::new();
        let mut rows = Vec::with_capacity(c.joints.len());
        for (j, s) in c.joints.iter().enumerate() {
            let p = |f: &str| format!("joints[{j}].{f}");
            limits::length3_mm(s.com_mm, &p("com_mm"))?;
            let com = vec3_mm(s.com_mm, &p("com_mm"))?;
            for (name, v) in [("alpha_deg", s.alpha_deg), ("theta_deg", s.theta_deg)] {
                limits::angle_deg(v, &p(name))?;
            }
            if let Some(b) = s.beta_deg {
                limits::angle_deg(b, &p("beta_deg"))?;
            }
            for (name, v) in [("a_mm", s.a_mm), ("d_mm", s.d_mm)] {
                limits::length_mm(v, &p(name))?;
            }
            finite(s.mass_kg, &p("mass_kg"))?;
            if s.mass_kg >= 0.0 {
                limits::mass(s.mass_kg, &p("mass_kg"))?;
            }
            for (i, v) in s.limits_deg.iter().enumerate() {
                limits::within(
                    *v,
                    -limits::MAX_JOINT_LIMIT_DEG,
                    limits::MAX_JOINT_LIMIT_DEG,
                    "deg",
                    &format!("joints[{j}].limits_deg[{i}]"),
                )?;
            }
            if s.beta_deg.is_some() {
                beta_joints.push(j);
            }
            rows.push(Link {
                alpha: s.alpha_deg * DEG,
                a: s.a_mm * MM,
                theta: s.theta_deg * DEG,
                d: s.d_mm * MM,
                beta: s.beta_deg.map(|b| b * DEG),
                limits: [s.limits_deg[0] * DEG, s.limits_deg[1] * DEG],
                mass: s.mass_kg,
                com,
            });
        }
        let links = match c.convention {
            Convention::Modified => rows,
            Convention::Standard => {
                let std_rows: Vec<StandardDhRow> = rows
                    .iter()
                    .map(|l| StandardDhRow {
                        theta: l.theta,
                        d: l.d,
                        a: l.a,
                        alpha: l.alpha,
                        limits: l.limits,
                        mass: l.mass,
                        com: l.com,
                    })
                    .collect();
                if std_rows.is_empty() {
                    return Err(DomainError::new("joints", "at least one joint is needed"));
                }
                let (mut links, flange) = modified_from_standard(&std_rows, &beta_joints);
                if flange.iter().any(|v| v.abs() > 1e-15) {
                    let last = c.joints.len() - 1;
                    return Err(DomainError::new(
                        format!("joints[{last}]"),
                        "the last standard-DH row must have a_mm = 0 and alpha_deg = 0 (put that offset in the tool)",
                    ));
                }
                for (l, s) in links.iter_mut().zip(&c.joints) {
                    l.beta = s.beta_deg.map(|b| b * DEG);
                }
                links
            }
        };
        let model = RobotModel { name: c.name.clone(), preset: None, links, gravity };
        model.validate().map_err(model_error)?;
        Ok(model)
    }

    /// The file form of a model: its preset name when it is an unmodified preset.
    pub fn from_model(model: &RobotModel) -> RobotSpec {
        if let Some(p) = model.preset
            && p.model() == *model
        {
            return RobotSpec::Preset(p);
        }
        RobotSpec::Custom(CustomRobotSpec {
            name: model.name.clone(),
            convention: Convention::Modified,
            gravity_mps2: Some([model.gravity.x, model.gravity.y, model.gravity.z]),
            joints: model
                .links
                .iter()
                .map(|l| JointSpec {
                    alpha_deg: l.alpha / DEG,
                    a_mm: l.a / MM,
                    theta_deg: l.theta / DEG,
                    d_mm: l.d / MM,
                    beta_deg: l.beta.map(|b| b / DEG),
                    limits_deg: [l.limits[0] / DEG, l.limits[1] / DEG],
                    mass_kg: l.mass,
                    com_mm: [l.com.x / MM, l.com.y / MM, l.com.z / MM],
                })
                .collect(),
        })
    }
}

fn model_error(e: ModelError) -> DomainError {
    match e {
        ModelError::JointCount(_) => DomainError::new("joints", e.to_string()),
        ModelError::Field { joint, field, reason } => {
            let wire = match field {
                "alpha" => "alpha_deg",
                "a" => "a_mm",
                "theta" => "theta_deg",
                "d" => "d_mm",
                "beta" => "beta_deg",
                "limits" => "limits_deg",
                "mass" => "mass_kg",
                "com" => "com_mm",
                other => other,
            };
            DomainError::new(format!("joints[{joint}].{wire}"), reason)
        }
        ModelError::Gravity(r) => DomainError::new("gravity_mps2", r),
    }
}

/// A tool: TCP position (and optional ZY'X'' orientation) in the flange frame, payload mass and
/// centre of mass in the flange frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct ToolSpec {
    /// TCP position in the flange frame, mm (each within ±10 000).
    #[cfg_attr(feature = "openapi", schema(min_items = 3, max_items = 3))]
    pub tcp_mm: [f64; 3],
    /// TCP orientation in the flange frame, ZY'X'' angles (a, b, c), deg (±360); absent: aligned
    /// with the flange.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "openapi", schema(min_items = 3, max_items = 3))]
    pub tcp_rotation_deg: Option<[f64; 3]>,
    /// Payload mass, kg (0 … 5 000); default 0.
    #[serde(default)]
    #[cfg_attr(feature = "openapi", schema(minimum = 0))]
    pub mass_kg: f64,
    /// Payload centre of mass in the flange frame, mm (each within ±10 000); default the origin.
    #[serde(default)]
    #[cfg_attr(feature = "openapi", schema(min_items = 3, max_items = 3))]
    pub com_mm: [f64; 3],
}

impl ToolSpec {
    /// The SI tool; refuses a field out of bounds or not finite, naming it (`tcp_mm[0]`,
    /// `mass_kg`, …).
    pub fn to_tool(&self) -> Result<Tool, DomainError> {
        use super::limits;
        limits::length3_mm(self.tcp_mm, "tcp_mm")?;
        let t = vec3_mm(self.tcp_mm, "tcp_mm")?;
        let mut tcp = [t.x, t.y, t.z, 0.0, 0.0, 0.0];
        if let Some(r) = self.tcp_rotation_deg {
            limits::angle3_deg(r, "tcp_rotation_deg")?;
            for i in 0..3 {
                tcp[3 + i] = r[i] * DEG;
            }
        }
        let mass = finite(self.mass_kg, "mass_kg")?;
        if mass < 0.0 {
            return Err(DomainError::new("mass_kg", "must not be negative"));
        }
        limits::mass(mass, "mass_kg")?;
        limits::length3_mm(self.com_mm, "com_mm")?;
        Ok(Tool { tcp, mass, com: vec3_mm(self.com_mm, "com_mm")? })
    }

    /// The file form of a tool, in mm and degrees (no `tcp_rotation_deg` when it is zero).
    pub fn from_tool(t: &Tool) -> ToolSpec {
        let rot = [t.tcp[3] / DEG, t.tcp[4] / DEG, t.tcp[5] / DEG];
        ToolSpec {
            tcp_mm: [t.tcp[0] / MM, t.tcp[1] / MM, t.tcp[2] / MM],
            tcp_rotation_deg: rot.iter().any(|v| *v != 0.0).then_some(rot),
            mass_kg: t.mass,
            com_mm: [t.com.x / MM, t.com.y / MM, t.com.z / MM],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::from_json;
    use serde_json::json;

    #[test]
    fn presets_and_custom_robots_parse() {
        let r = RobotSpec::from_json_value(&json!({"preset": "irb120"})).unwrap();
        assert_eq!(r.to_model().unwrap(), crate::kinematics::model::irb120());
        let e = RobotSpec::from_json_value(&json!({"preset": "kuka"})).unwrap_err();
        assert_eq!(e.path, "preset");
        // A custom copy of the IRB 120 round-trips through the file form.
        let spec = RobotSpec::from_model(&RobotModel { preset: None, ..crate::kinematics::model::irb120() });
        let v = spec.to_json_value();
        let back = RobotSpec::from_json_value(&v).unwrap().to_model().unwrap();
        let orig = crate::kinematics::model::irb120();
        for (a, b) in back.links.iter().zip(&orig.links) {
            assert!((a.alpha - b.alpha).abs() < 1e-15 && (a.d - b.d).abs() < 1e-15 && (a.com - b.com).norm() < 1e-15);
            assert_eq!(a.beta.is_some(), b.beta.is_some());
        }
    }

    #[test]
    fn a_standard_table_converts_like_the_ur10_preset() {
        let rows: Vec<Value> = crate::kinematics::model::ur10_standard_dh()
            .iter()
            .enumerate()
            .map(|(j, r)| {
                let mut v = json!({"alpha_deg": r.alpha / DEG, "a_mm": r.a / MM, "d_mm": r.d / MM,
                    "limits_deg": [-360.0, 360.0], "mass_kg": r.mass, "com_mm": [r.com.x / MM, r.com.y / MM, r.com.z / MM]});
                if j == 2 || j == 3 {
                    v["beta_deg"] = json!(0.0);
                }
                v
            })
            .collect();
        let m = RobotSpec::from_json_value(&json!({"name": "ur10-copy", "convention": "standard", "joints": rows}))
            .unwrap()
            .to_model()
            .unwrap();
        let p = crate::kinematics::model::ur10();
        for (a, b) in m.links.iter().zip(&p.links) {
            assert!((a.alpha - b.alpha).abs() < 1e-15 && (a.a - b.a).abs() < 1e-15 && (a.com - b.com).norm() < 1e-15);
            assert_eq!(a.beta, b.beta);
        }
    }

    #[test]
    fn errors_name_the_field() {
        let bad = json!({"name": "x", "joints": [{"alpha_deg": 0, "a_mm": 0, "d_mm": 1, "limits_deg": [10, -10]}]});
        let e = RobotSpec::from_json_value(&bad).unwrap().to_model().unwrap_err();
        assert_eq!(e.path, "joints[0].limits_deg");
        let bad = json!({"name": "x", "joints": [{"alpha_deg": 0, "a_mm": 0, "d_mm": 1, "limits_deg": [-10, 10], "colour": 3}]});
        let e = RobotSpec::from_json_value(&bad).unwrap_err();
        assert!(e.reason.contains("colour"), "{e}");
        let e = from_json::<ToolSpec>(r#"{"tcp_mm": [1, 2]}"#).unwrap_err();
        assert_eq!(e.path, "tcp_mm");
        let e = ToolSpec { tcp_mm: [0.0; 3], tcp_rotation_deg: None, mass_kg: -1.0, com_mm: [0.0; 3] }
            .to_tool()
            .unwrap_err();
        assert_eq!(e.path, "mass_kg");
    }
}
