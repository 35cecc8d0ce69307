//! The TriCal's three orthogonal dial indicators with spherical tips (thesis §2.4.2,
//! eq. 2.8–2.20): from the three readings to the offset of the constrained ball's centre.
//!
//! Frame: the TriCal frame, indicator k measuring along axis k, its tip centre on that axis.
//! A reading is the displacement of the tip centre along its axis from the zero position
//! (positive outwards). Each tip centre lies at R = r_ball + r_tip from the ball centre.

use nalgebra::Vector3;

/// Why readings or a geometry give no ball position.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TriCalError {
    /// A geometry value or reading is not a number it may be (radii: finite and positive; centre
    /// and readings: finite).
    #[error("{field}: {reason}")]
    Field {
        /// The value at fault: `ball_radius`, `tip_radius`, `zero_centre`, or reading `dx`, `dy`
        /// or `dz`.
        field: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// An indicator's axis does not meet the sphere of radius r_ball + r_tip about the ball
    /// centre: its tip cannot touch the ball.
    #[error("indicator {indicator} cannot touch a ball centred at ({x:.4}, {y:.4}, {z:.4}) mm")]
    NoContact {
        /// The indicator, 1-based (1, 2, 3 measure along X, Y, Z of the TriCal frame).
        indicator: usize,
        /// The ball centre's X in the TriCal frame, mm.
        x: f64,
        /// The ball centre's Y in the TriCal frame, mm.
        y: f64,
        /// The ball centre's Z in the TriCal frame, mm.
        z: f64,
    },
    /// Readings (dx, dy, dz), mm, that no ball of the given radius can produce: the displaced tip
    /// centres are (nearly) coincident or collinear, or too far apart to lie at r_ball + r_tip
    /// from one centre.
    #[error("readings ({0:.4}, {1:.4}, {2:.4}) mm are inconsistent with the ball and tip radii")]
    Inconsistent(f64, f64, f64),
}

/// TriCal geometry (SI).
#[derive(Clone, Debug, PartialEq)]
pub struct TriCal {
    /// Radius of the constrained precision ball r₀ (0.5 in diameter: 6.35 mm).
    pub ball_radius: f64,
    /// Radius of the spherical indicator tips r_s (3 mm diameter: 1.5 mm).
    pub tip_radius: f64,
    /// Ball centre P₀ at the zero position, in the TriCal frame.
    pub zero_centre: Vector3<f64>,
}

impl Default for TriCal {
    /// The thesis's instrument: a 0.5 in ball, 3 mm tips, zeroed with the ball centred on the
    /// indicators' common point.
    fn default() -> Self {
        Self { ball_radius: 0.0127 / 2.0, tip_radius: 0.0015, zero_centre: Vector3::zeros() }
    }
}

impl TriCal {
    /// A TriCal of these radii (m) and zero-position ball centre (TriCal frame, m). Refuses radii
    /// that are not finite and positive, a non-finite centre, and a centre some tip cannot touch.
    pub fn new(ball_radius: f64, tip_radius: f64, zero_centre: Vector3<f64>) -> Result<Self, TriCalError> {
        for (field, v) in [("ball_radius", ball_radius), ("tip_radius", tip_radius)] {
            if !v.is_finite() || v <= 0.0 {
                return Err(TriCalError::Field { field, reason: "must be a positive number".into() });
            }
        }
        if zero_centre.iter().any(|v| !v.is_finite()) {
            return Err(TriCalError::Field { field: "zero_centre", reason: "must be finite".into() });
        }
        let t = Self { ball_radius, tip_radius, zero_centre };
        t.tips_for(&zero_centre)?;
        Ok(t)
    }

    fn radius(&self) -> f64 {
        self.ball_radius + self.tip_radius
    }

    /// Tip-centre coordinates along their axes when the ball is centred at `c` (eq. 2.8–2.10:
    /// the outer intersection of each axis with the sphere of radius R about `c`).
    pub(crate) fn tips_for(&self, c: &Vector3<f64>) -> Result<[f64; 3], TriCalError> {
        let r2 = self.radius().powi(2);
        let mut out = [0.0; 3];
        for k in 0..3 {
            let disc = r2 - (c.norm_squared() - c[k] * c[k]);
            if disc < 0.0 {
                return Err(TriCalError::NoContact { indicator: k + 1, x: c.x * 1e3, y: c.y * 1e3, z: c.z * 1e3 });
            }
            out[k] = c[k] + disc.sqrt();
        }
        Ok(out)
    }

