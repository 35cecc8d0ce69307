//! Converters from real data sets' formats into cells.

pub mod three_reflector;
pub mod ur10_ipa;
