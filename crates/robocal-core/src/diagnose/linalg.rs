//! Small dense kernels the diagnosis needs on top of faer: products with a transposed factor,
//! symmetric solves that report and tolerate rank deficiency, orthonormal bases and canonical
//! correlations. faer does the arithmetic; these wrappers fix the conventions (tolerances
//! relative to the largest eigenvalue, sequential parallelism — the callers already run on
//! scoped threads).

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par, Side};

/// The columns of `a` then those of `b` (same rows).
pub(crate) fn hcat(a: &Mat<f64>, b: &Mat<f64>) -> Mat<f64> {
    let m = a.ncols();
    Mat::<f64>::from_fn(a.nrows(), m + b.ncols(), |r, c| if c < m { a[(r, c)] } else { b[(r, c - m)] })
}

/// AᵀB.
pub(crate) fn at_b(a: MatRef<'_, f64>, b: MatRef<'_, f64>) -> Mat<f64> {
    let mut out = Mat::<f64>::zeros(a.ncols(), b.ncols());
    matmul(out.as_mut(), Accum::Replace, a.transpose(), b, 1.0, Par::Seq);
    out
}

/// A·B.
pub(crate) fn a_b(a: MatRef<'_, f64>, b: MatRef<'_, f64>) -> Mat<f64> {
    let mut out = Mat::<f64>::zeros(a.nrows(), b.ncols());
    matmul(out.as_mut(), Accum::Replace, a, b, 1.0, Par::Seq);
    out
}

/// Aᵀv.
pub(crate) fn at_v(a: MatRef<'_, f64>, v: &[f64]) -> Vec<f64> {
    (0..a.ncols()).map(|c| (0..a.nrows()).map(|r| a[(r, c)] * v[r]).sum()).collect()
}

/// A symmetric positive semi-definite matrix's eigenpairs above `rel_tol`·λ_max: the basis of a
/// pseudo-inverse. Returns (eigenvalues, eigenvectors as columns).
pub(crate) fn psd_eigen(g: &Mat<f64>, rel_tol: f64) -> (Vec<f64>, Mat<f64>) {
    let m = g.nrows();
    if m == 0 {
        return (Vec::new(), Mat::zeros(0, 0));
    }
    let evd = g.self_adjoint_eigen(Side::Lower).expect("eigendecomposition of a symmetric matrix");
    let s = evd.S().column_vector();
    let u = evd.U();
    let max = (0..m).map(|i| s[i]).fold(0.0f64, f64::max);
    let keep: Vec<usize> = (0..m).filter(|&i| max > 0.0 && s[i] > rel_tol * max).collect();
    let vals = keep.iter().map(|&i| s[i]).collect();
    let vecs = Mat::<f64>::from_fn(m, keep.len(), |r, c| u[(r, keep[c])]);
    (vals, vecs)
}

/// x = G⁺·b for a symmetric positive semi-definite G (directions below `rel_tol`·λ_max dropped).
/// Tries Cholesky first (the common, full-rank case), falls back to the eigen pseudo-inverse.
pub(crate) fn psd_solve(g: &Mat<f64>, b: &[f64], rel_tol: f64) -> Vec<f64> {
    let m = g.nrows();
    if let Ok(llt) = g.llt(Side::Lower) {
        // Cholesky succeeds on nearly singular matrices too; accept it only when the smallest
        // pivot is comfortably above the tolerance.
        let l = llt.L();
        let (mut dmin, mut dmax) = (f64::INFINITY, 0.0f64);
        for i in 0..m {
            let d = l[(i, i)] * l[(i, i)];
            dmin = dmin.min(d);
            dmax = dmax.max(d);
        }
        if dmin > 1e3 * rel_tol * dmax {
            let mut rhs = Mat::<f64>::from_fn(m, 1, |r, _| b[r]);
            use faer::linalg::solvers::Solve;
            llt.solve_in_place(rhs.as_mut());
            return (0..m).map(|r| rhs[(r, 0)]).collect();
        }
    }
    let (vals, vecs) = psd_eigen(g, rel_tol);
    let mut x = vec![0.0; m];
    for (k, lam) in vals.iter().enumerate() {
        let c: f64 = (0..m).map(|r| vecs[(r, k)] * b[r]).sum::<f64>() / lam;
        for r in 0..m {
            x[r] += c * vecs[(r, k)];
        }
    }
    x
}

