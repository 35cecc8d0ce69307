//! A diagnosis as asked for: `robocal diagnose`'s flags and a diagnosis request, checked once for
//! both into the library's options, and the diagnosis's input from a parameter-set document.

use serde::{Deserialize, Serialize};

use super::{DomainError, ParameterSetDoc};
use crate::diagnose::{DiagnoseOptions, Input, SearchOptions};
use crate::identify::{Anchor, NoiseModel};
use crate::units::{MM, UM};

fn five() -> usize {
    5
}
fn one() -> u64 {
    1
}

/// The instrument model, 1σ per axis (defaults: the thesis's error budget and the tracker the
/// virtual cell simulates).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields, default)]
pub struct NoiseSpec {
    /// A TriCal ball measurement, µm (1e-6 … 1e6).
    #[cfg_attr(feature = "openapi", schema(minimum = 1e-6, maximum = 1e6))]
    pub trical_um: f64,
    /// A laser-tracker reading: constant part, µm (1e-6 … 1e6)…
    #[cfg_attr(feature = "openapi", schema(minimum = 1e-6, maximum = 1e6))]
    pub tracker_um: f64,
    /// …plus this per metre from the {W} origin, µm/m (0 … 1e6).
    #[cfg_attr(feature = "openapi", schema(minimum = 0, maximum = 1e6))]
    pub tracker_um_per_m: f64,
    /// The robot's positional repeatability RP (ISO 9283), µm (0 … 1e6).
    #[cfg_attr(feature = "openapi", schema(minimum = 0, maximum = 1e6))]
    pub repeatability_um: f64,
    /// A measured orientation, mrad (1e-6 … 1e3).
    #[cfg_attr(feature = "openapi", schema(minimum = 1e-6, maximum = 1e3))]
    pub rotation_mrad: f64,
}

impl Default for NoiseSpec {
    fn default() -> Self {
        let n = NoiseModel::default();
        Self {
            trical_um: n.trical / UM,
            tracker_um: n.tracker / UM,
            tracker_um_per_m: n.tracker_per_m / UM,
            repeatability_um: n.repeatability * 3.616 / UM,
            rotation_mrad: n.rotation * 1e3,
        }
    }
}

impl NoiseSpec {
    /// The σ in SI. On the wire each is bounded (the schema's `minimum`/`maximum`): an instrument
    /// σ from 1e-6 µm (1e-6 mrad), so that it stays positive in SI and its inverse square
    /// (the weight) finite, up to 1 m (1 rad); the others from 0.
    pub fn to_model(&self) -> Result<NoiseModel, DomainError> {
        for (field, v, lo, hi) in [
            ("noise.trical_um", self.trical_um, 1e-6, 1e6),
            ("noise.tracker_um", self.tracker_um, 1e-6, 1e6),
            ("noise.tracker_um_per_m", self.tracker_um_per_m, 0.0, 1e6),
            ("noise.repeatability_um", self.repeatability_um, 0.0, 1e6),
            ("noise.rotation_mrad", self.rotation_mrad, 1e-6, 1e3),
        ] {
            if !(v.is_finite() && (lo..=hi).contains(&v)) {
                return Err(DomainError::new(field, format!("must be a σ from {lo:e} to {hi:e}, got {v}")));
            }
        }
        let m = NoiseModel {
            trical: self.trical_um * UM,
            tracker: self.tracker_um * UM,
            tracker_per_m: self.tracker_um_per_m * UM,
            repeatability: self.repeatability_um * UM / 3.616,
            rotation: self.rotation_mrad * 1e-3,
            own: true,
        };
        m.check().map_err(|e| {
            let field = ["trical", "tracker_per_m", "tracker", "repeatability", "rotation"]
                .into_iter()
                .find(|f| e.contains(&format!(": {f} ")))
                .map(|f| match f {
                    "trical" => "noise.trical_um",
                    "tracker" => "noise.tracker_um",
                    "tracker_per_m" => "noise.tracker_um_per_m",
                    "repeatability" => "noise.repeatability_um",
                    _ => "noise.rotation_mrad",
                })
                .unwrap_or("noise");
            DomainError::new(field, "must be a finite, non-negative σ (positive for the instrument terms)")
        })?;
        Ok(m)
    }
}

