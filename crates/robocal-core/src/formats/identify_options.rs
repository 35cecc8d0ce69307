//! An identification's options as its front ends give them (`robocal identify`'s flags, an
//! identification request, the Python package's keyword arguments), checked once, with the
//! identification's own defaults; errors name the option (`kappa_limit`, `exclude[2].session`),
//! and each front end words them its own way (`--kappa-limit`, `kappa_limit=`).

use serde::{Deserialize, Serialize};

use super::DomainError;
use crate::identify::observability::Index;
use crate::identify::{IdentifyOptions, ModelOptions, NoiseModel, RESIDUAL_RATIO_LIMIT, SolverOptions};
use crate::units::MM;

/// The κ limit when none is given: the identification's own (thesis §4.2.3, κ ≤ 1000).
pub fn default_kappa_limit() -> f64 {
    IdentifyOptions::default().kappa_limit
}

/// The orientation-residual weight when none is given, mm per rad: the identification's own.
pub fn default_rotation_weight_mm() -> f64 {
    IdentifyOptions::default().rotation_weight / MM
}

/// A κ limit: a finite number above 1 (a fit is refused when the column-scaled κ(J) exceeds it).
pub fn kappa_limit(v: f64, path: &str) -> Result<f64, DomainError> {
    if v.is_finite() && v > 1.0 { Ok(v) } else { Err(DomainError::new(path, "must be above 1")) }
}

/// An observability index by name: `O1` … `O5`.
pub fn observability_index(name: &str, path: &str) -> Result<Index, DomainError> {
    Index::parse(name).ok_or_else(|| DomainError::new(path, format!("'{name}' is not O1…O5")))
}

/// The refusal limit of the residual against the instrument's noise when none is given.
pub fn default_residual_ratio_limit() -> f64 {
    RESIDUAL_RATIO_LIMIT
}

/// One measurement of a session: its name and 0-based index (as the quality report's `worst` and
/// `downweighted` entries name it). `robocal identify --exclude` writes it `session:index`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct MeasurementRef {
    /// Name of the session the measurement is in.
    pub session: String,
    /// 0-based (at most 2³¹−1, far beyond any session).
    #[cfg_attr(feature = "openapi", schema(maximum = 2147483647))]
    pub index: usize,
}

impl MeasurementRef {
    /// `reflector-2:40` (the index after the last colon, so session names may hold colons).
    pub fn parse(text: &str, path: &str) -> Result<MeasurementRef, DomainError> {
        let (session, index) = text
            .rsplit_once(':')
            .ok_or_else(|| DomainError::new(path, format!("'{text}' is not session:index (e.g. reflector-2:40)")))?;
        let index = index
            .trim()
            .parse()
            .map_err(|_| DomainError::new(path, format!("'{index}' in '{text}' is not a measurement index")))?;
        if session.trim().is_empty() {
            return Err(DomainError::new(path, format!("'{text}' names no session")));
        }
        Ok(MeasurementRef { session: session.trim().to_string(), index })
    }
}

/// The options of an identification as given, in file units. `robocal identify`'s flags and an
/// identification request both become one, and [`IdentifySpec::to_options`] checks it; errors
/// name the option (`kappa_limit`, `huber`, `rotation_weight_mm`, `model`).
#[derive(Clone, Debug, PartialEq)]
pub struct IdentifySpec {
    /// `+beta,-compliance,+cyc2_h1,…`; empty: geometry + β + compliance.
    pub model: String,
    /// Parameters held at their nominal values.
    pub fix: Vec<String>,
    /// Refuse fits whose column-scaled κ(J) exceeds this.
    pub kappa_limit: f64,
    /// Huber loss threshold in robust standard deviations; `None`: plain least squares.
    pub huber: Option<f64>,
    /// Length weighting orientation residuals of full-pose measurements, mm per rad.
    pub rotation_weight_mm: f64,
    /// Free only these parameters (names, or the groups `base`, `tool` and `zeros`, the joints' zero offsets); empty: all.
    pub only: Vec<String>,
    /// Measurements left out of the fit (outliers).
    pub exclude: Vec<MeasurementRef>,
    /// Weight each residual row by 1/σ: the measurement's own σ where it has one, the default
    /// instrument model's otherwise.
    pub weighted: bool,
    /// Refuse a fit whose residual RMS exceeds this many times the instrument's expected noise.
    pub residual_ratio_limit: f64,
}

impl Default for IdentifySpec {
    fn default() -> Self {
        Self {
            model: String::new(),
            fix: Vec::new(),
            kappa_limit: default_kappa_limit(),
            huber: None,
            rotation_weight_mm: default_rotation_weight_mm(),
            only: Vec::new(),
            exclude: Vec::new(),
            weighted: false,
            residual_ratio_limit: default_residual_ratio_limit(),
        }
    }
}

