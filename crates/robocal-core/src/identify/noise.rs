//! The instrument model: the standard deviation of each measurement, for weighted least squares
//! (W = diag(1/σ²), so the weighted residual has unit variance when the model is right) and for
//! the noise floor of the diagnosis.
//!
//! Defaults are the thesis's error budget (Table 2.1, §7) and the laser-tracker figures the
//! virtual cell simulates: TriCal centring within ε = 10 µm with a pair error of about the
//! robot's repeatability, a tracker at 16 µm + 0.8 µm/m (1σ per axis), the IRB 120's 10 µm
//! positional repeatability (ISO 9283 RP = mean + 3σ of the distances, σ = RP/3.616 per axis).

use nalgebra::Vector3;

use crate::cell::{Instrument, Sigma};

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
    /// Use a measurement's own σ (`sigma_mm`) where it has one; `false`: the model's everywhere.
    pub own: bool,
}

impl Default for NoiseModel {
    fn default() -> Self {
        Self {
            trical: 5e-6,
            tracker: 16e-6,
            tracker_per_m: 0.8e-6,
            repeatability: 10e-6 / 3.616,
            rotation: 1e-4,
            own: true,
        }
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

    /// σ of each residual row of a measurement (positions along X, Y, Z of {W}, then the
    /// rotation about them), repeatability included: the measurement's own σ where it carries one
    /// (a tracker's per-reading standard deviation), the instrument model's where not. Position m,
    /// rotation rad.
    pub fn row_sigmas(&self, instrument: Instrument, position: &Vector3<f64>, own: Option<&Sigma>) -> [f64; 6] {
        let model = self.position_sigma(instrument, position);
        let mut s = [model, model, model, self.rotation, self.rotation, self.rotation];
        if let Some(own) = own.filter(|_| self.own) {
            for k in 0..3 {
                s[k] = own.position[k].hypot(self.repeatability);
            }
            if let Some(r) = own.rotation {
                s[3..].copy_from_slice(&r);
            }
        }
        s
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
        assert!(NoiseModel { repeatability: f64::NAN, ..n.clone() }.check().unwrap_err().contains("repeatability"));
    }

    /// A reading's own σ replaces the instrument's (the repeatability still adds); without one,
    /// the instrument model's σ on every position row and the rotation σ on the rotation rows.
    #[test]
    fn own_sigmas_replace_the_instruments() {
        let n = NoiseModel::default();
        let at = Vector3::new(1.0, 0.0, 0.0);
        let model = n.position_sigma(Instrument::LaserTracker, &at);
        assert_eq!(n.row_sigmas(Instrument::LaserTracker, &at, None), [model, model, model, 1e-4, 1e-4, 1e-4]);
        let own = Sigma { position: [4e-6, 30e-6, 1e-6], rotation: None };
        let s = n.row_sigmas(Instrument::LaserTracker, &at, Some(&own));
        assert_eq!(s[1], 30e-6f64.hypot(n.repeatability));
        assert!(s[2] > n.repeatability && s[2] < 1.1 * n.repeatability, "the repeatability bounds σ below");
        assert_eq!(s[3..], [1e-4; 3]);
        let own = Sigma { rotation: Some([2e-5, 3e-5, 4e-5]), ..own };
        assert_eq!(n.row_sigmas(Instrument::LaserTracker, &at, Some(&own))[3..], [2e-5, 3e-5, 4e-5]);
        let model_only = NoiseModel { own: false, ..n.clone() };
        assert_eq!(
            model_only.row_sigmas(Instrument::LaserTracker, &at, Some(&own)),
            [model, model, model, 1e-4, 1e-4, 1e-4]
        );
    }
}
