//! The quality report a parameter-set file carries (`quality`): what an identification (and an
//! accepted diagnosis) records about its fit — the data it was fitted on, the conditioning and
//! observability of the problem, the residual against the instrument's prediction, the free
//! parameters' correlations, the calibrated envelope — in millimetres and degrees where it has
//! lengths and angles, SI (m, rad) where a field's name says `_si`.
//!
//! Written by [`super::identification::identification_doc`] in the order the fields are declared
//! here, rounded by [`super::rounding::round_json`]. Read leniently: every field may be missing (a
//! file written by an earlier version, or made by hand) and stays `None` — no figure is made up —
//! and `null` reads as `None` too (a figure that was not finite, written by JSON as `null`). A
//! field that is `None` is left out when written: a key is absent when it was not recorded (an
//! older or hand-made file, no selection, no envelope) or its figure was not finite. Keys this
//! version does not know are kept in `other` and written back, so a file passes through
//! unchanged; a known key of the wrong type is refused, naming its path (`quality.kappa_si`).

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use super::validity::EnvelopeFile;

/// `selection` is a JSON object, or `null` (read as absent). Read as a bare `Value` it took
/// anything, so a request with `"selection": [null, null]` — schema-invalid, the schema says
/// object — was stored (schemathesis, ST201). A wrong type is refused like any other known key's.
fn object_or_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<Value>, D::Error> {
    match Option::<Value>::deserialize(d)? {
        None | Some(Value::Null) => Ok(None),
        Some(v @ Value::Object(_)) => Ok(Some(v)),
        Some(other) => {
            let kind = match other {
                Value::Array(_) => "an array",
                Value::String(_) => "a string",
                Value::Number(_) => "a number",
                _ => "a boolean",
            };
            Err(serde::de::Error::custom(format!("expected an object (how the measurements were chosen), got {kind}")))
        }
    }
}

/// An identification's quality report (the `quality` of a parameter-set file).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(default)]
pub struct Quality {
    /// The sessions fitted on, in the order of the problem's tool blocks.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sessions: Option<Vec<String>>,
    /// The measurements fitted on, per session (0-based indices, ascending): what a validation
    /// checks to tell a held-out figure from an in-sample one. A session not listed here but in
    /// `sessions` was fitted on whole.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit_measurements: Option<Vec<FitMeasurements>>,
    /// The measurements the identification was told to leave out (its `exclude`: the outliers a
    /// fit refused), per session, with their fingerprints: a diagnosis of this set leaves the same
    /// readings out, found by their content. Absent when none was left out (and in files of
    /// earlier versions, which did not record them).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub excluded: Option<Vec<FitMeasurements>>,
    /// How the measurements were chosen when a selection ran (DETMAX: `method`, `n`, `seed`,
    /// `pool`, the selection index before and after, exchanges, …); absent when all were used.
    #[cfg_attr(feature = "openapi", schema(value_type = Option<Object>))]
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "object_or_null")]
    pub selection: Option<Value>,
    /// Measurements fitted (the n of O1's normalisation).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub n_measurements: Option<usize>,
    /// Rows of the Jacobian: the measurement rows, then the prior rows.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub n_rows: Option<usize>,
    /// Free (identified) parameters.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub n_parameters: Option<usize>,
    /// Iterations of the solver.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub iterations: Option<usize>,
    /// κ(J) = σ_max/σ_min of the Jacobian in SI units (m, rad), comparable to the thesis's
    /// κ ≤ 1000 criterion; dimensionless.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kappa_si: Option<f64>,
    /// κ of the Jacobian with unit-norm columns (what the `kappa` limit refuses on); dimensionless.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kappa_scaled: Option<f64>,
    /// The observability indices O1–O5 of the Jacobian in SI units.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub observability_si: Option<Observability>,
    /// Residual standard deviation per row, σ̂ = √(‖r‖²/(N − m)), mm; an unweighted fit's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sigma_mm: Option<f64>,
    /// σ̂ of a fit weighted by an instrument model, as a ratio to the instrument's σ (1 when the
    /// model and the instrument model are right); dimensionless. Written instead of `sigma_mm`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sigma_ratio: Option<f64>,
    /// How each parameter's `std` was computed: `classic` (σ̂²(JᵀJ)⁻¹), or
    /// `max(classic, cluster-robust by pose)`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub std_method: Option<String>,
    /// RMS of the measurement residual norms, mm (weighted fits: of the weighted residuals).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rms_residual_mm: Option<f64>,
    /// Singular values of the Jacobian in SI units (m, rad per parameter unit), descending.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub singular_values_si: Option<Vec<f64>>,
    /// The free parameters' names, in the order of `correlation`'s rows and columns.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub free: Option<Vec<String>>,
    /// Correlations of the free parameters (m × m, dimensionless, from σ̂²(JᵀJ)⁻¹); `null` where
    /// one is undefined (a zero standard deviation).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub correlation: Option<Vec<Vec<Option<f64>>>>,
    /// Every tool the identification fitted, its TCP as fitted.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tools: Option<Vec<ToolQuality>>,
    /// Measurements the robust (Huber) loss weighted down, with their weights.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub downweighted: Option<Vec<Downweighted>>,
    /// RMS of the residual the instrument model and the measurements' own σ predict (outliers
    /// left out), mm.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub expected_rms_mm: Option<f64>,
    /// `rms_residual_mm` over `expected_rms_mm` (near 1 when model and noise model are right);
    /// dimensionless.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub residual_ratio: Option<f64>,
    /// The calibrated envelope: the joint ranges and the box of {W} the measurements covered,
    /// with the margins compensation applies; `null` when there were no measurements to take it
    /// from.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub envelope: Option<EnvelopeFile>,
    /// The measurements with the largest residuals, largest first.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub worst: Option<Vec<WorstMeasurement>>,
    /// A payload the sessions do not declare (0 kg) and what the identification made of it: the
    /// mass where the sessions put its centre of mass, and again with it at the flange. Absent
    /// when the sessions declare a payload or the model identifies none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub payload: Option<PayloadQuality>,
    /// Per parameter held because the data leave it undetermined, the free parameters whose
    /// values and σ assume its held value: one σ of it would move them beyond their own.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub conditional: Option<Vec<ConditionalQuality>>,
    /// What the identification noted (parameters held, payload or compliances not determined, …).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub notes: Option<Vec<String>>,
    /// The diagnosis this set was accepted from (an accepted diagnosis's set only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub diagnosis: Option<AcceptedDiagnosis>,
    /// Keys this version does not know (a later version's, or a hand-made file's), kept as they
    /// came and written back after the known ones.
    #[serde(flatten)]
    #[cfg_attr(feature = "openapi", schema(value_type = std::collections::HashMap<String, AnyJson>))]
    pub other: Map<String, Value>,
}

