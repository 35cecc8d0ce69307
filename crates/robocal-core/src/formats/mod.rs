//! The file formats a user of the core needs — robots and tools, parameter sets, cells, and the
//! validation and diagnosis documents the CLI, the service and the Python package write — in millimetres
//! and degrees with the unit in each field's name, parsed once into the core's SI types, and the
//! error every format reports: the path of the field at fault and why. The service's `domain`
//! module re-exports these beside its wire formats. With the `openapi` feature the formats also
//! derive their OpenAPI schemas (utoipa), which the service publishes.

pub mod cell;
pub mod diagnosis;
pub mod diagnosis_spec;
pub mod identification;
pub mod identify_options;
pub mod limits;
pub mod param_set;
pub mod quality;
pub mod robot;
pub mod rounding;
pub mod validation;
pub mod validity;

use std::fmt;

use nalgebra::Vector3;
use serde::de::DeserializeOwned;

pub use param_set::{ParamEntry, ParameterSetDoc, ParameterSetFile};
pub use quality::Quality;
pub use robot::{JointSpec, RobotSpec, ToolSpec};

use crate::units::{DEG, MM};

/// Bad input: where (a JSON-style path such as `parameters[3].value`) and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DomainError {
    /// The field at fault, e.g. `parameters[3].value` or `tool.tcp_mm[2]`; empty: the whole document.
    pub path: String,
    /// Why the field is refused, in words (e.g. "must be a finite number").
    pub reason: String,
}

impl DomainError {
    /// An error at `path` (empty: the whole document) for `reason`.
    pub fn new(path: impl Into<String>, reason: impl Into<String>) -> Self {
        Self { path: path.into(), reason: reason.into() }
    }

    /// The field at fault as a request names it (`None`: the whole document).
    pub fn field(&self) -> Option<String> {
        (!self.path.is_empty()).then(|| self.path.clone())
    }

    /// The same error, nested under `prefix` (unchanged when `prefix` is empty).
    pub fn under(self, prefix: &str) -> Self {
        if prefix.is_empty() { self } else { self.within(prefix) }
    }

    /// The same error, nested under `prefix`.
    pub fn within(self, prefix: &str) -> Self {
        let path = if self.path.is_empty() {
            prefix.to_string()
        } else if self.path.starts_with('[') {
            format!("{prefix}{}", self.path)
        } else {
            format!("{prefix}.{}", self.path)
        };
        Self { path, reason: self.reason }
    }
}

impl fmt::Display for DomainError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.path.is_empty() { f.write_str(&self.reason) } else { write!(f, "{}: {}", self.path, self.reason) }
    }
}

impl std::error::Error for DomainError {}

/// Deserialize JSON text, reporting the path of the first field that does not fit.
pub fn from_json<T: DeserializeOwned>(text: &str) -> Result<T, DomainError> {
    let de = &mut serde_json::Deserializer::from_str(text);
    serde_path_to_error::deserialize(de).map_err(|e| {
        let path = e.path().to_string();
        let reason = e.into_inner().to_string();
        DomainError::new(field_path(&path, &reason), reason)
    })
}

/// The path of the field a deserialisation error is about. serde_path_to_error stops at the
/// object for a missing field ("." at the top level); the field's own name is in the message
/// ("missing field `name`"), so it is appended: `name`, `tool.tcp_mm`.
pub fn field_path(path: &str, reason: &str) -> String {
    let path = if path == "." { "" } else { path };
    // (An unknown field is already in the path.)
    let named =
        reason.strip_prefix("missing field `").and_then(|rest| rest.split('`').next()).filter(|f| !f.is_empty());
    match named {
        Some(f) if path.is_empty() => f.to_string(),
        Some(f) => format!("{path}.{f}"),
        None => path.to_string(),
    }
}

/// Deserialize an already-parsed JSON value, with paths.
pub fn from_value<T: DeserializeOwned>(v: &serde_json::Value) -> Result<T, DomainError> {
    serde_path_to_error::deserialize(v).map_err(|e| {
        let path = e.path().to_string();
        let reason = e.into_inner().to_string();
        DomainError::new(field_path(&path, &reason), reason)
    })
}

/// A finite number, or an error at `path`.
pub fn finite(v: f64, path: &str) -> Result<f64, DomainError> {
    if v.is_finite() { Ok(v) } else { Err(DomainError::new(path, "must be a finite number")) }
}

/// A finite 3-vector in mm → metres.
pub fn vec3_mm(v: [f64; 3], path: &str) -> Result<Vector3<f64>, DomainError> {
    for (i, x) in v.iter().enumerate() {
        finite(*x, &format!("{path}[{i}]"))?;
    }
    Ok(Vector3::new(v[0], v[1], v[2]) * MM)
}

/// Joint values in degrees → radians, checking the count and finiteness.
pub fn joints_deg(v: &[f64], dof: usize, path: &str) -> Result<Vec<f64>, DomainError> {
    if v.len() != dof {
        return Err(DomainError::new(path, format!("expected {dof} joint values, got {}", v.len())));
    }
    v.iter().enumerate().map(|(i, x)| finite(*x, &format!("{path}[{i}]")).map(|x| x * DEG)).collect()
}

/// Radians → degrees for output.
pub fn to_deg(v: &[f64]) -> Vec<f64> {
    v.iter().map(|x| x / DEG).collect()
}

/// `word` with its indefinite article: "an identification", "a validation".
pub fn with_article(word: &str) -> String {
    let vowel = word.chars().next().is_some_and(|c| "aeiouAEIOU".contains(c));
    format!("{} {word}", if vowel { "an" } else { "a" })
}

#[cfg(test)]
mod field_path_tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Inner {
        a: f64,
    }
    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Outer {
        name: String,
        inner: Vec<Inner>,
    }

    /// Missing and unknown fields are named by their own path, not their parent's.
    #[test]
    fn missing_and_unknown_fields_are_named() {
        assert_eq!(from_json::<Outer>(r#"{"inner": []}"#).unwrap_err().path, "name");
        assert_eq!(from_json::<Outer>(r#"{"name": "n", "inner": [{"a": 1}, {}]}"#).unwrap_err().path, "inner[1].a");
        assert_eq!(from_json::<Outer>(r#"{"name": "n", "inner": [], "x": 1}"#).unwrap_err().path, "x");
        assert_eq!(from_json::<Outer>(r#"{"name": 3, "inner": []}"#).unwrap_err().path, "name");
        assert_eq!(field_path(".", "invalid type"), "");
        assert_eq!(with_article("identification"), "an identification");
        assert_eq!(with_article("validation"), "a validation");
    }
}
