//! Output rounding, as README promises: printed numbers at 0.1 µm (mm fields), 1e-6° (deg fields)
//! and 1e-9 (quaternion components) — a tenth of the best instrument's resolution, so rounding
//! never hides a measurable difference — and every other number (ratios, p-values, slopes,
//! compliances) to 12 significant digits, which removes the binary noise of a unit conversion
//! (`-253.83500000000004` → `-253.835`) and nothing a double computed from measurements holds.
//! The field's unit is read from its name (the wire's convention: the unit in every name).

use serde_json::Value;

use crate::units::{OUT_DEG, OUT_MM, OUT_NM, OUT_UNIT, round_to};

/// Significant digits kept of a number whose name carries no unit with an output resolution.
pub const SIGNIFICANT: i32 = 12;

/// `v` rounded to `digits` significant digits (the nearest double to that decimal); non-finite
/// and zero pass through.
pub fn significant(v: f64, digits: i32) -> f64 {
    if !v.is_finite() || v == 0.0 {
        return v;
    }
    let text = format!("{:.*e}", (digits - 1).max(0) as usize, v);
    text.parse().unwrap_or(v)
}

/// The output step of a field, from its name; `None`: significant digits.
fn step(key: &str) -> Option<f64> {
    if key.contains("_per_") {
        return None; // a slope or a rate (mm_per_mm, deg_per_nm): no length or angle resolution
    }
    if key.ends_with("_mm") {
        Some(OUT_MM)
    } else if key.ends_with("_deg") {
        Some(OUT_DEG)
    } else if key == "quaternion" {
        Some(OUT_UNIT)
    } else if key.ends_with("_mrad") {
        Some(1e-5) // 0.01 µrad, finer than 1e-6° (0.017 µrad)
    } else if key.ends_with("_urad") {
        Some(1e-2)
    } else if key.ends_with("_nm") {
        Some(OUT_NM)
    } else {
        None
    }
}

fn round_number(v: f64, step: Option<f64>) -> f64 {
    match step {
        Some(s) => round_to(v, s),
        None => significant(v, SIGNIFICANT),
    }
}

fn walk(v: &mut Value, step: Option<f64>) {
    match v {
        Value::Number(n) if n.is_f64() => {
            let x = n.as_f64().expect("an f64 number");
            if let Some(r) = serde_json::Number::from_f64(round_number(x, step)) {
                *n = r;
            }
        }
        Value::Array(items) => items.iter_mut().for_each(|i| walk(i, step)),
        Value::Object(map) => {
            for (k, item) in map.iter_mut() {
                walk(item, self::step(k));
            }
        }
        _ => {}
    }
}

/// Round every floating-point number of a JSON document by its field's unit (see the module).
pub fn round_json(v: &mut Value) {
    walk(v, None);
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn numbers_round_by_their_fields_unit() {
        let mut v = json!({
            "residual_mm": 8.097108437906426e-13, "x_mm": -253.83500000000004, "mean_mm": 0.054123456789,
            "joints_deg": [29.999999999999996, 1.23456789], "quaternion": [std::f64::consts::FRAC_1_SQRT_2, 1e-12],
            "slope_mm_per_mm": 1.234567e-5, "p": 0.1 + 0.2, "n": 506, "r": -0.5400000000000001,
            "nested": [{"error_mm": [1e-9, 2.00000004]}], "residual_urad": 0.123456, "orientation_error_mrad": 0.0123456789,
            "gravity_torques_nm": [12.3456789], "compliance_deg_per_nm": -3.04480000000001e-2
        });
        round_json(&mut v);
        assert_eq!(v["residual_mm"], json!(0.0));
        assert_eq!(v["x_mm"].to_string(), "-253.835");
        assert_eq!(v["mean_mm"].to_string(), "0.0541");
        assert_eq!(v["joints_deg"], json!([30.0, 1.234568]));
        // 0.70710678118654757 → 0.707106781 (9 decimals).
        assert_eq!(v["quaternion"], json!([(std::f64::consts::FRAC_1_SQRT_2 * 1e9).round() / 1e9, 0.0]));
        assert_eq!(v["quaternion"][0].to_string(), "0.707106781");
        assert_eq!(v["slope_mm_per_mm"], json!(1.234567e-5), "a slope keeps its digits");
        assert_eq!(v["p"].to_string(), "0.3");
        assert_eq!(v["n"], json!(506), "integers untouched");
        assert_eq!(v["r"].to_string(), "-0.54");
        assert_eq!(v["nested"][0]["error_mm"], json!([0.0, 2.0]));
        assert_eq!(v["residual_urad"], json!(0.12));
        assert_eq!(v["orientation_error_mrad"], json!(0.01235));
        assert_eq!(v["gravity_torques_nm"], json!([12.345679]));
        assert_eq!(v["compliance_deg_per_nm"].to_string(), "-0.030448");
        assert_eq!(significant(200_000.0 / 3.0, 12), 66_666.666_666_7);
        assert_eq!(significant(0.0, 12), 0.0);
    }
}
