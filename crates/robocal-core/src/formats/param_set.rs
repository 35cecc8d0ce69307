//! Parameter-set JSON, the contract every later stage shares:
//! `{"robot": …, "tool": …, "parameters": [{"name": "a2", "value": 270.146, "nominal": 270.0,
//! "unit": "mm"}, …]}` — values in mm, deg, deg/(N·m) and the other units each entry's `unit`
//! names (kg, ppm/K, rad/rad, deg/(N·m)³).
//!
//! On input `parameters` may list a subset: the others take their nominal values. A `nominal`
//! that contradicts the robot's table is refused; for the base and tool (cell-specific, not in
//! the table) a missing `nominal` means "the controller uses this value".

use std::collections::HashSet;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::quality::Quality;
use super::robot::{RobotSpec, ToolSpec};
use super::{DomainError, from_json};
use crate::kinematics::ParameterSet;
use crate::kinematics::model::Tool;
use crate::kinematics::params::{JointTerm, Param, Unit};

/// One parameter of a set: its name, value and nominal value in its unit, and what the
/// identification says of it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct ParamEntry {
    /// The parameter, e.g. `a2`, `d4`, `theta3`, `alpha1`, `beta2`, `c2` (compliance), `base_x`,
    /// `tool_c`; an effect term (cyclic, backlash, coupling, cubic compliance, thermal) not in
    /// the robot's table joins the set. Listed at most once.
    pub name: String,
    /// The value, in `unit` (within ±100 000 mm, ±360 deg, ±5 000 kg, else ±1e6; a compliance
    /// within ±57 deg/(N·m)).
    pub value: f64,
    /// The nominal value, in `unit`; must agree with the robot's table (any value for the base
    /// and tool, which are cell-specific). Absent: the table's (a tool parameter: `tool`'s; a base
    /// parameter: `value` itself).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nominal: Option<f64>,
    /// The unit of `value`, `nominal` and `std` (`mm`, `deg`, `deg/(N·m)`, `kg`, `ppm/K`, …);
    /// absent: the parameter's own, which a given one must match.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
    /// Standard deviation from the identification, in `unit` (≥ 0); absent: not known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub std: Option<f64>,
    /// "identified", or why the parameter was held fixed; absent: not recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub status: Option<String>,
}

/// A parameter-set file as written: the robot, the tool and the parameters in mm and degrees, and
/// the identification's quality report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct ParameterSetFile {
    /// The robot: `{"preset": "irb120"}` or a custom joint table (its nominal model).
    #[cfg_attr(feature = "openapi", schema(value_type = super::robot::RobotDoc))]
    pub robot: Value,
    /// The tool the set was identified with; absent: the bare flange.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tool: Option<ToolSpec>,
    /// The parameters; on input a subset may be listed, the others take their nominal values.
    #[serde(default)]
    pub parameters: Vec<ParamEntry>,
    /// The identification's quality report (its keys this version does not know carried along
    /// unchanged).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quality: Option<Quality>,
}

/// A parameter set with the per-parameter metadata files carry (SI).
#[derive(Clone, Debug, PartialEq)]
pub struct ParameterSetDoc {
    /// The parameter values, nominal values, robot model and tool, SI.
    pub set: ParameterSet,
    /// Per parameter (in the set's order), its standard deviation, SI; `None`: not known.
    pub std: Vec<Option<f64>>,
    /// Per parameter, "identified" or why it was held fixed; `None`: not recorded.
    pub status: Vec<Option<String>>,
    /// The identification's quality report; `None`: none recorded.
    pub quality: Option<Quality>,
}

impl ParameterSetDoc {
    /// `set` with nothing else recorded: no standard deviations, statuses or quality report.
    pub fn new(set: ParameterSet) -> Self {
        let n = set.values.len();
        Self { set, std: vec![None; n], status: vec![None; n], quality: None }
    }

    /// Parse and validate parameter-set JSON text (mm and degrees, as the files carry them).
    ///
    /// ```
    /// use robocal_core::formats::ParameterSetDoc;
    /// use robocal_core::kinematics::Param;
    /// use robocal_core::kinematics::model::irb120;
    /// use robocal_core::kinematics::{ParameterSet, Tool};
    ///
    /// let mut set = ParameterSet::nominal(irb120(), Tool::flange(), [0.0; 6]);
    /// let a2 = set.layout.index_of(Param::A(2)).unwrap();
    /// set.values[a2] += 0.15e-3; // 0.15 mm longer than the table
    /// let text = ParameterSetDoc::new(set.clone()).to_json_pretty();
    /// assert!(text.contains("\"name\": \"a2\"") && text.contains("270.15"), "in mm: {text}");
    /// let back = ParameterSetDoc::from_json(&text)?;
    /// assert!((back.set.values[a2] - set.values[a2]).abs() < 1e-12);
    ///
    /// let err = ParameterSetDoc::from_json(&text.replace("270.15", "-1e400")).unwrap_err();
    /// assert!(err.path.starts_with("parameters["), "the field at fault: {err}");
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn from_json(text: &str) -> Result<Self, DomainError> {
        from_json::<ParameterSetFile>(text)?.to_doc()
    }

