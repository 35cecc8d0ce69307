//! Rigid registration of point pairs (Kabsch / Horn): the rotation and translation that best map
//! points `a` onto points `b` in the least-squares sense. Used to estimate T_0^W when a cell has
//! no base guess — real tracker data arrive in the tracker's own frame, far from any guess.
//! Takes points, not a cell: the cell's measurements are turned into point pairs by
//! `identify::base`, above this layer.

use nalgebra::{Matrix3, Vector3};

use crate::kinematics::Frame;

/// Why point pairs give no rigid transform.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RegistrationError {
    /// Fewer than 3 point pairs (the count given).
    #[error("registration needs at least 3 point pairs, got {0}")]
    TooFew(usize),
    /// The points are (nearly) collinear: the cross-covariance's second singular value is at most
    /// 1e-12 of the first, so the rotation about their line is undetermined.
    #[error("the points are (nearly) collinear: the rotation about their line is undetermined")]
    Degenerate,
    /// Point pair i (0-based) has a NaN or infinite coordinate.
    #[error("non-finite coordinates in point pair {0}")]
    NonFinite(usize),
}

/// The rigid transform F minimising Σ |F·a_i − b_i|², and its RMS residual (m).
pub fn register(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> Result<(Frame, f64), RegistrationError> {
    assert_eq!(a.len(), b.len(), "point pairs");
    let n = a.len();
    if n < 3 {
        return Err(RegistrationError::TooFew(n));
    }
    if let Some(i) = (0..n).find(|&i| a[i].iter().chain(b[i].iter()).any(|v| !v.is_finite())) {
        return Err(RegistrationError::NonFinite(i));
    }
    let ca = a.iter().sum::<Vector3<f64>>() / n as f64;
    let cb = b.iter().sum::<Vector3<f64>>() / n as f64;
    let mut h = Matrix3::zeros();
    for (p, q) in a.iter().zip(b) {
        h += (p - ca) * (q - cb).transpose();
    }
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u.expect("u"), svd.v_t.expect("v"));
    let s = svd.singular_values;
    // Two vanishing singular values: all points on a line.
    let mut sorted = [s[0], s[1], s[2]];
    sorted.sort_by(|x, y| y.total_cmp(x));
    if sorted[0] <= 0.0 || sorted[1] <= 1e-12 * sorted[0] {
        return Err(RegistrationError::Degenerate);
    }
    let v = v_t.transpose();
    let d = (v * u.transpose()).determinant().signum();
    let r = v * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * u.transpose();
    let t = cb - r * ca;
    let f = Frame::new(r, t);
    let rms = (a.iter().zip(b).map(|(p, q)| (f.transform_point(p) - q).norm_squared()).sum::<f64>() / n as f64).sqrt();
    Ok((f, rms))
}

/// T_0^W from point pairs: the rigid transform that maps the model's TCP positions, computed with
/// the base at identity, onto the observed ones (ball centres or measured positions), as χ
/// (m, rad), and its RMS residual (m). Assembling the pairs from a cell's measurements is the
/// caller's job (`identify::base`).
pub(crate) fn register_base(
    model: &[Vector3<f64>],
    observed: &[Vector3<f64>],
) -> Result<([f64; 6], f64), RegistrationError> {
    let (f, rms) = register(model, observed)?;
    Ok((f.to_xyzabc(), rms))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::frame::rot_zyx;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn recovers_a_random_rigid_transform() {
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        for _ in 0..100 {
            let truth = Frame::new(
                rot_zyx(rng.random_range(-3.0..3.0), rng.random_range(-1.5..1.5), rng.random_range(-3.0..3.0)),
                Vector3::new(rng.random_range(-3.0..3.0), 0.4, -2.0),
            );
            let a: Vec<Vector3<f64>> = (0..20)
                .map(|_| {
                    Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
                })
                .collect();
            let b: Vec<Vector3<f64>> = a.iter().map(|p| truth.transform_point(p)).collect();
            let (f, rms) = register(&a, &b).unwrap();
            assert!((f.r - truth.r).abs().max() < 1e-12 && (f.t - truth.t).norm() < 1e-12 && rms < 1e-12);
        }
    }

    #[test]
    fn three_balls_are_enough_and_lines_are_not() {
        let a = [Vector3::new(0.0, 0.0, 0.0), Vector3::new(0.3, 0.0, 0.0), Vector3::new(0.15, 0.26, 0.0)];
        let f = Frame::new(rot_zyx(1.6, 0.01, -0.02), Vector3::new(0.16, -0.25, -0.22));
        let b: Vec<_> = a.iter().map(|p| f.transform_point(p)).collect();
        let (g, _) = register(&a, &b).unwrap();
        assert!((g.r - f.r).abs().max() < 1e-12);
        let line: Vec<_> = (0..5).map(|i| Vector3::new(i as f64, 0.0, 0.0)).collect();
        assert_eq!(register(&line, &line), Err(RegistrationError::Degenerate));
        assert_eq!(register(&a[..2], &b[..2]), Err(RegistrationError::TooFew(2)));
    }
}
