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

/// Output resolution of positions, mm: 0.1 µm, a tenth of the best instrument's (a laser
/// tracker's) resolution, so rounding never hides a measurable difference.
pub const OUT_MM: f64 = 1e-4;
/// Output resolution of angles (Euler and joint), deg: 1e-6° is 17 nrad, 17 nm at a metre.
pub const OUT_DEG: f64 = 1e-6;
/// Output resolution of unit quaternion components (≈ 2 nrad).
pub const OUT_UNIT: f64 = 1e-9;

/// Output resolution of torques, N·m.
pub const OUT_NM: f64 = 1e-6;

/// `v` rounded to a multiple of `step` (a negative power of ten) for output, without a negative zero: `29.999999999999996`
/// prints as `30`, `-5.38e-31` as `0`. Non-finite values pass through.
pub fn round_to(v: f64, step: f64) -> f64 {
    if !v.is_finite() {
        return v;
    }
    // Multiply by the integer 1/step and divide by it again (rather than multiply by `step`), so
    // the result is the double nearest the decimal: 0.3, not 0.30000000000000004.
    let p = (1.0 / step).round();
    if (v * p).abs() >= 4_503_599_627_370_496.0 {
        return v; // 2⁵²: already an integer number of steps (or beyond any step's reach)
    }
    let r = (v * p).round() / p;
    if r == 0.0 { 0.0 } else { r }
}

/// Every element of `v` rounded to `step` (see [`round_to`]).
pub fn round_all<const N: usize>(v: [f64; N], step: f64) -> [f64; N] {
    v.map(|x| round_to(x, step))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outputs_round_to_their_resolution_without_noise() {
        assert_eq!(round_to(29.999999999999996, OUT_DEG), 30.0);
        assert_eq!(round_to(-5.38e-31, OUT_MM).to_string(), "0");
        assert_eq!(round_to(0.1 + 0.2, OUT_MM).to_string(), "0.3");
        assert_eq!(round_to(374.123456789, OUT_MM), 374.1235);
        assert_eq!(round_to(-std::f64::consts::FRAC_1_SQRT_2, OUT_UNIT).to_string(), "-0.707106781");
        assert_eq!(round_to(1e300, OUT_MM), 1e300);
        assert_eq!(round_to(1e305, OUT_UNIT), 1e305);
        assert!(round_to(f64::NAN, OUT_MM).is_nan());
        // Rounding moves a value by at most half a step.
        for &v in &[123.45678949, -0.00004999, 12345.67891234] {
            assert!((round_to(v, OUT_MM) - v).abs() <= 0.5 * OUT_MM + 1e-12);
        }
    }
}
