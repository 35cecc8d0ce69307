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
    /// Standard deviations of the free parameters (SI), in the fit's column order: the classic
    /// σ̂²(JᵀJ)⁻¹ ones, or after [`Quality::make_robust`] the larger of those and the cluster-robust
    /// ones.
    pub std: Vec<f64>,
    /// Correlations of the free parameters (the classic ones, also after [`Quality::make_robust`]).
    pub correlation: Mat<f64>,
    /// σ̂²(JᵀJ)⁻¹'s standard deviations, before [`Quality::make_robust`] (equal to `std` until then).
    pub std_classic: Vec<f64>,
    /// `std` is the larger of the classic and the cluster-robust (by pose) standard deviation.
    pub robust: bool,
    /// The direction of the smallest singular value of the scaled Jacobian: (column, coefficient).
    pub weakest: Vec<(usize, f64)>,
    /// Rows N of J: the measurement rows, then the prior rows.
    pub n_rows: usize,
    /// Configurations n of O1's normalisation (an identification passes its measurement count).
    pub n_configs: usize,
    /// The rows were weighted by an instrument model: `sigma` is then the ratio of the residual
    /// to the instrument's σ (1 when the model and the instrument model are right), not metres.
    pub weighted: bool,
    /// RMS of the noise the instrument model and the measurements' own σ predict for the
    /// measurement residuals (outliers left out), m; 0 until the identification sets it.
    pub expected_rms: f64,
    /// The residual RMS over `expected_rms` (1 when model and noise model are right), both with
    /// the outliers left out: with a robust loss that down-weighted some, this is not
    /// `rms_residual / expected_rms`.
    pub residual_ratio: f64,
}

impl Quality {
    /// The quality of a converged fit: the SVDs of its Jacobian in SI units and with unit-norm
    /// columns, O1–O5 for `n_configs`, σ̂ and the classic covariance. `obs_rows` gives each
    /// measurement's (first row, rows) for `rms_residual`; `weighted`, `expected_rms` and
    /// `residual_ratio` are left for the identification to set.
    pub fn of(fit: &Fit, n_configs: usize, obs_rows: &[(usize, usize)]) -> Quality {
        let j = &fit.jacobian;
        let (n, m) = (j.nrows(), j.ncols());
        // J = Q·R with Q orthonormal: J and R have the same singular values and right singular
        // vectors, and the same column norms, so both SVDs run on the m×m R instead of the tall
        // n×m J (the two tall SVDs were half of a 5,000-pose identification).
        let r = if n >= m { super::solver::r_factor(j.as_ref()) } else { j.clone() };
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
            std_classic: std.clone(),
            std,
            correlation: corr,
            robust: false,
            weakest,
            n_rows: n,
            n_configs,
            weighted: false,
            expected_rms: 0.0,
            residual_ratio: f64::NAN,
        }
    }
}

impl Quality {
    /// Cluster-robust ("sandwich") standard deviations with the measurements grouped by pose:
    /// Cov = c·B·(Σ_g u_g·u_gᵀ)·B with B = (JᵀJ)⁻¹, u_g = J_gᵀ·r_g over the measurement rows of
    /// pose g (regularisation rows carry no noise and are left out of the middle), and
    /// c = G/(G−1)·(N−1)/(N−m), the usual small-sample factor (CR1). `None` with fewer than
    /// `max(30, 2m)` poses, where the middle term is too noisy to be used.
    pub fn cluster_robust_std(
        &self,
        fit: &Fit,
        obs_rows: &[(usize, usize)],
        cluster_of_obs: &[usize],
        n_clusters: usize,
    ) -> Option<Vec<f64>> {
        let (u, c) = self.cluster_scores(fit, obs_rows, cluster_of_obs, n_clusters)?;
        let m = fit.jacobian.ncols();
        // The diagonal of Σ_g (B·u_g)(B·u_g)ᵀ, B = Cov/σ̂² (symmetric): the column sums of squares
        // of U·B, U the clusters' scores as rows, by one matrix product (one cluster a pose: 5,000
        // rows on the peers' largest problem).
        let s2 = self.sigma * self.sigma;
        let scores = Mat::<f64>::from_fn(u.len(), m, |g, k| u[g][k]);
        let ub = scores * &self.covariance;
        let var: Vec<f64> = (0..m).map(|a| (0..ub.nrows()).map(|g| (ub[(g, a)] / s2).powi(2)).sum::<f64>()).collect();
        let out: Vec<f64> = var.iter().map(|v| (c * v).sqrt()).collect();
        out.iter().all(|v| v.is_finite()).then_some(out)
    }