    /// The file form: every parameter with its nominal value and unit, in mm and degrees to 12
    /// significant digits, the robot and the tool.
    pub fn to_file(&self) -> ParameterSetFile {
        let s = &self.set;
        let parameters = s
            .layout
            .params()
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let k = p.unit().to_si();
                // In file units to 12 significant digits: the conversion's binary noise
                // (-253.83500000000004) goes, the model keeps its precision (5e-12 relative at worst).
                let out = |v: f64| super::rounding::significant(v / k, super::rounding::SIGNIFICANT);
                ParamEntry {
                    name: p.to_string(),
                    value: out(s.values[i]),
                    nominal: Some(out(s.nominal[i])),
                    unit: Some(p.unit().as_str().to_string()),
                    std: self.std[i].map(out),
                    status: self.status[i].clone(),
                }
            })
            .collect();
        ParameterSetFile {
            robot: RobotSpec::from_model(&s.model).to_json_value(),
            tool: Some(ToolSpec::from_tool(&s.tool)),
            parameters,
            quality: self.quality.clone(),
        }
    }

    /// The file form as indented JSON text.
    pub fn to_json_pretty(&self) -> String {
        serde_json::to_string_pretty(&self.to_file()).expect("parameter set serialises")
    }
}

impl ParameterSetFile {
    /// Check and convert to SI. Refuses a bad robot or tool (under `robot`, `tool`), an unknown
    /// or repeated parameter name, a wrong unit, a value, nominal or std out of bounds, a nominal
    /// contradicting the table and a negative std (each under `parameters[i]`).
    pub fn to_doc(&self) -> Result<ParameterSetDoc, DomainError> {
        let model =
            RobotSpec::from_json_value(&self.robot).and_then(|r| r.to_model()).map_err(|e| e.within("robot"))?;
        let tool = match &self.tool {
            Some(t) => t.to_tool().map_err(|e| e.within("tool"))?,
            None => Tool::flange(),
        };
        let mut set = ParameterSet::nominal(model, tool, [0.0; 6]);
        let mut doc = ParameterSetDoc::new(set.clone());
        let mut seen = HashSet::new();
        for (i, e) in self.parameters.iter().enumerate() {
            let path = |f: &str| format!("parameters[{i}].{f}");
            let idx = match (set.layout.find(&e.name), Param::parse(&e.name)) {
                (Some(idx), _) => idx,
                // An effect term (cyclic, backlash, coupling, cubic compliance, thermal) joins the set.
                (None, Some(p)) if set.layout.admits(p) => set.extend(&[p])[0],
                (None, Some(_)) => {
                    return Err(DomainError::new(
                        path("name"),
                        format!("'{}' is not a parameter of robot '{}'", e.name, set.model.name),
                    ));
                }
                (None, None) => {
                    return Err(DomainError::new(path("name"), format!("unknown parameter name '{}'", e.name)));
                }
            };
            if doc.std.len() < set.values.len() {
                doc.std.resize(set.values.len(), None);
                doc.status.resize(set.values.len(), None);
            }
            if !seen.insert(idx) {
                return Err(DomainError::new(path("name"), format!("'{}' is listed twice", e.name)));
            }
            let p = set.layout.params()[idx];
            let unit = p.unit();
            if let Some(u) = &e.unit
                && Unit::parse(u) != Some(unit)
            {
                return Err(DomainError::new(path("unit"), format!("'{}' is in {}, not '{u}'", e.name, unit.as_str())));
            }
            let k = unit.to_si();
            let bound = |v: f64, field: &str| -> Result<f64, DomainError> {
                let b = match unit {
                    Unit::Mm => super::limits::MAX_POSITION_MM,
                    Unit::Deg => super::limits::MAX_ANGLE_DEG,
                    Unit::Kg => super::limits::MAX_MASS_KG,
                    _ => super::limits::MAX_EFFECT_TERM,
                };
                super::limits::within(v, -b, b, unit.as_str(), &path(field))
            };
            let value = bound(e.value, "value")? * k;
            let table_nominal = set.nominal[idx];
            let nominal = match (e.nominal, p) {
                (Some(n), _) => Some(bound(n, "nominal")? * k),
                (None, Param::Base(_)) => Some(value),
                (None, _) => None,
            };
            if let Some(n) = nominal {
                let from_table = !matches!(p, Param::Base(_) | Param::Tool(_));
                if from_table && (n - table_nominal).abs() > 1e-9 * (1.0 + table_nominal.abs()) {
                    return Err(DomainError::new(
                        path("nominal"),
                        format!(
                            "{} {} contradicts the robot's nominal {} {}",
                            e.nominal.unwrap_or(n / k),
                            unit.as_str(),
                            table_nominal / k,
                            unit.as_str()
                        ),
                    ));
                }
                set.nominal[idx] = n;
            }
            if let Param::Joint(_, JointTerm::Compliance) = p
                && value.abs() > 1.0
            {
                return Err(DomainError::new(path("value"), "a compliance above 57 deg/(N·m) is not a gear"));
            }
            set.values[idx] = value;
            if let Some(sd) = e.std {
                let sd = bound(sd, "std")?;
                if sd < 0.0 {
                    return Err(DomainError::new(path("std"), "must not be negative"));
                }
                doc.std[idx] = Some(sd * k);
            }
            doc.status[idx] = e.status.clone();
        }
        doc.set = set;
        doc.quality = self.quality.clone();
        Ok(doc)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn round_trip_keeps_every_value() {
        let mut set = ParameterSet::nominal(
            crate::kinematics::model::irb120(),
            Tool::flange(),
            [0.1, 0.2, 0.3, 0.01, 0.02, 0.03],
        );
        set.set(Param::A(2), 0.270146);
        set.set(Param::Joint(4, JointTerm::Compliance), -30.448e-3f64.to_radians());
        set.set(Param::Beta(2), 0.039f64.to_radians());
        let mut doc = ParameterSetDoc::new(set);
        doc.std[5] = Some(4e-6);
        doc.status[5] = Some("identified".into());
        let text = doc.to_json_pretty();
        let back = ParameterSetDoc::from_json(&text).unwrap();
        // Written to 12 significant digits in file units.
        for (a, b) in back.set.values.iter().zip(&doc.set.values) {
            assert!((a - b).abs() <= 1e-11 * (1.0 + b.abs()), "{a} vs {b}");
        }
        assert!(!text.contains("00000000"), "no conversion noise in the file: {text}");
        assert_eq!(back.set.nominal.len(), 43);
        assert!((back.std[5].unwrap() - 4e-6).abs() < 1e-11 * 4e-6, "12 significant digits");
        let v: Value = serde_json::from_str(&text).unwrap();
        let a2 = v["parameters"].as_array().unwrap().iter().find(|p| p["name"] == "a2").unwrap();
        assert_eq!(a2["unit"], "mm");
        assert_eq!(a2["value"].as_f64().unwrap(), 270.146);
        assert_eq!(a2["nominal"].as_f64().unwrap(), 270.0);
    }

    #[test]
    fn bad_entries_are_named() {
        let doc = |params: Value| {
            ParameterSetDoc::from_json(&json!({"robot": {"preset": "irb120"}, "parameters": params}).to_string())
                .unwrap_err()
        };
        let e = doc(json!([{"name": "a2", "value": 270.1}, {"name": "a7", "value": 1.0}]));
        assert_eq!(e.path, "parameters[1].name");
        let e = doc(json!([{"name": "beta3", "value": 0.0}]));
        assert!(e.reason.contains("not a parameter"), "{e}");
        let e = doc(json!([{"name": "cyc7_h1_sin", "value": 0.0}]));
        assert!(e.reason.contains("not a parameter"), "{e}");
        let e = doc(json!([{"name": "a2", "value": 270.1, "unit": "m"}]));
        assert_eq!(e.path, "parameters[0].unit");
        let e = doc(json!([{"name": "a2", "value": 270.1, "nominal": 280.0}]));
        assert_eq!(e.path, "parameters[0].nominal");
        let e = doc(json!([{"name": "a2", "value": 1.0}, {"name": "a2", "value": 2.0}]));
        assert!(e.reason.contains("twice"));
        let e = doc(json!([{"name": "a2", "value": "x"}]));
        assert_eq!(e.path, "parameters[0].value");
        let e = ParameterSetDoc::from_json(r#"{"robot": {"preset": "irb120"}, "parametres": []}"#).unwrap_err();
        assert!(e.reason.contains("parametres"));
        let e = ParameterSetDoc::from_json(r#"{"robot": {"name": "x", "joints": []}}"#).unwrap_err();
        assert_eq!(e.path, "robot.joints");
    }

    #[test]
    fn effect_terms_join_the_set_and_round_trip() {
        let text = json!({"robot": {"preset": "irb120"}, "parameters": [
            {"name": "cyc2_h1_sin", "value": 0.01, "unit": "deg"},
            {"name": "coupling5_6", "value": 0.001},
            {"name": "thermal_alpha", "value": 23.0, "unit": "ppm/K"}]})
        .to_string();
        let d = ParameterSetDoc::from_json(&text).unwrap();
        assert_eq!(d.set.values.len(), 46);
        assert!((d.set.value(Param::Thermal).unwrap() - 23e-6).abs() < 1e-18);
        let back = ParameterSetDoc::from_json(&d.to_json_pretty()).unwrap();
        assert_eq!(back.set.layout, d.set.layout);
        assert_eq!(back.set.values, d.set.values);
    }

    #[test]
    fn base_nominal_defaults_to_the_value() {
        let d = ParameterSetDoc::from_json(
            &json!({"robot": {"preset": "irb120"}, "parameters": [{"name": "base_x", "value": 158.865}, {"name": "base_y", "value": -253.8, "nominal": -255.727}]})
                .to_string(),
        )
        .unwrap();
        assert!((d.set.nominal_value(Param::Base(0)).unwrap() - 0.158865).abs() < 1e-15);
        assert!((d.set.nominal_value(Param::Base(1)).unwrap() + 0.255727).abs() < 1e-15);
    }
}
