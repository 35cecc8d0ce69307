//! The validation report on the wire: millimetres for positions and distances, milliradians for
//! orientation errors, the unit in every field name. Flat summary fields for the calibrated model
//! at the top level (what a reader compares with the thesis's Table 5.2), the same fields for the
//! nominal model under `nominal`, the same again for each session under `per_session` (its name
//! and purpose, its calibrated figures flat, its nominal ones under `nominal`), and optionally
//! one row per measurement.
//!
//! The service stores the document, and the HTML report reads it back into these types, so they
//! read what earlier versions stored too. Those lack the fields added since, each noted where it
//! is declared: a field a document may lack is an `Option` (or a `Vec` never empty when written),
//! absent meaning "not recorded", never a made-up value. This version writes every one of them
//! (an absent one is skipped when written, so an old document reads and writes back as stored).
//! What was added when:
//! - `per_session`: 2026-11-24 (1c46f89);
//! - `balls_mm` and each residual's `position_mm`: 2026-11-24, with the HTML report (ad0899c);
//! - `validated_envelope`: 2026-11-24 (de0f43f), only for held-out validations since 8de8956;
//! - `held_out`, `fit`, `in_sample_sessions`, `held_out_statement`, `uncertainty`, and each
//!   session's `fitted` and `fitted_measurements`: 2026-11-27 (8de8956);
//! - `notes`: 2026-12-07.

use serde::{Deserialize, Serialize};

use super::cell::PurposeSpec;
use crate::units::{DEG, MM, MRAD};
use crate::validate::normality::ShapiroWilk;
use crate::validate::regression::LinearFit;
use crate::validate::report::{AxisStats, FitData, ModelErrors, Residual, SessionErrors, ValidationReport};
use crate::validate::stats::ErrorStats;

/// A validation report: the errors of a parameter set on the validated sessions' measurements,
/// calibrated (flat at the top level) and nominal (`nominal`), in mm and mrad.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ValidationOut {
    /// The validated sessions, by name.
    pub sessions: Vec<String>,
    /// `identification` or `validation`, per session.
    pub purposes: Vec<PurposeSpec>,
    /// Whether these figures are held out: none of the validated sessions was used to fit the set,
    /// and at least one is a validation session. Only a held-out validation vouches for the set
    /// (the service's compensation gate counts no other). `None`: not recorded (a document stored
    /// before 2026-11-27), which says nothing either way.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out: Option<bool>,
    /// What the set was fitted on, as its document records it. `None`: not recorded (a document
    /// stored before 2026-11-27).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit: Option<FitRecordOut>,
    /// The validated sessions the set was fitted on: their figures are fit residuals. `None`: not
    /// recorded (a document stored before 2026-11-27), not "none of them".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub in_sample_sessions: Option<Vec<String>>,
    /// The same in words. `None`: not recorded (a document stored before 2026-11-27).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out_statement: Option<String>,
    /// The positions the errors are taken against.
    pub reference: ReferenceOut,
    /// The calibrated model's errors (flattened into the top level).
    #[serde(flatten)]
    pub calibrated: ModelErrorsOut,
    /// The same figures for the nominal model (the set's nominal values, the declared tool).
    pub nominal: ModelErrorsOut,
    /// Each session's figures (several reflectors, or sessions of different purposes, apart).
    /// Empty: not recorded (a document stored before 2026-11-24); never empty when written, as a
    /// validation has at least one measurement.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub per_session: Vec<SessionErrorsOut>,
    /// The joint ranges and the box of {W} the held-out sessions cover (validation sessions the
    /// set was not fitted on): where this validation shows the model to hold (compensation
    /// accepts targets there). Absent when the validation is not held out (a document stored
    /// from 2026-11-24 to 2026-11-27 has it whether held out or not; one stored before, never).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub validated_envelope: Option<super::validity::EnvelopeFile>,
    /// What this held-out validation measured about the error the set's parameter covariance
    /// does not predict, and how it grows with distance: compensation's uncertainty per target
    /// reads it. Absent when the validation is not held out.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<super::validity::HeldOutUncertainty>,
    /// One row per measurement, when asked for.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub residuals: Option<Vec<ResidualOut>>,
    /// The artefact's ball centres in {W} (the calibration zone), when the cell has one (and the
    /// document was written after 2026-11-24: an earlier one never records them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub balls_mm: Option<[[f64; 3]; 3]>,
    /// What the validation derived rather than read, in sentences (the approach directions of
    /// sessions that do not log them, for a set with hysteresis). Empty: nothing derived (or a
    /// document stored before 2026-12-07).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

