//! Hand-written dense kernels on small row-major matrices (Cholesky, its inverse, LDLᵀ
//! determinants, the 3 × 3 case written out) and the sequential faer GEMM the updates use.

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};

/// A pivot of I − D (removal) below this makes the removal leave a singular set.
const SMALL_PIVOT: f64 = 1e-13;

/// dst = lhs · rhs, sequential faer GEMM into a column-major slice.
pub(super) fn gemm(dst: &mut [f64], lhs: MatRef<'_, f64>, rhs: MatRef<'_, f64>) {
    let dst = MatMut::from_column_major_slice_mut(dst, lhs.nrows(), rhs.ncols());
    matmul(dst, Accum::Replace, lhs, rhs, 1.0, Par::Seq);
}

/// a += w·x yᵀ on the lower triangle of a square row-major matrix (x, y of equal length).
#[inline]
pub(super) fn add_outer(a: &mut [f64], x: &[f64], y: &[f64], w: f64) {
    let m = x.len();
    for p in 0..m {
        let wx = w * x[p];
        let row = &mut a[p * m..p * m + p + 1];
        for (e, yq) in row.iter_mut().zip(&y[..=p]) {
            *e += wx * yq;
        }
    }
}

pub(super) fn symmetrise_lower(a: &mut [f64], m: usize) {
    for p in 0..m {
        for q in p + 1..m {
            a[p * m + q] = a[q * m + p];
        }
    }
}

#[inline]
pub(super) fn dot(x: &[f64], y: &[f64]) -> f64 {
    x.iter().zip(y).map(|(a, b)| a * b).sum()
}

/// In-place Cholesky factorisation A = L·Lᵀ of a symmetric r × r row-major matrix (lower triangle
/// read and overwritten by L). Returns ln det A, or `None` when a pivot is not above `rel_pivot`
/// times its diagonal entry (numerically not positive definite).
pub(super) fn cholesky(a: &mut [f64], r: usize, rel_pivot: f64) -> Option<f64> {
    let mut logdet = 0.0;
    for j in 0..r {
        let diag = a[j * r + j];
        let d = diag - dot(&a[j * r..j * r + j], &a[j * r..j * r + j]);
        if d.partial_cmp(&(rel_pivot * diag)) != Some(std::cmp::Ordering::Greater) {
            return None;
        }
        let l = d.sqrt();
        a[j * r + j] = l;
        logdet += d.ln();
        for i in j + 1..r {
            let s = a[i * r + j] - dot(&a[i * r..i * r + j], &a[j * r..j * r + j]);
            a[i * r + j] = s / l;
        }
    }
    Some(logdet)
}

/// The inverse of A from its Cholesky factor L (lower triangle of `l`), into `out` (full,
/// symmetric). `work` holds r² scratch.
pub(super) fn cholesky_inverse(l: &[f64], r: usize, work: &mut [f64], out: &mut [f64]) {
    // work = L⁻¹ (lower triangular), by forward substitution column by column.
    work[..r * r].fill(0.0);
    for c in 0..r {
        for i in c..r {
            let mut s = if i == c { 1.0 } else { 0.0 };
            for k in c..i {
                s -= l[i * r + k] * work[k * r + c];
            }
            work[i * r + c] = s / l[i * r + i];
        }
    }
    // A⁻¹ = L⁻ᵀ L⁻¹.
    for p in 0..r {
        for q in 0..=p {
            let s: f64 = (p..r).map(|k| work[k * r + p] * work[k * r + q]).sum();
            out[p * r + q] = s;
            out[q * r + p] = s;
        }
    }
}

/// det A of a small symmetric r × r row-major matrix by LDLᵀ (no square roots or logarithms),
/// 0 when a pivot is not above [`SMALL_PIVOT`] times its diagonal entry (not positive definite).
/// Overwrites `a`.
pub(super) fn det_spd(a: &mut [f64], r: usize) -> f64 {
    let mut det = 1.0;
    for j in 0..r {
        let mut d = a[j * r + j];
        for k in 0..j {
            d -= a[j * r + k] * a[j * r + k] * a[k * r + k];
        }
        if d.partial_cmp(&(SMALL_PIVOT * a[j * r + j])) != Some(std::cmp::Ordering::Greater) {
            return 0.0;
        }
        det *= d;
        for i in j + 1..r {
            let mut s = a[i * r + j];
            for k in 0..j {
                s -= a[i * r + k] * a[j * r + k] * a[k * r + k];
            }
            a[i * r + j] = s / d;
        }
        a[j * r + j] = d;
    }
    det
}

