//! Screening: the score (Lagrange-multiplier) test of each candidate on the residual of the
//! current model (DIAGNOSIS §1).
//!
//! - H0: the candidate's parameters are zero (the current model is complete in its direction).
//! - Statistic: with r̃ the weighted residual (orthogonal to the current model's columns at the
//!   least-squares solution) and J̃_k = (I − QQᵀ)J_k the part of the candidate the model cannot
//!   absorb, S_k = r̃ᵀJ̃_k(J̃_kᵀJ̃_k)⁺J̃_kᵀr̃ is the drop of the weighted RSS if the candidate were
//!   added (first order). No refit: one product with Q per candidate.
//! - σ is not trusted: the F form with the residual variance estimated *after* removing the
//!   candidate's share, F = (S/d)/((RSS − S)/(n − p − d)), so a strong effect cannot hide itself
//!   by inflating the variance it is tested against.
//! - A regularised candidate (a correction table) uses the penalised fit: S is the drop of the
//!   plain RSS at the penalised solution and d its effective degrees of freedom tr((G + Λ)⁻¹G).
//! - Separability ρ = ‖J̃_k‖_F/‖J_k‖_F: how much of the effect the model cannot absorb.
//! - Multiplicity: p-values are corrected by Holm over the whole family (see `super::stats`);
//!   the frequency scan enters as one test per joint, its best frequency's p-value multiplied by
//!   the effective number of independent frequencies.

use faer::{Mat, MatRef};

use super::linalg::{at_b, at_v, psd_eigen};
use super::stats::f_log10_sf;

/// The screening statistics of one candidate.
#[derive(Clone, Debug, PartialEq)]
pub struct Score {
    /// Drop of the weighted RSS if the candidate were added (first order).
    pub s: f64,
    /// Degrees of freedom (rank of J̃_k, or effective for a regularised candidate).
    pub dof: f64,
    /// F = (S/d)/((RSS − S)/(n − p − d)): the residual variance estimated after removing the
    /// candidate's share; 0 without a testable direction.
    pub f: f64,
    /// log10 of the uncorrected p-value (times the scan's multiplicity for a scanned frequency).
    pub log10_p: f64,
    /// Separability ‖J̃_k‖_F/‖J_k‖_F.
    pub rho: f64,
    /// n·ln(RSS/(RSS − S)) − d·ln n: the ranking, parsimony included.
    pub bic_gain: f64,
    /// The candidate's parameter values in the augmented linear fit (SI).
    pub estimate: Vec<f64>,
}

/// What the score of a candidate needs from the current model.
pub struct Basis<'a> {
    /// Orthonormal basis of the model's columns (n_rows × p).
    pub q: MatRef<'a, f64>,
    /// Weighted residual, projected orthogonally to Q.
    pub r: &'a [f64],
    /// Weighted residual sum of squares of the measurement rows.
    pub rss: f64,
    /// Measurement rows and the model's free parameters.
    pub n: usize,
    /// Parameters the residual was fitted with: p of n − p − d.
    pub p: usize,
}

impl<'a> Basis<'a> {
    /// Project `r` off Q (at an exact least-squares solution it is already orthogonal; this
    /// removes what convergence tolerance left).
    pub fn project(q: MatRef<'_, f64>, r: &[f64]) -> Vec<f64> {
        let c = at_v(q, r);
        let mut out = r.to_vec();
        for (k, ck) in c.iter().enumerate() {
            for (i, v) in out.iter_mut().enumerate() {
                *v -= q[(i, k)] * ck;
            }
        }
        out
    }
}

/// Directions of a candidate whose projected size is below this fraction of its own scale are
/// absorbed by the model: they carry no testable information (rounding, not signal).
const ABSORBED: f64 = 1e-9;

/// The score test of a candidate with columns `c` (weighted, n_rows × m) and an optional penalty
/// (m × m, for a regularised candidate).
pub fn score(basis: &Basis<'_>, c: MatRef<'_, f64>, penalty: Option<&Mat<f64>>) -> Score {
    let m = c.ncols();
    let g0 = at_b(c, c);
    let a = at_b(basis.q, c);
    let aa = at_b(a.as_ref(), a.as_ref());
    let g = Mat::<f64>::from_fn(m, m, |i, k| g0[(i, k)] - aa[(i, k)]);
    let gr = at_v(c, basis.r);
    score_gram(basis, &g0, &g, &gr, penalty)
}

