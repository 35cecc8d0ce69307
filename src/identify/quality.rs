//! The quality of a fit (thesis §4.2.3–4.2.5): conditioning in the thesis's units (SI: m, rad,
//! rad/(N·m) — comparable to its κ ≤ 1000 criterion and its 752–792) and on unit columns,
//! observability indices, and the parameter covariance σ̂²(JᵀJ)⁻¹ with standard deviations and
//! correlations.

use faer::Mat;

use super::observability::{self, Observability};
use super::solver::Fit;

/// Conditioning, observability and uncertainties of a fit.
#[derive(Clone, Debug)]
pub struct Quality {
    /// κ(J) = σ_max/σ_min in SI units.
    pub kappa: f64,
    /// κ of the Jacobian with unit-norm columns.
    pub kappa_scaled: f64,
    /// O1…O5 in SI units (digest §6).
    pub observability: Observability,
    /// Singular values of J (SI), descending.
    pub singular_values: Vec<f64>,
    /// Residual standard deviation per row, σ̂ = √(‖r‖²/(N − m)), m.
    pub sigma: f64,
    /// RMS of the measurement residual norms, m.
    pub rms_residual: f64,
    /// Parameter covariance (free parameters, SI).
    pub covariance: Mat<f64>,
    pub std: Vec<f64>,
    pub correlation: Mat<f64>,
    /// The direction of the smallest singular value of the scaled Jacobian: (column, coefficient).
    pub weakest: Vec<(usize, f64)>,
    pub n_rows: usize,
    pub n_configs: usize,
}

impl Quality {
    pub fn of(fit: &Fit, n_configs: usize, obs_rows: &[(usize, usize)]) -> Quality {
        let j = &fit.jacobian;
        let (n, m) = (j.nrows(), j.ncols());
        // J = Q·R with Q orthonormal: J and R have the same singular values and right singular
        // vectors, and the same column norms, so both SVDs run on the m×m R instead of the tall
        // n×m J (the two tall SVDs were half of a 5,000-pose identification).
        let r = if n >= m {
            let qr = j.qr();
            let r = qr.thin_R();
            Mat::<f64>::from_fn(m, m, |a, b| if a <= b { r[(a, b)] } else { 0.0 })
        } else {
            j.clone()
        };
        let svd = r.thin_svd().expect("SVD of the Jacobian");
        let s: Vec<f64> = (0..m).map(|i| if i < svd.S().dim() { svd.S().column_vector()[i] } else { 0.0 }).collect();
        let v = svd.V();
        let kappa = s[0] / s[m - 1];
        // Scaled columns (unit norm).
        let mut js = r.clone();
        for c in 0..m {
            let norm = (0..js.nrows()).map(|r| js[(r, c)].powi(2)).sum::<f64>().sqrt().max(f64::MIN_POSITIVE);
            for r in 0..js.nrows() {
                js[(r, c)] /= norm;
            }
        }
        let svs = js.thin_svd().expect("SVD of the scaled Jacobian");
        let ss: Vec<f64> = (0..m).map(|i| if i < svs.S().dim() { svs.S().column_vector()[i] } else { 0.0 }).collect();
        let kappa_scaled = ss[0] / ss[m - 1];
        let vs = svs.V();
        let mut weakest: Vec<(usize, f64)> = (0..m).map(|c| (c, vs[(c, m - 1)])).collect();
        weakest.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
        weakest.retain(|(_, w)| w.abs() > 0.1);

        let dof = n.saturating_sub(m).max(1) as f64;
        let sigma = (fit.cost / dof).sqrt();
        let mut cov = Mat::<f64>::zeros(m, m);
        for a in 0..m {
            for b in 0..=a {
                let mut sum = 0.0;
                for k in 0..m {
                    sum += v[(a, k)] * v[(b, k)] / (s[k] * s[k]);
                }
                cov[(a, b)] = sum * sigma * sigma;
                cov[(b, a)] = cov[(a, b)];
            }
        }
        let std: Vec<f64> = (0..m).map(|i| cov[(i, i)].sqrt()).collect();
        let mut corr = Mat::<f64>::zeros(m, m);
        for a in 0..m {
            for b in 0..m {
                corr[(a, b)] = cov[(a, b)] / (std[a] * std[b]);
            }
        }
        let rms_residual = (obs_rows
            .iter()
            .map(|&(row, rows)| fit.residual[row..row + rows].iter().map(|x| x * x).sum::<f64>())
            .sum::<f64>()
            / obs_rows.len().max(1) as f64)
            .sqrt();
        Quality {
            kappa,
            kappa_scaled,
            observability: observability::observability(&s, n_configs),
            singular_values: s,
            sigma,
            rms_residual,
            covariance: cov,
            std,
            correlation: corr,
            weakest,
            n_rows: n,
            n_configs,
        }
    }
}