/// The measurements of one session an identification fitted on (in `excluded`: was told to
/// leave out).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct FitMeasurements {
    /// The session's name.
    pub session: String,
    /// 0-based indices of those measurements, ascending (the service writes the stored
    /// indices).
    pub indices: Vec<usize>,
    /// The fingerprint of each of those measurements' content, in the order of `indices`
    /// (`cell::fingerprint`: 16 hexadecimal digits each), which tells them from other readings in a
    /// session of the same name; absent in files of earlier versions (the session's name and the
    /// indices alone then decide).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "openapi", schema(value_type = Option<Vec<String>>))]
    pub fingerprints: Option<Vec<String>>,
    /// Keys this version does not know, kept as they came.
    #[serde(flatten)]
    #[cfg_attr(feature = "openapi", schema(value_type = std::collections::HashMap<String, AnyJson>))]
    pub other: Map<String, Value>,
}

/// The observability indices (Borm & Menq) of the Jacobian in SI units; larger is better.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(default)]
pub struct Observability {
    /// O1 = (σ_1·…·σ_m)^{1/m}/√n, σ_i the singular values, n the measurements.
    #[serde(rename = "O1")]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub o1: Option<f64>,
    /// O2 = σ_min/σ_max (the inverse of κ).
    #[serde(rename = "O2")]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub o2: Option<f64>,
    /// O3 = σ_min.
    #[serde(rename = "O3")]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub o3: Option<f64>,
    /// O4 = σ_min²/σ_max.
    #[serde(rename = "O4")]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub o4: Option<f64>,
    /// O5 = 1/Σ 1/σ_i².
    #[serde(rename = "O5")]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub o5: Option<f64>,
    /// Keys this version does not know, kept as they came.
    #[serde(flatten)]
    #[cfg_attr(feature = "openapi", schema(value_type = std::collections::HashMap<String, AnyJson>))]
    pub other: Map<String, Value>,
}