/// What a validation's errors are taken against, as the document spells it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ReferenceOut {
    /// The cell's readings (ball centres, tracker readings).
    Measured,
    /// The simulator's true TCP positions (a virtual cell).
    Truth,
}

/// What a parameter set was fitted on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FitRecordOut {
    /// Whether the set records it (a table typed in or imported from elsewhere does not).
    pub recorded: bool,
    /// The sessions it was fitted on, by name.
    pub sessions: Vec<String>,
}

/// One validated session's figures: calibrated flat, nominal under `nominal`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SessionErrorsOut {
    /// The session, by name.
    pub session: String,
    /// `identification` or `validation`.
    pub purpose: PurposeSpec,
    /// The set was fitted on (some of) this session's measurements. `None`: not recorded (a
    /// document stored before 2026-11-27).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fitted: Option<bool>,
    /// How many of this session's validated measurements the fit used. `None`: not recorded (a
    /// document stored before 2026-11-27).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fitted_measurements: Option<usize>,
    /// The calibrated model's errors on this session (flattened).
    #[serde(flatten)]
    pub calibrated: ModelErrorsOut,
    /// The nominal model's errors on this session.
    pub nominal: ModelErrorsOut,
}

impl SessionErrorsOut {
    fn from_errors(s: &SessionErrors, r: &ValidationReport) -> Self {
        Self {
            session: s.session.clone(),
            purpose: PurposeSpec::from_purpose(s.purpose),
            fitted: Some(r.fit.as_ref().is_some_and(|f| f.has_session(&s.session))),
            fitted_measurements: Some(r.fitted_measurements(&s.session)),
            calibrated: ModelErrorsOut::from_errors(&s.calibrated),
            nominal: ModelErrorsOut::from_errors(&s.nominal),
        }
    }
}

/// One model's errors over the validated measurements (error = reference − model, {W}).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelErrorsOut {
    /// Number of measurements.
    pub n: usize,
    /// Statistics of the position error's magnitude |error|, mm (flattened).
    #[serde(flatten)]
    pub position: ErrorFigures,
    /// Orientation error statistics over the measurements that observed a full pose; `null` when
    /// none did or the reference is the truth.
    pub orientation: Option<OrientationOut>,
    /// Statistics of the signed error along X, Y and Z of {W}.
    pub per_axis: PerAxisOut,
    /// Shapiro–Wilk test of |error|; `null` for fewer than 3 or more than 5000 values, or all
    /// equal.
    pub shapiro: Option<ShapiroOut>,
    /// |error| regressed on the reference position's distance to the base origin; `null` when it
    /// cannot be fitted (n < 3, zero variance).
    pub vs_base_distance: Option<FitOut>,
    /// |error| regressed on the distance to the calibration zone (the artefact's ball centroid);
    /// `null` without an artefact or when it cannot be fitted.
    pub vs_zone_distance: Option<FitOut>,
}

/// Position error magnitudes, mm.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ErrorFigures {
    /// Mean, mm.
    pub mean_mm: f64,
    /// Median, mm.
    pub median_mm: f64,
    /// Sample standard deviation (divisor n − 1; 0 for one value), mm.
    pub std_mm: f64,
    /// Root mean square, mm.
    pub rms_mm: f64,
    /// 95th percentile (linear interpolation), mm.
    pub p95_mm: f64,
    /// Largest, mm.
    pub max_mm: f64,
}

impl ErrorFigures {
    /// The figures of error statistics in metres, converted to mm.
    pub fn of(s: &ErrorStats) -> Self {
        ErrorFigures {
            mean_mm: s.mean / MM,
            median_mm: s.median / MM,
            std_mm: s.std / MM,
            rms_mm: s.rms / MM,
            p95_mm: s.p95 / MM,
            max_mm: s.max / MM,
        }
    }
}