/// det A of a symmetric 3 × 3 matrix given by its lower triangle (a00, a10, a11, a20, a21, a22),
/// by LDLᵀ written out; 0 when not positive definite, like [`det_spd`].
#[inline(always)]
pub(super) fn det3_spd([a00, a10, a11, a20, a21, a22]: [f64; 6]) -> f64 {
    let d0 = a00;
    if d0.partial_cmp(&(SMALL_PIVOT * a00)) != Some(std::cmp::Ordering::Greater) {
        return 0.0;
    }
    let (l10, l20) = (a10 / d0, a20 / d0);
    let d1 = a11 - l10 * a10;
    if d1.partial_cmp(&(SMALL_PIVOT * a11)) != Some(std::cmp::Ordering::Greater) {
        return 0.0;
    }
    let l21 = (a21 - l20 * a10) / d1;
    let d2 = a22 - l20 * a20 - l21 * l21 * d1;
    if d2.partial_cmp(&(SMALL_PIVOT * a22)) != Some(std::cmp::Ordering::Greater) {
        return 0.0;
    }
    d0 * d1 * d2
}

/// det(I + sign·D) of an r × r block, 0 when not positive definite. `work` holds r².
#[inline]
pub(super) fn det_shifted(d: &[f64], r: usize, sign: f64, work: &mut [f64]) -> f64 {
    if r == 3 {
        return det3_spd([
            1.0 + sign * d[0],
            sign * d[3],
            1.0 + sign * d[4],
            sign * d[6],
            sign * d[7],
            1.0 + sign * d[8],
        ]);
    }
    identity_plus(d, r, sign, work);
    det_spd(&mut work[..r * r], r)
}

/// out = I + sign·D.
pub(super) fn identity_plus(d: &[f64], r: usize, sign: f64, out: &mut [f64]) {
    for p in 0..r {
        for q in 0..r {
            out[p * r + q] = sign * d[p * r + q] + if p == q { 1.0 } else { 0.0 };
        }
    }
}

/// ln det(I + sign·D) of an r × r block, −∞ when not positive definite. `work` holds r².
#[inline]
pub(super) fn logdet_shifted(d: &[f64], r: usize, sign: f64, work: &mut [f64]) -> f64 {
    det_shifted(d, r, sign, work).ln()
}

/// (I + sign·D)⁻¹ into `out`, `None` when not positive definite. `work` holds 2r² scratch.
pub(super) fn inverse_shifted(d: &[f64], r: usize, sign: f64, work: &mut [f64], out: &mut [f64]) -> Option<()> {
    let (a, rest) = work.split_at_mut(r * r);
    identity_plus(d, r, sign, a);
    cholesky(a, r, SMALL_PIVOT)?;
    cholesky_inverse(a, r, rest, out);
    Some(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::detmax::SINGULAR_PIVOT;
    use crate::identify::detmax::test_pools::to_dmatrix;
    use nalgebra::DMatrix;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Reference: nalgebra's Cholesky and inverse.
    #[test]
    fn cholesky_and_inverse_match_nalgebra() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for r in 1..9 {
            let x = DMatrix::from_fn(r + 3, r, |_, _| rng.random_range(-1.0..1.0));
            let a = x.transpose() * &x;
            let mut l: Vec<f64> = a.transpose().as_slice().to_vec();
            let logdet = cholesky(&mut l, r, 0.0).unwrap();
            assert!((logdet - a.determinant().ln()).abs() < 1e-10);
            let det = det_spd(&mut a.transpose().as_slice().to_vec(), r);
            assert!((det / a.determinant() - 1.0).abs() < 1e-10);
            let mut inv = vec![0.0; r * r];
            let mut work = vec![0.0; r * r];
            cholesky_inverse(&l, r, &mut work, &mut inv);
            let reference = a.clone().try_inverse().unwrap();
            let err = (to_dmatrix(&inv, r) - &reference).abs().max() / reference.abs().max();
            assert!(err < 1e-10, "r = {r}: {err}");
        }
        // A singular matrix is refused.
        let mut s = vec![1.0, 2.0, 2.0, 4.0];
        assert!(cholesky(&mut s, 2, SINGULAR_PIVOT).is_none());
        assert_eq!(det_spd(&mut [1.0, 2.0, 2.0, 4.0], 2), 0.0);
        assert_eq!(det_spd(&mut [1.0, 2.0, 2.0, 3.0], 2), 0.0, "indefinite");
    }

    /// The written-out 3 × 3 determinant against the general LDLᵀ one.
    #[test]
    fn det3_matches_det_spd() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for _ in 0..100 {
            let x = DMatrix::from_fn(4, 3, |_, _| rng.random_range(-1.0..1.0));
            let a = x.transpose() * &x - DMatrix::identity(3, 3) * rng.random_range(0.0..0.5);
            let mut full: Vec<f64> = a.as_slice().to_vec();
            let general = det_spd(&mut full, 3);
            let written = det3_spd([a[(0, 0)], a[(1, 0)], a[(1, 1)], a[(2, 0)], a[(2, 1)], a[(2, 2)]]);
            assert!((general - written).abs() <= 1e-12 * general.abs().max(1e-300), "{general} vs {written}");
            if a.clone().cholesky().is_some() {
                assert!((written / a.determinant() - 1.0).abs() < 1e-10);
            } else {
                assert_eq!(written, 0.0);
            }
        }
    }
}