/// A tool the identification fitted: its TCP as fitted (T_T^6), with uncertainties.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ToolQuality {
    /// The sessions measured with it.
    pub sessions: Vec<String>,
    /// TCP position x, y, z, mm.
    #[cfg_attr(feature = "openapi", schema(min_items = 3, max_items = 3))]
    pub tcp_mm: [f64; 3],
    /// TCP orientation a, b, c (ZY'X''), deg.
    #[cfg_attr(feature = "openapi", schema(min_items = 3, max_items = 3))]
    pub tcp_rotation_deg: [f64; 3],
    /// Standard deviation of each TCP component when identified: x, y, z in mm, a, b, c in deg;
    /// `null` for a component held.
    pub std: Vec<Option<f64>>,
    /// Per TCP component: `identified`, or why it is held.
    pub status: Vec<String>,
    /// Keys this version does not know, kept as they came.
    #[serde(flatten)]
    #[cfg_attr(feature = "openapi", schema(value_type = std::collections::HashMap<String, AnyJson>))]
    pub other: Map<String, Value>,
}

/// A measurement the robust loss weighted down.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Downweighted {
    /// The session's name.
    pub session: String,
    /// 0-based index of the measurement in the session (the service writes the stored index).
    pub index: usize,
    /// Its weight in the fit, 0–1; dimensionless.
    pub weight: f64,
    /// Keys this version does not know, kept as they came.
    #[serde(flatten)]
    #[cfg_attr(feature = "openapi", schema(value_type = std::collections::HashMap<String, AnyJson>))]
    pub other: Map<String, Value>,
}

/// A parameter held because the data leave it undetermined, and the free parameters whose values
/// and σ assume its held value (`quality.conditional`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(default)]
pub struct ConditionalQuality {
    /// The held parameter's name.
    pub held: String,
    /// Its file unit (`mm`, `deg`, `kg`).
    pub unit: String,
    /// The value it is held at, in `unit`.
    pub value: f64,
    /// Its standard deviation as judged when it was held, in `unit`: what the data would leave it.
    pub std: f64,
    /// The free parameters it moves beyond their σ, largest first.
    pub moves: Vec<ConditionalMove>,
    /// Keys this version does not know, kept as they came.
    #[serde(flatten)]
    #[cfg_attr(feature = "openapi", schema(value_type = std::collections::HashMap<String, AnyJson>))]
    pub other: Map<String, Value>,
}

/// A free parameter's least-squares shift per unit of a held one.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(default)]
pub struct ConditionalMove {
    /// The free parameter's name.
    pub name: String,
    /// Its file unit.
    pub unit: String,
    /// Its shift per unit of the held parameter (its unit per the held one's).
    pub per_unit: f64,
    /// Its own standard deviation as reported, in `unit`.
    pub std: f64,
    /// Keys this version does not know, kept as they came.
    #[serde(flatten)]
    #[cfg_attr(feature = "openapi", schema(value_type = std::collections::HashMap<String, AnyJson>))]
    pub other: Map<String, Value>,
}

/// A measurement with a large residual.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct WorstMeasurement {
    /// The session's name.
    pub session: String,
    /// 0-based index of the measurement in the session (the service writes the stored index).
    pub index: usize,
    /// |residual| (position and, for a pose, the weighted rotation), mm.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub residual_mm: Option<f64>,
    /// How many times the typical measurement's residual it is; dimensionless, `null` when the
    /// typical residual is zero.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ratio: Option<f64>,
    /// Keys this version does not know, kept as they came.
    #[serde(flatten)]
    #[cfg_attr(feature = "openapi", schema(value_type = std::collections::HashMap<String, AnyJson>))]
    pub other: Map<String, Value>,
}