impl IdentifySpec {
    /// The checked options for a robot of `dof` joints (every session; no subset, no start).
    pub fn to_options(&self, dof: usize) -> Result<IdentifyOptions, DomainError> {
        let kappa_limit = kappa_limit(self.kappa_limit, "kappa_limit")?;
        if self.huber.is_some_and(|k| !k.is_finite() || k <= 0.0) {
            return Err(DomainError::new("huber", "must be a positive threshold"));
        }
        if !self.rotation_weight_mm.is_finite() || self.rotation_weight_mm <= 0.0 {
            return Err(DomainError::new("rotation_weight_mm", "must be positive"));
        }
        let model = ModelOptions::parse(&self.model, dof).map_err(|e| DomainError::new("model", e))?;
        if self.residual_ratio_limit.is_nan() || self.residual_ratio_limit <= 1.0 {
            return Err(DomainError::new("residual_ratio_limit", "must be above 1 (infinite: never refuse)"));
        }
        let mut selection = crate::identify::MeasurementSelection::default();
        for (i, m) in self.exclude.iter().enumerate() {
            if m.session.trim().is_empty() {
                return Err(DomainError::new(format!("exclude[{i}].session"), "must name a session"));
            }
            selection.exclude.push((m.session.clone(), m.index));
        }
        Ok(IdentifyOptions {
            selection,
            noise: self.weighted.then(NoiseModel::default),
            residual_ratio_limit: self.residual_ratio_limit,
            model,
            fixed: self.fix.clone(),
            kappa_limit,
            solver: SolverOptions { huber: self.huber, ..Default::default() },
            rotation_weight: self.rotation_weight_mm * MM,
            only: self.only.clone(),
            ..Default::default()
        })
    }
}

fn o1() -> String {
    "O1".into()
}
fn one() -> u64 {
    1
}

/// DETMAX selection of `n` measurements maximising an observability index (thesis §4.2.5).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct SelectSpec {
    /// Number of measurements to select from the chosen sessions (1 … 100 000).
    #[cfg_attr(feature = "openapi", schema(minimum = 1, maximum = 100000))]
    pub n: usize,
    /// `O1` (default, the thesis's) … `O5`.
    #[serde(default = "o1")]
    pub index: String,
    /// Seed of the random start.
    #[serde(default = "one")]
    pub seed: u64,
}

/// A checked DETMAX selection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DetmaxSelection {
    /// Number of measurements to select (1 … 100 000).
    pub n: usize,
    /// The observability index maximised (O1 … O5).
    pub index: Index,
    /// Seed of the random start.
    pub seed: u64,
}

impl SelectSpec {
    /// Errors name `n` or `index`.
    pub fn to_selection(&self) -> Result<DetmaxSelection, DomainError> {
        if self.n == 0 || self.n > super::limits::MAX_SELECT {
            return Err(DomainError::new("n", format!("must be 1–{}, got {}", super::limits::MAX_SELECT, self.n)));
        }
        Ok(DetmaxSelection { n: self.n, index: observability_index(&self.index, "index")?, seed: self.seed })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The defaults are the identification's own, to the bit, and every option's error names it.
    #[test]
    fn options_are_checked_once_with_the_identifications_defaults() {
        let o = IdentifySpec::default().to_options(6).unwrap();
        let d = IdentifyOptions::default();
        assert_eq!(o.kappa_limit.to_bits(), d.kappa_limit.to_bits());
        assert_eq!(o.rotation_weight.to_bits(), d.rotation_weight.to_bits());
        assert_eq!((o.model, o.solver.huber), (d.model, d.solver.huber));
        let err = |spec: IdentifySpec| spec.to_options(6).unwrap_err().path;
        for k in [f64::NAN, f64::INFINITY, 1.0, 0.5] {
            assert_eq!(err(IdentifySpec { kappa_limit: k, ..Default::default() }), "kappa_limit", "{k}");
        }
        assert_eq!(err(IdentifySpec { huber: Some(0.0), ..Default::default() }), "huber");
        assert_eq!(err(IdentifySpec { rotation_weight_mm: f64::NAN, ..Default::default() }), "rotation_weight_mm");
        assert_eq!(err(IdentifySpec { model: "+warp".into(), ..Default::default() }), "model");
        for k in [f64::NAN, 1.0, -3.0] {
            assert_eq!(err(IdentifySpec { residual_ratio_limit: k, ..Default::default() }), "residual_ratio_limit");
        }
        assert_eq!(o.residual_ratio_limit, crate::identify::RESIDUAL_RATIO_LIMIT);
        assert!(o.noise.is_none(), "unweighted unless asked");
        // Exclusions: session:index, the index after the last colon; they reach the selection.
        let m = MeasurementRef::parse("day:2:17", "exclude").unwrap();
        assert_eq!((m.session.as_str(), m.index), ("day:2", 17));
        for bad in ["r1", "r1:x", ":4", "r1:-1"] {
            assert_eq!(MeasurementRef::parse(bad, "exclude").unwrap_err().path, "exclude", "{bad}");
        }
        let spec = IdentifySpec { exclude: vec![m], weighted: true, ..Default::default() };
        let o = spec.to_options(6).unwrap();
        assert_eq!(o.selection.exclude, [("day:2".to_string(), 17)]);
        assert_eq!(o.noise, Some(crate::identify::NoiseModel::default()));
        let s = |n: usize, index: &str| SelectSpec { n, index: index.into(), seed: 1 }.to_selection();
        assert_eq!(s(0, "O1").unwrap_err().path, "n");
        assert_eq!(s(5, "O9").unwrap_err().path, "index");
        assert_eq!(s(5, "O3").unwrap().index, Index::O3);
    }
}