/// Statistics of the orientation error (the angle of R_ref·R_modelᵀ), mrad.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OrientationOut {
    /// Number of full-pose measurements.
    pub n: usize,
    /// Mean, mrad.
    pub mean_mrad: f64,
    /// Median, mrad.
    pub median_mrad: f64,
    /// Sample standard deviation (divisor n − 1), mrad.
    pub std_mrad: f64,
    /// Root mean square, mrad.
    pub rms_mrad: f64,
    /// 95th percentile, mrad.
    pub p95_mrad: f64,
    /// Largest, mrad.
    pub max_mrad: f64,
}

/// Statistics of the signed error along each axis of {W}.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PerAxisOut {
    /// Along X of {W}.
    pub x: AxisOut,
    /// Along Y of {W}.
    pub y: AxisOut,
    /// Along Z of {W}.
    pub z: AxisOut,
}

/// Statistics of the signed error along one axis of {W}, mm.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AxisOut {
    /// Mean signed error, mm.
    pub mean_mm: f64,
    /// Sample standard deviation (divisor n − 1), mm.
    pub std_mm: f64,
    /// Smallest (most negative) signed error, mm.
    pub min_mm: f64,
    /// Largest signed error, mm.
    pub max_mm: f64,
    /// Shapiro–Wilk W of the signed errors; `null` for fewer than 3 or more than 5000 values, or
    /// all equal.
    pub shapiro_w: Option<f64>,
    /// Its p-value (Royston); `null` with `shapiro_w`.
    pub shapiro_p: Option<f64>,
}

/// A Shapiro–Wilk normality test.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShapiroOut {
    /// W ≤ 1, close to 1 for a normal sample.
    pub w: f64,
    /// Royston's p-value: a small p is evidence against normality.
    pub p: f64,
}

/// |error| = slope·distance + intercept.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FitOut {
    /// Number of points.
    pub n: usize,
    /// Slope, mm of |error| per mm of distance.
    pub slope_mm_per_mm: f64,
    /// Standard error of the slope, mm per mm.
    pub slope_stderr_mm_per_mm: f64,
    /// Intercept: |error| at distance 0, mm.
    pub intercept_mm: f64,
    /// Pearson correlation coefficient.
    pub r: f64,
    /// Coefficient of determination, r².
    pub r2: f64,
    /// Two-sided p-value of a zero slope.
    pub p: f64,
}

/// One measurement's errors.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ResidualOut {
    /// The measurement's session, by name.
    pub session: String,
    /// Index of the measurement within its session (0-based).
    pub index: usize,
    /// Reference − calibrated model, {W}, mm.
    pub error_mm: [f64; 3],
    /// |error_mm|, mm.
    pub error_norm_mm: f64,
    /// Reference − nominal model, {W}, mm.
    pub nominal_error_mm: [f64; 3],
    /// |nominal_error_mm|, mm.
    pub nominal_error_norm_mm: f64,
    /// Orientation error of the calibrated model (angle of R_ref·R_modelᵀ), mrad; absent unless
    /// a full pose was measured and the reference is measured.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub orientation_error_mrad: Option<f64>,
    /// The same for the nominal model, mrad.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nominal_orientation_error_mrad: Option<f64>,
    /// The reference position (measured or true), {W}, mm. `None`: not recorded (a document
    /// stored before 2026-11-24).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position_mm: Option<[f64; 3]>,
    /// Distance of the reference position to the base origin, mm.
    pub distance_to_base_mm: f64,
    /// Distance of the reference position to the artefact's ball centroid, mm; `null` without
    /// an artefact.
    pub distance_to_zone_mm: Option<f64>,
}