    /// Forward simulation: the three readings (m) when the ball centre is at `c`.
    pub fn readings(&self, c: &Vector3<f64>) -> Result<[f64; 3], TriCalError> {
        let zero = self.tips_for(&self.zero_centre)?;
        let now = self.tips_for(c)?;
        Ok([now[0] - zero[0], now[1] - zero[1], now[2] - zero[2]])
    }

    /// Ball centre P₀′ from the readings (eq. 2.11–2.19): trilateration of the three displaced tip
    /// centres in the frame {A} they span, choosing the intersection on the same side of the tips
    /// as the zero-position centre (eq. 2.18's negative root in the thesis's arrangement).
    pub fn centre(&self, d: [f64; 3]) -> Result<Vector3<f64>, TriCalError> {
        for (k, field) in ["dx", "dy", "dz"].into_iter().enumerate() {
            if !d[k].is_finite() {
                return Err(TriCalError::Field { field, reason: "must be a finite number".into() });
            }
        }
        let zero = self.tips_for(&self.zero_centre)?;
        let p = [
            Vector3::new(zero[0] + d[0], 0.0, 0.0),
            Vector3::new(0.0, zero[1] + d[1], 0.0),
            Vector3::new(0.0, 0.0, zero[2] + d[2]),
        ];
        let inconsistent = || TriCalError::Inconsistent(d[0] * 1e3, d[1] * 1e3, d[2] * 1e3);
        // {A}: origin P1', X towards P2', Y in the plane of the three tips (eq. 2.14–2.16).
        let ex = p[1] - p[0];
        let h = ex.norm();
        let ex = ex / h;
        let v3 = p[2] - p[0];
        let i = v3.dot(&ex);
        let ey = v3 - ex * i;
        let j = ey.norm();
        if h < 1e-9 || j < 1e-9 {
            return Err(inconsistent());
        }
        let ey = ey / j;
        let ez = ex.cross(&ey);
        // eq. 2.17
        let x = h / 2.0;
        let y = (i * i + j * j - h * i) / (2.0 * j);
        let z2 = self.radius().powi(2) - x * x - y * y;
        if z2 < 0.0 {
            return Err(inconsistent());
        }
        let side = if (self.zero_centre - p[0]).dot(&ez) <= 0.0 { -1.0 } else { 1.0 };
        Ok(p[0] + ex * x + ey * y + ez * (side * z2.sqrt()))
    }

    /// Offset of the ball centre from its zero position, P₀′ − P₀ (eq. 2.20 is its norm).
    pub fn offset(&self, d: [f64; 3]) -> Result<Vector3<f64>, TriCalError> {
        Ok(self.centre(d)? - self.zero_centre)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Trilateration against a forward simulation of the tips, for the default instrument and for
    /// a zero position off the indicators' common point.
    #[test]
    fn trilateration_inverts_the_tip_simulation() {
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        for tc in [TriCal::default(), TriCal::new(0.00635, 0.0015, Vector3::new(-0.001, 0.0005, -0.0008)).unwrap()] {
            for _ in 0..1000 {
                let off = Vector3::new(
                    rng.random_range(-5e-4..5e-4),
                    rng.random_range(-5e-4..5e-4),
                    rng.random_range(-5e-4..5e-4),
                );
                let c = tc.zero_centre + off;
                let d = tc.readings(&c).unwrap();
                let back = tc.offset(d).unwrap();
                assert!((back - off).norm() < 1e-14, "{}", (back - off).norm());
            }
        }
    }

    /// Spherical tips read the offset to first order (the planar-tip relation eq. 2.1 is the
    /// linearisation); the second-order difference is |o|²/(2R) at most.
    #[test]
    fn small_offsets_read_as_the_offset() {
        let tc = TriCal::default();
        let r = tc.ball_radius + tc.tip_radius;
        let off = Vector3::new(6e-6, -5e-6, 5e-6);
        let d = tc.readings(&off).unwrap();
        for k in 0..3 {
            assert!((d[k] - off[k]).abs() <= off.norm_squared() / (2.0 * r) + 1e-18);
        }
    }

    #[test]
    fn impossible_readings_are_errors() {
        let tc = TriCal::default();
        assert!(matches!(tc.centre([0.02, 0.0, 0.0]), Err(TriCalError::Inconsistent(..))));
        assert!(matches!(tc.centre([f64::NAN, 0.0, 0.0]), Err(TriCalError::Field { field: "dx", .. })));
        assert!(matches!(
            tc.readings(&Vector3::new(0.0, 0.05, 0.05)),
            Err(TriCalError::NoContact { indicator: 1, .. })
        ));
        assert!(TriCal::new(-1.0, 0.0015, Vector3::zeros()).is_err());
    }
}
