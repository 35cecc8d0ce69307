//! Truth files written by `robocal simulate --truth-out`: the true parameter set (effect terms
//! included, so any tool that reads parameter sets can evaluate it), the effects that made it and
//! those outside the parameter vector, the noise and seed of the run, and per measurement where
//! the TCP really was. `--truth` reads one back (or a plain parameter-set file).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::param_set::{ParamEntry, ParameterSetDoc, ParameterSetFile};
use super::robot::ToolSpec;
use super::{DomainError, from_json};
use crate::sim::effects::Effects;
use crate::sim::instruments::Noise;
use crate::sim::measure::{MeasurementTruth, RunTruth};
use crate::sim::truth::Truth;
use crate::units::{MM, UM};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseSpec {
    /// `loop` or `uniform-ball` (see `robocal simulate --centring`); absent in older files: loop.
    #[serde(default = "default_centring")]
    pub centring: String,
    pub epsilon_mm: f64,
    pub repeatability_mm: f64,
    pub tracker_sigma_um: f64,
    pub tracker_sigma_um_per_m: f64,
}

fn default_centring() -> String {
    "loop".into()
}

impl NoiseSpec {
    pub fn from_noise(n: &Noise) -> Self {
        Self {
            centring: n.centring.name().into(),
            epsilon_mm: n.epsilon / MM,
            repeatability_mm: n.repeatability / MM,
            // × (1 / UM), exactly 1e6, not ÷ UM: the latter rounds differently (0.8 µm/m has always
            // been written 0.7999999999999999) and would change the bytes of every truth file.
            tracker_sigma_um: n.tracker_sigma * (1.0 / UM),
            tracker_sigma_um_per_m: n.tracker_sigma_per_m * (1.0 / UM),
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationSpec {
    pub seed: u64,
    pub noise: NoiseSpec,
    /// Laser tracker in the robot base frame {0}.
    pub tracker_position_mm: [f64; 3],
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeasurementTruthSpec {
    /// Where the true model puts the TCP at the recorded joints, {W}.
    pub model_position_mm: [f64; 3],
    /// Where the TCP physically was, {W}.
    pub physical_position_mm: [f64; 3],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub centring_offset_mm: Option<[f64; 3]>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SessionTruthSpec {
    pub name: String,
    pub measurements: Vec<MeasurementTruthSpec>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TruthFile {
    pub robot: Value,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tool: Option<ToolSpec>,
    pub parameters: Vec<ParamEntry>,
    pub effects: Effects,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulation: Option<SimulationSpec>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sessions: Vec<SessionTruthSpec>,
}

fn mm(v: &Vector3<f64>) -> [f64; 3] {
    [v.x / MM, v.y / MM, v.z / MM]
}

fn m(v: [f64; 3]) -> Vector3<f64> {
    Vector3::new(v[0], v[1], v[2]) * MM
}

/// Serialise a truth, with the run's settings and per-measurement truth when given.
pub fn truth_to_json(truth: &Truth, run: Option<(&SimulationSpec, &RunTruth)>) -> String {
    let p = ParameterSetDoc::new(truth.set.clone()).to_file();
    let file = TruthFile {
        robot: p.robot,
        tool: p.tool,
        parameters: p.parameters,
        effects: truth.effects.clone(),
        simulation: run.map(|(s, _)| s.clone()),
        sessions: run
            .map(|(_, r)| {
                r.sessions
                    .iter()
                    .map(|(name, ms)| SessionTruthSpec {
                        name: name.clone(),
                        measurements: ms
                            .iter()
                            .map(|t| MeasurementTruthSpec {
                                model_position_mm: mm(&t.model_position),
                                physical_position_mm: mm(&t.physical_position),
                                centring_offset_mm: t.centring_offset.as_ref().map(mm),
                            })
                            .collect(),
                    })
                    .collect()
            })
            .unwrap_or_default(),
    };
    serde_json::to_string_pretty(&file).expect("truth serialises")
}

/// A truth read back: the truth itself and, when the file has it, the run's per-measurement truth.
pub struct ParsedTruth {
    pub truth: Truth,
    pub simulation: Option<SimulationSpec>,
    pub run: Option<RunTruth>,
}

/// Read a truth file, or a plain parameter-set file (a truth without effects).
pub fn parse_truth(text: &str) -> Result<ParsedTruth, DomainError> {
    let v: Value = from_json(text)?;
    if v.get("effects").is_none() {
        let doc = ParameterSetDoc::from_json(text)?;
        return Ok(ParsedTruth { truth: Truth::from_parts(doc.set, Effects::default()), simulation: None, run: None });
    }
    let f: TruthFile = from_json(text)?;
    let doc = ParameterSetFile { robot: f.robot, tool: f.tool, parameters: f.parameters, quality: None }.to_doc()?;
    let run = (!f.sessions.is_empty()).then(|| RunTruth {
        sessions: f
            .sessions
            .iter()
            .map(|s| {
                (
                    s.name.clone(),
                    s.measurements
                        .iter()
                        .map(|t| MeasurementTruth {
                            model_position: m(t.model_position_mm),
                            physical_position: m(t.physical_position_mm),
                            centring_offset: t.centring_offset_mm.map(m),
                        })
                        .collect(),
                )
            })
            .collect(),
    });
    // The joint-angle effects are already parameters of the set; keep the description as is.
    Ok(ParsedTruth { truth: Truth::from_parts(doc.set, f.effects), simulation: f.simulation, run })
}