    /// The cluster-robust variance of the combination wᵀθ of the free parameters (in the fit's
    /// column order): c·Σ_g (wᵀ·B·u_g)², as [`Quality::cluster_robust_std`] (which is its square
    /// root for each unit w). The larger of this and the classic wᵀ·Cov·w is the σ² of a derived
    /// quantity (a payload's centre of mass) whatever parameters it is derived from, where scaling
    /// each parameter's σ first would not be. Call it before [`Quality::make_robust`] scales the
    /// covariance.
    pub fn cluster_robust_variance(
        &self,
        fit: &Fit,
        obs_rows: &[(usize, usize)],
        cluster_of_obs: &[usize],
        n_clusters: usize,
        w: &[f64],
    ) -> Option<f64> {
        let m = fit.jacobian.ncols();
        if w.len() != m {
            return None;
        }
        let (u, c) = self.cluster_scores(fit, obs_rows, cluster_of_obs, n_clusters)?;
        // B·w, B = Cov/σ̂² (symmetric): wᵀ·B·u_g = (B·w)ᵀ·u_g.
        let s2 = self.sigma * self.sigma;
        let b: Vec<f64> = (0..m).map(|a| (0..m).map(|k| self.covariance[(a, k)] * w[k]).sum::<f64>() / s2).collect();
        let v = c * u.iter().map(|ug| ug.iter().zip(&b).map(|(x, y)| x * y).sum::<f64>().powi(2)).sum::<f64>();
        v.is_finite().then_some(v)
    }

    /// The sandwich's scores u_g = J_gᵀ·r_g per pose and its small-sample factor c (see
    /// [`Quality::cluster_robust_std`]); `None` where the sandwich is not used.
    fn cluster_scores(
        &self,
        fit: &Fit,
        obs_rows: &[(usize, usize)],
        cluster_of_obs: &[usize],
        n_clusters: usize,
    ) -> Option<(Vec<Vec<f64>>, f64)> {
        let j = &fit.jacobian;
        let (n, m) = (j.nrows(), j.ncols());
        if m == 0
            || n_clusters < (2 * m).max(30)
            || self.sigma.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
            || obs_rows.len() != cluster_of_obs.len()
        {
            return None;
        }
        let mut u = vec![vec![0.0; m]; n_clusters];
        for (&(row, rows), &g) in obs_rows.iter().zip(cluster_of_obs) {
            for r in row..row + rows {
                let e = fit.residual[r];
                for (c, uc) in u[g].iter_mut().enumerate() {
                    *uc += j[(r, c)] * e;
                }
            }
        }
        let g = n_clusters as f64;
        let c = g / (g - 1.0) * (n as f64 - 1.0) / (n.saturating_sub(m).max(1) as f64);
        Some((u, c))
    }