/// A diagnosis as requested. Every field has a default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct DiagnoseSpec {
    /// Identification sessions (names); default: every identification session.
    #[serde(default)]
    pub identification: Vec<String>,
    /// Validation sessions; omitted: every validation session; `[]`: none — the identification
    /// sessions are cross-validated on themselves.
    #[serde(default)]
    pub validation: Option<Vec<String>>,
    /// Folds of the grouped cross-validation (≥ 2).
    #[serde(default = "five")]
    #[cfg_attr(feature = "openapi", schema(minimum = 2, maximum = 20))]
    pub folds: usize,
    /// Seed of the folds' random assignment of poses and of the noise floor's Monte Carlo
    /// (default 1); the same seed gives the same diagnosis.
    #[serde(default = "one")]
    pub seed: u64,
    /// The instrument model (defaults: the thesis's error budget); weights the pooled fits and
    /// sets the noise floor.
    #[serde(default)]
    pub noise: NoiseSpec,
    /// Family-wise error rate of the screening (Holm).
    #[serde(default = "alpha")]
    #[cfg_attr(feature = "openapi", schema(exclusive_minimum = 0, exclusive_maximum = 0.5))]
    pub alpha: f64,
    /// Level of the held-out confirmation.
    #[serde(default = "confirm")]
    #[cfg_attr(feature = "openapi", schema(exclusive_minimum = 0, exclusive_maximum = 0.5))]
    pub confirm_p: f64,
    /// Knot spacing of joint correction tables, deg (0: about 60 knots over each joint's range).
    #[serde(default)]
    #[cfg_attr(feature = "openapi", schema(maximum = 90))]
    pub map_step_deg: u8,
    /// Edge of the workspace voxels, mm (0: automatic, about ten tested positions per voxel).
    #[serde(default)]
    #[cfg_attr(feature = "openapi", schema(minimum = 0))]
    pub voxel_mm: f64,
}

fn alpha() -> f64 {
    SearchOptions::default().alpha
}
fn confirm() -> f64 {
    SearchOptions::default().confirm_p
}

impl Default for DiagnoseSpec {
    fn default() -> Self {
        Self {
            identification: Vec::new(),
            validation: None,
            folds: five(),
            seed: one(),
            noise: NoiseSpec::default(),
            alpha: alpha(),
            confirm_p: confirm(),
            map_step_deg: 0,
            voxel_mm: 0.0,
        }
    }
}

impl DiagnoseSpec {
    /// The checked options; errors name the field.
    pub fn to_options(&self) -> Result<DiagnoseOptions, DomainError> {
        if !(2..=20).contains(&self.folds) {
            return Err(DomainError::new("folds", "must be 2–20"));
        }
        let level = |v: f64, path: &str| {
            if v.is_finite() && v > 0.0 && v < 0.5 {
                Ok(v)
            } else {
                Err(DomainError::new(path, "must be a probability in (0, 0.5)"))
            }
        };
        if !(self.voxel_mm.is_finite() && self.voxel_mm >= 0.0) {
            return Err(DomainError::new("voxel_mm", "must be 0 (automatic) or positive"));
        }
        if self.map_step_deg > 90 {
            return Err(DomainError::new("map_step_deg", "must be 0 (automatic) to 90"));
        }
        let search = SearchOptions {
            alpha: level(self.alpha, "alpha")?,
            confirm_p: level(self.confirm_p, "confirm_p")?,
            map_step_deg: self.map_step_deg,
            ..SearchOptions::default()
        };
        Ok(DiagnoseOptions {
            identification: self.identification.clone(),
            validation: self.validation.clone(),
            noise: self.noise.to_model()?,
            folds: self.folds,
            seed: self.seed,
            search,
            voxel_size: self.voxel_mm * MM,
            anchor: Anchor::default(),
            ..DiagnoseOptions::default()
        })
    }
}

/// The diagnosis's input from a parameter-set document: which parameters its identification
/// fitted (status `identified`), which the user held fixed (kept so), and which readings it was
/// told to leave out (left out).
pub fn input_of<'a>(cell: &'a crate::cell::Cell, doc: &'a ParameterSetDoc) -> Input<'a> {
    let known = doc.status.iter().any(|s| s.is_some());
    let identified = known.then(|| doc.status.iter().map(|s| s.as_deref() == Some("identified")).collect());
    let fixed = doc
        .set
        .layout
        .params()
        .iter()
        .zip(&doc.status)
        .filter(|(_, s)| s.as_deref().is_some_and(|s| s.contains("fixed by the user")))
        .map(|(p, _)| p.to_string())
        .collect();
    let excluded = doc
        .quality
        .iter()
        .flat_map(|q| q.excluded.iter().flatten())
        .flat_map(|f| {
            f.indices
                .iter()
                .enumerate()
                .map(|(k, &i)| (f.session.clone(), i, f.fingerprints.as_ref().and_then(|p| p.get(k).cloned())))
        })
        .collect();
    Input { cell, set: &doc.set, identified, fixed, excluded }
}