/// The score test from the candidate's Gram matrices: G₀ = J_kᵀJ_k, G = J̃_kᵀJ̃_k (after
/// projecting off the model) and J_kᵀr̃.
pub(crate) fn score_gram(
    basis: &Basis<'_>,
    g0: &Mat<f64>,
    g: &Mat<f64>,
    gr: &[f64],
    penalty: Option<&Mat<f64>>,
) -> Score {
    let m = g0.nrows();
    let tr0: f64 = (0..m).map(|i| g0[(i, i)]).sum();
    let tr: f64 = (0..m).map(|i| g[(i, i)].max(0.0)).sum();
    let rho = if tr0 > 0.0 { (tr / tr0).sqrt() } else { 0.0 };
    let scale = (0..m).map(|i| g0[(i, i)]).fold(0.0f64, f64::max);
    let h = match penalty {
        Some(l) => Mat::<f64>::from_fn(m, m, |i, k| g[(i, k)] + l[(i, k)]),
        None => g.clone(),
    };
    // Pseudo-inverse of H on the directions the model does not absorb.
    let (vals, vecs) = psd_eigen(&h, 0.0);
    let gr = gr.to_vec();
    let mut delta = vec![0.0; m];
    let mut dof = 0.0;
    for (k, &lam) in vals.iter().enumerate() {
        if lam <= ABSORBED * scale {
            continue;
        }
        let u: Vec<f64> = (0..m).map(|i| vecs[(i, k)]).collect();
        let ug: f64 = u.iter().zip(&gr).map(|(a, b)| a * b).sum();
        for i in 0..m {
            delta[i] += u[i] * ug / lam;
        }
        // u_kᵀ G u_k / λ_k: 1 without a penalty, less with one.
        let mut ugu = 0.0;
        for i in 0..m {
            for l in 0..m {
                ugu += u[i] * g[(i, l)] * u[l];
            }
        }
        dof += ugu / lam;
    }
    let gd: Vec<f64> = (0..m).map(|i| (0..m).map(|l| g[(i, l)] * delta[l]).sum()).collect();
    let s = (2.0 * delta.iter().zip(&gr).map(|(a, b)| a * b).sum::<f64>()
        - delta.iter().zip(&gd).map(|(a, b)| a * b).sum::<f64>())
    .clamp(0.0, basis.rss);
    let (n, p) = (basis.n as f64, basis.p as f64);
    let den_dof = (n - p - dof).max(1.0);
    let rest = (basis.rss - s).max(basis.rss * 1e-15);
    let (f, log10_p, bic_gain) = if dof > 0.0 && s > 0.0 {
        let f = (s / dof) / (rest / den_dof);
        (f, f_log10_sf(f, dof, den_dof), n * (basis.rss / rest).ln() - dof * n.ln())
    } else {
        (0.0, 0.0, f64::NEG_INFINITY)
    };
    Score { s, dof, f, log10_p, rho, bic_gain, estimate: delta }
}