impl ValidationOut {
    /// The wire form of a report, with one row per measurement when `include_residuals`;
    /// `uncertainty` is left absent (see [`report_to_json_with`]).
    pub fn from_report(r: &ValidationReport, include_residuals: bool) -> Self {
        let held_out = r.held_out();
        let fit = r.fit.clone().unwrap_or_default();
        Self {
            sessions: r.sessions.clone(),
            purposes: r.purposes.iter().map(|p| PurposeSpec::from_purpose(*p)).collect(),
            held_out: Some(held_out),
            fit: Some(FitRecordOut { recorded: fit.recorded, sessions: fit.sessions.clone() }),
            in_sample_sessions: Some(r.in_sample_sessions()),
            held_out_statement: Some(held_out_statement(r)),
            reference: if r.against_truth { ReferenceOut::Truth } else { ReferenceOut::Measured },
            calibrated: ModelErrorsOut::from_errors(&r.calibrated),
            nominal: ModelErrorsOut::from_errors(&r.nominal),
            per_session: r.per_session.iter().map(|s| SessionErrorsOut::from_errors(s, r)).collect(),
            validated_envelope: r
                .region
                .as_ref()
                .filter(|_| held_out)
                .and_then(super::validity::Envelope::of_region)
                .map(|e| e.file().clone()),
            uncertainty: None,
            residuals: include_residuals.then(|| r.residuals.iter().map(ResidualOut::from_residual).collect()),
            balls_mm: r.balls.map(|b| b.map(|c| [c.x / MM, c.y / MM, c.z / MM])),
            notes: r.notes.clone(),
        }
    }
}

impl ModelErrorsOut {
    /// The wire form of one model's errors, in mm and mrad.
    pub fn from_errors(e: &ModelErrors) -> Self {
        let p = &e.position;
        Self {
            n: p.n,
            position: ErrorFigures::of(p),
            orientation: e.orientation.as_ref().map(OrientationOut::from_stats),
            per_axis: PerAxisOut {
                x: AxisOut::from_axis(&e.per_axis[0]),
                y: AxisOut::from_axis(&e.per_axis[1]),
                z: AxisOut::from_axis(&e.per_axis[2]),
            },
            shapiro: e.shapiro.as_ref().map(ShapiroOut::from_test),
            vs_base_distance: e.vs_base_distance.as_ref().map(FitOut::from_fit),
            vs_zone_distance: e.vs_zone_distance.as_ref().map(FitOut::from_fit),
        }
    }
}

impl OrientationOut {
    fn from_stats(s: &ErrorStats) -> Self {
        Self {
            n: s.n,
            mean_mrad: s.mean / MRAD,
            median_mrad: s.median / MRAD,
            std_mrad: s.std / MRAD,
            rms_mrad: s.rms / MRAD,
            p95_mrad: s.p95 / MRAD,
            max_mrad: s.max / MRAD,
        }
    }
}

impl AxisOut {
    fn from_axis(a: &AxisStats) -> Self {
        Self {
            mean_mm: a.mean / MM,
            std_mm: a.std / MM,
            min_mm: a.min / MM,
            max_mm: a.max / MM,
            shapiro_w: a.shapiro.map(|s| s.w),
            shapiro_p: a.shapiro.map(|s| s.p_value),
        }
    }
}

impl ShapiroOut {
    fn from_test(s: &ShapiroWilk) -> Self {
        Self { w: s.w, p: s.p_value }
    }
}

impl FitOut {
    /// Both axes are lengths, so the slope is unit-free and only the intercept scales.
    fn from_fit(f: &LinearFit) -> Self {
        Self {
            n: f.n,
            slope_mm_per_mm: f.slope,
            slope_stderr_mm_per_mm: f.slope_stderr,
            intercept_mm: f.intercept / MM,
            r: f.r,
            r2: f.r2,
            p: f.p_value,
        }
    }
}

impl ResidualOut {
    fn from_residual(r: &Residual) -> Self {
        let mm = |v: &nalgebra::Vector3<f64>| [v.x / MM, v.y / MM, v.z / MM];
        Self {
            session: r.session.clone(),
            index: r.index,
            error_mm: mm(&r.error),
            error_norm_mm: r.error.norm() / MM,
            nominal_error_mm: mm(&r.nominal_error),
            nominal_error_norm_mm: r.nominal_error.norm() / MM,
            orientation_error_mrad: r.orientation_error.map(|a| a / MRAD),
            nominal_orientation_error_mrad: r.nominal_orientation_error.map(|a| a / MRAD),
            position_mm: Some(mm(&r.position)),
            distance_to_base_mm: r.distance_to_base / MM,
            distance_to_zone_mm: r.distance_to_zone.map(|d| d / MM),
        }
    }
}

