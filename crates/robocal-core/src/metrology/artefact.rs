//! The triangular plate of three precision balls that defines the world frame {W} (thesis §2,
//! eq. 4.3–4.7): ball 1 at the origin, ball 2 on +X, ball 3 in the XY plane with positive Y.

use nalgebra::Vector3;

/// Why three distances do not make an artefact.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ArtefactError {
    /// A distance is not a finite positive number.
    #[error("{field}: {reason}")]
    Distance {
        /// The distance at fault: `d12`, `d13` or `d23`.
        field: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// One distance exceeds the sum of the other two (the message names it, in mm).
    #[error("impossible triangle: {0}")]
    Impossible(String),
    /// The balls are (nearly) collinear: ball 3 lies within `MIN_HEIGHT_RATIO`·d12 of the line
    /// through balls 1 and 2.
    #[error("degenerate triangle: {0}")]
    Degenerate(String),
}

/// Ball 3 must stand at least this fraction of d12 off the line through balls 1 and 2 — about
/// 0.6° of apex angle; below it the plate's Y axis is set by measurement noise, not geometry.
pub const MIN_HEIGHT_RATIO: f64 = 0.01;

/// Three ball centres in {W}, from the three measured centre distances (m).
#[derive(Clone, Debug, PartialEq)]
pub struct BallTriangle {
    /// Centre distance of balls 1 and 2, m.
    pub d12: f64,
    /// Centre distance of balls 1 and 3, m.
    pub d13: f64,
    /// Centre distance of balls 2 and 3, m.
    pub d23: f64,
    centres: [Vector3<f64>; 3],
}

impl BallTriangle {
    /// The triangle of three centre distances (m), placed in {W} as the module says
    /// (eq. 4.6–4.7). Refuses a distance that is not finite or not positive, one longer than the
    /// sum of the other two, and ball 3 within [`MIN_HEIGHT_RATIO`]·d12 of the line through balls
    /// 1 and 2.
    pub(crate) fn from_distances(d12: f64, d13: f64, d23: f64) -> Result<Self, ArtefactError> {
        for (field, d) in [("d12", d12), ("d13", d13), ("d23", d23)] {
            if !d.is_finite() {
                return Err(ArtefactError::Distance { field, reason: "must be a finite number".into() });
            }
            if d <= 0.0 {
                return Err(ArtefactError::Distance {
                    field,
                    reason: format!("must be positive, got {:.6} mm", d * 1e3),
                });
            }
        }
        let mut sides = [(d12, "d12"), (d13, "d13"), (d23, "d23")];
        sides.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (longest, name) = sides[2];
        if longest > sides[0].0 + sides[1].0 {
            return Err(ArtefactError::Impossible(format!(
                "{name} = {:.6} mm exceeds the sum of the other two distances ({:.6} mm)",
                longest * 1e3,
                (sides[0].0 + sides[1].0) * 1e3
            )));
        }
        // eq. 4.6–4.7
        let x = (d12 * d12 + d13 * d13 - d23 * d23) / (2.0 * d12);
        let y2 = d13 * d13 - x * x;
        let y = y2.max(0.0).sqrt();
        if y < MIN_HEIGHT_RATIO * d12 {
            return Err(ArtefactError::Degenerate(format!(
                "ball 3 is {:.6} mm from the line through balls 1 and 2 (minimum {:.3} mm): the balls are (nearly) collinear",
                y * 1e3,
                MIN_HEIGHT_RATIO * d12 * 1e3
            )));
        }
        Ok(Self { d12, d13, d23, centres: [Vector3::zeros(), Vector3::new(d12, 0.0, 0.0), Vector3::new(x, y, 0.0)] })
    }

    /// Centre of ball `k` (1-based, as in the files), or `None` when k is not 1, 2 or 3.
    pub fn ball(&self, k: usize) -> Option<Vector3<f64>> {
        (1..=3).contains(&k).then(|| self.centres[k - 1])
    }

    /// The centres of balls 1, 2, 3 in {W}, m.
    pub fn centres(&self) -> &[Vector3<f64>; 3] {
        &self.centres
    }

    /// Centroid of the three balls: the calibration-zone centre of §5.4.1.
    pub fn centroid(&self) -> Vector3<f64> {
        (self.centres[0] + self.centres[1] + self.centres[2]) / 3.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centres_reproduce_the_distances() {
        let t = BallTriangle::from_distances(0.300, 0.320, 0.290).unwrap();
        let c = t.centres();
        assert!(((c[1] - c[0]).norm() - 0.300).abs() < 1e-15);
        assert!(((c[2] - c[0]).norm() - 0.320).abs() < 1e-15);
        assert!(((c[2] - c[1]).norm() - 0.290).abs() < 1e-15);
        assert!(c[2].y > 0.0 && c[2].z == 0.0);
        assert_eq!(t.ball(4), None);
        assert_eq!(t.ball(0), None);
    }

    #[test]
    fn bad_triangles_name_the_problem() {
        assert!(
            matches!(BallTriangle::from_distances(0.3, 0.1, 0.1), Err(ArtefactError::Impossible(m)) if m.contains("d12"))
        );
        assert!(matches!(BallTriangle::from_distances(0.3, 0.1, 0.2), Err(ArtefactError::Degenerate(_))));
        assert!(matches!(BallTriangle::from_distances(0.3, 0.15, 0.150001), Err(ArtefactError::Degenerate(_))));
        assert!(matches!(
            BallTriangle::from_distances(0.3, -0.1, 0.2),
            Err(ArtefactError::Distance { field: "d13", .. })
        ));
        assert!(matches!(
            BallTriangle::from_distances(f64::NAN, 0.1, 0.2),
            Err(ArtefactError::Distance { field: "d12", .. })
        ));
        assert!(matches!(
            BallTriangle::from_distances(0.3, 0.3, 0.0),
            Err(ArtefactError::Distance { field: "d23", .. })
        ));
    }
}