/// An orthonormal basis of A's column space (thin SVD, directions below `rel_tol`·σ_max dropped).
pub(crate) fn orthonormal_basis(a: MatRef<'_, f64>, rel_tol: f64) -> Mat<f64> {
    let svd = a.thin_svd().expect("SVD");
    let s = svd.S().column_vector();
    let u = svd.U();
    let k = s.nrows();
    let max = if k > 0 { s[0] } else { 0.0 };
    let keep: Vec<usize> = (0..k).filter(|&i| max > 0.0 && s[i] > rel_tol * max).collect();
    Mat::<f64>::from_fn(a.nrows(), keep.len(), |r, c| u[(r, keep[c])])
}

/// The largest canonical correlation between the column spaces of A and B (the cosine of the
/// smallest principal angle): 1 when a direction of one lies in the other.
pub(crate) fn canonical_correlation(a: MatRef<'_, f64>, b: MatRef<'_, f64>) -> f64 {
    let (ua, ub) = (orthonormal_basis(a, 1e-9), orthonormal_basis(b, 1e-9));
    if ua.ncols() == 0 || ub.ncols() == 0 {
        return 0.0;
    }
    let c = at_b(ua.as_ref(), ub.as_ref());
    let s = c.thin_svd().expect("SVD").S().column_vector().iter().copied().fold(0.0f64, f64::max);
    s.min(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random(n: usize, m: usize, rng: &mut ChaCha8Rng) -> Mat<f64> {
        Mat::from_fn(n, m, |_, _| rng.random_range(-1.0..1.0))
    }

    /// Residual checks ‖G·x − b‖ ≤ c·ε·‖G‖·‖x‖, full rank and rank-deficient.
    #[test]
    fn psd_solve_full_and_deficient() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let a = random(40, 6, &mut rng);
        let g = at_b(a.as_ref(), a.as_ref());
        let b: Vec<f64> = (0..6).map(|_| rng.random_range(-1.0..1.0)).collect();
        let x = psd_solve(&g, &b, 1e-12);
        for r in 0..6 {
            let gx: f64 = (0..6).map(|c| g[(r, c)] * x[c]).sum();
            assert!((gx - b[r]).abs() < 1e-10, "{gx} vs {}", b[r]);
        }
        // Column 5 = column 0 + column 1: the minimum-norm solution of a consistent system.
        let mut d = a.clone();
        for r in 0..40 {
            d[(r, 5)] = d[(r, 0)] + d[(r, 1)];
        }
        let g = at_b(d.as_ref(), d.as_ref());
        let y: Vec<f64> = (0..40).map(|_| rng.random_range(-1.0..1.0)).collect();
        let b = at_v(d.as_ref(), &y);
        let x = psd_solve(&g, &b, 1e-12);
        for r in 0..6 {
            let gx: f64 = (0..6).map(|c| g[(r, c)] * x[c]).sum();
            assert!((gx - b[r]).abs() < 1e-9, "row {r}: {gx} vs {}", b[r]);
        }
        // Minimum norm: no component along the null vector (1, 1, 0, 0, 0, −1).
        let null = [1.0, 1.0, 0.0, 0.0, 0.0, -1.0];
        assert!(x.iter().zip(null).map(|(a, b)| a * b).sum::<f64>().abs() < 1e-9);
    }

    #[test]
    fn canonical_correlations_of_known_subspaces() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let a = random(200, 3, &mut rng);
        // B shares one direction with A exactly.
        let mut b = random(200, 2, &mut rng);
        for r in 0..200 {
            b[(r, 1)] = a[(r, 0)] - 2.0 * a[(r, 2)];
        }
        assert!((canonical_correlation(a.as_ref(), b.as_ref()) - 1.0).abs() < 1e-9);
        // Two single columns: |cos| of the angle between them.
        let u = Mat::<f64>::from_fn(3, 1, |r, _| [1.0, 0.0, 0.0][r]);
        let v = Mat::<f64>::from_fn(3, 1, |r, _| [1.0, 1.0, 0.0][r]);
        assert!((canonical_correlation(u.as_ref(), v.as_ref()) - 0.5f64.sqrt()).abs() < 1e-12);
        // Independent random subspaces of a tall space: far from 1.
        let (a, c) = (random(2000, 3, &mut rng), random(2000, 2, &mut rng));
        assert!(canonical_correlation(a.as_ref(), c.as_ref()) < 0.15);
    }
}
