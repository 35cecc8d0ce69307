//! Validation statistics (thesis §5.4, digest §9): error magnitudes of a model against measured
//! or true positions.

pub mod normality;
pub(crate) mod regression;
pub mod report;
pub mod stats;

pub use regression::LinearFit;
pub use stats::ErrorStats;
