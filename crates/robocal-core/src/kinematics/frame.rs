//! Rigid frames, elementary rotations and the ZY'X'' Euler convention of the thesis (eq. 3.6–3.7).
//!
//! A [`Frame`] is a rotation matrix and a translation, kept as plain nalgebra fixed-size types:
//! the hot kinematic loops rotate many vectors and compose with elementary rotations, which is
//! cheaper on a 3×3 matrix than on a quaternion.

use nalgebra::{Matrix3, Rotation3, Vector3};

/// A rigid transform: `p_parent = r · p_child + t`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// Rotation: the child frame's axes as columns in the parent frame.
    pub r: Matrix3<f64>,
    /// Origin of the child frame in the parent frame, m.
    pub t: Vector3<f64>,
}

impl Default for Frame {
    fn default() -> Self {
        Self::identity()
    }
}

impl Frame {
    /// The identity transform.
    pub fn identity() -> Self {
        Self { r: Matrix3::identity(), t: Vector3::zeros() }
    }

    /// From a rotation matrix (not checked to be orthonormal) and a translation, m.
    pub fn new(r: Matrix3<f64>, t: Vector3<f64>) -> Self {
        Self { r, t }
    }

    /// `Tr(x, y, z) · Rz(a) · Ry(b) · Rx(c)`: the pose vector χ of eq. 3.6 (metres, radians).
    pub fn from_xyzabc(chi: &[f64; 6]) -> Self {
        Self { r: rot_zyx(chi[3], chi[4], chi[5]), t: Vector3::new(chi[0], chi[1], chi[2]) }
    }

    /// The pose vector χ = (x, y, z, a, b, c) of this frame (ZY'X'' Euler angles).
    pub fn to_xyzabc(&self) -> [f64; 6] {
        let [a, b, c] = zyx_from_rot(&self.r);
        [self.t.x, self.t.y, self.t.z, a, b, c]
    }

    /// `self · other`: with `self` = T_B^A and `other` = T_C^B, returns T_C^A.
    pub fn compose(&self, other: &Frame) -> Frame {
        Frame { r: self.r * other.r, t: self.r * other.t + self.t }
    }

    /// The inverse transform: T_A^B from T_B^A.
    pub fn inverse(&self) -> Frame {
        let rt = self.r.transpose();
        Frame { r: rt, t: -(rt * self.t) }
    }

    /// A point given in the child frame, expressed in the parent frame: `r · p + t`.
    pub fn transform_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.r * p + self.t
    }

    /// Position distance and geodesic rotation angle between two frames (m, rad).
    pub fn distance(&self, other: &Frame) -> (f64, f64) {
        ((self.t - other.t).norm(), rotation_angle(&(self.r.transpose() * other.r)))
    }
}

/// Rotation about x.
pub fn rot_x(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}

/// Rotation about y.
pub fn rot_y(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}

/// Rotation about z.
pub fn rot_z(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}

/// `Rz(a) · Ry(b) · Rx(c)`, the ZY'X'' convention of eq. 3.7.
pub fn rot_zyx(a: f64, b: f64, c: f64) -> Matrix3<f64> {
    let (sa, ca) = a.sin_cos();
    let (sb, cb) = b.sin_cos();
    let (sc, cc) = c.sin_cos();
    Matrix3::new(
        ca * cb,
        -sa * cc + ca * sb * sc,
        sa * sc + ca * sb * cc,
        sa * cb,
        ca * cc + sa * sb * sc,
        -ca * sc + sa * sb * cc,
        -sb,
        cb * sc,
        cb * cc,
    )
}

/// ZY'X'' angles (a, b, c) of a rotation matrix, with b in [−π/2, π/2].
/// At gimbal lock (|b| = π/2) the split between a and c is arbitrary; c = 0 is returned.
pub fn zyx_from_rot(r: &Matrix3<f64>) -> [f64; 3] {
    let cb = (r[(0, 0)] * r[(0, 0)] + r[(1, 0)] * r[(1, 0)]).sqrt();
    let b = (-r[(2, 0)]).atan2(cb);
    if cb > 1e-12 {
        [r[(1, 0)].atan2(r[(0, 0)]), b, r[(2, 1)].atan2(r[(2, 2)])]
    } else {
        [(-r[(0, 1)]).atan2(r[(1, 1)]), b, 0.0]
    }
}

/// Rotation angle of a rotation matrix, accurate near 0 and near π.
pub fn rotation_angle(r: &Matrix3<f64>) -> f64 {
    rotation_vector(r).norm()
}