/// An undeclared payload as identified (`quality.payload`). The gravity torques of a payload enter
/// the fit only through the compliances, so the data tell its mass little apart from where it
/// sits: each σ holds for the centre of mass its fit assumes, with the robot file's link masses
/// taken as exact, and an effect the model lacks biases the mass beyond it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(default)]
pub struct PayloadQuality {
    /// The mass identified with the centre of mass at `com_mm`, kg; 0 when the data do not
    /// determine it (then held there, and `std_kg` is absent).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mass_kg: Option<f64>,
    /// Its standard deviation, kg; absent when the mass was held as not determined.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub std_kg: Option<f64>,
    /// The centre of mass that fit assumed, in the flange frame, mm (the sessions' tool's: an
    /// import of reflector files puts it at the reflectors' centroid).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "openapi", schema(min_items = 3, max_items = 3))]
    pub com_mm: Option<[f64; 3]>,
    /// The mass identified again with the centre of mass at the flange's origin; absent when that
    /// fit was not run (the mass not determined, the centre of mass already within 1 mm of the
    /// flange, a DETMAX selection, whose subset the second fit would not share, or the set a
    /// diagnosis accepted).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub at_flange: Option<PayloadAtFlangeQuality>,
    /// The mass identified again with the centre of mass free beside it; absent when that fit was
    /// not run (the mass not determined, or a DETMAX selection).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub with_centre_of_mass: Option<PayloadComQuality>,
    /// Keys this version does not know, kept as they came.
    #[serde(flatten)]
    #[cfg_attr(feature = "openapi", schema(value_type = std::collections::HashMap<String, AnyJson>))]
    pub other: Map<String, Value>,
}

/// The undeclared payload identified with its centre of mass at the flange
/// (`identify::payload_at_flange`), or why that fit failed.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(default)]
pub struct PayloadAtFlangeQuality {
    /// The mass, kg; 0 when that fit holds it as not determined.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mass_kg: Option<f64>,
    /// Its standard deviation, kg; absent when that fit holds the mass as not determined.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub std_kg: Option<f64>,
    /// That fit's residual RMS, mm, to set beside the identification's `rms_residual_mm`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rms_residual_mm: Option<f64>,
    /// Why that fit failed (the fit's own error); the other fields are then absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failed: Option<String>,
    /// Keys this version does not know, kept as they came.
    #[serde(flatten)]
    #[cfg_attr(feature = "openapi", schema(value_type = std::collections::HashMap<String, AnyJson>))]
    pub other: Map<String, Value>,
}

/// The undeclared payload's mass identified with its centre of mass
/// (`identify::payload_centre_of_mass`: the first moment beyond `com_mm` fitted too, from the
/// identification's solution), or why that fit failed. Its mass σ includes the uncertainty of
/// where the payload sits, which the identification's own σ does not.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(default)]
pub struct PayloadComQuality {
    /// The mass, kg.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mass_kg: Option<f64>,
    /// Its standard deviation, kg, with the centre of mass free.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub std_kg: Option<f64>,
    /// The centre of mass in the flange frame, mm.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "openapi", schema(min_items = 3, max_items = 3))]
    pub com_mm: Option<[f64; 3]>,
    /// Its standard deviations, mm.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "openapi", schema(min_items = 3, max_items = 3))]
    pub com_std_mm: Option<[f64; 3]>,
    /// Whether these data determine the centre of mass: every σ within 10 mm, κ within its limit
    /// and the mass above 3 of its σ. When not, the reading says how little they tell, and the
    /// identification's mass (at the assumed centre of mass) is the one used.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub determined: Option<bool>,
    /// That fit's residual RMS, mm.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rms_residual_mm: Option<f64>,
    /// Why that fit failed (the fit's own error); the other fields are then absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failed: Option<String>,
    /// Keys this version does not know, kept as they came.
    #[serde(flatten)]
    #[cfg_attr(feature = "openapi", schema(value_type = std::collections::HashMap<String, AnyJson>))]
    pub other: Map<String, Value>,
}

impl PayloadComQuality {
    /// Why these data do not determine the centre of mass, in words (`None` when they do, or
    /// when the reading is absent): the components whose σ is above 10 mm, the mass within 3 of
    /// its σ of 0, or else κ above its limit.
    pub fn undetermined_because(&self) -> Option<String> {
        if self.determined != Some(false) {
            return None;
        }
        let mut why = Vec::new();
        if let Some(s) = self.com_std_mm {
            let wide: Vec<&str> =
                ["x", "y", "z"].into_iter().zip(s).filter(|(_, s)| *s > 10.0).map(|(n, _)| n).collect();
            if !wide.is_empty() {
                why.push(format!("the σ of {} above 10 mm", wide.join(", ")));
            }
        }
        if let (Some(m), Some(s)) = (self.mass_kg, self.std_kg)
            && m <= 3.0 * s
        {
            why.push("the mass within 3 σ of 0".to_string());
        }
        Some(if why.is_empty() { "κ above its limit".to_string() } else { why.join(" and ") })
    }
}