/// The smoothness penalty of a correction table with `m` consecutive knots whose (weighted)
/// columns are `c`: λ² Σ (second differences)² + (mean row)², with λ² = η·mean‖c_k‖² — the
/// rows `identify::map_priors` adds to an identification, as a matrix.
pub(crate) fn table_penalty(c: MatRef<'_, f64>, eta: f64) -> Mat<f64> {
    let m = c.ncols();
    let mean: f64 = (0..m).map(|k| (0..c.nrows()).map(|r| c[(r, k)].powi(2)).sum::<f64>()).sum::<f64>() / m as f64;
    let lam2 = eta * mean;
    let mut p = Mat::<f64>::zeros(m, m);
    for k in 1..m.saturating_sub(1) {
        let row = [(k - 1, 1.0), (k, -2.0), (k + 1, 1.0)];
        for &(a, wa) in &row {
            for &(b, wb) in &row {
                p[(a, b)] += lam2 * wa * wb;
            }
        }
    }
    let w = mean / (m * m) as f64;
    for a in 0..m {
        for b in 0..m {
            p[(a, b)] += w;
        }
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::linalg::{a_b, psd_solve};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::StandardNormal;

    /// S against the exact drop of the RSS from refitting with the candidate (a linear problem,
    /// so first order is exact), ρ against its definition, and the estimate against the
    /// augmented fit's coefficient.
    #[test]
    fn score_equals_the_refit_drop() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let (n, p) = (300, 5);
        let j = Mat::<f64>::from_fn(n, p, |_, _| rng.random_range(-1.0..1.0));
        let c = Mat::<f64>::from_fn(n, 2, |i, k| j[(i, 0)] * 0.5 + rng.random_range(-1.0..1.0) * (k + 1) as f64);
        let y: Vec<f64> =
            (0..n).map(|i| 0.3 * c[(i, 0)] - 0.2 * c[(i, 1)] + rng.sample::<f64, _>(StandardNormal)).collect();
        // Fit of the model alone.
        let jtj = at_b(j.as_ref(), j.as_ref());
        let beta = psd_solve(&jtj, &at_v(j.as_ref(), &y), 1e-14);
        let r: Vec<f64> = (0..n).map(|i| y[i] - (0..p).map(|k| j[(i, k)] * beta[k]).sum::<f64>()).collect();
        let rss: f64 = r.iter().map(|v| v * v).sum();
        // Fit of the augmented model.
        let aug = Mat::<f64>::from_fn(n, p + 2, |i, k| if k < p { j[(i, k)] } else { c[(i, k - p)] });
        let ata = at_b(aug.as_ref(), aug.as_ref());
        let b2 = psd_solve(&ata, &at_v(aug.as_ref(), &y), 1e-14);
        let fitted = a_b(aug.as_ref(), Mat::<f64>::from_fn(p + 2, 1, |k, _| b2[k]).as_ref());
        let rss2: f64 = (0..n).map(|i| (y[i] - fitted[(i, 0)]).powi(2)).sum();
        let q = j.qr().compute_thin_Q();
        let rp = Basis::project(q.as_ref(), &r);
        let sc = score(&Basis { q: q.as_ref(), r: &rp, rss, n, p }, c.as_ref(), None);
        assert!((sc.s - (rss - rss2)).abs() < 1e-9 * rss, "{} vs {}", sc.s, rss - rss2);
        assert!((sc.dof - 2.0).abs() < 1e-12);
        assert!((sc.estimate[0] - b2[p]).abs() < 1e-9 && (sc.estimate[1] - b2[p + 1]).abs() < 1e-9);
        // ρ by its definition.
        let proj = a_b(q.as_ref(), at_b(q.as_ref(), c.as_ref()).as_ref());
        let num: f64 =
            (0..n).flat_map(|i| (0..2).map(move |k| (i, k))).map(|(i, k)| (c[(i, k)] - proj[(i, k)]).powi(2)).sum();
        let den: f64 = (0..n).flat_map(|i| (0..2).map(move |k| (i, k))).map(|(i, k)| c[(i, k)].powi(2)).sum();
        assert!((sc.rho - (num / den).sqrt()).abs() < 1e-12);
        // The F statistic and its p-value by hand.
        let f = (sc.s / 2.0) / ((rss - sc.s) / (n - p - 2) as f64);
        assert!((sc.f - f).abs() < 1e-9 * f);
        assert!(sc.log10_p < -3.0);
    }

    /// A candidate inside the model's span: no testable direction, ρ ≈ 0, S = 0.
    #[test]
    fn absorbed_candidates_score_nothing() {
        let mut rng = ChaCha8Rng::seed_from_u64(10);
        let (n, p) = (200, 4);
        let j = Mat::<f64>::from_fn(n, p, |_, _| rng.random_range(-1.0..1.0));
        let c = Mat::<f64>::from_fn(n, 1, |i, _| j[(i, 1)] - 2.0 * j[(i, 3)]);
        let r: Vec<f64> = (0..n).map(|_| rng.sample::<f64, _>(StandardNormal)).collect();
        let q = j.qr().compute_thin_Q();
        let rp = Basis::project(q.as_ref(), &r);
        let rss = rp.iter().map(|v| v * v).sum();
        let sc = score(&Basis { q: q.as_ref(), r: &rp, rss, n, p }, c.as_ref(), None);
        assert!(sc.rho < 1e-7, "{}", sc.rho);
        assert_eq!(sc.dof, 0.0);
        assert_eq!(sc.log10_p, 0.0);
    }

    /// Under H0 (pure noise, the candidate unrelated), the F test's p-value is uniform: about 5 %
    /// of 400 seeded replications fall below 0.05.
    #[test]
    fn the_test_holds_its_level_under_the_null() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let (n, p) = (150, 6);
        let mut hits = 0;
        for _ in 0..400 {
            let j = Mat::<f64>::from_fn(n, p, |_, _| rng.random_range(-1.0..1.0));
            let c = Mat::<f64>::from_fn(n, 2, |_, _| rng.random_range(-1.0..1.0));
            let y: Vec<f64> = (0..n).map(|_| 3.0 * rng.sample::<f64, _>(StandardNormal)).collect();
            let q = j.qr().compute_thin_Q();
            let rp = Basis::project(q.as_ref(), &y);
            let rss = rp.iter().map(|v| v * v).sum();
            let sc = score(&Basis { q: q.as_ref(), r: &rp, rss, n, p }, c.as_ref(), None);
            if sc.log10_p < 0.05f64.log10() {
                hits += 1;
            }
        }
        // Binomial(400, 0.05): mean 20, sd 4.4.
        assert!((8..=34).contains(&hits), "{hits} of 400");
    }
}