/// The rotation vector (axis · angle) of a rotation matrix: the log map of SO(3).
///
/// Written by hand because the usual `acos((trace − 1)/2)` (nalgebra's `scaled_axis` among them)
/// loses half the digits near the identity — about 1e-8 rad — which is the regime of every
/// residual and finite difference in this crate. Here the angle is `atan2(|skew|, cos)`, exact to
/// rounding everywhere, with the symmetric part giving the axis near π.
pub fn rotation_vector(r: &Matrix3<f64>) -> Vector3<f64> {
    let v = Vector3::new(r[(2, 1)] - r[(1, 2)], r[(0, 2)] - r[(2, 0)], r[(1, 0)] - r[(0, 1)]) * 0.5;
    let s = v.norm();
    let c = (r.trace() - 1.0) * 0.5;
    let angle = s.atan2(c);
    if c > -0.5 {
        // sin θ carries the axis accurately; θ/sin θ → 1 smoothly as θ → 0.
        if s < 1e-300 {
            return Vector3::zeros();
        }
        return v * (angle / s);
    }
    // Near π: axis from the symmetric part (R + Rᵀ)/2 = cos θ·I + (1 − cos θ)·a·aᵀ, sign from v.
    let d = Vector3::new(r[(0, 0)], r[(1, 1)], r[(2, 2)]);
    let k = d.imax();
    let mut a = Vector3::zeros();
    let one_minus_c = 1.0 - c;
    a[k] = ((d[k] - c) / one_minus_c).max(0.0).sqrt();
    for i in 0..3 {
        if i != k {
            a[i] = (r[(i, k)] + r[(k, i)]) * 0.5 / (one_minus_c * a[k]);
        }
    }
    let a = a.normalize();
    let a = if a.dot(&v) < 0.0 { -a } else { a };
    a * angle
}

/// Unit quaternion (w, x, y, z) of a rotation matrix.
pub fn quaternion_from_rot(r: &Matrix3<f64>) -> [f64; 4] {
    let q = nalgebra::UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r));
    let q = if q.w < 0.0 { -q.into_inner() } else { q.into_inner() };
    [q.w, q.i, q.j, q.k]
}

/// Rotation matrix of a quaternion (w, x, y, z); the quaternion is normalised first.
/// Returns `None` for a zero or non-finite quaternion.
pub fn rot_from_quaternion(q: [f64; 4]) -> Option<Matrix3<f64>> {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    if !n.is_finite() || n < 1e-12 {
        return None;
    }
    let uq = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]));
    Some(*uq.to_rotation_matrix().matrix())
}

/// Wrap an angle to (−π, π].
pub fn wrap_pi(a: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let mut w = a % two_pi;
    if w <= -std::f64::consts::PI {
        w += two_pi;
    } else if w > std::f64::consts::PI {
        w -= two_pi;
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn zyx_matches_the_product_of_elementary_rotations() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for _ in 0..200 {
            let (a, b, c) = (rng.random_range(-3.1..3.1), rng.random_range(-1.5..1.5), rng.random_range(-3.1..3.1));
            let r = rot_zyx(a, b, c);
            let p = rot_z(a) * rot_y(b) * rot_x(c);
            assert!((r - p).abs().max() < 1e-15);
            let [a2, b2, c2] = zyx_from_rot(&r);
            assert!((a - a2).abs() < 1e-12 && (b - b2).abs() < 1e-12 && (c - c2).abs() < 1e-12);
        }
    }

    #[test]
    fn gimbal_lock_still_round_trips_the_rotation() {
        for b in [std::f64::consts::FRAC_PI_2, -std::f64::consts::FRAC_PI_2] {
            let r = rot_zyx(0.3, b, -0.4);
            let [a2, b2, c2] = zyx_from_rot(&r);
            assert!((rot_zyx(a2, b2, c2) - r).abs().max() < 1e-12);
        }
    }

    #[test]
    fn frame_inverse_and_compose() {
        let f = Frame::from_xyzabc(&[0.1, -0.2, 0.3, 0.4, -0.5, 0.6]);
        let i = f.compose(&f.inverse());
        assert!((i.r - Matrix3::identity()).abs().max() < 1e-15);
        assert!(i.t.norm() < 1e-16);
        let chi = f.to_xyzabc();
        assert!((chi[3] - 0.4).abs() < 1e-14 && (chi[4] + 0.5).abs() < 1e-14);
    }

    #[test]
    fn quaternion_round_trip_and_angle() {
        let r = rot_zyx(1.0, 0.2, -2.0);
        let q = quaternion_from_rot(&r);
        assert!((rot_from_quaternion(q).unwrap() - r).abs().max() < 1e-14);
        assert!(rot_from_quaternion([0.0; 4]).is_none());
        assert!((rotation_angle(&rot_x(3.0)) - 3.0).abs() < 1e-12);
        assert!((rotation_angle(&rot_y(1e-9)) - 1e-9).abs() < 1e-20);
    }

    /// The log map against the exponential (Rodrigues) on random axes, angles from 1e-12 to π.
    #[test]
    fn rotation_vector_inverts_rodrigues_everywhere() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        for i in 0..2000 {
            let axis =
                Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
                    .normalize();
            let angle = match i % 4 {
                0 => 10f64.powf(rng.random_range(-12.0..0.0)),
                1 => std::f64::consts::PI - 10f64.powf(rng.random_range(-9.0..0.0)),
                _ => rng.random_range(0.0..std::f64::consts::PI),
            };
            let r = *Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle).matrix();
            let w = rotation_vector(&r);
            let err = (w - axis * angle).norm();
            assert!(err <= 1e-15 + 1e-13 * angle, "angle {angle}: err {err}");
        }
    }

    #[test]
    fn wrap_pi_range() {
        for a in [-10.0, -std::f64::consts::PI, 0.0, 3.0, std::f64::consts::PI, 7.0] {
            let w = wrap_pi(a);
            assert!(w > -std::f64::consts::PI - 1e-15 && w <= std::f64::consts::PI);
            assert!(
                ((a - w) / std::f64::consts::TAU).fract().abs() < 1e-12
                    || ((a - w) / std::f64::consts::TAU).fract().abs() > 1.0 - 1e-12
            );
        }
    }
}