/// The diagnosis a set was accepted from.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(default)]
pub struct AcceptedDiagnosis {
    /// The effects accepted, by their candidate labels.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub accepted: Option<Vec<String>>,
    /// The model fitted, as `robocal identify --model` spells it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model: Option<String>,
    /// Keys this version does not know, kept as they came.
    #[serde(flatten)]
    #[cfg_attr(feature = "openapi", schema(value_type = std::collections::HashMap<String, AnyJson>))]
    pub other: Map<String, Value>,
}

/// Any JSON value — what a key this version does not know may hold — in the OpenAPI document
/// (`serde_json::Value`'s own schema names no type, which the document's checks cannot read).
#[cfg(feature = "openapi")]
pub struct AnyJson;

#[cfg(feature = "openapi")]
impl utoipa::PartialSchema for AnyJson {
    fn schema() -> utoipa::openapi::RefOr<utoipa::openapi::schema::Schema> {
        use utoipa::openapi::schema::{ObjectBuilder, SchemaType, Type};
        let any = [Type::Object, Type::Array, Type::String, Type::Number, Type::Boolean, Type::Null];
        ObjectBuilder::new()
            .schema_type(SchemaType::from_iter(any))
            .description(Some("Any JSON value (a key this version does not know, kept as it came)."))
            .into()
    }
}