/// Whether a validation is held out, in words: what was fitted on what.
pub fn held_out_statement(r: &ValidationReport) -> String {
    let fitted = r.in_sample_sessions();
    let list = |v: &[String]| v.join(", ");
    if !fitted.is_empty() {
        let n: usize = fitted.iter().map(|s| r.fitted_measurements(s)).sum();
        return format!(
            "in-sample, not held out: the set was fitted on {} ({n} of the measurements validated here were in its fit), \
            so these figures are fit residuals; validate it on sessions it was not fitted on",
            list(&fitted)
        );
    }
    let validation: Vec<String> = r
        .sessions
        .iter()
        .zip(&r.purposes)
        .filter(|(_, p)| **p == crate::cell::Purpose::Validation)
        .map(|(s, _)| s.clone())
        .collect();
    if validation.is_empty() {
        return "not held out: no validation session was validated on (identification sessions score the fit, \
               not the model)"
            .into();
    }
    match &r.fit {
        Some(f) if f.recorded => {
            let other: Vec<String> = f.other_data.iter().filter(|s| r.sessions.contains(s)).cloned().collect();
            let also = if other.is_empty() {
                String::new()
            } else {
                let (bear, hold) = if other.len() == 1 { ("bears", "holds") } else { ("bear", "hold") };
                format!(
                    " ({} here {bear} the name of a fitted session but {hold} other measurements than it was fitted on)",
                    list(&other)
                )
            };
            format!(
                "held out: the set was fitted on {}, none of the sessions validated here{also}",
                if f.sessions.is_empty() { "no recorded session".into() } else { list(&f.sessions) }
            )
        }
        _ => format!(
            "held out as far as is known: the set does not record what it was fitted on (a table typed in or \
            imported); validated on {}",
            list(&validation)
        ),
    }
}

/// What a parameter-set document records it was fitted on: `quality.sessions` and
/// `quality.fit_measurements` (identification and an accepted diagnosis write them), joined with
/// `also` (the sessions the store lists for the set). Not recorded when neither names a session.
pub fn fit_data(doc: &super::ParameterSetDoc, also: &[String]) -> FitData {
    let q = doc.quality.as_ref();
    let mut sessions: Vec<String> = q.and_then(|q| q.sessions.clone()).unwrap_or_default();
    for s in also {
        if !sessions.contains(s) {
            sessions.push(s.clone());
        }
    }
    let mut measurements = std::collections::BTreeMap::new();
    for item in q.and_then(|q| q.fit_measurements.as_ref()).into_iter().flatten() {
        let mut ix = item.indices.clone();
        ix.sort_unstable();
        measurements.insert(item.session.clone(), ix);
    }
    // A session the store names but the document's list does not: fitted on whole.
    measurements.retain(|name, _| sessions.contains(name));
    let fingerprints = q
        .and_then(|q| q.fit_measurements.as_ref())
        .into_iter()
        .flatten()
        .filter(|m| sessions.contains(&m.session))
        .filter_map(|m| Some((m.session.clone(), m.fingerprints.clone()?.into_iter().collect())))
        .collect();
    let mut tcps = std::collections::BTreeMap::new();
    for t in q.and_then(|q| q.tools.as_ref()).into_iter().flatten() {
        let (p, r) = (t.tcp_mm, t.tcp_rotation_deg);
        let tcp = [p[0] * MM, p[1] * MM, p[2] * MM, r[0] * DEG, r[1] * DEG, r[2] * DEG];
        for s in t.sessions.iter().filter(|s| sessions.contains(s)) {
            tcps.insert(s.clone(), tcp);
        }
    }
    FitData { recorded: !sessions.is_empty(), sessions, measurements, tcps, fingerprints, other_data: Vec::new() }
}

/// The report as the CLI prints it.
pub fn report_to_json(report: &ValidationReport, include_residuals: bool) -> serde_json::Value {
    report_to_json_with(report, None, include_residuals)
}

/// The report with the uncertainty model a held-out validation measured
/// ([`super::validity::HeldOutUncertainty::of_report`]).
pub fn report_to_json_with(
    report: &ValidationReport,
    uncertainty: Option<super::validity::HeldOutUncertainty>,
    include_residuals: bool,
) -> serde_json::Value {
    let mut out = ValidationOut::from_report(report, include_residuals);
    out.uncertainty = uncertainty;
    let mut v = serde_json::to_value(out).expect("the validation report has only string keys and numbers");
    super::rounding::round_json(&mut v);
    v
}