    /// Report each parameter's standard deviation as the larger of the classic σ̂²(JᵀJ)⁻¹ one and
    /// the cluster-robust one (by pose; see [`Quality::cluster_robust_std`]), and scale the
    /// covariance to match (D·Cov·D, D diagonal: the correlations stay the classic ones).
    ///
    /// Why: σ̂²(JᵀJ)⁻¹ holds when every row's error is independent with one variance. On real data
    /// the readings of one stop share the stop's error (several reflectors, a turn of the joints no
    /// term explains) and the misfit varies over the workspace. On a tracker twin with a random
    /// 0.012° turn of every joint at every stop, the payload's classic σ is 0.10 kg while its
    /// estimates over six seeds spread by 0.19 kg; the cluster-robust σ is 0.16–0.21 kg. With white
    /// noise both agree (ratio 0.99 on the twin without the turns). The larger of the two is
    /// reported so a σ is never made smaller by the noise of the robust estimate itself.
    pub fn make_robust(&mut self, fit: &Fit, obs_rows: &[(usize, usize)], cluster_of_obs: &[usize], n_clusters: usize) {
        let Some(rs) = self.cluster_robust_std(fit, obs_rows, cluster_of_obs, n_clusters) else { return };
        let std: Vec<f64> = self.std_classic.iter().zip(&rs).map(|(c, r)| c.max(*r)).collect();
        let m = std.len();
        for a in 0..m {
            for b in 0..m {
                let (ka, kb) = (std[a] / self.std_classic[a], std[b] / self.std_classic[b]);
                if ka.is_finite() && kb.is_finite() {
                    self.covariance[(a, b)] *= ka * kb;
                }
            }
        }
        self.std = std;
        self.robust = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A fit of `n` rows (`n / 3` measurements of 3 rows) and `m` parameters whose columns span
    /// five orders of magnitude, with a random residual; column `m − 1` is nearly the sum of
    /// columns 1 and 2 when `weak`.
    fn fit(n: usize, m: usize, weak: bool, seed: u64) -> (Fit, DMatrix<f64>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let scale: Vec<f64> = (0..m).map(|c| 10f64.powi(c as i32 % 5 - 3)).collect();
        let mut j = DMatrix::from_fn(n, m, |_, c| rng.random_range(-1.0..1.0) * scale[c]);
        if weak {
            for r in 0..n {
                j[(r, m - 1)] = j[(r, 1)] / scale[1] + j[(r, 2)] / scale[2] + 1e-4 * rng.random_range(-1.0..1.0);
            }
        }
        let residual: Vec<f64> = (0..n).map(|_| rng.random_range(-1e-5..1e-5)).collect();
        let cost = residual.iter().map(|v| v * v).sum();
        let jacobian = Mat::from_fn(n, m, |r, c| j[(r, c)]);
        let fit = Fit { x: vec![0.0; m], iterations: 1, residual, jacobian, weights: vec![1.0; n / 3], cost };
        (fit, j)
    }

    fn rel(a: f64, b: f64) -> f64 {
        (a - b).abs() / b.abs()
    }

    /// Covariance σ̂²(JᵀJ)⁻¹ with σ̂² = ‖r‖²/(N − m), its standard deviations and correlations,
    /// the singular values and both condition numbers, against nalgebra on the tall J directly.
    #[test]
    fn covariance_and_conditioning_match_an_independent_computation() {
        let (n, m) = (45, 7);
        let (f, j) = fit(n, m, false, 1);
        let rows: Vec<(usize, usize)> = (0..n / 3).map(|i| (3 * i, 3)).collect();
        let q = Quality::of(&f, n / 3, &rows);

        let sigma2 = f.cost / (n - m) as f64;
        let cov = (j.transpose() * &j).try_inverse().unwrap() * sigma2;
        assert!(rel(q.sigma * q.sigma, sigma2) < 1e-14);
        for a in 0..m {
            assert!(rel(q.std[a], cov[(a, a)].sqrt()) < 1e-9, "std {a}");
            for b in 0..m {
                let scale = (cov[(a, a)] * cov[(b, b)]).sqrt();
                assert!((q.covariance[(a, b)] - cov[(a, b)]).abs() < 1e-9 * scale, "cov ({a}, {b})");
                assert_eq!(q.covariance[(a, b)], q.covariance[(b, a)]);
                assert!((q.correlation[(a, b)] - cov[(a, b)] / scale).abs() < 1e-9);
            }
            assert!((q.correlation[(a, a)] - 1.0).abs() < 1e-12);
        }

        let s = j.clone().svd(false, false).singular_values;
        let mut s: Vec<f64> = s.iter().copied().collect();
        s.sort_by(|a, b| b.total_cmp(a));
        for (got, want) in q.singular_values.iter().zip(&s) {
            assert!(rel(*got, *want) < 1e-12, "σ {got} vs {want}");
        }
        assert!(rel(q.kappa, s[0] / s[m - 1]) < 1e-10);
        assert!(q.kappa > 1e3, "columns of mixed units are ill-scaled: κ {}", q.kappa);
        let mut unit = j.clone();
        for mut c in unit.column_iter_mut() {
            let norm = c.norm();
            c /= norm;
        }
        let su = unit.svd(false, false).singular_values;
        let (hi, lo) = su.iter().fold((0.0f64, f64::INFINITY), |(h, l), v| (h.max(*v), l.min(*v)));
        assert!(rel(q.kappa_scaled, hi / lo) < 1e-10);
        assert!(q.kappa_scaled < 10.0, "random unit columns are well conditioned: {}", q.kappa_scaled);

        // O1 = (Π σ)^(1/m)/√n; the RMS of the measurements' residual norms.
        let o1 = s.iter().map(|v| v.ln()).sum::<f64>() / m as f64;
        assert!(rel(q.observability.o1, o1.exp() / ((n / 3) as f64).sqrt()) < 1e-12);
        let rms = (f.cost / (n / 3) as f64).sqrt();
        assert!(rel(q.rms_residual, rms) < 1e-14);
        assert_eq!((q.n_rows, q.n_configs), (n, n / 3));
    }

    /// The weakest direction of the scaled Jacobian names the columns of a near-dependence.
    #[test]
    fn weakest_direction_names_the_near_dependence() {
        let (f, _) = fit(60, 6, true, 2);
        let q = Quality::of(&f, 20, &[]);
        let mut cols: Vec<usize> = q.weakest.iter().map(|w| w.0).collect();
        cols.sort_unstable();
        assert_eq!(cols, [1, 2, 5], "{:?}", q.weakest);
        let w = |c: usize| q.weakest.iter().find(|x| x.0 == c).unwrap().1;
        assert!(w(1).signum() == w(2).signum() && w(5).signum() == -w(1).signum(), "{:?}", q.weakest);
        assert!(q.kappa_scaled > 1e3);
        assert_eq!(q.rms_residual, 0.0, "no measurements named");
    }
    /// The cluster-robust standard deviations against the sandwich written out with nalgebra:
    /// c·(JᵀJ)⁻¹(Σ_g J_gᵀ r_g r_gᵀ J_g)(JᵀJ)⁻¹, c = G/(G−1)·(N−1)/(N−m).
    #[test]
    fn cluster_robust_std_matches_an_independent_sandwich() {
        let (n, m) = (240, 5); // 80 measurements of 3 rows, two per pose: 40 poses
        let (f, j) = fit(n, m, false, 3);
        let rows: Vec<(usize, usize)> = (0..n / 3).map(|i| (3 * i, 3)).collect();
        let cluster: Vec<usize> = (0..n / 3).map(|i| i / 2).collect();
        let q = Quality::of(&f, n / 3, &rows);
        let got = q.cluster_robust_std(&f, &rows, &cluster, 40).expect("40 poses ≥ max(30, 2m)");
        let bread = (j.transpose() * &j).try_inverse().unwrap();
        let r = DMatrix::from_column_slice(n, 1, &f.residual);
        let mut meat = DMatrix::<f64>::zeros(m, m);
        for g in 0..40 {
            let jg = j.rows(6 * g, 6);
            let ug = jg.transpose() * r.rows(6 * g, 6);
            meat += &ug * ug.transpose();
        }
        let c = 40.0 / 39.0 * (n as f64 - 1.0) / (n - m) as f64;
        let cov = &bread * meat * &bread * c;
        for a in 0..m {
            assert!(rel(got[a], cov[(a, a)].sqrt()) < 1e-9, "std {a}: {} vs {}", got[a], cov[(a, a)].sqrt());
        }
        // A combination's variance: wᵀ·Cov·w of the same sandwich.
        let w = [0.3, -1.2, 0.0, 2.5, 0.7];
        let wv = DMatrix::from_column_slice(m, 1, &w);
        let want = (wv.transpose() * &cov * &wv)[(0, 0)];
        let v = q.cluster_robust_variance(&f, &rows, &cluster, 40, &w).expect("40 poses");
        assert!(rel(v, want) < 1e-9, "{v} vs {want}");
        assert!(q.cluster_robust_std(&f, &rows, &cluster, 29).is_none(), "too few poses");
    }

    /// Readings of one pose that share an error: the classic σ understates the spread of the
    /// estimates over repeated draws, the reported (robust) σ matches it. With independent errors
    /// the two agree. A linear model, refitted exactly (one Gauss–Newton step is the minimum).
    #[test]
    fn a_shared_error_per_pose_is_covered_by_the_reported_std() {
        let (poses, per, m) = (90, 3, 3);
        let n = poses * per * 3;
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        // Rows of one pose are alike (one configuration seen by three reflectors).
        let base: Vec<Vec<f64>> =
            (0..poses * 3).map(|_| (0..m).map(|_| rng.random_range(-1.0..1.0)).collect()).collect();
        let j = DMatrix::from_fn(n, m, |r, c| {
            let (pose, k) = (r / (per * 3), r % 3);
            base[pose * 3 + k][c] + 0.05 * ((r * 7 + c * 13) % 11) as f64 / 11.0
        });
        let jm = Mat::from_fn(n, m, |r, c| j[(r, c)]);
        let bread = (j.transpose() * &j).try_inverse().unwrap();
        let rows: Vec<(usize, usize)> = (0..poses * per).map(|i| (3 * i, 3)).collect();
        let cluster: Vec<usize> = (0..poses * per).map(|i| i / per).collect();
        for shared in [true, false] {
            let (mut est, mut classic, mut reported) = (Vec::new(), Vec::new(), Vec::new());
            for _ in 0..300 {
                // The error of every row: the pose's own 3-vector, repeated for its readings, or
                // independent per row; 1 µm either way.
                let pose_err: Vec<f64> = (0..poses * 3).map(|_| rng.random_range(-1.0..1.0) * 1.7e-6).collect();
                let e: Vec<f64> = (0..n)
                    .map(|r| {
                        if shared {
                            pose_err[(r / (per * 3)) * 3 + r % 3]
                        } else {
                            rng.random_range(-1.0..1.0) * 1.7e-6
                        }
                    })
                    .collect();
                let y = DMatrix::from_column_slice(n, 1, &e);
                let x = &bread * j.transpose() * &y;
                let res = &y - &j * &x;
                let residual: Vec<f64> = res.iter().copied().collect();
                let cost = residual.iter().map(|v| v * v).sum();
                let f = Fit {
                    x: x.iter().copied().collect(),
                    iterations: 1,
                    residual,
                    jacobian: jm.clone(),
                    weights: vec![1.0; n / 3],
                    cost,
                };
                let mut q = Quality::of(&f, poses, &rows);
                q.make_robust(&f, &rows, &cluster, poses);
                assert!(q.robust);
                est.push(x[0]);
                classic.push(q.std_classic[0]);
                reported.push(q.std[0]);
            }
            let spread = (est.iter().map(|v| v * v).sum::<f64>() / est.len() as f64).sqrt();
            let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
            let (c, r) = (mean(&classic) / spread, mean(&reported) / spread);
            eprintln!("shared {shared}: classic/spread {c:.2}, reported/spread {r:.2}");
            assert!((0.8..1.3).contains(&r), "the reported σ matches the spread: {r}");
            if shared {
                assert!(c < 0.7, "the classic σ understates a shared error: {c}");
            } else {
                assert!((0.85..1.15).contains(&c), "independent errors: classic σ right: {c}");
            }
        }
    }
}
