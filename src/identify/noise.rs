//! The instrument model: the standard deviation of each measurement, for weighted least squares
//! (W = diag(1/σ²), so the weighted residual has unit variance when the model is right) and for
//! the noise floor of the diagnosis.
//!
//! Defaults are the thesis's error budget (Table 2.1, §7) and the laser-tracker figures the
//! virtual cell simulates: TriCal centring within ε = 10 µm with a pair error of about the
//! robot's repeatability, a tracker at 16 µm + 0.8 µm/m (1σ per axis), the IRB 120's 10 µm
//! positional repeatability (ISO 9283 RP = mean + 3σ of the distances, σ = RP/3.616 per axis).

use nalgebra::Vector3;

use crate::cell::Instrument;

/// 1σ per axis of each source, SI units.
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseModel {
    /// A TriCal ball measurement (centring and indicator errors, repeatability excluded), m.
    pub trical: f64,
    /// A laser-tracker position reading: constant part, m…
    pub tracker: f64,
    /// …plus this per metre of the position's distance from the {W} origin (the tracker's own
    /// position is not known to the cell file; the {W} origin stands in for it).
    pub tracker_per_m: f64,
    /// The robot's non-repeatable positioning, per axis, m (added to every position).
    pub repeatability: f64,
    /// A measured orientation, per axis, rad.
    pub rotation: f64,
}

impl Default for NoiseModel {
    fn default() -> Self {
        Self { trical: 5e-6, tracker: 16e-6, tracker_per_m: 0.8e-6, repeatability: 10e-6 / 3.616, rotation: 1e-4 }
    }
}

impl NoiseModel {
    /// σ per axis of a position measured by `instrument` at `position` ({W}), repeatability
    /// included, m.
    pub fn position_sigma(&self, instrument: Instrument, position: &Vector3<f64>) -> f64 {
        let inst = match instrument {
            Instrument::TriCal => self.trical,
            Instrument::LaserTracker => self.tracker + self.tracker_per_m * position.norm(),
        };
        inst.hypot(self.repeatability)
    }

    /// Checks: every σ finite and positive (the repeatability and the distance term may be zero).
    pub fn check(&self) -> Result<(), String> {
        for (name, v, zero_ok) in [
            ("trical", self.trical, false),
            ("tracker", self.tracker, false),
            ("tracker_per_m", self.tracker_per_m, true),
            ("repeatability", self.repeatability, true),
            ("rotation", self.rotation, false),
        ] {
            if !v.is_finite() || v < 0.0 || (!zero_ok && v == 0.0) {
                return Err(format!(
                    "noise model: {name} must be a finite σ{}, got {v}",
                    if zero_ok { " ≥ 0" } else { " > 0" }
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sigmas_combine_in_quadrature() {
        let n = NoiseModel::default();
        let at = Vector3::new(0.0, 3.0, 4.0); // 5 m from the origin
        let s = n.position_sigma(Instrument::LaserTracker, &at);
        let want = ((16e-6f64 + 4e-6).powi(2) + (10e-6f64 / 3.616).powi(2)).sqrt();
        assert!((s - want).abs() < 1e-15);
        let s = n.position_sigma(Instrument::TriCal, &at);
        assert!((s - (25e-12f64 + (10e-6f64 / 3.616).powi(2)).sqrt()).abs() < 1e-15);
        assert!(n.check().is_ok());
        assert!(NoiseModel { tracker: 0.0, ..n.clone() }.check().unwrap_err().contains("tracker"));
        assert!(NoiseModel { repeatability: f64::NAN, ..n }.check().unwrap_err().contains("repeatability"));
    }
}
