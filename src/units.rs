//! Units at the boundary, defined once: the wire and the files use millimetres and degrees (the
//! unit in every field name), the solver metres and radians. Multiply a file value by the
//! constant to get SI; divide to go back.

/// Radians per degree.
pub const DEG: f64 = std::f64::consts::PI / 180.0;
/// Metres per millimetre.
pub const MM: f64 = 1e-3;
/// Metres per micrometre.
pub const UM: f64 = 1e-6;
/// Radians per milliradian.
pub const MRAD: f64 = 1e-3;
