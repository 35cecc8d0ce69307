//! Self-contained HTML calibration reports (issue 15): the validation, the identification (a
//! parameter set with its quality and, when there is one, its latest validation), the diagnosis,
//! the study and the cross-validation, each one HTML string with inline CSS and inline SVG plots
//! (plotters' SVG backend) — no script, font, image or stylesheet fetched from anywhere, so a
//! report opens on an offline cell PC. Thesis chapter 5 is the reference set of pictures.
//!
//! The inputs are the documents the two front ends already share: the validation and diagnosis
//! reports in their wire form (mm, deg; what the service stores and `robocal validate` /
//! `robocal diagnose` write), the parameter-set file, and the study's and cross-validation's typed
//! results. The CLI and the service call the same function on the same document, so they write
//! the same HTML, byte for byte.
//!
//! Plots are ~900 px wide, axes titled with units, and told apart by lightness, marker shape and
//! dash as well as hue, so they survive grey-scale printing.

pub mod diagnosis;
pub mod history;
pub mod html;
pub mod iso9283;
pub mod parameters;
pub mod plot;
pub mod studies;
pub mod validation;

pub use diagnosis::diagnosis_report;
pub use history::{HistoryPoint, history_report};
pub use parameters::{ReportSource, parameter_set_report};
pub use studies::{crossval_report, study_report};
pub use validation::{read_validation, validation_report};

#[cfg(test)]
mod tests;