#[cfg(feature = "openapi")]
impl utoipa::ToSchema for AnyJson {}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;
    use crate::formats::ParameterSetDoc;
    use crate::formats::identification::run_identification;
    use crate::identify::{IdentifyOptions, NoiseModel};
    use crate::sim::simulate::{SimulateOptions, simulate};

    /// The parameter-set text of an identification of the virtual cell (seed 1), weighted or not,
    /// with a selection recorded.
    fn identification_text(weighted: bool) -> String {
        let sim = simulate(&SimulateOptions { seed: 1, ..Default::default() }).unwrap();
        let opts = IdentifyOptions { noise: weighted.then(NoiseModel::default), ..Default::default() };
        let (_, mut doc) = run_identification(&sim.cell, opts, None, &|| ()).unwrap();
        doc.quality.as_mut().unwrap().selection = Some(json!({"method": "detmax", "n": 75, "converged": true}));
        doc.to_json_pretty()
    }

    /// An identification's document reads back into the same report and writes the same bytes;
    /// the weighted fit writes `sigma_ratio` where the unweighted one writes `sigma_mm`.
    #[test]
    fn an_identifications_document_round_trips_byte_for_byte() {
        for weighted in [false, true] {
            let text = identification_text(weighted);
            let back = ParameterSetDoc::from_json(&text).unwrap();
            assert_eq!(back.to_json_pretty(), text, "weighted: {weighted}");
            let q = back.quality.unwrap();
            assert_eq!((q.sigma_mm.is_some(), q.sigma_ratio.is_some()), (!weighted, weighted));
            assert!(q.other.is_empty(), "every key is known: {:?}", q.other.keys().collect::<Vec<_>>());
            assert!(q.kappa_si.is_some() && q.envelope.is_some() && q.observability_si.unwrap().o1.is_some());
            assert_eq!(q.free.as_ref().map(Vec::len), q.n_parameters);
            let v: Value = serde_json::from_str(&text).unwrap();
            assert!(v["quality"].get(if weighted { "sigma_mm" } else { "sigma_ratio" }).is_none());
            assert!(v["quality"].get("diagnosis").is_none());
        }
    }

    /// A report written by an earlier version (no fit_measurements, std_method, envelope, worst,
    /// notes), one with nulls, and the {free, correlation} a test or an import may carry all read;
    /// what is missing stays `None`.
    #[test]
    fn old_and_partial_reports_read_and_nothing_is_made_up() {
        let old = json!({"sessions": ["trical-1"], "selection": null, "n_measurements": 360, "n_rows": 1080,
            "n_parameters": 31, "iterations": 3, "kappa_si": 2459.0, "kappa_scaled": 281.6,
            "observability_si": {"O1": 0.1265, "O2": null}, "sigma_mm": 0.0048, "rms_residual_mm": 0.0048,
            "singular_values_si": [3.1, 0.2], "free": ["a2", "d4"], "correlation": [[1.0, null], [null, 1.0]],
            "tools": [{"sessions": ["trical-1"], "tcp_mm": [40.0, 0.0, 130.0], "tcp_rotation_deg": [0.0, 0.0, 0.0],
                "std": [0.001, 0.001, 0.002, null, null, null], "status": ["identified", "identified", "identified",
                "orientation not measured", "orientation not measured", "orientation not measured"]}],
            "downweighted": []});
        let q: Quality = serde_json::from_value(old).unwrap();
        assert_eq!(q.kappa_si, Some(2459.0));
        assert_eq!(q.observability_si.as_ref().unwrap().o2, None);
        assert_eq!(q.correlation.as_ref().unwrap()[0], vec![Some(1.0), None]);
        assert_eq!(q.tools.as_ref().unwrap()[0].std[3], None);
        assert_eq!((q.fit_measurements.as_ref(), q.envelope.as_ref(), q.worst.as_ref()), (None, None, None));
        assert_eq!((q.expected_rms_mm, q.residual_ratio, q.sigma_ratio), (None, None, None));
        assert!(q.notes.is_none() && q.std_method.is_none() && q.diagnosis.is_none() && q.other.is_empty());

        let q: Quality = serde_json::from_value(json!({"free": ["a2"], "correlation": [[1.0]]})).unwrap();
        assert_eq!(
            q,
            Quality { free: Some(vec!["a2".into()]), correlation: Some(vec![vec![Some(1.0)]]), ..Default::default() }
        );
        let q: Quality = serde_json::from_value(json!({})).unwrap();
        assert_eq!(q, Quality::default());
        // Written back, what is missing stays missing: no key gets a figure, or a `null`.
        let v = serde_json::to_value(Quality { kappa_si: Some(812.5), ..Default::default() }).unwrap();
        assert_eq!(v, json!({"kappa_si": 812.5}));
    }

    /// A known key of the wrong type is refused, named by its path in the file.
    #[test]
    fn a_wrong_typed_field_is_refused_naming_it() {
        let text = identification_text(false);
        let refused = |from: &str, to: &str| {
            assert!(text.contains(from), "{from}");
            ParameterSetDoc::from_json(&text.replacen(from, to, 1)).unwrap_err()
        };
        let e = refused("\"kappa_si\": ", "\"kappa_si\": \"big\", \"was\": ");
        assert_eq!(e.path, "quality.kappa_si", "{e}");
        let e = refused("\"O1\": ", "\"O1\": [], \"was\": ");
        assert_eq!(e.path, "quality.observability_si.O1", "{e}");
        let e = refused(
            "\"worst\": [\n      {\n        \"session\": ",
            "\"worst\": [\n      {\n        \"session\": 7, \"was\": ",
        );
        assert_eq!(e.path, "quality.worst[0].session", "{e}");
        let e = refused("\"free\": [", "\"free\": [1, ");
        assert_eq!(e.path, "quality.free[0]", "{e}");
        let e = ParameterSetDoc::from_json(r#"{"robot": {"preset": "irb120"}, "quality": [1, 2]}"#).unwrap_err();
        assert_eq!(e.path, "quality", "{e}");
        // `selection` is an object (its content is free): an array, as a fuzzer sent, is refused.
        for bad in ["[null, null]", "\"detmax\"", "75"] {
            let e = refused("\"selection\": {", &format!("\"selection\": {bad}, \"was\": {{"));
            assert_eq!(e.path, "quality.selection", "{bad}: {e}");
            assert!(e.to_string().contains("expected an object"), "{bad}: {e}");
        }
    }

    /// Keys this version does not know — in the report and in its entries — are kept and written
    /// back where they were (after the known ones): the file passes through unchanged.
    #[test]
    fn unknown_keys_survive_a_round_trip() {
        let text = identification_text(false);
        let v: Value = serde_json::from_str(&text).unwrap();
        let mut v2 = v.clone();
        let q = v2["quality"].as_object_mut().unwrap();
        q.insert("uncertainty_model".into(), json!({"a_mm": 0.01, "b": [1, 2]}));
        q.insert("made_by".into(), json!("robocal 9"));
        q["worst"][0].as_object_mut().unwrap().insert("axis".into(), json!(3));
        q["tools"][0].as_object_mut().unwrap().insert("name".into(), json!("TriCal"));
        q["observability_si"].as_object_mut().unwrap().insert("O6".into(), json!(0.5));
        let with = serde_json::to_string_pretty(&v2).unwrap();
        let back = ParameterSetDoc::from_json(&with).unwrap();
        let q = back.quality.as_ref().unwrap();
        assert_eq!(q.other.keys().collect::<Vec<_>>(), ["uncertainty_model", "made_by"]);
        assert_eq!(q.worst.as_ref().unwrap()[0].other["axis"], json!(3));
        assert_eq!(back.to_json_pretty(), with);
    }
}
